"""Validate the cross-section pipeline on rendered simulated rods (``validate`` subcommand).

``python -m simulate validate SCENES --out REPORT`` runs ``crosssection.analyze`` on every scene
folder of SCENES (``image.png``, ``params.json``, ``calibration.csv``, ``truth/``; written by
``python -m simulate render``), scores it against the truth with
``crosssection.truth.scoring.score`` and writes ``REPORT/scores.csv`` (one row per scene),
``REPORT/summary.json`` (means over the scored scenes) and ``REPORT/failures.csv`` (one line
per scene that could not be analysed: the run goes on).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.errors import ConfigError, FoldstatError
from crosssection.core.fileio import write_csv, write_json
from crosssection.truth.scene import read_scene
from crosssection.truth.scoring import analyze_scene_folder, score

__all__ = ["validate_scenes", "score_scene", "add_subparser"]

# the headline scores, first in scores.csv (crosssection.truth.scoring names)
KEY_COLUMNS = ["scene", "rod_length_rel_error", "n_branches_rel_error", "junction_precision",
               "junction_recall", "n_br_exact_length_fraction", "n_voids_rel_error",
               "void_area_mean_rel_error", "total_energy_rel_error"]


def score_scene(scene_dir, *, match_px: float | None = None) -> dict:
    """Analyse one scene folder with the pipeline and score it against its ``truth/``.

    Parameters
    ----------
    scene_dir : str or Path
    match_px : float, optional
        Junction matching radius (default: the scorer's, 3 h in pixels).

    Returns
    -------
    dict
        The scores of :func:`crosssection.truth.scoring.score` plus ``scene`` and ``analyze_s``.

    Raises
    ------
    FoldstatError
        Not a scene folder (:func:`crosssection.truth.scene.read_scene`), or the analysis
        failed.
    """
    scene_dir = Path(scene_dir)
    truth = read_scene(scene_dir, image=False)
    t0 = time.perf_counter()
    _, pair = analyze_scene_folder(scene_dir)
    dt = time.perf_counter() - t0
    out = {"scene": scene_dir.name}
    out.update(score(pair, (truth.summary, truth.tables), match_px=match_px,
                     px_per_mm=truth.params["px_per_mm"],
                     thickness_mm=truth.params["thickness_mm"]))
    out["analyze_s"] = dt
    return out


def validate_scenes(scenes_dir, out_dir, *, match_px: float | None = None,
                    progress: bool | None = None) -> pd.DataFrame:
    """Score every scene folder under ``scenes_dir``; write the report into ``out_dir``.

    ``progress``: a progress bar on stderr (None: only when stderr is a terminal).

    Returns
    -------
    DataFrame
        One row per scored scene (also written to ``scores.csv``).
    """
    scenes_dir, out_dir = Path(scenes_dir), Path(out_dir)
    if not scenes_dir.is_dir():
        raise ConfigError("not a folder", scenes_dir)
    scenes = sorted(p for p in scenes_dir.iterdir() if (p / "truth" / "summary.json").exists())
    if not scenes:
        raise ConfigError("no scene folders (with truth/summary.json) inside", scenes_dir)
    rows, failures = [], []
    from tqdm import tqdm

    it = tqdm(scenes, desc="validate", unit="scene",
              disable=None if progress is None else not progress)
    for scene in it:
        try:
            rows.append(score_scene(scene, match_px=match_px))
        except FoldstatError as exc:
            failures.append({"scene": scene.name, "error": exc.one_line()})
        except Exception as exc:  # noqa: BLE001 - one line per failed scene, never a crash
            failures.append({"scene": scene.name,
                             "error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"})
    df = pd.DataFrame(rows)
    if len(df):
        df = df[[c for c in KEY_COLUMNS if c in df.columns]
                + [c for c in df.columns if c not in KEY_COLUMNS]]
    write_csv(out_dir / "scores.csv", df)
    write_csv(out_dir / "failures.csv", pd.DataFrame(failures, columns=["scene", "error"]))
    numeric = df.select_dtypes(include=[np.number, "bool"]) if len(df) else pd.DataFrame()
    summary = {"n_scenes": len(scenes), "n_scored": len(df), "n_failed": len(failures),
               "mean": {c: float(numeric[c].astype(float).mean()) for c in numeric.columns},
               "mean_abs": {c: float(numeric[c].astype(float).abs().mean())
                            for c in numeric.columns if c.endswith("error")}}
    write_json(out_dir / "summary.json", summary)
    return df


def add_subparser(sub) -> None:
    """Register ``validate``: ``python -m simulate validate SCENES --out REPORT``."""
    p = sub.add_parser("validate", help="run the pipeline on rendered scenes and score it",
                       description="Analyse every scene folder of SCENES and score it against "
                                   "its truth: REPORT/scores.csv, summary.json, failures.csv.")
    p.add_argument("scenes", metavar="SCENES",
                   help="folder of scene folders (from render), each with its truth/")
    p.add_argument("--out", required=True, metavar="REPORT",
                   help="report folder (created): scores.csv, summary.json, failures.csv")
    p.add_argument("--match-px", type=float, default=None,
                   help="junction matching radius in px (default: 3 h of each scene)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: only when stderr is a terminal)")
    p.set_defaults(func=_run)


def _run(args) -> int:
    df = validate_scenes(args.scenes, args.out, match_px=args.match_px, progress=args.progress)
    print(f"{len(df)} scenes scored; report in {args.out}")
    return 0
