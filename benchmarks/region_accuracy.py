#!/usr/bin/env python
"""Bulk against periphery: each stack's region against the truth, and how it moves with the hole.

The paper ("Two sub-systems") calls a branch periphery when one of its extremities touches the
container. Every output stack matched to a truth stack (midpoints within ``max(3 h, a quarter
of the truth stack's length)``, Hungarian matching as in
:func:`crosssection.truth.scoring.score`) is right when its ``region`` is the truth's. Scores,
per scene and hole: the share of the matched branch length (``n_br`` times the length) in the
right region, and the periphery's share of the branch length, measured and true.

Generators: the network generator (its truth: a stack with a wall node is periphery) and the
independent generator (a stack with a junction of kind ``wall``). The hole is given exactly,
given with its radius off by ``--radius-offsets`` px (the centre exact), and found.

Usage: python benchmarks/region_accuracy.py [--per-condition 4] [--seed 100]
       [--conditions typical,thick_dense,lowres,independent_typical,independent_thick]
       [--radius-offsets -3,-1,1,3] [--independent DIR] [--out DIR]
Writes DIR/region_accuracy.csv and prints the medians and minima per condition and hole.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))


def scene(condition: str, seed: int, independent_dir: Path):
    """(image, analyze keywords, truth stacks with ``region``, hole centre (x, y), radius px)."""
    if condition.startswith("independent_"):
        import independent_scenes as gen
        from independent_sweep import _scene_on_disk

        cond = condition.split("_", 1)[1]
        name = gen.scene_name(seed, cond)
        if not _scene_on_disk(independent_dir, name):
            gen.generate(seed, cond, independent_dir)
        if not (independent_dir / "calibration.csv").exists():
            gen.write_calibration(independent_dir / "calibration.csv")
        t = json.loads((independent_dir / f"{name}.json").read_text())
        wall = {j["id"] for j in t["junctions"] if j["kind"] == "wall"}
        st = pd.DataFrame([dict(n_br=s["n"], length_mm=s["length_mm"], mid_x_px=s["mid"][0],
                                mid_y_px=s["mid"][1],
                                region="periphery" if {s["u"], s["v"]} & wall else "bulk")
                           for s in t["stacks"]])
        kw = dict(px_per_mm=t["px_per_mm"], thickness_mm=t["thickness_mm"],
                  calibration=str(independent_dir / "calibration.csv"), rod_length_mm=t["L_mm"])
        ppm = float(t["px_per_mm"])
        return (str(independent_dir / f"{name}.png"), kw, st, tuple(t["hole_center_px"]),
                t["hole_radius_mm"] * ppm)
    from robust_sweep import make_network_scene, scene_options

    sc = make_network_scene(seed, scene_options(condition, seed))
    p = sc.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=sc.calibration)
    return (sc.rgb, kw, sc.tables["stacks"], tuple(p["hole_center_px"]),
            p["hole_radius_mm"] * p["px_per_mm"])


def region_scores(res, truth: pd.DataFrame, px_per_mm: float, thickness_mm: float) -> dict:
    """Share of the matched branch length in the right region; periphery shares."""
    from crosssection.truth.scoring import match_stacks

    so = res.stacks
    r, c = match_stacks(so, truth, match_px=3 * thickness_mm * px_per_mm, px_per_mm=px_per_mm)
    w = (truth["n_br"] * truth["length_mm"]).to_numpy(float)[c]
    right = so["region"].to_numpy()[r] == truth["region"].to_numpy()[c]
    out_w = (so["n_br"] * so["length_mm"]).to_numpy(float)
    true_w = (truth["n_br"] * truth["length_mm"]).to_numpy(float)
    return dict(right=float(w[right].sum() / w.sum()) if w.sum() else np.nan,
                periphery_out=float(out_w[so["region"].to_numpy() == "periphery"].sum()
                                    / out_w.sum()),
                periphery_true=float(true_w[truth["region"].to_numpy() == "periphery"].sum()
                                     / true_w.sum()))


def run_one(condition: str, seed: int, offsets, independent_dir: Path) -> list[dict]:
    import crosssection

    warnings.simplefilter("ignore")
    image, kw, truth, centre, radius_px = scene(condition, seed, independent_dir)
    rows = []
    for off in [0.0, *offsets, None]:
        hole = {} if off is None else dict(hole_center_px=centre,
                                           hole_radius_mm=(radius_px + off) / kw["px_per_mm"])
        res = crosssection.analyze(image, **kw, **hole)
        rows.append(dict(condition=condition, seed=seed,
                         hole="found" if off is None else f"{off:+g} px",
                         **region_scores(res, truth, kw["px_per_mm"], kw["thickness_mm"])))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--per-condition", type=int, default=4)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--conditions",
                    default="typical,thick_dense,lowres,independent_typical,independent_thick")
    ap.add_argument("--radius-offsets", default="-3,-1,1,3")
    ap.add_argument("--independent", default=None,
                    help="folder of the independent generator's scenes (default: a temporary one)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    args = ap.parse_args(argv)
    offsets = [float(v) for v in args.radius_offsets.split(",") if v]
    tmp = None
    if args.independent is None:
        tmp = tempfile.TemporaryDirectory()
        folder = Path(tmp.name)
    else:
        folder = Path(args.independent)
        folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for cond in args.conditions.split(","):
        for k in range(args.per_condition):
            seed = args.seed + k if not cond.startswith("independent_") else 1 + k
            rows += run_one(cond, seed, offsets, folder)
            last = rows[-len(offsets) - 2:]
            print(f"{cond} {seed}: " + ", ".join(f"{r['hole']} {r['right']:.3f}/"
                                                 f"{r['periphery_out']:.2f}" for r in last)
                  + f" (true periphery {last[0]['periphery_true']:.2f})", flush=True)
    df = pd.DataFrame(rows)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "region_accuracy.csv", index=False)
    print(df.groupby(["condition", "hole"], sort=False)[
        ["right", "periphery_out", "periphery_true"]].agg(["median", "min"]).round(3).to_string())
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
