"""`adpart report`: the demo's pipeline run as one self-contained HTML page, opened in Chromium.

The pipeline is the Makefile's demo command with smaller settings appended (as the README test
does for its pipeline line), so the page shows what the demo's would, in seconds. The page is
checked as HTML (its sections, only embedded images, the table's figures against summary.json,
the rerun command recomputing nothing) and in a real headless browser: Debian's chromium and
chromium-driver through selenium, the driver given by path so nothing is downloaded. Where
either is missing that test skips and says which.
"""

from __future__ import annotations

import json
import re
import shlex
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from adpart.cli import cli
from adpart.workflows.pipeline_report import EXPERIMENT_SECTIONS, SECTIONS

ROOT = Path(__file__).resolve().parents[2]
SMALLER = ["--runs", "2", "--episodes", "30", "--first-episodes", "60", "--eval-every", "10"]
CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")


def demo_pipeline_args() -> list[str]:
    make = (ROOT / "Makefile").read_text()
    line = re.search(r"\$\(ADPART\) (pipeline three-floor .*?)--out", make, re.DOTALL).group(1)
    return shlex.split(line.replace("\\\n", " "))


#: the Figure objects the demo's pipeline drew, by the PNG name they were saved as
DRAWN: dict[str, object] = {}


@pytest.fixture(scope="module")
def pipeline_run(tmp_path_factory) -> tuple[Path, Path, Path]:
    """``(kb, out folder, report.html)`` of the demo's pipeline at small settings; the figures
    it saved are kept in :data:`DRAWN` (read back, not looked at as pixels)."""
    from matplotlib.figure import Figure

    root = tmp_path_factory.mktemp("report")
    kb, out = root / "kb", root / "pipeline"
    runner = CliRunner()
    save = Figure.savefig

    def keep(fig, path, *args, **kwargs):
        if isinstance(path, (str, Path)):
            DRAWN[Path(path).name] = fig
        return save(fig, path, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Figure, "savefig", keep)
        res = runner.invoke(cli, [*demo_pipeline_args(), *SMALLER, "--kb", str(kb), "--out",
                                  str(out), "-q"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["report", str(out), "--kb", str(kb)])
    assert res.exit_code == 0, res.output
    page = out / "report.html"
    assert res.output.strip() == f"wrote {page}"
    return kb, out, page


class _Page(HTMLParser):
    """The headings, image sources, links and scripts of a page, and its table cells."""

    def __init__(self) -> None:
        super().__init__()
        self.headings: list[str] = []
        self.images: list[str] = []
        self.external: list[str] = []
        self.scripts = 0
        self.cells: list[str] = []
        self._in: str | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "img":
            self.images.append(a.get("src") or "")
        if tag == "script":
            self.scripts += 1
        for key in ("href", "src"):
            if (a.get(key) or "").startswith(("http:", "https:", "//")):
                self.external.append(a[key])
        if tag in ("h2", "td"):
            self._in = tag
            if tag == "h2":
                self.headings.append("")
            else:
                self.cells.append("")

    def handle_endtag(self, tag: str) -> None:
        if tag == self._in:
            self._in = None

    def handle_data(self, data: str) -> None:
        if self._in == "h2":
            self.headings[-1] += data
        elif self._in == "td":
            self.cells[-1] += data


@pytest.mark.extended
def test_the_page_holds_every_section_and_only_embedded_images(pipeline_run):
    _, out, page = pipeline_run
    parsed = _Page()
    parsed.feed(page.read_text())
    assert parsed.headings == list(SECTIONS)
    assert parsed.scripts == 0 and parsed.external == []
    assert len(parsed.images) >= 4  # a curve per task, the subgoals, the layer (or the maps)
    assert all(src.startswith("data:image/png;base64,") for src in parsed.images)
    summary = json.loads((out / "summary.json").read_text())
    for row in summary["tasks"]:  # the comparison's "within bound" column, from summary.json
        assert f"{row['runs_within_bound']}/{row['runs']}" in parsed.cells
    for stage in summary["stages"]:  # every stored id is in the provenance
        for ref in stage["result"].split(","):
            if re.fullmatch(r"(run|subgoal-set|option|partition):\d+", ref):
                assert ref in parsed.cells


@pytest.mark.extended
def test_the_rerun_command_recomputes_nothing(pipeline_run):
    """The page's command, run on the same knowledge base, takes every stage from it."""
    kb, out, page = pipeline_run
    command = re.search(r"<pre><code>(adpart pipeline .*?)</code></pre>", page.read_text())
    from html import unescape

    words = shlex.split(unescape(command.group(1)))
    assert words[:2] == ["adpart", "pipeline"]
    res = CliRunner().invoke(cli, [*words[1:], "--kb", str(kb), "--out", str(out / "again"),
                                   "--json"])
    assert res.exit_code == 0, res.output
    again = json.loads(res.output)
    first = json.loads((out / "summary.json").read_text())
    assert [s["result"] for s in again["stages"]] == [s["result"] for s in first["stages"]]
    assert all(s["reused"] for s in again["stages"] if s["stage"].startswith("learn-"))


def test_a_folder_without_a_pipeline_summary_is_refused(tmp_path):
    res = CliRunner().invoke(cli, ["report", str(tmp_path), "--kb", str(tmp_path / "kb")])
    assert res.exit_code == 2
    assert "no pipeline summary at" in res.output and "adpart pipeline --out" in res.output
    (tmp_path / "summary.json").write_text('{"something": 1}')
    res = CliRunner().invoke(cli, ["report", str(tmp_path), "--kb", str(tmp_path / "kb")])
    assert res.exit_code == 2 and "neither a pipeline summary" in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "kb").exists()  # refused before the knowledge base is opened


def open_in_chromium(page: Path, shot: Path) -> dict:
    """Open ``page`` in headless Chromium; its title, headings, images' natural widths and
    console errors, and a screenshot at ``shot``. Skips where Chromium or its driver is
    missing."""
    if not CHROMIUM.exists() or not CHROMEDRIVER.exists():
        pytest.skip(f"needs {CHROMIUM} and {CHROMEDRIVER} (apt-get install chromium "
                    "chromium-driver)")
    webdriver = pytest.importorskip("selenium.webdriver", reason="needs selenium (the dev extra)")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                 "--window-size=1280,4000"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=str(CHROMEDRIVER)),
                              options=options)
    try:
        driver.get(page.as_uri())
        seen = {
            "ready": driver.execute_script("return document.readyState"),
            "title": driver.title,
            "widths": driver.execute_script(
                "return Array.from(document.images).map(i => i.complete ? i.naturalWidth : 0)"),
            "headings": driver.execute_script(
                "return Array.from(document.querySelectorAll('h2')).map(h => h.textContent)"),
            "errors": [e for e in driver.get_log("browser") if e["level"] == "SEVERE"],
        }
        assert driver.save_screenshot(str(shot))
    finally:
        driver.quit()
    assert shot.read_bytes()[:4] == b"\x89PNG"
    return seen


@pytest.mark.extended
def test_the_page_renders_in_headless_chromium(pipeline_run):
    """A real browser: the page loads from the file, the console has no error, every image
    decodes (naturalWidth > 0); a screenshot is written beside the page."""
    _, out, page = pipeline_run
    seen = open_in_chromium(page, out / "report.png")
    assert seen["ready"] == "complete"
    assert seen["title"].startswith("adpart report: three-floor")
    assert len(seen["widths"]) >= 4 and min(seen["widths"]) > 0, seen["widths"]
    assert seen["headings"] == list(SECTIONS)
    assert seen["errors"] == []


def test_an_experiments_page(tmp_path):
    """`adpart report` on an experiment's folder: the seed's figures beside ours, every figure
    it wrote embedded, the command that reruns it with its settings; no knowledge base."""
    out = tmp_path / "exp"
    runner = CliRunner()
    res = runner.invoke(cli, ["experiment", "subgoals-two-rooms", "--quick", "--runs", "3",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["report", str(out), "--kb", str(tmp_path / "kb")])
    assert res.exit_code == 0, res.output
    assert not (tmp_path / "kb").exists()
    page = out / "report.html"
    parsed = _Page()
    parsed.feed(page.read_text())
    summary = json.loads((out / "summary.json").read_text())
    assert parsed.headings == list(EXPERIMENT_SECTIONS)
    assert len(parsed.images) == len(summary["figures"]) >= 1
    assert all(src.startswith("data:image/png;base64,") for src in parsed.images)
    assert parsed.scripts == 0 and parsed.external == []
    assert (f"adpart experiment subgoals-two-rooms --out {out} --runs 3 --seed 0 --quick"
            in page.read_text())
    seen = open_in_chromium(page, out / "report.png")
    assert min(seen["widths"]) > 0 and seen["errors"] == []


def test_the_docs_page_names_every_section_and_is_in_the_site():
    page = (ROOT / "docs" / "report.md").read_text()
    listed = re.findall(r"^- \*\*(.+?)\*\*", page, re.MULTILINE)
    assert listed == list(SECTIONS)
    assert "report.md" in (ROOT / "mkdocs.yml").read_text()
    assert "$ adpart report run" in page


@pytest.mark.extended
def test_the_demos_figures_read_back(pipeline_run):
    """Every figure the demo's pipeline wrote: the value-gap axis with its 0, the bound at the
    rows' bound, a thin line per run of every learner, the regime in the title; the maps letter
    each task's own goal and name every marker."""
    from adpart.workflows.resolve import resolve_domain

    _, out, _ = pipeline_run
    summary = json.loads((out / "summary.json").read_text())
    assert {Path(f).name for f in summary["figures"]} <= set(DRAWN)
    domain = resolve_domain("three-floor")
    feats = domain.dynamics().features
    for task in summary["config"]["tasks"]:
        ax = DRAWN[f"{task}.png"].axes[0]
        rows = [r for r in summary["tasks"] if r["task"] == task and r["learner"] != "planner"]
        assert ax.get_yscale() == "symlog" and ax.get_ylim()[0] < 0
        ax.figure.canvas.draw()
        assert {t.get_loc(): t.label1.get_text() for t in ax.yaxis.get_major_ticks()}[0] == "0"
        (bound,) = [line for line in ax.get_lines() if line.get_gid() == "bound"]
        assert list(bound.get_ydata()) == pytest.approx([rows[0]["bound"]] * 2)
        runs = [line for line in ax.get_lines() if line.get_gid() == "run"]
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        medians = [int(m) for t in legend for m in re.findall(r"\(median of (\d+)\)", t)]
        assert medians and all(m == summary["config"]["runs"] for m in medians)
        assert len(runs) == sum(medians)  # every run of every learner drawn
        assert f"three-floor/{task}" in ax.get_title() and "learned-model" in ax.get_title()
        layer = any(r["learner"] == "hierarchical" for r in rows)
        assert any("hierarchical" in t for t in legend) == layer
    for name, fig in DRAWN.items():
        if not name.startswith(("layer_", "subgoals_")):
            continue
        task = name.split("_", 1)[1].removesuffix(".png")
        goal = np.flatnonzero(domain.task(task).terminal)
        cells = {(int(feats["x"][g]), int(feats["y"][g]), int(feats["floor"][g])) for g in goal}
        lettered = {(round(t.get_position()[0]), round(t.get_position()[1]), floor)
                    for floor, ax in enumerate(a for a in fig.axes
                                               if a.get_title().startswith("floor"))
                    for t in ax.texts if t.get_gid() == "G"}
        assert lettered == cells, name
        (legend,) = fig.legends
        names = [t.get_text() for t in legend.get_texts()]
        assert f"goal of {task}" in names and "stairs up" in names
        if name.startswith("subgoals_"):
            assert "subgoals" in names
