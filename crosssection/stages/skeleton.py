"""Stage 4: a one-pixel skeleton without redundant kinks, spurs shorter than ``l_min`` pruned.

Paper, section "Image analysis procedure": "the binary image is skeletonized -- reduced to a one
pixel thick skeleton, without redundant kinks". Three steps, all in numba:

1. Zhang-Suen thinning (Zhang & Suen, Commun. ACM 27, 1984), the algorithm behind
   ``skimage.morphology.skeletonize`` in 2D. Ours visits only the current border pixels instead
   of sweeping the whole image at every sub-iteration, and deletes the pixels flagged by a
   sub-iteration one after the other, re-checking on the current image that each is still a
   simple point and not an end point: the parallel algorithm's known failures (2x2 squares and
   two-pixel-thick diagonal lines vanishing) cannot break a stack. Measured on a 2000x2000 scan
   mask (16 % ink, bands 5-60 px): 0.04 s against 0.38 s for ``skimage.morphology.skeletonize``
   (``thin`` takes 7.8 s); the skeletons differ only by single pixels.
2. Removal of redundant pixels: any skeleton pixel that is a simple point (8-connected
   foreground, 4-connected background) with two or more neighbours is deleted, sequentially,
   until none is left. This removes the staircase corners that Zhang-Suen leaves (a pixel whose
   two neighbours touch each other diagonally), which would otherwise be read as false junctions
   (>= 3 neighbours); the skeleton becomes 8-connected minimal with the same topology.
3. Spur pruning: from every free end, walk along the skeleton; if a junction pixel (>= 3
   neighbours) is reached before the walked length (1 per axial step, sqrt 2 per diagonal step,
   from the free end to the junction pixel) reaches ``l_min_px``, the walked pixels are deleted.
   Spurs are deleted shortest first and the procedure repeats until nothing changes, so a spur
   on a spur is pruned too. A segment whose walk reaches another free end (no junction) is never
   pruned, so an isolated stack is never pruned to nothing; closed loops have no free end and
   are never touched. Removing a spur can leave a redundant pixel at its junction, so step 2 is
   run again.
"""
from __future__ import annotations

import cv2
import numpy as np
from numba import njit
from scipy import ndimage as ndi

from crosssection.core.errors import ParameterError

# neighbour offsets, clockwise from north: P2..P9 of Zhang & Suen (bit k = offset k)
_DR = np.array([-1, -1, 0, 1, 1, 1, 0, -1], dtype=np.int64)
_DC = np.array([0, 1, 1, 1, 0, -1, -1, -1], dtype=np.int64)


def _build_luts():
    """Lookup tables over the 256 neighbourhood codes (bit k set = neighbour k foreground).

    Returns ``zs1``, ``zs2`` (Zhang-Suen deletion conditions of the two sub-iterations),
    ``simple`` (deleting the centre changes neither the number of 8-connected foreground
    components nor of 4-connected background components) and ``count`` (number of neighbours).
    """
    zs1 = np.zeros(256, np.bool_)
    zs2 = np.zeros(256, np.bool_)
    simple = np.zeros(256, np.bool_)
    count = np.zeros(256, np.uint8)
    eight = np.ones((3, 3), bool)
    four = ndi.generate_binary_structure(2, 1)
    for code in range(256):
        p = [(code >> k) & 1 for k in range(8)]  # p[0] = P2 (north), ..., p[7] = P9 (north-west)
        b = sum(p)
        a = sum(1 for k in range(8) if p[k] == 0 and p[(k + 1) % 8] == 1)
        count[code] = b
        p2, p3, p4, p5, p6, p7, p8, p9 = p
        base = 2 <= b <= 6 and a == 1
        zs1[code] = base and p2 * p4 * p6 == 0 and p4 * p6 * p8 == 0
        zs2[code] = base and p2 * p4 * p8 == 0 and p2 * p6 * p8 == 0
        nb = np.zeros((3, 3), bool)
        for k in range(8):
            nb[1 + _DR[k], 1 + _DC[k]] = p[k]
        _, n_fg = ndi.label(nb, structure=eight)
        bg = ~nb
        bg[1, 1] = False
        lab, _ = ndi.label(bg, structure=four)
        # background components 4-adjacent to the centre
        n_bg = len({lab[0, 1], lab[1, 0], lab[1, 2], lab[2, 1]} - {0})
        simple[code] = n_fg == 1 and n_bg == 1
    return zs1, zs2, simple, count


_ZS1, _ZS2, _SIMPLE, _COUNT = _build_luts()


@njit(cache=True)
def _zhang_suen(f, offs, lst, n, st, flags, zs1, zs2, simple, count):  # pragma: no cover - numba
    """Zhang-Suen thinning of the flat padded uint8 image ``f`` in place.

    ``offs``: flat offsets of the 8 neighbours, clockwise from north (:func:`_offsets`).

    ``lst[:n]`` holds the flat indices of the initial border pixels (foreground with a
    background 8-neighbour): interior pixels have 8 neighbours and cannot be deleted before a
    neighbour is. A pixel is re-examined in a sub-iteration only if its neighbourhood changed
    since it was last examined in that sub-iteration (same result as examining every pixel,
    about 4x fewer visits). ``lst`` and ``flags`` have room for every foreground pixel (a
    pixel is in the list at most once); ``st`` is a zeroed uint8 state per pixel.

    Only loops and indexing on arrays allocated by the caller, so that the kernel compiles in
    a fraction of a second.
    """
    for i in range(n):
        st[lst[i]] = 7
    changed = True
    while changed and n > 0:
        changed = False
        for sub in range(2):
            lut = zs1 if sub == 0 else zs2
            bit = 2 if sub == 0 else 4
            nf = 0
            for i in range(n):
                p = lst[i]
                s = st[p]
                if s & bit:
                    st[p] = s & ~bit
                    code = 0
                    for k in range(8):
                        code |= f[p + offs[k]] << k
                    if lut[code]:
                        flags[nf] = p
                        nf += 1
            # sequential deletion with a topology re-check on the current image
            for i in range(nf):
                p = flags[i]
                code = 0
                for k in range(8):
                    code |= f[p + offs[k]] << k
                if simple[code] and count[code] >= 2:
                    f[p] = 0
                    changed = True
                    for k in range(8):
                        q = p + offs[k]
                        if f[q]:
                            if not (st[q] & 1):
                                lst[n] = q
                                n += 1
                            st[q] = 7
            # keep only the pixels still to examine
            m = 0
            for i in range(n):
                p = lst[i]
                if f[p] and (st[p] & 6):
                    lst[m] = p
                    m += 1
                else:
                    st[p] = 0
            n = m


@njit(cache=True)
def _remove_redundant(f, offs, idx, m, simple, count):  # pragma: no cover - numba
    """Delete simple non-end pixels of ``f`` (flat indices ``idx[:m]``, in order) sequentially
    until none is left; compact the survivors to the front of ``idx`` and return their
    number."""
    changed = True
    while changed:
        changed = False
        for i in range(m):
            p = idx[i]
            if f[p]:
                code = 0
                for k in range(8):
                    code |= f[p + offs[k]] << k
                if count[code] >= 2 and simple[code]:
                    f[p] = 0
                    changed = True
    k = 0
    for i in range(m):
        if f[idx[i]]:
            idx[k] = idx[i]
            k += 1
    return k


@njit(cache=True)
def _spurs(f, offs, idx, m, l_min, count, buf, ends, lens, cut):  # pragma: no cover - numba
    """Free ends whose walk reaches a junction pixel before ``l_min``.

    ``cut`` False: scan the free ends among ``idx[:m]`` and store those spurs' end pixels and
    lengths in ``ends``, ``lens``; return their number. ``cut`` True: ``idx[:m]`` are such end
    pixels (in the order to process); walk each again on the current image and delete it if
    it is still a spur; return the number of pixels deleted.

    The walk from a free end: 1 per axial step, sqrt 2 per diagonal step, until a pixel with
    >= 3 neighbours (a junction: a spur), another free end or the length ``l_min`` (not a
    spur); the walked pixels are kept in ``buf``.
    """
    nk = 0
    removed = 0
    for i in range(m):
        p0 = idx[i]
        if not f[p0]:
            continue
        code = 0
        for k in range(8):
            code |= f[p0 + offs[k]] << k
        if count[code] != 1:
            continue
        prev = -1
        p = p0
        length = 0.0
        n = 0
        junction = False
        while True:
            code = 0
            for k in range(8):
                code |= f[p + offs[k]] << k
            nb = count[code]
            if n > 0 and nb >= 3:
                junction = True
                break
            if n > 0 and nb <= 1:
                break  # another free end: a junction-free segment
            buf[n] = p
            n += 1
            nxt = -1
            step = 1.0
            for k in range(8):  # even k axial, odd k diagonal
                q = p + offs[k]
                if f[q] and q != prev:
                    nxt = q
                    step = 1.0 if k % 2 == 0 else 1.4142135623730951
                    break
            if nxt < 0:
                break
            length += step
            if length >= l_min or n >= buf.shape[0]:
                break
            prev = p
            p = nxt
        if junction and length < l_min:
            if cut:
                for j in range(n):
                    f[buf[j]] = 0
                removed += n
            else:
                ends[nk] = p0
                lens[nk] = length
                nk += 1
    return removed if cut else nk


def _quicksort_order(keys) -> np.ndarray:
    """Ascending order of ``keys`` with ties in the order numba's ``np.argsort`` (its
    quicksort: insertion sort below 15 items, median-of-three partitions above) gives them.

    Spurs of equal length meeting at one junction are common (the two arms of the fork the
    skeleton makes at a band's end); once one is deleted the other is no longer a spur, so
    the tie order decides which arm survives. This is the order the pruning has always used.
    """
    a = [float(x) for x in keys]
    r = list(range(len(a)))
    stack = [(0, len(a) - 1)] if len(a) > 1 else []

    def insertion(low, high):
        for i in range(low + 1, high + 1):
            k = r[i]
            v = a[k]
            j = i
            while j > low and v < a[r[j - 1]]:
                r[j] = r[j - 1]
                j -= 1
            r[j] = k

    while stack:
        low, high = stack.pop()
        while high - low >= 15:
            mid = (low + high) >> 1
            if a[r[mid]] < a[r[low]]:
                r[low], r[mid] = r[mid], r[low]
            if a[r[high]] < a[r[mid]]:
                r[high], r[mid] = r[mid], r[high]
            if a[r[mid]] < a[r[low]]:
                r[low], r[mid] = r[mid], r[low]
            pivot = a[r[mid]]
            r[high], r[mid] = r[mid], r[high]
            i, j = low, high - 1
            while True:
                while i < high and a[r[i]] < pivot:
                    i += 1
                while j >= low and pivot < a[r[j]]:
                    j -= 1
                if i >= j:
                    break
                r[i], r[j] = r[j], r[i]
                i += 1
                j -= 1
            r[i], r[high] = r[high], r[i]
            if high - i > i - low:
                if high > i:
                    stack.append((i + 1, high))
                high = i - 1
            else:
                if i > low:
                    stack.append((low, i - 1))
                low = i + 1
        insertion(low, high)
    return np.asarray(r, dtype=np.int64)


def _offsets(w: int) -> np.ndarray:
    """Flat offsets of the 8 neighbours in an image of row length ``w``, clockwise from north
    (bit k of a neighbourhood code is neighbour k)."""
    return (_DR * w + _DC).astype(np.int64)


def _prune(f, offs, idx, m, l_min):
    """Delete spurs shorter than ``l_min`` ending on a junction, shortest first, until none is
    left (a spur on a spur included); ``idx[:m]`` the skeleton pixels. Returns the number of
    skeleton pixels left (compacted in ``idx``) and of pixels deleted."""
    buf = np.empty(int(l_min) * 2 + 8, np.int64)
    ends = np.empty(max(m, 1), np.int64)
    lens = np.empty(max(m, 1), np.float64)
    n_removed = 0
    while True:
        k = _spurs(f, offs, idx, m, l_min, _COUNT, buf, ends, lens, False)
        if k == 0:
            break
        order = ends[:k][_quicksort_order(lens[:k])]
        removed = _spurs(f, offs, order, k, l_min, _COUNT, buf, ends, lens, True)
        if removed == 0:
            break
        n_removed += removed
        m = _remove_redundant(f, offs, idx, m, _SIMPLE, _COUNT)
    return m, n_removed


def nonzero_rc(img) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) int64 of the nonzero pixels of a 2-D uint8 image, in raster order.

    The flat indices of a boolean image, split into rows and columns: on a sparse 2000x2000
    skeleton 2 ms, against 6 ms for ``cv2.findNonZero`` and 16 ms for the 2-D
    ``np.nonzero`` (numpy's nonzero is fast on booleans only, and on one axis).
    """
    a = np.asarray(img, dtype=np.uint8)
    flat = np.flatnonzero(a != 0).astype(np.int64, copy=False)
    return flat // a.shape[1], flat % a.shape[1]


def _border_pixels(img) -> np.ndarray:
    """Flat indices (raster order) of the foreground pixels of the padded uint8 image with a
    background 8-neighbour (the first candidates of the thinning)."""
    inner = cv2.erode(img, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                      borderValue=0)
    return np.flatnonzero(img > inner).astype(np.int64, copy=False)


def _check_mask(mask, name="mask"):
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ParameterError(f"{name} must be a 2-D array, got shape {mask.shape}")
    return mask.astype(bool, copy=False)


def thin_mask(mask) -> np.ndarray:
    """Zhang-Suen skeleton of a binary mask, then redundant pixels removed (no pruning).

    Parameters
    ----------
    mask : (H, W) bool array
        Foreground (ink) pixels.

    Returns
    -------
    (H, W) bool array
        The one-pixel, 8-connected minimal skeleton; same topology as ``mask``.
    """
    skel, _ = _skeleton_padded(_check_mask(mask), l_min_px=0.0)
    return skel[1:-1, 1:-1].astype(bool)


def _skeleton_padded(mask, *, l_min_px):
    h, w = mask.shape
    img = np.zeros((h + 2, w + 2), np.uint8)
    img[1:-1, 1:-1] = mask
    f = img.reshape(-1)
    offs = _offsets(w + 2)
    start = _border_pixels(img)
    # a pixel enters the thinning's list at most once: room for every foreground pixel
    cap = max(int(np.count_nonzero(f)), 1)
    lst = np.empty(cap, np.int64)
    lst[:len(start)] = start
    _zhang_suen(f, offs, lst, len(start), np.zeros(f.shape[0], np.uint8),
                np.empty(cap, np.int64), _ZS1, _ZS2, _SIMPLE, _COUNT)
    # numpy's nonzero is 10x faster on booleans than on uint8 (f holds 0 and 1)
    idx = np.flatnonzero(f.view(np.bool_)).astype(np.int64, copy=False)
    m = _remove_redundant(f, offs, idx, len(idx), _SIMPLE, _COUNT)
    n_removed = 0
    if l_min_px > 0:
        m, n_removed = _prune(f, offs, idx, m, float(l_min_px))
    return img, n_removed


def skeletonize_mask(mask, *, l_min_px: float) -> np.ndarray:
    """One-pixel skeleton without redundant kinks; spurs shorter than ``l_min_px`` pruned.

    Parameters
    ----------
    mask : (H, W) bool array
        Cleaned foreground (ink) mask.
    l_min_px : float
        Detection limit in pixels (paper: l_min = 1 mm). A terminal branch (free end to a
        junction pixel) shorter than this is a spur and is deleted, iteratively; a segment
        without junction and closed loops are kept whatever their length. 0 disables pruning.

    Returns
    -------
    (H, W) bool array
        The skeleton.

    Notes
    -----
    See the module docstring for the algorithm and the measurements behind hand-writing it.
    """
    mask = _check_mask(mask)
    if not np.isfinite(l_min_px) or l_min_px < 0:
        raise ParameterError(f"l_min_px must be a finite number >= 0, got {l_min_px}")
    img, _ = _skeleton_padded(mask, l_min_px=l_min_px)
    return img[1:-1, 1:-1].astype(bool)


def neighbour_count(skel) -> np.ndarray:
    """Number of 8-neighbours of every skeleton pixel (0 off the skeleton), uint8."""
    s = np.ascontiguousarray(skel, dtype=np.uint8)
    k = np.ones((3, 3), np.float32)
    k[1, 1] = 0
    cnt = cv2.filter2D(s, cv2.CV_8U, k, borderType=cv2.BORDER_CONSTANT)
    cnt[s == 0] = 0
    return cnt
