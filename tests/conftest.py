"""Shared fixtures: every test gets its own adpart home, so no test touches the user's files."""

from __future__ import annotations

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
