#!/usr/bin/env python
"""The scan's curvature noise floor, measured against its true value, at several resolutions.

The window fit's curvature noise ``v`` (``crosssection.stages.curvature.noise_variance``) is
measured on each scan from the curvature differences along its own stacks, and is what the
fork zones' trend test compares a slope with (``_fill_fork_zones``). Two measurements per
resolution (px/mm, layer thickness 0.1 mm):

* **arcs**: four single-layer arcs of constant curvature (radius 4.8-6 mm, 150 degrees each),
  drawn anti-aliased in blue ink on paper with a typical scan's defects (blur 0.75 px, noise
  5, JPEG 90), analysed with default settings. Their true window-fit noise is the variance of
  the measured curvature over each arc's fitted part (its curvature is constant); the
  estimate is the floor the analysis recorded for their window.
* **network**: the robust sweep's typical scenes (``benchmarks/robust_sweep.py``) drawn at the
  same scale: the floor recorded for single-layer stacks, how many stacks it was pooled from,
  and the total-energy error.

Usage: python benchmarks/noise_floor_check.py [--px-per-mm 25,35,50] [--seeds 4]
       [--scenes 100-108] [--workers 2] [--out benchmarks/out]
Writes OUT/noise_floor_check.csv (one row per scan).
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

THICKNESS_MM = 0.1


def arcs_scan(px_per_mm: float, seed: int, *, radius_mm: float = 6.0):
    """Four single-layer arcs (w(1) = 1.4 h wide) with a typical scan's defects."""
    from crosssection.truth.degrade import finish_scan

    rng = np.random.default_rng(seed)
    h = THICKNESS_MM * px_per_mm
    w = h * (1 + 0.4)
    cell = 2 * radius_mm + 3.0
    size = int(2 * cell * px_per_mm)
    rr, cc = np.mgrid[0:size, 0:size].astype(np.float32)
    cov = np.zeros((size, size), np.float32)
    for i in range(2):
        for j in range(2):
            cy = (i + 0.5) * cell * px_per_mm + rng.uniform(-2, 2)
            cx = (j + 0.5) * cell * px_per_mm + rng.uniform(-2, 2)
            r = radius_mm * px_per_mm * rng.uniform(0.8, 1.0)
            d = np.hypot(rr - cy, cc - cx)
            a0 = rng.uniform(-np.pi, np.pi)
            arc = np.cos(np.arctan2(rr - cy, cc - cx) - a0) > np.cos(np.radians(75))
            cov = np.maximum(cov, np.clip(w / 2 - np.abs(d - r) + 0.5, 0, 1) * arc)
    ink = np.array([40, 60, 170], np.float32)
    paper = np.array([240, 238, 230], np.float32)
    img = paper * (1 - cov[..., None]) + ink * cov[..., None]
    return finish_scan(img, rng, blur_px=0.75, noise_sigma=5.0, jpeg_quality=90), size


def _single_layer_floor(res) -> tuple[float, int]:
    """The floor recorded for single-layer stacks and the number of such stacks."""
    n = res.stacks["n_br"].to_numpy(int)
    v = [p.noise_var_per_mm2 for p, k in zip(res.profiles, n) if k == 1]
    return (float(v[0]) if v else np.nan), len(v)


def run_arcs(px_per_mm: float, seed: int) -> dict:
    import crosssection
    from crosssection.core.calibration import Calibration

    rgb, size = arcs_scan(px_per_mm, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(rgb, px_per_mm=px_per_mm, thickness_mm=THICKNESS_MM,
                                   calibration=Calibration.nonlinear(THICKNESS_MM),
                                   hole_radius_mm=0.7 * size / px_per_mm,
                                   hole_center_px=(size / 2, size / 2))
    num = den = 0.0
    for p in res.profiles:
        k = p.kappa_per_mm[p.fit_start:p.fit_stop]
        if len(k) > 50:
            num += float(np.var(k)) * len(k)
            den += len(k)
    v, n = _single_layer_floor(res)
    return {"kind": "arcs", "px_per_mm": px_per_mm, "seed": seed, "true_noise": num / den,
            "estimate": v, "single_layer_stacks": n}


def run_network(px_per_mm: float, seed: int) -> dict:
    from robust_sweep import make_network_scene, scene_options

    import crosssection
    from crosssection.truth.scoring import score

    opts = scene_options("typical", seed, px_per_mm=px_per_mm)
    scene = make_network_scene(seed, opts)
    p = scene.params
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(scene.rgb, px_per_mm=px_per_mm, thickness_mm=p["thickness_mm"],
                                   calibration=scene.calibration,
                                   hole_radius_mm=p["hole_radius_mm"],
                                   hole_center_px=tuple(p["hole_center_px"]))
    s = score((res.summary, res.tables), (scene.summary, scene.tables),
              match_px=3 * p["thickness_mm"] * px_per_mm)
    v, n = _single_layer_floor(res)
    return {"kind": "network", "px_per_mm": px_per_mm, "seed": seed, "estimate": v,
            "single_layer_stacks": n, "total_energy_rel_error": s["total_energy_rel_error"],
            "blur_px": opts["scene"].get("blur_px"), "noise_sigma": opts["scene"].get("noise_sigma")}


def _job(args):
    kind, ppm, seed = args
    return run_arcs(ppm, seed) if kind == "arcs" else run_network(ppm, seed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--px-per-mm", default="25,35,50")
    ap.add_argument("--seeds", type=int, default=4, help="arc scans per resolution")
    ap.add_argument("--scenes", default="100-108", help="network seeds, lo-hi (hi excluded)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    a = ap.parse_args(argv)
    from crosssection.core.parallel import get_executor

    ppms = [float(x) for x in a.px_per_mm.split(",")]
    lo, hi = (int(x) for x in a.scenes.split("-"))
    jobs = [("arcs", q, s) for q in ppms for s in range(a.seeds)]
    jobs += [("network", q, s) for q in ppms for s in range(lo, hi)]
    with get_executor(a.workers, None) as ex:
        df = pd.DataFrame(list(ex.map(_job, jobs)))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "noise_floor_check.csv", index=False)
    for q in ppms:
        ar = df[(df.kind == "arcs") & (df.px_per_mm == q)]
        nw = df[(df.kind == "network") & (df.px_per_mm == q)]
        print(f"{q:g} px/mm: arcs true {ar.true_noise.median():.4f} /mm^2, estimated "
              f"{ar.estimate.median():.4f}; network scenes' single-layer floor median "
              f"{nw.estimate.median():.4f} (range {nw.estimate.min():.4f}-{nw.estimate.max():.4f}), "
              f"energy error median {nw.total_energy_rel_error.median():+.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
