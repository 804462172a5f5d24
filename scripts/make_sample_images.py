#!/usr/bin/env python
"""Write the sample scans of ``sample_images/`` with their exact truth.

The scans are synthetic (``crosssection.truth.network.make_scene``): forked blue bands of known
layer counts inside a disk, varied in density, layer counts and degradations, at the paper's
resolution (50 px/mm, h = 0.1 mm). Layout written::

    sample_images/
        set.toml                 # read by `python -m crosssection batch sample_images ...`
        calibration.csv          # n_layers,width_mm (the generator's nonlinear width law)
        scan_01_sparse.png ...   # the scans (PNG, JPEG, 16-bit TIFF)
        scenes/<scan stem>/      # params.json + truth/ (summary.json and the four tables)

Score an analysis of one scan with
``crosssection.truth.scoring.score_folder(OUT_DIR, "sample_images/scenes/<stem>")``.

Usage::

    python scripts/make_sample_images.py [--out sample_images] [--seed 2024]

Deterministic: the same seed writes the same files. Keep the total size modest (< 5 MB).
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

from crosssection.core.fileio import write_csv, write_json, write_text
from crosssection.core import schema
from crosssection.core.parallel import spawn_seeds
from crosssection.truth.network import make_scene
from crosssection.truth.scene import write_image

#: (file name, generator options): sparse/thick, medium/noisy, dense/thin, JPEG, 16-bit TIFF
SAMPLES = [
    ("scan_01_sparse.png", dict(n_stacks=25, max_layers=12, mean_layers=5.0, receding_fraction=0.5)),
    ("scan_02_medium.png", dict(n_stacks=60, max_layers=6, mean_layers=3.0, noise_sigma=3.0, blur_px=0.7,
                                smears=4, specks=15, pinholes=10)),
    ("scan_03_dense.png", dict(n_stacks=150, max_layers=3, noise_sigma=1.5, specks=10)),
    ("scan_04_jpeg.jpg", dict(n_stacks=45, max_layers=8, mean_layers=3.0, jpeg_quality=85,
                              smears=3)),
    ("scan_05_16bit.tif", dict(n_stacks=30, max_layers=5, mean_layers=2.5)),
]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parents[1] / "sample_images"))
    ap.add_argument("--seed", type=int, default=2024)
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if (out / "scenes").exists():
        shutil.rmtree(out / "scenes")
    seeds = spawn_seeds(args.seed, len(SAMPLES))
    overrides = []
    cal = None
    for (name, opts), seed in zip(SAMPLES, seeds):
        sc = make_scene(seed=seed, **opts)
        cal = sc.calibration
        path = out / name
        rgb = sc.rgb
        if path.suffix == ".tif":
            rgb = rgb.astype(np.uint16) * 257  # 16-bit scan, same picture
        write_image(rgb, path)
        scene_dir = out / "scenes" / path.stem
        params = dict(sc.params, image=name)
        write_json(scene_dir / "params.json", params)
        schema.write_tables(scene_dir / "truth", sc.summary, sc.tables)
        cx, cy = sc.params["hole_center_px"]
        overrides.append(f'[images."{name}"]\nhole_radius_mm = {sc.params["hole_radius_mm"]:.4f}\n'
                         f"hole_center_px = [{cx:.2f}, {cy:.2f}]\n")
        print(f"{name}: {rgb.shape[1]}x{rgb.shape[0]}, {sc.summary['n_stacks']} stacks, "
              f"{sc.summary['n_branches']} branches, max n_br {sc.tables['stacks']['n_br'].max()}, "
              f"{path.stat().st_size / 1e6:.2f} MB")
    write_csv(out / "calibration.csv", cal.to_frame(20))
    toml = ("# Synthetic sample scans written by scripts/make_sample_images.py (do not edit).\n"
            "# Truth: scenes/<stem>/truth/; score with crosssection.truth.scoring.score_folder.\n"
            'name = "samples"\npx_per_mm = 50\nthickness_mm = 0.1\n'
            'calibration = "calibration.csv"\n\n'
            "# hole of each scan (known from the generator; remove to let the pipeline fit it)\n"
            + "\n".join(overrides))
    write_text(out / "set.toml", toml)
    total = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    print(f"total {total / 1e6:.2f} MB in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
