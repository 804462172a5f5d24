#!/usr/bin/env python
"""Per-stack bending energy against the truth, and what ``energy_rel_uncertainty`` says of it.

Every output stack matched to a truth stack (midpoints within ``max(3 h, a quarter of the
truth stack's length)``, Hungarian matching as in :func:`crosssection.truth.scoring.score`)
gives a ratio ``r = measured / true`` of the stack's bending energy (``energy_per_branch *
n_br`` against the sum of its truth branches' energies). The ratios are summarised per
generator by the stack's reported ``energy_rel_uncertainty`` (the share of its
``int kappa^2 ds`` that rests on the fork-zone model or the noise floor) and by its aspect
``length / (n_br h)`` (the fork zones cover about ``4 / aspect`` of a stack's length):
median ratio, median ``|log r|`` and its 84th percentile (a one-sigma spread in log), and the
share of the true energy in stacks read within a factor 1.5.

Generators: the network generator's typical and thick dense scans and the simulator's renders
(:mod:`robust_sweep`'s scenes, seeds from ``--seed``), and the independent generator's typical
scans (:mod:`independent_sweep`'s scenes, generated into ``--independent DIR`` unless there).

Usage: python benchmarks/stack_energy_errors.py [--per-condition 8] [--seed 100]
       [--independent-seed 1] [--independent DIR] [--workers 2] [--out DIR]
Writes DIR/stack_energy_errors.csv (one row per matched stack) and prints the summaries.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))

#: Bins of the reported share and of the aspect length / (n_br h).
SHARE_BINS = [-0.01, 0.001, 0.2, 0.5, 0.8, 0.999, 1.0]
ASPECT_BINS = [0, 5, 10, 20, 40, np.inf]
GENERATORS = ["typical", "thick_dense", "renders", "independent"]


def _matched_rows(res, truth_stacks: pd.DataFrame, px_per_mm: float, thickness_mm: float):
    """One dict per matched stack: truth n_br, length, energies, reported share."""
    from crosssection.truth.scoring import match_stacks

    so = res.stacks
    r, c = match_stacks(so, truth_stacks, match_px=3 * thickness_mm * px_per_mm,
                        px_per_mm=px_per_mm)
    rows = []
    for i, j in zip(r, c):
        o, t = so.iloc[i], truth_stacks.iloc[j]
        rows.append(dict(n_br=int(t["n_br"]), n_br_out=int(o["n_br"]),
                         length_mm=float(t["length_mm"]), thickness_mm=thickness_mm,
                         energy_true=float(t["energy"]),
                         energy_out=float(o["energy_per_branch"] * o["n_br"]),
                         energy_rel_uncertainty=float(o["energy_rel_uncertainty"])))
    return rows


def run_one(generator: str, seed: int, independent_dir: str) -> list[dict]:
    """Analyse one scene with default settings (hole and calibration given); its stack rows."""
    import crosssection

    warnings.simplefilter("ignore")
    if generator == "independent":
        import independent_scenes as gen
        from independent_sweep import _scene_on_disk

        folder = Path(independent_dir)
        name = gen.scene_name(seed, "typical")
        if not _scene_on_disk(folder, name):
            gen.generate(seed, "typical", folder)
        truth = json.loads((folder / f"{name}.json").read_text())
        ppm, h = float(truth["px_per_mm"]), float(truth["thickness_mm"])
        res = crosssection.analyze(str(folder / f"{name}.png"), px_per_mm=ppm, thickness_mm=h,
                                   calibration=str(folder / "calibration.csv"),
                                   rod_length_mm=truth["L_mm"],
                                   hole_radius_mm=truth["hole_radius_mm"],
                                   hole_center_px=tuple(truth["hole_center_px"]))
        st = pd.DataFrame([dict(n_br=s["n"], length_mm=s["length_mm"], energy=s["energy"],
                                mid_x_px=s["mid"][0], mid_y_px=s["mid"][1])
                           for s in truth["stacks"]])
    else:
        from robust_sweep import _render_scene, make_network_scene, scene_options

        scene = (_render_scene(seed) if generator == "renders"
                 else make_network_scene(seed, scene_options(generator, seed)))
        p = scene.params
        ppm, h = float(p["px_per_mm"]), float(p["thickness_mm"])
        hole = ({} if p.get("hole_center_px") is None else
                dict(hole_radius_mm=p["hole_radius_mm"], hole_center_px=tuple(p["hole_center_px"])))
        res = crosssection.analyze(scene.rgb, px_per_mm=ppm, thickness_mm=h,
                                   calibration=scene.calibration, **hole)
        st = scene.tables["stacks"].copy()
        st["energy"] = st["stack_id"].map(
            scene.tables["branches"].groupby("stack_id")["energy"].sum()).fillna(0.0)
    return [dict(generator=generator, seed=seed, **row)
            for row in _matched_rows(res, st, ppm, h)]


def summarize(df: pd.DataFrame, by: str, bins) -> pd.DataFrame:
    """Per generator and bin of ``by``: stacks, median ratio, median ``|log r|`` and its 84th
    percentile, the bin's share of the generator's true energy, and the share of the bin's
    true energy in stacks read within a factor 1.5."""
    d = df[df["energy_true"] > 0].copy()
    d["ratio"] = d["energy_out"] / d["energy_true"]
    d["abs_log"] = np.abs(np.log(d["ratio"].clip(lower=1e-3)))
    d["bin"] = pd.cut(d[by], bins)
    d["generator"] = pd.Categorical(d["generator"], GENERATORS)
    d["true_within"] = d["energy_true"].where(d["abs_log"] <= np.log(1.5), 0.0)
    t = (d.groupby(["generator", "bin"], observed=True)
         .agg(stacks=("ratio", "size"), median_ratio=("ratio", "median"),
              median_abs_log=("abs_log", "median"),
              abs_log_p84=("abs_log", lambda x: x.quantile(0.84)),
              true_within=("true_within", "sum"), true_energy=("energy_true", "sum")))
    total = t.groupby(level=0, observed=True)["true_energy"].transform("sum")
    t["energy_share"] = t["true_energy"] / total
    t["within_1_5x"] = t.pop("true_within") / t.pop("true_energy")
    return t.round(3)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--per-condition", type=int, default=8)
    ap.add_argument("--seed", type=int, default=100,
                    help="first seed of the network scenes and renders")
    ap.add_argument("--independent-seed", type=int, default=1,
                    help="first seed of the independent generator's scenes")
    ap.add_argument("--independent", default=None,
                    help="folder of the independent generator's scenes (default OUT/independent_scenes)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).parent / "out" / "stack_energy_errors"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ind = args.independent or str(out / "independent_scenes")
    Path(ind).mkdir(parents=True, exist_ok=True)
    if not (Path(ind) / "calibration.csv").is_file():
        import independent_scenes

        independent_scenes.write_calibration(Path(ind) / "calibration.csv")
    n = args.per_condition
    jobs = ([(g, args.seed + i) for g in GENERATORS[:3] for i in range(n)]
            + [("independent", args.independent_seed + i) for i in range(n)])
    with ProcessPoolExecutor(max(1, args.workers)) as ex:
        parts = list(ex.map(run_one, *zip(*jobs), [ind] * len(jobs)))
    df = pd.DataFrame([row for part in parts for row in part])
    df["aspect"] = df["length_mm"] / (df["n_br"] * df["thickness_mm"])
    tmp = out / "stack_energy_errors.csv.tmp"
    df.to_csv(tmp, index=False)
    tmp.replace(out / "stack_energy_errors.csv")
    with pd.option_context("display.width", 160):
        print(f"{len(df)} matched stacks")
        print("\nby energy_rel_uncertainty:")
        print(summarize(df, "energy_rel_uncertainty", SHARE_BINS).to_string())
        print("\nby aspect length / (n_br h):")
        print(summarize(df, "aspect", ASPECT_BINS).to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
