"""Minimisation protocols for the confined rod (paper section "Minimization procedure").

* ``powell`` -- the paper's protocol: Powell's method run ``n_runs`` (10) times from the noise
  shape, each run at most ``maxiter`` (30) iterations, the direction set reset between runs, the
  nematic self-contact term ``u sin^2 alpha`` in ``nematic_runs`` (2 early runs) only, hard core
  throughout. The numba engine is :mod:`simulate.powell` (a port of scipy's Powell).

  Parameters are the bend angles ``phi = (theta_0, theta_1 - theta_0, ..., theta_{N-1} -
  theta_{N-2})`` and the start point: a coordinate direction ``phi_k`` turns the tail of the rod
  rigidly about node ``k`` (the elementary move of the prototype), so one trial costs O(1).
  Direction reset: each run starts from a random permutation of the coordinate directions with
  random signs (a "set of random directions" in the paper's words, chosen among coordinate
  directions so that most line searches stay O(1)); Powell's own update then mixes in
  extrapolated directions.
* ``lbfgs`` -- scipy L-BFGS-B on bending + confinement + a smooth short-range repulsion between
  nodes far apart along the rod, with the hard core as a barrier (an inadmissible trial returns
  a huge energy, so the line search backtracks).
* ``anneal`` -- Lambda ramped geometrically from ``lam_start`` to the target, a short Powell
  protocol at every stage; approaches the spiral ground state (Ẽ -> 2 sqrt(Lambda)).

All functions take and return node positions ``xy`` (N+1, 2) in units of L.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from crosssection.errors import ParameterError

from .energy import bending_energy, confinement_energy
from .geometry import angles, positions
from .intersect import has_intersection_grid
from .powell import powell_run


@dataclass
class QuenchResult:
    """Outcome of one minimisation.

    Attributes
    ----------
    xy : (N+1, 2) array
        Final configuration (self-avoiding).
    energy_total, energy_bending, energy_confinement : float
        Ẽ and its two parts (no nematic term).
    method : str
    wall_s : float
        Wall time of the minimisation.
    stats : dict
        Counters (evaluations, line searches, collision checks, iterations, ...).
    history : list of (float, float)
        (wall seconds, energy) after every run / stage.
    """

    xy: np.ndarray
    energy_total: float
    energy_bending: float
    energy_confinement: float
    method: str
    wall_s: float
    stats: dict = field(default_factory=dict)
    history: list = field(default_factory=list)


def to_params(xy) -> np.ndarray:
    """Powell parameters (bend angles, start point) of a polyline, shape (N+2,)."""
    theta, start = angles(xy)
    return np.concatenate([[theta[0]], np.diff(theta), start])


def from_params(p) -> np.ndarray:
    """Node positions (N+1, 2) from Powell parameters (bend angles, start point)."""
    p = np.asarray(p, dtype=np.float64)
    n = p.size - 2
    return positions(np.cumsum(p[:n]), p[n:])


def _result(xy, lam, method, t0, stats, history):
    eb = bending_energy(xy)
    ec = confinement_energy(xy, lam)
    return QuenchResult(xy=xy, energy_total=eb + ec, energy_bending=eb, energy_confinement=ec,
                        method=method, wall_s=time.perf_counter() - t0, stats=stats,
                        history=history)


_STAT_NAMES = ("evaluations", "line_searches", "admissibility_checks", "iterations",
               "collision_tests", "clearance_skips")


def powell_protocol(xy0, lam: float, *, seed=None, n_runs: int = 10, maxiter: int = 30,
                    nematic_runs=(1, 2), u: float = 100.0, contact_cutoff: float | None = None,
                    min_separation: int = 10, xtol: float = 1e-4, ftol: float = 1e-4,
                    wall_radius: float | None = None, first_identity: bool = False,
                    parametrization: str = "bend") -> QuenchResult:
    """The paper's minimisation: ``n_runs`` Powell runs with direction resets.

    Parameters
    ----------
    xy0 : (N+1, 2) array
        Self-avoiding start (e.g. :func:`simulate.noise.initial_shape`).
    lam : float
        Confinement Lambda (switched on at once: a quench).
    seed : int, optional
        Seeds the direction resets.
    n_runs : int
        Powell runs (paper: 10).
    maxiter : int
        Iterations per run (~30 in the prototype).
    nematic_runs : sequence of int
        Runs (0-based) that include the nematic term ``u sin^2 alpha``; never put the last run
        here (paper: 2 early runs out of 10).
    u : float
        Nematic strength (paper: 50-150; "its precise value did not affect the results").
    contact_cutoff : float, optional
        Contact distance of the nematic term; default one segment length ``1/N``.
    min_separation : int
        Segments closer than this along the rod are never contacts.
    xtol, ftol : float
        scipy Powell tolerances.
    wall_radius : float, optional
        Hard-wall disk radius (centred at the origin).
    first_identity : bool
        Start run 0 with scipy's default direction set (identity) instead of a random one.
    parametrization : {"bend", "tangent"}
        Coordinates of Powell's search: ``"bend"`` -- bend angles ``phi_k`` (a coordinate
        move turns the whole tail about node k); ``"tangent"`` -- tangent angles ``theta_k``
        (segment k turns, the tail translates by at most 2/N). Both are exact Powell (checked
        against scipy in the respective coordinates). PARAMETRIZATION_NOTE gives the measurement.

    Returns
    -------
    QuenchResult
    """
    if parametrization not in ("bend", "tangent"):
        raise ParameterError(f"unknown parametrization {parametrization!r}")
    t0 = time.perf_counter()
    xy0 = np.asarray(xy0, dtype=np.float64)
    n = xy0.shape[0] - 1
    if has_intersection_grid(np.ascontiguousarray(xy0)):
        raise ParameterError("the initial configuration intersects itself")
    if wall_radius is not None and np.max(np.hypot(xy0[:, 0], xy0[:, 1])) > wall_radius:
        raise ParameterError("the initial configuration leaves the hard-wall disk")
    if n_runs > 0 and (n_runs - 1) in set(nematic_runs):
        raise ParameterError("the nematic term must not be used in the last run (paper)")
    rng = np.random.default_rng(seed)
    m = n + 2
    p = to_params(xy0)
    cutoff = 1.0 / n if contact_cutoff is None else float(contact_cutoff)
    wall = np.inf if wall_radius is None else float(wall_radius)
    stats = np.zeros(6, np.int64)
    dirs = np.zeros((m, m))
    history = []
    nem = set(int(r) for r in nematic_runs)
    for run in range(n_runs):
        if run == 0 and first_identity:
            kind = np.arange(m, dtype=np.int64)
            sgn = np.ones(m)
        else:
            kind = rng.permutation(m).astype(np.int64)
            sgn = rng.choice([-1.0, 1.0], size=m)
        powell_run(p, float(lam), kind, sgn, dirs, int(maxiter), float(xtol), float(ftol),
                   float(u) if run in nem else 0.0, cutoff, int(min_separation), wall, stats,
                   True, parametrization == "tangent")
        xy = from_params(p)
        history.append((time.perf_counter() - t0,
                        bending_energy(xy) + confinement_energy(xy, lam)))
    xy = from_params(p)
    return _result(xy, lam, "powell", t0, dict(zip(_STAT_NAMES, map(int, stats))), history)



def _repulsion(xy, sigma, eps, min_separation):
    """Smooth short-range repulsion ``eps sum (1 - d/sigma)^2`` between nodes far apart along
    the rod, and its gradient with respect to node positions."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(xy).query_pairs(sigma, output_type="ndarray")
    grad = np.zeros_like(xy)
    if pairs.size == 0:
        return 0.0, grad
    pairs = pairs[np.abs(pairs[:, 0] - pairs[:, 1]) >= min_separation]
    if pairs.size == 0:
        return 0.0, grad
    dv = xy[pairs[:, 0]] - xy[pairs[:, 1]]
    d = np.maximum(np.hypot(dv[:, 0], dv[:, 1]), 1e-12)
    g = 1.0 - d / sigma
    e = eps * np.sum(g * g)
    coef = (-2.0 * eps * g / sigma / d)[:, None] * dv
    np.add.at(grad, pairs[:, 0], coef)
    np.add.at(grad, pairs[:, 1], -coef)
    return float(e), grad


def lbfgs_quench(xy0, lam: float, *, seed=None, barrier: float = 100.0,
                 barrier_range: float | None = None, min_separation: int = 10,
                 maxiter: int = 20000, wall_radius: float | None = None,
                 restarts: int = 500) -> QuenchResult:
    """Gradient quench: L-BFGS-B on bending + confinement + a smooth contact barrier.

    Parameters
    ----------
    xy0 : (N+1, 2) array
        Self-avoiding start.
    lam : float
        Confinement Lambda.
    seed : int, optional
        Unused (deterministic); accepted for a uniform interface.
    barrier : float
        Strength ``eps`` of the repulsion ``eps (1 - d/sigma)^2`` between nodes.
    barrier_range : float, optional
        Range ``sigma`` (default 2/N).
    min_separation : int
        Nodes closer than this along the rod do not repel.
    maxiter : int
        L-BFGS-B iterations.
    wall_radius : float, optional
        Hard-wall disk; trials outside get a huge energy.
    restarts : int
        Maximum L-BFGS-B restarts after a line search stopped at the hard core.

    Returns
    -------
    QuenchResult
        The hard core is kept as a barrier: a self-intersecting trial returns a huge energy so
        the line search backtracks; the result is self-avoiding.
    """
    from scipy.optimize import minimize

    from .energy import energy_and_gradient

    t0 = time.perf_counter()
    xy0 = np.asarray(xy0, dtype=np.float64)
    n = xy0.shape[0] - 1
    ds = 1.0 / n
    sigma = 2.0 * ds if barrier_range is None else float(barrier_range)
    theta0, start0 = angles(xy0)
    x0 = np.concatenate([theta0, start0])
    count = [0]

    def fun(x):
        count[0] += 1
        th = x[:n]
        xy = positions(th, x[n:])
        if has_intersection_grid(xy) or (wall_radius is not None and
                                         np.max(np.einsum("ij,ij->i", xy, xy)) > wall_radius ** 2):
            return 1e30, np.zeros_like(x)
        e, g = energy_and_gradient(th, x[n:], lam)
        er, gr = _repulsion(xy, sigma, barrier, min_separation)
        # chain rule: node j > k moves by ds t_k^perp when theta_k changes
        suffix = np.cumsum(gr[::-1], axis=0)[::-1]
        tperp = np.stack([-np.sin(th), np.cos(th)], axis=1)
        g = g.copy()
        g[:n] += ds * np.einsum("ij,ij->i", tperp, suffix[1:])
        g[n:] += suffix[0]
        return e + er, g

    # L-BFGS-B stops when its line search meets the hard core; restart from there (fresh
    # curvature memory, short first step) until a restart gains nothing.
    x = x0
    f_old = np.inf
    nit = 0
    for _ in range(restarts):
        res = minimize(fun, x, jac=True, method="L-BFGS-B",
                       options=dict(maxiter=maxiter, maxfun=4 * maxiter, ftol=1e-12,
                                    gtol=1e-8))
        nit += int(res.nit)
        if res.fun < 1e29:
            x = res.x
        if not res.fun < f_old - 1e-9 * abs(f_old) or res.success:
            break
        f_old = res.fun
    xy = positions(x[:n], x[n:])
    if has_intersection_grid(xy):  # cannot happen: such trials are never accepted
        xy = xy0
    out = _result(xy, lam, "lbfgs", t0, {"evaluations": count[0], "iterations": int(res.nit)},
                  [])
    out.history.append((out.wall_s, out.energy_total))
    return out


def anneal(xy0, lam: float, *, lam_start: float = 1e3, stages: int = 12,
           ramp: str = "geometric", method: str = "powell", seed=None, n_runs: int = 10,
           maxiter: int = 30, nematic_runs=(1, 2), u: float = 100.0, ftol: float = 1e-4,
           xtol: float = 1e-4, wall_radius: float | None = None,
           runs_per_stage: int = 2) -> QuenchResult:
    """Annealing: Lambda ramped from ``lam_start`` to ``lam`` in ``stages`` stages.

    Every intermediate stage runs ``runs_per_stage`` Powell runs (or one L-BFGS quench) at its
    Lambda; the last stage runs the full protocol (``n_runs`` runs, nematic runs included) at
    the target. Slow compaction lets the rod wind up: the energy approaches the spiral ground
    state ``2 sqrt(Lambda)`` (paper, conclusion) instead of the quench's ~2.5 times more.

    Parameters
    ----------
    xy0 : (N+1, 2) array
    lam : float
        Target Lambda.
    lam_start : float
        First Lambda of the ramp.
    stages : int
        Number of Lambda values (>= 1), the last being ``lam``.
    ramp : {"geometric", "linear"}
    method : {"powell", "lbfgs"}
    seed, n_runs, maxiter, nematic_runs, u, ftol, xtol, wall_radius
        As in :func:`powell_protocol`.
    runs_per_stage : int
        Powell runs at each intermediate stage.

    Returns
    -------
    QuenchResult
        ``history`` holds (wall seconds, energy at the stage's Lambda) per stage.
    """
    t0 = time.perf_counter()
    if stages < 1:
        raise ParameterError(f"stages must be >= 1, got {stages}")
    if ramp == "geometric":
        lams = np.geomspace(min(lam_start, lam), lam, stages)
    elif ramp == "linear":
        lams = np.linspace(min(lam_start, lam), lam, stages)
    else:
        raise ParameterError(f"unknown ramp {ramp!r}")
    ss = np.random.SeedSequence(seed)
    xy = np.asarray(xy0, dtype=np.float64)
    history = []
    stats = {}
    for s, (lam_s, child) in enumerate(zip(lams, ss.spawn(stages))):
        last = s == stages - 1
        if method == "powell":
            r = powell_protocol(xy, float(lam_s), seed=child, n_runs=n_runs if last else
                                runs_per_stage, maxiter=maxiter,
                                nematic_runs=nematic_runs if last else (), u=u, ftol=ftol,
                                xtol=xtol, wall_radius=wall_radius)
        elif method == "lbfgs":
            r = lbfgs_quench(xy, float(lam_s), wall_radius=wall_radius)
        else:
            raise ParameterError(f"unknown method {method!r}")
        xy = r.xy
        for k, v in r.stats.items():
            stats[k] = stats.get(k, 0) + v
        history.append((time.perf_counter() - t0, r.energy_total))
    return _result(xy, lam, f"anneal-{method}", t0, stats, history)


def scipy_powell(xy0, lam: float, *, maxiter: int = 30, direc=None, xtol: float = 1e-4,
                 ftol: float = 1e-4, hard_core: bool = True):
    """Reference: ``scipy.optimize.minimize(method="Powell")`` on the same energy.

    Same parameters (bend angles, start point), same energy, hard core as the value 1e30.

    Parameters
    ----------
    xy0 : (N+1, 2) array
    lam : float
    maxiter : int
    direc : (N+2, N+2) array, optional
        Initial direction set (scipy's default: identity).
    xtol, ftol : float
    hard_core : bool

    Returns
    -------
    QuenchResult
    """
    from scipy.optimize import minimize

    t0 = time.perf_counter()
    n = np.asarray(xy0).shape[0] - 1
    count = [0]

    def f(p):
        count[0] += 1
        xy = positions(np.cumsum(p[:n]), p[n:])
        if hard_core and has_intersection_grid(xy):
            return 1e30
        return bending_energy(xy) + confinement_energy(xy, lam)

    opts = dict(maxiter=maxiter, xtol=xtol, ftol=ftol)
    if direc is not None:
        opts["direc"] = np.array(direc, dtype=float)
    res = minimize(f, to_params(xy0), method="Powell", options=opts)
    xy = from_params(res.x)
    out = _result(xy, lam, "scipy-powell", t0, {"evaluations": count[0],
                                                 "iterations": int(res.nit)}, [])
    out.history.append((out.wall_s, out.energy_total))
    return out


__all__ = ["QuenchResult", "powell_protocol", "lbfgs_quench", "anneal", "scipy_powell",
           "to_params", "from_params"]
