#!/usr/bin/env python
"""Accuracy sweep: the whole pipeline on many generated scans, scored against exact truth.

Density 20-300 stacks, layers 1-12, noise, blur, JPEG, smears/specks/pinholes; several seeds
per condition. Prints one row per scene and the fraction of scenes meeting each target of
the pipeline (rod length within 3 %, junction F1 >= 0.95, exact n_br on >= 90 % of stack length,
void count within 5 %), then the median of each metric.

Usage: python benchmarks/accuracy_sweep.py [--seeds 3] [--quick]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.parallel import spawn_seeds
from crosssection.truth.scoring import analyze_scene_folder, meets_targets, score
from crosssection.truth.network import make_scene
from crosssection.truth.scene import write_scene

CONDITIONS = [
    ("n20-L12-clean", dict(n_stacks=20, max_layers=12, mean_layers=5.0)),
    ("n40-L8-noise8", dict(n_stacks=40, max_layers=8, mean_layers=3.5, noise_sigma=8.0)),
    ("n60-L6-blur1.2", dict(n_stacks=60, max_layers=6, mean_layers=3.0, blur_px=1.2)),
    ("n80-L6-jpeg70", dict(n_stacks=80, max_layers=6, mean_layers=2.5, jpeg_quality=70)),
    ("n120-L4-dirt", dict(n_stacks=120, max_layers=4, smears=8, specks=40, pinholes=30,
                          noise_sigma=4.0)),
    ("n200-L3-mixed", dict(n_stacks=200, max_layers=3, noise_sigma=5.0, blur_px=0.8,
                           jpeg_quality=85)),
    ("n300-L4-clean", dict(n_stacks=300, max_layers=4)),
]
COLS = ["rod_length_rel_error", "junction_f1", "n_br_exact_length_fraction", "n_voids_rel_error",
        "n_stacks_rel_error", "void_area_median_rel_error", "total_energy_rel_error"]


def run(n_seeds: int = 3, quick: bool = False, use_calibration: bool = True) -> pd.DataFrame:
    rows = []
    conds = CONDITIONS[:4] if quick else CONDITIONS
    with tempfile.TemporaryDirectory() as tmp:
        for ci, (name, opts) in enumerate(conds):
            for seed in spawn_seeds(1000 + ci, n_seeds):
                t0 = time.perf_counter()
                scene = make_scene(seed=seed, **opts)
                folder = write_scene(scene, Path(tmp) / f"{name}-{seed}")
                t1 = time.perf_counter()
                try:
                    _, pair = analyze_scene_folder(folder, use_calibration=use_calibration)
                    s = score(pair, (scene.summary, scene.tables))
                    err = ""
                except Exception as exc:  # noqa: BLE001 - a failing scene is a row of the table
                    s, err = {}, f"{type(exc).__name__}: {exc}"[:80]
                t2 = time.perf_counter()
                row = {"condition": name, "seed": seed, "size_px": scene.rgb.shape[0],
                       "n_stacks": scene.summary["n_stacks"],
                       "max_n_br": int(scene.tables["stacks"]["n_br"].max()),
                       **{c: s.get(c, np.nan) for c in COLS},
                       "gen_s": round(t1 - t0, 1), "analyze_s": round(t2 - t1, 1), "error": err}
                if s:
                    row.update({f"ok_{k}": v for k, v in meets_targets(s).items()})
                rows.append(row)
                print(f"{name:16s} seed {seed:>10d}: " + "  ".join(
                    f"{c.split('_')[0]}={row[c]:.3f}" if isinstance(row[c], float) else ""
                    for c in COLS[:4]) + (f"  ERROR {err}" if err else ""), flush=True)
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="pipeline accuracy on generated scans")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="first four conditions only")
    ap.add_argument("--no-calibration", action="store_true",
                    help="let the pipeline assume its default width law")
    args = ap.parse_args(argv)
    df = run(args.seeds, args.quick, not args.no_calibration)
    pd.set_option("display.width", 200)
    pd.set_option("display.max_columns", 30)
    print()
    print(df.drop(columns=["error"]).round(3).to_string(index=False))
    ok = [c for c in df.columns if c.startswith("ok_")]
    if ok:
        print("\nfraction of scenes meeting each target, per condition:")
        print(df.groupby("condition", sort=False)[ok].mean().round(2).to_string())
        print("\nall scenes:", df[ok].mean().round(3).to_dict())
    print("\nmedian per condition:")
    print(df.groupby("condition", sort=False)[COLS].median().round(4).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
