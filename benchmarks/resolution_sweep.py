#!/usr/bin/env python
"""Resolution: one physical scene scanned at 20 to 100 px/mm, scored against its truth.

Each scene is drawn at every resolution with the same geometry in millimetres (the network
generator from its seed; a quenched rod rendered at the rod length its 50 px/mm render
takes), clean and with a scan's defects (``simulate.render.SCAN_DEFECTS``: noise, blur,
JPEG, smears, specks, pinholes, a plate with a rim, illumination and a colour cast, all fixed
in pixels, so that the blur is milder in millimetres at high resolution). Analysed with
default settings, the scale, thickness, calibration and hole given; scored by
:func:`crosssection.truth.scoring.score` (junctions matched within 3 h). Besides the scores:
each matched stack's ``|log(measured / true energy)|`` (median over the scene), the quality
codes raised and the analysis' wall time (the faster of two runs); for renders, the share of
the truth's energy at rod nodes that fold the rod back within one segment
(:func:`simulate.render.hairpin_nodes`: no drawing shows them) and the total's error
without it.

A statistic that worsens as the resolution rises points at a setting fixed in pixels, or at
a test whose power grows with the pixel count.

Usage: python benchmarks/resolution_sweep.py [--generators network,render]
       [--px-per-mm 20,25,35,50,70,100] [--seeds 1,2,3,4] [--conditions clean,scan]
       [--out DIR]
Writes DIR/resolution_sweep.csv and prints the medians (min, max) over seeds per generator,
condition and resolution.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

#: the sheet thickness of every scene, mm
THICKNESS_MM = 0.1
#: the network scenes by seed: stacks and the most layers a stack holds
NETWORK = {1: dict(n_stacks=40, max_layers=6), 2: dict(n_stacks=80, max_layers=9),
           3: dict(n_stacks=120, max_layers=6), 4: dict(n_stacks=60, max_layers=12)}
#: the resolution a rod's render fixes its rod length at (mm): every resolution draws that rod
ROD_PX_PER_MM = 50.0


def _defects():
    from simulate.render import SCAN_DEFECTS

    finish = {k: SCAN_DEFECTS[k] for k in ("noise_sigma", "blur_px", "jpeg_quality", "smears",
                                           "specks", "pinholes")}
    backdrop = {k: SCAN_DEFECTS[k] for k in ("plate", "rim_px", "illumination", "cast")}
    return finish, backdrop


def network_scene(seed: int, px_per_mm: float, condition: str):
    """The network generator's scene ``seed`` at ``px_per_mm``."""
    from crosssection.truth.network import make_scene
    from simulate.atlas import with_backdrop

    finish, backdrop = _defects()
    kw = dict(NETWORK[(seed - 1) % len(NETWORK) + 1])
    if condition == "scan":
        kw.update(finish)
    scene = make_scene(seed=seed, px_per_mm=px_per_mm, thickness_mm=THICKNESS_MM, **kw)
    if condition == "scan":
        scene = with_backdrop(scene, np.random.default_rng(seed + 7), **backdrop)
    return scene


def render_scene(seed: int, px_per_mm: float, condition: str, rods: dict):
    """A quenched rod (``seed``) rendered at ``px_per_mm``, its rod length that of its render
    at :data:`ROD_PX_PER_MM` (``rods`` caches the rod, its analysis and that length)."""
    from simulate.atlas import quench_rod, render_rod
    from simulate.contacts import analyze_rod
    from simulate.energy import LAMBDA

    if seed not in rods:
        xy = quench_rod(seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rod = analyze_rod(xy, lam=LAMBDA)
            ref = render_rod(xy, seed, rod, px_per_mm=ROD_PX_PER_MM,
                             thickness_mm=THICKNESS_MM, hole_radius_mm="auto")
        rods[seed] = (xy, rod, float(ref.params["rod_length_mm"]))
    xy, rod, length_mm = rods[seed]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return render_rod(xy, seed, rod, px_per_mm=px_per_mm, thickness_mm=THICKNESS_MM,
                          rod_length_mm=length_mm, hole_radius_mm="auto",
                          **({} if condition == "clean" else dict(clean=False)))


def stack_energy_abslog(result, scene, px_per_mm: float) -> float:
    """Median over the matched stacks of ``|log(measured / true energy)|`` (midpoints within
    ``max(3 h, a quarter of the truth stack's length)``); NaN when none matches."""
    from crosssection.truth.scoring import match_stacks

    truth = scene.tables["stacks"]
    energy = truth["stack_id"].map(
        scene.tables["branches"].groupby("stack_id")["energy"].sum()).fillna(0.0)
    out = result.stacks
    r, c = match_stacks(out, truth, match_px=3 * THICKNESS_MM * px_per_mm, px_per_mm=px_per_mm)
    measured = (out["energy_per_branch"] * out["n_br"]).to_numpy(float)[r]
    true = energy.to_numpy(float)[c]
    ok = (true > 0) & np.isfinite(measured)
    if not ok.any():
        return float("nan")
    return float(np.median(np.abs(np.log(np.clip(measured[ok] / true[ok], 1e-3, None)))))


def run_one(generator: str, seed: int, px_per_mm: float, condition: str, rods: dict) -> dict:
    """One scene at one resolution: its scores, warnings and time."""
    import crosssection
    from crosssection.truth.scoring import score
    from simulate.validate import error_without_hairpins

    scene = (network_scene(seed, px_per_mm, condition) if generator == "network"
             else render_scene(seed, px_per_mm, condition, rods))
    p = scene.params
    kw = dict(px_per_mm=px_per_mm, thickness_mm=THICKNESS_MM, calibration=scene.calibration)
    if p.get("hole_radius_mm"):
        kw.update(hole_radius_mm=p["hole_radius_mm"], hole_center_px=tuple(p["hole_center_px"]))
    row = dict(generator=generator, seed=seed, condition=condition, px_per_mm=px_per_mm,
               h_px=THICKNESS_MM * px_per_mm, image_mpx=scene.rgb.shape[0] * scene.rgb.shape[1]
               / 1e6, truth_energy=scene.summary.get("total_energy"))
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = crosssection.analyze(scene.rgb, **kw)
        except crosssection.FoldstatError as exc:
            row["error"] = exc.one_line()
            return row
        times.append(time.perf_counter() - t0)
    row["analyze_s"] = min(times)
    s = score(result, (scene.summary, scene.tables), match_px=3 * THICKNESS_MM * px_per_mm,
              px_per_mm=px_per_mm, thickness_mm=THICKNESS_MM)
    row.update({k: s[k] for k in ("rod_length_rel_error", "junction_f1",
                                  "n_br_exact_length_fraction", "total_energy_rel_error")})
    # a render's truth holds the energy of folds within one rod node, which no drawing shows
    share = float(scene.summary.get("hairpin_energy_share") or 0.0)
    row["truth_hairpin_share"] = share
    row["total_energy_rel_error_without_hairpins"] = error_without_hairpins(
        s["total_energy_rel_error"], share)
    row["void_count_error"] = len(result.voids) - len(scene.tables["voids"])
    row["stack_energy_abslog"] = stack_energy_abslog(result, scene, px_per_mm)
    row["quality"] = ";".join(result.summary["quality"]["codes"])
    return row


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """Median (min, max) over seeds of each score, per generator, condition and resolution."""
    df = df.assign(rod_abs=df["rod_length_rel_error"].abs(),
                   energy_abs=df["total_energy_rel_error"].abs())
    cols = ["rod_abs", "junction_f1", "n_br_exact_length_fraction", "energy_abs",
            "total_energy_rel_error", "stack_energy_abslog", "analyze_s"]

    def cell(x):
        return f"{x.median():.3f} ({x.min():.3f}, {x.max():.3f})"

    return (df.groupby(["generator", "condition", "px_per_mm"])[cols].agg(cell)
            .reset_index())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--generators", default="network,render")
    ap.add_argument("--px-per-mm", default="20,25,35,50,70,100")
    ap.add_argument("--seeds", default="1,2,3,4")
    ap.add_argument("--conditions", default="clean,scan")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/out"))
    args = ap.parse_args(argv)
    import crosssection
    from crosssection.truth.network import make_scene

    with warnings.catch_warnings():  # numba's compilation, not timed
        warnings.simplefilter("ignore")
        w = make_scene(seed=1, n_stacks=15, max_layers=3, px_per_mm=30.0)
        crosssection.analyze(w.rgb, px_per_mm=30.0, thickness_mm=THICKNESS_MM,
                             calibration=w.calibration)
    args.out.mkdir(parents=True, exist_ok=True)
    rows, rods = [], {}
    for generator in args.generators.split(","):
        for seed in map(int, args.seeds.split(",")):
            for condition in args.conditions.split(","):
                for ppm in map(float, args.px_per_mm.split(",")):
                    row = run_one(generator, seed, ppm, condition, rods)
                    rows.append(row)
                    print(generator, seed, condition, ppm,
                          row.get("error") or f"energy {row['total_energy_rel_error']:+.3f}",
                          flush=True)
    df = pd.DataFrame(rows)
    from crosssection.core.fileio import write_csv

    write_csv(args.out / "resolution_sweep.csv", df)
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(summarise(df).to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
