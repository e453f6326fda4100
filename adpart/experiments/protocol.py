"""One evaluation protocol for every learner of chapter 6 (docs/maxq.md, "Evaluation protocol").

Every learner is scored twice on the same greedy-policy value curve (exact policy evaluation on
the true model, or for MAXQ-Q on Parr's maze the mean of hierarchical greedy rollouts):

* against ``V*`` of the flat task - the gap a user cares about;
* against **its own ceiling**, the best value its representation can attain, so that a learner
  whose ceiling lies below ``V* - tol`` is reported as *unable* to reach the tolerance, with the
  ceiling, instead of as slow. The ceilings: flat Q and SMDP Q over options *plus* the
  primitives - ``V*``; MAXQ-Q - the recursively optimal value of its task graph
  (:func:`adpart.learning.maxq.recursively_optimal`; executed as scored: polled on Taxi,
  with the call stack on Parr's maze); a decision layer - the executed value of its point
  model's optimal policy (:func:`layer_ceiling`), on the layer each run ends with.

Per run we report primitive steps and episodes until the gap *stays* within the tolerance
(``inf`` = censored) against both references, and the area under the gap curve over episodes
(:func:`adpart.experiments.stats.gap_auc`, normalised to a time-averaged gap; undefined values
count as the cap). Medians or means carry percentile-bootstrap CIs. Step sizes are stated per
learner in the summary; all use ``alpha = 1/n^0.6`` with ``n`` the update count of the entry
being updated (flat: the (state, action) pair; MAXQ-Q: the C or V table entry, abstract
where abstraction merges states; SMDP Q and the layer: the (state or block, option) pair,
counted per decision).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from adpart.experiments.stats import bootstrap_ci, episodes_to_threshold, gap_auc


def absorb_unreachable(mdp: Any) -> Any:
    """The same task with the states no episode can enter made absorbing (terminal).

    With ``gamma = 1`` a greedy policy is scored by one linear solve over *all* states, which is
    singular - a NaN score - as soon as the policy loops in any state, even one that no start
    reaches under any policy. On fickle Taxi 100 of the 516 states are such configurations (the
    passenger at its destination outside the taxi); a flat Q-learner never visits them, so its
    greedy policy loops there forever and never scores. Absorbing them changes no value of a
    reachable state (they are never entered) and makes the score the value over ``mu``.
    """
    from adpart.learning.maxq.exact import reachable_states

    reach = reachable_states(mdp)
    if not (~reach & ~mdp.terminal).any():
        return mdp
    return mdp.with_rewards(mdp.R, terminal=mdp.terminal | ~reach)


def layer_ceiling(partition: Any, smdp: Any, mu: np.ndarray) -> float:
    """``sum_s mu(s) V^pi(s)`` of the decision layer's point-model optimal policy, executed on
    the true options (section 4.3.3): solve the point model, give every state its block's
    option, evaluate exactly. The best a learner on this layer can settle at."""
    from adpart.mdp.evaluation import policy_evaluation
    from adpart.partition import point_policy

    return float(mu @ policy_evaluation(smdp, point_policy(partition, smdp)))


def steps_to(gaps: np.ndarray, steps: np.ndarray, ev: np.ndarray, tol: float
             ) -> tuple[np.ndarray, np.ndarray]:
    """``(primitive steps, episodes)`` per run until ``gaps`` stays ``<= tol``; ``inf`` never."""
    episodes = episodes_to_threshold(gaps, ev, tol)
    cum = np.cumsum(steps, axis=1)
    idx = np.where(np.isfinite(episodes), episodes, 1).astype(np.int64) - 1
    at = cum[np.arange(cum.shape[0]), idx].astype(np.float64)
    return np.where(np.isfinite(episodes), at, np.inf), episodes


def score(label: str, gaps: np.ndarray, steps: np.ndarray, ev: np.ndarray, *, tol: float,
          ceiling_gap: np.ndarray | float, cap: float, ceiling_name: str, step_size: str,
          seed: int = 0) -> dict[str, Any]:
    """One learner's row under the protocol.

    Args:
        gaps: ``(K, N)`` gaps to ``V*`` (NaN where not evaluated or undefined).
        steps: ``(K, N)`` primitive steps per episode.
        ev: 1-based evaluated episodes.
        tol: the tolerance (both references).
        ceiling_gap: ``V*(mu) - ceiling(mu)``, scalar or per run (>= 0 up to solver error).
        cap: the gap an undefined value counts as in the area.
        ceiling_name: what the ceiling is, for the summary.
        step_size: the step-size rule, stated.
    """
    K = gaps.shape[0]
    cg = np.broadcast_to(np.asarray(ceiling_gap, dtype=np.float64), (K,))
    own = gaps - cg[:, None]
    star_steps, star_eps = steps_to(gaps, steps, ev, tol)
    own_steps, own_eps = steps_to(own, steps, ev, tol)
    auc = gap_auc(gaps[:, ev - 1], ev, cap)
    row: dict[str, Any] = {"learner": label, "runs": K, "tolerance": tol,
                           "ceiling": ceiling_name, "step_size": step_size,
                           "ceiling_gap_median": float(np.median(cg)),
                           "ceiling_gap_max": float(cg.max()),
                           "can_reach_v_star": bool(np.median(cg) <= tol)}
    for name, st, ep in (("v_star", star_steps, star_eps), ("own", own_steps, own_eps)):
        m, lo, hi = bootstrap_ci(st, seed=seed)
        me, loe, hie = bootstrap_ci(ep, seed=seed)
        row[name] = {"reached": int(np.isfinite(st).sum()), "steps_median": m,
                     "steps_ci": [lo, hi], "episodes_median": me, "episodes_ci": [loe, hie],
                     "steps": st.tolist(), "episodes": ep.tolist()}
    a, alo, ahi = bootstrap_ci(auc, statistic="mean", seed=seed)
    row["auc"] = {"mean": a, "ci": [alo, ahi], "per_run": auc.tolist(), "cap": cap,
                  "episodes": int(ev[-1])}
    final = gaps[:, ev[-1] - 1]
    row["final_gap_median"] = float(np.nanmedian(final)) if np.isfinite(final).any() \
        else float("nan")
    row["final_gap_undefined"] = int(np.isnan(final).sum())
    row["total_steps_mean"] = float(steps.sum(axis=1).mean())
    return row


def _f(v: float) -> str:
    return "never" if not np.isfinite(v) else f"{v:,.0f}"


def sentence(row: dict[str, Any]) -> str:
    """The row in words: both references, the ceiling, the area, the step size."""
    out = [(f"{row['learner']} (step size {row['step_size']}; ceiling: {row['ceiling']}, "
           f"{row['ceiling_gap_median']:.3g} below V*)")]
    for name, ref in (("v_star", "V*"), ("own", "own ceiling")):
        r = row[name]
        lo, hi = r["steps_ci"]
        out.append(f"to within {row['tolerance']:g} of {ref}: {r['reached']}/{row['runs']} runs,"
                   f" median {_f(r['steps_median'])} primitive steps [95% CI {_f(lo)}, "
                   f"{_f(hi)}], {_f(r['episodes_median'])} episodes")
    if not row["can_reach_v_star"]:
        out.append(f"CANNOT reach the tolerance against V*: its ceiling is "
                   f"{row['ceiling_gap_median']:.3g} below V* (> {row['tolerance']:g})")
    au = row["auc"]
    out.append(f"mean gap over episodes 1-{au['episodes']} (area under the gap curve, "
               f"undefined = {au['cap']:g}): {au['mean']:.3g} [95% CI {au['ci'][0]:.3g}, "
               f"{au['ci'][1]:.3g}]; final gap median {row['final_gap_median']:.3g} "
               f"({row['final_gap_undefined']} undefined)")
    return "; ".join(out)


def options_only_optimum(smdp: Any, n_primitives: int, mu: np.ndarray) -> float:
    """``sum_s mu(s) V*_O(s)``: the optimum over the stacked model's *options* alone (columns
    from ``n_primitives`` on) on the flat states - the best any layer over them could do
    without adding primitives. Set beside :func:`layer_ceiling` it says whether a layer loses
    value through its options or through its partition."""
    from adpart.mdp.model import SMDPModel
    from adpart.mdp.solvers import solve

    adm = np.asarray(smdp.admissible, dtype=bool).copy()
    adm[:, :n_primitives] = False
    live = adm.any(axis=1)
    adm[~live, 0] = True  # states no option starts from (terminal ones): any column, value 0
    model = SMDPModel(R=np.where(adm, smdp.R, 0.0), F=smdp.F, admissible=adm)
    return float(mu @ solve(model, 1e-10).V)


def option_chain_reach(smdp: Any, n_primitives: int, mu: np.ndarray,
                       terminal: np.ndarray) -> tuple[int, bool]:
    """Chaining options alone from the start states: ``(states reached, goal reached)``.

    A state is reached when some option admissible in a reached state can end there
    (``F_o(s, s') > 0``); the goal is reached when a terminal state is. A layer whose options
    cannot chain to the goal has a ceiling of never arriving, whatever its partition.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order

    S = smdp.admissible.shape[0]
    adj = sp.csr_array((S, S))
    for o in range(n_primitives, smdp.admissible.shape[1]):
        Fo = sp.csr_array(smdp.F[o * S:(o + 1) * S])
        adj = adj + sp.diags_array(smdp.admissible[:, o].astype(np.float64)) @ Fo
    adj = sp.csr_array(adj > 0, dtype=np.float64)
    seen = np.zeros(S, dtype=bool)
    for s0 in np.flatnonzero(mu > 0):
        if not seen[s0]:
            seen[breadth_first_order(adj, int(s0), return_predecessors=False)] = True
    return int(seen.sum()), bool((seen & np.asarray(terminal, dtype=bool)).any())
