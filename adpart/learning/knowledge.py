"""What a learner knows about the task it learns, as data, and a guard that holds it to that.

A comparison of two learners is fair only when each was given the same knowledge, so every
learner declares it (:class:`Knowledge`) and the record is stored with every run and printed
beside every comparison:

* **dynamics** - ``none`` (the learner only samples the environment), ``estimated`` (it reads a
  model estimated from the transitions earlier runs took, named in ``uses``: the learned-model
  regime, :mod:`adpart.mdp.experience`), or ``true-model`` (it reads the exact transition model
  ``P``: to solve option policies or option models, to build or refine a layer, to compute a
  reference value);
* **rewards** - ``observed`` (the learner sees a reward only when it takes the step that pays
  it, and a terminal state only when it enters it), or ``known`` (it reads the task's reward
  function ``R`` or its terminal set before or while learning: options to its reward states, a
  partition split by its rewards, a reward floor ``r_min``);
* **uses** - what was computed from that knowledge, by name (``option models``, ``threshold L
  from V*``, ...).

Evaluation against ``V*`` is for scoring only and is never knowledge. The environment's own
use of its model - drawing successor states and rewards, and scoring greedy policies - runs
inside :func:`world`; everything else a learner does with the task's :class:`FiniteMDP` is
knowledge. :func:`guard` returns a copy of an MDP whose dynamics and reward fields raise
:class:`KnowledgeError` when read outside :func:`world` by a learner whose declared knowledge
does not include them. A value read inside :func:`world` and then used for learning (``V*`` for a
threshold) is not caught by the guard, so the learners declare such uses in ``uses``.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from adpart.errors import AdpartError

__all__ = ["DYNAMICS", "FLAT", "OPTION_POLICIES", "PLANNER", "REGIMES", "REWARDS", "Knowledge",
           "KnowledgeError", "combine", "estimated_option_policies", "guard", "world"]

#: What a learner may know of the dynamics, least first.
DYNAMICS = ("none", "estimated", "true-model")
#: What a learner may know of the rewards, least first.
REWARDS = ("observed", "known")
#: What the off-line steps of the transfer chain read: the model estimated from the earlier
#: tasks' experience, or the true model (``adpart pipeline --regime``).
REGIMES = ("learned-model", "true-model")


class KnowledgeError(AdpartError):
    """A learner read knowledge of the task outside the regime it declared."""


@dataclass(frozen=True)
class Knowledge:
    """What a learner was given (module docstring)."""

    dynamics: str = "none"
    rewards: str = "observed"
    uses: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics {self.dynamics!r} is not one of {DYNAMICS}")
        if self.rewards not in REWARDS:
            raise ValueError(f"rewards {self.rewards!r} is not one of {REWARDS}")
        object.__setattr__(self, "uses", tuple(dict.fromkeys(self.uses)))

    def allows(self, kind: str) -> bool:
        """Whether reading ``kind`` (``"dynamics"`` or ``"rewards"``) of the task's own model is
        within the regime (an estimated model is another model, never the task's)."""
        return (self.dynamics == "true-model") if kind == "dynamics" else self.rewards == "known"

    @property
    def label(self) -> str:
        """One line: ``dynamics true-model, rewards observed (option models, ...)``."""
        text = f"dynamics {self.dynamics}, rewards {self.rewards}"
        return f"{text} ({', '.join(self.uses)})" if self.uses else text

    def to_dict(self) -> dict[str, Any]:
        return {"dynamics": self.dynamics, "rewards": self.rewards, "uses": list(self.uses)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Knowledge:
        return cls(str(data["dynamics"]), str(data["rewards"]), tuple(data.get("uses", ())))


#: A model-free learner that samples the environment and observes its rewards.
FLAT = Knowledge()
#: What a learner over options knows through them: every option adpart builds is a policy
#: solved on the environment's true dynamics (to its subgoal, with a pseudo-reward: 4.1).
OPTION_POLICIES = Knowledge("true-model", "observed",
                            ("option policies solved on the true dynamics",))


def estimated_option_policies(sources: str) -> Knowledge:
    """What a learner over options knows when they were solved on the model estimated from
    the experience of ``sources`` (run references)."""
    return Knowledge("estimated", "observed",
                     (f"option policies solved on the model estimated from {sources}",))


#: A planner on the task's exact model (value iteration): it needs no episode at all.
PLANNER = Knowledge("true-model", "known", ("value iteration on the exact model",))


def combine(parts: Iterable[Knowledge]) -> Knowledge:
    """The knowledge of a run whose inputs (options, a layer) and learner knew ``parts``."""
    parts = list(parts)
    dynamics = max((p.dynamics for p in parts), key=DYNAMICS.index, default="none")
    rewards = max((p.rewards for p in parts), key=REWARDS.index, default="observed")
    return Knowledge(dynamics, rewards, tuple(u for p in parts for u in p.uses))


# --------------------------------------------------------------------------------- the guard

_WORLD: contextvars.ContextVar[bool] = contextvars.ContextVar("adpart_world", default=False)

#: The FiniteMDP members that read the dynamics or the task's rewards and terminals.
_GUARDED = {
    "P": "dynamics", "transition_row": "dynamics", "sample_next": "dynamics",
    "sampler_keys": "dynamics", "sampler_arrays": "dynamics", "as_smdp": "dynamics",
    "_smdp": "dynamics", "with_rewards": "rewards", "R": "rewards", "terminal": "rewards",
}


#: What every agent knows: how many states and actions there are, and the task's identity.
_INTERFACE = frozenset({"n_states", "n_actions", "content_hash"})


@contextlib.contextmanager
def world() -> Iterator[None]:
    """The environment's own use of its model (sampling steps, scoring against ``V*``)."""
    token = _WORLD.set(True)
    try:
        yield
    finally:
        _WORLD.reset(token)


def guard(mdp: Any, knowledge: Knowledge) -> Any:
    """A copy of ``mdp`` that raises :class:`KnowledgeError` when a learner reads what
    ``knowledge`` does not include, outside :func:`world` (for tests and audits)."""
    from adpart.mdp.model import FiniteMDP

    mdp.content_hash  # noqa: B018 (computed on the original: a record may name the task)
    cls = _guarded_class(type(mdp) if isinstance(mdp, FiniteMDP) else FiniteMDP)
    copy = object.__new__(cls)
    copy.__dict__.update(mdp.__dict__)
    copy.__dict__["_knowledge"] = knowledge
    return copy


_CLASSES: dict[type, type] = {}


def _guarded_class(base: type) -> type:
    if base not in _CLASSES:

        def __getattribute__(self: Any, name: str) -> Any:
            if name in _INTERFACE:  # the agent's interface, whatever the model stores it in
                with world():
                    return base.__getattribute__(self, name)
            kind = _GUARDED.get(name)
            if kind is not None and not _WORLD.get():
                knowledge = object.__getattribute__(self, "__dict__")["_knowledge"]
                if not knowledge.allows(kind):
                    raise KnowledgeError(
                        f"read {name} ({kind}) of {object.__getattribute__(self, 'name')!r} "
                        f"outside the declared regime: {knowledge.label}"
                    )
            return base.__getattribute__(self, name)

        _CLASSES[base] = type(f"Guarded{base.__name__}", (base,),
                              {"__getattribute__": __getattribute__})
    return _CLASSES[base]
