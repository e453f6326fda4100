"""``adpart sweep``: run a grid of learning experiments from a TOML file, resumably.

Also home of the executor options every fanning-out command shares: ``--executor NAME``,
``--executor-opt KEY=VALUE`` (any declared parameter of the executor plugin) and
``--ray-address ADDRESS`` (shorthand for ``--executor-opt address=ADDRESS``; environment variable
``RAY_ADDRESS``). The work itself is :mod:`adpart.workflows.sweep`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from adpart.cli.common import (
    echo_json,
    executor_options,
    kb_location_options,
    make_executor,
    progress_callback,
)
from adpart.store.location import KBLocation


def _table(rows: list[dict[str, Any]]) -> str:
    heads = ["#", "cell", "status", "gap", "optimal", "run"]
    body = [
        [
            str(r["index"]),
            r["label"],
            r["status"],
            "" if r["final_value_gap"] is None else f"{r['final_value_gap']:.3g}",
            "" if r["optimal_runs"] is None else str(r["optimal_runs"]),
            r["run"] or "",
        ]
        for r in rows
    ]
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(heads)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(heads, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(b, widths, strict=True)) for b in body]
    return "\n".join(line.rstrip() for line in lines)


@click.command(name="sweep")
@click.argument("config", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@executor_options()
@click.option("--dry-run", is_flag=True, help="List the cells and which are stored; run nothing.")
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@kb_location_options
def sweep_cmd(
    config: Path,
    executor: str,
    executor_opts: tuple[str, ...],
    ray_address: str | None,
    dry_run: bool,
    as_json: bool,
    quiet: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
) -> None:
    """Run the grid of experiments in CONFIG (TOML), storing each cell in the knowledge base.

    \b
    A cell is one environment x task x learner-parameter combination x seed; cells already in
    the knowledge base are skipped, so an interrupted sweep resumes where it stopped. Only this
    process writes to the knowledge base; workers (local processes or Ray tasks) learn.
    See docs/scale-out.md for the file format.

    \b
    Examples:
      adpart sweep grid.toml --dry-run
      adpart sweep grid.toml --executor ray --ray-address 10.0.0.5:6379
    """
    from adpart.store import KnowledgeBase, StoreError
    from adpart.workflows.sweep import load_config, plan_cells, preview, run_sweep

    cfg = load_config(config)
    cells = plan_cells(cfg)
    if dry_run:  # a dry run reads: it creates no knowledge base
        try:
            kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts, create=False),
                                    read_only=True)
        except StoreError:  # none there yet: nothing is stored, every cell would run
            kb = None
        try:
            report = preview(cells, kb)
        finally:
            if kb is not None:
                kb.close()
    else:
        kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts))
        try:
            todo = preview(cells, kb).count("pending")
            update, close = progress_callback(
                not quiet and not as_json and todo > 0, todo, f"sweep {cfg.name}"
            )
            ex = make_executor(executor, executor_opts, ray_address)
            try:
                with ex:
                    connect = getattr(ex, "connect", None)
                    if callable(connect):
                        connect()  # a bad cluster address fails before any work
                    report = run_sweep(
                        cells, kb, ex, progress=lambda done, total, _result: update(done, total)
                    )
            finally:
                close()
        finally:
            kb.close()
    data = report.as_dict()
    for row, result in zip(data["results"], report.results, strict=True):
        row["label"] = result.cell.label
    data.update(name=cfg.name, config=str(config), executor=executor, dry_run=dry_run)
    if as_json:
        echo_json(data)
    else:
        click.echo(_table(data["results"]))
        verb = "would run" if dry_run else "stored"
        count = data["pending"] if dry_run else data["stored"]
        where = "" if dry_run else f"; {report.seconds:.1f} s on {executor}"
        click.echo(
            f"sweep {cfg.name}: {len(cells)} cells - {verb} {count}, skipped {data['skipped']} "
            f"(already stored), failed {data['failed']}{where}"
        )
        for r in report.results:
            if r.status == "failed":
                click.echo(f"failed {r.cell.label}: {r.error}", err=True)
    if data["failed"]:
        raise click.exceptions.Exit(1)
