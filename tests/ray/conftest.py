"""One local Ray cluster (2 CPUs, no dashboard) shared by every Ray test of the session.

Ray takes seconds to start, so the cluster is session-scoped; :class:`RayExecutor` reuses an
initialised Ray and leaves it running, so executors created by the tests do not restart it.
"""

from __future__ import annotations

import logging
import textwrap
from pathlib import Path

import pytest


def pytest_collection_modifyitems(items):
    """Every test on the Ray cluster is a process-level test (marker ``processes``)."""
    for item in items:
        if "ray_cluster" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.processes)


@pytest.fixture(scope="session")
def ray_cluster():
    ray = pytest.importorskip("ray")
    # address="local": a private cluster, never one another process (an xdist worker) started
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level=logging.WARNING)
    try:
        yield ray
    finally:
        ray.shutdown()


SMALL_SWEEP = textwrap.dedent(
    """
    name = "small"
    runs = 2
    episodes = 20
    eval_every = 10
    seeds = [0, 1]
    environments = ["two-rooms", { name = "four-rooms", tasks = ["G1"] }]

    [params]
    alpha = ["0.1", "0.5"]
    epsilon = "0.1"
    """
)


@pytest.fixture
def small_sweep(tmp_path) -> Path:
    """2 environments x 2 alphas x 2 seeds = 8 tiny cells."""
    path = tmp_path / "small.toml"
    path.write_text(SMALL_SWEEP)
    return path
