#!/usr/bin/env python
"""How far a branch turns near a junction: the truth, and the fork zones' continued trend.

The curvature stage bounds a stack's turn over one fork zone (``int |kappa| ds``) by a
quarter turn (``crosssection/stages/curvature.py``, step 3). This script measures what that
bound is against:

* ``--rods DIR`` (a ``python -m simulate compact`` output): the true turn of the rod over the
  first ``ell`` mm of every branch from each of its junction ends (the sum of the turns at the
  rod's nodes there; branches shorter than ``2 ell`` left out), at the renders' scale (h =
  0.1 mm, so ``rod_length_mm = 0.1 / thickness``), for ell = 0.5, 1.4 and 3 mm: quantiles and
  maximum per configuration.
* ``--conditions`` (scenes of ``benchmarks/robust_sweep.py``, the same seeds): the turn of
  every fork zone as the default analysis fills it without the bound (the trend continued, or
  the nearest fitted curvature), and how many zones the bound would scale.

Usage: python benchmarks/zone_turns.py [--rods DIR] [--conditions typical,thick_dense,tangential]
       [--per-condition 3] [--seed 100]
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import robust_sweep  # noqa: E402  (the scene definitions are shared)


def rod_turns(sim_dir, ells_mm=(0.5, 1.4, 3.0)) -> list:
    """Rows (config, ell_mm, ends, median, q90, q99, max) of the true turn near junctions."""
    from simulate.contacts import analyze_rod
    from simulate.geometry import angles

    sim_dir = Path(sim_dir)
    params = json.loads((sim_dir / "params.json").read_text())
    rod_mm = 0.1 / float(params["thickness"])
    rods = np.load(sim_dir / "rods.npz")
    rows = []
    for key in rods.files:
        xy = rods[key]
        an = analyze_rod(xy, lam=7e5, contact_distance=params.get("contact_distance"))
        n = len(xy) - 1
        dth = np.abs(np.diff(angles(xy)[0]))  # the turn at each inner node
        node_s = np.arange(1, n) / n
        for ell_mm in ells_mm:
            ell = ell_mm / rod_mm
            z = []
            for s0, s1 in an.branches[["s_start", "s_end"]].to_numpy():
                if s1 - s0 < 2 * ell:
                    continue
                for a, b in ((s0, s0 + ell), (s1 - ell, s1)):
                    if a > 1e-9 and b < 1 - 1e-9:  # a junction end, not a rod end
                        z.append(dth[(node_s >= a) & (node_s < b)].sum())
            z = np.asarray(z)
            rows.append((key, ell_mm, len(z), *np.quantile(z, [0.5, 0.9, 0.99]), z.max()))
    return rows


def zone_turns(condition: str, seeds) -> tuple:
    """(zones, zones the bound scales, largest turn) of the unbounded fork zones."""
    import crosssection
    import crosssection.stages.curvature as curvature

    turns = []
    bound = curvature._bound_turns

    def spy(k, s, a, n, z0, z1, edge, limit):
        turns.extend(curvature._zone_turns(k, s, a, n, z0, z1, edge)[1].tolist())
        return bound(k, s, a, n, z0, z1, edge, limit)

    curvature._bound_turns = spy
    try:
        for seed in seeds:
            options = robust_sweep.scene_options(condition, seed)
            scene = robust_sweep.make_network_scene(seed, options)
            p = scene.params
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                crosssection.analyze(scene.rgb, px_per_mm=p["px_per_mm"],
                                     thickness_mm=p["thickness_mm"],
                                     calibration=scene.calibration,
                                     hole_radius_mm=p["hole_radius_mm"],
                                     hole_center_px=tuple(p["hole_center_px"]))
    finally:
        curvature._bound_turns = bound
    t = np.asarray(turns)
    return len(t), int((t > curvature._ZONE_MAX_TURN).sum()), float(t.max(initial=0.0))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rods", help="a python -m simulate compact output folder")
    ap.add_argument("--conditions", default="typical,thick_dense,tangential,lowres")
    ap.add_argument("--per-condition", type=int, default=3)
    ap.add_argument("--seed", type=int, default=100)
    a = ap.parse_args(argv)
    if a.rods:
        print("| configuration | ell (mm) | branch ends | median | 90 % | 99 % | max (rad) |")
        print("|---|---|---|---|---|---|---|")
        for key, ell, m, q50, q90, q99, mx in rod_turns(a.rods):
            print(f"| {key} | {ell:g} | {m} | {q50:.2f} | {q90:.2f} | {q99:.2f} | {mx:.2f} |")
    seeds = range(a.seed, a.seed + a.per_condition)
    print("| condition | fork zones | turning more than a quarter turn | largest turn (rad) |")
    print("|---|---|---|---|")
    for cond in [c for c in a.conditions.split(",") if c]:
        n, over, mx = zone_turns(cond, seeds)
        print(f"| {cond} | {n} | {over} | {mx:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
