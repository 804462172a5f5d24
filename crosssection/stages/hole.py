"""Stage 12: the hole (container wall) and the bulk / periphery sub-systems.

Paper, section "Two sub-systems in the experiments": branches *with* an extremity in contact
with the container are *periphery*, the others *bulk*.

Hole fit (when the centre and/or radius are not given). The rod is pressed against a circular
wall, so the outer envelope of the ink is a circle with gaps where the rod leaves the wall:

1. Candidate points: the vertices of the convex hull of the foreground boundary pixels
   (``scipy.spatial.ConvexHull``): extreme points, all on the envelope (a gap only adds a hull
   edge, never a vertex inside the circle).
2. Algebraic circle fit of these points (Kasa: linear least squares of
   ``x^2 + y^2 + D x + E y + F = 0``).
3. Robust refinement on the outermost points: the boundary pixels are binned by polar angle
   around the current centre (bins of ~2 px of arc); the outermost pixel of each bin is a wall
   candidate; bins whose outermost pixel lies more than ``gap_px`` inside the current circle are
   gaps and dropped. A geometric fit (soft-L1 loss, :func:`_soft_l1_circle`) on the remaining
   points; three iterations.
4. Pixel centres of the outermost ink lie half a pixel inside the ink's outer edge: 0.5 px is
   added to the fitted radius (the wall is the outer edge of the ink).

When only the centre is given the radius is the median distance of the outermost points; when
only the radius is given the centre is fitted with the radius fixed.

Finding the hole in the scan (:func:`find_hole`). A scan often shows the plate around the hole;
the plate/paper boundary is the wall, a full circle even where the rod leaves the wall:

0. A plate blue enough to pass the ink's colour rule joins the wall band into one ink
   component reaching the scan's border; its pixels are told from the ink's by their hue and
   brightness (:func:`_without_plate`) and leave the ink mask of the search. A plate coloured
   like the ink cannot be told apart: the search then fails its confidence and says so.
1. First guess: the ink envelope (:func:`fit_hole`).
2. Rays from its centre, 0.7 R to 1.2 R + 10 px, sampled every pixel on the image
   smoothed over 3x3 px (plate texture). Per sector of 1/16 of the circle a local paper colour
   (median of the brightest fifth of the non-ink samples inside 0.95 R: receding surfaces
   are darker) and a local plate colour (median of the samples beyond 1.06 R + 4 px): local
   references absorb illumination gradients.
3. Each sample is projected on the paper -> plate colour axis (0 paper, 1 plate; linear in the
   pixel's plate coverage); ink samples count as inside. On each ray the wall is the outermost
   crossing of 0.5 before an unbroken plate run to the ray's end (a dark rim just outside
   the edge projects beyond 1 and counts as plate).
4. A robust circle fit (soft-L1) on these points; points more than 2 px off are dropped and
   the circle refitted. Found on fewer than :data:`_REREAD_BELOW` of the rays, the edge is
   read again on rays from the circle found, which cross it square (rays from an envelope off
   the hole's centre meet it obliquely, or not at all).
5. No edge found near the envelope: the rod may not reach the wall (a loosely packed rod, a
   render of a free rod, the hole twice the rod's size). The rays then run to the scan's
   border, the plate's colour taken on the outer fifth of each beyond the envelope; the
   circle through the edge found there is read again as in 4, and kept when it holds the
   rod (its largest piece of ink). On 12 renders of quenched rods (``python -m simulate render``; the hole is
   larger than the rod), the edge is found on all 12 on 94-100 % of the rays, centres within
   0.1 px and radii 0.6 px short of the drawn plate's edge (its 2-px dark rim, blurred
   into the paper's side, crosses the midpoint early); without steps 4 and 5, two
   of them returned the ink's envelope (flagged, centres 400-700 px off) and three found the
   edge on 50-88 % of the rays.

The confidence is the fraction of rays that give a wall point within 2 px of the circle;
without a plate distinct from the paper the ink envelope is returned with the fraction of its
angular bins where ink reaches the circle as confidence (a rod pressed all around the wall
gives 1), grown to hold every piece of the rod: each ink component of at least
:data:`PIECE_FRACTION` of the largest one's area (a rod drawn without its wall in two pieces
lost 37 % of its length to a frame around its largest piece). Grown by more than
:data:`GROWN_PX`, the circle takes its own confidence, the fraction of it that the ink reaches:
a blue label and a mark on the paper beside a sample scan's hole grow it from 398 to 668 px,
which the ink reaches on 0.2 % of the circle (the envelope's confidence, 1.0, would hide the
misfit), and the scan is flagged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from crosssection.core.errors import AnalysisError, ParameterError
from crosssection.params import _number

#: Without a plate, ink components of at least this fraction of the largest one's area are
#: pieces of the rod and lie inside the frame; smaller ones (specks) may be cut.
PIECE_FRACTION = 0.02
#: Without a plate, a circle grown by more than this to hold every piece of ink takes the
#: confidence of the grown circle (:func:`find_hole`).
GROWN_PX = 3.0
#: An ink component touching this fraction of the scan's border is a plate that passed the
#: ink's colour rule: a rod inside its hole never reaches the border (a scan cropped through
#: the hole lets its wall band touch a chord of it, a few % of the border).
PLATE_BORDER_FRACTION = 0.2
#: ... told apart from the ink by colour only when the two colours lie this many times the
#: plate's own colour spread apart.
PLATE_INK_SEPARATION = 4.0
#: The least spread of a plate's colour features (:func:`_plate_features`): a flat plate has
#: none, and one grey level moves a chromaticity by about 1/300.
PLATE_MIN_SPREAD = 0.005
#: A plate's edge found on fewer rays than this fraction is read again on rays from the
#: circle found (:func:`find_hole`).
_REREAD_BELOW = 0.9
#: Rays of the search beyond the envelope (:func:`find_hole`, step 5): they only locate the
#: edge, which is then read on rays from the circle through it.
_FAR_RAYS = 180

__all__ = ["Hole", "fit_hole", "find_hole", "frame_mask", "trim_margin", "check_hole",
           "classify_regions", "wall_tolerance_px", "wall_gaps_px", "wall_gap_max_px",
           "rim_inside", "kasa_fit", "ink_across_circle", "given_hole_wide"]


@dataclass
class Hole:
    """Circular container wall.

    Attributes
    ----------
    center_rc : ndarray (2,)
        Centre (row, col), px.
    radius_px : float
        Radius of the wall (outer edge of the ink pressed against it), px.
    fitted : bool
        True when any of the two was fitted to the mask.
    confidence : float
        In [0, 1]; 1 for a given hole (see :func:`find_hole`).
    reason : str
        Why the confidence is low, or how the hole was found.
    given_crossed : float
        For a given hole that the ink crosses (:func:`ink_across_circle`) where a hole found
        in the scan near it frames the ink: the fraction of the given circle crossed; else 0
        (the pipeline, :data:`GIVEN_CROSSED_LIMIT`).
    alternative : tuple or None
        ``(center_rc, radius_px)`` of the other hole then: the given one when this one,
        found in the scan, replaced it (``replaced``), else the one found.
    replaced : bool
        Whether this hole, found in the scan, replaced the given one.
    envelope : tuple or None
        For a given hole wider than the wall the ink is pressed against
        (:func:`given_hole_wide`): ``(center_rc, radius_px, reach_given, reach_envelope)``,
        the ink's envelope and the fractions of the given circle and of the envelope that
        the ink reaches; else None.
    """

    center_rc: np.ndarray
    radius_px: float
    fitted: bool
    confidence: float = 1.0
    reason: str = ""
    given_crossed: float = 0.0
    alternative: tuple | None = None
    replaced: bool = False
    envelope: tuple | None = None

    def as_summary(self) -> dict:
        """``{center_x_px, center_y_px, radius_px}`` for ``summary.json``."""
        return {"center_x_px": float(self.center_rc[1]), "center_y_px": float(self.center_rc[0]),
                "radius_px": float(self.radius_px)}

    def distance_to_wall(self, points_rc) -> np.ndarray:
        """``radius - |p - centre|`` (positive inside the hole)."""
        p = np.asarray(points_rc, dtype=np.float64).reshape(-1, 2)
        return self.radius_px - np.hypot(p[:, 0] - self.center_rc[0], p[:, 1] - self.center_rc[1])


def kasa_fit(points_rc) -> tuple[np.ndarray, float]:
    """Algebraic (Kasa) circle fit. Returns (centre_rc, radius)."""
    p = np.asarray(points_rc, dtype=np.float64)
    r, c = p[:, 0], p[:, 1]
    A = np.c_[r, c, np.ones(len(p))]
    b = -(r * r + c * c)
    (D, E, F), *_ = np.linalg.lstsq(A, b, rcond=None)
    center = np.array([-D / 2, -E / 2])
    rad2 = center @ center - F
    return center, float(np.sqrt(max(rad2, 0.0)))


def _boundary_points(mask):
    """(row, col) of the pixels on the outer borders of the ink components.

    Only outer borders can be on the envelope (a hole's border is enclosed by ink farther
    out); ``cv2.findContours(RETR_EXTERNAL)`` on the padded mask: 5 100 points and 1 ms on a
    2000x2000 scan, against 26 ms for the erosion boundary (all borders, 10x more points).
    """
    import cv2

    m = np.asarray(mask, dtype=bool)
    pad = np.zeros((m.shape[0] + 2, m.shape[1] + 2), np.uint8)
    pad[1:-1, 1:-1] = m.view(np.uint8)
    cs, _ = cv2.findContours(pad, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not cs:
        return np.zeros((0, 2))
    xy = np.concatenate([c.reshape(-1, 2) for c in cs])
    return xy[:, ::-1].astype(np.float64) - 1.0


def _outermost(points, center, n_bins):
    """The point farthest from ``center`` in every occupied angular bin (of ``n_bins``), in
    bin order, the last one given of equals, and its distance.

    What the last of each bin in ``np.lexsort((rad, bin))`` order is, by two maxima per bin
    (``np.maximum.at``): 0.4 ms for the 5 100 border points of a 2000x2000 scan, against
    0.7 ms with the sort (the hole's search asks four times).
    """
    d = points - center
    rad = np.hypot(d[:, 0], d[:, 1])
    ang = np.arctan2(d[:, 0], d[:, 1])
    b = np.clip(((ang + np.pi) / (2 * np.pi) * n_bins).astype(np.int64), 0, n_bins - 1)
    far = np.full(n_bins, -np.inf)
    np.maximum.at(far, b, rad)
    at_far = np.flatnonzero(rad == far[b])
    last = np.full(n_bins, -1, np.int64)
    np.maximum.at(last, b[at_far], at_far)
    sel = last[last >= 0]
    return points[sel], rad[sel]


def fit_hole(mask, *, center_rc=None, radius_px=None, gap_px=None, path=None) -> Hole:
    """Hole centre and radius: given, or fitted to the outer envelope of the foreground.

    Parameters
    ----------
    mask : bool array (H, W)
        Cleaned foreground (ink).
    center_rc : (2,) float, optional
        Known centre (row, col), px.
    radius_px : float, optional
        Known radius, px.
    gap_px : float, optional
        Outermost points more than this inside the circle are gaps (default: 2 % of the
        radius, at least 3 px).
    path : str, optional
        Image path, for error messages.

    Returns
    -------
    Hole

    Raises
    ------
    AnalysisError
        Fewer than 3 foreground boundary points to fit.
    ParameterError
        A given centre that is not two finite numbers, a given radius that is not a finite
        number > 0.
    """
    if center_rc is not None:
        c = np.asarray(center_rc, dtype=np.float64).reshape(-1)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ParameterError(f"the hole's centre must be two finite numbers (row, col), "
                                 f"got {center_rc!r}", path)
    if radius_px is not None and not (np.isfinite(radius_px) and radius_px > 0):
        raise ParameterError(f"the hole's radius must be a finite number > 0 px, got "
                             f"{radius_px!r}", path)
    if center_rc is not None and radius_px is not None:
        return Hole(np.asarray(center_rc, dtype=np.float64).copy(), float(radius_px), False)
    return _fit_points(_boundary_points(np.asarray(mask, dtype=bool)), center_rc, radius_px,
                       gap_px, path)


def _fit_points(pts, center_rc, radius_px, gap_px, path) -> Hole:
    """:func:`fit_hole` on the outer border points of the ink (:func:`_boundary_points`)."""
    from scipy.spatial import ConvexHull, QhullError

    if len(pts) < 3:
        raise AnalysisError("cannot fit the hole: the mask has no foreground", path)
    try:
        hull = pts[ConvexHull(pts).vertices]
    except QhullError:  # collinear points (Qhull's own message is a page of its options)
        # a plate of the ink's colour around the hole leaves the ink's envelope the scan's
        # edge, as too little ink kept does
        raise AnalysisError(f"cannot fit the hole: the ink's {len(pts)} border points lie on "
                            "one line (too little ink kept, or a plate of the ink's colour "
                            "around the hole: check the threshold, or give the hole with "
                            "hole_radius_mm and hole_center_px)", path) from None
    if center_rc is None:
        c0, r0 = kasa_fit(hull)
        if radius_px is not None:
            r0 = float(radius_px)
    else:
        c0 = np.asarray(center_rc, dtype=np.float64)
        r0 = float(np.median(np.hypot(*(hull - c0).T)))
    c, r = c0, r0
    for _ in range(3):
        n_bins = int(np.clip(np.pi * r, 36, 4096))      # ~2 px of arc per bin
        outer, rad = _outermost(pts, c, n_bins)
        gap = gap_px if gap_px is not None else max(3.0, 0.02 * r)
        keep = rad >= r - 0.5 - gap
        if keep.sum() < 3:
            break
        if center_rc is not None:
            r = float(np.median(rad[keep]))
            continue
        qr, qc = outer[keep, 0], outer[keep, 1]
        if radius_px is not None:
            c = _soft_l1_circle(qr, qc, np.r_[c, 0.0], float(radius_px) - 0.5)[:2]
        else:
            sol = _soft_l1_circle(qr, qc, np.r_[c, r - 0.5], np.nan)
            c, r = sol[:2], float(sol[2]) + 0.5
    if center_rc is not None:
        r = r + 0.5  # pixel centres -> outer edge of the ink
    if radius_px is not None:
        r = float(radius_px)
    return Hole(np.asarray(c, dtype=np.float64), float(r), True)


def _soft_l1_circle(qr, qc, x0, radius) -> np.ndarray:
    """The circle through the points (``qr``, ``qc``) that minimises the soft-L1 loss of
    their distances to it, ``sum 2 (sqrt(1 + f^2) - 1)`` with ``f = |q - c| - r`` (in px:
    a scale of 1 px), from ``x0`` = (row, col, radius); with ``radius`` finite the radius is
    held at it and only the centre is fitted (``x0[2]`` ignored).

    The loss of ``scipy.optimize.least_squares(loss="soft_l1", f_scale=1)``, minimised by
    :func:`_soft_l1_steps` (0.6 ms for the 2 800 wall points of a 2000 x 2000 scan against
    3.3 ms for ``least_squares``, which spends it in its trust-region machinery and
    numerical Jacobian; the hole's search fits five times). Where those steps do not reach
    a stationary point (points on a line or nearly, a single point repeated, a start far
    off: a circle the data do not fix), ``least_squares`` is run from ``x0`` as before.

    Parameters
    ----------
    qr, qc : (n,) float64 arrays
        Rows and columns of the points, px.
    x0 : (3,) float64 array
        The first circle: centre row, centre column, radius, px.
    radius : float
        The radius held fixed, or NaN to fit it.

    Returns
    -------
    (3,) float64 array
        Centre row, centre column and radius, px.
    """
    qr = np.ascontiguousarray(qr, dtype=np.float64)
    qc = np.ascontiguousarray(qc, dtype=np.float64)
    x0 = np.asarray(x0, dtype=np.float64)
    x, converged = _soft_l1_steps(qr, qc, x0, float(radius))
    if converged:
        return x
    from scipy.optimize import least_squares

    if np.isnan(radius):
        fun = lambda x: np.hypot(qr - x[0], qc - x[1]) - x[2]  # noqa: E731
        return least_squares(fun, x0, loss="soft_l1", f_scale=1.0).x
    fun = lambda x: np.hypot(qr - x[0], qc - x[1]) - radius  # noqa: E731
    return np.r_[least_squares(fun, x0[:2], loss="soft_l1", f_scale=1.0).x, radius]


@njit(cache=True, nogil=True)
def _soft_l1_steps(qr, qc, x0, radius):  # pragma: no cover - numba
    """:func:`_soft_l1_circle`'s minimisation: Gauss-Newton steps on the reweighted normal
    equations (weights ``1 / sqrt(1 + f^2)``, the loss' derivative), halved while the loss
    would not fall, until a step would move the circle by less than 1e-9 px: a stationary
    point of the loss. Over 120 synthetic arcs with up to 30 % of the points pulled inwards,
    as gaps in the wall band pull them (in the tests), it lies within 4e-7 px (median 5e-9)
    of the minimum ``least_squares`` reaches with its tolerances at 1e-15, and of where
    ``least_squares`` stops with its default ones (within 9e-7 px, median 3e-10, of that
    minimum). Returns the circle and whether it is such a point (False: normal equations
    singular or nearly, a step that no halving makes lower the loss, or 200 steps).
    """
    fixed = radius == radius  # not NaN
    x0_, x1_ = x0[0], x0[1]
    x2_ = radius if fixed else x0[2]
    cost = _soft_l1_loss(qr, qc, x0_, x1_, x2_)
    converged = False
    for _ in range(200):
        a00 = a01 = a02 = a11 = a12 = a22 = 0.0
        g0 = g1 = g2 = 0.0
        for i in range(qr.size):
            dr = qr[i] - x0_
            dc = qc[i] - x1_
            d = np.sqrt(dr * dr + dc * dc)
            f = d - x2_
            w = 1.0 / np.sqrt(1.0 + f * f)
            ur = dr / d if d > 0.0 else 0.0
            uc = dc / d if d > 0.0 else 0.0
            a00 += w * ur * ur
            a01 += w * ur * uc
            a11 += w * uc * uc
            a02 += w * ur
            a12 += w * uc
            a22 += w
            g0 += w * ur * f
            g1 += w * uc * f
            g2 += w * f
        # the Gauss-Newton step of the weighted problem: A s = g (Cramer's rule)
        if fixed:
            det = a00 * a11 - a01 * a01
            if not det > 1e-12 * (a00 * a11 + 1e-300):
                break
            s0 = (g0 * a11 - g1 * a01) / det
            s1 = (a00 * g1 - a01 * g0) / det
            s2 = 0.0
        else:
            c00 = a11 * a22 - a12 * a12
            c01 = a02 * a12 - a01 * a22
            c02 = a01 * a12 - a02 * a11
            det = a00 * c00 + a01 * c01 + a02 * c02
            if not det > 1e-12 * (a00 * a11 * a22 + 1e-300):
                break
            c11 = a00 * a22 - a02 * a02
            c12 = a01 * a02 - a00 * a12
            c22 = a00 * a11 - a01 * a01
            s0 = (c00 * g0 + c01 * g1 + c02 * g2) / det
            s1 = (c01 * g0 + c11 * g1 + c12 * g2) / det
            s2 = (c02 * g0 + c12 * g1 + c22 * g2) / det
        step = max(abs(s0), abs(s1), abs(s2))
        if step < 1e-9:
            converged = True
            break
        t = 1.0
        if step > 1e-4:
            # halved while the loss would not fall; within 1e-4 px of the minimum the loss
            # changes by less than its rounding, and the whole steps, whose normal matrix
            # is steeper than the loss (weights w against the loss' w^3), are taken as
            # they are (the loss read again only if a larger step follows)
            if cost != cost:
                cost = _soft_l1_loss(qr, qc, x0_, x1_, x2_)
            new = cost
            for _ in range(40):
                new = _soft_l1_loss(qr, qc, x0_ + t * s0, x1_ + t * s1, x2_ + t * s2)
                if new < cost:
                    break
                t *= 0.5
            if not new < cost:
                break
            cost = new
        else:
            cost = np.nan
        x0_ += t * s0
        x1_ += t * s1
        x2_ += t * s2
    out = np.empty(3)
    out[0] = x0_
    out[1] = x1_
    out[2] = x2_
    return out, converged


@njit(cache=True, nogil=True)
def _soft_l1_loss(qr, qc, r0, c0, rad):  # pragma: no cover - numba
    """The soft-L1 loss of :func:`_soft_l1_circle` for the circle (``r0``, ``c0``, ``rad``)."""
    s = 0.0
    for i in range(qr.size):
        dr = qr[i] - r0
        dc = qc[i] - c0
        f = np.sqrt(dr * dr + dc * dc) - rad
        s += 2.0 * (np.sqrt(1.0 + f * f) - 1.0)
    return s


def check_hole(shape, center_rc, radius_px, *, path=None) -> None:
    """Reject a hole that cannot frame a scan of ``shape``.

    Raises
    ------
    ParameterError
        A radius not positive and finite, a hole diameter more than twice the scan's largest
        side, or a hole that does not overlap the image.
    """
    H, W = shape[:2]
    r = float(radius_px)
    if not np.isfinite(r) or r <= 0:
        raise ParameterError(f"hole radius must be positive, got {radius_px!r} px", path)
    if 2 * r > 2 * max(H, W):
        raise ParameterError(f"hole diameter {2 * r:.0f} px is more than twice the scan "
                             f"({W}x{H} px): check hole_radius_mm and px_per_mm", path)
    if center_rc is not None:
        c = np.asarray(center_rc, dtype=np.float64)
        if c.shape != (2,) or not np.isfinite(c).all():
            raise ParameterError(f"hole centre must be 2 finite numbers, got {center_rc!r}", path)
        dr = max(0.0, -c[0], c[0] - (H - 1))
        dc = max(0.0, -c[1], c[1] - (W - 1))
        if np.hypot(dr, dc) >= r:
            raise ParameterError(f"the hole (centre x={c[1]:.0f}, y={c[0]:.0f} px, radius "
                                 f"{r:.0f} px) does not overlap the {W}x{H} px scan", path)


#: Extra radius of the scan's frame beyond the hole's radius, px (:func:`frame_mask`).
FRAME_MARGIN_PX = 2.0
#: Pixels inside the wall read to decide whether a margin pixel continues the ink inside
#: (:func:`trim_margin`).
TRIM_DEPTH_PX = 3


def frame_mask(shape, hole, *, margin_px: float = FRAME_MARGIN_PX) -> np.ndarray:
    """The scan's frame: pixels whose centre lies within ``radius + margin_px`` of the centre.

    Parameters
    ----------
    shape : tuple
        Image shape (H, W[, 3]).
    hole : Hole
    margin_px : float
        Extra radius: ink pressed against the wall reaches the wall itself, and a hole given by
        the user carries a pixel or two of error; the plate beyond is excluded by the colour
        threshold anyway.

    Returns
    -------
    (H, W) bool array

    Raises
    ------
    ParameterError
        See :func:`check_hole`.
    """
    check_hole(shape, hole.center_rc, hole.radius_px)
    H, W = shape[:2]
    r0, c0 = (float(v) for v in hole.center_rc)
    lim = (float(hole.radius_px) + margin_px) ** 2
    # The test is (r - r0)^2 + (c - c0)^2 <= lim in float64. Each rounded term is monotone in
    # |r - r0| and |c - c0|, so every row's inside is one run of columns: its ends are found
    # by testing the same expression on the columns next to the ends of the exact circle,
    # and the runs filled (a 2000x2000 scan: 3 ms and no full-image float64 temporaries,
    # against 10 ms and 32 MB for the expression on every pixel).
    a = (np.arange(H) - r0) ** 2
    b = (np.arange(W) - c0) ** 2
    half = np.sqrt(np.maximum(lim - a, 0.0))
    k = np.arange(-2, 3)
    lo_c = np.clip(np.ceil(c0 - half).astype(np.int64)[:, None] + k, 0, W - 1)
    hi_c = np.clip(np.floor(c0 + half).astype(np.int64)[:, None] + k, 0, W - 1)
    lo_in = a[:, None] + b[lo_c] <= lim
    hi_in = a[:, None] + b[hi_c] <= lim
    # first inside column among the candidates near the left end, last near the right end
    lo = np.where(lo_in.any(axis=1), lo_c[np.arange(H), np.argmax(lo_in, axis=1)], W)
    hi = np.where(hi_in.any(axis=1), hi_c[np.arange(H), 4 - np.argmax(hi_in[:, ::-1], axis=1)],
                  -1)
    out = np.zeros((H, W), bool)
    for r in np.flatnonzero(hi >= lo):
        out[r, lo[r]:hi[r] + 1] = True
    return out


#: A given hole whose circle the ink crosses on more than this fraction
#: (:func:`ink_across_circle`) cuts the rod: the pipeline looks for the hole in the scan.
#: Measured: 0 on the 48 scans of an independent generator with their hole given exactly;
#: 0.02-0.15 on 23 of them with the radius 1 % short, 0.07-1.0 on all 48 at 3 % short, 0-0.36
#: with the centre 0.5 mm off.
GIVEN_CROSSED_LIMIT = 0.01
#: ... and uses the hole found instead when it lies within this fraction of the given radius
#: of the given hole (centre and radius) and its own circle is crossed at most half as much
#: (a plate as blue as the ink, or noise, passes the ink's cut beyond a given hole that is
#: right, and beyond the hole found there as well: no flag).
GIVEN_NEAR_FRACTION = 0.2
#: :func:`ink_across_circle` looks this fraction of the radius beyond the circle.
BEYOND_FRACTION = 0.05


def ink_across_circle(is_ink, shape, hole, *, margin_px: float = FRAME_MARGIN_PX) -> float:
    """The fraction of a hole's circle beyond which the rod's ink goes on.

    A hole frames the rod: the ink reaches its wall from inside and stops there. A circle
    drawn too small, or off centre, cuts the wall band and the stacks pressed against the
    wall, or leaves them wholly beyond it (a one-layer wall band is 2.5 px wide at 25 px/mm).
    Sampled every pixel of arc, a point of the circle counts when ink lies on its ray within
    :data:`BEYOND_FRACTION` of the radius (plus 4 px) beyond the frame's edge
    (``radius + margin_px``, rays sampled every 2 px), but not at 1.1 times the radius plus
    10 px, where a wall band beyond a circle slightly off has ended: a plate or a background
    that passes the ink's cut everywhere does not count. Points outside the image are not
    counted.

    Parameters
    ----------
    is_ink : callable
        ``is_ink(rows, cols)`` -> bool array: whether those pixels pass the ink's cut (the
        frame ignored).
    shape : tuple
        The image's (rows, cols).
    hole : Hole
    margin_px : float
        The frame's margin (:func:`frame_mask`).

    Returns
    -------
    float
        In [0, 1].
    """
    H, W = shape[:2]
    r0, c0 = (float(v) for v in hole.center_rc)
    R = float(hole.radius_px)
    t = np.linspace(0.0, 2.0 * np.pi, max(int(2.0 * np.pi * (R + margin_px)), 16),
                    endpoint=False)
    sin, cos = np.sin(t), np.cos(t)

    def at(radius):
        rr = np.rint(r0 + radius * sin).astype(np.int64)
        cc = np.rint(c0 + radius * cos).astype(np.int64)
        inside = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
        ink = np.zeros(len(t), bool)
        ink[inside] = is_ink(rr[inside], cc[inside])
        return ink, inside

    edge = R + margin_px
    beyond = np.zeros(len(t), bool)
    for radius in np.arange(edge + 1.0, edge + BEYOND_FRACTION * R + 4.0, 2.0):
        beyond |= at(radius)[0]
    counted = at(edge + 1.0)[1]
    far, in_far = at(1.1 * R + 10.0)
    crossed = beyond & ~(far & in_far) & counted
    return float(np.count_nonzero(crossed)) / max(np.count_nonzero(counted), 1)


def trim_margin(mask, hole, *, margin_px: float = FRAME_MARGIN_PX, features=None,
                levels=None) -> tuple[np.ndarray, int]:
    """Ink of the frame's margin kept only where it continues ink lying inside the wall, and
    where it is more ink than plate.

    The margin of :func:`frame_mask` lets the ink pressed against the wall (and a given hole
    a pixel or two too small) in whole. A plate that passes the ink's colour rule (a blue
    plate: no colour rule can exclude it) would enter through it as a thin ring around the
    whole hole, one closed stack of the hole's circumference (+9 to +11 % rod length on
    drawn scans with a blue plate and the hole given). A margin pixel is kept when one of the
    :data:`TRIM_DEPTH_PX` pixels inside the wall on its ray from the centre is ink: the wall
    band continues there, paper does not. (With one pixel, noise of 30 grey levels left the
    wall band's outer edge ragged and read +30 % of energy on the validation atlas's network
    scenes, +2 % without the trim.)

    Beyond the wall the band's ink is blurred into the plate, not into the paper the cut was
    chosen against. A cut halfway from the ink to the paper passes a pixel of 8 % ink on a
    bluish plate (blue dominance 52 against the ink's 109 and the cut's 56.5): the margin
    widened the wall band by 2 px, a layer at 25 px/mm (rod +18 %, every wall stack one
    layer over). Given the features and the ink's levels, a margin pixel is also kept only
    when it lies at least halfway from the plate's levels (the medians of a ring 4-8 px
    beyond the margin) to the ink's, on the blue dominance and on the red-green darkness
    where the plate is nearer the ink than the paper is by a tenth of their contrast: the
    band's edge against the plate where it is against the paper. Where the plate is paper,
    the scan's cut is kept as it is; where it is as near the ink as the ink's own spread on
    both features (:data:`PLATE_DISTINCT`), no margin pixel is kept.

    Parameters
    ----------
    mask : (H, W) bool array
        Ink within the frame (``frame_mask(..., margin_px=margin_px)``).
    hole : Hole
    margin_px : float
        The frame's margin.
    features : ColourFeatures, optional
        The scan's (:func:`crosssection.stages.threshold.colour_features`).
    levels : tuple of two (2,) tuples, optional
        The ink's and the paper's blue dominance and darkness (``ThresholdResult.ink_level``,
        ``paper_level``); with ``features``, margin pixels nearer a plate's levels than the
        ink's are dropped.

    Returns
    -------
    mask : (H, W) bool array
        ``mask`` without the margin's unsupported ink (the same array when nothing goes).
    n_removed : int
        Pixels removed.
    """
    if margin_px <= 0:
        return mask, 0
    H, W = mask.shape
    r0, c0 = (float(v) for v in hole.center_rc)
    R = float(hole.radius_px)
    # the margin's pixels, row by row a run on each side of the inner circle (about
    # 2 pi R margin_px of them: 13 ms for every ink pixel of a 2000x2000 scan, under 1 ms so)
    rows = np.arange(max(int(np.floor(r0 - R - margin_px)), 0),
                     min(int(np.ceil(r0 + R + margin_px)) + 1, H))
    dr2 = (rows - r0) ** 2
    ho = np.sqrt(np.maximum((R + margin_px) ** 2 - dr2, 0.0))
    hi = np.sqrt(np.maximum(R ** 2 - dr2, 0.0))
    lo_a = np.maximum(np.ceil(c0 - ho), 0).astype(np.int64)
    lo_b = np.minimum(np.floor(c0 - hi), W - 1).astype(np.int64)
    # a hole centred left of the scan: the right run starts at column 0 at the latest
    hi_a = np.maximum(np.maximum(np.ceil(c0 + hi), lo_b + 1), 0).astype(np.int64)
    hi_b = np.minimum(np.floor(c0 + ho), W - 1).astype(np.int64)
    rr, cc = [], []
    for a, b in ((lo_a, lo_b), (hi_a, hi_b)):
        n = np.maximum(b - a + 1, 0)
        rr.append(np.repeat(rows, n))
        cc.append(np.repeat(a, n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n))
    rr, cc = np.concatenate(rr), np.concatenate(cc)
    keep = mask[rr, cc]
    rr, cc = rr[keep], cc[keep]
    dist = np.hypot(rr - r0, cc - c0)
    out_ = dist > R
    if not out_.any():
        return mask, 0
    rr, cc, dist = rr[out_], cc[out_], dist[out_]
    backed = np.zeros(len(rr), bool)
    for k in range(1, TRIM_DEPTH_PX + 1):
        f = max(R - k, 0.0) / dist
        ri = np.clip(np.rint(r0 + (rr - r0) * f).astype(np.int64), 0, H - 1)
        ci = np.clip(np.rint(c0 + (cc - c0) * f).astype(np.int64), 0, W - 1)
        backed |= mask[ri, ci]
    drop = ~backed
    plate = (None if features is None or levels is None or None in levels
             else _plate_levels(features, r0, c0, R + margin_px))
    if plate is not None:
        (ink_d, ink_m), (paper_d, paper_m) = ((float(a), float(b)) for a, b in levels)
        share_d = _share(plate[0], ink_d, paper_d)
        share_m = _share(plate[1], ink_m, paper_m)
        if share_d >= 1.0 - PLATE_DISTINCT and share_m >= 1.0 - PLATE_DISTINCT:
            # no colour tells this plate from the ink: the wall is the band's edge
            drop[:] = True
        if PLATE_APART < share_d < 1.0 - PLATE_DISTINCT:
            drop |= features.dominance[rr, cc] < 0.5 * (ink_d + plate[0])
        if PLATE_APART < share_m < 1.0 - PLATE_DISTINCT:
            drop |= features.darkness[rr, cc] > 0.5 * (ink_m + plate[1])
    if not drop.any():
        return mask, 0
    mask = mask.copy()
    mask[rr[drop], cc[drop]] = False
    return mask, int(np.count_nonzero(drop))


#: The ring whose medians are the plate's levels (:func:`trim_margin`), px beyond the frame:
#: past the wall band's blur (1-2 px), near enough to be the plate the band touches.
PLATE_RING_PX = (4.0, 8.0)
#: A plate's level nearer the ink's than the paper's by more than this share of the ink's
#: contrast to the paper moves the margin's cut on that feature (:func:`trim_margin`); below,
#: a plate of paper would move it by its noise.
PLATE_APART = 0.1
#: ... and only when it lies at least this share of that contrast from the ink's: a plate
#: coloured as the ink (blue dominance 80 against its 86) would put the cut inside the ink's
#: own noise, dropping half the wall band's margin at random. A plate that near the ink (or
#: beyond it) on both features cannot be told from it by any colour: the margin is dropped
#: whole, the wall taken as the band's edge (kept, its 2 px read every wall stack of a
#: 25-35 px/mm scan one layer over: rod +27 to +48 %).
PLATE_DISTINCT = 0.25


def _share(plate, ink, paper) -> float:
    """Where a plate's level of one feature lies from the paper's (0) to the ink's (1)."""
    contrast = ink - paper
    return (plate - paper) / contrast if contrast else 0.0


def _plate_levels(features, r0, c0, r_frame):
    """Median blue dominance and darkness of the ring ``PLATE_RING_PX`` beyond the frame of
    radius ``r_frame`` centred at (``r0``, ``c0``), or None when the scan holds none of it."""
    H, W = features.shape
    lo, hi = r_frame + PLATE_RING_PX[0], r_frame + PLATE_RING_PX[1]
    # five circles across the ring, a pixel apart along each
    n = max(int(2.0 * np.pi * hi), 8)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    radii = np.linspace(lo, hi, 5)
    rr = np.rint(r0 + np.outer(radii, np.sin(t))).astype(np.int64).ravel()
    cc = np.rint(c0 + np.outer(radii, np.cos(t))).astype(np.int64).ravel()
    ok = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
    if np.count_nonzero(ok) < 16:
        return None
    rr, cc = rr[ok], cc[ok]
    return (float(np.median(features.dominance[rr, cc])),
            float(np.median(features.darkness[rr, cc])))


def _circle_fit(points, c0, r0):
    """Soft-L1 geometric circle fit (:func:`_soft_l1_circle`), then again without points
    more than 2 px off."""
    x = np.r_[c0, r0].astype(np.float64)
    keep = np.ones(len(points), bool)
    for _ in range(2):
        q = points[keep]
        if len(q) < 5:
            break
        x = _soft_l1_circle(q[:, 0].copy(), q[:, 1].copy(), x, np.nan)
        keep = np.abs(np.hypot(*(points - x[:2]).T) - x[2]) <= 2.0
    return x[:2], float(x[2]), keep


def _envelope_confidence(pts, hole, within_px: float = 3.5) -> float:
    """Fraction of 2-px angular bins whose outermost ink (of the border points ``pts``)
    reaches the circle within ``within_px``."""
    n_bins = int(np.clip(np.pi * hole.radius_px, 36, 4096))
    outer, rad = _outermost(pts, hole.center_rc, n_bins)
    return float(np.count_nonzero(rad >= hole.radius_px - within_px)) / n_bins


#: A given hole is wider than the wall when the ink reaches within 2 h of its circle on
#: less than this fraction of it while the ink's envelope, a circle at least 2 h inside it,
#: is reached on :data:`WIDE_ENVELOPE_MIN` of it (:func:`given_hole_wide`). Measured: 1.0
#: on the exact holes of ``benchmarks/hole_given_off.py`` (typical, thick dense and 25 px/mm
#: scenes), 0.0 with their radius 3 % long where that exceeds 2 h (docs/validation/README.md,
#: "A hole given a little off").
WIDE_REACH_MAX = 0.1
#: ... see :data:`WIDE_REACH_MAX`.
WIDE_ENVELOPE_MIN = 0.5
#: An envelope the ink reaches on this fraction of it is the wall itself (the wall band lines
#: it all round): it replaces a given hole too wide where no plate's edge is found.
WIDE_LINED_MIN = 0.9
#: ... while the ink reaches the given circle on less than this fraction of it.
WIDE_LINED_REACH_MAX = 0.5


def wide_tolerance_px(thickness_px: float) -> float:
    """How far inside a given circle the ink may stop before the hole is too wide: 2 h (a
    radius given 1 % long on a 15 mm hole at h = 0.1 mm is 1.5 h), at least 3.5 px
    (:func:`_envelope_confidence`'s reach)."""
    return max(2.0 * float(thickness_px), 3.5)


def given_hole_wide(mask, hole, *, thickness_px: float):
    """The ink's envelope when a given hole is wider than the wall the rod is pressed against.

    The wall band lines the wall, so the ink reaches a right hole's circle on most of it;
    the stacks pressed against the wall end their junctions half a band inside it, within
    the periphery's tolerance (:func:`wall_tolerance_px`: half a band + 2 h). A radius given
    too large reads epsilon (``L / 2 pi R``) low by the radius' excess, and by more than the
    periphery's gap (:func:`wall_gap_max_px`) it leaves every such junction beyond that
    tolerance: every stack reads as bulk. Such a hole is
    told by the ink reaching within 2 h of its circle on less than :data:`WIDE_REACH_MAX` of
    it, where the ink's own envelope (:func:`fit_hole`, centred within a fifth of the radius)
    lies more than 2 h inside it and is reached on :data:`WIDE_ENVELOPE_MIN` of it (a rod
    pressed against a smaller wall), or by an envelope 2 h or more inside that the ink lines
    on :data:`WIDE_LINED_MIN` of it while it reaches the given circle on less than half (a
    radius given alone too large: the centre fitted with it hugs one side of the rod). A
    loose rod far from a right wall (a render of a quenched rod) does neither.

    Parameters
    ----------
    mask : bool array (H, W)
        The ink within the given hole's frame.
    hole : Hole
        The hole given.
    thickness_px : float
        Sheet thickness h, px.

    Returns
    -------
    tuple or None
        ``(center_rc, radius_px, reach_given, reach_envelope)`` of the envelope, or None when
        the given hole is not too wide.
    """
    pts = _boundary_points(mask)
    if len(pts) < 3:
        return None
    within = wide_tolerance_px(thickness_px)
    reach = _envelope_confidence(pts, hole, within)
    if reach >= WIDE_LINED_REACH_MAX:
        return None  # the ink lines the given circle (1.0 on every right hole measured)
    try:
        env = _fit_points(pts, None, None, None, None)
    except AnalysisError:
        return None
    env_reach = _envelope_confidence(pts, env)
    # the ink reaches the given circle nowhere while pressed against a smaller one, or it
    # lines a smaller circle all round (a radius given alone too large: the centre fitted
    # with it hugs one side of the rod, reached there)
    pressed = reach < WIDE_REACH_MAX and env_reach >= WIDE_ENVELOPE_MIN
    off = float(np.hypot(*(env.center_rc - hole.center_rc)))
    if (not (pressed or env_reach >= WIDE_LINED_MIN)
            or off > GIVEN_NEAR_FRACTION * hole.radius_px
            or env.radius_px > hole.radius_px - within):
        return None
    return env.center_rc, float(env.radius_px), reach, env_reach


#: A ring between the ink's envelope and a plate's edge found is a rim of the plate when its
#: median brightness is below this fraction of the paper's (:func:`rim_inside`).
RIM_BRIGHTNESS_MAX = 0.9


def rim_inside(rgb, ink_mask, hole, envelope, *, thickness_px: float) -> bool:
    """Whether the surface between the ink's envelope and a plate's edge found outside it is
    a rim of the plate rather than paper.

    The ring from 2 h beyond the envelope to 2 px inside the edge, ink left out, is a rim when
    its median brightness (the sum of the channels) is below :data:`RIM_BRIGHTNESS_MAX` of
    the paper's: the 80th percentile of the brightness of the surface inside the envelope
    (voids: paper, and the darker receding surfaces).

    Parameters
    ----------
    rgb : (H, W, 3) array
    ink_mask : (H, W) bool array
    hole : Hole
        The plate's edge found.
    envelope : tuple
        ``(center_rc, radius_px, ...)`` of the ink's envelope (:func:`given_hole_wide`).
    thickness_px : float

    Returns
    -------
    bool
        False too where either surface has fewer than 20 pixels.
    """
    (er, ec), env_r = envelope[0], float(envelope[1])
    h, w = ink_mask.shape
    r_lo, r_hi = hole.center_rc[0] - hole.radius_px, hole.center_rc[0] + hole.radius_px
    c_lo, c_hi = hole.center_rc[1] - hole.radius_px, hole.center_rc[1] + hole.radius_px
    r0, r1 = int(max(np.floor(r_lo), 0)), int(min(np.ceil(r_hi) + 1, h))
    c0, c1 = int(max(np.floor(c_lo), 0)), int(min(np.ceil(c_hi) + 1, w))
    rr, cc = np.ogrid[r0:r1, c0:c1]
    d_env = np.hypot(rr - er, cc - ec)
    d_edge = np.hypot(rr - hole.center_rc[0], cc - hole.center_rc[1])
    free = ~np.asarray(ink_mask, bool)[r0:r1, c0:c1]
    # the hole's box only, summed in integers (no float copy of the whole scan)
    lum = np.asarray(rgb)[r0:r1, c0:c1].sum(axis=2, dtype=np.int64)
    ring = lum[free & (d_env > env_r + 2 * thickness_px) & (d_edge < hole.radius_px - 2)]
    paper = lum[free & (d_env < env_r - 2 * thickness_px)]
    if ring.size < 20 or paper.size < 20:
        return False
    return bool(np.median(ring) < RIM_BRIGHTNESS_MAX * np.percentile(paper, 80))


def _wall_points(rgb, ink_mask, c0, r0, n_rays, *, far=False):
    """Wall points on rays from ``c0`` where a plate distinct from the paper surrounds it.

    The rays run from 0.7 ``r0`` to 1.2 ``r0`` + 10 px, the plate's colour taken beyond
    1.06 ``r0`` + 4 px; with ``far`` they run to the scan's border and the plate's colour is
    taken on the outer fifth of each ray beyond ``r0`` (a hole larger than the rod's
    envelope: a rod that does not reach the wall)."""
    import cv2
    H, W = ink_mask.shape
    ang = np.linspace(-np.pi, np.pi, n_rays, endpoint=False)
    if far:
        corners = np.array([[0, 0], [0, W - 1], [H - 1, 0], [H - 1, W - 1]], float)
        r_end = float(np.hypot(*(corners - np.asarray(c0, float)).T).max()) + 1.0
    else:
        r_end = 1.2 * r0 + 10.0
    # the far rays only locate the edge (read again from the circle through it): 2-px steps
    step = 2.0 if far else 1.0
    rad = np.arange(0.7 * r0, r_end, step)
    mr, mc, valid = _ray_grid(float(c0[0]), float(c0[1]), np.sin(ang), np.cos(ang), rad, H, W)
    # sample the scan on the rays, then smooth over 3 x 3 (ray, radius) samples: the same
    # denoising as blurring the scan first, on a few hundred thousand samples instead of all
    col = _remap(np.ascontiguousarray(rgb), mc, mr, cv2.INTER_LINEAR).astype(np.float32)
    col = cv2.blur(col, (3, 3))
    ink = _remap(ink_mask.view(np.uint8), mc, mr, cv2.INTER_NEAREST) > 0
    inner = (rad <= 0.95 * r0)[None, :] & valid & ~ink
    if far:
        # each ray's outer fifth between the envelope and the scan's border
        last = np.where(valid.any(axis=1), rad[valid.shape[1] - 1 - np.argmax(valid[:, ::-1],
                                                                              axis=1)], r0)
        outer = (rad[None, :] >= (r0 + 0.8 * (last - r0))[:, None]) & valid
    else:
        outer = (rad >= 1.06 * r0 + 4.0)[None, :] & valid
    sector = ((ang + np.pi) / (2 * np.pi) * 16).astype(int) % 16
    # the angles increase, so each sector is a run of rays: its samples are row slices, read
    # in place (fancy-indexed copies of them took a third of the search)
    bounds = np.searchsorted(sector, np.arange(17))
    pts = []
    for s in range(16):
        a, b = int(bounds[s]), int(bounds[s + 1])
        col_s, ink_s, valid_s = col[a:b], ink[a:b], valid[a:b]
        inner_s, outer_s = inner[a:b], outer[a:b]
        if np.count_nonzero(inner_s) < 20 or np.count_nonzero(outer_s) < 20:
            continue
        # paper is the brightest large surface inside: receding surfaces are darker
        # (channel by channel: each channel's samples are then one contiguous array, whose
        # medians numpy selects in one pass; 2.5 ms for the 16 sectors of 720 rays on a
        # 2000 x 2000 scan, against 8 ms for np.median and np.percentile on rows of 3)
        cin = [col_s[..., c][inner_s] for c in range(3)]
        lum = cin[0] + cin[1] + cin[2]
        top = lum >= _percentile(lum, 80)
        paper = np.array([_median(c[top]) for c in cin])
        cout = [col_s[..., c][outer_s] for c in range(3)]
        plate = np.array([_median(c) for c in cout])
        axis = plate - paper
        spread = np.array([_median(np.abs(c - p)) for c, p in zip(cout, plate)])
        # a plate only when it differs from the paper well beyond its own texture, and is
        # darker: a brighter "outside" is the paper itself around a rod whose inside is
        # receding surface (a scan without plate, the hole larger than the rod)
        if np.linalg.norm(axis) < max(25.0, 6.0 * np.linalg.norm(spread)) \
                or plate.sum() >= paper.sum():
            continue
        # (the paper's colour repeated along the rays: subtracted with a broadcast over the
        # last axis, of 3, numpy's loop costs 8x as much)
        rel = (col_s.reshape(b - a, -1) - np.tile(paper, col_s.shape[1])).reshape(col_s.shape)
        proj = rel @ axis / (axis @ axis)
        proj[ink_s] = 0.0
        plate_like = (proj >= 0.5) | ~valid_s
        n = plate_like.shape[1]
        # last inside sample of each ray, followed by plate up to the ray's end
        j = n - 1 - np.argmax(~plate_like[:, ::-1], axis=1)
        ok = (~plate_like).any(axis=1) & (j < n - 1)
        # (a far ray may leave the scan before its end: the part inside must hold the edge)
        ok &= valid_s[np.arange(b - a), np.minimum(j + 1, n - 1)] \
            & (valid_s.sum(axis=1) > (10 if far else n // 2))
        i = np.flatnonzero(ok)
        j = j[ok]
        p0, p1 = proj[i, j], proj[i, j + 1]
        f = np.clip((0.5 - p0) / np.maximum(p1 - p0, 1e-6), 0.0, 1.0)
        f[ink_s[i, j]] = 0.5
        rw = rad[j] + step * f
        a_i = ang[a + i]
        pts.append(np.column_stack([c0[0] + np.sin(a_i) * rw, c0[1] + np.cos(a_i) * rw]))
    if not pts:
        return np.zeros((0, 2))
    return np.concatenate(pts)


#: ``cv2.remap`` takes images and maps of fewer than this many rows and columns.
_REMAP_MAX = 32767


def _remap(src, map_c, map_r, interpolation, *, limit: int = _REMAP_MAX):
    """``cv2.remap(src, map_c, map_r, interpolation, borderMode=BORDER_REPLICATE)`` for maps
    and images of any size.

    OpenCV rejects a map or an image of ``limit`` rows or columns or more (a scan 40 000 px
    long, or rays longer than that). Such a sampling is done block by block: each block of
    the maps reads the part of the image its samples cover (clipped to the image, plus a
    pixel for the interpolation), with the same values, since a replicated border of that
    part is the image's own wherever a sample falls outside it. A block whose part is still
    too large is split in two along its longer side.

    Parameters
    ----------
    src : (H, W[, C]) array
    map_c, map_r : (n, m) float32 arrays
        Columns and rows of the samples in ``src``.
    interpolation : int
        ``cv2.INTER_LINEAR`` or ``cv2.INTER_NEAREST``.
    limit : int
        The largest side OpenCV takes, plus one.

    Returns
    -------
    (n, m[, C]) array of ``src``'s dtype
    """
    import cv2

    H, W = src.shape[:2]
    n, m = map_c.shape
    if max(H, W, n, m) < limit:
        return cv2.remap(src, map_c, map_r, interpolation, borderMode=cv2.BORDER_REPLICATE)
    out = np.empty((n, m) + src.shape[2:], src.dtype)
    step = max(limit // 2, 1)
    blocks = [(i, min(i + step, n), j, min(j + step, m))
              for i in range(0, n, step) for j in range(0, m, step)]
    while blocks:
        i0, i1, j0, j1 = blocks.pop()
        bc, br = map_c[i0:i1, j0:j1], map_r[i0:i1, j0:j1]
        # the image part the samples cover (the maps are finite: rays of a finite circle)
        c_lo, c_hi = np.clip([np.floor(bc.min()), np.floor(bc.max()) + 1], 0, W - 1).astype(int)
        r_lo, r_hi = np.clip([np.floor(br.min()), np.floor(br.max()) + 1], 0, H - 1).astype(int)
        if max(c_hi - c_lo + 1, r_hi - r_lo + 1) >= limit:
            if i1 - i0 >= j1 - j0:
                k = (i0 + i1) // 2
                blocks += [(i0, k, j0, j1), (k, i1, j0, j1)]
            else:
                k = (j0 + j1) // 2
                blocks += [(i0, i1, j0, k), (i0, i1, k, j1)]
            continue
        part = np.ascontiguousarray(src[r_lo:r_hi + 1, c_lo:c_hi + 1])
        out[i0:i1, j0:j1] = cv2.remap(part, bc - np.float32(c_lo), br - np.float32(r_lo),
                                      interpolation, borderMode=cv2.BORDER_REPLICATE)
    return out


@njit(cache=True)
def _ray_grid(r0, c0, sin, cos, rad, h, w):  # pragma: no cover - numba
    """Sample positions ``r0 + sin * rad`` (rows) and ``c0 + cos * rad`` (columns) of rays
    of directions ``(sin, cos)``, as float32 maps for ``cv2.remap``, and whether each lies
    on the ``h`` x ``w`` image (tested in float64).

    One pass, no float64 temporaries: 0.13 ms for 720 rays of 460 samples, against 1.7 ms
    in numpy; the same values (a product, then a sum, each rounded).
    """
    n, m = sin.size, rad.size
    mr = np.empty((n, m), np.float32)
    mc = np.empty((n, m), np.float32)
    valid = np.empty((n, m), np.bool_)
    for i in range(n):
        s = sin[i]
        c = cos[i]
        for j in range(m):
            rr = r0 + s * rad[j]
            cc = c0 + c * rad[j]
            mr[i, j] = rr
            mc[i, j] = cc
            valid[i, j] = (rr >= 0) & (rr <= h - 1) & (cc >= 0) & (cc <= w - 1)
    return mr, mc, valid


def _median(x):
    """``np.median`` of a 1-D float array: one partition on a single index, which numpy does
    in one vectorised pass (np.median asks for two indices, a slower selection)."""
    h = x.size // 2
    p = np.partition(x, h)
    if x.size % 2:
        return p[h]
    return (p[:h].max() + p[h]) / x.dtype.type(2)  # the mean of the middle two, in x's type


def _percentile(x, q):
    """``np.percentile(x, q)`` (linear method) of a 1-D float array and a number ``q`` in
    [0, 100), by partitions on single indices (see :func:`_median`).

    The interpolation is numpy's own, in x's type (``g`` is a Python float):
    ``lo + (hi - lo) * g``, or ``hi - (hi - lo) * (1 - g)`` from half way on.
    """
    v = (x.size - 1) * (q / 100)
    k = int(v)
    g = v - k
    if k + 1 >= x.size:
        return np.max(x)
    p = np.partition(x, k)
    lo, hi = p[k], p[k + 1:].min()
    d = hi - lo
    return hi - d * (1 - g) if g >= 0.5 else lo + d * g


def _can_be_hole(shape, center_rc, radius_px) -> bool:
    """Whether a candidate circle can be the hole of a scan of ``shape``: :func:`check_hole`'s
    rule (a positive finite radius, a diameter at most twice the scan's largest side, a circle
    overlapping the image).

    A brightness ramp across a scan without plate reads as a nearly straight "edge", whose
    circle fit lies far off the scan (a centre 10^6 px away): its rays would hold more
    samples than the image, and no such circle frames the rod.
    """
    try:
        check_hole(shape, center_rc, radius_px)
    except ParameterError:
        return False
    return True


def _wall_circle(rgb, ink, c0, r0):
    """The plate's edge read on rays from the circle (``c0``, ``r0``) and fitted:
    ``(centre, radius, confidence)``, or None when fewer than a fifth of the rays cross it,
    or when the circle cannot be the hole (:func:`_can_be_hole`).

    One ray per ~2.5 degrees at most: 720 wall points fit a circle to a tenth of a pixel, and
    the cost of the ray sampling grows with their number."""
    c0 = np.asarray(c0, float)
    if not _can_be_hole(ink.shape, c0, r0):
        return None
    n = int(np.clip(np.pi * r0, 90, 720))
    pts = _wall_points(np.asarray(rgb), ink, c0, float(r0), n)
    if len(pts) < 0.2 * n:
        return None
    c, r, keep = _circle_fit(pts, c0, float(r0))
    return c, r, float(np.count_nonzero(keep)) / n


def _plate_features(rgb) -> np.ndarray:
    """Colour features that illumination leaves alone: chromaticity and a tenth of the log
    brightness (a gain of +-15 % moves the latter by 0.014, a factor 2 by 0.07)."""
    c = np.asarray(rgb, dtype=np.float32)
    s = np.maximum(c.sum(axis=-1), 1.0)
    return np.stack([c[..., 0] / s, c[..., 2] / s, 0.1 * np.log(s)], axis=-1)


def _without_plate(rgb, ink_mask):
    """The ink mask without a plate that passed the ink's colour rule, or None.

    A blue plate around the hole is ink to any colour rule, and its pixels join the rod's
    wall band into one component reaching the scan's border. The plate's colour is read on
    that component's pixels in the outer sixteenth of the scan, the ink's as the other centre
    of a two-means split of the component's colours (started from the darker half of those
    far from the plate's), both in chromaticity and log brightness
    (:func:`_plate_features`: an illumination gradient or the plate's texture changes the
    brightness, not the hue); a pixel (smoothed over 3 x 3) nearer the plate's colour leaves
    the mask. When the two colours are not apart by :data:`PLATE_INK_SEPARATION` times the
    plate's own spread, nothing tells them apart and None is returned (the hole's search
    then flags itself: give the hole).

    Parameters
    ----------
    rgb : (H, W, 3) array
    ink_mask : (H, W) bool array

    Returns
    -------
    (H, W) bool array or None
    """
    import cv2

    step = 4
    small = np.ascontiguousarray(ink_mask[::step, ::step]).view(np.uint8)
    if min(small.shape) < 8:
        return None
    n, lab = cv2.connectedComponents(small, connectivity=8)
    if n < 2:
        return None
    edge = np.concatenate([lab[0], lab[-1], lab[1:-1, 0], lab[1:-1, -1]])
    touch = np.bincount(edge, minlength=n)
    touch[0] = 0
    k = int(np.argmax(touch))
    if touch[k] < PLATE_BORDER_FRACTION * edge.size:
        return None
    comp = lab == k
    # block means: the scan's noise averaged over step x step pixels
    rgb_s = cv2.resize(np.ascontiguousarray(rgb).astype(np.float32),
                       (small.shape[1], small.shape[0]), interpolation=cv2.INTER_AREA)
    f_s = _plate_features(rgb_s)
    m = max(max(comp.shape) // 16, 1)
    outer = np.zeros_like(comp)
    outer[:m], outer[-m:], outer[:, :m], outer[:, -m:] = True, True, True, True
    plate_px, col = f_s[comp & outer], f_s[comp]
    if len(plate_px) < 20 or len(col) < 40:
        return None
    plate = np.median(plate_px, axis=0)
    spread = max(float(np.linalg.norm(1.4826 * np.median(np.abs(plate_px - plate), axis=0))),
                 PLATE_MIN_SPREAD)
    d = np.linalg.norm(col - plate, axis=1)
    far = col[d > PLATE_INK_SEPARATION * spread]
    if len(far) < 20:
        return None
    # the ink's first guess: the darker half of the colours far from the plate's (a blurred
    # band's edge, ink mixed with paper, is brighter than its core and can have the hue of
    # a light plate)
    ink = np.median(far[far[:, 2] <= np.median(far[:, 2])], axis=0)
    for _ in range(10):  # two-means from the plate and that guess
        near_ink = np.linalg.norm(col - ink, axis=1) < np.linalg.norm(col - plate, axis=1)
        if near_ink.all() or not near_ink.any():
            return None
        plate_new, ink_new = np.median(col[~near_ink], axis=0), np.median(col[near_ink], axis=0)
        if np.allclose(plate_new, plate) and np.allclose(ink_new, ink):
            break
        plate, ink = plate_new, ink_new
    gap = float(np.linalg.norm(ink - plate))
    if gap < PLATE_INK_SEPARATION * spread:
        return None
    f = _plate_features(cv2.blur(np.ascontiguousarray(rgb).astype(np.float32), (3, 3)))
    axis = ((ink - plate) / gap).astype(np.float32)
    # nearer the ink than the plate: the projection on the plate -> ink axis past half way
    proj = (f - plate.astype(np.float32)) @ axis
    return np.asarray(ink_mask, bool) & (proj > 0.5 * gap)


def _within_upsampled(mask, small_mask):
    """``mask`` where a half-resolution component mask (``small_mask``, of ``mask[::2,
    ::2]``), dilated by one of its pixels, covers it at full resolution.

    Pixel (r, c) reads the dilated mask at (r // 2, c // 2), the pixel a nearest-neighbour
    resize of it to ``mask``'s shape (``cv2.resize``, ``INTER_NEAREST``) reads, for even and
    odd sides alike: ``floor(r (n + 1) / (2 n + 1)) = floor(r / 2)`` for ``r < 2 n + 1``.
    """
    import cv2

    keep = cv2.dilate(np.ascontiguousarray(small_mask).view(np.uint8), np.ones((3, 3), np.uint8))
    return _and_upsampled(np.ascontiguousarray(mask, dtype=bool), keep.view(bool))


@njit(cache=True)
def _and_upsampled(mask, keep):  # pragma: no cover - numba
    """``mask & keep[r // 2, c // 2]`` at every pixel (r, c), in one pass over ``mask``.

    0.3 ms for a 2000 x 2000 scan, against 1.2 ms for the resized ``keep`` (a new 4 MB
    image) and the ``&`` of the two: the pixels in pairs, each pair reading one ``keep``
    value, ``&`` on booleans (a short-circuit ``and`` is not vectorised: 1.6 ms).
    """
    h, w = mask.shape
    out = np.empty((h, w), np.bool_)
    for r in range(h):
        kr = keep[r >> 1]
        mr = mask[r]
        orow = out[r]
        for j in range(w >> 1):
            kv = kr[j]
            orow[2 * j] = mr[2 * j] & kv
            orow[2 * j + 1] = mr[2 * j + 1] & kv
        if w & 1:
            orow[w - 1] = mr[w - 1] & kr[w >> 1]
    return out


def find_hole(rgb, ink_mask, *, min_confidence: float = 0.5, path=None) -> Hole:
    """The hole found in the scan: the plate's circular edge, else the ink envelope.

    Parameters
    ----------
    rgb : (H, W, 3) uint8 or uint16 array
    ink_mask : (H, W) bool array
        The ink (threshold output; specks are harmless).
    min_confidence : float
        Below this the plate's circle is not trusted and the ink envelope is returned (with
        the lower of the two confidences).
    path : str, optional
        Image path, for error messages.

    Returns
    -------
    Hole
        ``fitted`` True; ``confidence`` in [0, 1] and ``reason`` as in the module docstring.

    Raises
    ------
    AnalysisError
        No ink to start from.
    """
    import cv2

    ink = np.asarray(ink_mask, dtype=bool)
    # a plate the colour rule passed is told from the ink by its own colour where it can be
    unplated = _without_plate(rgb, ink)
    if unplated is not None:
        ink = ink_mask = unplated
    # the rod is one network (wall stacks link it): its largest component gives the first
    # guess, free of specks and of any plate pixels that passed the threshold
    # (found on the scan at half resolution: bands are >= 2 px wide, and the labelling is
    # the costliest step of the search at full resolution)
    # (the areas by a count of the labels: OpenCV's statistics pass costs 4x the labelling;
    # the labels of the ink pixels only, every other pixel being background, label 0: a count
    # of all labels costs an intp copy of them, 2.5 ms against 0.6 ms)
    small = np.ascontiguousarray(ink[::2, ::2]).view(np.uint8)
    n, lab = cv2.connectedComponents(small, connectivity=8)
    big = ()  # the labels of the rod's pieces, when it is in more than one
    largest = 1
    if n > 2:
        area = np.bincount(lab[small.view(bool)], minlength=n)
        area[0] = small.size - np.count_nonzero(small)
        largest = 1 + int(np.argmax(area[1:]))
        big = np.flatnonzero(area >= PIECE_FRACTION * area[largest])
        big = big[big > 0] if len(big) > 2 else ()
    if n > 1:
        # the largest piece at full resolution; with it alone on the lattice too: a speck
        # off the lattice (one pixel at an odd row or column) grew a plateless hole by half
        ink = _within_upsampled(ink, lab == largest)
    border = _boundary_points(ink)
    env = _fit_points(border, None, None, None, path)
    env_conf = _envelope_confidence(border, env)
    plate_conf = 0.0
    fit = _wall_circle(rgb, ink, env.center_rc, env.radius_px)
    if fit is not None:
        c, r, plate_conf = fit
        if plate_conf < _REREAD_BELOW:
            # rays from an envelope off the hole's centre meet the edge obliquely, or miss it:
            # read it again from the circle found
            again = _wall_circle(rgb, ink, c, r)
            if again is not None and again[2] > plate_conf:
                c, r, plate_conf = again
        if plate_conf >= min_confidence:
            return Hole(np.asarray(c, dtype=np.float64), r, True, plate_conf,
                        f"plate edge on {100 * plate_conf:.0f} % of directions")
    # no plate edge near the envelope: the rod may not reach the wall (a loosely packed rod,
    # a render of a free rod). The edge is looked for out to the scan's border, then read
    # again on rays from the circle found there, which cross it square.
    n_far = int(np.clip(np.pi * env.radius_px, 90, _FAR_RAYS))
    far = (_wall_points(np.asarray(rgb), ink, env.center_rc, env.radius_px, n_far, far=True)
           if _can_be_hole(ink.shape, env.center_rc, env.radius_px) else np.zeros((0, 2)))
    # (the circle through points on a brightness ramp may lie far off the scan:
    # _wall_circle rejects it as a candidate)
    fit = (_wall_circle(rgb, ink, *_circle_fit(far, *kasa_fit(far))[:2])
           if len(far) >= 0.1 * n_far else None)
    if fit is not None:
        c, r, conf = fit
        # the hole holds the rod's largest piece
        holds = len(border) and np.hypot(*(border - c).T).max() <= r + 2.0
        if conf >= min_confidence and holds:
            return Hole(np.asarray(c, dtype=np.float64), r, True, conf,
                        f"plate edge on {100 * conf:.0f} % of directions, beyond the rod's "
                        "envelope")
        plate_conf = max(plate_conf, conf)
    why = ("no plate distinct from the paper" if plate_conf == 0 else
           f"plate edge found on only {100 * plate_conf:.0f} % of directions")
    try:
        check_hole(ink.shape, env.center_rc, env.radius_px)
    except ParameterError:
        # the ink's envelope is no circle (a few strokes): frame nothing out, flag it
        (x, y), r = cv2.minEnclosingCircle(np.argwhere(np.asarray(ink_mask, bool))[:, ::-1]
                                           .astype(np.float32))
        return Hole(np.array([y, x], np.float64), float(r) + 1.0, True, 0.0,
                    f"{why}, and the ink's envelope is not a circle: smallest circle around "
                    "the ink")
    # without a plate nothing marks the wall: the frame must not cut the rod, so the circle
    # grows to hold all of its largest ink component (a rod pressed on the wall is unchanged).
    # The ink pixel farthest from the centre has a 4-neighbour farther still, from which the
    # background runs outwards to the edge: it lies on an outer border, so the border pixels
    # give the same farthest distance as every ink pixel (without a pass over the scan)
    # The rod may be drawn or cut in pieces (a broken line, a layer lost in the cut): every
    # piece as large as PIECE_FRACTION of the largest is held too, specks are not
    if len(big):
        border = _boundary_points(_within_upsampled(ink_mask, np.isin(lab, big)))
    reach = float(np.sqrt(((border - env.center_rc) ** 2).sum(axis=1).max())) + 1.0 \
        if len(border) else env.radius_px
    if reach > env.radius_px + GROWN_PX:
        # grown to hold ink far beyond the envelope (a second piece of the rod, or a label or
        # a mark beside the hole): the confidence is that of the circle returned, which the
        # ink reaches only where that piece lies
        grown = Hole(env.center_rc, reach, True)
        conf = min(env_conf, _envelope_confidence(border, grown))
        return Hole(env.center_rc, reach, True, conf,
                    f"{why}: ink envelope grown by {reach - env.radius_px:.0f} px to hold every "
                    f"piece of ink; ink reaches it on {100 * conf:.0f} % of the circle")
    return Hole(env.center_rc, max(env.radius_px, reach), True, env_conf,
                f"{why}: ink envelope, ink reaches it on {100 * env_conf:.0f} % of the circle")


def wall_tolerance_px(graph, width_px, thickness_px) -> np.ndarray:
    """Per-stack wall-contact tolerance: half the widest stack meeting at either end + 2 h.

    A junction sits on the skeleton, i.e. half a stack width inside the wall when the stack
    along the wall touches it; 2 h absorbs the ink thickening and the fit of the circle.
    """
    widths = np.asarray(width_px, dtype=np.float64)
    widths = np.where(np.isfinite(widths), widths, 0.0)
    m = len(graph.ends)
    node_w: dict = {}
    for sid, (u, v) in enumerate(graph.ends):
        for node in (u, v):
            node_w[node] = max(node_w.get(node, 0.0), widths[sid] if sid < len(widths) else 0.0)
    tol = np.empty(m)
    for sid, (u, v) in enumerate(graph.ends):
        tol[sid] = 0.5 * max(node_w.get(u, 0.0), node_w.get(v, 0.0)) + 2.0 * float(thickness_px)
    return tol


#: Paper between the wall and the outermost ink up to half the widest stack and this many
#: sheet thicknesses is a gap that the periphery's contact tolerance does not count
#: (:func:`wall_gap_max_px`).
WALL_GAP_H = 2.0


def wall_gap_max_px(width_px, thickness_px: float) -> float:
    """The widest gap between the wall and the wall band that :func:`classify_regions` does
    not count as distance: half the scan's widest stack plus :data:`WALL_GAP_H` h.

    A wall band whose thick stretches are pressed against the wall lies up to half its widest
    stack inside it along its thin stretches when its inner side, not its outer one, follows
    a circle; 2 h takes in a hole given or fitted a little wide (1 % of a 15 mm radius is
    1.5 h at h = 0.1 mm).

    Parameters
    ----------
    width_px : array
        Stack widths (px); non-finite ones are ignored.
    thickness_px : float

    Returns
    -------
    float
    """
    w = np.asarray(width_px, dtype=np.float64)
    w = w[np.isfinite(w)]
    return 0.5 * (float(w.max()) if w.size else 0.0) + WALL_GAP_H * float(thickness_px)


def wall_gaps_px(mask, hole, points_rc, *, reach_px: float) -> np.ndarray:
    """Paper between the outermost ink and the wall on the ray from the hole's centre through
    each point.

    The ray is read on ``mask`` (nearest pixel, 0.5 px steps) from the point, or from
    ``reach_px`` inside the wall when the point lies deeper, out to 2 px beyond the wall.

    Parameters
    ----------
    mask : (H, W) bool array
        The ink.
    hole : Hole
    points_rc : (K, 2) array
        Points inside the hole (row, col).
    reach_px : float
        How far inside the wall the outermost ink is looked for.

    Returns
    -------
    (K,) float array
        ``radius - r`` of the outermost ink sample ``r`` on each ray (negative: ink beyond the
        wall); inf where no ink lies within ``reach_px`` of the wall.
    """
    p = np.asarray(points_rc, dtype=np.float64).reshape(-1, 2)
    reach_px = _number("reach_px", reach_px, allow_equal=True)
    if len(p) == 0:
        return np.zeros(0)
    c = np.asarray(hole.center_rc, dtype=np.float64)
    r0 = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])
    u = (p - c) / np.maximum(r0, 1e-9)[:, None]
    start = np.maximum(r0, hole.radius_px - reach_px)
    steps = np.arange(0.0, reach_px + 2.5, 0.5)
    rad = start[:, None] + steps[None, :]
    inside = rad <= hole.radius_px + 2.0
    h, w = mask.shape
    rr = np.clip(np.rint(c[0] + u[:, :1] * rad), 0, h - 1).astype(np.intp)
    cc = np.clip(np.rint(c[1] + u[:, 1:] * rad), 0, w - 1).astype(np.intp)
    ink = np.asarray(mask, bool)[rr, cc] & inside
    last = np.where(ink.any(axis=1), rad[np.arange(len(p)), ink.shape[1] - 1
                                         - np.argmax(ink[:, ::-1], axis=1)], -np.inf)
    return hole.radius_px - last


def classify_regions(graph, junction_centers_rc, hole, *, tol_px, mask=None,
                     gap_max_px: float = 0.0) -> list[str]:
    """``"periphery"`` or ``"bulk"`` per stack (paper, "Two sub-systems").

    A stack is periphery when one of its end nodes touches the wall: the distance from the
    node to the circle, ``R - |node - centre|``, is at most the tolerance (nodes outside the
    circle count as touching). With ``mask``, paper between the circle and the outermost ink
    on the node's ray (:func:`wall_gaps_px`) is not counted in that distance when it is at
    most ``gap_max_px`` wide: a wall band lying a little inside the circle (a hole given or
    found a little wide, a band whose thin stretches lie inside its widest one) still
    touches it, where a junction facing open paper up to the wall does not. End nodes are
    junctions or free skeleton ends, at their positions ``graph.node_rc`` (junction nodes:
    ``junction_centers_rc``). A closed loop without junction has no extremity; it is
    periphery when its path comes within the tolerance of the wall (the paper is silent;
    such a loop lying along the wall is the extreme case of a branch pressed against it).

    Parameters
    ----------
    graph : StackGraph
        ``ends``, ``node_rc``, ``node_kind``, ``paths``.
    junction_centers_rc : array (K, 2)
        Junction centres; junction ids 0..K-1 are the graph's junction nodes.
    hole : Hole or None
        None: every stack is bulk (no wall, e.g. simulations).
    tol_px : float or array (M,)
        Contact tolerance, scalar or per stack. Suggested: :func:`wall_tolerance_px`
        (half the widest stack at the junction + 2 h).
    mask : (H, W) bool array, optional
        The ink; without it the distance is to the circle alone.
    gap_max_px : float
        The widest gap not counted. Suggested: :func:`wall_gap_max_px` (half the scan's
        widest stack + 2 h).

    Returns
    -------
    list of str, one per stack id.
    """
    m = len(graph.ends)
    if hole is None or m == 0:
        return ["bulk"] * m
    tol = np.broadcast_to(np.asarray(tol_px, dtype=np.float64), (m,))
    jc = np.asarray(junction_centers_rc, dtype=np.float64).reshape(-1, 2)
    kinds = getattr(graph, "node_kind", {}) or {}

    def pos(node):
        if 0 <= node < len(jc) and kinds.get(node, "junction") == "junction":
            return jc[node]
        return np.asarray(graph.node_rc[node], dtype=np.float64)

    # both ends of every stack at once (the same element-wise distances as per stack)
    ends = np.array([[pos(u), pos(v)] for u, v in graph.ends], dtype=np.float64)
    d = hole.distance_to_wall(ends.reshape(-1, 2)).reshape(m, 2)
    if mask is not None and gap_max_px > 0:
        # the wall's side of each end beyond the tolerance: paper between the outermost ink
        # on its ray and the circle, when no wider than gap_max_px, is a gap, not a distance
        tol2 = np.repeat(tol, 2).reshape(m, 2)
        near = (d > tol2) & (d <= tol2 + gap_max_px)
        if near.any():
            gap = wall_gaps_px(mask, hole, ends[near], reach_px=gap_max_px)
            d[near] -= np.where(gap <= gap_max_px, np.maximum(gap, 0.0), 0.0)
    d = d.min(axis=1)
    for sid, (u, _v) in enumerate(graph.ends):
        if kinds.get(u) == "loop":
            d[sid] = hole.distance_to_wall(graph.paths[sid]).min() if len(graph.paths[sid]) \
                else np.inf
    return ["periphery" if d[sid] <= tol[sid] else "bulk" for sid in range(m)]
