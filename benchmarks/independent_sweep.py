#!/usr/bin/env python
"""Accuracy of the default pipeline on scans from an independent generator.

The scenes come from ``benchmarks/independent_scenes.py``, written apart from the package
(its own topology, fork geometry, width law, colours and defects; see its docstring for the
five conditions). Each scene is generated once (scenes already in OUT/independent_scenes
are reused), analysed by ``crosssection.analyze`` with default settings, given only what a
user knows about a scan: the scale (px/mm, layer thickness 0.1 mm), the generator's width
law as the calibration, the hole (radius and centre; left for the pipeline to find with
``--hole-not-given``) and the rod length, and scored:

==========================  =======================================================
rod_length_rel_error        sum of n_br * length over the output stacks / truth L - 1
junction_f1                 output junctions against the generator's junction points
                            (its graph vertices), Hungarian matching within 3 h
junction_f1_visible         the same with each tangential (peel) fork's truth point
                            moved to its visible split point; equals junction_f1 where a
                            scene has no peel
junction_f1_fork            the same with each truth point moved to the medial-axis fork
                            of the generator's bands redrawn without defects (the nearest
                            fork of their skeleton within the junction's widest band
                            width; the point is kept where none is): the placement the
                            issue of thick trunks is judged by, "within 3 h of the
                            medial-axis fork point"
n_br_exact_length_fraction  fraction of the truth stack length whose nearest output stack
                            (mid points within max(3 h, length / 4)) has exactly the
                            truth number of layers; unmatched stacks count as wrong
total_energy_rel_error      sum of the output branch energies / truth energy - 1
n_voids_rel_error           output voids / truth voids - 1; the truth voids are the
                            faces of the generator's planar graph inside the wall band
                            (stacks - junctions + connected components)
hidden_energy_fraction      fraction of the truth energy lying where a stack's centreline
                            is inside another band (fork zones merged in the ink, which no
                            skeleton sees): the part of the energy the scan does not show
==========================  =======================================================

Usage: python benchmarks/independent_sweep.py [--conditions typical,thick,lowres,peel,thick_dense,midres]
       [--seed 1] [--per-condition 8] [--workers 2] [--out benchmarks/out] [--quick]
       [--hole-not-given] [--no-calibration]
Writes OUT/independent_sweep.csv (one row per scene: condition, seed, the scene's
description, generate_s (empty when the scene was on disk), the scores above, warnings,
analyze_s) and OUT/independent_sweep.json (package version, parameters, library versions),
named ``independent_sweep_nohole`` with ``--hole-not-given`` (``_nocal`` added with
``--no-calibration``: the generator's width law withheld, the pipeline reads its own); prints the median of each
score per condition.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
import independent_scenes as gen  # noqa: E402  (the generator, deliberately not in the package)

CONDITIONS = tuple(gen.CONDITIONS)
SCENE_DIR = "independent_scenes"
METRICS = ("rod_length_rel_error", "junction_f1", "junction_f1_visible", "junction_f1_fork",
           "n_br_exact_length_fraction", "total_energy_rel_error", "n_voids_rel_error",
           "hidden_energy_fraction")


def truth_void_count(truth: dict) -> int:
    """Faces of the generator's planar graph inside its outer boundary (the wall band).

    Euler's formula for a plane graph with V vertices, E edges and C components gives
    ``E - V + C`` bounded faces; every vertex is a junction (the generator draws no free
    end) and the wall band closes the outer boundary, so each bounded face is a void.
    """
    ids = {j["id"]: i for i, j in enumerate(truth["junctions"])}
    for s in truth["stacks"]:
        for k in ("u", "v"):
            ids.setdefault(s[k], len(ids))
    u = np.array([ids[s["u"]] for s in truth["stacks"]], np.int64)
    v = np.array([ids[s["v"]] for s in truth["stacks"]], np.int64)
    n = len(ids)
    adj = coo_matrix((np.ones(len(u)), (u, v)), shape=(n, n))
    n_comp = connected_components(adj, directed=False)[0] if n else 0
    return len(u) - n + n_comp


def medial_fork_points(truth: dict, lines) -> np.ndarray:
    """Each truth junction moved to the nearest fork of the medial axis of the bands.

    The bands are redrawn without defects as the generator draws them (discs of its width law
    along every centreline) and thinned (``skimage.morphology.skeletonize``); the forks are
    the clusters of skeleton pixels with three or more neighbours. A junction takes the centre
    of the nearest cluster within the widest band width of its stacks, and keeps its own point
    where there is none.

    Parameters
    ----------
    truth : dict
        The scene's JSON.
    lines : mapping
        Its ``_lines.npz`` (``s<id>``: (P, 2) x, y px).

    Returns
    -------
    (J, 2) float array
        x, y px per junction, in the order of ``truth["junctions"]``.
    """
    from crosssection.truth.scoring import medial_fork_points as forks_rc

    ppm = float(truth["px_per_mm"])
    stacks = truth["stacks"]
    size = int(truth["render"]["size"])
    out_rc = forks_rc([np.asarray(lines[f"s{st['id']}"], float)[:, ::-1] for st in stacks],
                      [float(gen.width_mm(st["n"])) * ppm for st in stacks],
                      [(st["u"], st["v"]) for st in stacks],
                      [j["id"] for j in truth["junctions"]],
                      [[j["y"], j["x"]] for j in truth["junctions"]], (size, size), stride=4)
    return out_rc[:, ::-1]


def junction_f1(out_xy: np.ndarray, truth_xy: np.ndarray, tol: float) -> float:
    """F1 of a Hungarian matching of output to truth points, pairs farther than ``tol``
    rejected.

    Parameters
    ----------
    out_xy, truth_xy : ndarray
        (N, 2) and (M, 2) positions (px).
    tol : float
        Largest accepted distance (px).

    Returns
    -------
    float
        ``2 P R / (P + R)``; 0 when either set is empty or nothing matches.
    """
    if len(out_xy) == 0 or len(truth_xy) == 0:
        return 0.0
    d = np.hypot(out_xy[:, None, 0] - truth_xy[None, :, 0],
                 out_xy[:, None, 1] - truth_xy[None, :, 1])
    cost = np.where(d <= tol, d, 1e6)
    r, c = linear_sum_assignment(cost)
    tp = int(np.sum(cost[r, c] <= tol))
    if tp == 0:
        return 0.0
    p, rc = tp / len(out_xy), tp / len(truth_xy)
    return 2 * p * rc / (p + rc)


def hidden_energy_fraction(truth: dict, lines, step: float = 0.5) -> float:
    """Fraction of the truth energy where a stack's centreline lies inside another band.

    Each centreline is resampled every ``step`` px, its curvature taken from the turning
    angles and its energy density rescaled to the stack's analytic energy; a sample is hidden
    when it is closer than half a width to another stack's centreline.

    Parameters
    ----------
    truth : dict
        The scene's truth JSON.
    lines : mapping
        ``s<stack id>`` -> (K, 2) centreline in px (the scene's ``_lines.npz``).
    step : float
        Resampling step (px).

    Returns
    -------
    float
    """
    ppm, L = truth["px_per_mm"], truth["L_mm"]
    paths = {st["id"]: np.asarray(lines[f"s{st['id']}"], float) for st in truth["stacks"]}
    samples, energies, owners = [], [], []
    for st in truth["stacks"]:
        p = paths[st["id"]]
        cum = np.r_[0, np.cumsum(np.hypot(*np.diff(p, axis=0).T))]
        s = np.arange(0, cum[-1], step)
        q = np.stack([np.interp(s, cum, p[:, 0]), np.interp(s, cum, p[:, 1])], 1)
        d = np.diff(q, axis=0)
        theta = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        k = np.diff(theta) / step
        e = k ** 2 * step * ppm * st["n"] * L
        e *= st["energy"] / max(e.sum(), 1e-30)
        samples.append(q[1:-1])
        energies.append(e)
        owners.append(np.full(len(e), st["id"]))
    q, e, owner = np.concatenate(samples), np.concatenate(energies), np.concatenate(owners)
    hidden = np.zeros(len(q), bool)
    for st in truth["stacks"]:
        half_width = gen.width_mm(st["n"]) * ppm / 2
        dist, _ = cKDTree(paths[st["id"]]).query(q, distance_upper_bound=half_width)
        hidden |= np.isfinite(dist) & (owner != st["id"])
    return float(e[hidden].sum() / e.sum()) if e.sum() > 0 else 0.0


def score(truth: dict, lines, res) -> dict:
    """The scores of one analysis against the scene's truth (see the module docstring)."""
    ppm = truth["px_per_mm"]
    tol = 3 * truth["thickness_mm"] * ppm
    st = res.stacks
    L = truth["L_mm"]
    out_xy = res.junctions[["x_px", "y_px"]].to_numpy(float)
    truth_xy = np.array([[j["x"], j["y"]] for j in truth["junctions"]])
    visible = {}
    for f in truth["forks"]:
        if "vis_px" in f:
            visible.setdefault(f["v"], f["vis_px"])
    visible_xy = np.array([visible.get(j["id"], [j["x"], j["y"]]) for j in truth["junctions"]])
    mids = st[["mid_x_px", "mid_y_px"]].to_numpy(float)
    lengths, exact = [], []
    for s in truth["stacks"]:
        d = np.hypot(*(mids - np.array(s["mid"])).T)
        k = int(np.argmin(d)) if len(d) else -1
        ok = k >= 0 and d[k] <= max(tol, 0.25 * s["length_mm"] * ppm)
        lengths.append(s["length_mm"])
        exact.append(ok and int(st.iloc[k]["n_br"]) == s["n"])
    lengths = np.array(lengths)
    return {
        "rod_length_rel_error": float((st["n_br"] * st["length_mm"]).sum()) / L - 1,
        "junction_f1": junction_f1(out_xy, truth_xy, tol),
        "junction_f1_visible": junction_f1(out_xy, visible_xy, tol),
        "junction_f1_fork": junction_f1(out_xy, medial_fork_points(truth, lines), tol),
        "n_br_exact_length_fraction": float(lengths[np.array(exact, bool)].sum()
                                            / lengths.sum()),
        "total_energy_rel_error": float(res.branches["energy"].sum()) / truth["energy_total"] - 1,
        "n_voids_rel_error": len(res.voids) / max(truth_void_count(truth), 1) - 1,
        "n_stacks_out": len(st), "n_junctions_out": len(out_xy),
    }


def describe(truth: dict) -> dict:
    """The scene's description columns (what the generator drew)."""
    n = np.array([s["n"] for s in truth["stacks"]])
    length = np.array([s["length_mm"] for s in truth["stacks"]])
    r = truth["render"]
    return {"attempt": truth["attempt"], "px_per_mm": truth["px_per_mm"],
            "hole_radius_mm": truth["hole_radius_mm"], "size_px": r["size"],
            "n_stacks": len(n), "n_junctions": len(truth["junctions"]),
            "n_peel_forks": sum(f["type"] in ("peel", "wall_peel") for f in truth["forks"]),
            "mean_layers": float(np.average(n, weights=length)), "max_layers": int(n.max()),
            "L_mm": truth["L_mm"], "energy_true": truth["energy_total"],
            "ink": r["ink"], "plate": r["plate"], "blur_px": r["blur"], "noise_sigma": r["noise"],
            "jpeg_quality": r["jpeg"], "n_smears": r["n_smears"], "n_specks": len(r["specks"])}


def _scene_on_disk(folder: Path, name: str) -> bool:
    """The scene's three files exist (the JSON, written last and atomically, parses)."""
    if not all((folder / f).exists() for f in (f"{name}.png", f"{name}_lines.npz")):
        return False
    try:
        json.loads((folder / f"{name}.json").read_text())
    except (OSError, ValueError):
        return False
    return True


def run_one(condition: str, seed: int, folder: str, hole_given: bool = True,
            calibrated: bool = True) -> dict:
    """Generate (unless on disk), analyse and score one scene; return its row."""
    import crosssection

    folder = Path(folder)
    name = gen.scene_name(seed, condition)
    row = {"condition": condition, "seed": seed, "scene": name, "generate_s": np.nan}
    t0 = time.perf_counter()
    try:
        if not _scene_on_disk(folder, name):
            gen.generate(seed, condition, folder)
            row["generate_s"] = time.perf_counter() - t0
    except RuntimeError as exc:
        row["error"] = f"generation: {exc}"
        return row
    truth = json.loads((folder / f"{name}.json").read_text())
    row.update(describe(truth))
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            hole = (dict(hole_radius_mm=truth["hole_radius_mm"],
                         hole_center_px=tuple(truth["hole_center_px"])) if hole_given else {})
            res = crosssection.analyze(
                str(folder / f"{name}.png"), px_per_mm=truth["px_per_mm"],
                thickness_mm=truth["thickness_mm"],
                calibration=str(folder / "calibration.csv") if calibrated else None,
                rod_length_mm=truth["L_mm"], **hole)
    except crosssection.FoldstatError as exc:
        row.update(error=exc.one_line(), analyze_s=time.perf_counter() - t0)
        return row
    except Exception as exc:  # noqa: BLE001 - a crashing scene is a row of the table
        row.update(error=f"{type(exc).__name__}: {exc}", analyze_s=time.perf_counter() - t0)
        return row
    row["analyze_s"] = time.perf_counter() - t0
    with np.load(folder / f"{name}_lines.npz") as lines:
        row.update(score(truth, lines, res))
        row["hidden_energy_fraction"] = hidden_energy_fraction(truth, lines)
    row["total_energy_rel_uncertainty"] = res.summary.get("total_energy_rel_uncertainty")
    row["quality"] = ";".join(res.summary["quality"]["codes"])
    row["warnings"] = " | ".join(
        f"{w.category.__name__}: {str(w.message).split(': ', 1)[-1]}" for w in caught)
    return row


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """The median of each score per condition (scenes that failed left out, but counted)."""
    rows = []
    for cond, g in df.groupby("condition", sort=False):
        ok = g[g["error"].isna()] if "error" in g else g
        rows.append({"condition": cond, "n": len(g), "failed": len(g) - len(ok),
                     **{m: ok[m].median() for m in METRICS if m in ok},
                     "analyze_s": ok["analyze_s"].median() if "analyze_s" in ok else np.nan})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conditions", default=",".join(CONDITIONS))
    ap.add_argument("--seed", type=int, default=1, help="first seed of every condition")
    ap.add_argument("--per-condition", type=int, default=8)
    ap.add_argument("--quick", action="store_true", help="2 scenes per condition")
    ap.add_argument("--workers", type=int, default=2, help="processes, one scene each")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    ap.add_argument("--hole-not-given", action="store_true",
                    help="the pipeline finds the hole (default: radius and centre given)")
    ap.add_argument("--no-calibration", action="store_true",
                    help="withhold the generator's width law: the pipeline reads its own")
    args = ap.parse_args(argv)
    conditions = [c for c in args.conditions.split(",") if c]
    unknown = sorted(set(conditions) - set(CONDITIONS))
    if unknown:
        ap.error(f"unknown condition(s) {', '.join(unknown)}; known: {', '.join(CONDITIONS)}")
    if args.workers < 1 or args.per_condition < 1:
        ap.error("--workers and --per-condition must be >= 1")
    import crosssection
    import cv2
    import scipy
    import skimage
    from crosssection.core.fileio import write_csv, write_json

    n = 2 if args.quick else args.per_condition
    out = Path(args.out)
    folder = out / SCENE_DIR
    folder.mkdir(parents=True, exist_ok=True)
    gen.write_calibration(folder / "calibration.csv")
    jobs = [(c, args.seed + i) for c in conditions for i in range(n)]
    t0 = time.perf_counter()
    rows = []
    if args.workers == 1:
        for c, s in jobs:
            rows.append(run_one(c, s, str(folder), not args.hole_not_given,
                                not args.no_calibration))
            _progress(rows[-1])
    else:
        import multiprocessing as mp

        # 'spawn': workers start clean, without the parent's threads (numba, BLAS)
        with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as ex:
            futures = [ex.submit(run_one, c, s, str(folder), not args.hole_not_given,
                                 not args.no_calibration) for c, s in jobs]
            for fut in as_completed(futures):
                rows.append(fut.result())
                _progress(rows[-1])
    wall = time.perf_counter() - t0
    order = {c: i for i, c in enumerate(conditions)}
    df = pd.DataFrame(rows)
    df = df.sort_values(["condition", "seed"], key=lambda s: s.map(order) if s.name ==
                        "condition" else s, kind="stable").reset_index(drop=True)
    last = [c for c in (*METRICS, "n_stacks_out", "n_junctions_out", "warnings", "analyze_s",
                        "error") if c in df]
    df = df[[c for c in df if c not in last] + last]
    stem = ("independent_sweep_nohole" if args.hole_not_given else "independent_sweep") + \
        ("_nocal" if args.no_calibration else "")
    csv = out / f"{stem}.csv"
    write_csv(csv, df)
    meta = {"foldstat_version": crosssection.__version__,
            "parameters": {"conditions": conditions, "seed": args.seed, "per_condition": n,
                           "workers": args.workers, "scene_folder": SCENE_DIR,
                           "analyze": "defaults; px_per_mm, thickness_mm, "
                                      + ("" if args.no_calibration else "calibration, ")
                                      + ("" if args.hole_not_given else
                                         "hole_radius_mm, hole_center_px, ")
                                      + "rod_length_mm given",
                           "junction_match": "Hungarian within 3 h"},
            "generator": {"milp_node_limit": gen.MILP_NODE_LIMIT,
                          "max_attempts": gen.MAX_ATTEMPTS},
            "versions": {"python": platform.python_version(), "numpy": np.__version__,
                         "scipy": scipy.__version__, "opencv": cv2.__version__,
                         "pandas": pd.__version__, "scikit-image": skimage.__version__},
            "n_scenes": len(df), "wall_s": round(wall, 1)}
    write_json(out / f"{stem}.json", meta)
    pd.set_option("display.width", 200)
    print(summarize(df).to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    print(f"{len(df)} scenes in {wall:.0f} s -> {csv}")
    return 0


def _progress(row: dict) -> None:
    if "error" in row:
        print(f"{row['scene']}: {row['error']}", flush=True)
        return
    print(f"{row['scene']}: rod {row['rod_length_rel_error']:+.4f}, F1 {row['junction_f1']:.3f}"
          f" (visible {row['junction_f1_visible']:.3f}), exact n_br "
          f"{row['n_br_exact_length_fraction']:.3f}, energy {row['total_energy_rel_error']:+.3f}"
          f", voids {row['n_voids_rel_error']:+.3f}, hidden {row['hidden_energy_fraction']:.3f}",
          flush=True)


if __name__ == "__main__":
    sys.exit(main())
