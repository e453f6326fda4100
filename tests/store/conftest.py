"""Store fixtures: a KB on a real SQLite file, and on PostgreSQL when ADPART_TEST_PG_URL is set."""

from __future__ import annotations

import os
import uuid
from dataclasses import dataclass
from urllib.parse import quote

import numpy as np
import pytest
import scipy.sparse as sp
from sqlalchemy import create_engine, text

from adpart.store import KnowledgeBase

PG_URL = os.environ.get("ADPART_TEST_PG_URL")


def pg_scratch_schema(url: str) -> tuple[str, str]:
    """A fresh, uniquely named schema in the scratch database and a URL whose connections use it.

    Every test gets its own schema (``search_path`` set per connection through libpq's
    ``options``), so parallel test workers and repeated runs never see each other's tables.
    ``synchronous_commit=off`` spares each commit the wait for the server's disk flush; a commit
    is still atomic and visible to every other connection at once, which is what the tests check.
    """
    schema = f"adpart_test_{uuid.uuid4().hex[:12]}"
    engine = create_engine(url)
    with engine.begin() as conn:
        conn.execute(text(f'CREATE SCHEMA "{schema}"'))
    engine.dispose()
    sep = "&" if "?" in url else "?"
    # commits need not wait for the server's WAL flush: the tests kill clients, never the server
    options = f"-csearch_path={schema} -csynchronous_commit=off"
    return schema, f"{url}{sep}options={quote(options, safe='')}"


def drop_pg_schema(url: str, schema: str) -> None:
    engine = create_engine(url)
    with engine.begin() as conn:
        conn.execute(text(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE'))
    engine.dispose()


@dataclass(frozen=True)
class Where:
    """A knowledge-base location on one backend, as the library, a subprocess and the CLI see it.

    ``location``/``artifacts`` are what ``KnowledgeBase.open`` takes (``artifacts`` is ``""`` for
    a directory, so it can be passed on a command line); ``cli`` are the ``--kb`` options.
    """

    backend: str
    location: str
    artifacts: str
    db_url: str

    def open(self) -> KnowledgeBase:
        return KnowledgeBase.open(self.location, artifacts=self.artifacts or None)

    @property
    def cli(self) -> list[str]:
        extra = ["--kb-artifacts", self.artifacts] if self.artifacts else []
        return ["--kb", self.location, *extra]


@pytest.fixture(params=["sqlite", "postgresql"])
def where(request, tmp_path):
    """An empty knowledge-base location on SQLite (a directory) and on PostgreSQL (if set)."""
    if request.param == "sqlite":
        directory = str(tmp_path / "kb")
        yield Where("sqlite", directory, "", f"sqlite:///{directory}/kb.sqlite")
        return
    if not PG_URL:
        pytest.skip("set ADPART_TEST_PG_URL to run the store tests against PostgreSQL")
    schema, url = pg_scratch_schema(PG_URL)
    yield Where("postgresql", url, str(tmp_path / "pg-artifacts"), url)
    drop_pg_schema(PG_URL, schema)


@pytest.fixture
def kb(where):
    base = where.open()
    yield base
    base.close()


@pytest.fixture
def populated(kb):
    """An environment with one of every record kind; returns (kb, dict of records)."""
    env = kb.put_environment("five", model_hash="e" * 64, n_states=5, n_actions=2,
                             spec={"layout": "five"}, plugin="builtin", plugin_version="1")
    task = kb.put_task(env, "goal-4", spec={"goal": [4]}, gamma=0.9)
    q = np.arange(10, dtype=np.float64).reshape(5, 2)
    policy = kb.put_policy(task, "q-learning", q=q, pi=q.argmax(axis=1), seed=3, episodes=10,
                           steps=100, parameters={"alpha": 0.1})
    sgs = kb.put_subgoal_set(env, "count", [3, 1], scores=np.linspace(0, 1, 5), policy=policy)
    option = kb.put_option(env, "to-3", initiation=np.ones(5, bool), policy=np.zeros(5, int),
                           termination=np.array([0, 0, 0, 1, 1.0]), reward=np.ones(5),
                           transitions=sp.csr_array(np.eye(5) * 0.9), gamma=0.9,
                           subgoal=sgs.subgoal_ids[1])
    p1 = kb.put_partition(env, "per-option", [0, 0, 1, 1, 2], options=[option],
                          block_actions=np.ones((3, 3), bool), delta=0.1, epsilon=0.0)
    p2 = kb.put_partition(env, "reward-refined", [0, 1, 2, 2, 3], options=[option],
                          parents=[p1], task=task, epsilon=0.5, delta=0.0)
    run = kb.put_run(task, "smdp-q", partition=p2, seed=0, metrics={"final_gap": 0.25},
                     curve={"episode": np.arange(4), "gap": np.array([3.0, 1.0, 0.5, 0.25])})
    return kb, {"environment": env, "task": task, "policy": policy, "subgoal-set": sgs,
                "option": option, "p1": p1, "partition": p2, "run": run}
