"""Stage 3: fill the empty spaces smaller than ``s_min`` and remove foreground specks.

Paper, section "Image analysis procedure": "empty spaces of surface area larger than
s_min = (10 h)^2 are kept, allowing to remove light noise from the binary image". Hence:

- background components (4-connected, the dual of 8-connected ink) with area < ``s_min_px``
  are filled; the paper detects voids of area >= s_min only;
- except the slivers (:func:`is_sliver`): a hole smaller than ``s_min`` whose length reaches
  the detection limit ``l_min`` and whose width reaches 1.5 sheet thicknesses
  (``AnalysisParams.sliver_width_h``) is paper between two stacks, not noise. The paper's
  stacks are "branches in close contact, separated by distances smaller than the image
  resolution"; a gap wider than a sheet along a branch's length is resolved, so filling it
  would merge two stacks into one and erase the two junctions at its tips. On renders of rods
  compacted to epsilon 14-19 (11 scans) the lenses between two truth stacks were 1.8-2.9 h
  wide and the holes inside one truth stack (a pass standing off a band by less than the
  contact distance) 0.7-1.1 h (docs/validation/compact.md, "Slivers between stacks are
  kept"). Compact holes (pinholes, a small void between three stacks) stay filled: a sliver
  is at least :data:`SLIVER_ASPECT` times longer than wide. The void statistics still count
  only voids of area >= s_min (:mod:`crosssection.stages.voids`);
- foreground components (8-connected) with area < ``speck_px`` are removed. The design default
  is ``speck_px = s_min_px``; ``pipeline.analyze`` passes ``min(s_min_px, l_min h)`` in px,
  the area of the smallest detectable single-sheet stack (l_min long, h thick), so that no
  stack above the detection limit is erased as a speck.

Implemented with one OpenCV border following (``cv2.findContours``, the hierarchy of the
ink's outer borders and of its holes' borders), which gives every component and every hole
with its bounding box; every hole, and every component its box cannot decide, is measured by a
flood fill of its own box, the same fill that fills a small hole or erases a speck. Same result as
``skimage.morphology.remove_small_holes`` + ``remove_small_objects`` (and as labelling the
background and the ink, the way kept for the cases the borders cannot settle; see
:func:`clean_mask`). A 2000x2000 scan with about 290 holes and 50 ink components: 18 ms of CPU,
against 85 ms for the two labellings, which also gather a full-image lookup each.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from crosssection.core.errors import ParameterError
from crosssection.params import _number


def _small_components(binary_u8: np.ndarray, connectivity: int, max_area: float,
                      count: bool = False):
    """Bool mask of the nonzero pixels of components with area < max_area (and the number of
    components, with ``count``).

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
    out = np.zeros(binary_u8.shape, bool)
    if n > 1:
        if lab.dtype == np.uint16:
            # bins of width 1 from 0: bin k counts label k exactly
            area = cv2.calcHist([lab], [0], None, [n], [0, n]).ravel()
        else:
            area = np.bincount(lab.ravel(), minlength=n)
        small = area < max_area
        small[0] = False  # label 0 is the complement
        if small.any():
            out = np.take(small, lab)
    return (out, n - 1) if count else out


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


#: A hole at least this many times longer than wide is a sliver (:func:`is_sliver`); the
#: slivers between stacks measured on renders of compacted rods are 9-24 times.
SLIVER_ASPECT = 4.0


def is_sliver(hole_u8: np.ndarray, *, length_px: float, width_px: float) -> bool:
    """Whether one background hole is a resolved gap between two stacks.

    Parameters
    ----------
    hole_u8 : 2-D uint8 array
        The hole (nonzero) in a box whose border rows and columns are not hole.
    length_px : float
        Least length, along the hole (half its perimeter), in px.
    width_px : float
        Least width (the widest inscribed disc's diameter), in px.

    Returns
    -------
    bool
        True when the hole is at least ``length_px`` long, ``width_px`` wide, and
        :data:`SLIVER_ASPECT` times longer than wide.
    """
    import cv2

    hole = np.ascontiguousarray(hole_u8 != 0, dtype=np.uint8)
    # distance to the nearest non-hole pixel: a strip w pixels wide peaks at (w + 1) / 2
    width = 2.0 * float(cv2.distanceTransform(hole, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).max()) - 1
    if width < width_px:
        return False
    contours, _ = cv2.findContours(hole, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    length = max(cv2.arcLength(c, True) for c in contours) / 2
    return length >= length_px and length >= SLIVER_ASPECT * width


def clean_mask(mask, *, s_min_px: float, speck_px: float | None = None,
               min_extent_px: float = 0.0, sliver_length_px: float = 0.0,
               sliver_width_px: float = 0.0) -> np.ndarray:
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
    sliver_length_px, sliver_width_px : float, optional
        Holes smaller than ``s_min_px`` that are at least this long and this wide, and
        :data:`SLIVER_ASPECT` times longer than wide, are kept (:func:`is_sliver`; module
        docstring). Either one 0 (the default): off, every hole below ``s_min_px`` is
        filled. The pipeline passes ``l_min`` and ``sliver_width_h`` h in px.

    Returns
    -------
    (H, W) bool array
        Holes are filled first, then specks removed (a speck with a hole is judged on its
        filled area).
    """
    m = np.asarray(mask)
    if m.ndim != 2 or m.size == 0:
        raise ParameterError(f"mask must be a 2-D array with pixels, got shape {m.shape}")
    _number("s_min_px", s_min_px, allow_equal=True)
    speck_px = s_min_px if speck_px is None else speck_px
    _number("speck_px", speck_px, allow_equal=True)
    _number("min_extent_px", min_extent_px, allow_equal=True)
    for name, v in (("sliver_length_px", sliver_length_px), ("sliver_width_px", sliver_width_px)):
        if not np.isfinite(v) or v < 0:
            raise ParameterError(f"{name} must be a finite number >= 0, got {v}")
    sliver = ((float(sliver_length_px), float(sliver_width_px))
              if sliver_length_px > 0 and sliver_width_px > 0 else None)
    m = np.ascontiguousarray(m, dtype=bool)
    if m.size and _borders_settle(m, s_min_px) and not _pixel_texture(m):
        out = _clean_by_borders(m, s_min_px, speck_px, min_extent_px, sliver)
        if out is not None:
            return out
    out = m.copy()
    if s_min_px > 0:
        bg = (~m).view(np.uint8)
        small, n_holes = _small_components(bg, 4, s_min_px, count=True)
        if sliver is not None:
            small &= ~_slivers(small, sliver, wide_only=n_holes > MANY_HOLES)
        out |= small
    if speck_px > 0 or min_extent_px > 0:
        out = _drop_components(out.view(np.uint8), speck_px, min_extent_px)
    return out


#: Above this many holes, :func:`_slivers` keeps to those wide enough to be slivers before
#: it measures their boxes.
MANY_HOLES = 65_535


def _slivers(holes: np.ndarray, sliver: tuple[float, float], wide_only: bool = False) -> np.ndarray:
    """Bool mask of the 4-connected components of ``holes`` that are slivers.

    ``wide_only``: first keep the components holding a pixel as far from the ink as a sliver's
    least width asks. The distance within the whole mask is at least the distance within the
    component's own box (:func:`is_sliver`), so no sliver is lost; the boxes of a texture's
    millions of one-pixel holes are not gathered (a 4000 x 4000 checkerboard: 1.3 GB).
    """
    import cv2

    holes_u8 = holes.view(np.uint8)
    if wide_only:
        dist = cv2.distanceTransform(holes_u8, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        wide = dist >= (sliver[1] + 1.0) / 2.0  # is_sliver's width 2 max(dist) - 1
        del dist
        if not wide.any():
            return np.zeros(holes.shape, bool)
        n, lab = cv2.connectedComponents(holes_u8, connectivity=4, ltype=cv2.CV_32S)
        keep = np.zeros(n, bool)
        keep[lab[wide]] = True
        keep[0] = False
        holes_u8 = np.take(keep, lab).view(np.uint8)
        del lab
    n, lab, stats, _ = cv2.connectedComponentsWithStats(holes_u8, connectivity=4)
    out = np.zeros(holes.shape, bool)
    # the box test of _may_be_sliver on every component at once (a texture's 190 000 pinholes
    # took 0.4 s one by one)
    long_enough = np.hypot(stats[:, 2], stats[:, 3]) >= sliver[0] / 2
    for i in np.flatnonzero(long_enough[1:]).tolist():
        i += 1
        x, y, bw, bh = stats[i, :4]
        box = np.pad(lab[y:y + bh, x:x + bw] == i, 1).view(np.uint8)
        if is_sliver(box, length_px=sliver[0], width_px=sliver[1]):
            out[y:y + bh, x:x + bw] |= lab[y:y + bh, x:x + bw] == i
    return out


def _may_be_sliver(bw: int, bh: int, sliver) -> bool:
    """A hole whose box diagonal is under half the sliver length curls too much to be the gap
    along a branch; its shape is not measured."""
    return sliver is not None and math.hypot(bw, bh) >= sliver[0] / 2


#: Above this many borders the labelling is cheaper than a flood fill per border (a scan of
#: salt-and-pepper noise; a clean 2000x2000 scan has a few hundred).
MAX_BORDERS = 4000


#: Ink/paper transitions per ink pixel above which the ink is a texture at the pixel scale
#: (noise, a checkerboard) rather than bands (two transitions per row across a band at least
#: two pixels wide: at most 1; 0.13 on the dense 2000 x 2000 benchmark scan)
TEXTURE_TRANSITIONS = 1.0
#: Mean run of paper between ink along a row, in px, below which the paper is a texture at
#: the pixel scale (the pinholes of ink covering 60-90 % of the hole): the voids between
#: stacks are ``s_min`` = (10 h)^2 and more, the slivers between stacks 1.5 h wide and more.
TEXTURE_PAPER_RUN_PX = 2.5
#: Runs of paper this many times :data:`TEXTURE_PAPER_RUN_PX` long on average are voids: the
#: tiles are not read (the dense benchmark scan's runs: 128 px).
TEXTURE_WIDE_PAPER = 3.0
#: Mean area, in px, of the ink pieces and paper pieces in small tiles of the ink below
#: which the ink is a texture (a checkerboard of 3 x 1 px bricks: 3 px; the bands of the
#: dense benchmark scan cut by the tiles: hundreds of px).
TEXTURE_PIECE_PX = 20.0
#: Side of the tiles, in px, and how many are read.
TEXTURE_TILE_PX = 48
TEXTURE_TILES = 12


def _sampled_rows(h: int) -> np.ndarray:
    """Every eighth row, its phase cycling through the eight, so that no pattern of period
    eight rows (a checkerboard with every eighth row inked) hides in the rows read."""
    r = np.arange(0, h, 8)
    return np.minimum(r + (np.arange(r.size) * 3) % 8, h - 1)


def _pixel_texture(m: np.ndarray) -> bool:
    """Whether the ink has so many borders that their hierarchy costs more than a labelling.

    ``cv2.findContours(RETR_TREE)`` grows faster than the square of the number of borders:
    on a 2000 x 2000 checkerboard of ink and paper inside a disk it took 196 s (the
    labelling, 0.05 s), on 5 % salt-and-pepper noise 1.8 s, on 60-80 % random ink inside a
    disk of 1500 px 4.9-7.7 s, on a 2000 x 2000 checkerboard of 3 x 1 px bricks 35 s. The
    transitions along every eighth row (:func:`_sampled_rows`; 0.2 ms on a 2000 x 2000 scan)
    tell such ink from bands: enough of them to exceed :data:`MAX_BORDERS` borders, and
    either more than :data:`TEXTURE_TRANSITIONS` per ink pixel (specks), runs of paper
    between ink shorter than :data:`TEXTURE_PAPER_RUN_PX` on average (pinholes), or, where
    those runs are shorter than :data:`TEXTURE_WIDE_PAPER` times that, in
    :data:`TEXTURE_TILES` tiles about ink pixels of those rows, pieces of ink and paper
    smaller than :data:`TEXTURE_PIECE_PX` on average (a texture of small pieces of both).
    The labelling gives the same result: a band scan taken for a texture only costs time.
    """
    row_index = _sampled_rows(m.shape[0])
    rows = m[row_index]
    transitions = np.count_nonzero(rows[:, 1:] != rows[:, :-1])
    if 8 * transitions <= 2 * MAX_BORDERS:
        return False
    if transitions > TEXTURE_TRANSITIONS * max(np.count_nonzero(rows), 1):
        return True
    # paper between each row's first and last ink pixel, and the runs it makes there
    inked = rows.any(axis=1)
    rows = rows[inked]
    first = rows.argmax(axis=1)
    last = rows.shape[1] - 1 - rows[:, ::-1].argmax(axis=1)
    paper_px = int(np.sum(last - first + 1)) - np.count_nonzero(rows)
    paper_runs = (transitions - 2 * rows.shape[0]) // 2  # two edges per row are its ends
    if paper_runs > 0 and paper_px < TEXTURE_PAPER_RUN_PX * paper_runs:
        return True
    if paper_runs <= 0 or paper_px >= TEXTURE_WIDE_PAPER * TEXTURE_PAPER_RUN_PX * paper_runs:
        return False  # paper in wide runs between the ink: voids, not a texture's gaps
    return _small_pieces(m, row_index[inked], rows)


def _small_pieces(m: np.ndarray, row_index: np.ndarray, rows: np.ndarray) -> bool:
    """Whether tiles about ink pixels of the sampled ``rows`` (each an inked row, at
    ``row_index`` in ``m``) hold pieces of ink (8-connected) and of paper (4-connected) of less
    than :data:`TEXTURE_PIECE_PX` on average: about an ink pixel of each of
    :data:`TEXTURE_TILES` rows spread over the inked ones, at fractions of the row's ink
    spread over the tiles (a texture on 40 % of every row beside solid ink: 30 s of border
    following at 2000 px when the tiles sat on each row's middle ink pixel)."""
    import cv2

    half = TEXTURE_TILE_PX // 2
    pieces = area = 0
    picks = np.linspace(0, len(rows) - 1, TEXTURE_TILES).astype(np.int64)
    for t, i in enumerate(picks.tolist()):
        xs = np.flatnonzero(rows[i])
        # an ink pixel at a fraction of the row's ink that the golden ratio spreads over the
        # tiles: a texture on part of every row (beside solid ink) falls in some of them
        r, c = int(row_index[i]), int(xs[int((t * 0.6180339887) % 1.0 * xs.size)])
        tile = np.ascontiguousarray(m[max(r - half, 0):r + half, max(c - half, 0):c + half])
        u8 = tile.view(np.uint8)
        pieces += cv2.connectedComponents(u8, connectivity=8)[0] - 1
        pieces += cv2.connectedComponents(1 - u8, connectivity=4)[0] - 1
        area += tile.size
    return pieces > 0 and area < TEXTURE_PIECE_PX * pieces


def _borders_settle(m: np.ndarray, s_min_px: float) -> bool:
    """Whether the borders decide every background component that cleaning may fill.

    Border following sees the holes of the ink, i.e. the background not connected to the
    image's edge. The background that is connected to it is one component when no ink
    touches the edge (the edge's ring of pixels joins it), at least as large as that ring:
    never filled when the ring alone reaches ``s_min_px``. Otherwise (ink on the edge, as
    when the hole runs off the scan, or a tiny image) the labelling decides.
    """
    if s_min_px <= 0:
        return True
    h, w = m.shape
    ring = 2 * (h + w) - 4 if min(h, w) > 1 else h * w
    if ring < s_min_px:
        return False
    return not (m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any())


def _clean_by_borders(m: np.ndarray, s_min_px: float, speck_px: float,
                      min_extent_px: float, sliver=None) -> np.ndarray | None:
    """:func:`clean_mask` from the border hierarchy of the ink (None: too many borders).

    ``cv2.findContours(RETR_TREE)`` on the zero-padded ink: borders at even depth are the
    outer borders of 8-connected ink components, at odd depth those of their holes
    (4-connected background components). A border starts on the first pixel the raster scan
    meets: an outer border on its component's pixel with background on its left, a hole
    border on an ink pixel whose right neighbour is in the hole. From these seeds:

    - every hole is flood-filled (4-connected) on a copy of its border's box, which gives its
      area; the fill is kept when the area is below ``s_min_px`` and the hole is not a sliver
      (``sliver``: length and width in px, or None);
    - an ink component inside a filled hole joins the component around it (as the
      labelling of the filled mask sees it); every other outer border is a component of the
      filled mask, with that border's box, which gives its extent. One that is long enough
      and spans at least ``speck_px`` rows or columns is kept (an 8-connected set spanning
      ``n`` rows or columns has at least ``n`` pixels); any other is flood-filled
      (8-connected, with background) on a copy of its box, which gives its area, and
      erased when short or smaller than ``speck_px``.
    """
    import cv2

    h, w = m.shape
    pad = np.zeros((h + 2, w + 2), np.uint8)
    pad[1:-1, 1:-1] = m.view(np.uint8)
    contours, hier = cv2.findContours(pad, cv2.RETR_TREE, cv2.CHAIN_APPROX_NONE)
    if hier is None:
        return np.zeros((h, w), bool)
    if len(contours) > MAX_BORDERS:
        return None
    parent = hier[0][:, 3].astype(np.int64)
    depth = np.zeros(len(contours), np.int64)
    up = parent.copy()
    while (up >= 0).any():
        depth += up >= 0
        up = np.where(up >= 0, parent[np.maximum(up, 0)], -1)
    boxes = [cv2.boundingRect(c) for c in contours]
    starts = [c[0, 0] for c in contours]
    filled = np.zeros(len(contours), bool)
    # every flood fill runs on a copy of its region's box, written back when it changed the
    # box: OpenCV clears a mask the size of the image for a fill without one, and its fill
    # with a mask is the slow general one (200 small holes of a 2000x2000 scan: 1 ms, against
    # 11 ms in place with one shared mask)
    if s_min_px > 0:
        for i in np.flatnonzero(depth % 2 == 1):
            x, y, bw, bh = boxes[i]
            box = pad[y:y + bh, x:x + bw].copy()
            seed = (int(starts[i][0]) + 1 - x, int(starts[i][1]) - y)
            area, *_ = cv2.floodFill(box, None, seed, 1, flags=4)
            if area < s_min_px and not (_may_be_sliver(bw, bh, sliver) and is_sliver(
                    box ^ pad[y:y + bh, x:x + bw], length_px=sliver[0], width_px=sliver[1])):
                pad[y:y + bh, x:x + bw] = box
                filled[i] = True
    if speck_px > 0 or min_extent_px > 0:
        for i in np.flatnonzero(depth % 2 == 0):
            if parent[i] >= 0 and filled[parent[i]]:
                continue  # part of the component around its (filled) hole
            x, y, bw, bh = boxes[i]
            short = np.hypot(bw, bh) < min_extent_px
            if not short and max(bw, bh) >= speck_px:
                continue  # long enough, and at least as many pixels as it spans
            box = pad[y:y + bh, x:x + bw].copy()
            seed = (int(starts[i][0]) - x, int(starts[i][1]) - y)
            area, *_ = cv2.floodFill(box, None, seed, 0, flags=8)
            if short or area < speck_px:
                pad[y:y + bh, x:x + bw] = box
    return pad[1:-1, 1:-1].view(bool).copy()


def filled_in_discs(clean, thresholded, centers_rc, radii_px) -> np.ndarray:
    """Paper pixels the cleaning filled (``clean`` and not ``thresholded``) within each disc.

    Parameters
    ----------
    clean, thresholded : (H, W) bool arrays
        The cleaned ink mask and the threshold's mask it was made from.
    centers_rc : (K, 2) array
        Disc centres (row, col), px (a junction's mean position).
    radii_px : (K,) array
        Disc radii, px.

    Returns
    -------
    (K,) int array
        A void below ``s_min`` filled at a junction (the paper's rule) leaves tens of ``h^2``
        there, a pinhole a few pixels. All discs in one pass over their boxes: a numpy window
        per junction took about 30 us each, 5 ms on a dense scan of 170 junctions.
    """
    c = np.ascontiguousarray(clean, dtype=bool)
    t = np.ascontiguousarray(thresholded, dtype=bool)
    rc = np.asarray(centers_rc, dtype=np.float64).reshape(-1, 2)
    rad = np.asarray(radii_px, dtype=np.float64).reshape(-1)
    if c.shape != t.shape or c.ndim != 2 or len(rc) != len(rad):
        raise ParameterError(f"masks of shapes {c.shape} and {t.shape} with {len(rc)} centres "
                             f"and {len(rad)} radii")
    return _filled_in_discs(c, t, np.ascontiguousarray(rc[:, 0]),
                            np.ascontiguousarray(rc[:, 1]), rad)


@njit(cache=True)
def _filled_in_discs(c, t, ys, xs, rad):  # pragma: no cover - numba
    rows, cols = c.shape
    out = np.zeros(len(ys), np.int64)
    for i in range(len(ys)):
        y, x, r = ys[i], xs[i], rad[i]
        if not (r >= 0.0 and np.isfinite(y) and np.isfinite(x)):
            continue
        k = int(np.ceil(r)) + 1
        r0, c0 = int(round(y)), int(round(x))
        n = 0
        for rr in range(max(r0 - k, 0), min(r0 + k + 1, rows)):
            dy2 = (rr - y) * (rr - y)
            for cc in range(max(c0 - k, 0), min(c0 + k + 1, cols)):
                if c[rr, cc] and not t[rr, cc] and dy2 + (cc - x) * (cc - x) <= r * r:
                    n += 1
        out[i] = n
    return out
