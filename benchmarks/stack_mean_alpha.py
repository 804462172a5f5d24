#!/usr/bin/env python
"""How much of a scan's alpha_e comes from giving every branch of a stack its stack's energy.

A scan reads one curvature per stack (the paper's method), so the branches of a stack share
one energy; a simulated rod's branches each have their own. This script fits the Gamma shape
alpha_e (location 0, energies > 0) of the render truth's branch energies as they are, of the
same branches given their stack's mean energy, and of the scans' branch energies.

Usage::

    python -m simulate quench --n-configs 48 --seed 11 --workers 1 --out sim
    python -m simulate render sim --out scenes --limit 20 --seed 5
    python -m crosssection batch scenes --out batch --workers 1
    python benchmarks/stack_mean_alpha.py scenes batch

Measured (seeds as above, 20 renders): alpha_e 0.45 per branch, 0.55 with stack means, 0.55
on the scans.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd
from scipy import stats


def alpha(energy) -> float:
    """Gamma shape of the positive energies (location fixed at 0)."""
    e = pd.to_numeric(pd.Series(energy), errors="coerce").dropna()
    e = e[e > 0].to_numpy(float)
    return float(stats.gamma.fit(e, floc=0)[0]) if len(e) >= 2 else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenes", type=Path, help="folder of `simulate render` (config_*/truth/)")
    ap.add_argument("batch", type=Path, help="folder of `crosssection batch` on those scenes")
    args = ap.parse_args(argv)
    truth, scans = [], []
    for d in sorted(args.scenes.glob("config_*")):
        found = sorted((args.batch / "scenes").glob(f"{d.name}__*/branches.csv"))
        if not (d / "truth" / "branches.csv").is_file() or not found:
            continue
        t = pd.read_csv(d / "truth" / "branches.csv")
        t["config"] = d.name
        s = pd.read_csv(found[0])
        truth.append(t)
        scans.append(s)
    if not truth:
        print("no scene with both a truth and an analysis", file=sys.stderr)
        return 2
    t = pd.concat(truth, ignore_index=True)
    s = pd.concat(scans, ignore_index=True)
    mean = t.groupby(["config", "stack_id"])["energy"].transform("mean")
    print(f"{len(truth)} scenes, {len(t)} true branches, {len(s)} measured")
    print(f"alpha_e, true branches:                 {alpha(t['energy']):.3f}")
    print(f"alpha_e, true branches at stack means:  {alpha(mean):.3f}")
    print(f"alpha_e, scans:                         {alpha(s['energy']):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
