"""Stage 6: the stack graph. Nodes are junctions, edges are stacks with their pixel paths.

Paper, section "Image analysis procedure": "Two neighbouring junction points delimit a stack of
branches in close contact". A ``networkx.MultiGraph`` because parallel stacks (two stacks
between the same two junctions, around a void) and self-loops occur. Besides junctions, two
kinds of synthetic nodes keep every skeleton pixel in some stack:

- ``"end"``: a free end of the skeleton (a rod end, or a stack cut by the image);
- ``"loop"``: one node on a closed skeleton loop without any junction (its path starts and ends
  on that node's pixel);
- ``"step"``: where a stack's layer count steps along its path, some of its layers ending
  inside the band (added by :func:`split_stacks` once the widths are read).

Every non-junction skeleton pixel has at most two neighbours, so the non-junction pixels form
chains, each one stack: it is followed from a junction pixel, a free end or a loop start, all
chains at once by one depth-first traversal in scipy (see :func:`_trace`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import networkx as nx
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import depth_first_order

from crosssection.core import polyline
from crosssection.core.errors import ParameterError
from crosssection.params import _number
from crosssection.stages.junctions import (Junctions, fork_points, merge_junctions,
                                           padded_junctions)
from crosssection.stages.skeleton import nonzero_rc

# node kinds of the traced paths (see _trace)
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
        ``"junction"`` (ids 0..K-1, the order of ``Junctions.centers_rc``), ``"end"``,
        ``"loop"`` or ``"step"`` (ids >= K).
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


def _bit_tables():
    """Lookup tables over the 256 8-neighbourhood codes (bit k set: neighbour k, clockwise
    from north, is on the skeleton).

    Returns
    -------
    count, first, second : (256,) int arrays
        The number of neighbours; the first and the second neighbour clockwise from north
        (0 where there is none).
    top : (256,) bool array
        No neighbour comes before the pixel in raster order (none N, NE, W or NW).
    """
    codes = np.arange(256)
    bits = (codes[:, None] >> np.arange(8)) & 1
    count = bits.sum(axis=1)
    first = np.argmax(bits, axis=1)
    rest = bits.copy()
    rest[codes, first] = 0
    second = np.argmax(rest, axis=1)
    top = (codes & 0b11000011) == 0
    return count, first, second, top


_NB_COUNT, _NB_FIRST, _NB_SECOND, _NB_TOP = _bit_tables()


def _trace(sk: _Padded, sp_lab, jflat, j_lab):
    """Trace all stacks of a skeleton.

    Parameters
    ----------
    sk : _Padded
        The skeleton (:func:`_padded`).
    sp_lab : (P,) int array
        The junction label of every skeleton pixel (``sk.sp`` order): ``j + 1`` on the pixels
        of junction ``j``, else 0.
    jflat, j_lab : (J,) int64 arrays
        The junction pixels (flat padded indices) in the order of ``Junctions.pixels``, and
        their labels.

    Returns
    -------
    pix : (N,) int64 array
        The path pixels (flat padded indices), all paths one after the other.
    offs : (M + 1,) int64 array
        ``pix[offs[i]:offs[i + 1]]`` is path ``i``.
    meta : (M, 4) int64 array
        Per path (kind_u, id_u, kind_v, id_v): a junction's id, or for an end or loop node the
        flat index of its pixel (the caller numbers these nodes).

    Raises
    ------
    ParameterError
        If a pixel with three or more neighbours is in no junction, or the junction pixels
        are not the skeleton pixels the labels mark.

    Notes
    -----
    Every non-junction pixel has at most two skeleton neighbours, so the non-junction pixels
    form chains (open, or closed loops). The stacks, numbered in this order (that of the
    pixel-by-pixel walk this replaces), are:

    1. from every junction pixel (``jflat`` order), every non-junction neighbour of a chain
       not yet taken (clockwise from north) starts a stack: the junction pixel, the whole
       chain, and the junction pixel next to its last pixel (other than the one before it),
       or that last pixel as a free end;
    2. every chain left with free ends, from its first end in raster order to the other;
    3. every closed loop left, from its first pixel in raster order towards that pixel's
       first neighbour clockwise from north, and back to the first pixel.

    The chains are ordered by one depth-first traversal (``scipy.sparse.csgraph``, compiled)
    of the graph of the non-junction pixels, from a line of virtual nodes, one per start in
    the order above, each linked to its start pixel and to the next virtual node: a chain is
    walked whole from the first start that reaches it, and its other starts fall away.
    Vectorised over the pixels otherwise: on a dense 2000x2000 scan 2.9 ms per tracing (and
    0.9 ms once per skeleton in :func:`_padded`) against 1.2 ms for the compiled loop it
    replaces (and 1 ms per tracing to set that loop's label and visited arrays), with no JIT
    compilation at first use (3 s).
    """
    f, code, w = sk.img.reshape(-1), sk.code, sk.img.shape[1]
    offs8 = np.array([-w, -w + 1, 1, w + 1, w, w - 1, -1, -w - 1], np.int64)
    if (len(jflat) and (not f[jflat].all() or j_lab.min() <= 0)) \
            or np.count_nonzero(sp_lab) != len(np.unique(jflat)):
        raise ParameterError("the junctions do not match the skeleton: their pixels must be "
                             "the skeleton pixels their label image marks")
    free = sp_lab == 0
    npix = sk.sp[free]  # non-junction pixels, raster order
    n = len(npix)
    deg = _NB_COUNT[sk.bits[free]]
    if n and deg.max() > 2:
        raise ParameterError("the junctions do not match the skeleton: a pixel with more than "
                             "two neighbours is in no junction")
    # code: the junction label on junction pixels, -1 - i on non-junction pixel i
    code[sk.sp] = np.where(free, -np.cumsum(free), sp_lab)
    # the (at most two) neighbours, clockwise; code 0 where none
    q1, q2 = sk.q1[free], sk.q2[free]
    c1 = np.where(deg >= 1, code[q1], 0)
    c2 = np.where(deg >= 2, code[q2], 0)
    # the starts, in the order the walk takes them
    jnb = offs8[:, None] + jflat  # (8, J): junction pixel fastest, transposed below
    jon = f[jnb].view(np.bool_).T
    jrow = np.nonzero(jon)[0]
    jc = code[jnb.T[jon]]
    entry = jc < 0
    start1 = -1 - jc[entry]
    start1_j = jrow[entry]  # position in jflat of the junction pixel
    start2 = np.flatnonzero(deg == 1)
    start3 = np.flatnonzero((deg == 2) & _NB_TOP[sk.bits[free]])  # a loop's first pixel
    starts = np.concatenate([start1, start2, start3])
    n1, n12, v = len(start1), len(start1) + len(start2), len(starts)
    if v == 0:
        return np.zeros(0, np.int64), np.zeros(1, np.int64), np.zeros((0, 4), np.int64)
    # rows: a pixel's non-junction neighbours; a virtual node's start and next virtual node
    nbr = np.stack([-1 - c1, -1 - c2], axis=1)  # < 0: no neighbour, or a junction's
    has = nbr >= 0
    indptr = np.empty(n + v + 1, np.int32)
    indptr[0] = 0
    np.cumsum(has[:, 0].astype(np.int32) + has[:, 1], out=indptr[1:n + 1])
    indptr[n + 1:] = indptr[n] + 2 * np.arange(1, v + 1)
    indptr[-1] -= 1  # the last virtual node has no successor
    virt = np.empty((v, 2), np.int64)
    virt[:, 0] = starts
    virt[:, 1] = np.arange(n + 1, n + v + 1)
    indices = np.concatenate([nbr[has], virt.reshape(-1)[:-1]]).astype(np.int32)
    g = csr_matrix((np.ones(len(indices)), indices, indptr), shape=(n + v, n + v))
    order = depth_first_order(g, n, directed=True, return_predecessors=False)
    is_virt = order >= n
    start_of = (np.cumsum(is_virt) - 1)[~is_virt]  # the start each walked pixel comes from
    seq = order[~is_virt].astype(np.int64)
    first = np.flatnonzero(np.r_[True, start_of[1:] != start_of[:-1]])
    run_start = start_of[first]
    run_len = np.diff(np.r_[first, len(seq)])
    m = len(first)
    last = first + run_len - 1
    ph1 = run_start < n1
    ph3 = run_start >= n12
    head = npix[seq[first]]
    tail = npix[seq[last]]
    # stacks from a junction: the junction pixel first, then the junction pixel next to the
    # chain's last pixel (other than the one before it), if any
    i1 = np.flatnonzero(ph1)
    jpix = jflat[start1_j[run_start[i1]]]
    x = seq[last[i1]]
    prev = np.where(run_len[i1] > 1, npix[seq[np.maximum(last[i1] - 1, 0)]], jpix)
    to1 = (c1[x] > 0) & (q1[x] != prev)
    to2 = (c2[x] > 0) & (q2[x] != prev)
    has_j = to1 | to2
    jend = np.where(to1, q1[x], q2[x])
    # a loop goes from its first pixel towards its first neighbour clockwise from north;
    # which of its two neighbours the traversal took first is not documented by scipy
    i3 = np.flatnonzero(ph3)
    flip = np.zeros(m, bool)
    flip[i3] = npix[seq[first[i3] + 1]] != q1[seq[first[i3]]]
    pre = ph1.astype(np.int64)
    post = ph3.astype(np.int64)
    post[i1] = has_j
    offs = np.zeros(m + 1, np.int64)
    np.cumsum(run_len + pre + post, out=offs[1:])
    pix = np.empty(int(offs[-1]), np.int64)
    run_of = np.repeat(np.arange(m), run_len)
    pos = np.arange(len(seq)) - np.repeat(first, run_len)
    if len(i3):
        pos = np.where(flip[run_of] & (pos > 0), np.repeat(run_len, run_len) - pos, pos)
    pix[offs[:-1][run_of] + pre[run_of] + pos] = npix[seq]
    pix[offs[:-1][i1]] = jpix
    pix[offs[1:][i1[has_j]] - 1] = jend[has_j]
    pix[offs[1:][i3] - 1] = head[i3]
    meta = np.empty((m, 4), np.int64)
    meta[:, 0] = np.where(ph1, _JUNCTION, np.where(ph3, _LOOP, _END))
    meta[:, 1] = head
    meta[i1, 1] = code[jpix] - 1
    meta[:, 2] = np.where(ph3, _LOOP, _END)
    meta[i1[has_j], 2] = _JUNCTION
    meta[:, 3] = np.where(ph3, head, tail)
    meta[i1[has_j], 3] = code[jend[has_j]] - 1
    return pix, offs, meta


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


class _Padded(NamedTuple):
    """What every tracing of one skeleton reads (see :func:`_padded`)."""

    img: np.ndarray  # (H + 2, W + 2) uint8, the skeleton padded by one background pixel
    sr: np.ndarray  # rows of the skeleton pixels in img, raster order
    sc: np.ndarray  # their columns
    sp: np.ndarray  # their flat indices in img
    bits: np.ndarray  # their 8-neighbourhood codes (bit k: neighbour k, clockwise from north)
    q1: np.ndarray  # their first neighbours clockwise from north (flat), where they have one
    q2: np.ndarray  # their second neighbours, where they have two
    code: np.ndarray  # int32 scratch array of :func:`_trace`, as large as img


def _padded(skel) -> _Padded:
    """What every tracing of the same skeleton reads, computed once.

    Parameters
    ----------
    skel : (H, W) bool array
        The skeleton.

    Returns
    -------
    _Padded
        Its scratch array is never cleared: the tracing writes and reads it on skeleton pixels
        only (zeroing a 2000x2000 scan's 16 MB would take longer than the tracing). It is
        int32, which holds every label and pixel index: the first tracing touches most of its
        pages, 1.9 ms against 3.5 ms for int64 on such a scan.
    """
    h, w = skel.shape
    img = np.zeros((h + 2, w + 2), np.uint8)
    img[1:-1, 1:-1] = skel
    sr, sc = nonzero_rc(img)
    wp = w + 2
    sp = sr * wp + sc
    f = img.reshape(-1)
    offs8 = np.array([-wp, -wp + 1, 1, wp + 1, wp, wp - 1, -1, -wp - 1], np.int64)
    nb = f[offs8[:, None] + sp]  # (8, P): a short inner axis makes numpy slow
    bits = nb[0].copy()
    for k in range(1, 8):
        bits |= nb[k] << np.uint8(k)
    return _Padded(img, sr, sc, sp, bits, sp + offs8[_NB_FIRST[bits]],
                   sp + offs8[_NB_SECOND[bits]], np.empty(img.size, np.int32))


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

    Raises
    ------
    ParameterError
        If the junctions are not those of this skeleton: a skeleton pixel with three or more
        neighbours in no junction, or junction pixels other than the skeleton pixels marked
        in their label image.
    """
    skel = np.asarray(skel, dtype=bool)
    if skel.shape != junctions.label_image.shape:
        raise ParameterError(f"skeleton shape {skel.shape} differs from junction label "
                             f"image shape {junctions.label_image.shape}")
    return _build_stack_graph(_padded(skel), junctions, smooth_px)


def _multigraph(n_nodes: int, ends) -> nx.MultiGraph:
    """The MultiGraph of nodes ``0 .. n_nodes - 1`` (added in that order) and one edge per
    stack, key and ``stack_id`` its index in ``ends``."""
    g = nx.MultiGraph()
    g.add_nodes_from(range(n_nodes))
    g.add_edges_from((u, v, sid, {"stack_id": sid}) for sid, (u, v) in enumerate(ends))
    return g


def with_multigraph(sg: StackGraph) -> StackGraph:
    """``sg`` with its MultiGraph (``graph``) built when it has none: as
    :func:`build_stack_graph` builds it, its nodes being ``0 .. len(node_kind) - 1`` in
    order (``stack_graph(..., with_graph=False)``). Returns ``sg`` itself."""
    if sg.graph is None:
        sg.graph = _multigraph(len(sg.node_kind), sg.ends)
    return sg


def _build_stack_graph(sk: _Padded, junctions: Junctions, smooth_px: int, *,
                       with_graph: bool = True) -> StackGraph:
    """:func:`build_stack_graph` of a skeleton given as :func:`_padded` returns it.

    Without ``with_graph`` the returned graph's ``graph`` is None (:func:`stack_graph` asks
    for it once it knows the graph is kept: the MultiGraph of the dense 2000x2000 benchmark
    scan costs 0.4-1.2 ms, and merged crossings and dropped pieces replace the graph
    traced first); :func:`_multigraph` of ``len(node_kind)`` nodes and ``ends`` is the one
    built here."""
    wp = sk.img.shape[1]
    if junctions.pixels:
        jp = np.concatenate(junctions.pixels).astype(np.int64) + 1
    else:
        jp = np.zeros((0, 2), np.int64)
    jflat = jp[:, 0] * wp + jp[:, 1]
    lab = junctions.label_image
    pix, offs, meta = _trace(sk, lab[sk.sr - 1, sk.sc - 1], jflat,
                             lab[jp[:, 0] - 1, jp[:, 1] - 1])
    m = len(meta)
    # all paths in one (N, 2) array, each stack's path a view of its rows
    rc = np.empty((len(pix), 2), np.int64)
    np.floor_divide(pix, wp, out=rc[:, 0])
    np.remainder(pix, wp, out=rc[:, 1])
    rc -= 1
    is_loop = meta[:, 0] == _LOOP
    meta = meta.tolist()
    k = len(junctions)
    node_rc: dict[int, np.ndarray] = {}
    node_kind: dict[int, str] = {}
    for j in range(k):
        node_rc[j] = np.asarray(junctions.centers_rc[j], dtype=float)
        node_kind[j] = "junction"
    pixel_node: dict[int, int] = {}

    def node_of(kind, ident):
        # the nodes after the junctions are numbered as they are met: k, k + 1, ...
        if kind == _JUNCTION:
            return int(ident)
        ident = int(ident)
        if ident not in pixel_node:
            nid = k + len(pixel_node)
            pixel_node[ident] = nid
            node_rc[nid] = np.array([ident // wp - 1, ident % wp - 1], dtype=float)
            node_kind[nid] = "end" if kind == _END else "loop"
        return pixel_node[ident]

    ends = [(node_of(ku, iu), node_of(kv, iv)) for ku, iu, kv, iv in meta]
    g = _multigraph(k + len(pixel_node), ends) if with_graph else None
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


def split_stacks(sg: StackGraph, cuts: dict, *, smooth_px: int = 5) -> StackGraph:
    """The graph with stacks cut at layer steps (:func:`crosssection.stages.widths.layer_steps`).

    Each cut is a new node of kind ``"step"`` at the path pixel where it lies; the first part
    of a cut stack keeps its id, the others are numbered after the existing stacks (in the
    order of ``cuts``). Both parts hold the cut pixel, as the paths leaving a junction hold
    its pixel. A closed loop without junction (two cuts or more) becomes the arcs between its
    steps, and its ``"loop"`` node goes. ``sg`` is not modified.

    Parameters
    ----------
    sg : StackGraph
    cuts : dict stack_id -> list of int
        Ascending path indices, strictly inside each path.
    smooth_px : int
        Sliding-average window of the lengths (as :func:`build_stack_graph`).

    Returns
    -------
    StackGraph
    """
    if not cuts:
        return sg
    g = sg.graph.copy()
    node_rc, node_kind = dict(sg.node_rc), dict(sg.node_kind)
    paths, ends = list(sg.paths), list(sg.ends)
    changed = []
    nid = max(node_kind) + 1 if node_kind else 0
    for sid in sorted(cuts):
        path = sg.paths[sid]
        u, v = sg.ends[sid]
        g.remove_edge(u, v, key=sid)
        loop = node_kind[u] == "loop"
        at = [int(c) for c in cuts[sid]]
        steps = []
        for c in at:
            node_rc[nid] = np.asarray(path[c], dtype=float)
            node_kind[nid] = "step"
            g.add_node(nid)
            steps.append(nid)
            nid += 1
        if loop:
            # the loop's node goes: its path (whose first pixel closes it) is cut into the
            # arcs between consecutive steps, the last one running on through that pixel
            g.remove_node(u)
            del node_rc[u], node_kind[u]
            parts = [path[a:b + 1] for a, b in zip(at[:-1], at[1:])]
            parts.append(np.concatenate([path[at[-1]:], path[1:at[0] + 1]]))
            nodes = steps + [steps[0]]
        else:
            bounds = [0, *at, len(path) - 1]
            parts = [path[a:b + 1] for a, b in zip(bounds[:-1], bounds[1:])]
            nodes = [u, *steps, v]
        for i, part in enumerate(parts):
            end = (nodes[i], nodes[i + 1])
            if i == 0:
                k = sid
                paths[k], ends[k] = part, end
            else:
                k = len(paths)
                paths.append(part)
                ends.append(end)
            g.add_edge(*end, key=k, stack_id=k)
            changed.append(k)
    lengths = np.concatenate([np.asarray(sg.length_px, float),
                              np.zeros(len(paths) - len(sg.paths))])
    changed = np.asarray(sorted(changed), np.int64)
    rc, offs = polyline.concat_paths([paths[k] for k in changed])
    u_rc = np.array([node_rc[ends[k][0]] for k in changed])
    v_rc = np.array([node_rc[ends[k][1]] for k in changed])
    lengths[changed] = _stack_lengths(rc, offs, u_rc, v_rc, np.zeros(len(changed), bool),
                                      int(smooth_px))
    return StackGraph(graph=g, node_rc=node_rc, node_kind=node_kind, paths=paths, ends=ends,
                      length_px=lengths)


def without_stacks(sg: StackGraph, stacks) -> StackGraph:
    """The graph without the stacks ``stacks`` whose two ends are free (nodes of kind
    ``"end"``, which go with them); the other stacks keep their order, renumbered from 0.
    ``sg`` is not modified. Junctions are untouched: such a stack meets none.

    Parameters
    ----------
    sg : StackGraph
    stacks : iterable of int
        Stack ids, each with two ``"end"`` nodes.

    Returns
    -------
    StackGraph
    """
    drop = set(int(s) for s in stacks)
    keep = [sid for sid in range(sg.n_stacks) if sid not in drop]
    gone = {n for sid in drop for n in sg.ends[sid]}
    if any(sg.node_kind[n] != "end" for n in gone):
        raise ValueError("only stacks with two free ends can be dropped")
    g = nx.MultiGraph()
    node_rc = {n: rc for n, rc in sg.node_rc.items() if n not in gone}
    node_kind = {n: k for n, k in sg.node_kind.items() if n not in gone}
    g.add_nodes_from(node_rc)
    ends = [sg.ends[sid] for sid in keep]
    g.add_edges_from((u, v, k, {"stack_id": k}) for k, (u, v) in enumerate(ends))
    return StackGraph(graph=g, node_rc=node_rc, node_kind=node_kind,
                      paths=[sg.paths[sid] for sid in keep], ends=ends,
                      length_px=np.asarray(sg.length_px, dtype=float)[keep])


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
                merge_thick_crossings: bool = True, thickness_px: float | None = None,
                with_graph: bool = True):
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
        skeleton's fork, which lies several h away inside thick blobs (and, at a tangential
        fork, not beyond where the ink's width departs from the trunk's band); ``length_px``
        keeps the fork-to-fork lengths.
    with_graph : bool
        False: the returned graph's ``graph`` (the MultiGraph) is None, for a caller that
        builds another graph from this one (:func:`without_stacks`) or completes it
        (:func:`with_multigraph`).

    Returns
    -------
    junctions : Junctions
    graph : StackGraph
    n_merged : int
        Number of bridging stacks merged into junctions.
    """
    skel = np.asarray(skel, dtype=bool)
    if skel.ndim != 2:
        raise ParameterError(f"skeleton must be a 2-D array, got shape {skel.shape}")
    if thickness_px is not None:
        _number("thickness_px", thickness_px)
    padded = _padded(skel)  # the junctions and every tracing below read it
    junc = padded_junctions(padded.img, padded.sp, _NB_COUNT[padded.bits], merge_px=merge_px)
    # (the MultiGraph only of the graph kept: merged crossings trace it again)
    sg = _build_stack_graph(padded, junc, 5, with_graph=False)
    merged = 0
    if merge_thick_crossings and len(junc):
        for _ in range(3):
            links = short_junction_links(sg, _junction_radius(junc, distance_px))
            if not links:
                break
            groups = [sg.ends[s] for s in links]
            # (junc and sg are this function's own, replaced here: the label image is
            # rewritten in place)
            junc = merge_junctions(junc, groups, [sg.paths[s] for s in links],
                                   reuse_label_image=True)
            sg = _build_stack_graph(padded, junc, 5, with_graph=False)
            merged += len(links)
    if with_graph:
        sg = with_multigraph(sg)
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
    first_own, last_own = _own_band_span(sg.paths, distance_px, thickness_px)
    end_paths, end_junction, skip = [], [], []
    for sid, (u, v) in enumerate(sg.ends):
        path = sg.paths[sid]
        for node, p, k in ((u, path, first_own[sid]),
                           (v, path[::-1], len(path) - 1 - last_own[sid])):
            if sg.node_kind[node] == "junction":
                end_paths.append(p)
                end_junction.append(node)
                skip.append(np.hypot(*(p[k] - junc.centers_rc[node])) if 0 < k < len(p)
                            else 0.0)
    skip = np.asarray(skip, float)
    # only a path that runs obliquely through the blob beyond its radius is skipped farther
    skip[skip <= radius[np.asarray(end_junction, np.int64)]] = 0.0
    centers = fork_points(junc.centers_rc, radius, end_paths, end_junction,
                          thickness_px=thickness_px, skip_px=skip)
    return Junctions(centers_rc=centers, pixels=junc.pixels, label_image=junc.label_image)


def _own_band_span(paths, distance_px, thickness_px) -> tuple[np.ndarray, np.ndarray]:
    """Per stack, the first and the last pixel of its path that lie in its own band.

    A thin stack meeting a thick band at an angle has no centreline of its own inside that
    band: its skeleton crosses the band obliquely to the medial-axis fork, which thinning
    places up to 0.8 band half-widths along the thick band (a single sheet on a 16-layer
    trunk: 34 px at h = 5 px). A pixel is in the stack's own band when its distance to the
    background is within ``max(1, h / 2)`` of the median along the path (the half width of
    its own band); :func:`_at_fork_points` fits the centreline beyond these pixels.
    Vectorised over all stacks (one sort): 2.5 ms on a dense 2000x2000 scan.

    Parameters
    ----------
    paths : list of (P, 2) int arrays
        Stack paths (row, col).
    distance_px : (H, W) array
        Distance of every ink pixel to the background.
    thickness_px : float
        Sheet thickness h in px.

    Returns
    -------
    first, last : (M,) int arrays
        Positions along each path; ``first = len`` and ``last = -1`` where no pixel is.
    """
    q = len(paths)
    lens = np.fromiter((len(p) for p in paths), np.int64, count=q)
    if q == 0 or lens.sum() == 0:
        return np.full(q, 0, np.int64) + lens, np.full(q, -1, np.int64)
    pix = np.concatenate([np.asarray(p).reshape(-1, 2) for p in paths])
    dt = np.asarray(distance_px)[pix[:, 0], pix[:, 1]].astype(np.float64)
    path = np.repeat(np.arange(q), lens)
    start = np.zeros(q, np.int64)
    np.cumsum(lens[:-1], out=start[1:])
    # per-path median (np.median's: the mean of the two middle values of an even count);
    # distances are >= 0 and below the image size, so path * span + dt sorts by path first
    span = float(dt.max()) + 1.0
    srt = dt[np.argsort(path * span + dt, kind="stable")]
    last_i = len(dt) - 1
    med = 0.5 * (srt[np.minimum(start + (lens - 1) // 2, last_i)]
                 + srt[np.minimum(start + lens // 2, last_i)])
    own = dt <= med[path] + max(1.0, 0.5 * float(thickness_px))
    pos = np.arange(len(dt)) - start[path]
    first = lens.copy()
    last = np.full(q, -1, np.int64)
    np.minimum.at(first, path[own], pos[own])
    np.maximum.at(last, path[own], pos[own])
    return first, last


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
