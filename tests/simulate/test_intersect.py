import numpy as np
import pytest

from simulate.geometry import positions
from simulate.intersect import close_pairs, has_intersection, seg_dist2

METHODS = ("brute", "skip", "grid")


def _all(xy):
    return [has_intersection(xy, m) for m in METHODS]


@pytest.mark.parametrize("seed", range(6))
def test_agree_on_random_noise_shapes(seed):
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(60):
        n = int(rng.integers(20, 400))
        d = float(10 ** rng.uniform(2, 4.5))
        theta = np.cumsum(np.sqrt(2 * d) / n * rng.standard_normal(n))
        xy = positions(theta, rng.normal(size=2))
        res = _all(xy)
        assert res[0] == res[1] == res[2]
        hits += res[0]
    assert 0 < hits < 60  # both outcomes are exercised


@pytest.mark.parametrize("seed", range(3))
def test_agree_on_random_walks_unequal_segments(seed):
    rng = np.random.default_rng(100 + seed)
    for _ in range(50):
        xy = np.cumsum(rng.normal(size=(int(rng.integers(4, 60)), 2)) *
                       rng.uniform(0.2, 1.0, size=(1, 1)), axis=0)
        res = _all(xy)
        assert res[0] == res[1] == res[2]


def _hairpin(gap, n_leg=20, ds=0.01):
    """Two antiparallel legs joined by a half-square turn, at distance ``gap``."""
    leg = np.stack([np.arange(n_leg + 1) * ds, np.zeros(n_leg + 1)], axis=1)
    back = leg[::-1] + [0.0, gap]
    return np.concatenate([leg, back])  # the closing segment has length gap


@pytest.mark.parametrize("gap,expected", [(1e-12, False), (0.005, False), (0.0, True)])
def test_hairpin_legs(gap, expected):
    xy = _hairpin(gap)
    if gap == 0.0:
        # zero gap: the legs overlap collinearly
        xy = np.concatenate([_hairpin(0.01)[:21], _hairpin(0.01)[:21][::-1][1:] + [0.0, 0.0]])
    assert _all(xy) == [expected] * 3


@pytest.mark.parametrize("shift", [0.0, 1e-12, -1e-12])
def test_near_touching_endpoint(shift):
    # a polyline whose far segment ends exactly on / just off an earlier segment
    ds = 0.01
    xy = np.array([[0, 0], [ds, 0], [2 * ds, 0], [2 * ds, ds], [ds * 1.5, ds],
                   [ds * 1.5, shift]])
    expected = shift <= 0.0  # on the segment (0) or across it (< 0) is an intersection
    assert _all(xy) == [expected] * 3


def test_collinear_overlap_and_shared_node():
    # non-adjacent segments overlapping along the same line
    xy = np.array([[0, 0], [2, 0], [2, 1], [1.5, 1], [1.5, 0], [1.0, 0.0], [0.5, 0.0]])
    assert _all(xy) == [True] * 3
    # non-adjacent segments sharing a node (the rod comes back to a node): intersection
    xy = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [1, 0.0]])
    assert _all(xy) == [True] * 3
    # adjacent segments folding back partially: share a node only -> allowed by the rule
    xy = np.array([[0, 0], [1, 0], [1, 1], [1, 2]])
    assert _all(xy) == [False] * 3


def test_degenerate_sizes():
    assert _all(np.array([[0, 0], [1, 0.0]])) == [False] * 3
    assert _all(np.array([[0, 0], [1, 0], [2, 0.0]])) == [False] * 3


@pytest.mark.parametrize("seed", range(3))
def test_close_pairs_match_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = 120
    xy = positions(np.cumsum(np.sqrt(2 * 3000) / n * rng.standard_normal(n)))
    cut = float(rng.uniform(0.5, 3.0)) / n
    got = {tuple(p) for p in close_pairs(xy, cut, 4)}
    want = set()
    for i in range(n):
        for j in range(i + 4, n):
            if seg_dist2(*xy[i], *xy[i + 1], *xy[j], *xy[j + 1]) < cut * cut:
                want.add((i, j))
    assert got == want


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_contact_grid_matches_brute_distance(seed):
    from simulate.intersect import has_contact_grid, seg_dist2

    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 80))
    theta = np.cumsum(rng.normal(0, 0.6, n))
    xy = np.zeros((n + 1, 2))
    xy[1:] = np.cumsum(np.stack([np.cos(theta), np.sin(theta)], 1) / n, axis=0)
    dmin = min(np.sqrt(seg_dist2(*xy[i], *xy[i + 1], *xy[j], *xy[j + 1]))
               for i in range(n) for j in range(i + 2, n))
    for margin in (0.5 * dmin + 1e-15, 2.0 * dmin + 1e-12, 1.0 / n):
        assert has_contact_grid(xy, margin) == (dmin < margin)
    assert has_contact_grid(xy, 0.0) == (dmin == 0.0)
