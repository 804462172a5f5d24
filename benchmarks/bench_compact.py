"""Time of the ``compact`` protocol against the compaction rate epsilon and the segments N.

    python benchmarks/bench_compact.py [--grid 8:2000,19:2000,30:2000,19:1000,19:4000]
        [--seeds 1] [--hold-iter H] [--out benchmarks/out]

Every (epsilon, N) of the grid is compacted from ``--seeds`` initial shapes (seeds 0, 1, ...)
by :func:`simulate.compact.compact_rod` in this process, one after the other (one core).
Records per configuration: CPU time (``time.process_time``, what one core spends, whatever
else runs on the machine), wall time, iterations, levels, iterations and final force over
``2 ds / R^3`` of the final hold (``hold_iter`` default or ``--hold-iter``), the epsilon reached
and the final checks (smallest distance between non-adjacent segments over h, largest radius over R - h/2,
length); a compaction that fails its checks is recorded with its error. Writes ``OUT/bench_compact.csv`` and ``OUT/bench_compact.png`` (CPU time against
epsilon at fixed N and against N at fixed epsilon). Numba compiles outside the timings.

Measured: see ``docs/validation/compact.md``.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.errors import AnalysisError
from crosssection.core.fileio import save_figure, write_csv
from simulate.compact import CompactParams, compact_rod


def _grid(text):
    out = []
    for item in text.split(","):
        eps, n = item.split(":")
        out.append((float(eps), int(n)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grid", type=_grid, default=_grid("8:2000,19:2000,30:2000,19:1000,19:4000"),
                    help="comma-separated epsilon:N pairs")
    ap.add_argument("--seeds", type=int, default=1, help="configurations per grid point")
    ap.add_argument("--hold-iter", type=int, default=CompactParams.hold_iter,
                    help="iterations allowed to the final hold (default "
                         f"{CompactParams.hold_iter})")
    ap.add_argument("--out", default=str(Path(__file__).parent / "out"))
    a = ap.parse_args(argv)
    out = Path(a.out)
    compact_rod(CompactParams(epsilon=2.0, n_segments=64), np.random.default_rng(0))  # compile
    rows = []
    for eps, n in a.grid:
        for seed in range(a.seeds):
            p = CompactParams(epsilon=eps, n_segments=n, hold_iter=a.hold_iter)
            c0, w0 = time.process_time(), time.perf_counter()
            try:
                r = compact_rod(p, np.random.default_rng(seed))
            except AnalysisError as exc:  # a failed compaction is a result of the benchmark
                rows.append(dict(epsilon=eps, n_segments=n, seed=seed,
                                 cpu_s=time.process_time() - c0,
                                 wall_s=time.perf_counter() - w0, error=str(exc)))
                print(f"epsilon={eps:g} n_segments={n} seed={seed} FAILED: {exc}", flush=True)
                write_csv(out / "bench_compact.csv", pd.DataFrame(rows))
                continue
            cpu, wall = time.process_time() - c0, time.perf_counter() - w0
            row = dict(epsilon=eps, n_segments=n, seed=seed, cpu_s=cpu, wall_s=wall,
                       iterations=r.stats["iterations"], levels=r.stats["levels"],
                       hold_iterations=r.stats["hold_iterations"], force=r.stats["force"],
                       epsilon_reached=1.0 / (2.0 * np.pi * r.wall_radius),
                       min_distance_over_h=r.min_distance / r.thickness,
                       max_radius_over_limit=r.max_radius / (r.wall_radius - r.thickness / 2),
                       length=r.length, energy_bending=r.energy_bending)
            rows.append(row)
            print(" ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                           for k, v in row.items()), flush=True)
            write_csv(out / "bench_compact.csv", pd.DataFrame(rows))
    df = pd.DataFrame(rows)
    ok = df[df["error"].isna()] if "error" in df else df
    _plot(ok, out / "bench_compact.png")
    print(ok.groupby(["epsilon", "n_segments"])[["cpu_s", "wall_s", "iterations"]].mean()
          .to_string())


def _plot(df, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    m = df.groupby(["epsilon", "n_segments"]).cpu_s.mean().reset_index()
    n_ref = m.n_segments.mode().iloc[0]
    e = m[m.n_segments == n_ref]
    a1.plot(e.epsilon, e.cpu_s, "o-")
    a1.set(xlabel="epsilon = L / (2 pi R)", ylabel="CPU s per configuration",
           title=f"N = {n_ref}")
    eps_ref = m.epsilon.mode().iloc[0]
    s = m[m.epsilon == eps_ref]
    a2.plot(s.n_segments, s.cpu_s, "o-")
    a2.set(xlabel="segments N", ylabel="CPU s per configuration", title=f"epsilon = {eps_ref:g}")
    for ax in (a1, a2):
        ax.axhline(300, color="grey", ls="--", lw=0.8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
