"""Fixed-seed learner runs whose results are pinned in ``data/reference_curves.npz``.

The pinned arrays were produced by the learners as they were at commit de831d6 (the flat
Q-learning kernel written three times: Python, numpy and numba), before the flat kernel became
one source run interpreted or compiled. ``test_reference_curves.py`` asserts that today's code
gives the same arrays bit for bit (``np.array_equal``), for every kernel.

Regenerate (only when a change of results is intended and explained in the commit), all cases
or the named ones:

    python -m tests.learning.reference_cases [CASE ...]

``hierarchical_goal_grid`` was re-recorded when a split block's children began to start their
primitive columns grounded (``adpart.learning.hierarchical.child_values``): an intended change.
Since the learner's defaults became the ``state`` refinement rule and primitive exploration until
the first reward, that case pins the former rule (``refine="block"``,
``primitive_exploration="never"``), which must stay bit for bit as it was, and
``hierarchical_goal_grid_state`` pins the defaults.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from adpart.learning.settings import Run

DATA = Path(__file__).parent / "data" / "reference_curves.npz"

#: Curve columns pinned per case (``eval_value`` is NaN between evaluations; ``value_gap``
#: follows from it and ``v_star_start``).
CURVE_COLUMNS = ("steps", "decisions", "return", "discounted_return", "eval_value")


def _two_rooms(kernel: str):
    from adpart.envs.registry import get_domain
    from adpart.learning import q_learning

    mdp = get_domain("two-rooms").mdp()
    return q_learning(mdp, Run(runs=4, episodes=40, seed=7, alpha="1/n^0.8",
                               epsilon="exp:0.5,0.9,0.05", max_steps_per_episode=200,
                               eval_every=10, kernel=kernel))


def _slippery(kernel: str):
    from adpart.learning import q_learning

    from .conftest import slippery_grid

    return q_learning(slippery_grid(), Run(runs=3, episodes=30, seed=3, alpha=0.5,
                                           epsilon="0.3/n^0.5,0.05", q_init=1.0,
                                           max_steps_per_episode=50, eval_every=7, kernel=kernel))


def _four_rooms(kernel: str, intra: bool = False):
    from adpart.envs.registry import get_domain
    from adpart.options import hallway_options

    from .hierarchical_run import smdp_q_run

    mdp = get_domain("four-rooms").mdp("G1")
    return smdp_q_run(mdp, hallway_options(mdp), include_primitives=True, runs=2,
                           episodes=15, seed=4, eval_every=5, alpha="1/n^0.8",
                           epsilon="0.3/n^0.5,0.05", intra_option=intra, kernel=kernel)


def _hierarchical(kernel: str, **rule):
    from adpart.learning.hierarchical import decision_layer
    from adpart.options import subgoal_option

    from .hierarchical_run import hierarchical_run
    from .test_hierarchical import SETTINGS, SIDE, goal_grid

    mdp = goal_grid()
    corners = (0, SIDE - 1, SIDE * (SIDE - 1), SIDE * SIDE - 1)
    opts = [subgoal_option(mdp, c, initiation="reachable") for c in corners]
    part, _full, _smdp = decision_layer(mdp, opts, delta=SETTINGS["delta"], epsilon=0.0)
    kw = dict(SETTINGS, runs=2, episodes=150, eval_every=50)
    return hierarchical_run(mdp, opts, part, kernel=kernel, **kw, **rule)


#: name -> (learner taking a kernel name, kernels that must reproduce the pinned arrays).
CASES: dict[str, tuple[Callable[[str], object], tuple[str, ...]]] = {
    "flat_two_rooms": (_two_rooms, ("python", "numba")),
    "flat_slippery": (_slippery, ("python", "numba")),
    "smdp_four_rooms": (_four_rooms, ("python", "numba")),
    "smdp_four_rooms_intra": (lambda k: _four_rooms(k, intra=True), ("python", "numba")),
    "hierarchical_goal_grid": (
        lambda k: _hierarchical(k, refine="block", primitive_exploration="never"), ("numba",)),
    "hierarchical_goal_grid_state": (_hierarchical, ("numba",)),
}


def arrays(result) -> dict[str, np.ndarray]:
    """The pinned arrays of one result: final Q, visit counts and the curve columns."""
    out = {"Q": np.asarray(result.Q)}
    if hasattr(result, "visits"):
        out["visits"] = np.asarray(result.visits)
    for col in CURVE_COLUMNS:
        out[col] = np.asarray(result.curve.matrix(col))
    out["v_star_start"] = np.asarray(result.v_star_start)
    if hasattr(result, "Q_flat"):  # hierarchical: the flat values and the layer's growth
        out["Q_flat"] = np.asarray(result.Q_flat)
        out["blocks"] = np.asarray(result.blocks)
    return out


def main(names: list[str] | None = None) -> None:
    payload = {}
    if names:
        unknown = sorted(set(names) - set(CASES))
        if unknown:
            raise SystemExit(f"unknown case(s) {unknown}; the cases are {sorted(CASES)}")
        with np.load(DATA, allow_pickle=False) as data:
            payload = {k: data[k] for k in data.files if k.split("/", 1)[0] not in names}
    for name, (learn, kernels) in CASES.items():
        if names and name not in names:
            continue
        ref = arrays(learn(kernels[0]))
        for other in kernels[1:]:  # the kernels agreed when the file was written
            got = arrays(learn(other))
            assert all(np.array_equal(ref[k], got[k], equal_nan=True) for k in ref), name
        payload.update({f"{name}/{k}": v for k, v in ref.items()})
    DATA.parent.mkdir(exist_ok=True)
    np.savez_compressed(DATA, **payload)
    print(f"wrote {DATA} ({DATA.stat().st_size:,} bytes, {len(payload)} arrays)")


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
