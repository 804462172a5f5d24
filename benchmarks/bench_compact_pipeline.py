"""The pipeline on renders of compacted rods, where the experiments are (epsilon 14-30).

    python benchmarks/bench_compact_pipeline.py [--epsilon 19:4,14:3,30:3] [--segments 2000]
        [--n-configs 4] [--seed 1] [--conditions scan,clean,polyline]
        [--work benchmarks/out/compact_pipeline] [--out benchmarks/out] [--overlays]

For every epsilon E (``E:K``: K configurations, default ``--n-configs``):
``python -m simulate compact --epsilon E --segments N --n-configs K --seed S`` into
``WORK/epsE/sim`` (kept when already there), then every configuration rendered by
:func:`simulate.render.render_configuration` as ``python -m simulate render`` does (the wall is
the hole, h = 0.1 mm = 5 px at 50 px/mm, the generators' nonlinear calibration) under each
condition:

=========  ================================================================================
scan       the defaults: a real scan's defects and plate (``simulate.render.SCAN_DEFECTS``)
clean      ``--clean``: the drawing alone
polyline   clean, the stacks drawn as the analysis' polylines (``smooth="none"``): what the
           corners of an unsmoothed drawing do to the measured energy
passes     the defaults, the rod itself drawn (``draw="passes"``: every pass a stroke, the
           passes of a stack pressed together) instead of one band per stack
passes_    ``passes``, clean
clean
passes_    ``passes`` with the pressing smoothed over one rod segment (``pass_smooth=1``): the
smooth     drawn passes bend as the rod does (1.00-1.01 times its energy at epsilon = 19)
passes_    ``passes_smooth``, clean
smooth_
clean
passes_    ``passes_smooth`` scored against a truth read from the drawing itself
drawn      (:func:`drawn_truth`): stacks and junctions of the drawn pass curves in contact
           where their strokes touch, each junction moved to the nearest fork of the clean
           drawing's skeleton; the energy the rod's (measured, not kept:
           docs/validation/compact.md, "Drawing the rod itself")
passes_    ``passes_drawn``, clean
drawn_
clean
=========  ================================================================================

Each scene is analysed with the calibration and the hole given, as a user who measured them
would (:func:`crosssection.truth.scoring.analyze_scene_folder`), and scored against its truth
(:func:`crosssection.truth.scoring.score`, junctions matched within 3 h). Per scene: exact n_br
fraction of the truth stack length, junction F1 (precision, recall), rod length and total
energy errors, and where the errors are: the share of the truth stack length left unmatched or
matched with a wrong n_br, n_br errors (of +-1) among the thick stacks (n_br >= 5), truth
stacks shorter than twice their band width (lumps in junction zones rather than bands) and the
missed truth junctions at one of them, the energy of matched stacks by n_br (truth and
measured) and of unmatched ones, and the share of the rod's energy at nodes turning more than
90 degrees (collapsed folds, drawn as band ends), and how much rod the bands draw (the sum of
n_br times the drawn stack length, over the rod length) and how much bending: the drawn
centrelines' ``sum n_br int kappa^2 ds`` over the rod's energy, in all and outside discs of
the widest band's width around every truth junction (``drawn_energy_ratio``, ``drawn_energy_ratio_outside``: the bending the
image holds, where the truth is the rod's). Times (wall): compaction
(``configs.csv`` wall_s), contact analysis, render, analysis.

Writes ``OUT/compact_pipeline.csv`` (one row per scene) and, with ``--overlays``,
``WORK/epsE/overlays/<config>_<condition>.png`` (the scan with missed truth junctions, extra
output junctions and stacks whose n_br is wrong). Prints the table of
``docs/validation/compact.md``.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.fileio import write_csv
from crosssection.core import schema
from crosssection.truth.scene import LAYER_PIECES, read_scene, write_scene
from crosssection.truth.scoring import (analyze_scene_folder, match_points, match_stacks,
                                         medial_fork_points, score)
from simulate.cli import main as simulate_main
from simulate.contacts import analyze_rod
from simulate import render as _render
from simulate.render import render_configuration

CONDITIONS = {"scan": {}, "clean": {"clean": True},
              "polyline": {"clean": True, "smooth": "none"},
              "passes": {"draw": "passes"}, "passes_clean": {"clean": True, "draw": "passes"},
              "passes_smooth": {"draw": "passes", "pass_smooth": 1.0},
              "passes_smooth_clean": {"clean": True, "draw": "passes", "pass_smooth": 1.0},
              "passes_drawn": {"draw": "passes", "pass_smooth": 1.0},
              "passes_drawn_clean": {"clean": True, "draw": "passes", "pass_smooth": 1.0}}
#: conditions scored against :func:`drawn_truth` instead of the rod's contact analysis
DRAWN = ("passes_drawn", "passes_drawn_clean")
#: :func:`drawn_truth`: paper between touching strokes still read as contact (px), the drawn
#: curve's resampling step (px), the widest hole of the clean ink filled before its skeleton
#: (px; a one-pixel gap between touching strokes), and how far beyond the widest band meeting
#: there a junction may move to a skeleton fork (in h)
DRAWN_TOLERANCE_PX, DRAWN_STEP_PX, DRAWN_FILL_PX, DRAWN_SNAP_H = 0.0, 2.0, 2.0, 4.0
TARGETS = {"n_br_exact_length_fraction": 0.85, "junction_f1": 0.90, "rod_length": 0.05,
           "total_energy": 0.25}
PX_PER_MM, THICKNESS_MM = 50.0, 0.1
THICK = 5  # n_br from which a stack counts as thick in the error breakdown


def _drawn_curve(xy, an, p, kwargs):
    """The pressed pass curves (x, y) px of ``draw="passes"``, its frame and the clean ink,
    computed as :func:`simulate.render.render_configuration` draws them for ``kwargs``."""
    stroke_px = _render.PASS_WIDTH * THICKNESS_MM * PX_PER_MM
    pitch_px = stroke_px - _render.PASS_OVERLAP_PX
    cal = _render.passes_calibration(stroke_px / PX_PER_MM, pitch_px / PX_PER_MM)
    frame = _render._frame(xy, an, cal, px_per_mm=PX_PER_MM, thickness_mm=THICKNESS_MM,
                           rod_length_mm=None, hole_radius_mm="auto", margin_mm=2.0,
                           gap_px=2.0, max_size_px=2500, rod_thickness=p["thickness"],
                           wall_radius=p["wall_radius"])
    segment_px = frame.scale / (len(xy) - 1)
    curve, branch_of, _ = _render._pass_curves(
        xy, an, frame, segment_px=segment_px, pitch_px=pitch_px, stroke_px=stroke_px,
        taper_px=_render.PASS_TAPER * stroke_px,
        smooth_px=kwargs.get("pass_smooth", _render.PASS_SMOOTH) * segment_px)
    coverage, _ = _render._draw_passes(curve, branch_of, an.branches["stack_id"].to_numpy(int),
                                       stroke_px, frame.shape)
    return curve, frame, cal, coverage >= 0.5


def _skeleton_forks(ink) -> np.ndarray:
    """(row, col) centres of the forks of the clean ink's skeleton: holes at most
    :data:`DRAWN_FILL_PX` wide filled (gaps between touching strokes), spurs reaching less
    than l_min = 1 mm beyond their band pruned (the pipeline's skeleton rule,
    :func:`crosssection.stages.skeleton.skeletonize_mask`), forks the clusters of skeleton
    pixels with three or more neighbours."""
    import cv2
    from scipy import ndimage

    from crosssection.stages.skeleton import neighbour_count, skeletonize_mask

    ink = np.asarray(ink, bool)
    lab, n = ndimage.label(~ink)
    if n:
        gap = cv2.distanceTransform((~ink).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        wide = 2.0 * ndimage.maximum(gap, lab, np.arange(1, n + 1))
        outer = np.unique(np.r_[lab[0], lab[-1], lab[:, 0], lab[:, -1]])
        ink = ink | np.isin(lab, np.setdiff1d(np.flatnonzero(wide <= DRAWN_FILL_PX) + 1, outer))
    dist = cv2.distanceTransform(ink.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    skel = skeletonize_mask(ink, l_min_px=PX_PER_MM, distance_px=dist)
    lab, n = ndimage.label(neighbour_count(skel) >= 3, structure=np.ones((3, 3)))
    if not n:
        return np.zeros((0, 2))
    return np.array(ndimage.center_of_mass(lab > 0, lab, np.arange(1, n + 1)))


_DRAWN_CACHE: dict = {}


def drawn_truth(xy, an, p, scene, kwargs, tolerance_px=None):
    """The truth the passes drawing shows: the scene's tables read from its drawn curve.

    Stacks, branches and junctions are those of :func:`simulate.contacts.analyze_rod` on the
    pressed pass curves (resampled every :data:`DRAWN_STEP_PX`), two passes in contact where
    their strokes touch (axes one stroke width apart, plus ``tolerance_px`` of paper); every
    junction then moves to the nearest fork of the clean drawing's skeleton
    (:func:`_skeleton_forks`) within the widest band meeting there plus
    :data:`DRAWN_SNAP_H` h. Stack lengths are the mean drawn length of their passes, branch
    energies the rod's over the same stretch of rod, the summary (rod length, total energy)
    the rod's.

    Parameters
    ----------
    xy : (N+1, 2) array
        The rod (units of L).
    an : simulate.contacts.RodAnalysis
        Its contact analysis (the passes' stacks, as the drawing presses them).
    p : dict
        The compaction's params.json (``thickness``, ``wall_radius``).
    scene : crosssection.truth.scene.Scene
        The rendered scene (its ink mask is checked against the redrawn curve).
    kwargs : dict
        The render's options (``pass_smooth``).
    tolerance_px : float, optional
        Paper between touching strokes still read as contact (default
        :data:`DRAWN_TOLERANCE_PX`).

    Returns
    -------
    (tables, paths_rc, drawn_energy)
        The truth tables, the stacks' mean lines (row, col) px, and the drawn curve's
        ``L int kappa^2 ds`` (the rod's energy's units).
    """
    from scipy.spatial import cKDTree

    tol = DRAWN_TOLERANCE_PX if tolerance_px is None else tolerance_px
    curve, frame, cal, ink = _drawn_curve(xy, an, p, kwargs)
    if not np.array_equal(ink, scene.ink_mask):
        raise RuntimeError("the drawn curve does not reproduce the scene's ink")
    stroke_px = _render.PASS_WIDTH * THICKNESS_MM * PX_PER_MM
    arc = np.r_[0.0, np.cumsum(np.hypot(*np.diff(curve, axis=0).T))]
    length_px = arc[-1]
    t = np.linspace(0.0, length_px, int(round(length_px / DRAWN_STEP_PX)) + 1)
    pts = np.c_[np.interp(t, arc, curve[:, 0]), np.interp(t, arc, curve[:, 1])] / length_px
    key = (hash(pts.tobytes()), tol)
    if key not in _DRAWN_CACHE:  # the scan and clean conditions draw the same curve
        _DRAWN_CACHE.clear()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _DRAWN_CACHE[key] = analyze_rod(pts, lam=0.0,
                                            contact_distance=(stroke_px + tol) / length_px)
    dan = _DRAWN_CACHE[key]
    st, jt, br = dan.stacks, dan.junctions, dan.branches
    widths_px = cal.width(st["n_br"].to_numpy(int)) * PX_PER_MM
    # junctions at the skeleton's forks
    jxy = jt[["x", "y"]].to_numpy(float) * length_px if len(jt) else np.zeros((0, 2))
    forks = _skeleton_forks(ink)
    if len(jxy) and len(forks):
        widest = {}
        for sid, ends in enumerate(st[["junction_a", "junction_b"]].to_numpy(int)):
            for j in ends:
                widest[int(j)] = max(widest.get(int(j), 0.0), float(widths_px[sid]))
        reach = np.array([widest.get(int(j), 0.0) for j in jt["junction_id"]])
        d, k = cKDTree(forks[:, ::-1]).query(jxy)
        near = d <= reach + DRAWN_SNAP_H * THICKNESS_MM * PX_PER_MM
        jxy[near] = forks[k[near], ::-1]
    junctions = pd.DataFrame({"junction_id": jt["junction_id"].astype(int) if len(jt) else [],
                              "x_px": jxy[:, 0], "y_px": jxy[:, 1],
                              "n_stacks": jt["n_stacks"].astype(int) if len(jt) else []},
                             columns=schema.JUNCTION_COLUMNS)
    lines_px = [np.asarray(line, float) * length_px for line in dan.stack_lines]
    stacks = _render._stack_table(st, lines_px, frame, cal, px_per_mm=PX_PER_MM,
                                  thickness_mm=THICKNESS_MM,
                                  layer_px={sid: float(row.n_br * row.length * length_px)
                                            for sid, row in st.iterrows()})
    # branch energies: the rod's over the stretch of rod the branch draws (the drawn curve's
    # samples lie at equal steps of the rod's arclength)
    s_rod = np.interp(np.r_[br["s_start"].to_numpy(float), 1.0] * length_px, arc,
                      np.linspace(0.0, 1.0, len(curve)))
    d2 = xy[2:] - 2 * xy[1:-1] + xy[:-2]
    n_seg = len(xy) - 1
    node_e = np.r_[0.0, np.einsum("ij,ij->i", d2, d2) * n_seg ** 3, 0.0]
    cum_e = np.r_[0.0, np.cumsum(node_e)]
    nodes = np.searchsorted(np.arange(n_seg + 1) / n_seg, s_rod, side="left")
    energy = np.diff(cum_e[nodes])
    mm_per_unit = length_px / PX_PER_MM
    branches = pd.DataFrame({
        "branch_id": br["branch_id"].astype(int), "stack_id": br["stack_id"].astype(int),
        "length_mm": br["length"] * mm_per_unit, "kappa_pm": br["kappa_pm"] / mm_per_unit,
        "kappa_plus": br["kappa_plus"] / mm_per_unit,
        "kappa_m": br["kappa_pm"].abs() / mm_per_unit, "energy": energy,
        "region": stacks["region"].to_numpy()[br["stack_id"].to_numpy(int)]},
        columns=schema.BRANCH_COLUMNS)
    tables = {**scene.tables, "junctions": junctions, "stacks": stacks, "branches": branches}
    tables.pop(LAYER_PIECES, None)
    drawn_energy = float(dan.energy_bending * scene.summary["rod_length_mm"] * PX_PER_MM
                         / length_px)
    return tables, [line[:, ::-1] for line in lines_px], drawn_energy


def _fold_share(xy) -> float:
    """Share of the discrete bending energy at nodes turning more than 90 degrees."""
    d = np.diff(xy, axis=0)
    dth = np.abs(np.diff(np.unwrap(np.arctan2(d[:, 1], d[:, 0]))))
    e = dth ** 2
    return float(e[dth > np.pi / 2].sum() / e.sum()) if e.sum() > 0 else 0.0


def _junction_discs(scene) -> tuple[np.ndarray, np.ndarray]:
    """Truth junctions (row, col) px and the widest band width meeting at each, px."""
    st = scene.tables["stacks"].reset_index(drop=True)
    jt = scene.tables["junctions"]
    width_px = st["width_mm"].to_numpy(float) * scene.params["px_per_mm"]
    widest = np.zeros(len(jt))
    row = {int(j): i for i, j in enumerate(jt["junction_id"].to_numpy(int))}
    for end in ("junction_a", "junction_b"):
        for j, wd in zip(st[end].to_numpy(int), width_px):
            if j in row:
                widest[row[j]] = max(widest[row[j]], wd)
    return jt[["y_px", "x_px"]].to_numpy(float), widest


def _drawn_energy(scene) -> tuple[float, float]:
    """The drawn bands' ``sum n_br int kappa^2 ds`` over the rod's energy: in all, and outside
    discs of the widest band's width around every truth junction.

    The curvature of each drawn centreline (``scene.paths_rc``, about one point per px) is its
    turning angle per unit arc; the rod's energy is the truth's ``total_energy`` (``L int
    kappa^2 ds`` summed over branches) over L.
    """
    from scipy.spatial.distance import cdist

    st = scene.tables["stacks"].reset_index(drop=True)
    px = scene.params["px_per_mm"]
    junctions, widest = _junction_discs(scene)
    total = outside = 0.0
    for k, path in enumerate(scene.paths_rc):
        p = np.asarray(path, float).reshape(-1, 2)
        d = np.diff(p, axis=0)
        ds = np.hypot(d[:, 0], d[:, 1])
        p, d, ds = p[1:][ds > 1e-9], d[ds > 1e-9], ds[ds > 1e-9]
        if len(ds) < 5:
            continue
        theta = np.unwrap(np.arctan2(d[:, 0], d[:, 1]))
        w = 0.5 * (ds[:-1] + ds[1:])
        f = (np.diff(theta) / w) ** 2 * w * px * int(st["n_br"][k])  # 1/mm
        total += f.sum()
        inside = (cdist(p[:-1], junctions) < widest).any(axis=1)
        outside += f[~inside].sum()
    rod = scene.summary["total_energy"] / scene.summary["rod_length_mm"]
    return total / rod, outside / rod


def _measured_outside(scene, result) -> float:
    """The analysis' ``sum n_br int kappa^2 ds`` outside the discs of :func:`_drawn_energy`
    (its curvature profiles, fork zones included, before the noise floor is removed), over
    the rod's energy."""
    from scipy.spatial.distance import cdist

    junctions, widest = _junction_discs(scene)
    outside = 0.0
    for prof, n in zip(result.profiles, result.stacks["n_br"].to_numpy(int)):
        if len(prof.s_mm) < 2:
            continue
        e = n * prof.kappa_per_mm ** 2 * np.gradient(prof.s_mm)
        outside += e[~(cdist(prof.rc_px, junctions) < widest).any(axis=1)].sum()
    return outside / (scene.summary["total_energy"] / scene.summary["rod_length_mm"])


def _rod_outside(xy, scene) -> float:
    """Share of the rod's discrete energy (``sum dtheta^2 / ds`` over its nodes, equal
    segments) at nodes outside the discs of :func:`_drawn_energy`, the rod placed as the
    render placed it (``origin_xy``, ``margin_px``, px per unit L)."""
    from scipy.spatial.distance import cdist

    p = scene.params
    px = ((np.asarray(xy, float) - np.asarray(p["origin_xy"], float))
          * p["rod_length_mm"] * p["px_per_mm"] + p["margin_px"])[:, ::-1]  # (row, col)
    d = np.diff(np.asarray(xy, float), axis=0)
    e = np.angle(np.exp(1j * np.diff(np.arctan2(d[:, 1], d[:, 0])))) ** 2
    junctions, widest = _junction_discs(scene)
    inside = (cdist(px[1:-1], junctions) < widest).any(axis=1)
    return float(e[~inside].sum() / e.sum()) if e.sum() > 0 else float("nan")


def _fork_f1(scene, pair, h_px: float) -> float:
    """Junction F1 against the truth junctions moved to where the drawn bands separate (the
    medial-axis forks of the bands drawn without defects,
    :func:`crosssection.truth.scoring.medial_fork_points`): the targets' placement, where the
    contact analysis' points lie inside merged ink."""
    st, jt = scene.tables["stacks"], scene.tables["junctions"]
    forks = medial_fork_points(scene.paths_rc, st["width_mm"] * scene.params["px_per_mm"],
                               st[["junction_a", "junction_b"]].to_numpy(int),
                               jt["junction_id"].to_numpy(int),
                               jt[["y_px", "x_px"]].to_numpy(float), scene.rgb.shape)
    out = pair[1]["junctions"][["x_px", "y_px"]].to_numpy(float)
    r, _ = match_points(out, forks[:, ::-1], 3 * h_px)
    return 2.0 * len(r) / (len(out) + len(forks)) if len(out) + len(forks) else 1.0


def _breakdown(pair, truth, h_px: float) -> dict:
    """Where the errors are (the scorer's matching rules): n_br errors, unmatched stacks,
    missed junctions, and the energy by kind of stack."""
    (_, out_t), (_, tru_t) = pair, truth
    so, st = out_t["stacks"], tru_t["stacks"]
    r, c = match_stacks(so, st, match_px=3 * h_px, px_per_mm=PX_PER_MM)
    nbr_t = st["n_br"].to_numpy(int)
    length = st["length_mm"].to_numpy(float)
    # a stack shorter than twice its band's width is a lump in a junction zone, not a band
    stubby = length < 2.0 * st["width_mm"].to_numpy(float)
    err = so["n_br"].to_numpy(int)[r] - nbr_t[c]
    thick = nbr_t[c] >= THICK
    unmatched = np.setdiff1d(np.arange(len(st)), c)
    jo, jt = out_t["junctions"], tru_t["junctions"]
    rj, cj = match_points(jo[["x_px", "y_px"]].to_numpy(float),
                          jt[["x_px", "y_px"]].to_numpy(float), 3 * h_px)
    missed = np.setdiff1d(np.arange(len(jt)), cj)
    at_stubby = set()
    for k, (ja, jb) in enumerate(st[["junction_a", "junction_b"]].to_numpy(int)):
        if stubby[k]:
            at_stubby.update(j for j in (ja, jb) if j >= 0)
    jid = jt["junction_id"].to_numpy(int)
    # energy per stack: truth (the rod's) and measured, on matched stacks by thickness and
    # on the stacks the other side does not have
    e_t = tru_t["branches"].groupby("stack_id")["energy"].sum().reindex(range(len(st)),
                                                                        fill_value=0.0)
    e_o = out_t["branches"].groupby("stack_id")["energy"].sum().reindex(range(len(so)),
                                                                        fill_value=0.0)
    e_t, e_o = e_t.to_numpy(float), e_o.to_numpy(float)
    cls = np.where(nbr_t[c] == 1, "1", np.where(nbr_t[c] < THICK, "2-4", "5+"))
    energy = {}
    for name in ("1", "2-4", "5+"):
        m = cls == name
        energy[f"energy_truth_nbr{name}"] = float(e_t[c[m]].sum())
        energy[f"energy_out_nbr{name}"] = float(e_o[r[m]].sum())
    energy["energy_truth_unmatched"] = float(e_t[unmatched].sum())
    energy["energy_out_unmatched"] = float(np.delete(e_o, r).sum())
    return {
        "truth_stacks": len(st), "matched_stacks": len(c),
        "nbr_wrong_matched": int((err != 0).sum()),
        "nbr_wrong_pm1": int((np.abs(err) == 1).sum()),
        "thick_matched": int(thick.sum()), "thick_wrong": int((err[thick] != 0).sum()),
        "thick_wrong_pm1": int((np.abs(err[thick]) == 1).sum()),
        "nbr_wrong_length_fraction": float(length[c[err != 0]].sum() / length.sum()),
        "unmatched_stacks": len(unmatched),
        "unmatched_length_fraction": float(length[unmatched].sum() / length.sum()),
        "unmatched_stubby": int(stubby[unmatched].sum()),
        "stubby_stacks": int(stubby.sum()),
        "stubby_length_fraction": float(length[stubby].sum() / length.sum()),
        "missed_junctions": len(missed),
        "missed_at_stubby": int(sum(int(jid[j]) in at_stubby for j in missed)),
        "junctions_at_stubby": int(sum(int(j) in at_stubby for j in jid)),
        "extra_junctions": int(len(jo) - len(rj)),
        **energy,
        "_missed": missed, "_extra": np.setdiff1d(np.arange(len(jo)), rj),
        "_wrong": [(int(c[i]), int(err[i])) for i in np.flatnonzero(err != 0)],
        "_unmatched": unmatched,
    }


def _overlay(path, scene, pair, b):
    """The scan with the scoring's failures drawn on it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, out_t = pair
    jt, jo = scene.tables["junctions"], out_t["junctions"]
    fig, ax = plt.subplots(figsize=(12, 12))
    ax.imshow(scene.rgb)
    for sid, e in b["_wrong"]:
        p = scene.paths_rc[sid] if scene.paths_rc else None
        row = scene.tables["stacks"].iloc[sid]
        ax.annotate(f"{int(row.n_br)}{e:+d}", (row.mid_x_px, row.mid_y_px), color="red",
                    fontsize=7, ha="center")
        if p is not None:
            ax.plot(p[:, 1], p[:, 0], "r-", lw=0.6)
    for sid in b["_unmatched"]:
        row = scene.tables["stacks"].iloc[sid]
        ax.plot(row.mid_x_px, row.mid_y_px, "x", color="orange", ms=5)
    ax.plot(jt["x_px"].to_numpy()[b["_missed"]], jt["y_px"].to_numpy()[b["_missed"]], "o",
            mfc="none", mec="red", ms=8, label="truth junction missed")
    ax.plot(jo["x_px"].to_numpy()[b["_extra"]], jo["y_px"].to_numpy()[b["_extra"]], "s",
            mfc="none", mec="magenta", ms=8, label="output junction unmatched")
    ax.plot([], [], "r-", label="stack with wrong n_br (truth n_br and error)")
    ax.plot([], [], "x", color="orange", label="truth stack unmatched")
    ax.legend(loc="lower left", fontsize=8)
    ax.set_axis_off()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def run(epsilons, *, segments, seed, conditions, work, overlays):
    """Compact, render, analyse and score; ``epsilons`` holds (epsilon, configurations)."""
    rows = []
    h_px = THICKNESS_MM * PX_PER_MM
    for eps, n_configs in epsilons:
        base = Path(work) / f"eps{eps:g}"
        sim = base / "sim"
        if not (sim / "rods.npz").exists():
            status = simulate_main(["compact", "--epsilon", f"{eps:g}", "--segments",
                                    str(segments), "--n-configs", str(n_configs), "--seed",
                                    str(seed), "--out", str(sim), "--no-progress"])
            if status:
                raise SystemExit(f"compaction at epsilon {eps:g} failed (status {status})")
        p = json.loads((sim / "params.json").read_text())
        configs = pd.read_csv(sim / "configs.csv")
        with np.load(sim / "rods.npz") as rods:
            keys = sorted(rods.files)[:n_configs]
            xys = {k: np.asarray(rods[k], float) for k in keys}
        for i, key in enumerate(keys):
            xy = xys[key]
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                an = analyze_rod(xy, lam=0.0, contact_distance=p["contact_distance"])
            contacts_s = time.perf_counter() - t0
            for cond in conditions:
                folder = base / cond / key
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    scene = render_configuration(
                        xy, an, px_per_mm=PX_PER_MM, thickness_mm=THICKNESS_MM,
                        rod_thickness=p["thickness"], wall_radius=p["wall_radius"],
                        hole_radius_mm="auto", seed=seed + i, **CONDITIONS[cond])
                render_s = time.perf_counter() - t0
                drawn_ratio = np.nan
                if cond in DRAWN:
                    tables, paths, drawn_e = drawn_truth(xy, an, p, scene, CONDITIONS[cond])
                    n_br = tables["stacks"]["n_br"]
                    scene = dataclasses.replace(
                        scene, tables=tables, paths_rc=paths,
                        summary={**scene.summary, "n_junctions": len(tables["junctions"]),
                                 "n_stacks": len(n_br), "n_branches": int(n_br.sum()),
                                 "mean_branches_per_stack": float(n_br.mean()) if len(n_br)
                                 else 0.0})
                    drawn_ratio = drawn_e / scene.summary["total_energy"]
                write_scene(scene, folder)
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    result, pair = analyze_scene_folder(folder)
                analyze_s = time.perf_counter() - t0
                truth = read_scene(folder, image=False)
                tpair = (truth.summary, truth.tables)
                s = score(pair, tpair, px_per_mm=PX_PER_MM, thickness_mm=THICKNESS_MM)
                b = _breakdown(pair, tpair, h_px)
                if overlays:
                    _overlay(base / "overlays" / f"{key}_{cond}.png", scene, pair, b)
                row = {"epsilon": eps, "config": key, "condition": cond,
                       "n_br_exact": s["n_br_exact_length_fraction"],
                       "junction_f1": s["junction_f1"],
                       "junction_precision": s["junction_precision"],
                       "junction_recall": s["junction_recall"],
                       "junction_f1_fork": _fork_f1(scene, pair, h_px),
                       "rod_length_error": s["rod_length_rel_error"],
                       "total_energy_error": s["total_energy_rel_error"],
                       "total_energy_rel_uncertainty": pair[0].get(
                           "total_energy_rel_uncertainty"),
                       "quality": ";".join(pair[0]["quality"]["codes"]),
                       "total_energy_out": s["total_energy"],
                       "total_energy_truth": s["total_energy_truth"],
                       "n_br_mean_abs_error": s["n_br_mean_abs_error"],
                       "truth_junctions": s["junction_truth"],
                       "out_junctions": s["junction_out"],
                       "fold_energy_share": _fold_share(xy),
                       # the drawn pass curves' energy over the rod's (drawn truth only)
                       "drawn_curve_energy_ratio": drawn_ratio,
                       # how much rod the bands draw: sum n_br x drawn stack length over L
                       "drawn_rod_ratio": float((truth.tables["stacks"]["n_br"]
                                                 * truth.tables["stacks"]["length_mm"]).sum()
                                                / truth.summary["rod_length_mm"]),
                       **dict(zip(("drawn_energy_ratio", "drawn_energy_ratio_outside"),
                                  _drawn_energy(scene))),
                       "measured_energy_ratio_outside": _measured_outside(scene, result),
                       "rod_energy_share_outside": _rod_outside(xy, scene),
                       "compact_s": float(configs.loc[configs["config_id"] == i, "wall_s"]
                                          .iloc[0]) if "wall_s" in configs else np.nan,
                       "contacts_s": contacts_s, "render_s": render_s,
                       "analyze_s": analyze_s, "image_px": int(np.prod(scene.rgb.shape[:2]))}
                row.update({k: v for k, v in b.items() if not k.startswith("_")})
                row["pass"] = (row["n_br_exact"] >= TARGETS["n_br_exact_length_fraction"]
                               and row["junction_f1"] >= TARGETS["junction_f1"]
                               and abs(row["rod_length_error"]) <= TARGETS["rod_length"]
                               and abs(row["total_energy_error"]) <= TARGETS["total_energy"])
                rows.append(row)
                print(_line(row), flush=True)
    return pd.DataFrame(rows)


def _line(r) -> str:
    return (f"| {r['epsilon']:g} | {r['config'][-1]} | {r['condition']} | {r['n_br_exact']:.3f} | "
            f"{r['junction_f1']:.3f} ({r['junction_precision']:.2f}/{r['junction_recall']:.2f}) | "
            f"{r['junction_f1_fork']:.3f} | "
            f"{100 * r['rod_length_error']:+.1f} % | {100 * r['total_energy_error']:+.0f} % | "
            f"{100 * r['unmatched_length_fraction']:.0f} % + "
            f"{100 * r['nbr_wrong_length_fraction']:.0f} % | "
            f"{r['thick_wrong']}/{r['thick_matched']} ({r['thick_wrong_pm1']}) | "
            f"{r['missed_junctions']}/{r['truth_junctions']} ({r['missed_at_stubby']}) | "
            f"{r['render_s']:.0f} | {r['analyze_s']:.1f} |")


HEADER = ("| epsilon | config | condition | exact n_br | junction F1 (P/R) | F1 fork | "
          "rod length | total energy | stack length unmatched + n_br wrong | "
          "thick stacks wrong (+-1) | junctions missed (at a stack < 2 widths) | render s | "
          "analyze s |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--epsilon", default="19",
                    help="comma-separated compaction rates, each E or E:K with K "
                         "configurations (default 19)")
    ap.add_argument("--segments", type=int, default=2000)
    ap.add_argument("--n-configs", type=int, default=4)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--conditions", default="scan,clean,polyline",
                    help=f"comma-separated, of {', '.join(CONDITIONS)}")
    ap.add_argument("--work", default=str(Path(__file__).parent / "out" / "compact_pipeline"),
                    help="compactions, scenes and overlays")
    ap.add_argument("--out", default=str(Path(__file__).parent / "out"))
    ap.add_argument("--overlays", action="store_true",
                    help="draw the failures of every scene into WORK/epsE/overlays/")
    a = ap.parse_args(argv)
    conditions = [c.strip() for c in a.conditions.split(",") if c.strip()]
    bad = [c for c in conditions if c not in CONDITIONS]
    if bad:
        ap.error(f"unknown condition {bad[0]!r}")
    epsilons = []
    for item in a.epsilon.split(","):
        eps, _, k = item.partition(":")
        epsilons.append((float(eps), int(k) if k else a.n_configs))
    print(HEADER, flush=True)
    df = run(epsilons, segments=a.segments, seed=a.seed, conditions=conditions, work=a.work,
             overlays=a.overlays)
    write_csv(Path(a.out) / "compact_pipeline.csv", df)
    print(f"\n{len(df)} scenes; targets met by {int(df['pass'].sum())}; "
          f"{Path(a.out) / 'compact_pipeline.csv'}")


if __name__ == "__main__":
    main()
