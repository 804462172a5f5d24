"""Stage 10: centreline of a stack, its local curvature and bending (paper, "Image analysis
procedure" and "Curvature of branches").

Two estimators, one profile per stack (:class:`CurvatureProfile`, arc length ``s_mm`` and
curvature ``kappa_per_mm`` samples whose trapezoid integral of kappa^2 is the stack's bending).

``method="gcv"`` (default): fewest-parameter fit chosen by the data, and the fork model
-----------------------------------------------------------------------------------------
1. **Observed centreline.** The skeleton path, smoothed (:func:`crosssection.core.polyline.smooth`,
   about one sheet thickness h), minus its fork zones (below), resampled every h/2 of arc.
2. **Fit with the fewest parameters the scan supports.** x(s) and y(s) are fitted by least
   squares with Legendre polynomials (a Fourier series on closed loops) of every degree up to
   ``2 + l / h`` (at most 40); the degree is the minimum of the generalised cross-validation
   score ``n RSS / (n - p)^2``. The nested fits share one QR factorisation, so all degrees cost
   one fit (about 0.15 ms per stack). A smoothing spline whose smoothing GCV chooses
   (``scipy.interpolate.make_smoothing_spline``) gives the same kind of estimate but costs
   170 ms for 30 points (240 stacks: a minute per scan), hence this fit.
3. **Noise debiasing and uncertainty.** Noise makes the fitted kappa^2 too large on average by
   ``var kappa``: the linear fit's posterior variance, ``sigma^2 |B''(s) R^-1|^2`` (sigma from
   the residuals), is subtracted from the integral of kappa^2 (the profile's curvature is
   scaled accordingly, never below 0). ``energy_rel_uncertainty`` is the delta-method standard
   deviation of the integral, ``2 sigma |(w kappa)^T B'' R^-1|``, relative to it.
4. **Fork zones: where a branch's band is still merged with its neighbours'.** Within the
   inscribed ink radius r_J of a junction the bands of the stacks meeting there overlap: the
   image holds no centreline of this stack, and its skeleton hooks into the medial-axis fork
   point. Yet the sheet bends there: on generated networks 26-45 % of the true bending energy
   of interior stacks lies within half the widest band of a junction. The estimator does not
   fit the skeleton there; it models the sheet: an elastic rod leaving the observed centreline
   at its exit point with the fitted tangent (continuity of the sheet) and reaching the
   junction point, where the sheet is free to rotate (the layers of a pack only touch: no
   bending moment is transmitted, the natural boundary condition kappa = 0). The rod of least
   bending energy under these conditions, in the small-slope (linear elastica) limit, is the
   cubic ``y(x) = d (3 x^2 / l^2 - x^3 / l^3) / 2`` with l the distance along the exit tangent
   and d the lateral offset of the junction: curvature ``3 d (1 - x / l) / l^2``, bending
   ``3 d^2 / l^3``. The slope d / l is clipped at 1 (beyond it, the junction point is not
   where this sheet goes).
5. **Sign.** Positive when the path, followed from its start to its end, turns
   counter-clockwise in the image as displayed (x = column to the right, y = -row).

``method="paper"``: the paper's parabolic window
-----------------------------------------------
"The central position of stacks is deduced from the skeleton and smoothed out by
slide-averages along the stack trajectory. The local curvature is measured through a parabolic
fit on size 5 n_br h, after coordinates translation and rotation in the tangent frame." At every
centreline point the neighbours within +- w/2 of arc length, ``w = 5 n_br h`` (capped at half
the fitted length: a longer parabola cannot resolve an S-shaped stack), are rotated into the
local tangent frame and ``y = a x^2 + b x + c`` is fitted, ``kappa = 2 a / (1 + b^2)^1.5``;
the known x^4 leak of a circle into ``a`` is removed (``circle_correction``). Samples within
the fork zone (``max(n_br h, r_J)``) of an end are not fitted and take the curvature of the
nearest fitted sample. This window cannot follow curvature concentrated within a few h of a
junction, and a kinked skeleton at a merged junction inflates it.

Per stack: kappa_pm = (1/l) int kappa ds, kappa_plus = (1/l) int |kappa| ds,
kappa_m = |kappa_pm| (paper, section "Curvature of branches"), in 1/mm, trapezoid rule.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit
from numpy.polynomial import legendre
from scipy.linalg import solve_triangular

from crosssection.core import polyline
from crosssection.core.errors import ParameterError

__all__ = ["CurvatureProfile", "stack_curvature", "stack_profiles", "default_smooth_px",
           "METHODS"]

METHODS = ("gcv", "paper")


@dataclass(frozen=True)
class CurvatureProfile:
    """Local curvature along one stack's centreline.

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
    energy_rel_uncertainty : float
        Relative standard deviation of the stack's integral of kappa^2 from the scan's noise
        (``method="gcv"``; NaN for ``"paper"`` or when there is no bending).
    fork_fraction : float
        Fraction of the integral of kappa^2 in the modelled fork zones (0 for ``"paper"``).
    method : str
    """

    s_mm: np.ndarray
    kappa_per_mm: np.ndarray
    length_mm: float
    kappa_pm: float
    kappa_plus: float
    kappa_m: float
    closed: bool = False
    rc_px: np.ndarray | None = None
    energy_rel_uncertainty: float = float("nan")
    fork_fraction: float = 0.0
    method: str = "gcv"


def default_smooth_px(thickness_px: float) -> int:
    """Default sliding-average window: about two sheet thicknesses (11 points for h = 5 px).

    Measured on skeletons of drawn arcs (h = 5 px): the standard deviation of the local
    curvature (paper window 5 h) falls from 0.62/R (5 points) to 0.43/R (11 points) at
    R = 400 px, while the radius shrink stays 0.3 % at R = 40 px.
    """
    k = max(1, int(round(float(thickness_px))))
    return 2 * k + 1


def _make_profile(s_px, kappa_px, rc, px_per_mm, closed, method, rel_unc=np.nan,
                  fork_fraction=0.0) -> CurvatureProfile:
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
                            rc_px=np.asarray(rc, float), energy_rel_uncertainty=float(rel_unc),
                            fork_fraction=float(fork_fraction), method=method)


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


@lru_cache(maxsize=64)
def _legendre_derivative_maps(p: int):
    """(p, p) maps of Legendre coefficients to those of the first and second derivatives."""
    eye = np.eye(p)
    d1 = np.zeros((p, p))
    d2 = np.zeros((p, p))
    for j in range(p):
        a = legendre.legder(eye[j], 1)
        b = legendre.legder(eye[j], 2)
        d1[:len(a), j] = a
        d2[:len(b), j] = b
    d1.setflags(write=False)
    d2.setflags(write=False)
    return d1, d2


def _bases(s, closed, p_max, period):
    """Design matrix and its first two arc-length derivatives; candidate model sizes."""
    if closed:
        k_max = max(1, (p_max - 1) // 2)
        w = 2.0 * np.pi * np.arange(1, k_max + 1) / period
        ph = np.outer(s, w)
        c, sn = np.cos(ph), np.sin(ph)
        one = np.ones((len(s), 1))
        zero = np.zeros((len(s), 1))
        # interleave cos/sin so that the first 1 + 2k columns are harmonics <= k
        B = np.hstack([one, np.stack([c, sn], 2).reshape(len(s), -1)])
        B1 = np.hstack([zero, np.stack([-sn * w, c * w], 2).reshape(len(s), -1)])
        B2 = np.hstack([zero, np.stack([-c * w * w, -sn * w * w], 2).reshape(len(s), -1)])
        return B, B1, B2, np.arange(1, B.shape[1] + 1, 2)
    s0, s1 = s[0], s[-1]
    g = 2.0 / (s1 - s0)
    u = (s - s0) * g - 1.0
    B = legendre.legvander(u, p_max - 1)
    d1, d2 = _legendre_derivative_maps(p_max)
    return B, (B @ d1) * g, (B @ d2) * (g * g), np.arange(2, p_max + 1)


def _gcv_fit(s, xy, *, closed, p_max, period=None):
    """Least-squares fit of (x, y)(s) with the model size chosen by GCV (module docstring).

    Returns fitted positions, first and second derivatives, curvature, its variance,
    the (n, p) map M = B'' R^-1 and the noise variance per coordinate.
    """
    n = len(s)
    p_max = int(min(p_max, n - 2))
    B, B1, B2, orders = _bases(s, closed, max(p_max, 2), period)
    orders = orders[orders <= min(B.shape[1], n - 2)]
    mu = xy.mean(axis=0)
    z = xy - mu
    Q, R = np.linalg.qr(B)
    c = Q.T @ z
    tss = float((z * z).sum())
    cum = np.cumsum((c * c).sum(axis=1))
    rss = np.maximum(tss - cum[orders - 1], 0.0)
    gcv = n * rss / (n - orders) ** 2.0
    p = int(orders[int(np.argmin(gcv))])
    rinv = solve_triangular(R[:p, :p], np.eye(p))
    coef = rinv @ c[:p]
    sigma2 = float(rss[orders == p][0]) / (2.0 * (n - p))
    r0 = B[:, :p] @ coef + mu
    r1 = B1[:, :p] @ coef
    r2 = B2[:, :p] @ coef
    sp = np.maximum(np.hypot(r1[:, 0], r1[:, 1]), 1e-12)
    kappa = (r1[:, 0] * r2[:, 1] - r1[:, 1] * r2[:, 0]) / sp ** 3
    M = B2[:, :p] @ rinv
    var_k = sigma2 * (M * M).sum(axis=1) / sp ** 4
    return r0, r1, kappa, var_k, M, sigma2, sp


def _fork_zone(exit_xy, out_t, junction_xy, ds_px):
    """Least-bending sheet from the exit point (tangent out_t) to the junction point, free to
    rotate there (module docstring). Returns (points from exit to junction, arc length,
    curvature in the outward direction) or None when the junction is not ahead."""
    v = junction_xy - exit_xy
    nrm = np.array([-out_t[1], out_t[0]])
    ell = float(v @ out_t)
    if ell < 1.0:
        return None
    d = float(np.clip(v @ nrm, -ell, ell))
    m = max(4, int(np.ceil(ell / ds_px)) + 1)
    x = np.linspace(0.0, ell, m)
    y = 0.5 * d * (3.0 * x ** 2 / ell ** 2 - x ** 3 / ell ** 3)
    slope = 1.5 * d * (2.0 * x / ell ** 2 - x ** 2 / ell ** 3)
    kap = 3.0 * d * (1.0 - x / ell) / ell ** 2 / (1.0 + slope ** 2) ** 1.5
    pts = exit_xy + np.outer(x, out_t) + np.outer(y, nrm)
    seg = np.hypot(*np.diff(pts, axis=0).T)
    return pts, np.concatenate([[0.0], np.cumsum(seg)]), kap


def _trim_indices(s, trims):
    total = s[-1]
    t0 = int(np.searchsorted(s, trims[0], side="left"))
    t1 = int(np.searchsorted(s, total - trims[1], side="right"))
    return t0, t1


def _gcv_profile(p, *, closed, thickness_px, px_per_mm, smooth_px, trims, forks,
                 sample_px, max_params):
    """Profile of one stack by the GCV fit and the fork model (module docstring)."""
    sm = polyline.smooth(p, window_px=smooth_px, closed=closed)
    xy_all = np.column_stack([sm[:, 1], -sm[:, 0]])
    if closed:
        xy_all = np.vstack([xy_all, xy_all[:1]])
    seg = np.hypot(*np.diff(xy_all, axis=0).T)
    s_all = np.concatenate([[0.0], np.cumsum(seg)])
    total = float(s_all[-1])
    h = float(thickness_px)
    trims = (0.0, 0.0) if closed else tuple(float(t or 0.0) for t in trims)
    if not closed and total - trims[0] - trims[1] < max(2.0 * h, 4.0 * sample_px):
        trims, forks = (0.0, 0.0), (None, None)  # too short to leave anything: fit it all
    t0, t1 = (0, len(s_all)) if closed else _trim_indices(s_all, trims)
    s_obs0, s_obs1 = s_all[t0], s_all[t1 - 1]
    n = int(max(5, np.ceil((s_obs1 - s_obs0) / sample_px) + 1))
    if closed:
        s = np.linspace(0.0, total, n, endpoint=False)
    else:
        s = np.linspace(s_obs0, s_obs1, n)
    xy = np.column_stack([np.interp(s, s_all, xy_all[:, 0]), np.interp(s, s_all, xy_all[:, 1])])
    if s[-1] - s[0] <= 0 or n < 5:
        return None
    p_max = int(min(max_params, 2 + (s[-1] - s[0]) / h))
    r0, r1, kappa, var_k, M, sigma2, sp = _gcv_fit(s, xy, closed=closed, p_max=p_max,
                                                   period=total)
    if closed:
        s = np.append(s, total)
        r0 = np.vstack([r0, r0[:1]])
        kappa, var_k, sp = (np.append(a, a[0]) for a in (kappa, var_k, sp))
        M = np.vstack([M, M[:1]])
        r1 = np.vstack([r1, r1[:1]])
    w = np.zeros(len(s))
    dsv = np.diff(s)
    w[:-1] += 0.5 * dsv
    w[1:] += 0.5 * dsv
    raw = float((w * kappa * kappa).sum())
    debiased = max(raw - float((w * var_k).sum()), 0.0)
    scale = np.sqrt(debiased / raw) if raw > 0 else 0.0
    kappa = kappa * scale
    tang = r1 / sp[:, None]
    g = (2.0 * w * kappa / sp ** 2)[:, None] * np.column_stack([-tang[:, 1], tang[:, 0]])
    sd = np.sqrt(sigma2 * float(((M.T @ g) ** 2).sum()))
    rel = sd / debiased if debiased > 0 else np.nan
    parts_s, parts_k, parts_xy = [s - s[0]], [kappa], [r0]
    fork_int = 0.0
    for end in (0, 1):
        if closed or forks[end] is None:
            continue
        j_xy = np.array([forks[end][1], -forks[end][0]], float)
        i = 0 if end == 0 else -1
        out_t = -tang[0] if end == 0 else tang[-1]
        zone = _fork_zone(r0[i], out_t, j_xy, sample_px)
        if zone is None:
            continue
        pts, zs, zk = zone
        fork_int += float(np.trapezoid(zk * zk, zs))
        if end == 0:
            # the path runs from the junction inwards: reversed direction, opposite sign
            parts_s.insert(0, (-zs[::-1])[:-1])
            parts_k.insert(0, -zk[::-1][:-1])
            parts_xy.insert(0, pts[::-1][:-1])
        else:
            parts_s.append(parts_s[-1][-1] + zs[1:])
            parts_k.append(zk[1:])
            parts_xy.append(pts[1:])
    s_cat = np.concatenate(parts_s)
    s_cat -= s_cat[0]
    xy_cat = np.vstack(parts_xy)
    k_cat = np.concatenate(parts_k)
    frac = fork_int / (fork_int + debiased) if fork_int + debiased > 0 else 0.0
    rc = np.column_stack([-xy_cat[:, 1], xy_cat[:, 0]])
    return _make_profile(s_cat, k_cat, rc, px_per_mm, closed, "gcv", rel, frac)


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
    if closed and n >= 3:
        s_px = np.append(s_px, total_px)
        kappa_px = np.append(kappa_px, kappa_px[0])
        rc = np.vstack([sm, sm[:1]])
    return _make_profile(s_px, kappa_px, rc, px_per_mm, closed, "paper")


def stack_curvature(path_rc, *, n_br, thickness_px, px_per_mm, method: str = "gcv",
                    closed=None, smooth_px=None, trim_px=None, fork_rc=None, window_px=None,
                    circle_correction=True, ends="shift", max_window_frac=0.5,
                    sample_px=None, max_params: int = 40) -> CurvatureProfile:
    """Centreline, arc length and local curvature of one stack.

    Parameters
    ----------
    path_rc : array (P, 2)
        Ordered skeleton pixels (row, col) of the stack, from node u to node v.
    n_br : int
        Number of branches in the stack (sets the paper's window ``5 n_br h``).
    thickness_px : float
        Sheet thickness h in pixels.
    px_per_mm : float
        Scan resolution.
    method : {"gcv", "paper"}
        Estimator (module docstring).
    closed : bool, optional
        Closed loop (periodic). Default: first and last pixels equal or adjacent.
    smooth_px : int, optional
        Sliding-average window of the centreline, points (default :func:`default_smooth_px`).
    trim_px : float or (float, float), optional
        Fork zone at the path start and end, px of arc: not fitted. Default 0 for ``"gcv"``,
        ``n_br h`` for ``"paper"`` (which never uses less).
    fork_rc : ((row, col) or None, (row, col) or None), optional
        Junction point at the path start and end; where given, ``"gcv"`` models the trimmed
        zone as the least-bending sheet reaching it (module docstring).
    window_px, circle_correction, ends, max_window_frac
        Paper method: window override (full length, px), removal of the parabola-circle bias,
        window near an open end (``"shift"`` keeps its length, ``"truncate"`` cuts it), cap
        of the window as a fraction of the fitted length (None: no cap).
    sample_px : float, optional
        ``"gcv"`` resampling step along the centreline (default h / 2, at least 1 px).
    max_params : int
        ``"gcv"`` largest model size.

    Returns
    -------
    CurvatureProfile
    """
    if method not in METHODS:
        raise ParameterError(f"curvature method must be one of {METHODS}, got {method!r}")
    p = np.asarray(path_rc, dtype=np.float64).reshape(-1, 2)
    if closed is None:
        closed = polyline.is_closed(p)
    closed = bool(closed)
    if closed and len(p) > 1 and np.all(p[0] == p[-1]):
        p = p[:-1]  # the repeated closing pixel would count twice
    if len(p) == 0:
        z = np.zeros(0)
        return CurvatureProfile(z, z, 0.0, np.nan, np.nan, np.nan, closed, np.zeros((0, 2)),
                                method=method)
    if smooth_px is None:
        smooth_px = default_smooth_px(thickness_px)
    trims = tuple(trim_px) if np.ndim(trim_px) else (trim_px, trim_px)
    forks = tuple(fork_rc) if fork_rc is not None else (None, None)
    if method == "gcv" and len(p) >= 5:
        step = float(sample_px) if sample_px else max(1.0, 0.5 * float(thickness_px))
        prof = _gcv_profile(p, closed=closed, thickness_px=thickness_px, px_per_mm=px_per_mm,
                            smooth_px=int(smooth_px), trims=trims, forks=forks, sample_px=step,
                            max_params=int(max_params))
        if prof is not None:
            return prof
    return _paper_profile(p, closed=closed, n_br=n_br, thickness_px=thickness_px,
                          px_per_mm=px_per_mm, smooth_px=int(smooth_px), trims=trims,
                          window_px=window_px, circle_correction=circle_correction, ends=ends,
                          max_window_frac=max_window_frac)


def stack_profiles(graph, n_br, distance_px, *, thickness_px: float, px_per_mm: float,
                   smooth_px: int | None = None, method: str = "gcv") -> list:
    """Curvature profile of every stack of a stack graph.

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
    method : {"gcv", "paper"}
        Estimator (module docstring).

    Returns
    -------
    list of CurvatureProfile
        One per stack, in stack order.
    """
    H, W = distance_px.shape

    def fork(node):
        # the fork zone of a junction: its inscribed ink radius, where the bands overlap
        if graph.node_kind[node] != "junction":
            return 0.0, None
        rc = np.asarray(graph.node_rc[node], float)
        r, c = np.round(rc).astype(int)
        return float(distance_px[min(max(r, 0), H - 1), min(max(c, 0), W - 1)]), rc

    profiles = []
    for sid in range(graph.n_stacks):
        u, v = graph.ends[sid]
        (ru, pu), (rv, pv) = fork(u), fork(v)
        profiles.append(stack_curvature(
            graph.paths[sid], n_br=int(n_br[sid]), thickness_px=thickness_px,
            px_per_mm=px_per_mm, smooth_px=smooth_px, method=method,
            closed=(graph.node_kind[u] == "loop"), trim_px=(ru, rv), fork_rc=(pu, pv)))
    return profiles
