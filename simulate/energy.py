"""Energy of the confined rod, paper Eq. (8) (section "Energy functional").

``E = int (R'')^2 ds + Lambda int R^2 ds + hard core``, with ``R`` and ``s`` in units of L.
Discretisation (N segments, ``ds = 1/N``, nodes ``xy`` (N+1, 2)):

* bending: finite differences at the N-1 interior nodes,
  ``|R''_i|^2 = |R_{i+1} - 2 R_i + R_{i-1}|^2 / ds^4``, summed times ``ds``. For the
  inextensible rod this is ``(2 - 2 cos(theta_i - theta_{i-1})) / ds^2`` per node; the free ends
  carry no curvature.
* confinement: trapezoidal rule over the nodes, ``Lambda * sum_i w_i |R_i|^2`` with
  ``w = ds`` inside and ``ds/2`` at the ends.
* hard core: a self-intersecting configuration (or one leaving the optional hard-wall disk)
  has infinite energy.

The functions on ``xy`` are pure numpy (also used by ``simulate.contacts``); the incremental
kernels used by the minimiser live in :mod:`simulate.powell`.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from simulate.checks import check_real
from simulate.geometry import _trapezoid_weights, checked_angles, checked_rod, positions
from simulate.intersect import _grid_fill, _grid_setup

#: The paper's confinement Lambda (section "Numerical simulations"), the simulator's default.
LAMBDA = 7e5
#: Largest Lambda the quench and anneal accept. Measured (3 quenches each, N = 100 and 300,
#: Lambda 7e5 to 1e20, docs/validation/simulator/README.md "Largest Lambda"): from about 1e8
#: Rg stops shrinking and the bending energy stays at its largest, the rod jammed at the
#: scale of a segment, and Lambda only scales the confinement energy; the bending energy
#: falls below Powell's relative tolerance (ftol 1e-4) of the total near 1e11 (N = 100) and
#: between 1e12 and 1e13 (N = 300), beyond which the minimiser no longer relaxes it.
LAMBDA_MAX = 1e10


def _second_differences(xy):
    xy = np.asarray(xy, dtype=np.float64)
    return xy[2:] - 2.0 * xy[1:-1] + xy[:-2]


def bending_energy(xy) -> float:
    """Bending energy ``int (R'')^2 ds`` by finite differences (paper Eq. (8)).

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions, segment length ``1/N``.

    Returns
    -------
    float
        ``sum_i |R_{i+1} - 2R_i + R_{i-1}|^2 / ds^3`` over interior nodes. An arc of radius
        ``r`` gives ``(1 - 1/N) / r^2`` (N-1 interior nodes), i.e. ``1/r^2`` up to O(1/N).

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers with N >= 1 (see
        :func:`simulate.geometry.checked_rod`), naming the argument.
    """
    xy = checked_rod(xy)
    n = xy.shape[0] - 1
    if n < 2:
        return 0.0
    d2 = _second_differences(xy)
    return float(np.sum(d2 * d2) * n ** 3)


def node_curvature(xy) -> np.ndarray:
    """Signed curvature at every node, shape (N+1,), 0 at both free ends.

    ``kappa_i = sign(t_{i-1} x t_i) |R_{i+1} - 2R_i + R_{i-1}| / ds^2``; for the inextensible
    rod ``|kappa_i| = 2 sin(|dtheta_i|/2) / ds``, so ``sum_i kappa_i^2 ds`` equals
    :func:`bending_energy` exactly. Positive = turning left (counter-clockwise).

    Parameters
    ----------
    xy : (N+1, 2) array

    Returns
    -------
    (N+1,) float64 array

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers with N >= 1 (see
        :func:`simulate.geometry.checked_rod`), naming the argument.
    """
    xy = checked_rod(xy)
    n = xy.shape[0] - 1
    kappa = np.zeros(n + 1)
    if n < 2:
        return kappa
    d = np.diff(xy, axis=0)
    d2 = d[1:] - d[:-1]
    cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
    sign = np.where(cross < 0, -1.0, 1.0)
    kappa[1:-1] = sign * np.hypot(d2[:, 0], d2[:, 1]) * n * n
    return kappa


def confinement_energy(xy, lam: float) -> float:
    """Confinement energy ``Lambda int R^2 ds`` by the trapezoidal rule.

    Parameters
    ----------
    xy : (N+1, 2) array
    lam : float
        Dimensionless confinement Lambda (paper: 7e5).

    Returns
    -------
    float
        A straight rod centred at the origin gives ``Lambda/12`` (+ O(1/N^2)).

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers with N >= 1 (see
        :func:`simulate.geometry.checked_rod`) or ``lam`` is not a finite number >= 0,
        naming the argument.
    """
    xy = checked_rod(xy)
    lam = check_real("lam", lam, low=0.0)
    w = _trapezoid_weights(xy.shape[0] - 1)
    return float(lam * (w @ np.einsum("ij,ij->i", xy, xy)))


def total_energy(xy, lam: float, *, wall_radius: float | None = None,
                 hard_core: bool = True) -> float:
    """Total energy Ẽ of Eq. (8): bending + confinement + hard core.

    Parameters
    ----------
    xy : (N+1, 2) array
    lam : float
        Confinement Lambda.
    wall_radius : float, optional
        Radius of a hard-wall disk centred at the origin (V = inf outside), as in the
        experiment; ``None`` for no wall.
    hard_core : bool
        If true (default), a self-intersecting polyline has energy ``inf``.

    Returns
    -------
    float

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers with N >= 1 (see
        :func:`simulate.geometry.checked_rod`), ``lam`` is not a finite number >= 0 or
        ``wall_radius`` not one > 0, naming the argument.
    """
    xy = checked_rod(xy)
    lam = check_real("lam", lam, low=0.0)
    if wall_radius is not None:
        wall_radius = check_real("wall_radius", wall_radius, low=0.0, low_open=True)
        if np.max(np.einsum("ij,ij->i", xy, xy)) > wall_radius * wall_radius:
            return float("inf")
    if hard_core:
        from simulate.intersect import has_intersection

        if has_intersection(xy):
            return float("inf")
    return bending_energy(xy) + confinement_energy(xy, lam)


def energy_and_gradient(theta, start, lam: float) -> tuple[float, np.ndarray]:
    """Smooth energy (bending + confinement) and its exact gradient.

    Parameters
    ----------
    theta : (N,) array
        Tangent angles.
    start : (2,) array
        Position of node 0.
    lam : float
        Confinement Lambda.

    Returns
    -------
    energy : float
    grad : (N+2,) array
        ``dE/dtheta_k`` for k < N, then ``dE/dx0``, ``dE/dy0``.

    Notes
    -----
    Bending ``N sum_i (2 - 2cos(theta_i - theta_{i-1}))``; changing ``theta_k`` moves the nodes
    ``j > k`` by ``ds t_k^perp`` so ``dE_conf/dtheta_k = 2 Lambda ds t_k^perp . sum_{j>k} w_j R_j``.
    """
    theta = checked_angles(theta)
    n = theta.size
    ds = 1.0 / n
    xy = positions(theta, start)
    w = _trapezoid_weights(n)
    dth = np.diff(theta)
    e_b = n * np.sum(2.0 - 2.0 * np.cos(dth))
    e_c = lam * (w @ np.einsum("ij,ij->i", xy, xy))
    grad = np.zeros(n + 2)
    s = 2.0 * n * np.sin(dth)
    grad[1:n] += s
    grad[0:n - 1] -= s
    wr = w[:, None] * xy
    suffix = np.cumsum(wr[::-1], axis=0)[::-1]  # suffix[j] = sum_{i>=j} w_i R_i
    tail = suffix[1:]                            # tail[k] = sum_{j>k} w_j R_j
    tperp = np.stack([-np.sin(theta), np.cos(theta)], axis=1)
    grad[:n] += 2.0 * lam * ds * np.einsum("ij,ij->i", tperp, tail)
    grad[n:] = 2.0 * lam * suffix[0]
    return float(e_b + e_c), grad


def nematic_energy(xy, *, u: float, cutoff: float, min_separation: int = 6) -> float:
    """Nematic self-contact energy ``u sum sin^2(alpha)`` (paper, "Search for local minima").

    Sum over pairs of segments ``(i, j)``, ``j - i >= min_separation``, whose distance is below
    ``cutoff``; ``alpha`` is the angle between them (antiparallel and parallel cost nothing).

    Parameters
    ----------
    xy : (N+1, 2) array
    u : float
        Strength (paper: 50-150).
    cutoff : float
        Contact distance in units of L.
    min_separation : int
        Pairs closer than this along the rod are neighbours, not contacts.

    Returns
    -------
    float

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers with N >= 1 (see
        :func:`simulate.geometry.checked_rod`), naming the argument.
    """
    from simulate.intersect import close_pairs

    xy = checked_rod(xy)
    pairs = close_pairs(xy, cutoff, min_separation)
    if pairs.shape[0] == 0:
        return 0.0
    d = np.diff(xy, axis=0)
    th = np.arctan2(d[:, 1], d[:, 0])
    return float(u * np.sum(np.sin(th[pairs[:, 0]] - th[pairs[:, 1]]) ** 2))


@njit(cache=True)
def _barrier_kernel(xy, sigma, eps, min_separation, grad):
    n = xy.shape[0] - 1
    for i in range(n + 1):
        grad[i, 0] = 0.0
        grad[i, 1] = 0.0
    if n < 3:
        return 0.0, 0
    xmin, ymin, h, nx, ny = _grid_setup(xy, sigma)
    start, items = _grid_fill(xy, xmin, ymin, h, nx, ny, sigma)
    e = 0.0
    npairs = 0
    for i in range(n + 1):
        px = xy[i, 0]
        py = xy[i, 1]
        cx = min(int((px - xmin) / h), nx - 1)
        cy = min(int((py - ymin) / h), ny - 1)
        c = cx * ny + cy
        for q in range(start[c], start[c + 1]):
            j = items[q]
            # node i is not repelled by segments within min_separation along the rod
            if j > i - min_separation - 1 and j < i + min_separation:
                continue
            ax = xy[j, 0]
            ay = xy[j, 1]
            ux = xy[j + 1, 0] - ax
            uy = xy[j + 1, 1] - ay
            l2 = ux * ux + uy * uy
            t = ((px - ax) * ux + (py - ay) * uy) / l2
            t = min(max(t, 0.0), 1.0)
            dx = px - ax - t * ux
            dy = py - ay - t * uy
            d = math.sqrt(dx * dx + dy * dy)
            if d >= sigma:
                continue
            npairs += 1
            if d <= 0.0:
                return math.inf, npairs
            r = sigma / d - 1.0
            e += eps * r * r
            # dE/dd along the unit vector (p - q)/d, shared by the segment's nodes
            f = -2.0 * eps * r * sigma / (d * d) / d
            gx = f * dx
            gy = f * dy
            grad[i, 0] += gx
            grad[i, 1] += gy
            grad[j, 0] -= (1.0 - t) * gx
            grad[j, 1] -= (1.0 - t) * gy
            grad[j + 1, 0] -= t * gx
            grad[j + 1, 1] -= t * gy
    return e, npairs


def contact_barrier(xy, *, sigma: float, eps: float, min_separation: int = 3):
    """Smooth contact barrier between a node and the segments far from it along the rod.

    ``E = eps sum (sigma/d - 1)^2`` over node ``i`` / segment ``j`` pairs at distance
    ``d < sigma``, ``j`` outside ``[i - min_separation, i + min_separation - 1]``. It is C1 at
    ``d = sigma`` and diverges at contact: two segments moving continuously first touch at an
    endpoint lying on the other segment, so a rod following the barrier's gradient cannot
    cross itself. Neighbour search on a uniform grid (numba), O(N).

    Parameters
    ----------
    xy : (N+1, 2) array
    sigma : float
        Range (units of L).
    eps : float
        Strength.
    min_separation : int
        Segments within this many indices of the node are ignored.

    Returns
    -------
    energy : float
        ``inf`` if a node lies on a segment.
    grad : (N+1, 2) array
        dE/d(node positions).
    n_pairs : int
        Pairs within range.

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers with N >= 1 (see
        :func:`simulate.geometry.checked_rod`), naming the argument.
    """
    xy = np.ascontiguousarray(checked_rod(xy), dtype=np.float64)
    grad = np.empty_like(xy)
    e, npairs = _barrier_kernel(xy, float(sigma), float(eps), int(min_separation), grad)
    return float(e), grad, int(npairs)


__all__ = ["LAMBDA", "contact_barrier", "bending_energy", "confinement_energy",
           "node_curvature", "total_energy", "energy_and_gradient", "nematic_energy"]
