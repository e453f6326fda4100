"""The run settings every tabular learner takes: one :class:`Run`, checked once when built.

Flat Q-learning, SMDP Q-learning, the hierarchical learner and MAXQ-Q all take a ``Run``: how many
independent runs, how long, how they are seeded and scored, and the sample-based update's
step-size and exploration schedules. Its fields are the single declaration of each default,
range and help text: the learner plugins' parameters, ``adpart learn``'s run options and the
stored provenance are derived from it (:mod:`adpart.params`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from adpart.errors import ModelError
from adpart.learning.schedules import Schedule, parse_schedule
from adpart.params import hook, setting, settings

if TYPE_CHECKING:
    import numpy as np

__all__ = ["LEARNER_FIELDS", "MAX_SEED", "Run", "SFGPISettings", "SMDPQSettings", "fresh_seed",
           "require_mdp"]

#: The largest seed: the knowledge base stores seeds as signed 64-bit integers.
MAX_SEED = 2**63 - 1

#: The fields of :class:`Run` that describe the learner's update rather than the experiment:
#: they are the learner plugins' parameters (``--learner-opt alpha=1``); the rest are the
#: ``--runs/--episodes/--seed/--eval-every`` options of the commands that learn.
LEARNER_FIELDS = ("alpha", "epsilon", "max_steps_per_episode", "q_init", "kernel")

#: The experiment's fields, in the order the commands list them.
EXPERIMENT_FIELDS = ("episodes", "runs", "seed", "eval_every")


def _probability_schedule(what: str) -> Callable[[Any], Schedule]:
    """A parser: a schedule (or its spelling, or a number) that stays within [0, 1]."""

    def parse(value: Any) -> Schedule:
        return parse_schedule(value).check_probability(what)

    return parse


@settings
class Run:
    """How a learner's K runs go (dissertation section 2.x: epsilon-greedy Q-learning, eq. 2.4).

    Building one checks every field; a learner below this boundary trusts it.
    """

    runs: int = setting(20, min=1, max=100_000)
    """Independent runs, advanced together (20: the fewest for a CI)."""
    episodes: int = setting(300, min=1, max=10_000_000)
    """Episodes per run."""
    seed: int | None = setting(0, kind="int", min=0, max=MAX_SEED, none="fresh")
    """Root seed of default_rng(seed).spawn(runs); fresh: drawn from OS entropy, recorded."""
    eval_every: int = setting(10, min=1, max=10_000_000)
    """Score the greedy policies exactly every N episodes."""
    max_steps_per_episode: int = setting(1000, min=1, max=1_000_000_000, option="max-steps")
    """Primitive-step limit of one episode; a cut episode bootstraps through the cut."""
    alpha: Schedule = setting("1/n^0.8", kind="str", parse=_probability_schedule("alpha"))
    """Step-size schedule: 0.1 | 1/n^0.8 | exp:0.5,0.99 (its visit count is n(s, a))."""
    epsilon: Schedule = setting("0.1", kind="str", parse=_probability_schedule("epsilon"))
    """Exploration schedule, same forms as --alpha (its visit count is n(s))."""
    q_init: float | None = setting(None, kind="float", none="auto")
    """Starting value of every admissible Q entry (auto: 0, or the lower bound r_min/(1-gamma)
    under R-max exploration)."""
    kernel: str | None = setting(None, kind="str", none="auto", choices=("numba", "python"))
    """Step kernel: numba (compiled) or python (the same rule interpreted, the reference);
    identical results."""
    reference_values: np.ndarray | None = hook()
    """V* (S,) to score against; solved exactly when omitted."""
    progress: Callable[[int, int], object] | None = hook()
    """Called as progress(episodes done by every run, episodes) after every evaluation."""

    @property
    def start_q(self) -> float:
        """The starting Q-value when no learner rule overrides None: 0."""
        return 0.0 if self.q_init is None else float(self.q_init)


def fresh_seed(seed: int | None) -> int:
    """``seed``, or for a ``fresh`` seed (None) one drawn from OS entropy here, once."""
    if seed is None:
        import numpy as np

        return int(np.random.SeedSequence().entropy) % (MAX_SEED + 1)  # type: ignore[operator]
    return int(seed)


def require_mdp(learner: str, mdp: object) -> object:
    """``mdp`` if it is a FiniteMDP, else ModelError naming ``learner`` and the fix."""
    from adpart.mdp.model import FiniteMDP

    if not isinstance(mdp, FiniteMDP):
        raise ModelError(
            f"{learner} needs a FiniteMDP, got {type(mdp).__name__}; build one with "
            "adpart.envs.registry.get_domain(name).mdp()"
        )
    return mdp


@settings
class SMDPQSettings:
    """The settings of SMDP Q-learning over options (section 3.1) beyond its run."""

    include_primitives: bool = setting(False)
    """offer the primitive actions beside the options (their one-step options first)."""

    intra_option: bool = setting(False)
    """also update every option consistent with each primitive step (intra-option Q-learning,
    Sutton, Precup & Singh 1999)."""


@settings
class SFGPISettings:
    """The settings of successor features with GPI (:mod:`adpart.learning.sf_gpi`) beyond its
    run."""

    dynamics: str = setting("estimated", choices=("estimated", "true-model"))
    """what the successor features of the earlier runs' policies are computed on: those runs'
    counts (estimated) or the environment's true model (true-model, declared as such)."""
