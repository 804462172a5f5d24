"""Stage 3: fill the empty spaces smaller than ``s_min`` and remove foreground specks.

Paper, section "Image analysis procedure": "empty spaces of surface area larger than
s_min = (10 h)^2 are kept, allowing to remove light noise from the binary image". Hence:

- background components (4-connected, the dual of 8-connected ink) with area < ``s_min_px``
  are filled; the paper detects voids of area >= s_min only;
- foreground components (8-connected) with area < ``speck_px`` are removed. The design default
  is ``speck_px = s_min_px``; ``pipeline.analyze`` passes ``min(s_min_px, l_min h)`` in px,
  the area of the smallest detectable single-sheet stack (l_min long, h thick), so that no
  stack above the detection limit is erased as a speck.

Implemented with OpenCV's connected components: the background labelled once, the ink once
with its areas and bounding boxes (specks and short components in the same pass), same result
as ``skimage.morphology.remove_small_holes`` + ``remove_small_objects`` (2000x2000 scan: about
half the time of labelling the ink twice and counting areas with ``np.bincount``).
"""
from __future__ import annotations

import numpy as np

from crosssection.core.errors import ParameterError


def _small_components(binary_u8: np.ndarray, connectivity: int, max_area: float) -> np.ndarray:
    """Bool mask of the nonzero pixels of components with area < max_area.

    Labels are 16-bit while there are fewer than 65 536 components (OpenCV raises past
    that, and 32-bit labels take over): their areas are then one ``cv2.calcHist`` with a bin
    per label, 4 ms against 12 ms for ``np.bincount`` of 32-bit labels (2000x2000 scan).
    Its float32 counts are exact below 2^24 pixels; larger images count with ``bincount``.
    """
    import cv2

    lab = None
    if binary_u8.size < 2**24:
        try:
            n, lab = cv2.connectedComponents(binary_u8, connectivity=connectivity,
                                             ltype=cv2.CV_16U)
        except cv2.error:  # more than 65 535 labels
            lab = None
    if lab is None:
        n, lab = cv2.connectedComponents(binary_u8, connectivity=connectivity,
                                         ltype=cv2.CV_32S)
    if n <= 1:
        return np.zeros(binary_u8.shape, bool)
    if lab.dtype == np.uint16:
        # bins of width 1 from 0: bin k counts label k exactly
        area = cv2.calcHist([lab], [0], None, [n], [0, n]).ravel()
    else:
        area = np.bincount(lab.ravel(), minlength=n)
    small = area < max_area
    small[0] = False  # label 0 is the complement
    if not small.any():
        return np.zeros(binary_u8.shape, bool)
    return np.take(small, lab)


def _drop_components(binary_u8: np.ndarray, min_area: float, min_extent_px: float) -> np.ndarray:
    """Bool mask of the 8-connected components of area >= ``min_area`` whose bounding-box
    diagonal is at least ``min_extent_px``.

    One labelling gives both (the components are the same before and after removing
    either kind). With statistics, the block-based algorithm labels 8-connected images about
    3x faster than OpenCV's default (2000x2000 scan: 14 ms against 38 ms of CPU).
    """
    import cv2

    n, lab, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(
        binary_u8, 8, cv2.CV_32S, cv2.CCL_BBDT)
    if n <= 1:
        return binary_u8.view(bool).copy()
    extent = np.hypot(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT])
    keep = (stats[:, cv2.CC_STAT_AREA] >= min_area) & ~(extent < min_extent_px)
    keep[0] = False
    if keep[1:].all():
        return binary_u8.view(bool).copy()
    return np.take(keep, lab)


def clean_mask(mask, *, s_min_px: float, speck_px: float | None = None,
               min_extent_px: float = 0.0) -> np.ndarray:
    """Fill background holes smaller than ``s_min_px``, remove specks smaller than ``speck_px``.

    Parameters
    ----------
    mask : (H, W) bool array
        Thresholded ink.
    s_min_px : float
        Smallest void kept, in px^2 (paper: s_min = (10 h)^2).
    speck_px : float, optional
        Smallest ink component kept, in px^2 (default ``s_min_px``).
    min_extent_px : float, optional
        Ink components whose bounding box has a diagonal shorter than this are removed
        whatever their area (default 0: off). Pass the detection limit ``l_min`` in px: a
        component that short holds no branch of length >= l_min, and no ring around a void
        of area >= s_min = (10 h)^2 (paper, "Image analysis procedure"). Unlike an area,
        this limit does not depend on how thick a dust speck is, which matters at low
        resolution where the area of a real single-sheet stack, l_min h, is only a few
        times a speck's.

    Returns
    -------
    (H, W) bool array
        Holes are filled first, then specks removed (a speck with a hole is judged on its
        filled area).
    """
    m = np.asarray(mask)
    if m.ndim != 2:
        raise ParameterError(f"mask must be 2-D, got shape {m.shape}")
    if not np.isfinite(s_min_px) or s_min_px < 0:
        raise ParameterError(f"s_min_px must be a finite number >= 0, got {s_min_px}")
    speck_px = s_min_px if speck_px is None else speck_px
    if not np.isfinite(speck_px) or speck_px < 0:
        raise ParameterError(f"speck_px must be a finite number >= 0, got {speck_px}")
    if not np.isfinite(min_extent_px) or min_extent_px < 0:
        raise ParameterError(f"min_extent_px must be a finite number >= 0, got {min_extent_px}")
    m = np.ascontiguousarray(m, dtype=bool)
    out = m.copy()
    if s_min_px > 0:
        bg = (~m).view(np.uint8)
        out |= _small_components(bg, 4, s_min_px)
    if speck_px > 0 or min_extent_px > 0:
        out = _drop_components(out.view(np.uint8), speck_px, min_extent_px)
    return out
