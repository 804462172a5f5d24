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
                    ) -> QuenchResult:
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

    Returns
    -------
    QuenchResult
    """
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
                   True)
        xy = from_params(p)
        history.append((time.perf_counter() - t0,
                        bending_energy(xy) + confinement_energy(xy, lam)))
    xy = from_params(p)
    return _result(xy, lam, "powell", t0, dict(zip(_STAT_NAMES, map(int, stats))), history)


__all__ = ["QuenchResult", "powell_protocol", "to_params", "from_params"]
