#!/usr/bin/env python
"""The compaction protocol swept: segments N, thickness h and the wall's shrink rate, with the
configuration-to-configuration spread beside every mean.

For every point of the grid, ``python -m simulate compact --epsilon E --segments N
--thickness h --wall-rate r --n-configs K --seed S`` is run into ``WORK/N{N}_h{f}_r{r}``
(``f`` = h / default thickness 0.005 R; a re-run resumes), then one row per point is written:
the means of N_l, N_br (configs.csv), n_br (stacks.csv), sqrt(s)/p (voids.csv), l/L and e
(branches.csv), the Gamma shape alpha_e of the branch energies with its bootstrap interval over
branches, <E>, the wall time per configuration, and for N_l, N_br and <E> the standard error
of the mean over configurations (``*_sem``): two points differ only where their means are
further apart than their errors allow.

Usage::

    python benchmarks/compact_protocol.py --segments 1000 2000 --thickness-factors 0.5 1 2 \
        --n-configs 10 --workers 2 --work DIR --out docs/validation/compact_protocol.csv
    python benchmarks/compact_protocol.py --segments 1000 --wall-rates 5e-4 1e-3 2e-3 ...
"""
from __future__ import annotations

import argparse
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from simulate.compact import CompactParams, default_thickness  # noqa: E402


def point_dir(work: Path, n: int, factor: float, rate: float) -> Path:
    return work / f"N{n}_h{factor:g}_r{rate:g}"


def run_point(out: Path, *, epsilon: float, n: int, h: float, rate: float, n_configs: int,
              seed: int, workers: int) -> None:
    """One ensemble, through the command line a user would type (resumes if ``out`` exists)."""
    cmd = [sys.executable, "-m", "simulate", "compact", "--epsilon", f"{epsilon:g}",
           "--segments", str(n), "--thickness", repr(h), "--wall-rate", f"{rate:g}",
           "--n-configs", str(n_configs), "--seed", str(seed), "--workers", str(workers),
           "--no-progress", "--out", str(out)]
    subprocess.run(cmd, check=True, cwd=str(ROOT))


def _sem(x) -> float:
    x = np.asarray(x, float)
    return float(np.std(x, ddof=1) / math.sqrt(len(x))) if len(x) > 1 else float("nan")


def summarize(out: Path, *, n: int, h: float, rate: float) -> dict:
    """One row of the table from an ensemble folder."""
    from crosssection.stats.fits import fit_family

    c = pd.read_csv(out / "configs.csv")
    st = pd.read_csv(out / "stacks.csv")
    br = pd.read_csv(out / "branches.csv")
    vo = pd.read_csv(out / "voids.csv")
    e = br.energy.to_numpy(float)
    fit = fit_family(e[e > 0], "gamma", n_boot=200, seed=0, gof=False)
    lo, hi = fit.ci.get("alpha", (np.nan, np.nan))
    return {"N": n, "h/L": h, "wall_rate": rate, "configs": len(c),
            "N_l": c.n_stacks.mean(), "N_l_sem": _sem(c.n_stacks),
            "N_br": c.n_branches.mean(), "N_br_sem": _sem(c.n_branches),
            "n_br": st.n_br.mean(), "sqrt_s/p": vo.shape_ratio.mean(),
            "l/L": br.length.mean(), "e": e.mean(), "alpha_e": fit.params["alpha"],
            "alpha_lo": lo, "alpha_hi": hi, "E": c.energy_total.mean(),
            "E_sem": _sem(c.energy_total), "wall_s": c.wall_s.mean()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--epsilon", type=float, default=19.0)
    ap.add_argument("--segments", type=int, nargs="+", default=[1000, 2000])
    ap.add_argument("--thickness-factors", type=float, nargs="+", default=[1.0],
                    help="h in units of the default 0.005 R (default 1)")
    ap.add_argument("--wall-rates", type=float, nargs="+", default=[CompactParams.rate])
    ap.add_argument("--n-configs", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--work", required=True, help="folder of the ensembles (resumed)")
    ap.add_argument("--out", required=True, help="CSV written (one row per point)")
    args = ap.parse_args(argv)
    work = Path(args.work)
    rows = []
    for n in args.segments:
        for f in args.thickness_factors:
            for r in args.wall_rates:
                h = f * default_thickness(args.epsilon)
                d = point_dir(work, n, f, r)
                run_point(d, epsilon=args.epsilon, n=n, h=h, rate=r, n_configs=args.n_configs,
                          seed=args.seed, workers=args.workers)
                rows.append(summarize(d, n=n, h=h, rate=r))
                print(pd.DataFrame(rows[-1:]).to_string(index=False, float_format="%.4g"))
    df = pd.DataFrame(rows)
    tmp = Path(args.out).with_suffix(".tmp")
    df.to_csv(tmp, index=False)
    tmp.replace(args.out)
    print(f"{len(df)} points -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
