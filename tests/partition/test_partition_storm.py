"""Cross-check of exact lumping against Storm's bisimulation (skipped without stormpy)."""

from __future__ import annotations

import pytest

from adpart.partition import exact_lumping

pytest.importorskip("stormpy")
pytest.importorskip("pyarrow")


@pytest.mark.parametrize("n", [400, 2500])
def test_block_counts_agree_with_storm(n):
    from benchmarks.bench_partition import lumpable_grid_mdp, storm_bisimulation

    mdp = lumpable_grid_mdp(n)
    ours = exact_lumping(mdp)
    assert storm_bisimulation(mdp)["blocks"] == ours.n_blocks
