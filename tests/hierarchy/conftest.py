"""Fixtures of the hierarchy tests: a knowledge base with learned four-rooms tasks and options."""

from __future__ import annotations

import numpy as np
import pytest

from adpart.envs.registry import get_domain
from adpart.mdp.solvers import q_from_v, solve
from adpart.options import doorway_options, option_models
from adpart.plugins import manager
from adpart.store import KnowledgeBase


@pytest.fixture
def estimator_registry(monkeypatch):
    """The registry with the built-in estimators module registered (as the entry point does)."""
    monkeypatch.setitem(manager.BUILTIN_PLUGINS, "estimators", "adpart.plugins.builtin.estimators")
    manager.reset_registry()
    yield manager.get_registry()
    manager.reset_registry()


def store_domain(kb: KnowledgeBase, env_name: str, task_names: list[str]) -> dict:
    """Solve each task exactly and store it as learning would; store doorway options."""
    domain = get_domain(env_name)
    dyn = domain.dynamics()
    env = kb.put_environment(env_name, model_hash=dyn.content_hash, n_states=dyn.n_states,
                             n_actions=dyn.n_actions, spec={"name": env_name})
    tasks = {}
    for name in task_names:
        mdp = domain.mdp(name)
        Q = q_from_v(mdp, solve(mdp).V)
        task = kb.put_task(env, name, spec={"name": name, "model_hash": mdp.content_hash},
                           gamma=mdp.gamma)
        kb.put_policy(task, "value-iteration", q=np.where(np.isfinite(Q), Q, np.nan),
                      pi=np.argmax(Q, axis=1).astype(np.int64))
        tasks[name] = task
    mdp = domain.mdp(task_names[0])
    options = doorway_options(mdp)
    models = option_models(mdp, options, duration=False)
    sset = kb.put_subgoal_set(env, "hand", [o.subgoal for o in options])
    by_state = dict(zip(sset.states, sset.subgoal_ids, strict=True))
    records = [
        kb.put_option(env, o.name, initiation=o.initiation, policy=o.policy, termination=o.beta,
                      reward=m.R, transitions=m.F, gamma=mdp.gamma, subgoal=by_state[o.subgoal],
                      parameters={"subgoal_state": o.subgoal})
        for o, m in zip(options, models, strict=True)
    ]
    return {"env": env, "tasks": tasks, "options": records, "domain": domain}


@pytest.fixture
def four_rooms_kb(tmp_path):
    kb = KnowledgeBase.open(tmp_path / "kb")
    data = store_domain(kb, "four-rooms", ["G1", "G2"])
    yield kb, data
    kb.close()
