"""``adpart options``: learn options to a stored subgoal set and store them with exact models."""

from __future__ import annotations

import time

import click

from adpart.cli.common import echo_json, kb_location_options, registry, settings_options
from adpart.errors import TaskError
from adpart.options.settings import InitiationSettings


@click.command(name="options")
@click.argument("env")
@click.option(
    "--subgoals",
    "subgoals_ref",
    required=True,
    metavar="ID",
    help="The subgoal set (subgoal-set:N or N), from `adpart discover`.",
)
@settings_options(InitiationSettings, "initiation")
@click.option(
    "--cover/--no-cover",
    default=True,
    show_default=True,
    help="With local initiation, also offer each state far from every subgoal the option to "
    "its nearest one (a decision layer needs every state covered).",
)
@click.option(
    "--executor",
    default="serial",
    show_default=True,
    help="Executor plugin for the per-option model computations.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@kb_location_options
def options_cmd(
    env: str,
    subgoals_ref: str,
    initiation: InitiationSettings,
    cover: bool,
    executor: str,
    as_json: bool,
    kb_path: str | None,
    kb_artifacts: str | None,
) -> None:
    """Learn an option to every subgoal of a subgoal set of ENV; store options and models.

    \b
    Each option's initiation set holds the states of the subgoal's basin within --radius steps of
    it (or the whole basin, or every state that reaches it), it
    terminates at the subgoal and outside its initiation set, and its policy is solved by value
    iteration on the pseudo-reward task. Its exact multi-time model (R, discounted F) is computed
    by one sparse LU factorisation. Options already stored for these subgoals are reused.
    """
    from adpart.store import KBLocation, KnowledgeBase
    from adpart.workflows.options import options_for_subgoals
    from adpart.workflows.refs import get_ref

    kb = KnowledgeBase.open(KBLocation.resolve(kb_path, kb_artifacts))
    try:
        subgoal_set = get_ref(kb, subgoals_ref, "subgoal-set")
        env_rec = kb.get("environment", subgoal_set.environment_id)
        if env_rec.name != env:
            raise TaskError(
                f"{subgoal_set.ref} belongs to environment {env_rec.name!r}, not {env!r}"
            )
        start = time.perf_counter()
        with registry().get("executor", executor).create() as ex:
            stored = options_for_subgoals(kb, subgoal_set, initiation, cover=cover,
                                          executor=ex)
        seconds = time.perf_counter() - start
    finally:
        kb.close()
    rows = [
        {
            "id": rec.ref,
            "name": rec.name,
            "subgoal_state": int(opt.subgoal),
            "initiation_states": int(opt.initiation.sum()),
            "mean_discount": float(model.F.sum() / max(1, model.admissible.sum())),
        }
        for rec, opt, model in zip(stored.records, stored.options, stored.models, strict=True)
    ]
    result = {
        "env": env,
        "subgoal_set": subgoal_set.ref,
        "initiation": initiation.initiation,
        "radius": initiation.radius if initiation.initiation == "local" else None,
        "cover": cover if initiation.initiation == "local" else None,
        "reused": stored.reused,
        "seconds": round(seconds, 3),
        "options": rows,
    }
    if as_json:
        echo_json(result)
        return
    verb = "reused" if stored.reused else "learned"
    click.echo(f"{verb} {len(rows)} options to {subgoal_set.ref} on {env} ({seconds:.2f} s)")
    for r in rows:
        click.echo(
            f"  {r['id']:<12} to state {r['subgoal_state']:>6}  "
            f"|I| = {r['initiation_states']:>6}  mean E[gamma^tau] = {r['mean_discount']:.3f}"
        )
