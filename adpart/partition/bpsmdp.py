"""The bounded-parameter SMDP of a partition, interval value iteration, a point model, theorem 4.5.

**BPSMDP** (sections 3.2.1-3.2.2, 4.2.1.1): for every block ``b`` and option ``o`` offered in it,
the reward interval ``[min_{s in b} R(s,o), max_{s in b} R(s,o)]`` and, for every target block
``c``, the mass interval ``[min_{s in b} F(c|s,o), max_{s in b} F(c|s,o)]``. Because ``F`` is a
*discounted* multi-time model (eq. 3.2) its rows do not sum to one; the feasible rows of the
interval model are therefore ``{f : lo <= f <= hi, m_lo <= sum_c f_c <= m_hi}`` with
``[m_lo, m_hi]`` the range of the members' total discounted masses. Every member's own row,
aggregated to blocks, is feasible - so the model "contains" the true SMDP.

**Interval value iteration** (Givan, Leach & Dean 2000): the pessimistic values
``V_lo(b) = max_o [R_lo(b,o) + min_f sum_c f_c V_lo(c)]`` and the optimistic
``V_hi(b) = max_o [R_hi(b,o) + max_f sum_c f_c V_hi(c)]``. The inner extreme is found exactly by the
order-statistics rule: start from ``lo``, then add mass greedily to the targets with the smallest
(largest) values, as far as the caps ``hi - lo`` allow, until the minimum total ``m_lo`` is reached,
and beyond it (up to ``m_hi``) only while the value added is favourable (negative for the minimum,
positive for the maximum). By induction ``V_lo(block(s)) <= V*(s) <= V_hi(block(s))``.

**Point model** for learning: an :class:`SMDPModel` over blocks whose ``R(b,o)`` and
``F(c|b,o)`` are weighted averages over the block's members - uniform weights by default, or any
non-negative state weights such as the occupancy of a policy (normalised within each block).

**Theorem 4.5** (Kim & Dean, as printed in section 4.3.3):
``||V* - V*_P||_inf <= 2 (1 + gamma / (1 - gamma) * max(epsilon, delta))``. For an SMDP we take
``gamma`` to be the model's contraction modulus (the largest discounted row mass). The bound mixes
a reward scale (epsilon) with a probability (delta), so it is reported next to the measured gap
(:func:`value_gap`), not trusted blindly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from adpart.errors import ModelError
from adpart.mdp.model import SMDPModel
from adpart.mdp.solvers import solve
from adpart.partition._validate import (
    as_model,
    check_partition_fits,
    check_rewards,
    select_options,
)
from adpart.partition.partition import Partition


def _block_indicator(labels: np.ndarray, n_blocks: int) -> sp.csr_array:
    S = labels.size
    return sp.csr_array(
        (np.ones(S), labels.astype(np.int64), np.arange(S + 1, dtype=np.int64)), shape=(S, n_blocks)
    )


def _offered(partition: Partition, model: SMDPModel, options: Sequence[int] | None) -> np.ndarray:
    """The options used: given ones, else those offered in some block; every block needs one."""
    if partition.n_options != model.n_actions:
        raise ModelError(
            f"partition offers {partition.n_options} options but the model has {model.n_actions}"
        )
    sel = select_options(model, options) if options is not None else np.flatnonzero(
        partition.admissible.any(axis=0))
    adm = np.zeros_like(partition.admissible)
    adm[:, sel] = partition.admissible[:, sel]
    empty = np.flatnonzero(~adm.any(axis=1))
    if sel.size == 0 or empty.size:
        first = int(empty[0]) if empty.size else 0
        raise ModelError(
            f"block {first} offers no option of the set {sel.tolist()}; every block needs an "
            "admissible option (refine with an option set that covers every state)"
        )
    bad = adm[partition.labels] & ~model.admissible
    if bad.any():
        s, o = np.argwhere(bad)[0]
        raise ModelError(
            f"option {int(o)} is offered in block {int(partition.labels[s])} but not admissible in "
            f"its state {int(s)}; build the partition from this model's initiation sets"
        )
    return sel


@dataclass(frozen=True)
class IntervalValues:
    """Pessimistic and optimistic optimal block values of a BPSMDP, and the sweeps taken."""

    lower: np.ndarray
    upper: np.ndarray
    sweeps: int


@dataclass(frozen=True, eq=False)
class BPSMDP:
    """Interval rewards and block-to-block masses of a partition (a bounded-parameter SMDP).

    Attributes:
        admissible: ``(B, O)`` options offered per block (the selected ones).
        R_lo, R_hi: ``(B, O)`` reward bounds (0 where not offered).
        mass_lo, mass_hi: ``(B, O)`` bounds of the members' total discounted mass.
        pair_block, pair_option: the offered ``(block, option)`` pairs, ``(P,)`` each.
        entry_pair, entry_target, F_lo, F_hi: per pair and target block with some mass, the
            interval ``[F_lo, F_hi]`` of ``F(target | s, option)`` over the block's members.
        modulus: the largest ``mass_hi`` (the contraction modulus of interval value iteration).
    """

    admissible: np.ndarray
    R_lo: np.ndarray
    R_hi: np.ndarray
    mass_lo: np.ndarray
    mass_hi: np.ndarray
    pair_block: np.ndarray
    pair_option: np.ndarray
    entry_pair: np.ndarray
    entry_target: np.ndarray
    F_lo: np.ndarray
    F_hi: np.ndarray

    @property
    def n_blocks(self) -> int:
        return self.admissible.shape[0]

    @property
    def modulus(self) -> float:
        return float(self.mass_hi.max()) if self.mass_hi.size else 0.0

    @classmethod
    def from_partition(
        cls,
        partition: Partition,
        model: SMDPModel | object,
        *,
        options: Sequence[int] | None = None,
        rewards: np.ndarray | None = None,
    ) -> BPSMDP:
        """Interval bounds over each block's members (sections 3.2.2 and 4.2.1.1)."""
        smdp = as_model(model)
        S, n_opt = smdp.n_states, smdp.n_actions
        check_partition_fits(partition.labels, S)
        sel = _offered(partition, smdp, options)
        R = check_rewards(smdp.R if rewards is None else rewards, smdp)
        labels, B = partition.labels, partition.n_blocks
        adm = np.zeros((B, n_opt), dtype=bool)
        adm[:, sel] = partition.admissible[:, sel]
        sizes = partition.sizes
        onehot = _block_indicator(labels, B)
        R_lo, R_hi = np.zeros((B, n_opt)), np.zeros((B, n_opt))
        m_lo, m_hi = np.zeros((B, n_opt)), np.zeros((B, n_opt))
        pair_id = np.full((B, n_opt), -1, dtype=np.int64)
        pb, po = np.nonzero(adm)
        pair_id[pb, po] = np.arange(pb.size)
        e_pair, e_target, e_lo, e_hi = [], [], [], []
        order = np.argsort(labels, kind="stable")
        starts = np.r_[0, np.cumsum(sizes)[:-1]]
        for o in sel:  # a loop over options; each is vectorised over states and blocks
            offered = adm[:, o]
            r = R[order, o]
            R_lo[:, o] = np.where(offered, np.minimum.reduceat(r, starts), 0.0)
            R_hi[:, o] = np.where(offered, np.maximum.reduceat(r, starts), 0.0)
            Fo = sp.csr_array(smdp.F[o * S:(o + 1) * S])
            tot = np.asarray(Fo.sum(axis=1)).ravel()[order]
            m_lo[:, o] = np.where(offered, np.minimum.reduceat(tot, starts), 0.0)
            m_hi[:, o] = np.where(offered, np.maximum.reduceat(tot, starts), 0.0)
            M = sp.coo_array(Fo @ onehot)
            M.sum_duplicates()
            keep = (M.data > 0) & offered[labels[M.row]]
            src, tgt, mass = labels[M.row[keep]], M.col[keep].astype(np.int64), M.data[keep]
            key = src * B + tgt
            srt = np.argsort(key, kind="stable")
            key, mass = key[srt], mass[srt]
            if key.size == 0:
                continue
            st = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
            ukey = key[st]
            hi = np.maximum.reduceat(mass, st)
            lo = np.minimum.reduceat(mass, st)
            cnt = np.diff(np.r_[st, key.size])
            lo = np.where(cnt < sizes[ukey // B], 0.0, lo)
            e_pair.append(pair_id[ukey // B, o])
            e_target.append(ukey % B)
            e_lo.append(lo)
            e_hi.append(hi)

        def cat(parts: list[np.ndarray], dtype: type) -> np.ndarray:
            return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype=dtype)

        return cls(adm, R_lo, R_hi, m_lo, m_hi, pb.astype(np.int64), po.astype(np.int64),
                   cat(e_pair, np.int64), cat(e_target, np.int64), cat(e_lo, np.float64),
                   cat(e_hi, np.float64))

    def _extreme(self, V: np.ndarray, sign: float) -> np.ndarray:
        """Per pair, ``min_f sum_c f_c * sign * V(c)`` over the feasible rows (times ``sign``).

        ``sign = +1`` gives the pessimistic (minimal) expectation, ``-1`` the optimistic one.
        """
        n_pairs = self.pair_block.size
        pb, po = self.pair_block, self.pair_option
        W = sign * V[self.entry_target]
        order = np.lexsort((W, self.entry_pair))
        pair, w = self.entry_pair[order], W[order]
        lo, cap = self.F_lo[order], (self.F_hi - self.F_lo)[order]
        base = np.bincount(self.entry_pair, weights=self.F_lo, minlength=n_pairs)
        e_min = np.maximum(self.mass_lo[pb, po] - base, 0.0)
        e_max = np.maximum(self.mass_hi[pb, po] - base, e_min)
        favourable = w < 0
        alloc = np.zeros(w.size)
        for part, limit in ((favourable, e_max), (~favourable, None)):
            idx = np.flatnonzero(part)
            if idx.size == 0:
                continue
            p = pair[idx]
            c = cap[idx]
            cum = np.cumsum(c)
            first = np.r_[True, p[1:] != p[:-1]]
            seg_base = np.maximum.accumulate(np.where(first, cum - c, 0.0))
            within = cum - seg_base
            if limit is None:
                fav_total = np.bincount(pair[favourable], weights=alloc[favourable],
                                        minlength=n_pairs)
                lim = np.maximum(e_min - fav_total, 0.0)[p]
            else:
                lim = limit[p]
            got = np.minimum(within, lim)
            alloc[idx] = got - np.minimum(within - c, lim)
        value = np.bincount(pair, weights=(lo + alloc) * w, minlength=n_pairs)
        return sign * value

    def interval_values(self, tol: float = 1e-8, max_sweeps: int = 100_000) -> IntervalValues:
        """Pessimistic and optimistic optimal values by interval value iteration."""
        kappa = self.modulus
        if kappa >= 1.0:
            raise ModelError(
                f"interval value iteration needs discounted masses < 1; the largest is {kappa}"
            )
        stop = tol * (1 - kappa) / (2 * max(kappa, 1e-12))
        out = []
        sweeps_total = 0
        for sign, R in ((1.0, self.R_lo), (-1.0, self.R_hi)):
            V = np.zeros(self.n_blocks)
            for sweep in range(1, max_sweeps + 1):  # noqa: B007 (read after the loop)
                q = R[self.pair_block, self.pair_option] + self._extreme(V, sign)
                V_new = np.full(self.n_blocks, -np.inf)
                np.maximum.at(V_new, self.pair_block, q)
                diff = float(np.max(np.abs(V_new - V)))
                V = V_new
                if diff < stop:
                    break
            sweeps_total += sweep
            out.append(V)
        return IntervalValues(out[0], out[1], sweeps_total)


def point_model(
    partition: Partition,
    model: SMDPModel | object,
    *,
    options: Sequence[int] | None = None,
    weights: np.ndarray | None = None,
    rewards: np.ndarray | None = None,
) -> SMDPModel:
    """An :class:`SMDPModel` over blocks for learning: member averages of ``R`` and ``F``.

    ``weights`` (``(S,)``, non-negative, e.g. a policy's state occupancy) are normalised within
    each block; blocks whose weights sum to 0 fall back to uniform. Default: uniform.
    """
    smdp = as_model(model)
    S = smdp.n_states
    check_partition_fits(partition.labels, S)
    sel = _offered(partition, smdp, options)
    R = check_rewards(smdp.R if rewards is None else rewards, smdp)
    labels, B = partition.labels, partition.n_blocks
    w = np.ones(S) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (S,) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ModelError(f"weights must be {S} finite non-negative numbers; got shape {w.shape}")
    total = np.bincount(labels, weights=w, minlength=B)
    w = np.where(total[labels] > 0, w, 1.0)
    total = np.bincount(labels, weights=w, minlength=B)
    W = sp.csr_array((w / total[labels], (labels, np.arange(S))), shape=(B, S))
    adm = np.zeros((B, smdp.n_actions), dtype=bool)
    adm[:, sel] = partition.admissible[:, sel]
    onehot = _block_indicator(labels, B)
    blocks = []
    for o in range(smdp.n_actions):
        Fo = sp.csr_array(W @ (sp.csr_array(smdp.F[o * S:(o + 1) * S]) @ onehot))
        blocks.append(sp.csr_array(sp.diags_array(adm[:, o].astype(np.float64)) @ Fo))
    F = sp.csr_array(sp.vstack(blocks, format="csr"))
    F.eliminate_zeros()
    R_P = np.where(adm, W @ R, 0.0)
    return SMDPModel(R=R_P, F=F, admissible=adm)


def point_policy(partition: Partition, model: SMDPModel | object, tol: float = 1e-10
                 ) -> np.ndarray:
    """``(S,)`` the optimal block policy of :func:`point_model` lifted to states: every state
    takes its block's column (section 4.2.2), the policy a learner on the layer can settle at."""
    return solve(point_model(partition, model), tol).policy[partition.labels]


def theorem_4_5_bound(gamma: float, epsilon: float, delta: float) -> float:
    """Theorem 4.5 as printed: ``2 (1 + gamma / (1 - gamma) * max(epsilon, delta))``."""
    if not 0.0 <= gamma < 1.0:
        raise ModelError(f"theorem 4.5 needs a discount in [0, 1); got {gamma}")
    return 2.0 * (1.0 + gamma / (1.0 - gamma) * max(epsilon, delta))


def value_gap(
    partition: Partition,
    model: SMDPModel | object,
    *,
    epsilon: float,
    delta: float,
    options: Sequence[int] | None = None,
    weights: np.ndarray | None = None,
    solver_epsilon: float = 1e-9,
    states: np.ndarray | None = None,
) -> dict[str, float]:
    """Measured ``||V* - V*_P||_inf`` (point model, values lifted to states) next to theorem 4.5.

    ``V*`` is the optimal value of the original SMDP restricted to the options used; also reported
    is whether ``V*`` lies inside the interval values of the BPSMDP (it must). ``states``
    (``(S,)`` bool) restricts the maximum and the fraction to those states, e.g. the decision
    layer's (reachable and terminal) states; the states outside are lumped without regard to
    stability (:mod:`adpart.partition.layer`).
    """
    smdp = as_model(model)
    sel = _offered(partition, smdp, options)
    adm = np.zeros_like(smdp.admissible)
    adm[:, sel] = smdp.admissible[:, sel]
    if not adm.any(axis=1).all():
        s = int(np.flatnonzero(~adm.any(axis=1))[0])
        raise ModelError(f"state {s} has no admissible option in the set {sel.tolist()}")
    flat = SMDPModel(R=np.where(adm, smdp.R, 0.0), F=smdp.F, admissible=adm)
    V = solve(flat, solver_epsilon).V
    VP = solve(point_model(partition, smdp, options=sel, weights=weights), solver_epsilon).V
    iv = BPSMDP.from_partition(partition, smdp, options=sel).interval_values()
    lifted = VP[partition.labels]
    slack = 1e-6 * max(1.0, float(np.max(np.abs(V))))
    inside = (iv.lower[partition.labels] <= V + slack) & (V <= iv.upper[partition.labels] + slack)
    keep = np.ones(smdp.n_states, dtype=bool) if states is None else np.asarray(states, bool)
    if keep.shape != (smdp.n_states,) or not keep.any():
        raise ModelError(f"states must be a non-empty boolean mask of shape ({smdp.n_states},)")
    width = (iv.upper - iv.lower)[partition.labels]
    return {
        "measured": float(np.max(np.abs(V - lifted)[keep])),
        "bound": theorem_4_5_bound(smdp.modulus, epsilon, delta),
        "gamma": smdp.modulus,
        "interval_width": float(np.max(width[keep])),
        "inside_interval": float(inside[keep].mean()),
    }
