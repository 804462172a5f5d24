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
   its centre (:func:`_fitted_kappa`). The window is capped at half the fitted length
   (``max_window_frac``), a closed loop's at half the loop: a longer parabola cannot
   resolve an S-shaped stack. Where the window turns by more than two radians (a U-turn of
   one sheet of radius 2 h read +22 %, one of three sheets at 2 h lost a third), the sample
   is fitted again over a window scaled to turn by two (:func:`_tight_refits`; not with the
   paper's method, ``method="paper"``).
3. **Fork zones.** Near a junction the bands of the stacks meeting there overlap: the image
   holds no centreline of this stack, and the skeleton hooks into the medial-axis fork point.
   The maximal disc at the fork (radius r_J, the inscribed ink radius at the junction) touches
   both bands, so the skeleton reaches the band's own centre only about one r_J beyond the
   overlap; layers that peel apart tangentially stay in contact, their bands merged, further
   still (:func:`contact_arc_px`); a band whose ink stays wider than its own beyond the fork
   (a width stepping there, :func:`_merged_arcs`) has its skeleton in that ink's middle, and
   it jogs onto its own one r_J beyond; and the sliding average carries the hook half a
   smoothing window beyond: the fork zone is
   ``max(2 max(n_br h, r_J), contact, merged + r_J) + (smooth_px - 1) / 2`` of arc from the
   junction (measured on drawn tangential forks: arms' ``int kappa^2 ds``
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
   Free ends keep the paper's rule (their skeleton is shortened, not merged). With the
   ``walls`` and ``missing`` methods the curvature is bounded by ``2 / (n_br h)``: the innermost layer of a stack cannot have a negative radius,
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
stack's ``int kappa^2 ds`` before the floor is removed (the energy reported is that integral less
the floor), at most 1 (a gentle stack whose removed floor exceeds what is left of its energy
rests on the floor entirely; NaN for a path of fewer than 2 samples). Despite its name it is
a modelled share, not a standard error: it ranks the stacks' errors, it does not bound them
(an energy read more than twice the truth is never within it): a stack whose
share is at most 0.5 is read within a factor 1.5 for 79-100 % of the true energy of such
stacks, one above 0.5 for 0-86 % (four generators; ``benchmarks/stack_energy_errors.py``).

5. **Sign.** Positive when the path, followed from its start to its end, turns
   counter-clockwise in the image as displayed (x = column to the right, y = -row).

Per stack: kappa_pm = (1/l) int kappa ds, kappa_plus = (1/l) int |kappa| ds,
kappa_m = |kappa_pm| (paper, section "Curvature of branches"), in 1/mm, trapezoid rule.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial.distance import cdist

from crosssection.core import polyline
from crosssection.core.errors import ParameterError
from crosssection.params import CURVATURE_METHODS as METHODS
from crosssection.params import _number
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
        Share of the stack's ``int kappa^2 ds`` resting on the fork-zone model or the noise
        floor (module docstring: it ranks errors, it does not bound them; NaN for the paper
        method and for a path of fewer than 2 samples).
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


def _pymax(a, b):
    """Python's ``max(a, b)`` element by element: ``a`` unless ``b`` is larger (NaN kept)."""
    return np.where(b > a, b, a)


def _pymin(a, b):
    """Python's ``min(a, b)`` element by element: ``a`` unless ``b`` is smaller."""
    return np.where(b < a, b, a)


def _range_sums(x, lo, hi):
    """``np.add.reduce(x[lo[i]:hi[i]])`` of every range, to the last bit (0.0 where empty).

    ``np.add.reduceat`` sums each of its ranges by numpy's pairwise summation, but starting
    from the range's first value where a reduction starts from 0.0: every range is gathered
    behind a 0.0 of its own.
    """
    n = np.maximum(hi - lo, 0) + 1
    if len(n) == 0 or len(x) == 0:
        return np.zeros(len(n))
    pos = np.zeros(len(n), np.int64)
    np.cumsum(n[:-1], out=pos[1:])
    idx = np.arange(int(n.sum())) + np.repeat(lo - 1 - pos, n)
    idx[pos] = 0
    vals = x[idx]
    vals[pos] = 0.0
    return np.add.reduceat(vals, pos)


def _trapz_ranges(y, x, lo, hi):
    """``np.trapezoid(y[lo[i]:hi[i]], x[lo[i]:hi[i]])`` of every range, to the last bit: its
    products, then numpy's sum (:func:`_range_sums`)."""
    return _range_sums((x[1:] - x[:-1]) * (y[1:] + y[:-1]) / 2.0, lo, hi - 1)


@njit(cache=True)
def _bisect(s, lo, hi, v, right):  # pragma: no cover - numba
    """``np.searchsorted(s[lo[q]:hi[q]], v[q], side="right" if right[q] else "left")`` of
    every query ``q``: numpy's bisection, step for step, and its order of floats (NaN after
    everything). Compiled: the 2 800 searches of a dense 2000 x 2000 scan in 0.2 ms, against
    1.1 us a query for a call of ``np.searchsorted`` each."""
    out = np.empty(lo.shape[0], np.int64)
    for q in range(lo.shape[0]):
        i, j, x = lo[q], hi[q], v[q]
        while i < j:
            mid = i + ((j - i) >> 1)
            y = s[mid]
            if right[q]:
                go = not (x < y or (y != y and x == x))
            else:
                go = y < x or (x != x and y == y)
            if go:
                i = mid + 1
            else:
                j = mid
        out[q] = i - lo[q]
    return out


def _searches(s, lo, hi, values, sides):
    """``np.searchsorted(s[lo[i]:hi[i]], v[i], side)`` of every query ``v[i]`` of every
    array ``v`` of ``values``, on its side of ``sides`` (``"l"`` or ``"r"`` each), in one
    call of :func:`_bisect`.

    Returns
    -------
    ndarray (len(values), len(lo)) int
    """
    k = len(values)
    if len(lo) == 0:
        return np.zeros((k, 0), np.int64)
    return _bisect(s, np.tile(lo, k), np.tile(hi, k), np.concatenate(values).astype(np.float64),
                   np.repeat(np.array([side == "r" for side in sides]), len(lo))).reshape(k, -1)


def _profile_sums(s_px, kappa_px, offs, px_per_mm, fit_start, fit_stop, forks, walled_px,
                  noise_coef, rel):
    """The arrays and sums of many profiles (:func:`_profiles`), with the arithmetic of
    one profile at a time.

    With ``rel``, the relative uncertainty of ``int kappa^2 ds``: (the part of it not
    measured on a free centreline + the noise floor ``noise_coef`` per mm of length) / the
    integral. Not measured on a free centreline: the fork zones extrapolated (beyond the
    fitted samples at a fork end; all of a stack fitted whole at a fork, whose fork zones
    would cover it), and the ``walled_px`` of arc at each end followed along a merged band's
    wall (its layers assumed to lie along it).

    Returns
    -------
    s_mm, kappa : ndarray (N,)
    sums : ndarray (M, 4)
        Length (mm), mean signed and mean absolute curvature, and with ``rel`` the relative
        uncertainty of ``int kappa^2 ds`` (NaN without).
    """
    s_mm = s_px / px_per_mm
    kappa = kappa_px * px_per_mm
    a, b = offs[:-1], offs[1:]
    n = b - a
    sums = np.full((len(n), 4), np.nan)
    if len(s_mm) == 0:
        sums[:, 0] = 0.0
        return s_mm, kappa, sums
    last = np.clip(b - 1, 0, len(s_mm) - 1)
    length = np.where(n > 1, s_mm[last] - s_mm[np.minimum(a, last)], 0.0)
    sums[:, 0] = length
    ak = np.abs(kappa)
    rows = (kappa, ak, kappa * kappa) if rel else (kappa, ak)
    # the products of the trapezoid rule (np.trapezoid's) of kappa, |kappa| (and kappa^2),
    # each profile's behind a 0.0 (in the place of the product that joins it to the previous
    # profile): np.add.reduceat sums each profile's as numpy's reduction does, from 0.0
    ds = s_mm[1:] - s_mm[:-1]
    prods = np.zeros((len(rows), len(s_mm)))
    for row, v in zip(prods, rows):
        np.multiply(ds, v[1:] + v[:-1], out=row[1:])
        np.divide(row[1:], 2.0, out=row[1:])
    some = np.flatnonzero(a < len(s_mm))
    prods[:, a[some]] = 0.0
    trap = np.zeros((len(rows), len(n)))
    trap[:, some] = np.add.reduceat(prods, a[some], axis=1)
    on = np.flatnonzero(length > 0)
    sums[on, 1] = trap[0, on] / length[on]
    sums[on, 2] = trap[1, on] / length[on]
    mean = np.flatnonzero(~(length > 0) & (n > 0))
    sums[mean, 1] = _range_sums(kappa, a[mean], b[mean]) / n[mean]
    sums[mean, 2] = _range_sums(ak, a[mean], b[mean]) / n[mean]
    if not rel:
        return s_mm, kappa, sums
    r = np.flatnonzero(n >= 2)
    a, b, n = a[r], b[r], n[r]
    f0, f1 = forks[r, 0], forks[r, 1]
    t0, t1 = fit_start[r], fit_stop[r]
    q0, q1 = _searches(s_mm, a, b, [s_mm[a] + walled_px[r, 0] / px_per_mm,
                                    s_mm[b - 1] - walled_px[r, 1] / px_per_mm], "rl")
    z0 = np.maximum(np.where(f0, t0, 0), q0 - 1)
    z1 = np.minimum(np.where(f1, t1, n), q1 + 1)
    # fitted whole because its fork zones would cover it: every sample is a fork's
    whole = (f0 | f1) & (t0 == 0) & (t1 == n)
    part = (z1 - z0 > 1) & ~whole
    fitted = np.zeros(len(r))
    # (the products of samples z0:z1 at z0 + 1:z1)
    fitted[part] = _range_sums(prods[2], (a + z0 + 1)[part], (a + z1)[part])
    total = trap[2, r]
    noise = noise_coef[r] * length[r]
    sums[r, 3] = ((_pymax(total - fitted, 0.0) + noise)
                  / _pymax(_pymax(total, noise), 1e-300))
    return s_mm, kappa, sums


def _zone_sides(s, k, offs, t0, t1, nb, closed, forks, known, thickness_px, px_per_mm,
                window_px, max_window_frac, shifted):
    """The set-up of :func:`_fill_fork_zones` for many stacks: the curvature clipped to the
    bound, in place, and per side (0: the start, 1: the end) of every stack its trend's
    samples ``lo:hi`` and its zone ``z0:z1`` (``side[:, :, 0:4]``), and whether the side
    takes a trend (``side[:, :, 4]``).

    Returns
    -------
    kmax, w : ndarray (M,)
        The bound, 1/mm, and the window fitted, mm.
    side : ndarray (2, M, 5) int
    """
    a, b = offs[:-1], offs[1:]
    n = b - a
    m = len(n)
    kmax = 2.0 * px_per_mm / (nb * thickness_px)
    kr = np.repeat(kmax, n)
    k[:] = np.where(k < -kr, -kr, np.where(k > kr, kr, k))
    w = np.zeros(m)
    side = np.zeros((2, m, 5), np.int64)
    # an unfitted stack (t1 == t0) has no trend to continue: _fill_unfitted_stacks fills it
    act = np.flatnonzero(~closed & (n >= 3) & ((t0 > 0) | (t1 < n) | forks[:, 0] | forks[:, 1])
                         & (t1 > t0))
    if len(act) == 0:
        return kmax, w, side
    a, b, n, f0, f1 = a[act], b[act], n[act], t0[act], t1[act]
    # the window fitted (_fitted_window_mm; a NaN window_px: 5 n_br h)
    ww = (5.0 * nb[act] * thickness_px if window_px != window_px
          else np.full(len(act), window_px)) / px_per_mm
    if max_window_frac > 0:
        ww = _pymin(ww, max_window_frac * (s[a + f1 - 1] - s[a + f0]))
    w[act] = ww
    # shifted fits within w/2 of the zone: the trend window starts beyond them
    off = 0.5 * ww if shifted else np.zeros(len(act))
    first = s[a + f0] + off
    last = s[a + f1 - 1] - off
    c0, c1, lo_end, hi_start = _searches(s, a, b, [first, last, first + ww, last - ww], "lrlr")
    for e in range(2):
        if e == 0:
            lo, hi, z0, z1 = c0, np.minimum(np.maximum(lo_end, c0 + 3), f1), 0, c0
        else:
            lo, hi, z0, z1 = np.maximum(np.minimum(hi_start, c1 - 3), f0), c1, c1, n
        lo, hi = np.maximum(lo, f0), np.minimum(hi, f1)
        whole = (f0 == 0) if e == 0 else (f1 == n)
        side[e, act, 0] = lo
        side[e, act, 1] = hi
        side[e, act, 2] = z0
        side[e, act, 3] = z1
        # a stack fitted whole (its zones would cover it) has measured fits at its ends,
        # shifted onto one window's mean: they give way to a trend only where the scan's
        # noise is known and the trend exceeds it
        side[e, act, 4] = forks[act, e] & (hi - lo >= 3) & ~(whole & ~known[act])
    return kmax, w, side


def _arc_lengths(seg, a, n):
    """The arc length of every point from its path's start (path ``i`` at ``a[i]:a[i] +
    n[i]``, the step from point ``j`` to ``j + 1`` ``seg[j]``; a path's last entry of ``seg``
    is not one of its steps): each path's ``np.cumsum`` of its steps after a 0.

    One ``np.cumsum`` over all paths, each path's steps preceded by minus the previous path's
    sum: ``x + (-x)`` is exactly 0.0, and that sum is ``np.bincount``'s, which adds its
    weights in input order as the running sum does.
    """
    steps = seg.copy()
    steps[(a + n - 1)[n > 0]] = 0.0
    path = np.repeat(np.arange(len(n)), n)
    sums = np.bincount(path, weights=steps, minlength=len(n))
    if not np.isfinite(sums).all():
        return np.concatenate([np.cumsum(np.r_[0.0, steps[i:i + k - 1]]) for i, k in zip(a, n)
                               if k] + [np.zeros(0)])
    run = np.cumsum(np.insert(steps, a, np.r_[0.0, -sums[:-1]]))
    return run[np.arange(len(seg)) + path]


def _fit_ranges(r, c, offs, closed, nb, trims, unfitted, thickness_px, window_px,
                max_window_frac):
    """Arc length and fitted samples of many smoothed centrelines (:func:`_paper_profiles`).

    Returns
    -------
    s_px : ndarray (N,)
        Arc length from each path's start.
    total : ndarray (M,)
        Length of each path (a closed one with its closing segment), px.
    mode : ndarray (M,) int
        0: nothing fitted (fewer than three points, or ``unfitted``), 1: a closed loop,
        2: the open path's samples ``t0:t1``.
    t0, t1 : ndarray (M,) int
    half_w : ndarray (M,)
        Half window of the fits, px.
    """
    a, b = offs[:-1], offs[1:]
    n = b - a
    size = len(r)
    # seg[j] joins points j and j + 1 of a path, and a closed loop's last point to its first
    seg = np.zeros(size)
    seg[:-1] = np.hypot(r[1:] - r[:-1], c[1:] - c[:-1])
    ring = closed & (n > 0)
    first, last = a[ring], b[ring] - 1
    seg[last] = np.hypot(r[first] - r[last], c[first] - c[last])
    total = _range_sums(seg, a, a + np.where(ring, n, np.maximum(n - 1, 0)))
    s_px = _arc_lengths(seg, a, n)
    win = 5.0 * nb * thickness_px if window_px != window_px else np.full(len(n), window_px)
    half_w = 0.5 * win
    mode = np.zeros(len(n), np.int64)
    t0 = np.zeros(len(n), np.int64)
    t1 = n.copy()
    fits = n >= 3
    # no centreline of its own (stack_profiles): missing data, filled from its neighbours
    t1[fits & unfitted & ~closed] = 0
    # a closed loop is unrolled once on each side; a window never exceeds half the loop (a
    # parabola fitted round a whole circle reads no curvature)
    loop = fits & closed
    mode[loop] = 1
    half_w[loop] = _pymin(half_w[loop], 0.25 * total[loop])
    op = np.flatnonzero(fits & ~closed & ~unfitted)
    if len(op) == 0:
        return s_px, total, mode, t0, t1, half_w
    # the skeleton is distorted within about a stack width of a junction or a free end: the
    # fits use the samples beyond the trims, the end samples take the curvature of the
    # nearest fitted one
    a, b = a[op], b[op]
    floor = nb[op] * thickness_px
    tr0, tr1 = _pymax(floor, trims[op, 0]), _pymax(floor, trims[op, 1])
    f0, f1 = _searches(s_px, a, b, [tr0, s_px[b - 1] - tr1], "lr")
    # (the span is read only where three samples or more are left)
    span = s_px[a + np.maximum(f1 - 1, 0)] - s_px[np.minimum(a + f0, size - 1)]
    whole = (f1 - f0 < 3) | (span < tr0 + tr1)
    f0 = np.where(whole, 0, f0)
    f1 = np.where(whole, b - a, f1)
    if max_window_frac > 0:
        half_w[op] = _pymin(half_w[op],
                            0.5 * max_window_frac * (s_px[a + f1 - 1] - s_px[a + f0]))
    t0[op], t1[op], mode[op] = f0, f1, 2
    return s_px, total, mode, t0, t1, half_w


def _fit_arrays(r, c, s_px, offs, total, mode, t0, t1):
    """The entries of :func:`_fit_curvatures` for the paths :func:`_fit_ranges` fits: in a
    right-handed frame (x = col, y = -row), an open path's samples ``t0:t1``, a closed one
    unrolled once on each side (its points ``n .. 2 n - 1`` wanted).

    Returns
    -------
    x, y, s : ndarray
        Coordinates and arc length of the fitted paths, one after the other.
    start, length, i0, count : ndarray (F,) int
        Per fitted path: its first point and its length in ``x``, and the wanted points.
    """
    fitted = np.flatnonzero(mode != 0)
    loop = mode[fitted] == 1
    # pieces of the fitted paths: a loop's three turns, an open path's fitted part
    reps = np.where(loop, 3, 1)
    first = np.cumsum(reps) - reps
    path = np.repeat(fitted, reps)
    turn = np.arange(len(path)) - np.repeat(first, reps)
    ring = mode[path] == 1
    a = offs[path]
    idx, pos, n = polyline.ranges(np.where(ring, a, a + t0[path]),
                                  np.where(ring, offs[path + 1], a + t1[path]))
    # a loop's arc length continued backwards over its first turn, forwards over its third
    shift = np.where(ring & (turn != 1), np.where(turn == 0, -total[path], total[path]), 0.0)
    count = np.where(loop, n[first], t1[fitted] - t0[fitted])
    return (c[idx], -r[idx], s_px[idx] + np.repeat(shift, n), pos[first],
            np.where(loop, 3 * count, count), np.where(loop, count, 0), count)


def _fitted_kappa(s_px, total, offs, mode, t0, t1, half_w, shift, kin):
    """Every sample's curvature from the fits (``kin``, the fitted paths' wanted points one
    after the other): the fitted samples their fit, the others the nearest fitted one,
    nothing fitted 0; a closed loop's first sample repeated at its end.

    With ``shift``, the fits of the samples within ``half_w`` of an end of the fitted part
    all fit the window next to that end, so they hold its fit read at its centre, the
    nearest sample fitted on a window centred on it. Read again in the tangent frame of every
    end sample, the same window gave a curvature that turns with the skeleton's last pixels:
    where the skeleton hooks into a fork of merged ink, the end samples' frames turn with the
    hook, and the parabola, fitted in a frame oblique to the window, bends with them. A
    7-layer link between two forks of a compacted rod, blurred by 0.75 px, read 87 times the
    ``int kappa^2 ds`` it read unblurred, at the curvature bound at its end
    (docs/validation/README.md, "Shifted end windows").

    Returns
    -------
    s, kappa : ndarray
        Arc length (px) and curvature (1/px), path ``i`` at ``out[i]:out[i + 1]``.
    out : ndarray (M + 1,) int
    """
    a, b = offs[:-1], offs[1:]
    n = b - a
    loop = mode == 1
    out = offs.copy()
    np.cumsum(loop, out=out[1:])
    out[1:] += b  # a loop's closing sample added
    moved = np.repeat(out[:-1] - a, n)  # from a sample's index in s_px to its index in s
    s = np.empty(out[-1])
    s[np.arange(len(s_px)) + moved] = s_px
    s[out[1:][loop] - 1] = total[loop]
    kappa = np.zeros(out[-1])
    fitted = np.flatnonzero(mode != 0)
    if len(fitted) == 0:
        return s, kappa, out
    # per fitted path: its fitted part f0:f1, where its fits start in kin, and the wanted
    # points (relative to f0) whose own fit every sample takes, the nearest of them
    f0 = np.where(loop, 0, t0)[fitted]
    f1 = np.where(loop, n, t1)[fitted]
    q = np.zeros(len(fitted), np.int64)
    np.cumsum((f1 - f0)[:-1], out=q[1:])
    lo = np.zeros(len(fitted), np.int64)
    hi = f1 - f0 - 1
    if shift:
        # the fits centred on their own sample (_centred_fits of the fitted part)
        op = np.flatnonzero(~loop[fitted])
        p = fitted[op]
        lo_p, hi_p = a[p] + t0[p], a[p] + t1[p]
        c0, c1 = _searches(s_px, lo_p, hi_p, [s_px[lo_p] + half_w[p], s_px[hi_p - 1] - half_w[p]],
                           "lr")
        cut = c0 < c1
        lo[op[cut]] = c0[cut]
        hi[op[cut]] = c1[cut] - 1
    idx, pos, cnt = polyline.ranges(a[fitted], b[fitted])
    j = idx - np.repeat(a[fitted], cnt)
    f0r = np.repeat(f0, cnt)
    src = np.minimum(np.maximum(np.minimum(np.maximum(j, f0r), np.repeat(f1 - 1, cnt)) - f0r,
                                np.repeat(lo, cnt)), np.repeat(hi, cnt))
    kappa[idx + moved[idx]] = kin[src + np.repeat(q, cnt)]
    ends = out[1:][loop] - 1
    kappa[ends] = kappa[out[:-1][loop]]
    return s, kappa, out


def _profiles(s_px, kappa_px, offs, px_per_mm, closed, rc, fit, *, forks=None, walled_px=None,
              noise_coef=None, noise_var=None) -> list:
    """Curvature profiles of many stacks from flat arrays (stack ``i`` at
    ``offs[i]:offs[i + 1]``): arc length and curvature in mm, their means, and with ``forks``
    the relative uncertainty of ``int kappa^2 ds`` (:func:`_profile_sums`).

    Parameters
    ----------
    s_px, kappa_px : ndarray (N,)
        Arc length (px) and curvature (1/px) of every sample.
    offs : ndarray (M + 1,) int
    px_per_mm : float
    closed : sequence of bool
    rc : sequence of (n, 2) arrays
        Centreline of every stack.
    fit : ndarray (M, 2) int
        ``fit_start`` and ``fit_stop``.
    forks : ndarray (M, 2) bool, optional
        Fork ends; with them ``walled_px`` (M, 2) float, ``noise_coef`` (M,) (the noise floor
        of ``int kappa^2 ds`` per mm of length) and ``noise_var`` (the profiles'
        ``noise_var_per_mm2``).

    Returns
    -------
    list of CurvatureProfile
    """
    m = len(offs) - 1
    rel = forks is not None
    if not rel:
        forks = np.zeros((m, 2), np.bool_)
        walled_px = np.zeros((m, 2))
        noise_coef = np.zeros(m)
    fit = np.asarray(fit, np.int64).reshape(m, 2)
    s_mm, kappa, sums = _profile_sums(
        np.asarray(s_px, float), np.asarray(kappa_px, float), np.asarray(offs, np.int64),
        float(px_per_mm), fit[:, 0], fit[:, 1], np.asarray(forks, np.bool_).reshape(m, 2),
        np.asarray(walled_px, float).reshape(m, 2), np.asarray(noise_coef, float), rel)
    bounds = np.asarray(offs).tolist()
    fit = fit.tolist()
    out = []
    for i, (length, kpm, kplus, r) in enumerate(sums.tolist()):
        a, b = bounds[i], bounds[i + 1]
        out.append(CurvatureProfile(
            s_mm=s_mm[a:b], kappa_per_mm=kappa[a:b], length_mm=length, kappa_pm=kpm,
            kappa_plus=kplus, kappa_m=abs(kpm), closed=bool(closed[i]),
            rc_px=np.asarray(rc[i], float), fit_start=fit[i][0], fit_stop=fit[i][1],
            # a share: the removed noise floor can exceed what is left of a gentle stack
            energy_rel_uncertainty=min(r, 1.0), noise_var_per_mm2=noise_var[i] if rel else 0.0))
    return out


@njit(cache=True)
def _window_fits(X, Y, S, off, lens, half_w, i0, cnt, shift):  # pragma: no cover - numba
    """The parabola of every wanted point of :func:`_fit_curvatures`, by the scans and sums
    the fits are defined by.

    The tangent from the chord between the farthest points within 2 px of arc on each side
    (``s[i] - s[k] <= 2``, point after point from ``i``), the window the points within
    ``half_w`` of arc, shifted inwards at an end keeping its length (``shift``); on a path
    whose arc length never decreases the window's ends are found from the previous point's.
    Then the sums over the window of ``u, u^2 .. u^6, v, u v, u^2 v`` in the point's tangent
    frame, each window's samples added one after the other from its first in the point's own
    frame (running sums over a path in a common frame would subtract sums of u^6 grown over
    thousands of px), and the least-squares parabola ``v = a u^2 + b u + c`` from them
    (Cramer's rule on [[S4 S3 S2],[S3 S2 S1],[S2 S1 S0]]).

    Compiled: the fits of the 346 paths of a dense 2000 x 2000 scan (633 000 window samples)
    in 4.5 ms, against 11 ms with the scans and the solutions by numpy around the same sums
    compiled.

    Returns
    -------
    ndarray (4, cnt.sum())
        Per wanted point, path after path: the parabola's ``a`` and ``b``, and the
        projections ``c2``, ``c1`` of ``u^4`` on the window (the same system for the
        right-hand side ``S4, S5, S6``). NaN where the chord has zero length, the window
        holds fewer than three points, or the system is singular (its determinant not above
        1e-9 of ``S4 S2 S0``).
    """
    total = 0
    for f in range(cnt.shape[0]):
        total += cnt[f]
    out = np.empty((4, total))
    q = 0
    for f in range(cnt.shape[0]):
        st = off[f]
        en = st + lens[f] - 1
        ordered = True
        for k in range(st, en):
            if not S[k + 1] >= S[k]:
                ordered = False
                break
        a0 = b0 = st + i0[f]
        for i in range(st + i0[f], st + i0[f] + cnt[f]):
            si = S[i]
            # tangent from a central chord of about 2 px each side (b corrects the residual
            # tilt)
            lo = i
            while lo != st and si - S[lo - 1] <= 2.0:
                lo -= 1
            hi = i
            while hi != en and S[hi + 1] - si <= 2.0:
                hi += 1
            tx = X[hi] - X[lo]
            ty = Y[hi] - Y[lo]
            tn = math.sqrt(tx * tx + ty * ty)
            s_lo = si - half_w[f]
            s_hi = si + half_w[f]
            if shift[f]:
                if s_lo < S[st]:
                    x = s_hi + (S[st] - s_lo)
                    s_hi = x if x < S[en] else S[en]
                    s_lo = S[st]
                elif s_hi > S[en]:
                    x = s_lo - (s_hi - S[en])
                    s_lo = x if x > S[st] else S[st]
                    s_hi = S[en]
            if not ordered or i < a0:
                a0 = i
            if not ordered or i > b0:
                b0 = i
            while a0 != st and S[a0 - 1] >= s_lo:
                a0 -= 1
            while a0 != i and not S[a0] >= s_lo:
                a0 += 1
            while b0 != en and S[b0 + 1] <= s_hi:
                b0 += 1
            while b0 != i and not S[b0] <= s_hi:
                b0 -= 1
            a = b = c2 = c1 = np.nan
            if tn != 0.0 and b0 - a0 >= 2:
                tx = tx / tn
                ty = ty / tn
                # -0.0 + x is x: the sums start from their first sample
                s1 = s2 = s3 = s4 = s5 = s6 = t0 = t1 = t2 = -0.0
                for j in range(a0, b0 + 1):
                    dx = X[j] - X[i]
                    dy = Y[j] - Y[i]
                    u = dx * tx + dy * ty
                    v = dy * tx - dx * ty
                    u2 = u * u
                    u4 = u2 * u2
                    s1 += u
                    s2 += u2
                    s3 += u2 * u
                    s4 += u4
                    s5 += u4 * u
                    s6 += u4 * u2
                    t0 += v
                    t1 += u * v
                    t2 += u2 * v
                s0 = (b0 - a0) + 1.0
                m1 = s2 * s0 - s1 * s1
                m2 = s3 * s0 - s1 * s2
                det = s4 * m1 - s3 * m2 + s2 * (s3 * s1 - s2 * s2)
                if abs(det) > 1e-9 * s4 * s2 * s0:
                    a = (t2 * m1 - s3 * (t1 * s0 - s1 * t0) + s2 * (t1 * s1 - s2 * t0)) / det
                    b = (s4 * (t1 * s0 - t0 * s1) - t2 * m2 + s2 * (s3 * t0 - t1 * s2)) / det
                    c2 = (s6 * m1 - s3 * (s5 * s0 - s1 * s4) + s2 * (s5 * s1 - s2 * s4)) / det
                    c1 = (s4 * (s5 * s0 - s4 * s1) - s6 * m2 + s2 * (s3 * s4 - s5 * s2)) / det
            out[0, q] = a
            out[1, q] = b
            out[2, q] = c2
            out[3, q] = c1
            q += 1
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

    All paths in one call of :func:`_fit_curvatures`: numpy has no fit over a moving window
    in a moving frame, and its overhead per call is that of a whole path's fits.

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
    lens = np.array([len(fits[k][2]) for k in live], np.int64)
    off = np.zeros(len(live), np.int64)
    np.cumsum(lens[:-1], out=off[1:])
    X = np.concatenate([fits[k][0] for k in live]).astype(float, copy=False)
    Y = np.concatenate([fits[k][1] for k in live]).astype(float, copy=False)
    S = np.concatenate([fits[k][2] for k in live]).astype(float, copy=False)
    cnt = np.array([nw[k] for k in live], np.int64)
    kappa = _fit_curvatures(
        X, Y, S, off, lens, np.array([float(fits[k][3]) for k in live]),
        np.array([int(fits[k][4]) for k in live], np.int64), cnt,
        np.array([bool(fits[k][6]) for k in live]), np.array([bool(fits[k][7]) for k in live]))
    first = np.zeros(len(live), np.int64)
    np.cumsum(cnt[:-1], out=first[1:])
    out = [None] * len(fits)
    for k_, a_, c_ in zip(live, first.tolist(), cnt.tolist()):
        out[k_] = kappa[a_:a_ + c_]
    return [np.zeros(max(c, 0)) if o is None else o for o, c in zip(out, nw)]


def _fit_curvatures(X, Y, S, off, lens, half_w, i0, cnt, correct, shift):
    """:func:`_parabola_curvatures` of paths laid one after the other in flat arrays.

    The windows and the parabolas are compiled (:func:`_window_fits`); the curvature
    ``2 a / (1 + b^2)^1.5`` is numpy's, whose power differs from the C library's (numba's) in
    the last bit of about one value in twenty.

    Parameters
    ----------
    X, Y, S : ndarray (N,)
        Coordinates and arc length of all paths.
    off, lens : ndarray (F,) int
        Path ``f`` is ``off[f]:off[f] + lens[f]``.
    half_w : ndarray (F,)
    i0, cnt : ndarray (F,) int
        The wanted points ``i0 .. i0 + cnt - 1`` of every path (``cnt`` >= 1).
    correct, shift : ndarray (F,) bool

    Returns
    -------
    ndarray (cnt.sum(),)
        The curvature of the wanted points, path after path, 1/px.
    """
    if len(cnt) == 0:
        return np.zeros(0)
    a, b, c2, c1 = _window_fits(
        np.asarray(X, np.float64), np.asarray(Y, np.float64), np.asarray(S, np.float64),
        np.asarray(off, np.int64), np.asarray(lens, np.int64),
        np.asarray(half_w, np.float64), np.asarray(i0, np.int64), np.asarray(cnt, np.int64),
        np.asarray(shift, np.bool_))
    ok = np.isfinite(a)
    with np.errstate(invalid="ignore", over="ignore"):
        k = 2.0 * a / (1.0 + b * b) ** 1.5
        correct = np.repeat(correct, cnt)
        if correct.any():
            # A circle y = x^2/(2R) + x^4/(8R^3) + ... : the x^4 term leaks into the fitted a
            # and b by the projections (c2, c1) of x^4 on the window's samples. Remove it (two
            # fixed-point steps; exact to O((kappa X)^2)).
            kc = k
            for _ in range(2):
                k3 = kc * kc * kc / 8.0
                at = a - c2 * k3
                bt = b - c1 * k3
                kc = 2.0 * at / (1.0 + bt * bt) ** 1.5
            k = np.where(correct, kc, k)
    k[~ok] = 0.0  # not fitted, or a singular fit
    return k


#: Largest turn of the centreline over half a fit window, radians: a sample whose window
#: turns by more than twice this in all is fitted again over a shorter one
#: (:func:`_tight_refits`).
_WINDOW_MAX_TURN = 1.0
#: Refits of one path at most (:func:`_tight_refits`).
_REFITS = 4


def _tight_refits(kin, X, Y, S, start, length, half_w, i0, count, correct, shift):
    """The fits of the samples whose window turns by more than twice
    :data:`_WINDOW_MAX_TURN`, fitted again over shorter windows.

    The parabola in the tangent frame follows a bend only while the window turns by less
    than about a radian on each side: beyond it the arms of a tight turn come back across the
    frame, and the fit overshoots (a window centred on the turn) or spreads the turn over
    the window (one beside it). U-turns of one to three sheets
    (``python benchmarks/u_turns.py --raw``) read +22 to +118 % where the half window turned
    by 1.25-2 rad (1 sheet of radius 2 h, 2 sheets of 2.5-4 h, 3 sheets of 4-5 h), and within
    -7 to +1 % where it turned by 1 rad or less. The turn of a window is the integral of
    ``|kappa|`` over it from the current fits (a turn spread by a long window is still the
    turn); a path is fitted again over one window, the least its offending samples ask (that
    window scaled to turn by twice :data:`_WINDOW_MAX_TURN`, at least 2 px), which replaces
    their fits, up to :data:`_REFITS` times.
    """
    if not len(count):
        return kin
    kin = kin.copy()
    first = np.zeros(len(count) + 1, np.int64)
    np.cumsum(count, out=first[1:])
    k_abs = np.abs(kin)
    # a window turning by less than this holds no turn it could miss
    # (every fitted path has a wanted sample: count >= 1)
    peak = np.maximum.reduceat(k_abs * np.repeat(half_w, count), first[:-1])
    limit = 2.0 * _WINDOW_MAX_TURN
    for f in np.flatnonzero(peak > 0.25 * limit).tolist():
        a, b = first[f], first[f + 1]
        n = b - a
        loop = length[f] == 3 * n  # unrolled once on each side (_fit_arrays)
        s_all = S[start[f]:start[f] + length[f]]
        s_want = s_all[i0[f]:i0[f] + n]
        hw = np.full(n, float(half_w[f]))
        for _ in range(_REFITS):
            k = np.abs(kin[a:b])
            ks, ss = (np.tile(k, 3), s_all) if loop else (k, s_want)
            turn = np.concatenate([[0.0], np.cumsum(0.5 * (ks[1:] + ks[:-1]) * np.diff(ss))])
            t = np.interp(s_want + hw, ss, turn) - np.interp(s_want - hw, ss, turn)
            over = t > limit * (1.0 + 1e-9)
            if not over.any():
                break
            w = max(float(np.min(hw[over] * limit / t[over])), 2.0)
            swap = over & (w < hw)
            if not swap.any():
                break
            k2 = _fit_curvatures(X, Y, S, start[f:f + 1], length[f:f + 1], np.array([w]),
                                 i0[f:f + 1], count[f:f + 1], correct[f:f + 1], shift[f:f + 1])
            kin[a:b][swap] = k2[swap]
            hw[swap] = w
    return kin


def _flat_paths(paths):
    """Paths (n, 2) in flat arrays: ``(rows, cols, offs)``, path ``i`` at
    ``offs[i]:offs[i + 1]``."""
    flat, offs = polyline.concat_paths(paths, np.float64)
    return np.ascontiguousarray(flat[:, 0]), np.ascontiguousarray(flat[:, 1]), offs


def _path_lengths(r, c, lo, hi):
    """:func:`crosssection.core.polyline.length` of the paths ``lo[i]:hi[i]`` of the flat
    points ``r``, ``c`` (:func:`_flat_paths`)."""
    return _range_sums(np.hypot(r[1:] - r[:-1], c[1:] - c[:-1]), lo, hi - 1)


def _paper_profiles(smoothed, closed, n_br, trims, unfitted, *, thickness_px, px_per_mm,
                    window_px=None, circle_correction=True, ends="shift",
                    max_window_frac=0.5, tight_refits=True) -> list:
    """Profiles by the paper's parabolic window (module docstring) of many stacks, their
    window fits in one call of :func:`_fit_curvatures`.

    An open path whose trims leave a fitted part shorter than the two trims together is
    fitted whole; with ``unfitted`` nothing of it is fitted (zero curvature, no fitted
    sample: ``fit_start == fit_stop == 0``), to be filled by :func:`_fill_unfitted_stacks`.
    The window of an open path is capped at ``max_window_frac`` of its fitted part, that of
    a closed loop at half the loop. The samples outside the fitted part take the curvature
    of the nearest fitted one (the skeleton is distorted within about a stack width of a
    junction or a free end).

    All stacks at once, over their flat arrays (:func:`_fit_ranges`, :func:`_fit_arrays`,
    :func:`_fitted_kappa`, :func:`_profile_sums`): around the fits, 3.5 ms against 11 ms one
    stack at a time for the 346 paths of a dense 2000 x 2000 scan.

    Parameters
    ----------
    smoothed : sequence of (n, 2) arrays
        Every stack's smoothed centreline (row, col) px (:func:`_prepared_path`, then
        :func:`crosssection.core.polyline.smooth`).
    closed : sequence of bool
    n_br : sequence of int
        Layers of every stack (window ``5 n_br h``; trims at least ``n_br h``).
    trims : sequence of (float or None, float or None)
        Fork zone at the path start and end, px of arc (None: 0).
    unfitted : sequence of bool
        Stacks without a centreline of their own (:func:`stack_profiles`).
    thickness_px, px_per_mm : float
    window_px, circle_correction, ends, max_window_frac
        As in :func:`stack_curvature`, for all stacks.
    tight_refits : bool
        Fit again where the window turns by more than a radian (:func:`_tight_refits`; not
        the paper's method).

    Returns
    -------
    list of CurvatureProfile
    """
    m = len(smoothed)
    if m == 0:
        return []
    pts = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in smoothed]
    r, c, offs = _flat_paths(pts)
    lens = np.diff(offs)
    cl = np.fromiter((bool(x) for x in closed), np.bool_, count=m)
    nb = np.fromiter((max(1, int(x)) for x in n_br), np.int64, count=m)
    tr = np.array([[float(t or 0.0) for t in pair] for pair in trims]).reshape(m, 2)
    s_px, total, mode, t0, t1, half_w = _fit_ranges(
        r, c, offs, cl, nb, tr, np.fromiter((bool(x) for x in unfitted), np.bool_, count=m),
        float(thickness_px), np.nan if window_px is None else float(window_px),
        0.0 if max_window_frac is None else float(max_window_frac))
    X, Y, S, start, length, i0, count = _fit_arrays(r, c, s_px, offs, total, mode, t0, t1)
    fitted = mode != 0
    shift = ends == "shift"
    correct = np.full(len(count), bool(circle_correction))
    shifted = (mode[fitted] == 2) & shift
    kin = _fit_curvatures(X, Y, S, start, length, half_w[fitted], i0, count, correct, shifted)
    if tight_refits:
        kin = _tight_refits(kin, X, Y, S, start, length, half_w[fitted], i0, count, correct,
                            shifted)
    s, kappa, out = _fitted_kappa(s_px, total, offs, mode, t0, t1, half_w, shift, kin)
    rc = [np.vstack([p, p[:1]]) if loop else p for p, loop in zip(pts, (mode == 1).tolist())]
    profs = _profiles(s, kappa, out, px_per_mm, cl, rc,
                      np.stack([t0, t1 + (mode == 1)], axis=1))
    for i in np.flatnonzero(lens == 0).tolist():
        z = np.zeros(0)
        profs[i] = CurvatureProfile(z, z, 0.0, np.nan, np.nan, np.nan, bool(cl[i]),
                                    np.zeros((0, 2)))
    return profs


def _prepared_path(path_rc, closed):
    """The points of a stack's path as the fits take them, and whether it is closed."""
    p = polyline._as_points(path_rc)
    if closed is None:
        closed = polyline.is_closed(p)
    closed = bool(closed)
    if closed and len(p) > 1 and np.all(p[0] == p[-1]):
        p = p[:-1]  # the repeated closing pixel would count twice
    return p, closed


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

    Raises
    ------
    ParameterError
        A scale, thickness, count, window or noise that is not a finite positive number (the
        noise and the window may be None, the noise 0), ``ends`` or ``method`` not one of
        theirs, ``trim_px`` neither one number nor two (each finite, >= 0),
        ``max_window_frac`` outside (0, 1], ``smooth_px`` below 1, a window ``5 n_br h``
        below 2 px, a path that is not an (N, 2) array, a point of the path not finite.
    """
    _number("thickness_px", thickness_px)
    _number("px_per_mm", px_per_mm)
    _number("n_br", n_br, minimum=1.0, allow_equal=True)
    if window_px is not None:
        _number("window_px", window_px, minimum=2.0)
    if noise_var_per_mm2 is not None:
        _number("noise_var_per_mm2", noise_var_per_mm2, allow_equal=True)
    if ends not in ("shift", "truncate"):
        raise ParameterError(f"ends must be 'shift' or 'truncate', got {ends!r}")
    if np.ndim(trim_px) and np.size(trim_px) != 2:
        raise ParameterError(f"trim_px must be one number or two, got {trim_px!r}")
    for t in (np.ravel(trim_px) if trim_px is not None else ()):
        if t is not None:
            _number("trim_px", t, allow_equal=True)
    if max_window_frac is not None:
        _number("max_window_frac", max_window_frac, maximum=1.0)
    if window_px is None and 5.0 * float(n_br) * float(thickness_px) < 2.0:
        raise ParameterError(f"the window 5 n_br h = {5.0 * float(n_br) * float(thickness_px):g}"
                             f" px is below 2 px: no parabola fits it (thickness_px "
                             f"{thickness_px!r})")
    p, closed = _prepared_path(path_rc, closed)
    if not np.isfinite(p).all():
        raise ParameterError("path_rc holds a point that is not finite")
    if len(p) == 0:
        z = np.zeros(0)
        return CurvatureProfile(z, z, 0.0, np.nan, np.nan, np.nan, closed, np.zeros((0, 2)))
    if smooth_px is None:
        smooth_px = default_smooth_px(thickness_px)
    _number("smooth_px", smooth_px, minimum=1.0, allow_equal=True)
    if method not in ("missing", "paper"):
        raise ParameterError(f"curvature method must be 'missing' or 'paper', got {method!r}")
    trims = tuple(trim_px) if np.ndim(trim_px) else (trim_px, trim_px)
    prof = _paper_profiles(
        [polyline.smooth(p, window_px=int(smooth_px), closed=closed)], [closed], [n_br], [trims],
        [False], thickness_px=thickness_px, px_per_mm=px_per_mm, window_px=window_px,
        circle_correction=circle_correction, ends=ends, max_window_frac=max_window_frac,
        tight_refits=method != "paper")[0]
    if method == "paper":
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
#: Inscribed radius beyond a band's own, in sheet thicknesses, from which its skeleton runs in
#: merged ink (:func:`_merged_arcs`): 1.5 layers more, where the jog onto the band's own
#: middle reads as a kink. Where a band's width steps one to three millimetres beyond its
#: fork, a one-layer band read 4-10 times its int kappa^2 ds, and 1.04-1.06 times it with the
#: zone over the merged ink (``test_a_band_stepping_beyond_its_fork_keeps_its_energy``). The
#: total energy of 40 network-generator scans, 36 independent ones and 50 of a wall-band
#: generator with real-scan artefacts is unchanged but on one scan (+1.2 points); at 0.35 h the
#: zones grew at peels too, and that generator's median read -22.9 % instead of -20.5 %.
_MERGED_TOL_H = 0.75
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
        if x - t >= gap:
            # a crossing from here on lies at least ``gap`` beyond t: none is nearer than the
            # best (the march stops after about half its samples: 13.0 ms for the midlines of
            # the dense 2000x2000 benchmark scan, against 14.0 ms without the stop)
            break
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
    paths = [np.ascontiguousarray(p, dtype=np.float64).reshape(-1, 2) for p in paths]
    m = len(paths)
    offs = np.zeros(m + 1, np.int64)
    np.cumsum([len(p) for p in paths], out=offs[1:])
    width = np.zeros(m)
    tol = np.zeros(m)
    moved = np.zeros(m, np.bool_)
    for i, (p, r) in enumerate(zip(paths, radius_px)):
        if len(p) >= 3 and np.isfinite(r) and r > 0:
            # a band of w pixels has walls w px apart and a distance transform of about
            # w / 2 + 0.5 on its skeleton
            width[i] = 2.0 * float(r) - 0.5
            tol[i] = max(_MIDLINE_WIDTH_TOL_MIN_PX, _MIDLINE_WIDTH_TOL * width[i])
            moved[i] = True
    if not m:
        return []
    raw = np.concatenate(paths) if offs[-1] else np.zeros((0, 2))
    sm = np.ascontiguousarray(np.concatenate([np.asarray(q, np.float64).reshape(-1, 2)
                                              for q in smoothed]))
    # every stack in one compiled call: it releases the interpreter (the pipeline runs it on
    # a thread beside the widths and the linear system)
    out = _midlines_kernel(raw, sm, offs, width, tol, moved, np.asarray(closed, np.bool_),
                           dt, _MIDLINE_MAX_SHIFT_PX, feat, float(level))
    return [p if not moved[i] else out[offs[i]:offs[i + 1]] for i, p in enumerate(paths)]


@njit(cache=True, nogil=True)
def _midlines_kernel(raw, sm, offs, width, tol, moved, closed, dt, max_shift, feat,
                     level):  # pragma: no cover - numba
    # :func:`_midline_kernel` of every stack ``i`` (rows ``offs[i]:offs[i + 1]``) to move
    out = raw.copy()
    for i in range(offs.shape[0] - 1):
        if moved[i]:
            a, b = offs[i], offs[i + 1]
            out[a:b] = _midline_kernel(raw[a:b], sm[a:b], dt, width[i], tol[i], max_shift,
                                       closed[i], feat, level)
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
    # error paths cost 3 s of compilation here (4.4 s with them, 1.5 s without)
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


def _fork_zone_px(width_px, r_j, touching_px, smooth_px, merged_px=0.0):
    """Fork zone (module docstring, step 3): the overlap, the hook, the contact or the merged
    ink with its hook, the smoothing."""
    return max(2.0 * max(width_px, r_j), touching_px, merged_px + r_j) + 0.5 * (smooth_px - 1)


def _merged_arcs(prefixes, radius, distance_px, thickness_px) -> dict:
    """Arc length from a junction along which a stack's skeleton runs in ink wider than its
    own band (module docstring, step 3).

    There the stack's band is merged with others (a band that goes on past the fork, layers
    that end there, an arm joining a wall at a slant) and the skeleton runs at the merged
    ink's middle, not on the stack: where the merged ink ends, it jogs onto the stack's own
    middle. Ink is wider than the band where the inscribed radius exceeds the band's median
    one by :data:`_MERGED_TOL_H` h (at least 1 px).

    Parameters
    ----------
    prefixes : tuple
        :func:`_junction_prefixes` of the skeleton paths (pixels, the contact's reach).
    radius : (M,) array
        Every stack's median inscribed radius, px.
    distance_px : 2-D array
        Distance transform of the ink.
    thickness_px : float

    Returns
    -------
    dict
        (stack, end) -> arc length, px, from the junction to the first skeleton pixel whose
        inscribed radius is the band's own (the prefix's length when none is).
    """
    keys, r, c, offs = prefixes
    if not keys:
        return {}
    lens = np.diff(offs)
    walk = np.repeat(np.arange(len(keys)), lens)
    own = np.asarray(radius, float)[[sid for sid, _ in keys]] \
        + max(1.0, _MERGED_TOL_H * float(thickness_px))
    # (skeleton pixels: whole numbers)
    free = distance_px[r.astype(np.intp), c.astype(np.intp)] <= own[walk]
    # each prefix's first free pixel (the prefixes lie one after the other, in walk order)
    first = lens.copy()
    w_free, at = np.unique(walk[free], return_index=True)
    first[w_free] = np.flatnonzero(free)[at] - offs[:-1][w_free]
    arc = _path_lengths(r, c, offs[:-1], offs[:-1] + np.minimum(first, lens - 1) + 1)
    return {key: float(a) for key, a in zip(keys, arc)}


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


def _junction_prefixes(paths, at_node, reach):
    """Every stack end at a junction and its path's first ``reach`` pixels from there, in flat
    arrays: ``(keys, rows, cols, offs)``, key ``i``'s prefix at ``offs[i]:offs[i + 1]``
    (float), the keys junction after junction as ``at_node`` lists them."""
    keys = [key for ks in at_node.values() for key in ks]
    r, c, offs = _flat_paths([_prefix(paths[sid], end, reach) for sid, end in keys])
    return keys, r, c, offs


def _contact_arcs(prefixes, at_node, radius, gap_px: float = _CONTACT_GAP_PX) -> dict:
    """:func:`contact_arc_px` of every stack end at a junction against the other ends there.

    Parameters
    ----------
    prefixes : tuple
        :func:`_junction_prefixes` of the stack paths (the prefix length, pixels, compared
        from each junction).
    at_node : dict
        Junction -> list of (stack, end) meeting there.
    radius : (M,) float array
        Half width of every stack (median inscribed radius).
    gap_px : float
        As in :func:`contact_arc_px`.

    Returns
    -------
    dict
        (stack, end) -> arc length, px.
    """
    keys, r, c, offs = prefixes
    if not keys:
        return {}
    sizes = np.array([len(ks) for ks in at_node.values()], np.int64)
    ends = np.cumsum(sizes)
    group_lo = np.repeat(ends - sizes, sizes)
    group_hi = np.repeat(ends, sizes)
    lens = np.diff(offs)
    rad = np.asarray(radius, np.float64)[np.array([sid for sid, _ in keys], np.int64)]
    first_far = _first_far_kernel(r, c, offs, rad, group_lo, group_hi, float(gap_px))
    # an end whose junction has no other end with a prefix has nothing to touch
    filled = (lens > 0).astype(np.int64)
    has_other = np.repeat(np.add.reduceat(filled, ends - sizes), sizes) - filled > 0
    arc = _path_lengths(r, c, offs[:-1], offs[:-1] + np.minimum(first_far, lens - 1) + 1)
    arc[(lens < 2) | (first_far < 1) | ~has_other] = 0.0
    return dict(zip(keys, arc.tolist()))


@dataclass(frozen=True)
class StackCentrelines:
    """What :func:`stack_profiles` reads from the scan before the branch counts: every
    stack's centreline between its walls and the bands' radii and contacts at the junctions
    (:func:`stack_centrelines`)."""

    n_stacks: int
    thickness_px: float
    smooth_px: int
    method: str
    #: whether the walls were placed on the threshold's feature (``edge`` given)
    on_feature: bool
    #: junction -> [(stack, end)]
    at_node: dict
    radius_px: np.ndarray
    #: per band end at a junction: its skeleton from the junction, and the other bands'
    #: skeleton points there with the distance below which each touches it
    contact: dict
    at_junction: np.ndarray
    #: the inscribed ink radius at the junction of every stack end (0 at a free end)
    r_j: list
    raw: list
    closed: list
    skeleton_px: list
    #: the smoothed centrelines: between the walls, or the skeleton's for the paper's method
    smoothed: list
    dt32: np.ndarray
    #: per band end at a junction: the arc along which its skeleton runs in merged ink
    merged: dict


def stack_centrelines(graph, distance_px, *, thickness_px: float, smooth_px: int | None = None,
                      method: str = METHODS[0], edge=None) -> StackCentrelines:
    """The part of :func:`stack_profiles` that needs no branch count: the stacks'
    centrelines (module docstring, step 1) and their junctions' geometry.

    The pipeline draws them on a thread while the widths and the linear system are read: the
    costliest step, the walls' midpoints, is one compiled call that releases the interpreter.

    Parameters
    ----------
    graph, distance_px, thickness_px, smooth_px, method, edge
        As :func:`stack_profiles`.

    Returns
    -------
    StackCentrelines
        To hand to :func:`stack_profiles` with the same graph and settings.
    """
    sm = default_smooth_px(thickness_px) if smooth_px is None else int(smooth_px)
    if method not in METHODS:
        raise ParameterError(f"curvature method must be one of {METHODS}, got {method!r}")
    H, W = distance_px.shape
    at_node = {}  # junction -> [(stack, end)]
    for sid in range(graph.n_stacks):
        for end, node in enumerate(graph.ends[sid]):
            if graph.node_kind[node] == "junction":
                at_node.setdefault(node, []).append((sid, end))
    reach = int(np.ceil(_CONTACT_REACH_H * float(thickness_px)))
    radius = median_radii_px(graph.paths, distance_px)
    # per band end at a junction: its skeleton from the junction, and the skeleton points of
    # the other bands there with the distance below which each touches it
    prefixes = _junction_prefixes(graph.paths, at_node, reach)
    contact = _contact_arcs(prefixes, at_node, radius)
    merged = _merged_arcs(prefixes, radius, distance_px, thickness_px)

    # the inscribed ink radius at the junction of every stack end (0 at a free end)
    ends = np.array(graph.ends, np.int64).reshape(-1, 2)
    at_junction = np.array([[graph.node_kind[node] == "junction" for node in e]
                            for e in graph.ends], bool).reshape(-1, 2)
    r_j = np.zeros(ends.shape)
    if at_junction.any():
        rc = np.round(np.array([graph.node_rc[node] for node in ends[at_junction].tolist()],
                               float).reshape(-1, 2)).astype(int)
        r_j[at_junction] = distance_px[np.clip(rc[:, 0], 0, H - 1), np.clip(rc[:, 1], 0, W - 1)]
    r_j = r_j.tolist()

    prepared = [_prepared_path(graph.paths[sid], graph.node_kind[graph.ends[sid][0]] == "loop")
                for sid in range(graph.n_stacks)]
    raw = [p for p, _ in prepared]
    closed = [c for _, c in prepared]
    # the skeleton's length (polyline.length; a path that is not a loop is prepared as it is)
    r, c, offs = _flat_paths(raw)
    skeleton_px = _path_lengths(r, c, offs[:-1], offs[1:]).tolist()
    smoothed = polyline.smooth_paths(raw, window_px=sm, closed=closed)
    dt32 = np.ascontiguousarray(distance_px, dtype=np.float32)
    if method != "paper":
        # the paper's centreline is the skeleton's; the others read it between the walls
        mid = _midlines(raw, smoothed, closed, radius, dt32, edge)
        smoothed = polyline.smooth_paths(mid, window_px=sm, closed=closed)
    return StackCentrelines(graph.n_stacks, float(thickness_px), sm, method, edge is not None,
                            at_node, radius, contact, at_junction, r_j, raw, closed,
                            skeleton_px, smoothed, dt32, merged)


def stack_profiles(graph, n_br, distance_px, *, thickness_px: float, px_per_mm: float,
                   smooth_px: int | None = None, method: str = METHODS[0], edge=None,
                   centrelines: StackCentrelines | None = None) -> list:
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
    centrelines : StackCentrelines, optional
        :func:`stack_centrelines` of the same graph with the same settings, computed
        beforehand (None: computed here).

    Returns
    -------
    list of CurvatureProfile
        One per stack, in stack order.
    """
    if method not in METHODS:
        raise ParameterError(f"curvature method must be one of {METHODS}, got {method!r}")
    sm = default_smooth_px(thickness_px) if smooth_px is None else int(smooth_px)
    if centrelines is None:
        centrelines = stack_centrelines(graph, distance_px, thickness_px=thickness_px,
                                        smooth_px=sm, method=method, edge=edge)
    elif (centrelines.n_stacks, centrelines.smooth_px, centrelines.method,
          centrelines.thickness_px, centrelines.on_feature) != (
            graph.n_stacks, sm, method, float(thickness_px), edge is not None):
        raise ParameterError("centrelines were computed for another graph or other settings "
                             "than the profiles asked for")
    cl = centrelines
    at_node, radius, contact, at_junction, r_j = (cl.at_node, cl.radius_px, cl.contact,
                                                  cl.at_junction, cl.r_j)
    raw, closed, skeleton_px, smoothed, dt32 = (cl.raw, cl.closed, cl.skeleton_px,
                                                cl.smoothed, cl.dt32)

    def fork_zone(sid, end, nb):
        # module docstring, step 3
        if not at_junction[sid, end]:
            return 0.0
        return _fork_zone_px(nb * float(thickness_px), r_j[sid][end], contact[(sid, end)], sm,
                             cl.merged[(sid, end)])

    nbs = [max(1, int(x)) for x in n_br]
    all_trims, forks, lumps, walled = [], [], [], {}
    for sid in range(graph.n_stacks):
        u, v = graph.ends[sid]
        nb = nbs[sid]
        trims = (fork_zone(sid, 0, nb), fork_zone(sid, 1, nb))
        all_trims.append(trims)
        forks.append(tuple(t > 0 for t in trims))
        # a stack within its forks' hooks from end to end: its skeleton is the link between
        # medial-axis fork points, no centreline of its own (step 3). A junction blob wider
        # than the band (thick stacks meeting, at epsilon 19) holds longer such links.
        hooks = max(2.0 * radius[sid], r_j[sid][0] + r_j[sid][1])
        lump = (method != "paper" and any(forks[-1]) and graph.node_kind[u] != "loop"
                and skeleton_px[sid] < _LUMP_WIDTHS * hooks)
        lumps.append(lump)
        if (method == "walls" and not closed[sid] and any(forks[-1]) and not lump
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
    # the window fits of all stacks in one call (numpy's overhead per call is that of a
    # whole stack's fits)
    every = _paper_profiles(
        list(smoothed) + list(wsmooth), closed + [False] * len(wsids),
        nbs + [nbs[sid] for sid in wsids], all_trims + [walled[sid][1] for sid in wsids],
        lumps + [False] * len(wsids), thickness_px=thickness_px, px_per_mm=px_per_mm,
        tight_refits=method != "paper")
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
    profiles = _fill_fork_zones_many(
        profiles, nbs, forks, [var[nb] or 0.0 for nb in nbs],
        [walled[sid][2] if sid in walled else (0.0, 0.0) for sid in range(graph.n_stacks)],
        thickness_px=thickness_px, px_per_mm=px_per_mm, max_window_frac=0.5, shifted=True)
    return _fill_unfitted_stacks(profiles, at_node, n_br, px_per_mm=px_per_mm,
                                 thickness_px=thickness_px)


def _unfitted(prof) -> bool:
    """Whether a profile has samples but none fitted (:func:`_fill_unfitted_stacks`)."""
    return len(prof.s_mm) > 0 and prof.fit_stop <= prof.fit_start


def _fitted_window_mm(s, t0, t1, window_px, px_per_mm, max_window_frac=0.5) -> float:
    """The window the fits of samples ``t0:t1`` used, mm: ``window_px``, capped by
    :func:`_paper_profiles` at ``max_window_frac`` of the fitted length."""
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
        s_px, k_px = [], []
        for sid, (k0, k1, v) in filled.items():
            kmax = 2.0 * px_per_mm / (nb[sid] * float(thickness_px))
            k0, k1 = float(np.clip(k0, -kmax, kmax)), float(np.clip(k1, -kmax, kmax))
            s = out[sid].s_mm
            frac = (s - s[0]) / (s[-1] - s[0]) if s[-1] > s[0] else np.zeros_like(s)
            k = k0 + (k1 - k0) * frac
            s_px.append(s * px_per_mm)
            k_px.append(k / px_per_mm)
            end_value[(sid, 0)] = (k0, v)
            end_value[(sid, 1)] = (k1, v)
        sids = list(filled)
        offs = np.zeros(len(sids) + 1, np.int64)
        np.cumsum([len(s) for s in s_px], out=offs[1:])
        noise = [filled[sid][2] for sid in sids]
        new = _profiles(np.concatenate(s_px), np.concatenate(k_px), offs, px_per_mm,
                        [False] * len(sids), [out[sid].rc_px for sid in sids],
                        np.zeros((len(sids), 2), np.int64),
                        forks=np.ones((len(sids), 2), np.bool_),
                        walled_px=np.zeros((len(sids), 2)), noise_coef=np.array(noise, float),
                        noise_var=noise)
        for sid, prof in zip(sids, new):
            out[sid] = prof
        todo -= set(filled)
    return out


def _slope(ds, dk):
    """Slope ``a`` of the least-squares line ``k = b + a (s - s_mean)`` from the deviations
    ``ds``, ``dk`` of ``s`` and ``k`` from their means (0 where ``s`` does not vary)."""
    den = float(ds @ ds)
    return float(ds @ dk) / den if den > 0 else 0.0


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
    :func:`_paper_profiles`. With the scan's curvature noise ``v`` known, the trend is continued
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
        The window fits (:func:`_paper_profiles`): samples ``fit_start:fit_stop`` fitted, the
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
    return _fill_fork_zones_many(
        [prof], [n_br], [forks], [noise_var_per_mm2], [walled_px], thickness_px=thickness_px,
        px_per_mm=px_per_mm, noise_px=noise_px, max_window_frac=max_window_frac,
        shifted=shifted, window_px=window_px, max_turn=max_turn)[0]


def _fill_fork_zones_many(profs, n_br, forks, noise_var, walled_px, *, thickness_px, px_per_mm,
                          noise_px=0.3, max_window_frac=0.5, shifted=True, window_px=None,
                          max_turn=_ZONE_MAX_TURN) -> list:
    """:func:`_fill_fork_zones` of many stacks, the same arithmetic on all of them at once.

    Over the stacks' flat arrays (:func:`_zone_sides`, :func:`_bound_turns`,
    :func:`_profile_sums`), but for the trends' dot products (numpy's BLAS, whose order of
    summation a loop does not reproduce): 3 ms against 14 ms stack by stack for the 244
    stacks of a dense 2000 x 2000 scan.

    Parameters
    ----------
    profs : list of CurvatureProfile
    n_br : sequence of int
    forks : sequence of (bool, bool)
    noise_var : sequence of float or None
        ``noise_var_per_mm2`` of every stack.
    walled_px : sequence of (float, float)
    thickness_px, px_per_mm, noise_px, max_window_frac, shifted, window_px, max_turn
        As in :func:`_fill_fork_zones`, for all stacks.

    Returns
    -------
    list of CurvatureProfile
    """
    m = len(profs)
    if m == 0:
        return []
    h, ppm = float(thickness_px), float(px_per_mm)
    lens = np.fromiter((len(p.s_mm) for p in profs), np.int64, count=m)
    offs = np.zeros(m + 1, np.int64)
    np.cumsum(lens, out=offs[1:])
    s = np.concatenate([np.asarray(p.s_mm, float) for p in profs])
    k = np.concatenate([np.asarray(p.kappa_per_mm, float) for p in profs])
    nb = np.fromiter((max(1, int(x)) for x in n_br), np.int64, count=m)
    t0 = np.fromiter((p.fit_start for p in profs), np.int64, count=m)
    t1 = np.fromiter((p.fit_stop for p in profs), np.int64, count=m)
    closed = np.fromiter((p.closed for p in profs), np.bool_, count=m)
    fk = np.array([[bool(f0), bool(f1)] for f0, f1 in forks], np.bool_).reshape(m, 2)
    known = np.fromiter((v is not None for v in noise_var), np.bool_, count=m)
    noise = np.fromiter((0.0 if v is None else float(v) for v in noise_var), float, count=m)
    kmax, w, side = _zone_sides(
        s, k, offs, t0, t1, nb, closed, fk, known, h, ppm,
        np.nan if window_px is None else float(window_px),
        0.0 if max_window_frac is None else float(max_window_frac), bool(shifted))
    limit = _TREND_DEVIATIONS ** 2 * _SLOPE_NOISE
    for e in (0, 1):
        act = np.flatnonzero(side[e, :, 4])
        if len(act) == 0:
            continue
        a, lo, hi = offs[act], side[e, act, 0], side[e, act, 1]
        # the trend line k = km + slope (s - sm) over the samples lo:hi (numpy's means)
        sm = _range_sums(s, a + lo, a + hi) / (hi - lo)
        km = _range_sums(k, a + lo, a + hi) / (hi - lo)
        idx, pos, cnt = polyline.ranges(a + lo, a + hi)
        ds = s[idx] - np.repeat(sm, cnt)
        dk = k[idx] - np.repeat(km, cnt)
        at = np.append(pos, len(idx)).tolist()
        slope = np.array([_slope(ds[at[i]:at[i + 1]], dk[at[i]:at[i + 1]])
                          for i in range(len(act))])
        # no trend beyond the noise: the zone keeps the nearest fitted curvature and the
        # shifted fits their own
        quiet = known[act] & (slope * slope * w[act] * w[act] <= limit * noise[act])
        z0 = np.where(quiet, 0 if e == 0 else t1[act], side[e, act, 2])
        z1 = np.where(quiet, t0[act] if e == 0 else lens[act], side[e, act, 3])
        go = ~quiet
        idx, pos, cnt = polyline.ranges((a + z0)[go], (a + z1)[go])
        x = np.repeat(km[go], cnt) + np.repeat(slope[go], cnt) * (s[idx] - np.repeat(sm[go], cnt))
        bound = np.repeat(kmax[act[go]], cnt)
        k[idx] = np.where(x < -bound, -bound, np.where(x > bound, bound, x))
        _bound_turns(k, s, a, lens[act], z0, z1, z1 if e == 0 else z0 - 1, max_turn)
    # the noise floor of every stack's int kappa^2 ds, per mm of its length
    coef = np.array([float(v) if v is not None else
                     720.0 * noise_px ** 2 / (5.0 * b * h) ** 5 * px_per_mm ** 2
                     for v, b in zip(noise_var, nb.tolist())])
    fit = np.stack([t0, np.where(t1 < 0, lens, t1)], axis=1)
    return _profiles(s * px_per_mm, k / px_per_mm, offs, ppm, closed, [p.rc_px for p in profs],
                     fit, forks=fk, walled_px=np.asarray(walled_px, float).reshape(m, 2),
                     noise_coef=coef,
                     noise_var=[0.0 if v is None else float(v) for v in noise_var])


def _zone_turns(k, s, a, n, z0, z1, edge):
    """Total turns ``int |kappa| ds`` of the fork zones ``k[a + z0:a + z1]`` (of the stacks at
    ``a:a + n``) up to the fitted sample ``a + edge`` next to each, radians: the indices of
    the zones that have one (not empty, their edge on the stack) and their turns."""
    on = np.flatnonzero((z1 > z0) & (edge >= 0) & (edge < n))
    idx, pos, cnt = polyline.ranges(a[on] + np.minimum(z0[on], edge[on]),
                                    a[on] + np.maximum(z1[on], edge[on] + 1))
    return on, _trapz_ranges(np.abs(k[idx]), s[idx], pos, pos + cnt)


def _bound_turns(k, s, a, n, z0, z1, edge, limit):
    """Scale every fork zone ``k[a + z0:a + z1]`` (of the stack at ``a:a + n``) in place so
    that its total turn (:func:`_zone_turns`) is at most ``limit`` radians (an empty zone, or
    one without its edge, as it is)."""
    on, turn = _zone_turns(k, s, a, n, z0, z1, edge)
    a, z0, z1, edge = a[on], z0[on], z1[on], edge[on]
    over = ~(turn <= limit)
    e = (a + edge)[over]
    # the edge sample's half of its interval is measured, not scaled
    half = 0.5 * np.abs(k[e]) * np.abs(s[e] - s[e + np.where(edge[over] < z0[over], 1, -1)])
    idx, pos, cnt = polyline.ranges((a + z0)[over], (a + z1)[over])
    k[idx] *= np.repeat(_pymax(limit - half, 0.0) / _pymax(turn[over] - half, 1e-300), cnt)


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


#: Largest centreline jitter (px, independent from pixel to pixel) a measured curvature noise
#: may stand for (:func:`noise_variance`): ``720 sigma^2 / w^5`` for a parabola fitted over
#: ``w`` px. Generated scans read 0-0.06 px, a JPEG saved five times at quality 30 0.5 px,
#: a scan enlarged twice by pixel repetition 0.65 px; a sticker cutting a dense scan's wall
#: band into two long open stacks, the only ones the estimate rested on, 1.3 px: their bends,
#: taken as noise and removed from every stack, took the scan's energy from -19 to -73 %.
NOISE_MAX_PX = 1.0

#: A stack whose own noise estimate exceeds this many times the pooled estimate of the scan's
#: other stacks of its window is left out of the pooled noise (:func:`_without_outliers`): on
#: noise-only arcs the stacks' own estimates are 0.3-1.9 times the pooled one (5-95 %, at most
#: 2.3; 120 stacks), a stack with one 90-degree turn of radius 12 px among them 80 times
#: (pooled with it, the noise read 12 times its value).
NOISE_OUTLIER = 4.0
#: With one other stack of its window, a stack is left out beyond this many times that one's
#: estimate: two noise-only estimates differ by at most 1.9 / 0.3 = 6.3 times (above), a stack
#: hooked across a layer step beside a gentle arc read 330 times it (pooled with it, the noise
#: floor removed 92 % of the arc's energy).
NOISE_OUTLIER_PAIR = 16.0


def _without_outliers(v, w):
    """Per-stack noise estimates ``v`` (weights ``w``) without the stacks whose own estimate
    exceeds :data:`NOISE_OUTLIER` times the pooled estimate of the others (their mean absolute
    estimate where they pool to 0 or below), largest first, while two stacks or more remain
    besides it; of two stacks, the larger when it exceeds :data:`NOISE_OUTLIER_PAIR` times
    the other's.

    A stack with real bending at the scale of the lags (a hook, a kink) reads tens of times the
    scan's noise, and pooled with the others it would set the noise removed from every stack.
    """
    order = np.argsort(v)
    v, w = v[order], w[order]
    if len(v) == 2:
        ref = abs(float(v[0]))
        if ref > 0 and v[1] > NOISE_OUTLIER_PAIR * ref:
            return v[:1], w[:1]
        return v, w
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
    measured = _measured_noise(profiles, n_br, nbs, window, sm, px_per_mm, min_pairs,
                               loops=False)
    if not measured:
        # a scan of closed loops only (rings, a rolled sheet): their stretches are the only
        # measure of its noise (a lone ring of radius 8 mm read +27 % without it)
        measured = _measured_noise(profiles, n_br, nbs, window, sm, px_per_mm, min_pairs,
                                   loops=True)
    # an estimate beyond what a centreline jittered by NOISE_MAX_PX gives is bending the
    # lags caught on the few stacks it rests on, not the scan's noise
    measured = {nb: v for nb, v in measured.items()
                if v <= 720.0 * NOISE_MAX_PX ** 2 / window[nb] ** 5 * float(px_per_mm) ** 2}
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


def _measured_noise(profiles, n_br, nbs, window, sm, px_per_mm, min_pairs, *, loops):
    """The windows' pooled noise estimates of :func:`noise_variance` (n_br -> v), from the
    open stacks, or from the closed loops as well (``loops``)."""
    measured = {}
    for nb in nbs:
        lag = (window[nb] + sm) / float(px_per_mm)
        per_stack, weights = [], []
        for prof, n in zip(profiles, n_br):
            if max(1, int(n)) != nb or (prof.closed and not loops):
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
        if w.sum() > 0 and w.sum() >= min_pairs:
            measured[nb] = max(float(v @ w) / float(w.sum()), 0.0)
    return measured
