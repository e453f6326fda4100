"""``adpart report``: one self-contained HTML page of a pipeline or experiment run."""

from __future__ import annotations

from pathlib import Path

import click

from adpart.cli.common import kb_location_options
from adpart.store.location import KBLocation


@click.command(name="report")
@click.argument("ref", metavar="FOLDER")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="The page to write [default: FOLDER/report.html].")
@kb_location_options
def report_cmd(ref: str, out: Path | None, kb_path: str | None, kb_artifacts: str | None
               ) -> None:
    """Write one self-contained HTML page of the pipeline or experiment run in FOLDER.

    \b
    FOLDER is what `adpart pipeline --out` (or `adpart experiment --out`) wrote. A pipeline's
    page takes the stored ids from its summary.json and the curves, maps and provenance from
    the knowledge base (--kb): the tasks and regime, the comparison table with CIs, every run's
    curve with the bound, the subgoal and layer maps, the blocks during learning, provenance
    and the command that reruns it. An experiment's page is built from its folder. Images are
    embedded and nothing is loaded at view time (docs/report.md).
    """
    from adpart.workflows.pipeline_report import is_pipeline, load_summary, write_report

    _, summary = load_summary(ref)  # a wrong FOLDER is refused before anything is opened
    if not is_pipeline(summary):
        click.echo(f"wrote {write_report(None, ref, out)}")
        return
    from adpart.store import KnowledgeBase

    location = KBLocation.resolve(kb_path, kb_artifacts)
    kb = KnowledgeBase.open(location, read_only=True)
    try:
        path = write_report(kb, ref, out, kb_label=location.label)
    finally:
        kb.close()
    click.echo(f"wrote {path}")
