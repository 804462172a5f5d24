"""Stage 7: packs of stacks at every junction (paper, section "Image analysis procedure").

At a junction the stacks arriving from one side merge into (or separate from) the stacks on
the other side.  The paper distinguishes the two *packs* with the tangent vectors of the stacks
near the junction: the straight line perpendicular to one tangent (the reference) splits the
plane in two half-planes, stacks in the same half-plane form one pack.  The paper then checks
that the result does not depend on the reference.  We do both:

* every tangent is used once as the reference (the paper's rule) and the junction is flagged
  ``reference_dependent`` when the partitions differ;
* the partition actually returned is the one given by the separating line (through the
  junction) that is farthest, in angle, from every tangent: fold the tangent angles modulo
  pi, sort them, and put the line in the middle of the widest angular gap.  This line
  maximises the minimum ``|t . n|`` over all tangents ``t`` (``n`` the line normal), so it is the
  most robust split; when the paper's rule is reference independent both rules agree (all
  tangents lie within 45 degrees of the line normal or its opposite).

A degree-4 crossing comes out as 2|2 or 1|3 depending on the geometry; a self-loop stack
appears twice (once per end).  Both packs must be non-empty: when every tangent lies in one
half-plane the junction is flagged ``ambiguous`` (the best two-sided split is still returned
when one exists, and alternatives are listed in ``candidates`` for the linear system).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from crosssection.core.polyline import grouped_axes, walk_ends

EdgeEnd = tuple[int, int]  # (stack_id, end): end 0 = path start, 1 = path end

__all__ = ["EdgeEnd", "Pack", "StackGraphLike", "compute_packs", "junction_edge_ends",
           "end_tangent", "partition_by_gap", "partition_by_reference"]


class StackGraphLike(Protocol):
    """What this module needs from ``crosssection.stages.graph.StackGraph`` (duck-typed)."""

    graph: Any                      # networkx MultiGraph, edge attribute ``stack_id``
    node_rc: dict                   # node -> (row, col)
    node_kind: dict                 # node -> "junction" | "end" | "loop"
    paths: list                     # stack_id -> (P, 2) int pixel path from u to v
    ends: list                      # stack_id -> (u, v)


@dataclass
class Pack:
    """The two packs of stacks meeting at one junction.

    Attributes
    ----------
    node : int
        Junction node id.
    side_a, side_b : list of EdgeEnd
        The two packs; ``side_a`` is the smaller one (the "trunk" of a Y junction), ties broken
        by the smallest EdgeEnd.  Conservation reads ``sum(n[side_a]) == sum(n[side_b])``.
    ambiguous : bool
        No two-sided split is defined by the geometry (fewer than two usable tangents, or all
        tangents in one half-plane).
    reference_dependent : bool
        The paper's rule (split perpendicular to one tangent) gives different partitions for
        different reference tangents.
    margin_deg : float
        Half the widest angular gap (modulo 180 degrees) between tangents: the smallest angle
        between any tangent and the separating line.  Large is clear-cut.
    tangents : dict
        EdgeEnd -> unit tangent (row, col) pointing away from the junction (NaN if unknown).
    candidates : list of (list, list)
        Distinct two-sided partitions (best first): the returned one, the other gap splits and
        the ones produced by every reference.  The linear system may pick among them by width
        when the junction is ``reference_dependent`` or ``ambiguous``.
    """

    node: int
    side_a: list[EdgeEnd]
    side_b: list[EdgeEnd]
    ambiguous: bool = False
    reference_dependent: bool = False
    margin_deg: float = float("nan")
    tangents: dict = field(default_factory=dict)
    candidates: list = field(default_factory=list)

    @property
    def degree(self) -> int:
        """Number of stack ends at the junction."""
        return len(self.side_a) + len(self.side_b)


def junction_edge_ends(graph: StackGraphLike, node) -> list[EdgeEnd]:
    """Stack ends incident to ``node``, sorted; a self-loop contributes (s, 0) and (s, 1)."""
    out: list[EdgeEnd] = []
    seen: set[int] = set()
    for _, _, sid in graph.graph.edges(node, data="stack_id"):
        sid = int(sid)
        if sid in seen:  # networkx lists a self-loop once per incidence; ends decide below
            continue
        seen.add(sid)
        u, v = graph.ends[sid]
        if u == node:
            out.append((sid, 0))
        if v == node:
            out.append((sid, 1))
    return sorted(out)


def end_tangent(path_rc: np.ndarray, node_rc, end: int, *, tangent_px: float,
                skip_px: float = 2.0) -> np.ndarray:
    """Unit tangent of a stack at one of its ends, pointing away from the junction.

    Parameters
    ----------
    path_rc : (P, 2) array
        Pixel path of the stack (row, col), ordered from its node u to its node v.
    node_rc : (2,) array-like
        Position of the junction at this end.
    end : {0, 1}
        0: the junction is at the path start, 1: at the path end.
    tangent_px : float
        Length of the fitting window: the path is followed from the junction until it first
        gets farther than ``skip_px + tangent_px`` from the junction centre.
    skip_px : float
        Pixels closer than this to the junction centre (inside the junction blob, where the
        skeleton of merging stacks bends) are ignored.

    Returns
    -------
    (2,) float array
        Unit vector (d_row, d_col): principal axis (PCA, i.e. a total least-squares line fit)
        of the selected pixels, oriented from the junction outwards; NaN if undefined.
    """
    pts = np.asarray(path_rc, dtype=float).reshape(-1, 2)
    if end == 1:
        pts = pts[::-1]
    p0 = np.asarray(node_rc, dtype=float)
    if len(pts) == 0:
        return np.full(2, np.nan)
    dist = np.hypot(*(pts - p0).T)
    beyond = np.flatnonzero(dist > skip_px + tangent_px)
    stop = beyond[0] + 1 if beyond.size else len(pts)
    sel = pts[:stop][dist[:stop] >= skip_px]
    if len(sel) < 2:  # short stack: take what there is
        sel = pts[: max(2, min(len(pts), int(np.ceil(tangent_px))))]
    if len(sel) >= 2:
        centred = sel - sel.mean(axis=0)
        _, _, vt = np.linalg.svd(centred, full_matrices=False)
        t = vt[0]
        orient = sel[-1] - sel[0]
        if np.dot(orient, orient) < 1e-12:
            orient = sel.mean(axis=0) - p0
        if np.dot(t, orient) < 0:
            t = -t
        if np.dot(orient, orient) >= 1e-12:
            return t / np.linalg.norm(t)
    d = pts.mean(axis=0) - p0
    n = np.linalg.norm(d)
    return d / n if n > 1e-9 else np.full(2, np.nan)


def _tangents_kernel(pr, pc, offs, sids, ends, p0r, p0c, skips, tangent_px):
    """:func:`end_tangent` for many ends at once (same rules; closed-form 2x2 PCA).

    Vectorised over all ends: every end's points walked from its junction, the per-end sums
    by ``np.bincount``, which adds in the walk order as a loop would.
    """
    q = sids.shape[0]
    out = np.full((q, 2), np.nan)
    rev = ends == 1
    e, pos, ii, lens = walk_ends(offs, sids, rev)
    a = offs[sids]
    d = np.hypot(pr[ii] - p0r[e], pc[ii] - p0c[e])
    # the walk stops after the first point farther than skip + tangent_px
    stop = lens.copy()
    beyond = d > skips[e] + tangent_px
    np.minimum.at(stop, e[beyond], pos[beyond] + 1)
    near = d >= skips[e]
    cnt = np.bincount(e[(pos < stop[e]) & near], minlength=q)
    use_all = cnt < 2  # short stack: take what there is
    stop = np.where(use_all, np.minimum(np.maximum(2, np.minimum(lens, int(np.ceil(tangent_px)))),
                                        lens), stop)
    sel = (pos < stop[e]) & (use_all[e] | near)
    cnt, mr, mc, ang, first, last = grouped_axes(e[sel], pr[ii[sel]], pc[ii[sel]], pos[sel], q)
    fit = cnt >= 2
    done = np.zeros(q, np.bool_)
    k = np.flatnonzero(fit)
    if len(k):
        tr = np.cos(ang[k])
        tc = np.sin(ang[k])
        i0 = a[k] + np.where(rev[k], lens[k] - 1 - first[k], first[k])
        i1 = a[k] + np.where(rev[k], lens[k] - 1 - last[k], last[k])
        orr = pr[i1] - pr[i0]
        orc = pc[i1] - pc[i0]
        flat = orr * orr + orc * orc < 1e-12
        orr = np.where(flat, mr[k] - p0r[k], orr)
        orc = np.where(flat, mc[k] - p0c[k], orc)
        flip = tr * orr + tc * orc < 0
        tr[flip] = -tr[flip]
        tc[flip] = -tc[flip]
        ok = orr * orr + orc * orc >= 1e-12
        out[k[ok], 0] = tr[ok]
        out[k[ok], 1] = tc[ok]
        done[k[ok]] = True
    # otherwise: the direction from the junction to the mean of the whole path
    rest = np.flatnonzero(~done & (lens > 0))
    if len(rest):
        pe = np.repeat(np.arange(len(rest)), lens[rest])
        pi = np.arange(len(pe)) - np.repeat(np.cumsum(lens[rest]) - lens[rest], lens[rest])
        pi = pi + a[rest][pe]
        dr0 = np.bincount(pe, weights=pr[pi], minlength=len(rest)) / lens[rest] - p0r[rest]
        dc0 = np.bincount(pe, weights=pc[pi], minlength=len(rest)) / lens[rest] - p0c[rest]
        nn = np.hypot(dr0, dc0)
        good = nn > 1e-9
        out[rest[good], 0] = dr0[good] / nn[good]
        out[rest[good], 1] = dc0[good] / nn[good]
    return out


def _canonical(a: list[EdgeEnd], b: list[EdgeEnd]) -> tuple[tuple, tuple]:
    """Order a partition: smaller pack first, ties by smallest element; sorted packs."""
    a, b = tuple(sorted(a)), tuple(sorted(b))
    if (len(b), b[:1]) < (len(a), a[:1]):
        a, b = b, a
    return a, b


def _split_rows(keys: list[EdgeEnd], proj: np.ndarray) -> list[tuple[list, list]]:
    """Per row of ``proj`` (projections of the ends ``keys`` on one normal): the ends with a
    positive projection and the others (``p <= 0``)."""
    out = []
    for pos, neg in zip((proj > 0).tolist(), (proj <= 0).tolist()):
        out.append(([k for k, p in zip(keys, pos) if p], [k for k, p in zip(keys, neg) if p]))
    return out


def _splits(keys: list[EdgeEnd], tangents: np.ndarray, references: bool = False):
    """:func:`partition_by_gap`, and with ``references`` the list of
    :func:`partition_by_reference` of every reference ``0 .. k - 1``.

    Every gap's normal is computed by the same ufuncs on arrays, and the projections on all
    normals and reference tangents by one batched ``np.matmul``: numpy computes each batch as
    the product of the matrix by one vector, the product ``tangents @ normal`` of a loop over
    them, so every projection is that loop's to the bit (a matrix product ``tangents @
    normals.T`` rounds differently where the BLAS fuses multiply and add). numpy's calls on
    a junction's few tangents cost more than their work: 23 us a junction, against 28 us
    normal by normal (the 162 junctions of the dense 2000 x 2000 benchmark scan)."""
    ang = np.mod(np.arctan2(tangents[:, 0], tangents[:, 1]), np.pi)
    order = ang.argsort(kind="stable")
    s = ang[order]
    nxt = np.empty_like(s)
    nxt[:-1] = s[1:]
    nxt[-1:] = s[:1] + np.pi
    gaps = nxt - s
    g = (-gaps).argsort(kind="stable")
    half = gaps[g] / 2.0
    phi = s[g] + half  # directions of the separating lines
    ng = len(phi)
    # line direction in (row, col) is (sin phi, cos phi); its normal is (cos phi, -sin phi)
    cos = np.cos(phi)
    vec = np.empty((ng + len(tangents) if references else ng, 2, 1), cos.dtype)
    vec[:ng, 0, 0] = cos
    vec[:ng, 1, 0] = -np.sin(phi)
    if references:
        vec[ng:, :, 0] = tangents
    rows = _split_rows(keys, np.matmul(tangents, vec)[..., 0])
    out = []
    for (a, b), m in zip(rows[:ng], np.degrees(half).tolist()):
        ca, cb = _canonical(a, b) if a and b else (tuple(sorted(a or b)), ())
        out.append((ca, cb, m))
    if not references:
        return out
    return out, [_canonical(a, b) for a, b in rows[ng:]]


def partition_by_reference(keys: list[EdgeEnd], tangents: np.ndarray, ref: int):
    """The paper's rule: split by the line perpendicular to tangent ``ref``.

    Returns ``(side_a, side_b)`` canonical, where ends with positive projection on the
    reference tangent are on the reference's side.
    """
    proj = (tangents @ tangents[ref]).tolist()  # Python floats: the tests cost less
    same = [k for k, p in zip(keys, proj) if p > 0]
    other = [k for k, p in zip(keys, proj) if p <= 0]
    return _canonical(same, other)


def partition_by_gap(keys: list[EdgeEnd], tangents: np.ndarray):
    """All line splits through the junction, best (widest angular gap) first.

    Parameters
    ----------
    keys : list of EdgeEnd
    tangents : (k, 2) unit vectors (row, col)

    Returns
    -------
    list of (side_a, side_b, margin_deg)
        One entry per gap between consecutive tangent directions folded modulo pi, sorted by
        decreasing margin (half the gap).  A side may be empty (all tangents on one side).
    """
    return _splits(keys, tangents)


def compute_packs(graph: StackGraphLike, *, tangent_px: float, skip_px: float = 2.0,
                  distance_px: np.ndarray | None = None, blob_factor: float = 1.0,
                  nodes=None) -> dict:
    """Split the stacks meeting at every junction into two packs.

    Parameters
    ----------
    graph : StackGraph
        Stage-6 graph (see docs/design.md); only junction nodes (``node_kind == "junction"``)
        are processed.
    tangent_px : float
        Length of path, beyond the skipped blob, over which each stack's tangent is fitted.
        Short is better on curved stacks: on 4 generated scenes (crosssection.truth.network,
        h = 5 px, up to 8 layers, 151 junctions) the partitions matched the truth packs for
        148 junctions with ``tangent_px=10, skip_px=4``, 147 with 15/4, 136 with 30/4,
        71 with 60/8; skipping the inscribed-disk radius (``distance_px``) did not help
        (139 with 15 px).  Recommended: about 2 h (10 px at 50 px/mm), ``skip_px`` about h.
    skip_px : float
        Pixels closer than this to the junction centre are ignored in the fit.
    distance_px : 2-D array, optional
        Euclidean distance transform of the mask.  When given, the skipped radius at each
        junction is ``max(skip_px, blob_factor * EDT at the junction centre)``: the inscribed
        disk of the junction blob, where the skeleton of thick merging stacks bends.
    blob_factor : float
        See ``distance_px``.
    nodes : iterable, optional
        Restrict to these nodes.

    Returns
    -------
    dict
        node -> :class:`Pack`.
    """
    kind = graph.node_kind
    if nodes is None:
        nodes = [n for n in graph.graph.nodes if kind.get(n, "junction") == "junction"]
    nodes = list(nodes)
    # stack ends per node in one pass over graph.ends (as junction_edge_ends, sorted)
    by_node: dict = {}
    for sid, (u, v) in enumerate(graph.ends):
        by_node.setdefault(u, []).append((sid, 0))
        by_node.setdefault(v, []).append((sid, 1))
    keys_of = {nd: sorted(by_node.get(nd, [])) for nd in nodes}
    q_sid, q_end, q_r, q_c, q_skip = [], [], [], [], []
    for node in nodes:
        p0 = np.asarray(graph.node_rc[node], float)
        skip = float(skip_px)
        if distance_px is not None:
            r, c = np.round(p0).astype(int)
            if 0 <= r < distance_px.shape[0] and 0 <= c < distance_px.shape[1]:
                skip = max(skip, blob_factor * float(distance_px[r, c]))
        for sid, end in keys_of[node]:
            q_sid.append(sid)
            q_end.append(end)
            q_r.append(p0[0])
            q_c.append(p0[1])
            q_skip.append(skip)
    paths = [np.asarray(p).reshape(-1, 2) for p in graph.paths]
    lens = np.fromiter((len(p) for p in paths), np.int64, count=len(paths))
    offs = np.zeros(len(paths) + 1, np.int64)
    np.cumsum(lens, out=offs[1:])
    flat = np.concatenate(paths).astype(float) if offs[-1] else np.zeros((0, 2))
    tan = _tangents_kernel(np.ascontiguousarray(flat[:, 0]), np.ascontiguousarray(flat[:, 1]),
                           offs, np.asarray(q_sid, np.int64), np.asarray(q_end, np.int64),
                           np.asarray(q_r, float), np.asarray(q_c, float),
                           np.asarray(q_skip, float), float(tangent_px)) if q_sid else \
        np.zeros((0, 2))
    finite = np.isfinite(tan).all(axis=1).tolist()
    out = {}
    k = 0
    for node in nodes:
        keys = keys_of[node]
        tans = {key: tan[k + i] for i, key in enumerate(keys)}
        good = [key for i, key in enumerate(keys) if finite[k + i]]
        k += len(keys)
        out[node] = _pack_from_tangents(node, keys, tans, good)
    return out


def _pack_from_tangents(node, keys: list[EdgeEnd], tans: dict, good=None) -> Pack:
    """The pack of a junction from its ends' tangents ``tans``; ``good``: the ends whose
    tangent is finite, in the order of ``keys`` (found here when not given: the caller
    tests them all at once, 1.5 ms on the dense 2000x2000 benchmark scan for a test per
    end)."""
    if good is None:
        good = [k for k in keys if np.all(np.isfinite(tans[k]))]
    if len(good) < 2:
        return Pack(node, [], list(keys), ambiguous=True, tangents=tans)
    t = np.array([tans[k] for k in good])
    splits, refs = _splits(good, t, references=True)
    refs = set(refs)
    refs_two = [p for p in refs if p[0] and p[1]]
    reference_dependent = len(refs) > 1
    two_sided = [(a, b, m) for a, b, m in splits if a and b]
    ambiguous = not splits[0][1]  # the clearest split leaves one side empty
    bad = [k for k in keys if k not in good]
    if two_sided:
        a, b, margin = two_sided[0]
    else:  # all tangents identical: no split at all
        a, b, margin = (), tuple(good), 0.0
        ambiguous = True
    cands = []
    for p in [(a, b)] + [(x, y) for x, y, _ in two_sided] + sorted(refs_two):
        if p[0] and p[1] and p not in cands:
            cands.append(p)
    side_b = list(b) + bad  # ends without a tangent cannot be placed: keep them, flag
    return Pack(node, list(a), side_b, ambiguous=ambiguous or bool(bad),
                reference_dependent=reference_dependent, margin_deg=margin, tangents=tans,
                candidates=[(list(x), list(y)) for x, y in cands])
