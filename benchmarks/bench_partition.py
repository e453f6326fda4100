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

Second part: :func:`adpart.partition.refine` with ``delta = 0.3`` (eq. 4.6, reward independent)
over 20 options - for each of the four moves, the open-loop macro "repeat the move k times",
``k = 1..5``, with the discounted model ``F = (gamma P_a)^k`` - on ``lumpable_grid_mdp`` grids of
increasing size, starting from the reward-strip partition; reported with its scaling exponent,
against exact lumping of the same 20-option model (the reference: the worklist's cost per split
should stay within a small factor of it), and against the earlier round-based refiner
(:func:`adpart.partition.refine.delta_refine_rounds`, up to ``rounds_max`` states), with block
counts of both and the independent delta-stability checker run on the result (up to
``check_max`` states). Last, ``refine(delta=0, epsilon=0)`` (routed to exact lumping) against
Storm on the same grid.
"""

from __future__ import annotations

import math
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
    """20 options: repeat move ``a`` open-loop ``k`` times (``F = (gamma P_a)^k``, k = 1..5)."""
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
    F = sp.csr_array(sp.vstack(F_blocks, format="csr"))
    return SMDPModel(R=np.column_stack(R_cols), F=F, admissible=np.ones((S, len(R_cols)), bool))


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
         rounds_max: int = 100_000, check_max: int = 100_000) -> dict[str, object]:
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

    print("\ndelta = 0.3 refinement over 20 macro options (reward independent), lumpable_grid_mdp;")
    print("reference: exact lumping of the same 20-option model; 'rounds' = the earlier "
          f"round-based refiner (up to {rounds_max:,} states)")
    print(f"{'states':>9} {'blocks':>7} {'worklist s':>10} {'exact s':>8} {'wl/exact':>8} "
          f"{'rounds s':>9} {'r blocks':>8} {'rounds/wl':>9} {'delta-stable':>12}")
    drows = []
    for n in delta_sizes:
        mdp = lumpable_grid_mdp(n)
        model = macro_options(mdp)
        start = Partition.from_labels(mdp.R[:, 0].astype(np.int64), model.admissible)
        t, part = _best(lambda model=model, start=start: refine(start, model, delta=0.3), 1)
        t_ex, ex = _best(lambda model=model, start=start: exact_lumping(
            model, initial=start, use_rewards=False), 1)
        row = {"states": mdp.n_states, "blocks": part.n_blocks, "seconds": t,
               "exact_s": t_ex, "exact_blocks": ex.n_blocks, "ratio_exact": t / t_ex}
        if mdp.n_states <= rounds_max:
            labels, F, k = _stacked(model, start)
            t_r, (old, _) = _best(
                lambda labels=labels, F=F, k=k: delta_refine_rounds(labels, F, k, 0.3, 1e-9), 1)
            row.update(rounds_s=t_r, rounds_blocks=int(old.max()) + 1)
        stable = "-"
        if mdp.n_states <= check_max:
            stable = str(bool(check_stability(part, model, delta=0.3)))
        row["stable"] = stable
        drows.append(row)
        r_s = f"{row['rounds_s']:>9.2f}" if "rounds_s" in row else f"{'-':>9}"
        r_b = f"{row['rounds_blocks']:>8}" if "rounds_blocks" in row else f"{'-':>8}"
        r_r = f"{row['rounds_s'] / t:>9.1f}" if "rounds_s" in row else f"{'-':>9}"
        print(f"{mdp.n_states:>9} {part.n_blocks:>7} {t:>10.2f} {t_ex:>8.2f} {t / t_ex:>8.2f} "
              f"{r_s} {r_b} {r_r} {stable:>12}", flush=True)
        del model
    if len(drows) >= 2:
        a, b = drows[0], drows[-1]
        expo = math.log(b["seconds"] / a["seconds"]) / math.log(b["states"] / a["states"])
        ex_expo = math.log(b["exact_s"] / a["exact_s"]) / math.log(b["states"] / a["states"])
        print(f"scaling exponent (time ~ states^x) {a['states']:,} to {b['states']:,}: "
              f"worklist x = {expo:.2f}, exact lumping x = {ex_expo:.2f}")
        olds = [r for r in drows if "rounds_s" in r]
        if len(olds) >= 2:
            a, b = olds[0], olds[-1]
            expo_r = math.log(b["rounds_s"] / a["rounds_s"]) / math.log(b["states"] / a["states"])
            print(f"  round-based refiner {a['states']:,} to {b['states']:,}: x = {expo_r:.2f}")
    if storm:
        mdp = lumpable_grid_mdp(delta_sizes[0])
        t0, part0 = _best(lambda: refine(Partition.from_labels(
            mdp.R[:, 0].astype(np.int64), mdp.admissible), mdp, delta=0.0, epsilon=0.0), repeats)
        st = storm_bisimulation(mdp)
        print(f"refine(delta=0, epsilon=0) on lumpable_grid_mdp({delta_sizes[0]:_}): {t0:.3f} s, "
              f"{part0.n_blocks} blocks; Storm {st['bisim_s']:.3f} s, {st['blocks']} blocks; "
              f"adpart/Storm = {t0 / st['bisim_s']:.2f}")
    return {"lumping": rows, "delta": drows}


if __name__ == "__main__":
    main()
