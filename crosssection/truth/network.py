"""Synthetic scans of folded-sheet cross-sections with exact ground truth.

An independent generator used to test and score the pipeline (``crosssection.analyze``): it
never calls a pipeline stage, and its truth is computed from the construction, not from the
image.

Construction (paper, sections "Image analysis procedure", "Stacking" and "Tiling")
----------------------------------------------------------------------------------
1. *Network.* Random points in the hole (disk of radius R), relaxed by a few Lloyd steps, and
   their Voronoi diagram computed together with the points mirrored through the circle, so that
   the cells meeting the wall end on it. Interior Voronoi vertices are Y junctions, the points
   where Voronoi ridges meet the circle are *wall junctions*, and the circle between two
   consecutive wall junctions is a wall stack (the rod pressed against the hole). Ridges shorter
   than a few band widths are contracted, which creates the rare degree-4 crossings (paper:
   "exactly 3 stacks intersect at 99 % of the junction points").
2. *Packs and layer counts.* At every junction the stacks are split into two packs A | B
   (cyclically contiguous; at a wall junction each wall stack lies in a different pack). The
   layer counts n_br >= 1 solve, as a mixed-integer program (``scipy.optimize.milp``), the pack
   conservation  sum_A n = sum_B n  at every junction (the linear system of the paper, section
   "Image analysis procedure"), with the pack split itself a binary choice per junction, the
   counts drawn toward an exponential target (paper Fig. 5c) and capped so that every band fits
   its stack length and its voids. Pairing the A and B layers at each junction decomposes the
   counts into closed strands that only ever pass A <-> B, i.e. physical sheet layers.
3. *Geometry.* Pack A leaves a junction along -t, pack B along +t, the members of a pack fanned
   by ``fan_deg`` (60 degrees by default), so two branches leave side by side and separate (the
   Y of paper Fig. 1c). The 60 degree opening puts the centre of the largest inscribed disc of
   the fork (the skeleton's branch point, the paper's junction definition) at the junction node,
   which is the truth position; narrower fans (30-35 degrees, the tangential forks of real
   scans) keep the truth at the node, where the centrelines start, while the bands stay merged
   farther out. Every interior stack is a cubic Bezier with these end tangents; wall stacks
   are arcs of radius R - w/2 (touching the wall). Each stack is drawn as a band of width
   ``calibration.width(n_br)`` at 4x resolution and area-averaged (anti-aliasing).
4. *Validation.* Distinct stacks keep a gap >= 2h except within a disc around their common
   junction, every enclosed void is >= 1.5 s_min, and the number of voids equals the number of
   faces of the network; otherwise the layout is redrawn (the hole grows by 5 % every 4 failures).

Calibration
-----------
The default width of a stack of n layers is ``w(n) = h (n + 0.4 sqrt(n))``
(:meth:`crosssection.core.calibration.Calibration.nonlinear`): the hot-wire cut thickens each
stack by a melted rim that grows sub-linearly with the stack thickness.

Truth tables follow :mod:`crosssection.core.schema`. Curvatures come from the analytic curves; the
energy of a branch is e = L * integral(kappa^2 ds) with L = sum(n_br * length) the rod length
(paper, section "Energetical properties"). Voids are those of the noise-free 4x rendering
(:func:`crosssection.truth.voids.truth_voids`, s_min = (10 h)^2). Colours and scan defects come
from :mod:`crosssection.truth.ink` and :mod:`crosssection.truth.degrade`, as for every generator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd

from crosssection.core import polyline
from crosssection.core.calibration import Calibration
from crosssection.core.errors import ParameterError
from crosssection.truth import degrade, ink
from crosssection.truth.scene import Scene
from crosssection.truth.voids import truth_voids

__all__ = ["SceneGenerationError", "make_scene"]

SUPERSAMPLE = 4  # rendering resolution factor (anti-aliasing and void truth)


class SceneGenerationError(ParameterError):
    """No valid layout found (too many stacks or layers for the requested image size)."""


# ----------------------------------------------------------------------------- network
@dataclass
class _Network:
    pos: np.ndarray          # (V, 2) float (x, y) in px, centre of the hole at the origin
    is_wall: np.ndarray      # (V,) bool
    edges: list              # list of (u, v, kind) kind "ridge" | "wall"
    wall_angles: dict        # wall edge index -> (phi_start, phi_end) ccw, phi_end > phi_start


def _voronoi_network(rng, n_cells: int, radius: float, min_edge: float, lloyd: int = 5):
    """A planar network of Voronoi ridges inside the disk plus the wall arcs.

    Returns ``_Network`` (may contain short edges; see :func:`_contract_short`)."""
    from scipy.spatial import Voronoi

    # uniform points in the disk, kept a little away from the wall
    r = radius * np.sqrt(rng.uniform(0, 0.92 ** 2, n_cells))
    a = rng.uniform(0, 2 * np.pi, n_cells)
    pts = np.column_stack([r * np.cos(a), r * np.sin(a)])

    def mirror(p):
        rr = np.hypot(p[:, 0], p[:, 1])[:, None]
        return p * (2 * radius - rr) / np.maximum(rr, 1e-9)

    for _ in range(lloyd):  # a few Lloyd steps: less extreme cells, still varied (paper Fig. 6a)
        vor = Voronoi(np.vstack([pts, mirror(pts)]))
        new = pts.copy()
        for i in range(n_cells):
            reg = vor.regions[vor.point_region[i]]
            if -1 in reg or not reg:
                continue
            poly = vor.vertices[reg]
            new[i] = poly.mean(axis=0)
        rr = np.hypot(new[:, 0], new[:, 1])
        new *= np.minimum(1.0, 0.92 * radius / np.maximum(rr, 1e-9))[:, None]
        pts = new

    allp = np.vstack([pts, mirror(pts)])
    vor = Voronoi(allp)
    nv = len(vor.vertices)
    pos = []
    is_wall = []
    vmap = {}

    def node_for(vi, wall):
        key = (vi, wall)
        if key not in vmap:
            p = vor.vertices[vi].copy()
            if wall:
                p = p / np.hypot(*p) * radius
            vmap[key] = len(pos)
            pos.append(p)
            is_wall.append(wall)
        return vmap[key]

    # generators of each Voronoi vertex (to know if it is interior: all 3 originals)
    gens = [set() for _ in range(nv)]
    for (p, q), rv in zip(vor.ridge_points, vor.ridge_vertices):
        for v in rv:
            if v >= 0:
                gens[v].update((p, q))
    edges = []
    for (p, q), rv in zip(vor.ridge_points, vor.ridge_vertices):
        if p >= n_cells or q >= n_cells or -1 in rv:
            continue
        ends = []
        for v in rv:
            interior = all(g < n_cells for g in gens[v])
            inside = np.hypot(*vor.vertices[v]) < radius
            ends.append(node_for(v, wall=not (interior and inside)))
        if ends[0] != ends[1]:
            edges.append((ends[0], ends[1], "ridge"))
    pos = np.array(pos, float).reshape(-1, 2)
    is_wall = np.array(is_wall, bool)
    if np.count_nonzero(is_wall) < 3:
        raise SceneGenerationError("the Voronoi cells give fewer than 3 wall nodes (too few "
                                   "cells for the disk)")
    # the wall arcs between consecutive wall nodes
    wall_nodes = np.flatnonzero(is_wall)
    phi = np.mod(np.arctan2(pos[wall_nodes, 1], pos[wall_nodes, 0]), 2 * np.pi)
    order = np.argsort(phi)
    wall_angles = {}
    for k in range(len(order)):
        i, j = wall_nodes[order[k]], wall_nodes[order[(k + 1) % len(order)]]
        p0, p1 = phi[order[k]], phi[order[(k + 1) % len(order)]]
        if p1 <= p0:
            p1 += 2 * np.pi
        wall_angles[len(edges)] = (p0, p1)
        edges.append((i, j, "wall"))
    return _Network(pos, is_wall, edges, wall_angles)


def _contract_short(net: _Network, radius: float, min_edge: float) -> _Network:
    """Merge the two ends of every edge shorter than ``min_edge`` (degree-4 crossings)."""
    parent = list(range(len(net.pos)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def edge_len(k, u, v, kind):
        if kind == "wall":
            p0, p1 = net.wall_angles[k]
            return radius * (p1 - p0)
        return float(np.hypot(*(net.pos[u] - net.pos[v])))

    deg = np.zeros(len(net.pos), int)
    for u, v, _ in net.edges:
        deg[u] += 1
        deg[v] += 1
    order = sorted(range(len(net.edges)), key=lambda k: edge_len(k, *net.edges[k]))
    # at most ~4 % crossings (paper: 1 %); other short stacks stay, thin (see the caps)
    merges, max_merges = 0, max(1, int(0.04 * len(net.pos)))
    for k in order:
        u, v, kind = net.edges[k]
        if edge_len(k, u, v, kind) >= min_edge:
            break
        ru, rv = find(u), find(v)
        # merge only two Y junctions into one crossing (never degree > 4)
        if ru != rv and deg[ru] == 3 and deg[rv] == 3 and merges < max_merges:
            parent[rv] = ru
            deg[ru] = 4
            merges += 1
    roots = sorted({find(i) for i in range(len(net.pos))})
    new_id = {r: k for k, r in enumerate(roots)}
    members = {r: [] for r in roots}
    for i in range(len(net.pos)):
        members[find(i)].append(i)
    pos = np.zeros((len(roots), 2))
    is_wall = np.zeros(len(roots), bool)
    for r, mem in members.items():
        wall = net.is_wall[mem]
        if wall.any():
            p = net.pos[np.array(mem)[wall]].mean(axis=0)
            pos[new_id[r]] = p / np.hypot(*p) * radius
            is_wall[new_id[r]] = True
        else:
            pos[new_id[r]] = net.pos[mem].mean(axis=0)
    edges, wall_angles = [], {}
    for k, (u, v, kind) in enumerate(net.edges):
        a, b = new_id[find(u)], new_id[find(v)]
        if a == b:
            continue
        if kind == "wall":
            p0 = math.atan2(pos[a, 1], pos[a, 0]) % (2 * np.pi)
            p1 = math.atan2(pos[b, 1], pos[b, 0]) % (2 * np.pi)
            if p1 <= p0:
                p1 += 2 * np.pi
            wall_angles[len(edges)] = (p0, p1)
        edges.append((a, b, kind))
    return _Network(pos, is_wall, edges, wall_angles)


# ----------------------------------------------------------------------------- packs and counts
def _edge_ends(net: _Network):
    """Per node, its edge ends in counter-clockwise order of departure direction.

    Returns a list over nodes of lists of (edge, end, angle, kind)."""
    ends = [[] for _ in range(len(net.pos))]
    for k, (u, v, kind) in enumerate(net.edges):
        for end, (a, b) in enumerate(((u, v), (v, u))):
            if kind == "wall":
                phi = math.atan2(net.pos[a, 1], net.pos[a, 0])
                tang = np.array([-math.sin(phi), math.cos(phi)])  # ccw tangent
                d = tang if end == 0 else -tang
            else:
                d = net.pos[b] - net.pos[a]
            ends[a].append((k, end, math.atan2(d[1], d[0]), kind))
    return [sorted(e, key=lambda t: t[2]) for e in ends]


def _candidate_splits(node_ends, wall: bool):
    """Cyclically contiguous splits A | B of a node's edge ends (indices into node_ends)."""
    k = len(node_ends)
    cands = set()
    for start in range(k):
        for size in range(1, k):
            a = frozenset((start + i) % k for i in range(size))
            b = frozenset(range(k)) - a
            key = min(a, b, key=lambda s: sorted(s))
            if wall:
                kinds_a = [node_ends[i][3] for i in a]
                kinds_b = [node_ends[i][3] for i in b]
                if kinds_a.count("wall") != 1 or kinds_b.count("wall") != 1:
                    continue
            cands.add(frozenset([key, frozenset(range(k)) - key]))
    out = []
    for c in cands:
        a, b = sorted(c, key=lambda s: (len(s), sorted(s)))
        out.append((sorted(a), sorted(b)))
    return sorted(out)


def _solve_counts(rng, net, ends, caps, mean_layers, time_limit=60.0):
    """Integer layer counts with exact pack conservation (mixed-integer program).

    Returns (n per edge, chosen split per node) or (None, None) when infeasible."""
    from scipy.optimize import Bounds, LinearConstraint

    from crosssection.core.quiet import milp

    E = len(net.edges)
    splits = [_candidate_splits(ends[v], bool(net.is_wall[v])) for v in range(len(net.pos))]
    nz = sum(len(s) for s in splits)
    # variables: n (E), d (E) = |n - target|, z (nz)
    target = np.minimum(caps, 1 + np.floor(rng.exponential(max(mean_layers - 1, 0.3), E)))
    nvar = 2 * E + nz
    c = np.zeros(nvar)
    c[E:2 * E] = 1.0 + rng.uniform(0, 0.1, E)
    rows, lo, hi = [], [], []
    M = 3 * caps.max() + 4

    def row():
        return np.zeros(nvar)

    for e in range(E):  # d >= n - t, d >= t - n
        r = row(); r[2 * E - E + e] = 1; r[e] = -1; rows.append(r); lo.append(-target[e]); hi.append(np.inf)
        r = row(); r[E + e] = 1; r[e] = 1; rows.append(r); lo.append(target[e]); hi.append(np.inf)
    zi = 2 * E
    for v in range(len(net.pos)):
        if not splits[v]:
            return None, None
        r = row()
        for j in range(len(splits[v])):
            r[zi + j] = 1
        rows.append(r); lo.append(1); hi.append(1)
        for j, (A, B) in enumerate(splits[v]):
            r = row()
            for i in A:
                r[ends[v][i][0]] += 1
            for i in B:
                r[ends[v][i][0]] -= 1
            # sum_A - sum_B = 0 if z else free within +-M
            r1 = r.copy(); r1[zi + j] = M; rows.append(r1); lo.append(-np.inf); hi.append(M)
            r2 = r.copy(); r2[zi + j] = -M; rows.append(r2); lo.append(-M); hi.append(np.inf)
        zi += len(splits[v])
    A = np.array(rows)
    lb = np.concatenate([np.ones(E), np.zeros(E), np.zeros(nz)])
    ub = np.concatenate([caps.astype(float), np.full(E, np.inf), np.ones(nz)])
    integrality = np.concatenate([np.ones(E), np.zeros(E), np.ones(nz)])
    res = milp(c, constraints=LinearConstraint(A, lo, hi), bounds=Bounds(lb, ub),
               integrality=integrality, options={"time_limit": time_limit, "disp": False, "mip_rel_gap": 0.25,
                        "node_limit": 500})  # node limit, not time, decides: deterministic
    if res.x is None:
        return None, None
    x = res.x
    n = np.rint(x[:E]).astype(int)
    chosen = []
    zi = 2 * E
    for v in range(len(net.pos)):
        j = int(np.argmax(x[zi:zi + len(splits[v])]))
        chosen.append(splits[v][j])
        zi += len(splits[v])
    # exact check of conservation (the MILP tolerance must not leak into the truth)
    for v in range(len(net.pos)):
        A_, B_ = chosen[v]
        if sum(n[ends[v][i][0]] for i in A_) != sum(n[ends[v][i][0]] for i in B_):
            return None, None
    return n, chosen


# ----------------------------------------------------------------------------- geometry
def _rot(d, ang):
    c, s = math.cos(ang), math.sin(ang)
    return np.array([c * d[0] - s * d[1], s * d[0] + c * d[1]])


def _departures(net, ends, chosen, fan_deg=60.0, wall_deg=55.0):
    """Unit departure direction of every edge end: dict (edge, end) -> (dx, dy)."""
    dep = {}
    fan = math.radians(fan_deg)
    for v in range(len(net.pos)):
        A, B = chosen[v]
        e = ends[v]
        if net.is_wall[v]:
            # t along the wall, pointing toward pack B's wall stack
            wb = [i for i in B if e[i][3] == "wall"][0]
            wa = [i for i in A if e[i][3] == "wall"][0]
            for pack, wi in ((A, wa), (B, wb)):
                ang0 = e[wi][2]
                t = np.array([math.cos(ang0), math.sin(ang0)])
                inward = -net.pos[v] / np.hypot(*net.pos[v])
                sgn = 1.0 if (t[0] * inward[1] - t[1] * inward[0]) > 0 else -1.0
                others = [i for i in pack if i != wi]
                # fan the interior stacks inward, ordered by their chord angle from t
                others.sort(key=lambda i: abs(_angdiff(e[i][2], ang0)))
                dep[(e[wi][0], e[wi][1])] = t
                for rank, i in enumerate(others):
                    dep[(e[i][0], e[i][1])] = _rot(t, sgn * math.radians(wall_deg + 30.0 * rank))
            continue
        ua = sum(np.array([math.cos(e[i][2]), math.sin(e[i][2])]) for i in A)
        ub = sum(np.array([math.cos(e[i][2]), math.sin(e[i][2])]) for i in B)
        t = ub - ua
        t = t / max(np.hypot(*t), 1e-12)
        for pack, axis in ((B, t), (A, -t)):
            ax_ang = math.atan2(axis[1], axis[0])
            members = sorted(pack, key=lambda i: _angdiff(e[i][2], ax_ang))
            m = len(members)
            for rank, i in enumerate(members):
                off = (rank - (m - 1) / 2) * fan
                dep[(e[i][0], e[i][1])] = _rot(axis, off)
    return dep


def _angdiff(a, b):
    return (a - b + math.pi) % (2 * math.pi) - math.pi


def _bezier(p0, d0, p3, d3, n_pts):
    """Cubic Bezier leaving p0 along d0 and arriving at p3 from direction -d3 (d3 = departure
    at p3). Returns points, first and second derivatives, parameter step."""
    L = float(np.hypot(*(p3 - p0)))
    arm = 0.36 * L
    p1, p2 = p0 + arm * d0, p3 + arm * d3
    t = np.linspace(0, 1, n_pts)[:, None]
    pts = ((1 - t) ** 3) * p0 + 3 * ((1 - t) ** 2) * t * p1 + 3 * (1 - t) * t ** 2 * p2 + t ** 3 * p3
    d1 = 3 * (1 - t) ** 2 * (p1 - p0) + 6 * (1 - t) * t * (p2 - p1) + 3 * t ** 2 * (p3 - p2)
    d2 = 6 * (1 - t) * (p2 - 2 * p1 + p0) + 6 * t * (p3 - 2 * p2 + p1)
    return pts, d1, d2


@dataclass
class _Stack:
    xy: np.ndarray        # (P, 2) centreline (x, y) px, hole centre at origin
    s_px: np.ndarray      # arc length at each point
    kappa_px: np.ndarray  # signed curvature 1/px at each point
    width_px: float
    n: int


def _stack_geometry(net, k, dep, width_px, n):
    u, v, kind = net.edges[k]
    if kind == "wall":
        p0, p1 = net.wall_angles[k]
        rad = math.hypot(*net.pos[u]) - width_px / 2
        m = max(8, int((p1 - p0) * rad / 1.0))
        phi = np.linspace(p0, p1, m)
        xy = np.column_stack([rad * np.cos(phi), rad * np.sin(phi)])
        s = (phi - p0) * rad
        kap = np.full(m, 1.0 / rad)  # ccw arc: positive curvature
        return _Stack(xy, s, kap, width_px, n)
    p0, p3 = net.pos[u], net.pos[v]
    m = max(16, int(np.hypot(*(p3 - p0)) * 1.5))
    pts, d1, d2 = _bezier(p0, dep[(k, 0)], p3, dep[(k, 1)], m)
    speed = np.hypot(d1[:, 0], d1[:, 1])
    kap = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.maximum(speed, 1e-9) ** 3
    seg = np.hypot(*np.diff(pts, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return _Stack(pts, s, kap, width_px, n)


# ----------------------------------------------------------------------------- rendering
def _draw_band(img, xy, width_px, centre, ss, value=255):
    pts = np.round((xy + centre) * ss * 16).astype(np.int32)  # 4 fractional bits
    thick = max(1, int(round(width_px * ss)))
    cv2.polylines(img, [pts.reshape(-1, 1, 2)], False, value, thickness=thick,
                  lineType=cv2.LINE_8, shift=4)


def _render_masks(stacks, shape, centre, ss):
    """Per-stack 4x masks are not stored; returns the 4x union mask and a 4x label image."""
    H, W = shape
    union = np.zeros((H * ss, W * ss), np.uint8)
    labels = np.zeros((H * ss, W * ss), np.int32)
    for k, st in enumerate(stacks):
        _draw_band(union, st.xy, st.width_px, centre, ss)
        _draw_band(labels, st.xy, st.width_px, centre, ss, value=k + 1)
    return union, labels


def _check_gaps(stacks, net, shape, centre, gap_px, node_xy):
    """Indices of pairs of stacks closer than ``gap_px`` away from a shared junction.

    Each band is drawn widened by the gap; overlaps of two widened bands outside the discs
    around the junctions (radius = widest stack there + 2 gaps) are contacts. The disc also
    suffices for 30-45 degree fans (``make_scene(fan_deg=...)``): the branches of a fork are
    narrower than its trunk, the widest band there, and part by 2h within it (measured: a disc
    widened by sin(30 deg) / sin(fan / 2) accepts no other layout of the typical and thick
    dense scenes of ``benchmarks/robust_sweep.py``, seeds 100-107 and 100-103)."""
    H, W = shape
    count = np.zeros((H, W), np.uint8)
    one = np.zeros((H, W), np.uint8)
    for st in stacks:
        one[:] = 0
        _draw_band(one, st.xy, st.width_px + gap_px, centre, 1, value=1)
        count += one
    excl = np.zeros((H, W), np.uint8)
    node_w = {}
    for k, (u, v, _) in enumerate(net.edges):
        for a in (u, v):
            node_w[a] = max(node_w.get(a, 0.0), stacks[k].width_px)
    for a, w in node_w.items():
        c = node_xy[a] + centre
        cv2.circle(excl, (int(round(c[0])), int(round(c[1]))), int(math.ceil(1.3 * w + 2 * gap_px + 2)), 1, -1)
    bad = (count >= 2) & (excl == 0)
    return int(bad.sum())


# ----------------------------------------------------------------------------- layout
@dataclass(frozen=True)
class _Layout:
    """A valid drawing: network, packs, stack geometry, hole."""

    net: _Network
    ends: list               # per node, its edge ends (see _edge_ends)
    chosen: list             # per node, the chosen pack split (A, B) of its edge ends
    stacks: list             # _Stack per edge
    node_xy: np.ndarray      # (V, 2) junction positions (x, y) px, hole centre at the origin
    centre: np.ndarray       # hole centre (x, y) in image px
    shape: tuple             # (H, W) of the image
    radius_px: float


#: Largest scene generated, in pixels (10 000 x 10 000; the typical scenes are 1000-2500 px a
#: side).
MAX_SCENE_PX = 10_000 * 10_000


def _initial_radius_px(*, n_cells, image_size, hole_radius_mm, px_per_mm, w_max_px):
    """Hole radius: given, from the image size, or room for the widest bands plus voids."""
    if hole_radius_mm is not None:
        return hole_radius_mm * px_per_mm
    if image_size is not None:
        return 0.45 * image_size
    # cell spacing: room for the widest bands plus a void >= a few s_min
    spacing = max(2.4 * px_per_mm, 2.5 * w_max_px + 1.4 * px_per_mm)
    return spacing * math.sqrt(n_cells / math.pi)


def _stack_caps(net, radius_px, spacing, widths_table_px, max_layers):
    """Largest layer count per edge: a band must fit its own length, its neighbours' lengths
    and its faces."""
    lengths = np.array([(radius_px * (net.wall_angles[k][1] - net.wall_angles[k][0]))
                        if kind == "wall" else float(np.hypot(*(net.pos[u] - net.pos[v])))
                        for k, (u, v, kind) in enumerate(net.edges)])
    min_adj = np.full(len(net.pos), np.inf)
    for k, (u, v, _) in enumerate(net.edges):
        min_adj[u] = min(min_adj[u], lengths[k])
        min_adj[v] = min(min_adj[v], lengths[k])
    caps = np.empty(len(net.edges), int)
    for k, (u, v, _) in enumerate(net.edges):
        room = min(lengths[k], min_adj[u], min_adj[v]) / 2.2
        room = min(room, 0.22 * spacing)
        caps[k] = max(1, int(np.searchsorted(widths_table_px, room, side="right")))
    return np.minimum(caps, max_layers)


def _place_stacks(net, ends, chosen, n, widths_px, radius_px, fan_deg=60.0):
    """Centrelines of all stacks and the junction positions they end at."""
    dep = _departures(net, ends, chosen, fan_deg=fan_deg)
    # wall junctions sit half the widest wall band inside the wall
    node_xy = net.pos.copy()
    for v in np.flatnonzero(net.is_wall):
        ww = max(widths_px[e[0]] for e in ends[v] if e[3] == "wall")
        node_xy[v] = net.pos[v] * (radius_px - ww / 2) / radius_px
    geo_net = _Network(node_xy, net.is_wall, net.edges, net.wall_angles)
    stacks = []
    for k in range(len(net.edges)):
        st = _stack_geometry(geo_net if net.edges[k][2] == "ridge" else net, k, dep,
                             float(widths_px[k]), int(n[k]))
        if net.edges[k][2] == "wall":
            # join the arc to the junction nodes (radial offsets of at most (w_T - w)/2)
            u, v, _ = net.edges[k]
            xy = np.vstack([node_xy[u], st.xy, node_xy[v]])
            seg = np.hypot(*np.diff(xy, axis=0).T)
            s = np.concatenate([[0.0], np.cumsum(seg)])
            kap = np.concatenate([[st.kappa_px[0]], st.kappa_px, [st.kappa_px[-1]]])
            st = _Stack(xy, s, kap, st.width_px, st.n)
        stacks.append(st)
    return stacks, node_xy


def _attempt_layout(rng, *, n_cells, radius_px, image_size, max_layers, mean_layers, cal,
                    px_per_mm, gap_px, fan_deg=60.0, scatter=(0.0, None)):
    """One layout try: a :class:`_Layout`, or the reason (str) it was rejected."""
    size = image_size or int(math.ceil(2 * radius_px / 0.9))
    shape = (size, size)
    centre = np.array([size / 2.0, size / 2.0]) + rng.uniform(-0.02, 0.02, 2) * size * (image_size is None)
    centre = np.minimum(np.maximum(centre, radius_px + 2), size - radius_px - 2)
    spacing = radius_px * math.sqrt(math.pi / n_cells)
    min_edge = max(0.6 * px_per_mm, 0.18 * spacing)
    net = _voronoi_network(rng, n_cells, radius_px, min_edge)
    net = _contract_short(net, radius_px, min_edge)
    ends = _edge_ends(net)
    deg = np.array([len(e) for e in ends])
    if deg.max() > 4 or deg.min() < 3:
        return "degree"
    if (deg == 4).mean() > 0.06:
        return "too many degree-4"
    widths_table_px = cal.width(np.arange(1, max_layers + 1)) * px_per_mm
    caps = _stack_caps(net, radius_px, spacing, widths_table_px, max_layers)
    n, chosen = _solve_counts(rng, net, ends, caps, mean_layers)
    if n is None:
        return "counts infeasible"
    widths_px = cal.width(n) * px_per_mm
    if scatter[0] > 0:
        widths_px = widths_px * (1.0 + scatter[0] * np.clip(
            scatter[1].standard_normal(len(widths_px)), -2.5, 2.5))
    stacks, node_xy = _place_stacks(net, ends, chosen, n, widths_px, radius_px,
                                    fan_deg=fan_deg)
    out = max(float(np.max(np.hypot(st.xy[:, 0], st.xy[:, 1]) + st.width_px / 2 - radius_px))
              for st in stacks)
    if out > 1.0:
        return "band outside hole"
    nbad = _check_gaps(stacks, net, shape, centre, gap_px, node_xy)
    if nbad > 0:
        return f"contacts ({nbad} px)"
    return _Layout(net, ends, chosen, stacks, node_xy, centre, shape, float(radius_px))


# ----------------------------------------------------------------------------- truth
def _branch_rows(st, k, region, length_mm, rod_length_mm, px_per_mm, kappa_c_per_mm):
    """The ``st.n`` identical branch rows of stack ``k`` (curvature of the analytic curve)."""
    # curvature 1/mm of the curve as drawn in image coordinates (x right, y down): the sign is
    # flipped for (row, col) users, whence the comparisons in absolute value
    kap = st.kappa_px * px_per_mm
    s = st.s_px / px_per_mm
    ell = s[-1]
    kpm = float(np.trapezoid(kap, s) / ell)
    kplus = float(np.trapezoid(np.abs(kap), s) / ell)
    if kappa_c_per_mm is None:
        integrand = kap ** 2
    else:
        a = np.abs(kap)
        integrand = np.where(a > kappa_c_per_mm, kappa_c_per_mm * (2 * a - kappa_c_per_mm), a ** 2)
    e = rod_length_mm * float(np.trapezoid(integrand, s))
    return [{"stack_id": k, "length_mm": length_mm, "kappa_pm": kpm, "kappa_plus": kplus,
             "kappa_m": abs(kpm), "energy": e, "region": region}] * st.n


def _truth_tables(layout, paths_rc, union4, labels4, *, px_per_mm, thickness_mm, s_min_mm2,
                  kappa_c_per_mm):
    """Truth summary and tables of a layout; also the count of enclosed background regions
    smaller than s_min (a valid layout has none)."""
    net, stacks = layout.net, layout.stacks
    deg = np.zeros(len(net.pos), int)
    for u, v, _ in net.edges:
        deg[u] += 1
        deg[v] += 1
    # junctions: every node (wall nodes included: they are junctions of the network)
    junctions = pd.DataFrame({"junction_id": np.arange(len(net.pos)),
                              "x_px": layout.node_xy[:, 0] + layout.centre[0],
                              "y_px": layout.node_xy[:, 1] + layout.centre[1],
                              "n_stacks": deg, "wall": net.is_wall})
    lengths = np.array([polyline.length(p) for p in paths_rc]) / px_per_mm
    ns = np.array([st.n for st in stacks])
    rod_length_mm = float((lengths * ns).sum())
    rows, brows = [], []
    for k, ((u, v, kind), st) in enumerate(zip(net.edges, stacks)):
        mid_rc = polyline.mid_point(paths_rc[k])
        region = "periphery" if (net.is_wall[u] or net.is_wall[v]) else "bulk"
        rows.append({"stack_id": k, "junction_a": u, "junction_b": v, "length_mm": lengths[k],
                     "width_mm": st.width_px / px_per_mm, "n_br": st.n, "region": region,
                     "mid_x_px": mid_rc[1], "mid_y_px": mid_rc[0], "wall": kind == "wall"})
        brows += _branch_rows(st, k, region, lengths[k], rod_length_mm, px_per_mm, kappa_c_per_mm)
    branches = pd.DataFrame(brows)
    branches.insert(0, "branch_id", np.arange(len(branches)))
    voids = truth_voids(union4, supersample=SUPERSAMPLE, hole_center_xy=layout.centre,
                        hole_radius_px=layout.radius_px, s_min_px=s_min_mm2 * px_per_mm ** 2,
                        px_per_mm=px_per_mm, stack_labels=labels4,
                        stack_ends=[(u, v) for u, v, _ in net.edges],
                        stack_widths_px=[st.width_px for st in stacks],
                        min_contact_px=2 * thickness_mm * px_per_mm)
    summary = {
        "n_junctions": int(len(junctions)),
        "n_stacks": int(len(rows)),
        "n_branches": int(len(branches)),
        "n_voids": int(len(voids.table)),
        "mean_branches_per_stack": float(ns.mean()) if len(ns) else 0.0,
        "rod_length_mm": rod_length_mm,
        "epsilon": rod_length_mm / (2 * math.pi * layout.radius_px / px_per_mm),
        "total_energy": float(branches["energy"].sum()) if len(branches) else 0.0,
        "hole": {"center_x_px": float(layout.centre[0]), "center_y_px": float(layout.centre[1]),
                 "radius_px": float(layout.radius_px)},
        "timings_s": {},
        "n_degree4": int((deg == 4).sum()),
        "n_wall_junctions": int(net.is_wall.sum()),
        "n_small_background": int(voids.n_small),
    }
    tables = {"junctions": junctions, "stacks": pd.DataFrame(rows), "branches": branches,
              "voids": voids.table}
    return summary, tables


def _void_problem(layout, summary, tables, s_min_mm2):
    """Why the voids disagree with the network's faces (None when they agree)."""
    net = layout.net
    n_faces = len(net.edges) - len(net.pos) + 1  # Euler, connected planar graph, no outer face
    voids = tables["voids"]
    small_voids = int((voids["area_mm2"] < 1.5 * s_min_mm2).sum()) if len(voids) else 0
    if summary["n_voids"] != n_faces or small_voids or summary["n_small_background"]:
        return (f"voids {summary['n_voids']} vs faces {n_faces}, small {small_voids}"
                f"+{summary['n_small_background']}")
    return None


# ----------------------------------------------------------------------------- colour
def _receding_surfaces(img, rng, voids, receding_fraction, px_per_mm):
    """Light grey-blue patches seen through a fraction of the voids."""
    for _, v in voids.iterrows():
        if rng.uniform() > receding_fraction:
            continue
        col = ink.receding_rgb(rng)
        r = math.sqrt(v["area_mm2"]) * 0.5 * px_per_mm * rng.uniform(0.4, 0.9)
        ax = (int(r * rng.uniform(0.6, 1.2)), int(r * rng.uniform(0.6, 1.2)))
        cv2.ellipse(img, (int(v["centroid_x_px"]), int(v["centroid_y_px"])), ax,
                    float(rng.uniform(0, 180)), 0, 360, tuple(float(c) for c in col), -1, cv2.LINE_AA)


def _draw_scan(rng, layout, union4, labels4, voids, *, px_per_mm, smears, specks, pinholes,
               receding_fraction):
    """The noise-free float32 scan: paper, receding surfaces, smears, ink, specks, pinholes."""
    ss = SUPERSAMPLE
    H, W = layout.shape
    coverage = cv2.resize(union4.astype(np.float32) / 255.0, (W, H), interpolation=cv2.INTER_AREA)
    # every pixel takes the shade of the stack under its centre sample
    labels = labels4[ss // 2::ss, ss // 2::ss]
    background = cv2.resize(union4, (W, H), interpolation=cv2.INTER_AREA) == 0
    img = np.empty((H, W, 3), np.float32)
    img[:] = ink.paper_rgb(rng)
    _receding_surfaces(img, rng, voids, receding_fraction, px_per_mm)
    degrade.add_smears(img, rng, count=smears, centre_xy=layout.centre, radius_px=layout.radius_px)
    # one ink per scan within the design range, each stack within +-4 of it
    base = ink.ink_rgb(rng)
    shades = base + rng.uniform(-4, 4, (len(layout.stacks) + 1, 3))
    a = coverage[..., None]
    img = img * (1 - a) + shades[labels].astype(np.float32) * a
    degrade.add_specks(img, rng, count=specks, background=background, ink_rgb=base)
    degrade.add_pinholes(img, rng, count=pinholes,
                         paths_xy=[st.xy + layout.centre for st in layout.stacks],
                         widths_px=[st.width_px for st in layout.stacks])
    return img


# ----------------------------------------------------------------------------- public API
def make_scene(*, seed: int, n_stacks: int = 40, max_layers: int = 6, px_per_mm: float = 50.0,
               thickness_mm: float = 0.1, calibration: Calibration | None = None,
               hole_radius_mm: float | None = None,
               noise_sigma: float = 0.0, blur_px: float = 0.0, jpeg_quality: int | None = None,
               smears: int = 0, specks: int = 0, pinholes: int = 0,
               image_size: int | None = None, mean_layers: float | None = None,
               receding_fraction: float = 0.3, kappa_c_per_mm: float | None = None,
               fan_deg: float = 60.0, width_scatter: float = 0.0,
               max_tries: int = 40) -> Scene:
    """Generate a synthetic cross-section scan with exact truth.

    Parameters
    ----------
    seed : int
        Seed of every random choice (same seed, same scene).
    n_stacks : int
        Approximate number of stacks (20-300 is the tested range; the realised number depends on
        the Voronoi tiling and is in ``summary['n_stacks']``).
    max_layers : int
        Largest number of layers (branches) in a stack, 2-12 tested (with 1, no junction
        of three stacks conserves its layers: the counts are infeasible).
    px_per_mm, thickness_mm : float
        Scan resolution and sheet thickness h.
    calibration : Calibration, optional
        Width law of the bands; default :meth:`Calibration.nonlinear` ``h (n + 0.4 sqrt(n))``.
    hole_radius_mm : float, optional
        Hole radius; by default chosen from ``n_stacks`` and ``max_layers`` so that bands fit
        (or from ``image_size``).
    noise_sigma : float
        Standard deviation of additive Gaussian noise (uint8 units).
    blur_px : float
        Gaussian blur sigma in pixels.
    jpeg_quality : int, optional
        Round trip through JPEG at this quality.
    smears, specks, pinholes : int
        Numbers of light-blue smears, dark-blue specks (< s_min) and pinholes in the ink
        (:mod:`crosssection.truth.degrade`).
    image_size : int, optional
        Side of the square image; the hole fills 90 % of it.
    mean_layers : float, optional
        Mean of the exponential layer-count target (default ``max(1.5, max_layers / 3)``).
    receding_fraction : float
        Fraction of voids showing a light grey-blue receding surface.
    kappa_c_per_mm : float, optional
        Plastic threshold used in the truth energies (paper, "Expression of energy").
    fan_deg : float
        Angle in degrees between neighbouring members of a pack leaving an interior junction
        (0 < fan_deg <= 90). The default 60 opens the forks quickly; 30-35 gives the tangential
        forks of real scans, where two branches leave side by side and stay merged longer.
        Wall junctions keep their own fan.
    width_scatter : float
        Relative scatter of each stack's drawn width about the calibration's (a normal
        deviate clipped at 2.5 sigma, drawn apart from the scene's other draws: 0 draws
        nothing, and the scene is the one drawn without it). A cut's melted rim varies from
        stack to stack; the scene's calibration stays the mean law.
    max_tries : int
        Layouts tried before giving up.

    Returns
    -------
    Scene
        With ``paths_rc`` and ``packs``; ``params["options"]`` holds the generator options.

    Raises
    ------
    ParameterError
        An option outside its range (a degradation, ``fan_deg``, ``width_scatter``, a scene
        too large to draw).
    SceneGenerationError
        When no valid layout is found.
    """
    if calibration is not None and not isinstance(calibration, Calibration):
        raise ParameterError(f"calibration must be a Calibration, got {type(calibration).__name__}")
    if not 0.0 < fan_deg <= 90.0:
        raise ParameterError(f"fan_deg must be in (0, 90], got {fan_deg}")
    if not 0.0 <= width_scatter <= 0.3:
        raise ParameterError(f"width_scatter must be in [0, 0.3], got {width_scatter}")
    degrade.check_degradations(blur_px=blur_px, noise_sigma=noise_sigma,
                               jpeg_quality=jpeg_quality, smears=smears, specks=specks,
                               pinholes=pinholes)
    rng = np.random.default_rng(seed)
    scatter = (width_scatter, np.random.default_rng((seed, 1)))
    cal = calibration or Calibration.nonlinear(thickness_mm, n_max=max(40, max_layers + 5))
    s_min_mm2 = (10 * thickness_mm) ** 2
    n_cells = max(3, int(round(n_stacks / 3.0)))
    if mean_layers is None:
        mean_layers = max(1.5, max_layers / 3.0)
    radius_px = _initial_radius_px(n_cells=n_cells, image_size=image_size,
                                   hole_radius_mm=hole_radius_mm, px_per_mm=px_per_mm,
                                   w_max_px=float(cal.width(max_layers)) * px_per_mm)
    side = image_size or 2 * radius_px / 0.9
    if side * side > MAX_SCENE_PX:
        # the drawing holds several float images of the scene: refuse before allocating them
        raise ParameterError(f"the scene would be about {side:.0f} x {side:.0f} px (> "
                             f"{math.isqrt(MAX_SCENE_PX)} px a side) at {px_per_mm:g} px/mm: "
                             "lower px_per_mm, n_stacks, image_size or hole_radius_mm")
    fixed_radius = image_size is not None or hole_radius_mm is not None
    failures = []
    for attempt in range(max_tries):
        if attempt and attempt % 4 == 0 and not fixed_radius:
            radius_px *= 1.05
        layout = _attempt_layout(rng, n_cells=n_cells, radius_px=radius_px,
                                 image_size=image_size, max_layers=max_layers,
                                 mean_layers=mean_layers, cal=cal, px_per_mm=px_per_mm,
                                 gap_px=2 * thickness_mm * px_per_mm, fan_deg=fan_deg,
                                 scatter=scatter)
        if isinstance(layout, str):
            failures.append(layout)
            continue
        union4, labels4 = _render_masks(layout.stacks, layout.shape, layout.centre, SUPERSAMPLE)
        paths_rc = [st.xy[:, ::-1] + layout.centre[::-1] for st in layout.stacks]
        summary, tables = _truth_tables(layout, paths_rc, union4, labels4, px_per_mm=px_per_mm,
                                        thickness_mm=thickness_mm, s_min_mm2=s_min_mm2,
                                        kappa_c_per_mm=kappa_c_per_mm)
        problem = _void_problem(layout, summary, tables, s_min_mm2)
        if problem is None:
            break
        failures.append(problem)
    else:
        raise SceneGenerationError(f"no valid layout after {max_tries} tries: {failures[-5:]}")

    img = _draw_scan(rng, layout, union4, labels4, tables["voids"], px_per_mm=px_per_mm,
                     smears=smears, specks=specks, pinholes=pinholes,
                     receding_fraction=receding_fraction)
    rgb = degrade.finish_scan(img, rng, blur_px=blur_px, noise_sigma=noise_sigma,
                              jpeg_quality=jpeg_quality)
    params = {
        "px_per_mm": float(px_per_mm), "thickness_mm": float(thickness_mm),
        "hole_radius_mm": layout.radius_px / px_per_mm,
        "hole_center_px": [float(layout.centre[0]), float(layout.centre[1])],
        "seed": int(seed), "rod_length_mm": summary["rod_length_mm"],
        "generator": "crosssection.truth.network",
        "options": {"n_stacks": n_stacks, "max_layers": max_layers, "noise_sigma": noise_sigma,
                    "blur_px": blur_px, "jpeg_quality": jpeg_quality, "smears": smears,
                    "specks": specks, "pinholes": pinholes, "image_size": layout.shape[0],
                    "mean_layers": mean_layers, "kappa_c_per_mm": kappa_c_per_mm,
                    "fan_deg": fan_deg, "width_scatter": width_scatter,
                    "layout_attempts": len(failures) + 1},
    }
    ends = layout.ends
    packs = [([int(ends[v][i][0]) for i in A], [int(ends[v][i][0]) for i in B])
             for v, (A, B) in enumerate(layout.chosen)]
    return Scene(rgb, summary, tables, params, cal, paths_rc, packs)
