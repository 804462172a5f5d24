"""Benchmark of stage 9 (crosssection.linsys.solve_branch_counts) against np.linalg.lstsq.

Plain script: ``python benchmarks/bench_linsys.py [--sizes 20 100 ...] [--repeat 3]``.
For every size a random stack network with known n_br (``crosssection.truth.graphs``) gets
width estimates with 0.3-layer noise; we time the full solver (equations, rank, condition
number, residual, integer search) and, on the same run, np.linalg.lstsq on the paper's dense
M x M system [C; I_S] (rows scaled to unit norm) that the solver reports on, and the exact
MILP (``method="milp"``, up to ``--milp-max`` stacks). The table prints the ratio
solver / lstsq, the MILP time, whether both give the same n_br, and the fraction of stacks
recovered exactly.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from crosssection.linsys import conservation_equations, solve_branch_counts  # noqa: E402
from crosssection.truth.graphs import random_network  # noqa: E402


def paper_matrix(fg, res, est):
    hard, soft, _, _ = conservation_equations(fg, fg.packs, est, np.full(len(est), 0.3))
    M = len(fg.paths)
    rows = [r for _, r in hard + soft]
    sel = np.flatnonzero(res.fixed_by_width)
    A = np.zeros((len(rows) + len(sel), M))
    for j, r in enumerate(rows):
        for s, c in r.items():
            A[j, s] = c
        A[j] /= np.linalg.norm(A[j])
    A[len(rows) + np.arange(len(sel)), sel] = 1.0
    b = np.concatenate([np.zeros(len(rows)), np.maximum(np.round(est[sel]), 1)])
    return A, b


def best_of(fn, repeat):
    t = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        t.append(time.perf_counter() - t0)
    return min(t), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[20, 50, 100, 200, 500, 1000, 2000])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--milp-max", type=int, default=600)
    args = ap.parse_args(argv)
    print(f"{'M':>6} {'K':>6} {'solve_s':>9} {'lstsq_s':>9} {'ratio':>7} {'rank':>6} "
          f"{'cond':>9} {'exact':>6} {'round':>6} {'milp_s':>8} {'same':>5}")
    for i, target in enumerate(args.sizes):
        fg = random_network(args.seed + i, n_junctions=max(4, int(target / 1.15)), n_free=6)
        M = len(fg.paths)
        rng = np.random.default_rng(args.seed + 1000 + i)
        est = fg.n_true + rng.normal(0, 0.3, M)
        t_solve, res = best_of(lambda: solve_branch_counts(fg, fg.packs, est), args.repeat)
        A, b = paper_matrix(fg, res, est)
        t_ls, _ = best_of(lambda: np.linalg.lstsq(A, b, rcond=None), args.repeat)
        exact = np.mean(res.n_br == fg.n_true)
        rnd = np.mean(np.maximum(np.round(est), 1) == fg.n_true)
        t_milp, same = float("nan"), ""
        if M <= args.milp_max:
            t_milp, ref = best_of(lambda: solve_branch_counts(fg, fg.packs, est, method="milp",
                                                              time_limit_s=60), 1)
            same = "yes" if np.array_equal(ref.n_br, res.n_br) else "no"
        print(f"{M:6d} {len(fg.packs):6d} {t_solve:9.4f} {t_ls:9.4f} {t_solve / t_ls:7.2f} "
              f"{res.rank:6d} {res.condition_number:9.3g} {exact:6.3f} {rnd:6.3f} "
              f"{t_milp:8.3f} {same:>5}")


if __name__ == "__main__":
    main()
