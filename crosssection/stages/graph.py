"""Stage 6: the stack graph. Nodes are junctions, edges are stacks with their pixel paths.

Paper, section "Image analysis procedure": "Two neighbouring junction points delimit a stack of
branches in close contact". A ``networkx.MultiGraph`` because parallel stacks (two stacks
between the same two junctions, around a void) and self-loops occur. Besides junctions, two
kinds of synthetic nodes keep every skeleton pixel in some stack:

- ``"end"``: a free end of the skeleton (a rod end, or a stack cut by the image);
- ``"loop"``: one node on a closed skeleton loop without any junction (its path starts and ends
  on that node's pixel).

Paths are traced in numba: every non-junction skeleton pixel has at most two neighbours, so a
stack is followed pixel by pixel from a junction pixel, a free end or a loop start.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import networkx as nx
import numpy as np
from numba import njit

from crosssection.core import polyline
from crosssection.core.errors import ParameterError
from crosssection.stages.junctions import (Junctions, find_junctions, fork_points,
                                           merge_junctions)
from crosssection.stages.skeleton import nonzero_rc

# node kinds of the traced paths (numba side)
_JUNCTION, _END, _LOOP = 0, 1, 2


@dataclass
class StackGraph:
    """The network of junctions (nodes) and stacks (edges).

    Attributes
    ----------
    graph : networkx.MultiGraph
        Nodes are int ids; every edge has key and attribute ``stack_id`` (0..M-1).
    node_rc : dict[int, ndarray]
        (row, col) float position of every node.
    node_kind : dict[int, str]
        ``"junction"`` (ids 0..K-1, the order of ``Junctions.centers_rc``), ``"end"`` or
        ``"loop"`` (ids >= K).
    paths : list of (P, 2) int arrays
        ``paths[stack_id]``: (row, col) skeleton pixels ordered from node u to node v. A path
        leaving a junction starts on the junction pixel it touches and ends on the junction
        pixel it reaches; a path from a free end starts on that end pixel; a closed loop
        starts and ends on its loop node's pixel.
    ends : list of (int, int)
        ``ends[stack_id] = (u, v)``, the nodes at path start and path end.
    length_px : (M,) float array
        Length of every stack along its path smoothed by a sliding average
        (:func:`crosssection.core.polyline.smooth`), from node position to node position.
    """

    graph: nx.MultiGraph
    node_rc: dict
    node_kind: dict
    paths: list
    ends: list
    length_px: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def n_junctions(self) -> int:
        return sum(1 for k in self.node_kind.values() if k == "junction")

    @property
    def n_stacks(self) -> int:
        return len(self.paths)

    def degree(self, node: int) -> int:
        """Number of stack ends at ``node`` (a self-loop counts twice)."""
        return int(self.graph.degree(node))


@njit(cache=True)
def _walk(f, lab, visited, p, prev, offs, out, n):  # pragma: no cover - numba
    """Follow the skeleton from flat pixel ``p`` (coming from ``prev``) until a junction or a
    free end, appending the pixels to ``out`` from position ``n``; return the (kind, id) of
    the node reached (a junction's label, or the flat index of the end pixel) and the new
    ``n``. Non-junction pixels have at most two neighbours: the next pixel is the first
    neighbour (clockwise from north) other than ``prev``."""
    while True:
        out[n] = p
        n += 1
        if lab[p] != 0:
            return _JUNCTION, lab[p] - 1, n
        visited[p] = 1
        nxt = -1
        for k in range(8):
            q = p + offs[k]
            if f[q] and q != prev:
                nxt = q
                break
        # a visited non-junction neighbour cannot happen on a clean skeleton: stop safely
        if nxt < 0 or (lab[nxt] == 0 and visited[nxt]):
            return _END, p, n
        prev = p
        p = nxt


@njit(cache=True)
def _trace(f, lab, offs, jp, sp, visited, out, path_offs, meta):  # pragma: no cover - numba
    """Trace all stacks of the flat padded skeleton ``f`` with padded junction labels ``lab``.

    ``jp``: junction pixels, ``sp``: all skeleton pixels in raster order (flat padded
    indices); ``offs``: the 8 neighbour offsets, clockwise from north. Writes the path
    pixels to ``out``, the path offsets to ``path_offs`` and per path (kind_u, id_u, kind_v,
    id_v) to ``meta`` (for end/loop nodes the id is the flat index of the node pixel; the
    caller numbers them); returns the number of paths. ``visited`` is a uint8 array like
    ``f``, zero on the skeleton. ``lab`` and ``visited`` are read and written on the pixels
    of ``sp`` and ``jp`` only (every neighbour is tested in ``f`` first), so the caller sets
    them there alone. Only loops and indexing on arrays the caller allocates, so that the kernel
    compiles quickly.
    """
    n = 0
    m = 0
    path_offs[0] = 0
    # 1. from every junction pixel, every unvisited non-junction neighbour starts a stack
    for i in range(jp.shape[0]):
        p0 = jp[i]
        for k in range(8):
            p = p0 + offs[k]
            if not f[p] or lab[p] != 0 or visited[p]:
                continue
            out[n] = p0
            n += 1
            kind_v, id_v, n = _walk(f, lab, visited, p, p0, offs, out, n)
            path_offs[m + 1] = n
            meta[m, 0] = _JUNCTION
            meta[m, 1] = lab[p0] - 1
            meta[m, 2] = kind_v
            meta[m, 3] = id_v
            m += 1
    # 2. junction-free segments, from a free end to the other
    for i0 in range(sp.shape[0]):
        p0 = sp[i0]
        if lab[p0] != 0 or visited[p0]:
            continue
        nb = 0
        for k in range(8):
            nb += f[p0 + offs[k]]
        if nb != 1:
            continue
        kind_v, id_v, n = _walk(f, lab, visited, p0, -1, offs, out, n)
        path_offs[m + 1] = n
        meta[m, 0] = _END
        meta[m, 1] = p0
        meta[m, 2] = kind_v
        meta[m, 3] = id_v
        m += 1
    # 3. closed loops without junction: every remaining pixel has two neighbours
    for i0 in range(sp.shape[0]):
        p0 = sp[i0]
        if lab[p0] != 0 or visited[p0]:
            continue
        nb = 0
        for k in range(8):
            nb += f[p0 + offs[k]]
        if nb == 0:
            visited[p0] = 1  # isolated pixel: no stack
            continue
        p = p0
        prev = -1
        while True:
            out[n] = p
            n += 1
            visited[p] = 1
            nxt = -1
            for k in range(8):
                q = p + offs[k]
                if f[q] and q != prev:
                    nxt = q
                    break
            if nxt < 0:
                break
            if nxt == p0:
                out[n] = p0
                n += 1
                break
            if visited[nxt]:
                break
            prev = p
            p = nxt
        path_offs[m + 1] = n
        meta[m, 0] = _LOOP
        meta[m, 1] = p0
        meta[m, 2] = _LOOP
        meta[m, 3] = p0
        m += 1
    return m


def path_length_px(points, *, window_px: int = 5, closed: bool = False) -> float:
    """Length of a pixel path after :func:`crosssection.core.polyline.smooth`.

    The raw 8-connected chain overestimates the length of oblique lines (by 8 % at 22.5 deg);
    the sliding average removes the staircase (measured error < 1 % on straight lines at all
    angles and on circles of radius >= 20 px; see tests).
    """
    return polyline.length(polyline.smooth(points, window_px=window_px, closed=closed),
                           closed=closed)


def _stack_lengths(rc, offs, u_rc, v_rc, is_loop, window_px) -> np.ndarray:
    """Smoothed lengths of all stacks (:func:`path_length_px`, one compiled pass): open paths
    run from node position to node position, loops are closed periodically.

    ``rc[offs[i]:offs[i + 1]]`` is the path of stack ``i``; the node positions are inserted
    around the open paths by one scatter (a stack of ``np.vstack`` per path took 5 ms for
    the 400 stacks of a 2000x2000 scan).
    """
    n = np.diff(offs)
    is_open = ~np.asarray(is_loop, dtype=bool)
    starts = np.zeros(len(n) + 1, np.int64)
    np.cumsum(n + 2 * is_open, out=starts[1:])
    pts = np.empty((int(starts[-1]), 2))
    pts[np.arange(len(rc)) + np.repeat(starts[:-1] + is_open - offs[:-1], n)] = rc
    pts[starts[:-1][is_open]] = u_rc[is_open]
    pts[starts[1:][is_open] - 1] = v_rc[is_open]
    return polyline.smoothed_lengths(pts, starts, is_loop, window_px=window_px)


def _padded(skel):
    """What every tracing of the same skeleton reads: the skeleton padded by one background
    pixel (uint8), its pixels' rows and columns in the padded image (raster order), and the
    tracing's label and visited arrays (see :func:`_build_stack_graph`), allocated once."""
    h, w = skel.shape
    img = np.zeros((h + 2, w + 2), np.uint8)
    img[1:-1, 1:-1] = skel
    sr, sc = nonzero_rc(img)
    return img, sr, sc, np.empty(img.size, np.int64), np.empty(img.size, np.uint8)


def build_stack_graph(skel, junctions: Junctions, *, smooth_px: int = 5) -> StackGraph:
    """Trace the skeleton into a MultiGraph of junctions and stacks.

    Parameters
    ----------
    skel : (H, W) bool array
        One-pixel skeleton (:func:`crosssection.stages.skeleton.skeletonize_mask`).
    junctions : Junctions
        From :func:`crosssection.stages.junctions.find_junctions` on the same skeleton.
    smooth_px : int, optional
        Sliding-average window used for ``length_px``.

    Returns
    -------
    StackGraph
        Stacks numbered in tracing order: first those leaving junctions (junction order),
        then junction-free segments, then junction-free closed loops (raster order).
    """
    skel = np.asarray(skel, dtype=bool)
    if skel.shape != junctions.label_image.shape:
        raise ParameterError(f"skeleton shape {skel.shape} differs from junction label "
                             f"image shape {junctions.label_image.shape}")
    return _build_stack_graph(_padded(skel), junctions, smooth_px)


def _build_stack_graph(padded, junctions: Junctions, smooth_px: int) -> StackGraph:
    """:func:`build_stack_graph` of a skeleton given as :func:`_padded` returns it."""
    img, sr, sc, labp, visited = padded
    wp = img.shape[1]
    sp = sr * wp + sc
    # the tracing reads the labels and the visited flags on skeleton and junction pixels
    # only (see _trace): both are set there alone, which spares zeroing 36 MB per tracing
    # (a 2000x2000 scan: 8 ms; large zeroed blocks come from the reused heap, not from
    # fresh pages), and lets the tracings of one skeleton share the arrays
    labp[sp] = junctions.label_image[sr - 1, sc - 1]
    visited[sp] = 0
    if junctions.pixels:
        jp = np.concatenate(junctions.pixels).astype(np.int64) + 1
    else:
        jp = np.zeros((0, 2), np.int64)
    jflat = jp[:, 0] * wp + jp[:, 1]
    labp[jflat] = junctions.label_image[jp[:, 0] - 1, jp[:, 1] - 1]  # where paths start
    # every pixel is walked once, except junction pixels, which start or end paths: a path
    # adds at most two of them (and a loop its closing pixel)
    cap_paths = 8 * len(jflat) + len(sp) + 1
    out = np.empty(len(sp) + 2 * cap_paths, np.int64)
    path_offs = np.empty(cap_paths + 1, np.int64)
    meta = np.empty((cap_paths, 4), np.int64)
    offs8 = np.array([-wp, -wp + 1, 1, wp + 1, wp, wp - 1, -1, -wp - 1], np.int64)
    m = _trace(img.reshape(-1), labp, offs8, jflat, sp, visited, out, path_offs, meta)
    offs = path_offs[:m + 1]
    pix = out[:offs[-1]]
    # all paths in one (N, 2) array, each stack's path a view of its rows
    rc = np.empty((len(pix), 2), np.int64)
    np.floor_divide(pix, wp, out=rc[:, 0])
    np.remainder(pix, wp, out=rc[:, 1])
    rc -= 1
    is_loop = meta[:m, 0] == _LOOP
    meta = meta[:m].tolist()
    k = len(junctions)
    g = nx.MultiGraph()
    node_rc: dict[int, np.ndarray] = {}
    node_kind: dict[int, str] = {}
    for j in range(k):
        g.add_node(j)
        node_rc[j] = np.asarray(junctions.centers_rc[j], dtype=float)
        node_kind[j] = "junction"
    pixel_node: dict[int, int] = {}

    def node_of(kind, ident):
        if kind == _JUNCTION:
            return int(ident)
        ident = int(ident)
        if ident not in pixel_node:
            nid = k + len(pixel_node)
            pixel_node[ident] = nid
            g.add_node(nid)
            node_rc[nid] = np.array([ident // wp - 1, ident % wp - 1], dtype=float)
            node_kind[nid] = "end" if kind == _END else "loop"
        return pixel_node[ident]

    ends = [(node_of(ku, iu), node_of(kv, iv)) for ku, iu, kv, iv in meta]
    g.add_edges_from((u, v, sid, {"stack_id": sid}) for sid, (u, v) in enumerate(ends))
    bounds = offs.tolist()
    paths = [rc[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    if m:
        u_rc = np.array([node_rc[u] for u, _ in ends])
        v_rc = np.array([node_rc[v] for _, v in ends])
        lengths = _stack_lengths(rc, offs, u_rc, v_rc, is_loop, int(smooth_px))
    else:
        lengths = np.zeros(0)
    return StackGraph(graph=g, node_rc=node_rc, node_kind=node_kind, paths=paths, ends=ends,
                      length_px=np.asarray(lengths, dtype=float))


def short_junction_links(sg: StackGraph, radius_px) -> list[int]:
    """Stacks joining two junctions whose inscribed ink disks overlap.

    A stack between junctions u and v (u may equal v) is a link to merge when its length is
    smaller than ``radius_px[u] + radius_px[v]``: both branch points lie in one ink blob, as
    when two thick stacks cross (the skeleton resolves an X into two Y joined by a short
    bridge). Junctions closer than that cannot be told apart from one of degree 4.

    Parameters
    ----------
    sg : StackGraph
    radius_px : array of float
        Per junction id, the distance to the background at the junction (distance transform).

    Returns
    -------
    list of int
        Stack ids to absorb into their junctions.
    """
    out = []
    for sid, (u, v) in enumerate(sg.ends):
        if sg.node_kind[u] != "junction" or sg.node_kind[v] != "junction":
            continue
        if sg.length_px[sid] < radius_px[u] + radius_px[v]:
            out.append(sid)
    return out


def stack_graph(skel, distance_px, *, merge_px: float = 2.0,
                merge_thick_crossings: bool = True, thickness_px: float | None = None):
    """Junctions and stack graph of a skeleton (stages 5-6), thick crossings merged.

    The skeleton of an X of thick stacks is two Y joined by a short bridge; junctions joined by
    a stack shorter than the sum of the inscribed ink radii at both ends are merged with that
    stack's pixels, so the crossing becomes one junction of degree 4.

    Parameters
    ----------
    skel : bool ndarray
        One-pixel skeleton.
    distance_px : ndarray
        Distance transform of the cleaned ink mask.
    merge_px : float
        Junction pixels closer than this are one junction.
    merge_thick_crossings : bool
        Merge junctions joined by a stack inside one ink blob.
    thickness_px : float, optional
        Sheet thickness h in px. When given, every junction is moved to where the centrelines
        of its stacks meet (:func:`crosssection.stages.junctions.fork_points`) instead of the
        skeleton's fork, which lies several h away inside thick blobs; ``length_px`` keeps
        the fork-to-fork lengths.

    Returns
    -------
    junctions : Junctions
    graph : StackGraph
    n_merged : int
        Number of bridging stacks merged into junctions.
    """
    junc = find_junctions(skel, merge_px=merge_px)
    padded = _padded(np.asarray(skel, dtype=bool))  # every tracing below reads it
    sg = _build_stack_graph(padded, junc, 5)
    merged = 0
    if merge_thick_crossings and len(junc):
        for _ in range(3):
            links = short_junction_links(sg, _junction_radius(junc, distance_px))
            if not links:
                break
            groups = [sg.ends[s] for s in links]
            junc = merge_junctions(junc, groups, [sg.paths[s] for s in links])
            sg = _build_stack_graph(padded, junc, 5)
            merged += len(links)
    if thickness_px is not None and len(junc):
        # lengths stay those between the skeleton's forks: the centreline intersection moves
        # a junction along some of its stacks and away from others, and the pixel paths
        # cannot be re-cut consistently inside the ink blob
        junc = _at_fork_points(junc, sg, distance_px, float(thickness_px))
        for j in range(len(junc)):
            sg.node_rc[j] = junc.centers_rc[j].copy()
    return junc, sg, merged


def _at_fork_points(junc: Junctions, sg: StackGraph, distance_px, thickness_px) -> Junctions:
    """``junc`` with its centres moved to the stacks' centreline intersections."""
    radius = _junction_radius(junc, distance_px)
    end_paths, end_junction = [], []
    for sid, (u, v) in enumerate(sg.ends):
        for node, path in ((u, sg.paths[sid]), (v, sg.paths[sid][::-1])):
            if sg.node_kind[node] == "junction":
                end_paths.append(path)
                end_junction.append(node)
    centers = fork_points(junc.centers_rc, radius, end_paths, end_junction,
                          thickness_px=thickness_px)
    return Junctions(centers_rc=centers, pixels=junc.pixels, label_image=junc.label_image)


def _junction_radius(junc: Junctions, distance_px) -> np.ndarray:
    """Per junction, the largest distance to the background over its pixels (float64)."""
    sizes = np.array([len(p) for p in junc.pixels], np.int64)
    if len(sizes) == 0 or sizes.min() == 0:
        return np.array([float(np.asarray(distance_px)[p[:, 0], p[:, 1]].max())
                         for p in junc.pixels])
    pix = np.concatenate(junc.pixels)
    vals = np.asarray(distance_px)[pix[:, 0], pix[:, 1]]
    starts = np.zeros(len(sizes), np.int64)
    np.cumsum(sizes[:-1], out=starts[1:])
    return np.maximum.reduceat(vals, starts).astype(np.float64)
