"""Stage 8: stack widths from the distance transform, and the width -> layers calibration.

Paper, section "Image analysis procedure": the thickness of a stack gives its number of
branches through a calibration, because the hot-wire cut thickens stacks *nonlinearly*; the
calibration is the user's measurement (CSV ``n_layers,width_mm``) and is used as given.

Width along the skeleton
------------------------
For a band of ``w`` foreground pixels, the Euclidean distance transform (distance to the
nearest *background pixel centre*) along the cross-section is a tent peaking at
``D = w/2 + 1/2`` at the band's true centre line, which may lie between pixels.  Reading the
EDT only at the skeleton pixel gives ``2 d`` = ``w + 1`` (odd w) or ``w`` (even w), a +-0.5 px
ambiguity.  We instead sample the EDT (bilinear) one pixel on each side of the skeleton along
the local normal: for a tent, ``(d(-1) + d(+1)) / 2 + 1 = D`` exactly wherever the peak lies
within half a pixel, so ``width = d(-1) + d(+1) + 1``.  The residual bias, measured on bands
of known width 5..60 px at several angles (tests/test_widths.py), is below 0.3 px.
The per-stack value is the median along the path, skipping the parts within
``max(junction_margin_px, width)`` of a junction or a free end, where the mask widens (or
narrows); short stacks fall back to their central half. ``statistic="mean"`` (the analysis
option ``width_statistic``) takes the mean of the same samples instead: the samples skipped
are chosen from a median first estimate either way, so the two differ only where the
profile has outliers (a speck or a smear on the stack, a pinch).
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit
from scipy.ndimage import median_filter

from crosssection.core.calibration import Calibration
from crosssection.core.polyline import concat_paths
from crosssection.core.errors import ParameterError

__all__ = ["distance_map", "stack_widths", "stack_widths_px", "path_width_profile_px",
           "width_profiles_px", "layer_steps", "Calibration"]

#: A level of :func:`layer_steps` is at least this many of its own widths long.
STEP_SIDE_WIDTHS = 3.0
#: Largest distance (layers) of a smoothed sample to a whole number of layers on a level.
STEP_ON_LEVEL = 0.3
#: Longest transition between two levels of a step, in widths of the wider.
STEP_TRANSITION_WIDTHS = 3.0


def distance_map(mask) -> np.ndarray:
    """Euclidean distance of every pixel of a mask to the nearest pixel outside it, float32
    (0 outside the mask): the exact transform, as ``cv2.distanceTransform(mask, cv2.DIST_L2,
    cv2.DIST_MASK_PRECISE)`` gives it.

    Computed on the mask's pixels only (:func:`_distance_kernel`): on the dense 2000x2000
    benchmark scan (7 % ink) 7 ms against 17-33 ms for OpenCV on two threads and 43 ms on
    one. Bit for bit OpenCV's values on its multi-threaded path; on one thread (a batch
    worker) and on images under 2^14 px OpenCV calls IPP, whose square roots differ from the
    correctly rounded ones by one unit in the last place on about 1 % of the ink: here every
    analysis reads the same distances (the sample scans' tables were the same either way). A
    mask without a pixel outside it goes to OpenCV.

    Parameters
    ----------
    mask : (H, W) array of bool

    Returns
    -------
    (H, W) float32 array
    """
    m = np.ascontiguousarray(mask, dtype=bool)
    if m.ndim != 2:
        raise ParameterError(f"mask must be a 2-D array, got shape {m.shape}")
    flat = np.flatnonzero(m)
    if len(flat) == m.size:
        if m.size == 0:
            return np.zeros(m.shape, np.float32)
        return cv2.distanceTransform(m.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    out = np.zeros(m.size, np.float32)
    row_start = np.searchsorted(flat, np.arange(m.shape[0] + 1, dtype=np.int64) * m.shape[1])
    _distance_kernel(flat, row_start, m.shape[0], m.shape[1], out)
    return out.reshape(m.shape)


@njit(cache=True, nogil=True)
def _distance_kernel(flat, row_start, m, n, out):  # pragma: no cover - numba
    """Squared distances of the mask pixels ``flat`` (raster order; ``row_start[i]`` the first
    of row ``i``) to the nearest background pixel, their square roots written to ``out``.

    Felzenszwalb and Huttenlocher's two passes (as OpenCV), in integers and on the ink only:
    first the distance along each column to the background (none when the column's run of
    ink reaches the image's edge: beyond the edge is not background), then along each row
    the lower envelope of the parabolas ``(x - c)^2 + h_c``. For a pixel of a row's run of
    ink the nearest background pixel lies in a column of the run or in the background pixel
    just before or after it (one beyond is farther than that pixel), so the envelope of a run
    covers those columns only. Boundaries between parabolas are kept as exact fractions, the
    squared distance is an integer, and its float32 square root is correctly rounded.
    """
    k_n = flat.shape[0]
    none = np.int64(-1)
    h = np.empty(k_n, np.int64)  # squared distance along the column
    start = np.empty(n, np.int64)  # first row of each column's current run of ink
    last = np.full(n, -2, np.int64)  # last row of ink seen in each column
    for i in range(m):
        for k in range(row_start[i], row_start[i + 1]):
            j = flat[k] - i * n
            if last[j] != i - 1:
                start[j] = i
            last[j] = i
            d = i - start[j] + 1
            h[k] = d * d if start[j] > 0 else none
    stop = np.empty(n, np.int64)  # last row of each column's current run (upwards)
    last[:] = m + 1
    for i in range(m - 1, -1, -1):
        for k in range(row_start[i + 1] - 1, row_start[i] - 1, -1):
            j = flat[k] - i * n
            if last[j] != i + 1:
                stop[j] = i
            last[j] = i
            if stop[j] < m - 1:
                d = stop[j] - i + 1
                if h[k] == none or d * d < h[k]:
                    h[k] = d * d
    vc = np.empty(n + 2, np.int64)  # the envelope's parabolas: their columns and heights
    vh = np.empty(n + 2, np.int64)
    zn = np.empty(n + 3, np.int64)  # boundary between parabolas e - 1 and e: zn[e] / zd[e]
    zd = np.empty(n + 3, np.int64)
    for i in range(m):
        k = row_start[i]
        k_end = row_start[i + 1]
        while k < k_end:
            kb = k + 1
            while kb < k_end and flat[kb] == flat[kb - 1] + 1:
                kb += 1
            a = flat[k] - i * n  # the run's columns a .. b - 1
            b = a + (kb - k)
            top = -1
            for c in range(max(a - 1, 0), min(b + 1, n)):
                hc = np.int64(0) if (c < a or c >= b) else h[k + c - a]
                if hc == none:
                    continue
                while top > 0:  # drop the parabolas the new one hides
                    p = vc[top]
                    num = hc + c * c - vh[top] - p * p
                    if num * zd[top] > zn[top] * (2 * (c - p)):
                        break
                    top -= 1
                if top >= 0:
                    p = vc[top]
                    zn[top + 1] = hc + c * c - vh[top] - p * p
                    zd[top + 1] = 2 * (c - p)
                top += 1
                vc[top] = c
                vh[top] = hc
            e = 0
            for x in range(a, b):
                while e < top and zn[e + 1] < x * zd[e + 1]:
                    e += 1
                dx = x - vc[e]
                # the square root of the exact integer, in float64 then rounded once more:
                # correctly rounded in float32 (a float32 of the square would round it first
                # beyond 2^24, distances over 4096 px)
                out[flat[k + x - a]] = np.float32(math.sqrt(float(dx * dx + vh[e])))
            k = kb


def _segment_medians(values, seg, n_seg) -> np.ndarray:
    """``np.median`` of the values of every segment id ``0 .. n_seg - 1`` (NaN when empty),
    all at once; ``seg`` is ascending (each segment one run of ``values``) and the values
    finite (:func:`_run_medians`, whose selection compares them)."""
    offs = np.zeros(n_seg + 1, np.int64)
    np.cumsum(np.bincount(seg, minlength=n_seg), out=offs[1:])
    return _run_medians(np.ascontiguousarray(values, dtype=np.float64), offs)


@njit(cache=True, nogil=True)
def _run_medians(values, offs):  # pragma: no cover - numba
    """Median of every run ``values[offs[k]:offs[k + 1]]`` (NaN when empty): its middle
    element, or the mean of its two middle ones, as ``np.median`` returns them bit for bit.

    By selection in a copy of each run (Hoare's quickselect: no greater value before the
    middle one, no smaller after it). Compiled: 0.3 ms against 1.3 ms for one lexicographic
    sort of the 28 000 samples of a dense 2000x2000 scan by segment and value; numba's own
    ``np.median`` runs as fast but takes three times as long to compile.
    """
    n_seg = offs.shape[0] - 1
    out = np.full(n_seg, np.nan)
    buf = np.empty(values.shape[0])
    for k in range(n_seg):
        a = offs[k]
        n = offs[k + 1] - a
        if n == 0:
            continue
        for i in range(n):
            buf[i] = values[a + i]
        mid = (n - 1) // 2
        left, right = 0, n - 1
        while left < right:
            pivot = buf[(left + right) // 2]
            i, j = left, right
            while i <= j:
                while buf[i] < pivot:
                    i += 1
                while buf[j] > pivot:
                    j -= 1
                if i <= j:
                    buf[i], buf[j] = buf[j], buf[i]
                    i += 1
                    j -= 1
            if mid <= j:
                right = j
            elif mid >= i:
                left = i
            else:
                break
        if n % 2 == 1:
            out[k] = buf[mid]
        else:
            upper = buf[mid + 1]
            for i in range(mid + 2, n):
                if buf[i] < upper:
                    upper = buf[i]
            out[k] = (buf[mid] + upper) / 2
    return out


def _segment_means(values, seg, n_seg) -> np.ndarray:
    """Mean of the values of every segment id ``0 .. n_seg - 1`` (NaN when empty)."""
    lens = np.bincount(seg, minlength=n_seg)
    sums = np.bincount(seg, weights=values, minlength=n_seg)
    out = np.full(n_seg, np.nan)
    ok = lens > 0
    out[ok] = sums[ok] / lens[ok]
    return out


def _profiles_kernel(pr, pc, offs, half_windows, dist, step):
    """Width at every pixel of every path (see :func:`path_width_profile_px`).

    All path pixels of all stacks at once (concatenated, ``offs`` the CSR offsets): the local
    normal from a central difference over ``half_windows[k]`` pixels, then a walk outwards on
    each side in steps of ``step`` until the bilinearly interpolated mask ``dist > 0`` drops
    below 0.5 (or the walk leaves the band, ``|t| > EDT + 2``); the crossing is interpolated
    linearly between the last inside and first outside samples (:func:`_walk_widths`). Every
    corner of the bilinear cell of a sample closer than ``EDT - sqrt(2)`` to the skeleton
    pixel is ink, so a walk starts there and takes at most ``(1.6 + 2) / step`` samples.
    """
    n_tot = pr.shape[0]
    if n_tot == 0:
        return np.zeros(0)
    lens = np.diff(offs)
    seg = np.repeat(np.arange(len(lens)), lens)
    a = offs[:-1][seg]
    n = lens[seg]
    i = np.arange(n_tot) - a
    d_path = dist[pr, pc].astype(np.float64)
    hw_path = np.asarray(half_windows, np.int64).copy()
    default = (hw_path <= 0) & (lens > 0)
    if default.any():  # clip(median EDT along the path, 3, 15)
        med = _segment_medians(d_path, seg, len(lens))
        hw_path[default] = np.minimum(np.maximum(med[default], 3.0), 15.0).astype(np.int64)
    hw = hw_path[seg]
    lo = a + np.maximum(i - hw, 0)
    hi = a + np.minimum(i + hw, n - 1)
    tr = (pr[hi] - pr[lo]).astype(np.float64)
    tc = (pc[hi] - pc[lo]).astype(np.float64)
    nn = np.sqrt(tr * tr + tc * tc)
    nn[nn == 0.0] = 1.0
    nr = -(tc / nn)
    nc = tr / nn
    single = n < 2
    nr[single] = 1.0
    nc[single] = 0.0
    j0 = np.floor(np.maximum(d_path - 1.6, 0.0) / step).astype(np.int64)
    return _walk_widths(pr, pc, nr, nc, d_path, j0, dist, float(step))


@njit(cache=True, nogil=True)
def _walk_widths(pr, pc, nr, nc, d_path, j0, dist, step):  # pragma: no cover - numba
    """The walks of :func:`_profiles_kernel`: from sample ``j0 + 1`` outwards on each side
    (``+normal``, then ``-normal``) of every pixel until the bilinearly interpolated mask
    ``dist > 0`` (background off the image) drops below 0.5 or ``t > EDT + 2``; the width is
    the sum of the two interpolated crossings.

    Compiled, each walk stopping at its own crossing: 7 ms against about 30 ms for all walks
    advanced together by numpy (a dense 2000x2000 scan, 246 stacks), same values.
    """
    h, w = dist.shape
    n = pr.shape[0]
    out = np.empty(n)
    for i in range(n):
        half0 = 0.0
        for side in range(2):
            # the side's sign is folded into the direction: (side * t) * n == t * (side * n)
            dr = nr[i] if side == 0 else -nr[i]
            dc = nc[i] if side == 0 else -nc[i]
            limit = d_path[i] + 2.0
            prev_t = j0[i] * step
            prev_v = 1.0
            j = j0[i] + 1
            half = 0.0
            while True:
                t = j * step
                y = pr[i] + t * dr
                x = pc[i] + t * dc
                y0 = math.floor(y)
                x0 = math.floor(x)
                fy = y - y0
                fx = x - x0
                r = int(y0)
                c = int(x0)
                gx = 1.0 - fx
                gy = 1.0 - fy
                in_r0 = 0 <= r < h
                in_r1 = 0 <= r + 1 < h
                in_c0 = 0 <= c < w
                in_c1 = 0 <= c + 1 < w
                v = (gy * gx) if (in_r0 and in_c0 and dist[r, c] > 0) else 0.0
                v = v + ((gy * fx) if (in_r0 and in_c1 and dist[r, c + 1] > 0) else 0.0)
                v = v + ((fy * gx) if (in_r1 and in_c0 and dist[r + 1, c] > 0) else 0.0)
                v = v + ((fy * fx) if (in_r1 and in_c1 and dist[r + 1, c + 1] > 0) else 0.0)
                if t > limit:
                    v = 0.0
                if v < 0.5:
                    drop = prev_v - v
                    frac = (prev_v - 0.5) / drop if drop > 1e-12 else 0.0
                    half = prev_t + frac * step
                    break
                prev_t = t
                prev_v = v
                j += 1
            if side == 0:
                half0 = half
            else:
                out[i] = (0.0 + half0) + half
    return out


def _profiles(paths, dist, *, step_px=0.25, normal_half_window=None):
    """Width profiles of many paths at once: (flat profile, offsets, flat path)."""
    flat, offs = concat_paths(paths)
    dist = np.ascontiguousarray(dist, dtype=np.float32) if dist.dtype != np.float64 \
        else np.ascontiguousarray(dist)
    if len(flat) == 0:
        return np.zeros(0), offs, flat
    # half window <= 0: the kernel uses clip(median EDT, 3, 15) per path (a wider band needs
    # a better direction, the width error being w (1/cos(angle error) - 1))
    hw = np.full(len(paths), 0 if normal_half_window is None else int(normal_half_window),
                 np.int64)
    prof = _profiles_kernel(np.ascontiguousarray(flat[:, 0]), np.ascontiguousarray(flat[:, 1]),
                            offs, hw, dist, float(step_px))
    return prof, offs, flat


def width_profiles_px(paths, distance_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`path_width_profile_px` of many paths at once.

    Parameters
    ----------
    paths : list of (P, 2) int arrays
    distance_px : 2-D float array

    Returns
    -------
    profile : (N,) float array
        The widths (px) of all paths' pixels, concatenated.
    offsets : (M + 1,) int array
        Path ``i`` is ``profile[offsets[i]:offsets[i + 1]]``.
    """
    prof, offs, _ = _profiles([np.asarray(p).reshape(-1, 2) for p in paths],
                              np.asarray(distance_px))
    return prof, offs


def path_width_profile_px(path_rc: np.ndarray, distance_px: np.ndarray, *,
                          step_px: float = 0.25, normal_half_window: int | None = None
                          ) -> np.ndarray:
    """Local width (px) at every pixel of a skeleton path.

    Parameters
    ----------
    path_rc : (P, 2) int array
        Skeleton pixel path (row, col).
    distance_px : 2-D float array
        Euclidean distance transform of the foreground mask
        (``scipy.ndimage.distance_transform_edt(mask)``); the mask is ``distance_px > 0``
        and the EDT bounds how far to look.
    step_px : float
        Sampling step along the normal.
    normal_half_window : int, optional
        Half window (path pixels) of the central difference giving the local direction;
        default ``clip(median EDT, 3, 15)`` (a wider band needs a better direction, the
        width error being ``w (1/cos(angle error) - 1)``).

    Returns
    -------
    (P,) float array
        Distance between the two 0.5-crossings of the bilinearly interpolated mask along the
        local normal, on the run of foreground containing the skeleton pixel (the
        sub-pixel iso-contour of the binary image, as ``skimage.measure.find_contours`` at
        level 0.5 would place it).  Computed by walking outwards from each pixel, all pixels
        at once (``_profiles_kernel``): ``scipy.ndimage.map_coordinates`` per stack gives
        the same values (the reference in the tests) in 1.1 s instead of a few hundredths
        of a second on a 2000^2 scan with 244 stacks.
    """
    path = np.asarray(path_rc).reshape(-1, 2).astype(np.int64)
    if len(path) == 0:
        return np.zeros(0)
    prof, _, _ = _profiles([path], np.asarray(distance_px), step_px=step_px,
                           normal_half_window=normal_half_window)
    return prof


def _stack_medians(prof, pr, pc, offs, margin_abs, loop_u, loop_v, factor,
                   statistic="median"):
    """Per stack, the median (or mean) width away from its ends (:func:`stack_widths_px`).

    The samples kept are chosen with the median first estimate ``w0`` whatever the
    statistic, so that "mean" and "median" summarise the same samples.
    """
    m = offs.shape[0] - 1
    lens = np.diff(offs)
    seg = np.repeat(np.arange(m), lens)
    step = np.zeros(len(pr))
    dr = np.diff(pr).astype(np.float64)
    dc = np.diff(pc).astype(np.float64)
    step[1:] = np.sqrt(dr * dr + dc * dc)
    step[offs[:-1][lens > 0]] = 0.0
    # arc length from each path's start, a running sum per path (not a difference of one
    # global cumulative sum, which would round differently at the quarter points)
    s = np.empty(len(pr))
    for k in np.flatnonzero(lens):
        np.cumsum(step[offs[k]:offs[k + 1]], out=s[offs[k]:offs[k + 1]])
    total = np.zeros(m)
    total[lens > 0] = s[offs[1:][lens > 0] - 1]
    tot = total[seg]
    central = (s >= 0.25 * tot) & (s <= 0.75 * tot)
    has_central = np.bincount(seg[central], minlength=m) > 0
    # a stack too short for a central half (two pixels, say) takes all its samples
    short = ~has_central[seg]
    w0 = np.where(has_central, _segment_medians(prof[central], seg[central], m),
                  _segment_medians(prof[short], seg[short], m))
    margin = np.maximum(margin_abs, factor * w0)[seg]
    keep = np.ones(len(pr), np.bool_)
    keep &= loop_u[seg] | (s >= margin)
    keep &= loop_v[seg] | (s <= tot - margin)
    if statistic == "mean":
        w0 = np.where(has_central, _segment_means(prof[central], seg[central], m),
                      _segment_means(prof[short], seg[short], m))
        w_keep = _segment_means(prof[keep], seg[keep], m)
    else:
        w_keep = _segment_medians(prof[keep], seg[keep], m)
    return np.where(np.bincount(seg[keep], minlength=m) >= 3, w_keep, w0)


def stack_widths_px(graph, distance_px: np.ndarray, *, junction_margin_px: float,
                    margin_width_factor: float = 1.0, statistic: str = "median",
                    profiles=None) -> np.ndarray:
    """Width in pixels of every stack (median of the local width away from its ends).

    Parameters
    ----------
    graph : StackGraph
        Stage-6 graph (``paths``, ``ends``, ``node_kind``).
    distance_px : 2-D float array
        Euclidean distance transform of the cleaned mask.
    junction_margin_px : float
        Path pixels closer (in arc length) than ``max(junction_margin_px,
        margin_width_factor * w0)`` to an end at a junction or a free end are skipped, ``w0``
        being a first width estimate from the central half of the stack.  Loop nodes
        (closed loops without a junction) get no margin.
    margin_width_factor : float
        See above: a thick stack's junction blob extends about one width.
    statistic : {"median", "mean"}
        Summary of the local widths kept (or, for a stack with fewer than 3 of them, of
        its central half). The samples kept are the same for both.
    profiles : (profile, offsets), optional
        :func:`width_profiles_px` of the graph's paths, if already computed.

    Returns
    -------
    (M,) float array
        Width in px; NaN for an empty path.

    Raises
    ------
    ParameterError
        An unknown ``statistic``.
    """
    if statistic not in ("median", "mean"):
        raise ParameterError(f"width statistic must be 'median' or 'mean', got {statistic!r}")
    paths = [np.asarray(p).reshape(-1, 2) for p in graph.paths]
    if not paths:
        return np.zeros(0)
    if profiles is None:
        prof, offs, flat = _profiles(paths, np.asarray(distance_px))
    else:
        (prof, offs), (flat, _) = profiles, concat_paths(paths)
    kind = graph.node_kind
    loop_u = np.array([kind.get(u, "junction") == "loop" for u, _ in graph.ends], np.bool_)
    loop_v = np.array([kind.get(v, "junction") == "loop" for _, v in graph.ends], np.bool_)
    return _stack_medians(prof, np.ascontiguousarray(flat[:, 0]),
                          np.ascontiguousarray(flat[:, 1]), offs, float(junction_margin_px),
                          loop_u, loop_v, float(margin_width_factor), statistic)


def stack_widths(graph, distance_px: np.ndarray, *, px_per_mm: float,
                 junction_margin_px: float, margin_width_factor: float = 1.0) -> np.ndarray:
    """Width in mm of every stack; see :func:`stack_widths_px`.

    Parameters
    ----------
    graph : StackGraph
    distance_px : 2-D float array
        Euclidean distance transform of the cleaned mask.
    px_per_mm : float
        Scan resolution (50 in the paper).
    junction_margin_px : float
        Minimal arc length skipped at junction / free ends.
    margin_width_factor : float
        The skipped length is at least this many first-estimate widths.

    Returns
    -------
    (M,) float array
        ``width_mm`` per stack (NaN for an empty path).
    """
    if not px_per_mm > 0:
        raise ValueError("px_per_mm must be positive")
    return stack_widths_px(graph, distance_px, junction_margin_px=junction_margin_px,
                           margin_width_factor=margin_width_factor) / float(px_per_mm)


def layer_steps(graph, distance_px: np.ndarray, layers_of_px, *, thickness_px: float,
                side_widths: float = STEP_SIDE_WIDTHS, on_level: float = STEP_ON_LEVEL,
                max_transition_widths: float = STEP_TRANSITION_WIDTHS,
                profiles=None) -> dict:
    """Where a stack's layer count steps along it: some of its layers end inside the band.

    A rod end lying in a band, or passes folding back at a band's end while one pass goes on
    (a Z fold), leave ``n`` layers on one side and fewer on the other with no junction of the
    skeleton between them: the ink narrows, the skeleton runs on. Read as one stack, the band
    gets one count from its median width, and the rod length and energy are wrong by the
    missing layers over the other part (a 13-mm band of 5 layers read as one single sheet
    drops 52 mm of rod).

    The local width along each path (:func:`path_width_profile_px`) is turned into layers and
    smoothed by a running median over one band width. Runs of samples on one whole number of
    layers (within ``on_level``) at least ``side_widths`` times their own width long are the
    levels; two consecutive levels that differ, each at least ``side_widths`` widths of the
    wider long, with at most ``max_transition_widths`` such widths between them, are a step,
    placed at the middle of that transition. The parts
    within one width (and at least ``2 h``) of a junction or free end, where the ink widens
    into the junction or rounds off, are not read. A closed loop without junction (a rolled
    sheet, whose rod ends lie in the ring) is read all round and cut where it has two steps
    or more.

    Parameters
    ----------
    graph : StackGraph
    distance_px : 2-D float array
        Distance transform of the cleaned mask.
    layers_of_px : callable
        Width in px -> continuous number of layers (the calibration at the scan's scale).
    thickness_px : float
        Sheet thickness h in px.
    side_widths, on_level, max_transition_widths : float
        See above.
    profiles : (profile, offsets), optional
        :func:`width_profiles_px` of the graph's paths, if already computed.

    Returns
    -------
    dict stack_id -> list of int
        Path indices where each stack with steps is to be split (ascending).
    """
    paths = [np.asarray(p).reshape(-1, 2) for p in graph.paths]
    if profiles is None:
        profiles = width_profiles_px(paths, distance_px)
    prof, offs = profiles
    if len(prof) == 0:
        return {}
    # the calibration once on a grid of widths, then interpolated: its monotone inverse is
    # a bisection, 60 passes over every path pixel otherwise
    grid = np.linspace(0.0, float(np.nanmax(prof)) + 1.0, 512)
    lay = np.interp(prof, grid, np.asarray(layers_of_px(grid), float))
    is_loop = np.array([graph.node_kind.get(u) == "loop" for u, _ in graph.ends], bool)
    opts = dict(side_widths=side_widths, on_level=on_level,
                max_transition_widths=max_transition_widths)
    out = {}
    for sid in _step_candidates(lay, prof, offs, thickness_px, 1.0 - 2.0 * on_level,
                                is_loop):
        path = paths[sid]
        a, b = int(offs[sid]), int(offs[sid + 1])
        if is_loop[sid]:
            cuts = _loop_cuts(path, lay[a:b], prof[a:b], **opts)
        else:
            s = _arc(path)
            w = prof[a:b]
            lo = int(np.searchsorted(s, max(2.0 * thickness_px, w[0])))
            hi = int(np.searchsorted(s, s[-1] - max(2.0 * thickness_px, w[-1]), side="right"))
            cuts = [lo + c for c in _level_cuts(lay[a:b][lo:hi], w[lo:hi], s[lo:hi], **opts)]
        if cuts:
            out[sid] = cuts
    return out


def _arc(path) -> np.ndarray:
    """Arc length (px) along a pixel path, from 0 at its first pixel."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])


def _level_cuts(x, w, s, *, side_widths, on_level, max_transition_widths) -> list:
    """The steps of :func:`layer_steps` on one stretch of path: layers ``x``, widths ``w``
    (px) and arc length ``s`` of its samples; indices into the stretch."""
    if len(x) < 8:
        return []
    k = max(int(round(float(np.median(w)))) | 1, 5)
    xs = median_filter(x, size=k, mode="nearest")
    level = np.round(xs)
    runs = _level_runs(level, np.abs(xs - level) <= on_level, s, w, side_widths)
    cuts = []
    for (a0, b0, l0, w0), (a1, b1, l1, w1) in zip(runs[:-1], runs[1:]):
        wide = max(w0, w1)
        # both sides long against the wider band: a thin tail shorter than that is the
        # rounding of a band's end or a junction's ink, not a stack of its own
        if l0 != l1 and s[a1] - s[b0 - 1] <= max_transition_widths * wide \
                and min(s[b0 - 1] - s[a0], s[b1 - 1] - s[a1]) >= side_widths * wide:
            cuts.append((b0 - 1 + a1) // 2)
    return cuts


def _loop_cuts(path, x, w, **opts) -> list:
    """The steps of a closed loop without junction (a rolled sheet: its two rod ends lie in
    the ring's band), read from the middle of its longest stretch on one level so that the
    loop's arbitrary first pixel splits no level; at least two, or none (one step alone
    cannot close a ring)."""
    q = len(path) - 1  # the first pixel closes the loop
    if q < 16:
        return []
    k = max(int(round(float(np.median(w[:q])))) | 1, 5)
    level = np.round(median_filter(x[:q], size=k, mode="wrap"))
    change = np.flatnonzero(level != np.roll(level, 1))
    if len(change) < 2:
        return []
    gaps = np.diff(np.concatenate([change, [change[0] + q]]))
    i = int(np.argmax(gaps))
    start = int((change[i] + gaps[i] // 2) % q)
    order = (np.arange(q + 1) + start) % q
    cuts = _level_cuts(x[order], w[order], _arc(path[order]), **opts)
    cuts = sorted((c + start) % q for c in cuts)
    return cuts if len(cuts) >= 2 else []


def _step_candidates(lay, prof, offs, thickness_px, min_range, is_loop) -> np.ndarray:
    """Stacks whose layer profile, averaged over ``2 h`` and away from their ends, spans at
    least ``min_range`` layers: the only ones :func:`layer_steps` reads sample by sample
    (all stacks at once; 1 ms on a dense 2000x2000 scan, against 15 ms for reading
    every stack)."""
    lens = np.diff(offs)
    m = len(lens)
    seg = np.repeat(np.arange(m), lens)
    i = np.arange(len(lay)) - offs[:-1][seg]
    n = lens[seg]
    r = max(int(round(thickness_px)), 2)
    lo = offs[:-1][seg] + np.maximum(i - r, 0)
    hi = offs[:-1][seg] + np.minimum(i + r, n - 1)
    cs = np.concatenate([[0.0], np.cumsum(np.nan_to_num(lay))])
    mean = (cs[hi + 1] - cs[lo]) / (hi - lo + 1)
    # the ends' margins of layer_steps, in samples: a path step is 1 to sqrt(2) px long, so
    # a sample that layer_steps reads is at least margin / sqrt(2) samples from its end
    first = np.zeros(m)
    last = np.zeros(m)
    first[lens > 0] = np.maximum(2.0 * thickness_px, prof[offs[:-1][lens > 0]])
    last[lens > 0] = np.maximum(2.0 * thickness_px, prof[offs[1:][lens > 0] - 1])
    first[is_loop] = 0.0
    last[is_loop] = 0.0
    inner = (i >= first[seg] / np.sqrt(2.0)) & (i < n - last[seg] / np.sqrt(2.0))
    top = np.full(m, -np.inf)
    bottom = np.full(m, np.inf)
    np.maximum.at(top, seg[inner], mean[inner])
    np.minimum.at(bottom, seg[inner], mean[inner])
    return np.flatnonzero(top - bottom >= min_range)


def _level_runs(level, on, s, w, side_widths):
    """Maximal runs of on-level samples of one level, kept when ``side_widths`` times their
    median width long: ``(start, stop, level, width)``, consecutive kept runs of the same
    level merged."""
    runs = []
    i, n = 0, len(level)
    while i < n:
        if not on[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and on[j + 1] and level[j + 1] == level[i]:
            j += 1
        wr = float(np.median(w[i:j + 1]))
        if s[j] - s[i] >= side_widths * wr:
            if runs and runs[-1][2] == level[i]:
                runs[-1] = (runs[-1][0], j + 1, level[i], max(runs[-1][3], wr))
            else:
                runs.append((i, j + 1, level[i], wr))
        i = j + 1
    return runs
