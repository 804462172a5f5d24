"""Stage 2: the ink mask from RGB values (paper Fig. 2).

Paper, section "Image analysis procedure": "only pixels of blue values larger than a given
threshold but of red and green values smaller than another given threshold are kept, allowing
to distinguish the cut edge from back receding surfaces and to remove noise".

The cut edges are inked in blue; ink absorbs red and green and passes blue. Every other
surface of a scan is close to neutral (white paper, the light grey-blue receding surfaces, a
grey, dark or beige plate) or of another hue (a brown or coloured plate), or is pale
(light-blue smears of wiped ink). Two features separate them:

- the blue dominance ``d = blue - max(red, green)``: about +120 on ink, 0 on any neutral
  surface whatever its brightness (an illumination gradient multiplies it, a neutral stays
  neutral), +10 to +20 on receding surfaces, below +40 on brown, beige or bluish plates;
- the red-green darkness ``m = max(red, green)``: about 70 on ink, 245 on paper and 170 or more
  on light-blue smears, which share their hue with ink but not its depth.

Methods
-------
- ``"auto"`` (default): both cuts chosen from the scan. A provisional split of ``d`` by Otsu's
  method gives the ink class; the ink level is its median, the paper level the median over a
  ring 2-6 px around it (the paper that borders the ink, not the plate or the rest of the
  frame). Each cut is the midpoint of the two levels, i.e. the value of a pixel half covered
  by ink, so the band widths that give the layer counts are not biased by the threshold.
  A pixel is ink when ``d >= d_cut`` and ``m <= m_cut``. Only pixels of ``region`` (the
  scan's frame, inside the hole) enter the statistics and can be ink. Illumination and colour
  casts move both levels together with the cuts; a plate is outside ``region``, and without a
  region any plate that is not blue fails ``d``. The cuts are the same over the whole frame:
  under a strong gradient with a colour cast the ink on the dark side can fall below them.
  :func:`missed_ink` finds that ink with the same rule applied tile by tile (each tile's own
  midpoints), and the pipeline adds what it finds to the mask where the ``ink_missed``
  quality check flags the scan (more than 0.5 % of the ink): elsewhere, every scan within
  the documented range among them, the mask is the scan's cut, pixel for pixel. Missed ink
  in pieces smaller than the cleaning keeps is neither counted nor added: a thin band lost
  over a short stretch can go unflagged. When the scan has no blue-dominant
  class (ink and paper levels closer than :data:`MIN_CONTRAST_U8`) the mask is empty.
- ``"fixed"``: the paper's rule ``blue >= blue_min`` and ``red, green <= rg_max``, defaults
  100 and 130 (uint8). It assumes the scanner exposure of the scans they were set on: a neutral
  grey plate (~ (128, 125, 120)) passes it.
- ``"otsu"``: Otsu's threshold on ``d`` and ``red, green <= rg_max`` (default 130).

With ``"auto"``, a given ``blue_min`` or ``rg_max`` is an extra bound (it can only remove
pixels). Below 3 px per sheet a single sheet blurred by the scanner may not reach the cut
along its whole length; :func:`bridge_broken_lines` joins such dashes again with one-pixel
threads (the pipeline calls it; ``bridged_px`` in the summary's thresholds). All values are
in the native units of the image (uint16: uint8 values times 257).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from crosssection.core.errors import ParameterError

BLUE_MIN_U8 = 100
RG_MAX_U8 = 130
#: Least difference (uint8 units) between the ink and paper levels of both features for
#: ``"auto"`` to accept a blue-dominant class; ink on paper differs by 100 or more.
MIN_CONTRAST_U8 = 30.0
METHODS = ("auto", "fixed", "otsu")
DOMINANCE = "blue - max(red, green)"


@dataclass(frozen=True)
class ThresholdResult:
    """Binary mask and the thresholds used (native units of the image dtype).

    Attributes
    ----------
    mask : (H, W) bool array
    blue_min : float or None
        Blue lower bound (``"fixed"``, or given to ``"auto"``).
    rg_max : float or None
        Red and green upper bound (``"auto"``: the data-chosen ``m_cut``).
    method : str
        ``"auto"``, ``"fixed"`` or ``"otsu"``.
    dominance_min : float or None
        Threshold on ``blue - max(red, green)`` (``"auto"``, ``"otsu"``).
    scale : float
        1 for uint8 images, 257 for uint16.
    ink_level, paper_level : (2,) tuple or None
        ``"auto"``: the (dominance, max(red, green)) levels of ink and of the paper around it.
    region_fraction : float
        Fraction of the image inside ``region`` (1 without region).
    note : str
        Why the mask is empty, when it is.
    options : str
        ``"auto"`` with an empty mask: the options of the ``"fixed"`` method that read the
        marks of another colour the note names, when a cut reads them; else ``""``.
    n_outside : int
        Pixels outside ``region`` that pass the same cut: ink (or plate) the frame left out;
        when they exceed :data:`OUTSIDE_NOISE_CHECK` of the ink inside, those in pieces of
        at least :data:`OUTSIDE_MIN_PIECE_PX` only (:func:`_structured_px`).
    bridged_px : int
        Pixels of the threads that join thin lines broken by the cut
        (:func:`bridge_broken_lines`).
    local_px : int
        Pixels of ink that the cut left out and cuts chosen locally took in (:func:`missed_ink`;
        the pipeline adds them to the mask).
    """

    mask: np.ndarray
    blue_min: float | None
    rg_max: float | None
    method: str
    dominance_min: float | None = None
    scale: float = 1.0
    ink_level: tuple | None = None
    paper_level: tuple | None = None
    region_fraction: float = 1.0
    note: str = ""
    options: str = ""
    n_outside: int = 0
    bridged_px: int = 0
    local_px: int = 0

    @property
    def feature(self) -> str:
        """The feature the method cuts."""
        return "blue, red, green" if self.method == "fixed" else DOMINANCE

    @property
    def cut(self) -> float | None:
        """The cut on :attr:`feature` (``blue_min`` for ``"fixed"``)."""
        return self.blue_min if self.method == "fixed" else self.dominance_min

    def as_summary(self) -> dict:
        """JSON-friendly thresholds for ``summary.json``."""
        def _f(x):
            return None if x is None else float(x)

        def _t(x):
            return None if x is None else [float(v) for v in x]
        return {"method": self.method, "feature": self.feature, "cut": _f(self.cut),
                "blue_min": _f(self.blue_min), "rg_max": _f(self.rg_max),
                "dominance_min": _f(self.dominance_min), "ink_level": _t(self.ink_level),
                "paper_level": _t(self.paper_level), "dtype_scale": float(self.scale),
                "region_fraction": float(self.region_fraction),
                # a count, not a mean: no float64 pass over the image, the same fraction
                "foreground_fraction": (float(np.count_nonzero(self.mask)) / self.mask.size
                                        if self.mask.size else 0.0),
                "bridged_px": int(self.bridged_px), "local_px": int(self.local_px),
                "note": self.note}


def _scale(rgb) -> float:
    if rgb.dtype == np.uint8:
        return 1.0
    if rgb.dtype == np.uint16:
        return 257.0
    raise ParameterError(f"threshold needs a uint8 or uint16 RGB image, got {rgb.dtype}")


#: An image whose brightest value lies below this fraction of its type's range holds data of
#: fewer bits (12-bit scanner data in a 16-bit file reach 4095 of 65535), darker than every
#: default cut expects: an empty mask then says so (:func:`_range_note`).
NARROW_RANGE_FRACTION = 0.25


def _range_note(rgb, reg) -> str:
    """Why an empty mask may be the data's fault, not the ink's: the image (within the region
    ``reg``, or all of it) reaches only a small part of its type's range; else ``""``."""
    vmax = 255 if rgb.dtype == np.uint8 else 65535
    hi = int(rgb.max() if reg is None else rgb[reg].max(initial=0))
    if hi >= NARROW_RANGE_FRACTION * vmax:
        return ""
    guess = (f"{max(int(hi).bit_length(), 1)}-bit data?" if rgb.dtype == np.uint16
             else "an underexposed scan?")
    return (f"the image's values reach only {hi} of {vmax} ({guess}): rescale it to the "
            f"full range of its type; ")


def _check_value(name, value, vmax):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}") from None
    if not (0 <= v <= vmax):
        # an integer array whose values all lie within 0..255 is read as 8-bit
        bits = "8-bit" if vmax == 255 else "16-bit"
        raise ParameterError(f"{name}={value} outside the image range 0..{vmax:g} (the image "
                             f"is read as {bits})")
    return v


def _region(region, shape):
    if region is None:
        return None
    reg = np.asarray(region)
    if reg.shape != shape:
        raise ParameterError(f"region shape {reg.shape} differs from the image's {shape}")
    reg = reg.astype(bool, copy=False)
    if not reg.any():
        raise ParameterError("the region (scan's frame) is empty: the hole lies outside the "
                             "image")
    return reg


def _otsu_hist(counts) -> float:
    """Otsu's threshold of a histogram of 1-unit bins, bin ``k`` holding the value ``k - 256``."""
    from skimage.filters import threshold_otsu

    nz = np.flatnonzero(counts)
    if len(nz) < 2:
        return float(nz[0] - 256) + 1.0 if len(nz) else 1.0
    counts = counts[nz[0]:nz[-1] + 1]
    centers = np.arange(nz[0], nz[-1] + 1) - 256.0
    return float(threshold_otsu(hist=(counts, centers)))


def _hist_u8(values) -> np.ndarray:
    """Counts of values in uint8 units rounded to 1-unit bins (:func:`_otsu_hist`'s)."""
    idx = np.clip(np.rint(np.ravel(values)).astype(np.int64) + 256, 0, 512)
    return np.bincount(idx, minlength=513)


def _median_hist(counts) -> float:
    """Median, to the nearest unit, of the values counted by a :func:`_hist_u8` histogram."""
    cum = np.cumsum(counts)
    return float(np.searchsorted(cum, 0.5 * cum[-1])) - 256.0


def _otsu_u8(values) -> float:
    """Otsu's threshold of values in uint8 units (histogram of 1-unit bins)."""
    return _otsu_hist(_hist_u8(values))


def _median_u8(values) -> float:
    """Median of values in uint8 units, to the nearest unit (a histogram, no sort)."""
    return _median_hist(_hist_u8(values))


def _ring(prov, reg, ring_px):
    """The ring 2 to ``ring_px`` px around ``prov`` (inside ``reg``), or None when either
    holds fewer than 10 pixels."""
    import cv2

    if np.count_nonzero(prov) < 10:
        return None
    u8 = prov.view(np.uint8)
    near = cv2.dilate(u8, np.ones((3, 3), np.uint8)).view(bool)
    far = cv2.dilate(u8, np.ones((2 * ring_px + 1,) * 2, np.uint8)).view(bool)
    ring = far & ~near
    if reg is not None:
        ring &= reg
    if np.count_nonzero(ring) < 10:
        return None
    return ring


def _levels_of(prov, ds, ms, reg, ring_px):
    """Ink levels (median over ``prov``) and paper levels (median over the ring around it)."""
    ring = _ring(prov, reg, ring_px)
    if ring is None:
        return None
    ink = (_median_u8(ds[prov]), _median_u8(ms[prov]))
    paper = (_median_u8(ds[ring]), _median_u8(ms[ring]))
    return ink, paper


def _best_levels(levels, best, best_score):
    if levels is None:
        return best, best_score
    (d_i, m_i), (d_p, m_p) = levels
    score = min(d_i - d_p, m_p - m_i)
    return (levels, score) if score >= best_score else (best, best_score)


def _auto_levels(d, m, region, scale, features=None):
    """Ink and paper levels (uint8 units) of dominance ``d`` and darkness ``m``.

    Candidate ink classes are the upper class of Otsu's split of ``d`` and the upper class of
    a second Otsu split within it: with a plate in the statistics (no region) the first split
    may separate the plate from paper and ink, or the paper from a bluish plate and ink. The
    candidate kept is the one that contrasts most with the ring of surface that borders it,
    ``min(d_ink - d_ring, m_ring - m_ink)``: ink is bluer and darker in red and green than
    the paper around it, a plate is not. Returns ``((d_ink, m_ink), (d_paper, m_paper))`` or
    None when no candidate contrasts by :data:`MIN_CONTRAST_U8`. Large scans (more than a
    million pixels in the region) are sampled on a 2 px lattice (every band, at least a sheet
    thickness wide, is still sampled).
    ``features`` (:class:`ColourFeatures` of ``d`` and ``m``) keeps the lattice for the next
    call.
    """
    # the lattice follows the pixels that choose the cut (the frame's, when given), so that
    # paper around the scan (a wider scan of the same cut) leaves the levels unchanged
    n_px = d.size if region is None else int(np.count_nonzero(region))
    step = 2 if n_px > 1_000_000 else 1
    reg = None if region is None else np.ascontiguousarray(region[::step, ::step])
    ring_px = 6 // step  # the paper 2-6 px out from the ink
    if scale == 1.0:
        ds, ms = features.lattice(step) if features is not None else \
            (np.ascontiguousarray(d[::step, ::step]), np.ascontiguousarray(m[::step, ::step]))
        return _auto_levels_u8(ds, ms, reg, ring_px)
    ds = d[::step, ::step].astype(np.float32) / scale
    ms = m[::step, ::step].astype(np.float32) / scale
    vals = ds if reg is None else ds[reg]
    best, best_score = None, MIN_CONTRAST_U8
    t = -np.inf
    for _ in range(2):
        sub = vals[vals > t]
        if sub.size < 20 or sub.min() == sub.max():
            break
        # Otsu's class above the cut is strictly greater (skimage's convention): with a
        # two-level image ">=" would put the whole image in the ink class
        t = _otsu_u8(sub)
        prov = ds > t
        if reg is not None:
            prov &= reg
        best, best_score = _best_levels(_levels_of(prov, ds, ms, reg, ring_px), best,
                                        best_score)
    return best


def _auto_levels_u8(ds, ms, reg, ring_px):
    """:func:`_auto_levels` of a uint8 scan: the same statistics from integer features.

    The features are whole numbers, so counts of the (dominance, darkness) pairs hold all
    that Otsu's splits and the ink's medians need: the ink class is the pairs whose dominance
    lies above a cut. Only the ring around that class is read from the pixels, once per
    split. Same levels as the float path (a 2000 x 2000 scan: 3.5 ms, against 7 ms for histograms of the pixels
    gathered by mask and 45 ms for the float path).
    """
    import cv2

    joint = _pair_counts(ds, ms, reg)
    hist = joint.sum(axis=1)  # the region's dominance, in _hist_u8's bins
    value = np.arange(513) - 256.0
    best, best_score = None, MIN_CONTRAST_U8
    t = -np.inf
    for _ in range(2):
        sub = np.where(value > t, hist, 0)
        if sub.sum() < 20 or np.count_nonzero(sub) < 2:
            break
        t = _otsu_hist(sub)  # the upper class is strictly greater, as in the float path
        above = value > t
        # the ink's darkness: the pairs above the cut, in _hist_u8's bins
        ink_m = np.zeros(513, np.int64)
        ink_m[256:512] = joint[above].sum(axis=0)
        if ink_m.sum() < 10:  # :func:`_ring`'s least ink
            continue
        prov = ds > t
        if reg is not None:
            prov &= reg
        u8 = prov.view(np.uint8)
        near = cv2.dilate(u8, np.ones((3, 3), np.uint8))
        far = cv2.dilate(u8, np.ones((2 * ring_px + 1,) * 2, np.uint8))
        ring_d, ring_m = _ring_counts(near, far, reg, ds, ms)
        if ring_d.sum() < 10:
            continue
        # the ink's dominance: the region's histogram above the cut
        ink = (_median_hist(np.where(above, hist, 0)), _median_hist(ink_m))
        paper = (_median_hist(ring_d), _median_hist(ring_m))
        best, best_score = _best_levels((ink, paper), best, best_score)
    return best


@njit(cache=True)
def _pair_counts(ds, ms, reg):  # pragma: no cover - numba
    """Counts of the (dominance, darkness) pairs of a uint8 scan, ``counts[d + 256, m]``,
    over ``reg`` when given.

    One pass over the pixels: 0.5 ms on a 2000 x 2000 scan's 2 px lattice, against 1.5 ms
    for ``np.bincount`` of the dominance alone (an intp copy of the pixels first).
    """
    counts = np.zeros((513, 256), np.int64)
    h, w = ds.shape
    if reg is None:
        for i in range(h):
            for j in range(w):
                counts[ds[i, j] + 256, ms[i, j]] += 1
    else:
        for i in range(h):
            for j in range(w):
                if reg[i, j]:
                    counts[ds[i, j] + 256, ms[i, j]] += 1
    return counts


@njit(cache=True)
def _ring_counts(near, far, reg, ds, ms):  # pragma: no cover - numba
    """Histograms (:func:`_hist_u8`'s bins) of ``ds`` and of ``ms`` over the ring
    ``far & ~near`` (and ``reg`` when given), without the ring's mask or the gathered pixels.

    0.7 ms on a 2000 x 2000 scan's 2 px lattice, against 1.8 ms for both histograms of the
    pixels gathered by the ring's mask.
    """
    hd = np.zeros(513, np.int64)
    hm = np.zeros(513, np.int64)
    h, w = ds.shape
    for i in range(h):
        for j in range(w):
            if far[i, j] and not near[i, j]:
                if reg is None or reg[i, j]:
                    hd[ds[i, j] + 256] += 1
                    hm[ms[i, j] + 256] += 1
    return hd, hm


class ColourFeatures:
    """The per-pixel features of a scan that every method cuts: blue, the red-green darkness
    ``m = max(red, green)`` and the blue dominance ``d = blue - m``.

    Computed once per scan and given to each :func:`threshold_rgb` call on it (the pipeline
    thresholds the whole scan to find the hole, then again inside it).

    Parameters
    ----------
    rgb : (H, W, 3) uint8 or uint16 array

    Attributes
    ----------
    blue, darkness : (H, W) arrays of the image's dtype
    dominance : (H, W) int16 (uint8 image) or int32 (uint16 image) array
    scale : float
        1 for uint8 images, 257 for uint16.
    shape : tuple
        (H, W).
    """

    def __init__(self, rgb):
        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ParameterError(f"threshold needs an (H, W, 3) RGB array, got shape "
                                 f"{rgb.shape}")
        self.scale = _scale(rgb)
        self.shape = rgb.shape[:2]
        self.blue = np.empty(self.shape, rgb.dtype)
        self.darkness = np.empty(self.shape, rgb.dtype)
        # d needs one bit more than the image's depth
        self.dominance = np.empty(self.shape, np.int16 if rgb.dtype == np.uint8 else np.int32)
        _split_features(np.ascontiguousarray(rgb).reshape(-1), self.blue.reshape(-1),
                        self.darkness.reshape(-1), self.dominance.reshape(-1))
        self._lattice: dict = {}

    def lattice(self, step: int):
        """(dominance, darkness) on the ``step`` px lattice, contiguous (copied once)."""
        if step not in self._lattice:
            self._lattice[step] = (np.ascontiguousarray(self.dominance[::step, ::step]),
                                   np.ascontiguousarray(self.darkness[::step, ::step]))
        return self._lattice[step]


@njit(cache=True)
def _split_features(rgb, blue, darkness, dominance):  # pragma: no cover - numba
    """Blue, ``max(red, green)`` and ``blue - max(red, green)`` of the flat interleaved
    ``rgb``, into the flat outputs.

    One pass over the pixels: 1 ms on a 2000 x 2000 uint8 scan (3 ms uint16), against 5 ms
    (14 ms) for OpenCV's split of the channels and two element-wise passes.
    """
    for k in range(blue.size):
        r = rgb[3 * k]
        g = rgb[3 * k + 1]
        b = rgb[3 * k + 2]
        m = max(r, g)
        blue[k] = b
        darkness[k] = m
        dominance[k] = np.int64(b) - np.int64(m)


def passes_at(thr: ThresholdResult, features: ColourFeatures, rows, cols) -> np.ndarray:
    """Whether the pixels at ``(rows, cols)`` pass the cut of ``thr``, its region ignored.

    Parameters
    ----------
    thr : ThresholdResult
    features : ColourFeatures
        Those of the image ``thr`` was cut from.
    rows, cols : int arrays

    Returns
    -------
    bool array
    """
    ok = np.ones(np.shape(rows), bool)
    if thr.method != "fixed" and thr.dominance_min is None:
        return ~ok  # no cut found: nothing is ink
    if thr.blue_min is not None:
        ok &= features.blue[rows, cols] >= np.ceil(thr.blue_min)
    if thr.rg_max is not None:
        ok &= features.darkness[rows, cols] <= np.floor(thr.rg_max)
    if thr.dominance_min is not None:
        ok &= features.dominance[rows, cols] >= np.ceil(thr.dominance_min)
    return ok


def colour_features(rgb) -> ColourFeatures:
    """The :class:`ColourFeatures` of a scan (to share between :func:`threshold_rgb` calls)."""
    return ColourFeatures(rgb)


def _at_least(a, x):
    """``a >= x`` for an integer array and a real ``x``: compared with ``ceil(x)`` in the
    array's own type (no float64 copy of the image)."""
    info = np.iinfo(a.dtype)
    return a >= int(np.clip(np.ceil(x), info.min, info.max + 1)) if x <= info.max else \
        np.zeros(a.shape, bool)


def _at_most(a, x):
    """``a <= x`` for an integer array and a real ``x`` (see :func:`_at_least`)."""
    info = np.iinfo(a.dtype)
    return a <= int(np.clip(np.floor(x), info.min - 1, info.max)) if x >= info.min else \
        np.zeros(a.shape, bool)


def threshold_rgb(rgb, *, method: str = "auto", region=None, blue_min=None,
                  rg_max=None, features: ColourFeatures | None = None) -> ThresholdResult:
    """Binary mask of the blue-inked cut edge.

    Parameters
    ----------
    rgb : (H, W, 3) uint8 or uint16 array
    method : {"auto", "fixed", "otsu"}
        See the module docstring.
    region : (H, W) bool array, optional
        The scan's frame (inside the hole): only its pixels choose the cuts and can be ink.
    blue_min : float, optional
        Minimum blue (native units); ``"fixed"`` default 100 (uint8), 100 * 257 (uint16).
        An extra bound for ``"auto"``; ignored by ``"otsu"``.
    rg_max : float, optional
        Maximum red and green (native units); ``"fixed"`` and ``"otsu"`` default 130 (uint8),
        130 * 257 (uint16). An extra bound for ``"auto"``.
    features : ColourFeatures, optional
        The features of ``rgb`` when already computed (:func:`colour_features`).

    Returns
    -------
    ThresholdResult

    Raises
    ------
    ParameterError
        Not an (H, W, 3) uint8/uint16 array, unknown method, a bound outside the image range,
        a region of another shape or empty.
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.size == 0:
        raise ParameterError(f"threshold needs an (H, W, 3) RGB array with pixels, got shape "
                             f"{rgb.shape}")
    if method not in METHODS:
        raise ParameterError(f"threshold method must be one of {METHODS}, got {method!r}")
    scale = _scale(rgb)
    vmax = 255.0 * scale
    reg = _region(region, rgb.shape[:2])
    reg_frac = 1.0 if reg is None else float(np.count_nonzero(reg)) / reg.size
    rg = None if rg_max is None else _check_value("rg_max", rg_max, vmax)
    bm = None if blue_min is None else _check_value("blue_min", blue_min, vmax)
    if features is None:
        features = ColourFeatures(rgb)
    elif features.shape != rgb.shape[:2] or features.scale != scale:
        raise ParameterError("the colour features are not those of this image")
    b, m, d = features.blue, features.darkness, features.dominance

    n_out = [0]

    def _bounds(mask, blue, rgmax):
        if blue is not None:
            mask &= b >= int(np.ceil(blue))
        if rgmax is not None:
            mask &= m <= int(np.floor(rgmax))
        if reg is not None:
            inside = mask & reg
            n_in = np.count_nonzero(inside)
            n_out[0] = np.count_nonzero(mask) - n_in
            if n_out[0] > OUTSIDE_NOISE_CHECK * n_in:
                n_out[0] = _structured_px(mask & ~reg)
            mask = inside
        return mask

    if method == "fixed":
        bm = BLUE_MIN_U8 * scale if bm is None else bm
        rg = RG_MAX_U8 * scale if rg is None else rg
        mask = _bounds(np.ones(rgb.shape[:2], bool), bm, rg)
        return ThresholdResult(mask, float(bm), float(rg), "fixed", None, scale,
                               region_fraction=reg_frac, n_outside=n_out[0],
                               note="" if mask.any() else _range_note(rgb, reg).rstrip("; "))
    if method == "otsu":
        rg = RG_MAX_U8 * scale if rg is None else rg
        dd = d if reg is None else d[reg]
        if dd.min() == dd.max():
            t = float(dd.max()) + 1.0  # uniform image: nothing dominates
        else:
            t = max(_otsu_u8(dd / scale) * scale, 1.0)
        mask = _bounds(_at_least(d, t), None, rg)
        return ThresholdResult(mask, None, float(rg), "otsu", t, scale, region_fraction=reg_frac,
                               n_outside=n_out[0],
                               note="" if mask.any() else _range_note(rgb, reg).rstrip("; "))
    levels = _auto_levels(d, m, reg, scale, features)
    if levels is None:
        note, options = _marks_of_another_colour(rgb, reg, scale)
        blue = _at_least(b, BLUE_MIN_U8 * scale) & _at_most(m, RG_MAX_U8 * scale)
        n_blue = int(np.count_nonzero(blue if reg is None else blue & reg))
        if not note and 0 < n_blue < FEW_INK_PX:
            # ink there is, but too little of it for a class of its own: the contrast
            # advice below would be wrong
            note = (f"only {n_blue} px are blue ink by the paper's rule (blue >= "
                    f"{BLUE_MIN_U8:g}, red and green <= {RG_MAX_U8:g}), too few for a class of "
                    "their own (a blank scan, or the wrong file?); to read them all the same: "
                    "--threshold-method fixed (in Python threshold_method='fixed')")
            options = "--threshold-method fixed"
        note = note or (
            f"no ink darker in red and green than the paper by {MIN_CONTRAST_U8:g} (uint8 "
            "units); for faint ink set the cut with --threshold-method fixed --blue-min B "
            "--rg-max R (in Python threshold_method='fixed', blue_min=B, rg_max=R)")
        return ThresholdResult(np.zeros(rgb.shape[:2], bool), bm, rg, "auto", None, scale,
                               region_fraction=reg_frac,
                               note=_range_note(rgb, reg) + "no blue-dominant class: " + note,
                               options=options)
    ink, paper = levels
    d_cut = 0.5 * (ink[0] + paper[0]) * scale
    m_cut = 0.5 * (ink[1] + paper[1]) * scale
    rg_used = m_cut if rg is None else min(m_cut, rg)
    mask = _bounds(_at_least(d, d_cut), bm, rg_used)
    return ThresholdResult(mask, bm, float(rg_used), "auto", float(d_cut), scale,
                           tuple(v * scale for v in ink), tuple(v * scale for v in paper),
                           reg_frac, n_outside=n_out[0])


#: Fewer pixels than this passing the paper's rule, where the automatic threshold finds no ink
#: class, are too little ink, not too faint (the class statistics need 10-20 px of it).
FEW_INK_PX = 50
#: Share of the ink inside the region above which the pixels passing the cut outside it are
#: told from noise (:func:`_structured_px`): below it no quality check can fire on them.
OUTSIDE_NOISE_CHECK = 0.01
#: Fewest pixels of a connected piece of ink counted outside the region: a line 2 px wide
#: and 10 px long. The scattered pixels that a plate close to the cut's colour puts through it
#: with the scan's noise are pieces of 1-4 px (a bluish plate: 1 899 of them, 5.4 % of the
#: ink).
OUTSIDE_MIN_PIECE_PX = 20


def _structured_px(mask) -> int:
    """Pixels of ``mask`` in 8-connected pieces of at least :data:`OUTSIDE_MIN_PIECE_PX`:
    ink, however thin, rather than a plate's noise (20 ms on a 2000 x 2000 scan whose
    outside holds 2 % noise pixels; made only past :data:`OUTSIDE_NOISE_CHECK`)."""
    import cv2

    _, _, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8), connectivity=8)
    area = stats[1:, cv2.CC_STAT_AREA]
    return int(area[area >= OUTSIDE_MIN_PIECE_PX].sum())


#: Least difference (uint8 units) in the larger of red and green between the paper and a class
#: of marks for :func:`_marks_of_another_colour` to name them: a pen's line on paper differs
#: by 150 or more, a faded blue ink by less than the automatic cut's own contrast.
OTHER_MARKS_CONTRAST_U8 = 60.0
#: Marks whose channels spread less than this (uint8 units), and less than
#: :data:`NEUTRAL_SATURATION` of their brightest channel, are neutral (black or grey): a dark
#: purple (48, 23, 62) spreads 39 levels, 63 % of its blue.
NEUTRAL_SPREAD_U8 = 40.0
NEUTRAL_SATURATION = 0.35
_HUES = ((15, "red"), (45, "orange or brown"), (70, "yellow"), (165, "green"), (195, "cyan"),
         (255, "blue"), (335, "purple"), (360, "red"))


#: Least share of the pixels of a class between the marks and the paper for it to be a plate
#: framing the paper: a blurred line's edge pixels, also between the two, are a few per cent.
PLATE_CLASS_SHARE = 0.1


def _three_classes(px, rg):
    """Marks, plate and paper (median colours) when ``rg``, the larger of red and green of
    the pixels ``px``, splits into three classes (Otsu's method, three classes) whose darkest
    holds at most half the pixels and lies :data:`OTHER_MARKS_CONTRAST_U8` below a middle
    class of :data:`PLATE_CLASS_SHARE` or more; ``(None, None, None)`` otherwise."""
    from skimage.filters import threshold_multiotsu

    if np.ptp(rg) == 0:
        return None, None, None
    try:
        lo, hi = threshold_multiotsu(rg, classes=3)
    except ValueError:  # fewer than three grey levels
        return None, None, None
    c0, c2 = rg <= lo, rg > hi
    c1 = ~c0 & ~c2
    n = len(rg)
    if not (0 < np.count_nonzero(c0) <= 0.5 * n and np.count_nonzero(c1) >= PLATE_CLASS_SHARE * n
            and np.count_nonzero(c2)):
        return None, None, None
    ink, plate, paper = (np.median(px[c], axis=0) for c in (c0, c1, c2))
    if plate[:2].max() - ink[:2].max() < OTHER_MARKS_CONTRAST_U8:
        return None, None, None
    return ink, plate, paper


#: Pixels less than half covered by marks of another colour that pass a cut of the paper's
#: rule, per pixel of the marks, above which the cut takes a surface for marks (the surfaces
#: receding behind a bright red ink's cut, at the cut halfway to the paper: 0.2 to 0.9; the
#: marks' own blurred edges and noise: 0.015 at most) ...
SURFACE_SHARE = 0.1
#: ... and least share of the pixels three quarters covered by the marks or more that the cut
#: must pass (a cut that reads a red ink's bands: 0.93 to 1; one that breaks them: 0.82 or
#: less).
MARKS_SHARE = 0.9


def _rule_cut(px, ink, paper, level, *, by_low=False):
    """The bound of the paper's rule on the larger of red and green that reads the marks.

    The bound lies halfway between the marks' level and ``level`` (the nearest class's: the
    paper or a plate). When it passes pixels less than half covered by the marks (by the
    smaller of red and green), more than :data:`SURFACE_SHARE` times as many as the marks'
    (a surface lighter than the marks in the smaller of red and green but not in the
    larger, such as those receding behind a red ink's cut), it lies halfway between the
    marks and the median of those pixels instead. It reads the marks when it passes :data:`MARKS_SHARE` of the
    pixels at least three quarters covered by them (by the feature that told them apart) and
    at most :data:`SURFACE_SHARE` times as many others.

    Parameters
    ----------
    px : (N, 3) float array
        The sampled pixels, uint8 units.
    ink, paper : (3,) arrays
        The marks' and the paper's median colours.
    level : float
        The nearest class's larger of red and green.
    by_low : bool
        Whether the marks were told apart by the smaller of red and green
        (:func:`_marks_light_in_rg`), not the larger.

    Returns
    -------
    cut : float or None
        ``None`` when the bound does not read the marks.
    level : float
        What the bound stays below: ``level``, or the surface's.
    surface : bool
        Whether a surface set the bound.
    """
    low, rg = px[:, :2].min(axis=1), px[:, :2].max(axis=1)
    ink_low, paper_low = float(ink[:2].min()), float(paper[:2].min())
    if by_low:
        marks = low <= ink_low + 0.25 * (paper_low - ink_low)
    else:  # a plate dark in one of red and green only is not the marks'
        marks = rg <= ink[:2].max() + 0.25 * (paper[:2].max() - ink[:2].max())
    n = np.count_nonzero(marks)
    foreign = low > 0.5 * (ink_low + paper_low)
    surface = False
    cut = 0.5 * (float(ink[:2].max()) + level)
    passing = foreign & (rg <= cut)
    if np.count_nonzero(passing) > SURFACE_SHARE * n:
        level, surface = float(np.median(rg[passing])), True
        cut = 0.5 * (float(ink[:2].max()) + level)
    reads = (np.count_nonzero(marks & (rg <= cut)) >= MARKS_SHARE * n
             and np.count_nonzero(foreign & (rg <= cut)) <= SURFACE_SHARE * n)
    return (cut if reads else None), level, surface


def _marks_light_in_rg(px):
    """Marks dark in only one of red and green (a bright red ink, (190, 30, 35) on paper
    (249, 245, 239), lies 60 levels below it in the larger of the two, 215 in the smaller):
    the smaller of red and green of the pixels ``px`` split in three classes by Otsu's
    method, the darkest holding at most half the pixels and
    :data:`OTHER_MARKS_CONTRAST_U8` darker than the lightest (the paper).

    Returns
    -------
    None, or (ink, paper, bound)
        The marks' and the paper's median colours, and the marks' upper bound in the smaller
        of red and green.
    """
    from skimage.filters import threshold_multiotsu

    low = px[:, :2].min(axis=1)
    if np.ptp(low) == 0:
        return None
    try:
        lo, hi = threshold_multiotsu(low, classes=3)
    except ValueError:  # fewer than three grey levels
        return None
    marks, light = low <= lo, low > hi
    if not (0 < np.count_nonzero(marks) <= 0.5 * len(px) and np.count_nonzero(light)):
        return None
    ink, paper = np.median(px[marks], axis=0), np.median(px[light], axis=0)
    if paper[:2].min() - ink[:2].min() < OTHER_MARKS_CONTRAST_U8:
        return None
    return ink, paper, float(lo)


def _marks_of_another_colour(rgb, reg, scale) -> tuple[str, str]:
    """Why a scan without a blue-dominant class holds no blue ink, when it holds dark marks,
    and the options of the ``"fixed"`` method that read them.

    The larger of red and green of each pixel, the feature the paper's rule cuts, is split
    by Otsu's method (a sample of about 250 000 pixels of ``reg``) into three classes when
    they are marks, a plate framing the paper and the paper (:func:`_three_classes`), into
    two otherwise; a darkest class of at most half the pixels, darker than the paper by
    :data:`OTHER_MARKS_CONTRAST_U8`, is named by its median colour. Marks dark in only one
    of red and green (a bright red ink) are told apart by the smaller of the two
    (:func:`_marks_light_in_rg`) and named the same way. Such marks (a black or grey pen, a
    photocopy, a purple or red ink) can be cut by the paper's rule with the blue bound
    removed, and the note says with which bound: halfway to the nearest class, so that
    neither the paper nor a plate passes it, or halfway to a surface lighter than the marks
    that such a bound would pass (:func:`_rule_cut`). When no bound reads the marks on the
    scan's own pixels the note says so (and, for marks bright in one channel only, that
    swapping it with blue makes them blue ink, which the automatic threshold reads). A
    darkest class along most of the scan's edge is a plate or background, not marks: the
    note says so (marks lighter in red and green than a grey plate, such as a red ink,
    cannot be cut apart from it). Light marks of a blue hue are left to the faint-ink advice;
    dark ones are named blue-black (blue above red and green by too little for the classes).

    Returns
    -------
    note : str
        ``""`` when there is no such class.
    options : str
        ``"--threshold-method fixed --blue-min 0 --rg-max R"`` when a bound reads the marks,
        else ``""``.
    """
    import colorsys

    step = max(1, int(np.sqrt(rgb.shape[0] * rgb.shape[1] / 250_000)))
    px = rgb[::step, ::step]
    if reg is not None:
        px = px[reg[::step, ::step]]
    px = px.reshape(-1, 3).astype(np.float32) / scale
    if len(px) < 20:
        return "", ""
    rg = px[:, :2].max(axis=1)
    ink, nearest, paper = _three_classes(px, rg)
    if ink is None:
        dark = rg <= _otsu_u8(rg)
        if 0 < np.count_nonzero(dark) <= 0.5 * len(px):
            ink, paper = np.median(px[dark], axis=0), np.median(px[~dark], axis=0)
            nearest = paper
    light = ink is None or paper[:2].max() - ink[:2].max() < OTHER_MARKS_CONTRAST_U8
    if light:
        found = _marks_light_in_rg(px)
        if found is None:
            return "", ""
        ink, paper, edge_bound = found
        nearest = paper
    else:
        edge_bound = 0.5 * (ink[:2].max() + nearest[:2].max())
    colours = (f"(median RGB ({ink[0]:.0f}, {ink[1]:.0f}, {ink[2]:.0f}) on paper "
               f"({paper[0]:.0f}, {paper[1]:.0f}, {paper[2]:.0f}))")
    if reg is None:
        # marks lie inside the hole: a darkest class along most of the scan's edge is a
        # plate or background (darker in red and green than red or green marks on paper)
        sub = rgb[::step, ::step]
        edge = np.concatenate([sub[0], sub[-1], sub[1:-1, 0], sub[1:-1, -1]])
        edge = edge[:, :2].min(axis=1) if light else edge[:, :2].max(axis=1)
        if np.mean(edge / scale <= edge_bound) > 0.5:
            return (f"the scan's darkest pixels (median RGB ({ink[0]:.0f}, {ink[1]:.0f}, "
                    f"{ink[2]:.0f})) frame it: a plate or background, not marks, and no cut "
                    "on red and green tells marks from it; give the hole (--hole-radius-mm, "
                    "--hole-center-px) or crop the scan to it"), ""
    rg_cut, level, surface = _rule_cut(px, ink, paper, float(nearest[:2].max()), by_low=light)
    # marks bright in red (or green) alone turn into ink that is blue by as much; red marks
    # are what blue ink looks like in an array in OpenCV's BGR order
    k = int(np.argmax(ink))
    swap = (f"; swapping the scan's {('red', 'green')[k]} and blue channels makes them "
            "blue ink" + (" (an array in OpenCV's BGR order reads so: pass image[..., ::-1])"
                          if k == 0 else "")
            if k < 2 and ink[k] - np.delete(ink, k).max() >= OTHER_MARKS_CONTRAST_U8 else "")
    if rg_cut is None:
        options = ""
        what = ("the lighter surfaces around them" if surface
                else "the plate" if nearest is not paper else "the paper")
        recipe = (f", and no bound on red and green tells them from {what} (the larger of red "
                  f"and green: {ink[:2].max():.0f} on the marks, {level:.0f} there)" + swap)
    else:
        options = f"--threshold-method fixed --blue-min 0 --rg-max {rg_cut * scale:.0f}"
        recipe = (swap + "; to read them with the paper's rule without its blue bound: "
                  + options + f" (in Python threshold_method='fixed', blue_min=0, "
                  f"rg_max={rg_cut * scale:.0f})")
    spread = float(ink.max() - ink.min())
    # a dark colour spreads its channels little in grey levels, not in proportion
    if spread < NEUTRAL_SPREAD_U8 and spread < NEUTRAL_SATURATION * max(float(ink.max()), 1.0):
        return f"the scan's dark marks are black or grey {colours}, not blue ink" + recipe, options
    hue = 360.0 * colorsys.rgb_to_hsv(*(ink / 255.0))[0]
    name = next(n for h, n in _HUES if hue < h)
    if name == "blue":
        # ink nearly black: blue above red and green by less than the contrast the classes
        # need, which the faint-ink advice (darker than the paper by too little) misnames
        apart = (ink[2] - ink[:2].max()) - (paper[2] - paper[:2].max())
        if light or apart >= MIN_CONTRAST_U8:
            # blue ink the threshold tells apart well: the cause lies elsewhere (too little
            # of it, say), for the caller's own words
            return "", ""
        return (f"the scan's dark marks are blue-black {colours}: blue above red and green "
                f"sets them apart from the paper by {apart:.0f} only, less than the "
                f"{MIN_CONTRAST_U8:g} the automatic threshold needs" + recipe), options
    return (f"the scan's dark marks are {name} {colours}, not blue ink: the threshold is the "
            "paper's rule for a cut inked in blue" + recipe), options


#: Thin lines are looked for below this sheet thickness, px: a single sheet is then narrower
#: than about twice a scanner's blur (at 5 px per sheet only noise breaks a band, and the
#: threads drawn through noise read as bending: +47 % energy on a 50 px/mm scan at noise 20).
BRIDGE_MAX_H_PX = 3.0
#: A cut leaving at least this many pieces of ink in the frame is checked for thin lines broken
#: into dashes (:func:`bridge_broken_lines`); a scan's rod is one piece and a few specks.
BROKEN_MIN_PIECES = 8
#: ... and bridged when the cut halfway to the paper joins at least this many pieces of
#: ``min_piece_px`` or more, and a quarter of those.
BROKEN_MIN_JOINED = 5


def bridge_broken_lines(thr: ThresholdResult, features: ColourFeatures, region=None, *,
                        min_piece_px: float = 0.0):
    """Thin lines that the ``"auto"`` cut breaks into dashes, joined again by 1-px threads.

    The cut lies at half the contrast of the ink's level, read where bands are wide enough to
    reach it. A single sheet narrower than about twice the blur does not: at 20 px per mm
    (sheets 2.8 px wide) a cyan ink (blue dominance 66, half a navy's) blurred by 1.3 px
    passes the cut in dashes, and the dashes, too small to hold a branch, are cleaned away
    with the voids they closed (69 % of the voids lost on such a scan, F1 0.62). A cut
    halfway to the paper (a quarter of the contrast) joins the dashes again; the skeleton of
    what it joins (``skimage.morphology.skeletonize``) is added where it runs outside the
    mask, one pixel wide, so that no band is widened (its width gives its layer count).

    Only a scan that holds broken lines is bridged: its cut leaves :data:`BROKEN_MIN_PIECES`
    pieces of at least ``min_piece_px`` or more, and the lower cut joins
    :data:`BROKEN_MIN_JOINED` of them and a quarter. A scan's noise leaves 5-25 specks of
    1-27 px at 25 px/mm, which the lower cut joins to the bands: they do not count, and no
    scan of the robust or independent sweeps is bridged. On a bridged scan a thread is added
    where it touches the mask (a thread through nothing is a blob of the lower cut alone) and
    where the lower cut is no wider than the mask's bands (a pale smear is wide).

    Parameters
    ----------
    thr : ThresholdResult
        An ``"auto"`` threshold (other methods are returned unchanged).
    features : ColourFeatures
        The scan's features.
    region : (H, W) bool array, optional
        The scan's frame, as given to :func:`threshold_rgb`.
    min_piece_px : float
        Least area of a piece of a line, px (the pipeline: 3 h^2).

    Returns
    -------
    mask : (H, W) bool array
        ``thr.mask`` with the threads (the same array when none is added).
    n_px : int
        Pixels added.
    """
    import cv2

    mask = thr.mask
    if thr.method != "auto" or thr.paper_level is None or thr.dominance_min is None:
        return mask, 0
    n_main, lab_main = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
    if n_main - 1 < BROKEN_MIN_PIECES:
        return mask, 0
    big = np.bincount(lab_main.reshape(-1), minlength=n_main) >= min_piece_px
    big[0] = False
    if np.count_nonzero(big) < BROKEN_MIN_PIECES:
        return mask, 0
    d_low = 0.5 * (thr.paper_level[0] + thr.dominance_min)
    m_low = 0.5 * (thr.paper_level[1] + thr.rg_max)
    low = _at_least(features.dominance, d_low) & (features.darkness <= int(np.floor(m_low)))
    if region is not None:
        low &= region
    low |= mask
    _, lab_low = cv2.connectedComponents(low.view(np.uint8), connectivity=8)
    big_px = big[lab_main]
    keep = np.unique(lab_low[big_px])
    keep = keep[keep > 0]
    n_big = int(np.count_nonzero(big))
    joined = n_big - len(keep)
    if joined < max(BROKEN_MIN_JOINED, 0.25 * n_big):
        return mask, 0
    from skimage.morphology import skeletonize

    # the scan holds broken lines: every piece the lower cut joins to one of them is part of
    # a line, the smallest dots of the faintest stretches included
    hyst = np.isin(lab_low, keep)
    threads = skeletonize(hyst) & ~mask
    if not threads.any():
        return mask, 0
    # no wider than the bands: the lower cut's inscribed radius at the thread against the
    # mask's own (the bands' half widths)
    dt_low = cv2.distanceTransform(hyst.view(np.uint8), cv2.DIST_L2, 3)
    dt_main = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, 3)
    half = float(np.percentile(dt_main[mask], 95)) if mask.any() else 0.0
    threads &= dt_low <= max(half, 1.0) + 1.0
    # a thread piece touching the mask (an 8-neighbour of it)
    n_t, lab_t = cv2.connectedComponents(threads.view(np.uint8), connectivity=8)
    if n_t < 2:
        return mask, 0
    touched = np.unique(cv2.dilate(lab_t.astype(np.float32), np.ones((3, 3), np.uint8))[mask])
    touched = touched[touched > 0].astype(np.int64)
    if not len(touched):
        return mask, 0
    add = np.isin(lab_t, touched)
    return mask | add, int(np.count_nonzero(add))


#: :func:`missed_ink`: side of the square tiles whose own levels set a local cut, in
#: sheet thicknesses (20 h = 2 mm at h = 0.1 mm: a few bands and their paper in each tile, an
#: illumination gradient across a scan nearly flat over one)
LOCAL_TILE_H = 20.0


def missed_ink(thr: ThresholdResult, features: ColourFeatures, region, *,
               thickness_px: float, min_piece_px: float, disc=None):
    """Ink the scan's cut leaves out that the same rule, applied to each part of the scan,
    takes in: the pixels, and the count of those in pieces of at least ``min_piece_px``.

    ``"auto"`` chooses one cut for the whole frame, the midpoint of the ink's and the
    paper's levels. An illumination gradient multiplies the blue dominance, so on the dark
    side of a strongly lit scan (with a colour cast that raises the paper's level too) the
    ink's own level can fall below the cut: whole bands are lost there and nothing else
    looks wrong. Here the frame is cut into tiles of :data:`LOCAL_TILE_H` sheet thicknesses;
    a tile whose pixels hold a blue-dominant class (:func:`_auto_levels`, contrast
    :data:`MIN_CONTRAST_U8` or more) gets its own midpoint cuts, and its pixels that pass
    them (and the scan's darkness cut) but not the scan's cut are missed ink. Only pieces of
    ``min_piece_px`` or more count: every band has a rim of half-covered pixels that a
    slightly lower cut takes in, a thread a pixel wide along the band's edge, not a piece.
    Tiles are read only where pixels clear of that rim could be missed ink: about 1 ms on the
    sample scans and 10 ms on a 2200 x 2200 render where none are, tens of ms where ink is
    missed.

    Where pieces are missed, every pixel the local cuts take in is returned, the small pieces
    with the large: the tiles' cuts replace the scan's where they are lower, rims included
    (their midpoints are the half-covered level there, as the scan's cut is on an evenly lit
    scan), and ink at the level of the scan's cut, which dithers across it, leaves no seam a
    pixel wide across a band. The pipeline adds them to the mask where the count exceeds the
    ``ink_missed`` quality check's limit (:data:`crosssection.quality.INK_MISSED_LIMIT`), so
    that the ink is repaired where the check says so. Measured on 216 variants of
    the sparse, medium and dense sample scans (blue and yellow casts of 6, 10 and 15 %,
    gradients of +-20, 30 and 40 % along either axis, both ways): nothing is missed on 206
    (tables unchanged); on the other 10 (blue casts of 10 and 15 % at +-40 %) the scan's cut
    alone put the sum of n_br off by up to 5 and lost up to 5 junctions and 5.2 % of the rod
    (exact n_br 0.89-1.0 of the stack length), and with the pixels taken in they read every n_br
    right (exact n_br 1.0, the original scan's sum of n_br), the rod to within 0.42 % of the
    original scan's and its junctions on 8 (one short on the other 2). Bands were not thickened:
    no stack reads a layer more.

    Parameters
    ----------
    thr : ThresholdResult
        The ``"auto"`` cut of the scan (others: ``(None, 0)`` is returned).
    features : ColourFeatures
        The scan's features.
    region : (H, W) bool array or None
        The frame (inside the hole).
    disc : (row, col, radius_px), optional
        The hole's circle: missed pixels count inside it only (the frame's margin holds the
        wall band's edge and the plate pieces that
        :func:`~crosssection.stages.hole.trim_margin` took out, which local cuts would take in
        again). Tested in the tiles read only: a circle mask of the whole scan costs 6 ms.
    thickness_px : float
        Sheet thickness h in pixels (the tile's side).
    min_piece_px : float
        Least area of a missed piece.

    Returns
    -------
    taken : (H, W) bool array or None
        The pixels the local cuts take in and the scan's cut leaves out (inside ``region``),
        every piece of them; None when no piece reaches ``min_piece_px``.
    n_px : int
        Pixels of the pieces of ``min_piece_px`` or more: the missed ink.
    """
    import cv2

    if (thr.method != "auto" or thr.dominance_min is None or thr.rg_max is None
            or thr.paper_level is None):
        return None, 0
    reg = np.ones(features.shape, bool) if region is None else np.asarray(region, bool)
    rows, cols = np.flatnonzero(reg.any(axis=1)), np.flatnonzero(reg.any(axis=0))
    if not len(rows):
        return None, 0
    # the frame's box: nothing outside it can be ink
    frame = (slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1))
    reg, ink = reg[frame], np.ascontiguousarray(thr.mask[frame])
    d, m = features.dominance[frame], features.darkness[frame]
    blue = features.blue[frame] if thr.blue_min is not None else None
    scale = features.scale
    d_cut, m_cut = float(thr.dominance_min), float(thr.rg_max)
    # only pixels clear of the cut ink's rim, darker in red and green than the cut and bluer
    # than the paper by half the least contrast, can be missed ink: the levels are read only
    # in tiles that hold enough of them (counted on a 2 px lattice on large frames, as the
    # levels are: a missed piece holds a quarter of its pixels there)
    step = 2 if reg.size > 1_000_000 else 1
    d_floor = float(thr.paper_level[0]) + 0.5 * MIN_CONTRAST_U8 * scale  # native units
    ink_s = np.ascontiguousarray(ink[::step, ::step])
    near = cv2.dilate(ink_s.view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
    maybe = _at_least(d[::step, ::step], d_floor)
    maybe &= _at_most(m[::step, ::step], m_cut)
    maybe &= reg[::step, ::step]
    maybe &= ~near
    least = 0.25 * min_piece_px / step ** 2
    if np.count_nonzero(maybe) < least:
        return None, 0
    count = cv2.integral(maybe.view(np.uint8))
    tile = max(int(round(LOCAL_TILE_H * thickness_px)), 16)
    H, W = reg.shape
    missed = np.zeros((H, W), np.uint8)
    # tiles at half steps: a band on a tile's edge is whole in the next one
    for r0 in range(0, H, tile // 2):
        for c0 in range(0, W, tile // 2):
            r1, c1 = min(r0 + tile, H), min(c0 + tile, W)
            a0, b0, a1, b1 = (-(-v // step) for v in (r0, c0, r1, c1))
            if count[a1, b1] - count[a0, b1] - count[a1, b0] + count[a0, b0] < least:
                continue
            box = (slice(r0, r1), slice(c0, c1))
            reg_t = reg[box]
            if np.count_nonzero(reg_t) < 0.25 * tile * tile:
                continue
            levels = _auto_levels(d[box], m[box], reg_t, scale)
            if levels is None:
                continue
            (d_i, m_i), (d_p, m_p) = levels
            local_d = 0.5 * (d_i + d_p) * scale
            if local_d >= d_cut:
                continue
            local_m = min(0.5 * (m_i + m_p) * scale, m_cut)
            new = reg_t & _at_least(d[box], local_d) & _at_most(m[box], local_m) & ~ink[box]
            if blue is not None:  # a blue bound given to "auto" holds here too
                new &= blue[box] >= int(np.ceil(thr.blue_min))
            if disc is not None:
                rr = np.arange(r0, r1)[:, None] + (frame[0].start - disc[0])
                cc = np.arange(c0, c1)[None, :] + (frame[1].start - disc[1])
                new &= rr * rr + cc * cc <= disc[2] * disc[2]
            missed[box] |= new.view(np.uint8)
    if not missed.any():
        return None, 0
    _, _, stats, _ = cv2.connectedComponentsWithStats(missed, connectivity=8)
    area = stats[1:, cv2.CC_STAT_AREA]
    n_px = int(area[area >= min_piece_px].sum())
    if not n_px:
        return None, 0
    # every pixel the local cuts take in, the small pieces with the large: ink at the level
    # of the scan's cut dithers across it, and a column of it left between two pieces cuts a
    # band in two (a 5-layer band of a sample scan at a 15 % cast and +-40 %: two free ends,
    # rod +1.9 %, where all of it reads the rod to 0.03 %)
    taken = np.zeros(features.shape, bool)
    taken[frame] = missed.view(bool)
    return taken, n_px


#: :func:`faint_band_ends`: length of the stretch beyond a band's free end that is read, in
#: band widths (at least :data:`FAINT_MIN_H` sheet thicknesses), and the share of its samples
#: that must lie at or above the faint level for the band to be taken as continued there
FAINT_WIDTHS = 2.0
FAINT_MIN_H = 4.0
FAINT_SHARE = 0.8


def faint_band_ends(graph, dominance, *, paper_level: float, cut: float, mask, hole,
                    width_px, thickness_px: float) -> list:
    """Free band ends that fainter ink continues: a band whose ink fades below the cut.

    A marker running dry, or ink washed out along part of the rod, leaves bands that end in
    the middle of the scan where the rod goes on, lighter: the cut drops it and the rod loses
    that length, with nothing else wrong (a test scan whose ink faded to 35 % of its contrast
    across it lost 20 % of its rod, its junctions and stacks otherwise right). The fading ink
    is as light as the smears and the receding surfaces the cut is there to refuse, so it is
    not taken in; it is told by its shape. From each free end of a stack (a node of kind
    ``"end"``) a ray is followed along the end's direction (the chord of its skeleton from
    three widths to one width before the end: the last width may hook into a corner of the
    cut) for :data:`FAINT_WIDTHS` widths (at least :data:`FAINT_MIN_H` h) past the band's
    own cap, reading the bluest of three samples across it, a quarter width apart. The end
    is continued when :data:`FAINT_SHARE` of the ray's samples inside the hole (at least half
    of the ray must be) are bluer than the midpoint of the paper's dominance and the cut, the
    level of :func:`bridge_broken_lines` (a receding surface, blue by 8-16 levels over its
    grey, stays below it; a light-blue smear at a band's end passes). A ray meeting ink stops
    there.

    Parameters
    ----------
    graph : StackGraph
    dominance : (H, W) array
        ``blue - max(red, green)`` (native units, as ``cut`` and ``paper_level``).
    paper_level, cut : float
        The paper's dominance and the cut's (:class:`ThresholdResult` ``paper_level[0]`` and
        ``dominance_min``).
    mask : (H, W) bool array
        The ink.
    hole : Hole
    width_px : (M,) array
        Every stack's band width, px.
    thickness_px : float

    Returns
    -------
    list of (int, (float, float))
        The stack and the (row, col) of every end continued by fainter ink.
    """
    H, W = mask.shape
    level = 0.5 * (float(paper_level) + float(cut))
    cr, cc = (float(v) for v in hole.center_rc)
    inner = float(hole.radius_px) - float(thickness_px)
    found = []
    for sid, (u, v) in enumerate(graph.ends):
        w = max(float(width_px[sid]), float(thickness_px))
        for node, reverse in ((u, True), (v, False)):
            if graph.node_kind.get(node) != "end":
                continue
            path = np.asarray(graph.paths[sid], float)
            if reverse:
                path = path[::-1]
            # the direction before the cap, where the skeleton may hook into a corner
            k1 = min(len(path) - 3, int(round(w)))
            k2 = min(len(path) - 1, int(round(3 * w)))
            if k1 < 0 or k2 - k1 < 2:
                continue
            d = path[-1 - k1] - path[-1 - k2]
            n = math.hypot(*d)
            if n == 0:
                continue
            d /= n
            span = max(FAINT_WIDTHS * w, FAINT_MIN_H * thickness_px)
            t = np.arange(1.0, w + span)
            r = np.rint(path[-1, 0] + t * d[0]).astype(np.int64)
            c = np.rint(path[-1, 1] + t * d[1]).astype(np.int64)
            on = (r >= 0) & (r < H) & (c >= 0) & (c < W)
            r, c, t = r[on], c[on], t[on]
            ink = mask[r, c]
            # past the band's own cap (the skeleton ends inside it), up to the next ink
            paper = np.flatnonzero(~ink)
            if not len(paper):
                continue
            r, c, t, ink = r[paper[0]:], c[paper[0]:], t[paper[0]:], ink[paper[0]:]
            t = t - t[0]
            stop = np.flatnonzero(ink)
            keep = (t < span) & ((r - cr) ** 2 + (c - cc) ** 2 <= inner * inner)
            if len(stop):
                keep[stop[0]:] = False
            r, c = r[keep], c[keep]
            if len(r) < 0.5 * span:
                continue
            # the bluest of three samples across the ray: a direction a few degrees off
            # still reads a band as narrow as the one that ends
            q = 0.25 * w
            best = np.full(len(r), -np.inf)
            for o in (-q, 0.0, q):
                rr = np.clip(np.rint(r - o * d[1]).astype(np.int64), 0, H - 1)
                ccol = np.clip(np.rint(c + o * d[0]).astype(np.int64), 0, W - 1)
                best = np.maximum(best, dominance[rr, ccol])
            if np.count_nonzero(best >= level) >= FAINT_SHARE * len(r):
                found.append((sid, (float(path[-1, 0]), float(path[-1, 1]))))
    return found


#: ``dark_marks``: the least piece (in sheet thicknesses squared) of dark pixels that are not
#: ink counted as marks; the step of the lattice they are read on (px)
DARK_MARK_MIN_H2 = 4.0
DARK_MARK_STEP = 2
#: ``marks_on_ink``: how much greyer than any mix of ink and paper a pixel beside the ink must
#: be to count as a mark on it: its share of the ink's darkness (in red and green, from the
#: paper's to the ink's) exceeds its share of the ink's blue dominance by this much. A pixel
#: of the ink's rim, a mix, has the two shares equal; graphite (105, 105, 110) on the sample
#: scans 0.73, a black hair 1.1 or more; noise 20 and channels misregistered by a pixel let
#: a few rim pixels pass, in pieces of at most 0.15 % of the ink's area
ON_INK_GREYNESS = 0.4


@dataclass(frozen=True)
class DarkMarks:
    """Dark pixels inside the frame that are not ink, over the ink's pixels.

    Attributes
    ----------
    apart : float
        Marks apart from the ink: as dark as the ink in red and green (``dark_marks``).
    on_ink : float
        Marks lying on the ink's edge: darker than the ink itself (``marks_on_ink``).
    """

    apart: float = 0.0
    on_ink: float = 0.0


@njit(cache=True, nogil=True)
def _greyer_than_ink(dark, dom, where, paper_dark, d_dark, paper_dom, d_dom,
                     margin):  # pragma: no cover - numba
    """Where ``where``: the pixels whose share of the ink's darkness (red and green, from the
    paper's level to the ink's) exceeds their share of its blue dominance by ``margin``: equal
    on a mix of ink and paper, larger on a grey or black mark (a redder pixel counts no
    blue, not less). One pass over the lattice: under 1 ms against 12 ms for numpy's
    temporaries on the 1000 x 1000 lattice of a 2000 x 2000 scan."""
    out = np.zeros(where.shape, np.bool_)
    for i in range(where.shape[0]):
        for j in range(where.shape[1]):
            if where[i, j]:
                blue = (dom[i, j] - paper_dom) / d_dom
                out[i, j] = (dark[i, j] - paper_dark) / d_dark - max(blue, 0.0) > margin
    return out


def _pieces_share(cand, step: int, min_px: float, n_ink: int, touching=None) -> float:
    """The pixels of the 8-connected pieces of ``cand`` (a lattice of ``step`` px) of at
    least ``min_px`` pixels, and with ``touching`` only those holding one of its pixels,
    over ``n_ink``."""
    import cv2

    if not cand.any():
        return 0.0
    n, labels, stats, _ = cv2.connectedComponentsWithStats(
        np.ascontiguousarray(cand, np.uint8), connectivity=8)
    area = stats[:, cv2.CC_STAT_AREA].copy()
    area[0] = 0
    if touching is not None:
        hit = np.zeros(n, bool)
        hit[labels[np.asarray(touching, bool) & cand]] = True
        area[~hit] = 0
    return float(area[area * step * step >= min_px].sum()) * step * step / n_ink


def dark_marks(thr: ThresholdResult, features: ColourFeatures, region, *,
               thickness_px: float) -> DarkMarks:
    """Pixels inside the frame dark in red and green but not taken as ink (a black or grey
    pen, pencil, a shadow, a hair), in pieces of at least :data:`DARK_MARK_MIN_H2` h^2, over
    the ink's pixels.

    Dark means a larger of red and green below the midpoint of the ink's and the paper's
    (``"auto"``'s levels; with the other methods the median of the ink's pixels and of the
    frame's others). The ink's own rim, whose half-covered pixels are darker than the paper
    and less blue than the ink, is left out of ``apart``: pixels within ``max(3, h)`` px of
    the ink are not counted, nor those as near the frame's edge (a dark plate's rim inside
    the hole's circle). Within that distance of the ink, ``on_ink`` counts the pixels greyer
    than any mix of ink and paper (:data:`ON_INK_GREYNESS`), in pieces that touch the paper
    (a band's near-black core, which the cut leaves out and the cleaning fills, does not): a
    hair or a pencil line lying along a band's edge hides the ink under it, and the band
    reads narrower or is split (a black fibre 0.07 mm wide along 100 degrees of a sample
    scan's wall band: 3.0 % of the ink's area, 9 of 112 branches lost, rod length -6.3 %;
    graphite along a band: 0.5-0.9 %, energy +11 to +20 %, and along an inner stack +217 %;
    none of them flagged by another check). Read on a lattice of
    :data:`DARK_MARK_STEP` px (a piece of 4 h^2 holds 25 lattice points at h = 5 px), about
    5 ms on a 2000 x 2000 scan.

    Returns
    -------
    DarkMarks
        Zeros when the ink's and the paper's levels are not known or the frame holds no ink.
    """
    import cv2

    step = DARK_MARK_STEP
    mask = np.asarray(thr.mask, bool)
    n_ink = int(np.count_nonzero(mask))
    if not n_ink:
        return DarkMarks()
    dom, dark = features.lattice(step)
    ink = mask[::step, ::step]
    frame = np.ones_like(ink) if region is None else np.asarray(region, bool)[::step, ::step]
    if thr.ink_level is not None and thr.paper_level is not None:
        (ink_dom, ink_dark), (paper_dom, paper_dark) = (
            (float(a), float(b)) for a, b in (thr.ink_level, thr.paper_level))
    else:
        if not (frame & ~ink).any():
            return DarkMarks()
        ink_dom, ink_dark = float(np.median(dom[ink])), float(np.median(dark[ink]))
        paper_dom = float(np.median(dom[frame & ~ink]))
        paper_dark = float(np.median(dark[frame & ~ink]))
    if not paper_dark - ink_dark > MIN_CONTRAST_U8 * features.scale:
        return DarkMarks()
    cut = 0.5 * (ink_dark + paper_dark)
    rim = max(3.0, float(thickness_px)) / step
    size = 2 * int(math.ceil(rim)) + 1
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    near = cv2.dilate(np.ascontiguousarray(ink, np.uint8), disc) > 0
    # nor the frame's own edge, where a dark plate's rim inside the hole's circle runs
    inner = cv2.erode(np.ascontiguousarray(frame, np.uint8), disc,
                      borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
    min_px = DARK_MARK_MIN_H2 * thickness_px ** 2
    apart = _pieces_share((dark < cut) & inner & ~near, step, min_px, n_ink)
    if not ink_dom - paper_dom > MIN_CONTRAST_U8 * features.scale:
        return DarkMarks(apart=apart)
    grey = _greyer_than_ink(dark, dom, near & ~ink, paper_dark, ink_dark - paper_dark,
                            paper_dom, ink_dom - paper_dom, ON_INK_GREYNESS)
    # pieces on the ink's edge, touching the paper: not a dark core the cut left inside a
    # band (the cleaning fills it)
    paper = cv2.dilate(np.ascontiguousarray(frame & ~ink & ~grey, np.uint8),
                       np.ones((3, 3), np.uint8)) > 0
    return DarkMarks(apart=apart, on_ink=_pieces_share(grey & inner & near, step, min_px,
                                                       n_ink, touching=paper))
