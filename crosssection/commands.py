"""The ``analyze`` and ``steps`` subcommands of ``python -m crosssection``.

``python -m crosssection analyze IMAGE --px-per-mm 50 --thickness-mm 0.1 [--hole-radius-mm R]
[--hole-center-px X Y] [--calibration CSV] [--rod-length-mm L] [--no-figure] --out DIR`` writes
``summary.json``, ``junctions.csv``, ``stacks.csv``, ``branches.csv``, ``voids.csv`` and
``overlay.png`` into DIR.

``python -m crosssection steps IMAGE [same options] --out DIR`` writes the step images of paper
Fig. 2: ``step1_raw.png``, ``step2_threshold.png``, ``step3_clean.png``,
``step4_skeleton.png`` and ``steps.png`` (the four side by side).

Expected failures (bad image, bad parameter) are turned into one line on stderr with a
non-zero exit status by ``crosssection.cli``.
"""
from __future__ import annotations

import argparse
from pathlib import Path


def _common(p: argparse.ArgumentParser, *, full: bool) -> None:
    p.add_argument("image", help="scan (PNG, TIFF 8/16-bit, JPEG)")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--px-per-mm", type=float, default=50.0, help="scan resolution (default 50)")
    p.add_argument("--thickness-mm", type=float, default=0.1,
                   help="sheet thickness h in mm (default 0.1)")
    p.add_argument("--blue-min", type=float, default=None,
                   help="threshold: minimum blue, native units (default 100 for 8-bit)")
    p.add_argument("--rg-max", type=float, default=None,
                   help="threshold: maximum red and green, native units (default 130 for 8-bit)")
    p.add_argument("--threshold-method", choices=("fixed", "otsu"), default="fixed",
                   help="fixed thresholds, or Otsu on blue dominance (default fixed)")
    p.add_argument("--s-min-mm2", type=float, default=None,
                   help="smallest void in mm^2 (default (10 h)^2)")
    p.add_argument("--l-min-mm", type=float, default=1.0,
                   help="shortest branch detected, mm (default 1; shorter spurs are pruned)")
    if not full:
        return
    p.add_argument("--hole-radius-mm", type=float, default=None,
                   help="hole radius R in mm (default: fitted to the ink)")
    p.add_argument("--hole-center-px", type=float, nargs=2, metavar=("X", "Y"), default=None,
                   help="hole centre in pixels, x = column, y = row (default: fitted)")
    p.add_argument("--calibration", default=None,
                   help="CSV n_layers,width_mm of cut stacks (default width = n h)")
    p.add_argument("--rod-length-mm", type=float, default=None,
                   help="known rod length L, mm (default: measured sum n_br l)")
    p.add_argument("--kappa-c-per-mm", type=float, default=None,
                   help="plastic curvature threshold for the energy, 1/mm (default none)")
    p.add_argument("--tangent-mm", type=float, default=None,
                   help="length of the tangent fit at junctions, mm (default automatic)")
    p.add_argument("--no-figure", action="store_true", help="do not draw overlay.png")
    p.add_argument("--steps", action="store_true",
                   help="also save the step images of paper Fig. 2")


def add_subparser(subparsers) -> None:
    """Register ``analyze`` and ``steps`` on the ``python -m crosssection`` parser."""
    pa = subparsers.add_parser(
        "analyze", help="analyse one scan into junctions, stacks, branches and voids",
        description="Analyse one scan of a cut cross-section (paper, 'Image analysis "
                    "procedure') and write summary.json, junctions.csv, stacks.csv, "
                    "branches.csv, voids.csv and overlay.png.")
    _common(pa, full=True)
    pa.set_defaults(func=run)
    ps = subparsers.add_parser(
        "steps", help="save the image-processing steps of one scan (paper Fig. 2)",
        description="Save the raw scan, the thresholded and cleaned masks and the skeleton "
                    "with its junctions as PNG images (paper Fig. 2).")
    _common(ps, full=False)
    ps.add_argument("--no-figure", action="store_true",
                    help="only the four single images, not the combined steps.png")
    ps.set_defaults(func=run_steps)


def run(args) -> int:
    """``analyze``: run the pipeline and write the output folder."""
    from crosssection.pipeline import analyze

    result = analyze(
        args.image, px_per_mm=args.px_per_mm, thickness_mm=args.thickness_mm,
        hole_radius_mm=args.hole_radius_mm,
        hole_center_px=tuple(args.hole_center_px) if args.hole_center_px else None,
        calibration=args.calibration, rod_length_mm=args.rod_length_mm,
        blue_min=args.blue_min, rg_max=args.rg_max, threshold_method=args.threshold_method,
        s_min_mm2=args.s_min_mm2, l_min_mm=args.l_min_mm, kappa_c_per_mm=args.kappa_c_per_mm,
        tangent_mm=args.tangent_mm)
    result.write(Path(args.out), figure=not args.no_figure, steps=args.steps)
    s = result.summary
    print(f"{args.image}: {s['n_junctions']} junctions, {s['n_stacks']} stacks, "
          f"{s['n_branches']} branches, {s['n_voids']} voids, L = {s['rod_length_mm']:.1f} mm"
          f" -> {args.out}")
    return 0


def run_steps(args) -> int:
    """``steps``: stages 1-6 only, then the step images."""
    from crosssection.pipeline import preprocess, write_step_images

    pre = preprocess(args.image, px_per_mm=args.px_per_mm, thickness_mm=args.thickness_mm,
                     blue_min=args.blue_min, rg_max=args.rg_max,
                     threshold_method=args.threshold_method, s_min_mm2=args.s_min_mm2,
                     l_min_mm=args.l_min_mm)
    paths = write_step_images(args.out, pre.rgb, pre.threshold.mask, pre.mask_clean,
                              pre.skeleton, pre.junctions.centers_rc,
                              figure=not args.no_figure)
    print(f"{args.image}: {len(paths)} step images -> {args.out}")
    return 0
