"""Learning curves: per-run, per-episode records of a learner, as columns.

DESIGN.md, "Learning curves".

A :class:`LearningCurve` is a long table with one row per (run, episode), runs first:

========================  =======  ===============================================================
column                    dtype    meaning
========================  =======  ===============================================================
``run``                   int64    run index ``0..K-1``
``episode``               int64    episode number ``1..N`` of that run (the seed's "iterations")
``steps``                 int64    primitive steps taken in the episode
``decisions``             int64    decisions taken in the episode (``= steps`` for flat Q; an SMDP
                                   learner counts one decision per option choice)
``return``                float64  undiscounted return ``sum_t r_t`` of the episode
``discounted_return``     float64  discounted return ``sum_t gamma**t r_t`` from the episode's start
``eval_value``            float64  exact value ``sum_s mu(s) V^pi(s)`` of the greedy policy at the
                                   start distribution ``mu`` after this episode; NaN on episodes
                                   that were not evaluated (every ``eval_every``-th and the
                                   last are)
``value_gap``             float64  ``sum_s mu(s) V*(s) - eval_value``; NaN where not evaluated
========================  =======  ===============================================================

The greedy policy is scored by exact policy evaluation on the true model against ``V*``
(DESIGN.md: "a value gap, not only a noisy return"). ``metadata`` carries what is needed to read
the numbers (learner, gamma, ``V*`` at the start distribution, seed) and travels with the Arrow
table as schema metadata, so a curve stored as Parquet reads back whole.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from adpart.errors import ModelError, TaskError
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.solvers import solve
from adpart.mdp.start_value import StartValueSolver

__all__ = [
    "COLUMNS",
    "LearningCurve",
    "StartValues",
    "curve_figure",
    "distinct_rows",
    "episodes_within",
    "optimal_start_value",
    "plot_curves",
    "start_distribution",
    "start_values",
]

#: Column names and dtypes, in table order.
COLUMNS: dict[str, type] = {
    "run": np.int64,
    "episode": np.int64,
    "steps": np.int64,
    "decisions": np.int64,
    "return": np.float64,
    "discounted_return": np.float64,
    "eval_value": np.float64,
    "value_gap": np.float64,
}

_METADATA_KEY = b"adpart.learning_curve"


@dataclass(frozen=True, eq=False)
class LearningCurve:
    """Per-episode records of ``K`` runs of ``N`` episodes each (see the module docstring).

    Build it with :meth:`from_matrices`; read columns with ``curve["steps"]`` (long form) or
    :meth:`matrix` (``(K, N)`` form).
    """

    columns: dict[str, np.ndarray]
    metadata: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        missing = [c for c in COLUMNS if c not in self.columns]
        if missing:
            raise TaskError(f"learning curve lacks columns {missing}; it needs {list(COLUMNS)}")
        lengths = {len(self.columns[c]) for c in COLUMNS}
        if len(lengths) != 1:
            raise TaskError(f"learning curve columns have different lengths {sorted(lengths)}")
        cols = {c: np.ascontiguousarray(self.columns[c], dtype=COLUMNS[c]) for c in COLUMNS}
        for arr in cols.values():
            arr.setflags(write=False)
        object.__setattr__(self, "columns", cols)

    @classmethod
    def from_matrices(
        cls,
        *,
        steps: np.ndarray,
        decisions: np.ndarray,
        returns: np.ndarray,
        discounted_returns: np.ndarray,
        eval_value: np.ndarray,
        value_gap: np.ndarray,
        metadata: Mapping[str, object] | None = None,
    ) -> LearningCurve:
        """A curve from ``(K, N)`` matrices indexed by (run, episode - 1)."""
        K, N = np.shape(steps)
        cols = {
            "run": np.repeat(np.arange(K, dtype=np.int64), N),
            "episode": np.tile(np.arange(1, N + 1, dtype=np.int64), K),
            "steps": np.asarray(steps).reshape(-1),
            "decisions": np.asarray(decisions).reshape(-1),
            "return": np.asarray(returns).reshape(-1),
            "discounted_return": np.asarray(discounted_returns).reshape(-1),
            "eval_value": np.asarray(eval_value).reshape(-1),
            "value_gap": np.asarray(value_gap).reshape(-1),
        }
        return cls(cols, dict(metadata or {}))

    def __getitem__(self, column: str) -> np.ndarray:
        try:
            return self.columns[column]
        except KeyError:
            raise TaskError(
                f"no learning-curve column {column!r}; columns are {list(COLUMNS)}"
            ) from None

    def __len__(self) -> int:
        return len(self.columns["run"])

    @property
    def n_runs(self) -> int:
        return int(self.columns["run"].max()) + 1 if len(self) else 0

    @property
    def n_episodes(self) -> int:
        return len(self) // self.n_runs if len(self) else 0

    def matrix(self, column: str) -> np.ndarray:
        """Column ``column`` as a ``(K, N)`` array (rows are runs, columns episodes)."""
        return self[column].reshape(self.n_runs, self.n_episodes)

    def evaluated_episodes(self) -> np.ndarray:
        """1-based episode numbers at which the greedy policy was evaluated."""
        gap = self.matrix("eval_value")
        done = ~np.all(np.isnan(gap), axis=0)
        return np.flatnonzero(done) + 1

    def episodes_to_gap(self, threshold: float) -> np.ndarray:
        """Per run, the first evaluated episode from which ``value_gap <= threshold`` holds at
        every later evaluation (``-1`` if the last evaluation is still above it).

        The answer to the knowledge base's "how fast did each task learn" in episodes.
        """
        return episodes_within(self.matrix("value_gap"), self.evaluated_episodes(), threshold)

    def to_dict(self) -> dict[str, np.ndarray]:
        """The columns as a dict of (read-only) numpy arrays."""
        return dict(self.columns)

    @classmethod
    def from_dict(
        cls, columns: Mapping[str, np.ndarray], metadata: Mapping[str, object] | None = None
    ) -> LearningCurve:
        return cls(dict(columns), dict(metadata or {}))

    def to_arrow(self):  # -> pyarrow.Table (pyarrow imported lazily)
        """A ``pyarrow.Table``: the columns in :data:`COLUMNS` order, the metadata as JSON."""
        import pyarrow as pa

        table = pa.table({c: self.columns[c] for c in COLUMNS})
        meta = json.dumps(self.metadata, sort_keys=True, default=_json_default).encode()
        return table.replace_schema_metadata({_METADATA_KEY: meta})

    @classmethod
    def from_arrow(cls, table) -> LearningCurve:
        """Inverse of :meth:`to_arrow`."""
        raw = (table.schema.metadata or {}).get(_METADATA_KEY)
        meta = json.loads(raw) if raw else {}
        return cls({c: table.column(c).to_numpy() for c in COLUMNS}, meta)


def episodes_within(value_gap: np.ndarray, evaluated: np.ndarray, threshold: float
                    ) -> np.ndarray:
    """Per run, the first of the ``evaluated`` episodes (1-based columns of the ``(K, N)``
    ``value_gap``) from which the gap stays ``<= threshold`` at every later evaluation; ``-1``
    where the last evaluation is still above it (NaN counts as above). The one rule behind
    :meth:`LearningCurve.episodes_to_gap` and :func:`adpart.experiments.stats.
    episodes_to_threshold`."""
    evaluated = np.asarray(evaluated, dtype=np.int64)
    ok = np.asarray(value_gap)[:, evaluated - 1] <= threshold  # NaN compares False
    # suffix-all: ok from this evaluation on
    stays = np.flip(np.logical_and.accumulate(np.flip(ok, axis=1), axis=1), axis=1)
    first = np.argmax(stays, axis=1)
    return np.where(stays.any(axis=1), evaluated[first], -1).astype(np.int64)


def _json_default(value: object) -> object:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot store {type(value).__name__} in learning-curve metadata")


_X_AXES = ("episode", "steps", "decisions")
_BANDS = ("quartiles", "minmax", "sd")
#: Runs up to which every run is also drawn as a thin line under the band.
PER_RUN_LINES = 100
#: The success bound's default fraction of ``|V*(start)|`` (a run has learned a task once its
#: greedy policy's value gap stays within it): the one default of the pipeline's
#: ``gap_fraction``, the comparisons, the figures' bound and every stored run's per-run figures
#: (:func:`adpart.learning.comparison.success_bound`).
SUCCESS_FRACTION = 0.05
#: Value gaps within this fraction of ``max(1, |V*(start)|)`` are rounding, drawn as 0: exact
#: evaluations of the optimal policy differ from ``V*`` by ~1e-15 (either sign).
ROUNDING = 1e-9


def curve_figure(
    curve: LearningCurve | Mapping[str, LearningCurve],
    metric: str = "value_gap",
    *,
    x: str = "episode",
    band: str = "quartiles",
    logy: bool | None = None,
    title: str | None = None,
    bound: float | None = None,
    bound_label: str | None = None,
) -> Any:
    """The figure :func:`plot_curves` saves: every run, their median and a band, the bound.

    Args:
        curve: one curve, or ``{label: curve}`` to compare learners on one axes.
        metric: a column: ``value_gap`` (default), ``eval_value``, ``steps``, ``decisions``,
            ``return`` or ``discounted_return``. Evaluation metrics are drawn at the evaluated
            episodes only.
        x: ``episode``, or ``steps`` / ``decisions``: the mean over runs of the cumulative count
            at the end of each episode.
        band: ``quartiles`` (default: the median and the 25-75% band, so a two-way split of the
            runs shows instead of hiding in a mean), ``minmax`` (median, range over runs) or
            ``sd`` (mean +- one standard deviation). With at most :data:`PER_RUN_LINES` runs
            every run is also drawn, thin (gid ``run``), so a minority that succeeds shows.
        logy: for ``value_gap`` (the default there) the value-gap axis of
            :func:`adpart.plotting.gap_axis`: symmetric-log with an explicit ``0`` at the bottom
            and its linear part up to a tenth of the bound, gaps within :data:`ROUNDING` of 0
            drawn as 0; for another metric a log axis.
        title: the axes title (default: the environment and task, the metric, and the learner
            and what it knew, from the curves' metadata).
        bound: the dashed horizontal line (gid ``bound``) labelled ``bound_label``; by default
            on a value-gap figure the success bound, :data:`SUCCESS_FRACTION` of ``|V*|`` at the
            start (``curve.metadata["v_star_start"]`` of the first curve).

    Returns:
        A :class:`matplotlib.figure.Figure` (no pyplot state; save it or read its artists).
    """
    from adpart.plotting import gap_axis, gap_threshold, legend_below, new_figure

    curves = {"": curve} if isinstance(curve, LearningCurve) else dict(curve)
    if not curves:
        raise TaskError("plot_curves needs at least one learning curve")
    if metric not in COLUMNS or metric in ("run", "episode"):
        raise TaskError(
            f"cannot plot metric {metric!r}; choose one of "
            f"{[c for c in COLUMNS if c not in ('run', 'episode')]}"
        )
    if x not in _X_AXES:
        raise TaskError(f"x axis {x!r} is not one of {list(_X_AXES)}")
    if band not in _BANDS:
        raise TaskError(f"band {band!r} is not one of {list(_BANDS)}")
    gaps = metric == "value_gap"
    logy = gaps if logy is None else logy
    first = next(iter(curves.values()))
    v_star = float(first.metadata.get("v_star_start", np.nan))
    if bound is None and gaps and np.isfinite(v_star):
        bound = max(1e-9, SUCCESS_FRACTION * abs(v_star))
        bound_label = bound_label or f"success bound ({SUCCESS_FRACTION:.0%} of |V*(start)|)"
    series = []
    for label, c in curves.items():
        values = c.matrix(metric).astype(np.float64)
        xs = (np.arange(1, c.n_episodes + 1, dtype=np.float64) if x == "episode"
              else np.cumsum(c.matrix(x), axis=1).mean(axis=0))
        if metric in ("eval_value", "value_gap"):
            keep = c.evaluated_episodes() - 1
            xs, values = xs[keep], values[:, keep]
        if gaps:
            scale = float(c.metadata.get("v_star_start", np.nan))
            scale = max(1.0, abs(scale)) if np.isfinite(scale) else 1.0
            values = np.where(np.abs(values) <= ROUNDING * scale, 0.0, values)
        series.append((_series_label(label, c, len(curves)), xs, values))
    fig, ax = new_figure((7.0, 4.8))
    for label, xs, values in series:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns stay NaN
            if band == "sd":
                centre = np.nanmean(values, axis=0)
                sd = np.nanstd(values, axis=0)
                lo, hi = centre - sd, centre + sd
            else:
                centre = np.nanmedian(values, axis=0)
                q = (25, 75) if band == "quartiles" else (0, 100)
                lo, hi = np.nanpercentile(values, q, axis=0)
        what = "mean" if band == "sd" else "median"
        runs = values.shape[0]
        (line,) = ax.plot(xs, centre, label=f"{label} ({what} of {runs})", lw=1.8, gid="centre",
                          zorder=3)
        if runs <= PER_RUN_LINES:
            for row in values:
                ax.plot(xs, row, color=line.get_color(), lw=0.6, alpha=0.35, gid="run",
                        zorder=2)
        ax.fill_between(xs, lo, hi, color=line.get_color(), alpha=0.15, lw=0)
    if bound is not None and np.isfinite(bound):
        ax.axhline(bound, color="0.2", ls="--", lw=1.0, label=bound_label or "bound",
                   gid="bound", zorder=4)
    if logy and gaps:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            top = max([float(np.nanmax(v)) for _, _, v in series if np.isfinite(v).any()],
                      default=1.0)
        gap_axis(ax, gap_threshold(bound, top), top)
    elif logy:
        ax.set_yscale("log")
    ax.set_xlabel({"episode": "episode", "steps": "primitive steps (mean over runs)",
                   "decisions": "decisions (mean over runs)"}[x])
    ax.set_ylabel(metric.replace("_", " ") + (" (0 = optimal)" if gaps else ""))
    band_text = {"quartiles": "band: 25-75% of runs", "minmax": "band: min-max over runs",
                 "sd": "band: mean +- 1 sd over runs"}[band]
    ax.set_title(title or _default_title(curves, metric), fontsize="medium")
    ax.plot([], [], " ", label=band_text + ("; thin lines: single runs"
                                            if any(v.shape[0] <= PER_RUN_LINES
                                                   for _, _, v in series) else ""))
    legend_below(ax, columns=1 if len(series) > 2 else 2)
    fig.tight_layout()
    return fig


def _series_label(label: str, c: LearningCurve, n_series: int) -> str:
    """A legend label naming the learner (unless the caller's label does) and, with one curve,
    what it knew."""
    learner = str(c.metadata.get("learner", ""))
    text = label or learner or f"{c.n_runs} runs"
    if learner and learner not in text:
        text = f"{text}: {learner}"
    known = c.metadata.get("knowledge")
    if n_series > 1 and known:
        from adpart.learning.knowledge import Knowledge

        k = Knowledge.from_dict(known)
        text += f" [dynamics {k.dynamics}, rewards {k.rewards}]"
    return text


def _default_title(curves: Mapping[str, LearningCurve], metric: str) -> str:
    """``ENV/TASK: METRIC of the greedy policy`` and, for one curve, its learner and regime."""
    first = next(iter(curves.values()))
    where = str(first.metadata.get("mdp", "")) or "learning curve"
    text = f"{where}: {metric.replace('_', ' ')}" + (
        " of the greedy policy" if metric in ("value_gap", "eval_value") else "")
    known = first.metadata.get("knowledge")
    if len(curves) == 1:
        learner = str(first.metadata.get("learner", ""))
        if known:
            from adpart.learning.knowledge import Knowledge

            k = Knowledge.from_dict(known)
            learner += f" (dynamics {k.dynamics}, rewards {k.rewards})"
        if learner:
            text += f"\n{learner}, {first.n_runs} runs"
    return text


def plot_curves(
    curve: LearningCurve | Mapping[str, LearningCurve],
    path: str | Path,
    metric: str = "value_gap",
    **options: Any,
) -> Path:
    """Save :func:`curve_figure` ``(curve, metric, **options)`` as a PNG at ``path``.

    Parent directories are created; returns the path written.
    """
    fig = curve_figure(curve, metric, **options)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    return out


# --------------------------------------------------------------------------- exact scoring


def start_distribution(mdp) -> np.ndarray:
    """The distribution episodes start from: ``mdp.initial`` conditioned on non-terminal states.

    An episode that started in a terminal state would be over before its first step, so learners
    never start there; scoring uses the same distribution ``mu`` so that the value gap compares
    like with like (terminal states have value 0 in any case).
    """
    mu = np.where(mdp.terminal, 0.0, mdp.initial)
    total = float(mu.sum())
    if total <= 0.0:
        raise ModelError(
            "the start distribution puts all its mass on terminal states, so no episode can "
            "begin; give the MDP an initial distribution over non-terminal states"
        )
    return mu / total


def optimal_start_value(mdp, mu: np.ndarray, reference_values: np.ndarray | None = None) -> float:
    """``sum_s mu(s) V*(s)``: from ``reference_values`` if given, else solved exactly.

    Without reference values the MDP is solved by modified policy iteration to a 1e-10-optimal
    policy, whose value is then computed *exactly* by a sparse solve, so the reference carries no
    iteration error of its own (a value gap below 1e-6 is meaningful).
    """
    if reference_values is not None:
        V = np.asarray(reference_values, dtype=np.float64)
        if V.shape != (mdp.n_states,) or not np.all(np.isfinite(V)):
            raise ModelError(
                f"reference_values must be {mdp.n_states} finite numbers (V* of every state); "
                f"got shape {V.shape}"
            )
    else:
        V = policy_evaluation(mdp, solve(mdp, 1e-10).policy)
    return float(mu @ V)


def _row_hashes(a: np.ndarray) -> np.ndarray:
    """One int64 per row of the integer matrix ``a``: its dot product with fixed random odd
    weights, wrapping modulo 2^64 (numpy integer matmul wraps silently)."""
    weights = np.random.default_rng(0x5EED).integers(1, 2**62, size=a.shape[1]) | 1
    return np.ascontiguousarray(a, dtype=np.int64) @ weights


def distinct_rows(rows: np.ndarray, hashes: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``(first, inverse)``: one row index per distinct row of ``rows`` and each row's group.

    ``rows[first][inverse]`` equals ``rows``. Rows are hashed to one int64 each (a dot product
    with fixed odd random weights, wrapping on overflow) and the ``K`` hashes deduplicated, then
    every row is compared with its group's first row; only if two different rows shared a hash
    (never seen; ~K^2 / 2^64) does it fall back to ``np.unique(axis=0)``. This replaces the
    structured-dtype sort of ``np.unique(axis=0)``, which measured 2.2 s on a (50, 10^5) policy
    matrix, with one pass over the matrix.

    Args:
        rows: ``(K, S)`` integer array.
        hashes: their :func:`_row_hashes`, when the caller has them already.

    Returns:
        ``first`` (n_distinct,) int64 indices in order of first appearance and ``inverse``
        (K,) int64 group of each row.
    """
    a = np.asarray(rows)
    if hashes is None:
        hashes = _row_hashes(a)
    _, first, inverse = np.unique(hashes, return_index=True, return_inverse=True)
    inverse = np.asarray(inverse, dtype=np.int64).reshape(-1)
    order = np.argsort(first, kind="stable")  # groups numbered by first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    first, inverse = first[order].astype(np.int64), rank[inverse]
    # K row comparisons (one per run, not per state) prove the hash grouping exact
    if not all(np.array_equal(a[k], a[first[inverse[k]]]) for k in range(a.shape[0])):
        _, first, inverse = np.unique(a, axis=0, return_index=True, return_inverse=True)
        first, inverse = first.astype(np.int64), np.asarray(inverse, np.int64).reshape(-1)
    return first, inverse


def start_values(mdp, policies: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Exact ``sum_s mu(s) V^pi(s)`` of ``K`` deterministic policies, once per distinct policy.

    The distinct policies among the ``K`` rows (:func:`distinct_rows`) are evaluated one by one
    with :func:`adpart.mdp.evaluation.policy_evaluation`, one sparse LU of ``I - F_pi`` each (an
    earlier version stacked them block-diagonally into one LU; its fill-reducing ordering on the
    big matrix measured 2.5x slower than the separate LUs at 10^5 states, for the same values to
    ~1e-13). With ``gamma = 1`` a policy that loops somewhere makes its system singular; it is then
    evaluated again on the states it can reach from the start distribution (every other state made
    absorbing with value 0, which changes no reachable value: the policy never enters them), so a
    loop where no episode can go does not spoil the score (fickle Taxi has 100 such states). A
    policy that loops on a reachable state scores NaN.

    Args:
        mdp: the true model (anything with ``as_smdp()``).
        policies: ``(K, S)`` int actions (admissible ones).
        mu: ``(S,)`` start distribution.

    Returns:
        ``(K,)`` float64.
    """
    smdp = mdp.as_smdp()
    S = smdp.n_states
    pols = np.asarray(policies, dtype=np.int64)
    first, inverse = distinct_rows(pols)
    unique = pols[first]
    if not np.all(smdp.admissible[np.arange(S), unique]):
        raise ModelError("a policy to score chooses an inadmissible action")
    values = np.empty(first.size)
    for u in range(first.size):  # one sparse solve per distinct policy (not per state)
        values[u] = _start_value(smdp, unique[u], mu)
    return values[inverse]


def _start_value(smdp, policy: np.ndarray, mu: np.ndarray) -> float:
    """``sum_s mu(s) V^pi(s)`` of one deterministic policy (int64), as :func:`start_values`
    documents it: one sparse LU, or the reachable states only where ``gamma = 1`` loops."""
    try:
        # einsum, not BLAS ddot: a threaded ddot spin-waits on a loaded machine (solvers._dot)
        return np.einsum("i,i->", policy_evaluation(smdp, policy), mu)
    except ModelError:
        return _reachable_start_value(smdp, policy, mu)


class StartValues:
    """:func:`start_values` of K runs' policies over successive evaluations, each distinct policy
    solved once.

    A learner keeps its ``(K, S)`` greedy policies in one array that it updates in place and
    flags the runs whose policy changed since the last call (:func:`adpart.learning._kernels.
    refresh_greedy`); :meth:`__call__` then re-scores only those. A changed run's policy is
    looked up, by its bytes, among the policies scored before -- of any run, at any earlier
    evaluation (late in learning most runs' policies repeat, and different runs converge to the
    same one). The look-up is a dict keyed by the policy's bytes, so a hit is an exact match
    (hash, then full comparison), never a collision; the policies not found are grouped the same
    way and solved once each by one :class:`adpart.mdp.start_value.StartValueSolver`, which
    solves only the states reachable from ``mu`` under the policy, starting from the values of the
    policy it solved last (the previous evaluation's, or another run's), and stops when the
    start value is within :data:`adpart.mdp.start_value.START_VALUE_TOL` (1e-10) of the exact one
    (its sparse LU where the push would cost more, and for every undiscounted model); so every
    value agrees with :func:`start_values`' LU within 1e-9 (tested), not bit for bit. At 10^5
    states (``benchmarks/bench_qlearning.py``) this took the end-to-end call's scoring from one
    LU per distinct policy to a fraction of the kernel's time. The dict replaces the int64 row
    hashes of :func:`distinct_rows` here: policies are stored in the learner's smallest action
    dtype (int8: ``S`` bytes), and no int64 copy of a policy is made (the solver reads int8
    policies as they are).
    The store keeps the most recently used policies up to ``store_bytes``.
    """

    def __init__(self, mdp, mu: np.ndarray, runs: int, *, store_bytes: int = 64 << 20) -> None:
        self._smdp = mdp.as_smdp()
        self._mu = mu
        self._all_admissible = bool(np.all(self._smdp.admissible))
        self._values = np.full(runs, np.nan)
        self._scored = np.zeros(runs, dtype=bool)
        self._store: dict[bytes, float] = {}  # policy bytes -> start value, oldest use first
        self._stored_bytes = 0
        self._store_bytes = store_bytes
        self._solver = StartValueSolver(self._smdp, mu)
        self.solves = 0  #: policies solved so far (the others came from the store)

    def __call__(self, policies: np.ndarray, changed: np.ndarray) -> np.ndarray:
        """``(K,)`` start values of ``policies`` (K, S); ``changed[k]`` says run ``k``'s policy
        may differ from the last call's (ignored on a run's first call). Clears ``changed``."""
        redo = np.flatnonzero(changed | ~self._scored)
        changed[:] = False
        todo: dict[bytes, list[int]] = {}  # policies not in the store -> their runs
        for k in redo.tolist():
            key = policies[k].tobytes()
            value = self._store.pop(key, None)
            if value is None:
                todo.setdefault(key, []).append(k)
            else:
                self._store[key] = value  # most recently used last
                self._values[k] = value
        for key, runs in todo.items():
            policy = policies[runs[0]]  # the learner's dtype (the solver reads int8 as is)
            if not self._all_admissible and not np.all(
                    self._smdp.admissible[np.arange(policy.size), policy]):
                raise ModelError("a policy to score chooses an inadmissible action")
            value = self._solver(policy)
            self.solves += 1
            self._values[runs] = value
            self._keep(key, value)
        self._scored[redo] = True
        return self._values.copy()

    def _keep(self, key: bytes, value: float) -> None:
        self._store[key] = value
        self._stored_bytes += len(key)
        while self._stored_bytes > self._store_bytes and len(self._store) > 1:
            oldest = next(iter(self._store))
            del self._store[oldest]
            self._stored_bytes -= len(oldest)


def _reachable_start_value(smdp, policy: np.ndarray, mu: np.ndarray) -> float:
    """``sum_s mu(s) V^pi(s)`` with the states ``policy`` cannot reach from ``mu`` absorbed (NaN
    if it still loops)."""
    import scipy.sparse as sp
    from scipy.sparse import csgraph

    from adpart.mdp.model import SMDPModel

    S = smdp.n_states
    F_pi = sp.csr_array(smdp.F[policy * S + np.arange(S)])
    starts = np.flatnonzero(mu > 0)
    source = sp.csr_array((np.ones(starts.size), (np.full(starts.size, S), starts)),
                          shape=(S + 1, S + 1))
    graph = sp.csr_array(sp.block_diag((F_pi, sp.csr_array((1, 1)))) + source)
    order = csgraph.breadth_first_order(graph, S, directed=True, return_predecessors=False)
    keep = np.zeros(S, dtype=bool)
    keep[order[order < S]] = True
    live = sp.diags_array(np.tile(keep, smdp.n_actions).astype(np.float64))
    absorbed = SMDPModel(R=np.where(keep[:, None], smdp.R, 0.0),
                         F=sp.csr_array(live @ smdp.F), admissible=smdp.admissible)
    try:
        return float(np.einsum("i,i->", policy_evaluation(absorbed, policy), mu))
    except ModelError:
        return float("nan")
