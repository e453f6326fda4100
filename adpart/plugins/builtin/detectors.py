"""Built-in subgoal detectors (section 4.1 and the literature): thin plugin classes over the
library functions of :mod:`adpart.subgoals`, registered like any third-party plugin.

Call signature (hookspec ``register_subgoal_detectors``): ``cls(**params).detect(mdp, policy,
rng) -> SubgoalResult`` where ``policy`` is ``(S,)`` action ids or ``(S, A)`` probabilities.
Each detector's parameters (their defaults, ranges and help) are derived from its settings
dataclass in :mod:`adpart.subgoals.settings`, and the parameters a result stores are those
settings (:func:`~adpart.params.settings_dict`).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from adpart.params import build_settings, settings_dict, settings_params, with_help
from adpart.plugins.hookspecs import hookimpl
from adpart.plugins.registry import Registrar
from adpart.subgoals.settings import (
    BetweennessSettings,
    CountSettings,
    CoveringSettings,
    EigenoptionSettings,
    MonteCarloSettings,
    RewardVariationSettings,
    VisitFrequencySettings,
)

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy as np

    from adpart.mdp.model import FiniteMDP
    from adpart.subgoals.result import SubgoalResult
    from adpart.subgoals.spectral import CoveringOption, Eigenoption


class CountExhaustive:
    """Count metric by sparse mat-vecs (eq. 4.1), gradient ratios, t-test threshold.

    Its parameters are :class:`~adpart.subgoals.settings.CountSettings`' fields.
    """

    name = "count-exhaustive"
    description = "count metric by sparse mat-vecs (eq. 4.1), gradient ratios, t-test threshold"
    params = settings_params(CountSettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(CountSettings, values)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray, rng: np.random.Generator) -> SubgoalResult:
        from adpart.subgoals.discover import discover_exhaustive

        return discover_exhaustive(mdp, policy, rng, self.settings)


class CountMonteCarlo:
    """Sampled count metric in batches (def. 4.4), Bernstein/stability stops, raised threshold.

    Its parameters are :class:`~adpart.subgoals.settings.MonteCarloSettings`' fields (its
    ``count`` group's, the exhaustive detector's, included).
    """

    name = "count-mc"
    description = "Monte Carlo count metric in batches (def. 4.4, eq. 4.3, theorem 4.3)"
    params = with_help(
        settings_params(MonteCarloSettings),
        trajectories="trajectories of the first batch, and the sampled paths along which "
        "ratios are taken (--ratios paths).")

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(MonteCarloSettings, values)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray, rng: np.random.Generator) -> SubgoalResult:
        from adpart.subgoals.discover import discover_monte_carlo

        return discover_monte_carlo(mdp, policy, rng, self.settings)


#: The detector of each of :data:`~adpart.subgoals.settings.REWARD_BASES` (none: no detector).
_BASES = {"count-exhaustive": CountExhaustive, "count-mc": CountMonteCarlo, "none": None}


class RewardVariation:
    """A base detector's subgoals plus the states with above-minimum reward (4.3.1).

    Its parameters are :class:`~adpart.subgoals.settings.RewardVariationSettings`' fields; the
    base detector runs with its defaults.
    """

    name = "reward-variation"
    description = "base detector's subgoals plus states with reward above the minimum (4.3.1)"
    params = settings_params(RewardVariationSettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(RewardVariationSettings, values)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray, rng: np.random.Generator) -> SubgoalResult:
        import numpy as np

        from adpart.subgoals.policy import check_mdp, check_policy
        from adpart.subgoals.result import SubgoalResult
        from adpart.subgoals.reward import with_reward_variation

        t0 = time.perf_counter()
        factory = _BASES[self.settings.base]
        if factory is None:
            mdp = check_mdp(mdp)
            check_policy(mdp, policy)
            base = SubgoalResult(np.zeros(0, np.int64), np.zeros(mdp.n_states), None)
        else:
            base = factory().detect(mdp, policy, rng)
        out = with_reward_variation(base, mdp, self.settings)
        stats = dict(out.stats, time_s=time.perf_counter() - t0, base_detector=self.settings.base)
        params = {**settings_dict(self.settings), "base_params": dict(base.params)}
        return SubgoalResult(out.subgoals, out.scores, out.threshold, stats, params, self.name)


class Betweenness:
    """Betweenness centrality of the policy-independent transition graph (Simsek & Barto 2008).

    Subgoals are the local maxima of betweenness (``select="local-maxima"``, the paper's rule:
    more central than every neighbour) or the ``top`` most central states (``select="top"``).
    Its parameters are :class:`~adpart.subgoals.settings.BetweennessSettings`' fields.
    """

    name = "betweenness"
    description = "local maxima (or top-k) of transition-graph betweenness (Simsek & Barto 2008)"
    params = settings_params(BetweennessSettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(BetweennessSettings, values)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray | None, rng: np.random.Generator) -> (
        SubgoalResult
    ):
        import numpy as np

        from adpart.subgoals.literature import (
            betweenness,
            local_maxima,
            top_states,
            transition_graph,
        )
        from adpart.subgoals.policy import check_mdp
        from adpart.subgoals.result import SubgoalResult

        t0 = time.perf_counter()
        s = self.settings
        mdp = check_mdp(mdp)
        S = mdp.n_states
        src = None
        if 0 < s.sources < S:
            src = np.sort(rng.choice(S, size=s.sources, replace=False))
        graph = transition_graph(mdp)
        scores = betweenness(graph, sources=src)
        subgoals = (local_maxima(graph, scores) if s.select == "local-maxima"
                    else top_states(scores, s.top))
        stats = {"time_s": time.perf_counter() - t0, "sources": S if src is None else src.size}
        return SubgoalResult(subgoals, scores, None, stats, settings_dict(s), self.name)


class VisitFrequency:
    """States visited by many successful random walks (Digney 1996, McGovern & Barto 2001).

    Its parameters are :class:`~adpart.subgoals.settings.VisitFrequencySettings`' fields.
    """

    name = "visit-frequency"
    description = "top-k states on successful random walks (Digney 1996; McGovern & Barto 2001)"
    params = settings_params(VisitFrequencySettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(VisitFrequencySettings, values)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray | None, rng: np.random.Generator) -> (
        SubgoalResult
    ):
        from adpart.subgoals.literature import top_states, visit_frequency
        from adpart.subgoals.result import SubgoalResult

        t0 = time.perf_counter()
        s = self.settings
        scores, ok = visit_frequency(mdp, rng, s)
        stats = {"time_s": time.perf_counter() - t0, "successful_walks": ok, "walks": s.walks}
        return SubgoalResult(top_states(scores, s.top), scores, None, stats, settings_dict(s),
                             self.name)


def _spectral_result(options: Sequence[Eigenoption | CoveringOption], stats: dict[str, object],
                     S: int, t0: float, key: str, params: dict[str, object],
                     name: str) -> SubgoalResult:
    """The union of the options' subgoals; a state's score is how many options end there."""
    import numpy as np

    from adpart.subgoals.result import SubgoalResult

    ends = [o.subgoals for o in options]
    flat = np.concatenate(ends) if ends else np.zeros(0, np.int64)
    scores = np.bincount(flat, minlength=S).astype(np.float64)
    stats = {**stats, "time_s": time.perf_counter() - t0, key: [o.to_json() for o in options]}
    return SubgoalResult(np.unique(flat), scores, None, stats, params, name)


class Eigenoptions:
    """Eigenoptions of the transition graph's Laplacian (Machado, Bellemare & Bowling 2017).

    For each of the first ``k`` non-constant eigenvectors ``e`` (normalised Laplacian of the
    symmetrised graph of the reachable states) and each sign, the eigenpurpose ``e(s') - e(s)``
    is solved by value iteration with a terminate action; the subgoals are the option's sink of
    largest ``e`` (``sinks="extreme"``: the argmax) or all its sinks (``sinks="all"``). A
    state's score is the number of eigenoptions with it as a subgoal. Policy-independent. Its
    parameters are :class:`~adpart.subgoals.settings.EigenoptionSettings`' fields.
    """

    name = "eigenoptions"
    description = "sinks of the Laplacian's eigenoptions (Machado, Bellemare & Bowling 2017)"
    params = settings_params(EigenoptionSettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(EigenoptionSettings, values)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray | None, rng: np.random.Generator) -> (
        SubgoalResult
    ):
        from adpart.subgoals.policy import check_mdp
        from adpart.subgoals.spectral import eigenoptions

        t0 = time.perf_counter()
        mdp = check_mdp(mdp)
        options, stats = eigenoptions(mdp, self.settings)
        return _spectral_result(options, stats, mdp.n_states, t0, "eigenoptions",
                                settings_dict(self.settings), self.name)


class Covering:
    """Covering options: Fiedler-vector extremes, one edge per round (Jinnai et al. 2019).

    Each round takes the argmin and argmax of the Fiedler vector of the combinatorial Laplacian
    of the symmetrised graph of the reachable states, joins them by an edge and repeats
    ``rounds`` times; the subgoals are the ends. A state's score is the number of options ending
    there. Policy-independent. Its parameters are
    :class:`~adpart.subgoals.settings.CoveringSettings`' fields.
    """

    name = "covering"
    description = "Fiedler-vector ends of covering options (Jinnai, Park, Abel & Konidaris 2019)"
    params = settings_params(CoveringSettings)

    def __init__(self, **values: object) -> None:
        self.settings = build_settings(CoveringSettings, values)

    def detect(self, mdp: FiniteMDP, policy: np.ndarray | None, rng: np.random.Generator) -> (
        SubgoalResult
    ):
        from adpart.subgoals.policy import check_mdp
        from adpart.subgoals.spectral import covering_options

        t0 = time.perf_counter()
        mdp = check_mdp(mdp)
        options, stats = covering_options(mdp, self.settings)
        return _spectral_result(options, stats, mdp.n_states, t0, "options",
                                settings_dict(self.settings), self.name)


DETECTORS = (CountExhaustive, CountMonteCarlo, RewardVariation, Betweenness, VisitFrequency,
             Eigenoptions, Covering)


@hookimpl
def register_subgoal_detectors(register: Registrar) -> None:
    for cls in DETECTORS:
        register(cls)
