"""Figures without pyplot: one constructor and one house style for every plot adpart draws.

Figures are :class:`matplotlib.figure.Figure` objects built directly, never through pyplot: no
backend is chosen for the user (a notebook keeps its own), nothing enters pyplot's global figure
registry, so nothing needs closing, and ``Figure.savefig`` renders PNGs with Agg on any machine.
The domain maps (:mod:`adpart.envs.render`) are built the same way.

:data:`RUN_COLOURS` is a colour-blind-safe cycle (Okabe & Ito) shared by the curve figures, so a
learner keeps its colour across figures of one report.

Value gaps (:func:`gap_axis`) are drawn on one kind of axis everywhere: symmetric-log, linear
from an explicit ``0`` up to a tenth of the success bound and logarithmic above it, so an
optimal policy sits on the tick labelled ``0`` in every figure and rounding noise (a gap of
1e-15) draws as zero instead of as fourteen decades of empty axis.

Block maps (:func:`map_colouring`) colour a partition so that no two blocks that touch share a
colour: a greedy colouring of the blocks' adjacency graph, largest degree first.
"""

from __future__ import annotations

import colorsys
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["GAP_LINEAR_DECADES", "RUN_COLOURS", "block_adjacency", "distinct_colours",
           "gap_axis", "legend_below", "map_colouring", "map_figure", "new_figure"]

#: Okabe & Ito's colour-blind-safe palette, black last.
RUN_COLOURS = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442",
               "#000000")

#: A value-gap axis is linear from 0 up to the success bound divided by 10**GAP_LINEAR_DECADES.
GAP_LINEAR_DECADES = 1


def new_figure(figsize: tuple[float, float] = (7.0, 4.2), **subplots: Any) -> tuple[Figure, Any]:
    """A figure and its axes (``Figure.subplots(**subplots)``), in the house style."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    axes = fig.subplots(**subplots)
    for ax in (axes.flat if hasattr(axes, "flat") else [axes]):
        style_axes(ax)
    return fig, axes


def map_figure(figsize: tuple[float, float], panels: int) -> tuple[Figure, Any]:
    """A figure of ``panels`` map panels side by side (one per floor), laid out to fit their
    colour bar and title; maps keep their own colours (:mod:`adpart.envs.render`)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.subplots(1, panels, squeeze=False)[0]


def style_axes(ax: Axes) -> None:
    """Light grid behind the data, the colour cycle, no top and right spines."""
    from cycler import cycler

    ax.set_prop_cycle(cycler(color=RUN_COLOURS))
    ax.grid(True, alpha=0.3, linewidth=0.6)
    ax.set_axisbelow(True)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)


def gap_threshold(bound: float | None, largest: float) -> float:
    """Where a value-gap axis turns from linear to logarithmic: the success ``bound`` over
    ``10**GAP_LINEAR_DECADES``, or without a finite bound a thousandth of the ``largest`` gap
    drawn (1 when nothing positive is drawn)."""
    if bound is not None and np.isfinite(bound) and bound > 0:
        return float(bound) / 10.0**GAP_LINEAR_DECADES
    return float(largest) * 1e-3 if np.isfinite(largest) and largest > 0 else 1.0


def gap_axis(ax: Axes, threshold: float, top: float) -> None:
    """Make ``ax``'s y axis a value-gap axis (module docstring): symmetric-log with its linear
    part ``[0, threshold]``, a tick labelled ``0`` at 0 just above the bottom, decades above.

    Args:
        ax: the axes.
        threshold: the linear part's end (:func:`gap_threshold`).
        top: the largest value drawn; the axis ends a little above it.
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    ax.set_yscale("symlog", linthresh=threshold, linscale=0.5)
    high = max(float(top), threshold * 10.0)
    first = int(np.floor(np.log10(threshold)))
    last = int(np.ceil(np.log10(high * 1.05)))
    decades = [10.0**k for k in range(first, last + 1) if 10.0**k >= threshold]
    step = max(1, int(np.ceil(len(decades) / 6)))  # at most ~6 labelled decades
    ax.yaxis.set_major_locator(FixedLocator([0.0, *decades[::-1][::step][::-1]]))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(_gap_tick))
    # the top at the decade above the data, so it is labelled; a line at 0 shows above the spine
    ax.set_ylim(-0.2 * threshold, 10.0**last * 1.05)


def _gap_tick(value: float, _pos: object = None) -> str:
    if value == 0:
        return "0"
    exponent = round(np.log10(abs(value)))
    return f"$10^{{{exponent}}}$" if not -1 <= exponent <= 2 else f"{value:g}"


def legend_below(ax: Axes, *, columns: int = 2) -> Any:
    """The axes' legend below the plotting area, off the data, in ``columns`` columns."""
    return ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=columns,
                     fontsize="small", frameon=False)


def distinct_colours(n: int) -> np.ndarray:
    """``(n, 3)`` distinct RGB colours: tab20 for up to 20, golden-ratio hues beyond."""
    if n <= 20:
        from matplotlib import colormaps

        return np.asarray(colormaps["tab20"](np.arange(n)))[:, :3]
    hues = (np.arange(n) * 0.618033988749895) % 1.0
    light = 0.45 + 0.25 * ((np.arange(n) * 7) % 3) / 2
    return np.array([colorsys.hls_to_rgb(h, li, 0.75) for h, li in zip(hues, light, strict=True)])


def block_adjacency(cells: np.ndarray) -> np.ndarray:
    """``(m, 2)`` distinct pairs ``a < b`` of labels that touch in the label grid ``cells``
    (``(..., H, W)`` int, -1 for no label): horizontally or vertically neighbouring cells."""
    grid = np.asarray(cells, dtype=np.int64)
    pairs = []
    for axis in (-1, -2):
        n = grid.shape[axis]
        a = np.take(grid, np.arange(n - 1), axis=axis).ravel()
        b = np.take(grid, np.arange(1, n), axis=axis).ravel()
        keep = (a >= 0) & (b >= 0) & (a != b)
        pairs.append(np.stack([np.minimum(a[keep], b[keep]), np.maximum(a[keep], b[keep])], 1))
    both = np.concatenate(pairs)
    return np.unique(both, axis=0) if both.size else both.reshape(0, 2)


def map_colouring(n_labels: int, adjacency: np.ndarray, palette: int = 12) -> np.ndarray:
    """``(n_labels,)`` colour indices with different colours on every adjacent pair.

    A greedy colouring in Welsh & Powell's order (falling degree): each label takes, among the
    ``palette`` colours none of its coloured neighbours has, the one used least so far, so up to
    ``palette`` labels all get colours of their own and more labels spread evenly over the
    palette. A label whose neighbours hold every palette colour opens a new one (at most
    maximum degree + 1 colours in all).
    """
    neighbours: list[set[int]] = [set() for _ in range(n_labels)]
    for a, b in np.asarray(adjacency, dtype=np.int64).tolist():
        neighbours[a].add(b)
        neighbours[b].add(a)
    colour = np.full(n_labels, -1, dtype=np.int64)
    used = [0] * palette
    for label in sorted(range(n_labels), key=lambda k: (-len(neighbours[k]), k)):
        taken = {int(colour[n]) for n in neighbours[label]}
        free = [c for c in range(len(used)) if c not in taken]
        if not free:
            used.append(0)
            free = [len(used) - 1]
        choice = min(free, key=lambda c: (used[c], c))
        colour[label] = choice
        used[choice] += 1
    return colour
