#!/usr/bin/env python
"""An independent generator of synthetic cross-section scans, with exact truth.

Why it exists
-------------
The package's own test scenes (``crosssection.truth.network``, ``simulate.render``) were
written together with the pipeline, so they may share its assumptions: how forks look, how
wide a stack of ``n`` layers is, which colours and defects a scan has. This generator was
written apart from the package, as a check: its own topology, fork geometry, width law,
colours and defects. It imports neither ``crosssection`` nor ``simulate`` (numpy, scipy and
OpenCV only). ``benchmarks/independent_sweep.py`` scores the pipeline on its scenes.

The model
---------
Topology
    A Voronoi diagram of Poisson-disc points (spacing ``dmin``) clipped to a wall circle of
    radius ``Rw``; every ridge crossing the circle ends at a wall vertex, and consecutive wall
    vertices are joined by wall arcs. An interior edge shorter than ``0.2 dmin`` between two
    degree-3 vertices is contracted into a degree-4 junction (onto the wall vertex if it
    touches the wall). Each edge is one stack of ``n`` layers.
Pairing rule
    At every junction the incident stacks are split into two groups, and a layer arriving by
    one group leaves by the other: degree 3, trunk | two branches (at the wall the trunk is a
    wall arc, the interior stack peels off the wall); degree 4, two neighbouring stacks | the
    other two. Integer layer counts ``1 <= n <= cap`` with equal sums on both sides of every
    junction (layer conservation, exactly) are found together with the pairing by a
    mixed-integer program whose objective pulls ``n`` towards gamma-distributed targets.
Forks
    Angled: the branches leave at +-phi/2 about the fork axis, the trunk along minus the
    axis (phi 30-60 degrees); at the wall the interior stack leaves at phi from the wall.
    Tangential (peel): one branch goes straight on, the other leaves tangent to it along an
    arc of constant curvature 1/R0 (R0 1.2-3 mm) until the two centrelines are
    ``(w1 + w2) / 2 + 3`` px apart; at the wall the interior stack starts tangent to the wall.
    The end of such a lead arc is the visible split point (``vis_px`` of the fork).
Curves
    Between its end tangents (and lead arcs) each interior stack is the least-bending cubic
    Bezier (handle lengths from a 4 x 4 grid minimising the integral of kappa^2, as a relaxed
    sheet would), its handles perturbed by +-10 %. Short stacks cannot turn much, so their
    end tangents are clamped towards the chord. Wall stacks are circular arcs, the wall
    radius chosen so that the widest wall stack stays 2-6 px inside the hole.
Truth
    The energy of a stack is ``n L int kappa^2 ds`` (kappa in 1/mm, analytic on the Bezier,
    exact on arcs; ``L`` is the rod length ``sum n * length``); junctions are the graph's
    vertices. Band width: ``w(n) = h (n + 0.4 sqrt(n))`` (``calibration.csv``).
Rendering and defects
    Each band is the union of anti-aliased discs of radius ``w(n) / 2`` along its centreline;
    ink (one of five blues / purples) of patchy density on off-white paper, an illumination
    gradient, 1-4 faint light-blue smears, 3-9 ink specks in the voids, a textured plate
    (grey, dark or brown) outside the hole with a shadow ring on half the scenes, Gaussian
    blur 0.3-1.5 px, noise sigma 2-10, JPEG quality 75-90, written as PNG.
Rejection
    A scene whose curvature is tighter than its band, whose lead arcs meet, with a very short
    edge or arc, a band outside the hole, non-adjacent bands closer than 4 px or adjacent
    bands overlapping away from their junction, is rejected; attempt ``k`` of seed ``s``
    draws from seed ``1000 s + k`` (up to 400 attempts).

Conditions
----------
==========  ===============================================================================
typical     50 px/mm (h = 5 px), hole radius 13-18 mm, Poisson spacing 3.2-4.6 mm, 1-8
            layers per stack (target mean 2.5-4.5), angled forks only
thick       as typical with spacing 5.0-6.5 mm and 1-20 layers (target mean 6-8): fewer,
            thicker stacks
lowres      25 px/mm (h = 2.5 px), hole radius 14-20 mm, spacing 2.8-4.4 mm
peel        spacing 4.0-5.5 mm, target mean 2.5-4.0, each fork of degree 3 (wall ones too)
            tangential with probability 0.3, the curvature limit relaxed to 0.6 w (0.25 mm)
thick_dense hole radius 20-24 mm, spacing 4.2-4.8 mm, 1-20 layers (target mean 5.5-8):
            about 120 stacks of 6-7 layers in the mean; drawn with repairs (a site next to
            a short edge or wall arc dropped, a stack too tight for its band clamped towards
            its chord) instead of rejections, which alone cannot draw so many stacks
midres      as typical at 35 px/mm (h = 3.5 px, a sheet thickness that is not a whole
            number of pixels)
==========  ===============================================================================

Reproducibility: a seed gives the same PNG bytes and truth JSON on the same numpy, scipy
(HiGHS) and OpenCV versions. The layer-count program stops after a fixed number of
branch-and-bound nodes, not after a wall-clock time, so the load of the machine does not
change the scene.

Usage: python benchmarks/independent_scenes.py [OUTDIR [SEED [CONDITION]]]
Writes OUTDIR/CONDITION_SS.png (the scan), CONDITION_SS.json (truth), CONDITION_SS_lines.npz
(centrelines in px, one array ``s<stack id>`` each) and OUTDIR/calibration.csv. Without
arguments (as ``benchmarks/run_all.py`` runs it) it writes typical seed 1 into
``benchmarks/out/independent_scenes``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import cv2
import numpy as np
from scipy import ndimage
from scipy.optimize import Bounds, LinearConstraint
from scipy.optimize import milp as _milp
from scipy.spatial import Voronoi, cKDTree

def milp(*args, **kwargs):
    """scipy's ``milp`` with file descriptor 1 sent to the null device: HiGHS 1.12 prints
    stray lines with C's ``printf`` whatever its ``disp`` option (this generator imports
    nothing of the package, which has its own wrapper for the same reason). Without a C
    library to flush or a usable fd 1, the call is left as it is."""
    import ctypes

    try:
        libc = ctypes.CDLL(None)
        sys.stdout.flush()
        libc.fflush(None)
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):
        return _milp(*args, **kwargs)
    try:
        null = os.open(os.devnull, os.O_WRONLY)
    except OSError:
        os.close(saved)
        return _milp(*args, **kwargs)
    try:
        os.dup2(null, 1)
        return _milp(*args, **kwargs)
    finally:
        libc.fflush(None)
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


#: Layer thickness h (mm).
H_MM = 0.1
#: Attempts per seed before giving up (a seed often needs several, sometimes tens).
MAX_ATTEMPTS = 400
#: Branch-and-bound node budget of the layer-count program. The generator was first written
#: with a 4 s time limit, which made a scene depend on the machine's speed and load (the
#: incumbent at the limit, even whether a scene is rejected); a node budget stops HiGHS at
#: the same incumbent everywhere. 300 nodes take about those 4 s on typical scenes.
MILP_NODE_LIMIT = 300


@dataclass(frozen=True)
class Condition:
    """The parameters one condition varies (ranges are drawn per scene)."""

    px_per_mm: float
    hole_radius_mm: tuple[float, float]
    spacing_mm: tuple[float, float]
    max_layers: int
    mean_layers: tuple[float, float]
    peel_probability: float
    #: Layers of the widest wall stack assumed before the counts are known (the wall circle
    #: is rescaled once they are).
    provisional_layers: int
    #: Repair a draw instead of rejecting it: a site next to a short edge or wall arc is
    #: dropped and the diagram rebuilt, and a stack bending tighter than its band has its
    #: end tangents clamped further towards its chord. With 100 or more stacks nearly every
    #: draw breaks one rule somewhere (12 of 12 draws at 3.0-3.6 mm spacing did), so dense
    #: scenes cannot be drawn by rejection alone.
    repair: bool = False


CONDITIONS = MappingProxyType({
    "typical": Condition(50.0, (13, 18), (3.2, 4.6), 8, (2.5, 4.5), 0.0, 8),
    "thick": Condition(50.0, (13, 18), (5.0, 6.5), 20, (6.0, 8.0), 0.0, 12),
    "lowres": Condition(25.0, (14, 20), (2.8, 4.4), 8, (2.5, 4.5), 0.0, 8),
    "peel": Condition(50.0, (13, 18), (4.0, 5.5), 8, (2.5, 4.0), 0.3, 8),
    "thick_dense": Condition(50.0, (20, 24), (4.2, 4.8), 20, (5.5, 8.0), 0.0, 12, repair=True),
    "midres": Condition(35.0, (13, 18), (3.2, 4.6), 8, (2.5, 4.5), 0.0, 8),
})

PAPERS = ((252, 251, 247), (247, 242, 228), (245, 240, 232), (250, 250, 250), (240, 236, 222))
INKS = (("navy", (28, 36, 105)), ("royal", (45, 75, 195)), ("purple", (80, 55, 165)),
        ("cyan", (35, 115, 190)), ("dark", (40, 50, 140)))
PLATES = (("grey", (128, 125, 120)), ("dark", (45, 44, 48)), ("brown", (112, 82, 58)))
SMEAR_RGB = (170, 195, 235)


class SceneRejected(Exception):
    """A drawn scene violates a rule of the model; the next attempt is drawn instead.

    Parameters
    ----------
    reason : str
        Short fixed name of the rule (the key of the rejection tally).
    detail : str, optional
        What exactly failed.
    where : array_like, optional
        Where the defect lies (px, hole centre at the origin), for a topology that is
        repaired rather than redrawn (:attr:`Condition.repair`).
    """

    def __init__(self, reason: str, detail: str = "", where=None):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.where = where


def width_mm(n, h=H_MM):
    """Width of a stack of ``n`` layers, ``h (n + 0.4 sqrt(n))``.

    Parameters
    ----------
    n : int, float or array_like
        Number of layers.
    h : float
        Layer thickness (mm).

    Returns
    -------
    float or ndarray
        Width (mm).
    """
    n = np.asarray(n, dtype=float)
    return h * (n + 0.4 * np.sqrt(n))


def width_px(n, ppm):
    """Width of a stack of ``n`` layers in pixels at ``ppm`` px/mm."""
    return width_mm(n) * ppm


def write_calibration(path, nmax=30):
    """Write the generator's width law as a calibration table for ``crosssection.analyze``.

    Parameters
    ----------
    path : str or Path
        CSV file to write (columns ``n_layers,width_mm``).
    nmax : int
        Largest number of layers listed.
    """
    with open(path, "w") as f:
        f.write("n_layers,width_mm\n")
        for n in np.arange(1, nmax + 1):
            f.write(f"{n},{width_mm(n):.6f}\n")


# ----------------------------------------------------------------------------- geometry
def _rot(v, a):
    """``v`` rotated by ``a`` radians (counter-clockwise)."""
    c, s = math.cos(a), math.sin(a)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])


def _unit(v):
    return v / np.linalg.norm(v)


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _arc_points(P, T, k, s, ds=0.25):
    """Constant-curvature arc from ``P`` with unit tangent ``T``, signed curvature ``k``
    (counter-clockwise positive) and length ``s``: (points, end tangent, int kappa^2 ds in
    1/px)."""
    m = max(2, int(math.ceil(s / ds)) + 1)
    t = np.linspace(0.0, s, m)
    th0 = math.atan2(T[1], T[0])
    if abs(k) < 1e-12:
        pts = P[None, :] + t[:, None] * T[None, :]
    else:
        th = th0 + k * t
        pts = np.stack([P[0] + (np.sin(th) - math.sin(th0)) / k,
                        P[1] - (np.cos(th) - math.cos(th0)) / k], axis=1)
    Tend = np.array([math.cos(th0 + k * s), math.sin(th0 + k * s)])
    return pts, Tend, k * k * s


def _bezier(P0, P1, P2, P3, nsamp=4000):
    """Cubic Bezier: (points ~0.25 px apart, int kappa^2 ds, length, max |kappa|), px units.

    The curvature and its integral are analytic (from the derivatives), not measured on the
    sampled points, so the truth energy carries no discretisation error of its own.
    """
    t = np.linspace(0, 1, nsamp)[:, None]
    B = (1 - t) ** 3 * P0 + 3 * (1 - t) ** 2 * t * P1 + 3 * (1 - t) * t ** 2 * P2 + t ** 3 * P3
    d1 = 3 * (1 - t) ** 2 * (P1 - P0) + 6 * (1 - t) * t * (P2 - P1) + 3 * t ** 2 * (P3 - P2)
    d2 = 6 * (1 - t) * (P2 - 2 * P1 + P0) + 6 * t * (P3 - 2 * P2 + P1)
    sp = np.hypot(d1[:, 0], d1[:, 1])
    kap = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / sp ** 3
    f = kap ** 2 * sp
    tt = t[:, 0]
    I = float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(tt)))
    length = float(np.sum(0.5 * (sp[1:] + sp[:-1]) * np.diff(tt)))
    # the rendering wants points evenly spaced in arc length, not in t
    seg = np.hypot(*np.diff(B, axis=0).T)
    cum = np.concatenate([[0], np.cumsum(seg)])
    m = max(2, int(cum[-1] / 0.25) + 1)
    su = np.linspace(0, cum[-1], m)
    pts = np.stack([np.interp(su, cum, B[:, 0]), np.interp(su, cum, B[:, 1])], axis=1)
    return pts, I, length, float(np.max(np.abs(kap)))


def _poisson_disc(rng, R, dmin, n_try=3000):
    """Dart throwing in a disc of radius ``R``: candidates closer than ``dmin`` are dropped."""
    pts = []
    for _ in range(n_try):
        r = R * math.sqrt(rng.random())
        a = rng.random() * 2 * math.pi
        p = np.array([r * math.cos(a), r * math.sin(a)])
        if all(np.hypot(*(p - q)) >= dmin for q in pts):
            pts.append(p)
    return np.array(pts)


def _seg_circle(p, q, R):
    """Parameters t in [0, 1] where the segment p -> q crosses the circle |x| = R."""
    d = q - p
    a = d @ d
    b = 2 * p @ d
    c = p @ p - R * R
    disc = b * b - 4 * a * c
    if disc <= 0:
        return []
    sq = math.sqrt(disc)
    return sorted(t for t in ((-b - sq) / (2 * a), (-b + sq) / (2 * a)) if 0 <= t <= 1)


# ----------------------------------------------------------------------------- topology
def _build_topology(pts, Rw):
    """Vertices (positions, kinds 'int' / 'wall') and edges ``[u, v, 'line']`` or
    ``[u, v, 'wall', (theta0, theta1)]`` in px of the Voronoi diagram of the sites ``pts``
    clipped to the wall circle ``Rw``, the hole's centre at the origin."""
    # a far ring of sites closes every cell, so that no ridge near the wall is infinite
    ring = np.array([[3 * Rw * math.cos(a), 3 * Rw * math.sin(a)]
                     for a in np.linspace(0, 2 * math.pi, 24, endpoint=False)])
    vor = Voronoi(np.vstack([pts, ring]))
    V = []
    kind = []
    vmap = {}
    edges = []
    wall_vs = []

    def vid(i):
        if i not in vmap:
            vmap[i] = len(V)
            V.append(vor.vertices[i].copy())
            kind.append("int")
        return vmap[i]

    def wall_vertex(p):
        V.append(p * (Rw / np.linalg.norm(p)))
        kind.append("wall")
        wall_vs.append(len(V) - 1)
        return len(V) - 1

    for (i, j) in vor.ridge_vertices:
        if i < 0 or j < 0:
            continue
        p, q = vor.vertices[i], vor.vertices[j]
        ip, iq = np.linalg.norm(p) < Rw, np.linalg.norm(q) < Rw
        ts = _seg_circle(p, q, Rw)
        if ip and iq:
            edges.append([vid(i), vid(j), "line"])
        elif ip and not iq:
            w = wall_vertex(p + ts[-1] * (q - p))
            edges.append([vid(i), w, "line"])
        elif iq and not ip:
            w = wall_vertex(p + ts[0] * (q - p))
            edges.append([w, vid(j), "line"])
        elif len(ts) == 2:
            a = wall_vertex(p + ts[0] * (q - p))
            b = wall_vertex(p + ts[1] * (q - p))
            edges.append([a, b, "line"])
    ang = {w: math.atan2(V[w][1], V[w][0]) % (2 * math.pi) for w in wall_vs}
    order = sorted(wall_vs, key=lambda w: ang[w])
    for k in range(len(order)):
        a, b = order[k], order[(k + 1) % len(order)]
        th0 = ang[a]
        th1 = ang[b] if k + 1 < len(order) else ang[b] + 2 * math.pi
        edges.append([a, b, "wall", (th0, th1)])
    return [np.array(v) for v in V], kind, edges


def _topology_checked(sites, Rw, dmin):
    """:func:`_build_topology` with short edges contracted, rejected where an edge or a wall
    arc is shorter than ``0.2 dmin`` (the exception says where)."""
    V, kind, edges = _build_topology(sites, Rw)
    _contract_short(V, kind, edges, lmin=0.2 * dmin)
    for e in edges:
        if e[2] == "wall":
            if (e[3][1] - e[3][0]) * Rw < 0.2 * dmin:
                th = 0.5 * (e[3][0] + e[3][1])
                raise SceneRejected("short wall arc", where=Rw * np.array([math.cos(th),
                                                                          math.sin(th)]))
        elif np.linalg.norm(V[e[0]] - V[e[1]]) < 0.2 * dmin:
            raise SceneRejected("short edge", kind[e[0]] + kind[e[1]],
                                where=0.5 * (V[e[0]] + V[e[1]]))
    return V, kind, edges


def _topology_repaired(sites, Rw, dmin, max_repairs):
    """:func:`_topology_checked`, dropping the site nearest to each located defect and
    rebuilding, at most ``max_repairs`` times (0: the first defect rejects the draw).

    Returns ``V``, ``kind``, ``edges`` and the sites kept."""
    for _ in range(max_repairs + 1):
        try:
            return (*_topology_checked(sites, Rw, dmin), sites)
        except SceneRejected as exc:
            if max_repairs == 0 or exc.where is None:
                raise
            sites = np.delete(sites, np.argmin(np.hypot(*(sites - exc.where).T)), axis=0)
    raise SceneRejected("topology not repaired")


def _relabel(edges, old, new):
    for f in edges:
        if f[0] == old:
            f[0] = new
        if f[1] == old:
            f[1] = new


def _contract_short(V, kind, edges, lmin):
    """Contract edges shorter than ``lmin`` between two degree-3 vertices into one degree-4
    junction (onto the wall vertex when one end is on the wall); edits in place."""
    changed = True
    while changed:
        changed = False
        deg = np.zeros(len(V), int)
        for e in edges:
            deg[e[0]] += 1
            deg[e[1]] += 1
        for ei, e in enumerate(edges):
            u, v = e[0], e[1]
            if e[2] == "line" and kind[u] != kind[v] and np.linalg.norm(V[u] - V[v]) < lmin:
                w_, x_ = (u, v) if kind[u] == "wall" else (v, u)
                if deg[w_] != 3 or deg[x_] != 3:
                    raise SceneRejected("short wall edge", "near a degree-4 vertex",
                                        where=0.5 * (V[u] + V[v]))
                edges.pop(ei)
                _relabel(edges, x_, w_)
                changed = True
                break
            if e[2] != "line" or kind[u] != "int" or kind[v] != "int":
                continue
            if np.linalg.norm(V[u] - V[v]) < lmin:
                if deg[u] != 3 or deg[v] != 3:
                    raise SceneRejected("short edge", "near a degree-4 vertex",
                                        where=0.5 * (V[u] + V[v]))
                V[u] = 0.5 * (V[u] + V[v])
                edges.pop(ei)
                _relabel(edges, v, u)
                changed = True
                break


def _incident(nV, edges):
    inc = [[] for _ in range(nV)]
    for ei, e in enumerate(edges):
        inc[e[0]].append(ei)
        inc[e[1]].append(ei)
    return inc


def _end_dir(V, e, v):
    """Unit direction in which edge ``e`` leaves vertex ``v`` (chord, or wall tangent)."""
    u, w = e[0], e[1]
    if e[2] == "wall":
        p = V[v]
        t = np.array([-p[1], p[0]]) / np.linalg.norm(p)  # counter-clockwise tangent
        return t if v == u else -t
    other = w if v == u else u
    return _unit(V[other] - V[v])


def _pairing_options(V, kind, edges, inc):
    """The admissible groupings ``(A, B)`` per vertex (layers arriving by A leave by B)."""
    opts = {}
    for v in range(len(V)):
        es = inc[v]
        if len(es) == 0:
            continue
        if len(es) == 3:
            if kind[v] == "wall":
                walls = [e for e in es if edges[e][2] == "wall"]
                if len(walls) != 2:
                    raise SceneRejected("wall vertex", "without two arcs")
                cands = walls  # the trunk is a wall arc: the interior stack peels off it
            else:
                cands = es
            opts[v] = [([t], [e for e in es if e != t]) for t in cands]
        elif len(es) == 4:
            # only angular neighbours can be grouped: crossing pairs would cross bands
            dirs = {e: _end_dir(V, edges[e], v) for e in es}
            o = sorted(es, key=lambda e: math.atan2(dirs[e][1], dirs[e][0]))
            if kind[v] == "wall":
                for sh in range(4):
                    oo = o[sh:] + o[:sh]
                    if edges[oo[0]][2] == "wall" and edges[oo[3]][2] == "wall":
                        break
                else:
                    raise SceneRejected("wall degree-4", "arcs not adjacent")
                opts[v] = [([oo[0], oo[1]], [oo[2], oo[3]])]
            else:
                opts[v] = [([o[0], o[1]], [o[2], o[3]]), ([o[1], o[2]], [o[3], o[0]])]
        else:
            raise SceneRejected("degree", f"{len(es)}")
    return opts


def _assign_pairing(V, kind, edges, inc, rng, cap, tmean):
    """A pairing per vertex and layer counts ``1 <= n <= cap`` conserving layers at every
    vertex, as close to gamma-distributed targets (mean ``tmean``) as the program finds.

    Variables: ``n`` per edge, a binary choice per (vertex, option), ``|n - target|`` per
    edge; big-M rows enforce ``sum_A n = sum_B n`` for the chosen option only.
    """
    opts = _pairing_options(V, kind, edges, inc)
    nE = len(edges)
    tv = [(v, g) for v, ol in opts.items() for g in range(len(ol))]
    nT = len(tv)
    nvar = nE + nT + nE
    rows, lo, hi = [], [], []
    target = np.clip(np.round(rng.gamma(2.0, tmean / 2.0, nE)), 1, cap)
    for e in range(nE):
        r = np.zeros(nvar)
        r[e] = 1
        r[nE + nT + e] = -1
        rows.append(r)
        lo.append(-np.inf)
        hi.append(target[e])
        r = np.zeros(nvar)
        r[e] = -1
        r[nE + nT + e] = -1
        rows.append(r)
        lo.append(-np.inf)
        hi.append(-target[e])
    M = 4.0 * cap
    for j, (v, g) in enumerate(tv):
        A, B = opts[v][g]
        r = np.zeros(nvar)
        for e in A:
            r[e] += 1
        for e in B:
            r[e] -= 1
        r1 = r.copy()
        r1[nE + j] = M
        r2 = -r
        r2[nE + j] = M
        rows += [r1, r2]
        lo += [-np.inf, -np.inf]
        hi += [M, M]
    for v in opts:
        r = np.zeros(nvar)
        for j, (vv, g) in enumerate(tv):
            if vv == v:
                r[nE + j] = 1
        rows.append(r)
        lo.append(1)
        hi.append(1)
    c = np.concatenate([np.zeros(nE), np.zeros(nT), np.ones(nE)])
    res = milp(c, constraints=LinearConstraint(np.array(rows), lo, hi),
               integrality=np.r_[np.ones(nE + nT), np.zeros(nE)],
               bounds=Bounds(np.r_[np.ones(nE), np.zeros(nT), np.zeros(nE)],
                             np.r_[np.full(nE, cap), np.ones(nT), np.full(nE, np.inf)]),
               options=dict(node_limit=MILP_NODE_LIMIT))
    if res.x is None:
        raise SceneRejected("no feasible pairing")
    x = np.round(res.x).astype(int)
    pair = {v: opts[v][g] for j, (v, g) in enumerate(tv) if x[nE + j] == 1}
    n = x[:nE]
    for v, (A, B) in pair.items():
        if sum(n[e] for e in A) != sum(n[e] for e in B):
            raise AssertionError(f"layer conservation broken at vertex {v}")
    return pair, n


# ----------------------------------------------------------------------------- scene
def _sep_lead(R0, sep):
    """Length of an arc of radius ``R0`` leaving a straight line tangentially until it is
    ``sep`` away from it (half a turn when it never gets that far)."""
    return R0 * math.acos(max(-1.0, 1 - sep / R0)) if sep < 2 * R0 else math.pi * R0


def _fork_tangents(V, kind, edges, inc, pair, n, rng, Rw, ppm, peel_p):
    """End tangents (pointing into the edge) and lead arcs ``(curvature, length)`` per
    (edge, vertex), and a description of every fork."""
    tang = {}
    lead = {}
    forks = []
    for v in range(len(V)):
        es = inc[v]
        if not es:
            continue
        A, B = pair[v]
        peel = rng.random() < peel_p
        phi = math.radians(rng.uniform(30, 60))
        if kind[v] == "wall":
            for grp in (A, B):
                arcs = [e for e in grp if edges[e][2] == "wall"]
                ies = [e for e in grp if edges[e][2] == "line"]
                if len(arcs) != 1:
                    continue
                # the interior stack leaves beside the wall arc of its own group (its sibling
                # branch), turned inwards
                arc_o = arcs[0]
                for ie in ies:
                    tb = _end_dir(V, edges[arc_o], v)
                    nin = _unit(-V[v])
                    sgn = 1.0 if _cross(tb, nin) > 0 else -1.0
                    if peel:
                        R0 = rng.uniform(1.2, 3.0) * ppm
                        k = sgn * (1.0 / Rw + 1.0 / R0)
                        sep = (width_px(n[ie], ppm) + width_px(n[arc_o], ppm)) / 2 + 3
                        s = _sep_lead(R0, sep)
                        tang[(ie, v)] = tb
                        lead[(ie, v)] = (k, s)
                        ep, _, _ = _arc_points(V[v], tb, k, s)
                        q = ep[-1] / np.linalg.norm(ep[-1]) * Rw
                        forks.append(dict(v=v, type="wall_peel", R0_px=R0, s_lead=s,
                                          vis=0.5 * (ep[-1] + q)))
                    else:
                        tang[(ie, v)] = _rot(tb, sgn * phi)
                        forks.append(dict(v=v, type="wall_angle", phi=math.degrees(phi)))
            continue
        if len(es) == 3:
            a = A[0]
            b, c = B
            da, db, dc = (_end_dir(V, edges[x], v) for x in (a, b, c))
            axis = _unit(_unit(db + dc) - da)
            tang[(a, v)] = -axis
            sb = 1.0 if _cross(axis, db) > 0 else -1.0
            if peel:
                # one branch goes straight on, the other peels off it with constant curvature
                if rng.random() < 0.5:
                    b, c = c, b
                # the straight-on branch continues the trunk: the axis mostly along its chord
                db_ = _end_dir(V, edges[b], v)
                axis = _unit(0.7 * db_ - 0.3 * da)
                tang[(a, v)] = -axis
                sb = -1.0 if _cross(axis, _end_dir(V, edges[c], v)) > 0 else 1.0
                R0 = rng.uniform(1.2, 3.0) * ppm
                sep = (width_px(n[b], ppm) + width_px(n[c], ppm)) / 2 + 3
                s = _sep_lead(R0, sep)
                tang[(b, v)] = axis
                tang[(c, v)] = axis
                lead[(b, v)] = (0.0, s)
                lead[(c, v)] = (-sb / R0, s)
                eb, _, _ = _arc_points(V[v], axis, 0.0, s)
                ec, _, _ = _arc_points(V[v], axis, -sb / R0, s)
                forks.append(dict(v=v, type="peel", R0_px=R0, s_lead=s,
                                  vis=0.5 * (eb[-1] + ec[-1])))
            else:
                tang[(b, v)] = _rot(axis, sb * phi / 2)
                tang[(c, v)] = _rot(axis, -sb * phi / 2)
                forks.append(dict(v=v, type="angle", phi=math.degrees(phi)))
        else:
            d = {e: _end_dir(V, edges[e], v) for e in es}
            axis = _unit(_unit(d[B[0]] + d[B[1]]) - _unit(d[A[0]] + d[A[1]]))
            for grp, ax in ((A, -axis), (B, axis)):
                s0 = 1.0 if _cross(ax, d[grp[0]]) > _cross(ax, d[grp[1]]) else -1.0
                tang[(grp[0], v)] = _rot(ax, s0 * phi / 2)
                tang[(grp[1], v)] = _rot(ax, -s0 * phi / 2)
            forks.append(dict(v=v, type="deg4", phi=math.degrees(phi)))
    return tang, lead, forks


def _kappa_limit(n, ppm, peel_p):
    """Largest curvature (1/px) a band of ``n`` layers may have without folding onto itself
    (relaxed where tangential forks are drawn: their lead arcs are tight)."""
    if peel_p == 0:
        return 1.0 / max(1.0 * width_px(n, ppm), 0.4 * ppm)
    return 1.0 / max(0.6 * width_px(n, ppm), 0.25 * ppm)


def _lead_arc(P, T, arc):
    """A lead arc ``arc = (k, s)`` from ``P`` along ``T``: its points, end tangent,
    int kappa^2 ds, length and |kappa|."""
    k, s = arc
    pts, T_end, I = _arc_points(P, T, k, s)
    return pts, T_end, I, s, abs(k)


def _stack_curve(ei, e, V, tang, lead, n, ppm, peel_p, rng, repair=False):
    """Centreline points, int kappa^2 ds (1/px), length (px) and max |kappa| of an interior
    stack: lead arcs at its ends and the least-bending cubic between them (with ``repair``,
    its end tangents clamped closer to the chord, step by step, until it bends no tighter
    than its band)."""
    u, w = e[0], e[1]
    Pu, Tu = V[u], tang[(ei, u)]
    Pv, Tv = V[w], tang[(ei, w)]
    I = 0.0
    length = 0.0
    kmax = 0.0
    parts_u, parts_v = [Pu[None]], [Pv[None]]
    if (ei, u) in lead:
        pts_u, Tu, Iu, s_u, k_u = _lead_arc(Pu, Tu, lead[(ei, u)])
        parts_u, Pu = [pts_u], pts_u[-1]
        I, length, kmax = I + Iu, length + s_u, max(kmax, k_u)
    if (ei, w) in lead:
        pts_v, Tv, Iv, s_v, k_v = _lead_arc(Pv, Tv, lead[(ei, w)])
        parts_v, Pv = [pts_v], pts_v[-1]
        I, length, kmax = I + Iv, length + s_v, max(kmax, k_v)
    chord = np.linalg.norm(Pv - Pu)
    if chord < 5:
        raise SceneRejected("lead arcs meet")
    # short stacks cannot turn much: clamp the end tangents towards the chord
    dmax0 = math.radians(np.interp(chord / ppm, [1.0, 3.0], [25.0, 70.0]))
    cu = (Pv - Pu) / chord
    Tu0, Tv0 = Tu, Tv
    for shrink in ((1.0, 0.8, 0.6, 0.45, 0.3, 0.2, 0.1) if repair else (1.0,)):
        dmax = dmax0 * shrink
        Tu, Tv = Tu0, Tv0
        for which in ("u", "v"):
            T0, cd = (Tu, cu) if which == "u" else (Tv, -cu)
            if (ei, u if which == "u" else w) in lead:
                continue
            ang = math.atan2(_cross(cd, T0), float(cd @ T0))
            if abs(ang) > dmax:
                T0 = _rot(cd, math.copysign(dmax, ang))
                if which == "u":
                    Tu = T0
                else:
                    Tv = T0
        # handles: the least-bending cubic (a relaxed sheet), slightly perturbed
        best = None
        for lu in (0.2, 0.35, 0.5, 0.7):
            for lv in (0.2, 0.35, 0.5, 0.7):
                _, Ib_, _, _ = _bezier(Pu, Pu + lu * chord * Tu, Pv + lv * chord * Tv, Pv,
                                       nsamp=200)
                if best is None or Ib_ < best[0]:
                    best = (Ib_, lu, lv)
        lam_u, lam_v = best[1] * rng.uniform(0.9, 1.1), best[2] * rng.uniform(0.9, 1.1)
        bp, Ib, Lb, kb = _bezier(Pu, Pu + lam_u * chord * Tu, Pv + lam_v * chord * Tv, Pv)
        if max(kmax, kb) <= _kappa_limit(n, ppm, peel_p):
            break
    I += Ib
    length += Lb
    kmax = max(kmax, kb)
    if kmax > _kappa_limit(n, ppm, peel_p):
        raise SceneRejected("curvature tighter than the band",
                            f"radius {1 / kmax:.1f} px, chord {chord:.0f} px, n {n}")
    pts = np.vstack([parts_u[0], bp[1:], parts_v[0][::-1][1:]])
    return pts, I, length, kmax


def make_scene(seed, cond):
    """Draw one scene's geometry (no image).

    Parameters
    ----------
    seed : int
        Seed of ``numpy.random.default_rng`` for this attempt.
    cond : str
        A key of :data:`CONDITIONS`.

    Returns
    -------
    dict
        ``seed``, ``cond``, ``ppm``, ``h_px``, ``R_px`` (hole radius), ``Rw_px`` (wall
        circle), ``V`` (vertex positions, px, hole centre at the origin), ``kind``, ``stacks``
        (per edge: ``id``, ``u``, ``v``, ``n``, ``kind``, ``pts``, ``int_k2_px``,
        ``length_px``, ``kmax_px``), ``forks`` and ``mode_p`` (the peel probability).

    Raises
    ------
    SceneRejected
        When the draw breaks a rule of the model.
    """
    spec = CONDITIONS[cond]
    rng = np.random.default_rng(seed)
    ppm = spec.px_per_mm
    h = H_MM * ppm
    R = rng.uniform(*spec.hole_radius_mm) * ppm
    dmin_mm = rng.uniform(*spec.spacing_mm)
    cap = spec.max_layers
    tmean = rng.uniform(*spec.mean_layers)
    mode_p = spec.peel_probability
    dmin = dmin_mm * ppm
    gap_wall = rng.uniform(2, 6)
    Rw = R - gap_wall - width_px(spec.provisional_layers, ppm) / 2
    sites = _poisson_disc(rng, Rw * 0.97, dmin)
    V, kind, edges, _ = _topology_repaired(sites, Rw, dmin, 200 if spec.repair else 0)
    inc = _incident(len(V), edges)
    pair, n = _assign_pairing(V, kind, edges, inc, rng, cap, tmean)
    # now that the counts are known, rescale so that the widest wall stack keeps its gap
    wmax_wall = max(width_px(n[i], ppm) for i, e in enumerate(edges) if e[2] == "wall")
    Rw_new = R - gap_wall - wmax_wall / 2
    scale = Rw_new / Rw
    V = [v * scale for v in V]
    Rw = Rw_new

    tang, lead, forks = _fork_tangents(V, kind, edges, inc, pair, n, rng, Rw, ppm, mode_p)
    stacks = []
    for ei, e in enumerate(edges):
        u, w = e[0], e[1]
        if e[2] == "wall":
            th0, th1 = e[3]
            m = max(2, int((th1 - th0) * Rw / 0.25) + 1)
            th = np.linspace(th0, th1, m)
            pts = np.stack([Rw * np.cos(th), Rw * np.sin(th)], axis=1)
            I = (th1 - th0) * Rw / Rw ** 2
            length = (th1 - th0) * Rw
            kmax = 1 / Rw
        else:
            pts, I, length, kmax = _stack_curve(ei, e, V, tang, lead, n[ei], ppm, mode_p, rng,
                                                repair=spec.repair)
        stacks.append(dict(id=ei, u=int(u), v=int(w), n=int(n[ei]), kind=e[2], pts=pts,
                           int_k2_px=I, length_px=length, kmax_px=kmax))
    for st in stacks:  # the wall arcs too
        if st["kmax_px"] > _kappa_limit(st["n"], ppm, mode_p):
            raise SceneRejected("curvature tighter than the band", f"wall arc {st['id']}")
    return dict(seed=seed, cond=cond, ppm=ppm, h_px=h, R_px=R, Rw_px=Rw, V=V, kind=kind,
                stacks=stacks, forks=forks, mode_p=mode_p)


# ----------------------------------------------------------------------------- rendering
def _band_masks(scene, shape, centre):
    """Per stack, in its bounding box: ``(y0, x0, coverage, distance to the centreline)``;
    the coverage is anti-aliased over one pixel."""
    out = []
    for st in scene["stacks"]:
        r = width_px(st["n"], scene["ppm"]) / 2
        P = st["pts"] + centre[None, :]
        x0 = int(math.floor(P[:, 0].min() - r - 2))
        x1 = int(math.ceil(P[:, 0].max() + r + 2))
        y0 = int(math.floor(P[:, 1].min() - r - 2))
        y1 = int(math.ceil(P[:, 1].max() + r + 2))
        x0, y0 = max(x0, 0), max(y0, 0)
        x1, y1 = min(x1, shape[1] - 1), min(y1, shape[0] - 1)
        yy, xx = np.mgrid[y0:y1 + 1, x0:x1 + 1]
        tree = cKDTree(P)
        d, _ = tree.query(np.stack([xx.ravel(), yy.ravel()], 1), distance_upper_bound=r + 8)
        d = d.reshape(xx.shape)
        cov = np.clip(r - d + 0.5, 0, 1)
        cov[~np.isfinite(d)] = 0
        out.append((y0, x0, cov, d))
    return out


def _check_overlaps(scene, masks, shape, gap=4.0):
    """Reject non-adjacent bands closer than ``gap`` and adjacent ones overlapping away from
    their shared junction (beyond 4 widths + 10 px, plus any lead arc there)."""
    st = scene["stacks"]
    owner = -np.ones(shape, int)
    V = scene["V"]
    c = scene["centre"]
    ppm = scene["ppm"]
    for i, (y0, x0, cov, d) in enumerate(masks):
        r = width_px(st[i]["n"], ppm) / 2
        m = np.isfinite(d) & (d <= r + gap / 2)
        sub = owner[y0:y0 + m.shape[0], x0:x0 + m.shape[1]]
        hit = m & (sub >= 0)
        if hit.any():
            ys, xs = np.nonzero(hit)
            others = sub[ys, xs]
            for j in np.unique(others):
                shared = {st[i]["u"], st[i]["v"]} & {st[j]["u"], st[j]["v"]}
                if not shared:
                    raise SceneRejected("bands overlap", f"{i}, {j}")
                sel = others == j
                pp = np.stack([xs[sel] + x0, ys[sel] + y0], 1).astype(float)
                ok = np.zeros(len(pp), bool)
                for v in shared:
                    allow = 4.0 * max(width_px(st[i]["n"], ppm), width_px(st[j]["n"], ppm)) + 10
                    for f in scene["forks"]:
                        if f["v"] == v and "s_lead" in f:
                            allow += f["s_lead"]
                    ok |= np.hypot(*(pp - (V[v] + c)).T) < allow
                if not ok.all():
                    raise SceneRejected("adjacent bands overlap", f"{i}, {j} far from junction")
        sub[m] = i


def _value_noise(rng, shape, cell, lo, hi):
    """Smooth random field: uniform values on a grid of ``cell`` px, cubic interpolation."""
    gh, gw = shape[0] // cell + 3, shape[1] // cell + 3
    g = rng.uniform(lo, hi, (gh, gw)).astype(np.float32)
    up = cv2.resize(g, (gw * cell, gh * cell), interpolation=cv2.INTER_CUBIC)
    return up[:shape[0], :shape[1]]


def render(scene, rng):
    """Render a scene as a scan with its defects.

    Parameters
    ----------
    scene : dict
        From :func:`make_scene`; ``scene["centre"]`` (the hole centre in the image, px) is
        set here.
    rng : numpy.random.Generator
        Source of the image's random choices (colours, defects, placement).

    Returns
    -------
    img : ndarray
        (size, size, 3) uint8 RGB.
    meta : dict
        ``ink``, ``ink_rgb``, ``paper``, ``plate``, ``blur``, ``noise``, ``jpeg``,
        ``n_smears``, ``specks`` (``[x, y, radius]`` each) and ``size``.

    Raises
    ------
    SceneRejected
        When a band leaves the hole or bands overlap.
    """
    R = scene["R_px"]
    margin = int(rng.uniform(0.09, 0.16) * R) + 40
    size = int(2 * R + 2 * margin)
    shape = (size, size)
    centre = np.array([size / 2 + rng.uniform(-30, 30), size / 2 + rng.uniform(-30, 30)])
    scene["centre"] = centre
    masks = _band_masks(scene, shape, centre)
    for (y0, x0, cov, d), st in zip(masks, scene["stacks"]):
        ys, xs = np.nonzero(cov > 0)
        if len(ys) and np.max(np.hypot(xs + x0 - centre[0], ys + y0 - centre[1])) > R - 0.5:
            raise SceneRejected("band outside the hole", f"stack {st['id']}")
    _check_overlaps(scene, masks, shape)
    alpha = np.zeros(shape, np.float32)
    for (y0, x0, cov, d) in masks:
        sub = alpha[y0:y0 + cov.shape[0], x0:x0 + cov.shape[1]]
        np.maximum(sub, cov, out=sub)
    paper = np.array(rng.choice(PAPERS), float)
    paper += rng.uniform(-4, 4, 3)
    ink_name, ink_rgb = INKS[rng.integers(len(INKS))]
    ink = np.array(ink_rgb, float) + rng.uniform(-10, 10, 3)
    # patchy ink density (uneven dye uptake), then transmission per channel: overlapping
    # coverage darkens the way layers of dyed paper do
    dens = _value_noise(rng, shape, int(rng.uniform(60, 200)), rng.uniform(0.6, 0.85), 1.05)
    dens = np.clip(dens, 0.5, 1.0)
    trans = np.clip(ink / paper, 0.02, 1.0)
    a = (alpha * dens)[..., None]
    img = paper[None, None, :] * trans[None, None, :] ** a
    illum = _value_noise(rng, shape, 400, 0.96, 1.03)[..., None]
    img = img * illum
    yy, xx = np.mgrid[0:size, 0:size]
    rr = np.hypot(xx - centre[0], yy - centre[1])
    dist_ink = ndimage.distance_transform_edt(alpha < 0.05)
    n_sm = int(rng.integers(1, 5))
    for _ in range(n_sm):  # faint light-blue smears, anywhere
        cx, cy = centre + rng.uniform(-0.7, 0.7, 2) * R
        ang = rng.uniform(0, math.pi)
        L1, L2 = rng.uniform(40, 160), rng.uniform(8, 25)
        dx, dy = xx - cx, yy - cy
        u = (dx * math.cos(ang) + dy * math.sin(ang)) / L1
        v = (-dx * math.sin(ang) + dy * math.cos(ang)) / L2
        m = np.exp(-(u * u + v * v)) * rng.uniform(0.12, 0.25)
        sm_col = np.array(SMEAR_RGB, float)
        img = img * (1 - m[..., None]) + sm_col[None, None] * m[..., None]
    specks = []
    n_sp = int(rng.integers(3, 10))
    cand = np.argwhere((dist_ink > 20) & (rr < R - 20))
    for _ in range(n_sp):  # ink specks in the voids, clear of the bands
        y, x = cand[rng.integers(len(cand))]
        r = rng.uniform(1.0, 3.0)
        win = (slice(y - 6, y + 7), slice(x - 6, x + 7))
        m = np.clip(r - np.hypot(xx[win] - x, yy[win] - y) + 0.5, 0, 1)
        img[win] = img[win] * (1 - m[..., None]) + ink * m[..., None]
        specks.append([int(x), int(y), r])
    plate_name, plate_rgb = PLATES[rng.integers(len(PLATES))]
    plate = np.array(plate_rgb, float) + rng.uniform(-8, 8, 3)
    edge = np.clip(rr - R + 0.5, 0, 1)[..., None]
    plate_img = plate[None, None] * _value_noise(rng, shape, 150, 0.9, 1.1)[..., None]
    img = img * (1 - edge) + plate_img * edge
    if rng.random() < 0.5:  # the shadow of the hole's edge
        wd = rng.uniform(2, 7)
        sh = np.exp(-((rr - R - wd / 2) / (wd / 2)) ** 2) * rng.uniform(0.3, 0.6)
        img = img * (1 - sh[..., None])
    blur = rng.uniform(0.3, 1.5)
    img = cv2.GaussianBlur(img.astype(np.float32), (0, 0), blur)
    sig = rng.uniform(2, 10)
    img = img + rng.normal(0, sig, img.shape)
    img = np.clip(img, 0, 255).astype(np.uint8)
    q = int(rng.integers(75, 91))
    ok, buf = cv2.imencode(".jpg", img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, q])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    img = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
    meta = dict(ink=ink_name, ink_rgb=ink.tolist(), paper=paper.tolist(), plate=plate_name,
                blur=blur, noise=sig, jpeg=q, n_smears=n_sm, specks=specks, size=size)
    return img, meta


# ----------------------------------------------------------------------------- output
def scene_name(seed, cond):
    """File stem of a scene: ``CONDITION_SS``."""
    return f"{cond}_{seed:02d}"


def generate(seed, cond, outdir):
    """Draw, render and write one scene (the first attempt that passes every rule).

    Parameters
    ----------
    seed : int
        Scene seed; attempt ``k`` uses ``1000 seed + k`` for the geometry and that plus 7 for
        the image.
    cond : str
        ``typical``, ``thick``, ``lowres``, ``peel`` or ``thick_dense``
        (:data:`CONDITIONS`).
    outdir : str or Path
        Folder (created) for ``NAME.png``, ``NAME_lines.npz`` and ``NAME.json``, where
        NAME is :func:`scene_name`; the JSON is written last, under its final name only once
        complete, so its presence marks a finished scene.

    Returns
    -------
    name : str
        The scene's file stem.
    truth : dict
        The content of ``NAME.json``: scale, hole, rod length ``L_mm``, ``energy_total``,
        ``junctions`` (``id``, ``x``, ``y`` px, ``kind``, ``degree``), ``stacks`` (``id``,
        ends ``u``/``v``, ``n``, ``kind``, ``length_mm``, ``int_k2_per_mm``, ``energy``,
        ``mid``), ``forks`` and ``render`` (the image's random choices).
    rejected : dict
        Rejected attempts per rule.

    Raises
    ------
    ValueError
        For an unknown condition.
    RuntimeError
        When no attempt passes.
    """
    if cond not in CONDITIONS:
        raise ValueError(f"unknown condition {cond!r}; known: {', '.join(CONDITIONS)}")
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    rejected = {}
    for attempt in range(MAX_ATTEMPTS):
        s = seed * 1000 + attempt
        try:
            scene = make_scene(s, cond)
            img, meta = render(scene, np.random.default_rng(s + 7))
            break
        except SceneRejected as exc:
            rejected[exc.reason] = rejected.get(exc.reason, 0) + 1
    else:
        raise RuntimeError(f"no {cond} scene for seed {seed} in {MAX_ATTEMPTS} attempts: "
                           f"{rejected}")
    ppm = scene["ppm"]
    L_mm = sum(st["n"] * st["length_px"] / ppm for st in scene["stacks"])
    c = scene["centre"]
    stacks_out = []
    E = 0.0
    for st in scene["stacks"]:
        Ik2 = st["int_k2_px"] * ppm  # 1/px -> 1/mm
        e = st["n"] * L_mm * Ik2
        E += e
        P = st["pts"] + c[None]
        cum = np.concatenate([[0], np.cumsum(np.hypot(*np.diff(P, axis=0).T))])
        mid = P[np.searchsorted(cum, cum[-1] / 2)]
        stacks_out.append(dict(id=st["id"], u=st["u"], v=st["v"], n=st["n"], kind=st["kind"],
                               length_mm=st["length_px"] / ppm, int_k2_per_mm=Ik2,
                               energy=e, mid=mid.tolist()))
    junctions = [dict(id=i, x=float(p[0] + c[0]), y=float(p[1] + c[1]), kind=k,
                      degree=sum(1 for st in scene["stacks"] if i in (st["u"], st["v"])))
                 for i, (p, k) in enumerate(zip(scene["V"], scene["kind"]))]
    junctions = [j for j in junctions if j["degree"] > 0]  # vertices removed by contraction
    for f in scene["forks"]:  # visible split points, in image coordinates
        if "vis" in f:
            f["vis_px"] = (np.asarray(f.pop("vis")) + c).tolist()
    truth = dict(seed=seed, attempt=attempt, cond=cond, px_per_mm=ppm, thickness_mm=H_MM,
                 hole_radius_mm=scene["R_px"] / ppm, hole_center_px=c.tolist(),
                 wall_radius_px=scene["Rw_px"], L_mm=L_mm, energy_total=E,
                 junctions=junctions, stacks=stacks_out, forks=scene["forks"], render=meta)
    name = scene_name(seed, cond)
    if not cv2.imwrite(str(outdir / f"{name}.png"), img[..., ::-1]):
        raise OSError(f"cannot write {outdir / f'{name}.png'}")
    np.savez_compressed(outdir / f"{name}_lines.npz",
                        **{f"s{st['id']}": (st["pts"] + c[None]).astype(np.float32)
                           for st in scene["stacks"]})
    tmp = outdir / f".{name}.json.tmp"
    with open(tmp, "w") as f:
        json.dump(truth, f, indent=1)
    os.replace(tmp, outdir / f"{name}.json")
    return name, truth, rejected


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("outdir", nargs="?",
                    default=str(Path(__file__).resolve().parent / "out" / "independent_scenes"),
                    help="output folder (default: benchmarks/out/independent_scenes)")
    ap.add_argument("seed", nargs="?", type=int, default=1, help="scene seed (default: 1)")
    ap.add_argument("condition", nargs="?", default="typical", choices=list(CONDITIONS),
                    help="default: typical")
    args = ap.parse_args(argv)
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    write_calibration(out / "calibration.csv")
    name, t, rejected = generate(args.seed, args.condition, out)
    print(f"{name}: attempt {t['attempt']}, {len(t['stacks'])} stacks, "
          f"{len(t['junctions'])} junctions, L {t['L_mm']:.1f} mm, E {t['energy_total']:.4g}, "
          f"rejected {rejected} -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
