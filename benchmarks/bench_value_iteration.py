"""Time to an epsilon-optimal policy: adpart's VI and MPI against pymdptoolbox's ValueIteration.

Workload: ``random_grid_mdp(n, gamma=0.95, slip=0.2, seed=0)`` for n = 10^4, 10^5, 10^6 (a
slippery square grid, four moves, at most three successors per row, i.i.d. normal rewards, no
terminal states). Every solver gets the same MDP and the same guarantee:

* pymdptoolbox ``ValueIteration(P, R, gamma, epsilon)`` stops when
  ``sp(V_{n+1} - V_n) < epsilon (1 - gamma) / gamma`` (its ``thresh``; Puterman Prop. 6.6.5)
  and returns the policy attaining ``V_{n+1} = T V_n``, whose loss is then below ``epsilon``.
* adpart's solvers use the same span rule with the same threshold whenever the discount is
  uniform (it is here), so the same ``epsilon`` is the same guarantee ``||V* - V^pi|| < epsilon``.

pymdptoolbox's constructor runs ``util.check`` (dense ``(S, S)`` temporaries: it fails at 10^5
states) and ``_boundIter``, a Python loop over states that densifies one column per state, so the
benchmark builds the ``ValueIteration`` object without its constructor and sets the attributes the
constructor would set (``thresh`` exactly as it computes it, ``max_iter`` large); ``run()`` is then
pymdptoolbox's own unchanged solver loop. P is given as a tuple of per-action scipy CSR matrices
and R as per-action ``(S,)`` vectors, the formats its constructor produces.

Figures: total wall time of each solve (best of ``repeats``); one sweep, i.e. one Bellman backup
over all ``A*S`` rows, timed separately for pymdptoolbox's ``_bellmanOperator`` and adpart's backup
kernel; the number of full sweeps (and MPI's policy-evaluation mat-vecs over ``S`` rows); ratios
``pymdptoolbox time / adpart time``. Policies are checked, not only timed: at every size each
returned policy is evaluated (sparse direct solve at 10^4, otherwise ``T_pi`` iterated from a tight
``V*`` with the printed error bar) and its loss against ``V*`` from a tight (epsilon = 1e-9) solve
must be below epsilon.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np
import scipy.sparse as sp
from mdptoolbox.mdp import ValueIteration

from adpart.mdp import _kernels
from adpart.mdp.evaluation import policy_evaluation
from adpart.mdp.generate import random_grid_mdp
from adpart.mdp.model import FiniteMDP
from adpart.mdp.solvers import _Backup, default_kernel, modified_policy_iteration, value_iteration

SIZES = (10_000, 100_000, 1_000_000)
GAMMA = 0.95
EPSILON = 1e-6


def pymdptoolbox_arrays(mdp: FiniteMDP) -> tuple[tuple, tuple]:
    """``(P, R)`` per action for pymdptoolbox: the same MDP in its format.

    pymdptoolbox knows neither terminal states nor admissible actions, so a terminal state becomes
    absorbing with reward 0 (its value, 0, is then the same as adpart's) and an inadmissible
    action gets reward ``-1e12`` and no successors (it never attains a maximum). With no terminal
    states every row keeps discount ``gamma``, so its span rule stays valid.
    """
    S, A = mdp.n_states, mdp.n_actions
    smdp = mdp.as_smdp()
    stay = sp.diags_array(mdp.terminal.astype(np.float64), format="csr")
    P, R = [], []
    for a in range(A):
        Pa = sp.csr_matrix(smdp.F[a * S:(a + 1) * S] / mdp.gamma + stay)
        P.append(Pa)
        R.append(np.where(mdp.admissible[:, a], smdp.R[:, a], -1e12))
    return tuple(P), tuple(R)


def pymdptoolbox_solver(mdp: FiniteMDP, epsilon: float, arrays: tuple | None = None
                        ) -> ValueIteration:
    """pymdptoolbox's ValueIteration for ``mdp``, built past its dense input check.

    Sets exactly the attributes ``MDP.__init__`` and ``ValueIteration.__init__`` set, except that
    ``util.check`` and ``_boundIter`` are skipped (see the module docstring) and ``max_iter`` is
    large, so the solve stops only by the epsilon-optimality rule.
    """
    S, A = mdp.n_states, mdp.n_actions
    P, R = pymdptoolbox_arrays(mdp) if arrays is None else arrays
    vi = ValueIteration.__new__(ValueIteration)
    vi.discount = float(mdp.gamma)
    vi.epsilon = float(epsilon)
    vi.max_iter = 1_000_000
    vi.S, vi.A = S, A
    vi.P = P
    vi.R = R
    vi.verbose = False
    vi.time = None
    vi.iter = 0
    vi.V = np.zeros(S)
    vi.policy = None
    vi.thresh = epsilon * (1 - vi.discount) / vi.discount
    return vi


def _best_time(fn: Callable[[], object], repeats: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _policy_value(
    mdp: FiniteMDP, policy: np.ndarray, V_star: np.ndarray
) -> tuple[np.ndarray, float]:
    """``V^pi`` and a bound on its error: a direct solve when small, else ``T_pi`` from ``V*``.

    Iterating ``T_pi`` k times from ``V*`` leaves an error of at most
    ``gamma^k / (1 - gamma) * ||T_pi V* - V*||`` (a contraction argument independent of adpart's
    solvers), which is printed next to the loss.
    """
    if mdp.n_states <= 20_000:
        return policy_evaluation(mdp, policy), 0.0
    S = mdp.n_states
    rows = policy * S + np.arange(S)
    P_pi = mdp.P[rows]
    R_pi = mdp.R[np.arange(S), policy]
    V = V_star.copy()
    first = np.abs(R_pi + mdp.gamma * (P_pi @ V) - V).max()
    k = 200
    for _ in range(k):
        V = R_pi + mdp.gamma * (P_pi @ V)
    return V, float(mdp.gamma**k / (1 - mdp.gamma) * first)


def run_size(n: int, *, epsilon: float = EPSILON, gamma: float = GAMMA, repeats: int = 1) -> dict:
    """Solve one generated grid with all three solvers; return the figures of one table row."""
    mdp = random_grid_mdp(n, gamma=gamma, seed=0)
    smdp = mdp.as_smdp()
    V0 = np.zeros(mdp.n_states)

    tool = pymdptoolbox_solver(mdp, epsilon)
    k = 5
    t_sweep_tool, _ = _best_time(lambda: tool._bellmanOperator(V0), k)
    backup = _Backup(smdp)  # the default kernel: fused numba backup + greedy policy when present
    t_sweep_ad, _ = _best_time(lambda: backup.step(V0, want_policy=True), k)

    def run_tool() -> ValueIteration:
        vi = pymdptoolbox_solver(mdp, epsilon)
        vi.run()
        return vi

    t_tool, tool = _best_time(run_tool, repeats)
    t_vi, sol_vi = _best_time(lambda: value_iteration(mdp, epsilon), repeats)
    t_mpi, sol_mpi = _best_time(lambda: modified_policy_iteration(mdp, epsilon), repeats)
    t_np, sol_np = _best_time(
        lambda: modified_policy_iteration(mdp, epsilon, kernel="numpy"), repeats
    )

    tight = modified_policy_iteration(mdp, 1e-9)
    V_star = tight.V
    pol_tool = np.asarray(tool.policy, dtype=np.int64)
    losses = {}
    named = (
        ("pymdptoolbox", pol_tool),
        ("vi", sol_vi.policy),
        ("mpi", sol_mpi.policy),
        ("mpi-numpy", sol_np.policy),
    )
    for name, pol in named:
        V_pi, err = _policy_value(mdp, pol, V_star)
        losses[name] = (float(np.max(V_star - V_pi)), err + tight.value_error_bound)
    return {
        "n": n,
        "tool_sweeps": tool.iter,
        "tool_time": t_tool,
        "tool_sweep_ms": 1e3 * t_sweep_tool,
        "vi_sweeps": sol_vi.sweeps,
        "vi_time": t_vi,
        "vi_sweep_ms": 1e3 * t_sweep_ad,
        "mpi_sweeps": sol_mpi.sweeps,
        "mpi_evals": sol_mpi.evaluation_sweeps,
        "mpi_time": t_mpi,
        "np_sweeps": sol_np.sweeps,
        "np_evals": sol_np.evaluation_sweeps,
        "np_time": t_np,
        "losses": losses,
        # adpart shifts V to MacQueen's midpoint (a constant), so compare values up to a constant.
        "value_gap": float(np.ptp(np.asarray(tool.V) - sol_vi.V)),
        "agree_vi": float(np.mean(pol_tool == sol_vi.policy)),
        "agree_mpi": float(np.mean(pol_tool == sol_mpi.policy)),
    }


def _print_row(r: dict) -> None:
    print(
        f"{r['n']:>9,d} | {r['tool_time']:8.2f} {r['tool_sweeps']:>5d} {r['tool_sweep_ms']:7.2f} | "
        f"{r['vi_time']:7.2f} {r['vi_sweeps']:>5d} {r['vi_sweep_ms']:7.2f} "
        f"{r['tool_time'] / r['vi_time']:5.1f}x | "
        f"{r['mpi_time']:7.2f} {r['mpi_sweeps']:>3d}+{r['mpi_evals']:<4d} "
        f"{r['tool_time'] / r['mpi_time']:5.1f}x | "
        f"{r['np_time']:7.2f} {r['np_sweeps']:>3d}+{r['np_evals']:<4d} "
        f"{r['tool_time'] / r['np_time']:5.1f}x | {r['tool_sweep_ms'] / r['vi_sweep_ms']:5.1f}x",
        flush=True,
    )


ROOMS_SIZES = (10_000, 100_000, 1_000_000)
DOMAINS = ("three-floor", "urban", "taxi", "three-floor-arm")


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS"):
                return int(line.split()[1]) / 1024
    return float("nan")


def _peak_mb(fn: Callable[[], object]) -> tuple[float, object]:
    """Peak resident memory of ``fn()`` above the resident memory before it (Linux), in MB."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")  # resets the peak (VmHWM) to the current resident size
    except OSError:
        return float("nan"), fn()
    before = _rss_mb()
    out = fn()
    with open("/proc/self/status") as f:
        hwm = next(int(line.split()[1]) / 1024 for line in f if line.startswith("VmHWM"))
    return hwm - before, out


def _smdp_policy_loss(smdp, policy: np.ndarray, V_star: np.ndarray, exact: bool
                      ) -> tuple[float, float]:
    """``(max(V* - V^pi), error bar)``: a direct solve when ``exact``, else ``T_pi`` iterated
    200 times from ``V*`` (error ``kappa^200 / (1 - kappa) ||T_pi V* - V*||``)."""
    if exact:
        return float(np.max(V_star - policy_evaluation(smdp, policy))), 0.0
    S = smdp.n_states
    F_pi = smdp.F[policy * S + np.arange(S)]
    R_pi = smdp.R[np.arange(S), policy]
    V = V_star.copy()
    first = float(np.abs(R_pi + F_pi @ V - V).max())
    for _ in range(200):
        V = R_pi + F_pi @ V
    kappa = smdp.modulus
    return float(np.max(V_star - V)), kappa**200 / (1 - kappa) * first


def run_goal_model(name: str, mdp: FiniteMDP, *, epsilon: float = EPSILON, repeats: int = 3,
                   memory: bool = False) -> dict:
    """pymdptoolbox against vi, mpi, gs and ``solve()``'s default on one goal-directed model."""
    from adpart.mdp.solvers import choose_method, gauss_seidel_value_iteration, solve

    smdp = mdp.as_smdp()
    arrays = pymdptoolbox_arrays(mdp)

    def run_tool() -> ValueIteration:
        vi = pymdptoolbox_solver(mdp, epsilon, arrays)
        vi.run()
        return vi

    reps = repeats if mdp.n_states < 200_000 else 1
    t_tool, tool = _best_time(run_tool, reps)
    t_vi, sol_vi = _best_time(lambda: value_iteration(mdp, epsilon), reps)
    t_mpi, sol_mpi = _best_time(lambda: modified_policy_iteration(mdp, epsilon), reps)
    t_gs, sol_gs = _best_time(lambda: gauss_seidel_value_iteration(mdp, epsilon), reps)
    t_def, sol_def = _best_time(lambda: solve(mdp, epsilon), reps)
    row = {"name": name, "n": mdp.n_states, "default": choose_method(mdp),
           "tool_time": t_tool, "tool_sweeps": tool.iter, "vi_time": t_vi,
           "vi_sweeps": sol_vi.sweeps, "mpi_time": t_mpi,
           "mpi_sweeps": f"{sol_mpi.sweeps}+{sol_mpi.evaluation_sweeps}", "gs_time": t_gs,
           "gs_sweeps": sol_gs.sweeps, "default_time": t_def}
    if memory:
        del arrays
        row["tool_mb"], _ = _peak_mb(lambda: run_tool_fresh(mdp, epsilon))
        row["default_mb"], _ = _peak_mb(lambda: solve(mdp, epsilon))
    tight = gauss_seidel_value_iteration(mdp, 1e-9)
    exact = mdp.n_states <= 20_000
    losses = {}
    for label, pol in (("pymdptoolbox", np.asarray(tool.policy, dtype=np.int64)),
                       ("vi", sol_vi.policy), ("mpi", sol_mpi.policy), ("gs", sol_gs.policy),
                       ("default", sol_def.policy)):
        loss, err = _smdp_policy_loss(smdp, pol, tight.V, exact)
        losses[label] = (loss, err + tight.value_error_bound)
    row["losses"] = losses
    return row


def run_tool_fresh(mdp: FiniteMDP, epsilon: float) -> ValueIteration:
    """pymdptoolbox including the conversion into its per-action format (for its memory)."""
    vi = pymdptoolbox_solver(mdp, epsilon)
    vi.run()
    return vi


def main_goal(rooms_sizes: Sequence[int] = ROOMS_SIZES, domains: Sequence[str] = DOMAINS,
              epsilon: float = EPSILON) -> list[dict]:
    """The goal-directed table: the peers' rooms grid and the built-in domains."""
    from adpart.envs.registry import get_domain
    from benchmarks._models import rooms_grid_mdp

    print(f"\ngoal-directed models (single terminal goal / the domains' default tasks), "
          f"epsilon = {epsilon:g}; times in s; ratio = adpart / pymdptoolbox (below 0.5 is the "
          "target); 'default' is solve() with method='auto'")
    header = (f"{'model':>22} {'states':>9} | {'pymdptb':>8} {'sw':>4} | {'vi':>7} {'sw':>4} "
              f"{'ratio':>5} | {'mpi':>7} {'sw':>9} {'ratio':>5} | {'gs':>7} {'sw':>4} "
              f"{'ratio':>5} | {'default':>7} {'ratio':>5} | memory MB tool/default")
    print(header)
    print("-" * len(header))
    models = [(f"rooms-grid({n:_})", lambda n=n: rooms_grid_mdp(n)) for n in rooms_sizes]
    models += [(d, lambda d=d: get_domain(d).mdp()) for d in domains]
    rows = []
    for name, make in models:
        mdp = make()
        r = run_goal_model(name, mdp, epsilon=epsilon, memory=mdp.n_states >= 500_000)
        rows.append(r)
        tt = r["tool_time"]
        mem = (f"{r['tool_mb']:.0f}/{r['default_mb']:.0f} (x{r['default_mb'] / r['tool_mb']:.2f})"
               if "tool_mb" in r else "-")
        print(f"{name:>22} {r['n']:>9,d} | {tt:8.3f} {r['tool_sweeps']:>4d} | {r['vi_time']:7.3f} "
              f"{r['vi_sweeps']:>4d} {r['vi_time'] / tt:5.2f} | {r['mpi_time']:7.3f} "
              f"{r['mpi_sweeps']:>9} {r['mpi_time'] / tt:5.2f} | {r['gs_time']:7.3f} "
              f"{r['gs_sweeps']:>4d} {r['gs_time'] / tt:5.2f} | {r['default_time']:7.3f} "
              f"{r['default_time'] / tt:5.2f} ({r['default']}) | {mem}", flush=True)
        del mdp
    print("policy checks: loss = max(V* - V^pi) against a tight (epsilon = 1e-9) solve")
    ok = True
    for r in rows:
        parts = []
        for label, (loss, err) in r["losses"].items():
            good = loss <= epsilon + err
            ok &= good
            parts.append(f"{label} {loss:.1e}{'' if good else ' FAIL'}")
        print(f"{r['name']:>22}: " + "; ".join(parts))
    print("all policies epsilon-optimal" if ok else "SOME POLICY IS NOT EPSILON-OPTIMAL")
    return rows


def main(sizes: Sequence[int] = SIZES, epsilon: float = EPSILON, repeats: int = 1) -> list[dict]:
    """Print the comparison table and the policy checks; return the figures."""
    print(
        f"value iteration to an epsilon-optimal policy: random_grid_mdp(n, gamma={GAMMA}, "
        f"slip=0.2, seed=0), epsilon = {epsilon:g}\n"
        "pymdptoolbox 4.0b3 ValueIteration, built past its dense input check (util.check) and its\n"
        "per-state _boundIter loop, which fail / take hours at 1e5+ states; run() is unchanged.\n"
        "Same stopping rule for all: span(T V - V) < epsilon (1 - gamma) / gamma "
        "=> loss < epsilon.\n"
        "times in s (best of %d); sweep = one full backup over all A*S rows, ms; "
        "ratio = pymdptoolbox / adpart;\nmpi sweeps = full backups + S-row evaluation mat-vecs"
        % repeats
    )
    header = (
        f"{'states':>9} | {'pymdptoolbox':^8} {'sweeps':>5} {'ms/swp':>7} | "
        f"{'vi':>7} {'sweeps':>5} {'ms/swp':>7} {'ratio':>6} | "
        f"{'mpi':>7} {'sweeps':>8} {'ratio':>6} | "
        f"{'mpi-np':>7} {'sweeps':>8} {'ratio':>6} | {'swp ratio':>6}"
    )
    kernel = default_kernel()
    t0 = time.perf_counter()
    _kernels.load()
    value_iteration(random_grid_mdp(100, seed=0), epsilon)  # compile (or load the cache) once
    modified_policy_iteration(random_grid_mdp(100, seed=0), epsilon)
    print(
        f"vi/mpi use kernel={kernel!r} (numba compile or cache load "
        f"{time.perf_counter() - t0:.2f} s, once, not timed); "
        "mpi-np = modified_policy_iteration(kernel='numpy')"
    )
    print(header)
    print("-" * len(header))
    rows = []
    for n in sizes:
        r = run_size(n, epsilon=epsilon, repeats=repeats)
        rows.append(r)
        _print_row(r)
    print("\npolicy checks: loss = max(V* - V^pi) against a tight (epsilon=1e-9) solve, +- bound")
    ok = True
    for r in rows:
        parts = []
        for name, (loss, err) in r["losses"].items():
            good = loss <= epsilon + err
            ok &= good
            parts.append(f"{name} {loss:.2e} (+-{err:.0e}){'' if good else ' FAIL'}")
        print(
            f"{r['n']:>9,d}: " + "; ".join(parts)
            + f"; same action as pymdptoolbox: vi {100 * r['agree_vi']:.2f}%, "
            f"mpi {100 * r['agree_mpi']:.2f}%; span(V_pymdptoolbox - V_vi) {r['value_gap']:.1e}"
        )
    print("all policies epsilon-optimal" if ok else "SOME POLICY IS NOT EPSILON-OPTIMAL")
    rows.extend(main_goal(epsilon=epsilon))
    return rows


if __name__ == "__main__":
    main()
