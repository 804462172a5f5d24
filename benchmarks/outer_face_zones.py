#!/usr/bin/env python
"""Fork zones read on the stack's free outer face: measured on both generators, not kept.

Inside a fork zone the image holds no centreline of the stack (its band is merged with a
neighbour's), but the band's face away from that neighbour is still the stack's own outer
layer. This script reads the zone's curvature there instead of continuing the trend of the
visible curvature (``crosssection.stages.curvature``, step 3), and compares the two on the
scenes of both generators, with everything else the default:

1. at every centreline sample of the zone and of one window ``5 n_br h`` beyond it, the
   distance to the ink's edge along each normal (where the bilinear distance transform of the
   cleaned mask crosses 0.5 px, :func:`edge_distance_px`);
2. the outer side is the one whose distance stays nearest, over the zone, to its median over
   the fitted window (the other side runs into the neighbour's ink); the face is followed from
   the fitted window toward the junction while that distance stays within ``tol_rel r +
   tol_px`` of its fitted median ``r``;
3. the centreline is the face moved inwards by ``r`` along the face's own normal
   (:func:`face_centreline`), and its curvature is fitted with the paper's window, truncated
   (not shifted) at the ends so that the samples next to the junction keep their own fits;
4. ``kink``: a zone whose face-derived curvature exceeds ``kink / (2 r)`` (a centreline radius
   below the band's width) is taken for a drawn corner, where two bands meet at an angle, and
   keeps the default reading.

Variants (``--variants``): ``default``; ``face`` (tol_rel 0.5, tol_px 2: the face followed
onto the trunk's face); ``face_kink``, ``face_kink075``, ``face_kink05`` (the same with kink
1, 0.75, 0.5); ``face_own`` (tol_rel 0.15, tol_px 0.75, kink 1: only while the face is the
stack's own).

Scenes: the network generator's conditions of ``benchmarks/robust_sweep.py`` (typical,
thick_dense, lowres, tangential, renders; seeds 100-107) and the independent generator's
(``benchmarks/independent_scenes.py``: typical, thick, lowres; seeds 1-8, read from or written
to ``OUT/independent_scenes`` as ``benchmarks/independent_sweep.py`` does). Each variant is
installed in its worker process by replacing ``crosssection.stages.curvature.stack_profiles``.

Usage: python benchmarks/outer_face_zones.py [--per-condition 8] [--quick] [--workers 2]
       [--variants default,face,face_kink,...] [--out benchmarks/out]
Writes OUT/outer_face_zones.csv (generator, condition, seed, variant, total energy error) and
prints the median (and median absolute) error per condition and variant.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.ndimage import map_coordinates

sys.path.insert(0, str(Path(__file__).resolve().parent))

VARIANTS = {"default": None,
            "face": dict(tol_rel=0.5, tol_px=2.0, kink=0.0),
            "face_kink": dict(tol_rel=0.5, tol_px=2.0, kink=1.0),
            "face_kink075": dict(tol_rel=0.5, tol_px=2.0, kink=0.75),
            "face_kink05": dict(tol_rel=0.5, tol_px=2.0, kink=0.5),
            "face_own": dict(tol_rel=0.15, tol_px=0.75, kink=1.0)}
NETWORK = ("typical", "thick_dense", "lowres", "tangential", "renders")
INDEPENDENT = ("typical", "thick", "lowres")


def edge_distance_px(distance_px, points_rc, normals, max_px, step=0.5):
    """Distance from each point to the ink's edge along its (unit) normal, px.

    The edge is where the distance transform, interpolated bilinearly, crosses 0.5 px (half
    way between the last ink pixel and the first background one); ``inf`` where the ray stays
    in ink for ``max_px``.
    """
    points_rc = np.asarray(points_rc, float)
    ts = np.arange(0.0, max_px + step, step)
    q = points_rc[:, None, :] + ts[None, :, None] * np.asarray(normals, float)[:, None, :]
    v = map_coordinates(distance_px, [q[..., 0].ravel(), q[..., 1].ravel()], order=1,
                        mode="constant").reshape(q.shape[:2])
    below = v < 0.5
    out = np.full(len(points_rc), np.inf)
    for i in np.flatnonzero(below.any(axis=1)):
        j = int(below[i].argmax())
        if j == 0:
            out[i] = 0.0
            continue
        a, b = v[i, j - 1], v[i, j]
        out[i] = ts[j - 1] + step * (a - 0.5) / max(a - b, 1e-9)
    return out


def unit_normals(points_rc):
    """Unit normals of a polyline (its tangent turned by 90 degrees)."""
    t = np.gradient(np.asarray(points_rc, float), axis=0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return np.stack([t[:, 1], -t[:, 0]], axis=1)


def face_centreline(face_rc, inward_hint, half_width_px, smooth_px):
    """The centreline of a band of half width ``half_width_px`` whose face is ``face_rc``.

    Each face point is moved by the half width along the face's own normal (smoothed over
    ``smooth_px`` points), toward the side of ``inward_hint`` (vectors pointing into the band).
    """
    from crosssection.core import polyline

    face_rc = np.asarray(face_rc, float)
    smooth = (polyline.smooth_paths([face_rc], window_px=smooth_px, closed=[False])[0]
              if smooth_px > 1 else face_rc)
    n = unit_normals(smooth)
    sign = np.sign(np.sum(n * inward_hint, axis=1))
    sign[sign == 0] = 1.0
    return face_rc + sign[:, None] * n * half_width_px


def face_zone_curvature(prof, side, n_br, thickness_px, px_per_mm, distance_px, smooth_px, *,
                        tol_rel, tol_px, kink):
    """Curvature of one fork zone read on the outer face: (sample indices, 1/mm) or None."""
    from crosssection.stages import curvature

    n, t0, t1 = len(prof.s_mm), prof.fit_start, prof.fit_stop
    w = 5.0 * n_br * thickness_px
    s_px = prof.s_mm * px_per_mm
    if side == 0:
        zone = np.arange(0, t0)
        ext = np.arange(0, min(int(np.searchsorted(s_px, s_px[t0] + w)), n)) if t0 > 0 else None
    else:
        zone = np.arange(t1, n)
        ext = np.arange(max(int(np.searchsorted(s_px, s_px[t1 - 1] - w)), 0), n) \
            if t1 < n else None
    if ext is None:
        return None
    rc = prof.rc_px[ext]
    normals = unit_normals(rc)
    fitted = (ext >= t0) & (ext < t1)
    if fitted.sum() < 3 or fitted.all():
        return None
    best = None
    for sign in (1.0, -1.0):
        d = edge_distance_px(distance_px, rc, sign * normals, 3.0 * n_br * thickness_px + 10)
        r = float(np.median(d[fitted]))
        dev = float(np.median(np.abs(d[~fitted] - r)))
        if best is None or dev < best[0]:
            best = (dev, sign, d, r)
    dev, sign, d, r = best
    if not np.isfinite(dev) or dev > 0.25 * r + 1.0:
        return None
    ok = np.abs(d - r) < tol_rel * r + tol_px
    idx = np.arange(len(ext))
    bad = idx[~ok & ~fitted]
    sel = (idx[bad.max() + 1:] if len(bad) else idx) if side == 0 else \
        (idx[:bad.min()] if len(bad) else idx)
    if len(sel) < 5:
        return None
    face = rc[sel] + sign * normals[sel] * d[sel, None]
    centre = face_centreline(face, -sign * normals[sel], r, smooth_px)
    prof_face = curvature.stack_curvature(centre, n_br=n_br, thickness_px=thickness_px,
                                          px_per_mm=px_per_mm, closed=False, trim_px=0,
                                          method="paper", smooth_px=smooth_px, ends="truncate")
    k = prof_face.kappa_per_mm
    if len(k) != len(sel):
        return None
    inside = np.isin(ext[sel], zone)
    if kink and np.abs(k[inside]).max(initial=0.0) > kink * px_per_mm / (2.0 * r):
        return None
    return ext[sel][inside], k[inside]


def face_stack_profiles(original, options):
    """``stack_profiles`` with its fork zones read on the outer face (module docstring)."""
    from crosssection.stages import curvature

    def profiles(graph, n_br, distance_px, *, thickness_px, px_per_mm, smooth_px=None,
                 method="missing"):
        out = original(graph, n_br, distance_px, thickness_px=thickness_px,
                       px_per_mm=px_per_mm, smooth_px=smooth_px, method=method)
        if method != "missing":
            return out
        sm = curvature.default_smooth_px(thickness_px) if smooth_px is None else int(smooth_px)
        for sid, prof in enumerate(out):
            nb = max(1, int(n_br[sid]))
            if prof.closed or len(prof.s_mm) < 3:
                continue
            k = prof.kappa_per_mm.copy()
            kmax = 2.0 * px_per_mm / (nb * thickness_px)
            for side in (0, 1):
                if graph.node_kind[graph.ends[sid][side]] != "junction":
                    continue
                got = face_zone_curvature(prof, side, nb, float(thickness_px), px_per_mm,
                                          distance_px, sm, **options)
                if got is not None:
                    k[got[0]] = np.clip(got[1], -kmax, kmax)
            out[sid] = replace(prof, kappa_per_mm=k)
        return out

    return profiles


def _network_scene(condition, seed):
    import robust_sweep as rs

    options = rs.scene_options(condition, seed)
    scene = rs._render_scene(seed) if condition == "renders" else \
        rs.make_network_scene(seed, options)
    p = scene.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=scene.calibration)
    if options["hole_given"] and p.get("hole_radius_mm"):
        kw.update(hole_radius_mm=p["hole_radius_mm"], hole_center_px=tuple(p["hole_center_px"]))
    truth = float(scene.summary.get("total_energy") or scene.tables["branches"]["energy"].sum())
    return scene.rgb, kw, truth


def _independent_scene(condition, seed, folder):
    import independent_scenes as gen
    import independent_sweep as isw

    name = gen.scene_name(seed, condition)
    if not isw._scene_on_disk(folder, name):
        gen.generate(seed, condition, folder)
    t = json.loads((folder / f"{name}.json").read_text())
    kw = dict(px_per_mm=t["px_per_mm"], thickness_mm=t["thickness_mm"],
              calibration=str(folder / "calibration.csv"), rod_length_mm=t["L_mm"],
              hole_radius_mm=t["hole_radius_mm"], hole_center_px=tuple(t["hole_center_px"]))
    return str(folder / f"{name}.png"), kw, float(t["energy_total"])


def run_scene(generator, condition, seed, variants, folder):
    """Total-energy error of one scene under every variant: a list of rows."""
    import crosssection
    from crosssection.stages import curvature

    if generator == "network":
        image, kw, truth = _network_scene(condition, seed)
    else:
        image, kw, truth = _independent_scene(condition, seed, Path(folder))
    original = curvature.stack_profiles
    rows = []
    try:
        for name in variants:
            opts = VARIANTS[name]
            curvature.stack_profiles = original if opts is None else \
                face_stack_profiles(original, opts)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = crosssection.analyze(image, **kw)
            rows.append({"generator": generator, "condition": condition, "seed": seed,
                         "variant": name, "total_energy_rel_error":
                             float(res.branches["energy"].sum()) / truth - 1})
    finally:
        curvature.stack_profiles = original
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--per-condition", type=int, default=8)
    ap.add_argument("--quick", action="store_true", help="2 scenes per condition")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    args = ap.parse_args(argv)
    if args.quick:
        args.per_condition = 2
    variants = [v for v in args.variants.split(",") if v]
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        ap.error(f"unknown variant(s) {', '.join(unknown)}; known: {', '.join(VARIANTS)}")
    if args.workers < 1 or args.per_condition < 1:
        ap.error("--workers and --per-condition must be >= 1")
    import independent_scenes as gen
    from crosssection.core.fileio import write_csv

    out = Path(args.out)
    folder = out / "independent_scenes"
    folder.mkdir(parents=True, exist_ok=True)
    gen.write_calibration(folder / "calibration.csv")
    jobs = [("network", c, 100 + i) for c in NETWORK for i in range(args.per_condition)]
    jobs += [("independent", c, 1 + i) for c in INDEPENDENT for i in range(args.per_condition)]
    t0 = time.perf_counter()
    import multiprocessing as mp

    with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as ex:
        futures = [ex.submit(run_scene, g, c, s, variants, str(folder)) for g, c, s in jobs]
        rows = [r for f in futures for r in f.result()]
    df = pd.DataFrame(rows)
    write_csv(out / "outer_face_zones.csv", df)
    e = df.groupby(["generator", "condition", "variant"], sort=False)["total_energy_rel_error"]
    table = pd.DataFrame({"median": e.median(),
                          "median_abs": e.apply(lambda x: float(np.median(np.abs(x))))})
    print(table.unstack("variant").round(3).to_string())
    print(f"{len(jobs)} scenes x {len(variants)} variants in {time.perf_counter() - t0:.0f} s "
          f"-> {out / 'outer_face_zones.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
