"""Which learned run the pipeline takes its policy from (:func:`best_final_run`)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from adpart.learning.comparison import TIE_TOLERANCE, best_final_run, task_row
from adpart.learning.curves import LearningCurve


def _curve(final_gaps: list[float], v_star: float = -12.7) -> LearningCurve:
    gaps = np.column_stack([np.full(len(final_gaps), 5.0), final_gaps])
    zeros = np.zeros_like(gaps)
    return LearningCurve.from_matrices(steps=zeros + 1, decisions=zeros + 1, returns=zeros,
                                       discounted_returns=zeros, eval_value=v_star - gaps,
                                       value_gap=gaps, metadata={"v_star_start": v_star})


def test_gaps_that_differ_by_rounding_are_a_tie_won_by_the_first_run() -> None:
    """Three-floor's 20 optimal runs scored 0.0 but one -1.8e-15; argmin took that one, and on
    another machine another, so the discovered subgoals (6 or 12) depended on the machine."""
    gaps = [0.0] * 20
    gaps[12] = -1.7763568394002505e-15
    assert best_final_run(_curve(gaps)) == 0
    assert best_final_run(_curve([0.5, 0.2, 0.2 + 1e-13, 0.1])) == 3


def test_undefined_final_values_are_passed_over() -> None:
    assert best_final_run(_curve([np.nan, 3.0, 2.0, np.nan])) == 2
    assert best_final_run(_curve([np.nan, np.nan])) == 0


@given(st.lists(st.floats(0.0, 100.0), min_size=1, max_size=30), st.floats(-200.0, 0.0))
def test_the_choice_is_within_the_tolerance_of_the_best_and_the_first_such(gaps, v_star):
    """Oracle: a plain loop over the runs."""
    chosen = best_final_run(_curve(gaps, v_star))
    tol = TIE_TOLERANCE * max(1.0, abs(v_star))
    first = next(k for k, g in enumerate(gaps) if g <= min(gaps) + tol)
    assert chosen == first


def test_a_row_reports_censored_runs_and_the_kaplan_meier_time_to_the_bound() -> None:
    """Four runs evaluated at episodes 1..4 (every episode 10 steps), bound 0.05 |V*| = 1: runs
    0 and 1 get within at episodes 2 and 3 and stay; runs 2 and 3 never do (censored at 4).
    Oracle by hand: S(t) drops to 3/4 at 2 and to 1/2 at 3, so the KM median is episode 3
    (step 30); the old figure counted the censored runs as 5 episodes."""
    gaps = np.array([[5.0, 0.5, 0.0, 0.0],
                     [5.0, 3.0, 0.2, 0.1],
                     [5.0, 4.0, 3.0, 2.0],
                     [9.0, 9.0, 9.0, 9.0]])
    ones = np.ones_like(gaps)
    curve = LearningCurve.from_matrices(steps=10 * ones, decisions=ones, returns=0 * ones,
                                        discounted_returns=0 * ones, eval_value=-20.0 - gaps,
                                        value_gap=gaps, metadata={"v_star_start": -20.0})
    row = task_row("t", "x", curve, 0.05, {})
    assert row["bound"] == 1.0 and row["runs_within_bound"] == 2 and row["censored_runs"] == 2
    assert row["time_to_bound_km"]["episodes"][0] == 3.0
    assert row["time_to_bound_km"]["steps"][0] == 30.0
    assert row["jumpstart_gap_mean"] == 6.0  # (5 + 5 + 5 + 9) / 4
    assert row["asymptotic_gap_mean"] == np.mean(gaps[:, 1:])  # the last three evaluations
    never = task_row("t", "x", LearningCurve.from_matrices(
        steps=10 * ones, decisions=ones, returns=0 * ones, discounted_returns=0 * ones,
        eval_value=-20.0 - 9 * ones, value_gap=9 * ones, metadata={"v_star_start": -20.0}),
        0.05, {})
    assert never["censored_runs"] == 4 and never["time_to_bound_km"]["episodes"][0] == np.inf


@pytest.mark.parametrize(("args", "kwargs", "text"), [
    ((161.0, 156.0, 166.0), {}, "161 [156, 166]"),
    ((0.528, 0.51, 0.541), {"style": "sentence"}, "0.528 (95% CI 0.51-0.541)"),
    ((66.5, 66.5, 66.5), {}, "66.5 (all resamples equal)"),
    ((2.0, 2.0, 2.0), {"style": "sentence"}, "2 (all resamples equal)"),
    ((np.inf, np.inf, np.inf), {"inf": "never"}, "never"),
    ((np.inf, 260.0, np.inf), {"inf": "never"}, "never [260, never]"),
    ((0.1, 0.0, np.inf), {"style": "sentence"}, "0.1 (95% CI 0-inf)"),
])
def test_an_interval_of_zero_width_is_said_not_drawn(args, kwargs, text):
    """``interval_text`` is the one spelling of an estimate and its CI in every table: a CI of
    zero width (every resample gave the estimate) is named, never printed as ``[x, x]``."""
    from adpart.learning.comparison import interval_text

    assert interval_text(*args, **kwargs) == text


def test_a_layer_learner_that_starts_on_other_blocks_than_its_layer_says_why():
    """The comparison's ``blocks`` column is the learner's start; where the stored layer has
    another count, a line under the table names both (the counts of one output agree or are
    explained)."""
    from adpart.workflows.pipeline_table import block_note, comparison_lines

    row = {"task": "t", "learner": "hierarchical", "initial_blocks": 48, "partition_blocks": 47,
           "partition": "partition:12", "runs": 20, "runs_within_bound": 20,
           "ratio_to_flat": {"ratio": 0.5, "ci95": [0.4, 0.6], "p_sooner": 0.01,
                             "censored": [0, 0], "first_evaluation": 1,
                             "steps": {"ratio": 0.4, "ci95": [0.3, 0.5]}}}
    note = block_note(row)
    assert note is not None and "48 blocks" in note and "partition:12 has 47" in note
    assert f"  {note}" in comparison_lines([row])
    assert block_note({**row, "initial_blocks": 47}) is None
    assert block_note({**row, "partition_blocks": None}) is None
