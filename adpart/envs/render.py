"""Draw a grid domain as PNG, one panel per floor, with optional per-state overlays.

:meth:`adpart.envs.base.Domain.render` calls :func:`render_domain`. Cells are placed by the
``x``, ``y`` (and, if present, ``floor``) state features, with ``y`` growing downwards as in the
map language (:mod:`adpart.envs.grid`). Factored states (arm, object ...) share a cell, so each
overlay is reduced to one value per cell: ``values`` by the max, ``marked`` by any, ``labels``
by the first state's label. This is how the dissertation's figures show value functions (Fig.
4.2b), subgoals (the black cells of Fig. 5.1) and partitions.

Walls come from ``domain.layout()`` (a ``(floors, H, W)`` bool array of free cells) when the
domain defines it; otherwise every cell no state occupies is drawn as a wall. A domain may add
drawing of its own through ``domain.draw_extras(ax, floor)`` (e.g. thin walls, stair arrows),
which may return legend entries ``(symbol, colour, meaning)`` for what it drew. Blocks are
coloured so that no two touching blocks share a colour (:func:`adpart.plotting.map_colouring`),
and every marker on the map has a legend entry below it: the marked states, the task's goal and
start letters and the domain's own symbols. The figure is built without pyplot (no global
state, no GUI backend needed).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
from matplotlib import patheffects
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from adpart.envs.base import Task
from adpart.envs.task_language import goal_mask
from adpart.errors import AdpartError, ModelError
from adpart.plotting import block_adjacency, distinct_colours, map_colouring, map_figure

if TYPE_CHECKING:
    from adpart.envs.base import Domain

WALL_RGB = (0.15, 0.15, 0.18)
FREE_RGB = (0.96, 0.96, 0.94)
MARK_COLOUR = "crimson"


def _overlay(arr: np.ndarray | None, S: int, what: str) -> np.ndarray | None:
    if arr is None:
        return None
    out = np.asarray(arr)
    if out.shape != (S,):
        raise ModelError(f"render: {what} has shape {out.shape}; give one entry per state, ({S},)")
    return out


def label_colours(n: int) -> np.ndarray:
    """``(n, 3)`` colours for ``n`` map colours: Set3's 12 light colours (letters and borders
    read on each), :func:`adpart.plotting.distinct_colours` beyond."""
    if n <= 12:
        from matplotlib import colormaps

        return np.asarray(colormaps["Set3"](np.arange(n)))[:, :3]
    return distinct_colours(n)


def _boundaries(lab: np.ndarray) -> np.ndarray:
    """Line segments ``(n, 2, 2)`` between horizontally or vertically adjacent cells whose
    labels differ (both labelled), so blocks that share a colour stay distinguishable."""
    ys, xs = np.nonzero((lab[:, 1:] != lab[:, :-1]) & (lab[:, 1:] >= 0) & (lab[:, :-1] >= 0))
    vertical = np.stack(
        [np.stack([xs + 0.5, ys - 0.5], 1), np.stack([xs + 0.5, ys + 0.5], 1)], axis=1
    )
    ys, xs = np.nonzero((lab[1:, :] != lab[:-1, :]) & (lab[1:, :] >= 0) & (lab[:-1, :] >= 0))
    horizontal = np.stack(
        [np.stack([xs - 0.5, ys + 0.5], 1), np.stack([xs + 0.5, ys + 0.5], 1)], axis=1
    )
    return np.concatenate([vertical, horizontal]).astype(np.float64)


#: Most cells a task's goal or start may cover and still be lettered.
MAX_LETTERED = 20


def _task_letters(domain: Domain, task: Task | str | None, cell: np.ndarray,
                  shape: tuple[int, int, int]) -> dict[str, np.ndarray]:
    """``{"G": cells, "S": cells}`` (bool ``shape``) of the task's goal and start."""
    try:
        chosen = task if isinstance(task, Task) else domain.task(task)
    except AdpartError:
        if task is not None:
            raise
        return {}  # a domain without a default task: nothing to letter
    out = {}  # G: the terminal states; a move-goal: (...) task's goal only, not its holes
    for letter, states in (("G", goal_mask(domain, chosen)), ("S", np.asarray(chosen.initial) > 0)):
        mask = np.zeros(int(np.prod(shape)), dtype=bool)
        mask[cell[np.asarray(states, dtype=bool)]] = True
        if 0 < mask.sum() <= MAX_LETTERED:
            out[letter] = mask.reshape(shape)
    return out


def render_domain(
    domain: Domain,
    path: str | None = None,
    *,
    values: np.ndarray | None = None,
    marked: np.ndarray | None = None,
    labels: np.ndarray | None = None,
    title: str | None = None,
    task: Task | str | None = None,
    value_label: str = "value",
    mark_label: str = "marked states",
) -> Figure:
    """Draw ``domain`` with optional overlays; save a PNG at ``path`` if given.

    Args:
        domain: a domain whose states have ``x`` and ``y`` features (``floor`` optional).
        path: where to write the PNG (None: only return the figure).
        values: ``(S,)`` numbers shown as a colour map with a colour bar (max per cell).
        marked: ``(S,)`` bool, cells with any marked state get a marker (e.g. subgoals).
        labels: ``(S,)`` int, a colour per label (e.g. partition blocks) such that touching
            blocks differ, with block borders.
        title: the figure's title (default: the domain's name).
        task: the task whose goal (``G``: its terminal cells) and start (``S``: the cells it
            starts from) are lettered, white on a black outline so they read on any colour;
            default the domain's default task. Letters are left out when a task has more than
            :data:`MAX_LETTERED` such cells (a factored task ends or starts almost anywhere).
        value_label: the colour bar's label (what ``values`` are: "V*", "count score").
        mark_label: the legend's entry for the ``marked`` cells ("subgoals").

    Returns:
        The matplotlib Figure.
    """
    dyn = domain.dynamics()
    S = dyn.n_states
    feats = dyn.features
    if "x" not in feats or "y" not in feats:
        raise ModelError(
            f"environment {domain.name!r} has no x and y state features, so it cannot be drawn "
            "as a grid; give its states x and y features"
        )
    x = np.asarray(feats["x"], dtype=np.int64)
    y = np.asarray(feats["y"], dtype=np.int64)
    fl = np.asarray(feats.get("floor", np.zeros(S)), dtype=np.int64)
    layout = getattr(domain, "layout", None)
    if callable(layout):
        free = np.asarray(layout(), dtype=bool)
        if free.ndim == 2:
            free = free[None]
    else:
        free = np.zeros((int(fl.max()) + 1, int(y.max()) + 1, int(x.max()) + 1), dtype=bool)
        free[fl, y, x] = True
    F, H, W = free.shape
    cell = (fl * H + y) * W + x

    vals = _overlay(values, S, "values")
    mark = _overlay(marked, S, "marked")
    labs = _overlay(labels, S, "labels")

    panel = 4.5 * min(1.0, max(W, H) / 12.0) + 1.5
    fig, axes = map_figure((panel * W / max(W, H) * F + (1.2 if vals is not None else 0.4),
                            panel * H / max(W, H) + 0.8), F)

    base = np.where(free[..., None], np.array(FREE_RGB), np.array(WALL_RGB))
    cell_lab = None
    if labs is not None:
        first = np.unique(cell, return_index=True)[1]
        uniq, dense = np.unique(labs.astype(np.int64), return_inverse=True)
        cell_lab = np.full(F * H * W, -1, dtype=np.int64)
        cell_lab[cell[first]] = dense[first]
        cell_lab = cell_lab.reshape(F, H, W)
        colour_of = map_colouring(uniq.size, block_adjacency(cell_lab), palette=12)
        colours = label_colours(int(colour_of.max()) + 1)
        coloured = cell_lab.reshape(-1) >= 0
        flat = base.reshape(-1, 3)
        flat[coloured] = colours[colour_of[cell_lab.reshape(-1)[coloured]]]
    cell_val = None
    if vals is not None:
        cell_val = np.full(F * H * W, -np.inf)
        np.maximum.at(cell_val, cell, vals.astype(np.float64))
        cell_val = np.where(np.isfinite(cell_val), cell_val, np.nan).reshape(F, H, W)
    cell_mark = None
    if mark is not None:
        cell_mark = np.zeros(F * H * W, dtype=bool)
        np.logical_or.at(cell_mark, cell, mark.astype(bool))
        cell_mark = cell_mark.reshape(F, H, W)

    letters = _task_letters(domain, task, cell, (F, H, W))
    legend: dict[str, tuple[str, str]] = {}  # meaning -> (symbol, colour)
    image = None
    small = max(W, H) <= 40
    for f, ax in enumerate(axes):
        ax.imshow(base[f], interpolation="nearest")
        if cell_val is not None:
            finite = cell_val[np.isfinite(cell_val)]
            lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
            image = ax.imshow(
                np.ma.masked_invalid(cell_val[f]), cmap="viridis", vmin=lo, vmax=hi,
                interpolation="nearest",
            )
        if cell_lab is not None:
            segs = _boundaries(cell_lab[f])
            if segs.size:
                ax.add_collection(LineCollection(segs, colors="black", linewidths=0.6))
        if cell_mark is not None:
            my, mx = np.nonzero(cell_mark[f])
            ax.scatter(mx, my, s=(40 if small else 6), marker="o", c=MARK_COLOUR,
                       edgecolors="black", linewidths=0.4, zorder=3, gid="marked")
            if my.size:
                legend[mark_label] = ("o", MARK_COLOUR)
        extras = getattr(domain, "draw_extras", None)
        if callable(extras):
            for symbol, colour, meaning in _entries(extras(ax, f)):
                legend.setdefault(meaning, (symbol, colour))
        for letter, cells in letters.items():
            for y_, x_ in np.argwhere(cells[f]):
                ax.text(x_, y_, letter, ha="center", va="center", color="white", gid=letter,
                        fontsize=9 if small else 6, fontweight="bold", zorder=4,
                        path_effects=[patheffects.withStroke(linewidth=2.2, foreground="black")])
                legend.setdefault(_letter_meaning(letter, domain, task), (letter, "black"))
        if F > 1:
            ax.set_title(f"floor {f}", fontsize=9)
        ax.set_xlim(-0.5, W - 0.5)
        ax.set_ylim(H - 0.5, -0.5)
        ax.set_xticks([])
        ax.set_yticks([])
    if image is not None:
        fig.colorbar(image, ax=list(axes), shrink=0.8, label=value_label)
    if legend:
        _legend(fig, legend)
    fig.suptitle(title if title is not None else domain.name, fontsize=11)
    if path is not None:
        fig.savefig(path, dpi=110, format="png")
    return fig



def _entries(drawn: Iterable[tuple[str, str, str]] | None) -> list[tuple[str, str, str]]:
    """The legend entries a domain's ``draw_extras`` returned (None: it names none)."""
    return [] if drawn is None else [tuple(e) for e in drawn]  # type: ignore[misc]


def _letter_meaning(letter: str, domain: Domain, task: Task | str | None) -> str:
    name = domain.task(task).name  # resolved before, by _task_letters
    return f"goal of {name}" if letter == "G" else f"start of {name}"


def _legend(fig: Figure, entries: dict[str, tuple[str, str]]) -> None:
    """One legend below the panels: a proxy marker per meaning (gid ``map-legend``)."""
    from matplotlib.lines import Line2D

    handles = []
    for meaning, (symbol, colour) in entries.items():
        marker = "o" if symbol == "o" else f"${symbol}$"
        handles.append(Line2D([], [], ls="none", marker=marker, color=colour, label=meaning,
                              markeredgecolor="black" if symbol == "o" else colour,
                              markersize=7 if symbol == "o" else 9))
    legend = fig.legend(handles=handles, loc="outside lower center", fontsize=8,
                        ncol=min(4, len(handles)), frameon=False)
    legend.set_gid("map-legend")
