#!/usr/bin/env python
"""Where the network generator puts its bending energy: the share near junctions.

For the scenes of ``benchmarks/robust_sweep.py`` (conditions ``typical``, ``thick_dense`` and
``lowres``, the same seeds), the truth centreline of every stack (``Scene.paths_rc``, dense
samples of the generator's curves) gives ``kappa(s)``; the share of ``sum n_br int kappa^2 ds``
and of ``sum n_br l`` lying within ``m n_br h`` of a junction end is reported for m = 1, 2, 3
(median over scenes). The two end samples of every path are left out: a wall stack's drawn
path ends with a corner onto its junction point that is not part of its truth curve (its
curvature there is 10-40 /mm).

An estimator that does not see a fork zone can only recover its energy by a model; where
the energy share exceeds the length share, the bending is concentrated at the forks.

The share inside the forks' merged zones, where a stack's band overlaps another's (the image
shows one band there), is reported beside them (``energy_merged``, ``length_merged``), and
the share where a stack's centreline lies inside another band's ink (``energy_covered``,
``length_covered``: not even its position is in the image there).

Usage: python benchmarks/fork_energy_share.py [--per-condition 8] [--seed 100]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import robust_sweep  # noqa: E402  (the scene definitions are shared)


def _curvature(path_rc: np.ndarray):
    """Arc length of the interior samples, their curvature (1/px), the path's length, the
    weights ds and the interior samples themselves (row, col)."""
    d = np.diff(path_rc, axis=0)
    keep = np.r_[True, np.hypot(d[:, 0], d[:, 1]) > 1e-9]
    p = path_rc[keep]
    d = np.diff(p, axis=0)
    ds = np.hypot(d[:, 0], d[:, 1])
    theta = np.unwrap(np.arctan2(d[:, 0], d[:, 1]))
    k = np.diff(theta) / (0.5 * (ds[:-1] + ds[1:]))
    s = np.cumsum(ds)[:-1]
    return s, k, float(ds.sum()), 0.5 * (ds[:-1] + ds[1:]), p[1:-1]


def shares(scene, multiples=(1, 2, 3)) -> dict:
    """Energy and length shares within ``m n_br h`` of a junction for one scene."""
    st = scene.tables["stacks"]
    h = scene.params["thickness_mm"] * scene.params["px_per_mm"]
    e_near = dict.fromkeys(multiples, 0.0)
    l_near = dict.fromkeys(multiples, 0.0)
    e_tot = l_tot = 0.0
    for i, row in st.reset_index(drop=True).iterrows():
        p = np.asarray(scene.paths_rc[i], float)
        if len(p) < 8:
            continue
        s, k, length, w, _ = _curvature(p)
        s, k, w = s[2:-2], k[2:-2], w[2:-2]
        f = k * k * w
        n = int(row.n_br)
        e_tot += n * f.sum()
        l_tot += n * w.sum()
        for m in multiples:
            z = m * n * h
            near = np.zeros(len(s), bool)
            if row.junction_a >= 0:
                near |= s < z
            if row.junction_b >= 0:
                near |= s > length - z
            e_near[m] += n * f[near].sum()
            l_near[m] += n * w[near].sum()
    out = {}
    for m in multiples:
        out[f"energy_within_{m}nh"] = e_near[m] / e_tot if e_tot else np.nan
        out[f"length_within_{m}nh"] = l_near[m] / l_tot if l_tot else np.nan
    return out


def merged_share(scene) -> dict:
    """Energy and length shares where a stack's band overlaps another band, and where its
    centreline lies inside another band.

    Two bands overlap where their centrelines are closer than half the sum of their widths:
    the image shows one merged band there and no centreline of either (``energy_merged``,
    ``length_merged``). Where a stack's centreline is closer to another stack's centreline
    than half that other band's width, its centre is covered by the other band's ink: not
    even the stack's position is in the image there, only its outer face at best
    (``energy_covered``, ``length_covered``). Distinct stacks keep a gap of 2h away from
    their junctions, so both are the forks'. (The generator draws overlapping bands; real
    layers cannot interpenetrate, they lie side by side in contact.)"""
    from scipy.spatial import cKDTree

    st = scene.tables["stacks"].reset_index(drop=True)
    px = scene.params["px_per_mm"]
    paths = [np.asarray(p, float) for p in scene.paths_rc]
    half = st["width_mm"].to_numpy(float) * px / 2
    owner = np.concatenate([np.full(len(p), i) for i, p in enumerate(paths)])
    tree = cKDTree(np.concatenate(paths))
    e = dict(merged=0.0, covered=0.0, total=0.0)
    ln = dict(merged=0.0, covered=0.0, total=0.0)
    for i, p in enumerate(paths):
        if len(p) < 8:
            continue
        s, k, length, w, pts = _curvature(p)
        s, k, w, pts = s[2:-2], k[2:-2], w[2:-2], pts[2:-2]
        merged = np.zeros(len(pts), bool)
        covered = np.zeros(len(pts), bool)
        for q, near in enumerate(tree.query_ball_point(pts, half[i] + half.max())):
            others = owner[near]
            other = others != i
            if other.any():
                d = np.hypot(*(tree.data[near][other] - pts[q]).T)
                h_other = half[others[other]]
                merged[q] = np.any(d < half[i] + h_other - 0.5)
                covered[q] = np.any(d < h_other - 0.5)
        n = int(st.n_br[i])
        f = k * k * w
        for key, sel in (("merged", merged), ("covered", covered), ("total", slice(None))):
            e[key] += n * f[sel].sum()
            ln[key] += n * w[sel].sum()
    out = {}
    for key in ("merged", "covered"):
        out[f"energy_{key}"] = e[key] / e["total"] if e["total"] else np.nan
        out[f"length_{key}"] = ln[key] / ln["total"] if ln["total"] else np.nan
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--per-condition", type=int, default=8)
    ap.add_argument("--seed", type=int, default=100)
    args = ap.parse_args(argv)
    rows = []
    for cond in ("typical", "thick_dense", "lowres", "tangential"):
        for seed in range(args.seed, args.seed + args.per_condition):
            scene = robust_sweep.make_network_scene(seed, robust_sweep.scene_options(cond, seed))
            rows.append({"condition": cond, "seed": seed, **shares(scene),
                         **merged_share(scene)})
    df = pd.DataFrame(rows)
    print(df.drop(columns="seed").groupby("condition", sort=False).median().round(3)
          .to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
