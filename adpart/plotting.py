"""Figures without pyplot: one constructor and one house style for every plot adpart draws.

Figures are :class:`matplotlib.figure.Figure` objects built directly, never through pyplot: no
backend is chosen for the user (a notebook keeps its own), nothing enters pyplot's global figure
registry, so nothing needs closing, and ``Figure.savefig`` renders PNGs with Agg on any machine.
The domain maps (:mod:`adpart.envs.render`) are built the same way.

:data:`RUN_COLOURS` is a colour-blind-safe cycle (Okabe & Ito) shared by the curve figures, so a
learner keeps its colour across figures of one report.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["RUN_COLOURS", "map_figure", "new_figure"]

#: Okabe & Ito's colour-blind-safe palette, black last.
RUN_COLOURS = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442",
               "#000000")


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
