"""The same seeds give bit-identical curves and Q before and after the kernel rewrite.

``data/reference_curves.npz`` holds final Q, visit counts and the learning-curve columns of fixed
runs (:mod:`tests.learning.reference_cases`) recorded with the code of commit de831d6; every
kernel of today's code must reproduce them exactly (``np.array_equal``, NaN where not evaluated).
"""

from __future__ import annotations

import numpy as np
import pytest

from .reference_cases import CASES, DATA, arrays

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
        assert np.array_equal(got[key], ref, equal_nan=True), f"{case}/{key} ({kernel})"
