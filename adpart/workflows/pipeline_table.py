"""The pipeline's comparison as text: a line per task and learner, what each learner knew, and
the survival figures of every layer learner against flat (docs/pipeline.md)."""

from __future__ import annotations

from typing import Any

from adpart.learning.comparison import interval_text, survival_sentence

__all__ = ["block_note", "comparison_lines"]


def block_note(row: dict[str, Any]) -> str | None:
    """Why a layer learner's row starts on another number of blocks than its layer, or None.

    The learner takes the stored layer as given but splits off each live state whose block
    offers an option it cannot start (a layer built before the task was known, such as the
    learned-model regime's phases 1-2, keeps the earlier task's terminal states in one block
    that offers every option), and the reward-variation modes split blocks by where the task's
    reward-state options can start, so the counts of one run's output may differ; this says so.
    """
    layer, start = row.get("partition_blocks"), row.get("initial_blocks")
    if layer is None or start is None or int(layer) == int(start):
        return None
    return (f"{row['learner']} starts on {start} blocks, {row.get('partition')} has {layer}: "
            "the learner splits off each state whose block offers an option the state cannot "
            "start, and splits blocks by where the task's reward-state options can start")


def comparison_lines(rows: list[dict[str, Any]]) -> list[str]:
    """The comparison: a line per learner and task, what each knew, and the survival figures
    of every layer learner against flat (Kaplan-Meier medians; censored runs stay censored)."""
    width = max([13, *(len(r["learner"]) for r in rows)])
    header = (
        f"{'task':<22} {'learner':<{width}} {'blocks':>6} {'within':>7} {'KM episodes':>16} "
        f"{'KM steps':>18}"
    )
    lines = [header, "-" * len(header)]
    for r in rows:
        blocks = str(r.get("initial_blocks", "-"))
        km = r.get("time_to_bound_km") or {}
        if r["learner"] == "planner":
            ep, st = "0", f"0 ({r['compute_seconds']:.2g} s)"
        else:
            ep, st = (_km(km.get(u)) for u in ("episodes", "steps"))
        lines.append(
            f"{r['task'][:22]:<22} {r['learner']:<{width}} {blocks:>6} "
            f"{r['runs_within_bound']:>3}/{r['runs']:<3} {ep:>16} {st:>18}"
        )
    lines.append("")
    lines.append("what each learner knew:")
    seen: set[tuple[str, str]] = set()
    for r in rows:
        key = (r["learner"], str(r.get("knowledge")))
        if r.get("knowledge") and key not in seen:
            seen.add(key)
            lines.append(f"  {r['learner']}: {r['knowledge']}")
    for r in rows:
        if "ratio_to_flat" in r:
            q = r["ratio_to_flat"]
            lines.append(f"{r['task']}: {survival_sentence(r['learner'], 'flat', q)}")
            if "ratio_to_model_based" in r:
                lines.append(f"{r['task']}: " + survival_sentence(
                    r["learner"], r["model_based"], r["ratio_to_model_based"]))
            note = block_note(r)
            if note:
                lines.append(f"  {note}")
            if "chain_cost" in r:
                c = r["chain_cost"]
                lines.append(
                    f"  the layer's cost before {r['task']}: {c['first_task_episodes']} episodes "
                    f"of the first task per run ({c['first_task_steps_mean']:.3g} primitive "
                    "steps), "
                    f"{c['offline_seconds']:.2g} s off-line"
                    + (" (looked up in the knowledge base)" if c["offline_reused"] else ""))
            fired = r.get("firings")
            if fired and fired["total"]:
                lines.append(
                    f"  the inconsistency test fired {fired['total']} times over the runs; "
                    f"{fired['real']} ({fired['real'] / fired['total']:.0%}) were real: the "
                    "added action beats every column the block offered under the task's "
                    "exact Q*"
                    + (f"; {fired['tied']} were ties" if fired.get("tied") is not None else "")
                    + (f", {fired['own_step']} of them the first step of an offered option"
                       if fired.get("tied") and fired.get("own_step") is not None else "")
                    + " (an audit after learning)")
            if q["first_evaluation"] > 1 and _sets_it(r, q["first_evaluation"]):
                lines.append(f"  (the first evaluation, after episode {q['first_evaluation']}, "
                             f"sets {r['learner']}'s median: evaluate more often with "
                             "--eval-every to measure it)")
    return lines


def _sets_it(row: dict[str, Any], first: int) -> bool:
    """Whether a learner's Kaplan-Meier median time is its first evaluation point."""
    km = (row.get("time_to_bound_km") or {}).get("episodes")
    return bool(km) and km[0] <= first


def _km(median: list[float] | None) -> str:
    """``median [low, high]`` of a Kaplan-Meier median; ``never`` where under half arrive."""
    if not median:
        return "-"
    return interval_text(*median, inf="never")

