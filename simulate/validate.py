"""Validate the cross-section pipeline on rendered simulated rods (``validate`` subcommand).

``python -m simulate validate SCENES --out REPORT`` runs ``crosssection.analyze`` on every scene
folder of SCENES (``image.png``, ``params.json``, ``calibration.csv``, ``truth/``; written by
``python -m simulate render``), scores it against the truth with
``crosssection.truth.scoring.score`` and writes ``REPORT/scores.csv`` (one row per scene),
``REPORT/summary.json`` (means over the scored scenes, the options with the ``match_px``
used, the input folder and the package version) and ``REPORT/failures.csv`` (one line per
scene that could not be analysed or scored: the run goes on). Every subfolder of SCENES is
taken for a scene, so that one whose ``truth/`` is missing is listed as failed rather than
lost, but for report folders (:func:`is_report_folder`): a report may be written directly in
SCENES, not deeper.

A scene whose render flagged its truth (``truth_warnings`` in ``truth/summary.json``: the truth
disagrees with its own drawing, :class:`simulate.render.TruthWarning`) is scored, counted in the
``truth_warnings`` column of ``scores.csv`` and warned about, but left out of the summary's
``mean`` and ``mean_abs``: its scores measure the render as much as the analysis.
``mean_all`` and ``mean_abs_all`` are the means over every scored scene. Scenes of a rod
coarser than the render's truth is validated from (``truth_range`` in ``truth/summary.json``)
are scored and kept in the means, and named in ``summary.json`` (``beyond_validated``) and in
one warning per such range.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection._version import __version__
from crosssection.core import schema
from crosssection.core.errors import ConfigError, FoldstatError, ParameterError
from crosssection.core.fileio import foreign_entry, write_csv, write_json
from crosssection.truth.scene import LAYER_PIECES, read_scene_params, read_truth_tables
from crosssection.truth.scoring import analyze_scene_folder, score

__all__ = ["validate_scenes", "score_scene", "read_truth", "truth_warnings", "is_report_folder",
           "error_without_hairpins", "add_subparser", "REPORT_FILES"]

# the headline scores, first in scores.csv (crosssection.truth.scoring names)
KEY_COLUMNS = ["scene", "rod_length_rel_error", "n_branches_rel_error", "junction_precision",
               "junction_recall", "n_br_exact_length_fraction", "n_voids_rel_error",
               "void_area_mean_rel_error", "total_energy_rel_error"]

#: exit status of a run that finished with some scenes failed (as ``batch``, ``quench``)
EXIT_SOME_FAILED = 3

# the truth columns that score() turns into numbers: a text or missing value there would
# either crash the scoring with a message naming no file or score garbage
_NUMERIC_TRUTH = {
    "junctions": ["x_px", "y_px"],
    "stacks": ["length_mm", "n_br", "mid_x_px", "mid_y_px"],
    "branches": ["energy"],
    "voids": ["area_mm2", "centroid_x_px", "centroid_y_px"],
    LAYER_PIECES: ["length_mm", "n_br", "mid_x_px", "mid_y_px"],
}
# truth totals that score() prefers to the tables' sums when present
_SUMMARY_TOTALS = ["rod_length_mm", "n_branches", "total_energy"]


#: The largest junction matching radius (px) scoring takes: the default is 3 h (15 px at
#: 50 px/mm); a radius of a large scene's half width matches any junction to any other.
MAX_MATCH_PX = 1000.0


def _check_match_px(value, name: str) -> None:
    """Raise ParameterError unless ``value`` is None or a finite number in (0,
    :data:`MAX_MATCH_PX`]."""
    if value is None:
        return
    ok = (not isinstance(value, bool) and isinstance(value, (int, float, np.number))
          and math.isfinite(value) and value > 0)
    shown = f"{value:g}" if isinstance(value, (float, np.floating)) else repr(value)
    if not ok:
        raise ParameterError(f"must be a finite number > 0, got {shown}", name)
    if value > MAX_MATCH_PX:
        raise ParameterError(f"must be at most {MAX_MATCH_PX:g} px (the default is 3 sheet "
                             "thicknesses: a radius of half a scene matches any junction to "
                             f"any other), got {shown}", name)


def read_truth(truth_dir) -> tuple[dict, dict]:
    """Read a scene's ``truth/`` folder, checking what the scoring relies on.

    Parameters
    ----------
    truth_dir : str or Path
        Holds ``summary.json`` and the four tables of :data:`crosssection.core.schema.TABLES`
        (and a render's ``layer_pieces.csv``, :data:`crosssection.truth.scene.LAYER_PIECES`).

    Returns
    -------
    (summary, tables) : (dict, dict of DataFrame)
        The pair :func:`crosssection.truth.scoring.score` takes; each table has the schema's
        columns first.

    Raises
    ------
    ConfigError
        A file is missing or unreadable, ``summary.json`` is not a JSON object or holds a
        non-numeric total, a table lacks one of the schema's columns or holds a non-numeric
        or missing value where the scoring needs a number. The message names the file.
    """
    truth_dir = Path(truth_dir)
    summary, tables = read_truth_tables(truth_dir)
    path = truth_dir / "summary.json"
    for key in _SUMMARY_TOTALS:
        value = summary.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                  or not math.isfinite(value)):
            raise ConfigError(f"{key} must be a finite number or null, got {value!r}", path)
    for name, df in tables.items():
        for col in _NUMERIC_TRUTH[name]:
            values = pd.to_numeric(df[col], errors="coerce")
            if not np.isfinite(values.to_numpy(float)).all():
                raise ConfigError(f"column {col} must hold finite numbers",
                                  truth_dir / f"{name}.csv")
            df[col] = values
    warned = summary.get("truth_warnings")
    if warned is not None and not (isinstance(warned, list)
                                   and all(isinstance(m, str) for m in warned)):
        raise ConfigError(f"truth_warnings must be a list of messages, got {warned!r}", path)
    return summary, tables


def truth_warnings(summary: dict) -> list[str]:
    """The messages with which a scene's render flagged its truth.

    Parameters
    ----------
    summary : dict
        A truth ``summary.json`` as :func:`read_truth` returns it.

    Returns
    -------
    list of str
        Its ``truth_warnings`` (empty when the render flagged nothing or recorded no check).
    """
    return list(summary.get("truth_warnings") or [])


def score_scene(scene_dir, *, match_px: float | None = None) -> dict:
    """Analyse one scene folder with the pipeline and score it against its ``truth/``.

    Parameters
    ----------
    scene_dir : str or Path
    match_px : float, optional
        Junction matching radius in pixels, finite and > 0 (default: the scorer's, 3 h in
        pixels).

    Returns
    -------
    dict
        The scores of :func:`crosssection.truth.scoring.score` plus ``scene``, ``analyze_s``
        (seconds of the analysis; on a fresh install the first scene's include numba's
        compilation, several seconds), ``truth_warnings``, the number of messages with
        which the render flagged the scene's truth (:func:`truth_warnings`), and
        ``hairpin_energy_share``, the share of the truth's energy at nodes that fold the rod
        back within one segment (:func:`simulate.render.hairpin_nodes`), which no drawing
        shows, with ``total_energy_rel_error_without_hairpins``, the total's error against
        the truth's energy without them.

    Raises
    ------
    ParameterError
        ``match_px`` is not a finite number > 0.
    FoldstatError
        Not a scene folder (no ``truth/summary.json``), malformed ``truth/``
        (:func:`read_truth`) or ``params.json``, or the analysis failed.
    """
    _check_match_px(match_px, "match_px")
    scene_dir = Path(scene_dir)
    # the truth first: a folder without it is no scene, whatever else it holds
    if not (scene_dir / "truth" / "summary.json").is_file():
        raise ConfigError("no truth/summary.json (not a scene folder)", scene_dir)
    truth = read_truth(scene_dir / "truth")
    params = read_scene_params(scene_dir)
    t0 = time.perf_counter()
    _, pair = analyze_scene_folder(scene_dir)
    dt = time.perf_counter() - t0
    out = {"scene": scene_dir.name}
    out.update(score(pair, truth, match_px=match_px, px_per_mm=params["px_per_mm"],
                     thickness_mm=params["thickness_mm"]))
    out["analyze_s"] = dt
    out["truth_warnings"] = len(truth_warnings(truth[0]))
    # the truth's energy held by folds within one node, which no drawing shows (NaN for a
    # scene rendered before it was recorded), and the total's error without it
    share = float(truth[0].get("hairpin_energy_share", math.nan))
    out["hairpin_energy_share"] = share
    out["total_energy_rel_error_without_hairpins"] = error_without_hairpins(
        float(out.get("total_energy_rel_error", math.nan)), share)
    return out


def error_without_hairpins(error: float, share: float) -> float:
    """A total energy's relative error against the truth's energy less the share held by
    folds within one rod node (``hairpin_energy_share``), which no drawing shows.

    Parameters
    ----------
    error : float
        ``measured / truth - 1``.
    share : float
        The truth's share at such folds, in [0, 1).

    Returns
    -------
    float
        ``measured / (truth (1 - share)) - 1``; NaN where ``share`` is NaN or 1.
    """
    return (1.0 + error) / (1.0 - share) - 1.0 if share < 1.0 else math.nan


#: The files of a report folder (:func:`validate_scenes`).
REPORT_FILES = ("scores.csv", "summary.json", "failures.csv")


def is_report_folder(folder) -> bool:
    """Whether ``folder`` is a report folder: it holds a :data:`REPORT_FILES` and nothing
    else."""
    folder = Path(folder)
    return (folder.is_dir() and any((folder / f).is_file() for f in REPORT_FILES)
            and foreign_entry(folder, REPORT_FILES) is None)


def _check_out_dir(out_dir: Path) -> None:
    """Refuse a report folder holding anything but an earlier report (which a re-run
    replaces): the scores would be written beside another command's files (a render's
    scenes, an ensemble), which that command then refuses to resume."""
    if not out_dir.is_dir():
        return
    foreign = foreign_entry(out_dir, REPORT_FILES)
    if foreign is not None:
        raise ConfigError(f"holds {foreign}, which is no part of a validate report: give a "
                          "new folder, an empty one or one an earlier validate wrote", out_dir)


def _check_out_inside(scenes_dir: Path, out_dir: Path) -> None:
    """Refuse a report folder deeper inside ``scenes_dir`` than one of its subfolders: it
    would lie in a scene folder (or a subfolder taken for one), which the next ``validate``
    or ``render`` then finds holding files no scene has. A report directly in
    ``scenes_dir`` is kept apart from the scenes (:func:`_scene_folders`)."""
    out, root = out_dir.resolve(), scenes_dir.resolve()
    if out != root and out.is_relative_to(root) and out.parent != root:
        raise ConfigError(f"lies inside {scenes_dir / out.relative_to(root).parts[0]}, which "
                          f"validate takes for a scene: give a folder outside {scenes_dir} or "
                          "directly in it", out_dir)


def _scene_folders(scenes_dir: Path, out_dir: Path) -> list[Path]:
    """Every subfolder of ``scenes_dir`` but hidden ones and report folders: this run's
    (perhaps not yet written) and those of earlier runs given an ``--out`` there, which hold
    no scene (:func:`is_report_folder`), and other commands' outputs (a batch of the scenes,
    a stats report: :func:`crosssection.core.records.output_of`), which batch skips too."""
    from crosssection.core.records import output_of

    out = out_dir.resolve()
    return sorted(p for p in scenes_dir.iterdir()
                  if p.is_dir() and not p.name.startswith(".") and p.resolve() != out
                  and not is_report_folder(p) and output_of(p) is None)


def _one_line(exc: BaseException, scene: Path) -> str:
    """The cause of a failed scene in one line, a file named relative to the scene folder
    (which the failure line names already)."""
    if not isinstance(exc, FoldstatError):
        return f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    cause = " ".join(exc.cause.split())
    if exc.path is None:
        return cause
    where = Path(exc.path)
    if where == scene:
        return cause
    if where.is_relative_to(scene):
        return f"{where.relative_to(scene)}: {cause}"
    return exc.one_line()


def _means(df: pd.DataFrame) -> tuple[dict, dict]:
    """Mean of every numeric column of ``df``, and mean absolute value of its errors."""
    numeric = df.select_dtypes(include=[np.number, "bool"]) if len(df) else pd.DataFrame()
    return ({c: float(numeric[c].astype(float).mean()) for c in numeric.columns},
            {c: float(numeric[c].astype(float).abs().mean())
             for c in numeric.columns if c.endswith("error")})


def validate_scenes(scenes_dir, out_dir, *, match_px: float | None = None,
                    progress: bool | None = None) -> pd.DataFrame:
    """Score every scene folder under ``scenes_dir``; write the report into ``out_dir``.

    Every subfolder of ``scenes_dir`` (but hidden ones and report folders, ``out_dir`` and
    those of earlier runs, :func:`is_report_folder`) is a scene; one that
    cannot be analysed or scored, or has no ``truth/summary.json``, is a line of
    ``failures.csv`` (``scene``, ``error``) and the run goes on.

    Parameters
    ----------
    scenes_dir : str or Path
        Folder of scene folders (``python -m simulate render``).
    out_dir : str or Path
        Report folder, created first: ``scores.csv``, ``summary.json``, ``failures.csv``.
    match_px : float, optional
        Junction matching radius in pixels, finite and > 0 (default: 3 h of each scene);
        ``summary.json`` records the one used as ``options.match_px`` (by default the
        scenes' 3 h, or ``{scene: match_px}`` when their scales differ).
    progress : bool, optional
        A progress bar on stderr (None: only when stderr is a terminal).

    Returns
    -------
    DataFrame
        One row per scored scene (also written to ``scores.csv``).

    Raises
    ------
    ParameterError
        ``match_px`` is not a finite number > 0.
    ConfigError
        ``scenes_dir`` is not a folder or no subfolder of it has a ``truth/summary.json``,
        ``out_dir`` holds anything but an earlier report, or lies inside a subfolder of
        ``scenes_dir``.
    OSError
        ``out_dir`` cannot be created or written.

    Warns
    -----
    simulate.render.TruthWarning
        Once per scored scene whose render flagged its truth (``truth_warnings`` in its
        ``truth/summary.json``): it is scored but left out of the summary's ``mean`` and
        ``mean_abs`` (``mean_all`` and ``mean_abs_all`` hold it).
    simulate.render.ScanRangeWarning
        Once per ``truth_range`` of the scenes' renders (a rod coarser than the truth is
        validated from), naming how many scenes it holds (``beyond_validated`` in
        ``summary.json``).
    """
    return _validate(scenes_dir, out_dir, match_px=match_px, progress=progress)[0]


def _validate(scenes_dir, out_dir, *, match_px, progress) -> tuple[pd.DataFrame, list]:
    """:func:`validate_scenes`, returning the failures (dicts ``scene``, ``error``) too."""
    from simulate.render import ScanRangeWarning, TruthWarning

    _check_match_px(match_px, "match_px")
    scenes_dir, out_dir = Path(scenes_dir), Path(out_dir)
    if not scenes_dir.exists():
        raise ConfigError("folder not found", scenes_dir)
    if not scenes_dir.is_dir():
        raise ConfigError("not a folder", scenes_dir)
    _check_out_inside(scenes_dir, out_dir)
    scenes = _scene_folders(scenes_dir, out_dir)
    if not any((p / "truth" / "summary.json").is_file() for p in scenes):
        raise ConfigError("no scene folders (with truth/summary.json) inside", scenes_dir)
    # before the analyses: an unusable --out should not cost the whole run
    _check_out_dir(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows, failures, ranges = [], [], {}
    from tqdm import tqdm

    it = tqdm(scenes, desc="validate", unit="scene",
              disable=None if progress is None else not progress)
    for scene in it:
        try:
            rows.append(score_scene(scene, match_px=match_px))
        except Exception as exc:  # noqa: BLE001 - one line per failed scene, never a crash
            failures.append({"scene": scene.name, "error": _one_line(exc, scene)})
            continue
        # the messages: score_scene returns numbers only (and has checked the file)
        truth = json.loads((scene / "truth" / "summary.json").read_text())
        if rows[-1]["truth_warnings"]:
            warnings.warn(f"{scene}: its truth is flagged by its render: "
                          f"{'; '.join(truth_warnings(truth))} (scored, left out of the means)",
                          TruthWarning, stacklevel=3)
        if isinstance(truth.get("truth_range"), str):
            ranges.setdefault(truth["truth_range"], []).append(scene.name)
    for message, names in ranges.items():
        # once per range (an ensemble's rods share their segment count), not per scene
        warnings.warn(f"{scenes_dir}: {len(names)} scene(s): {message}", ScanRangeWarning,
                      stacklevel=3)
    df = pd.DataFrame(rows)
    if len(df):
        df = df[[c for c in KEY_COLUMNS if c in df.columns]
                + [c for c in df.columns if c not in KEY_COLUMNS]]
    write_csv(out_dir / "scores.csv", df)
    write_csv(out_dir / "failures.csv", pd.DataFrame(failures, columns=["scene", "error"]))
    flagged = df["scene"][df["truth_warnings"] > 0].tolist() if len(df) else []
    mean, mean_abs = _means(df[df["truth_warnings"] == 0] if len(df) else df)
    mean_all, mean_abs_all = _means(df)
    summary = {"package": "foldstat", "version": __version__,
               "scenes_dir": str(scenes_dir.resolve()),
               "options": {"match_px": _match_px_used(df, match_px)},
               "n_scenes": len(scenes), "n_scored": len(df), "n_failed": len(failures),
               "failed": [f["scene"] for f in failures],
               # a truth its render flagged measures the render as much as the analysis
               "n_flagged": len(flagged), "flagged": flagged,
               # rods coarser than the render's truth is validated from: scored, in the means
               "beyond_validated": sorted(n for names in ranges.values() for n in names),
               "mean": mean, "mean_abs": mean_abs,
               "mean_all": mean_all, "mean_abs_all": mean_abs_all}
    write_json(out_dir / "summary.json", summary)
    return df, failures


def _match_px_used(df: pd.DataFrame, match_px: float | None):
    """The junction matching radius the scores used (``summary.json`` ``options.match_px``):
    the one given; by default each scene's own 3 h, one number when the scenes share it (the
    usual case: one scale and thickness), else ``{scene: match_px}``; None when no scene was
    scored."""
    if match_px is not None:
        return float(match_px)
    if not len(df) or "match_px" not in df.columns:
        return None
    used = {str(k): float(v) for k, v in zip(df["scene"], df["match_px"])}
    values = set(used.values())
    return values.pop() if len(values) == 1 else used


def add_subparser(sub) -> None:
    """Register ``validate``: ``python -m simulate validate SCENES --out REPORT``."""
    p = sub.add_parser(
        "validate", help="run the pipeline on rendered scenes and score it",
        description="Analyse every scene folder of SCENES and score it against its truth: "
                    "REPORT/scores.csv, summary.json, failures.csv. A scene that cannot be "
                    "analysed or scored (a subfolder without truth/ included) is listed in "
                    "REPORT/failures.csv and on stderr as 'warning: SCENE: not analysed: "
                    "REASON'; the run goes on and exits with status 3. A scene whose render "
                    "flagged its truth (truth_warnings in its truth/summary.json) is scored, "
                    "named in a 'warning: SCENE: its truth is flagged by its render' line and "
                    "left out of summary.json's mean and mean_abs (mean_all and mean_abs_all "
                    "keep it).")
    p.add_argument("scenes", metavar="SCENES",
                   help="folder of scene folders (from render), each with its truth/")
    p.add_argument("--out", required=True, metavar="REPORT",
                   help="report folder (created): scores.csv, summary.json, failures.csv; "
                        "a re-run replaces them; a folder holding other files is refused; "
                        "inside SCENES only directly (a report there is no scene)")
    p.add_argument("--match-px", type=float, default=None,
                   help="junction matching radius in px, > 0 (default: 3 h of each scene)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: only when stderr is a terminal)")
    p.set_defaults(func=_run)


def _run(args) -> int:
    """Entry point of ``validate``; returns the exit status (0 every scene scored, 3 some
    failed, each named in one ``warning:`` line on stderr)."""
    from crosssection.core.fileio import check_out

    check_out(args.out)
    _check_match_px(args.match_px, "--match-px")
    df, failures = _validate(args.scenes, args.out, match_px=args.match_px,
                             progress=args.progress)
    for f in failures:
        print(f"warning: {Path(args.scenes) / f['scene']}: not analysed: {f['error']}",
              file=sys.stderr)
    n_flagged = int((df["truth_warnings"] > 0).sum()) if len(df) else 0
    flagged = (f" ({n_flagged} with a truth flagged by its render, left out of the means)"
               if n_flagged else "")
    if n_flagged and n_flagged == len(df):
        # summary.json's mean is then empty: say where the scores are
        flagged = (f" (every one with a truth flagged by its render: summary.json's mean is "
                   "empty, mean_all holds their means)")
    print(f"{len(df)} scenes scored{flagged}, {len(failures)} failed; report in {args.out}"
          + (f" (see {Path(args.out) / 'failures.csv'})" if len(failures) else ""))
    return EXIT_SOME_FAILED if len(failures) else 0
