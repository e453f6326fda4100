"""``adpart experiment``: run one of the seed's experiments, or list them."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from adpart.cli.common import echo_json, field_options, stage_bars
from adpart.learning.settings import Run, fresh_seed


@click.command(name="experiment")
@click.argument("name", required=False)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Output folder [default: adpart-experiments/NAME].",
)
@field_options(Run, ("runs", "seed"))
@click.option("--quick", is_flag=True, help="A small, fast version (few runs and episodes).")
@click.option(
    "--kb",
    "kb_path",
    envvar="ADPART_KB",
    metavar="PATH|URL",
    help="Record into this knowledge base [env ADPART_KB; default: the per-user KB].",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--list", "list_only", is_flag=True, help="List the experiments and exit.")
def experiment_cmd(
    name: str | None,
    out: Path | None,
    runs: int,
    seed: int,
    quick: bool,
    kb_path: str | None,
    as_json: bool,
    list_only: bool,
) -> None:
    """Run experiment NAME (PNG figures, summary.json, summary.md in --out), or --list them."""
    from adpart.experiments import EXPERIMENTS, ExperimentConfig, load_all, run_experiment
    from adpart.workflows.progress import progress_bars
    from adpart.workflows.reports import folder_name

    load_all()
    if list_only or name is None:
        rows = [
            {"name": e.name, "title": e.title, "figures": e.figures}
            for e in sorted(EXPERIMENTS.values(), key=lambda e: e.name)
        ]
        if as_json:
            echo_json(rows)
        else:
            for r in rows:
                click.echo(f"{r['name']:<24} {r['title']} ({r['figures']})")
        return
    out = out or Path("adpart-experiments") / folder_name(name)
    tty = sys.stderr.isatty()
    config = ExperimentConfig(
        out=out,
        runs=runs,
        seed=fresh_seed(seed),
        quick=quick,
        kb=kb_path,
        progress=(lambda message: click.echo(f"[{name}] {message}", err=True))
        if tty
        else (lambda message: None),
    )
    with progress_bars(stage_bars(not as_json)):  # a bar inside each learning stage
        report, files = run_experiment(name, config)
    if as_json:
        echo_json(
            {
                "name": name,
                "files": files,
                "figures": report.figures,
                "findings": report.findings,
                "data": report.data,
            }
        )
        return
    click.echo(f"{report.title} ({report.seconds:.1f} s)")
    for line in report.findings:
        click.echo(f"  - {line}")
    click.echo(
        f"wrote {out}/: summary.json summary.md " + " ".join(Path(f).name for f in report.figures)
    )
