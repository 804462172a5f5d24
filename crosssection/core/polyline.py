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
from numba import njit

__all__ = ["length", "mid_point", "smooth", "smoothed_lengths", "is_closed"]


def _as_points(path_rc) -> np.ndarray:
    return np.asarray(path_rc, dtype=np.float64).reshape(-1, 2)


def _ring(p: np.ndarray) -> np.ndarray:
    """Distinct points of a closed loop (a repeated closing point dropped)."""
    if len(p) > 3 and p[0, 0] == p[-1, 0] and p[0, 1] == p[-1, 1]:
        return p[:-1]
    return p


def is_closed(path_rc) -> bool:
    """Whether a pixel path is a closed loop: first and last pixels equal or 8-neighbours,
    with more than 3 points."""
    p = np.asarray(path_rc)
    if len(p) < 4:
        return False
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


@njit(cache=True)
def _smooth_into(x, y, k, closed, proj, ox, oy):
    """Smooth (x, y) into (ox, oy): module rule, window 2k + 1 (k already fits the path)."""
    n = x.shape[0]
    w = 2 * k + 1
    if closed:
        for i in range(n):
            sx = 0.0
            sy = 0.0
            for d in range(-k, k + 1):
                q = (i + d) % n
                sx += x[q]
                sy += y[q]
            ox[i] = sx / w
            oy[i] = sy / w
        return
    for i in range(k, n - k):
        sx = 0.0
        sy = 0.0
        for d in range(-k, k + 1):
            sx += x[i + d]
            sy += y[i + d]
        ox[i] = sx / w
        oy[i] = sy / w
    for i in range(k):
        ax = 0.0
        ay = 0.0
        bx = 0.0
        by = 0.0
        for j in range(w):
            ax += proj[i, j] * x[j]
            ay += proj[i, j] * y[j]
            bx += proj[i, j] * x[n - 1 - j]
            by += proj[i, j] * y[n - 1 - j]
        ox[i] = ax
        oy[i] = ay
        ox[n - 1 - i] = bx
        oy[n - 1 - i] = by


def _half_window(window_px, n: int, closed: bool) -> int:
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


@njit(cache=True)
def _lengths_kernel(r, c, offs, closed, half, projs):
    m = offs.shape[0] - 1
    out = np.zeros(m)
    for i in range(m):
        a = offs[i]
        b = offs[i + 1]
        n = b - a
        if closed[i] and n > 3 and r[a] == r[b - 1] and c[a] == c[b - 1]:
            n -= 1
        if n < 2:
            continue
        k = min(half, (n - 1) // 2)
        x = r[a:a + n]
        y = c[a:a + n]
        ox = np.empty(n)
        oy = np.empty(n)
        if n < 3 or k < 1:
            ox[:] = x
            oy[:] = y
        else:
            _smooth_into(x, y, k, closed[i], projs[k], ox, oy)
        total = 0.0
        for j in range(n - 1):
            total += np.hypot(ox[j + 1] - ox[j], oy[j + 1] - oy[j])
        if closed[i]:
            total += np.hypot(ox[0] - ox[n - 1], oy[0] - oy[n - 1])
        out[i] = total
    return out


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
    # a fixed-size stack of end projectors, one per half window 0..half (row k used for k)
    projs = np.zeros((half + 1, max(half, 1), 2 * half + 1))
    for k in range(1, half + 1):
        projs[k, :k, :2 * k + 1] = _end_projector(k)
    if len(offs) < 2:
        return np.zeros(0)
    return _lengths_kernel(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
                           offs, cl, half, projs)
