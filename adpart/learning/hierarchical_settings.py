"""The hierarchical learner's settings: one frozen dataclass of named parts (section 4.3).

:class:`HierarchicalSettings` is the single declaration of every setting of
:func:`adpart.learning.hierarchical.hierarchical_learning`: its default, range, choices and help
(the docstring under each field), and the rules across fields (:meth:`HierarchicalSettings.check`).
The ``hierarchical`` learner plugin's parameters, their command-line options
(``adpart learn --learner hierarchical --lcb-z 1``, ``--hier-opt lcb-z=1``) and the stored
provenance are derived from it. Its parts:

* :class:`Exploration` - how the agent explores (epsilon over primitives until the first reward,
  the optimistic flat action, R-max);
* :class:`InconsistencyTest` - the test of section 4.3.3 and its reference;
* :class:`Refinement` - where an action added by a firing joins, and the thresholds of eqs.
  4.6-4.7 the refined block is split with.

The run settings every tabular learner shares (runs, episodes, seed, schedules) are
:class:`adpart.learning.settings.Run`'s.
"""

from __future__ import annotations

from dataclasses import field

from adpart.errors import TaskError
from adpart.params import setting, settings

__all__ = [
    "EXPLORATION_RULES",
    "LAYER_VALUES",
    "MODES",
    "PRIMITIVE_EXPLORATION",
    "REFERENCES",
    "REFINE_RULES",
    "REWARD_OPTION_MODES",
    "TESTING_MODES",
    "Exploration",
    "HierarchicalSettings",
    "InconsistencyTest",
    "Refinement",
]

#: How the goal becomes reachable on the layer (section 4.3; hierarchical.py's docstring).
MODES = ("inconsistency", "action-refinement", "reward-variation",
         "reward-variation+inconsistency")
#: The modes that add options to the task's reward states (4.3.1) and those that test (4.3.3).
REWARD_OPTION_MODES = ("reward-variation", "reward-variation+inconsistency")
TESTING_MODES = ("inconsistency", "reward-variation+inconsistency")
#: What the grounded flat value must beat by L.
REFERENCES = ("model", "learned", "offered", "policy")
#: Where an action added by a firing joins the layer.
REFINE_RULES = ("state", "block")
#: When epsilon-exploration draws among the primitive actions alone (kernel codes).
PRIMITIVE_EXPLORATION = {"never": 0, "always": 1, "until-reward": 2}
#: What the layer learner explores by beside epsilon over the block's columns (section 4.3.3).
EXPLORATION_RULES = ("optimistic-flat", "r-max", "columns")
#: What the greedy policy is greedy on.
LAYER_VALUES = ("learned", "planned")


@settings
class Exploration:
    """How the agent explores beside epsilon-greedy choice on the layer."""

    primitive_exploration: str = setting("until-reward", choices=tuple(PRIMITIVE_EXPLORATION))
    """when epsilon-exploration draws among the primitive actions alone: until the run first
    collects a reward above the step reward (until-reward), always, or never (a random option
    jumps to a subgoal of the earlier task; testing modes only)."""

    explore: str = setting("optimistic-flat", choices=EXPLORATION_RULES)
    """what the agent explores by beside epsilon over the block's columns, a strategy of its own
    (inconsistency mode only; the other modes explore by the columns): at a greedy decision take
    the action of the optimistic flat Q-table where it beats the block's best value
    (optimistic-flat), or the action of R-max's optimistic model of the run's counts, a pair
    known after known-after tries and an unknown one worth value-ceiling, the test then reading
    the grounded values of the empirical model (r-max); or nothing more (columns: the seed's
    decisions "only based on the abstract partition")."""

    known_after: int = setting(1, min=1)
    """R-max's m: the tries after which a flat pair's model is known (explore r-max)."""

    value_ceiling: float | None = setting(None, kind="float", none="auto")
    """R-max's v_max, what an unknown pair is worth (explore r-max); auto: max(R, 0) / (1 -
    gamma) of the task's own rewards (the true-model regime; a learner on a belief model must be
    given one: the pipeline's learned-model regime gives the ceiling of the rewards its first
    task paid)."""


@settings
class InconsistencyTest:
    """The test of section 4.3.3: where a primitive action's grounded value beats the layer."""

    reference: str | None = setting(None, kind="str", choices=REFERENCES, none="auto")
    """what the grounded flat value must beat by L: the block's learned value (learned), its
    point-model value V*_P(b) (model), the larger of that and the best the options offered at the
    state achieve from it (offered), or the value from the state of the layer's best block
    policy (policy); auto: offered in reward-variation+inconsistency mode, else learned."""

    threshold: float | None = setting(None, kind="float", min=0.0, none="auto", finite=False)
    """the threshold L a firing must exceed; auto: threshold-scale x |V*(start)| (from Python,
    inf turns the test off: the layer is learned without refinement)."""

    threshold_scale: float = setting(0.025, min=0.0)
    """the default L as a fraction of |V*(start)| (half the 5% gap at which a run counts as
    learned)."""

    lcb_z: float = setting(2.0, min=0.0)
    """standard errors subtracted from a stochastic pair's lower-bound flat value (its lower
    confidence bound)."""

    min_visits: int = setting(2, min=0)
    """visits of the flat pair and of the block before the test may fire."""

    split_offered: bool = setting(False)
    """with reference policy: also test an action the state's block already offers, and where
    it beats what the layer's policy gets from the state by more than L, split the state from
    its block."""


@settings
class Refinement:
    """What a firing does to the layer (section 4.3.3, eqs. 4.6-4.7)."""

    refine: str = setting("state", choices=REFINE_RULES)
    """where an action added by a firing joins: the firing state, which becomes a block of its
    own (state), or every state of its block, as 4.3.3 writes it (block)."""

    delta: float = setting(0.0, min=0.0, max=1.0)
    """delta of eq. 4.6 for building the layer and refining a block, in [0, 1]."""

    partition_epsilon: float | None = setting(0.0, min=0.0, none="none")
    """epsilon of eq. 4.7 (the reward split) for building the layer and refining a block; none:
    no reward split."""

    online_phase3: bool = setting(False)
    """phase 3 online, on a belief model (the learned-model regime): after every episode a run's
    belief takes the rewards of the pairs it tried and the terminal states it entered, and the
    blocks where that changes its option models are split by eq. 4.7 and to delta-stability
    (adpart.learning.online_phase3); the true-model layer was built with phase 3 already."""


@settings
class HierarchicalSettings:
    """Every setting of the hierarchical learner (section 4.3), in named parts."""

    mode: str = setting("inconsistency", choices=MODES)
    """how the goal becomes reachable on the layer (section 4.3): inconsistency refinement
    (4.3.3), action-refinement (4.3.2), reward-variation (4.3.1), or reward variation with the
    inconsistency test."""

    layer_values: str = setting("learned", choices=LAYER_VALUES)
    """what the greedy policy is greedy on: the layer's learned Q-values (learned), or the
    layer's point model planned on the counts of R-max, explore r-max (planned)."""

    intra_option: bool = setting(False)
    """update every offered option consistent with each step (virtual executions, block
    level)."""

    exploration: Exploration = field(default_factory=Exploration)
    test: InconsistencyTest = field(default_factory=InconsistencyTest)
    refinement: Refinement = field(default_factory=Refinement)

    def check(self) -> None:
        """The rules across parts (each stated once, here)."""
        if self.test.split_offered and self.test.reference != "policy":
            raise TaskError("split_offered (--split-offered) compares with what the layer's "
                            "policy gets from each state: give reference = policy "
                            "(--reference policy)")
        if self.layer_values == "planned" and not self.directed:
            raise TaskError("layer_values = planned (--layer-values planned) plans on the counts "
                            "of R-max exploration: give explore = r-max (--explore r-max) in "
                            "inconsistency mode")

    @property
    def testing(self) -> bool:
        """Whether the mode runs the inconsistency test (4.3.3)."""
        return self.mode in TESTING_MODES

    @property
    def reward_options(self) -> bool:
        """Whether the mode adds options to the task's reward states (4.3.1)."""
        return self.mode in REWARD_OPTION_MODES

    @property
    def exploration_rule(self) -> str:
        """The exploration strategy in force: the given one in inconsistency mode, else the
        block's columns."""
        return self.exploration.explore if self.mode == "inconsistency" else "columns"

    @property
    def flat_explore(self) -> bool:
        """A flat action is explored at greedy decisions (optimistic-flat or r-max)."""
        return self.exploration_rule != "columns"

    @property
    def directed(self) -> bool:
        """R-max exploration is on (explore r-max, inconsistency mode)."""
        return self.exploration_rule == "r-max"

    @property
    def test_reference(self) -> str:
        """The reference in force: the given one, or the mode's default."""
        if self.test.reference is not None:
            return self.test.reference
        return "offered" if self.mode == "reward-variation+inconsistency" else "learned"
