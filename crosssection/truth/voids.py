"""Ground-truth voids of a drawn scene, one definition for every generator.

A void (paper, section "Tiling") is a connected background region enclosed by the ink: a
4-connected component of the background (the complement of the 8-connected ink) that touches
neither the image border nor the outside of the hole circle, with area ``>= s_min``. A region
closed partly by the rod and partly by the wall is therefore not a void, as in the pipeline.

The generators call :func:`truth_voids` on their noise-free drawing, possibly supersampled
(``supersample`` pixels per scan pixel), never on the degraded image.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import pandas as pd

from crosssection.core import schema

__all__ = ["VoidTruth", "truth_voids"]


@dataclass(frozen=True)
class VoidTruth:
    """Voids of a drawing.

    Attributes
    ----------
    table : DataFrame
        One row per void in :data:`crosssection.core.schema.VOID_COLUMNS`; lengths in scan
        pixels / mm, centroids in scan pixels (x = column, y = row).
    n_small : int
        Enclosed background regions of at least one scan pixel but below ``s_min`` (a valid
        drawing has none: they would be specks of paper the cleaning removes).
    enclosed : np.ndarray
        Bool mask (drawing resolution) of all enclosed background, voids and smaller regions.
    """

    table: pd.DataFrame
    n_small: int
    enclosed: np.ndarray


def _outside(shape, supersample, hole_center_xy, hole_radius_px):
    """Pixels on the image border or whose centre lies outside the hole circle."""
    out = np.zeros(shape, bool)
    out[0, :] = out[-1, :] = out[:, 0] = out[:, -1] = True
    if hole_radius_px is not None:
        yy, xx = np.ogrid[:shape[0], :shape[1]]
        cx, cy = hole_center_xy
        out |= (((xx + 0.5) / supersample - cx) ** 2 + ((yy + 0.5) / supersample - cy) ** 2
                > hole_radius_px ** 2)
    return out


def _void_row(lab, i, stats, centroid, supersample, stack_labels, stack_ends, px_per_mm,
              contact_px):
    """One row of the voids table for component ``i`` of ``lab``; ``contact_px[k]`` is
    the contact length (scan px) that makes stack ``k`` a side of the void."""
    ss = supersample
    x0, y0, w0, h0 = stats[i, :4]
    pad = 3 * ss
    xs, ys = max(0, x0 - pad), max(0, y0 - pad)
    window = (slice(ys, y0 + h0 + pad), slice(xs, x0 + w0 + pad))
    crop = (lab[window] == i).astype(np.uint8)
    contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    outline = max(contours, key=cv2.contourArea)
    # the outline joins boundary pixel centres, half a drawing pixel inside the region's
    # edge: an outline offset outwards by d gains 2 pi d (Steiner's formula for parallel curves)
    perim_px = (cv2.arcLength(cv2.approxPolyDP(outline, 0.5 * ss, True), True) + math.pi) / ss
    # the stacks whose ink borders the void, then their junctions: the paper counts "the
    # junction points belonging to each void contour". A ring one scan pixel wide around the
    # void also grazes, at its corners, the bands of the other stacks of its junctions, over
    # less than their width: a side borders the void along its width or more.
    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * ss + 1, 2 * ss + 1))
    ring = (cv2.dilate(crop, ker) & (crop == 0)).astype(bool)
    labels, contact = np.unique(stack_labels[window][ring], return_counts=True)
    labels, contact = labels[labels > 0] - 1, contact[labels > 0]
    adjacent = labels[contact >= contact_px[labels] * ss * ss]
    junctions = np.unique(np.asarray(stack_ends, dtype=np.int64).reshape(-1, 2)[adjacent])
    area_mm2 = stats[i, cv2.CC_STAT_AREA] / (px_per_mm * ss) ** 2
    perim_mm = perim_px / px_per_mm
    cx, cy = centroid / ss
    return {"void_id": 0, "area_mm2": area_mm2, "perimeter_mm": perim_mm,
            "shape_ratio": math.sqrt(area_mm2) / perim_mm,
            "n_edges": int((junctions >= 0).sum()), "centroid_x_px": cx, "centroid_y_px": cy}


def truth_voids(ink: np.ndarray, *, supersample: int = 1, hole_center_xy=None,
                hole_radius_px: float | None = None, s_min_px: float, px_per_mm: float,
                stack_labels: np.ndarray, stack_ends, stack_widths_px,
                min_contact_px: float) -> VoidTruth:
    """The voids of a noise-free drawing (module docstring for the definition).

    Parameters
    ----------
    ink : 2-D bool or uint8 array
        The drawn ink (nonzero = ink), at ``supersample`` times the scan resolution.
    supersample : int
        Drawing pixels per scan pixel, along each axis.
    hole_center_xy : (float, float), optional
        Hole centre (x = column, y = row) in scan pixels; needed with ``hole_radius_px``.
    hole_radius_px : float, optional
        Hole radius in scan pixels; None: only the image border bounds the background.
    s_min_px : float
        Smallest void area, in scan pixels.
    px_per_mm : float
        Scan resolution.
    stack_labels : 2-D int array
        Same shape as ``ink``: ``k + 1`` on the ink of stack ``k``, 0 elsewhere.
    stack_ends : (M, 2) int array-like
        Junction ids at the two ends of every stack (-1: no junction).
    stack_widths_px : (M,) array-like
        Band width of every stack.
    min_contact_px : float
        Least length (scan pixels) along which a stack's ink borders a void it bounds, also
        for thin stacks (e.g. two sheet thicknesses). A stack bounds a void when their contact
        is at least ``max(min_contact_px, width)``.

    Returns
    -------
    VoidTruth
        Voids numbered in raster order of their first pixel.
    """
    ss = int(supersample)
    background = (np.asarray(ink) == 0).astype(np.uint8)
    n_lab, lab, stats, centroids = cv2.connectedComponentsWithStats(background, connectivity=4)
    excluded = np.zeros(n_lab, bool)
    excluded[np.unique(lab[_outside(lab.shape, ss, hole_center_xy, hole_radius_px)])] = True
    excluded[0] = True  # the ink
    contact_px = np.maximum(np.asarray(stack_widths_px, float), min_contact_px)
    rows, n_small = [], 0
    s_min_draw = s_min_px * ss * ss
    for i in np.flatnonzero(~excluded):
        area = stats[i, cv2.CC_STAT_AREA]
        if area < s_min_draw:
            n_small += int(area >= ss * ss)
            continue
        rows.append(_void_row(lab, i, stats, centroids[i], ss, stack_labels, stack_ends,
                              px_per_mm, contact_px))
    table = pd.DataFrame(rows, columns=schema.VOID_COLUMNS) if rows else schema.empty_table("voids")
    table["void_id"] = np.arange(len(table))
    return VoidTruth(table, n_small, ~excluded[lab])
