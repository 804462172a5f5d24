"""Stage 3: fill the empty spaces smaller than ``s_min`` and remove foreground specks.

Paper, section "Image analysis procedure": "empty spaces of surface area larger than
s_min = (10 h)^2 are kept, allowing to remove light noise from the binary image". Hence:

- background components (4-connected, the dual of 8-connected ink) with area < ``s_min_px``
  are filled; the paper detects voids of area >= s_min only;
- foreground components (8-connected) with area < ``speck_px`` are removed. The design default
  is ``speck_px = s_min_px``; ``pipeline.analyze`` passes ``min(s_min_px, l_min h)`` in px,
  the area of the smallest detectable single-sheet stack (l_min long, h thick), so that no
  stack above the detection limit is erased as a speck.

Implemented with OpenCV's connected components and ``np.bincount`` (measured on a 2000x2000
mask: 2 x 22 ms, against 80 ms for ``skimage.morphology.remove_small_holes`` +
``remove_small_objects``, same result).
"""
from __future__ import annotations

import numpy as np

from crosssection.core.errors import ParameterError


def _small_components(binary_u8: np.ndarray, connectivity: int, max_area: float) -> np.ndarray:
    """Bool mask of the nonzero pixels of components with area < max_area."""
    import cv2

    n, lab = cv2.connectedComponents(binary_u8, connectivity=connectivity, ltype=cv2.CV_32S)
    if n <= 1:
        return np.zeros(binary_u8.shape, bool)
    area = np.bincount(lab.ravel(), minlength=n)
    small = area < max_area
    small[0] = False  # label 0 is the complement
    if not small.any():
        return np.zeros(binary_u8.shape, bool)
    return small[lab]


def _short_components(binary_u8: np.ndarray, min_extent_px: float) -> np.ndarray:
    """Bool mask of the 8-connected components whose bounding-box diagonal is shorter than
    ``min_extent_px``."""
    import cv2

    n, lab, stats, _ = cv2.connectedComponentsWithStats(binary_u8, connectivity=8,
                                                        ltype=cv2.CV_32S)
    if n <= 1:
        return np.zeros(binary_u8.shape, bool)
    extent = np.hypot(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT])
    short = extent < min_extent_px
    short[0] = False
    if not short.any():
        return np.zeros(binary_u8.shape, bool)
    return short[lab]


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
    if speck_px > 0:
        out &= ~_small_components(out.view(np.uint8), 8, speck_px)
    if min_extent_px > 0:
        out &= ~_short_components(out.view(np.uint8), min_extent_px)
    return out
