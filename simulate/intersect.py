"""Self-intersection of a polyline (the hard core of Eq. (8)), in numba.

Rules: segments ``i`` and ``i+1`` share a node and never count as intersecting; any other pair
that touches (a common point, an endpoint on the other segment, a collinear overlap) IS an
intersection. Three detectors with identical answers:

* :func:`has_intersection_brute` -- all ``N(N-1)/2`` pairs, the reference;
* :func:`has_intersection_skip` -- the paper's input-sensitive test (section "Energy
  functional"): after testing the pair ``(i, j)`` at distance ``d``, segments ``j+1 .. j+m`` with
  ``m = floor(d/ds) - 1`` are skipped: a point of segment ``j+m`` is within ``m ds`` of the node
  ``R_{j+1}`` along the rod, so it stays at a distance ``>= d - m ds > 0`` from segment ``i``;
* :func:`has_intersection_grid` -- uniform grid of cells (side >= ds), only pairs sharing a cell
  are tested, each once; O(N) for a rod of bounded density. The default (:func:`has_intersection`).

All take ``xy`` (N+1, 2) float64; segment ``i`` joins ``xy[i]`` and ``xy[i+1]``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _orient(ax, ay, bx, by, cx, cy):
    v = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    if v > 0.0:
        return 1
    if v < 0.0:
        return -1
    return 0


@njit(cache=True, inline="always")
def _on_seg(ax, ay, bx, by, px, py):
    # p collinear with a-b: is it within the bounding box of a-b?
    return (min(ax, bx) <= px <= max(ax, bx)) and (min(ay, by) <= py <= max(ay, by))


@njit(cache=True)
def seg_intersect(ax, ay, bx, by, cx, cy, dx, dy):
    """True if closed segments [a, b] and [c, d] share at least one point."""
    o1 = _orient(ax, ay, bx, by, cx, cy)
    o2 = _orient(ax, ay, bx, by, dx, dy)
    o3 = _orient(cx, cy, dx, dy, ax, ay)
    o4 = _orient(cx, cy, dx, dy, bx, by)
    if o1 * o2 < 0 and o3 * o4 < 0:
        return True
    if o1 == 0 and _on_seg(ax, ay, bx, by, cx, cy):
        return True
    if o2 == 0 and _on_seg(ax, ay, bx, by, dx, dy):
        return True
    if o3 == 0 and _on_seg(cx, cy, dx, dy, ax, ay):
        return True
    if o4 == 0 and _on_seg(cx, cy, dx, dy, bx, by):
        return True
    return False


@njit(cache=True, inline="always")
def _pt_seg_d2(px, py, ax, ay, bx, by):
    ux = bx - ax
    uy = by - ay
    l2 = ux * ux + uy * uy
    t = 0.0
    if l2 > 0.0:
        t = ((px - ax) * ux + (py - ay) * uy) / l2
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
    ex = ax + t * ux - px
    ey = ay + t * uy - py
    return ex * ex + ey * ey


@njit(cache=True)
def seg_dist2(ax, ay, bx, by, cx, cy, dx, dy):
    """Squared distance between closed segments [a, b] and [c, d] (0 if they intersect)."""
    if seg_intersect(ax, ay, bx, by, cx, cy, dx, dy):
        return 0.0
    d = _pt_seg_d2(ax, ay, cx, cy, dx, dy)
    d = min(d, _pt_seg_d2(bx, by, cx, cy, dx, dy))
    d = min(d, _pt_seg_d2(cx, cy, ax, ay, bx, by))
    d = min(d, _pt_seg_d2(dx, dy, ax, ay, bx, by))
    return d


@njit(cache=True)
def has_intersection_brute(xy):
    """Reference O(N^2) test: does the polyline intersect itself? (see module docstring)"""
    n = xy.shape[0] - 1
    for i in range(n - 2):
        ax, ay, bx, by = xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1]
        for j in range(i + 2, n):
            if seg_intersect(ax, ay, bx, by, xy[j, 0], xy[j, 1], xy[j + 1, 0], xy[j + 1, 1]):
                return True
    return False


@njit(cache=True)
def _max_seg_len(xy):
    m = 0.0
    for i in range(xy.shape[0] - 1):
        dx = xy[i + 1, 0] - xy[i, 0]
        dy = xy[i + 1, 1] - xy[i, 1]
        m = max(m, math.sqrt(dx * dx + dy * dy))
    return m


@njit(cache=True)
def has_intersection_skip(xy):
    """The paper's input-sensitive test: skip segments that cannot come back (module docstring).

    ``ds`` is the longest segment, so the skip stays valid for unequal segments.
    """
    n = xy.shape[0] - 1
    ds = _max_seg_len(xy)
    if ds <= 0.0:
        return n >= 3
    for i in range(n - 2):
        ax, ay, bx, by = xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1]
        j = i + 2
        while j < n:
            d2 = seg_dist2(ax, ay, bx, by, xy[j, 0], xy[j, 1], xy[j + 1, 0], xy[j + 1, 1])
            if d2 == 0.0:
                return True
            m = int(math.floor(math.sqrt(d2) / ds)) - 1
            j += 1 + max(m, 0)
    return False


@njit(cache=True)
def _grid_setup(xy, cell):
    n = xy.shape[0] - 1
    xmin = xy[0, 0]
    ymin = xy[0, 1]
    xmax = xmin
    ymax = ymin
    for i in range(1, n + 1):
        xmin = min(xmin, xy[i, 0])
        xmax = max(xmax, xy[i, 0])
        ymin = min(ymin, xy[i, 1])
        ymax = max(ymax, xy[i, 1])
    ds = _max_seg_len(xy)
    side = max(xmax - xmin, ymax - ymin)
    h = max(cell, ds, side / math.ceil(math.sqrt(4.0 * n)), 1e-300)
    nx = int((xmax - xmin) / h) + 1
    ny = int((ymax - ymin) / h) + 1
    return xmin, ymin, h, nx, ny


@njit(cache=True)
def _grid_fill(xy, xmin, ymin, h, nx, ny, pad):
    """Bucket every segment (bbox grown by ``pad``) into cells: CSR (start, items)."""
    n = xy.shape[0] - 1
    ncell = nx * ny
    count = np.zeros(ncell + 1, np.int64)
    for s in range(n):
        x0 = int((min(xy[s, 0], xy[s + 1, 0]) - pad - xmin) / h)
        x1 = int((max(xy[s, 0], xy[s + 1, 0]) + pad - xmin) / h)
        y0 = int((min(xy[s, 1], xy[s + 1, 1]) - pad - ymin) / h)
        y1 = int((max(xy[s, 1], xy[s + 1, 1]) + pad - ymin) / h)
        for cx in range(max(x0, 0), min(x1, nx - 1) + 1):
            for cy in range(max(y0, 0), min(y1, ny - 1) + 1):
                count[cx * ny + cy + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    items = np.empty(count[ncell], np.int64)
    fill = count[:-1].copy()
    for s in range(n):
        x0 = int((min(xy[s, 0], xy[s + 1, 0]) - pad - xmin) / h)
        x1 = int((max(xy[s, 0], xy[s + 1, 0]) + pad - xmin) / h)
        y0 = int((min(xy[s, 1], xy[s + 1, 1]) - pad - ymin) / h)
        y1 = int((max(xy[s, 1], xy[s + 1, 1]) + pad - ymin) / h)
        for cx in range(max(x0, 0), min(x1, nx - 1) + 1):
            for cy in range(max(y0, 0), min(y1, ny - 1) + 1):
                c = cx * ny + cy
                items[fill[c]] = s
                fill[c] += 1
    return count, items


@njit(cache=True)
def has_intersection_grid(xy):
    """Uniform-grid test: only pairs of segments whose bounding boxes share a cell are tested.

    Each pair is tested once, in the cell holding the lower-left corner of the overlap of the two
    bounding boxes. Cell side ``max(ds, extent / ceil(sqrt(4N)))`` keeps at most ~4N cells.
    """
    n = xy.shape[0] - 1
    if n < 3:
        return False
    xmin, ymin, h, nx, ny = _grid_setup(xy, 0.0)
    start, items = _grid_fill(xy, xmin, ymin, h, nx, ny, 0.0)
    for c in range(nx * ny):
        a0 = start[c]
        a1 = start[c + 1]
        if a1 - a0 < 2:
            continue
        cx = c // ny
        cy = c - cx * ny
        for p in range(a0, a1):
            i = items[p]
            axl = min(xy[i, 0], xy[i + 1, 0])
            ayl = min(xy[i, 1], xy[i + 1, 1])
            for q in range(p + 1, a1):
                j = items[q]
                if j == i + 1 or i == j + 1:
                    continue
                # dedupe: the pair belongs to the cell of max(lower-left corners)
                ox = max(axl, min(xy[j, 0], xy[j + 1, 0]))
                oy = max(ayl, min(xy[j, 1], xy[j + 1, 1]))
                if min(int((ox - xmin) / h), nx - 1) != cx or \
                        min(int((oy - ymin) / h), ny - 1) != cy:
                    continue
                if seg_intersect(xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1],
                                 xy[j, 0], xy[j, 1], xy[j + 1, 0], xy[j + 1, 1]):
                    return True
    return False


@njit(cache=True)
def close_pairs(xy, cutoff, min_separation):
    """Pairs of segments ``(i, j)``, ``j - i >= min_separation``, closer than ``cutoff``.

    Parameters
    ----------
    xy : (N+1, 2) float64
    cutoff : float
        Distance threshold (units of L); touching segments have distance 0.
    min_separation : int
        Minimum index difference (>= 2: adjacent segments are never reported).

    Returns
    -------
    (P, 2) int64 array, ``i < j``, sorted by ``i`` then ``j``.
    """
    n = xy.shape[0] - 1
    out = np.empty((0, 2), np.int64)
    if n < 3:
        return out
    xmin, ymin, h, nx, ny = _grid_setup(xy, cutoff)
    start, items = _grid_fill(xy, xmin, ymin, h, nx, ny, 0.0)
    seen = np.full(n, -1, np.int64)
    res_i = []
    res_j = []
    c2 = cutoff * cutoff
    for i in range(n):
        x0 = int((min(xy[i, 0], xy[i + 1, 0]) - cutoff - xmin) / h)
        x1 = int((max(xy[i, 0], xy[i + 1, 0]) + cutoff - xmin) / h)
        y0 = int((min(xy[i, 1], xy[i + 1, 1]) - cutoff - ymin) / h)
        y1 = int((max(xy[i, 1], xy[i + 1, 1]) + cutoff - ymin) / h)
        for cx in range(max(x0, 0), min(x1, nx - 1) + 1):
            for cy in range(max(y0, 0), min(y1, ny - 1) + 1):
                c = cx * ny + cy
                for p in range(start[c], start[c + 1]):
                    j = items[p]
                    if j - i < min_separation or seen[j] == i:
                        continue
                    seen[j] = i
                    if seg_dist2(xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1],
                                 xy[j, 0], xy[j, 1], xy[j + 1, 0], xy[j + 1, 1]) < c2:
                        res_i.append(i)
                        res_j.append(j)
    m = len(res_i)
    out = np.empty((m, 2), np.int64)
    for k in range(m):
        out[k, 0] = res_i[k]
        out[k, 1] = res_j[k]
    if m > 1:
        order = np.argsort(out[:, 0] * (n + 1) + out[:, 1])
        out = out[order]
    return out


@njit(cache=True)
def has_contact_grid(xy, margin):
    """Is any pair of non-adjacent segments closer than ``margin`` (0 = touching)?

    ``has_contact_grid(xy, 0.0)`` is :func:`has_intersection_grid`; a positive margin is the
    minimiser's clearance, which keeps its configurations robust to rounding (see
    :mod:`simulate.powell`).
    """
    n = xy.shape[0] - 1
    if n < 3:
        return False
    if margin <= 0.0:
        return has_intersection_grid(xy)
    xmin, ymin, h, nx, ny = _grid_setup(xy, margin)
    start, items = _grid_fill(xy, xmin, ymin, h, nx, ny, 0.0)
    seen = np.full(n, -1, np.int64)
    m2 = margin * margin
    for i in range(n):
        x0 = int((min(xy[i, 0], xy[i + 1, 0]) - margin - xmin) / h)
        x1 = int((max(xy[i, 0], xy[i + 1, 0]) + margin - xmin) / h)
        y0 = int((min(xy[i, 1], xy[i + 1, 1]) - margin - ymin) / h)
        y1 = int((max(xy[i, 1], xy[i + 1, 1]) + margin - ymin) / h)
        for cx in range(max(x0, 0), min(x1, nx - 1) + 1):
            for cy in range(max(y0, 0), min(y1, ny - 1) + 1):
                c = cx * ny + cy
                for p in range(start[c], start[c + 1]):
                    j = items[p]
                    if j < i + 2 or seen[j] == i:
                        continue
                    seen[j] = i
                    if seg_dist2(xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1],
                                 xy[j, 0], xy[j, 1], xy[j + 1, 0], xy[j + 1, 1]) < m2:
                        return True
    return False


def has_intersection(xy, method: str = "grid") -> bool:
    """Does the polyline ``xy`` (N+1, 2) intersect itself?

    Parameters
    ----------
    xy : (N+1, 2) array
    method : {"grid", "skip", "brute"}
        Detector (same answer; see module docstring).

    Returns
    -------
    bool
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    if method == "grid":
        return bool(has_intersection_grid(xy))
    if method == "skip":
        return bool(has_intersection_skip(xy))
    if method == "brute":
        return bool(has_intersection_brute(xy))
    raise ValueError(f"unknown method {method!r}")


__all__ = ["has_intersection", "has_intersection_brute", "has_intersection_skip",
           "has_intersection_grid", "has_contact_grid", "close_pairs", "seg_intersect", "seg_dist2"]
