#!/usr/bin/env python
"""Stability: one scan read in the eight orientations of the square, and after a JPEG round trip.

A scan turned by a quarter turn or mirrored holds the same sheet, pixel for pixel; so does a
scan saved once more as JPEG at quality 95 (the changes are of one or two grey levels). An
analysis should read the same counts and nearly the same energy from each. The skeleton is
not invariant (its thinning has a preferred direction), so small differences are expected;
large ones show a decision of the estimator that a pixel tips one way or the other.

Every scene of the robust sweep's conditions (``benchmarks/robust_sweep.py``: the same
generators, options and seeds) is analysed with the default settings in the eight
orientations (``numpy.rot90`` by 0-3 quarter turns, with and without a left-right mirror) and
after a JPEG round trip at quality 95, and scored against its truth. Per scene: the total
energy error in each orientation, its spread (largest minus smallest, in units of the true
energy) and the spread of the branch count.

Usage: python benchmarks/orientation_spread.py [--conditions typical,lowres,renders]
       [--per-condition 4] [--seed 100] [--workers 2] [--px-per-mm P] [--out benchmarks/out]
Writes OUT/orientation_spread.csv (one row per scene and orientation) and prints per condition
the median spread and the median |energy error| over all orientations.
"""
from __future__ import annotations

import argparse
import io
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

ORIENTATIONS = [(k, m) for m in (False, True) for k in range(4)]


def _oriented(rgb: np.ndarray, k: int, mirror: bool) -> np.ndarray:
    out = np.rot90(rgb[:, ::-1] if mirror else rgb, k)
    return np.ascontiguousarray(out)


def _jpeg(rgb: np.ndarray, quality: int = 95) -> np.ndarray:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, "JPEG", quality=quality)
    return np.array(Image.open(buf).convert("RGB"))


def scene_rows(condition: str, seed: int, px_per_mm: float | None = None) -> list[dict]:
    """Analyse one scene in every orientation and after a JPEG round trip (``px_per_mm``: the
    generator's scenes drawn at that scale, as ``robust_sweep.py --px-per-mm``)."""
    import crosssection
    from robust_sweep import _render_scene, make_network_scene, scene_options

    options = scene_options(condition, seed, px_per_mm=px_per_mm)
    scene = _render_scene(seed) if condition == "renders" else make_network_scene(seed, options)
    p = scene.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=scene.calibration)
    truth = float(scene.summary["total_energy"])
    variants = [(f"rot{90 * k}{'_mirror' if m else ''}", _oriented(scene.rgb, k, m))
                for k, m in ORIENTATIONS]
    variants.append(("jpeg95", _jpeg(scene.rgb)))
    rows = []
    for name, rgb in variants:
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = crosssection.analyze(rgb, **kw)
        except crosssection.FoldstatError as exc:
            rows.append(dict(condition=condition, seed=seed, variant=name, error=exc.one_line()))
            continue
        s = res.summary
        rows.append(dict(condition=condition, seed=seed, variant=name,
                         total_energy=s["total_energy"], total_energy_truth=truth,
                         total_energy_rel_error=s["total_energy"] / truth - 1.0,
                         n_branches=s["n_branches"], n_branches_truth=scene.summary["n_branches"],
                         rod_length_mm=s["rod_length_mm"], analyze_s=time.perf_counter() - t0))
    return rows


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """Per scene the spreads over the eight orientations; per condition their medians."""
    orient = df[df["variant"] != "jpeg95"]
    per = orient.groupby(["condition", "seed"]).agg(
        e_min=("total_energy_rel_error", "min"), e_max=("total_energy_rel_error", "max"),
        e_abs_med=("total_energy_rel_error", lambda x: float(np.median(np.abs(x)))),
        nbr_spread=("n_branches", lambda x: int(x.max() - x.min())))
    per["spread"] = per["e_max"] - per["e_min"]
    jp = df[df["variant"] == "jpeg95"].set_index(["condition", "seed"])["total_energy_rel_error"]
    ref = df[df["variant"] == "rot0"].set_index(["condition", "seed"])["total_energy_rel_error"]
    per["jpeg_shift"] = (jp - ref).abs()
    return per.reset_index().groupby("condition").agg(
        scenes=("seed", "size"), spread_med=("spread", "median"), spread_max=("spread", "max"),
        jpeg_shift_med=("jpeg_shift", "median"), e_abs_med=("e_abs_med", "median"),
        nbr_spread_max=("nbr_spread", "max"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conditions", default="typical,lowres,thick_dense,renders")
    ap.add_argument("--per-condition", type=int, default=4)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--px-per-mm", type=float, default=None,
                    help="draw the generator's scenes at this scale (default: the condition's)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    args = ap.parse_args(argv)
    jobs = [(c, args.seed + i, args.px_per_mm) for c in args.conditions.split(",")
            for i in range(args.per_condition)]
    rows = []
    with ProcessPoolExecutor(max_workers=args.workers) as ex:
        for out in ex.map(scene_rows, *zip(*jobs)):
            rows += out
            r = pd.DataFrame(out)
            print(f"{out[0]['condition']} {out[0]['seed']}: energy "
                  + " ".join(f"{x:+.3f}" for x in r.get("total_energy_rel_error", [])),
                  flush=True)
    df = pd.DataFrame(rows)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / "orientation_spread.csv.tmp"
    df.to_csv(tmp, index=False)
    tmp.replace(out / "orientation_spread.csv")
    with pd.option_context("display.width", 160):
        print(summarize(df).round(3).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
