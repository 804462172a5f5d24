"""The vectorised window fits of the curvature stage against a point-by-point reference.

``_ref_solve3`` and ``_ref_parabola_curvature`` are the loops that the vectorised
``_parabola_curvatures`` replaces, kept here as plain Python: the reference of every test.
"""
from __future__ import annotations

import numpy as np
import pytest

from crosssection.core import polyline
from crosssection.stages import curvature
from crosssection.stages.curvature import _parabola_curvatures, stack_curvature


def _parabola_curvature(*fit):
    """The vectorised fits of one path (a one-entry batch)."""
    return _parabola_curvatures([fit])[0]

#: agreement asked of the vectorised fits: relative where the curvature is not about 0,
#: absolute (1/px) near 0
RTOL = 1e-9
ATOL = 1e-12


# ---- the reference: one point at a time -------------------------------------------------

def _ref_solve3(S0, S1, S2, S3, S4, T0, T1, T2):
    """Least-squares parabola: [[S4 S3 S2],[S3 S2 S1],[S2 S1 S0]] (a b c) = (T2 T1 T0)."""
    det = (S4 * (S2 * S0 - S1 * S1) - S3 * (S3 * S0 - S1 * S2) + S2 * (S3 * S1 - S2 * S2))
    if not (abs(det) > 1e-9 * S4 * S2 * S0):
        return np.nan, np.nan
    deta = (T2 * (S2 * S0 - S1 * S1) - S3 * (T1 * S0 - S1 * T0) + S2 * (T1 * S1 - S2 * T0))
    detb = (S4 * (T1 * S0 - T0 * S1) - T2 * (S3 * S0 - S1 * S2) + S2 * (S3 * T0 - T1 * S2))
    return deta / det, detb / det


def _ref_parabola_curvature(x, y, s, half_w, i0, i1, correct, shift):
    """Signed curvature (1/px) at points i0..i1-1, and which of them were skipped (left 0)."""
    n = x.shape[0]
    kappa = np.zeros(i1 - i0)
    skipped = np.zeros(i1 - i0, bool)
    for i in range(i0, i1):
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
            skipped[i - i0] = True
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
            skipped[i - i0] = True
            continue
        S0 = S1 = S2 = S3 = S4 = S5 = S6 = T0 = T1 = T2 = 0.0
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
        a, b = _ref_solve3(S0, S1, S2, S3, S4, T0, T1, T2)
        if not np.isfinite(a):
            skipped[i - i0] = True
            continue
        k = 2.0 * a / (1.0 + b * b) ** 1.5
        if correct:
            c2, c1 = _ref_solve3(S0, S1, S2, S3, S4, S4, S5, S6)
            for _ in range(2):
                k3 = k * k * k / 8.0
                at = a - c2 * k3
                bt = b - c1 * k3
                k = 2.0 * at / (1.0 + bt * bt) ** 1.5
        kappa[i - i0] = k
    return kappa, skipped


def _assert_matches_reference(fit, got):
    ref, skipped = _ref_parabola_curvature(*fit)
    assert got.shape == ref.shape
    assert np.all(np.isfinite(got))
    # the same points skipped (left exactly 0), the same curvature elsewhere
    assert np.all(got[skipped] == 0.0)
    np.testing.assert_allclose(got, ref, rtol=RTOL, atol=ATOL)
    return ref, skipped


# ---- generated inputs -----------------------------------------------------------------------

def _frame(rc):
    """The kernel's inputs from a (row, col) path: x = col, y = -row, arc length."""
    rc = np.asarray(rc, float)
    d = np.diff(rc, axis=0)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(d[:, 0], d[:, 1]))])
    return rc[:, 1].copy(), -rc[:, 0], s


def _noisy_arc(rng):
    R = rng.uniform(15.0, 2000.0)
    n = int(rng.integers(20, 300))
    step = rng.uniform(0.6, 1.5)
    th = rng.uniform(0, 2 * np.pi) + np.cumsum(np.full(n, step / R)) * rng.choice([-1, 1])
    c = rng.uniform(-3000.0, 3000.0, 2)
    rc = np.c_[c[0] + R * np.sin(th), c[1] + R * np.cos(th)]
    rc += rng.normal(0.0, rng.choice([0.0, 0.05, 0.3]), rc.shape)
    if rng.random() < 0.5:  # a skeleton staircase smoothed as the stage does
        rc = polyline.smooth(np.round(rc), window_px=int(rng.choice([5, 11])), closed=False)
    return rc


def _straight(rng):
    n = int(rng.integers(10, 250))
    ang = rng.uniform(0, 2 * np.pi)
    t = np.arange(n) * rng.uniform(0.7, 1.4)
    rc = rng.uniform(0, 4000, 2) + np.c_[t * np.sin(ang), t * np.cos(ang)]
    if rng.random() < 0.5:
        rc = polyline.smooth(np.round(rc), window_px=11, closed=False)
    return rc


def _short(rng):
    n = int(rng.integers(3, 11))
    steps = rng.integers(-1, 2, (n - 1, 2))
    steps[np.all(steps == 0, axis=1)] = (0, 1)
    return np.vstack([[0, 0], np.cumsum(steps, axis=0)]) + rng.uniform(0, 2000, 2)


def _open_fit(rc, rng, *, half_w=None, correct=None, shift=None, part=True):
    x, y, s = _frame(rc)
    n = len(s)
    if half_w is None:
        half_w = float(rng.choice([rng.uniform(0.5, 4.0), rng.uniform(4.0, 60.0)]))
    i0, i1 = 0, n
    if part and n > 4 and rng.random() < 0.3:
        i0 = int(rng.integers(0, n // 2))
        i1 = int(rng.integers(i0 + 1, n + 1))
    correct = bool(rng.random() < 0.5) if correct is None else correct
    shift = bool(rng.random() < 0.5) if shift is None else shift
    return (x, y, s, half_w, i0, i1, correct, shift)


def _closed_fit(rng, *, correct=True):
    """A noisy closed loop unrolled as the stage unrolls it (np.tile, arc length +- total)."""
    R = rng.uniform(8.0, 300.0)
    n = max(8, int(2 * np.pi * R / rng.uniform(0.7, 1.3)))
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rad = R * (1 + rng.uniform(0, 0.3) * np.cos(rng.integers(2, 5) * th + rng.uniform(0, 6)))
    rc = np.c_[rad * np.sin(th), rad * np.cos(th)] + rng.uniform(0, 3000, 2)
    rc += rng.normal(0, 0.2, rc.shape)
    x, y = rc[:, 1], -rc[:, 0]
    d = np.diff(np.vstack([rc, rc[:1]]), axis=0)
    seg = np.hypot(d[:, 0], d[:, 1])
    total = float(seg.sum())
    s = np.concatenate([[0.0], np.cumsum(seg[:n - 1])])
    half_w = min(rng.uniform(3.0, 80.0), 0.5 * total)
    s_ext = np.concatenate([s - total, s, s + total])
    return (np.tile(x, 3), np.tile(y, 3), s_ext, half_w, n, 2 * n, correct, False)


# ---- tests ----------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(6))
def test_noisy_arcs_match_reference(seed):
    rng = np.random.default_rng(seed)
    for _ in range(6):
        fit = _open_fit(_noisy_arc(rng), rng)
        ref, skipped = _assert_matches_reference(fit, _parabola_curvature(*fit))
        if fit[3] > 4.0 and fit[5] - fit[4] > 3:
            assert not skipped.all()


@pytest.mark.parametrize("shift", [False, True])
@pytest.mark.parametrize("correct", [False, True])
def test_arc_of_known_radius(shift, correct):
    """Both switches on a clean arc: the vectorised fits agree with the reference and give
    the radius (within 1 % with the circle correction; 8 % without, at the shifted ends)."""
    rng = np.random.default_rng(11)
    R = 120.0
    th = np.arange(200) / R
    rc = np.c_[500 + R * np.sin(th), 700 + R * np.cos(th)]
    fit = _open_fit(rc, rng, half_w=25.0, correct=correct, shift=shift, part=False)
    got = _parabola_curvature(*fit)
    _assert_matches_reference(fit, got)
    # the path turns clockwise as displayed (row = R sin, col = R cos): negative curvature
    assert np.all(np.abs(got * R + 1.0) < (0.01 if correct else 0.08))


@pytest.mark.parametrize("seed", range(4))
def test_straight_lines_match_reference(seed):
    rng = np.random.default_rng(100 + seed)
    for _ in range(6):
        fit = _open_fit(_straight(rng), rng)
        got = _parabola_curvature(*fit)
        _assert_matches_reference(fit, got)
        if fit[3] >= 10.0:  # over windows of 20 px a line (or a smoothed staircase) is straight
            assert np.abs(got).max() < 0.01


def test_exact_straight_line_is_flat():
    x = np.arange(100.0) * 0.6 + 1234.0
    y = np.arange(100.0) * 0.8 - 987.0
    s = np.arange(100.0)
    fit = (x, y, s, 12.0, 0, 100, True, True)
    got = _parabola_curvature(*fit)
    _assert_matches_reference(fit, got)
    assert np.abs(got).max() < 1e-12


@pytest.mark.parametrize("seed", range(4))
def test_short_paths_match_reference(seed):
    """Paths of 3 to 10 points: windows of fewer than three points and singular fits."""
    rng = np.random.default_rng(200 + seed)
    n_skipped = 0
    for _ in range(25):
        fit = _open_fit(_short(rng), rng)
        _, skipped = _assert_matches_reference(fit, _parabola_curvature(*fit))
        n_skipped += skipped.sum()
    assert n_skipped > 0  # the skips were exercised


@pytest.mark.parametrize("seed", range(4))
def test_closed_loops_match_reference(seed):
    rng = np.random.default_rng(300 + seed)
    for correct in (False, True):
        fit = _closed_fit(rng, correct=correct)
        got = _parabola_curvature(*fit)
        _assert_matches_reference(fit, got)
        assert got.shape == (fit[5] - fit[4],)
        # the loop, clockwise as displayed, turns by -2 pi
        n = fit[5] - fit[4]
        ds = np.diff(fit[2][n:2 * n + 1])
        assert abs(np.sum(0.5 * (got + np.roll(got, -1)) * ds) + 2 * np.pi) < 0.15 * 2 * np.pi


def test_zero_chord_and_singular_windows():
    """Repeated points: a chord of zero length (tn == 0) and windows whose points sit at
    two places only (singular fit) are skipped, as by the reference."""
    x = np.array([0.0, 0.0, 0.0, 0.0, 3.0, 3.0, 3.0, 6.0, 7.0, 8.0, 9.0, 9.5])
    y = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.5, 1.7, 1.8, 1.8])
    s = np.arange(len(x)) * 1.5  # the arc length is an input of the fits
    for half_w in (0.5, 1.6, 3.1, 8.0):
        for shift in (False, True):
            fit = (x, y, s, half_w, 0, len(x), True, shift)
            got = _parabola_curvature(*fit)
            _, skipped = _assert_matches_reference(fit, got)
            assert skipped[:3].all()  # the chord of the first points has zero length


def test_nearly_singular_windows():
    """Three points, two of them eps apart: around the determinant threshold the same
    windows are skipped as by the reference."""
    n_skipped = n_fitted = 0
    for eps in np.geomspace(1e-5, 1e-3, 30):
        x = np.array([0.0, eps, 1.0]) + 812.0
        y = np.array([0.0, 0.3 * eps, 0.2]) - 95.0
        fit = (x, y, np.array([0.0, 1.0, 2.0]), 5.0, 0, 3, False, False)
        got = _parabola_curvature(*fit)
        _, skipped = _assert_matches_reference(fit, got)
        n_skipped += skipped.sum()
        n_fitted += (~skipped).sum()
        assert np.all(np.abs(got[~skipped]) > 0.1)  # a fitted window bends: 0 means skipped
    assert n_skipped > 10 and n_fitted > 10


def test_tiny_window_skips_every_point():
    x, y, s = _frame(np.c_[np.zeros(30), np.arange(30.0)])
    fit = (x, y, s, 0.9, 0, 30, True, True)  # at most two points per window
    got = _parabola_curvature(*fit)
    _, skipped = _assert_matches_reference(fit, got)
    assert skipped.all() and np.all(got == 0.0)


def test_arc_length_that_decreases():
    """The scans run from each point, as the loops do, where the arc length decreases (a
    loop's unrolled arc length may, by rounding)."""
    rng = np.random.default_rng(7)
    rc = _noisy_arc(rng)
    x, y, s = _frame(rc)
    s = s.copy()
    k = np.arange(5, len(s) - 5, 17)
    s[k] = s[k - 1] - rng.uniform(0.0, 0.5, k.size)  # steps back
    for shift in (False, True):
        fit = (x, y, s, 9.0, 0, len(s), True, shift)
        _assert_matches_reference(fit, _parabola_curvature(*fit))


def test_densely_sampled_path():
    """Samples 0.2 px apart: the tangent chords span ten samples (longer scans than on
    skeletons)."""
    rng = np.random.default_rng(8)
    th = np.arange(600) * 0.2 / 80.0
    rc = np.c_[900 + 80 * np.sin(th), 40 + 80 * np.cos(th)] + rng.normal(0, 0.01, (600, 2))
    for shift in (False, True):
        fit = _open_fit(rc, rng, half_w=15.0, correct=True, shift=shift, part=False)
        got = _parabola_curvature(*fit)
        _assert_matches_reference(fit, got)
        assert abs(np.median(got) * 80 + 1) < 0.05


def test_batch_equals_one_path_at_a_time():
    """The fits of many paths in one call (windows of all lengths mixed in the blocks) give
    each path's curvature as a call of its own, and the reference."""
    rng = np.random.default_rng(9)
    fits = []
    for _ in range(30):
        kind = rng.integers(4)
        if kind == 0:
            fits.append(_open_fit(_noisy_arc(rng), rng))
        elif kind == 1:
            fits.append(_open_fit(_straight(rng), rng))
        elif kind == 2:
            fits.append(_open_fit(_short(rng), rng))
        else:
            fits.append(_closed_fit(rng))
    fits.insert(5, (np.zeros(0), np.zeros(0), np.zeros(0), 5.0, 0, 0, True, True))
    got = _parabola_curvatures(fits)
    assert len(got) == len(fits)
    assert got[5].shape == (0,)
    for fit, k in zip(fits, got):
        np.testing.assert_allclose(k, _parabola_curvature(*fit), rtol=1e-12, atol=1e-15)
        _assert_matches_reference(fit, k)


def test_window_parabolas_are_each_windows_solution():
    """The compiled parabola of every window, and the projections of u^4 on it (the circle
    correction's), are the solutions of a plain loop's sums over the window in its point's
    tangent frame (windows shifted and not, of three samples and of many)."""
    rng = np.random.default_rng(12)
    checked = 0
    for _ in range(30):
        x, y, s = _frame(_noisy_arc(rng))
        n = len(s)
        half_w = float(rng.uniform(1.0, 40.0))
        shift = bool(rng.random() < 0.5)
        a, b, c2, c1 = curvature._window_fits(
            x, y, s, np.array([0]), np.array([n]), np.array([half_w]), np.array([0]),
            np.array([n]), np.array([shift]))
        for i in range(n):
            lo, hi = i, i
            while lo > 0 and s[i] - s[lo - 1] <= 2.0:
                lo -= 1
            while hi < n - 1 and s[hi + 1] - s[i] <= 2.0:
                hi += 1
            t = np.array([x[hi] - x[lo], y[hi] - y[lo]])
            s_lo, s_hi = s[i] - half_w, s[i] + half_w
            if shift and s_lo < s[0]:
                s_lo, s_hi = s[0], min(s_hi + (s[0] - s_lo), s[-1])
            elif shift and s_hi > s[-1]:
                s_lo, s_hi = max(s_lo - (s_hi - s[-1]), s[0]), s[-1]
            j = np.flatnonzero((s >= s_lo) & (s <= s_hi))
            if not np.hypot(*t) or len(j) < 3:
                assert np.isnan([a[i], b[i], c2[i], c1[i]]).all()
                continue
            t /= np.hypot(*t)
            dx, dy = x[j] - x[i], y[j] - y[i]
            u = dx * t[0] + dy * t[1]
            v = dy * t[0] - dx * t[1]
            S = [float(np.sum(u ** p)) for p in range(7)]
            want = (_ref_solve3(*S[:5], np.sum(v), np.sum(u * v), np.sum(u * u * v))
                    + _ref_solve3(*S[:5], *S[4:7]))
            np.testing.assert_allclose([a[i], b[i]], want[:2], rtol=1e-7, atol=1e-12)
            # c1 is a difference of terms of c2's size
            np.testing.assert_allclose([c2[i], c1[i]], want[2:], rtol=1e-7,
                                       atol=1e-9 * abs(want[2]))
            checked += 1
    assert checked > 1000


@pytest.mark.parametrize("closed", [False, True])
def test_stack_curvature_fits_match_reference(monkeypatch, closed):
    """Through the stage: every fit that stack_curvature hands to the window fits (trimmed
    open paths, unrolled loops) gives the reference's curvature."""
    seen = []
    real = curvature._fit_curvatures

    def spy(X, Y, S, off, lens, half_w, i0, cnt, correct, shift):
        out = real(X, Y, S, off, lens, half_w, i0, cnt, correct, shift)
        first = np.concatenate([[0], np.cumsum(cnt)])
        for f in range(len(cnt)):
            path = slice(off[f], off[f] + lens[f])
            fit = (X[path], Y[path], S[path], half_w[f], i0[f], i0[f] + cnt[f], correct[f],
                   shift[f])
            seen.append((fit, out[first[f]:first[f + 1]]))
        return out

    monkeypatch.setattr(curvature, "_fit_curvatures", spy)
    rng = np.random.default_rng(21)
    for _ in range(4):
        R = rng.uniform(30, 200)
        th = np.linspace(0, (2 * np.pi if closed else rng.uniform(1, 4)), int(6 * R),
                         endpoint=not closed)
        c = rng.uniform(R + 5, 3 * R, 2)
        rc = np.round(np.c_[c[0] - R * np.sin(th), c[1] + R * np.cos(th)]).astype(int)
        rc = rc[np.r_[True, np.any(np.diff(rc, axis=0) != 0, axis=1)]]
        if closed and np.all(rc[0] == rc[-1]):
            rc = rc[:-1]
        prof = stack_curvature(rc, n_br=int(rng.integers(1, 4)), thickness_px=5.0,
                               px_per_mm=50.0, closed=closed, trim_px=(12.0, 0.0))
        assert prof.closed == closed
    assert len(seen) == 4
    for fit, k in seen:
        assert fit[7] == (not closed)  # loops: no shifted windows; open paths: shifted
        _assert_matches_reference(fit, k)


def test_range_sums_are_numpys_to_the_last_bit():
    """The sums and trapezoids of many ranges at once are numpy's own of each range, bit for
    bit (its pairwise summation: below 8, up to 128 and beyond, split into halves), empty and
    overlapping ranges included."""
    rng = np.random.default_rng(31)
    n = 40000
    a = rng.standard_normal(n) * 10.0 ** rng.uniform(-3, 3, n)
    x = np.cumsum(rng.random(n))
    width = np.r_[np.arange(0, 300), rng.integers(300, 8000, 60), [0, 0, 1]]
    lo = rng.integers(0, n - width + 1)
    hi = lo + width
    got = curvature._range_sums(a, lo, hi)
    trapz = curvature._trapz_ranges(a, x, lo, hi)
    for i in range(len(lo)):
        assert got[i] == np.add.reduce(a[lo[i]:hi[i]])
        assert trapz[i] == (np.trapezoid(a[lo[i]:hi[i]], x[lo[i]:hi[i]]) if width[i] else 0.0)
    # the zero numpy's sum starts from
    zeros = curvature._range_sums(np.full(20, -0.0), np.array([0, 3]), np.array([20, 5]))
    assert str(zeros.tolist()) == str([float(np.add.reduce(np.full(k, -0.0))) for k in (20, 2)])


def test_arc_lengths_are_each_paths_running_sums():
    """The arc lengths of many paths in one running sum are each path's own, bit for bit
    (empty paths, paths of one point, a path whose steps are not finite)."""
    rng = np.random.default_rng(32)
    for bad in (False, True):
        n = rng.integers(0, 400, 60)
        n[::7] = 0
        n[::11] = 1
        a = np.r_[0, np.cumsum(n)[:-1]]
        seg = rng.random(n.sum()) * 10.0 ** rng.uniform(-3, 3, n.sum())
        if bad:
            seg[a[5] + 2] = np.inf
        got = curvature._arc_lengths(seg, a, n)
        want = [np.r_[0.0, np.cumsum(seg[i:i + k - 1])] for i, k in zip(a, n) if k]
        assert got.tobytes() == np.concatenate(want).tobytes()


def test_searches_are_numpys_bisection():
    """The compiled searches of many ranges are ``np.searchsorted``'s, on both sides, on
    sorted ranges with ties and on unsorted ones with NaN (the same bisection)."""
    rng = np.random.default_rng(33)
    for sort in (True, False):
        s = np.round(rng.uniform(0, 50, 3000), 1)
        if sort:
            s = np.sort(s)
        else:
            s[rng.integers(0, 3000, 50)] = np.nan
        lo = rng.integers(0, 3000, 2000)
        hi = np.minimum(lo + rng.integers(0, 300, 2000), 3000)
        v = np.where(rng.random(2000) < 0.3, s[np.minimum(lo, 2999)],
                     np.round(rng.uniform(-5, 55, 2000), 1))
        v[::97] = np.nan
        right = rng.random(2000) < 0.5
        got = curvature._bisect(s, lo, hi, v, right)
        for q in range(2000):
            side = "right" if right[q] else "left"
            assert got[q] == np.searchsorted(s[lo[q]:hi[q]], v[q], side=side)


def test_fork_zones_of_many_stacks_are_each_stacks():
    """Filled together, the stacks' fork zones are those each stack gets alone, bit for bit
    (one flat array holds them all: nothing of one may reach another)."""
    rng = np.random.default_rng(8)
    profs, n_br, forks, noise = [], [], [], []
    for i in range(12):
        n = int(rng.integers(2, 300))
        th = np.cumsum(rng.normal(0.0, 0.05, n))
        xy = np.cumsum(np.c_[np.cos(th), np.sin(th)], axis=0) + 100.0
        nb = int(rng.integers(1, 4))
        trims = tuple(float(rng.choice([0.0, 15.0, 40.0])) for _ in range(2))
        profs.append(stack_curvature(np.round(xy).astype(int), n_br=nb, thickness_px=4.0,
                                     px_per_mm=40.0, trim_px=trims, method="paper"))
        n_br.append(nb)
        forks.append(tuple(t > 0 for t in trims))
        noise.append([None, 0.0, float(rng.uniform(0, 0.05))][i % 3])
    walled = [(float(rng.choice([0.0, 10.0])), 0.0) for _ in profs]
    together = curvature._fill_fork_zones_many(profs, n_br, forks, noise, walled,
                                               thickness_px=4.0, px_per_mm=40.0)
    for p, nb, f, v, w, got in zip(profs, n_br, forks, noise, walled, together):
        alone = curvature._fill_fork_zones(p, nb, 4.0, 40.0, f, noise_var_per_mm2=v,
                                           walled_px=w)
        assert got.kappa_per_mm.tobytes() == alone.kappa_per_mm.tobytes()
        assert got.s_mm.tobytes() == alone.s_mm.tobytes()
        for name in ("length_mm", "kappa_pm", "kappa_plus", "energy_rel_uncertainty",
                     "noise_var_per_mm2", "fit_start", "fit_stop"):
            assert str(getattr(got, name)) == str(getattr(alone, name)), name


def test_smoothed_paths_together_are_each_paths():
    """The centrelines smoothed all at once are ``polyline.smooth`` of each path, bit for
    bit: open and closed, a repeated closing point, paths shorter than the window."""
    rng = np.random.default_rng(9)
    paths, closed = [], []
    for i in range(60):
        p = np.cumsum(rng.integers(-1, 2, (int(rng.integers(0, 40)), 2)), axis=0) + 50
        if i % 5 == 0 and len(p) > 4:
            p[-1] = p[0]
        paths.append(p)
        closed.append(bool(i % 3 == 0))
    for window in (1, 3, 7, 11):
        together = polyline.smooth_paths(paths, window_px=window, closed=closed)
        for p, c, got in zip(paths, closed, together):
            want = polyline.smooth(p, window_px=window, closed=c)
            assert got.shape == want.shape and got.tobytes() == want.tobytes()
