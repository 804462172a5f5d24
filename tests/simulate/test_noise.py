import numpy as np
import pytest
from scipy import stats

from crosssection.core.errors import ParameterError
from simulate.geometry import angles, center_of_mass
from simulate.intersect import has_intersection
from simulate.noise import angle_increments, initial_shape, intersection_rate, largest_noise


@pytest.mark.parametrize("n,d,seed", [(300, 750.0, 0), (100, 50.0, 1), (500, 2000.0, 2)])
def test_angle_increment_statistics(n, d, seed):
    rng = np.random.default_rng(seed)
    inc = np.concatenate([angle_increments(n, d, rng) for _ in range(40)])
    sigma = np.sqrt(2 * d) / n  # kappa_i = sqrt(2D) xi_i, dtheta = kappa_i ds
    assert stats.kstest(inc / sigma, "norm").pvalue > 1e-3
    # the variance is within its sampling error (chi-square, 99.9 %)
    k = inc.size
    lo, hi = stats.chi2.ppf([5e-4, 1 - 5e-4], k)
    assert lo / k < np.var(inc) / sigma**2 < hi / k
    # wrong readings are rejected: continuum variance 2 D ds would be far larger
    assert stats.kstest(inc / np.sqrt(2 * d / n), "norm").pvalue < 1e-6


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_initial_shape_centred_self_avoiding_and_seeded(seed):
    xy = initial_shape(300, 750.0, seed=seed)
    assert xy.shape == (301, 2)
    assert np.allclose(center_of_mass(xy), 0.0, atol=1e-14)
    assert not has_intersection(xy, "brute")
    seg = np.hypot(*np.diff(xy, axis=0).T)
    assert np.allclose(seg, 1 / 300)
    assert np.array_equal(xy, initial_shape(300, 750.0, seed=seed))
    assert not np.array_equal(xy, initial_shape(300, 750.0, seed=seed + 10))
    # the measured increments follow the documented law
    theta, _ = angles(xy)
    assert np.std(np.diff(theta)) == pytest.approx(np.sqrt(1500) / 300, rel=0.25)


def test_redraws_self_intersecting_shapes():
    # at D = 2000, N = 100 about 80 % of raw draws intersect; returned shapes never do
    for seed in range(5):
        assert not has_intersection(initial_shape(100, 2000.0, seed=seed), "brute")
    with pytest.raises(ParameterError):
        initial_shape(100, 1e5, seed=0, max_tries=20)


def test_intersection_rate_grows_with_noise():
    low = intersection_rate(100.0, n_segments=300, n_samples=200, seed=1)
    high = intersection_rate(5000.0, n_segments=300, n_samples=200, seed=1)
    assert low == 0.0 and high > 0.3
    best, rates = largest_noise(n_segments=300, threshold=0.05, noises=(250, 750, 5000),
                                n_samples=200, seed=2)
    assert best == 750 and rates[5000.0] > 0.3
