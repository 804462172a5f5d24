import numpy as np
import pytest

from crosssection.core import polyline as pl


def _digital_circle(r, c0=(100.0, 100.0)):
    """8-connected pixel loop of a circle of radius r (ordered by angle, duplicates dropped)."""
    t = np.linspace(0, 2 * np.pi, int(16 * r), endpoint=False)
    p = np.round(np.stack([c0[0] + r * np.sin(t), c0[1] + r * np.cos(t)], 1))
    keep = np.r_[True, np.any(np.diff(p, axis=0) != 0, axis=1)]
    p = p[keep]
    if np.array_equal(p[0], p[-1]):
        p = p[:-1]
    return p


def _digital_line(ang_deg, n=200):
    a = np.radians(ang_deg)
    p = np.round(np.stack([np.arange(n) * np.sin(a), np.arange(n) * np.cos(a)], 1))
    return p[np.r_[True, np.any(np.diff(p, axis=0) != 0, axis=1)]]


def test_length_and_mid_point_of_simple_paths():
    p = np.array([[0, 0], [0, 3], [4, 3]], float)
    assert pl.length(p) == pytest.approx(7.0)
    assert pl.length(p, closed=True) == pytest.approx(12.0)
    np.testing.assert_allclose(pl.mid_point(p), [0.5, 3.0])
    # a closed loop starts at its first point: half of 3 + 4 + 5 is 3 into the second side
    np.testing.assert_allclose(pl.mid_point(p, closed=True), [3.0, 3.0])
    # a repeated closing point adds nothing
    q = np.vstack([p, p[:1]])
    assert pl.length(q, closed=True) == pytest.approx(12.0)
    assert pl.length(np.zeros((1, 2))) == 0.0
    assert np.all(np.isnan(pl.mid_point(np.zeros((0, 2)))))
    np.testing.assert_allclose(pl.mid_point([[2, 5], [2, 5]]), [2, 5])


def test_mid_point_is_at_half_arc_length():
    t = np.linspace(0, np.pi, 301)
    p = np.stack([50 * np.sin(t), 50 * np.cos(t)], 1)
    np.testing.assert_allclose(pl.mid_point(p), [50.0, 0.0], atol=1e-9)


@pytest.mark.parametrize("ang_deg", [0, 10, 22.5, 30, 45, 67, 80])
@pytest.mark.parametrize("window", [5, 11])
def test_smoothed_length_of_oblique_lines(ang_deg, window):
    p = _digital_line(ang_deg)
    true = np.hypot(*(p[-1] - p[0]))
    assert pl.length(p) / true - 1 > -1e-12  # the raw staircase is never shorter
    sm = pl.smooth(p, window_px=window)
    assert abs(pl.length(sm) / true - 1) < 0.01


@pytest.mark.parametrize("r", [20, 40, 100])
def test_smoothed_length_of_circles(r):
    p = _digital_circle(r)
    assert pl.is_closed(p)
    got = pl.length(pl.smooth(p, window_px=5, closed=True), closed=True)
    assert abs(got / (2 * np.pi * r) - 1) < 0.01
    # the raw 8-connected loop is ~5 % too long: smoothing matters
    assert pl.length(p, closed=True) / (2 * np.pi * r) > 1.03


def test_smooth_keeps_lines_and_arcs_at_the_ends():
    # the end rule (quadratic end fit) reproduces uniformly sampled lines and parabolas exactly
    t = np.arange(30, dtype=float)
    line = np.stack([2.0 + 0.5 * t, 1.0 - 0.25 * t], 1)
    np.testing.assert_allclose(pl.smooth(line, window_px=7), line, atol=1e-9)
    par = np.stack([0.01 * t ** 2, t], 1)
    sm = pl.smooth(par, window_px=7)
    # ends: the quadratic end fit reproduces the parabola; interior: the uniform average of
    # 2k + 1 points offsets it by a k (k + 1) / 3 (the O(k^2 / R) shrink of the docstring)
    off = sm[:, 0] - par[:, 0]
    np.testing.assert_allclose(off[:3], 0.0, atol=1e-9)
    np.testing.assert_allclose(off[-3:], 0.0, atol=1e-9)
    np.testing.assert_allclose(off[3:-3], 0.01 * 3 * 4 / 3, atol=1e-9)
    # no smoothing for window 1 or tiny paths
    np.testing.assert_allclose(pl.smooth(par, window_px=1), par)
    np.testing.assert_allclose(pl.smooth(par[:2], window_px=9), par[:2])


def test_smooth_closed_with_repeated_point_and_reversal():
    p = _digital_circle(30)
    q = np.vstack([p, p[:1]])
    a = pl.smooth(p, window_px=5, closed=True)
    b = pl.smooth(q, window_px=5, closed=True)
    assert len(b) == len(q)
    np.testing.assert_allclose(b[:-1], a)
    np.testing.assert_allclose(b[-1], b[0])
    # reversal symmetry of open paths
    rng = np.random.default_rng(3)
    o = np.cumsum(rng.integers(-1, 2, (80, 2)), axis=0).astype(float)
    np.testing.assert_allclose(pl.smooth(o[::-1], window_px=9)[::-1], pl.smooth(o, window_px=9),
                               atol=1e-9)


def test_smoothed_lengths_batch_equals_single():
    rng = np.random.default_rng(7)
    paths = [_digital_line(a, n) for a, n in ((5, 40), (33, 7), (71, 120))]
    paths += [_digital_circle(25), np.array([[1.0, 1.0]]), np.array([[1.0, 1.0], [2.0, 2.0]])]
    paths += [np.cumsum(rng.integers(-1, 2, (60, 2)), axis=0).astype(float)]
    closed = np.array([False, False, False, True, False, False, False])
    offs = np.concatenate([[0], np.cumsum([len(p) for p in paths])])
    for w in (1, 5, 11):
        got = pl.smoothed_lengths(np.vstack(paths), offs, closed, window_px=w)
        ref = [pl.length(pl.smooth(p, window_px=w, closed=c), closed=c)
               for p, c in zip(paths, closed)]
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    assert pl.smoothed_lengths(np.zeros((0, 2)), [0], np.zeros(0, bool)).shape == (0,)


def test_a_window_longer_than_the_paths_costs_only_the_windows_they_use():
    # the end projectors of every half window up to 2500 would take 233 GiB; the paths here
    # take half windows of at most 149
    rng = np.random.default_rng(3)
    paths = [np.cumsum(rng.normal(size=(n, 2)), axis=0) for n in (40, 120, 299)]
    big = pl.smooth_paths(paths, window_px=5001)
    exact = pl.smooth_paths(paths, window_px=2 * 149 + 1)
    for a, b, p in zip(big, exact, paths):
        assert np.array_equal(a, b) and np.array_equal(a, pl.smooth(p, window_px=5001))
    lengths = pl.smoothed_lengths(np.concatenate(paths), np.cumsum([0, 40, 120, 299]),
                                  np.zeros(3, bool), window_px=5001)
    assert np.allclose(lengths, [pl.length(b) for b in big])


def test_walked_ends_and_grouped_axes_match_a_loop_over_the_paths():
    rng = np.random.default_rng(3)
    paths = [np.cumsum(rng.normal(size=(n, 2)), axis=0) for n in (5, 1, 12, 7)]
    flat, offs = pl.concat_paths(paths, dtype=float)
    sids = np.array([0, 2, 2, 3, 1])
    rev = np.array([False, False, True, True, False])
    walk, pos, idx, lens = pl.walk_ends(offs, sids, rev)
    for w, (s, r) in enumerate(zip(sids, rev)):
        expected = paths[s][::-1] if r else paths[s]
        np.testing.assert_array_equal(flat[idx[walk == w]], expected)
        np.testing.assert_array_equal(pos[walk == w], np.arange(len(expected)))
        assert lens[w] == len(expected)
    # groups: the first four points of every walk, one empty group at the end
    keep = pos < 4
    count, mr, mc, ang, first, last = pl.grouped_axes(
        walk[keep], flat[idx[keep], 0], flat[idx[keep], 1], pos[keep], len(sids) + 1)
    for w in range(len(sids)):
        pts = flat[idx[(walk == w) & keep]]
        assert count[w] == len(pts)
        np.testing.assert_allclose([mr[w], mc[w]], pts.mean(axis=0))
        assert (first[w], last[w]) == (0, len(pts) - 1)
        if len(pts) >= 2:
            axis = np.linalg.svd(pts - pts.mean(axis=0))[2][0]
            assert abs(abs(np.dot(axis, [np.cos(ang[w]), np.sin(ang[w])])) - 1) < 1e-9
    assert count[-1] == 0 and last[-1] == -1 and mr[-1] == 0
