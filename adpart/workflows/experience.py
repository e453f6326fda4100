"""The learned-model regime: an environment as the agent's own experience estimates it.

In the dissertation's chain the options are learned "off-line" from what the first task taught
(section 4.1) and phases 1-2 run "prior to having knowledge of the specific task" (4.2). With
the environment's true model read at every step that claim is not tested, so the learned-model
regime builds every off-line step on the **counts model** of the transitions the earlier tasks'
runs took (:class:`adpart.mdp.experience.Experience`, stored with each Q-learning run):

* :class:`EstimatedDomain` is an environment whose dynamics are that estimate (a pair never
  tried a self-loop, :meth:`Experience.estimate`), with the true environment's state features,
  action names, admissible actions and tasks (a task is a reward over the features; on the
  estimate its arrival rewards are those the estimated transitions give);
* it is named ``ENV@experience:run:N[+run:M...]`` and stored in the knowledge base as an
  environment of its own (keyed, like every environment, by its dynamics' hash), so subgoals,
  options and partitions built on it say so in their environment;
* :func:`estimated_environment` loads the named runs' experience, builds the domain and makes
  its name resolvable in this process (:func:`adpart.workflows.resolve.register_domain`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from adpart.envs.base import Domain, Dynamics, GoalSpec, TaskFactory
from adpart.errors import TaskError
from adpart.mdp.experience import Experience
from adpart.mdp.model import FiniteMDP
from adpart.partition.layer import step_baseline
from adpart.workflows.refs import parse_ref
from adpart.workflows.resolve import EXPERIENCE_MARK, register_domain, resolve_domain
from adpart.workflows.store import KnowledgeStore

__all__ = ["EstimatedDomain", "belief_model", "estimated_environment", "resolve_model",
           "run_experience", "run_policies"]


class EstimatedDomain(Domain):
    """``base``'s state space, features and tasks with the dynamics ``experience`` estimates."""

    def __init__(self, base: Domain, experience: Experience, name: str) -> None:
        self.base = base
        self.experience = experience
        self.name = name
        self.description = (f"{base.name} as estimated from the experience of "
                            f"{', '.join(experience.sources) or 'no run'}")
        self.source = base.source
        self.default_task = base.default_task

    def _build_dynamics(self) -> Dynamics:
        true = self.base.dynamics()  # its interface: the states, actions and features
        return Dynamics(self.experience.estimate(), true.action_names, true.action_costs,
                        features=true.features, admissible=true.admissible, start=true.start)

    def tasks(self) -> Mapping[str, TaskFactory | GoalSpec]:
        return self.base.tasks()

    def render(self, *args: Any, **kwargs: Any) -> Any:
        return self.base.render(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:  # a task factory may read its domain's layout
        if name == "base":
            raise AttributeError(name)
        return getattr(self.base, name)


def run_experience(kb: KnowledgeStore, run_ref: str) -> Experience:
    """The experience stored with ``run_ref``.

    Raises:
        TaskError: the run has none (a learner that does not count its transitions, or a run
            stored before schema 3); the message names ``--regime true-model``.
    """
    run = kb.get("run", parse_ref(run_ref, "run"))
    table = kb.load(run, "experience")
    if table is None:
        raise TaskError(
            f"{run.ref} ({run.learner}) stored no experience (the transitions its runs took), so "
            "no model can be estimated from it: learn the first task with q-learning, or give "
            "--regime true-model to build the layer on the true model")
    env = kb.get("environment", kb.get("task", run.task_id).environment_id)
    return Experience.from_table(table, env.n_states, env.n_actions, sources=(run.ref,))


def run_policies(kb: KnowledgeStore, run_refs: Sequence[str]) -> np.ndarray:
    """``(n, S)`` the greedy policies stored with the runs ``run_refs`` (one per run of each
    record, in order): what a learner that transfers the earlier runs' policies is given
    (``sf-gpi``).

    Raises:
        TaskError: a run stored no policy.
    """
    rows = []
    for ref in run_refs:
        run = kb.get("run", parse_ref(ref, "run"))
        ids = run.provenance.parameters.get("policies", [])
        if not ids:
            raise TaskError(f"{run.ref} ({run.learner}) stored no policies to transfer; learn "
                            "the earlier task with a learner that stores them (q-learning)")
        for policy_id in ids:
            pi = kb.load(kb.get("policy", int(policy_id)), "pi")
            if pi is None:
                raise TaskError(f"policy:{policy_id} of {run.ref} has no greedy policy stored")
            rows.append(np.asarray(pi, dtype=np.int64))
    return np.vstack(rows)


def estimated_environment(kb: KnowledgeStore, env: str, run_refs: Sequence[str]) -> str:
    """The name of ``env`` as estimated from the experience of ``run_refs``, resolvable in this
    process from now on (:class:`EstimatedDomain`)."""
    if not run_refs:
        raise TaskError("an estimated model needs at least one run's experience")
    name = f"{env}{EXPERIENCE_MARK}{'+'.join(run_refs)}"
    experience = Experience.merge(run_experience(kb, ref) for ref in run_refs)
    register_domain(name, EstimatedDomain(resolve_domain(env), experience, name))
    return name


def resolve_model(kb: KnowledgeStore, name: str) -> EstimatedDomain:
    """The estimated environment ``name`` (``ENV@experience:run:N[+run:M]``), rebuilt from the
    named runs' experience in the knowledge base when this process has not built it yet.

    Raises:
        TaskError: ``name`` is not such a name, or a run has no experience.
    """
    if EXPERIENCE_MARK not in name:
        raise TaskError(f"--model {name!r} is not a model estimated from experience; write "
                        f"ENV{EXPERIENCE_MARK}run:N (the runs whose transitions estimate it)")
    base, runs = name.split(EXPERIENCE_MARK, 1)
    built = estimated_environment(kb, base, runs.split("+"))
    return resolve_domain(built)  # type: ignore[return-value]


def belief_model(domain: EstimatedDomain, mdp: FiniteMDP, earlier_task: str) -> FiniteMDP:
    """What a layer learner of ``mdp`` may read in the learned-model regime: the dynamics
    ``domain`` estimates (an unknown pair a self-loop), the step reward the earlier task's steps
    paid (the reward most of its tried pairs paid; no goal reward is known), no terminal state
    (one is learned when entered), and the task's discount, start distribution and action set
    (its interface)."""
    P = domain.experience.estimate()
    earlier = domain.base.mdp(earlier_task)
    tried = domain.experience.tried
    step = step_baseline(earlier.R, tried & earlier.admissible, earlier.terminal, rule="mode")
    return FiniteMDP(P, np.full((mdp.n_states, mdp.n_actions), step), mdp.gamma,
                     admissible=mdp.admissible, initial=mdp.initial, features=mdp.features,
                     action_names=mdp.action_names, name=f"belief[{domain.name}]")
