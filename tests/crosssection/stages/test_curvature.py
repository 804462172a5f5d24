"""Stage 10: centerline smoothing, arc length and local curvature (crosssection.stages.curvature)."""
from __future__ import annotations

import warnings

import networkx as nx
import numpy as np
import pytest
from skimage.draw import line
from skimage.morphology import skeletonize

from crosssection.core.errors import ParameterError
from crosssection.core.polyline import is_closed
from crosssection.core.polyline import smooth as _smooth
from crosssection.stages.curvature import default_smooth_px, noise_variance, stack_curvature

H = 5.0  # sheet thickness in px (0.1 mm at 50 px/mm)


def _band(R, theta0, theta1, seed, h=H):
    """A drawn band of width h along an arc of radius R with round caps; random subpixel
    centre. Angles are as displayed (counter-clockwise, y up)."""
    rng = np.random.default_rng(seed)
    size = int(2 * R + 4 * h + 20)
    c = (size / 2 + rng.uniform(-0.5, 0.5), size / 2 + rng.uniform(-0.5, 0.5))
    rr, cc = np.mgrid[0:size, 0:size]
    d = np.hypot(rr - c[0], cc - c[1])
    ang = np.mod(np.arctan2(-(rr - c[0]), cc - c[1]) - theta0, 2 * np.pi)
    m = (np.abs(d - R) <= h / 2) & (ang <= theta1 - theta0)
    for th in (theta0, theta1):
        m |= np.hypot(rr - (c[0] - R * np.sin(th)), cc - (c[1] + R * np.cos(th))) <= h / 2
    return m, c


def _skeleton_path(mask):
    """Ordered pixels of the longest path of the skeleton (an 8-connected 1-px path)."""
    pts = np.argwhere(skeletonize(mask))
    idx = {tuple(p): i for i, p in enumerate(pts)}
    g = nx.Graph()
    for i, (r, c) in enumerate(pts):
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                j = idx.get((r + dr, c + dc))
                if j is not None and j != i:
                    g.add_edge(i, j, weight=float(np.hypot(dr, dc)))
    a = next(iter(g.nodes))
    d = nx.single_source_dijkstra_path_length(g, a)
    b = max(d, key=d.get)
    d2, paths = nx.single_source_dijkstra(g, b)
    return pts[paths[max(d2, key=d2.get)]]


def _digital_circle(R, seed):
    rng = np.random.default_rng(seed)
    c = rng.uniform(0, 1, 2) + R + 5
    t = np.linspace(0, 2 * np.pi, int(2 * np.pi * R * 20), endpoint=False)
    pts = np.round(np.c_[c[0] - R * np.sin(t), c[1] + R * np.cos(t)]).astype(int)
    keep = np.r_[True, np.any(np.diff(pts, axis=0) != 0, axis=1)]
    pts = pts[keep]
    if np.all(pts[0] == pts[-1]):
        pts = pts[:-1]
    return pts


@pytest.mark.parametrize("R", [40, 70, 150, 400])
def test_arc_curvature_from_skeleton(R):
    """Mean curvature of skeletonised arcs, 12 seeds: within 2 % on average (4 % at R = 40 px
    = 8 h, where the round caps' skeleton bends the ends), 7 % each (10 % at R = 40 px: the
    end windows, a third of such an arc, hold the cap's bend; the largest error of 30 seeds
    there is 9.4 %, sd 3.3 %); the length within 1 % of the true arc between the skeleton's
    end angles. (On ideal digital circles the estimator is within 0.5 %, see
    test_closed_loop.)"""
    kms, lens = [], []
    for seed in range(12):
        rng = np.random.default_rng(100 * R + seed)
        th0 = rng.uniform(0, 2 * np.pi)
        span = rng.uniform(1.6, 2.4)
        m, c = _band(R, th0, th0 + span, seed=100 * R + seed)
        p = _skeleton_path(m)
        prof = stack_curvature(p, n_br=1, thickness_px=H, px_per_mm=50.0)
        ang = np.unwrap(np.arctan2(-(p[:, 0] - c[0]), p[:, 1] - c[1]))
        # skeleton radius (it may sit a fraction of a pixel off R)
        r_sk = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1]).mean()
        true_len = abs(ang[-1] - ang[0]) * r_sk
        kms.append(prof.kappa_m / 50.0 * r_sk)
        lens.append(prof.length_mm * 50.0 / true_len)
        assert prof.kappa_plus >= prof.kappa_m - 1e-12
    kms = np.array(kms)
    assert np.all(np.abs(kms - 1) < (0.10 if R < 50 else 0.07)), kms
    assert abs(kms.mean() - 1) < (0.04 if R < 50 else 0.02), kms
    assert np.all(np.abs(np.array(lens) - 1) < 0.01), lens


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sign_follows_direction(seed):
    m, _ = _band(100, 0.5 + seed, 2.5 + seed, seed=seed)
    p = _skeleton_path(m)
    a = stack_curvature(p, n_br=1, thickness_px=H, px_per_mm=50.0)
    b = stack_curvature(p[::-1], n_br=1, thickness_px=H, px_per_mm=50.0)
    assert a.kappa_pm * b.kappa_pm < 0
    assert abs(a.kappa_m - b.kappa_m) < 0.02 * a.kappa_m


@pytest.mark.parametrize("angle_deg", [0, 7, 22.5, 30, 45, 63, 90, 123, 171])
def test_straight_line_length_and_zero_curvature(angle_deg):
    a = np.deg2rad(angle_deg)
    L = 300.0
    r1, c1 = int(round(10 + L * np.sin(a) + 300)), int(round(10 + L * np.cos(a) + 300))
    rr, cc = line(310, 310, r1, c1)
    p = np.c_[rr, cc]
    true_len = np.hypot(r1 - 310, c1 - 310)
    prof = stack_curvature(p, n_br=1, thickness_px=H, px_per_mm=50.0)
    assert abs(prof.length_mm * 50 / true_len - 1) < 0.01
    # curvature radius > 500 px everywhere on average
    assert prof.kappa_plus / 50.0 < 1 / 500.0
    raw = np.hypot(*np.diff(p, axis=0).T).sum()
    if 5 < angle_deg % 45 < 40:
        assert raw / true_len - 1 > 0.01  # the raw staircase would have failed


@pytest.mark.parametrize("R,seed", [(40, 0), (90, 1), (250, 2)])
def test_closed_loop(R, seed):
    p = _digital_circle(R, seed)
    assert is_closed(p)
    prof = stack_curvature(p, n_br=1, thickness_px=H, px_per_mm=50.0)
    assert prof.closed
    assert abs(prof.length_mm * 50 / (2 * np.pi * R) - 1) < 0.01
    assert abs(prof.kappa_m / 50 * R - 1) < 0.02
    assert prof.s_mm[-1] == pytest.approx(prof.length_mm)
    # a rotated start point gives the same result (periodic treatment, no seam)
    q = np.roll(p, len(p) // 3, axis=0)
    prof2 = stack_curvature(q, n_br=1, thickness_px=H, px_per_mm=50.0)
    assert prof2.kappa_m == pytest.approx(prof.kappa_m, rel=1e-6)


@pytest.mark.parametrize("seed", [3, 4])
def test_s_curve_kappa_plus_exceeds_kappa_m(seed):
    """Two arcs of opposite curvature joined tangentially: kappa_+ ~ 1/R, kappa_m ~ 0."""
    rng = np.random.default_rng(seed)
    R = rng.uniform(60, 120)
    t = np.linspace(0, np.pi / 2, 4000)
    arc = np.c_[R - R * np.cos(t), R * np.sin(t)]             # from the origin, bending right
    xy = np.vstack([-arc[::-1], arc[1:]])                      # point-symmetric S
    # xy: a smooth S through the origin; rasterise
    rc = np.round(np.c_[500 - xy[:, 1], 500 + xy[:, 0]]).astype(int)
    keep = np.r_[True, np.any(np.diff(rc, axis=0) != 0, axis=1)]
    rc = rc[keep]
    prof = stack_curvature(rc, n_br=1, thickness_px=H, px_per_mm=50.0)
    kplus = prof.kappa_plus / 50
    assert kplus > 0.8 / R
    assert prof.kappa_m / 50 < 0.2 / R
    assert prof.kappa_plus > 4 * prof.kappa_m


def test_window_scales_with_n_br():
    """A corner: the wider window of a 4-layer stack spreads and lowers the peak curvature."""
    rr1, cc1 = line(100, 20, 100, 200)
    rr2, cc2 = line(100, 200, 280, 200)
    p = np.vstack([np.c_[rr1, cc1], np.c_[rr2, cc2][1:]])
    k1 = stack_curvature(p, n_br=1, thickness_px=H, px_per_mm=50.0).kappa_per_mm
    k4 = stack_curvature(p, n_br=4, thickness_px=H, px_per_mm=50.0).kappa_per_mm
    assert np.abs(k4).max() < np.abs(k1).max()
    assert (np.abs(k4) > 0.005 * 50).sum() > (np.abs(k1) > 0.005 * 50).sum()


def test_smooth_path_keeps_lines_and_ends():
    rng = np.random.default_rng(7)
    t = np.arange(50.0)
    p = np.c_[3 + 0.4 * t, 7 - 1.3 * t]
    s = _smooth(p, window_px=11)
    assert np.allclose(s, p)
    q = np.c_[t, rng.integers(0, 2, 50)]
    s = _smooth(q, window_px=11)
    assert np.abs(np.diff(s[:, 1])).max() < 0.5


def test_degenerate_paths():
    one = stack_curvature(np.array([[3, 4]]), n_br=1, thickness_px=H, px_per_mm=50.0)
    assert one.length_mm == 0
    two = stack_curvature(np.array([[3, 4], [3, 5]]), n_br=2, thickness_px=H, px_per_mm=50.0)
    assert two.length_mm == pytest.approx(1 / 50)
    assert np.all(two.kappa_per_mm == 0)
    empty = stack_curvature(np.zeros((0, 2), int), n_br=1, thickness_px=H, px_per_mm=50.0)
    assert empty.length_mm == 0 and len(empty.s_mm) == 0


@pytest.mark.parametrize("seed", [5, 6])
def test_window_capped_by_stack_length(seed):
    """A short S-shaped stack of 4 layers (paper window 5 n h = 100 px, longer than half the
    stack): the capped window still resolves the inflection; the uncapped one averages it
    away (kappa_+ collapses onto kappa_m)."""
    rng = np.random.default_rng(seed)
    R = rng.uniform(45, 60)
    t = np.linspace(0, 0.8, 3000)
    arc = np.c_[R - R * np.cos(t), R * np.sin(t)]
    xy = np.vstack([-arc[::-1], arc[1:]])
    rc = np.round(np.c_[300 - xy[:, 1], 300 + xy[:, 0]]).astype(int)
    rc = rc[np.r_[True, np.any(np.diff(rc, axis=0) != 0, axis=1)]]
    capped = stack_curvature(rc, n_br=4, thickness_px=H, px_per_mm=50.0)
    full = stack_curvature(rc, n_br=4, thickness_px=H, px_per_mm=50.0, max_window_frac=None)
    assert capped.kappa_plus / 50 > 0.5 / R
    assert capped.kappa_plus > 3 * capped.kappa_m
    assert full.kappa_plus < 0.5 * capped.kappa_plus


def _noisy_pixel_path(xy_rc, sigma_px, seed):
    """Round a dense (row, col) curve with Gaussian jitter to a pixel chain (no repeats)."""
    rng = np.random.default_rng(seed)
    p = np.round(xy_rc + rng.normal(0.0, sigma_px, xy_rc.shape))
    return p[np.r_[True, np.any(np.diff(p, axis=0) != 0, axis=1)]]


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("R", [60.0, 150.0])
def test_energy_of_noisy_arcs_with_fork_zones(R, seed):
    # an arc of 200 px, jittered pixels (sigma 0.4 px), fork zones of 15 and 25 px trimmed.
    # Measured (seeds 0-2): int kappa^2 ds 1.15-1.24 x the truth (noise inflates kappa^2),
    # mean curvature within 4 %: bounds fail on a regression, not on the known noise bias
    t = np.linspace(0.0, 200.0 / R, 2000)
    path = _noisy_pixel_path(np.stack([R * np.sin(t), R * np.cos(t)], 1), 0.4, seed)
    prof = stack_curvature(path, n_br=2, thickness_px=H, px_per_mm=50.0, trim_px=(15.0, 25.0))
    ratio = np.trapezoid(prof.kappa_per_mm ** 2, prof.s_mm) / (200.0 / R ** 2 * 50.0)
    assert 0.95 < ratio < 1.35
    assert abs(prof.kappa_pm) * R / 50.0 == pytest.approx(1.0, abs=0.06)


@pytest.mark.parametrize("seed", range(3))
def test_energy_of_noisy_sinusoid_with_fork_zones(seed):
    # y = A sin(2 pi x / lam), two wavelengths, curvature varying over lam / 4 = 8 h.
    # Measured (seeds 0-2): 1.32-1.40 x the truth
    A, lam = 12.0, 160.0
    x = np.linspace(0.0, 2 * lam, 4000)
    k = 2 * np.pi / lam
    y, yp, ypp = A * np.sin(k * x), A * k * np.cos(k * x), -A * k * k * np.sin(k * x)
    truth = np.trapezoid(ypp ** 2 / (1 + yp ** 2) ** 2.5, x) * 50.0
    path = _noisy_pixel_path(np.stack([y, x], 1), 0.4, seed)
    prof = stack_curvature(path, n_br=1, thickness_px=H, px_per_mm=50.0, trim_px=(20.0, 20.0))
    ratio = np.trapezoid(prof.kappa_per_mm ** 2, prof.s_mm) / truth
    assert 1.0 < ratio < 1.6


def _clothoid(l_px, k_end_px, n=6000):
    """(row, col) of a curve whose curvature grows linearly from 0 to ``k_end_px`` over
    ``l_px``, and its exact int kappa^2 ds (1/px)."""
    s = np.linspace(0.0, l_px, n)
    th = 0.5 * k_end_px * s ** 2 / l_px
    ds = np.diff(s, prepend=0.0)
    x = np.cumsum(np.cos(th) * ds)
    y = np.cumsum(np.sin(th) * ds)
    return np.stack([-y, x], 1), k_end_px ** 2 * l_px / 3.0


def _s_link(l_px, k0_px, n=6000):
    """(row, col) of an S whose curvature falls linearly from ``k0_px`` to ``-k0_px`` over
    ``l_px``, and its exact int kappa^2 ds (1/px)."""
    s = np.linspace(0.0, l_px, n)
    th = k0_px * (s - s * s / l_px)
    ds = np.diff(s, prepend=0.0)
    return (np.stack([-np.cumsum(np.sin(th) * ds), np.cumsum(np.cos(th) * ds)], 1),
            k0_px ** 2 * l_px / 3.0)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("l_px,r_px", [(50.0, 20.0), (60.0, 25.0), (80.0, 30.0)])
def test_short_link_fitted_whole_continues_its_trend_at_both_ends(l_px, r_px, seed):
    # a one-layer link between two forks whose zones (40 px each) would cover it is fitted
    # whole; its curvature runs from 1/r to -1/r, so the shifted fits at both ends, flat at
    # one window's mean, miss the ends' bending. With the scan's noise known the trend of the
    # centred fits replaces them (a trend within the noise would not). Measured (seeds 0-2):
    # paper 0.49-0.78 x the truth, trend 0.96-1.02 x; noise unknown: the shifted fits stay.
    # A measured noise of 0 (below what the lags resolve) is known: it reads as a noise just
    # above 0, not as unknown
    rc, truth = _s_link(l_px, 1.0 / r_px)
    path = _noisy_pixel_path(rc + 50.0 + np.random.default_rng(seed).uniform(0, 1, 2), 0.0,
                             seed)
    kw = dict(n_br=1, thickness_px=H, px_per_mm=1.0, trim_px=(40.0, 40.0))
    e = {}
    for name, extra in (("paper", dict(method="paper")), ("trend", dict(noise_var_per_mm2=1e-6)),
                        ("zero", dict(noise_var_per_mm2=0.0)), ("unknown", dict())):
        prof = stack_curvature(path, **kw, **extra)
        assert (prof.fit_start, prof.fit_stop) == (0, len(prof.s_mm))  # fitted whole
        e[name] = np.trapezoid(prof.kappa_per_mm ** 2, prof.s_mm) / truth
    assert e["paper"] < 0.85
    assert e["trend"] == pytest.approx(1.0, abs=0.1)
    assert e["zero"] == pytest.approx(e["trend"], rel=1e-6)
    assert e["unknown"] == pytest.approx(e["paper"], rel=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_fork_zone_continues_the_curvature_trend(seed):
    # the curvature rises toward the junction end, where a fork zone of 40 px is not fitted:
    # the nearest fitted value (paper) misses the rise, its trend continued does not.
    # Pixel rounding only (jitter makes int kappa^2 noise-dominated at this window).
    # Measured (seeds 0-2): paper 0.60-0.71 x the truth, trend continued 0.67-1.17 x: the
    # slope of one window of 5 h is itself noisy
    rc, truth = _clothoid(120.0, 1.0 / 30.0)
    offset = np.random.default_rng(seed).uniform(0.0, 1.0, 2) + 50.0
    path = _noisy_pixel_path(rc + offset, 0.0, seed)
    kw = dict(n_br=1, thickness_px=H, px_per_mm=1.0, trim_px=(1e-9, 40.0))
    e = {m: np.trapezoid(stack_curvature(path, method=m, **kw).kappa_per_mm ** 2,
                         stack_curvature(path, method=m, **kw).s_mm) / truth
         for m in ("paper", "missing")}
    assert abs(e["missing"] - 1.0) < 0.4
    assert abs(e["missing"] - 1.0) < abs(e["paper"] - 1.0)


@pytest.mark.parametrize("l_px,k_end_px,zone_px", [(150.0, 1 / 30.0, 40.0),
                                                    (200.0, 1 / 40.0, 30.0),
                                                    (150.0, 1 / 30.0, 20.0)])
def test_fork_zone_trend_from_centred_fits(l_px, k_end_px, zone_px):
    # a clothoid (curvature rising linearly toward the fork end), sampled at 1 px of arc
    # without noise: its trend, continued into the fork zone, is the curvature itself. The
    # fits within half a window of the zone share one shifted window (flat curvature): the
    # trend is taken beyond them and replaces them. Measured: 1.003-1.006 x the truth (int
    # kappa^2 ds and the end curvature); with the trend over the first fitted window (half of
    # it shifted fits) 0.84-0.95 x and 0.83-0.92 x.
    s = np.linspace(0.0, l_px, 6000)
    th = 0.5 * k_end_px * s ** 2 / l_px
    ds = np.diff(s, prepend=0.0)
    rc = np.stack([-np.cumsum(np.sin(th) * ds), np.cumsum(np.cos(th) * ds)], 1)
    t = np.arange(0.0, l_px + 1e-9, 1.0)
    path = np.stack([np.interp(t, s, rc[:, 0]), np.interp(t, s, rc[:, 1])], 1)
    prof = stack_curvature(path, n_br=1, thickness_px=H, px_per_mm=1.0,
                           trim_px=(1e-9, zone_px))
    energy = np.trapezoid(prof.kappa_per_mm ** 2, prof.s_mm) / (k_end_px ** 2 * l_px / 3.0)
    assert energy == pytest.approx(1.0, abs=0.02)
    assert abs(prof.kappa_per_mm[-1]) / k_end_px == pytest.approx(1.0, abs=0.02)


def test_kink_bounded_by_stack_thickness():
    # a right-angle corner is not a bend a stack of 4 layers can make: |kappa| <= 2 / (4 h)
    a = np.stack([np.arange(60), np.full(60, 60)], 1)
    b = np.stack([np.full(60, 60), np.arange(60, 120)], 1)
    path = np.vstack([a, b[1:]])
    paper = stack_curvature(path, n_br=4, thickness_px=H, px_per_mm=1.0, method="paper",
                            window_px=6.0)
    prof = stack_curvature(path, n_br=4, thickness_px=H, px_per_mm=1.0, window_px=6.0)
    assert np.abs(paper.kappa_per_mm).max() > 2.0 / (4 * H)
    assert np.abs(prof.kappa_per_mm).max() <= 2.0 / (4 * H) + 1e-12


@pytest.mark.parametrize("seed", range(2))
def test_free_ends_and_arcs_unchanged(seed):
    # on an arc the trend is flat, and a free end (no trim given) is never extrapolated
    t = np.linspace(0.0, 200.0 / 80.0, 2000)
    path = _noisy_pixel_path(np.stack([80 * np.sin(t), 80 * np.cos(t)], 1), 0.3, seed)
    kw = dict(n_br=2, thickness_px=H, px_per_mm=50.0)
    p = stack_curvature(path, method="paper", **kw)
    m = stack_curvature(path, **kw)
    np.testing.assert_allclose(m.kappa_per_mm, p.kappa_per_mm)
    pt = stack_curvature(path, method="paper", trim_px=(20.0, 20.0), **kw)
    mt = stack_curvature(path, trim_px=(20.0, 20.0), **kw)
    assert mt.kappa_pm == pytest.approx(pt.kappa_pm, rel=0.05)


def test_energy_uncertainty_grows_with_fork_zones():
    rc, _ = _clothoid(240.0, 1.0 / 30.0)
    path = _noisy_pixel_path(rc + 50.0, 0.3, 0)
    kw = dict(n_br=1, thickness_px=H, px_per_mm=50.0)
    u = [stack_curvature(path, trim_px=(t, t), **kw).energy_rel_uncertainty
         for t in (1e-9, 15.0, 40.0)]
    assert all(np.isfinite(u)) and u[0] >= 0
    assert u[0] < u[1] < u[2]

def test_energy_uncertainty_counts_the_arc_followed_along_a_wall():
    # a zone followed along a merged band's wall is fitted, but not on a free centreline:
    # its share of int kappa^2 ds is the wall model's. Here all the bending lies in the
    # first millimetre, so following it there makes the whole integral the model's
    from crosssection.stages.curvature import _profiles

    s = np.linspace(0.0, 5.0, 501)
    k = np.where(s < 1.0, 0.2, 0.0)

    def rel(forks, noise, walled_mm=(0.0, 0.0), fit_start=0):
        # the profile at 1 px/mm, its noise floor given per mm of its 5 mm
        prof = _profiles(s, k, np.array([0, len(s)]), 1.0, [False], [np.zeros((len(s), 2))],
                         [(fit_start, len(s))], forks=np.array([forks]),
                         walled_px=np.array([walled_mm], float),
                         noise_coef=np.array([noise / 5.0]), noise_var=[0.0])[0]
        return prof.energy_rel_uncertainty

    free = (False, False)
    assert rel(free, 0.0) == 0.0
    assert rel(free, 0.0, walled_mm=(0.0, 1.0)) == pytest.approx(0.0, abs=1e-9)
    assert rel(free, 0.0, walled_mm=(1.0, 0.0)) == pytest.approx(1.0, abs=0.01)
    half = rel(free, 0.0, walled_mm=(0.5, 0.0))
    assert half == pytest.approx(0.5, abs=0.01)
    # the removed noise floor adds its own share
    assert rel(free, 0.004, walled_mm=(0.5, 0.0)) == pytest.approx(half + 0.1, abs=0.01)
    # an extrapolated zone and a followed one overlapping count once
    assert rel((True, False), 0.0, walled_mm=(0.8, 0.0), fit_start=50) == pytest.approx(
        0.8, abs=0.01)


def test_unknown_method_rejected():
    from crosssection.core.errors import ParameterError
    with pytest.raises(ParameterError):
        stack_curvature(np.stack([np.arange(20), np.arange(20)], 1), n_br=1, thickness_px=H,
                        px_per_mm=50.0, method="spline")


def _noisy_arc_profiles(R, n_arcs, sigma_px, seed, length_px=600.0, **kw):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n_arcs):
        t = np.linspace(0.0, length_px / R, 6000)
        c = rng.uniform(0, 1, 2) + R + 10
        path = _noisy_pixel_path(np.stack([c[0] - R * np.sin(t), c[1] + R * np.cos(t)], 1),
                                 sigma_px, seed * 100 + i)
        out.append(stack_curvature(path, n_br=1, thickness_px=H, px_per_mm=50.0,
                                   trim_px=(20.0, 20.0), **kw))
    return out


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("R", [200.0, 600.0])
def test_noise_variance_is_the_curvature_noise(R, seed):
    # the pooled lag estimate against the empirical variance of (kappa - 1/R) over the fitted
    # samples of 6 jittered arcs (sigma 0.4 px). Measured (seeds 0-2): ratio 0.8-1.2
    from crosssection.stages.curvature import noise_variance
    profs = _noisy_arc_profiles(R, 6, 0.4, seed)
    v = noise_variance(profs, np.ones(len(profs), int), thickness_px=H, px_per_mm=50.0)[1]
    k_true = 50.0 / R
    emp = np.mean(np.concatenate([(p.kappa_per_mm[p.fit_start:p.fit_stop] - k_true) ** 2
                                  for p in profs]))
    assert 0.6 < v / emp < 1.5


def _kinked_path(seed, r_px=12.0, arm_px=400.0):
    """A jittered pixel chain: a straight arm, a 90-degree turn of radius ``r_px``, an arm."""
    a = np.linspace(0.0, arm_px, 4000)
    t = np.linspace(0.0, 0.5 * np.pi, 400)
    turn = np.stack([r_px * (1 - np.cos(t)), arm_px + r_px * np.sin(t)], 1)
    xy = np.concatenate([np.stack([np.zeros_like(a), a], 1), turn[1:],
                         turn[-1] + np.outer(a[1:], [1.0, 0.0])])
    return _noisy_pixel_path(xy + 30 + np.random.default_rng(seed).uniform(0, 1, 2), 0.4,
                             seed + 7)


@pytest.mark.parametrize("seed", range(3))
def test_noise_variance_ignores_a_kinked_stack(seed):
    # six jittered arcs and one stack turning by 90 degrees over 12 px: pooled with the others,
    # the kink's own differences read 12 times the arcs' noise (it would be removed from
    # every stack of the scan); left out, the estimate is the arcs' own (measured 0.86-0.95)
    from crosssection.stages.curvature import noise_variance
    profs = _noisy_arc_profiles(600.0, 6, 0.4, seed)
    kink = stack_curvature(_kinked_path(seed), n_br=1, thickness_px=H, px_per_mm=50.0,
                           trim_px=(20.0, 20.0))
    emp = np.mean(np.concatenate([(p.kappa_per_mm[p.fit_start:p.fit_stop] - 50.0 / 600.0) ** 2
                                  for p in profs]))
    v = noise_variance(profs + [kink], np.ones(7, int), thickness_px=H, px_per_mm=50.0)[1]
    assert 0.6 < v / emp < 1.5


def _fitted_energy(p, v=0.0):
    """``int kappa^2 ds`` over a profile's fitted samples, the noise floor ``v`` removed."""
    from crosssection.stages.branches import bending_energy
    sl = slice(p.fit_start, p.fit_stop)
    return bending_energy(p.kappa_per_mm[sl], p.s_mm[sl], rod_length_mm=1.0,
                          noise_var_per_mm2=v)


@pytest.mark.parametrize("seed", range(3))
def test_noise_floor_removed_from_gentle_arcs(seed):
    # long single-layer arcs of curvature 0.083 /mm: the window fit's noise alone makes
    # int kappa^2 ds several times the truth; the measured floor removed, within 25 %.
    # Measured over the fitted parts (the fork zones' trend is tested apart, below;
    # seeds 0-2): raw 2.2-2.3 x, removed 0.98-1.17 x
    from crosssection.stages.curvature import noise_variance
    R = 600.0
    profs = _noisy_arc_profiles(R, 6, 0.4, seed, method="paper")
    v = noise_variance(profs, np.ones(len(profs), int), thickness_px=H, px_per_mm=50.0)[1]
    raw = sum(_fitted_energy(p) for p in profs)
    fixed = sum(_fitted_energy(p, v) for p in profs)
    truth = sum(p.s_mm[p.fit_stop - 1] - p.s_mm[p.fit_start] for p in profs) * (50.0 / R) ** 2
    assert raw / truth > 1.5
    assert fixed / truth == pytest.approx(1.0, abs=0.25)


@pytest.mark.parametrize("h_px,sigma", [(5.0, 0.0), (5.0, 0.4), (2.5, 0.2)])
def test_trend_slope_noise_model(h_px, sigma, monkeypatch):
    # On stacks of constant curvature (no trend to find) the slope of the fork zones' trend
    # is noise: its variance is c v / w^2 with c = _SLOPE_NOISE (measured median 2.4,
    # quartiles 2.0-2.9; here 1.9-6.0 per n_br, medians 2.6-3.6), and the gate at four
    # deviations continues almost none of these noise slopes (here 0-1.7 % of 240 trends;
    # 3-6 % at two deviations).
    import crosssection.stages.curvature as cv
    from crosssection.stages.curvature import _SLOPE_NOISE, noise_variance

    slopes, continued = [], []
    orig = cv._slope
    monkeypatch.setattr(cv, "_slope", lambda ds, dk: slopes.append(orig(ds, dk)) or slopes[-1])
    rng = np.random.default_rng(int(10 * h_px + 100 * sigma))
    ratios = []
    for nb in (1, 2, 3):
        paths = []
        for i in range(40):
            R, length = 600.0, 40 * nb * h_px + 100
            t = np.linspace(0.0, length / R, 4000)
            a0 = rng.uniform(0, 2 * np.pi)
            x, y = R * np.sin(t), R * (1 - np.cos(t))
            xy = np.stack([x * np.sin(a0) + y * np.cos(a0), x * np.cos(a0) - y * np.sin(a0)], 1)
            paths.append(_noisy_pixel_path(xy + rng.uniform(0, 1, 2) + 10, sigma, i))
        kw = dict(n_br=nb, thickness_px=h_px, px_per_mm=10 * h_px, trim_px=(6 * h_px, 6 * h_px))
        profs = [stack_curvature(p, method="paper", **kw) for p in paths]
        v = noise_variance(profs, np.full(len(profs), nb), thickness_px=h_px,
                           px_per_mm=10 * h_px)[nb]
        slopes.clear()
        fills = [stack_curvature(p, noise_var_per_mm2=v, **kw) for p in paths]
        a = np.array(slopes)
        w = 5 * nb * h_px / (10 * h_px)
        ratios.append(np.mean(a * a) * w * w / v)
        for prof, paper in zip(fills, profs):  # a continued trend changes the zone
            continued += [not np.allclose(prof.kappa_per_mm[:prof.fit_start],
                                          paper.kappa_per_mm[:paper.fit_start]),
                          not np.allclose(prof.kappa_per_mm[prof.fit_stop:],
                                          paper.kappa_per_mm[paper.fit_stop:])]
    assert 0.5 * _SLOPE_NOISE < np.median(ratios) < 1.3 * _SLOPE_NOISE
    assert np.mean(continued) < 0.04


def test_noise_variance_fallback_and_guards():
    from crosssection.stages.branches import bending_energy
    from crosssection.core.errors import ParameterError
    from crosssection.stages.curvature import noise_variance
    profs = _noisy_arc_profiles(300.0, 3, 0.4, 0)
    # a window with no stack of its own takes the measured one scaled as w^-5
    v = noise_variance(profs, np.ones(3, int), thickness_px=H, px_per_mm=50.0)
    short = [stack_curvature(np.stack([np.arange(12), np.arange(12)], 1), n_br=2,
                             thickness_px=H, px_per_mm=50.0)]
    v2 = noise_variance(profs + short, np.array([1, 1, 1, 2]), thickness_px=H,
                        px_per_mm=50.0)
    assert v2[2] == pytest.approx(v2[1] / 32.0) and v[1] > 0
    # nothing measurable: no correction, or unknown when asked to say so
    assert noise_variance(short, [1], thickness_px=H, px_per_mm=50.0) == {1: 0.0}
    assert noise_variance(short, [1], thickness_px=H, px_per_mm=50.0,
                          unmeasured=None) == {1: None}
    assert noise_variance(profs, np.ones(3, int), thickness_px=H, px_per_mm=50.0,
                          unmeasured=None) == v
    # the energy never goes negative, and a bad variance is refused
    k = np.full(50, 0.01)
    s = np.linspace(0.0, 1.0, 50)
    assert bending_energy(k, s, rod_length_mm=1.0, noise_var_per_mm2=1.0) == 0.0
    with pytest.raises(ParameterError):
        bending_energy(k, s, rod_length_mm=1.0, noise_var_per_mm2=-1.0)


def test_contact_arc_of_peeling_and_fanned_bands():
    from crosssection.stages.curvature import contact_arc_px
    s = np.arange(0.0, 120.0)
    # two bands of half-width 2.5 px side by side (centres 5 px apart) for 40 px, then
    # parting on a parabola: contact while the gap is below 1 px
    off = 2.5 + np.where(s < 40, 0.0, (s - 40) ** 2 / 200.0)
    a = np.stack([100 - off, s], 1)
    b = np.stack([100 + off, s], 1)
    arc = contact_arc_px(a, 2.5, [(b, 2.5)])
    assert 40 < arc < 40 + np.sqrt(2 * 100 * 1.0) + 2
    # bands leaving a common point 60 degrees apart are apart within two widths
    t = np.deg2rad(30.0)
    c = np.stack([100 - s * np.sin(t), s * np.cos(t)], 1)
    d = np.stack([100 + s * np.sin(t), s * np.cos(t)], 1)
    assert contact_arc_px(c, 2.5, [(d, 2.5)]) < 12
    # no neighbour, no contact
    assert contact_arc_px(c, 2.5, []) == 0.0


def _raster(rc):
    """Integer pixel path of a densely sampled curve (consecutive repeats dropped)."""
    p = np.round(np.asarray(rc, float)).astype(int)
    keep = np.r_[True, np.any(np.diff(p, axis=0) != 0, axis=1)]
    return p[keep]


def _link_between_two_junctions(left, link, right, j0_rc, j1_rc):
    """Stack graph of three stacks: free end - left - junction - link - junction - right -
    free end (stack ids 0, 1, 2)."""
    from crosssection.stages.graph import StackGraph

    paths = [_raster(left), _raster(link), _raster(right)]
    g = nx.MultiGraph()
    ends = [(2, 0), (0, 1), (1, 3)]
    for sid, (u, v) in enumerate(ends):
        g.add_edge(u, v, key=sid, stack_id=sid)
    return StackGraph(graph=g, node_rc={0: np.array(j0_rc, float), 1: np.array(j1_rc, float),
                                        2: left[0], 3: right[-1]},
                      node_kind={0: "junction", 1: "junction", 2: "end", 3: "end"},
                      paths=paths, ends=ends)


def _band_through_link(R, arc_px, link_px, bulge_px, r0=200.0, c0=300.0):
    """A band bent at radius R (px) on both sides of a link of ``link_px`` between two
    junctions: arcs of ``arc_px`` curving the same way (centre below), tangent to the row at
    the joins, and the link bulging ``bulge_px`` off it (the skeleton between two medial-axis
    fork points). Returns the stack graph and the two junction points (row, col)."""
    t = np.linspace(0.0, 1.0, 4000)
    a = (arc_px / R) * t[::-1]
    left = np.c_[r0 + R * (1 - np.cos(a)), c0 - R * np.sin(a)]
    c1 = c0 + link_px
    right = np.c_[r0 + R * (1 - np.cos(a[::-1])), c1 + R * np.sin(a[::-1])]
    link = np.c_[r0 - bulge_px * np.sin(np.pi * t), c0 + link_px * t]
    graph = _link_between_two_junctions(left, link, right, (r0, c0), (r0, c1))
    return graph, (int(r0), int(c0)), (int(r0), int(c1))


@pytest.mark.parametrize("link_px, fitted", [(24.0, False), (60.0, True)])
def test_lump_between_two_junctions_takes_its_neighbours_curvature(link_px, fitted):
    """A band of 3 layers bent at R = 400 px runs through two junctions 24 px apart (less
    than twice its width, 2 r = 20 px): the skeleton between them is the link between two
    medial-axis fork points, here a bulge of 6 px (curvature about 4 /mm), not the band's
    centreline. It is not fitted and takes the neighbours' curvature (0.125 /mm); a link of
    60 px (three widths) is fitted as before, whole: every sample lies in a fork zone, so
    all its energy counts as uncertain."""
    from crosssection.stages.curvature import stack_profiles

    R = 400.0
    graph, _, _ = _band_through_link(R, 400.0, link_px, 6.0)
    distance = np.full((600, 1000), 10.0)
    prof = stack_profiles(graph, np.array([3, 3, 3]), distance, thickness_px=H,
                          px_per_mm=50.0)
    lump = prof[1]
    if fitted:
        assert lump.fit_stop - lump.fit_start == len(lump.s_mm)
        assert lump.energy_rel_uncertainty >= 1.0
        assert prof[0].energy_rel_uncertainty < 1.0
        return
    k_true = 50.0 / R  # 1/mm
    assert np.all(np.abs(np.abs(lump.kappa_per_mm) / k_true - 1) < 0.5)
    assert lump.fit_start == lump.fit_stop == 0
    # the same sign as the band's (turning the same way along the path)
    assert np.sign(lump.kappa_per_mm.mean()) == np.sign(prof[0].kappa_per_mm.mean())
    assert lump.energy_rel_uncertainty >= 1.0


def test_link_within_two_wide_junction_blobs_is_not_fitted():
    """The same 60-px link (three band widths: fitted when the junctions are as wide as the
    band) between two junction blobs of inscribed radius 20 px (thick stacks meeting, as at
    epsilon 19): each fork's hook reaches one r_J beyond an overlap of r_J, 80 px of the link
    in all, so no sample of it is the band's own centreline. It takes the neighbours'
    curvature instead of fitting the bulge between the fork points (fitted whole it read
    4.9 times the band's curvature, root mean square: 24 times its energy)."""
    from crosssection.stages.curvature import stack_profiles

    R = 400.0
    graph, j0, j1 = _band_through_link(R, 400.0, 60.0, 6.0)
    distance = np.full((600, 1000), 10.0)
    distance[j0] = distance[j1] = 20.0
    prof = stack_profiles(graph, np.array([3, 3, 3]), distance, thickness_px=H,
                          px_per_mm=50.0)
    lump = prof[1]
    assert lump.fit_start == lump.fit_stop == 0
    k_true = 50.0 / R  # 1/mm
    assert np.all(np.abs(np.abs(lump.kappa_per_mm) / k_true - 1) < 0.5)
    # with band-wide junctions the same link is fitted (the case above)
    prof_narrow = stack_profiles(graph, np.array([3, 3, 3]), np.full((600, 1000), 10.0),
                                 thickness_px=H, px_per_mm=50.0)
    assert prof_narrow[1].fit_stop > prof_narrow[1].fit_start


def test_lump_takes_its_neighbours_measured_curvature_not_their_continued_trend():
    """A lump takes, across its junction, its neighbour's centred fit nearest to that
    junction: a measured value. The neighbour's shifted fits next to the junction may hold a
    trend continued beyond its centred fits (_fill_fork_zones); on compacted renders a
    13-layer lump 10 mm long took such a value and 12 times its earlier energy (epsilon 30,
    configuration 1: total energy +601 % -> +172 % when it takes the centred fit)."""
    from crosssection.stages.curvature import _fill_unfitted_stacks, _profiles

    px = 50.0
    n = 200
    s_px = np.arange(n, dtype=float)  # 4 mm, one layer: window 5 h = 25 px
    k_mm = np.full(n, 0.5)
    k_mm[n - 12:] = np.linspace(0.5, 3.0, 12)  # a trend continued over the last half window
    rc = np.stack([np.zeros(n), s_px], 1)
    source, lump = _profiles(np.r_[s_px, np.arange(30.0)], np.r_[k_mm / px, np.zeros(30)],
                             np.array([0, n, n + 30]), px, [False, False], [rc, rc[:30]],
                             [(0, n), (0, 0)])
    out = _fill_unfitted_stacks([source, lump], {7: [(0, 1), (1, 0)]}, np.array([1, 1]),
                                px_per_mm=px, thickness_px=H)
    assert np.allclose(out[1].kappa_per_mm, 0.5)
    assert out[0] is source


def test_unfitted_lump_keeps_its_own_curvature_bound():
    """A thick lump (20 layers, 24 px between two junctions) between single sheets bent at
    R = 25 px (2 /mm) takes their curvature only up to its own bound 2 / (n_br h): its
    innermost layer cannot have a negative radius (without the bound a 41-layer lump of a
    compacted render took 2.7 /mm)."""
    from crosssection.stages.curvature import stack_profiles

    graph, _, _ = _band_through_link(25.0, 60.0, 24.0, 0.0)
    n_br = np.array([1, 20, 1])
    prof = stack_profiles(graph, n_br, np.full((600, 1000), 10.0), thickness_px=H,
                          px_per_mm=50.0)
    lump = prof[1]
    assert lump.fit_start == lump.fit_stop == 0
    kmax = 2.0 * 50.0 / (20 * H)
    assert np.max(np.abs(prof[0].kappa_per_mm)) > 1.5 * kmax  # the neighbours are tighter
    assert np.all(np.abs(lump.kappa_per_mm) <= kmax + 1e-9)
    assert np.all(np.abs(lump.kappa_per_mm) > 0.5 * kmax)


def _s_curve_rc(R, length_px, n=6000):
    """Two arcs of radius R joined where the curvature reverses: (row, col), and arc length."""
    s = np.linspace(0.0, length_px, n)
    k = np.where(s < length_px / 2, 1.0 / R, -1.0 / R)
    th = np.concatenate([[0.0], np.cumsum(k[:-1] * np.diff(s))])
    x = np.concatenate([[0.0], np.cumsum(np.cos(th[:-1]) * np.diff(s))])
    y = np.concatenate([[0.0], np.cumsum(np.sin(th[:-1]) * np.diff(s))])
    return np.stack([y, x], 1)


@pytest.mark.parametrize("seed", range(3))
def test_noise_variance_where_the_curvature_reverses(seed):
    # jittered S-curves (R = 100 px, the curvature reversing once): the pairs straddling the
    # reversal add a term growing as the lag, which two lags counted as noise (1.5-2.5 x the
    # empirical variance of kappa - kappa_true away from the reversal); three lags remove it.
    # Measured (seeds 0-2): 0.49-0.83
    from crosssection.stages.curvature import noise_variance
    R, rng, profs, err = 100.0, np.random.default_rng(seed), [], []
    for i in range(6):
        path = _noisy_pixel_path(_s_curve_rc(R, 600.0) + 300 + rng.uniform(0, 1, 2), 0.4,
                                 seed * 100 + i)
        p = stack_curvature(path, n_br=1, thickness_px=H, px_per_mm=50.0, trim_px=(20.0, 20.0))
        profs.append(p)
        s = p.s_mm[p.fit_start:p.fit_stop] * 50.0
        k = p.kappa_per_mm[p.fit_start:p.fit_stop]
        mid = 0.5 * p.s_mm[-1] * 50.0
        far = np.abs(s - mid) > 5 * H + default_smooth_px(H)  # beyond the window straddling it
        k_true = np.where(s < mid, 50.0 / R, -50.0 / R)
        e = min((k - k_true)[far], (k + k_true)[far], key=lambda x: float(x @ x))
        err.append(e)
    emp = np.mean(np.concatenate(err) ** 2)
    v = noise_variance(profs, np.ones(len(profs), int), thickness_px=H, px_per_mm=50.0)[1]
    assert 0.35 < v / emp < 1.3


@pytest.mark.parametrize("zone_px", [40.0, 50.0, 60.0])
def test_fork_zone_turns_at_most_a_quarter_turn(zone_px):
    """A single sheet whose visible curvature rises steeply toward a fork zone (a clothoid,
    0 to 1/15 px^-1 over 150 px): its trend, continued over a zone of 40-60 px, would turn it
    by 2.4-3.2 radians there, a loop inside the junction's ink. The zone turns by a quarter
    turn at most (a branch's true turn over 1.4-3 mm from a junction is at most 1.23 rad on
    compacted rods at epsilon 19, and the network generator's zones turn by at most 1.48 rad;
    hooks of thin sheets into the wide junction blobs of compacted renders were extrapolated
    to 4-8.5 radians, 95 % of their stacks' energy)."""
    from crosssection.stages.curvature import _fill_fork_zones

    rc, _ = _clothoid(150.0, 1.0 / 15.0)
    t = np.arange(0.0, 150.0 + 1e-9, 1.0)
    s = np.linspace(0.0, 150.0, len(rc))
    path = np.stack([np.interp(t, s, rc[:, 0]), np.interp(t, s, rc[:, 1])], 1)
    kw = dict(n_br=1, thickness_px=H, px_per_mm=1.0, trim_px=(1e-9, zone_px))
    prof = stack_curvature(path, **kw)
    paper = stack_curvature(path, method="paper", **kw)
    free = _fill_fork_zones(paper, 1, H, 1.0, (True, True), max_turn=np.inf)

    def zone_turn(p):
        z = slice(p.fit_stop - 1, len(p.s_mm))
        return np.trapezoid(np.abs(p.kappa_per_mm[z]), p.s_mm[z])

    assert zone_turn(free) > 1.5
    assert zone_turn(prof) <= np.pi / 2 + 1e-9
    # the fitted part is not touched beyond the shifted fits the trend replaces (half a
    # window from the zone)
    f = prof.s_mm < prof.s_mm[prof.fit_stop - 1] - 2.5 * H
    np.testing.assert_array_equal(prof.kappa_per_mm[f], free.kappa_per_mm[f])


def _tangential_fork(R_px, *, arc_deg=50.0, angle_deg=0.0, noise=0.0, seed=0):
    """A scan of a 3-layer band splitting at x = 350 px into its 2 lower layers, straight on,
    and its top layer peeling off along an arc of radius ``R_px`` tangent to the band (or,
    with ``angle_deg``, leaving it at that angle): the arm's outer layer is the merged ink's
    wall up to the fork. Returns the RGB scan, its calibration and the arc's
    ``int kappa^2 ds`` (1/px)."""
    import cv2

    from crosssection.core.calibration import Calibration

    cal = Calibration.nonlinear(0.1)
    w = {k: float(cal.width(k)) * 50.0 for k in (1, 2, 3)}
    mask = np.zeros((600, 900), np.uint8)

    def draw(rc, width):
        p = np.round(np.asarray(rc)[:, ::-1] * 16).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(mask, [p], False, 1, int(round(width)), cv2.LINE_8, 4)

    y0, x_f = 350.0, 350.0
    xs = np.linspace(100.0, x_f, 400)
    draw(np.c_[np.full_like(xs, y0), xs], w[3])
    xs = np.linspace(x_f - 2.0, 800.0, 600)
    draw(np.c_[np.full_like(xs, y0 + (w[3] - w[2]) / 2), xs], w[2])
    yb = y0 - (w[3] - w[1]) / 2
    t = np.linspace(0.0, np.radians(arc_deg), 800)
    a = np.radians(angle_deg)
    arc = np.c_[yb - R_px * (np.cos(a) - np.cos(a + t)), x_f + R_px * (np.sin(a + t) - np.sin(a))]
    draw(np.r_[np.c_[[yb], [x_f - 2.0]], arc], w[1])
    rgb = np.full((600, 900, 3), 245.0)
    rgb[mask > 0] = (40, 50, 190)
    if noise:
        rgb += np.random.default_rng(seed).normal(0.0, noise, rgb.shape)
    return np.clip(rgb, 0, 255).astype(np.uint8), cal, np.radians(arc_deg) / R_px


def _arm_energies(rgb, cal, method):
    """``int kappa^2 ds`` (1/px) of every stack and its layer count."""
    import crosssection

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = crosssection.analyze(rgb, px_per_mm=50.0, thickness_mm=0.1, calibration=cal,
                                 curvature_method=method)
    k2s = [np.trapezoid(p.kappa_per_mm ** 2, p.s_mm) / 50.0 for p in r.profiles]
    return np.array(k2s), r.tables["stacks"]["n_br"].to_numpy()


def test_walls_read_a_tangential_peel_where_the_skeleton_hooks():
    """A layer peels tangentially off a band (radius R = 250-600 px): inside the fork zone
    its outer layer is the merged ink's wall, and the followed centreline reads the arc; the
    skeleton hooks into the medial-axis fork, and the trend continued from it reads the
    hook. Measured: walls 0.87-0.99 x the arc's int kappa^2 ds (mean |error| 0.08), missing
    0.87-1.28 x (0.14); the straight stacks stay straight; noise of 8 grey levels changes
    nothing."""
    err = {"walls": [], "missing": []}
    for R_px, noise in ((250.0, 0.0), (300.0, 0.0), (300.0, 8.0), (400.0, 0.0), (500.0, 0.0),
                        (600.0, 0.0)):
        rgb, cal, truth = _tangential_fork(R_px, noise=noise)
        for method in err:
            k2s, n_br = _arm_energies(rgb, cal, method)
            assert sorted(n_br) == [1, 2, 3]
            arm = int(np.flatnonzero(n_br == 1)[0])
            err[method].append(k2s[arm] / truth - 1.0)
            if method == "walls":
                assert -0.2 < err[method][-1] < 0.1
                assert np.all(np.delete(k2s, arm) < 0.01 * truth)
    assert np.mean(np.abs(err["walls"])) < 0.7 * np.mean(np.abs(err["missing"]))


def test_walls_leave_a_fork_at_an_angle_to_the_fork_zone():
    """An arm leaving the band at 40 degrees turns its wall round a corner of the ink: no
    layer runs along it, the follow stops, and the zone is the missing-data zone."""
    rgb, cal, _ = _tangential_fork(300.0, angle_deg=40.0)
    walls, _ = _arm_energies(rgb, cal, "walls")
    missing, _ = _arm_energies(rgb, cal, "missing")
    np.testing.assert_allclose(walls, missing, rtol=1e-9, atol=1e-12)


def test_short_links_take_their_trends_where_no_noise_is_measured(sample_dir):
    # the dense sample scan (201 branches, most of its energy in links shorter than 2 mm)
    # has no stretch of six lags, so no measured noise: its links fitted whole take their
    # trends, as its other stacks do. Measured: -18 % of the truth; with their flat end
    # fits -34 %
    import json
    import warnings

    import crosssection
    from crosssection.stages.curvature import _fill_fork_zones

    truth = json.loads((sample_dir / "scenes" / "scan_03_dense" / "truth" / "summary.json")
                       .read_text())["total_energy"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(str(sample_dir / "scan_03_dense.png"), px_per_mm=50.0,
                                   calibration=str(sample_dir / "calibration.csv"))
    assert abs(res.summary["total_energy"] / truth - 1.0) < 0.25
    # the switch itself, on one S-link fitted whole: a noise of 0 (what the pipeline passes
    # where none is measured) takes the trends, an unknown one (None) keeps the fits
    rc, _ = _s_link(60.0, 1.0 / 25.0)
    prof = stack_curvature(_noisy_pixel_path(rc + 50.3, 0.0, 0), n_br=1, thickness_px=H,
                           px_per_mm=1.0, trim_px=(40.0, 40.0), method="paper")
    e = {v: np.trapezoid(_fill_fork_zones(prof, 1, H, 1.0, noise_var_per_mm2=v)
                         .kappa_per_mm ** 2, prof.s_mm)
         for v in (0.0, None)}
    paper = np.trapezoid(prof.kappa_per_mm ** 2, prof.s_mm)
    assert e[None] == pytest.approx(paper, rel=1e-9) and e[0.0] > 1.2 * paper


def _arc_band(radius_px, width_px, start_deg, size=700, sub=8):
    """A band of ``width_px`` along a circle of ``radius_px`` about the image centre, 200
    degrees from ``start_deg``, drawn 8 times finer and averaged down (a scan's pixels):
    its ink coverage (0-255), and the centre."""
    import cv2

    big = np.zeros((size * sub, size * sub), np.uint8)
    c = size * sub // 2
    cv2.ellipse(big, (c, c), (int(radius_px * sub), int(radius_px * sub)), 0, start_deg,
                start_deg + 200, 255, thickness=int(width_px * sub))
    cover = cv2.resize(big, (size, size), interpolation=cv2.INTER_AREA)
    # the drawing's centre in pixel coordinates of the small image
    return cover, (c + 0.5) / sub - 0.5


@pytest.mark.parametrize("width_px,h_px", [(3, 2.5), (5, 5.0), (11, 5.0)])
def test_centreline_between_the_walls_is_nearer_the_arc(width_px, h_px):
    # the thinning's staircases depend on the band's direction, its walls do not. Measured
    # over radii 60-300 px and five angles (medians over the 15 bands, widths 3/5/11 px):
    # the smoothed skeleton's radial scatter 0.18/0.17/0.19 px, the centreline between the
    # mask's walls 0.11/0.11/0.13 px, between the walls where the ink's coverage crosses the
    # cut 0.045/0.048/0.077 px
    import cv2

    from crosssection.core.polyline import smooth_paths
    from crosssection.stages.curvature import _midlines
    from crosssection.stages.graph import stack_graph
    from crosssection.stages.junctions import median_radii_px
    from crosssection.stages.skeleton import skeletonize_mask

    sd = {"skeleton": [], "walls": [], "feature": []}
    for radius in (60.0, 150.0, 300.0):
        for start in range(0, 90, 22):
            cover, centre = _arc_band(radius, width_px, start)
            mask = cover > 127
            dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
            skel = skeletonize_mask(mask, l_min_px=10, distance_px=dist)
            _, sg, _ = stack_graph(skel, dist, merge_px=3, thickness_px=h_px)
            path = np.asarray(sg.paths[int(np.argmax(sg.length_px))], float)
            sm_px = default_smooth_px(h_px)
            smoothed = smooth_paths([path], window_px=sm_px, closed=[False])
            radii = median_radii_px([path], dist)
            mid = _midlines([path], smoothed, [False], radii, dist.astype(np.float32))
            sub = _midlines([path], smoothed, [False], radii, dist.astype(np.float32),
                            edge=(cover.astype(np.int16), 127.5))
            for key, p in (("skeleton", path), ("walls", mid[0]), ("feature", sub[0])):
                q = smooth_paths([p], window_px=sm_px, closed=[False])[0]
                r = np.hypot(q[:, 0] - centre, q[:, 1] - centre)
                n = len(r)
                sd[key].append(np.std(r[n // 5: -n // 5]))  # away from the band's ends
    skel_sd, walls_sd, sub_sd = (np.median(sd[k]) for k in ("skeleton", "walls", "feature"))
    assert walls_sd < 0.14 and walls_sd < 0.75 * skel_sd, (walls_sd, skel_sd)
    assert sub_sd < 0.09 and sub_sd < 0.7 * walls_sd, (sub_sd, walls_sd)


def test_noise_outlier_beside_estimates_scattered_about_zero():
    # estimates of the lags' noise scatter about 0 where it is below what they resolve; a
    # stack with bending at the lags' scale beside them is still an outlier (an independent
    # generator's scan: pooled in, it set the scan's noise at 0.069 /mm^2)
    from crosssection.stages.curvature import _without_outliers

    v = np.array([-0.018, 0.0017, 0.0033, 0.0061, 0.30])
    w = np.array([191.0, 224.0, 268.0, 200.0, 270.0])
    kept, _ = _without_outliers(v, w)
    assert kept.max() < 0.01 and len(kept) == 4
    # a scatter about 0 alone loses nothing
    v = np.array([-0.001, -0.0005, 0.0002, 0.0008, 0.0012])
    kept, _ = _without_outliers(v, np.ones(5))
    assert len(kept) == 5


def test_noise_outlier_of_two_stacks():
    # a stack hooked across a layer step beside a gentle arc, the two stacks of their window:
    # pooled, the hook's estimate removed 92 % of the arc's energy
    from crosssection.stages.curvature import _without_outliers

    kept, w = _without_outliers(np.array([0.166, 0.0005]), np.array([444.0, 284.0]))
    assert kept.tolist() == [0.0005] and w.tolist() == [284.0]
    # two noise-only estimates (0.3-1.9 times their pooled value) are both kept
    for pair in ([0.3, 1.9], [-0.002, 0.01], [0.0, 0.2]):
        kept, _ = _without_outliers(np.array(pair), np.ones(2))
        assert len(kept) == 2, pair


@pytest.mark.parametrize("h_px", [1.0, 2.0, 2.5, 3.0, 3.5, 3.8, 4.0, 4.5, 5.0, 5.5, 6.0, 7.5, 10.0])
def test_smoothing_window_is_about_two_thicknesses_never_wider(h_px):
    # an odd window of 2 floor(h) + 1 points: at most 2 h + 1, more than 2 h - 1; rounded to
    # the nearest instead, h = 3.5 px took 9 points (2.6 h) and lost bending near the forks
    w = default_smooth_px(h_px)
    assert w % 2 == 1
    assert 2 * h_px - 1 < w <= 2 * h_px + 1
    # a scale read from a file's DPI lands a hair below its nominal value
    assert default_smooth_px(h_px * (1 - 1e-12)) == w


def test_a_scan_of_rings_alone_measures_its_noise_on_them():
    """No open stack: the fit noise is measured on the closed loops (taken as 0, a lone ring
    of radius 8 mm reads its 4 pi^2 at +27 %)."""
    import math
    import warnings

    import crosssection

    n = 900
    yy, xx = np.mgrid[0:n, 0:n]
    r = np.hypot(xx - 450.3, yy - 449.7)
    rgb = np.empty((n, n, 3), np.uint8)
    rgb[:] = (246, 245, 240)
    rgb[(r > 397.5) & (r <= 402.5)] = (36, 66, 181)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(rgb, px_per_mm=50)
    prof = res.profiles[0]
    assert prof.closed and prof.noise_var_per_mm2 > 0
    assert res.summary["total_energy"] / (4 * math.pi ** 2) - 1 < 0.15
    assert res.summary["total_energy_rel_uncertainty"] > 0


@pytest.mark.parametrize("r_px", [7.5, 10.0])
def test_a_circle_tighter_than_the_window_is_fitted_on_a_shorter_one(r_px):
    # a closed circle of radius 1.5-2 h, sampled every pixel of arc: its half window (2.5 h)
    # turns by 1.25-1.7 rad, where the parabola overshoots (the paper's method: 2.15 and 1.45
    # times the curvature); refitted, what is left is the smoothing's shrinking of so tight
    # a circle, k (k + 1) / (6 R^2) = 8.9 and 5.0 % (1.10 and 1.08 times)
    t = np.arange(0.0, 2 * np.pi * r_px) / r_px
    p = np.column_stack([100 + r_px * np.sin(t), 100 + r_px * np.cos(t)])
    ours = stack_curvature(p, n_br=1, thickness_px=H, px_per_mm=50.0, closed=True)
    paper = stack_curvature(p, n_br=1, thickness_px=H, px_per_mm=50.0, closed=True,
                            method="paper")
    assert abs(ours.kappa_m * r_px / 50.0 - 1) < 0.12, ours.kappa_m
    assert paper.kappa_m * r_px / 50.0 > 1.4, paper.kappa_m


@pytest.mark.parametrize("r_px", [10.0, 12.0, 15.0])
def test_a_loop_no_longer_than_the_window_reads_its_curvature(r_px):
    # a ring of three sheets whose circumference is about the window (5 n_br h = 75 px): a
    # window capped at the whole loop read no curvature (a parabola round a whole circle)
    t = np.arange(0.0, 2 * np.pi * r_px) / r_px
    p = np.column_stack([100 + r_px * np.sin(t), 100 + r_px * np.cos(t)])
    prof = stack_curvature(p, n_br=3, thickness_px=H, px_per_mm=50.0, closed=True,
                           smooth_px=1)
    assert abs(prof.kappa_m * r_px / 50.0 - 1) < 0.08, prof.kappa_m


@pytest.mark.parametrize("n_br, r_px", [(3, 10.0), (2, 7.5)])
def test_a_u_turn_the_window_spans_whole_keeps_its_energy(n_br, r_px):
    # legs of 80 px and a half circle: the windows beside the turn, spanning both legs, read it
    # spread out (0.67 of its int kappa^2 ds at n_br = 3, r = 2 h) until refitted by the turn
    # their window holds
    leg = np.arange(0.0, 80.0)
    t = np.arange(0.0, np.pi * r_px) / r_px
    xy = np.concatenate([np.column_stack([80.0 - leg, np.zeros_like(leg)]),
                         np.column_stack([-r_px * np.sin(t), r_px - r_px * np.cos(t)]),
                         np.column_stack([leg, np.full_like(leg, 2 * r_px)])])
    p = np.column_stack([500 - xy[:, 1], 500 + xy[:, 0]])
    prof = stack_curvature(p, n_br=n_br, thickness_px=H, px_per_mm=1.0)
    energy = np.trapezoid(prof.kappa_per_mm ** 2, prof.s_mm) * r_px / np.pi
    assert 0.85 < energy < 1.15, energy


@pytest.mark.parametrize("kw", [dict(thickness_px=0.0), dict(px_per_mm=0.0), dict(n_br=0),
                                dict(window_px=1.0), dict(noise_var_per_mm2=-1.0),
                                dict(ends="Shift"), dict(trim_px=(1.0, 2.0, 3.0)),
                                dict(px_per_mm=float("nan"))])
def test_stack_curvature_refuses_what_it_cannot_read(kw):
    p = np.column_stack([np.zeros(60), np.arange(60.0)])
    args = dict(n_br=1, thickness_px=H, px_per_mm=50.0) | kw
    with pytest.raises(ParameterError):
        stack_curvature(p, **args)
    with pytest.raises(ParameterError, match="not finite"):
        stack_curvature(np.vstack([p, [[np.nan, 3.0]]]), n_br=1, thickness_px=H,
                        px_per_mm=50.0)


def test_noise_variance_without_pairs_asked_and_none_found():
    short = stack_curvature(np.column_stack([np.zeros(30), np.arange(30.0)]), n_br=1,
                            thickness_px=5.0, px_per_mm=50.0)
    assert noise_variance([short], [1], thickness_px=5.0, px_per_mm=50.0,
                          min_pairs=0) == {1: 0.0}


def test_an_open_float_path_with_ends_apart_is_not_closed():
    t = np.linspace(0.0, 1.9 * np.pi, 120)
    p = np.column_stack([40 * np.sin(t), 40 * np.cos(t)])  # ends 12 px apart
    assert not is_closed(p)
    assert not is_closed(np.array([[0.0, 0.0], [0.0, 5.0], [3.0, 5.0], [2.8, 0.0]]))
    assert is_closed(np.array([[0.0, 0.0], [0.0, 5.0], [3.0, 5.0], [0.6, 0.7]]))
