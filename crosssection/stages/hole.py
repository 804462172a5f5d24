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
   gaps and dropped. A geometric fit (``scipy.optimize.least_squares``, soft-L1 loss) on the
   remaining points; three iterations.
4. Pixel centres of the outermost ink lie half a pixel inside the ink's outer edge: 0.5 px is
   added to the fitted radius (the wall is the outer edge of the ink).

When only the centre is given the radius is the median distance of the outermost points; when
only the radius is given the centre is fitted with the radius fixed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crosssection.core.errors import AnalysisError

__all__ = ["Hole", "fit_hole", "classify_regions", "wall_tolerance_px", "kasa_fit"]


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
    """

    center_rc: np.ndarray
    radius_px: float
    fitted: bool

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
    d = points - center
    rad = np.hypot(d[:, 0], d[:, 1])
    ang = np.arctan2(d[:, 0], d[:, 1])
    b = np.clip(((ang + np.pi) / (2 * np.pi) * n_bins).astype(np.int64), 0, n_bins - 1)
    order = np.lexsort((rad, b))
    last = np.r_[b[order][1:] != b[order][:-1], True]
    sel = order[last]
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
    """
    from scipy.optimize import least_squares
    from scipy.spatial import ConvexHull, QhullError

    if center_rc is not None and radius_px is not None:
        return Hole(np.asarray(center_rc, dtype=np.float64).copy(), float(radius_px), False)
    pts = _boundary_points(np.asarray(mask, dtype=bool))
    if len(pts) < 3:
        raise AnalysisError("cannot fit the hole: the mask has no foreground", path)
    try:
        hull = pts[ConvexHull(pts).vertices]
    except QhullError as exc:  # collinear points
        raise AnalysisError(f"cannot fit the hole: degenerate foreground ({exc.args[0][:40]})",
                            path) from None
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
        q = outer[keep]
        if center_rc is not None:
            r = float(np.median(rad[keep]))
            continue
        if radius_px is not None:
            fun = lambda x: np.hypot(*(q - x).T) - (float(radius_px) - 0.5)  # noqa: E731
            c = least_squares(fun, c, loss="soft_l1", f_scale=1.0).x
        else:
            fun = lambda x: np.hypot(*(q - x[:2]).T) - x[2]  # noqa: E731
            sol = least_squares(fun, np.r_[c, r - 0.5], loss="soft_l1", f_scale=1.0).x
            c, r = sol[:2], float(sol[2]) + 0.5
    if center_rc is not None:
        r = r + 0.5  # pixel centres -> outer edge of the ink
    if radius_px is not None:
        r = float(radius_px)
    return Hole(np.asarray(c, dtype=np.float64), float(r), True)


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


def classify_regions(graph, junction_centers_rc, hole, *, tol_px) -> list[str]:
    """``"periphery"`` or ``"bulk"`` per stack (paper, "Two sub-systems").

    A stack is periphery when one of its end nodes touches the wall: the distance from the
    node to the circle, ``R - |node - centre|``, is at most the tolerance (nodes outside the
    circle count as touching). End nodes are junctions or free skeleton ends, at their
    positions ``graph.node_rc`` (junction nodes: ``junction_centers_rc``). A closed loop
    without junction has no extremity; it is periphery when its path comes within the
    tolerance of the wall (the paper is silent; such a loop lying along the wall is the
    extreme case of a branch pressed against it).

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

    out = []
    for sid, (u, v) in enumerate(graph.ends):
        if kinds.get(u) == "loop":
            d = hole.distance_to_wall(graph.paths[sid]).min() if len(graph.paths[sid]) else np.inf
        else:
            d = hole.distance_to_wall(np.vstack([pos(u), pos(v)])).min()
        out.append("periphery" if d <= tol[sid] else "bulk")
    return out
