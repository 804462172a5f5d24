"""Ordered point paths (polylines) in (row, col): length, mid-point and centreline smoothing.

One smoothing for every centreline of the toolkit (stack lengths, curvature), the paper's
"smoothed out by slide-averages along the stack trajectory" (Adda-Bedia, Boudaoud, Boué,
Deboeuf, "Statistical distributions in the folding of elastic structures", section "Image
analysis procedure").

**End rule.** In the interior (and everywhere on a closed loop) a point is replaced by the
uniform average of the ``2 k + 1`` consecutive points centred on it. Within ``k`` points of an
open end, where the centred window does not fit, it is replaced by the value at its index of
the least-squares quadratic (in the point index) through the first (last) ``2 k + 1`` points.
So the end pixels, where skeletons fork or kink into a junction, are smoothed about as much as
the rest, and neither straight lines nor circular arcs are bent: a window shrinking to the end
point leaves the end raw (staircase and fork hook kept), a linear end fit straightens arcs
(measured: ~10 % of an arc's mean curvature lost on skeletons of drawn arcs). A quadratic
reproduces a uniformly sampled line exactly and a uniformly sampled arc to O((k / R)^2).

A uniform average over an arc of radius R shrinks it by about ``k (k + 1) / (6 R^2)`` (in
units of the sample spacing; 0.06 % for k = 2, R = 40 px): negligible, not corrected.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from crosssection.core.errors import ParameterError

__all__ = ["length", "mid_point", "smooth", "smooth_paths", "smoothed_lengths", "is_closed",
           "concat_paths", "walk_ends", "grouped_axes"]


def concat_paths(paths, dtype=np.int64) -> tuple[np.ndarray, np.ndarray]:
    """Paths in one array: ``(flat, offsets)``, path ``i`` being
    ``flat[offsets[i]:offsets[i + 1]]`` ((N, 2) of ``dtype``, pixels by default; ``(0, 2)``
    when all are empty)."""
    lens = np.fromiter((len(p) for p in paths), dtype=np.int64, count=len(paths))
    offs = np.zeros(len(paths) + 1, dtype=np.int64)
    np.cumsum(lens, out=offs[1:])
    if offs[-1]:
        flat = np.concatenate([np.asarray(p, dtype=dtype).reshape(-1, 2) for p in paths])
    else:
        flat = np.zeros((0, 2), dtype)
    return flat, offs


def ranges(lo, hi):
    """The indices ``lo[i]:hi[i]`` of many ranges, one range after the other.

    Returns
    -------
    idx : ndarray (L,) int
    pos, n : ndarray (M,) int
        Each range's first position in ``idx``, and its length (0 where ``hi <= lo``).
    """
    n = np.maximum(hi - lo, 0)
    pos = np.zeros(len(n), np.int64)
    np.cumsum(n[:-1], out=pos[1:])
    return np.arange(int(n.sum())) + np.repeat(lo - pos, n), pos, n


def walk_ends(offs, sids, rev):
    """The points of many paths of one flat array, each walked from one of its ends.

    Parameters
    ----------
    offs : ndarray (P + 1,) int
        Offsets of the flat array (:func:`concat_paths`).
    sids : ndarray (Q,) int
        The path of every walk.
    rev : ndarray (Q,) bool
        Walk from the path's last point instead of its first.

    Returns
    -------
    walk, pos, idx : ndarray (M,) int
        For every point of every walk, one walk after the other: its walk, its position along
        the walk, and its index in the flat array.
    lens : ndarray (Q,) int
        Length of every walk.
    """
    a = offs[sids]
    lens = offs[sids + 1] - a
    walk = np.repeat(np.arange(len(sids)), lens)
    pos = np.arange(len(walk)) - np.repeat(np.cumsum(lens) - lens, lens)
    idx = a[walk] + np.where(rev[walk], lens[walk] - 1 - pos, pos)
    return walk, pos, idx, lens


def grouped_axes(groups, rows, cols, pos, n_groups: int):
    """Principal axis of many groups of points at once (closed-form 2 x 2 PCA).

    Per-group sums are ``np.bincount`` sums, which add in the points' order as a loop would.

    Parameters
    ----------
    groups : ndarray (M,) int
        Group of every point, in ``[0, n_groups)``.
    rows, cols : ndarray (M,) float
        The points.
    pos : ndarray (M,) int
        Position of every point along its group's walk.
    n_groups : int

    Returns
    -------
    count : ndarray (G,) int
    mean_r, mean_c : ndarray (G,) float
        Mean point (0 for an empty group).
    angle : ndarray (G,) float
        Direction of the principal axis, ``(cos, sin)`` of it in (row, col); its sign is
        arbitrary.
    first, last : ndarray (G,) int
        Least and largest position in the group (int64 max and -1 for an empty group).
    """
    count = np.bincount(groups, minlength=n_groups)
    cn = np.maximum(count, 1)
    mean_r = np.bincount(groups, weights=rows, minlength=n_groups) / cn
    mean_c = np.bincount(groups, weights=cols, minlength=n_groups) / cn
    dr = rows - mean_r[groups]
    dc = cols - mean_c[groups]
    vrr = np.bincount(groups, weights=dr * dr, minlength=n_groups)
    vcc = np.bincount(groups, weights=dc * dc, minlength=n_groups)
    vrc = np.bincount(groups, weights=dr * dc, minlength=n_groups)
    first = np.full(n_groups, np.iinfo(np.int64).max)
    last = np.full(n_groups, -1)
    np.minimum.at(first, groups, pos)
    np.maximum.at(last, groups, pos)
    angle = 0.5 * np.arctan2(2.0 * vrc, vrr - vcc)
    return count, mean_r, mean_c, angle, first, last


def _as_points(path_rc) -> np.ndarray:
    p = np.asarray(path_rc, dtype=np.float64)
    if p.size and (p.ndim != 2 or p.shape[1] != 2):
        # reshaped, an (N, 3) array would read as a path of 1.5 N points
        raise ParameterError(f"a path must be an (N, 2) array of (row, col) points, got "
                             f"shape {p.shape}")
    return p.reshape(-1, 2)


def _ring(p: np.ndarray) -> np.ndarray:
    """Distinct points of a closed loop (a repeated closing point dropped)."""
    if len(p) > 3 and p[0, 0] == p[-1, 0] and p[0, 1] == p[-1, 1]:
        return p[:-1]
    return p


def is_closed(path_rc) -> bool:
    """Whether a pixel path is a closed loop: first and last pixels equal or 8-neighbours
    (for float points: at most 1 px apart along each axis), with more than 3 points."""
    p = np.asarray(path_rc)
    if len(p) < 4:
        return False
    if p.dtype.kind == "f":
        # truncated to pixels, ends 2.8 px apart could read as neighbours
        return bool(np.abs(p[0] - p[-1]).max() <= 1.0)
    d = np.abs(p[0].astype(np.int64) - p[-1].astype(np.int64))
    return bool(d.max() <= 1)


def length(path_rc, *, closed: bool = False) -> float:
    """Length of a polyline, in the units of its coordinates.

    Parameters
    ----------
    path_rc : array (P, 2)
        Ordered (row, col) points.
    closed : bool
        Add the segment from the last point back to the first (nothing is added when the
        last point repeats the first).

    Returns
    -------
    float
        0 for fewer than two points.
    """
    p = _as_points(path_rc)
    if len(p) < 2:
        return 0.0
    total = float(np.hypot(*np.diff(p, axis=0).T).sum())
    if closed:
        total += float(np.hypot(*(p[0] - p[-1])))
    return total


def mid_point(path_rc, *, closed: bool = False) -> np.ndarray:
    """Point at half the arc length of a polyline, by linear interpolation.

    Parameters
    ----------
    path_rc : array (P, 2)
        Ordered (row, col) points.
    closed : bool
        The loop starts at its first point and includes the closing segment.

    Returns
    -------
    ndarray (2,)
        (row, col); NaN for an empty path, the point itself for a single point.
    """
    p = _as_points(path_rc)
    if len(p) == 0:
        return np.full(2, np.nan)
    if closed and len(p) > 1:
        p = np.vstack([p, p[:1]])
    seg = np.hypot(*np.diff(p, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] == 0.0:
        return p[0].copy()
    return np.array([np.interp(0.5 * s[-1], s, p[:, 0]), np.interp(0.5 * s[-1], s, p[:, 1])])


@lru_cache(maxsize=64)
def _end_projector(k: int) -> np.ndarray:
    """(k, 2k+1) least-squares quadratic through 2k + 1 points, evaluated at the first k."""
    t = np.arange(2 * k + 1, dtype=np.float64)
    V = np.vander(t, 3)
    proj = V[:k] @ np.linalg.pinv(V)
    proj.setflags(write=False)
    return proj


def _smooth_into(x, y, k, closed, proj, ox, oy):
    """Smooth (x, y) into (ox, oy): module rule, window 2k + 1 (k already fits the path).

    Vectorised over the points; every output is the same sum, in the same order, as a
    point-by-point loop would form (left to right from 0.0).
    """
    n = x.shape[0]
    w = 2 * k + 1
    if closed:
        i = np.arange(n)
        sx = np.zeros(n)
        sy = np.zeros(n)
        for d in range(-k, k + 1):
            q = (i + d) % n
            sx = sx + x[q]
            sy = sy + y[q]
        ox[:] = sx / w
        oy[:] = sy / w
        return
    sx = np.zeros(n - 2 * k)
    sy = np.zeros(n - 2 * k)
    for d in range(-k, k + 1):
        sx = sx + x[k + d:n - k + d]
        sy = sy + y[k + d:n - k + d]
    ox[k:n - k] = sx / w
    oy[k:n - k] = sy / w
    ax = np.zeros(k)
    ay = np.zeros(k)
    bx = np.zeros(k)
    by = np.zeros(k)
    for j in range(w):
        ax = ax + proj[:k, j] * x[j]
        ay = ay + proj[:k, j] * y[j]
        bx = bx + proj[:k, j] * x[n - 1 - j]
        by = by + proj[:k, j] * y[n - 1 - j]
    ox[:k] = ax
    oy[:k] = ay
    ox[n - 1 - np.arange(k)] = bx
    oy[n - 1 - np.arange(k)] = by


def _half_window(window_px, n: int, closed: bool) -> int:
    if isinstance(window_px, bool) or not np.isfinite(window_px) or window_px < 0:
        raise ParameterError(f"the smoothing window must be a finite number of points >= 0, "
                             f"got {window_px!r}")
    k = max(0, int(window_px)) // 2
    return max(0, min(k, (n - 1) // 2))


def smooth(path_rc, *, window_px: int = 5, closed: bool = False) -> np.ndarray:
    """Sliding average of an ordered path with the module's end rule.

    Parameters
    ----------
    path_rc : array (P, 2)
        Ordered (row, col) points, one per skeleton pixel.
    window_px : int
        Points averaged, made odd (``2 k + 1``; reduced to fit short paths; 1 = none).
    closed : bool
        Periodic (a closed loop); a last point repeating the first is kept repeated.

    Returns
    -------
    ndarray (P, 2) float
    """
    p = _as_points(path_rc)
    ring = _ring(p) if closed else p
    n = len(ring)
    k = _half_window(window_px, n, closed)
    if n < 3 or k < 1:
        return p.copy()
    ox = np.empty(n)
    oy = np.empty(n)
    proj = _end_projector(k) if not closed else np.zeros((1, 1))
    _smooth_into(np.ascontiguousarray(ring[:, 0]), np.ascontiguousarray(ring[:, 1]), k,
                 bool(closed), proj, ox, oy)
    out = np.stack([ox, oy], axis=1)
    if len(ring) != len(p):
        out = np.vstack([out, out[:1]])
    return out


def _smooth_flat(r, c, offs, closed, half, projs):
    """:func:`smooth` of all paths at once (flat ``r``, ``c``; path ``i`` is
    ``offs[i]:offs[i + 1]``), vectorised over all paths of the same half window.

    Returns
    -------
    ox, oy : ndarray (N,)
        The smoothed points; a closed loop's repeated closing point is left at 0.
    n : ndarray (M,) int
        Points of each path that were smoothed (the closing point dropped).
    """
    a = offs[:-1]
    n = np.diff(offs)
    ring = closed & (n > 3)
    ring[ring] = (r[a[ring]] == r[offs[1:][ring] - 1]) & (c[a[ring]] == c[offs[1:][ring] - 1])
    n = n - ring  # a closed loop's repeated closing point is dropped
    k = np.minimum(half, (n - 1) // 2)
    k[n < 3] = 0
    ox = np.zeros(len(r))
    oy = np.zeros(len(r))
    for kk in np.unique(k[n >= 2]):
        for cl in (False, True):
            sel = np.flatnonzero((k == kk) & (n >= 2) & (closed == cl))
            if len(sel):
                _smooth_many(r, c, a[sel], n[sel], int(kk), cl, projs[kk], ox, oy)
    return ox, oy, n


class _end_projectors(dict):
    """The end projectors of half windows 0..``half``, ``[k]`` of shape (k, 2k + 1), made
    when first asked for: only the half windows the paths use (a path shorter than its
    window takes a shorter one): all of them at once would take (half + 1) half
    (2 half + 1) floats, 233 GiB at a 5001-px window."""

    def __init__(self, half: int):
        super().__init__()
        self.half = int(half)

    def __missing__(self, k: int) -> np.ndarray:
        if not 0 <= k <= self.half:
            raise KeyError(k)
        proj = _end_projector(k) if k else np.zeros((0, 1))
        self[k] = proj
        return proj


def _lengths_kernel(r, c, offs, closed, half, projs):
    """Lengths of all paths after :func:`smooth` (see :func:`smoothed_lengths`).

    The smoothing is vectorised over all paths of the same half window at once; each length
    is then a running sum along its path, as a point-by-point loop forms it.
    """
    m = offs.shape[0] - 1
    out = np.zeros(m)
    a = offs[:-1]
    ox, oy, n = _smooth_flat(r, c, offs, closed, half, projs)
    paths = np.flatnonzero(n >= 2)
    if len(paths) == 0:
        return out
    step = np.hypot(np.diff(ox), np.diff(oy))  # step t joins points t and t + 1
    n_steps = n[paths] - 1
    out[paths] = _running_totals(step, a[paths], n_steps)
    cl = paths[closed[paths]]
    last = a[cl] + n[cl] - 1
    out[cl] += np.hypot(ox[a[cl]] - ox[last], oy[a[cl]] - oy[last])
    return out


def _running_totals(values, starts, lens) -> np.ndarray:
    """``sum(values[s:s + n])`` for every (s, n), each summed left to right from 0.0 (the
    rounding of a point-by-point loop, which neither ``np.add.reduceat`` nor differences of
    one cumulative sum reproduce; ``np.bincount`` adds its weights in input order)."""
    rows = np.repeat(np.arange(len(lens)), lens)
    cols = np.arange(len(rows)) - np.repeat(np.cumsum(lens) - lens, lens)
    return np.bincount(rows, weights=values[np.repeat(starts, lens) + cols],
                       minlength=len(lens))


def _smooth_many(r, c, starts, lens, k, closed, proj, ox, oy):
    """:func:`_smooth_into` for many paths of half window ``k`` (flat ``r``, ``c``; path
    ``i`` is ``starts[i] .. starts[i] + lens[i]``), written into ``ox``, ``oy``."""
    if k < 1:
        idx = ranges(starts, starts + lens)[0]
        ox[idx] = r[idx]
        oy[idx] = c[idx]
        return
    w = 2 * k + 1
    if closed:
        seg = np.repeat(np.arange(len(starts)), lens)
        pos = np.arange(len(seg)) - np.repeat(np.cumsum(lens) - lens, lens)  # index in its path
        base = starts[seg]
        nn = lens[seg]
        tgt = base + pos
        sx = np.zeros(len(seg))
        sy = np.zeros(len(seg))
        for d in range(-k, k + 1):
            q = base + (pos + d) % nn
            sx = sx + r[q]
            sy = sy + c[q]
        ox[tgt] = sx / w
        oy[tgt] = sy / w
        return
    tgt = ranges(starts + k, starts + lens - k)[0]
    if 4 * len(tgt) > len(r):
        # most points of the scan: shifted slices of the flat arrays, not gathers (the
        # windows that cross from one path into the next are summed, not used)
        s = np.zeros((2, len(r) - 2 * k))
        xy = np.stack([r, c])
        for d in range(-k, k + 1):
            np.add(s, xy[:, k + d:len(r) - k + d], out=s)
        np.divide(s, w, out=s)
        keep = np.zeros(len(r) - 2 * k, np.bool_)
        keep[tgt - k] = True
        np.copyto(ox[k:len(r) - k], s[0], where=keep)
        np.copyto(oy[k:len(r) - k], s[1], where=keep)
    else:
        sx = np.zeros(len(tgt))
        sy = np.zeros(len(tgt))
        for d in range(-k, k + 1):
            sx = sx + r[tgt + d]
            sy = sy + c[tgt + d]
        ox[tgt] = sx / w
        oy[tgt] = sy / w
    # the i-th point (i < k) from the start and from the end of every path, all at once:
    # (start x, start y, end x, end y) x i x path
    last = starts + lens - 1
    at = np.stack([starts, starts + len(r), last, last + len(r)])
    step = np.array([[1], [1], [-1], [-1]])
    rc = np.concatenate([r, c])
    acc = np.zeros((4, k, len(starts)))
    for j in range(w):
        acc = acc + proj[:k, j, None] * rc[at + step * j][:, None, :]
    first = starts + np.arange(k)[:, None]
    end = last - np.arange(k)[:, None]
    ox[first], oy[first], ox[end], oy[end] = acc


def smoothed_lengths(points_rc, offsets, closed, *, window_px: int = 5) -> np.ndarray:
    """Lengths of many paths after :func:`smooth`, in one compiled pass.

    Parameters
    ----------
    points_rc : array (N, 2)
        All paths' points concatenated.
    offsets : int array (M + 1,)
        Path ``i`` is ``points_rc[offsets[i]:offsets[i + 1]]``.
    closed : bool array (M,)
        Which paths are closed loops.
    window_px : int
        As in :func:`smooth`.

    Returns
    -------
    ndarray (M,)
        ``length(smooth(path, window_px=window_px, closed=c), closed=c)`` for every path.
    """
    p = _as_points(points_rc)
    offs = np.asarray(offsets, dtype=np.int64)
    cl = np.asarray(closed, dtype=np.bool_).reshape(-1)
    half = max(0, int(window_px) // 2)
    if len(offs) < 2:
        return np.zeros(0)
    return _lengths_kernel(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
                           offs, cl, half, _end_projectors(half))


def smooth_paths(paths, *, window_px: int = 5, closed=False) -> list:
    """:func:`smooth` of many paths, vectorised over them (the same values, point by point).

    One call of :func:`smooth` per path costs about 0.1 ms of numpy overhead at an 11-point
    window: 29 ms for the 246 stacks of a dense 2000x2000 scan against 1 ms here. The paths
    returned share one array.

    Parameters
    ----------
    paths : sequence of arrays (P, 2)
        Ordered (row, col) points of every path.
    window_px : int
        As in :func:`smooth`.
    closed : bool or sequence of bool
        Which paths are closed loops (one value for all, or one per path).

    Returns
    -------
    list of ndarray (P, 2) float
        ``smooth(path, window_px=window_px, closed=c)`` for every path.
    """
    pts = [_as_points(p) for p in paths]
    m = len(pts)
    if m == 0:
        return []
    cl = np.broadcast_to(np.asarray(closed, dtype=np.bool_), (m,)).copy()
    lens = np.fromiter((len(p) for p in pts), np.int64, count=m)
    offs = np.zeros(m + 1, np.int64)
    np.cumsum(lens, out=offs[1:])
    flat = np.concatenate(pts) if offs[-1] else np.zeros((0, 2))
    r = np.ascontiguousarray(flat[:, 0])
    c = np.ascontiguousarray(flat[:, 1])
    half = max(0, int(window_px) // 2)
    ox, oy, n = _smooth_flat(r, c, offs, cl, half, _end_projectors(half))
    out = np.stack([ox, oy], axis=1)
    res = []
    bounds = offs.tolist()
    for i, k in enumerate(n.tolist()):
        a, b = bounds[i], bounds[i + 1]
        if k < 3 or min(half, (k - 1) // 2) < 1:
            res.append(pts[i].copy())
            continue
        # the paths share the array of the smoothed points
        o = out[a:a + k]
        res.append(np.vstack([o, o[:1]]) if k != b - a else o)
    return res
