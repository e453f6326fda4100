"""The subgoal detectors' settings: one frozen dataclass per detector, each default declared once.

* :class:`CountSettings` - the count metric's detection (section 4.1.1): the t-test level ``p``
  and ``N`` of eq. 4.2, the ratio paths, how the ratios are collected and what a policy that
  never terminates does. :func:`~adpart.subgoals.discover.discover_exhaustive` and
  :func:`~adpart.subgoals.count.count_metric` take it.
* :class:`MonteCarloSettings` - the sampled count metric in batches (definition 4.4, eq. 4.3,
  theorem 4.3): a :class:`CountSettings` group plus the batches and the stopping rule.
  :func:`~adpart.subgoals.discover.discover_monte_carlo` takes it.
* :class:`RewardVariationSettings` - a base detector's subgoals plus the states with a reward
  above a level (4.3.1); :func:`~adpart.subgoals.reward.reward_variation_states` takes it.
* :class:`BetweennessSettings` and :class:`VisitFrequencySettings` - the literature's detectors;
  :func:`~adpart.subgoals.literature.visit_frequency` takes the latter.
* :class:`EigenoptionSettings` and :class:`CoveringSettings` - the spectral option-discovery
  methods (Machado et al. 2017; Jinnai et al. 2019); :func:`~adpart.subgoals.spectral.eigenoptions`
  and :func:`~adpart.subgoals.spectral.covering_options` take them.

The built-in ``subgoal-detector`` plugins' parameters, their command-line options
(``adpart discover --detector count-mc --count-epsilon 1``, ``--detector-opt on-loop=error``)
and the parameters stored with a :class:`~adpart.subgoals.result.SubgoalResult` are derived from
these classes (:mod:`adpart.params`). A core function given ``settings=None`` uses the class's
defaults.
"""

from __future__ import annotations

from dataclasses import field
from typing import Any, TypeVar

from adpart.errors import TaskError
from adpart.params import setting, settings

__all__ = [
    "LAPLACIANS",
    "ON_LOOP",
    "RATIO_MODES",
    "REWARD_BASES",
    "SELECT_RULES",
    "SINK_RULES",
    "STOP_RULES",
    "BetweennessSettings",
    "CountSettings",
    "CoveringSettings",
    "EigenoptionSettings",
    "MonteCarloSettings",
    "RewardVariationSettings",
    "VisitFrequencySettings",
    "given",
]

#: How the gradient ratios are collected: along sampled paths (the seed's Fig. 4.2) or over every
#: path of the count's walker (:mod:`adpart.subgoals.discover`).
RATIO_MODES = ("paths", "all")
#: What a policy that never terminates does: raise, or sum to the ``|S|`` cap of eq. 4.1.
ON_LOOP = ("error", "truncate")
#: The Monte Carlo detector's stopping rules (:func:`~adpart.subgoals.discover_monte_carlo`).
STOP_RULES = ("passes", "predicted", "either", "bernstein", "stable", "max")
#: The detectors reward variation extends (``none``: the reward states alone).
REWARD_BASES = ("count-exhaustive", "count-mc", "none")
#: How the betweenness detector turns scores into subgoals.
SELECT_RULES = ("local-maxima", "top")
#: The graph Laplacians whose eigenvectors are the eigenoptions' proto-value functions:
#: ``I - D^{-1/2} W D^{-1/2}`` (Machado et al. 2017) or ``D - W``.
LAPLACIANS = ("normalised", "combinatorial")
#: Which of an eigenoption's sink states are its subgoals (:mod:`adpart.subgoals.spectral`).
SINK_RULES = ("extreme", "all")


def _level(p: float) -> None:
    if not 0.0 < p < 1.0:
        raise TaskError("the level p of the t-test must be in (0, 1), e.g. 0.025 (section "
                        "4.1.1.1)")


def _ratio_samples(n: int) -> None:
    if n == 1:
        raise TaskError("one ratio sample per state leaves the t-test of eq. 4.2 no degree of "
                        "freedom; give N >= 2, or 0 for automatic")


def _positive(epsilon: float) -> None:
    if epsilon <= 0.0:
        raise TaskError("must be a positive number (count units)")


def _confidence(p: float) -> None:
    if not 0.0 < p < 1.0:
        raise TaskError("the probability p of eq. 4.3 must be in (0, 1), e.g. 0.9")


@settings
class CountSettings:
    """Subgoals from the count metric: gradient ratios and the t-test threshold (4.1.1)."""

    p: float = setting(0.025, min=0.0, max=1.0, check=_level)
    """level of the one-sided t-test (eq. 4.2), in (0, 1)."""

    trajectories: int = setting(30, min=1)
    """sampled paths along which ratios are taken (--ratios paths; the seed's Fig. 4.2 uses 10,
    too few for the automatic N)."""

    n: int = setting(0, min=0, check=_ratio_samples)
    """N of eq. 4.2 (ratio samples per state), 0 or >= 2; 0 = automatic (the mean ratio samples
    per sampled state, 4 with --ratios all)."""

    ratios: str = setting("paths", choices=RATIO_MODES)
    """gradient ratios along sampled paths (paths, the seed's Fig. 4.2) or over every path of
    the count's walker, weighted by likelihood (all)."""

    on_loop: str = setting("truncate", choices=ON_LOOP)
    """a policy that never terminates: error, or truncate (sum to the |S| cap of eq. 4.1)."""


@settings
class MonteCarloSettings:
    """The sampled count metric in batches (def. 4.4), its stopping rule and eq. 4.3."""

    count: CountSettings = field(default_factory=CountSettings)
    """the detection settings the exhaustive detector takes too (p, trajectories, n, ratios,
    on_loop)."""

    batch: int = setting(50, min=1)
    """trajectories per batch (the pass rules take a pass over the start states per batch)."""

    count_epsilon: float = setting(2.0, min=0.0, check=_positive)
    """count accuracy eps_N of eq. 4.3 / theorem 4.3, > 0, in standard count units (section
    5.1.4: 2)."""

    confidence: float = setting(0.9, min=0.0, max=1.0, check=_confidence)
    """probability p of eq. 4.3, in (0, 1) (section 5.1.4: 0.9)."""

    stable_batches: int = setting(3, min=1)
    """stop when the subgoals are unchanged this many batches (--stop stable or either)."""

    stop: str = setting("passes", choices=STOP_RULES)
    """stopping rule (passes: the subgoal sets of two passes over the start states agree;
    predicted: passes until the predicted Jaccard index with the exact set is 0.95; bernstein:
    eq. 4.3 met; stable; either: bernstein or stable; max: at --max-samples)."""

    max_samples: int = setting(50_000, min=1)
    """most trajectories sampled."""


@settings
class RewardVariationSettings:
    """A base detector's subgoals plus the states with a reward above a level (4.3.1)."""

    base: str = setting("count-exhaustive", choices=REWARD_BASES)
    """detector whose subgoals are extended (none: the reward states alone)."""

    reward_level: float | None = setting(None, kind="float", none="min")
    """level a state's reward (for some admissible action) must exceed: min, the smallest reward
    of an admissible pair of a non-terminal state (4.3.1), or a number (5.1.3: 0)."""

    terminal_targets: bool = setting(True)
    """also add the terminal states a rewarded pair reaches (adpart pays a goal's reward on
    arrival, so these are the goals)."""


@settings
class BetweennessSettings:
    """Betweenness centrality of the transition graph (Simsek & Barto 2008)."""

    select: str = setting("local-maxima", choices=SELECT_RULES)
    """local-maxima (more central than every neighbour, the paper's rule) or top."""

    top: int = setting(4, min=1)
    """number of subgoals with --select top (the most central states)."""

    sources: int = setting(0, min=0)
    """sampled BFS sources (Brandes & Pich 2007); 0 = all (exact)."""


@settings
class VisitFrequencySettings:
    """States visited by many successful random walks (Digney 1996; McGovern & Barto 2001)."""

    top: int = setting(4, min=1)
    """number of subgoals (the most visited states)."""

    walks: int = setting(500, min=1)
    """uniformly random walks sampled from uniform non-terminal starts."""

    horizon: int = setting(0, min=0, check=_ratio_samples)
    """step limit of a walk; 0 = 10 |S|."""


def _discount(gamma: float) -> None:
    if not 0.0 < gamma < 1.0:
        raise TaskError("the eigenoptions' discount must be in (0, 1), e.g. 0.9 (Machado et al. "
                        "2017's value iteration)")


@settings
class EigenoptionSettings:
    """Eigenoptions: sinks of the eigenpurposes of the graph Laplacian (Machado et al. 2017)."""

    k: int = setting(4, min=1)
    """non-constant eigenvectors used, the smallest eigenvalues first; each with both signs, so up
    to 2 k eigenoptions."""

    laplacian: str = setting("normalised", choices=LAPLACIANS)
    """normalised (I - D^-1/2 W D^-1/2, the paper's) or combinatorial (D - W)."""

    discount: float = setting(0.9, min=0.0, max=1.0, check=_discount)
    """discount of the eigenpurpose's value iteration, in (0, 1) (the authors' code: 0.9)."""

    sinks: str = setting("extreme", choices=SINK_RULES)
    """subgoals of an eigenoption: extreme (its sink of largest eigenvector value, the argmax) or
    all (every state where the option terminates)."""


@settings
class CoveringSettings:
    """Covering options: Fiedler-vector extremes joined round by round (Jinnai et al. 2019)."""

    rounds: int = setting(4, min=1)
    """rounds of the algorithm; each adds one option (a pair of subgoals) per component."""


_S = TypeVar("_S")


def given(cls: type[_S], value: Any) -> _S:
    """``value`` when it is a ``cls``, ``cls()`` (the defaults) for None; else TaskError."""
    if value is None:
        return cls()
    if not isinstance(value, cls):
        raise TaskError(f"settings must be a {cls.__name__} (or None for its defaults), got "
                        f"{type(value).__name__}; build one with {cls.__name__}(...) or "
                        f"adpart.params.build_settings({cls.__name__}, {{...}})")
    return value
