#!/usr/bin/env python
"""The ``merged_junctions`` check's measure: the share of junctions joining four stacks or more.

Default settings with each scan's calibration and hole: the network generator (typical, thick
dense, 25 px/mm, tangential forks; seeds 100-103, with its truth's share beside), the
independent generator (typical, thick, thick dense, 25 px/mm, peels; seeds 1-3), the bundled
sample scans, and the scene folders of a render given with ``--scenes`` (renders of
compacted rods: ``python benchmarks/bench_compact_pipeline.py`` writes them under
``WORK/epsE/scan``; their truth's share beside). Prints one row per scan and the largest share
per source against :data:`crosssection.quality.MERGED_SHARE`.

Usage: python benchmarks/junction_degrees.py [--scenes DIR] [--work DIR]
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

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _share(degrees) -> float:
    degrees = np.asarray(degrees)
    return float(np.mean(degrees >= 4)) if degrees.size else float("nan")


def _row(source, name, res, truth=None) -> dict:
    return {"source": source, "scan": name, "n_junctions": len(res.junctions),
            "share_degree4": _share(res.junctions["n_stacks"]),
            "truth_share_degree4": _share(truth) if truth is not None else float("nan"),
            "flagged": "merged_junctions" in res.summary["quality"]["codes"]}


def _quiet(fn, *args, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kwargs)


def network_rows() -> list[dict]:
    import robust_sweep as rs

    import crosssection

    rows = []
    for cond in ("typical", "thick_dense", "lowres", "tangential"):
        for seed in range(100, 104):
            scene = rs.make_network_scene(seed, rs.scene_options(cond, seed))
            p = scene.params
            res = _quiet(crosssection.analyze, scene.rgb, px_per_mm=p["px_per_mm"],
                         thickness_mm=p["thickness_mm"], calibration=scene.calibration,
                         hole_radius_mm=p["hole_radius_mm"],
                         hole_center_px=tuple(p["hole_center_px"]))
            rows.append(_row(f"network {cond}", seed, res,
                             scene.tables["junctions"]["n_stacks"]))
    return rows


def independent_rows(folder: Path) -> list[dict]:
    import independent_scenes as gen

    import crosssection

    folder.mkdir(parents=True, exist_ok=True)
    gen.write_calibration(folder / "calibration.csv")
    rows = []
    for cond in ("typical", "thick", "thick_dense", "lowres", "peel"):
        for seed in range(1, 4):
            name = gen.scene_name(seed, cond)
            if not (folder / f"{name}.png").exists():
                gen.generate(seed, cond, folder)
            truth = json.loads((folder / f"{name}.json").read_text())
            res = _quiet(crosssection.analyze, str(folder / f"{name}.png"),
                         px_per_mm=truth["px_per_mm"], thickness_mm=truth["thickness_mm"],
                         calibration=str(folder / "calibration.csv"),
                         hole_radius_mm=truth["hole_radius_mm"],
                         hole_center_px=tuple(truth["hole_center_px"]))
            rows.append(_row(f"independent {cond}", seed, res))
    return rows


def sample_rows() -> list[dict]:
    import crosssection

    samples = HERE.parent / "sample_images"
    return [_row("samples", f.name, _quiet(crosssection.analyze, str(f), px_per_mm=50,
                                           thickness_mm=0.1,
                                           calibration=str(samples / "calibration.csv")))
            for f in sorted(samples.glob("*.png"))]


def scene_rows(scenes: Path) -> list[dict]:
    from crosssection.truth.scoring import analyze_scene_folder

    rows = []
    for scene in sorted(p for p in scenes.iterdir() if (p / "truth").is_dir()):
        res, _ = _quiet(analyze_scene_folder, scene)
        truth = pd.read_csv(scene / "truth" / "junctions.csv")["n_stacks"]
        rows.append(_row(f"scenes {scenes.name}", scene.name, res, truth))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", type=Path, help="a render's folder of scene folders")
    ap.add_argument("--work", type=Path, help="folder of the independent generator's scans "
                    "(kept; default: a temporary one)")
    args = ap.parse_args(argv)
    from crosssection.quality import MERGED_SHARE

    with tempfile.TemporaryDirectory() as tmp:
        rows = sample_rows() + network_rows() + independent_rows(args.work or Path(tmp))
    if args.scenes is not None:
        rows += scene_rows(args.scenes)
    df = pd.DataFrame(rows)
    print(df.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    print(f"\nlargest share per source (flagged above {MERGED_SHARE:.2f}):")
    print(df.groupby("source", sort=False)[["share_degree4", "truth_share_degree4"]].max()
          .to_string(float_format=lambda v: f"{v:.3f}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
