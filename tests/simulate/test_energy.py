import numpy as np
import pytest

from simulate.energy import (bending_energy, confinement_energy, energy_and_gradient,
                             node_curvature, total_energy)
from simulate.geometry import angles, center_of_mass, positions, radius_of_gyration


@pytest.mark.parametrize("n,r", [(100, 0.3), (300, 0.2), (300, 1.0), (500, 0.05)])
def test_arc_bending_is_inverse_radius_squared(n, r):
    theta = np.arange(n) / n / r + 0.7
    xy = positions(theta, (0.1, -0.2))
    # N-1 interior nodes carry the curvature: exact value (1 - 1/N) / r^2 up to O(ds^2)
    assert bending_energy(xy) == pytest.approx(1.0 / r**2, rel=1.5 / n)
    assert bending_energy(xy) == pytest.approx((1 - 1.0 / n) / r**2, rel=1e-3)


@pytest.mark.parametrize("n,lam,angle", [(300, 7e5, 0.0), (60, 12.0, 1.1), (301, 3.0, -2.0)])
def test_straight_centred_rod_confinement(n, lam, angle):
    xy = positions(np.full(n, angle))
    xy -= center_of_mass(xy)
    assert confinement_energy(xy, lam) == pytest.approx(lam / 12.0, rel=3.0 / n**2)  # trapezoid error 2 ds^2
    assert bending_energy(xy) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_gradient_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(10, 40))
    theta = np.cumsum(rng.normal(0, 0.3, n))
    start = rng.normal(0, 0.2, 2)
    lam = float(10 ** rng.uniform(1, 4))
    e, g = energy_and_gradient(theta, start, lam)
    x = np.concatenate([theta, start])
    h = 1e-6
    fd = np.empty_like(x)
    for i in range(x.size):
        xp = x.copy(); xp[i] += h
        xm = x.copy(); xm[i] -= h
        fd[i] = (energy_and_gradient(xp[:n], xp[n:], lam)[0]
                 - energy_and_gradient(xm[:n], xm[n:], lam)[0]) / (2 * h)
    assert np.allclose(g, fd, rtol=1e-5, atol=1e-5 * np.abs(g).max())
    xy = positions(theta, start)
    assert e == pytest.approx(bending_energy(xy) + confinement_energy(xy, lam), rel=1e-12)


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_node_curvature_consistent_with_bending(seed):
    rng = np.random.default_rng(seed)
    n = 200
    theta = np.cumsum(rng.normal(0, 0.05, n))
    xy = positions(theta)
    k = node_curvature(xy)
    assert k.shape == (n + 1,) and k[0] == 0 and k[-1] == 0
    assert np.sum(k**2) / n == pytest.approx(bending_energy(xy), rel=1e-10)
    # sign: counter-clockwise turn is positive, magnitude ~ dtheta / ds
    dth = np.diff(theta)
    assert np.all(np.sign(k[1:-1]) == np.sign(dth))
    assert np.allclose(k[1:-1], 2 * np.sin(dth / 2) * n, rtol=1e-8)


def test_total_energy_hard_core_and_wall():
    # a figure-eight-like crossing polyline
    xy = np.array([[0, 0], [1, 1], [1, 0], [0, 1]], float) / 3.0
    assert total_energy(xy, 10.0) == np.inf
    assert np.isfinite(total_energy(xy, 10.0, hard_core=False))
    xy = positions(np.zeros(50), (-0.5, 0.0))
    assert total_energy(xy, 1.0, wall_radius=0.4) == np.inf
    assert np.isfinite(total_energy(xy, 1.0, wall_radius=0.6))


def test_angles_roundtrip_and_rg():
    rng = np.random.default_rng(9)
    theta = np.cumsum(rng.normal(0, 0.2, 80))
    xy = positions(theta, (0.3, 0.1))
    th2, st = angles(xy)
    assert np.allclose(positions(th2, st), xy, atol=1e-12)
    assert radius_of_gyration(xy) ** 2 * 5.0 == pytest.approx(confinement_energy(xy, 5.0))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_contact_barrier_gradient_and_range(seed):
    from simulate.energy import contact_barrier

    rng = np.random.default_rng(seed)
    n = 40
    ds = 1.0 / n
    # a hairpin: two antiparallel strands at a random gap inside the range, with noise
    gap = rng.uniform(0.2, 0.35) * ds
    top = np.stack([np.arange(21) * ds, np.zeros(21)], axis=1)
    bot = np.stack([np.arange(19, -1, -1) * ds, np.full(20, gap)], axis=1)
    xy = np.concatenate([top, bot]) + rng.normal(0, 0.02 * gap, (41, 2))
    sigma = 0.4 * ds
    e, g, npairs = contact_barrier(xy, sigma=sigma, eps=0.3, min_separation=3)
    assert e > 0 and npairs > 10
    h = 1e-7 * ds
    for i in rng.choice(41, 8, replace=False):
        for c in range(2):
            xp = xy.copy()
            xp[i, c] += h
            xm = xy.copy()
            xm[i, c] -= h
            fd = (contact_barrier(xp, sigma=sigma, eps=0.3)[0]
                  - contact_barrier(xm, sigma=sigma, eps=0.3)[0]) / (2 * h)
            assert g[i, c] == pytest.approx(fd, rel=1e-4, abs=1e-6 * np.abs(g).max())
    # out of range: nothing; brute-force energy agrees
    far = contact_barrier(xy, sigma=0.5 * gap * 0.5, eps=0.3)
    assert far[0] == 0.0 and far[2] == 0
    brute = 0.0
    for i in range(41):
        for j in range(40):
            if i - 3 <= j <= i + 2:
                continue
            a, b = xy[j], xy[j + 1]
            t = np.clip(np.dot(xy[i] - a, b - a) / np.dot(b - a, b - a), 0, 1)
            d = np.linalg.norm(xy[i] - a - t * (b - a))
            if d < sigma:
                brute += 0.3 * (sigma / d - 1) ** 2
    assert e == pytest.approx(brute, rel=1e-12)
    # a node (almost) on another segment: the barrier diverges
    xy[30] = 0.5 * (xy[5] + xy[6]) + [0.0, 1e-12]
    assert contact_barrier(xy, sigma=sigma, eps=0.3)[0] > 1e15


@pytest.mark.parametrize("xy, says", [
    (np.zeros((1, 2)), "got shape (1, 2)"),
    (np.zeros((0, 2)), "got shape (0, 2)"),
    (np.zeros((2, 301)), "transposed? pass xy.T"),
    (np.zeros(10), "got shape (10,)"),
    (np.array([[0.0, 0.0], [np.nan, 1.0]]), "1 non-finite coordinate(s)"),
])
def test_a_rod_that_is_not_an_n_plus_1_by_2_array_is_named(xy, says):
    """One node, no node, transposed, 1-D or NaN: a ParameterError naming xy, never a
    ZeroDivisionError, an IndexError, a numba error or a silent 0."""
    from crosssection.core.errors import ParameterError
    from simulate.energy import contact_barrier, nematic_energy

    calls = [bending_energy, node_curvature, center_of_mass, radius_of_gyration, angles,
             lambda x: confinement_energy(x, 7e5), lambda x: total_energy(x, 7e5),
             lambda x: nematic_energy(x, u=100.0, cutoff=0.01),
             lambda x: contact_barrier(x, sigma=0.01, eps=1.0)]
    for call in calls:
        with pytest.raises(ParameterError, match=r"^xy must be an \(N\+1, 2\) array") as e:
            call(xy)
        assert says in str(e.value)


def test_energy_arguments_are_checked():
    from crosssection.core.errors import ParameterError
    from simulate.geometry import trapezoid_weights

    xy = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]])
    with pytest.raises(ParameterError, match="^lam must be"):
        confinement_energy(xy, float("nan"))
    with pytest.raises(ParameterError, match="^wall_radius must be"):
        total_energy(xy, 1.0, wall_radius=-1.0)
    with pytest.raises(ParameterError, match="^n_segments must be"):
        trapezoid_weights(0)
    # a list of nodes is a rod as well
    assert confinement_energy(xy.tolist(), 12.0) == pytest.approx(confinement_energy(xy, 12.0))
