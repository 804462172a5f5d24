#!/usr/bin/env python
"""Scans analysed without their calibration: the width law read from the scan against the given one.

Each scene is analysed three times with default settings, the scale and the hole given:

- ``given``: with the generator's width law as the calibration (what the other sweeps do);
- ``fitted``: without a calibration, the law read from the scan (the default,
  ``crosssection.stages.widthlaw``);
- ``linear``: without a calibration, ``width_law="linear"`` (n layers read as n h wide).

Scenes: the conditions of ``benchmarks/robust_sweep.py`` (network scenes drawn with the
generators' law ``h (n + 0.4 sqrt n)``, and simulator renders); typical network scenes drawn
with other width laws (``--laws``): ``nh`` (w = n h), ``step1.3`` (0.05 h + 1.3 h n),
``sqrt1.0`` (h (n + sqrt n)), ``step1.6`` (1.6 h n), ``step0.9`` (0.5 h + 0.9 h n), ``quad``
(h (0.3 + 1.2 n + 0.01 n^2)), ``sqrt2`` (h (n + 2 sqrt n): one layer 3 h), ``rim1.4`` (h (n +
1.4)), ``thin0.55`` (h (n - 0.45)) and ``saturating`` (8 h (1 - exp(-n / 5))); typical
network scenes whose stacks' widths scatter about the generators' law from stack to stack
(``--scatters``, relative: a cut's rim varies; ``make_scene(width_scatter=...)``); and
typical scenes analysed without a calibration with ``px_per_mm`` given wrong by a factor
(``--scales``; the calibration's analysis keeps the right one; rod lengths scored in pixels);
and ``blurred`` scenes beyond what the pipeline reads even with its calibration (25-40 px/mm,
blur 2-3 px, noise 20-45; ``--per-blurred``).

Usage: python benchmarks/width_law_check.py [--conditions typical,lowres,thick_dense,renders]
       [--laws nh,step1.3,...] [--per-condition 6] [--per-law 3]
       [--scatters 0.06,0.1] [--per-scatter 4] [--scales 0.7,1.4] [--per-scale 3]
       [--per-blurred 8] [--seed 100] [--workers 2] [--out DIR]
Writes DIR/width_law.csv (one row per scene and analysis: rod length error, junction F1, exact
n_br on stack length, energy error, the law read: offset a/h, step b/h, lattice contrast,
junctions, the share of them its counts conserve and the share under w = n h, reason when
refused) and prints the medians per scene set and analysis.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

CONDITIONS = ("typical", "lowres", "thick_dense", "renders")
H = 0.1
LAWS = {
    "nh": lambda n: H * n,
    "step1.3": lambda n: H * (0.05 + 1.3 * n),
    "sqrt1.0": lambda n: H * (n + np.sqrt(n)),
    "step1.6": lambda n: 1.6 * H * n,
    "step0.9": lambda n: H * (0.5 + 0.9 * n),
    "quad": lambda n: H * (0.3 + 1.2 * n + 0.01 * n ** 2),
    "sqrt2": lambda n: H * (n + 2.0 * np.sqrt(n)),
    "rim1.4": lambda n: H * (n + 1.4),
    "thin0.55": lambda n: H * (n - 0.45),
    "saturating": lambda n: 8.0 * H * (1.0 - np.exp(-n / 5.0)),
}
ANALYSES = ("given", "fitted", "linear")


def _scene(kind: str, name: str, seed: int):
    import robust_sweep as rs
    from crosssection.core.calibration import Calibration
    from crosssection.truth.network import make_scene

    if kind == "condition":
        if name == "renders":
            return rs._render_scene(seed)
        return rs.make_network_scene(seed, rs.scene_options(name, seed))
    opt = rs.scene_options("typical", seed)
    if kind == "scale":
        return rs.make_network_scene(seed, opt)
    if kind == "blurred":
        # beyond what the pipeline reads with its calibration: blur 2-3 px, noise 20-45
        rng = np.random.default_rng(seed + 11)
        return make_scene(seed=seed, n_stacks=40, max_layers=6,
                          px_per_mm=float(rng.choice([25.0, 30.0, 35.0, 40.0])),
                          blur_px=float(rng.uniform(2.0, 3.0)),
                          noise_sigma=float(rng.uniform(20.0, 45.0)))
    if kind == "scatter":
        scene = make_scene(seed=seed, **opt["scene"], width_scatter=float(name))
        return rs.with_backdrop(scene, np.random.default_rng(seed + 7), **opt["backdrop"])
    n = np.arange(1, 41.0)
    scene = make_scene(seed=seed, **opt["scene"],
                       calibration=Calibration(tuple(n), tuple(LAWS[name](n))))
    return rs.with_backdrop(scene, np.random.default_rng(seed + 7), **opt["backdrop"])


def run_one(kind: str, name: str, seed: int) -> list[dict]:
    """Generate one scene, analyse it three ways and score each; its rows."""
    import crosssection
    from crosssection.truth.scoring import score

    scene = _scene(kind, name, seed)
    p = scene.params
    h_px = p["thickness_mm"] * p["px_per_mm"]
    # a scale given wrong by a factor f (kind "scale") to the analyses without a calibration:
    # the hole stays where it is on the scan, and the rod length is scored in pixels
    factor = float(name) if kind == "scale" else 1.0
    rows = []
    for analysis in ANALYSES:
        f = 1.0 if analysis == "given" else factor
        base = dict(px_per_mm=p["px_per_mm"] * f, thickness_mm=p["thickness_mm"])
        if p.get("hole_radius_mm"):
            base.update(hole_radius_mm=p["hole_radius_mm"] / f,
                        hole_center_px=tuple(p["hole_center_px"]))
        extra = {"given": dict(calibration=scene.calibration), "fitted": {},
                 "linear": dict(width_law="linear")}[analysis]
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = crosssection.analyze(scene.rgb, **base, **extra)
        t = time.perf_counter() - t0
        s = score((res.summary, res.tables), (scene.summary, scene.tables), match_px=3 * h_px)
        law = res.summary.get("width_law") or {}
        h = p["thickness_mm"]
        rows.append({"scenes": kind, "name": name, "seed": seed, "analysis": analysis,
                     "rod_length_rel_error": (1.0 + s["rod_length_rel_error"]) * f - 1.0,
                     "junction_f1": s["junction_f1"],
                     "n_br_exact_length_fraction": s["n_br_exact_length_fraction"],
                     "total_energy_rel_error": s["total_energy_rel_error"],
                     "offset_h": law["offset_mm"] / h if law.get("offset_mm") is not None
                     else np.nan,
                     "step_h": law["step_mm"] / h if law.get("step_mm") is not None else np.nan,
                     "contrast": law.get("contrast", np.nan),
                     "closure": law.get("closure", np.nan),
                     "closure_linear": law.get("closure_linear", np.nan),
                     "law_junctions": law.get("n_junctions", np.nan),
                     "law_reason": law.get("reason", ""), "analyze_s": t})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conditions", default=",".join(CONDITIONS))
    ap.add_argument("--laws", default=",".join(LAWS))
    ap.add_argument("--per-condition", type=int, default=6)
    ap.add_argument("--per-law", type=int, default=3)
    ap.add_argument("--scatters", default="0.06,0.1")
    ap.add_argument("--per-scatter", type=int, default=4)
    ap.add_argument("--scales", default="0.7,1.4",
                    help="factors px_per_mm is given wrong by, without a calibration")
    ap.add_argument("--per-scale", type=int, default=3)
    ap.add_argument("--per-blurred", type=int, default=8)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    args = ap.parse_args(argv)
    conds = [c for c in args.conditions.split(",") if c]
    laws = [c for c in args.laws.split(",") if c]
    bad = sorted(set(conds) - set(CONDITIONS)) + sorted(set(laws) - set(LAWS))
    if bad:
        ap.error(f"unknown condition(s) or law(s): {', '.join(bad)}")
    jobs = [("condition", c, args.seed + i) for c in conds for i in range(args.per_condition)]
    jobs += [("law", w, args.seed + i) for w in laws for i in range(args.per_law)]
    jobs += [("scatter", f"{float(x):g}", args.seed + i)
             for x in args.scatters.split(",") if x for i in range(args.per_scatter)]
    jobs += [("scale", f"{float(x):g}", args.seed + i)
             for x in args.scales.split(",") if x for i in range(args.per_scale)]
    jobs += [("blurred", "2-3px", args.seed + i) for i in range(args.per_blurred)]
    t0 = time.perf_counter()
    if args.workers > 1:
        import multiprocessing as mp

        with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as ex:
            results = list(ex.map(run_one, *zip(*jobs)))
    else:
        results = [run_one(*j) for j in jobs]
    df = pd.DataFrame([r for rows in results for r in rows])
    from crosssection.core.fileio import write_csv

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "width_law.csv", df)
    g = df.groupby(["scenes", "name", "analysis"], sort=False)
    summary = g.agg(n=("seed", "size"),
                    rod_abs=("rod_length_rel_error", lambda x: np.median(np.abs(x))),
                    rod_max=("rod_length_rel_error", lambda x: np.max(np.abs(x))),
                    f1_min=("junction_f1", "min"),
                    nbr_min=("n_br_exact_length_fraction", "min"),
                    energy=("total_energy_rel_error", "median"),
                    step_h=("step_h", "median"),
                    refused=("law_reason", lambda x: int((x.astype(str) != "").sum())))
    pd.set_option("display.width", 200)
    print(summary.to_string(float_format=lambda v: f"{v:.3f}"))
    print(f"{len(jobs)} scenes in {time.perf_counter() - t0:.0f} s -> {out / 'width_law.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
