"""The figures and per-cell tables of ``adpart experiment methods`` (:mod:`.methods`).

* :func:`draw_profile_panels`: the run-score performance profiles, one panel per option learner
  (the decision layer, SMDP Q), each with the methods that use no options, one colour per source;
* :func:`draw_intervals`: one aggregate (the interquartile mean, or the probability of reaching
  the bound sooner than flat) per method with its 95 % CI, methods sorted by the estimate, a
  reference line where a method ties with flat - rliable's interval-estimate plot
  (Agarwal et al. 2021, fig. 1);
* :func:`cell_tables`: a table per cell, a row per method.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["cell_tables", "draw_intervals", "draw_profile_panels", "ratio_text"]


def draw_profile_panels(taus: np.ndarray, profiles: dict[str, dict[str, Any]],
                        learners: Sequence[str], groups: Sequence[str], title: str,
                        path: Path) -> str:
    """The profiles of ``"learner [source]"`` methods, a panel per learner in ``learners``, the
    methods without a source (``[...]``) in every panel; one colour per group of ``groups``."""
    from adpart.experiments.benchmark import profile_lines
    from adpart.plotting import legend_below, new_figure

    fig, axes = new_figure((12.8, 5.0), ncols=len(learners), sharey=True)
    axes = np.atleast_1d(axes)
    plain = {m: p for m, p in profiles.items() if "[" not in m}
    for ax, learner in zip(axes, learners, strict=True):
        mine = {m: p for m, p in profiles.items() if m.startswith(f"{learner} [")}
        profile_lines(ax, taus, {**mine, **plain}, bands=False, groups=list(groups))
        ax.set_title(f"{learner} over each source's options")
        legend_below(ax, columns=3)
    fig.suptitle(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return str(path)


def draw_intervals(estimates: dict[str, Sequence[float]], groups: Sequence[str], *,
                   xlabel: str, reference: float, log: bool, title: str, path: Path) -> str:
    """Each method's ``(estimate, low, high)`` as a point and a bar, the methods sorted by the
    estimate (best at the top: the lowest when ``log``, a time; the highest otherwise, a
    probability), a dotted line at ``reference`` (a tie with flat). An infinite value is drawn at
    the axis's right end with a right-pointing marker and labelled ``never``."""
    import matplotlib as mpl
    from matplotlib import ticker

    from adpart.experiments.benchmark import colour_group
    from adpart.plotting import new_figure

    names = sorted(estimates, key=lambda m: float(estimates[m][0]), reverse=not log)
    values = np.asarray([estimates[m] for m in names], dtype=np.float64).reshape(-1, 3)
    finite = values[np.isfinite(values)]
    if log:
        positive = finite[finite > 0]
        left = float(positive.min()) / 1.5 if positive.size else 0.1
        right = float(max(positive.max(), reference)) * 2.0 if positive.size else 10.0
    else:
        left, right = 0.0, 1.0
    shown = np.where(np.isfinite(values), values, right)
    palette = mpl.colormaps["tab10"].colors
    order = list(groups)
    order += [g for g in dict.fromkeys(colour_group(m) for m in names) if g not in order]
    fig, ax = new_figure((7.6, 0.34 * len(names) + 1.4))
    y = np.arange(len(names))[::-1]
    for row, name in enumerate(names):
        colour = palette[order.index(colour_group(name)) % len(palette)]
        est, low, high = shown[row]
        ax.plot([low, high], [y[row], y[row]], color=colour, linewidth=2.2, alpha=0.6)
        never = not np.isfinite(values[row, 0])
        ax.plot(est, y[row], ">" if never else "o", color=colour, markersize=6)
        if never:
            ax.annotate("never", (est, y[row]), xytext=(-8, 0), textcoords="offset points",
                        ha="right", va="center", fontsize="small")
    ax.axvline(reference, color="0.5", linewidth=0.9, linestyle=":")
    if log:  # ticks at 1, 2 and 5 of each decade, as plain numbers
        ax.set_xscale("log")
        ax.xaxis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(ticker.FormatStrFormatter("%g"))
        ax.xaxis.set_minor_formatter(ticker.NullFormatter())
    ax.set_xlim(left, right * (1.02 if not log else 1.0))
    ax.set_yticks(y, names)
    ax.set_ylim(-0.7, len(names) - 0.3)
    ax.set_xlabel(xlabel)
    ax.set_title(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    return str(path)


def cell_tables(by_regime: dict[str, list[dict[str, Any]]], regime_text: dict[str, str],
                interval_text: Callable[..., str]) -> str:
    """A Markdown page: per regime, a table per cell, a row per method - what it knew, its runs
    within the bound, its Kaplan-Meier median of episodes to the bound and the ratio of that
    median to flat's with a 95 % bootstrap CI (censored runs stay censored)."""
    lines = ["# The field's methods, per cell", "",
             ("`adpart experiment methods` (the aggregates and figures: "
             "[methods.md](methods.md)). Per cell and method: the runs that reached the bound "
             "(a value gap below 10 % of |V*| that stays there), the Kaplan-Meier median of "
             "episodes to it, and the ratio of that median to flat Q-learning's in the same run "
             "with a 95 % bootstrap CI (below 1: sooner than flat; censored runs stay "
             "censored). `flat (no subgoals)`: the source found no subgoal there, so the chain "
             "learned flat."), ""]
    for regime, cells in by_regime.items():
        lines += [f"## {regime} regime", "", regime_text[regime] + ".", ""]
        for number, row in enumerate(cells, 1):
            scale = ("flat's KM median" if row.get("flat_median_within_budget", True)
                     else "flat's budget: its median lies beyond it")
            lines += [(f"### {regime} {number}: `{row['env']}`, {row['tasks'][0]} then "
                      f"{row['tasks'][1]}"), "",
                      f"Scale of the aggregates here: {row['scale']:.4g} episodes ({scale})."
                      + ("" if not row["notes"] else " " + "; ".join(row["notes"]) + "."), "",
                      ("| method | what it knew | within the bound | KM median (episodes) | "
                      "ratio to flat [95 % CI] |"), "|---|---|---|---|---|"]
            for method, entry in row["methods"].items():
                lines.append(f"| {method} | {_known(entry)} | {entry['within']} | "
                             f"{_median(entry)} | {ratio_text(entry, interval_text)} |")
            lines.append("")
    return "\n".join(lines)


def _known(entry: dict[str, Any]) -> str:
    return (entry.get("knowledge") or "not declared").split(" (", 1)[0]


def _median(entry: dict[str, Any]) -> str:
    median = entry.get("km_median")
    return "never" if median is None or not np.isfinite(median) else f"{median:.4g}"


def ratio_text(entry: dict[str, Any], interval_text: Callable[..., str]) -> str:
    """A method's KM-median ratio to flat [95 % CI] on a cell, as the tables print it."""
    if entry.get("flat_instead"):
        return "flat (no subgoals)"
    q = entry["ratio_to_flat"]
    if q.get("ratio") is None:
        if "at_most" in q:
            return f"<= {q['at_most']:.3g}"
        if "at_least" in q:
            return f">= {q['at_least']:.3g}"
        return "never"
    return interval_text(q["ratio"], *q["ci95"], inf="never")
