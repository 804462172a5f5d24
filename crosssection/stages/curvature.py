"""Stage 10: centreline of a stack and its local curvature (paper, "Image analysis procedure"
and "Curvature of branches").

The paper: "The central position of stacks is deduced from the skeleton and smoothed out by
slide-averages along the stack trajectory. The local curvature is measured through a parabolic
fit on size 5 n_br h, after coordinates translation and rotation in the tangent frame."

1. **Centreline.** The skeleton path smoothed by :func:`crosssection.core.polyline.smooth`
   (``smooth_px`` points, about two sheet thicknesses h; its end rule is documented there).
2. **Local curvature.** At every centreline point the neighbours within +- w/2 of arc length,
   ``w = 5 n_br h``, are rotated into the local tangent frame and ``y = a x^2 + b x + c`` is
   fitted; ``kappa = 2 a / (1 + b^2)^1.5``. The known leak of a circle's x^4 term into ``a``
   is removed (``circle_correction``: exact to O((kappa w)^2) on arcs). Near an open end the
   window keeps its length and is shifted inwards. The window is capped at half the fitted
   length (``max_window_frac``): a longer parabola cannot resolve an S-shaped stack.
3. **Fork zones.** Near a junction the bands of the stacks meeting there overlap: the image
   holds no centreline of this stack, and the skeleton hooks into the medial-axis fork point.
   The maximal disc at the fork (radius r_J, the inscribed ink radius at the junction) touches
   both bands, so the skeleton reaches the band's own centre only about one r_J beyond the
   overlap; layers that peel apart tangentially stay in contact, their bands merged, further
   still (:func:`contact_arc_px`); and the sliding average carries the hook half a smoothing
   window beyond: the fork zone is ``max(2 max(n_br h, r_J), contact) + (smooth_px - 1) / 2``
   of arc from the junction (measured on drawn tangential forks: arms' ``int kappa^2 ds``
   0.9-2.3 x the truth with ``max(n_br h, r_J)``, 0.9-1.2 x with this zone). Those samples
   are not fitted: they are missing data. The default (``method="missing"``) continues the
   linear trend of the curvature over the nearest fitted window (5 n_br h) to the junction,
   so that a bend that tightens toward the fork keeps tightening; the paper's rule
   (``method="paper"``) gives them the curvature of the nearest fitted sample. Free ends keep
   the paper's rule (their skeleton is shortened, not merged). Everywhere the curvature is
   bounded by ``2 / (n_br h)``: the innermost layer of a stack cannot have a negative radius,
   so a tighter estimate is a skeleton kink, not a bend.
4. **Noise floor.** The window fit turns the pixel noise of the centreline into a curvature
   noise of variance ``v`` that adds ``v l`` to every stack's ``int kappa^2 ds`` whatever its
   true bending (on a render's long single-pass stacks, curvature about 0.2 /mm, it was a
   third of the measured energy). ``v`` is measured on the scan itself, for each window (each
   n_br), from the curvature differences at lags ``d`` and ``2 d`` beyond the noise's
   correlation length (``d`` = window + smoothing): ``D(d) = v + a d^2`` for a curvature that
   varies smoothly, so ``v = (4 D(d) - D(2 d)) / 3`` (:func:`noise_variance`). The branch
   energies subtract ``v`` over the quadratic part of the energy density
   (:func:`crosssection.stages.branches.bending_energy`); the profile itself is not changed.

**What these estimators miss** (docs/validation/README.md, "Bending energy"): the share of
the true energy inside fork zones depends on the generator -- 54 % within 2 n_br h of a
junction on ``crosssection.truth.network`` scenes (36 % of the length: its branches leave the
node fanned and bend back), 3-7 % on simulator renders (rod segments of 6-7 h resolve no
bending at that scale). Median total-energy error of the default: renders +4 %, 25 px/mm
-17 %, network typical -32 %, thick dense -29 %. Models that add bending inside the zone (a
curve constrained to reach the junction point, a least-bending turn from the parent band's
axis) overshoot every generator (+36 to +280 %): the skeleton's junction point is not on any
layer's path.

``CurvatureProfile.energy_rel_uncertainty``: the extrapolated share of ``int kappa^2 ds``
(not measured: counted in full) plus the removed noise floor, relative to the stack's
``int kappa^2 ds``.

5. **Sign.** Positive when the path, followed from its start to its end, turns
   counter-clockwise in the image as displayed (x = column to the right, y = -row).

Per stack: kappa_pm = (1/l) int kappa ds, kappa_plus = (1/l) int |kappa| ds,
kappa_m = |kappa_pm| (paper, section "Curvature of branches"), in 1/mm, trapezoid rule.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from scipy.spatial.distance import cdist

from crosssection.core import polyline
from crosssection.core.errors import ParameterError

__all__ = ["CurvatureProfile", "stack_curvature", "stack_profiles", "default_smooth_px",
           "noise_variance", "contact_arc_px"]


@dataclass(frozen=True)
class CurvatureProfile:
    """Local curvature along one stack's smoothed centreline.

    Attributes
    ----------
    s_mm : ndarray (n,)
        Arc length of every sample from the path start, in mm. For a closed loop the first
        sample is repeated at the end so that trapezoid integrals cover the whole loop.
    kappa_per_mm : ndarray (n,)
        Signed local curvature in 1/mm (sign convention in the module docstring).
    length_mm : float
        Length of the centreline in mm (``s_mm[-1]``).
    kappa_pm, kappa_plus, kappa_m : float
        Signed mean, mean absolute value, and absolute signed mean of the curvature, 1/mm.
    closed : bool
        Whether the path was treated as a closed loop.
    rc_px : ndarray (n, 2)
        Centreline (row, col) in px, same samples as ``s_mm``.
    fit_start, fit_stop : int
        Samples ``fit_start:fit_stop`` were fitted; the others lie in fork zones or at ends.
    energy_rel_uncertainty : float
        Relative uncertainty of the stack's ``int kappa^2 ds`` (module docstring; NaN for the
        paper method).
    noise_var_per_mm2 : float
        Variance of the curvature noise of the window fit, 1/mm^2 (module docstring, step 4;
        0 when not measured). The bending energy removes it.
    """

    s_mm: np.ndarray
    kappa_per_mm: np.ndarray
    length_mm: float
    kappa_pm: float
    kappa_plus: float
    kappa_m: float
    closed: bool = False
    rc_px: np.ndarray | None = None
    fit_start: int = 0
    fit_stop: int = -1
    energy_rel_uncertainty: float = float("nan")
    noise_var_per_mm2: float = 0.0


def default_smooth_px(thickness_px: float) -> int:
    """Default sliding-average window: about two sheet thicknesses (11 points for h = 5 px).

    Measured on skeletons of drawn arcs (h = 5 px): the standard deviation of the local
    curvature (paper window 5 h) falls from 0.62/R (5 points) to 0.43/R (11 points) at
    R = 400 px, while the radius shrink stays 0.3 % at R = 40 px.
    """
    k = max(1, int(round(float(thickness_px))))
    return 2 * k + 1


def _make_profile(s_px, kappa_px, rc, px_per_mm, closed, fit=(0, -1)) -> CurvatureProfile:
    kappa = np.asarray(kappa_px, float) * float(px_per_mm)
    s_mm = np.asarray(s_px, float) / float(px_per_mm)
    length_mm = float(s_mm[-1] - s_mm[0]) if len(s_mm) > 1 else 0.0
    if length_mm > 0:
        kpm = float(np.trapezoid(kappa, s_mm) / length_mm)
        kplus = float(np.trapezoid(np.abs(kappa), s_mm) / length_mm)
    else:
        kpm = float(kappa.mean()) if len(kappa) else np.nan
        kplus = float(np.abs(kappa).mean()) if len(kappa) else np.nan
    return CurvatureProfile(s_mm=s_mm, kappa_per_mm=kappa, length_mm=length_mm, kappa_pm=kpm,
                            kappa_plus=kplus, kappa_m=abs(kpm), closed=bool(closed),
                            rc_px=np.asarray(rc, float), fit_start=int(fit[0]),
                            fit_stop=int(len(s_mm) if fit[1] < 0 else fit[1]))


@njit(cache=True)
def _solve3(S0, S1, S2, S3, S4, T0, T1, T2):
    """Least-squares parabola: [[S4 S3 S2],[S3 S2 S1],[S2 S1 S0]] (a b c) = (T2 T1 T0)."""
    det = (S4 * (S2 * S0 - S1 * S1) - S3 * (S3 * S0 - S1 * S2) + S2 * (S3 * S1 - S2 * S2))
    if not (abs(det) > 1e-9 * S4 * S2 * S0):
        return np.nan, np.nan
    deta = (T2 * (S2 * S0 - S1 * S1) - S3 * (T1 * S0 - S1 * T0) + S2 * (T1 * S1 - S2 * T0))
    detb = (S4 * (T1 * S0 - T0 * S1) - T2 * (S3 * S0 - S1 * S2) + S2 * (S3 * T0 - T1 * S2))
    return deta / det, detb / det


@njit(cache=True)
def _parabola_curvature(x, y, s, half_w, i0, i1, correct, shift):
    """Signed curvature (1/px) at points i0..i1-1 by a parabolic fit in the tangent frame.

    x, y: smoothed coordinates in a right-handed frame (x = col, y = -row); s: increasing arc
    length of each point; half_w: half window in px. Near the array ends the window is shifted
    inwards keeping its length (``shift``) or truncated. Closed loops are unrolled by the
    caller.
    """
    n = x.shape[0]
    kappa = np.zeros(i1 - i0)
    for i in range(i0, i1):
        # tangent from a central chord of about 2 px each side (b corrects the residual tilt)
        lo = i
        while lo > 0 and s[i] - s[lo - 1] <= 2.0:
            lo -= 1
        hi = i
        while hi < n - 1 and s[hi + 1] - s[i] <= 2.0:
            hi += 1
        tx = x[hi] - x[lo]
        ty = y[hi] - y[lo]
        tn = np.sqrt(tx * tx + ty * ty)
        if tn == 0.0:
            continue
        tx /= tn
        ty /= tn
        s_lo = s[i] - half_w
        s_hi = s[i] + half_w
        if shift:
            if s_lo < s[0]:
                s_hi = min(s_hi + (s[0] - s_lo), s[n - 1])
                s_lo = s[0]
            elif s_hi > s[n - 1]:
                s_lo = max(s_lo - (s_hi - s[n - 1]), s[0])
                s_hi = s[n - 1]
        a0 = i
        while a0 > 0 and s[a0 - 1] >= s_lo:
            a0 -= 1
        b0 = i
        while b0 < n - 1 and s[b0 + 1] <= s_hi:
            b0 += 1
        if b0 - a0 < 2:
            continue
        S0 = 0.0
        S1 = 0.0
        S2 = 0.0
        S3 = 0.0
        S4 = 0.0
        S5 = 0.0
        S6 = 0.0
        T0 = 0.0
        T1 = 0.0
        T2 = 0.0
        for j in range(a0, b0 + 1):
            dx = x[j] - x[i]
            dy = y[j] - y[i]
            u = dx * tx + dy * ty
            v = -dx * ty + dy * tx
            u2 = u * u
            S0 += 1.0
            S1 += u
            S2 += u2
            S3 += u2 * u
            S4 += u2 * u2
            S5 += u2 * u2 * u
            S6 += u2 * u2 * u2
            T0 += v
            T1 += u * v
            T2 += u2 * v
        a, b = _solve3(S0, S1, S2, S3, S4, T0, T1, T2)
        if not np.isfinite(a):
            continue
        k = 2.0 * a / (1.0 + b * b) ** 1.5
        if correct:
            # A circle y = x^2/(2R) + x^4/(8R^3) + ... : the x^4 term leaks into the fitted
            # a and b by the projections (c2, c1) of x^4 on the window's samples. Remove it
            # (two fixed-point steps; exact to O((kappa X)^2)).
            c2, c1 = _solve3(S0, S1, S2, S3, S4, S4, S5, S6)
            for _ in range(2):
                k3 = k * k * k / 8.0
                at = a - c2 * k3
                bt = b - c1 * k3
                k = 2.0 * at / (1.0 + bt * bt) ** 1.5
        kappa[i - i0] = k
    return kappa


def _trim_indices(s, trims):
    total = s[-1]
    t0 = int(np.searchsorted(s, trims[0], side="left"))
    t1 = int(np.searchsorted(s, total - trims[1], side="right"))
    return t0, t1


def _paper_profile(p, *, closed, n_br, thickness_px, px_per_mm, smooth_px, trims, window_px,
                   circle_correction, ends, max_window_frac):
    """Profile by the paper's parabolic window (module docstring)."""
    n = len(p)
    sm = polyline.smooth(p, window_px=smooth_px, closed=closed)
    d = np.diff(np.vstack([sm, sm[:1]]) if closed else sm, axis=0)
    seg = np.hypot(d[:, 0], d[:, 1])
    total_px = float(seg.sum())
    s_px = np.concatenate([[0.0], np.cumsum(seg[:n - 1])]) if n > 1 else np.zeros(1)
    if window_px is None:
        window_px = 5.0 * max(1, int(n_br)) * float(thickness_px)
    half_w = 0.5 * float(window_px)
    x = sm[:, 1]
    y = -sm[:, 0]
    if n < 3:
        kappa_px = np.zeros(n)
    elif closed:
        # unroll the loop once on each side; a window never exceeds the loop
        half_w = min(half_w, 0.5 * total_px)
        s_ext = np.concatenate([s_px - total_px, s_px, s_px + total_px])
        kappa_px = _parabola_curvature(np.tile(x, 3), np.tile(y, 3), s_ext, half_w, n, 2 * n,
                                       bool(circle_correction), False)
    else:
        # the skeleton is distorted within about a stack width of a junction or a free end:
        # the fits use the samples beyond the trims, the end samples take the curvature of
        # the nearest fitted one
        floor = max(1, int(n_br)) * float(thickness_px)
        tr = [max(floor, float(t or 0.0)) for t in trims]
        t0, t1 = _trim_indices(s_px, tr)
        if t1 - t0 < 3 or (s_px[t1 - 1] - s_px[t0]) < tr[0] + tr[1]:
            t0, t1 = 0, n
        if max_window_frac is not None and max_window_frac > 0:
            half_w = min(half_w, 0.5 * float(max_window_frac) * (s_px[t1 - 1] - s_px[t0]))
        kin = _parabola_curvature(np.ascontiguousarray(x[t0:t1]), np.ascontiguousarray(y[t0:t1]),
                                  np.ascontiguousarray(s_px[t0:t1]), half_w, 0, t1 - t0,
                                  bool(circle_correction), ends == "shift")
        kappa_px = np.empty(n)
        kappa_px[t0:t1] = kin
        kappa_px[:t0] = kin[0]
        kappa_px[t1:] = kin[-1]
    rc = sm
    fit = (0, -1) if (closed or n < 3) else (t0, t1)
    if closed and n >= 3:
        s_px = np.append(s_px, total_px)
        kappa_px = np.append(kappa_px, kappa_px[0])
        rc = np.vstack([sm, sm[:1]])
    return _make_profile(s_px, kappa_px, rc, px_per_mm, closed, fit)


def stack_curvature(path_rc, *, n_br, thickness_px, px_per_mm, closed=None, smooth_px=None,
                    trim_px=None, window_px=None, circle_correction=True, ends="shift",
                    max_window_frac=0.5, method="missing",
                    noise_var_per_mm2=None) -> CurvatureProfile:
    """Smoothed centreline, arc length and local curvature of one stack.

    Parameters
    ----------
    path_rc : array (P, 2)
        Ordered skeleton pixels (row, col) of the stack, from node u to node v.
    n_br : int
        Number of branches in the stack; sets the fit window ``5 n_br h`` (paper).
    thickness_px : float
        Sheet thickness h in pixels.
    px_per_mm : float
        Scan resolution.
    closed : bool, optional
        Closed loop (periodic smoothing and windows). Default: first and last pixels equal or
        adjacent (:func:`crosssection.core.polyline.is_closed`).
    smooth_px : int, optional
        Sliding-average window, points (default :func:`default_smooth_px`).
    trim_px : float or (float, float), optional
        Fork zone at the path start and end, px of arc: not fitted, takes the nearest fitted
        curvature (module docstring). Never less than ``n_br h`` (the default).
    window_px : float, optional
        Override the fit window (full length, px).
    circle_correction : bool
        Remove the parabola-versus-circle bias (module docstring).
    ends : {"shift", "truncate"}
        Window near an open end: shifted inwards keeping its length, or cut.
    max_window_frac : float or None
        Cap of the window as a fraction of the fitted length (None: 5 n_br h everywhere).
    method : {"missing", "paper"}
        Fork zones: ``"missing"`` (default) continues the curvature trend of the nearest
        fitted window into them and bounds the curvature by ``2 / (n_br h)``; ``"paper"``
        gives them the nearest fitted curvature (module docstring).
    noise_var_per_mm2 : float, optional
        The scan's curvature noise (:func:`noise_variance`): the trend is continued only where
        it exceeds the noise, and the profile records it for the energy. Default: unknown
        (trend always continued, nothing removed).

    Returns
    -------
    CurvatureProfile
    """
    p = np.asarray(path_rc, dtype=np.float64).reshape(-1, 2)
    if closed is None:
        closed = polyline.is_closed(p)
    closed = bool(closed)
    if closed and len(p) > 1 and np.all(p[0] == p[-1]):
        p = p[:-1]  # the repeated closing pixel would count twice
    if len(p) == 0:
        z = np.zeros(0)
        return CurvatureProfile(z, z, 0.0, np.nan, np.nan, np.nan, closed, np.zeros((0, 2)))
    if smooth_px is None:
        smooth_px = default_smooth_px(thickness_px)
    if method not in ("missing", "paper"):
        raise ParameterError(f"curvature method must be 'missing' or 'paper', got {method!r}")
    trims = tuple(trim_px) if np.ndim(trim_px) else (trim_px, trim_px)
    prof = _paper_profile(p, closed=closed, n_br=n_br, thickness_px=thickness_px,
                          px_per_mm=px_per_mm, smooth_px=int(smooth_px), trims=trims,
                          window_px=window_px, circle_correction=circle_correction, ends=ends,
                          max_window_frac=max_window_frac)
    if method == "paper":
        return prof
    # only junction ends are fork zones; a free end keeps the nearest fitted curvature
    forks = tuple(bool(t) and float(t) > 0 for t in trims)
    return _fill_fork_zones(prof, n_br, thickness_px, px_per_mm, forks,
                            noise_var_per_mm2=noise_var_per_mm2)


#: How far from a junction (in sheet thicknesses) two stacks' skeletons are compared for
#: contact: a tangential peel of radius R stays within 1 px over sqrt(2 R) px, 30 h at R = 90 h.
_CONTACT_REACH_H = 30.0
#: Largest gap (px) between two bands still counted as contact: a thinner gap is not resolved
#: by the threshold at the paper's 50 px/mm and 1-px blur.
_CONTACT_GAP_PX = 1.0
_CHUNK = 16


def _fork_zone_px(width_px, r_j, touching_px, smooth_px):
    """Fork zone (module docstring, step 3): the overlap, the hook, the contact, the smoothing."""
    return max(2.0 * max(width_px, r_j), touching_px) + 0.5 * (smooth_px - 1)


def _prefix(path_rc, end, reach):
    """The first ``reach`` pixels of a path from its start (end 0) or its end (end 1)."""
    p = np.asarray(path_rc, dtype=np.float64).reshape(-1, 2)
    return (p if end == 0 else p[::-1])[:reach]


def _median_radii(paths, distance_px) -> np.ndarray:
    """Median inscribed ink radius along every skeleton path, px (half each band's width),
    from one gather and one sort (one ``np.median`` per path took 30 ms for the 244 stacks of
    a 2000x2000 scan)."""
    n = np.array([len(p) for p in paths], np.int64)
    out = np.zeros(len(paths))
    if not n.sum():
        return out
    rc = np.round(np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in paths if len(p)]))
    rc = np.clip(rc.astype(np.int64), 0, np.array(distance_px.shape) - 1)
    vals = distance_px[rc[:, 0], rc[:, 1]].astype(np.float64)
    gid = np.repeat(np.arange(len(paths)), n)
    order = np.lexsort((vals, gid))
    v = vals[order]
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    ok = n > 0
    lo = start[ok] + (n[ok] - 1) // 2
    hi = start[ok] + n[ok] // 2
    out[ok] = 0.5 * (v[lo] + v[hi])
    return out


def contact_arc_px(prefix_rc, radius_px, others, *, gap_px: float = _CONTACT_GAP_PX) -> float:
    """Arc length from a junction along which a stack's band still touches another band there.

    Two layers that peel apart tangentially stay in contact, their bands merged in the image,
    for a while after the junction (``sqrt(2 R gap)`` for a relative bending radius R): along
    that stretch the skeleton is the merged band's, not the stack's own centreline (module
    docstring, step 3).

    Parameters
    ----------
    prefix_rc : (P, 2) array
        The stack's skeleton from the junction outwards, px.
    radius_px : float
        The stack's half-width, px (median inscribed radius along its skeleton).
    others : sequence of ((Q, 2) array, float)
        The other stacks at that junction: their skeleton from the junction and half-width.
    gap_px : float
        Largest gap between the bands still counted as contact.

    Returns
    -------
    float
        Arc length, px, from the junction to the first skeleton pixel farther than
        ``radius + radius_other + gap_px`` from every other stack's skeleton there.
    """
    pre = np.asarray(prefix_rc, float).reshape(-1, 2)
    others = [(np.asarray(q, float).reshape(-1, 2), float(r)) for q, r in others]
    others = [(q, r) for q, r in others if len(q)]
    if len(pre) < 2 or not others:
        return 0.0
    pts = np.concatenate([q for q, _ in others])
    limit = np.concatenate([np.full(len(q), radius_px + r + gap_px) for q, r in others])
    return _contact_arc(pre, pts, limit)


def _contact_arc(pre, pts, limit):
    """:func:`contact_arc_px` on the other bands' skeleton points ``pts`` (K, 2) and the
    distance ``limit`` (K,) below which each one touches."""
    # in chunks from the junction: bands that part at an angle are apart within a few pixels,
    # so the whole prefix is rarely needed
    first_far = len(pre)
    for i in range(0, len(pre), _CHUNK):
        chunk = pre[i:i + _CHUNK]
        near = (cdist(chunk, pts) <= limit).any(axis=1)
        if not near.all():
            first_far = i + int(np.argmin(near))
            break
    if first_far < 1:
        return 0.0
    seg = np.diff(pre[:min(first_far, len(pre) - 1) + 1], axis=0)
    return float(np.hypot(seg[:, 0], seg[:, 1]).sum())


def stack_profiles(graph, n_br, distance_px, *, thickness_px: float, px_per_mm: float,
                   smooth_px: int | None = None, method: str = "missing") -> list:
    """Curvature profile of every stack of a stack graph (paper: parabolic fits over 5 n_br h).

    Parameters
    ----------
    graph : StackGraph
        Stacks with their pixel paths and end nodes.
    n_br : (M,) int array
        Branches per stack (linear system).
    distance_px : ndarray
        Distance transform of the cleaned ink mask (inscribed ink radius at every pixel).
    thickness_px : float
        Sheet thickness h in pixels.
    px_per_mm : float
        Scan resolution.
    smooth_px : int, optional
        Sliding-average window of the centreline (default :func:`default_smooth_px`).
    method : {"missing", "paper"}
        Fork zones (module docstring, step 3); ``"missing"`` also measures the scan's
        curvature noise (step 4) and records it in every profile.

    Returns
    -------
    list of CurvatureProfile
        One per stack, in stack order.
    """
    if method not in ("missing", "paper"):
        raise ParameterError(f"curvature method must be 'missing' or 'paper', got {method!r}")
    H, W = distance_px.shape
    sm = default_smooth_px(thickness_px) if smooth_px is None else int(smooth_px)
    at_node = {}  # junction -> [(stack, end)]
    for sid in range(graph.n_stacks):
        for end, node in enumerate(graph.ends[sid]):
            if graph.node_kind[node] == "junction":
                at_node.setdefault(node, []).append((sid, end))
    reach = int(np.ceil(_CONTACT_REACH_H * float(thickness_px)))
    radius = _median_radii(graph.paths, distance_px)
    # per band end at a junction: its skeleton from the junction, and the skeleton points of
    # the other bands there with the distance below which each touches it
    contact = {}
    for node, keys in at_node.items():
        pre = [_prefix(graph.paths[sid], end, reach) for sid, end in keys]
        for i, (sid, end) in enumerate(keys):
            others = [(pre[j], radius[keys[j][0]]) for j in range(len(keys)) if j != i]
            contact[(sid, end)] = contact_arc_px(pre[i], radius[sid], others)

    def fork_zone(sid, end, nb):
        # module docstring, step 3
        node = graph.ends[sid][end]
        if graph.node_kind[node] != "junction":
            return 0.0
        r, c = np.round(graph.node_rc[node]).astype(int)
        r_j = float(distance_px[min(max(r, 0), H - 1), min(max(c, 0), W - 1)])
        touching = contact[(sid, end)]
        return _fork_zone_px(nb * float(thickness_px), r_j, touching, sm)

    profiles, forks = [], []
    for sid in range(graph.n_stacks):
        u, v = graph.ends[sid]
        nb = max(1, int(n_br[sid]))
        trims = (fork_zone(sid, 0, nb), fork_zone(sid, 1, nb))
        forks.append(tuple(t > 0 for t in trims))
        profiles.append(stack_curvature(
            graph.paths[sid], n_br=nb, thickness_px=thickness_px,
            px_per_mm=px_per_mm, smooth_px=sm, closed=(graph.node_kind[u] == "loop"),
            trim_px=trims, method="paper"))
    if method == "paper":
        return profiles
    var = noise_variance(profiles, n_br, thickness_px=thickness_px, px_per_mm=px_per_mm,
                         smooth_px=sm)
    return [_fill_fork_zones(prof, max(1, int(n_br[sid])), thickness_px, px_per_mm, forks[sid],
                             noise_var_per_mm2=var[max(1, int(n_br[sid]))])
            for sid, prof in enumerate(profiles)]


def _trend(s, k):
    """Least-squares line k = b + a (s - s_mean): (a, b, s_mean)."""
    sm = s.mean()
    ds = s - sm
    den = float(ds @ ds)
    a = float(ds @ (k - k.mean())) / den if den > 0 else 0.0
    return a, float(k.mean()), sm


def _fill_fork_zones(prof, n_br, thickness_px, px_per_mm, forks=(True, True), noise_px=0.3,
                     noise_var_per_mm2=None):
    """Fork zones as missing data, and the physical bound on curvature.

    Within a fork zone the image holds no centreline of this stack (module docstring), so its
    curvature is not measured there: the linear trend of the curvature over the first (last)
    fitted window of ``5 n_br h`` is continued to the junction. With the scan's curvature noise
    ``v`` known, the trend is continued only where the data show one: the noise is correlated
    over about a window, so a window holds about one independent sample and its slope has a
    noise variance of about ``12 v / w^2``; a slope within twice that deviation is noise, and
    the zone keeps the nearest fitted curvature (extrapolating a noise slope multiplied the
    noise there by about five on jittered arcs). The curvature is bounded
    everywhere by ``2 / (n_br h)``: the innermost layer of a stack of ``n_br`` layers cannot
    have a negative radius, so anything tighter is a skeleton kink, not a bend.

    The relative uncertainty of ``int kappa^2 ds`` adds the extrapolated part (not measured:
    counted in full) and the noise floor of the parabolic fit, ``720 sigma^2 / w^5`` per unit
    length for ``noise_px`` of centreline noise and a window of ``w`` px.
    """
    n = len(prof.s_mm)
    t0, t1 = prof.fit_start, prof.fit_stop
    nb = max(1, int(n_br))
    w_px = 5.0 * nb * float(thickness_px)
    s = prof.s_mm
    kmax = 2.0 * px_per_mm / (nb * float(thickness_px))
    k = np.clip(prof.kappa_per_mm, -kmax, kmax)
    w = w_px / px_per_mm
    if not prof.closed and n >= 3 and (t0 > 0 or t1 < n):
        lo_end = int(np.searchsorted(s, s[t0] + w))
        hi_start = int(np.searchsorted(s, s[t1 - 1] - w))
        for lo, hi, z0, z1 in ((t0, min(max(lo_end, t0 + 3), t1), 0, t0),
                               (max(min(hi_start, t1 - 3), t0), t1, t1, n)):
            if z0 == z1 or hi - lo < 3 or not forks[0 if z0 == 0 else 1]:
                continue
            a, b, sm = _trend(s[lo:hi], k[lo:hi])
            if noise_var_per_mm2 is not None and a * a * w * w <= 4.0 * 12.0 * noise_var_per_mm2:
                continue
            k[z0:z1] = np.clip(b + a * (s[z0:z1] - sm), -kmax, kmax)
    out = _make_profile(s * px_per_mm, k / px_per_mm, prof.rc_px, px_per_mm, prof.closed,
                        (t0, t1))
    if noise_var_per_mm2 is not None:
        out = replace(out, noise_var_per_mm2=float(noise_var_per_mm2))
        noise = float(noise_var_per_mm2) * out.length_mm
    else:
        noise = 720.0 * noise_px ** 2 / w_px ** 5 * px_per_mm ** 2 * out.length_mm
    return replace(out, energy_rel_uncertainty=_rel_uncertainty(out, forks, noise))


def _rel_uncertainty(prof, forks, noise_int):
    """(extrapolated part of int kappa^2 ds + the noise floor ``noise_int``) / the integral."""
    k, s, n = prof.kappa_per_mm, prof.s_mm, len(prof.s_mm)
    if n < 2:
        return float("nan")
    f = k * k
    total = float(np.trapezoid(f, s))
    z0 = prof.fit_start if forks[0] else 0
    z1 = prof.fit_stop if forks[1] else n
    fitted = float(np.trapezoid(f[z0:z1], s[z0:z1])) if z1 - z0 > 1 else 0.0
    return float((max(total - fitted, 0.0) + noise_int) / max(total, noise_int, 1e-300))


def _lag_variance(prof, lag_mm):
    """Half the mean squared curvature difference at ``lag_mm`` over the fitted samples, and
    the number of pairs (None when the fitted part is shorter than two lags)."""
    s = prof.s_mm[prof.fit_start:prof.fit_stop]
    k = prof.kappa_per_mm[prof.fit_start:prof.fit_stop]
    if len(s) < 3 or s[-1] - s[0] < 2.0 * lag_mm:
        return None
    j = np.searchsorted(s, s + lag_mm)
    ok = j < len(s)
    d = k[j[ok]] - k[ok]
    return float(d @ d) / (2.0 * d.size), int(d.size)


def noise_variance(profiles, n_br, *, thickness_px: float, px_per_mm: float,
                   smooth_px: int | None = None, min_pairs: int = 200) -> dict:
    """Variance of the curvature noise of the window fit, per window (per n_br), 1/mm^2.

    Noise beyond its correlation length ``d`` (the fit window ``5 n_br h`` plus the smoothing
    window) is independent, so half the mean squared difference of the curvature at lag ``d``
    is ``D(d) = v + a d^2`` for a curvature that varies smoothly over ``2 d``; two lags give
    ``v = (4 D(d) - D(2 d)) / 3`` (Richardson). Pooled over the scan's stacks of each n_br:
    the noise comes from the scan (resolution, blur, edge noise), not from one stack. Windows
    with fewer than ``min_pairs`` pairs take the nearest measured one scaled as ``w^-5`` (the
    variance of a parabola's curvature fitted over ``w`` px of independent samples).

    Parameters
    ----------
    profiles : sequence of CurvatureProfile
    n_br : (M,) int array
    thickness_px, px_per_mm : float
    smooth_px : int, optional
        Sliding-average window (default :func:`default_smooth_px`).
    min_pairs : int
        Pairs needed for a window's own estimate.

    Returns
    -------
    dict
        n_br -> v (1/mm^2, >= 0); every n_br of ``n_br`` present (0 when no window could be
        measured).
    """
    sm = default_smooth_px(thickness_px) if smooth_px is None else int(smooth_px)
    nbs = sorted({max(1, int(x)) for x in n_br})
    window = {nb: 5.0 * nb * float(thickness_px) for nb in nbs}
    measured = {}
    for nb in nbs:
        lag = (window[nb] + sm) / float(px_per_mm)
        d1 = d2 = 0.0
        pairs = 0
        for prof, n in zip(profiles, n_br):
            if max(1, int(n)) != nb or prof.closed:
                continue
            a, b = _lag_variance(prof, lag), _lag_variance(prof, 2.0 * lag)
            if a is None or b is None:
                continue
            d1 += a[0] * a[1]
            d2 += b[0] * a[1]
            pairs += a[1]
        if pairs >= min_pairs:
            measured[nb] = max((4.0 * d1 - d2) / (3.0 * pairs), 0.0)
    out = {}
    for nb in nbs:
        if nb in measured:
            out[nb] = measured[nb]
        elif measured:
            ref = min(measured, key=lambda m: abs(m - nb))
            out[nb] = measured[ref] * (window[ref] / window[nb]) ** 5
        else:
            out[nb] = 0.0
    return out
