"""Shared fixtures: every test gets its own adpart home, so no test touches the user's files."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import pytest
from hypothesis import HealthCheck, settings

matplotlib.use("Agg")

settings.register_profile(
    "adpart", max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("adpart")


@pytest.fixture(autouse=True)
def _isolated_home(tmp_path, monkeypatch):
    monkeypatch.setenv("ADPART_HOME", str(tmp_path / "adpart-home"))
    monkeypatch.delenv("ADPART_KB", raising=False)


#: test modules that use the session's Ray cluster (tests/ray/conftest.py::ray_cluster)
RAY_CLUSTER_MODULES = frozenset(
    f"tests/ray/{path.name}" for path in (Path(__file__).parent / "ray").glob("test_*.py")
    if "ray_cluster" in path.read_text()
)


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist; without it (-p no:xdist) unused
def pytest_xdist_make_scheduler(config, log):
    """``-n N``: tests are load-balanced one by one as with xdist's default ``--dist load``, but
    the tests on the Ray cluster form one unit, run by one worker and scheduled first, so the
    session starts one Ray cluster instead of one per worker."""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class OneRayCluster(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            path = nodeid.split("::", 1)[0]
            return "ray-cluster" if path in RAY_CLUSTER_MODULES else nodeid

    return OneRayCluster(config, log)
