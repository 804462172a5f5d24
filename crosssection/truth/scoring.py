"""Score an analysis against ground truth (synthetic scenes, simulator renders).

Both sides are ``(summary, tables)`` pairs in the schema of :mod:`crosssection.core.schema`, so the
scorer does not care how the truth was made (``crosssection.truth.network`` or ``simulate render``)
nor how the result was computed. An object with ``summary`` and ``junctions``/``stacks``/
``branches``/``voids`` DataFrame attributes (``AnalysisResult``) is accepted as well.

Matching rules (documented choices)
-----------------------------------
- Junctions: Hungarian assignment (``scipy.optimize.linear_sum_assignment``) on the Euclidean
  distance between (x_px, y_px), pairs farther than ``match_px`` (default 3 h) rejected;
  precision = matched / output, recall = matched / truth.
- Stacks: Hungarian assignment on the distance between stack mid points (``mid_x_px``,
  ``mid_y_px``, the point at half the centreline length), a pair accepted within
  ``max(match_px, 0.25 * truth length)``: the mid point of one physical stack moves by at most
  the junction offsets at its ends, while neighbouring stacks are about a stack length away.
  The n_br score is the fraction of the truth stack length (sum of ``length_mm``) whose matched
  output stack has exactly the truth ``n_br``; unmatched truth stacks count as wrong. The same
  fraction weighted by branches (``n_br * length``) is reported too, and the fraction whose
  matched n_br is within +-1 of the truth (the paper's error level on thick stacks).
- Voids: Hungarian assignment on centroid distance, accepted within
  ``max(match_px, 0.5 * sqrt(truth area))``; the area error is the median and the mean of
  ``|a_out / a_truth - 1|`` over matched voids, plus the error on the total void area.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

from crosssection.core import schema
from crosssection.core.errors import ConfigError, ParameterError
from crosssection.truth.scene import LAYER_PIECES, read_scene, read_scene_params

TABLE_NAMES = ("junctions", "stacks", "branches", "voids")


def _as_pair(obj, name: str = "result"):
    """(summary, tables) from a pair, an AnalysisResult-like object, a scene or a folder path;
    ``ParameterError`` naming the argument for anything else."""
    if isinstance(obj, (str, Path)):
        return schema.read_tables(obj)
    if isinstance(obj, tuple) and len(obj) == 2:
        summary, tables = obj
    else:
        summary = getattr(obj, "summary", None)
        # an AnalysisResult holds its tables as attributes, a Scene in its ``tables``
        held = getattr(obj, "tables", None)
        tables = (held if isinstance(held, dict) else
                  {t: getattr(obj, t, None) for t in TABLE_NAMES})
    missing = [t for t in TABLE_NAMES
               if not isinstance(tables, dict) or not isinstance(tables.get(t), pd.DataFrame)]
    if not isinstance(summary, dict) or missing:
        raise ParameterError(
            f"{name} must be an analysis result, a (summary, tables) pair or a folder path, "
            f"got {type(obj).__name__}"
            + (f" without the table(s) {', '.join(missing)}" if missing and
               isinstance(summary, dict) else ""))
    return summary, tables


def _rel(a, b):
    """Relative error (a - b) / b; NaN when b == 0 and a != 0, 0 when both are 0."""
    a, b = float(a), float(b)
    if b == 0:
        return 0.0 if a == 0 else float("nan")
    return (a - b) / abs(b)


def medial_fork_points(paths_rc, width_px, stack_ends, junction_ids, junctions_rc, shape, *,
                       stride: int = 1) -> np.ndarray:
    """Every truth junction moved to where its bands separate: the nearest fork of the medial
    axis of the bands drawn without defects.

    A generator's junction is a node of its graph, where the centrelines meet, inside the ink
    of merged bands at a thick or tangential fork; an image shows the fork where the bands
    separate, the medial-axis fork (the paper's junction is a skeleton pixel with three
    neighbours). The bands are redrawn as discs of their width along every centreline
    (1/16 px precision) and thinned (``skimage.morphology.skeletonize``); forks are the
    clusters of skeleton pixels with three or more neighbours. A junction takes the centre of
    the nearest cluster within the widest band meeting there, and keeps its own point where
    there is none.

    Parameters
    ----------
    paths_rc : sequence of (P, 2) arrays
        Centreline of every stack, (row, col) px.
    width_px : (M,) array
        Band width of every stack, px.
    stack_ends : (M, 2) int array
        Junction id at both ends of every stack (-1: none).
    junction_ids : (K,) int array
    junctions_rc : (K, 2) array
        The generator's junction points, (row, col) px.
    shape : (int, int)
        Image shape.
    stride : int
        Draw a disc at every ``stride``-th centreline point (the points lie well within a
        band width of each other).

    Returns
    -------
    (K, 2) float array
        (row, col) px per junction.
    """
    import cv2
    from scipy import ndimage
    from scipy.spatial import cKDTree
    from skimage.morphology import skeletonize

    out = np.array(junctions_rc, float).reshape(-1, 2)
    widest = {}
    mask = np.zeros(tuple(shape[:2]), np.uint8)
    for path, w, ends in zip(paths_rc, np.asarray(width_px, float), np.asarray(stack_ends, int)):
        for j in ends:
            widest[int(j)] = max(widest.get(int(j), 0.0), float(w))
        radius16 = int(round(8.0 * w))  # radius in 1/16 px (shift=4)
        for r, c in np.asarray(path, float).reshape(-1, 2)[::stride]:
            cv2.circle(mask, (int(round(16 * c)), int(round(16 * r))), radius16, 1, -1,
                       cv2.LINE_8, 4)
    skel = skeletonize(mask > 0)
    nb = ndimage.convolve(skel.astype(np.uint8), np.ones((3, 3), np.uint8), mode="constant")
    lab, n = ndimage.label(skel & (nb >= 4), structure=np.ones((3, 3)))
    if n == 0 or not len(out):
        return out
    forks = np.array(ndimage.center_of_mass(lab > 0, lab, np.arange(1, n + 1)))
    d, k = cKDTree(forks).query(out)
    near = d <= np.array([widest.get(int(j), 0.0) for j in junction_ids])
    out[near] = forks[k[near]]
    return out


def match_points(out_xy: np.ndarray, truth_xy: np.ndarray, max_dist) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian matching of two point sets within ``max_dist``.

    Parameters
    ----------
    out_xy, truth_xy : np.ndarray
        (N, 2) and (M, 2) coordinates.
    max_dist : float or np.ndarray
        Largest accepted distance, scalar or one per truth point.

    Returns
    -------
    (out_idx, truth_idx) : tuple of int arrays
        Indices of the matched pairs.
    """
    out_xy = np.asarray(out_xy, float).reshape(-1, 2)
    truth_xy = np.asarray(truth_xy, float).reshape(-1, 2)
    if not len(out_xy) or not len(truth_xy):
        return np.zeros(0, int), np.zeros(0, int)
    d = cdist(out_xy, truth_xy)
    lim = np.broadcast_to(np.asarray(max_dist, float), (len(truth_xy),))[None, :]
    big = 1e9
    cost = np.where(d <= lim, d, big)
    r, c = linear_sum_assignment(cost)
    ok = cost[r, c] < big
    return r[ok], c[ok]


def match_stacks(out_stacks, truth_stacks, *, match_px: float,
                 px_per_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Match output stacks to truth stacks by their mid points (:func:`match_points`), each
    truth stack within ``max(match_px, a quarter of its length)``: the mid point of one
    physical stack moves along it with where its ends are placed.

    Parameters
    ----------
    out_stacks, truth_stacks : pandas.DataFrame
        Stack tables with ``mid_x_px`` and ``mid_y_px``; the truth's with ``length_mm``.
    match_px : float
        The least accepted distance, px (3 h in the benchmarks).
    px_per_mm : float

    Returns
    -------
    (out_idx, truth_idx) : tuple of int arrays
        Row positions of the matched pairs.
    """
    lim = np.maximum(match_px, 0.25 * truth_stacks["length_mm"].to_numpy(float) * px_per_mm)
    return match_points(out_stacks[["mid_x_px", "mid_y_px"]].to_numpy(float),
                        truth_stacks[["mid_x_px", "mid_y_px"]].to_numpy(float), lim)


def _recorded(given, name, result_summary, truth_summary, default) -> float:
    """A scale the caller gave, else the one the analysis (or the truth) recorded: a scan of
    25 px/mm scored at 50 would match junctions within 6 h."""
    if given is not None:
        return float(given)
    for summary in (result_summary, truth_summary):
        for record in (summary.get("parameters") or {}, summary):
            value = record.get(name) if isinstance(record, dict) else None
            if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0:
                return float(value)
    return default


def score(result, truth, *, match_px: float | None = None, px_per_mm: float | None = None,
          thickness_mm: float | None = None) -> dict:
    """Compare an analysis with the truth.

    Parameters
    ----------
    result, truth : (summary, tables) pair, AnalysisResult-like object, scene or folder path
        ``tables`` holds the four schema DataFrames.
    match_px : float, optional
        Junction matching radius in pixels; default 3 h (``3 * thickness_mm * px_per_mm``).
    px_per_mm, thickness_mm : float, optional
        The scan's scale and sheet thickness, for the default ``match_px`` and the stack and
        void matching radii; default: those the analysis recorded (``summary["parameters"]``),
        else the truth's, else 50 px/mm and 0.1 mm.

    Returns
    -------
    dict
        ``rod_length_rel_error``, ``n_branches_rel_error``, ``n_stacks_rel_error``,
        ``n_junctions_rel_error``, ``junction_precision``, ``junction_recall``,
        ``junction_f1``, ``stack_match_fraction``, ``n_br_exact_length_fraction``,
        ``n_br_exact_branch_length_fraction``, ``n_br_within1_length_fraction``,
        ``n_br_mean_abs_error``, ``n_voids_rel_error``,
        ``void_match_fraction``, ``void_area_median_rel_error``, ``void_area_mean_rel_error``,
        ``void_total_area_rel_error``, ``stack_length_median_rel_error`` (matched stacks),
        ``total_energy_rel_error``, and what they rest on: ``match_px`` (the junction
        matching radius used), ``rod_length_mm`` and ``rod_length_mm_truth``,
        ``total_energy`` and ``total_energy_truth``, ``junction_matched``, ``junction_out``
        and ``junction_truth`` (counts) and ``junction_median_offset_px`` (matched pairs).
        Relative errors are signed ((out - truth) / truth). The branch and stack counts and
        the stack and n_br scores take the truth's ``layer_pieces`` table for its stacks when
        it has one (a render's bands as drawn, :data:`crosssection.truth.scene.LAYER_PIECES`).
    """
    rs, rt = _as_pair(result, "result")
    ts, tt = _as_pair(truth, "truth")
    px_per_mm = _recorded(px_per_mm, "px_per_mm", rs, ts, 50.0)
    thickness_mm = _recorded(thickness_mm, "thickness_mm", rs, ts, 0.1)
    if match_px is None:
        # rounded to 12 digits: 3 h of 0.1 mm at 50 px/mm is 15, not 15.000000000000002
        match_px = float(f"{3.0 * thickness_mm * px_per_mm:.12g}")
    out = {"match_px": float(match_px)}

    def total(summary, tables, key, col, weight=None):
        if key in summary and summary[key] is not None:
            return float(summary[key])
        df = tables[col[0]]
        if not len(df):
            return 0.0
        return float((df[col[1]] * (df[weight] if weight else 1)).sum())

    L_out = total(rs, rt, "rod_length_mm", ("stacks", "length_mm"), "n_br")
    L_true = total(ts, tt, "rod_length_mm", ("stacks", "length_mm"), "n_br")
    out["rod_length_mm"] = L_out
    out["rod_length_mm_truth"] = L_true
    out["rod_length_rel_error"] = _rel(L_out, L_true)
    nb_out = total(rs, rt, "n_branches", ("stacks", "n_br"))
    # counts, stacks and n_br against the bands as drawn where the truth has them: a band
    # narrowing where a layer ends inside it is two stacks of the analysis, cut at the step
    pieces = tt.get(LAYER_PIECES)
    drawn = pieces if isinstance(pieces, pd.DataFrame) and len(pieces) else None
    nb_true = (float(drawn["n_br"].sum()) if drawn is not None
               else total(ts, tt, "n_branches", ("stacks", "n_br")))
    out["n_branches_rel_error"] = _rel(nb_out, nb_true)
    out["n_stacks_rel_error"] = _rel(len(rt["stacks"]),
                                     len(drawn if drawn is not None else tt["stacks"]))
    out["n_junctions_rel_error"] = _rel(len(rt["junctions"]), len(tt["junctions"]))

    # junctions
    jo, jt = rt["junctions"], tt["junctions"]
    r, c = match_points(jo[["x_px", "y_px"]].to_numpy(float), jt[["x_px", "y_px"]].to_numpy(float),
                        match_px)
    nm = len(r)
    prec = nm / len(jo) if len(jo) else (1.0 if not len(jt) else 0.0)
    rec = nm / len(jt) if len(jt) else 1.0
    out.update(junction_matched=nm, junction_out=len(jo), junction_truth=len(jt),
               junction_precision=prec, junction_recall=rec,
               junction_f1=(2 * prec * rec / (prec + rec)) if prec + rec else 0.0)
    if nm:
        d = np.hypot(*(jo[["x_px", "y_px"]].to_numpy(float)[r] - jt[["x_px", "y_px"]].to_numpy(float)[c]).T)
        out["junction_median_offset_px"] = float(np.median(d))

    # stacks and n_br
    so, st = rt["stacks"], (drawn if drawn is not None else tt["stacks"])
    if len(st):
        r, c = match_stacks(so, st, match_px=match_px, px_per_mm=px_per_mm)
        ok = np.zeros(len(st), bool)
        nbr_out = np.full(len(st), -1)
        nbr_out[c] = so["n_br"].to_numpy(int)[r]
        ok[c] = nbr_out[c] == st["n_br"].to_numpy(int)[c]
        length = st["length_mm"].to_numpy(float)
        nbr_t = st["n_br"].to_numpy(int)
        out["stack_match_fraction"] = len(c) / len(st)
        out["n_br_exact_length_fraction"] = float(length[ok].sum() / length.sum())
        out["n_br_exact_branch_length_fraction"] = float((length * nbr_t)[ok].sum()
                                                         / (length * nbr_t).sum())
        # the paper's own error level (+-1 on about 20 % of the thick stacks at epsilon 19)
        near = np.zeros(len(st), bool)
        near[c] = np.abs(nbr_out[c] - nbr_t[c]) <= 1
        out["n_br_within1_length_fraction"] = float(length[near].sum() / length.sum())
        out["n_br_mean_abs_error"] = (float(np.mean(np.abs(nbr_out[c] - nbr_t[c]))) if len(c)
                                      else float("nan"))
        if len(c):
            lo = so["length_mm"].to_numpy(float)[r]
            out["stack_length_median_rel_error"] = float(np.median(np.abs(lo / length[c] - 1)))
    else:
        out.update(stack_match_fraction=1.0, n_br_exact_length_fraction=1.0,
                   n_br_exact_branch_length_fraction=1.0, n_br_within1_length_fraction=1.0,
                   n_br_mean_abs_error=0.0)

    # voids
    vo, vt = rt["voids"], tt["voids"]
    out["n_voids_rel_error"] = _rel(len(vo), len(vt))
    if len(vt):
        at = vt["area_mm2"].to_numpy(float)
        lim = np.maximum(match_px, 0.5 * np.sqrt(at) * px_per_mm)
        r, c = match_points(vo[["centroid_x_px", "centroid_y_px"]].to_numpy(float),
                            vt[["centroid_x_px", "centroid_y_px"]].to_numpy(float), lim)
        out["void_match_fraction"] = len(c) / len(vt)
        if len(c):
            rel = np.abs(vo["area_mm2"].to_numpy(float)[r] / at[c] - 1)
            out["void_area_median_rel_error"] = float(np.median(rel))
            out["void_area_mean_rel_error"] = float(np.mean(rel))
        out["void_total_area_rel_error"] = _rel(vo["area_mm2"].sum() if len(vo) else 0.0, at.sum())
    else:
        out["void_match_fraction"] = 1.0

    e_out = total(rs, rt, "total_energy", ("branches", "energy"))
    e_true = total(ts, tt, "total_energy", ("branches", "energy"))
    out["total_energy"] = e_out
    out["total_energy_truth"] = e_true
    out["total_energy_rel_error"] = _rel(e_out, e_true)
    return out


def score_folder(out_dir, scene_dir, *, match_px: float | None = None) -> dict:
    """Score an ``analyze`` output folder against a scene folder (``truth/`` + ``params.json``).

    Parameters
    ----------
    out_dir : str or Path
        Holds ``summary.json`` and the four CSV tables.
    scene_dir : str or Path
        A scene folder (:func:`crosssection.truth.scene.read_scene`; its ``px_per_mm`` and
        ``thickness_mm`` give the default matching radius).
    match_px : float, optional
        See :func:`score`.

    Returns
    -------
    dict
        As :func:`score`.

    Raises
    ------
    ConfigError
        Naming the file: a missing or malformed table or ``summary.json`` in ``out_dir``
        (:func:`crosssection.core.schema.read_tables`), or a malformed scene folder
        (:func:`crosssection.truth.scene.read_scene`).
    """
    scene = read_scene(scene_dir, image=False)
    result = schema.read_tables(out_dir)
    return score(result, (scene.summary, scene.tables), match_px=match_px,
                 px_per_mm=float(scene.params["px_per_mm"]),
                 thickness_mm=float(scene.params["thickness_mm"]))


def meets_targets(s: dict) -> dict:
    """The accuracy targets of typical scans as booleans: rod length within 3 %, junction F1 >= 0.95,
    exact n_br on >= 95 % of stack length, void count within 5 %."""
    return {
        "rod_length": abs(s["rod_length_rel_error"]) <= 0.03,
        "junction_f1": s["junction_f1"] >= 0.95,
        "n_br_exact": s["n_br_exact_length_fraction"] >= 0.95,
        "void_count": abs(s["n_voids_rel_error"]) <= 0.05,
    }


def _beside_or_above(scene_dir: Path, name: str) -> Path:
    """``scene_dir / name``, or the same name two folders up when only that exists: the
    bundled samples keep each scan beside its set, and its truth in ``scenes/<stem>/``."""
    here = scene_dir / name
    up = scene_dir.parent.parent / name
    return up if not here.exists() and up.exists() else here


def _set_calibration(scene_dir: Path) -> str | None:
    """The calibration file a scene's own ``set.toml`` names (relative to the scene folder),
    or None (no such file or key, an empty name, or a file that is no TOML: the analysis then
    looks for ``calibration.csv`` as without it)."""
    import tomllib

    try:
        with open(scene_dir / "set.toml", "rb") as fh:
            name = tomllib.load(fh).get("calibration")
    except (OSError, tomllib.TOMLDecodeError):
        return None
    return name.strip() if isinstance(name, str) and name.strip() else None


def analyze_scene_folder(scene_dir, *, image_name: str | None = None, use_hole: bool = True,
                         use_calibration: bool = True, **kwargs):
    """Run ``crosssection.analyze`` on a scene folder with the parameters of its ``params.json``.

    Parameters
    ----------
    scene_dir : str or Path
        Holds the image (``image.png`` unless ``image_name``), ``params.json`` and
        ``calibration.csv`` (the image and calibration may lie two folders up instead, as in
        the bundled samples: ``scan.png`` beside ``scenes/scan/``).
    use_hole : bool
        Pass the known hole (radius, centre); otherwise the pipeline fits it.
    use_calibration : bool
        Pass ``calibration.csv``; otherwise the pipeline's default (linear) law is used.
    **kwargs
        Fields of :class:`crosssection.params.AnalysisParams` overriding the scene's.

    Returns
    -------
    (result, (summary, tables))
        The ``AnalysisResult`` and the pair :func:`score` takes.

    Raises
    ------
    ConfigError
        The calibration file the scene's ``set.toml`` names is missing (with
        ``use_calibration``).
    """
    from crosssection import AnalysisParams, analyze

    scene_dir = Path(scene_dir)
    params = read_scene_params(scene_dir)
    image = _beside_or_above(scene_dir, image_name or params.get("image") or "image.png")
    want = {"px_per_mm": params.get("px_per_mm", 50.0),
            "thickness_mm": params.get("thickness_mm", 0.1)}
    if use_hole and params.get("hole_radius_mm"):
        want["hole_radius_mm"] = params["hole_radius_mm"]
        if params.get("hole_center_px"):
            want["hole_center_px"] = tuple(params["hole_center_px"])
    named = _set_calibration(scene_dir)
    cal = scene_dir / named if named else _beside_or_above(scene_dir, "calibration.csv")
    if use_calibration and cal.is_file():
        want["calibration"] = str(cal)
    elif use_calibration and named:
        # the scene was drawn with that law: read without it, its counts are another's
        raise ConfigError(f"{named}, the calibration its set.toml names, is missing",
                          scene_dir)
    want.update(kwargs)
    result = analyze(str(image), AnalysisParams.from_mapping(want, path=image),
                     scale_given="px_per_mm" in params)
    return result, _as_pair(result)


__all__ = ["score", "score_folder", "match_points", "match_stacks", "meets_targets",
           "analyze_scene_folder"]
