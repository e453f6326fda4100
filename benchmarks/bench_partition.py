"""Exact lumping against Storm's bisimulation, and delta = 0.3 refinement over 20 options.

Workload (exact lumping): ``lumpable_grid_mdp(n)`` - a slippery grid of ``n`` cells on a cylinder
(rows wrap around north-south, walls east and west; four moves, slip 0.2 sideways, at most three
successors per row), whose reward depends on a coarse feature only: 1 in the westmost eighth of the
columns, 0 elsewhere. Every row of cells is then a translate of every other, so the coarsest exact
lumping has about one block per column (``~sqrt(n)`` blocks), but reaching it takes refinement
across the whole width of the grid: signature rounds grow with the grid's diameter.

Compared, on the same model in the same run:

* adpart :func:`adpart.partition.exact_lumping` (worklist of splitters, numba kernel; the time
  includes building the transposed model; the kernel is compiled before timing);
* Storm (stormpy 2.0.0) strong bisimulation of the same MDP written in Storm's explicit format
  (``.tra`` rows ``state choice target probability``, choices in our action order; the reward class
  as a state label ``r1`` preserved through the property ``Pmax=? [F "r1"]``). Loading the files is
  timed separately from the bisimulation. Storm matches choices existentially rather than one to
  one; on this grid both notions give the same blocks, and the block counts are checked to agree;
* a straightforward numpy signature refinement that re-signs every state each round (the
  reference the issue measured; run up to ``naive_max`` states because its rounds grow with the
  diameter).

Second part (:func:`delta_table`): :func:`adpart.partition.refine` with ``delta = 0.3`` (eq. 4.6,
reward independent) over 20 options - for each of the four moves, the open-loop macro "repeat the
move k times", ``k = 1..5``, with the discounted model ``F = (gamma P_a)^k`` - on two grids of
10^4-10^6 states, both with the 0.8/0.1/0.1 slip: the rooms grid of
:func:`benchmarks._models.rooms_grid_mdp`, starting from the goal cell against the rest (phase 1's
termination partition), and ``lumpable_grid_mdp``, starting from its reward strip. Each size
reports the delta refinement against exact lumping of the same 20-option model from the same start
(one after the other in the same run), their ratio, both block counts, the peak resident memory,
and, over all sizes, the fitted scaling exponents; the earlier round-based refiner
(:func:`adpart.partition.refine.delta_refine_rounds`) and the independent delta-stability checker
are run on the small sizes. Last, ``refine(delta=0, epsilon=0)`` (routed to exact lumping) against
Storm on the same grid.

``python -m benchmarks.bench_partition delta [rooms|lumpable [SIZE ...]]`` runs the delta tables
alone.
"""

from __future__ import annotations

import gc
import math
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from adpart.mdp.generate import GRID_ACTION_NAMES, GRID_MOVES, _canonical_csr
from adpart.mdp.model import FiniteMDP, SMDPModel
from adpart.partition import Partition, check_stability, exact_lumping, refine
from adpart.partition.partition import canonical_labels
from adpart.partition.refine import delta_refine_rounds

SIZES = (10_000, 100_000, 1_000_000)
DELTA_SIZES = (10_000, 100_000, 1_000_000)
WORKLOADS = ("rooms", "lumpable")


def lumpable_grid_mdp(n_states: int, *, slip: float = 0.2, gamma: float = 0.95) -> FiniteMDP:
    """A cylinder grid (``~sqrt(n)`` columns) with a reward strip at its west side (see above)."""
    width = max(2, math.isqrt(n_states))
    height = max(1, n_states // width)
    n = width * height
    s = np.arange(n, dtype=np.int64)
    row, col = s // width, s % width

    def step(move: int) -> np.ndarray:
        dr, dc = GRID_MOVES[move]
        r, c = (row + dr) % height, col + dc
        return np.where((c >= 0) & (c < width), r * width + c, s)

    succ = [step(m) for m in range(4)]
    cols = np.empty((4, n, 3), dtype=np.int64)
    for a in range(4):
        cols[a, :, 0], cols[a, :, 1], cols[a, :, 2] = succ[a], succ[(a + 1) % 4], succ[(a + 3) % 4]
    probs = np.broadcast_to(np.array([1.0 - slip, slip / 2, slip / 2]), (4 * n, 3))
    P = _canonical_csr(cols.reshape(4 * n, 3), np.ascontiguousarray(probs), n)
    reward = (col < max(1, width // 8)).astype(np.float64)
    R = np.repeat(reward[:, None], 4, axis=1)
    return FiniteMDP(P, R, gamma, features={"row": row, "col": col},
                     action_names=GRID_ACTION_NAMES, name=f"lumpable-grid-{n}")


def naive_signature_lumping(mdp: FiniteMDP) -> int:
    """Blocks of the coarsest lumping by plain signature rounds (every state re-signed per round).

    Signature of ``s``: its block, and per action the masses into every block, rounded to 9
    decimals and hashed into one int64 (collisions are negligible at these sizes); rounds
    repeat until the block count stops growing.
    """
    S, A = mdp.n_states, mdp.n_actions
    labels = canonical_labels(np.unique(mdp.R, axis=0, return_inverse=True)[1].reshape(-1))
    rng = np.random.default_rng(0)
    while True:
        B = int(labels.max()) + 1
        onehot = sp.csr_array((np.ones(S), labels, np.arange(S + 1)), shape=(S, B))
        M = sp.coo_array(mdp.P @ onehot)
        weights = rng.integers(1, 2**31, size=B)
        h = np.zeros(A * S, dtype=np.int64)
        np.add.at(h, M.row, np.round(M.data * 1e9).astype(np.int64) * weights[M.col])
        mix = rng.integers(1, 2**31, size=A + 1)
        sig = labels * mix[0] + h.reshape(A, S).T @ mix[1:]  # one int64 hash per state
        new = canonical_labels(sig)
        if new.max() == labels.max():
            return B
        labels = new


def write_storm_explicit(mdp: FiniteMDP, folder: Path) -> tuple[Path, Path]:
    """Write ``mdp`` as Storm explicit files; state label ``r1`` marks reward class 1."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    S = mdp.n_states
    P = sp.coo_array(mdp.P)
    state, action = P.row % S, P.row // S
    order = np.lexsort((P.col, action, state))
    table = pa.table({"s": state[order], "a": action[order], "t": P.col[order],
                      "p": P.data[order]})
    tra = folder / "model.tra"
    with open(tra, "wb") as f:
        f.write(b"mdp\n")
        pacsv.write_csv(table, f, pacsv.WriteOptions(include_header=False, delimiter=" ",
                                                     quoting_style="none"))
    lab = folder / "model.lab"
    marked = np.flatnonzero(mdp.R[:, 0] > 0)
    with open(lab, "w") as f:
        f.write("#DECLARATION\ninit r1\n#END\n")
        lines = [f"{i} r1\n" for i in marked]
        if marked.size and marked[0] == 0:
            lines[0] = "0 init r1\n"
        else:
            lines.insert(0, "0 init\n")
        f.write("".join(lines))
    return tra, lab


def storm_bisimulation(mdp: FiniteMDP) -> dict[str, float]:
    """Storm's strong bisimulation of ``mdp``: blocks, load seconds, bisimulation seconds."""
    import stormpy
    import stormpy.transformations

    with tempfile.TemporaryDirectory() as tmp:
        tra, lab = write_storm_explicit(mdp, Path(tmp))
        t0 = time.perf_counter()
        model = stormpy.build_model_from_explicit(str(tra), str(lab))
        t1 = time.perf_counter()
    props = stormpy.parse_properties('Pmax=? [F "r1"]')
    t2 = time.perf_counter()
    quotient = stormpy.transformations.perform_bisimulation(model, props)
    t3 = time.perf_counter()
    return {"blocks": quotient.nr_states, "load_s": t1 - t0, "bisim_s": t3 - t2}


def macro_options(mdp: FiniteMDP, k_max: int = 5) -> SMDPModel:
    """20 options: repeat move ``a`` open-loop ``k`` times (``F = (gamma P_a)^k``, k = 1..5).

    Every product is sparse (no dense intermediate); the option blocks are stacked by
    :func:`stack_rows`, so the build holds the blocks and one block's copy at a time.
    """
    S, g = mdp.n_states, mdp.gamma
    F_blocks, R_cols = [], []
    for a in range(mdp.n_actions):
        Pa = sp.csr_array(mdp.P[a * S:(a + 1) * S])
        Fk = sp.csr_array(sp.eye_array(S, format="csr"))
        Rk = np.zeros(S)
        for _ in range(k_max):
            Rk = Rk + Fk @ mdp.R[:, a]
            Fk = sp.csr_array(g * (Fk @ Pa))
            F_blocks.append(Fk)
            R_cols.append(Rk.copy())
    del Fk
    F = stack_rows(F_blocks, S)
    return SMDPModel(R=np.column_stack(R_cols), F=F, admissible=np.ones((S, len(R_cols)), bool))


def stack_rows(blocks: list[sp.csr_array], n_cols: int) -> sp.csr_array:
    """``sp.vstack(blocks, format="csr")`` (the same arrays), emptying ``blocks``: each block is
    copied into arrays allocated once and dropped at once, and the result's pages are committed
    as they are written, so stacking costs one block beyond the blocks where ``vstack`` holds a
    second copy of them all (5.8 GiB at the peak of the 10^6-state rooms build, 2.5 GiB model)."""
    nnz = sum(b.nnz for b in blocks)
    rows = sum(b.shape[0] for b in blocks)
    idx = np.int32 if max(nnz, rows, n_cols) < 2**31 else np.int64
    data = np.empty(nnz, dtype=np.result_type(*(b.dtype for b in blocks)))
    indices = np.empty(nnz, dtype=idx)
    indptr = np.empty(rows + 1, dtype=idx)
    indptr[0] = 0
    at = row = 0
    blocks.reverse()
    while blocks:
        b = blocks.pop()
        data[at:at + b.nnz] = b.data
        indices[at:at + b.nnz] = b.indices
        indptr[row + 1:row + 1 + b.shape[0]] = b.indptr[1:] + at
        at += b.nnz
        row += b.shape[0]
        del b
    return sp.csr_array((data, indices, indptr), shape=(rows, n_cols))


def _best(fn, repeats: int) -> tuple[float, object]:
    best, out = math.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _stacked(model: SMDPModel, start: Partition) -> tuple[np.ndarray, sp.csr_array, int]:
    """The labels and stacked rows :func:`refine` hands its delta stage (for the old refiner)."""
    from adpart.partition._validate import masked_rows, select_options, selected_admissible
    from adpart.partition.partition import combine_labels, row_codes

    sel = select_options(model, None)
    adm = selected_admissible(model, sel)
    labels = combine_labels(start.labels, row_codes(adm[:, sel]))
    return labels, masked_rows(model, sel, adm), sel.size


def main(sizes: tuple[int, ...] = SIZES, delta_sizes: tuple[int, ...] = DELTA_SIZES,
         naive_max: int = 100_000, repeats: int = 2, storm: bool = True,
         rounds_max: int = 10_000, check_max: int = 100_000,
         workloads: tuple[str, ...] = WORKLOADS) -> dict[str, object]:
    """Print and return the exact-lumping table and the delta = 0.3 scaling table."""
    exact_lumping(lumpable_grid_mdp(400))  # compile the numba kernels outside the timings
    try:
        import stormpy  # noqa: F401
    except ImportError:
        storm = False
        print("stormpy not installed (pip install stormpy==2.0.0): Storm column skipped")
    rows = []
    print("exact lumping (delta = epsilon = 0, actions matched one to one), lumpable_grid_mdp")
    print(f"{'states':>9} {'blocks':>7} {'adpart s':>9} {'storm s':>8} {'load s':>7} "
          f"{'storm/adpart':>12} {'naive s':>8} {'naive/adpart':>12} agree")
    for n in sizes:
        mdp = lumpable_grid_mdp(n)
        t_ours, part = _best(lambda mdp=mdp: exact_lumping(mdp), repeats)
        row: dict[str, object] = {"states": mdp.n_states, "blocks": part.n_blocks,
                                  "adpart_s": t_ours}
        agree = True
        if storm:
            st = storm_bisimulation(mdp)
            row.update(storm_s=st["bisim_s"], storm_load_s=st["load_s"],
                       storm_blocks=st["blocks"])
            agree &= st["blocks"] == part.n_blocks
        if mdp.n_states <= naive_max:
            t_naive, nb = _best(lambda mdp=mdp: naive_signature_lumping(mdp), 1)
            row.update(naive_s=t_naive, naive_blocks=nb)
            agree &= nb == part.n_blocks
        row["agree"] = agree
        rows.append(row)

        def fmt(key: str, width: int, r: dict = row) -> str:
            return f"{r[key]:>{width}.3f}" if key in r else f"{'-':>{width}}"

        ratio_s = f"{row['storm_s'] / t_ours:>12.2f}" if "storm_s" in row else f"{'-':>12}"
        ratio_n = f"{row['naive_s'] / t_ours:>12.1f}" if "naive_s" in row else f"{'-':>12}"
        print(f"{row['states']:>9} {part.n_blocks:>7} {t_ours:>9.3f} {fmt('storm_s', 8)} "
              f"{fmt('storm_load_s', 7)} {ratio_s} {fmt('naive_s', 8)} {ratio_n} {agree}",
              flush=True)

    drows = []
    for workload in workloads:
        drows += delta_table(workload, delta_sizes, rounds_max=rounds_max, check_max=check_max,
                             repeats=repeats)
    if storm:
        mdp = lumpable_grid_mdp(delta_sizes[0])
        t0, part0 = _best(lambda: refine(Partition.from_labels(
            mdp.R[:, 0].astype(np.int64), mdp.admissible), mdp, delta=0.0, epsilon=0.0), repeats)
        st = storm_bisimulation(mdp)
        print(f"refine(delta=0, epsilon=0) on lumpable_grid_mdp({delta_sizes[0]:_}): {t0:.3f} s, "
              f"{part0.n_blocks} blocks; Storm {st['bisim_s']:.3f} s, {st['blocks']} blocks; "
              f"adpart/Storm = {t0 / st['bisim_s']:.2f}")
    return {"lumping": rows, "delta": drows}


def delta_workload(workload: str, n: int) -> tuple[FiniteMDP, np.ndarray]:
    """The grid of a delta workload and its initial labels.

    ``rooms``: :func:`benchmarks._models.rooms_grid_mdp` (the peers' rooms grid, slip 0.8/0.1/0.1),
    starting from the goal cell against the rest (phase 1's termination partition);
    ``lumpable``: :func:`lumpable_grid_mdp`, starting from its reward strip.
    """
    if workload == "rooms":
        from benchmarks._models import rooms_grid_mdp

        mdp = rooms_grid_mdp(n)
        return mdp, mdp.terminal.astype(np.int64)
    if workload == "lumpable":
        mdp = lumpable_grid_mdp(n)
        return mdp, mdp.R[:, 0].astype(np.int64)
    raise ValueError(f"unknown delta workload {workload!r}; choose rooms or lumpable")


def _peak_rss_gb() -> float:
    """The process's peak resident set so far (``getrusage`` ``ru_maxrss``, KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def _reset_peak() -> bool:
    """Reset the kernel's resident high-water mark (Linux ``/proc/self/clear_refs`` value 5)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _status_gb(field: str) -> float:
    """A size field of ``/proc/self/status`` (``VmHWM``, ``VmRSS``) in GiB (NaN elsewhere)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(f"{field}:"):
                    return int(line.split()[1]) / 2**20
    except OSError:
        pass
    return math.nan


def _peak_since_reset_gb() -> float:
    """``VmHWM`` of ``/proc/self/status``: the peak resident set since the last reset (GiB)."""
    return _status_gb("VmHWM")


def _trim_heap() -> None:
    """Hand the C heap's free pages back to the kernel (glibc's ``malloc_trim``; a no-op where
    there is none).

    Building the 20-option model leaves freed small arrays in the heap (0.64 GiB of the 3.51 GiB
    resident after the 10^6-state rooms model is built; 2.87 GiB after a trim). They would count
    in a call's resident peak though neither the model nor the call holds them, and how much is
    left depends on the order of the build's allocations, not on the code measured.
    """
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        if libc is not None and hasattr(libc, "malloc_trim"):
            libc.malloc_trim(0)
    except OSError:
        pass


def _timed(fn, repeats: int) -> tuple[float, float, float, object, float]:
    """Best wall and best CPU seconds over ``repeats`` calls, the peak memory, the last result,
    and the resident GiB before the first call.

    The peak (GiB) is the process's resident high-water mark during the first call: the model,
    already resident, plus the call's working memory. Free heap pages are returned first
    (:func:`_trim_heap`). Where the mark cannot be reset it is the process's peak so far
    (``ru_maxrss``).
    """
    wall, cpu, out = math.inf, math.inf, None
    gc.collect()
    _trim_heap()
    base = _status_gb("VmRSS")
    reset = _reset_peak()
    peak = math.nan
    for i in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
        if i == 0:
            peak = _peak_since_reset_gb() if reset else _peak_rss_gb()
    return wall, cpu, peak, out, base


def fitted_exponent(states: list[int], seconds: list[float]) -> float:
    """Least-squares slope of log(seconds) on log(states): ``time ~ states^x``."""
    return float(np.polyfit(np.log(states), np.log(seconds), 1)[0])


def delta_table(workload: str, sizes: tuple[int, ...], *, rounds_max: int = 10_000,
                check_max: int = 100_000, repeats: int = 2) -> list[dict[str, object]]:
    """delta = 0.3 over 20 macro options against exact lumping of the same model, same run.

    Per size: the best wall (and CPU) seconds of ``refine(start, model, delta=0.3)`` and of
    ``exact_lumping(model, initial=start, use_rewards=False)`` over ``repeats`` calls each, one
    after the other on the same model; their ratio; both block counts; the model's transition
    entries (and the GiB of its ``F`` arrays: data, indices, indptr) and the peak resident memory
    of the process during one call of each (the model included), with the resident size before
    the calls (``base GB``: the model, its rewards, the interpreter and libraries) and each peak
    over the model's GiB; the seconds and the peak resident GiB of building the 20 options
    (:func:`macro_options`); the independent delta-stability checker up to ``check_max`` states
    and the earlier round-based refiner up to ``rounds_max``. Last, the exponents fitted over all
    sizes.
    """
    # compile the kernels outside the timings
    mdp, lab = delta_workload(workload, 400)
    model = macro_options(mdp)
    start = Partition.from_labels(lab, model.admissible)
    refine(start, model, delta=0.3)
    exact_lumping(model, initial=start, use_rewards=False)
    print(f"\ndelta = 0.3 refinement over 20 macro options (reward independent), "
          f"{workload} grid; reference: exact lumping of the same 20-option model, same run")
    print(f"{'states':>9} {'entries':>11} {'model GB':>8} {'blocks':>7} {'delta s':>8} "
          f"{'cpu s':>7} {'peak GB':>7} {'exact s':>8} {'cpu s':>7} {'peak GB':>7} "
          f"{'ex blocks':>9} {'ratio':>6} {'cpu ratio':>9} {'rounds s':>8} {'stable':>6} "
          f"{'base GB':>7} {'peak/model':>10} {'build s':>7} {'build GB':>8}", flush=True)
    rows = []
    for n in sizes:
        mdp, lab = delta_workload(workload, n)
        gc.collect()
        _trim_heap()
        reset = _reset_peak()
        t0 = time.perf_counter()
        model = macro_options(mdp)
        build_s = time.perf_counter() - t0
        build_gb = _peak_since_reset_gb() if reset else _peak_rss_gb()
        start = Partition.from_labels(lab, model.admissible)
        del mdp
        F = model.F
        model_gb = (F.data.nbytes + F.indices.nbytes + F.indptr.nbytes) / 2**30

        def run_delta(model=model, start=start):
            return refine(start, model, delta=0.3)

        def run_exact(model=model, start=start):
            return exact_lumping(model, initial=start, use_rewards=False)

        t, c, peak, part, base_gb = _timed(run_delta, repeats)
        t_ex, c_ex, peak_ex, ex, _ = _timed(run_exact, repeats)
        row = {"workload": workload, "states": model.n_states, "entries": F.nnz,
               "model_gb": model_gb, "blocks": part.n_blocks, "seconds": t, "cpu_s": c,
               "exact_s": t_ex, "exact_cpu_s": c_ex, "exact_blocks": ex.n_blocks,
               "ratio_exact": t / t_ex, "cpu_ratio": c / c_ex, "peak_gb": peak,
               "exact_peak_gb": peak_ex, "base_gb": base_gb, "build_s": build_s,
               "build_gb": build_gb}
        if model.n_states <= rounds_max:
            labels, F, k = _stacked(model, start)
            t_r, (old, _) = _best(
                lambda labels=labels, F=F, k=k: delta_refine_rounds(labels, F, k, 0.3, 1e-9), 1)
            row.update(rounds_s=t_r, rounds_blocks=int(old.max()) + 1)
        row["stable"] = "-"
        # the checker builds a dense (members x blocks) table per block and option
        if model.n_states <= check_max and part.n_blocks * model.n_states <= 2 * 10**8:
            row["stable"] = str(bool(check_stability(part, model, delta=0.3)))
        rows.append(row)
        r_s = f"{row['rounds_s']:>8.2f}" if "rounds_s" in row else f"{'-':>8}"
        ratios = f"{peak / model_gb:.2f}/{peak_ex / model_gb:.2f}"
        print(f"{row['states']:>9} {row['entries']:>11} {model_gb:>8.2f} {part.n_blocks:>7} "
              f"{t:>8.3f} {c:>7.3f} {peak:>7.2f} {t_ex:>8.3f} {c_ex:>7.3f} {peak_ex:>7.2f} "
              f"{ex.n_blocks:>9} {t / t_ex:>6.2f} {c / c_ex:>9.2f} {r_s} {row['stable']:>6} "
              f"{base_gb:>7.2f} {ratios:>10} {build_s:>7.2f} {build_gb:>8.2f}", flush=True)
        del model, part, ex, start, F, run_delta, run_exact
    if len(rows) >= 2:
        st = [r["states"] for r in rows]
        x = fitted_exponent(st, [r["seconds"] for r in rows])
        xc = fitted_exponent(st, [r["cpu_s"] for r in rows])
        xe = fitted_exponent(st, [r["exact_s"] for r in rows])
        print(f"fitted exponent (time ~ states^x, {st[0]:,} to {st[-1]:,} states): delta x = "
              f"{x:.2f} (cpu {xc:.2f}), exact lumping x = {xe:.2f}", flush=True)
        for r in rows:
            r.update(exponent=x, cpu_exponent=xc, exact_exponent=xe)
    return rows


if __name__ == "__main__":
    # python -m benchmarks.bench_partition [delta [WORKLOAD [SIZE ...]]]: the delta table alone
    if sys.argv[1:2] == ["delta"]:
        chosen = tuple(sys.argv[2:3]) or WORKLOADS
        given = tuple(int(a) for a in sys.argv[3:]) or DELTA_SIZES
        for w in chosen:
            delta_table(w, given)
    else:
        main()
