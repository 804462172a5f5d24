#!/usr/bin/env python
"""Stacks bending near the tightest bend their layers allow: how close each scan comes.

A band of ``n_br`` layers of thickness h cannot bend tighter than ``2 / (n_br h)`` (its
innermost layer would reach zero radius). For every scan this prints the largest ratio of a
stack's mean curvature ``kappa_plus`` to that bound, and the share of the scan's total
bending energy carried by the stacks at 0.6, 0.7, 0.8 and 0.9 of it: what the
``tight_bends`` check of ``crosssection.quality`` (``TIGHT_BEND_RATIO``,
``TIGHT_BEND_SHARE``) is set against.

Either generated scenes (the conditions of ``benchmarks/robust_sweep.py``, analysed with
default settings, hole given) or analysis output folders (``summary.json`` and
``stacks.csv``, as ``foldstat analyze`` or ``batch`` writes them).

Usage: python benchmarks/tight_bends.py [--conditions typical,lowres,thick_dense,renders,tangential]
       [--seed 100] [--per-condition 8] [--folders DIR ...]
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

RATIOS = (0.6, 0.7, 0.8, 0.9)


def bound_shares(stacks: pd.DataFrame, thickness_mm: float) -> tuple[dict, float]:
    """Energy share of the stacks at each ratio of :data:`RATIOS` or more, and the largest
    ratio, of one scan's stack table."""
    n = stacks["n_br"].to_numpy(float)
    ratio = stacks["kappa_plus"].to_numpy(float) * np.maximum(n, 1.0) * thickness_mm / 2.0
    e = (stacks["energy_per_branch"] * stacks["n_br"]).to_numpy(float)
    total = float(np.nansum(e))
    shares = {r: float(np.nansum(e[ratio >= r]) / total) if total > 0 else 0.0
              for r in RATIOS}
    return shares, float(np.nanmax(ratio)) if len(ratio) else 0.0


def _line(name: str, shares: dict, largest: float) -> str:
    cells = "  ".join(f">= {r:.1f}: {100 * v:5.1f} %" for r, v in shares.items())
    return f"{name:32s} largest ratio {largest:4.2f}   energy share {cells}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conditions", default="typical,lowres,thick_dense,renders,tangential")
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--per-condition", type=int, default=8)
    ap.add_argument("--folders", nargs="*", default=None,
                    help="analysis output folders to read instead of generated scenes")
    args = ap.parse_args(argv)
    if args.folders is not None:
        for folder in map(Path, args.folders):
            summary = json.loads((folder / "summary.json").read_text())
            h = float(summary["parameters"]["thickness_mm"])
            print(_line(folder.name, *bound_shares(pd.read_csv(folder / "stacks.csv"), h)))
        return 0
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import crosssection
    from robust_sweep import _render_scene, make_network_scene, scene_options

    for cond in args.conditions.split(","):
        for seed in range(args.seed, args.seed + args.per_condition):
            opt = scene_options(cond, seed)
            sc = _render_scene(seed) if cond == "renders" else make_network_scene(seed, opt)
            p = sc.params
            kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
                      calibration=sc.calibration)
            if opt["hole_given"] and p.get("hole_radius_mm"):
                kw.update(hole_radius_mm=p["hole_radius_mm"],
                          hole_center_px=tuple(p["hole_center_px"]))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = crosssection.analyze(sc.rgb, **kw)
            print(_line(f"{cond} {seed}", *bound_shares(res.stacks, p["thickness_mm"])),
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
