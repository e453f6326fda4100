"""Built-in learner plugins ``smdp-q`` and ``hierarchical`` (docs/hierarchical-learning.md).

A plain ``learn(mdp, ...)`` call carries no options or partition, so both learners take them as
keywords of :meth:`learn` (``options=`` a list of :class:`adpart.options.Option`, ``partition=`` an
:class:`adpart.partition.Partition`); the CLI reads them from the knowledge base
(``adpart learn ENV --learner smdp-q --options ID``, ``--partition ID``). Without options
``smdp-q`` learns over the primitive actions alone (flat Q-learning in SMDP form) and
``hierarchical`` refuses to run.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from adpart.errors import TaskError
from adpart.learning.result import LearnResult
from adpart.mdp.model import FiniteMDP
from adpart.options.option import Option
from adpart.params import Param
from adpart.partition.partition import Partition
from adpart.plugins.builtin.learners import ALPHA, EPSILON, MAX_STEPS, kernel, q_init
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar


class SMDPQLearner:
    """SMDP Q-learning over options, K runs in lock-step, scored exactly."""

    name = "smdp-q"
    description = "SMDP Q-learning over options (plus primitive actions), runs in lock-step"
    accepts = frozenset({"options"})
    params = (
        ALPHA,
        EPSILON,
        Param("primitives", "bool", False, "offer the primitive actions beside the options"),
        Param("intra-option", "bool", False,
              "update every option consistent with each step (Sutton, Precup & Singh 1999)"),
        MAX_STEPS,
        q_init("Q(s, o)"),
        kernel("numba", "python"),
    )

    def __init__(self, alpha: str = "1/n^0.8", epsilon: str = "0.1", primitives: bool = False,
                 intra_option: bool = False, max_steps: int = 1000, q_init: float = 0.0,
                 kernel: str = "auto") -> None:
        self.alpha, self.epsilon, self.primitives = alpha, epsilon, bool(primitives)
        self.intra_option = bool(intra_option)
        self.max_steps, self.q_init = max_steps, q_init
        self.kernel = None if kernel == "auto" else kernel

    def learn(self, mdp: FiniteMDP, *, runs: int, episodes: int, seed: int, eval_every: int,
              progress: Callable[[int, int], object] | None = None,
              options: Sequence[Option] | None = None,
              partition: Partition | None = None) -> LearnResult:
        from adpart.learning.smdp_q import smdp_q_learning

        opts = list(options or [])
        return smdp_q_learning(
            mdp, opts, include_primitives=self.primitives or not opts, runs=runs,
            episodes=episodes, seed=seed, alpha=self.alpha, epsilon=self.epsilon,
            max_steps_per_episode=self.max_steps, eval_every=eval_every, progress=progress,
            q_init=self.q_init, kernel=self.kernel, intra_option=self.intra_option,
        )


class HierarchicalLearner:
    """Decision-layer learning with inconsistency refinement or its alternatives (4.3)."""

    name = "hierarchical"
    description = "SMDP Q on a partition's blocks, refined where flat and abstract values disagree"
    accepts = frozenset({"options", "partition"})
    params = (
        Param("mode", "str", "inconsistency", "how the goal becomes reachable (section 4.3)",
              choices=("inconsistency", "action-refinement", "reward-variation",
                       "reward-variation+inconsistency")),
        Param("delta", "float", 0.0, "delta of eq. 4.6 for building/refining blocks", min=0.0),
        Param("partition-epsilon", "float", 0.0, "epsilon of eq. 4.7 (reward split)", min=0.0),
        Param("threshold", "float", -1.0, "inconsistency threshold L; < 0 = scale-aware default"),
        Param("threshold-scale", "float", 0.025, "default L = scale x |V*(start)|", min=0.0),
        Param("lcb-z", "float", 2.0,
              "standard errors off a stochastic pair's lower-bound flat value", min=0.0),
        Param("flat-explore", "bool", True,
              "take the optimistic flat action where it beats the block's best"),
        Param("reference", "str", "auto",
              "what the grounded flat value must beat by L: the block's point-model value "
              "(model), its learned value (learned), the larger of that point-model value and "
              "the best the options offered at the state achieve from it (offered), or the "
              "value from the state of the layer's best block policy (policy); auto: offered "
              "in reward-variation+inconsistency mode, else learned",
              choices=("auto", "model", "learned", "offered", "policy")),
        Param("min-visits", "int", 2, "visits of the flat pair and block before a test fires",
              min=0),
        Param("intra-option", "bool", False,
              "update every offered option consistent with each step (block level)"),
        Param("refine", "str", "state",
              "where an action added by a firing joins: the firing state (state) or its whole "
              "block (block)", choices=("state", "block")),
        Param("primitive-exploration", "str", "until-reward",
              "when epsilon-exploration draws among the primitive actions alone",
              choices=("until-reward", "always", "never")),
        Param("explore-known", "int", 0,
              "R-max: explore by the optimistic model of the flat pairs, a pair known after "
              "this many tries, and test against its grounded model values (0: off)", min=0),
        Param("layer-values", "str", "learned",
              "what the greedy policy is greedy on: the layer's learned Q-values (learned), or "
              "the layer's point model planned on the counts of explore-known (planned)",
              choices=("learned", "planned")),
        Param("split-offered", "bool", False,
              "with reference policy: where an action the state's block already offers beats "
              "what the layer's policy gets there, split the state from its block"),
        ALPHA,
        EPSILON,
        MAX_STEPS,
        kernel("numba", "python"),
    )

    def __init__(self, mode: str = "inconsistency", delta: float = 0.0,
                 partition_epsilon: float = 0.0, threshold: float = -1.0,
                 threshold_scale: float = 0.025, lcb_z: float = 2.0, flat_explore: bool = True,
                 reference: str = "auto",
                 min_visits: int = 2, intra_option: bool = False, refine: str = "state",
                 primitive_exploration: str = "until-reward", explore_known: int = 0,
                 layer_values: str = "learned", split_offered: bool = False,
                 alpha: str = "1/n^0.8", epsilon: str = "0.1", max_steps: int = 1000,
                 kernel: str = "auto") -> None:
        self.intra_option = bool(intra_option)
        self.refine, self.primitive_exploration = refine, primitive_exploration
        if layer_values == "planned" and explore_known == 0:
            raise TaskError("--layer-values planned plans on the counts of R-max exploration; "
                            "give --explore-known 1 or more")
        self.explore_known, self.layer_values = explore_known, layer_values
        if split_offered and reference != "policy":
            raise TaskError("--split-offered compares with what the layer's policy gets from "
                            "each state; give --reference policy")
        self.split_offered = bool(split_offered)
        self.lcb_z, self.flat_explore = lcb_z, bool(flat_explore)
        self.reference = None if reference == "auto" else reference
        self.mode, self.delta, self.partition_epsilon = mode, delta, partition_epsilon
        self.threshold = None if threshold < 0 else threshold
        self.threshold_scale, self.min_visits = threshold_scale, min_visits
        self.alpha, self.epsilon, self.max_steps = alpha, epsilon, max_steps
        self.kernel = None if kernel == "auto" else kernel

    def learn(self, mdp: FiniteMDP, *, runs: int, episodes: int, seed: int, eval_every: int,
              progress: Callable[[int, int], object] | None = None,
              options: Sequence[Option] | None = None,
              partition: Partition | None = None) -> LearnResult:
        from adpart.learning.hierarchical import REWARD_OPTION_MODES, hierarchical_learning

        if not options and self.mode not in REWARD_OPTION_MODES:
            raise TaskError(
                "the hierarchical learner needs options (and optionally a partition); pass "
                "--options ID (and --partition ID) from the knowledge base, or use a "
                "reward-variation mode, which makes options to the task's reward states"
            )
        return hierarchical_learning(
            mdp, list(options or []), partition, mode=self.mode, delta=self.delta,
            epsilon=self.partition_epsilon, threshold=self.threshold,
            threshold_scale=self.threshold_scale, min_visits=self.min_visits, lcb_z=self.lcb_z,
            flat_explore=self.flat_explore, reference=self.reference, runs=runs,
            episodes=episodes, seed=seed, alpha=self.alpha, epsilon_greedy=self.epsilon,
            max_steps_per_episode=self.max_steps, eval_every=eval_every, progress=progress,
            kernel=self.kernel, intra_option=self.intra_option, refine=self.refine,
            primitive_exploration=self.primitive_exploration, explore_known=self.explore_known,
            layer_values=self.layer_values, split_offered=self.split_offered,
        )


@hookimpl
def register_learners(register: Registrar) -> None:
    register(SMDPQLearner)
    register(HierarchicalLearner)
