#!/usr/bin/env python
"""Total bending-energy error of whichever ``crosssection`` is importable, on fixed scans.

The scans are written once to a folder (``write``), so that every version of the package
scored on them (``score``) reads the same bytes: run ``score`` with this checkout, then with
another checkout of the package first on PYTHONPATH, and compare the medians.

``write`` draws each scene exactly as ``benchmarks/robust_sweep.py`` does (its
``scene_options``, ``make_network_scene`` and ``_render_scene``; every random choice from the
seed) and writes, per condition and seed, ``<cond>_<seed>.png`` (the RGB scan),
``<cond>_<seed>_calibration.csv`` (``n_layers,width_mm``, n = 1-60, the width law the bands
were drawn with) and ``<cond>_<seed>.json`` (the truth: px_per_mm, thickness_mm,
hole_radius_mm and hole_center_px, null when the scene has no hole or it is withheld, L_mm =
sum of n_br * length_mm over the truth stacks, energy_total). Files are written atomically and
scenes already written are skipped. The scenes folder of ``benchmarks/independent_sweep.py``
(``<cond>_NN.json`` with the same keys and one shared ``calibration.csv``) is scored as is.

``score`` analyses every ``<cond>_<N>.json`` scene with ``crosssection.analyze``, given the
scale, the calibration, the rod length and the hole (when known), and default settings
(``--threshold-method`` / ``--curvature-method`` are passed only when given, since older
versions may not accept them); a scene that raises is recorded and the others go on:

=====================  ====================================================================
energy_rel_error       sum of the output branch energies / truth energy_total - 1
rod_length_rel_error   sum of n_br * length_mm over the output stacks / truth L_mm - 1
modelled_stack_share   the largest share of the energy carried by one stack none of whose
                       energy is measured (the ``modelled_stack`` check's value)
version                ``crosssection.__version__`` of the package scored
=====================  ====================================================================

Usage: python benchmarks/estimator_transfer.py write --out DIR [--seeds 100-107]
       [--conditions typical,tangential,renders]
       python benchmarks/estimator_transfer.py score DIR [--conditions typical,...]
       [--threshold-method M] [--curvature-method M] [--csv OUT.csv]
``score`` prints one line per scene and the medians per condition (signed and absolute energy
error, rod length error, scenes, failures); ``--csv`` writes one row per scene.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

CONDITIONS = ("typical", "tangential", "renders")
N_CALIBRATION_ROWS = 60
SCENE_NAME = re.compile(r"^(?P<condition>.+)_(?P<seed>\d+)$")


def parse_seeds(text: str) -> list[int]:
    """``"100-107"``, ``"100,103"`` or a mix of both as a list of seeds."""
    seeds = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        seeds.extend(range(int(lo), int(hi or lo) + 1))
    return seeds


def build_scene(condition: str, seed: int):
    """The scene of ``robust_sweep`` for a condition and seed, and whether its hole is given."""
    import robust_sweep as rs  # the sibling script (needs the repository on PYTHONPATH)

    options = rs.scene_options(condition, seed)
    scene = rs._render_scene(seed) if condition == "renders" else \
        rs.make_network_scene(seed, options)
    return scene, options["hole_given"]


def scene_truth(scene, hole_given: bool = True) -> dict:
    """The JSON truth of a scene: scale, hole (None when absent or withheld), L and energy."""
    p = scene.params
    stacks = scene.tables["stacks"]
    energy_total = scene.summary.get("total_energy")
    if energy_total is None:
        energy_total = scene.tables["branches"]["energy"].sum()
    has_hole = hole_given and p.get("hole_radius_mm") is not None
    return {"px_per_mm": float(p["px_per_mm"]), "thickness_mm": float(p["thickness_mm"]),
            "hole_radius_mm": float(p["hole_radius_mm"]) if has_hole else None,
            "hole_center_px": [float(v) for v in p["hole_center_px"]] if has_hole else None,
            "L_mm": float((stacks["n_br"] * stacks["length_mm"]).sum()),
            "energy_total": float(energy_total)}


def write_scene(scene, folder, name: str, hole_given: bool = True) -> dict:
    """Write ``name``.png, ``name``_calibration.csv and ``name``.json (last) atomically."""
    from crosssection.core.fileio import write_csv, write_json
    from crosssection.truth.scene import write_image

    folder = Path(folder)
    write_image(scene.rgb, folder / f"{name}.png")
    n = np.arange(1, N_CALIBRATION_ROWS + 1)
    write_csv(folder / f"{name}_calibration.csv",
              pd.DataFrame({"n_layers": n, "width_mm": scene.calibration.width(n)}))
    truth = scene_truth(scene, hole_given)
    write_json(folder / f"{name}.json", truth)
    return truth


def scene_written(folder: Path, name: str) -> bool:
    """The JSON (written last) parses and the scan is there."""
    try:
        json.loads((folder / f"{name}.json").read_text())
    except (OSError, ValueError):
        return False
    return (folder / f"{name}.png").exists()


def list_scenes(folder, conditions=None) -> list[tuple[str, str]]:
    """``(condition, name)`` of every ``<cond>_<N>.json`` in ``folder``, by condition and N."""
    found = []
    for path in Path(folder).glob("*.json"):
        m = SCENE_NAME.match(path.stem)
        if m and (conditions is None or m["condition"] in conditions):
            found.append((m["condition"], int(m["seed"]), path.stem))
    order = {c: i for i, c in enumerate(conditions or ())}
    found.sort(key=lambda t: (order.get(t[0], len(order)), t[0], t[1]))
    return [(c, name) for c, _, name in found]


def score_scene(folder, name: str, analyze, **methods) -> dict:
    """Analyse one scene (warnings silenced) and return its errors, or the exception raised."""
    folder = Path(folder)
    truth = json.loads((folder / f"{name}.json").read_text())
    calibration = folder / f"{name}_calibration.csv"
    if not calibration.exists():
        calibration = folder / "calibration.csv"
    kw = dict(px_per_mm=truth["px_per_mm"], thickness_mm=truth["thickness_mm"],
              calibration=str(calibration), rod_length_mm=truth["L_mm"], **methods)
    if truth.get("hole_radius_mm") is not None:
        kw["hole_radius_mm"] = truth["hole_radius_mm"]
    if truth.get("hole_center_px") is not None:
        kw["hole_center_px"] = tuple(truth["hole_center_px"])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = analyze(str(folder / f"{name}.png"), **kw)
        stacks = res.stacks
        return {"energy_rel_error": res.branches["energy"].sum() / truth["energy_total"] - 1,
                "rod_length_rel_error":
                    (stacks["n_br"] * stacks["length_mm"]).sum() / truth["L_mm"] - 1,
                "modelled_stack_share": _modelled_stack_share(stacks)}
    except Exception as exc:  # noqa: BLE001 - a failing scene is a row of the table
        message = (str(exc).splitlines() or [""])[0].replace(f"{folder}{os.sep}", "")
        return {"error": f"{type(exc).__name__}: {message}"}  # no folder path in the outputs


def _modelled_stack_share(stacks) -> float:
    """The largest share of the scan's energy carried by one stack none of whose energy is
    measured (the ``modelled_stack`` check's measure), NaN for a version of the package
    without that check or the column."""
    try:
        from crosssection.quality import MODELLED_STACK_UNCERTAINTY, _energy_shares
    except ImportError:
        return float("nan")
    if "energy_rel_uncertainty" not in stacks:
        return float("nan")
    wholly = stacks["energy_rel_uncertainty"] >= MODELLED_STACK_UNCERTAINTY
    return float(_energy_shares(stacks)[wholly].max()) if wholly.any() else 0.0


def score_folder(folder, conditions=None, analyze=None, version=None, **methods):
    """One row per scene of ``folder``: condition, scene, version, errors; printed as it goes."""
    if analyze is None:
        import crosssection

        analyze, version = crosssection.analyze, getattr(crosssection, "__version__", "unknown")
    rows = []
    for condition, name in list_scenes(folder, conditions):
        row = {"condition": condition, "scene": name, "version": version or "unknown",
               "energy_rel_error": np.nan, "rod_length_rel_error": np.nan,
               "modelled_stack_share": np.nan, "error": None,
               **score_scene(folder, name, analyze, **methods)}
        print(f"{name:<20} " + (f"failed: {row['error']}" if row["error"] else
                                f"energy {row['energy_rel_error']:+.3f}  "
                                f"rod {row['rod_length_rel_error']:+.3f}"), flush=True)
        rows.append(row)
    return pd.DataFrame(rows, columns=["condition", "scene", "version", "energy_rel_error",
                                       "rod_length_rel_error", "modelled_stack_share", "error"])


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """Medians per condition (failed scenes left out of the medians, but counted)."""
    rows = []
    for condition, g in df.groupby("condition", sort=False):
        ok = g[g["error"].isna()]
        rows.append({"condition": condition,
                     "energy_signed_med": ok["energy_rel_error"].median(),
                     "energy_abs_med": ok["energy_rel_error"].abs().median(),
                     "rod_med": ok["rod_length_rel_error"].median(),
                     "modelled_stack_max": ok["modelled_stack_share"].max(),
                     "scenes": len(g), "failures": len(g) - len(ok)})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    w = sub.add_parser("write", help="write the scans and their truth to a folder")
    w.add_argument("--out", required=True)
    w.add_argument("--seeds", default="100-107")
    w.add_argument("--conditions", default=",".join(CONDITIONS))
    s = sub.add_parser("score", help="score the importable crosssection on a folder")
    s.add_argument("folder")
    s.add_argument("--conditions", default=None, help="default: every condition in the folder")
    s.add_argument("--threshold-method", default=None)
    s.add_argument("--curvature-method", default=None)
    s.add_argument("--csv", default=None)
    args = ap.parse_args(argv)

    if args.command == "write":
        out = Path(args.out)
        for condition in args.conditions.split(","):
            for seed in parse_seeds(args.seeds):
                name = f"{condition}_{seed}"
                if scene_written(out, name):
                    print(f"{name:<20} on disk")
                    continue
                scene, hole_given = build_scene(condition, seed)
                truth = write_scene(scene, out, name, hole_given)
                print(f"{name:<20} L {truth['L_mm']:.1f} mm, energy {truth['energy_total']:.1f}"
                      f"{'' if truth['hole_radius_mm'] else ', no hole'}", flush=True)
        return 0

    methods = {k: v for k, v in (("threshold_method", args.threshold_method),
                                 ("curvature_method", args.curvature_method)) if v is not None}
    conditions = args.conditions.split(",") if args.conditions else None
    df = score_folder(args.folder, conditions, **methods)
    if df.empty:
        print("no scenes found")
        return 1
    print(f"crosssection {df['version'].iloc[0]}")
    print(summarize(df).to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    if args.csv:  # plain pandas: the package scored may predate crosssection.core.fileio
        Path(args.csv).parent.mkdir(parents=True, exist_ok=True)
        df.to_csv(args.csv, index=False)
        print(f"{len(df)} scenes -> {Path(args.csv).name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
