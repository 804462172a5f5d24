"""The ``analyze`` and ``steps`` subcommands of ``python -m crosssection``.

``python -m crosssection analyze IMAGE [analysis options] [--no-figure] [--steps] --out DIR``
writes ``summary.json``, ``junctions.csv``, ``stacks.csv``, ``branches.csv``, ``voids.csv``
and ``overlay.png`` into DIR. The analysis options are generated from
:class:`crosssection.params.AnalysisParams` (``--help`` lists them with units and defaults).

``python -m crosssection steps IMAGE [analysis options] --out DIR`` writes the step images of
paper Fig. 2: ``step1_raw.png``, ``step2_threshold.png``, ``step3_clean.png``,
``step4_skeleton.png`` and ``steps.png`` (the four side by side).
"""
from __future__ import annotations

from pathlib import Path

from crosssection.params import AnalysisParams, add_analysis_arguments


def add_subparser(subparsers) -> None:
    """Register ``analyze`` and ``steps`` on the ``python -m crosssection`` parser."""
    pa = subparsers.add_parser(
        "analyze", help="analyse one scan into junctions, stacks, branches and voids",
        description="Analyse one scan of a cut cross-section (paper, 'Image analysis "
                    "procedure') and write summary.json, junctions.csv, stacks.csv, "
                    "branches.csv, voids.csv and overlay.png.")
    pa.add_argument("image", help="scan (PNG, TIFF 8/16-bit, JPEG)")
    pa.add_argument("--out", required=True, help="output folder (created)")
    pa.add_argument("--no-figure", action="store_true", help="do not draw overlay.png")
    pa.add_argument("--steps", action="store_true",
                    help="also save the step images of paper Fig. 2")
    add_analysis_arguments(pa)
    pa.set_defaults(func=run)
    ps = subparsers.add_parser(
        "steps", help="save the image-processing steps of one scan (paper Fig. 2)",
        description="Save the raw scan, the thresholded and cleaned masks and the skeleton "
                    "with its junctions as PNG images (paper Fig. 2).")
    ps.add_argument("image", help="scan (PNG, TIFF 8/16-bit, JPEG)")
    ps.add_argument("--out", required=True, help="output folder (created)")
    ps.add_argument("--no-figure", action="store_true",
                    help="only the four single images, not the combined steps.png")
    add_analysis_arguments(ps)
    ps.set_defaults(func=run_steps)


def run(args) -> int:
    """``analyze``: run the pipeline and write the output folder."""
    from crosssection.pipeline import analyze

    params = AnalysisParams.from_cli_args(args, path=args.image)
    result = analyze(args.image, params)
    result.write(Path(args.out), figure=not args.no_figure, steps=args.steps)
    s = result.summary
    print(f"{args.image}: {s['n_junctions']} junctions, {s['n_stacks']} stacks, "
          f"{s['n_branches']} branches, {s['n_voids']} voids, L = {s['rod_length_mm']:.1f} mm"
          f" -> {args.out}")
    return 0


def run_steps(args) -> int:
    """``steps``: stages 1-6 only, then the step images."""
    from crosssection.pipeline import preprocess, write_step_images

    pre = preprocess(args.image, AnalysisParams.from_cli_args(args, path=args.image))
    paths = write_step_images(args.out, pre.rgb, pre.threshold.mask, pre.mask_clean,
                              pre.skeleton, pre.junctions.centers_rc,
                              figure=not args.no_figure)
    print(f"{args.image}: {len(paths)} step images -> {args.out}")
    return 0
