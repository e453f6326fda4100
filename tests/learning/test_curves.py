from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adpart.errors import TaskError
from adpart.learning import LearningCurve, plot_curves, q_learning
from adpart.learning.curves import COLUMNS, distinct_rows, start_values
from adpart.learning.settings import Run
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.model import FiniteMDP

from .conftest import slippery_grid


@pytest.fixture(scope="module")
def curve() -> LearningCurve:
    return q_learning(slippery_grid(3), Run(runs=3, episodes=12, seed=0, eval_every=4)).curve


def test_columns_and_shapes(curve):
    assert list(curve.to_dict()) == list(COLUMNS)
    assert len(curve) == 36 and curve.n_runs == 3 and curve.n_episodes == 12
    assert np.array_equal(curve.matrix("run")[:, 0], [0, 1, 2])
    assert np.array_equal(curve.matrix("episode")[0], np.arange(1, 13))
    assert list(curve.evaluated_episodes()) == [4, 8, 12]
    ev = curve.matrix("eval_value")
    assert np.isnan(ev[:, [0, 1, 2, 4]]).all() and np.isfinite(ev[:, [3, 7, 11]]).all()


def test_arrow_round_trip(curve):
    table = curve.to_arrow()
    assert table.column_names == list(COLUMNS)
    back = LearningCurve.from_arrow(table)
    for c in COLUMNS:
        assert np.array_equal(back[c], curve[c], equal_nan=True)
    assert back.metadata["learner"] == "q-learning"
    assert back.metadata["seed"] == 0


def test_unknown_column(curve):
    with pytest.raises(TaskError, match="no learning-curve column"):
        curve["reward"]


def test_episodes_to_gap():
    gap = np.full((2, 6), np.nan)
    gap[:, [1, 3, 5]] = [[0.5, 0.0, 0.0], [0.0, 0.3, 0.2]]
    z = np.zeros((2, 6))
    c = LearningCurve.from_matrices(steps=z, decisions=z, returns=z, discounted_returns=z,
                                    eval_value=-gap, value_gap=gap)
    assert list(c.episodes_to_gap(1e-6)) == [4, -1]


@pytest.mark.parametrize("band", ["minmax", "sd"])
@pytest.mark.parametrize(("metric", "x"), [("value_gap", "episode"), ("steps", "steps"),
                                           ("return", "decisions")])
def test_plot_writes_png(curve, tmp_path, metric, x, band):
    out = plot_curves({"flat": curve, "again": curve}, tmp_path / "sub" / "c.png", metric=metric,
                      x=x, band=band)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_rejects_bad_metric(curve, tmp_path):
    with pytest.raises(TaskError, match="metric"):
        plot_curves(curve, tmp_path / "c.png", metric="run")
    with pytest.raises(TaskError, match="band"):
        plot_curves(curve, tmp_path / "c.png", band="iqr")


def test_batched_start_values_match_one_by_one(rng):
    mdp = slippery_grid(3, slip=0.3, gamma=0.9)
    pols = rng.integers(0, 4, size=(6, mdp.n_states))
    pols[3] = pols[1]  # duplicates are evaluated once
    mu = rng.dirichlet(np.ones(mdp.n_states))
    batched = start_values(mdp, pols, mu)
    single = [policy_evaluation(mdp, p) @ mu for p in pols]
    np.testing.assert_allclose(batched, single, rtol=1e-12, atol=1e-12)


def test_non_terminating_policy_scores_nan_with_gamma_one():
    # gamma = 1: policy 0 loops forever in state 0 (singular), policy 1 reaches the goal.
    P = np.zeros((2, 2, 2))
    P[0, 0, 0] = 1.0
    P[0, 1, 1] = 1.0
    P[1, :, 1] = 1.0
    mdp = FiniteMDP.from_dense(P, -np.ones((2, 2)), 1.0, terminal=np.array([False, True]),
                               initial=np.array([1.0, 0.0]))
    values = start_values(mdp, np.array([[0, 0], [1, 0]]), np.array([1.0, 0.0]))
    assert np.isnan(values[0]) and values[1] == -1.0


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 8), st.integers(1, 30), st.integers(1, 4), st.integers(0, 2**32 - 1))
def test_distinct_rows_groups_like_np_unique(k, s, values, seed):
    rows = np.random.default_rng(seed).integers(0, values, size=(k, s))
    first, inverse = distinct_rows(rows)
    np.testing.assert_array_equal(rows[first][inverse], rows)
    assert len(np.unique(rows, axis=0)) == first.size  # one group per distinct row
    assert np.all(np.diff(first) > 0)  # numbered by first appearance


def test_distinct_rows_survives_hash_collisions(monkeypatch):
    from adpart.learning import curves

    monkeypatch.setattr(curves, "_row_hashes", lambda a: np.zeros(a.shape[0], dtype=np.int64))
    rows = np.array([[0, 1], [1, 0], [0, 1]])
    first, inverse = distinct_rows(rows)
    np.testing.assert_array_equal(rows[first][inverse], rows)
    assert first.size == 2


def test_undiscounted_score_ignores_a_loop_no_episode_can_enter():
    """gamma = 1: a policy looping in states unreachable from the start still gets its value.

    States: 0 -> 1 -> 2 (terminal), -1 a step, episodes start in 0; 3 <-> 4 is a cycle no start
    reaches. By hand: V(0) = -2. A policy that loops on a reachable state scores NaN.
    """
    from adpart.learning.curves import start_values
    from adpart.mdp.model import FiniteMDP

    S, A = 5, 2
    P = np.zeros((S, A, S))
    P[0, 0, 1] = P[1, 0, 2] = 1.0  # forward
    P[0, 1, 0] = P[1, 1, 1] = 1.0  # stay
    P[2, :, 2] = 1.0
    P[3, :, 4] = P[4, :, 3] = 1.0  # the unreachable cycle
    terminal = np.array([False, False, True, False, False])
    mu = np.array([1.0, 0, 0, 0, 0])
    mdp = FiniteMDP.from_dense(P, -np.ones((S, A)), 1.0, terminal=terminal, initial=mu)
    forward = np.array([[0, 0, 0, 0, 0]])
    assert start_values(mdp, forward, mu)[0] == pytest.approx(-2.0)
    stuck = np.array([[0, 1, 0, 0, 0]])  # stays in 1 forever
    assert np.isnan(start_values(mdp, stuck, mu)[0])


def test_start_values_over_evaluations_equal_start_values_within_1e_9(rng):
    # StartValues re-scores only flagged runs, reuses any policy scored before (other runs,
    # earlier calls) and solves each new distinct policy once, warm-started from the last
    # (adpart.mdp.start_value, error <= 1e-10); values equal start_values' LU within 1e-9
    from adpart.learning.curves import StartValues

    mdp = slippery_grid(3, slip=0.3, gamma=0.9)
    mu = rng.dirichlet(np.ones(mdp.n_states))
    pool = rng.integers(0, 4, size=(4, mdp.n_states)).astype(np.int8)  # 4 distinct policies
    K = 6
    pols = pool[rng.integers(0, 4, size=K)]
    score = StartValues(mdp, mu, K)
    changed = np.zeros(K, dtype=bool)  # ignored on the first call: every run is scored
    seen = set()
    for _ in range(8):
        got = score(pols, changed)
        np.testing.assert_allclose(got, start_values(mdp, pols, mu), rtol=0, atol=1e-9)
        assert not changed.any()  # cleared
        seen |= {p.tobytes() for p in pols}
        assert score.solves == len(seen)  # each distinct policy solved once, ever
        moved = rng.random(K) < 0.5
        pols[moved] = pool[rng.integers(0, 4, size=int(moved.sum()))]
        changed[moved] = True


def test_start_values_store_is_bounded_and_still_exact(rng):
    from adpart.learning.curves import StartValues

    mdp = slippery_grid(3, slip=0.3, gamma=0.9)
    mu = np.full(mdp.n_states, 1.0 / mdp.n_states)
    score = StartValues(mdp, mu, 2, store_bytes=2 * mdp.n_states)  # room for two policies
    a, b, c = (rng.integers(0, 4, size=(2, mdp.n_states)).astype(np.int8) for _ in range(3))
    for pols in (a, b, c, a):
        np.testing.assert_allclose(score(pols, np.ones(2, dtype=bool)),
                                   start_values(mdp, pols, mu), rtol=0, atol=1e-9)
    assert score.solves == 8  # a was evicted by b and c, so it is solved again
    assert len(score._store) == 2


def _gap_curve(gap: np.ndarray, **metadata) -> LearningCurve:
    z = np.zeros_like(gap)
    return LearningCurve.from_matrices(steps=z, decisions=z, returns=z, discounted_returns=z,
                                       eval_value=-gap, value_gap=gap, metadata=metadata)


def _tick_labels(ax) -> dict[float, str]:
    ax.figure.canvas.draw()  # Agg: tick labels are formatted on draw
    return {float(t.get_loc()): t.label1.get_text() for t in ax.yaxis.get_major_ticks()}


def test_the_figure_shows_medians_quartiles_runs_and_the_bound():
    """Read back what was drawn: the centre line is the median over runs (not the mean, which
    hides a two-way split), each run is a thin line, the bound is a dashed line at its value,
    and a gap of 0 sits at the tick labelled 0 of a symmetric-log axis."""
    from adpart.learning.curves import curve_figure

    gap = np.array([[5.0, 2.0, 0.0, 0.0], [5.0, 4.0, 3.0, 3.0], [5.0, 2.0, 0.5, 0.0]])
    fig = curve_figure({"layer": _gap_curve(gap)}, bound=1.0, bound_label="success bound")
    ax = fig.axes[0]
    by_label = {line.get_label(): line for line in ax.get_lines()}
    median = by_label["layer (median of 3)"]
    np.testing.assert_allclose(median.get_ydata(), np.median(gap, axis=0))
    runs = [line for line in ax.get_lines() if line.get_gid() == "run"]
    assert sorted(map(tuple, (r.get_ydata() for r in runs))) == sorted(map(tuple, gap))
    bound = by_label["success bound"]
    assert bound.get_gid() == "bound" and set(bound.get_ydata()) == {1.0}
    assert bound.get_linestyle() == "--"
    assert ax.get_yscale() == "symlog"
    assert ax.yaxis.get_transform().linthresh == pytest.approx(0.1)  # a decade below the bound
    low, high = ax.get_ylim()
    assert low < 0 < 0.1 * 0.5 and high >= 5.0
    assert _tick_labels(ax)[0.0] == "0"


def test_the_zero_floor_is_the_same_whatever_the_rounding():
    """Optimal runs evaluate to gaps of +-1e-15 (rounding) or exactly 0: both are drawn at the
    tick labelled 0, and the axis spans the decades from a tenth of the bound to the largest
    gap, not the decades of the rounding (the old log axis put 0 at 1e-17 or at 1)."""
    from adpart.learning.curves import curve_figure

    shapes = []
    for zero in (0.0, 1.8e-15, -8.9e-17):
        gap = np.array([[90.0, 50.0, zero, zero], [90.0, 90.0, 3.0, zero]])
        fig = curve_figure(_gap_curve(gap, v_star_start=-12.7, mdp="three-floor/reach-goal",
                                      learner="q-learning"))
        ax = fig.axes[0]
        (median,) = [line for line in ax.get_lines() if line.get_gid() == "centre"]
        assert median.get_ydata()[-1] == 0.0
        bound = [line for line in ax.get_lines() if line.get_gid() == "bound"]
        assert list(bound[0].get_ydata()) == pytest.approx([0.05 * 12.7] * 2)  # the default bound
        shapes.append((ax.get_ylim(), tuple(_tick_labels(ax).items())))
        title = ax.get_title()
        assert "three-floor/reach-goal" in title and "q-learning" in title
    assert shapes[0] == shapes[1] == shapes[2]
    (_, high), ticks = shapes[0]
    assert dict(ticks)[0.0] == "0" and high / (0.05 * 12.7 / 10) < 1e4  # 3-4 decades, not 17
