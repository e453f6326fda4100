"""Which learned run the pipeline takes its policy from (:func:`best_final_run`)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from adpart.learning.comparison import TIE_TOLERANCE, best_final_run
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
