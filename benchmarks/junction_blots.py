#!/usr/bin/env python
"""The ``junction_blot`` check's measure on scans without blots, and on blotted ones.

For every junction: the radius of the ink disc inscribed there over half the width of its
widest stack (:func:`crosssection.quality.junction_blot_ratios`). Scans of the network
generator (typical, 25 px/mm, thick dense, tangential forks, the simulator's renders; seeds 100-103)
and of the independent generator (typical, thick, 25 px/mm, peels, thick dense; seeds
100-102), default settings with their calibration; then typical network scans with a disc of
ink of 0.6 and 0.9 mm radius drawn over the hole's centre (seeds 1-4: a blot lying in a void
is dropped by the cleaning and changes nothing; one over the network is what the check is
for). Prints the median, the 99th percentile and the largest ratio per condition, and the
scans flagged.

Usage: python benchmarks/junction_blots.py [--workers 2]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _ratios(res) -> tuple[list, bool]:
    """Per junction, the check's ratio (the pipeline's distance map of the cleaned ink), and
    whether the analysis raised the flag."""
    from crosssection.pipeline import _inscribed_radius_px
    from crosssection.quality import junction_blot_ratios
    from crosssection.stages.widths import distance_map

    radius = _inscribed_radius_px(distance_map(res.mask_clean), res.junctions)
    ratios = junction_blot_ratios(radius, res.junctions, res.stacks, res.params.px_per_mm)
    return ratios.tolist(), "junction_blot" in res.summary["quality"]["codes"]


def network(condition: str, seed: int, blot_mm: float = 0.0):
    import cv2
    import robust_sweep as rs

    import crosssection

    warnings.simplefilter("ignore")
    opts = rs.scene_options(condition, seed)
    scene = rs._render_scene(seed) if condition == "renders" else rs.make_network_scene(seed,
                                                                                         opts)
    p = scene.params
    rgb = scene.rgb
    if blot_mm:
        rgb = rgb.copy()
        cx, cy = p["hole_center_px"]
        cv2.circle(rgb, (int(cx), int(cy)), int(round(blot_mm * p["px_per_mm"])),
                   (40, 60, 170), -1)
    res = crosssection.analyze(rgb, px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
                               calibration=scene.calibration)
    name = f"network {condition}" + (f", blot {blot_mm:g} mm" if blot_mm else "")
    return (name, *_ratios(res))


def independent(condition: str, seed: int, folder: str):
    import independent_scenes as gen

    import crosssection

    warnings.simplefilter("ignore")
    folder = Path(folder)
    name = gen.scene_name(seed, condition)
    gen.generate(seed, condition, folder)
    truth = json.loads((folder / f"{name}.json").read_text())
    res = crosssection.analyze(str(folder / f"{name}.png"), px_per_mm=truth["px_per_mm"],
                               thickness_mm=truth["thickness_mm"],
                               calibration=str(folder / "calibration.csv"))
    return (f"independent {condition}", *_ratios(res))


def _run(workers: int, folder: str) -> dict:
    jobs = [(network, (c, s)) for c in ("typical", "lowres", "thick_dense", "tangential",
                                        "renders") for s in range(100, 104)]
    jobs += [(independent, (c, s, folder)) for c in ("typical", "thick", "lowres", "peel",
                                                      "thick_dense") for s in range(100, 103)]
    jobs += [(network, ("typical", s, b)) for b in (0.6, 0.9) for s in range(1, 5)]
    rows: dict = {}
    with ProcessPoolExecutor(workers) as ex:
        for fut in [ex.submit(f, *a) for f, a in jobs]:
            name, ratios, flagged = fut.result()
            r = rows.setdefault(name, {"ratios": [], "scans": 0, "flagged": 0})
            r["ratios"] += ratios
            r["scans"] += 1
            r["flagged"] += int(flagged)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    import independent_scenes as gen

    with tempfile.TemporaryDirectory(prefix="junction-blots-") as folder:
        gen.write_calibration(Path(folder) / "calibration.csv")
        rows = _run(args.workers, folder)
    print(f"{'scans':34s} {'junctions':>9s} {'median':>7s} {'p99':>6s} {'max':>6s}  flagged")
    for name, r in rows.items():
        a = np.asarray(r["ratios"])
        a = a[np.isfinite(a)]  # a junction whose stacks hold no measured width
        print(f"{name:34s} {len(a):9d} {np.median(a):7.2f} {np.percentile(a, 99):6.2f} "
              f"{a.max():6.2f}  {r['flagged']} of {r['scans']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
