"""One self-contained HTML page per pipeline (or experiment) run (``adpart report``).

A pipeline run is recorded in two places: its output folder's ``summary.json`` (the settings,
the stages with the ids of what each stored, and the comparison rows) and the knowledge base
(the runs, their curves, the subgoal set, the options, the partitions, each with its
provenance). The page takes the settings and the stage ids from ``summary.json`` and everything
else from the knowledge base: the curves are loaded from the stored runs and drawn again, the
maps are drawn from the stored subgoal set and partitions, the provenance is the records' own.

The page holds, in order (:data:`SECTIONS`): the tasks and the regime with what each learner
knew; the comparison table (runs within the bound, Kaplan-Meier medians with their 95 % CIs,
ratios to the baselines with bootstrap CIs); per-task curves of every run with the bound; the
subgoal map and every decision layer; the blocks during learning (each layer run's blocks
before and after refinement, its firings, the map of its median run's final layer);
provenance (versions, settings, seeds, ids); and the command that reruns it. Figures are
embedded as base64 PNG and the style sheet is inline; the page loads nothing and runs no
script, so it opens offline from a file or an attachment.

An experiment's folder (``adpart experiment --out``) gets a page of its own
(:func:`experiment_html`): the dissertation's figures beside the measured findings, every figure
it wrote, its numbers and the command that reruns it, from the folder alone.
"""

from __future__ import annotations

import base64
import io
import json
import platform
import shlex
from html import escape
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import numpy as np

from adpart.errors import TaskError
from adpart.learning.comparison import TIE_TOLERANCE, interval_text, survival_sentence
from adpart.workflows.learning import load_curve
from adpart.workflows.pipeline_table import block_note
from adpart.workflows.refs import parse_ref
from adpart.workflows.store import KnowledgeStore

__all__ = ["EXPERIMENT_SECTIONS", "SECTIONS", "experiment_html", "is_experiment", "is_pipeline",
           "load_summary", "pipeline_command", "report_html", "write_report"]

#: The page's sections (``<h2>`` headings, in order); docs/report.md lists the same.
SECTIONS = ("Tasks and regime", "Comparison", "Learning curves", "Subgoals and layers",
            "Blocks during learning", "Provenance", "Rerun")

#: Packages whose versions the provenance lists.
_PACKAGES = ("adpart", "numpy", "scipy", "numba", "pyarrow", "sqlalchemy", "matplotlib")

_STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;margin:2rem auto;max-width:72rem;
padding:0 1rem;color:#222;line-height:1.45}
h1{font-size:1.5rem}h2{font-size:1.2rem;border-bottom:1px solid #ccc;padding-bottom:.2rem;
margin-top:2rem}table{border-collapse:collapse;margin:.5rem 0;font-size:.9rem}
th,td{border:1px solid #ddd;padding:.25rem .5rem;text-align:left;vertical-align:top}
th{background:#f4f4f4}td.num{text-align:right;font-variant-numeric:tabular-nums}
figure{margin:1rem 0}img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:.85rem;color:#555}pre{background:#f6f6f6;padding:.6rem;white-space:pre-wrap}
code{font-size:.85rem}details{margin:.2rem 0}.note{color:#555;font-size:.9rem}
"""


def load_summary(ref: str | Path) -> tuple[Path, dict[str, Any]]:
    """``(folder, summary)`` of a pipeline or experiment run: ``ref`` is the folder ``adpart
    pipeline --out`` or ``adpart experiment --out`` wrote, or its ``summary.json``; anything else
    is a :class:`TaskError` naming the fix."""
    path = Path(ref)
    summary_path = path / "summary.json" if path.is_dir() else path
    fix = "give the folder `adpart pipeline --out` or `adpart experiment --out` wrote"
    if not summary_path.is_file():
        raise TaskError(f"no pipeline summary at {summary_path}: {fix} (it holds summary.json)")
    try:
        summary = json.loads(summary_path.read_text())
    except (OSError, ValueError) as exc:
        raise TaskError(f"cannot read {summary_path} as JSON ({exc}); {fix}") from None
    if not isinstance(summary, dict) or not (is_pipeline(summary) or is_experiment(summary)):
        raise TaskError(f"{summary_path} is neither a pipeline summary (config, stages, tasks) "
                        f"nor an experiment's (name, findings, figures); {fix}")
    return summary_path.parent, summary


def is_pipeline(summary: dict[str, Any]) -> bool:
    """Whether ``summary`` is what ``adpart pipeline`` writes."""
    return {"config", "stages", "tasks"} <= summary.keys()


def is_experiment(summary: dict[str, Any]) -> bool:
    """Whether ``summary`` is what ``adpart experiment`` writes."""
    return {"name", "findings", "figures"} <= summary.keys()


def pipeline_command(config: dict[str, Any]) -> str:
    """The ``adpart pipeline`` command line that reruns ``config`` (a summary's ``config``):
    every run setting spelled out, the other settings where they differ from the defaults."""
    from adpart.workflows.pipeline import PipelineConfig

    default = PipelineConfig(env=config["env"], tasks=tuple(config["tasks"]))
    words = ["adpart", "pipeline", config["env"], "--tasks", ",".join(config["tasks"])]
    for key in ("runs", "episodes", "first_episodes", "seed", "eval_every"):
        words += [f"--{key.replace('_', '-')}", str(config[key])]
    words += ["--regime", config["regime"]]
    for key in ("detector", "criterion", "flat_learner", "hierarchy"):
        if config.get(key) != getattr(default, key):
            words += [f"--{key.replace('_', '-')}", str(config[key])]
    for section in ("initiation", "partition"):
        for key, value in (config.get(section) or {}).items():
            if value != getattr(getattr(default, section), key):
                words += [f"--{key.replace('_', '-')}", str(value)]
    options = {"detector_params": "--detector-opt", "criterion_params": "--criterion-opt",
               "flat_params": "--flat-opt", "hierarchical_params": "--hier-opt",
               "hierarchy_params": "--hierarchy-opt"}
    for key, option in options.items():
        for name, value in (config.get(key) or {}).items():
            words += [option, f"{name}={value}"]
    if not config.get("fallback", True):
        words.append("--no-fallback")
    if not config.get("baseline", True):
        words.append("--no-baseline")
    if not config.get("model_baseline", True):
        words.append("--no-model-baseline")
    return shlex.join(words)


def write_report(kb: KnowledgeStore | None, ref: str | Path, out: Path | None = None, *,
                 kb_label: str = "") -> Path:
    """Write the page of the run at ``ref`` (:func:`load_summary`) to ``out`` (default
    ``report.html`` in its folder); return the path written. A pipeline's page reads ``kb``;
    an experiment's (:func:`experiment_html`) only its folder."""
    folder, summary = load_summary(ref)
    target = out or folder / "report.html"
    if is_pipeline(summary):
        if kb is None:
            raise TaskError("a pipeline's page reads its knowledge base: give --kb")
        html = report_html(kb, summary, source=str(folder), kb_label=kb_label)
    else:
        html = experiment_html(folder, summary)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(html, encoding="utf-8")
    except OSError as exc:
        raise TaskError(f"cannot write {target}: {exc.strerror}; choose another --out") from None
    return target


#: An experiment's page's sections, in order.
EXPERIMENT_SECTIONS = ("What the dissertation reports", "What we measured", "Figures",
                       "Provenance", "Rerun")


def experiment_html(folder: Path, summary: dict[str, Any]) -> str:
    """The page of an ``adpart experiment`` run: the seed's figures beside the measured
    findings, every figure it wrote (embedded from the folder), the numbers and the command
    that reruns it."""
    body = [f"<h1>{escape(summary.get('title') or summary['name'])}</h1>",
            (f"<p class=note>experiment {escape(summary['name'])} in {escape(str(folder))}, "
             f"{float(summary.get('seconds') or 0):.1f} s</p>")]
    body += _section("What the dissertation reports", [
        "<ul>" + "".join(f"<li>{escape(x)}</li>" for x in summary.get("seed_reports", []))
        + "</ul>"])
    body += _section("What we measured", [
        "<ul>" + "".join(f"<li>{escape(x)}</li>" for x in summary["findings"]) + "</ul>"])
    figures = []
    for name in summary["figures"]:
        path = folder / Path(name).name
        if path.suffix == ".png" and path.is_file():
            data = base64.b64encode(path.read_bytes()).decode("ascii")
            figures.append(f"<figure><img alt='{escape(path.stem, quote=True)}' "
                           f"src='data:image/png;base64,{data}'><figcaption>"
                           f"{escape(path.name)}</figcaption></figure>")
        else:
            figures.append(f"<p>{escape(path.name)}: not in {escape(str(folder))}</p>")
    body += _section("Figures", figures or ["<p>No figures.</p>"])
    versions = ", ".join(_versions())
    numbers = json.dumps(summary.get("data", {}), sort_keys=True, indent=1, default=str)
    body += _section("Provenance", [
        (f"<p>Settings {escape(json.dumps(summary.get('settings', {}), sort_keys=True))}; "
         f"page made with Python {escape(platform.python_version())}, {escape(versions)}.</p>"),
        (f"<details><summary>every number (summary.json)</summary><pre><code>"
         f"{escape(numbers)}</code></pre></details>")])
    words = ["adpart", "experiment", summary["name"], "--out", str(folder)]
    settings = summary.get("settings") or {}
    for key in ("runs", "seed"):
        if key in settings:
            words += [f"--{key}", str(settings[key])]
    if settings.get("quick"):
        words.append("--quick")
    body += _section("Rerun", [f"<pre><code>{escape(shlex.join(words))}</code></pre>"])
    title = escape(f"adpart report: experiment {summary['name']}")
    return ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
            f"<meta name=viewport content='width=device-width, initial-scale=1'>"
            f"<title>{title}</title><style>{_STYLE}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")


def report_html(kb: KnowledgeStore, summary: dict[str, Any], *, source: str = "",
                kb_label: str = "") -> str:
    """The page (module docstring) of the pipeline run ``summary`` over the records of ``kb``."""
    config = summary["config"]
    stages = summary["stages"]
    rows = summary["tasks"]
    env = config["env"]
    body = [f"<h1>{escape(env)}: {escape(' → '.join(config['tasks']))}</h1>",
            (f"<p class=note>pipeline run of {escape(source)} over the knowledge base "
             f"{escape(kb_label)}</p>")]
    body += _section("Tasks and regime", _tasks_and_regime(config, rows))
    body += _section("Comparison", _comparison(rows))
    body += _section("Learning curves", _curves(kb, config, stages, rows))
    body += _section("Subgoals and layers", _maps(kb, config, stages))
    body += _section("Blocks during learning", _blocks(kb, config, stages))
    body += _section("Provenance", _provenance(kb, config, stages))
    body += _section("Rerun", [
        ("<p>Every step looks in the knowledge base for a result of the same request first, so "
         "on this knowledge base the command recomputes nothing:</p>"),
        (f"<pre><code>{escape(pipeline_command(config))} --out {escape(shlex.quote(source))}"
         "</code></pre>")])
    title = escape(f"adpart report: {env} {','.join(config['tasks'])}")
    return ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
            f"<meta name=viewport content='width=device-width, initial-scale=1'>"
            f"<title>{title}</title><style>{_STYLE}</style></head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")


# ----------------------------------------------------------------------------- the sections


def _section(title: str, parts: list[str]) -> list[str]:
    anchor = title.lower().replace(" ", "-")
    return [f"<h2 id={anchor}>{escape(title)}</h2>", *parts]


def _table(header: list[str], rows: list[list[str]], numeric: set[int] = frozenset()) -> str:
    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    lines = []
    for row in rows:
        cells = "".join(f"<td class=num>{c}</td>" if i in numeric else f"<td>{c}</td>"
                        for i, c in enumerate(row))
        lines.append(f"<tr>{cells}</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(lines)}</tbody></table>"


def _png(fig: Any, alt: str, caption: str) -> str:
    """``fig`` as an embedded PNG (base64 data URI) in a captioned figure."""
    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=100, format="png")
    data = base64.b64encode(buffer.getvalue()).decode("ascii")
    return (f"<figure><img alt='{escape(alt, quote=True)}' src='data:image/png;base64,{data}'>"
            f"<figcaption>{escape(caption)}</figcaption></figure>")


def _tasks_and_regime(config: dict[str, Any], rows: list[dict[str, Any]]) -> list[str]:
    first, *later = config["tasks"]
    regime = {"learned-model": "the learned-model regime: the subgoals, options and layer are "
                               f"built on the dynamics estimated from {first}'s runs",
              "true-model": "the true-model regime: the subgoals, options and layer are built "
                            "on the true model (the seed's figures)"}.get(config["regime"],
                                                                          config["regime"])
    parts = [(f"<p><b>{escape(first)}</b> is learned flat first; "
              f"{escape(', '.join(later))} then transfer, in {escape(regime)}. "
              f"{config['runs']} runs per learner, {config['first_episodes']} episodes of the "
              f"first task, {config['episodes']} of each later one, scored exactly every "
              f"{config['eval_every']} episodes; the success bound is "
              f"{config['gap_fraction']:.0%} of |V*| at the start.</p>")]
    seen: dict[str, str] = {}
    for r in rows:
        if r.get("knowledge") and r["learner"] not in seen:
            seen[r["learner"]] = str(r["knowledge"])
    parts.append(_table(["learner", "what it knew"],
                        [[escape(k), escape(v)] for k, v in seen.items()]))
    return parts


def _gap(value: Any, v_star: Any) -> str:
    """A final value gap: within rounding of 0 (:data:`TIE_TOLERANCE` of the value scale) is 0."""
    if value is None or not np.isfinite(value):
        return "-"
    scale = max(1.0, abs(v_star)) if v_star is not None and np.isfinite(v_star) else 1.0
    return "0" if abs(value) <= TIE_TOLERANCE * scale else f"{value:.3g}"


def _km(entry: Any) -> str:
    if not entry:
        return "-"
    return interval_text(*(float("inf") if x is None else x for x in entry), inf="never")


def _comparison(rows: list[dict[str, Any]]) -> list[str]:
    table = []
    for r in rows:
        km = r.get("time_to_bound_km") or {}
        planner = r["learner"] == "planner"
        ratio = r.get("ratio_to_flat")
        table.append([
            escape(r["task"]), escape(r["learner"]),
            escape(str(r.get("initial_blocks", "-"))),
            f"{r['runs_within_bound']}/{r['runs']}",
            "0" if planner else _km(km.get("episodes")),
            "0" if planner else _km(km.get("steps")),
            "-" if planner else _gap(r.get("final_gap_mean"), r.get("v_star_start")),
            _ratio(ratio) if ratio else "",
            _ratio(r["ratio_to_model_based"]) if r.get("ratio_to_model_based") else "",
        ])
    parts = [_table(["task", "learner", "blocks", "within bound", "KM episodes [95% CI]",
                     "KM steps [95% CI]", "final gap (mean)", "÷ flat (episodes)",
                     "÷ model-based (episodes)"], table, numeric={2, 3, 4, 5, 6, 7, 8})]
    parts.append("<p class=note>Kaplan-Meier median time to the bound over runs; a run that "
                 "never stays within the bound is censored, and \"never\" means fewer than half "
                 "reach it. Ratios are of the Kaplan-Meier medians with a 95 % bootstrap CI over "
                 "runs. A final gap within 1e-9 of the value scale is rounding, shown as 0.</p>")
    sentences = []
    for r in rows:
        if r.get("ratio_to_flat"):
            sentences.append(f"{r['task']}: "
                             + survival_sentence(r["learner"], "flat", r["ratio_to_flat"]))
        if r.get("ratio_to_model_based"):
            sentences.append(f"{r['task']}: " + survival_sentence(
                r["learner"], r["model_based"], r["ratio_to_model_based"]))
        if r.get("fallback"):
            sentences.append(f"{r['task']}: {r['fallback']}")
        if block_note(r):
            sentences.append(f"{r['task']}: {block_note(r)}")
    parts += [f"<p>{escape(s)}</p>" for s in sentences]
    return parts


def _ratio(q: dict[str, Any]) -> str:
    if q.get("ratio") is not None:
        return interval_text(q["ratio"], *(float("inf") if x is None else x for x in q["ci95"]),
                             inf="∞")
    if "at_most" in q:
        return f"≤ {q['at_most']:.3g}"
    if "at_least" in q:
        return f"≥ {q['at_least']:.3g}"
    return "undefined"


def _learn_stages(stages: list[dict[str, Any]]) -> dict[str, dict[str, str]]:
    """``{task: {label: run ref}}`` of every learning stage, in order, each run once."""
    out: dict[str, dict[str, str]] = {}
    for s in stages:
        if s["stage"].startswith("learn-") and s["result"].startswith("run:"):
            runs = out.setdefault(s["task"], {})
            if s["result"] not in runs.values():
                runs[s["stage"].removeprefix("learn-")] = s["result"]
    return out


def _curves(kb: KnowledgeStore, config: dict[str, Any], stages: list[dict[str, Any]],
            rows: list[dict[str, Any]]) -> list[str]:
    from adpart.learning.curves import curve_figure

    parts = []
    for task, runs in _learn_stages(stages).items():
        curves = {f"{label} ({ref})": load_curve(kb, kb.get("run", parse_ref(ref, "run")))
                  for label, ref in runs.items()}
        bound = next((r["bound"] for r in rows if r["task"] == task and r.get("bound")), None)
        fig = curve_figure(
            curves, "value_gap", bound=bound,
            bound_label=f"success bound ({config['gap_fraction']:.0%} of |V*|)",
            title=(f"{config['env']}/{task}: value gap of the greedy policy\n"
                   f"{config['runs']} runs per learner, {config['regime']} regime"))
        parts.append(_png(fig, f"value gap on {task}",
                          f"{task}: every run (thin), the median and quartiles of each learner, "
                          "the success bound dashed; 0 is an optimal policy."))
    return parts


def _maps(kb: KnowledgeStore, config: dict[str, Any], stages: list[dict[str, Any]]) -> list[str]:
    from adpart.errors import ModelError
    from adpart.workflows.resolve import resolve_domain

    domain = resolve_domain(config["env"])
    parts = []
    try:
        for s in stages:
            if s["stage"] == "discover":
                found = kb.get("subgoal-set", parse_ref(s["result"], "subgoal-set"))
                mask = np.zeros(domain.n_states, dtype=bool)
                mask[list(found.states)] = True
                scores = kb.load(found, "scores") if found.scores else None
                fig = domain.render(
                    marked=mask, values=scores, task=s["task"], mark_label="subgoals",
                    value_label=f"{found.detector} score",
                    title=f"{config['env']}: {int(mask.sum())} subgoals of {found.ref} in the "
                          f"policy of {s['task']} ({found.detector})")
                parts.append(_png(fig, f"subgoals of {found.ref}",
                                  f"{found.ref}: the subgoals found ({found.detector}); the "
                                  "colour is the detector's score."))
            elif s["stage"] in ("partition", "hierarchy") and s["result"].startswith("partition:"):
                record = kb.get("partition", parse_ref(s["result"], "partition"))
                fig = domain.render(
                    labels=kb.load(record, "labels"), task=s["task"],
                    title=f"{config['env']}/{s['task']}: decision layer {record.ref} "
                          f"({record.kind}), {record.n_blocks} blocks before refinement")
                parts.append(_png(fig, f"layer {record.ref}",
                                  f"{record.ref}: {record.n_blocks} blocks (delta "
                                  f"{record.delta:g}, epsilon {record.epsilon:g}); touching "
                                  "blocks differ in colour."))
    except ModelError:
        parts.append(f"<p>{escape(config['env'])} has no map (no x, y state features).</p>")
    return parts or ["<p>This run built no layer (no subgoals, or the fallback).</p>"]


def _blocks(kb: KnowledgeStore, config: dict[str, Any], stages: list[dict[str, Any]]
            ) -> list[str]:
    from adpart.errors import ModelError
    from adpart.plotting import legend_below, new_figure
    from adpart.workflows.resolve import resolve_domain

    parts = []
    for s in stages:
        if s["stage"] != "learn-hierarchical":
            continue
        run = kb.get("run", parse_ref(s["result"], "run"))
        m = run.metrics
        final = [int(b) for b in m.get("final_blocks") or []]
        if not final:
            continue
        start = int(m.get("initial_blocks", 0))
        fired = [int(f) for f in m.get("firings") or []]
        real = [int(f) for f in m.get("real_firings") or []]
        fig, ax = new_figure((7.0, 3.6))
        runs = np.arange(len(final))
        ax.bar(runs, final, color="#0072B2", label="blocks after refinement", gid="final")
        ax.axhline(start, color="0.2", ls="--", lw=1.0, label=f"{start} blocks at the start",
                   gid="initial")
        ax.set_xlabel("run")
        ax.set_ylabel("blocks")
        ax.set_title(f"{config['env']}/{s['task']}: blocks of {run.ref}'s layer per run",
                     fontsize="medium")
        legend_below(ax)
        fig.tight_layout()
        parts.append(_png(fig, f"blocks of {run.ref}",
                          f"{run.ref}: {start} blocks at the start, median "
                          f"{int(np.median(final))} after refinement."))
        table = [[str(k), str(start), str(final[k]),
                  str(fired[k]) if k < len(fired) else "-",
                  str(real[k]) if k < len(real) else "-"] for k in range(len(final))]
        parts.append(_table(["run", "blocks at the start", "after", "firings",
                             "real firings"], table, numeric={0, 1, 2, 3, 4}))
        learned = m.get("final_partitions") or []
        if learned:
            median_run = int(np.argsort(final)[len(final) // 2])
            record = kb.get("partition", int(learned[median_run]))
            try:
                fig = resolve_domain(config["env"]).render(
                    labels=kb.load(record, "labels"), task=s["task"],
                    title=f"{config['env']}/{s['task']}: run {median_run}'s layer after "
                          f"learning, {record.ref}, {record.n_blocks} blocks")
            except ModelError:
                continue
            parts.append(_png(fig, f"learned layer {record.ref}",
                              f"{record.ref}: the layer run {median_run} (the median's) ended "
                              "on."))
    return parts or ["<p>No layer was learned on (no hierarchical run).</p>"]


def _provenance(kb: KnowledgeStore, config: dict[str, Any], stages: list[dict[str, Any]]
                ) -> list[str]:
    refs: list[str] = []
    for s in stages:
        for ref in str(s["result"]).split(","):
            kind, _, number = ref.partition(":")
            if number.isdigit() and kind in ("run", "subgoal-set", "option", "partition") \
                    and ref not in refs:
                refs.append(ref)
    table = []
    for ref in refs:
        kind, _, number = ref.partition(":")
        record = kb.get(kind, int(number))
        p = record.provenance
        seed = getattr(record, "seed", None)
        params = json.dumps(p.parameters, sort_keys=True, default=str)
        table.append([escape(ref), escape(p.plugin or getattr(record, "learner", "")),
                      escape(p.plugin_version), escape(p.adpart_version),
                      escape(p.created_at.isoformat(timespec="seconds")),
                      "" if seed is None else str(seed),
                      (f"<details><summary>{len(p.parameters)} settings</summary>"
                       f"<code>{escape(params)}</code></details>")])
    versions = _versions()
    settings = json.dumps(config, sort_keys=True, indent=1)
    return [
        _table(["record", "plugin", "plugin version", "adpart", "created", "seed", "settings"],
               table),
        (f"<p>Page made with Python {escape(platform.python_version())}, "
         f"{escape(', '.join(versions))}.</p>"),
        (f"<details><summary>the pipeline's settings (summary.json)</summary><pre><code>"
         f"{escape(settings)}</code></pre></details>"),
    ]


def _versions() -> list[str]:
    """``name version`` of each of :data:`_PACKAGES` installed here."""
    versions = []
    for name in _PACKAGES:
        try:
            versions.append(f"{name} {importlib_metadata.version(name)}")
        except importlib_metadata.PackageNotFoundError:
            continue
    return versions
