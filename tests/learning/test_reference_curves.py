"""The same seeds give bit-identical curves and Q before and after the kernel rewrite.

``data/reference_curves.npz`` holds final Q, visit counts and the learning-curve columns of fixed
runs (:mod:`tests.learning.reference_cases`) recorded with the code of commit de831d6; every
kernel of today's code must reproduce them exactly (``np.array_equal``, NaN where not evaluated).

The exact *scores* - the greedy policies' values and ``V*(start)``, from a sparse linear solve in
scipy - are held to a relative 1e-12 instead: their last bits follow the installed scipy and
its LAPACK (a fresh install with numpy 2.4.6 and scipy 1.17.1 moved them by up to 1.0e-15), while
everything the learners compute must stay bit for bit.
"""

from __future__ import annotations

import numpy as np
import pytest

from .reference_cases import CASES, DATA, arrays

#: Arrays computed by the scorer's linear solve rather than by a learner.
SCORES = frozenset({"eval_value", "v_star_start"})
PARAMS = [(name, kernel) for name, (_, kernels) in CASES.items() for kernel in kernels]


@pytest.fixture(scope="module")
def pinned() -> dict[str, np.ndarray]:
    with np.load(DATA, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


@pytest.mark.parametrize(("case", "kernel"), PARAMS, ids=[f"{c}-{k}" for c, k in PARAMS])
def test_same_seeds_give_bit_identical_curves_and_q_as_before(pinned, case, kernel):
    learn, _ = CASES[case]
    got = arrays(learn(kernel))
    expected = {k.split("/", 1)[1]: v for k, v in pinned.items() if k.startswith(case + "/")}
    assert sorted(got) == sorted(expected)
    for key, ref in expected.items():
        assert got[key].dtype == ref.dtype and got[key].shape == ref.shape, key
        if key in SCORES:
            np.testing.assert_allclose(got[key], ref, rtol=1e-12, atol=0.0, equal_nan=True,
                                       err_msg=f"{case}/{key} ({kernel})")
        else:
            assert np.array_equal(got[key], ref, equal_nan=True), f"{case}/{key} ({kernel})"
