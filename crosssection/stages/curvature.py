"""Stage 10: centreline of a stack and its local curvature (paper, "Image analysis procedure"
and "Curvature of branches").

The paper: "The central position of stacks is deduced from the skeleton and smoothed out by
slide-averages along the stack trajectory. The local curvature is measured through a parabolic
fit on size 5 n_br h, after coordinates translation and rotation in the tangent frame."

1. **Centreline.** The skeleton path smoothed by :func:`crosssection.core.polyline.smooth`
   (``smooth_px`` points, about two sheet thicknesses h; its end rule is documented there).
   Before the smoothing (methods ``"walls"`` and ``"missing"``), each skeleton pixel is moved
   along the centreline's normal to the midpoint of the band's two walls, where both walls
   are the band's own (:func:`_midlines`). The thinning's pixel staircases depend on the
   scan's orientation and the walls do not. A wall is found on the mask's distance transform,
   then placed where the threshold's feature crosses its cut along the same normal, to a
   fraction of a pixel that the mask rounds away (:func:`_refine_wall`). On drawn arc bands
   (widths 3-11 px) the smoothed centreline's radial scatter is 0.17-0.19 px on the
   skeleton, 0.11-0.13 px between the mask's walls and 0.05-0.08 px between the feature's;
   at 25 px/mm the total energy of one scan read in the eight orientations of the square
   spreads by 10 % instead of 23 % on the skeleton, and a JPEG copy at quality 95 moves a
   typical scan's energy by 2.6 % instead of 4.4 % between the mask's walls
   (docs/validation/README.md, "Stability").
2. **Local curvature.** At every centreline point the neighbours within +- w/2 of arc length,
   ``w = 5 n_br h``, are rotated into the local tangent frame and ``y = a x^2 + b x + c`` is
   fitted; ``kappa = 2 a / (1 + b^2)^1.5``. The known leak of a circle's x^4 term into ``a``
   is removed (``circle_correction``: exact to O((kappa w)^2) on arcs). Near an open end the
   window keeps its length and is shifted inwards; the samples it serves hold its fit read at
   its centre (:func:`_flat_shifted`). The window is capped at half the fitted length
   (``max_window_frac``): a longer parabola cannot resolve an S-shaped stack.
3. **Fork zones.** Near a junction the bands of the stacks meeting there overlap: the image
   holds no centreline of this stack, and the skeleton hooks into the medial-axis fork point.
   The maximal disc at the fork (radius r_J, the inscribed ink radius at the junction) touches
   both bands, so the skeleton reaches the band's own centre only about one r_J beyond the
   overlap; layers that peel apart tangentially stay in contact, their bands merged, further
   still (:func:`contact_arc_px`); and the sliding average carries the hook half a smoothing
   window beyond: the fork zone is ``max(2 max(n_br h, r_J), contact) + (smooth_px - 1) / 2``
   of arc from the junction (measured on drawn tangential forks: arms' ``int kappa^2 ds``
   0.9-2.3 x the truth with ``max(n_br h, r_J)``, 0.9-1.2 x with this zone). Those samples
   are not measured on the skeleton. **Sheets cannot cross**: an arm in contact with a band
   lies along that band's outer layer, so its own outer layer is the merged ink's wall on its
   side, and its centreline runs at its half width from that wall. The default
   (``method="walls"``, :func:`_walled_path`) follows that wall from the zone's edge to the
   junction, on each side, while the wall stays at the distance it had at the zone's edge
   (within ``_WALL_TOL`` of the band's inscribed radius) and the direction within
   ``_WALL_MAX_TURN`` of its start; a zone followed on a side is measured there and fitted
   like the rest of the stack (a stack whose zones would cover it is followed from its
   middle). A band narrower than ``2 _WALL_MIN_RADIUS_PX`` is not followed: its wall's pixel
   steps are as large as the distance kept from it. On rods compacted to epsilon 19 and drawn as they lie (every pass a stroke,
   ``simulate.render``, ``pass_smooth=1``), the total energy reads -2 to +9 %, against +18
   to +169 % with the zones as missing data, whose trend continues the skeleton's hooks
   (docs/validation/README.md, "Fork zones along the outer wall"). A wall that turns a corner
   (an arm meeting a band at an angle) or runs into another band holds no layer of this arm:
   the zone stays missing data. Missing data (``method="missing"``, and where no wall is
   followed) continues the linear trend of the curvature over the nearest window (5 n_br h)
   of fits centred on their own sample to the junction, so that a bend that tightens toward
   the fork keeps tightening; the fits within half a window of the zone, whose windows are
   shifted inwards onto one window's mean (flat whatever the bend does), are replaced by the
   trend too
   (:func:`_fill_fork_zones`); the paper's rule
   (``method="paper"``) gives them the curvature of the nearest fitted sample. Over one fork
   zone a stack turns by a quarter turn at most (``int |kappa| ds <= pi / 2``,
   :data:`_ZONE_MAX_TURN`; the zone's curvature is scaled down to it): the zone is a few band
   widths of the branch inside the junction's ink, where it turns from its visible direction
   onto its direction at the fork. The true turn over 1.4 mm (3 mm) from a junction is at
   most 1.0 (1.23) rad on compacted rods at epsilon 19, and the zones filled on the network
   generator's scenes turn by at most 1.48 rad (``benchmarks/zone_turns.py``); a trend
   continued from a skeleton's hook into a wide junction blob of a compacted render turned
   4-8.5 rad, a loop the image would show, and carried up to 42 % of its measured energy.
   Free ends keep the paper's rule (their skeleton is shortened, not merged). Everywhere the curvature is
   bounded by ``2 / (n_br h)``: the innermost layer of a stack cannot have a negative radius,
   so a tighter estimate is a skeleton kink, not a bend. A stack at a junction shorter than
   twice ``max(2 r, r_Ja + r_Jb)`` (r its median inscribed radius, r_J the inscribed radius
   at each junction end, 0 at a free end) has no sample outside its forks' hooks (each one
   r_J beyond an overlap of r_J, and r_J >= r): its skeleton is the link between two fork
   points, and it is not fitted at all; its curvature is the nearest
   fitted one across its junctions, in the stacks its layers run on into
   (:func:`_fill_unfitted_stacks`; the paper's rule fits it whole). A longer stack whose fork
   zones would still cover it (a short link between two forks) is fitted whole; its end fits,
   shifted onto one window's mean, give way at a fork end to the trend of its centred fits
   where the scan's noise is known and the trend exceeds it, as next to a zone (on S-shaped
   links of 50-80 px whose curvature runs from 1/r to -1/r: 0.96-1.02 x the truth against
   0.49-0.78 x; network generator, typical scans -15 % -> -2 %, thick dense -17.5 % -> -3 %,
   docs/validation/README.md).
4. **Noise floor.** The window fit turns the pixel noise of the centreline into a curvature
   noise of variance ``v`` that adds ``v l`` to every stack's ``int kappa^2 ds`` whatever its
   true bending (on a render's long single-pass stacks, curvature about 0.2 /mm, it was a
   third of the measured energy). ``v`` is measured on the scan itself, for each window (each
   n_br), from the curvature differences at lags ``d``, ``2 d`` and ``3 d`` beyond the noise's
   correlation length (``d`` = window + smoothing): ``D(d) = v + b d + a d^2`` for a curvature
   that varies smoothly (``a``) or changes within a lag (``b``), so
   ``v = 3 D(d) - 3 D(2 d) + D(3 d)`` (:func:`noise_variance`). The branch
   energies subtract ``v`` over the quadratic part of the energy density
   (:func:`crosssection.stages.branches.bending_energy`); the profile itself is not changed.

**What these estimators miss** (docs/validation/README.md, "Bending energy"): the share of
the true energy inside fork zones depends on the generator -- 54 % within 2 n_br h of a
junction on ``crosssection.truth.network`` scenes (36 % of the length: its branches leave the
node fanned and bend back), 3-7 % on simulator renders (rod segments of 6-7 h resolve no
bending at that scale). Median total-energy error of the default (seeds 100-107 of
``benchmarks/robust_sweep.py``, 8 scenes per condition): renders +4 % (median absolute
6 %), 25 px/mm -6 % (11 %), network typical -11 %, thick dense -11 %, tangential forks
-47 %; with the zones as missing data (measured with an earlier default) +6.6 % (15 %),
+9 % (16 %), -2 %, -2 %, -46 %: the network generator's centrelines bend inside merged ink,
where no wall shows it. The missing
data's construction applied to the network generator's own curvature (no pixels, no noise) keeps
0.99 of its energy: the continued trends make up for what the window averages away
(``benchmarks/energy_split.py``). Models that add bending inside the zone (a curve
constrained to reach the junction point, a least-bending turn from the parent band's axis)
overshoot every generator (+36 to +280 %): the skeleton's junction point is not on any
layer's path.

``CurvatureProfile.energy_rel_uncertainty``: the share of ``int kappa^2 ds`` not measured on a
free centreline (the fork zones extrapolated, or followed along a merged band's wall; all of it
for a stack fitted whole inside its fork zones) plus the removed noise floor, relative to the
stack's ``int kappa^2 ds``. It ranks the stacks' errors, it does not bound them: a stack whose
share is at most 0.5 is read within a factor 1.5 for 79-100 % of the true energy of such
stacks, one above 0.5 for 0-86 % (four generators; ``benchmarks/stack_energy_errors.py``).

5. **Sign.** Positive when the path, followed from its start to its end, turns
   counter-clockwise in the image as displayed (x = column to the right, y = -row).

Per stack: kappa_pm = (1/l) int kappa ds, kappa_plus = (1/l) int |kappa| ds,
kappa_m = |kappa_pm| (paper, section "Curvature of branches"), in 1/mm, trapezoid rule.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
from scipy.spatial.distance import cdist

from crosssection.core import polyline
from crosssection.core.errors import ParameterError
from crosssection.params import CURVATURE_METHODS as METHODS
from crosssection.stages.junctions import median_radii_px

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
    """Default sliding-average window: about two sheet thicknesses, ``2 floor(h) + 1`` points
    (11 for h = 5 px, 7 for h = 3.5 px).

    Measured on skeletons of drawn arcs (h = 5 px): the standard deviation of the local
    curvature (paper window 5 h) falls from 0.62/R (5 points) to 0.43/R (11 points) at
    R = 400 px, while the radius shrink stays 0.3 % at R = 40 px. The window is rounded down,
    never up: a wider one takes bending out of the bends near forks, and rounded to the
    nearest (9 points, 2.6 h, at h = 3.5 px) it cost the network generator's typical scans at
    35 px/mm 4.3 points of energy (16 scenes: median -19.2 % against -14.9 % with 7 points;
    38 px/mm -15.0 against -13.7 %, 55 px/mm -11.6 against -10.5 %, 75 px/mm -10.8 against
    -9.7 %; on 32 held-out scenes at 35 px/mm a wash, median -17.6 against -18.3 %, mean
    -18.0 against -16.6 %; 39 of 56 scenes of two generators closer to their truth;
    docs/validation/README.md, "Other resolutions"). The narrower window costs
    stability where it differs: the 35 px/mm scans' energy spread over the eight orientations
    of the square is 9.0 % in the median against 5.7 % with 9 points, that of the 25 px/mm
    scans (9.9 %), whose 5 points are the same 2 h.
    """
    # the small margin keeps a scale read from a file's DPI (49.999... px/mm) on its window
    k = max(1, int(math.floor(float(thickness_px) + 1e-6)))
    return 2 * k + 1


def _trapezoid(y, x):
    """``np.trapezoid(y, x)`` along the last axis, the same sums (its products, then numpy's
    pairwise sum of each row), without its overhead (a third of a profile's cost)."""
    return np.add.reduce((x[1:] - x[:-1]) * (y[..., 1:] + y[..., :-1]) / 2.0, axis=-1)


def _make_profile(s_px, kappa_px, rc, px_per_mm, closed, fit=(0, -1)) -> CurvatureProfile:
    kappa = np.asarray(kappa_px, float) * float(px_per_mm)
    s_mm = np.asarray(s_px, float) / float(px_per_mm)
    n = len(s_mm)
    length_mm = float(s_mm[-1] - s_mm[0]) if n > 1 else 0.0
    if length_mm > 0:
        # both integrals in one pass: a reduction along rows sums each row as a 1-D one
        both = np.empty((2, n))
        both[0] = kappa
        np.abs(kappa, out=both[1])
        ints = _trapezoid(both, s_mm)
        kpm = float(ints[0] / length_mm)
        kplus = float(ints[1] / length_mm)
    else:
        kpm = float(kappa.mean()) if len(kappa) else np.nan
        kplus = float(np.abs(kappa).mean()) if len(kappa) else np.nan
    return CurvatureProfile(s_mm=s_mm, kappa_per_mm=kappa, length_mm=length_mm, kappa_pm=kpm,
                            kappa_plus=kplus, kappa_m=abs(kpm), closed=bool(closed),
                            rc_px=np.asarray(rc, float), fit_start=int(fit[0]),
                            fit_stop=int(len(s_mm) if fit[1] < 0 else fit[1]))


def _solve3(S0, S1, S2, S3, S4, T0, T1, T2):
    """Least-squares parabolas: [[S4 S3 S2],[S3 S2 S1],[S2 S1 S0]] (a b c) = (T2 T1 T0).

    Parameters
    ----------
    S0, S1, S2, S3, S4, T0, T1, T2 : ndarray (m,)
        Window sums of every fit (:func:`_parabola_curvatures`).

    Returns
    -------
    a, b : ndarray (m,)
        Quadratic and linear coefficients; NaN where the system is singular (determinant
        not above 1e-9 of ``S4 S2 S0``).
    """
    m1 = S2 * S0 - S1 * S1
    m2 = S3 * S0 - S1 * S2
    det = S4 * m1 - S3 * m2 + S2 * (S3 * S1 - S2 * S2)
    deta = T2 * m1 - S3 * (T1 * S0 - S1 * T0) + S2 * (T1 * S1 - S2 * T0)
    detb = S4 * (T1 * S0 - T0 * S1) - T2 * m2 + S2 * (S3 * T0 - T1 * S2)
    singular = ~(np.abs(det) > 1e-9 * S4 * S2 * S0)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.divide(deta, det, out=deta)
        b = np.divide(detb, det, out=detb)
    if singular.any():
        a[singular] = np.nan
        b[singular] = np.nan
    return a, b


def _settle(c, i, lim, step, inside):
    """Where the scan from ``i`` by ``step`` stops -- at the last index in a range, or at
    ``lim`` -- found from an estimate ``c``.

    The ranges are defined by the scans' own tests (``s[i] - s[k] <= 2`` is not
    ``s[k] >= s[i] - 2`` in floating point), and the estimates of one search over all paths
    are off by the rounding of each path's shift into a key range of its own: on a dense
    2000x2000 scan they settle in one step or none. For a range that holds ``i`` and is
    contiguous (increasing arc length) any estimate between ``i`` and ``lim`` settles; from
    ``c = i`` this is the scan itself whatever the arc length.

    Parameters
    ----------
    c, i, lim : ndarray (m,) int
        Estimates, the scans' starts, and the last indices the scans may reach.
    step : {-1, 1}
        Direction of the scans.
    inside : callable
        ``inside(k)``: whether index ``k[r]`` is in the range of point ``r``.

    Returns
    -------
    ndarray (m,) int
        ``c``, settled in place.
    """
    while True:
        more = c != lim
        more &= inside(np.where(more, c + step, c))
        if not more.any():
            break
        c += more if step > 0 else -more.view(np.int8)
    while True:
        back = c != i
        back &= ~inside(c)
        if not back.any():
            return c
        c -= back if step > 0 else -back.view(np.int8)


def _chord_end(i, lim, step, inside, estimate):
    """:func:`_settle` for short scans: a few steps from ``i`` (a tangent chord of 2 px spans
    at most two samples on the skeletons of a dense scan, where one search of all the points
    takes 0.5 ms), the estimate ``estimate()`` settled when some scan goes farther."""
    c = i.copy()
    for _ in range(3):
        more = c != lim
        more &= inside(np.where(more, c + step, c))
        if not more.any():
            return c
        c += more if step > 0 else -more.view(np.int8)
    return _settle(estimate(), i, lim, step, inside)


@njit(cache=True)
def _window_sums(X, Y, i, a0, m, tx, ty):  # pragma: no cover - numba
    """Sums over every window of ``u, u^2 .. u^6, v, u v, u^2 v`` in its point's tangent frame.

    Point by point, each window's samples added one after the other from its first, in the
    point's own frame: running sums over a path in a common frame would subtract sums of u^6
    grown over thousands of px. Compiled: 2-3 ms against 11-12 ms for the same sums by numpy
    over blocks of gathered windows (the 633 000 window samples of a dense 2000x2000 scan).

    Parameters
    ----------
    X, Y : ndarray (N,)
        Coordinates of all points.
    i, a0, m : ndarray (n,) int
        The points, their windows' first points and lengths minus one.
    tx, ty : ndarray (n,)
        Unit tangents.

    Returns
    -------
    ndarray (9, n)
    """
    n = i.shape[0]
    out = np.empty((9, n))
    for p in range(n):
        xp = X[i[p]]
        yp = Y[i[p]]
        ptx = tx[p]
        pty = ty[p]
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = s8 = 0.0
        for t in range(m[p] + 1):
            j = a0[p] + t
            dx = X[j] - xp
            dy = Y[j] - yp
            u = dx * ptx + dy * pty
            v = dy * ptx - dx * pty
            u2 = u * u
            u4 = u2 * u2
            if t == 0:
                s0 = u
                s1 = u2
                s2 = u2 * u
                s3 = u4
                s4 = u4 * u
                s5 = u4 * u2
                s6 = v
                s7 = u * v
                s8 = u2 * v
            else:
                s0 += u
                s1 += u2
                s2 += u2 * u
                s3 += u4
                s4 += u4 * u
                s5 += u4 * u2
                s6 += v
                s7 += u * v
                s8 += u2 * v
        out[0, p] = s0
        out[1, p] = s1
        out[2, p] = s2
        out[3, p] = s3
        out[4, p] = s4
        out[5, p] = s5
        out[6, p] = s6
        out[7, p] = s7
        out[8, p] = s8
    return out


def _parabola_curvatures(fits):
    """Signed curvature (1/px) by a parabolic fit in the tangent frame, for many paths at once.

    At every wanted point: the tangent from the chord between the farthest points within
    2 px of arc on each side; the window of the points within ``half_w`` of arc, shifted
    inwards at an end keeping its length (``shift``) or truncated; in the point's tangent
    frame the parabola ``v = a u^2 + b u + c`` fitted to the window by least squares,
    ``kappa = 2 a / (1 + b^2)^1.5``, and with ``correct`` the circle's x^4 term removed
    (module docstring). A point whose chord has zero length, whose window holds fewer than
    three points or whose fit is singular gets 0. Closed loops are unrolled by the caller.

    Vectorised over the points of all paths (:func:`_window_sums`), with the arithmetic of a
    loop over each point and its window, in the same order (the same curvature to the last
    bit on a dense 2000x2000 scan). numpy has no fit over a moving window in a moving frame;
    and the arrays must hold many paths: one call per path costs about 0.5 ms of numpy
    overhead (120 ms for the 246 stacks of a dense 2000x2000 scan, against 20 ms in one
    call).

    Parameters
    ----------
    fits : sequence of tuple
        Per path ``(x, y, s, half_w, i0, i1, correct, shift)``: coordinates in a right-handed
        frame (x = col, y = -row) and increasing arc length, float arrays (n,), px; the half
        window, px; the wanted points ``i0..i1-1``; the circle correction; shifted windows.

    Returns
    -------
    list of ndarray
        Curvature at points ``i0..i1-1`` of every path, 1/px.
    """
    nw = [int(f[5]) - int(f[4]) for f in fits]
    live = [k for k, f in enumerate(fits) if nw[k] > 0 and len(f[2])]
    if not live:
        return [np.zeros(max(c, 0)) for c in nw]
    lens = np.array([len(fits[k][2]) for k in live])
    off = np.zeros(len(live), np.int64)
    np.cumsum(lens[:-1], out=off[1:])
    X = np.concatenate([fits[k][0] for k in live]).astype(float, copy=False)
    Y = np.concatenate([fits[k][1] for k in live]).astype(float, copy=False)
    S = np.concatenate([fits[k][2] for k in live]).astype(float, copy=False)
    i0 = np.array([int(fits[k][4]) for k in live])
    cnt = np.array([nw[k] for k in live])
    g = np.repeat(np.arange(len(live)), cnt)
    first = np.zeros(len(live), np.int64)
    np.cumsum(cnt[:-1], out=first[1:])
    i = np.arange(cnt.sum()) + np.repeat(off + i0 - first, cnt)
    st = off[g]
    en = (off + lens - 1)[g]

    # estimates of the scans' ends from one sorted key over all paths, each path's arc length
    # moved into a range of its own; _settle makes them exact on the path's own s
    s_min = np.minimum.reduceat(S, off)
    base = np.zeros(len(live))
    np.cumsum((np.maximum.reduceat(S, off) - s_min + 1.0)[:-1], out=base[1:])
    base -= s_min
    key = np.maximum.accumulate(S + np.repeat(base, lens))
    base_i = base[g]
    falls = S[1:] < S[:-1]
    falls[off[1:] - 1] = False
    falls = np.flatnonzero(falls)
    if falls.size:
        # a path whose arc length decreases somewhere is scanned from each point
        unordered = np.zeros(len(live), bool)
        unordered[np.searchsorted(off, falls, side="right") - 1] = True
        unordered = unordered[g]

    def estimate(q, right):
        c = np.searchsorted(key, q + base_i, side="right" if right else "left")
        c = np.clip(c - 1, i, en) if right else np.clip(c, st, i)
        if falls.size:
            c[unordered] = i[unordered]
        return c

    si = S[i]
    # tangent from a central chord of about 2 px each side (b corrects the residual tilt)
    lo = _chord_end(i, st, -1, lambda k: si - S.take(k) <= 2.0,
                    lambda: estimate(si - 2.0, False))
    hi = _chord_end(i, en, 1, lambda k: S.take(k) - si <= 2.0, lambda: estimate(si + 2.0, True))
    tx = X.take(hi) - X.take(lo)
    ty = Y.take(hi) - Y.take(lo)
    tn = np.sqrt(tx * tx + ty * ty)
    with np.errstate(divide="ignore", invalid="ignore"):
        tx /= tn
        ty /= tn
    half_w = np.array([float(fits[k][3]) for k in live]).repeat(cnt)
    s_lo = si - half_w
    s_hi = si + half_w
    shift = np.array([bool(fits[k][7]) for k in live]).repeat(cnt)
    if shift.any():
        s0 = S.take(st)
        s1 = S.take(en)
        before = shift & (s_lo < s0)
        after = shift & ~before & (s_hi > s1)
        s_hi, s_lo = (np.where(before, np.minimum(s_hi + (s0 - s_lo), s1), s_hi),
                      np.where(before, s0, s_lo))
        s_lo, s_hi = (np.where(after, np.maximum(s_lo - (s_hi - s1), s0), s_lo),
                      np.where(after, s1, s_hi))
    a0 = _settle(estimate(s_lo, False), i, st, -1, lambda k: S.take(k) >= s_lo)
    b0 = _settle(estimate(s_hi, True), i, en, 1, lambda k: S.take(k) <= s_hi)
    m = b0 - a0
    fit = np.flatnonzero((tn != 0.0) & (m >= 2))

    i, a0, m = i[fit], a0[fit], m[fit]
    S1, S2, S3, S4, S5, S6, T0, T1, T2 = _window_sums(X, Y, i, a0, m, tx[fit], ty[fit])
    S0 = m + 1.0
    a, b = _solve3(S0, S1, S2, S3, S4, T0, T1, T2)
    ok = np.isfinite(a)
    with np.errstate(invalid="ignore", over="ignore"):
        k = 2.0 * a / (1.0 + b * b) ** 1.5
        correct = np.array([bool(fits[k_][6]) for k_ in live]).repeat(cnt).take(fit)
        if correct.any():
            # A circle y = x^2/(2R) + x^4/(8R^3) + ... : the x^4 term leaks into the fitted a
            # and b by the projections (c2, c1) of x^4 on the window's samples. Remove it (two
            # fixed-point steps; exact to O((kappa X)^2)).
            c2, c1 = _solve3(S0, S1, S2, S3, S4, S4, S5, S6)
            kc = k
            for _ in range(2):
                k3 = kc * kc * kc / 8.0
                at = a - c2 * k3
                bt = b - c1 * k3
                kc = 2.0 * at / (1.0 + bt * bt) ** 1.5
            k = np.where(correct, kc, k)
    k[~ok] = 0.0  # a singular fit
    kappa = np.zeros(len(g))
    kappa[fit] = k
    out = [None] * len(fits)
    for k_, a_, c_ in zip(live, first.tolist(), cnt.tolist()):
        out[k_] = kappa[a_:a_ + c_]
    return [np.zeros(max(c, 0)) if o is None else o for o, c in zip(out, nw)]


def _trim_indices(s, trims):
    total = s[-1]
    t0 = int(np.searchsorted(s, trims[0], side="left"))
    t1 = int(np.searchsorted(s, total - trims[1], side="right"))
    return t0, t1


def _paper_job(p, *, closed, n_br, thickness_px, px_per_mm, smooth_px, trims, window_px,
               circle_correction, ends, max_window_frac, unfitted=False, smoothed=None):
    """Profile by the paper's parabolic window (module docstring), in two steps so that the
    window fits of many stacks run in one call of :func:`_parabola_curvatures`.

    An open path whose trims leave a fitted part shorter than the two trims together is
    fitted whole; with ``unfitted`` nothing of it is fitted (zero curvature, no fitted
    sample: ``fit_start == fit_stop == 0``), to be filled by :func:`_fill_unfitted_stacks`.
    ``smoothed``, when given, is ``polyline.smooth(p, window_px=smooth_px, closed=closed)``
    (computed for all stacks at once by :func:`stack_profiles`).

    Returns
    -------
    fit : tuple or None
        The stack's entry of :func:`_parabola_curvatures` (None: nothing to fit).
    finish : callable
        ``finish(kappa)``: the CurvatureProfile from the curvature of the fitted points
        (ignored when ``fit`` is None).
    """
    n = len(p)
    sm = (polyline.smooth(p, window_px=smooth_px, closed=closed) if smoothed is None
          else smoothed)
    d = np.diff(np.vstack([sm, sm[:1]]) if closed else sm, axis=0)
    seg = np.hypot(d[:, 0], d[:, 1])
    total_px = float(seg.sum())
    s_px = np.concatenate([[0.0], np.cumsum(seg[:n - 1])]) if n > 1 else np.zeros(1)
    if window_px is None:
        window_px = 5.0 * max(1, int(n_br)) * float(thickness_px)
    half_w = 0.5 * float(window_px)
    x = sm[:, 1]
    y = -sm[:, 0]
    t0, t1 = 0, n
    if n < 3:
        fit = None
    elif unfitted and not closed:
        # no centreline of its own (stack_profiles): missing data, filled from its neighbours
        t0 = t1 = 0
        fit = None
    elif closed:
        # unroll the loop once on each side; a window never exceeds the loop
        half_w = min(half_w, 0.5 * total_px)
        s_ext = np.concatenate([s_px - total_px, s_px, s_px + total_px])
        fit = (np.tile(x, 3), np.tile(y, 3), s_ext, half_w, n, 2 * n, bool(circle_correction),
               False)
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
        fit = (x[t0:t1], y[t0:t1], s_px[t0:t1], half_w, 0, t1 - t0, bool(circle_correction),
               ends == "shift")

    def finish(kin):
        s, rc = s_px, sm
        if n < 3 or t1 == t0:
            kappa_px = np.zeros(n)
        elif closed:
            kappa_px = kin
        else:
            kappa_px = np.empty(n)
            if ends == "shift":
                kin = _flat_shifted(kin, s_px[t0:t1], half_w)
            kappa_px[t0:t1] = kin
            kappa_px[:t0] = kin[0]
            kappa_px[t1:] = kin[-1]
        if closed and n >= 3:
            s = np.append(s_px, total_px)
            kappa_px = np.append(kappa_px, kappa_px[0])
            rc = np.vstack([sm, sm[:1]])
        return _make_profile(s, kappa_px, rc, px_per_mm, closed,
                             (0, -1) if (closed or n < 3) else (t0, t1))

    return fit, finish


def _prepared_path(path_rc, closed):
    """The points of a stack's path as the fits take them, and whether it is closed."""
    p = np.asarray(path_rc, dtype=np.float64).reshape(-1, 2)
    if closed is None:
        closed = polyline.is_closed(p)
    closed = bool(closed)
    if closed and len(p) > 1 and np.all(p[0] == p[-1]):
        p = p[:-1]  # the repeated closing pixel would count twice
    return p, closed


def _flat_shifted(kin, s, half_w):
    """The fits of the samples within ``half_w`` of an end of the fitted part ``s`` (px):
    they all fit the window next to that end, so they hold its fit read at its centre, the
    nearest sample fitted on a window centred on it.

    Read again in the tangent frame of every end sample, the same window gave a curvature
    that turns with the skeleton's last pixels: where the skeleton hooks into a fork of merged
    ink, the end samples' frames turn with the hook, and the parabola, fitted in a frame
    oblique to the window, bends with them. A 7-layer link between two forks of a compacted
    rod, blurred by 0.75 px, read 87 times the ``int kappa^2 ds`` it read unblurred, at the
    curvature bound at its end (docs/validation/README.md, "Shifted end windows").
    """
    c0, c1 = _centred_fits(s, 0, len(s), half_w)
    if c0 >= c1:
        return kin
    k = np.array(kin, dtype=float)
    k[:c0] = k[c0]
    k[c1:] = k[c1 - 1]
    return k


def _stack_job(path_rc, *, n_br, thickness_px, px_per_mm, closed, smooth_px, trim_px,
               window_px, circle_correction, ends, max_window_frac, method, unfitted=False,
               smoothed=None):
    """:func:`stack_curvature` up to the window fits: ``(fit, finish, trims)`` as
    :func:`_paper_job` (``unfitted`` and ``smoothed`` there; ``path_rc`` and ``closed`` then
    as :func:`_prepared_path` returns them), and the fork zones (None for an empty path,
    whose profile ``finish`` returns as it is)."""
    # with ``smoothed`` the path comes prepared (preparing it twice could drop two points)
    p, closed = _prepared_path(path_rc, closed) if smoothed is None else (path_rc, closed)
    if len(p) == 0:
        z = np.zeros(0)
        empty = CurvatureProfile(z, z, 0.0, np.nan, np.nan, np.nan, closed, np.zeros((0, 2)))
        return None, lambda _: empty, None
    if smooth_px is None:
        smooth_px = default_smooth_px(thickness_px)
    if method not in ("missing", "paper"):
        raise ParameterError(f"curvature method must be 'missing' or 'paper', got {method!r}")
    trims = tuple(trim_px) if np.ndim(trim_px) else (trim_px, trim_px)
    fit, finish = _paper_job(p, closed=closed, n_br=n_br, thickness_px=thickness_px,
                             px_per_mm=px_per_mm, smooth_px=int(smooth_px), trims=trims,
                             window_px=window_px, circle_correction=circle_correction,
                             ends=ends, max_window_frac=max_window_frac,
                             unfitted=unfitted, smoothed=smoothed)
    return fit, finish, trims


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
    fit, finish, trims = _stack_job(
        path_rc, n_br=n_br, thickness_px=thickness_px, px_per_mm=px_per_mm, closed=closed,
        smooth_px=smooth_px, trim_px=trim_px, window_px=window_px,
        circle_correction=circle_correction, ends=ends, max_window_frac=max_window_frac,
        method=method)
    prof = finish(None if fit is None else _parabola_curvatures([fit])[0])
    if trims is None or method == "paper":
        return prof
    # only junction ends are fork zones; a free end keeps the nearest fitted curvature
    forks = tuple(bool(t) and float(t) > 0 for t in trims)
    return _fill_fork_zones(prof, n_br, thickness_px, px_per_mm, forks,
                            noise_var_per_mm2=noise_var_per_mm2,
                            max_window_frac=max_window_frac, window_px=window_px,
                            shifted=(ends == "shift"))


#: How far from a junction (in sheet thicknesses) two stacks' skeletons are compared for
#: contact: a tangential peel of radius R stays within 1 px over sqrt(2 R) px, 30 h at R = 90 h.
_CONTACT_REACH_H = 30.0
#: Largest gap (px) between two bands still counted as contact: a thinner gap is not resolved
#: by the threshold at the paper's 50 px/mm and 1-px blur.
_CONTACT_GAP_PX = 1.0
#: A stack at a junction shorter than this many times ``max(2 r, r_Ja + r_Jb)`` (r its median
#: inscribed radius, r_J the inscribed radius at each junction end) has no centreline of its
#: own (module docstring, step 3): not fitted.
_LUMP_WIDTHS = 2.0
#: Largest total turn ``int |kappa| ds`` of a stack over one fork zone, radians (module
#: docstring, step 3).
_ZONE_MAX_TURN = 0.5 * math.pi
#: Noise variance of the fork-zone trend's slope, in units of ``v / w^2`` (``v`` the window
#: fit's curvature noise, ``w`` the window). Measured on noise-only stacks (jittered arcs and
#: lines, h = 2.5 and 5 px, n_br 1-4, jitter 0-0.7 px; 48 settings of 60 stacks each): median
#: 2.4, quartiles 2.0-2.9 (``test_trend_slope_noise_model``); the upper quartile is kept.
_SLOPE_NOISE = 3.0
#: A trend is continued when its slope exceeds this many deviations of its noise
#: (:func:`_fill_fork_zones`).
_TREND_DEVIATIONS = 4.0
_CHUNK = 16


#: Wall following through a fork zone (module docstring, step 3): a point of the arm's outer
#: wall further from the followed centreline than ``_WALL_TOL`` times the band's inscribed
#: radius (at least ``_WALL_TOL_MIN_PX``) from where it started is no longer the arm's own
#: outer layer (the tip of the paper wedge, another band against it): the follow stops.
_WALL_TOL = 0.35
_WALL_TOL_MIN_PX = 1.5
#: A band narrower than twice this (its inscribed radius, px) is not followed: its wall's
#: pixel steps are as large as the distance kept from it (at h <= 3 px, renders read -23 to
#: -40 % along such walls against -17 to +3 % with the zones as missing data).
_WALL_MIN_RADIUS_PX = 3.0
#: A followed centreline turning by more than this from its start (radians, 20 degrees) has
#: gone round a corner of the ink (an arm meeting a band at an angle), not along a layer.
_WALL_MAX_TURN = 0.35
#: Weight of each step's new direction in the followed direction (a low-pass of the pixel
#: steps of the wall).
_WALL_DAMP = 0.3


@njit(cache=True)
def _bilinear(img, r, c):  # pragma: no cover - numba
    H, W = img.shape
    if r < 0.0 or c < 0.0 or r > H - 1.001 or c > W - 1.001:
        return 0.0
    r0 = int(r)
    c0 = int(c)
    fr = r - r0
    fc = c - c0
    return ((1.0 - fr) * ((1.0 - fc) * img[r0, c0] + fc * img[r0, c0 + 1])
            + fr * ((1.0 - fc) * img[r0 + 1, c0] + fc * img[r0 + 1, c0 + 1]))


@njit(cache=True)
def _wall_distance(dt, qr, qc, nr, nc, max_t):  # pragma: no cover - numba
    # distance from q along the unit ray n to the ink's edge (distance transform 0.5, linear
    # between quarter-pixel samples); -1 when the edge is not within max_t
    prev = _bilinear(dt, qr, qc)
    if prev < 0.5:
        return 0.0
    # no paper lies nearer than the distance transform at q (less a pixel for the bilinear
    # interpolation): the march starts there
    t = max(0.0, math.floor(4.0 * (prev - 1.0)) * 0.25)
    if t > 0.0:
        prev = _bilinear(dt, qr + t * nr, qc + t * nc)
    while t < max_t:
        t2 = t + 0.25
        v = _bilinear(dt, qr + t2 * nr, qc + t2 * nc)
        if v < 0.5:
            return t + 0.25 * (prev - 0.5) / max(prev - v, 1e-9)
        prev = v
        t = t2
    return -1.0


@njit(cache=True)
def _follow_wall(dt, pr, pc, tr, tc, side, length, tol, max_ref, max_turn,
                 damp):  # pragma: no cover - numba
    # from (pr, pc) in the direction (tr, tc), 1-px steps kept at the starting distance from
    # the wall on ``side`` (+1: left of the direction in (row, col)), over ``length`` px of
    # arc; returns the points and whether the whole length was followed
    out = np.empty((int(length) + 3, 2))
    ref = _wall_distance(dt, pr, pc, -tc * side, tr * side, max_ref)
    if ref <= 0.0:
        return out[:0], False
    out[0, 0] = pr
    out[0, 1] = pc
    t0r, t0c = tr, tc
    cos_turn = math.cos(max_turn)
    k = 1
    travelled = 0.0
    while travelled < length and k < out.shape[0]:
        qr, qc = pr + tr, pc + tc
        nr, nc = -tc * side, tr * side
        e = _wall_distance(dt, qr, qc, nr, nc, ref + tol + 1.0)
        if e < 0.0 or abs(e - ref) > tol:
            return out[:k], False
        qr += (e - ref) * nr
        qc += (e - ref) * nc
        d = math.hypot(qr - pr, qc - pc)
        if d < 1e-9:
            return out[:k], False
        ur = (1.0 - damp) * tr + damp * (qr - pr) / d
        uc = (1.0 - damp) * tc + damp * (qc - pc) / d
        nu = math.hypot(ur, uc)
        tr, tc = ur / nu, uc / nu
        if tr * t0r + tc * t0c < cos_turn:
            return out[:k], False
        out[k, 0] = qr
        out[k, 1] = qc
        k += 1
        travelled += d
        pr, pc = qr, qc
    return out[:k], travelled >= length


#: Centreline at the walls' midpoint (module docstring, step 1): a sample is moved only where
#: the distance between the two walls along its normal is within ``_MIDLINE_WIDTH_TOL`` of the
#: band's width (at least ``_MIDLINE_WIDTH_TOL_MIN_PX``; elsewhere a fork, a touching band or a
#: layer step is in the way) and the move is at most ``_MIDLINE_MAX_SHIFT_PX``: a skeleton
#: pixel lies within half a pixel of the middle of a band of odd or even width, and the walls
#: are read to a quarter pixel.
_MIDLINE_WIDTH_TOL = 0.15
_MIDLINE_WIDTH_TOL_MIN_PX = 1.0
_MIDLINE_MAX_SHIFT_PX = 0.75
#: A wall found on the mask is looked for in the threshold's feature within this distance
#: (px): the mask moves an edge by at most half a pixel, its cleaning and a 1-px blur by
#: about one more.
_EDGE_SEARCH_PX = 1.5


@njit(cache=True)
def _refine_wall(feat, level, qr, qc, nr, nc, t):  # pragma: no cover - numba
    # the wall where the threshold's feature ``feat`` falls through its cut ``level`` along
    # the ray, the crossing nearest ``t`` (the mask's wall) within _EDGE_SEARCH_PX of it;
    # ``t`` itself where there is none (a filled void, a thread drawn across a gap)
    best = t
    gap = _EDGE_SEARCH_PX
    x = max(0.0, t - _EDGE_SEARCH_PX)
    prev = _bilinear(feat, qr + x * nr, qc + x * nc) - level
    while x < t + _EDGE_SEARCH_PX:
        x2 = x + 0.25
        v = _bilinear(feat, qr + x2 * nr, qc + x2 * nc) - level
        if prev > 0.0 and v <= 0.0:
            c = x + 0.25 * prev / (prev - v)
            if abs(c - t) < gap:
                gap = abs(c - t)
                best = c
        prev = v
        x = x2
    return best


@njit(cache=True)
def _midline_kernel(raw, sm, dt, width, tol, max_shift, closed, feat,
                    level):  # pragma: no cover - numba
    # every point of ``raw`` moved along the normal of ``sm`` (the smoothed path) to the
    # midpoint of the two walls, where they lie ``width`` +- ``tol`` apart and the move is at
    # most ``max_shift``; the other points as they are. With a feature (``feat.size > 1``)
    # each wall is placed where it crosses ``level``
    sub = feat.size > 1
    out = raw.copy()
    n = raw.shape[0]
    max_t = width + tol + 1.0
    for i in range(n):
        a, b = i - 1, i + 1
        if closed:
            a, b = a % n, b % n
        else:
            a, b = max(a, 0), min(b, n - 1)
        tr = sm[b, 0] - sm[a, 0]
        tc = sm[b, 1] - sm[a, 1]
        nt = math.hypot(tr, tc)
        if nt < 1e-9:
            continue
        nr, nc = -tc / nt, tr / nt
        d1 = _wall_distance(dt, raw[i, 0], raw[i, 1], nr, nc, max_t)
        d2 = _wall_distance(dt, raw[i, 0], raw[i, 1], -nr, -nc, max_t)
        if d1 <= 0.0 or d2 <= 0.0 or abs(d1 + d2 - width) > tol:
            continue
        if sub:
            d1 = _refine_wall(feat, level, raw[i, 0], raw[i, 1], nr, nc, d1)
            d2 = _refine_wall(feat, level, raw[i, 0], raw[i, 1], -nr, -nc, d2)
        shift = 0.5 * (d1 - d2)
        if abs(shift) <= max_shift:
            out[i, 0] = raw[i, 0] + shift * nr
            out[i, 1] = raw[i, 1] + shift * nc
    return out


def _midlines(paths, smoothed, closed, radius_px, dt, edge=None) -> list:
    """Every stack's skeleton pixels moved to the midpoint of its band's walls.

    Along the normal of the smoothed centreline, the band's walls (where the distance
    transform crosses 0.5 px, :func:`_wall_distance`) are found on both sides of each pixel;
    where they are the band's own (module constants ``_MIDLINE_*``) the pixel moves to their
    midpoint. The walls of the ink are exact under quarter turns and mirrors of the scan, the
    thinning's staircases are not (module docstring, step 1).

    Parameters
    ----------
    paths : list of (n, 2) arrays
        Skeleton paths (row, col) px, as the fits take them.
    smoothed : list of (n, 2) arrays
        The same paths smoothed (their normals are used).
    closed : list of bool
        Which paths are closed loops.
    radius_px : (M,) array
        Median inscribed radius of every band (distance transform on its skeleton), px.
    dt : 2-D float32 array
        Distance transform of the ink, px.
    edge : (2-D array, float), optional
        The threshold's feature and its cut: each wall found on the mask is moved to where
        the feature crosses the cut (within :data:`_EDGE_SEARCH_PX`), a fraction of a pixel
        that the mask rounds away.

    Returns
    -------
    list of (n, 2) float arrays
    """
    feat, level = (np.zeros((1, 1), np.int16), 0.0) if edge is None else edge
    if feat.dtype not in (np.int16, np.float32):
        feat = feat.astype(np.float32)  # one compiled kernel per type
    out = []
    for p, sm, c, r in zip(paths, smoothed, closed, radius_px):
        p = np.ascontiguousarray(p, dtype=np.float64)
        if len(p) < 3 or not np.isfinite(r) or r <= 0:
            out.append(p)
            continue
        # a band of w pixels has walls w px apart and a distance transform of about w / 2 + 0.5
        # on its skeleton
        width = 2.0 * float(r) - 0.5
        tol = max(_MIDLINE_WIDTH_TOL_MIN_PX, _MIDLINE_WIDTH_TOL * width)
        out.append(_midline_kernel(p, np.ascontiguousarray(sm, dtype=np.float64), dt, width,
                                   tol, _MIDLINE_MAX_SHIFT_PX, bool(c), feat, float(level)))
    return out


def _walled_path(path_rc, trims, radius_px, dt):
    """A stack's smoothed centreline with its fork zones followed along the outer wall.

    Inside a fork zone the arm's band is merged with its neighbour's and its skeleton hooks
    into the medial-axis fork point, but sheets cannot cross: an arm in contact with a band
    lies along that band's outer layer, and its own outer layer is the merged ink's wall on
    its side (module docstring, step 3). From the end of the zone the centreline is followed
    at its distance from that wall (about its inscribed radius), on each side, up to the
    junction. A side is followed only while the wall stays within ``_WALL_TOL`` of that
    distance and the direction within ``_WALL_MAX_TURN`` of its start; the zone takes the
    mean of the sides followed to the end, and keeps its skeleton when neither is. A stack
    whose zones would cover it is followed from its middle.

    Parameters
    ----------
    path_rc : (n, 2) array
        The smoothed centreline (row, col) px, junction ends first and last.
    trims : (float, float)
        Fork zone at the start and the end, px of arc (0: a free end, not followed).
    radius_px : float
        The band's median inscribed radius, px.
    dt : 2-D float32 array
        Distance transform of the ink (distance to the paper), px.

    Returns
    -------
    path : (m, 2) array
        The centreline with every followed zone replaced (1-px steps).
    followed : (bool, bool)
        Whether the start's and the end's zones were followed.
    """
    p = np.ascontiguousarray(path_rc, dtype=np.float64)
    if len(p) < 5:
        return p, (False, False)
    z0, z1 = (float(t or 0.0) for t in trims)
    tol = max(_WALL_TOL_MIN_PX, _WALL_TOL * float(radius_px))
    out, f0, f1 = _walled_kernel(p, z0, z1, float(radius_px), dt, tol, _WALL_MAX_TURN,
                                 _WALL_DAMP)
    return out, (bool(f0), bool(f1))


@njit(cache=True)
def _first_at_least(s, v):  # pragma: no cover - numba
    # np.searchsorted(s, v) (side "left") of an ascending s, by bisection: numba's own
    # searchsorted takes 0.4 s to compile
    lo, hi = 0, s.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if s[mid] < v:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(cache=True)
def _walled_kernel(p, z0, z1, radius_px, dt, tol, max_turn,
                   damp):  # pragma: no cover - numba
    # _walled_path in one numba call: per stack, its steps in Python cost about as much as
    # the follow itself (7 of 15 ms on the dense 2000x2000 benchmark scan)
    n = p.shape[0]
    s = np.zeros(n)
    for i in range(1, n):
        s[i] = s[i - 1] + math.hypot(p[i, 0] - p[i - 1, 0], p[i, 1] - p[i - 1, 1])
    total = s[n - 1]
    if total >= z0 + z1 + 4.0:
        a0 = _first_at_least(s, z0) if z0 > 0 else 0
        a1 = _first_at_least(s, total - z1) - 1 if z1 > 0 else n - 1
        a1 = max(a1, a0)
    else:
        a0 = _first_at_least(s, 0.5 * total)
        a1 = a0
    k = max(3, int(round(2.0 * radius_px + 2.0)))
    max_ref = 2.0 * radius_px + 3.0
    piece0 = np.empty((0, 2))
    piece1 = np.empty((0, 2))
    f0 = False
    f1 = False
    for end in range(2):
        a = a0 if end == 0 else a1
        z = z0 if end == 0 else z1
        if z <= 0:
            continue
        # the direction at the zone's edge from the centreline beyond it (one-sided: the
        # zone's side is the hook)
        b = min(a + k, n - 1) if end == 0 else max(a - k, 0)
        tr = p[a, 0] - p[b, 0]
        tc = p[a, 1] - p[b, 1]
        norm = math.hypot(tr, tc)
        if norm < 1e-9:
            continue
        tr /= norm
        tc /= norm
        length = s[a] if end == 0 else total - s[a]
        pa, oka = _follow_wall(dt, p[a, 0], p[a, 1], tr, tc, 1.0, length, tol, max_ref,
                               max_turn, damp)
        pb, okb = _follow_wall(dt, p[a, 0], p[a, 1], tr, tc, -1.0, length, tol, max_ref,
                               max_turn, damp)
        if oka and okb:
            m = min(pa.shape[0], pb.shape[0])
            piece = np.empty((m, 2))
            for i in range(m):
                piece[i, 0] = 0.5 * (pa[i, 0] + pb[i, 0])
                piece[i, 1] = 0.5 * (pa[i, 1] + pb[i, 1])
        elif oka:
            piece = pa.copy()
        elif okb:
            piece = pb.copy()
        else:
            continue
        if end == 0:
            piece0 = piece
            f0 = True
        else:
            piece1 = piece
            f1 = True
    if not (f0 or f1) or (a0 == a1 and not (f0 and f1)):
        return p, False, False
    nh = piece0.shape[0] - 1 if f0 else a0
    nt = piece1.shape[0] - 1 if f1 else n - 1 - a1
    mid = a1 - a0 + 1
    # element by element: numba compiles array-slice assignments with shape checks whose
    # error paths took most of this kernel's 4 s of compilation
    out = np.empty((nh + mid + nt, 2))
    for i in range(nh):
        for j in range(2):
            out[i, j] = piece0[piece0.shape[0] - 1 - i, j] if f0 else p[i, j]
    for i in range(mid):
        for j in range(2):
            out[nh + i, j] = p[a0 + i, j]
    for i in range(nt):
        for j in range(2):
            out[nh + mid + i, j] = piece1[i + 1, j] if f1 else p[a1 + 1 + i, j]
    return out, f0, f1


def _fork_zone_px(width_px, r_j, touching_px, smooth_px):
    """Fork zone (module docstring, step 3): the overlap, the hook, the contact, the smoothing."""
    return max(2.0 * max(width_px, r_j), touching_px) + 0.5 * (smooth_px - 1)


def _prefix(path_rc, end, reach):
    """The first ``reach`` pixels of a path from its start (end 0) or its end (end 1)."""
    p = np.asarray(path_rc, dtype=np.float64).reshape(-1, 2)
    return (p if end == 0 else p[::-1])[:reach]


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


@njit(cache=True)
def _first_far_kernel(pr, pc, offs, rad, group_lo, group_hi, gap_px):  # pragma: no cover
    """Per stack end, the first point of its prefix farther than ``rad[e] + rad[o] + gap_px``
    from every point of every other prefix ``o`` of its junction (``group_lo[e] <= o <
    group_hi[e]``); the prefix's length when there is none. The test of
    :func:`_contact_arc` (``cdist``'s distance, ``sqrt(dr^2 + dc^2)``), point after point.

    Compiled: all contact arcs (:func:`_contact_arcs`) in 7-10 ms against 30-50 ms for
    :func:`contact_arc_px` end by end (its ``cdist`` calls and their set-up) on the 488 stack
    ends of a dense 2000x2000 scan.
    """
    q = offs.shape[0] - 1
    out = np.empty(q, np.int64)
    for e in range(q):
        a, b = offs[e], offs[e + 1]
        out[e] = b - a
        for i in range(a, b):
            near = False
            for o in range(group_lo[e], group_hi[e]):
                if o == e:
                    continue
                lim = rad[e] + rad[o] + gap_px
                for k in range(offs[o], offs[o + 1]):
                    dr = pr[i] - pr[k]
                    dc = pc[i] - pc[k]
                    if math.sqrt(dr * dr + dc * dc) <= lim:
                        near = True
                        break
                if near:
                    break
            if not near:
                out[e] = i - a
                break
    return out


def _contact_arcs(paths, at_node, radius, reach, gap_px: float = _CONTACT_GAP_PX) -> dict:
    """:func:`contact_arc_px` of every stack end at a junction against the other ends there.

    Parameters
    ----------
    paths : list of (P, 2) arrays
        Stack paths.
    at_node : dict
        Junction -> list of (stack, end) meeting there.
    radius : (M,) float array
        Half width of every stack (median inscribed radius).
    reach : int
        Prefix length, pixels, compared from each junction.
    gap_px : float
        As in :func:`contact_arc_px`.

    Returns
    -------
    dict
        (stack, end) -> arc length, px.
    """
    keys = [key for ks in at_node.values() for key in ks]
    if not keys:
        return {}
    pre = [_prefix(paths[sid], end, reach) for sid, end in keys]
    sizes = np.array([len(ks) for ks in at_node.values()], np.int64)
    ends = np.cumsum(sizes)
    group_lo = np.repeat(ends - sizes, sizes)
    group_hi = np.repeat(ends, sizes)
    lens = np.fromiter((len(p) for p in pre), np.int64, count=len(pre))
    offs = np.zeros(len(pre) + 1, np.int64)
    np.cumsum(lens, out=offs[1:])
    flat = np.concatenate(pre) if offs[-1] else np.zeros((0, 2))
    rad = np.asarray(radius, np.float64)[np.array([sid for sid, _ in keys], np.int64)]
    first_far = _first_far_kernel(np.ascontiguousarray(flat[:, 0]),
                                  np.ascontiguousarray(flat[:, 1]), offs, rad, group_lo,
                                  group_hi, float(gap_px))
    # an end whose junction has no other end with a prefix has nothing to touch
    filled = (lens > 0).astype(np.int64)
    has_other = np.repeat(np.add.reduceat(filled, ends - sizes), sizes) - filled > 0
    out = {}
    for e, key in enumerate(keys):
        p, ff = pre[e], int(first_far[e])
        if len(p) < 2 or ff < 1 or not has_other[e]:
            out[key] = 0.0
            continue
        seg = np.diff(p[:min(ff, len(p) - 1) + 1], axis=0)
        out[key] = float(np.hypot(seg[:, 0], seg[:, 1]).sum())
    return out


def stack_profiles(graph, n_br, distance_px, *, thickness_px: float, px_per_mm: float,
                   smooth_px: int | None = None, method: str = METHODS[0], edge=None) -> list:
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
    method : {"walls", "missing", "paper"}
        Fork zones (module docstring, step 3): followed along the merged ink's outer wall
        where it holds the arm's outer layer, as missing data elsewhere (``"walls"``), as
        missing data everywhere (``"missing"``), or given the nearest fitted curvature
        (``"paper"``). ``"walls"`` and ``"missing"`` also measure the scan's curvature noise
        (step 4) and record it in every profile.
    edge : (2-D array, float), optional
        The threshold's feature (the scan's ``blue - max(red, green)``) and its cut: the
        centreline's walls (step 1) are placed where the feature crosses the cut, to a
        fraction of a pixel. None: on the mask's distance transform alone.

    Returns
    -------
    list of CurvatureProfile
        One per stack, in stack order.
    """
    if method not in METHODS:
        raise ParameterError(f"curvature method must be one of {METHODS}, got {method!r}")
    H, W = distance_px.shape
    sm = default_smooth_px(thickness_px) if smooth_px is None else int(smooth_px)
    at_node = {}  # junction -> [(stack, end)]
    for sid in range(graph.n_stacks):
        for end, node in enumerate(graph.ends[sid]):
            if graph.node_kind[node] == "junction":
                at_node.setdefault(node, []).append((sid, end))
    reach = int(np.ceil(_CONTACT_REACH_H * float(thickness_px)))
    radius = median_radii_px(graph.paths, distance_px)
    # per band end at a junction: its skeleton from the junction, and the skeleton points of
    # the other bands there with the distance below which each touches it
    contact = _contact_arcs(graph.paths, at_node, radius, reach)

    def junction_radius(sid, end):
        # the inscribed ink radius at the junction of a stack end (0 at a free end)
        node = graph.ends[sid][end]
        if graph.node_kind[node] != "junction":
            return 0.0
        r, c = np.round(graph.node_rc[node]).astype(int)
        return float(distance_px[min(max(r, 0), H - 1), min(max(c, 0), W - 1)])

    def fork_zone(sid, end, nb):
        # module docstring, step 3
        if graph.node_kind[graph.ends[sid][end]] != "junction":
            return 0.0
        return _fork_zone_px(nb * float(thickness_px), junction_radius(sid, end),
                             contact[(sid, end)], sm)

    prepared = [_prepared_path(graph.paths[sid], graph.node_kind[graph.ends[sid][0]] == "loop")
                for sid in range(graph.n_stacks)]
    raw = [p for p, _ in prepared]
    closed = [c for _, c in prepared]
    smoothed = polyline.smooth_paths(raw, window_px=sm, closed=closed)
    dt32 = np.ascontiguousarray(distance_px, dtype=np.float32)
    if method != "paper":
        # the paper's centreline is the skeleton's; the others read it between the walls
        mid = _midlines(raw, smoothed, closed, radius, dt32, edge)
        prepared = list(zip(mid, closed))
        smoothed = polyline.smooth_paths(mid, window_px=sm, closed=closed)
    jobs, forks, walled = [], [], {}
    for sid in range(graph.n_stacks):
        u, v = graph.ends[sid]
        nb = max(1, int(n_br[sid]))
        trims = (fork_zone(sid, 0, nb), fork_zone(sid, 1, nb))
        forks.append(tuple(t > 0 for t in trims))
        # a stack within its forks' hooks from end to end: its skeleton is the link between
        # medial-axis fork points, no centreline of its own (step 3). A junction blob wider
        # than the band (thick stacks meeting, at epsilon 19) holds longer such links.
        hooks = max(2.0 * radius[sid], junction_radius(sid, 0) + junction_radius(sid, 1))
        lump = (method != "paper" and any(forks[-1]) and graph.node_kind[u] != "loop"
                and polyline.length(graph.paths[sid]) < _LUMP_WIDTHS * hooks)
        jobs.append(_stack_job(
            prepared[sid][0], n_br=nb, thickness_px=thickness_px, px_per_mm=px_per_mm,
            closed=prepared[sid][1], smooth_px=sm, trim_px=trims,
            window_px=None, circle_correction=True, ends="shift", max_window_frac=0.5,
            method="paper", unfitted=lump, smoothed=smoothed[sid]))
        if (method == "walls" and not prepared[sid][1] and any(forks[-1]) and not lump
                and radius[sid] >= _WALL_MIN_RADIUS_PX):
            path, followed = _walled_path(smoothed[sid], trims, radius[sid], dt32)
            if any(followed):
                # a followed zone is measured: fitted, not extrapolated, but on the merged
                # band's edge, not on a free centreline (``energy_rel_uncertainty``)
                walled[sid] = (path, tuple(0.0 if f else t for t, f in zip(trims, followed)),
                               tuple(t if f else 0.0 for t, f in zip(trims, followed)))
    wsids = sorted(walled)
    wsmooth = polyline.smooth_paths([walled[sid][0] for sid in wsids], window_px=sm,
                                    closed=False) if wsids else []
    for sid, wsm in zip(wsids, wsmooth):
        path, trims, _ = walled[sid]
        jobs.append(_stack_job(
            path, n_br=max(1, int(n_br[sid])), thickness_px=thickness_px, px_per_mm=px_per_mm,
            closed=False, smooth_px=sm, trim_px=trims, window_px=None, circle_correction=True,
            ends="shift", max_window_frac=0.5, method="paper", smoothed=wsm))
    # the window fits of all stacks in one call (numpy's overhead per call is that of a
    # whole stack's fits)
    kin = iter(_parabola_curvatures([fit for fit, _, _ in jobs if fit is not None]))
    every = [finish(None if fit is None else next(kin)) for fit, finish, _ in jobs]
    profiles = every[:graph.n_stacks]
    if method == "paper":
        return profiles
    # the scan's noise from the stacks' own centrelines: a followed wall carries one
    # edge's noise, and pooled in it moved the trend tests of the other stacks
    var = noise_variance(profiles, n_br, thickness_px=thickness_px, px_per_mm=px_per_mm,
                         smooth_px=sm, unmeasured=None)
    for sid, prof in zip(wsids, every[graph.n_stacks:]):
        profiles[sid] = prof
        forks[sid] = tuple(t > 0 for t in walled[sid][1])
    profiles = [_fill_fork_zones(prof, max(1, int(n_br[sid])), thickness_px, px_per_mm,
                                 forks[sid], noise_var_per_mm2=var[max(1, int(n_br[sid]))] or 0.0,
                                 max_window_frac=0.5, shifted=True,
                                 walled_px=walled[sid][2] if sid in walled else (0.0, 0.0))
                for sid, prof in enumerate(profiles)]
    return _fill_unfitted_stacks(profiles, at_node, n_br, px_per_mm=px_per_mm,
                                 thickness_px=thickness_px)


def _unfitted(prof) -> bool:
    """Whether a profile has samples but none fitted (:func:`_fill_unfitted_stacks`)."""
    return len(prof.s_mm) > 0 and prof.fit_stop <= prof.fit_start


def _fitted_window_mm(s, t0, t1, window_px, px_per_mm, max_window_frac=0.5) -> float:
    """The window the fits of samples ``t0:t1`` used, mm: ``window_px``, capped by
    :func:`_paper_job` at ``max_window_frac`` of the fitted length."""
    w = float(window_px) / px_per_mm
    if max_window_frac is not None and max_window_frac > 0:
        w = min(w, float(max_window_frac) * float(s[t1 - 1] - s[t0]))
    return w


def _centred_fits(s, t0, t1, half_mm):
    """``(c0, c1)``: the fits of samples ``t0:t1`` centred on their own sample, those
    ``half_mm`` (half the window) or more from both ends of the fitted part; the others
    are shifted inwards onto the window next to the end."""
    c0 = int(np.searchsorted(s, s[t0] + half_mm))
    c1 = int(np.searchsorted(s, s[t1 - 1] - half_mm, side="right"))
    return c0, c1


def _fill_unfitted_stacks(profiles, at_node, n_br, *, px_per_mm, thickness_px):
    """Stacks without a centreline of their own: the nearest fitted curvature, across their
    junctions.

    A stack at a junction shorter than twice its band's width, or than twice the inscribed
    radii of its junctions summed (:data:`_LUMP_WIDTHS`, module docstring step 3), lies within
    its forks' hooks from end to end: its skeleton links two
    medial-axis fork points, which lie off every layer's path. Fitted whole (the window
    capped at half its length), it measured that link: on renders of compacted rods
    (epsilon 19, 5-16 such stacks per scan) 0.2-1.35 times the rod's total energy against
    0.01-0.13 in the rod. The junction blobs of thick stacks there are wider than the bands
    leaving them, and the links between two of them longer: counting them by the junctions'
    radii took the total energy error of four such renders from +224 to +388 % to +186 to
    +269 % (``benchmarks/bench_compact_pipeline.py --epsilon 19:4 --conditions scan``), and
    changed no scan of the robust sweep. Its curvature is missing data, filled as a fork zone's is by the
    nearest fitted curvature: its layers run on through the junctions into the other stacks
    there, so each end takes the curvature of their centred fits nearest to that junction (a
    measured value: not the trend continued beyond them over the shifted fits, which on a
    compacted render gave a 13-layer lump 10 mm long 12 times the energy,
    ``test_lump_takes_its_neighbours_measured_curvature_not_their_continued_trend``)
    -- magnitude the root mean square (the energy density), sign the mean, weighted by the
    layers the two bands can share (``min(n_br, n_br_other)``), signed for this stack's
    direction -- and the curvature goes linearly from one end to the other (constant with a
    single junction end), bounded by the stack's own ``2 / (n_br h)`` (:func:`_fill_fork_zones`:
    a thick lump between thin, tightly bent stacks cannot take their curvature; unbounded, a
    41-layer lump at epsilon 30 took 2.7 /mm and 40 % of the scan's measured energy). The
    borrowed samples carry their window fits' noise: their mean
    noise variance is recorded for the energy to remove. A stack whose neighbours are all
    unfitted takes, in a later pass, the ends of those filled before; a cluster without any
    fitted stack keeps zero curvature.

    Parameters
    ----------
    profiles : list of CurvatureProfile
        Per stack, fork zones filled (:func:`_fill_fork_zones`).
    at_node : dict
        Junction node -> list of (stack, end) meeting there (end 0: path start).
    n_br : (M,) int array
    px_per_mm, thickness_px : float

    Returns
    -------
    list of CurvatureProfile
        ``profiles`` with the unfitted stacks filled (``fit_start == fit_stop == 0`` kept:
        nothing of them is measured; ``energy_rel_uncertainty`` counts all of it).
    """
    todo = {sid for sid, prof in enumerate(profiles) if _unfitted(prof) and not prof.closed}
    if not todo:
        return profiles
    out = list(profiles)
    nb = [max(1, int(x)) for x in n_br]
    # (stack, end) -> the junction there
    node_of = {key: node for node, keys in at_node.items() for key in keys}
    # a source's curvature and noise variance at each end: fitted stacks their fitted sample
    # nearest to that end (1/mm), filled stacks their end value (filled in earlier passes)
    end_value = {}
    for sid, prof in enumerate(profiles):
        if sid in todo or not len(prof.s_mm) or prof.fit_stop <= prof.fit_start:
            continue
        k, s = prof.kappa_per_mm, prof.s_mm
        v = prof.noise_var_per_mm2
        t0, t1 = prof.fit_start, prof.fit_stop
        # the centred fit nearest to each end: a measured value, not the trend continued
        # beyond it over the shifted fits (_fill_fork_zones)
        w = _fitted_window_mm(s, t0, t1, 5.0 * nb[sid] * float(thickness_px), px_per_mm)
        c0, c1 = _centred_fits(s, t0, t1, 0.5 * w)
        end_value[(sid, 0)] = (float(k[min(c0, t1 - 1)]), v)
        end_value[(sid, 1)] = (float(k[max(c1 - 1, t0)]), v)
    while todo:
        filled = {}
        for sid in sorted(todo):
            end_k, noise, layers = [], [], []
            for end in (0, 1):
                node = node_of.get((sid, end))
                if node is None:
                    continue
                ks, w = [], []
                for other, o_end in at_node[node]:
                    if other == sid or (other, o_end) not in end_value:
                        continue
                    k_o, v_o = end_value[(other, o_end)]
                    # a layer going on from this stack's end into the other's: the same
                    # direction of travel when one path arrives (end 1) and the other leaves
                    # (end 0); the curvature's sign flips with the direction
                    ks.append(k_o if end != o_end else -k_o)
                    w.append(float(min(nb[sid], nb[other])))
                    noise.append(v_o)
                layers += w
                if ks:
                    ks, w = np.asarray(ks), np.asarray(w)
                    rms = float(np.sqrt(np.average(ks * ks, weights=w)))
                    end_k.append(float(np.copysign(rms, np.average(ks, weights=w))))
            if end_k:
                filled[sid] = (end_k[0], end_k[-1], float(np.average(noise, weights=layers)))
        if not filled:
            break
        for sid, (k0, k1, v) in filled.items():
            kmax = 2.0 * px_per_mm / (nb[sid] * float(thickness_px))
            k0, k1 = float(np.clip(k0, -kmax, kmax)), float(np.clip(k1, -kmax, kmax))
            prof = out[sid]
            s = prof.s_mm
            frac = (s - s[0]) / (s[-1] - s[0]) if s[-1] > s[0] else np.zeros_like(s)
            k = k0 + (k1 - k0) * frac
            new = _make_profile(s * px_per_mm, k / px_per_mm, prof.rc_px, px_per_mm, False,
                                (0, 0))
            out[sid] = replace(new, noise_var_per_mm2=v, energy_rel_uncertainty=_rel_uncertainty(
                new, (True, True), v * new.length_mm))
            end_value[(sid, 0)] = (k0, v)
            end_value[(sid, 1)] = (k1, v)
        todo -= set(filled)
    return out


def _trend(s, k):
    """Least-squares line k = b + a (s - s_mean): (a, b, s_mean)."""
    sm = s.mean()
    ds = s - sm
    den = float(ds @ ds)
    km = k.mean()
    a = float(ds @ (k - km)) / den if den > 0 else 0.0
    return a, float(km), sm


def _fill_fork_zones(prof, n_br, thickness_px, px_per_mm, forks=(True, True), noise_px=0.3,
                     noise_var_per_mm2=None, max_window_frac=0.5,
                     shifted=True, window_px=None, max_turn=_ZONE_MAX_TURN,
                     walled_px=(0.0, 0.0)):
    """Fork zones as missing data, and the physical bound on curvature.

    Within a fork zone the image holds no centreline of this stack (module docstring), so its
    curvature is not measured there: the linear trend of the curvature over the first (last)
    window of centred fits is continued to the junction. With shifted windows (``shifted``,
    ``ends="shift"``) the fitted samples within half a window ``w/2`` of the zone all fit the
    same window, the one next to the zone: their curvature is that window's mean, located at
    its centre, not a local value, and it is flat there whatever the bend does. The trend is
    therefore taken over the next window (arc ``w/2 .. 3 w/2`` from the zone: the first fits
    centred on their own sample) and, where it is continued, it replaces those shifted fits
    as well. (Taken over the first ``w`` of arc, half of it flat, the slope came out about
    half the bend's: on a clothoid whose curvature rises toward the zone, the zone's
    ``int kappa^2 ds`` was 0.84-0.95 x the truth, 1.00 x now; on the network generator's
    tangential forks the visible arc of the zones, outside the merged bands, got 32 % of its
    true ``int kappa^2 ds``, 52 % now.) ``w`` is the window actually fitted: ``5 n_br h`` (or
    ``window_px``), capped at ``max_window_frac`` of the fitted length as in
    :func:`_paper_job`. With the scan's curvature noise ``v`` known, the trend is continued
    only where the data show one: the noise is correlated over about a window, and the slope
    of the trend over noise alone has a variance of ``c v / w^2``, ``c`` =
    :data:`_SLOPE_NOISE` (measured on noise-only stacks: 2.0-2.9, median 2.4); a slope within
    :data:`_TREND_DEVIATIONS` (4) deviations is taken for noise, and the zone keeps the
    nearest fitted curvature and the shifted fits their own. Four, not two: a continued
    noise slope is extrapolated over the zone and costs more than a missed trend, which keeps
    the nearest value (extrapolating noise slopes multiplied the noise in the zones by about
    five on jittered arcs; on the simulator's renders, whose branches bend little near
    forks, two deviations let 5 % of them through: median |error| 12.3 -> 14.7 %, the worst
    render +58 -> +115 %, against 1-2 points gained on the network generator's typical and
    thick dense scans, 24 scenes each).
    A stack fitted whole (its zones would cover it) has no zone, but at a fork end its fits
    within ``w/2`` are shifted as next to a zone: the trend replaces them under the same test,
    only where the noise is known (``noise_var_per_mm2`` not None), for they are measured
    values. Known includes a measured 0 (noise below what the lags resolve: any trend exceeds
    it). Read as unknown, a measured 0 would make the energy of a clean scan follow the sign
    of a noise estimate near 0 (a sample scan's stacks fitted whole: 8 370 with the trends,
    4 990 without, 7 970 in the truth; its PNG and its JPEG copies at quality 85-95 fall on
    either side). On a scan where no stack could be measured the pipeline passes 0, and the
    links take their trends too, as every other stack does there: 12 of 32 held-out typical network
    scenes have no measured noise, and read -18 % in the median with it against -20 % (each
    of the 12 toward the truth), the tangential forks -46 % against -52 %, the renders (whose
    noise is measured) the same. At 25 px/mm, where a window of one layer spans under 15 px,
    this holds on centrelines read between the walls (step 1): the network generator's scenes
    read a median |error| of 2 % with the trends (held out 14 %) against 16-19 % without,
    another generator's -25 % against -27 %; on the skeleton itself the pixels' slopes passed
    for trends there (21 % against 16 %).
    The curvature is bounded everywhere by ``2 / (n_br h)``: the innermost layer of a stack of
    ``n_br`` layers cannot have a negative radius, so anything tighter is a skeleton kink, not
    a bend. A zone's total turn, up to the fitted sample next to it, is bounded by ``max_turn``
    (the zone's curvature scaled down; module docstring, step 3).

    The relative uncertainty of ``int kappa^2 ds`` adds the extrapolated part (not measured:
    counted in full) and the noise floor of the parabolic fit, ``720 sigma^2 / w^5`` per unit
    length for ``noise_px`` of centreline noise and a window of ``w`` px.

    Parameters
    ----------
    prof : CurvatureProfile
        The window fits (:func:`_paper_job`): samples ``fit_start:fit_stop`` fitted, the
        others holding the nearest fitted curvature.
    n_br : int
        Layers of the stack (window ``5 n_br h``, bound ``2 / (n_br h)``).
    thickness_px, px_per_mm : float
        Sheet thickness h in px; scan resolution.
    forks : (bool, bool)
        Whether the path's start and end are fork zones (free ends are never extrapolated).
    noise_px : float
        Centreline noise assumed for the uncertainty when ``noise_var_per_mm2`` is None.
    noise_var_per_mm2 : float, optional
        The scan's curvature noise (:func:`noise_variance`); None: trend always continued
        beyond the zones, and a stack fitted whole keeps its fits.
    max_window_frac : float or None
        The cap of the fitted window as a fraction of the fitted length (as given to the
        fits).
    shifted : bool
        Whether the windows near the fitted part's ends were shifted inwards
        (``ends="shift"``); with truncated windows the trend starts at the fitted end.
    window_px : float, optional
        The fitted window when it overrides ``5 n_br h``, px.
    max_turn : float
        Largest ``int |kappa| ds`` over one fork zone, radians (``numpy.inf``: no bound).
    walled_px : (float, float)
        Arc at the start and the end followed along a merged band's wall (fitted, but counted
        in ``energy_rel_uncertainty`` as not measured on a free centreline), px.

    Returns
    -------
    CurvatureProfile
        Same samples and ``fit_start``/``fit_stop``; ``noise_var_per_mm2`` and
        ``energy_rel_uncertainty`` set.
    """
    n = len(prof.s_mm)
    t0, t1 = prof.fit_start, prof.fit_stop
    nb = max(1, int(n_br))
    w_px = 5.0 * nb * float(thickness_px)
    s = prof.s_mm
    kmax = 2.0 * px_per_mm / (nb * float(thickness_px))
    k = np.clip(prof.kappa_per_mm, -kmax, kmax)
    # an unfitted stack (t1 == t0) has no trend to continue: _fill_unfitted_stacks fills it
    if not prof.closed and n >= 3 and (t0 > 0 or t1 < n or any(forks)) and t1 > t0:
        w = _fitted_window_mm(s, t0, t1, w_px if window_px is None else float(window_px),
                              px_per_mm, max_window_frac)
        # shifted fits within w/2 of the zone: the trend window starts beyond them
        off = 0.5 * w if shifted else 0.0
        c0, c1 = _centred_fits(s, t0, t1, off)
        lo_end = int(np.searchsorted(s, s[t0] + off + w))
        hi_start = int(np.searchsorted(s, s[t1 - 1] - off - w, side="right"))
        for side, (lo, hi, z0, z1, fork) in enumerate((
                (c0, min(max(lo_end, c0 + 3), t1), 0, c0, forks[0]),
                (max(min(hi_start, c1 - 3), t0), c1, c1, n, forks[1]))):
            lo, hi = max(lo, t0), min(hi, t1)
            whole = (t0 == 0) if side == 0 else (t1 == n)
            # a stack fitted whole (its zones would cover it) has measured fits at its ends,
            # shifted onto one window's mean: they give way to a trend only where the scan's
            # noise is known and the trend exceeds it
            if not fork or hi - lo < 3 or (whole and noise_var_per_mm2 is None):
                continue
            a, b, sm = _trend(s[lo:hi], k[lo:hi])
            if (noise_var_per_mm2 is not None and a * a * w * w
                    <= _TREND_DEVIATIONS ** 2 * _SLOPE_NOISE * noise_var_per_mm2):
                # no trend beyond the noise: the zone keeps the nearest fitted curvature and
                # the shifted fits their own
                z0, z1 = (0, t0) if side == 0 else (t1, n)
            else:
                k[z0:z1] = np.clip(b + a * (s[z0:z1] - sm), -kmax, kmax)
            _bound_turn(k, s, z0, z1, z1 if side == 0 else z0 - 1, max_turn)
    out = _make_profile(s * px_per_mm, k / px_per_mm, prof.rc_px, px_per_mm, prof.closed,
                        (t0, t1))
    if noise_var_per_mm2 is not None:
        v = float(noise_var_per_mm2)
        noise = v * out.length_mm
    else:
        v = 0.0
        noise = 720.0 * noise_px ** 2 / w_px ** 5 * px_per_mm ** 2 * out.length_mm
    return replace(out, noise_var_per_mm2=v, energy_rel_uncertainty=_rel_uncertainty(
        out, forks, noise, walled_mm=[w / px_per_mm for w in walled_px]))


def _zone_turn(k, s, z0, z1, edge) -> float | None:
    """Total turn ``int |kappa| ds`` of the fork zone ``k[z0:z1]`` up to the fitted sample
    ``edge`` next to it, radians (None for an empty zone)."""
    if z1 <= z0 or not 0 <= edge < len(k):
        return None
    i, j = min(z0, edge), max(z1, edge + 1)
    return float(_trapezoid(np.abs(k[i:j]), s[i:j]))


def _bound_turn(k, s, z0, z1, edge, limit):
    """Scale the fork zone ``k[z0:z1]`` in place so that its total turn
    (:func:`_zone_turn`) is at most ``limit`` radians."""
    turn = _zone_turn(k, s, z0, z1, edge)
    if turn is None or turn <= limit:
        return
    # the edge sample's half of its interval is measured, not scaled
    half = 0.5 * abs(float(k[edge])) * abs(float(s[edge] - s[edge + (1 if edge < z0 else -1)]))
    k[z0:z1] *= max(limit - half, 0.0) / max(turn - half, 1e-300)


def _rel_uncertainty(prof, forks, noise_int, walled_mm=(0.0, 0.0)):
    """(part of int kappa^2 ds not measured on a free centreline + the noise floor
    ``noise_int``) / the integral.

    Not measured on a free centreline: the fork zones extrapolated, and the ``walled_mm`` of
    arc at each end followed along a merged band's wall (its layers assumed to lie along it).
    """
    k, s, n = prof.kappa_per_mm, prof.s_mm, len(prof.s_mm)
    if n < 2:
        return float("nan")
    f = k * k
    total = float(_trapezoid(f, s))
    z0 = prof.fit_start if forks[0] else 0
    z1 = prof.fit_stop if forks[1] else n
    z0 = max(z0, int(np.searchsorted(s, s[0] + walled_mm[0], side="right")) - 1)
    z1 = min(z1, int(np.searchsorted(s, s[-1] - walled_mm[1])) + 1)
    # fitted whole because its fork zones would cover it: every sample is a fork's
    whole = any(forks) and prof.fit_start == 0 and prof.fit_stop == n
    fitted = float(_trapezoid(f[z0:z1], s[z0:z1])) if z1 - z0 > 1 and not whole else 0.0
    return float((max(total - fitted, 0.0) + noise_int) / max(total, noise_int, 1e-300))


def _lag_variance(prof, lag_mm):
    """Half the mean squared curvature difference at ``lag_mm`` over the fitted samples (None
    when the fitted part is shorter than two lags)."""
    s = prof.s_mm[prof.fit_start:prof.fit_stop]
    k = prof.kappa_per_mm[prof.fit_start:prof.fit_stop]
    if len(s) < 3 or s[-1] - s[0] < 2.0 * lag_mm:
        return None
    j = np.searchsorted(s, s + lag_mm)
    ok = j < len(s)
    d = k[j[ok]] - k[ok]
    return float(d @ d) / (2.0 * d.size)


#: A stack whose own noise estimate exceeds this many times the pooled estimate of the scan's
#: other stacks of its window is left out of the pooled noise (:func:`_without_outliers`): on
#: noise-only arcs the stacks' own estimates are 0.3-1.9 times the pooled one (5-95 %, at most
#: 2.3; 120 stacks), a stack with one 90-degree turn of radius 12 px among them 80 times
#: (pooled with it, the noise read 12 times its value).
NOISE_OUTLIER = 4.0


def _without_outliers(v, w):
    """Per-stack noise estimates ``v`` (weights ``w``) without the stacks whose own estimate
    exceeds :data:`NOISE_OUTLIER` times the pooled estimate of the others (their mean absolute
    estimate where they pool to 0 or below), largest first, while two stacks or more remain
    besides it.

    A stack with real bending at the scale of the lags (a hook, a kink) reads tens of times the
    scan's noise, and pooled with the others it would set the noise removed from every stack.
    """
    order = np.argsort(v)
    v, w = v[order], w[order]
    while len(v) >= 3:
        rest = float(v[:-1] @ w[:-1]) / float(w[:-1].sum())
        if rest <= 0:
            # the others' noise is below what the lags resolve, their estimates scattered about
            # 0: their scatter is the scale (an independent generator's scan: -0.018 to 0.006
            # beside a stack of 0.30 /mm^2, which pooled in set the scan's noise at 0.069)
            rest = float(np.abs(v[:-1]) @ w[:-1]) / float(w[:-1].sum())
        if rest <= 0 or v[-1] <= NOISE_OUTLIER * rest:
            break
        v, w = v[:-1], w[:-1]
    return v, w


def noise_variance(profiles, n_br, *, thickness_px: float, px_per_mm: float,
                   smooth_px: int | None = None, min_pairs: int = 200,
                   unmeasured: float | None = 0.0) -> dict:
    """Variance of the curvature noise of the window fit, per window (per n_br), 1/mm^2.

    Noise beyond its correlation length ``d`` (the fit window ``5 n_br h`` plus the smoothing
    window) is independent, so half the mean squared difference of the curvature at lag ``d``
    is ``D(d) = v + b d + a d^2``: ``a d^2`` for a curvature that varies smoothly over the
    lags, ``b d`` for one that changes over less than a lag (a bend ending, a curvature
    reversing: the share of pairs straddling it grows as ``d``). Three lags give
    ``v = 3 D(d) - 3 D(2 d) + D(3 d)`` (Richardson). Two lags, ``v = (4 D(d) - D(2 d)) / 3``,
    leave ``2 b d / 3`` in ``v``: on jittered S-curves of radius 100-150 px (the curvature
    reversing once) they read 1.5-2.5 times the noise, three lags 0.4-1.2 (0.85-1.25 on arcs,
    as two lags), and removing the excess took the energy of the network generator's
    typical scans from -19 % to -15 % and of its 25 px/mm scans from |e| 26 % to 15 %
    (``test_noise_variance_where_the_curvature_reverses``). The third lag needs fitted stretches
    of ``6 d``, and only such stacks enter: on shorter ones (``4 d``) the signal's own
    differences are not of that form (a curvature concentrated at both ends of a short stack)
    and the typical scans read -19 % again. A scan without such stretches has no measured
    floor and nothing is removed: on 25 px/mm scans of 20-60 stacks, 2 of 8 (-10 and +8 %; the
    two-lag estimate there, -38 and -40 %); on a lone fork of gentle arcs the noise stays
    (``tests/crosssection/test_fork_energy.py``). Pooled over the scan's stacks of each n_br:
    the noise comes from the scan (resolution, blur, edge noise), not from one stack; a stack
    whose own estimate is an outlier (:func:`_without_outliers`) holds real bending at the
    lags' scale and is left out. Windows
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
        Pairs at the first lag needed for a window's own estimate, counted one per pixel of
        arc whatever the skeleton's direction (its samples are 1 to 1.4 px apart); the pooled
        estimate weights each stack by the same count.
    unmeasured : float or None
        The value of every window when none could be measured. A measured estimate at or
        below 0 is 0: noise below what the lags resolve, which is not the same as unknown.

    Returns
    -------
    dict
        n_br -> v (1/mm^2, >= 0); every n_br of ``n_br`` present (``unmeasured`` when no window
        could be measured).
    """
    sm = default_smooth_px(thickness_px) if smooth_px is None else int(smooth_px)
    nbs = sorted({max(1, int(x)) for x in n_br})
    window = {nb: 5.0 * nb * float(thickness_px) for nb in nbs}
    measured = {}
    for nb in nbs:
        lag = (window[nb] + sm) / float(px_per_mm)
        per_stack, weights = [], []
        for prof, n in zip(profiles, n_br):
            if max(1, int(n)) != nb or prof.closed:
                continue
            lags = [_lag_variance(prof, m * lag) for m in (1.0, 2.0, 3.0)]
            if any(x is None for x in lags):
                continue
            per_stack.append(3.0 * lags[0] - 3.0 * lags[1] + lags[2])
            # pairs per pixel of arc, not per sample: a diagonal skeleton has 1.4 px between
            # samples, and counted in samples a scan turned by 45 degrees can lose its estimate
            # (a sample scan's one 5-mm stack: 180 pairs against 215 unturned, 200 needed)
            fitted = prof.s_mm[prof.fit_stop - 1] - prof.s_mm[prof.fit_start]
            weights.append((fitted - lag) * float(px_per_mm))
        v, w = _without_outliers(np.asarray(per_stack, float), np.asarray(weights, float))
        if w.sum() >= min_pairs:
            measured[nb] = max(float(v @ w) / float(w.sum()), 0.0)
    out = {}
    for nb in nbs:
        if nb in measured:
            out[nb] = measured[nb]
        elif measured:
            ref = min(measured, key=lambda m: abs(m - nb))
            out[nb] = measured[ref] * (window[ref] / window[nb]) ** 5
        else:
            out[nb] = unmeasured
    return out
