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


@njit(cache=True, inline="always")
def _code(img, r, c):
    return (img[r - 1, c] | (img[r - 1, c + 1] << 1) | (img[r, c + 1] << 2)
            | (img[r + 1, c + 1] << 3) | (img[r + 1, c] << 4) | (img[r + 1, c - 1] << 5)
            | (img[r, c - 1] << 6) | (img[r - 1, c - 1] << 7))


@njit(cache=True, inline="always")
def _code_flat(f, p, w):
    return (f[p - w] | (f[p - w + 1] << 1) | (f[p + 1] << 2) | (f[p + w + 1] << 3)
            | (f[p + w] << 4) | (f[p + w - 1] << 5) | (f[p - 1] << 6) | (f[p - w - 1] << 7))


@njit(cache=True)
def _zhang_suen(img, start, zs1, zs2, simple, count):
    """Zhang-Suen thinning of the padded uint8 image ``img`` in place.

    ``start`` holds the flat indices of the initial border pixels (foreground with a
    background 8-neighbour): interior pixels have 8 neighbours and cannot be deleted before a
    neighbour is. A pixel is re-examined in a sub-iteration only if its neighbourhood changed
    since it was last examined in that sub-iteration (same result as examining every pixel,
    about 4x fewer visits).
    """
    h, w = img.shape
    f = img.ravel()
    offs = np.array([-w, -w + 1, 1, w + 1, w, w - 1, -1, -w - 1], np.int64)
    n = start.shape[0]
    cap = max(n * 2, 1024)
    lst = np.empty(cap, np.int64)
    lst[:n] = start
    # state bits: 1 = in the list, 2 = to examine in sub-iteration 0, 4 = in sub-iteration 1
    st = np.zeros(h * w, np.uint8)
    for i in range(n):
        st[start[i]] = 7
    flags = np.empty(cap, np.int64)
    changed = True
    while changed and n > 0:
        changed = False
        for sub in range(2):
            lut = zs1 if sub == 0 else zs2
            bit = 2 if sub == 0 else 4
            nf = 0
            if flags.shape[0] < n:
                flags = np.empty(lst.shape[0], np.int64)
            for i in range(n):
                p = lst[i]
                s = st[p]
                if s & bit:
                    st[p] = s & ~bit
                    if lut[_code_flat(f, p, w)]:
                        flags[nf] = p
                        nf += 1
            # sequential deletion with a topology re-check on the current image
            for i in range(nf):
                p = flags[i]
                code = _code_flat(f, p, w)
                if simple[code] and count[code] >= 2:
                    f[p] = 0
                    changed = True
                    for k in range(8):
                        q = p + offs[k]
                        if f[q]:
                            if not (st[q] & 1):
                                if n >= lst.shape[0]:
                                    l2 = np.empty(lst.shape[0] * 2, np.int64)
                                    l2[:n] = lst[:n]
                                    lst = l2
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
def _remove_redundant(img, rows, cols, simple, count):
    """Delete simple non-end pixels sequentially until none is left; return the survivors."""
    n = rows.shape[0]
    changed = True
    while changed:
        changed = False
        for i in range(n):
            r = rows[i]
            c = cols[i]
            if img[r, c]:
                code = _code(img, r, c)
                if count[code] >= 2 and simple[code]:
                    img[r, c] = 0
                    changed = True
    m = 0
    for i in range(n):
        if img[rows[i], cols[i]]:
            rows[m] = rows[i]
            cols[m] = cols[i]
            m += 1
    return rows[:m].copy(), cols[:m].copy()


@njit(cache=True)
def _walk_spur(img, r0, c0, l_min, count, buf_r, buf_c):
    """Walk from free end (r0, c0). Return (n_pixels, length, reached_junction)."""
    pr = -1
    pc = -1
    r = r0
    c = c0
    length = 0.0
    n = 0
    while True:
        code = _code(img, r, c)
        nb = count[code]
        if n > 0 and nb >= 3:
            return n, length, True
        if n > 0 and nb <= 1:
            return n, length, False  # another free end: a junction-free segment
        if n == 0 and nb != 1:
            return 0, 0.0, False
        buf_r[n] = r
        buf_c[n] = c
        n += 1
        found = False
        step = 1.0
        nr = -1
        nc = -1
        for k in range(8):
            rr = r + _DR[k]
            c2 = c + _DC[k]
            if img[rr, c2] and not (rr == pr and c2 == pc):
                nr = rr
                nc = c2
                found = True
                if _DR[k] == 0 or _DC[k] == 0:
                    step = 1.0
                else:
                    step = 1.4142135623730951
                break
        if not found:
            return n, length, False
        length += step
        if length >= l_min or n >= buf_r.shape[0]:
            return n, length, False
        pr = r
        pc = c
        r = nr
        c = nc


@njit(cache=True)
def _prune(img, rows, cols, l_min, simple, count):
    """Iteratively delete spurs shorter than ``l_min`` that end on a junction."""
    cap = int(l_min) * 2 + 8
    buf_r = np.empty(cap, np.int64)
    buf_c = np.empty(cap, np.int64)
    n_removed = 0
    while True:
        ends_r = []
        ends_c = []
        lens = []
        for i in range(rows.shape[0]):
            r = rows[i]
            c = cols[i]
            if img[r, c] and count[_code(img, r, c)] == 1:
                k, length, junc = _walk_spur(img, r, c, l_min, count, buf_r, buf_c)
                if junc and length < l_min:
                    ends_r.append(r)
                    ends_c.append(c)
                    lens.append(length)
        if len(lens) == 0:
            break
        order = np.argsort(np.array(lens))
        any_removed = False
        for j in order:
            r = ends_r[j]
            c = ends_c[j]
            if not img[r, c]:
                continue
            k, length, junc = _walk_spur(img, r, c, l_min, count, buf_r, buf_c)
            if junc and length < l_min:
                for i in range(k):
                    img[buf_r[i], buf_c[i]] = 0
                n_removed += k
                any_removed = True
        if not any_removed:
            break
        rows, cols = _remove_redundant(img, rows, cols, simple, count)
    return rows, cols, n_removed


@njit(cache=True)
def nonzero_rc(img):
    """(rows, cols) of the nonzero pixels in raster order; 4-5x faster than ``np.nonzero``
    on a sparse 2000x2000 skeleton (3 ms against 15 ms)."""
    h, w = img.shape
    n = 0
    for r in range(h):
        for c in range(w):
            if img[r, c]:
                n += 1
    rows = np.empty(n, np.int64)
    cols = np.empty(n, np.int64)
    k = 0
    for r in range(h):
        for c in range(w):
            if img[r, c]:
                rows[k] = r
                cols[k] = c
                k += 1
    return rows, cols


@njit(cache=True)
def _border_pixels(img):
    """Flat indices of the foreground pixels of the padded image with a background
    8-neighbour (the first candidates of the thinning)."""
    h, w = img.shape
    out = []
    for r in range(1, h - 1):
        for c in range(1, w - 1):
            if img[r, c]:
                if not (img[r - 1, c - 1] and img[r - 1, c] and img[r - 1, c + 1]
                        and img[r, c - 1] and img[r, c + 1] and img[r + 1, c - 1]
                        and img[r + 1, c] and img[r + 1, c + 1]):
                    out.append(r * w + c)
    return np.array(out, dtype=np.int64)


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
    start = _border_pixels(img)
    _zhang_suen(img, start, _ZS1, _ZS2, _SIMPLE, _COUNT)
    rows, cols = nonzero_rc(img)
    rows, cols = _remove_redundant(img, rows, cols, _SIMPLE, _COUNT)
    n_removed = 0
    if l_min_px > 0:
        rows, cols, n_removed = _prune(img, rows, cols, float(l_min_px), _SIMPLE, _COUNT)
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
    import cv2

    s = np.ascontiguousarray(skel, dtype=np.uint8)
    k = np.ones((3, 3), np.float32)
    k[1, 1] = 0
    cnt = cv2.filter2D(s, cv2.CV_8U, k, borderType=cv2.BORDER_CONSTANT)
    cnt[s == 0] = 0
    return cnt
