"""Exhaustive vs Monte Carlo subgoal discovery (sections 4.1.1, 4.1.1.2; Figs. 5.7-5.8).

Workloads: ``three-floor-arm`` (3,600 states, task ``deliver``, optimal policy from
:func:`adpart.mdp.solvers.solve`); slippery open grids ``random_grid_mdp(n, slip=0.2)`` of 10^5
and 10^6 cells with one terminal goal in a corner, reward -1 per step, and the
shortest-path policy of :func:`goal_grid` (both detectors find no subgoals there: a speed with an
empty answer); and grids of rooms joined by doorways, ``rooms_grid_mdp(n, room, slip=0)`` of
10^4-10^6 cells, goal in the south-east corner, the shortest-path policy of
:func:`~benchmarks._models.distance_policy`, where the count metric finds subgoals in front of
the doorways (:func:`rooms`: the sets, their agreement and the exhaustive set's own agreement
across seeds are printed beside the speed; :func:`samples_needed`: Monte Carlo stopped at a
fixed number of trajectories, to show how many agreement takes). Each detector runs with
seed 0, once with its defaults and once with the opt-in every-path ratios and predicted-agreement
stop (:data:`CHOICES`); printed: wall time (best of ``repeats``), the number of subgoals of
each and their overlap, the ratio exhaustive / Monte Carlo, and the MC samples and stop rule.
First, :func:`agreement` for each choice: the Jaccard index of the two subgoal sets on two-rooms,
three-floor, three-floor-arm and urban for seeds 0-4 (and each MC seed against another exhaustive
seed), with the samples Monte Carlo's stopping rule took and both detectors' times. Policies come
from the default :func:`~adpart.mdp.solvers.solve`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import numpy as np

from adpart.envs.registry import get_domain
from adpart.mdp.generate import random_grid_mdp
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import solve
from adpart.params import build_settings
from adpart.subgoals.discover import discover_exhaustive, discover_monte_carlo
from adpart.subgoals.result import SubgoalResult
from adpart.subgoals.settings import CountSettings, MonteCarloSettings
from benchmarks._models import distance_policy, rooms_grid_mdp


def goal_grid(n: int) -> tuple[FiniteMDP, np.ndarray]:
    """Square grid, goal in cell 0 (top-left), and the shortest-path policy toward it.

    The policy moves west until the first column, then north (actions 3 and 0): every move
    shortens the Manhattan distance to the goal, which is optimal for the deterministic part of
    the dynamics. (Solving by value iteration costs 32 s at 10^5 cells with gamma 0.999 and
    would dominate the benchmark.)
    """
    base = random_grid_mdp(n, slip=0.2, gamma=0.999, seed=0)
    terminal = np.zeros(n, dtype=bool)
    terminal[0] = True
    mdp = base.with_rewards(np.full((n, base.n_actions), -1.0), terminal=terminal)
    policy = np.where(base.features["col"] > 0, 3, 0).astype(np.int64)
    return mdp, policy


def best(fn: Callable[[], SubgoalResult], repeats: int) -> tuple[float, SubgoalResult]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    assert out is not None
    return min(times), out


#: ``name -> (discover_exhaustive settings, discover_monte_carlo settings)``: the defaults (ratios
#: along sampled paths, the two-passes stop) and the opt-in every-path ratios with the
#: predicted-agreement stop (docs/subgoals.md).
CHOICES: dict[str, tuple[CountSettings, MonteCarloSettings]] = {
    "defaults": (CountSettings(), MonteCarloSettings()),
    "ratios=all, stop=predicted": (
        CountSettings(ratios="all"),
        build_settings(MonteCarloSettings, {"ratios": "all", "stop": "predicted"})),
}


def run(label: str, mdp: FiniteMDP, policy: np.ndarray, repeats: int,
        choice: str = "defaults") -> None:
    ex_set, mc_set = CHOICES[choice]
    discover_exhaustive(mdp, policy, np.random.default_rng(0), ex_set)  # compiled, caches warm
    te, ex = best(lambda: discover_exhaustive(mdp, policy, np.random.default_rng(0), ex_set),
                  repeats)
    tm, mc = best(lambda: discover_monte_carlo(mdp, policy, np.random.default_rng(0), mc_set),
                  repeats)
    both = np.intersect1d(ex.subgoals, mc.subgoals).size
    print(f"{label:<18} {mdp.n_states:>9,} {te:>8.3f} {tm:>8.3f} {te / tm:>7.1f}x "
          f"{ex.subgoals.size:>5} {mc.subgoals.size:>5} {both:>5} {mc.stats['samples']:>7} "
          f"{mc.stats['stop_reason']}")


AGREEMENT_DOMAINS = (("two-rooms", None), ("three-floor", None), ("three-floor-arm", "deliver"),
                     ("urban", None))


def agreement(seeds: tuple[int, ...] = (0, 1, 2, 3, 4), choice: str = "defaults",
              domains: tuple[tuple[str, str | None], ...] = AGREEMENT_DOMAINS) -> list[dict]:
    """Jaccard index of the exhaustive and Monte Carlo subgoal sets under ``choice``
    (:data:`CHOICES`; ``"defaults"``: MC's default stop).

    Per seed ``k``: ``J`` is MC seed ``k`` against exhaustive seed ``k``, ``J x`` MC seed ``k``
    against exhaustive seed ``k+1`` (a different seed per detector), ``exh~0`` exhaustive seed
    ``k`` against exhaustive seed 0 (1.00 when the exhaustive set does not depend on the seed).
    """
    ex_set, mc_set = CHOICES[choice]
    print(f"agreement with {choice} (Jaccard of the subgoal sets; both empty = 1)")
    print(f"{'domain':<16} {'states':>7} {'seed':>4} {'#exh':>5} {'#MC':>5} {'J':>5} {'J x':>5} "
          f"{'exh~0':>5} {'samples':>8} {'stop':<7} {'exh s':>7} {'MC s':>7}")
    rows = []
    for name, task in domains:
        mdp = get_domain(name).mdp(task)
        policy = solve(mdp).policy
        ex_runs = {k: best(lambda m=mdp, p=policy, k=k: discover_exhaustive(
            m, p, np.random.default_rng(k), ex_set), 3) for k in (*seeds, max(seeds) + 1)}
        for seed in seeds:
            te, ex = ex_runs[seed]
            tm, mc = best(lambda m=mdp, p=policy, k=seed: discover_monte_carlo(
                m, p, np.random.default_rng(k), mc_set), 3)
            jac = _jaccard(ex.subgoals, mc.subgoals)
            jac_x = _jaccard(ex_runs[seed + 1][1].subgoals, mc.subgoals)
            jac_ex = _jaccard(ex.subgoals, ex_runs[seeds[0]][1].subgoals)
            rows.append({"choice": choice, "domain": name, "seed": seed, "jaccard": jac,
                         "jaccard_cross": jac_x, "jaccard_exhaustive": jac_ex,
                         "samples": mc.stats["samples"], "time_exhaustive": te, "time_mc": tm,
                         "ratio_time": tm / te})
            print(f"{name:<16} {mdp.n_states:>7,} {seed:>4} {ex.subgoals.size:>5} "
                  f"{mc.subgoals.size:>5} {jac:>5.2f} {jac_x:>5.2f} {jac_ex:>5.2f} "
                  f"{mc.stats['samples']:>8} {mc.stats['stop_reason']:<7} {te:>7.3f} "
                  f"{tm:>7.3f}", flush=True)
    low = min(r["jaccard"] for r in rows)
    low_x = min(r["jaccard_cross"] for r in rows)
    print(f"lowest Jaccard against the exhaustive set of the same seed (J) {low:.2f}, of another "
          f"seed (J x) {low_x:.2f} (target >= 0.9)\n")
    return rows


def _jaccard(a: np.ndarray, b: np.ndarray) -> float:
    union = np.union1d(a, b).size
    return np.intersect1d(a, b).size / union if union else 1.0


ROOM_WORKLOADS = ((10**4, 20), (10**5, 30), (10**6, 100))


def _room_grids(workloads: tuple[tuple[int, int], ...]
                ) -> Iterator[tuple[FiniteMDP, np.ndarray, int, str]]:
    """``(mdp, shortest-path policy, room side, label)`` of each rooms grid (deterministic)."""
    for n, room in workloads:
        mdp = rooms_grid_mdp(n, room=room, slip=0.0)
        yield mdp, distance_policy(mdp), room, f"rooms {mdp.n_states:,} ({room})"


def rooms(workloads: tuple[tuple[int, int], ...] = ROOM_WORKLOADS,
          seeds: tuple[int, ...] = (0, 1, 2)) -> list[dict]:
    """Both detectors on the rooms grids with doorways (deterministic moves, the shortest-path
    policy), each choice and seed: times (warm, best of 2), subgoal counts, ``J`` (Monte Carlo
    against the exhaustive set of the same seed) and ``exh~0`` (the exhaustive set against
    seed 0's: how much the answer itself depends on the seed)."""
    print("rooms grids with doorways: exhaustive (eq. 4.1) vs Monte Carlo (def. 4.4)")
    print(f"{'workload':<22} {'choice':<26} {'seed':>4} {'exh s':>7} {'MC s':>7} {'MC/exh':>7} "
          f"{'#exh':>5} {'#MC':>5} {'J':>5} {'exh~0':>5} {'samples':>7} stop")
    rows = []
    for mdp, policy, room, label in _room_grids(workloads):
        for choice, (ex_set, mc_set) in CHOICES.items():
            discover_exhaustive(mdp, policy, np.random.default_rng(0), ex_set)  # warm
            first = None
            for seed in seeds:
                te, ex = best(lambda m=mdp, p=policy, c=ex_set, s=seed: discover_exhaustive(
                    m, p, np.random.default_rng(s), c), 2)
                tm, mc = best(lambda m=mdp, p=policy, c=mc_set, s=seed: discover_monte_carlo(
                    m, p, np.random.default_rng(s), c), 2)
                first = ex.subgoals if first is None else first
                row = {"n_states": mdp.n_states, "room": room, "choice": choice, "seed": seed,
                       "time_exhaustive": te, "time_mc": tm, "ratio_time": tm / te,
                       "n_exhaustive": int(ex.subgoals.size), "n_mc": int(mc.subgoals.size),
                       "jaccard": _jaccard(ex.subgoals, mc.subgoals),
                       "jaccard_exhaustive": _jaccard(ex.subgoals, first),
                       "samples": mc.stats["samples"], "stop": mc.stats["stop_reason"]}
                rows.append(row)
                print(f"{label:<22} {choice:<26} {seed:>4} {te:>7.3f} {tm:>7.3f} "
                      f"{tm / te:>7.3f} {row['n_exhaustive']:>5} {row['n_mc']:>5} "
                      f"{row['jaccard']:>5.2f} {row['jaccard_exhaustive']:>5.2f} "
                      f"{row['samples']:>7} {row['stop']}", flush=True)
    print()
    return rows


#: Monte Carlo sample counts of :func:`samples_needed`, up to about one path per start state.
SAMPLE_COUNTS = (1_000, 3_000, 10_000, 30_000, 100_000)


def samples_needed(workloads: tuple[tuple[int, int], ...] = ROOM_WORKLOADS[1:],
                   counts: tuple[int, ...] = SAMPLE_COUNTS) -> list[dict]:
    """How many trajectories Monte Carlo needs to agree with the exhaustive count.

    On the rooms grids, seed 0, each :data:`CHOICES` ratio rule: Monte Carlo stopped at exactly
    ``H`` samples (``stop = "max"``), its time over the exhaustive count's and ``J`` against the
    exhaustive set of the same seed. The count of eq. 4.1 sums over paths from every start
    state, and a subgoal is decided by differences of counts along a path (the gradient ratio),
    so ``J`` climbs to 0.9 only as ``H`` nears the number of start states.
    """
    print("Monte Carlo stopped at H samples against the exhaustive count, seed 0")
    print(f"{'workload':<22} {'ratios':<7} {'H':>8} {'exh s':>7} {'MC s':>8} {'MC/exh':>8} "
          f"{'#exh':>5} {'#MC':>5} {'J':>5}")
    rows = []
    for mdp, policy, room, label in _room_grids(workloads):
        for ratios in ("paths", "all"):
            count = CountSettings(ratios=ratios)
            discover_exhaustive(mdp, policy, np.random.default_rng(0), count)  # warm
            te, ex = best(lambda m=mdp, p=policy, c=count: discover_exhaustive(
                m, p, np.random.default_rng(0), c), 2)
            for h in counts:
                mc_set = build_settings(MonteCarloSettings,
                                        {"ratios": ratios, "stop": "max", "max_samples": h})
                tm, mc = best(lambda m=mdp, p=policy, c=mc_set: discover_monte_carlo(
                    m, p, np.random.default_rng(0), c), 1)
                row = {"n_states": mdp.n_states, "room": room, "ratios": ratios, "samples": h,
                       "time_exhaustive": te, "time_mc": tm, "ratio_time": tm / te,
                       "n_exhaustive": int(ex.subgoals.size), "n_mc": int(mc.subgoals.size),
                       "jaccard": _jaccard(ex.subgoals, mc.subgoals)}
                rows.append(row)
                print(f"{label:<22} {ratios:<7} {h:>8,} {te:>7.3f} {tm:>8.3f} {tm / te:>8.3f} "
                      f"{row['n_exhaustive']:>5} {row['n_mc']:>5} {row['jaccard']:>5.2f}",
                      flush=True)
    print()
    return rows


def main() -> None:
    rooms()
    samples_needed()
    for choice in CHOICES:
        agreement(choice=choice)
    arm = get_domain("three-floor-arm").mdp("deliver")
    arm_policy = solve(arm).policy
    grids = {}
    for choice in CHOICES:
        print("subgoal discovery: exhaustive (eq. 4.1) vs Monte Carlo (def. 4.4), seed 0, "
              f"{choice}")
        print(f"{'workload':<18} {'states':>9} {'exh s':>8} {'MC s':>8} {'ratio':>8} "
              f"{'#exh':>5} {'#MC':>5} {'both':>5} {'samples':>7} stop")
        run("three-floor-arm", arm, arm_policy, 3, choice)
        for n in (10**5, 10**6):
            if n not in grids:
                t0 = time.perf_counter()
                grids[n] = goal_grid(n)
                print(f"  (grid {n:,}: model and policy in {time.perf_counter() - t0:.1f} s)")
            mdp, policy = grids[n]
            run(f"grid {n:,}", mdp, policy, 3 if n <= 10**5 else 1, choice)
        print()


if __name__ == "__main__":
    main()
