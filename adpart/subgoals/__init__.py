"""Subgoal discovery (dissertation section 4.1, 4.3.1): count metric, sampling, thresholds.

Library functions, usable without the plugin layer:

* :func:`count_metric` - exhaustive count metric of eq. 4.1 by sparse mat-vecs;
* :func:`sample_trajectories`, :func:`arrival_counts`, :func:`bernstein_samples` - Monte Carlo;
* :func:`gradient_ratios`, :func:`t_test_threshold` - ratios along paths, eq. 4.2;
* :func:`discover_exhaustive`, :func:`discover_monte_carlo` - the two pipelines;
* :func:`reward_variation_states`, :func:`with_reward_variation` - section 4.3.1;
* :func:`betweenness`, :func:`visit_frequency` - the literature's detectors;
* :func:`eigenoptions`, :func:`covering_options` - spectral option discovery reduced to subgoals
  (Machado et al. 2017; Jinnai et al. 2019), with :func:`spectral_components`,
  :func:`laplacian_eigenpairs` and :func:`fiedler_vector` (:mod:`adpart.subgoals.spectral`);
* :class:`CountSettings`, :class:`MonteCarloSettings`, :class:`RewardVariationSettings`,
  :class:`BetweennessSettings`, :class:`VisitFrequencySettings`, :class:`EigenoptionSettings`,
  :class:`CoveringSettings` - each detector's settings, the one declaration of their defaults
  and checks (:mod:`adpart.subgoals.settings`).

See ``docs/subgoals.md`` for the interpretations chosen.
"""

from typing import TYPE_CHECKING

from adpart.lazy import lazy_exports

if TYPE_CHECKING:
    from adpart.subgoals.count import CountMetric, count_metric
    from adpart.subgoals.discover import discover_exhaustive, discover_monte_carlo
    from adpart.subgoals.literature import (
        betweenness,
        local_maxima,
        transition_graph,
        visit_frequency,
    )
    from adpart.subgoals.montecarlo import (
        Trajectories,
        arrival_counts,
        bernstein_epsilon,
        bernstein_samples,
        sample_arrivals,
        sample_trajectories,
    )
    from adpart.subgoals.policy import check_policy, policy_matrix, trapped_states, walker_matrix
    from adpart.subgoals.ratios import (
        RatioSamples,
        gradient_ratios,
        samples_per_state,
        t_test_threshold,
    )
    from adpart.subgoals.result import SubgoalResult
    from adpart.subgoals.reward import reward_variation_states, with_reward_variation
    from adpart.subgoals.settings import (
        BetweennessSettings,
        CountSettings,
        CoveringSettings,
        EigenoptionSettings,
        MonteCarloSettings,
        RewardVariationSettings,
        VisitFrequencySettings,
    )
    from adpart.subgoals.spectral import (
        covering_options,
        eigenoptions,
        fiedler_vector,
        laplacian_eigenpairs,
        spectral_components,
    )

lazy_exports(__name__, {
    "adpart.subgoals.count": ("CountMetric", "count_metric"),
    "adpart.subgoals.discover": ("discover_exhaustive", "discover_monte_carlo"),
    "adpart.subgoals.literature": (
        "betweenness", "local_maxima", "transition_graph", "visit_frequency",
    ),
    "adpart.subgoals.montecarlo": (
        "Trajectories", "arrival_counts", "bernstein_epsilon", "bernstein_samples",
        "sample_arrivals", "sample_trajectories",
    ),
    "adpart.subgoals.policy": ("check_policy", "policy_matrix", "trapped_states", "walker_matrix"),
    "adpart.subgoals.ratios": (
        "RatioSamples", "gradient_ratios", "samples_per_state", "t_test_threshold",
    ),
    "adpart.subgoals.result": ("SubgoalResult",),
    "adpart.subgoals.reward": ("reward_variation_states", "with_reward_variation"),
    "adpart.subgoals.settings": (
        "BetweennessSettings", "CountSettings", "CoveringSettings", "EigenoptionSettings",
        "MonteCarloSettings", "RewardVariationSettings", "VisitFrequencySettings",
    ),
    "adpart.subgoals.spectral": (
        "covering_options", "eigenoptions", "fiedler_vector", "laplacian_eigenpairs",
        "spectral_components",
    ),
})

__all__ = [
    "BetweennessSettings", "CountMetric", "CountSettings", "CoveringSettings",
    "EigenoptionSettings", "MonteCarloSettings", "RatioSamples",
    "RewardVariationSettings", "SubgoalResult", "Trajectories", "VisitFrequencySettings",
    "arrival_counts",
    "bernstein_epsilon", "bernstein_samples", "betweenness", "check_policy", "count_metric",
    "covering_options", "discover_exhaustive", "discover_monte_carlo", "eigenoptions",
    "fiedler_vector", "gradient_ratios", "laplacian_eigenpairs", "local_maxima",
    "policy_matrix", "reward_variation_states", "sample_arrivals", "sample_trajectories",
    "samples_per_state", "spectral_components", "t_test_threshold", "transition_graph",
    "trapped_states", "visit_frequency", "walker_matrix", "with_reward_variation",
]
