"""Minimisation protocols for the confined rod (paper section "Minimization procedure").

* ``powell`` -- the paper's protocol: Powell's method run ``n_runs`` (10) times from the noise
  shape, each run at most ``maxiter`` (30) iterations, the direction set reset between runs, the
  nematic self-contact term ``u sin^2 alpha`` in ``nematic_runs`` (2 early runs) only, hard core
  throughout. The numba engine is :mod:`simulate.powell` (a port of scipy's Powell).

  Search coordinates (``parametrization``): ``"tangent"`` (default) -- the tangent angles
  ``theta_k`` and the start point: a coordinate move turns segment ``k`` and translates the tail
  by at most 2/N; ``"bend"`` -- the bend angles ``phi_k = theta_k - theta_{k-1}``: a coordinate
  move turns the whole tail rigidly about node ``k``. Both cost O(1) per trial. Measured on the
  same 15 starts (N = 300, Lambda = 7e5, D = 750, seeds 0-14, 10 runs x 30 iterations):

  ==============  ======  =======  ===========  ======  ==========
  coordinates       <E>   bending  confinement   <Rg>   s / config
  ==============  ======  =======  ===========  ======  ==========
  tangent          4273     2018       2255      0.0563     2.4
  bend             4364     2476       1888      0.0509     1.8
  prototype        4240     1970       2270      0.057     ~60
  ==============  ======  =======  ===========  ======  ==========

  The tangent coordinates reproduce the prototype (bending < confinement, Rg 0.057); the bend
  coordinates' long-range moves let the rod contract further (smaller Rg, lower confinement)
  at the price of more bending. Other knobs (5 starts, tangent): ftol 1e-6 changes nothing
  (4713 vs 4769), maxiter 60 lowers Ẽ by ~10 % (4211), u = 50 / 100 / 150 gives 4296 / 4273 /
  4366 over 15 starts ("its precise value did not affect the resulting configurations"), no
  nematic term raises confinement (2675 vs 2277, Rg 0.061), a nematic cut-off of 2/N instead
  of 1/N raises bending (3226).
  Direction reset: each run starts from a random permutation of the coordinate directions with
  random signs (a "set of random directions" in the paper's words, chosen among coordinate
  directions so that most line searches stay O(1)); Powell's own update then mixes in
  extrapolated directions.
* ``lbfgs`` -- scipy L-BFGS-B on bending + confinement + a smooth contact barrier (see
  :func:`lbfgs_quench`): contacts slide, so it reaches lower, more ordered states than Powell
  (16 starts: Ẽ 2506, Rg 0.041, vs powell 4151, 0.058; KS p ~ 1e-7 on Ẽ), as a reference
  prototype found (2600, 0.04). Hard core alone (1e30 for crossings) jams L-BFGS-B at the
  first contact (Ẽ 1.8-2.3e4 after ~20 iterations).
* ``scipy_protocol`` -- the powell protocol with ``scipy.optimize.minimize(method="Powell")``
  (the prototype's way): same statistics (KS p 0.37 / 0.94 on Ẽ / Rg), ~40x slower.

Benchmarks: ``benchmarks/bench_quench.py`` (energy against wall time, ensemble statistics,
two-sample KS tests).
* ``anneal`` -- Lambda ramped geometrically from ``lam_start`` to the target, a short Powell
  protocol at every stage; approaches the spiral ground state (Ẽ -> 2 sqrt(Lambda)).

All functions take and return node positions ``xy`` (N+1, 2) in units of L.
"""
from __future__ import annotations

import reprlib
import time
from dataclasses import dataclass, field

import numpy as np

from crosssection.core.errors import ParameterError

from simulate.checks import check_real, check_seed, check_whole
from simulate.energy import LAMBDA_MAX, bending_energy, confinement_energy
from simulate.geometry import angles, checked_rod, positions
from simulate.intersect import has_intersection_grid
from simulate.powell import powell_run

#: Defaults of the paper's protocol, for the functions here and the ``quench`` / ``anneal``
#: options: Powell runs per configuration, iterations per run (~30 in the prototype), the runs
#: (0-based) with the nematic term, its strength u (paper: 50-150) and scipy's Powell
#: tolerances.
N_RUNS = 10
MAXITER = 30
NEMATIC_RUNS = (1, 2)
NEMATIC_U = 100.0
#: Strongest nematic term the ``quench`` / ``anneal`` options take: ten times the paper's
#: value, the strongest the protocol was measured with (docs/validation/simulator, "The
#: nematic term of the Powell protocol"), where the rods already end in minima 24 % higher
#: than at the paper's 50-150; stronger, the term outweighs the energy it is meant to help
#: minimise.
NEMATIC_U_MAX = 1000.0
FTOL = 1e-4
XTOL = 1e-4
#: Loosest Powell tolerances the ``quench`` / ``anneal`` options take. A run stops once an
#: iteration lowers the energy by less than ``ftol`` of it, and its line searches locate a
#: step to ``100 xtol`` of the step (relative): at ``xtol`` 1e-2 that is the whole step.
#: Measured (quench, N = 120, 2 configurations, <E> 3911 at the defaults): ftol 1e-2 and
#: xtol 1e-3 end in the same minima (<E> 3603 and 3968), ftol 0.1 and xtol 1e-2 stop 25-30 %
#: above them (4870 and 5098), ftol 1 66 % (6502).
FTOL_MAX = 1e-2
XTOL_MAX = 1e-3
#: Most Powell runs per configuration the options take: a hundred times the paper's 10 runs,
#: already about a quarter of an hour per configuration at N = 120 (about a second a run).
N_RUNS_MAX = 1000
#: Most iterations of one Powell run the options take: a thousand times the default 30 (a
#: run of 30 iterations takes about a second at N = 120, and ftol ends it long before).
MAXITER_MAX = 30_000
#: Defaults of :func:`anneal`: first Lambda of the ramp and number of Lambda stages.
LAM_START = 1e3
STAGES = 24
#: Most Lambda stages the ``anneal`` option takes: four hundred times the default 24; each
#: stage is a whole Powell protocol, so more would run for days per configuration.
STAGES_MAX = 10_000
#: Lambda schedules of :func:`anneal`; the first is the default.
RAMPS = ("geometric", "linear")


def default_contact_cutoff(n_segments: int) -> float:
    """Default contact distance of the nematic term: one segment length, ``1 / N`` (units of L).

    Parameters
    ----------
    n_segments : int
        Number of segments N of the rod.

    Returns
    -------
    float

    Raises
    ------
    ParameterError
        ``n_segments`` is not a whole number >= 1.
    """
    return 1.0 / check_whole("n_segments", n_segments, low=1)


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
    """Powell parameters (bend angles, start point) of a polyline, shape (N+2,).

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions, finite, N >= 1.

    Returns
    -------
    (N+2,) float64 array

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers (with a hint when transposed).
    """
    theta, start = angles(checked_rod(xy, min_segments=1))
    return np.concatenate([[theta[0]], np.diff(theta), start])


def from_params(p) -> np.ndarray:
    """Node positions (N+1, 2) from Powell parameters (bend angles, start point).

    Parameters
    ----------
    p : (N+2,) array
        Bend angles (the first is the first tangent angle), then node 0; finite, N >= 1.

    Returns
    -------
    (N+1, 2) float64 array

    Raises
    ------
    ParameterError
        ``p`` is not a flat array of at least 3 finite numbers.
    """
    need = "p must be a flat array of N+2 >= 3 finite numbers"
    try:
        p = np.asarray(p, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(f"{need}, got {reprlib.repr(p)}") from None
    if p.ndim != 1 or p.size < 3:
        raise ParameterError(f"{need}, got shape {p.shape}")
    bad = int(np.count_nonzero(~np.isfinite(p)))
    if bad:
        raise ParameterError(f"{need}, got {bad} non-finite value(s)")
    return _from_params(p)


def _from_params(p) -> np.ndarray:
    """:func:`from_params` of a checked float array."""
    n = p.size - 2
    return positions(np.cumsum(p[:n]), p[n:])


def _result(xy, lam, method, t0, stats, history):
    eb = bending_energy(xy)
    ec = confinement_energy(xy, lam)
    return QuenchResult(xy=xy, energy_total=eb + ec, energy_bending=eb, energy_confinement=ec,
                        method=method, wall_s=time.perf_counter() - t0, stats=stats,
                        history=history)


def _checked_start(xy0, lam) -> tuple[np.ndarray, float]:
    """The start ``xy0`` and ``lam`` of a minimisation, checked: an (N+1, 2) array of finite
    numbers with N >= 2 and a finite Lambda from 0 (a negative one pushes the rod to infinity) to
    :data:`simulate.energy.LAMBDA_MAX`, the command line's bound."""
    try:
        xy0 = checked_rod(xy0, min_segments=2)
    except ParameterError as exc:
        # the shared check names the argument xy; here it is called xy0
        raise ParameterError("xy0" + exc.cause[len("xy"):].replace("xy.T", "xy0.T")) from None
    return xy0, check_real("lam", lam, low=0.0, high=LAMBDA_MAX,
                           why="above it the rod is jammed and the bending energy drowns in "
                               "the confinement")


def _check_powell_options(*, maxiter, xtol, ftol, u, contact_cutoff, min_separation,
                          wall_radius, parametrization) -> None:
    """Refuse absurd options of a Powell run, naming the first one (``contact_cutoff`` and
    ``wall_radius`` may be None)."""
    check_whole("maxiter", maxiter, low=1)
    check_real("xtol", xtol, low=0.0, low_open=True)
    check_real("ftol", ftol, low=0.0, low_open=True)
    check_real("u", u, low=0.0)
    check_whole("min_separation", min_separation, low=1)
    if contact_cutoff is not None:
        check_real("contact_cutoff", contact_cutoff, low=0.0, low_open=True)
    if wall_radius is not None:
        check_real("wall_radius", wall_radius, low=0.0, low_open=True)
    if parametrization not in ("bend", "tangent"):
        raise ParameterError(f"parametrization must be 'bend' or 'tangent', got "
                             f"{parametrization!r}")


def _check_runs(n_runs, nematic_runs) -> tuple[int, set]:
    """``n_runs`` (a whole number >= 0) and the set of ``nematic_runs`` (whole numbers of
    runs before the last)."""
    n_runs = check_whole("n_runs", n_runs, low=0)
    try:
        nem = {check_whole("nematic_runs", r, low=0) for r in nematic_runs}
    except TypeError:
        raise ParameterError(f"nematic_runs must be a sequence of run numbers, got "
                             f"{reprlib.repr(nematic_runs)}") from None
    if n_runs > 0 and (n_runs - 1) in nem:
        raise ParameterError(f"nematic_runs {sorted(nem)} names run {n_runs - 1}, the last of "
                             f"n_runs = {n_runs}: the nematic term must not be used in the last "
                             f"run (paper; nematic_runs defaults to {list(NEMATIC_RUNS)})")
    return n_runs, nem


_STAT_NAMES = ("evaluations", "line_searches", "admissibility_checks", "iterations",
               "collision_tests", "clearance_skips")


def powell_protocol(xy0, lam: float, *, seed=None, n_runs: int = N_RUNS,
                    maxiter: int = MAXITER, nematic_runs=NEMATIC_RUNS, u: float = NEMATIC_U,
                    contact_cutoff: float | None = None, min_separation: int = 10,
                    xtol: float = XTOL, ftol: float = FTOL,
                    wall_radius: float | None = None, first_identity: bool = False,
                    parametrization: str = "tangent") -> QuenchResult:
    """The paper's minimisation: ``n_runs`` Powell runs with direction resets.

    Parameters
    ----------
    xy0 : (N+1, 2) array
        Self-avoiding start of finite nodes, N >= 2 (e.g.
        :func:`simulate.noise.initial_shape`).
    lam : float
        Confinement Lambda, finite and >= 0 (switched on at once: a quench).
    seed : int, numpy.random.SeedSequence or numpy.random.Generator, optional
        Seeds the direction resets.
    n_runs : int
        Powell runs (paper: 10), >= 0.
    maxiter : int
        Iterations per run (~30 in the prototype), >= 1.
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
        against scipy in the respective coordinates). The module docstring gives the
        measurement: ``"tangent"`` reproduces the prototype's statistics.

    Returns
    -------
    QuenchResult

    Raises
    ------
    ParameterError
        An argument out of range (naming it), a start that intersects itself or leaves the
        hard-wall disk, or the nematic term in the last run.
    """
    t0 = time.perf_counter()
    xy0, lam = _checked_start(xy0, lam)
    n_runs, nem = _check_runs(n_runs, nematic_runs)
    _check_powell_options(maxiter=maxiter, xtol=xtol, ftol=ftol, u=u,
                          contact_cutoff=contact_cutoff, min_separation=min_separation,
                          wall_radius=wall_radius, parametrization=parametrization)
    rng = np.random.default_rng(check_seed(seed))
    n = xy0.shape[0] - 1
    if has_intersection_grid(np.ascontiguousarray(xy0)):
        raise ParameterError("the initial configuration intersects itself")
    if wall_radius is not None and np.max(np.hypot(xy0[:, 0], xy0[:, 1])) > wall_radius:
        raise ParameterError("the initial configuration leaves the hard-wall disk")
    m = n + 2
    p = to_params(xy0)
    cutoff = default_contact_cutoff(n) if contact_cutoff is None else float(contact_cutoff)
    wall = np.inf if wall_radius is None else float(wall_radius)
    stats = np.zeros(6, np.int64)
    dirs = np.zeros((m, m))
    history = []
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
        xy = _from_params(p)
        history.append((time.perf_counter() - t0,
                        bending_energy(xy) + confinement_energy(xy, lam)))
    xy = _from_params(p)
    return _result(xy, lam, "powell", t0, dict(zip(_STAT_NAMES, map(int, stats))), history)



def lbfgs_quench(xy0, lam: float, *, seed=None, barrier: float = 0.1,
                 barrier_range: float | None = None, min_separation: int = 3,
                 maxiter: int = 20000, wall_radius: float | None = None,
                 restarts: int = 50, gtol: float = 1e-6) -> QuenchResult:
    """Gradient quench: L-BFGS-B on bending + confinement + a smooth contact barrier.

    The hard core is replaced, for the gradient, by :func:`simulate.energy.contact_barrier`
    (``eps (sigma/d - 1)^2`` between a node and the segments far from it along the rod,
    diverging at contact), so contacts can slide instead of jamming. Every evaluation also runs
    the exact hard-core test: a trial that crosses the rod (a line-search step may jump over
    the barrier) gets the energy 1e30 and the line search backtracks; L-BFGS-B is restarted
    from the last admissible point when its line search gives up. The returned configuration is
    self-avoiding (checked), and its energies exclude the barrier.

    Parameters
    ----------
    xy0 : (N+1, 2) array
        Self-avoiding start.
    lam : float
        Confinement Lambda.
    seed : int, optional
        Unused (deterministic); accepted for a uniform interface.
    barrier : float
        Strength ``eps`` of the barrier (per node/segment pair).
    barrier_range : float, optional
        Range ``sigma`` (default 0.4/N, inside the contact cut-off 0.5/N of
        :mod:`simulate.contacts`, so strands held apart by the barrier count as in contact).
    min_separation : int
        A node does not feel the segments within this many indices along the rod.
    maxiter : int
        L-BFGS-B iterations per start.
    wall_radius : float, optional
        Hard-wall disk (centred at the origin), holding the start; trials outside are
        rejected.
    restarts : int
        Maximum L-BFGS-B restarts after an abnormal line-search stop.
    gtol : float
        Projected-gradient tolerance of L-BFGS-B.

    Returns
    -------
    QuenchResult
        ``stats`` holds evaluations, iterations, restarts, rejected (crossing) trials and the
        final barrier energy.

    Raises
    ------
    ParameterError
        An argument out of range (naming it: ``xy0`` not an (N+1, 2) array of finite numbers
        with N >= 2, ``lam`` negative, a count below 1, ...), or the start intersects itself
        or leaves the hard-wall disk.
    """
    from scipy.optimize import minimize

    from simulate.energy import contact_barrier, energy_and_gradient

    t0 = time.perf_counter()
    xy0, lam = _checked_start(xy0, lam)
    check_seed(seed)
    check_real("barrier", barrier, low=0.0)
    if barrier_range is not None:
        check_real("barrier_range", barrier_range, low=0.0, low_open=True)
    check_whole("min_separation", min_separation, low=1)
    check_whole("maxiter", maxiter, low=1)
    check_whole("restarts", restarts, low=1)
    check_real("gtol", gtol, low=0.0, low_open=True)
    if wall_radius is not None:
        check_real("wall_radius", wall_radius, low=0.0, low_open=True)
    if has_intersection_grid(np.ascontiguousarray(xy0)):
        raise ParameterError("the initial configuration intersects itself")
    if wall_radius is not None and np.max(np.hypot(xy0[:, 0], xy0[:, 1])) > wall_radius:
        # every trial would be rejected and the start returned, outside the wall
        raise ParameterError("the initial configuration leaves the hard-wall disk")
    n = xy0.shape[0] - 1
    ds = 1.0 / n
    sigma = 0.4 * ds if barrier_range is None else float(barrier_range)
    theta0, start0 = angles(xy0)
    x0 = np.concatenate([theta0, start0])
    count = {"evaluations": 0, "rejected": 0}
    best = {"f": np.inf, "x": x0.copy()}

    def fun(x):
        count["evaluations"] += 1
        th = x[:n]
        xy = positions(th, x[n:])
        bad = has_intersection_grid(xy) or (wall_radius is not None and np.max(
            np.einsum("ij,ij->i", xy, xy)) > wall_radius ** 2)
        er, gr, _ = contact_barrier(xy, sigma=sigma, eps=barrier, min_separation=min_separation)
        e, g = energy_and_gradient(th, x[n:], lam)
        if bad or not np.isfinite(er):
            # inadmissible trial: a value well above the best admissible one with the smooth
            # gradient, so that L-BFGS-B's line search backtracks (1e30 would end the search)
            count["rejected"] += 1
            gr = np.where(np.isfinite(gr), gr, 0.0)
            er = 0.0
            e = 2.0 * abs(best["f"]) + 1e3 if np.isfinite(best["f"]) else 1e30
            bad = True
        # chain rule: node j > k moves by ds t_k^perp when theta_k changes
        suffix = np.cumsum(gr[::-1], axis=0)[::-1]
        g = g.copy()
        g[:n] += ds * (np.cos(th) * suffix[1:, 1] - np.sin(th) * suffix[1:, 0])
        g[n:] += suffix[0]
        f = e + er
        if f < best["f"] and not bad:
            best["f"] = f
            best["x"] = x.copy()
        return f, g

    x = x0
    nit = 0
    n_restarts = 0
    f_old = np.inf
    for n_restarts in range(restarts):
        res = minimize(fun, x, jac=True, method="L-BFGS-B",
                       options=dict(maxiter=maxiter, maxfun=4 * maxiter, ftol=1e-13,
                                    gtol=gtol))
        nit += int(res.nit)
        x = best["x"]
        if res.success or (np.isfinite(f_old) and not best["f"] < f_old - 1e-10 * abs(f_old)):
            break
        f_old = best["f"]
    xy = positions(x[:n], x[n:])
    if has_intersection_grid(xy):  # cannot happen: crossing trials are never the best point
        raise RuntimeError("lbfgs_quench produced a self-intersecting rod")
    er = contact_barrier(xy, sigma=sigma, eps=barrier, min_separation=min_separation)[0]
    out = _result(xy, lam, "lbfgs", t0, {**count, "iterations": nit,
                                          "restarts": n_restarts, "barrier_energy": er}, [])
    out.history.append((out.wall_s, out.energy_total))
    return out


def anneal(xy0, lam: float, *, lam_start: float = LAM_START, stages: int = STAGES,
           ramp: str = RAMPS[0], method: str = "powell", seed=None, n_runs: int = N_RUNS,
           maxiter: int = MAXITER, nematic_runs=NEMATIC_RUNS, u: float = NEMATIC_U,
           ftol: float = FTOL, xtol: float = XTOL, wall_radius: float | None = None,
           runs_per_stage: int = 2, parametrization: str = "bend") -> QuenchResult:
    """Annealing: Lambda ramped from ``lam_start`` to ``lam`` in ``stages`` stages.

    Every intermediate stage runs ``runs_per_stage`` Powell runs (or one L-BFGS quench) at its
    Lambda; the last stage runs the full protocol (``n_runs`` runs, nematic runs included) at
    the target. Slow compaction lets the rod wind up: the energy approaches the spiral ground
    state ``2 sqrt(Lambda)`` (paper, conclusion) instead of the quench's ~2.5 times more.

    Measured (N = 300, Lambda = 7e5, D = 750, starts 0 and 1; 2 sqrt(Lambda) = 1673):
    bend coordinates, 12 / 24 / 48 stages -> Ẽ = 1909 / 1847 / 1827 (Rg 0.040 / 0.040 /
    0.039), about 5 / 5 / 14 s per configuration; 24 stages with 4 runs per stage: 2041 (no
    better); tangent coordinates, 12 stages: 6694 (local moves cannot wind the rod up). More
    stages approach the spiral slowly (+9 % above 2 sqrt(Lambda) at 48 stages); the remaining
    gap is the open spiral's ends and imperfect winding, not the ramp.

    Parameters
    ----------
    xy0 : (N+1, 2) array
        Self-avoiding start of finite nodes, N >= 2.
    lam : float
        Target Lambda, finite and >= 0 (> 0 for the geometric ramp).
    lam_start : float
        First Lambda of the ramp, finite and > 0.
    stages : int
        Number of Lambda values (>= 1), the last being ``lam``.
    ramp : {"geometric", "linear"}
    method : {"powell", "lbfgs"}
    seed : int or numpy.random.SeedSequence, optional
        Spawns one seed per stage (a Generator cannot be spawned from).
    n_runs, maxiter, nematic_runs, u, ftol, xtol, wall_radius
        As in :func:`powell_protocol`.
    parametrization : {"bend", "tangent"}
        Powell coordinates; ``"bend"`` (default) rotates whole tails and winds the spiral.
    runs_per_stage : int
        Powell runs at each intermediate stage, >= 1.

    Returns
    -------
    QuenchResult
        ``history`` holds (wall seconds, energy at the stage's Lambda) per stage.

    Raises
    ------
    ParameterError
        An argument out of range (naming it), checked before the first stage, or a start
        that intersects itself or leaves the hard-wall disk.
    """
    t0 = time.perf_counter()
    # every option is checked before the first stage: the last stage comes minutes later
    xy, lam = _checked_start(xy0, lam)
    lam_start = check_real("lam_start", lam_start, low=0.0, low_open=True)
    stages = check_whole("stages", stages, low=1)
    check_whole("runs_per_stage", runs_per_stage, low=1)
    check_seed(seed, generator=False)
    if method not in ("powell", "lbfgs"):
        raise ParameterError(f"method must be 'powell' or 'lbfgs', got {method!r}")
    if method == "powell":
        _check_runs(n_runs, nematic_runs)
        _check_powell_options(maxiter=maxiter, xtol=xtol, ftol=ftol, u=u, contact_cutoff=None,
                              min_separation=1, wall_radius=wall_radius,
                              parametrization=parametrization)
    elif wall_radius is not None:
        check_real("wall_radius", wall_radius, low=0.0, low_open=True)
    if ramp == "geometric":
        if lam == 0:
            raise ParameterError("lam must be > 0 for the geometric ramp (ramp='linear' "
                                 "reaches 0), got 0")
        lams = np.geomspace(min(lam_start, lam), lam, stages)
    elif ramp == "linear":
        lams = np.linspace(min(lam_start, lam), lam, stages)
    else:
        raise ParameterError(f"unknown ramp {ramp!r}")
    # the last stage is the target: with one stage, numpy's ramp holds only its start
    lams[-1] = lam
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    history = []
    stats = {}
    for s, (lam_s, child) in enumerate(zip(lams, ss.spawn(stages))):
        last = s == stages - 1
        if method == "powell":
            r = powell_protocol(xy, float(lam_s), seed=child, n_runs=n_runs if last else
                                runs_per_stage, maxiter=maxiter,
                                nematic_runs=nematic_runs if last else (), u=u, ftol=ftol,
                                xtol=xtol, wall_radius=wall_radius,
                                parametrization=parametrization)
        else:
            r = lbfgs_quench(xy, float(lam_s), wall_radius=wall_radius)
        xy = r.xy
        for k, v in r.stats.items():
            stats[k] = stats.get(k, 0) + v
        history.append((time.perf_counter() - t0, r.energy_total))
    return _result(xy, lam, f"anneal-{method}", t0, stats, history)


def scipy_powell(xy0, lam: float, *, maxiter: int = MAXITER, direc=None, xtol: float = XTOL,
                 ftol: float = FTOL, hard_core: bool = True, parametrization: str = "tangent",
                 u: float = 0.0, contact_cutoff: float | None = None,
                 min_separation: int = 10, wall_radius: float | None = None):
    """Reference: one ``scipy.optimize.minimize(method="Powell")`` run on the same energy.

    Parameters
    ----------
    xy0 : (N+1, 2) array
    lam : float
    maxiter : int
    direc : (N+2, N+2) array, optional
        Initial direction set in the chosen coordinates (scipy's default: identity).
    xtol, ftol : float
    hard_core : bool
        Self-intersecting trials get the energy 1e30 (as in the paper).
    parametrization : {"tangent", "bend"}
        Coordinates ``(theta, x0, y0)`` or ``(phi, x0, y0)``, as :func:`powell_protocol`.
    u, contact_cutoff, min_separation
        Nematic term (``u = 0``: none); its contact list is recomputed at every evaluation
        (the numba engine keeps it fixed during an iteration).
    wall_radius : float, optional
        Hard-wall disk radius (centred at the origin): a trial with a node beyond it gets the
        energy 1e30, as the hard core's, so the wall binds as in :func:`powell_protocol`.

    Returns
    -------
    QuenchResult

    Raises
    ------
    ParameterError
        An argument out of range, naming it (as :func:`powell_protocol`).
    """
    from scipy.optimize import minimize

    from simulate.energy import nematic_energy

    t0 = time.perf_counter()
    xy0, lam = _checked_start(xy0, lam)
    _check_powell_options(maxiter=maxiter, xtol=xtol, ftol=ftol, u=u,
                          contact_cutoff=contact_cutoff, min_separation=min_separation,
                          wall_radius=wall_radius, parametrization=parametrization)
    n = xy0.shape[0] - 1
    cutoff = default_contact_cutoff(n) if contact_cutoff is None else float(contact_cutoff)
    count = [0]
    tangent = parametrization == "tangent"
    wall2 = None if wall_radius is None else float(wall_radius) ** 2

    def f(p):
        count[0] += 1
        xy = positions(p[:n] if tangent else np.cumsum(p[:n]), p[n:])
        if hard_core and has_intersection_grid(xy):
            return 1e30
        if wall2 is not None and np.max(np.einsum("ij,ij->i", xy, xy)) > wall2:
            return 1e30
        e = bending_energy(xy) + confinement_energy(xy, lam)
        if u > 0:
            e += nematic_energy(xy, u=u, cutoff=cutoff, min_separation=min_separation)
        return e

    if tangent:
        theta, start = angles(xy0)
        p0 = np.concatenate([theta, start])
    else:
        p0 = to_params(xy0)
    opts = dict(maxiter=maxiter, xtol=xtol, ftol=ftol)
    if direc is not None:
        opts["direc"] = np.array(direc, dtype=float)
    res = minimize(f, p0, method="Powell", options=opts)
    xy = positions(res.x[:n] if tangent else np.cumsum(res.x[:n]), res.x[n:])
    out = _result(xy, lam, "scipy-powell", t0, {"evaluations": count[0],
                                                 "iterations": int(res.nit)}, [])
    out.history.append((out.wall_s, out.energy_total))
    return out


def scipy_protocol(xy0, lam: float, *, seed=None, n_runs: int = N_RUNS, maxiter: int = MAXITER,
                   nematic_runs=NEMATIC_RUNS, u: float = NEMATIC_U, ftol: float = FTOL,
                   xtol: float = XTOL, parametrization: str = "tangent",
                   wall_radius: float | None = None) -> QuenchResult:
    """The paper's protocol with scipy's Powell (the prototype's way; slow reference).

    Same runs, direction resets (random signed permutations of the coordinate directions) and
    nematic runs as :func:`powell_protocol`, each run a :func:`scipy_powell` call.

    Parameters
    ----------
    xy0 : (N+1, 2) array
        Self-avoiding start, inside the wall when there is one.
    lam : float
        Confinement Lambda.
    seed, n_runs, maxiter, nematic_runs, u, ftol, xtol, parametrization, wall_radius
        As in :func:`powell_protocol`.

    Returns
    -------
    QuenchResult
        ``history`` holds (wall seconds, energy) after every run.

    Raises
    ------
    ParameterError
        An argument out of range, naming it (as :func:`powell_protocol`), or the start leaves
        the hard-wall disk: every trial would be rejected and the rod would stay where it is,
        outside.
    """
    t0 = time.perf_counter()
    xy, lam = _checked_start(xy0, lam)
    _, nem = _check_runs(n_runs, nematic_runs)
    _check_powell_options(maxiter=maxiter, xtol=xtol, ftol=ftol, u=u, contact_cutoff=None,
                          min_separation=1, wall_radius=wall_radius,
                          parametrization=parametrization)
    rng = np.random.default_rng(check_seed(seed))
    if wall_radius is not None and np.max(np.hypot(xy[:, 0], xy[:, 1])) > wall_radius:
        raise ParameterError("the initial configuration leaves the hard-wall disk")
    m = xy.shape[0] + 1
    history = []
    evals = 0
    for run in range(n_runs):
        direc = np.zeros((m, m))
        perm = rng.permutation(m)  # same draws, same order as powell_protocol
        direc[np.arange(m), perm] = rng.choice([-1.0, 1.0], size=m)
        r = scipy_powell(xy, lam, maxiter=maxiter, direc=direc, xtol=xtol, ftol=ftol,
                         parametrization=parametrization, u=u if run in nem else 0.0,
                         wall_radius=wall_radius)
        xy = r.xy
        evals += r.stats["evaluations"]
        history.append((time.perf_counter() - t0, r.energy_total))
    return _result(xy, lam, "scipy-powell", t0, {"evaluations": evals}, history)


__all__ = ["QuenchResult", "powell_protocol", "lbfgs_quench", "anneal", "scipy_powell",
           "scipy_protocol", "default_contact_cutoff",
           "to_params", "from_params"]
