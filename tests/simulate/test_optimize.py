import numpy as np
import pytest
from scipy.optimize import minimize

from crosssection.core.errors import ParameterError
from simulate.energy import bending_energy, confinement_energy
from simulate.intersect import has_intersection
from simulate.noise import initial_shape
from simulate.geometry import angles, positions
from simulate.optimize import (anneal, from_params, lbfgs_quench, powell_protocol,
                               scipy_powell, scipy_protocol, to_params)
from simulate.powell import powell_run


def _energy(p, lam, n, hard_core):
    xy = from_params(p)
    if hard_core and has_intersection(xy):
        return 1e30
    return bending_energy(xy) + confinement_energy(xy, lam)


@pytest.mark.parametrize("seed,n,permute", [(0, 20, False), (1, 30, True), (2, 40, True)])
def test_powell_run_is_scipy_powell(seed, n, permute):
    """Same energy, same start, same direction set: the numba port follows scipy step by step."""
    rng = np.random.default_rng(seed)
    lam = float(10 ** rng.uniform(2.5, 3.5))
    xy0 = initial_shape(n, 200.0, seed=seed)
    p0 = to_params(xy0)
    m = n + 2
    perm = rng.permutation(m) if permute else np.arange(m)
    sg = rng.choice([-1.0, 1.0], m) if permute else np.ones(m)
    direc = np.zeros((m, m))
    direc[np.arange(m), perm] = sg
    ref = minimize(_energy, p0, args=(lam, n, False), method="Powell",
                   options=dict(maxiter=4, direc=direc.copy(), xtol=1e-4, ftol=1e-4))
    p = p0.copy()
    stats = np.zeros(6, np.int64)
    f = powell_run(p, lam, perm.astype(np.int64), sg.copy(), np.zeros((m, m)), 4, 1e-4, 1e-4,
                   0.0, 1.0 / n, 10, np.inf, stats, False)
    # identical up to rounding (the O(1) incremental energy differs from scipy's full
    # evaluation in the last digits, which can flip a Brent decision at the 1e-8 level)
    assert f == pytest.approx(ref.fun, rel=1e-6)
    assert np.allclose(p, ref.x, atol=1e-3)
    assert f == pytest.approx(_energy(p, lam, n, False), rel=1e-9)
    assert stats[3] == ref.nit


def _energy_theta(x, lam, n, hard_core):
    xy = positions(x[:n], x[n:])
    if hard_core and has_intersection(xy):
        return 1e30
    return bending_energy(xy) + confinement_energy(xy, lam)


@pytest.mark.parametrize("seed,n", [(7, 20), (8, 35)])
def test_tangent_powell_run_is_scipy_powell_in_theta(seed, n):
    """tangent=True is Powell in (theta, x0, y0): same steps as scipy in those coordinates."""
    rng = np.random.default_rng(seed)
    lam = float(10 ** rng.uniform(2.5, 3.5))
    xy0 = initial_shape(n, 200.0, seed=seed)
    theta, start = angles(xy0)
    m = n + 2
    perm = rng.permutation(m)
    sg = rng.choice([-1.0, 1.0], m)
    direc = np.zeros((m, m))
    direc[np.arange(m), perm] = sg
    ref = minimize(_energy_theta, np.concatenate([theta, start]), args=(lam, n, False),
                   method="Powell", options=dict(maxiter=4, direc=direc, xtol=1e-4, ftol=1e-4))
    p = to_params(xy0)
    stats = np.zeros(6, np.int64)
    f = powell_run(p, lam, perm.astype(np.int64), sg.copy(), np.zeros((m, m)), 4, 1e-4, 1e-4,
                   0.0, 1.0 / n, 10, np.inf, stats, False, True)
    assert f == pytest.approx(ref.fun, rel=1e-6)
    assert np.allclose(np.cumsum(p[:n]), ref.x[:n], atol=1e-3)
    assert stats[3] == ref.nit
    # the bend-angle engine on the same start takes other steps (not equivariant by accident)
    p2 = to_params(xy0)
    f2 = powell_run(p2, lam, perm.astype(np.int64), sg.copy(), np.zeros((m, m)), 4, 1e-4, 1e-4,
                    0.0, 1.0 / n, 10, np.inf, np.zeros(6, np.int64), False, False)
    assert abs(f2 - f) > 1e-6 * f


@pytest.mark.parametrize("seed,param", [(9, "tangent"), (10, "bend")])
def test_protocol_matches_scipy_protocol(seed, param):
    """Same runs, same direction resets: the numba protocol follows the scipy protocol."""
    n = 24
    xy0 = initial_shape(n, 200.0, seed=seed)
    a = powell_protocol(xy0, 500.0, seed=seed, n_runs=3, maxiter=4, nematic_runs=(),
                        parametrization=param)
    b = scipy_protocol(xy0, 500.0, seed=seed, n_runs=3, maxiter=4, nematic_runs=(),
                       parametrization=param)
    # equal up to how trials beyond the hard core enter the interpolation (scipy: 1e30 for
    # every such trial; numba: only for candidates of the best point)
    assert [h[1] for h in a.history] == pytest.approx([h[1] for h in b.history], rel=1e-3)
    # a different seed gives another direction sequence and another result
    c = powell_protocol(xy0, 500.0, seed=seed + 1, n_runs=3, maxiter=4, nematic_runs=(),
                        parametrization=param)
    assert abs(c.energy_total - a.energy_total) > 1e-3 * a.energy_total


@pytest.mark.parametrize("seed", [11, 12])
def test_tangent_hard_core_stays_admissible(seed):
    """Tangent moves in a compact rod: many contacts, never an intersection."""
    n = 120
    xy0 = initial_shape(n, 600.0, seed=seed)
    r = powell_protocol(xy0, 2e5, seed=seed, n_runs=3, maxiter=8, nematic_runs=(1,),
                        parametrization="tangent")
    assert not has_intersection(r.xy, "brute")
    assert np.allclose(np.hypot(*np.diff(r.xy, axis=0).T), 1.0 / n)
    assert r.stats["collision_tests"] > 0 and r.stats["clearance_skips"] > 0
    # the minimiser keeps its clearance margin, so rounding can never create a crossing
    from simulate.intersect import has_contact_grid
    from simulate.powell import MARGIN

    assert not has_contact_grid(r.xy, 0.99 * MARGIN)
    assert not has_intersection(from_params(to_params(r.xy)), "brute")
    assert r.energy_total < 0.3 * (bending_energy(xy0) + confinement_energy(xy0, 2e5))


@pytest.mark.parametrize("seed", [3, 4])
def test_powell_hard_core_close_to_scipy(seed):
    n = 30
    lam = 3e3
    xy0 = initial_shape(n, 300.0, seed=seed)
    ref = scipy_powell(xy0, lam, maxiter=15, parametrization="bend")
    p = to_params(xy0)
    m = n + 2
    stats = np.zeros(6, np.int64)
    f = powell_run(p, lam, np.arange(m, dtype=np.int64), np.ones(m), np.zeros((m, m)), 15,
                   1e-4, 1e-4, 0.0, 1.0 / n, 10, np.inf, stats, True)
    xy = from_params(p)
    assert not has_intersection(xy, "brute")
    assert f == pytest.approx(bending_energy(xy) + confinement_energy(xy, lam), rel=1e-9)
    # the only difference is how trial points beyond the hard core enter the interpolation
    assert f == pytest.approx(ref.energy_total, rel=0.1)
    assert f < 0.5 * (bending_energy(xy0) + confinement_energy(xy0, lam))


@pytest.mark.parametrize("seed", [5, 6])
def test_protocol_admissible_and_decreasing(seed):
    n = 80
    lam = 4e4
    xy0 = initial_shape(n, 500.0, seed=seed)
    r = powell_protocol(xy0, lam, seed=seed, n_runs=4, maxiter=6, nematic_runs=(1,))
    assert not has_intersection(r.xy, "brute")
    assert np.allclose(np.hypot(*np.diff(r.xy, axis=0).T), 1.0 / n)
    assert r.energy_total == pytest.approx(bending_energy(r.xy) + confinement_energy(r.xy, lam))
    e0 = bending_energy(xy0) + confinement_energy(xy0, lam)
    assert r.energy_total < 0.5 * e0
    assert len(r.history) == 4 and r.stats["line_searches"] > 0
    # runs without the nematic term never increase the energy
    assert r.history[3][1] <= r.history[2][1] + 1e-9
    # seeded: identical twice
    r2 = powell_protocol(xy0, lam, seed=seed, n_runs=4, maxiter=6, nematic_runs=(1,))
    assert np.array_equal(r.xy, r2.xy)


def test_protocol_wall_and_errors():
    n = 60
    xy0 = initial_shape(n, 300.0, seed=1)
    rmax = np.max(np.hypot(*xy0.T))
    r = powell_protocol(xy0, 1e3, seed=0, n_runs=2, maxiter=4, nematic_runs=(),
                        wall_radius=rmax * 1.01)
    assert np.max(np.hypot(*r.xy.T)) <= rmax * 1.01 + 1e-12
    with pytest.raises(ParameterError):
        powell_protocol(xy0, 1e3, n_runs=3, nematic_runs=(2,))
    bad = np.array([[0, 0], [1, 1], [1, 0], [0, 1]], float)
    with pytest.raises(ParameterError):
        powell_protocol(bad, 1e3)


@pytest.mark.parametrize("param", ["tangent", "bend"])
def test_wall_binds_and_holds(param):
    """A weak confinement lets the rod unfold against a wall that barely holds the start: the
    wall changes the outcome, and no node ever leaves it."""
    n = 100
    xy0 = initial_shape(n, 750.0, seed=2)
    wall = 1.001 * np.max(np.hypot(*xy0.T))
    kw = dict(seed=2, n_runs=3, maxiter=6, nematic_runs=(1,), parametrization=param)
    free = powell_protocol(xy0, 20.0, **kw)
    held = powell_protocol(xy0, 20.0, wall_radius=wall, **kw)
    assert np.max(np.hypot(*free.xy.T)) > wall
    assert np.max(np.hypot(*held.xy.T)) <= wall
    assert not has_intersection(held.xy, "brute")
    assert held.energy_total < bending_energy(xy0) + confinement_energy(xy0, 20.0)


def test_lbfgs_and_anneal_admissible():
    n = 60
    lam = 2e4
    xy0 = initial_shape(n, 300.0, seed=7)
    e0 = bending_energy(xy0) + confinement_energy(xy0, lam)
    r = lbfgs_quench(xy0, lam)
    assert not has_intersection(r.xy, "brute") and r.energy_total < 0.5 * e0
    assert r.stats["iterations"] > 20
    a = anneal(xy0, lam, lam_start=100.0, stages=4, seed=1, n_runs=2, maxiter=5,
               nematic_runs=())
    assert not has_intersection(a.xy, "brute")
    assert a.energy_total < e0 and len(a.history) == 4
    # ground-state bound: a closed circle wound n times has 2 sqrt(Lambda); nothing goes below
    # it by more than the discretisation allows
    assert a.energy_total > 0.9 * 2 * np.sqrt(lam)


@pytest.mark.parametrize("seed", [13, 14])
def test_lbfgs_slides_below_jammed_state(seed):
    """The smooth barrier lets contacts slide: far below the hard-core-only gradient quench,
    admissible, with the barrier holding strands apart (pairs in range, finite barrier)."""
    from scipy.optimize import minimize as sp_min

    from simulate.energy import energy_and_gradient
    from simulate.intersect import has_intersection_grid

    n = 150
    lam = 1e5
    xy0 = initial_shape(n, 600.0, seed=seed)
    r = lbfgs_quench(xy0, lam)
    assert not has_intersection(r.xy, "brute")
    assert 0.0 < r.stats["barrier_energy"] < 0.05 * r.energy_total
    theta, start = angles(xy0)

    def hard(x):  # hard core only: L-BFGS-B stops at the first contact
        if has_intersection_grid(positions(x[:n], x[n:])):
            return 1e30, np.zeros_like(x)
        return energy_and_gradient(x[:n], x[n:], lam)

    jam = sp_min(hard, np.concatenate([theta, start]), jac=True, method="L-BFGS-B")
    assert r.energy_total < 0.8 * jam.fun
    assert r.energy_total > 2 * np.sqrt(lam) * 0.9


def _head_grid(xy, k, hcell):
    """Reference grid (CSR) of head segments 0..k-1 over their bounding box, built plainly
    with its own allocations: what the scratch-buffer builder must reproduce."""
    xmin = xy[0, 0]
    xmax = xmin
    ymin = xy[0, 1]
    ymax = ymin
    for i in range(1, k + 1):
        xmin = min(xmin, xy[i, 0])
        xmax = max(xmax, xy[i, 0])
        ymin = min(ymin, xy[i, 1])
        ymax = max(ymax, xy[i, 1])
    h = max(hcell, max(xmax - xmin, ymax - ymin) / 40.0)
    nx = int((xmax - xmin) / h) + 1
    ny = int((ymax - ymin) / h) + 1
    ncell = nx * ny
    count = np.zeros(ncell + 1, np.int64)
    for s in range(k):
        x0 = int((min(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        x1 = int((max(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        y0 = int((min(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        y1 = int((max(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        for cx in range(x0, min(x1, nx - 1) + 1):
            for cy in range(y0, min(y1, ny - 1) + 1):
                count[cx * ny + cy + 1] += 1
    for c in range(ncell):
        count[c + 1] += count[c]
    items = np.empty(count[ncell], np.int64)
    fill = count[:-1].copy()
    for s in range(k):
        x0 = int((min(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        x1 = int((max(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        y0 = int((min(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        y1 = int((max(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        for cx in range(x0, min(x1, nx - 1) + 1):
            for cy in range(y0, min(y1, ny - 1) + 1):
                c = cx * ny + cy
                items[fill[c]] = s
                fill[c] += 1
    return xmin, ymin, h, nx, ny, count, items



def test_head_grid_in_scratch_and_bounded_clearance_match_the_plain_ones():
    """The allocation-free head grid equals the reference grid, and the clearance queries of
    all tail segments (one call), with their midpoint bound and per-query de-duplication,
    return the capped brute-force minima."""
    from numba import njit

    from simulate.intersect import seg_dist2
    from simulate.powell import _head_clearances, _new_scratch, _store_head_grid

    @njit
    def buffers(scratch):
        return scratch.grid_start, scratch.grid_items, scratch.clear2

    rng = np.random.default_rng(4)
    n = 120
    xy = initial_shape(n, 300.0, seed=rng) * 0.3  # crowded: many neighbours per cell
    scratch = _new_scratch(n, np.zeros(6, np.int64))
    capped = 0
    for k in (1, 7, 60, 119):
        xmin, ymin, h, nx, ny, start, items = _head_grid(xy, k, 1.0 / n)
        assert _store_head_grid(xy, k, n, scratch) == h
        grid_start, grid_items, clear2 = buffers(scratch)
        assert np.array_equal(grid_start[:nx * ny + 1], start)
        assert np.array_equal(grid_items[:items.size], items)
        clear2[:] = -1.0
        _head_clearances(xy, k, n, h, scratch)
        assert np.all(clear2[:k] == -1.0)  # the head's own entries are left alone
        for j in range(k, n):
            a, b = xy[j], xy[j + 1]
            brute = min([seg_dist2(*xy[i], *xy[i + 1], *a, *b) for i in range(k) if i != j - 1]
                        + [h * h])
            assert clear2[j] == brute
            capped += brute == h * h
    assert 0 < capped < sum(n - k for k in (1, 7, 60, 119))  # both kinds of segments occur


@pytest.mark.parametrize("tangent", [True, False])
def test_collision_test_of_coordinate_trials_matches_brute_force(tangent):
    """On a quenched (jammed) rod, the explicit test of a coordinate trial -- clearance skips,
    head grid, midpoint bound, every tail segment in one call -- rejects exactly the trials
    that bring a moved tail segment within MARGIN of a head segment (or, for a tangent move,
    of the turned segment k)."""
    import math
    from pathlib import Path

    from numba import njit

    from simulate.intersect import seg_dist2
    from simulate.powell import (MARGIN, Model, _admissible, _bend_line, _new_rod,
                                 _new_scratch, _tangent_line)

    @njit
    def trial(k, a, tangent, rod, scratch, model):
        if tangent:
            line = _tangent_line(k, 1.0, 0.0, rod, scratch, model)
        else:
            line = _bend_line(k, 1.0, 0.0, rod, scratch, model)
        scratch.ready[0] = False  # a new line search
        return _admissible(a, line, rod, scratch, model.wall2), rod.xy, rod.theta

    @njit
    def hits(xy, moved, k, tangent, m2):
        n = xy.shape[0] - 1
        for j in range(k, n):
            ax, ay, bx, by = moved[j, 0], moved[j, 1], moved[j + 1, 0], moved[j + 1, 1]
            if j == k and tangent:
                bx, by = moved[n + 1, 0], moved[n + 1, 1]  # the turned segment's own end
            for i in range(k):
                if i != j - 1 and seg_dist2(xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1],
                                            ax, ay, bx, by) < m2:
                    return True
            if tangent and j >= k + 2 and seg_dist2(moved[k, 0], moved[k, 1], moved[n + 1, 0],
                                                    moved[n + 1, 1], ax, ay, bx, by) < m2:
                return True
        return False

    xy0 = np.load(Path(__file__).parent / "data" / "quench_rod_5.npy")
    n = xy0.shape[0] - 1
    rod = _new_rod(to_params(xy0))
    scratch = _new_scratch(n, np.zeros(6, np.int64))
    model = Model(7e5, 0.0, np.inf, True)
    steps = [s * t for s in (-1.0, 1.0)
             for t in ((1e-3, 1e-2, 3e-2, 0.1, 0.3) if tangent else (1e-6, 1e-5, 1e-4, 1e-3))]
    got, want = [], []
    for k in range(1, n - 1, 9):
        for a in steps:
            ok, xy, theta = trial(k, a, tangent, rod, scratch, model)
            # the trial's positions, as the kernels form them; row n+1: end of turned segment k
            moved = np.vstack([xy, xy[-1:]])
            if tangent:
                ds = 1.0 / n
                ck, sk = math.cos(theta[k]), math.sin(theta[k])
                c, s = math.cos(a), math.sin(a)
                tx, ty = ck * c - sk * s, sk * c + ck * s
                moved[k + 1:n + 1] += (ds * tx - ds * ck, ds * ty - ds * sk)
                moved[n + 1] = (xy[k, 0] + ds * tx, xy[k, 1] + ds * ty)
            else:
                c, s = math.cos(a), math.sin(a)
                d = xy[k:] - xy[k]
                moved[k:n + 1, 0] = xy[k, 0] + c * d[:, 0] - s * d[:, 1]
                moved[k:n + 1, 1] = xy[k, 1] + s * d[:, 0] + c * d[:, 1]
            got.append(ok)
            want.append(not hits(xy, moved, k, tangent, MARGIN * MARGIN))
    assert got == want
    assert 20 < sum(got) < len(got) - 20  # both outcomes are exercised
