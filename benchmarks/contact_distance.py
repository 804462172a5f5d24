#!/usr/bin/env python
"""The contact distance swept on one compaction ensemble: what counts as a stack.

Every configuration of ``SIM/rods.npz`` (the output of ``python -m simulate compact``) is
analysed by :func:`simulate.contacts.analyze_rod` with the contact distance set to each factor
times the rod's thickness (the minimum contact run follows it, as in the default analysis), and
one row per factor is written: the means over configurations of N_l (stacks), N_br
(branches), N_J (junctions), <n_br> (branches per stack), the number of voids and
<sqrt(s)/p>, with the standard error of the mean over configurations (``*_sem``) for N_l and
N_br.

Usage::

    python benchmarks/contact_distance.py --sim DIR --factors 1.5 2 3 4 --workers 2 \\
        --out docs/validation/compact_contact_distance.csv
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from crosssection.core.fileio import write_csv  # noqa: E402
from simulate.contacts import analyze_rod  # noqa: E402


def _one(task):
    """Counts of one configuration analysed at one contact distance."""
    xy, factor, thickness = task
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = analyze_rod(xy, lam=0.0, contact_distance=factor * thickness)
    v = a.voids
    ratio = (np.sqrt(v["area"]) / v["perimeter"]).to_numpy(float) if len(v) else np.zeros(0)
    return {"factor": factor, "n_stacks": a.n_stacks, "n_branches": a.n_branches,
            "n_junctions": a.n_junctions,
            "n_br_mean": a.n_branches / a.n_stacks if a.n_stacks else np.nan,
            "n_voids": a.n_voids, "sqrt_s_over_p": float(ratio.mean()) if len(ratio) else np.nan}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sim", required=True, help="output folder of `python -m simulate compact`")
    ap.add_argument("--factors", type=float, nargs="+", default=[1.5, 2.0, 3.0, 4.0],
                    help="contact distances in units of the rod's thickness")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", required=True, help="CSV written (one row per factor)")
    a = ap.parse_args(argv)
    sim = Path(a.sim)
    thickness = float(json.loads((sim / "params.json").read_text())["thickness"])
    with np.load(sim / "rods.npz") as rods:
        xys = [np.asarray(rods[k], float) for k in sorted(rods.files)]
    tasks = [(xy, f, thickness) for f in a.factors for xy in xys]
    with ProcessPoolExecutor(max_workers=a.workers) as ex:
        rows = pd.DataFrame(list(ex.map(_one, tasks)))
    g = rows.groupby("factor")
    out = g.mean()
    for col in ("n_stacks", "n_branches"):
        out[f"{col}_sem"] = g[col].std(ddof=1) / np.sqrt(g[col].count())
    out["n_configs"] = g.size()
    out = out.reset_index()
    write_csv(Path(a.out), out)
    print(out.round(3).to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
