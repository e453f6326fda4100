from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from adpart.errors import TaskError
from adpart.learning import Schedule, constant, exponential, parse_schedule, visit_count

probs = st.floats(0.0, 1.0, allow_nan=False)
counts = st.integers(1, 10**6)
episodes = st.integers(0, 10**4)


@given(v=probs, n=counts, e=episodes)
def test_constant_ignores_visits_and_episodes(v, n, e):
    assert constant(v).value(n, e) == v


@given(omega=st.floats(0.0, 1.0), n=counts, m=counts, e=episodes)
def test_visit_count_is_power_law_and_non_increasing(omega, n, m, e):
    s = visit_count(omega)
    assert s.value(n, e) == pytest.approx(n ** -omega, rel=1e-12)
    assert s.value(1, e) == 1.0
    lo, hi = sorted((n, m))
    assert s.value(hi, e) <= s.value(lo, e)


@given(x=st.floats(0.01, 1.0), rate=st.floats(0.5, 1.0), floor=st.floats(0.0, 0.2), e=episodes,
       n=counts)
def test_exponential_decays_per_episode_down_to_floor(x, rate, floor, e, n):
    s = exponential(x, rate, floor=floor)
    assert s.value(n, e) == pytest.approx(max(floor, x * rate**e), rel=1e-9, abs=1e-300)
    assert s.value(n, e + 1) <= s.value(n, e)
    assert s.value(n, e) >= floor


@given(omega=st.floats(0.51, 1.0), n=st.integers(1, 10**4))
def test_robbins_monro_partial_sums(omega, n):
    # sum alpha_n grows without bound like n^(1-omega) while sum alpha_n^2 stays bounded.
    # Lower bound: the integral of x^-omega from 1 to n, (n^(1-omega) - 1) / (1 - omega), written
    # with expm1 so that omega within rounding of 1 gives log(n) instead of 0/0 noise.
    a = visit_count(omega).value(np.arange(1, n + 1), 0)
    c = 1.0 - omega
    integral = np.expm1(c * np.log(n)) / c if c > 0 else np.log(n)
    assert a.sum() >= integral * (1 - 1e-9)
    assert (a**2).sum() <= 1 + 1 / (2 * omega - 1) + 1e-9


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("0.1", constant(0.1)),
        (0.25, constant(0.25)),
        ("1/n", visit_count(1.0)),
        ("1/n^0.8", visit_count(0.8)),
        ("0.5/n^0.6,0.01", visit_count(0.6, scale=0.5, floor=0.01)),
        ("exp:0.5,0.99", exponential(0.5, 0.99)),
        ("exp: 0.5, 0.99, 0.05", exponential(0.5, 0.99, floor=0.05)),
    ],
)
def test_parse(text, expected):
    assert parse_schedule(text) == expected
    assert Schedule(**parse_schedule(text).to_dict()) == expected


@pytest.mark.parametrize("text", ["fast", "1/m", "exp:0.5", "", "exp:a,b"])
def test_parse_rejects(text):
    with pytest.raises(TaskError, match="schedule"):
        parse_schedule(text)


@pytest.mark.parametrize(
    "kwargs", [{"scale": -1.0}, {"scale": 1.0, "rate": 0.0}, {"scale": 1.0, "rate": 1.5},
               {"scale": 1.0, "omega": 2.0}, {"scale": 1.0, "floor": -0.1},
               {"scale": float("nan")}],
)
def test_invalid_parameters(kwargs):
    with pytest.raises(TaskError):
        Schedule(**kwargs)


def test_probability_check():
    with pytest.raises(TaskError, match="alpha"):
        constant(2.0).check_probability("alpha")
