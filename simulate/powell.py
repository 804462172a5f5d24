"""Powell's method for the confined rod, entirely in numba (paper, "Search for local minima").

A faithful port of ``scipy.optimize.minimize(method="Powell")`` (same bracketing, same Brent
line search with ``tol = 100 xtol``, same direction-set update) on the parameters
``p = (phi_0 .. phi_{N-1}, x0, y0)``, bend angles ``phi_k = theta_k - theta_{k-1}`` (``phi_0 =
theta_0``) and the start point, made fast by the structure of the rod:

* coordinates: the engine stores bend angles; a coordinate slot is either the bend angle
  ``phi_k`` (``tangent=False``) or the tangent angle ``theta_k`` (``tangent=True``, direction
  ``e_k - e_{k+1}`` in bend space; Powell's method is equivariant under this linear map, so this
  IS Powell on ``(theta, x0, y0)``, checked against scipy);
* along a tangent direction ``theta_k`` segment ``k`` turns about ``R_k`` and the tail
  translates by ``v`` (``|v| <= 2/N``): bending changes at two nodes, confinement by
  ``Lambda (2 v . sum_{j>k} w_j R_j + |v|^2 sum_{j>k} w_j)``, O(1); the hard-core test uses
  per-segment clearances to the head and to segment k (no test while ``|v|`` is below all);
* along a coordinate direction ``phi_k`` the tail (nodes ``j > k``) rotates rigidly about
  ``R_k``: the bending energy changes at one node and the confinement energy follows from
  suffix sums of ``w_j``, ``w_j R_j``, ``w_j |R_j|^2``, so one trial costs O(1); along ``x0``,
  ``y0`` the rod translates (O(1), no new contact possible);
* hard core: a trial is tested for self-intersection only when it would be accepted (its energy
  is not above the current best of the line search); otherwise its finite value only enters
  the parabolic interpolation. For a coordinate trial only head (segments < k) against rotated
  tail (segments >= k) is tested: each tail segment ``j`` has a precomputed clearance ``c_j`` to
  the head (grid, capped) and moves by at most ``2 |sin(alpha/2)| r_j``, so a trial with
  ``|alpha|`` below ``min_j c_j / r_j`` is admissible with no test at all, and otherwise only the
  tail segments that could reach the head are tested, through the head's grid;
  the clearances skip the exact distance of a pair whose midpoints are farther apart than the
  smallest distance found so far plus one segment length (it cannot lower the minimum), and
  measure a segment met in several grid cells once, so they are the same numbers as the plain
  minimum at 0.65x the CPU time of the whole minimisation (N = 300, 20 starts; same
  trajectories and counters), and one call measures every tail segment (0.73x again: a call
  per segment spent most of its time counting references to its buffers);
* general directions (Powell's extrapolated ones) cost O(N) per trial and use the full grid test;
* the nematic self-contact term ``u sin^2 alpha`` (pairs of segments closer than a cut-off) uses
  the contact list of the configuration at the start of each Powell iteration, kept fixed during
  the iteration; along ``theta_k`` it is O(1) from ``sum cos 2phi``, ``sum sin 2phi`` of the
  head-tail pairs.

Inadmissible trials get the energy ``BIG`` (1e30), "a very large number" as in the paper; a
trial is inadmissible when two non-adjacent segments come closer than ``MARGIN`` (1e-9 L).

The state shared by the kernels has named fields: :class:`Rod` (the configuration of the run)
and :class:`Scratch` (reused buffers, the lazily built hard-core test, the direction of a
general line search, the nematic contact list, the counters) are mutable numba ``structref``
records, passed by reference so that a call does not copy or reference-count each of their
arrays; :class:`Line` (the move of one line search and its step-0 constants, scalars only) and
:class:`Model` (energy parameters and constraints) are small named tuples passed by value.
Every array or record passed to a compiled function costs an atomic reference-count increment
and decrement per call, so the kernels called per trial take these two records and scalars
alone, and the loops over tail segments (clearances, collision tests) run inside one call.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from numba.core import types
from numba.experimental import structref

from simulate.intersect import close_pairs, has_contact_grid, seg_dist2

BIG = 1e30
# Clearance kept between non-adjacent segments (units of L). The hard core pushes contacts to
# the boundary of the admissible set: without a margin, contacts end ~1e-15 apart and the
# rounding of rebuilding positions from angles (or of the next stage's start) can turn them
# into crossings (measured: 2e-15 minimum gaps, and a crossing after an anneal stage).
MARGIN = 1e-9
_M2 = MARGIN * MARGIN
_GOLD = 1.618034
_CG = 0.3819660
_MINTOL = 1.0e-11

# moves of a line search (``Line.mode``)
BEND = 0      # bend angle phi_k: the tail rotates rigidly about node k
SHIFT = 1     # x0 or y0: the whole rod translates
GENERAL = 2   # any direction of parameter space (Powell's extrapolated ones): O(N) per trial
TANGENT = 3   # tangent angle theta_k: segment k turns, the tail translates

# relative slack of the midpoint bounds (segment distance >= midpoint distance - one segment
# length): far above rounding, so a pair the bound skips is never one the exact test catches
_REL = 1e-6

# head-grid bounds: cells no smaller than a segment, at most 41 x 41 of them
_GRID_CELLS = 41 * 41 + 2


@structref.register
class _RodType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class Rod(structref.StructRefProxy):
    """The configuration of a Powell run, kept consistent with ``p`` after every step.

    Attributes
    ----------
    p : (N+2,) float64
        Search parameters: bend angles ``phi_0 .. phi_{N-1}``, then ``x0, y0``.
    xy : (N+1, 2) float64
        Node positions.
    theta : (N,) float64
        Tangent angles ``theta_k = phi_0 + .. + phi_k``.
    w : (N+1,) float64
        Trapezoid weights of the confinement integral.
    tail_w, tail_wx, tail_wy, tail_wr2 : (N+2,) float64
        Suffix sums over nodes ``j >= k`` of ``w_j``, ``w_j x_j``, ``w_j y_j``,
        ``w_j |R_j|^2`` (index N+1 holds zeros).
    """


_ROD_FIELDS = ["p", "xy", "theta", "w", "tail_w", "tail_wx", "tail_wy", "tail_wr2"]
structref.define_proxy(Rod, _RodType, _ROD_FIELDS)


class Line(NamedTuple):
    """One line search: its move and the step-0 constants every trial along it shares.

    A trial at step ``a`` moves the coordinate by ``x = sign * a``. Fields a move does not
    use are 0.

    Attributes
    ----------
    mode : int
        ``BEND``, ``TANGENT``, ``SHIFT`` or ``GENERAL``.
    k : int
        The coordinate: node / segment ``k`` (``BEND``, ``TANGENT``) or the axis (0: ``x0``,
        1: ``y0``) of a ``SHIFT``.
    sign : float
        Sign of the coordinate direction (+1 or -1).
    f0 : float
        Energy at step 0.
    lin_x, lin_y : float
        Confinement coefficients: ``BEND``: ``R_k . V`` and ``R_k x V`` with ``V = sum_{j>k}
        w_j (R_j - R_k)``; ``TANGENT``: ``sum_{j>k} w_j R_j``; ``SHIFT``: ``sum_j w_j`` times
        the coordinate along the axis (``lin_x`` only).
    weight : float
        Weight of the translated nodes: ``sum_{j>k} w_j`` (``TANGENT``), ``sum_j w_j``
        (``SHIFT``).
    phi_k, phi_k1 : float
        Bend angles at nodes ``k`` and ``k+1`` (``phi_k1 = 0`` past the last node).
    bend_k, bend_k1 : float
        Their bending terms ``2 - 2 cos phi`` at step 0.
    nem_cos, nem_sin : float
        Nematic pairs cut by the move: sums of ``cos 2(theta_a - theta_b)`` and of the signed
        ``sin 2(theta_a - theta_b)``.
    cos_k, sin_k : float
        ``cos theta_k``, ``sin theta_k`` (``TANGENT``).

    The direction of a ``GENERAL`` line is held in ``Scratch.direction``: a line of scalars
    alone is passed to the kernels of every trial without reference counting.
    """

    mode: int
    k: int
    sign: float
    f0: float
    lin_x: float
    lin_y: float
    weight: float
    phi_k: float
    phi_k1: float
    bend_k: float
    bend_k1: float
    nem_cos: float
    nem_sin: float
    cos_k: float
    sin_k: float


@structref.register
class _ScratchType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class Scratch(structref.StructRefProxy):
    """Buffers reused by every line search of a run, and the run's counters.

    The hard-core test of a coordinate move is built lazily, at the first trial of its line
    search that needs it (most line searches end without one).

    Attributes
    ----------
    p_trial : (N+2,) float64
        Parameters of a ``GENERAL`` trial.
    xy_trial : (N+1, 2) float64
        Its node positions.
    theta_trial : (N,) float64
        Its tangent angles (nematic term).
    reach : (N,) float64
        ``BEND``: farthest distance ``r_j`` of tail segment ``j`` from the pivot node ``k``.
    clear2 : (N,) float64
        Squared clearance of moving segment ``j`` to the fixed part, capped at one grid cell.
    ready : (1,) bool
        ``reach``, ``clear2``, ``safe`` and the head grid hold the current line search's test.
    safe : (1,) float64
        Move below which every trial is admissible: the chord ``2 |sin(x/2)|`` (``BEND``) or
        the translation ``|v|`` (``TANGENT``).
    grid_origin : (2,) float64
        Lower-left corner of the head grid (segments ``0 .. k-1``).
    grid_cell : (1,) float64
        Its cell side.
    grid_shape : (2,) int64
        Its cell counts ``nx, ny``.
    grid_start, grid_items : int64 arrays
        Its segments per cell (CSR).
    grid_range : (N, 4) int64
        Cell ranges ``x0, x1, y0, y1`` of each head segment while the grid is built.
    seen : (N + 1,) int64
        Per segment, the last clearance query that met it (a segment in several cells is
        measured once per query); ``seen[N]`` counts the queries.
    direction : (N+2,) float64
        The direction in parameter space of the current ``GENERAL`` line search.
    pairs : (P, 2) int64
        The nematic contact list of the current Powell iteration (empty without the term).
    stats : (6,) int64
        Counters (see :func:`powell_run`).
    """


_SCRATCH_FIELDS = ["p_trial", "xy_trial", "theta_trial", "reach", "clear2", "ready", "safe",
                   "grid_origin", "grid_cell", "grid_shape", "grid_start", "grid_items",
                   "grid_range", "seen", "direction", "pairs", "stats"]
structref.define_proxy(Scratch, _ScratchType, _SCRATCH_FIELDS)


class Model(NamedTuple):
    """Energy and constraints of a run.

    Attributes
    ----------
    lam : float
        Confinement Lambda.
    u : float
        Nematic strength (0: no nematic term).
    wall2 : float
        Squared hard-wall radius (``inf``: no wall).
    hard_core : bool
        Test trials for self-intersection.
    """

    lam: float
    u: float
    wall2: float
    hard_core: bool


# ----------------------------------------------------------------------------- rod state
@njit(cache=True)
def _build_xy(p, n, xy):
    # p holds bend angles: theta_i = p_0 + ... + p_i
    ds = 1.0 / n
    xy[0, 0] = p[n]
    xy[0, 1] = p[n + 1]
    th = 0.0
    for i in range(n):
        th += p[i]
        xy[i + 1, 0] = xy[i, 0] + ds * math.cos(th)
        xy[i + 1, 1] = xy[i, 1] + ds * math.sin(th)


@njit(cache=True)
def _theta(p, n, th):
    t = 0.0
    for i in range(n):
        t += p[i]
        th[i] = t


@njit(cache=True)
def _suffix(rod):
    """Suffix sums of ``w``, ``w x``, ``w y``, ``w |R|^2`` over nodes ``j >= k``."""
    xy = rod.xy
    w = rod.w
    sw = rod.tail_w
    swx = rod.tail_wx
    swy = rod.tail_wy
    swr2 = rod.tail_wr2
    n1 = xy.shape[0]
    sw[n1] = 0.0
    swx[n1] = 0.0
    swy[n1] = 0.0
    swr2[n1] = 0.0
    for j in range(n1 - 1, -1, -1):
        x = xy[j, 0]
        y = xy[j, 1]
        sw[j] = sw[j + 1] + w[j]
        swx[j] = swx[j + 1] + w[j] * x
        swy[j] = swy[j + 1] + w[j] * y
        swr2[j] = swr2[j + 1] + w[j] * (x * x + y * y)


@njit(cache=True)
def _sync(rod):
    """Positions, tangent angles and suffix sums from the parameters (no drift from moves)."""
    n = rod.theta.shape[0]
    _build_xy(rod.p, n, rod.xy)
    _suffix(rod)
    _theta(rod.p, n, rod.theta)


@njit(cache=True)
def _new_rod(p):
    n = p.shape[0] - 2
    ds = 1.0 / n
    w = np.full(n + 1, ds)
    w[0] = 0.5 * ds
    w[n] = 0.5 * ds
    rod = Rod(p, np.empty((n + 1, 2)), np.empty(n), w, np.empty(n + 2), np.empty(n + 2),
              np.empty(n + 2), np.empty(n + 2))
    _sync(rod)
    return rod


@njit(cache=True)
def _new_scratch(n, stats):
    return Scratch(np.empty(n + 2), np.empty((n + 1, 2)), np.empty(n), np.empty(n),
                   np.empty(n), np.zeros(1, np.bool_), np.zeros(1), np.empty(2), np.empty(1),
                   np.empty(2, np.int64), np.empty(_GRID_CELLS, np.int64),
                   np.empty(4 * n + 4, np.int64), np.empty((n, 4), np.int64),
                   np.full(n + 1, -1, np.int64), np.empty(n + 2), np.empty((0, 2), np.int64),
                   stats)


@njit(cache=True)
def _bending_p(p, n):
    e = 0.0
    for i in range(1, n):
        e += 2.0 - 2.0 * math.cos(p[i])
    return e * n


@njit(cache=True)
def _nematic_p(th, pairs, u):
    # th: tangent angles
    if u == 0.0:
        return 0.0
    e = 0.0
    for q in range(pairs.shape[0]):
        s = math.sin(th[pairs[q, 0]] - th[pairs[q, 1]])
        e += s * s
    return u * e


@njit(cache=True)
def _rod_energy(rod, model, pairs):
    n = rod.theta.shape[0]
    return (_bending_p(rod.p, n) + model.lam * rod.tail_wr2[0]
            + _nematic_p(rod.theta, pairs, model.u))


@njit(cache=True)
def _outside_wall(xy, wall2):
    for j in range(xy.shape[0]):
        if xy[j, 0] * xy[j, 0] + xy[j, 1] * xy[j, 1] > wall2:
            return True
    return False


# ----------------------------------------------------------------------------- head/tail test
@njit(cache=True, inline="always")
def _seg_reach(xy):
    """Upper bound of the sum of two segments' half lengths: one nominal segment length
    ``1/N`` with slack (moves are rigid, so lengths stay ``1/N`` up to rounding)."""
    return (1.0 + _REL) / (xy.shape[0] - 1) + 1e-15


@njit(cache=True)
def _store_head_grid(xy, k, n, scratch):
    """Build the grid of head segments 0..k-1 into ``scratch``; returns its cell side.

    Cells no smaller than a segment, at most 41 x 41 of them, over the head's bounding box;
    CSR in the scratch buffers (built without allocating).
    """
    hcell = 1.0 / n
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
    start = scratch.grid_start
    items = scratch.grid_items
    rng = scratch.grid_range
    for c in range(ncell + 1):
        start[c] = 0
    for s in range(k):
        x0 = int((min(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        x1 = int((max(xy[s, 0], xy[s + 1, 0]) - xmin) / h)
        y0 = int((min(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        y1 = int((max(xy[s, 1], xy[s + 1, 1]) - ymin) / h)
        rng[s, 0] = x0
        rng[s, 1] = x1
        rng[s, 2] = y0
        rng[s, 3] = y1
        for cx in range(x0, min(x1, nx - 1) + 1):
            for cy in range(y0, min(y1, ny - 1) + 1):
                start[cx * ny + cy + 1] += 1
    for c in range(ncell):
        start[c + 1] += start[c]
    # fill with start[c] as the cursor of cell c, then shift the cursors back
    for s in range(k):
        x0 = rng[s, 0]
        x1 = rng[s, 1]
        y0 = rng[s, 2]
        y1 = rng[s, 3]
        for cx in range(x0, min(x1, nx - 1) + 1):
            for cy in range(y0, min(y1, ny - 1) + 1):
                c = cx * ny + cy
                items[start[c]] = s
                start[c] += 1
    for c in range(ncell, 0, -1):
        start[c] = start[c - 1]
    start[0] = 0
    scratch.grid_origin[0] = xmin
    scratch.grid_origin[1] = ymin
    scratch.grid_cell[0] = h
    scratch.grid_shape[0] = nx
    scratch.grid_shape[1] = ny
    return h


@njit(cache=True)
def _head_clearances(xy, k, n, pad, scratch):
    """``clear2[j] = min(d2_j, pad^2)`` for the tail segments ``j = k .. n-1``, ``d2_j`` the
    smallest squared distance (0 = touching) of segment ``j`` to the head segments whose cells
    (the grid in ``scratch``) meet its bbox grown by ``pad``.

    A head segment is skipped, without its exact distance, when the distance of the two
    midpoints less one segment length (with slack) already exceeds the smallest distance
    found so far (or ``pad``): it cannot lower the result, which is therefore the same as
    the minimum over every candidate, capped at ``pad^2``. A segment met in several cells is
    measured once per query (``seen``). All segments are handled in one call so that the
    buffers are bound once, not once per segment.
    """
    xmin = scratch.grid_origin[0]
    ymin = scratch.grid_origin[1]
    h = scratch.grid_cell[0]
    nx = scratch.grid_shape[0]
    ny = scratch.grid_shape[1]
    start = scratch.grid_start
    items = scratch.grid_items
    seen = scratch.seen
    out = scratch.clear2
    last = seen.shape[0] - 1
    cap = pad * pad
    reach = _seg_reach(xy)
    for j in range(k, n):
        ax = xy[j, 0]
        ay = xy[j, 1]
        bx = xy[j + 1, 0]
        by = xy[j + 1, 1]
        out[j] = cap
        x0 = int(math.floor((min(ax, bx) - pad - xmin) / h))
        x1 = int(math.floor((max(ax, bx) + pad - xmin) / h))
        y0 = int(math.floor((min(ay, by) - pad - ymin) / h))
        y1 = int(math.floor((max(ay, by) + pad - ymin) / h))
        if x1 < 0 or y1 < 0 or x0 > nx - 1 or y0 > ny - 1:
            continue
        best = cap
        mx = 0.5 * (ax + bx)
        my = 0.5 * (ay + by)
        thr = pad * (1.0 + _REL) + reach
        thr2 = thr * thr
        qid = seen[last] + 1
        seen[last] = qid
        for cx in range(max(x0, 0), min(x1, nx - 1) + 1):
            for cy in range(max(y0, 0), min(y1, ny - 1) + 1):
                c = cx * ny + cy
                for q in range(start[c], start[c + 1]):
                    i = items[q]
                    if i == j - 1 or seen[i] == qid:
                        continue
                    seen[i] = qid
                    ex = 0.5 * (xy[i, 0] + xy[i + 1, 0]) - mx
                    ey = 0.5 * (xy[i, 1] + xy[i + 1, 1]) - my
                    if ex * ex + ey * ey > thr2:
                        continue
                    d2 = seg_dist2(xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1], ax, ay, bx,
                                   by)
                    if d2 < best:
                        best = d2
                        if best == 0.0:
                            break  # touching: nothing is closer
                        thr = math.sqrt(best) * (1.0 + _REL) + reach
                        thr2 = thr * thr
                if best == 0.0:
                    break
            if best == 0.0:
                break
        out[j] = best


@njit(cache=True)
def _tail_hits(xy, k, n, scratch, bend, c, s, chord, vx, vy, v2, kx1, ky1):
    """Explicit collision test of a coordinate trial: does a moved tail segment ``j >= k``
    come closer than ``MARGIN`` to a head segment (or, ``TANGENT``, ``j >= k + 2`` to the
    turned segment ``k``)?

    ``BEND`` (``bend``): the tail turns by ``(c, s) = (cos x, sin x)`` about node ``k`` and
    segment ``j`` moves by at most ``chord`` times its reach. ``TANGENT``: segment ``k`` ends
    at ``(kx1, ky1)``, the tail translates by ``(vx, vy)``, ``v2 = |v|^2``. A segment whose
    clearance exceeds its move is skipped; the others are tested against the head segments
    of the grid cells its bbox (grown by ``MARGIN``) meets, skipping those whose midpoints are
    too far apart (as in :func:`_head_clearances`). One call tests every segment, so that the
    buffers are bound once per trial.
    """
    xmin = scratch.grid_origin[0]
    ymin = scratch.grid_origin[1]
    h = scratch.grid_cell[0]
    nx = scratch.grid_shape[0]
    ny = scratch.grid_shape[1]
    start = scratch.grid_start
    items = scratch.grid_items
    clear2 = scratch.clear2
    reach = scratch.reach
    rkx = xy[k, 0]
    rky = xy[k, 1]
    thr = MARGIN * (1.0 + _REL) + _seg_reach(xy)
    thr2 = thr * thr
    for j in range(k, n):
        if bend:
            if chord * chord * reach[j] * reach[j] < clear2[j]:
                continue
            dx = xy[j, 0] - rkx
            dy = xy[j, 1] - rky
            ax = rkx + c * dx - s * dy
            ay = rky + s * dx + c * dy
            dx = xy[j + 1, 0] - rkx
            dy = xy[j + 1, 1] - rky
            bx = rkx + c * dx - s * dy
            by = rky + s * dx + c * dy
        else:
            if v2 < clear2[j]:
                continue
            if j == k:
                ax, ay, bx, by = rkx, rky, kx1, ky1
            else:
                ax = xy[j, 0] + vx
                ay = xy[j, 1] + vy
                bx = xy[j + 1, 0] + vx
                by = xy[j + 1, 1] + vy
        if k >= 1:
            x0 = int(math.floor((min(ax, bx) - MARGIN - xmin) / h))
            x1 = int(math.floor((max(ax, bx) + MARGIN - xmin) / h))
            y0 = int(math.floor((min(ay, by) - MARGIN - ymin) / h))
            y1 = int(math.floor((max(ay, by) + MARGIN - ymin) / h))
            if not (x1 < 0 or y1 < 0 or x0 > nx - 1 or y0 > ny - 1):
                mx = 0.5 * (ax + bx)
                my = 0.5 * (ay + by)
                for cx in range(max(x0, 0), min(x1, nx - 1) + 1):
                    for cy in range(max(y0, 0), min(y1, ny - 1) + 1):
                        cell = cx * ny + cy
                        for q in range(start[cell], start[cell + 1]):
                            i = items[q]
                            if i == j - 1:
                                continue
                            ex = 0.5 * (xy[i, 0] + xy[i + 1, 0]) - mx
                            ey = 0.5 * (xy[i, 1] + xy[i + 1, 1]) - my
                            if ex * ex + ey * ey > thr2:
                                continue
                            if seg_dist2(xy[i, 0], xy[i, 1], xy[i + 1, 0], xy[i + 1, 1], ax,
                                         ay, bx, by) < _M2:
                                return True
        if not bend and j >= k + 2 and seg_dist2(rkx, rky, kx1, ky1, ax, ay, bx, by) < _M2:
            return True
    return False


@njit(cache=True)
def _prepare_bend(line, xy, scratch, n):
    """Head grid, per-tail-segment reach r_j and clearance c_j (capped), safe chord."""
    k = line.k
    h = _store_head_grid(xy, k, n, scratch)
    pad = h
    _head_clearances(xy, k, n, pad, scratch)
    rkx = xy[k, 0]
    rky = xy[k, 1]
    safe = math.inf
    reach = scratch.reach
    clear2 = scratch.clear2
    for j in range(k, n):
        r = max(math.hypot(xy[j, 0] - rkx, xy[j, 1] - rky),
                math.hypot(xy[j + 1, 0] - rkx, xy[j + 1, 1] - rky))
        reach[j] = r
        c = max(math.sqrt(min(clear2[j], pad * pad)) - MARGIN, 0.0)
        clear2[j] = c * c
        if r > 0.0:
            safe = min(safe, c / r)
    scratch.ready[0] = True
    scratch.safe[0] = safe


@njit(cache=True)
def _prepare_tangent(line, xy, scratch, n):
    """Tangent move of segment k: head 0..k-1 fixed, segment k turns about R_k, the tail
    translates; every moving point moves by at most |v| relative to the head and to segment
    k. Clearance c_j of segment j >= k to the head (and, j >= k+2, to segment k), capped."""
    k = line.k
    h = 1.0 / n
    if k >= 1:
        h = _store_head_grid(xy, k, n, scratch)
        _head_clearances(xy, k, n, h, scratch)
    pad = h
    clear2 = scratch.clear2
    safe = math.inf
    kx0 = xy[k, 0]
    ky0 = xy[k, 1]
    kx1 = xy[k + 1, 0]
    ky1 = xy[k + 1, 1]
    kmx = 0.5 * (kx0 + kx1)
    kmy = 0.5 * (ky0 + ky1)
    thr = pad * (1.0 + _REL) + _seg_reach(xy)
    thr2 = thr * thr
    for j in range(k, n):
        c2 = pad * pad
        if k >= 1:
            c2 = min(c2, clear2[j])
        if j >= k + 2:
            ax = xy[j, 0]
            ay = xy[j, 1]
            bx = xy[j + 1, 0]
            by = xy[j + 1, 1]
            # segments whose midpoints are farther apart than pad + one segment length
            # (with slack) are farther apart than pad >= sqrt(c2): the min is unchanged
            ex = 0.5 * (ax + bx) - kmx
            ey = 0.5 * (ay + by) - kmy
            if ex * ex + ey * ey <= thr2:
                c2 = min(c2, seg_dist2(kx0, ky0, kx1, ky1, ax, ay, bx, by))
        c = max(math.sqrt(c2) - MARGIN, 0.0)
        clear2[j] = c * c
        safe = min(safe, c)
    scratch.ready[0] = True
    scratch.safe[0] = safe


# ----------------------------------------------------------------------------- evaluation
@njit(cache=True)
def _energy_coordinate(a, line, n, lam, u):
    """Energy at step ``a`` along a coordinate move (``BEND``, ``SHIFT``, ``TANGENT``): O(1)."""
    x = line.sign * a
    if line.mode == BEND:
        e = line.f0
        if line.k >= 1:
            e += n * (2.0 - 2.0 * math.cos(line.phi_k + x) - line.bend_k)
        e += 2.0 * lam * ((math.cos(x) - 1.0) * line.lin_x + math.sin(x) * line.lin_y)
        if u > 0.0:
            e += 0.5 * u * ((1.0 - math.cos(2.0 * x)) * line.nem_cos
                            - math.sin(2.0 * x) * line.nem_sin)
        return e
    if line.mode == SHIFT:
        return line.f0 + lam * (2.0 * x * line.lin_x + x * x * line.weight)
    c = math.cos(x)
    sn = math.sin(x)
    e = line.f0
    if line.k >= 1:
        e += n * (2.0 - 2.0 * math.cos(line.phi_k + x) - line.bend_k)
    if line.k < n - 1:
        e += n * (2.0 - 2.0 * math.cos(line.phi_k1 - x) - line.bend_k1)
    vx, vy = _tail_shift(line, c, sn, n)
    e += lam * (2.0 * (vx * line.lin_x + vy * line.lin_y) + (vx * vx + vy * vy) * line.weight)
    if u > 0.0:
        e += 0.5 * u * ((1.0 - math.cos(2.0 * x)) * line.nem_cos
                        - math.sin(2.0 * x) * line.nem_sin)
    return e


@njit(cache=True)
def _energy_general(a, direction, p, w, pt, xyt, tht, lam, u, pairs):
    """Energy at step ``a`` along ``direction``: O(N), the trial left in ``pt``, ``xyt``."""
    n = tht.shape[0]
    for i in range(pt.shape[0]):
        pt[i] = p[i] + a * direction[i]
    _build_xy(pt, n, xyt)
    eb = _bending_p(pt, n)
    ec = 0.0
    for j in range(n + 1):
        ec += w[j] * (xyt[j, 0] * xyt[j, 0] + xyt[j, 1] * xyt[j, 1])
    if u > 0.0:
        _theta(pt, n, tht)
    return eb + lam * ec + _nematic_p(tht, pairs, u)


@njit(cache=True)
def _tail_shift(line, c, sn, n):
    """Translation ``v = ds (t_k(theta_k + x) - t_k(theta_k))`` of the tail (nodes j > k) by a
    ``TANGENT`` move of ``x`` (``c = cos x``, ``sn = sin x``)."""
    ds = 1.0 / n
    vx = ds * (line.cos_k * c - line.sin_k * sn - line.cos_k)
    vy = ds * (line.sin_k * c + line.cos_k * sn - line.sin_k)
    return vx, vy


@njit(cache=True)
def _admissible_tangent(a, line, xy, wall2, scratch, n):
    k = line.k
    x = line.sign * a
    c = math.cos(x)
    sn = math.sin(x)
    ds = 1.0 / n
    tx = line.cos_k * c - line.sin_k * sn
    ty = line.sin_k * c + line.cos_k * sn
    vx = ds * tx - ds * line.cos_k
    vy = ds * ty - ds * line.sin_k
    if wall2 < math.inf:
        for j in range(k + 1, n + 1):
            qx = xy[j, 0] + vx
            qy = xy[j, 1] + vy
            if qx * qx + qy * qy > wall2:
                return False
    if not scratch.ready[0]:
        _prepare_tangent(line, xy, scratch, n)
    v2 = vx * vx + vy * vy
    if v2 < scratch.safe[0] * scratch.safe[0]:
        scratch.stats[5] += 1
        return True
    scratch.stats[4] += 1
    kx1 = xy[k, 0] + ds * tx
    ky1 = xy[k, 1] + ds * ty
    return not _tail_hits(xy, k, n, scratch, False, 1.0, 0.0, 0.0, vx, vy, v2, kx1, ky1)


@njit(cache=True)
def _admissible_bend(a, line, xy, wall2, scratch, n):
    k = line.k
    x = line.sign * a
    c = math.cos(x)
    s = math.sin(x)
    rkx = xy[k, 0]
    rky = xy[k, 1]
    if wall2 < math.inf:
        for j in range(k + 1, n + 1):
            dx = xy[j, 0] - rkx
            dy = xy[j, 1] - rky
            qx = rkx + c * dx - s * dy
            qy = rky + s * dx + c * dy
            if qx * qx + qy * qy > wall2:
                return False
    if k == 0:
        return True
    if not scratch.ready[0]:
        _prepare_bend(line, xy, scratch, n)
    chord = 2.0 * abs(math.sin(0.5 * x))
    if chord < scratch.safe[0]:
        scratch.stats[5] += 1
        return True
    scratch.stats[4] += 1
    return not _tail_hits(xy, k, n, scratch, True, c, s, chord, 0.0, 0.0, 0.0, 0.0, 0.0)


@njit(cache=True)
def _admissible(a, line, rod, scratch, wall2):
    """Hard core (and wall) for the trial at step ``a``; a ``GENERAL`` trial is read from
    ``scratch.xy_trial``."""
    n = rod.theta.shape[0]
    xy = rod.xy
    scratch.stats[2] += 1
    if line.mode == TANGENT:
        return _admissible_tangent(a, line, xy, wall2, scratch, n)
    if line.mode == BEND:
        return _admissible_bend(a, line, xy, wall2, scratch, n)
    if line.mode == SHIFT:
        if wall2 < math.inf:
            axis = line.k
            x = line.sign * a
            for j in range(n + 1):
                qx = xy[j, 0] + (x if axis == 0 else 0.0)
                qy = xy[j, 1] + (x if axis == 1 else 0.0)
                if qx * qx + qy * qy > wall2:
                    return False
        return True
    scratch.stats[4] += 1
    if wall2 < math.inf and _outside_wall(scratch.xy_trial, wall2):
        return False
    return not has_contact_grid(scratch.xy_trial, MARGIN)


@njit(cache=True)
def _ev(a, thresh, line, rod, scratch, model):
    """Energy of the trial at step ``a``, ``BIG`` if it is inadmissible; trials above
    ``thresh`` (the line search's best so far) cannot be accepted and skip the hard-core test."""
    scratch.stats[0] += 1
    if line.mode == GENERAL:
        f = _energy_general(a, scratch.direction, rod.p, rod.w, scratch.p_trial,
                            scratch.xy_trial, scratch.theta_trial, model.lam, model.u,
                            scratch.pairs)
    else:
        f = _energy_coordinate(a, line, rod.theta.shape[0], model.lam, model.u)
    if f <= thresh and model.hard_core:
        if not _admissible(a, line, rod, scratch, model.wall2):
            return BIG
    return f


# ----------------------------------------------------------------------------- line search
@njit(cache=True)
def _bracket(line, rod, scratch, model):
    """scipy's ``bracket`` from ``xa = 0``, ``xb = 1`` (``grow_limit = 110``, at most 1000
    steps). Returns ``(xa, xb, xc, fa, fb, fc, ok)``; ``ok`` is false when it gave up."""
    f0 = line.f0
    xa = 0.0
    xb = 1.0
    fa = f0
    fb = _ev(xb, f0, line, rod, scratch, model)
    if fa < fb:
        xa, xb = xb, xa
        fa, fb = fb, fa
    xc = xb + _GOLD * (xb - xa)
    fc = _ev(xc, f0, line, rod, scratch, model)
    it = 0
    while fc < fb:
        tmp1 = (xb - xa) * (fb - fc)
        tmp2 = (xb - xc) * (fb - fa)
        val = tmp2 - tmp1
        if abs(val) < 1e-21:
            denom = 2.0e-21
        else:
            denom = 2.0 * val
        wv = xb - ((xb - xc) * tmp2 - (xb - xa) * tmp1) / denom
        wlim = xb + 110.0 * (xc - xb)
        if it > 1000:
            return xa, xb, xc, fa, fb, fc, False
        it += 1
        if (wv - xc) * (xb - wv) > 0.0:
            fw = _ev(wv, f0, line, rod, scratch, model)
            if fw < fc:
                return xb, wv, xc, fb, fw, fc, True
            elif fw > fb:
                return xa, xb, wv, fa, fb, fw, True
            wv = xc + _GOLD * (xc - xb)
            fw = _ev(wv, f0, line, rod, scratch, model)
        elif (wv - wlim) * (wlim - xc) >= 0.0:
            wv = wlim
            fw = _ev(wv, f0, line, rod, scratch, model)
        elif (wv - wlim) * (xc - wv) > 0.0:
            fw = _ev(wv, f0, line, rod, scratch, model)
            if fw < fc:
                xb = xc
                xc = wv
                wv = xc + _GOLD * (xc - xb)
                fb = fc
                fc = fw
                fw = _ev(wv, f0, line, rod, scratch, model)
        else:
            wv = xc + _GOLD * (xc - xb)
            fw = _ev(wv, f0, line, rod, scratch, model)
        xa = xb
        xb = xc
        xc = wv
        fa = fb
        fb = fc
        fc = fw
    return xa, xb, xc, fa, fb, fc, True


@njit(cache=True)
def _brent(xa, xb, xc, fb, tol, line, rod, scratch, model):
    """scipy's ``Brent`` minimisation in the bracket ``xa, xb, xc`` (at most 500 steps).
    Returns ``(x_min, f_min)``."""
    x = xb
    wb = xb
    v = xb
    fx = fb
    fw = fb
    fv = fb
    if xa < xc:
        a = xa
        b = xc
    else:
        a = xc
        b = xa
    deltax = 0.0
    rat = 0.0
    it = 0
    while it < 500:
        tol1 = tol * abs(x) + _MINTOL
        tol2 = 2.0 * tol1
        xmid = 0.5 * (a + b)
        if abs(x - xmid) < (tol2 - 0.5 * (b - a)):
            break
        if abs(deltax) <= tol1:
            if x >= xmid:
                deltax = a - x
            else:
                deltax = b - x
            rat = _CG * deltax
        else:
            tmp1 = (x - wb) * (fx - fv)
            tmp2 = (x - v) * (fx - fw)
            pp = (x - v) * tmp2 - (x - wb) * tmp1
            tmp2 = 2.0 * (tmp2 - tmp1)
            if tmp2 > 0.0:
                pp = -pp
            tmp2 = abs(tmp2)
            dx_temp = deltax
            deltax = rat
            if (pp > tmp2 * (a - x)) and (pp < tmp2 * (b - x)) and \
                    (abs(pp) < abs(0.5 * tmp2 * dx_temp)):
                rat = pp * 1.0 / tmp2
                uu = x + rat
                if (uu - a) < tol2 or (b - uu) < tol2:
                    if xmid - x >= 0:
                        rat = tol1
                    else:
                        rat = -tol1
            else:
                if x >= xmid:
                    deltax = a - x
                else:
                    deltax = b - x
                rat = _CG * deltax
        if abs(rat) < tol1:
            if rat >= 0:
                uu = x + tol1
            else:
                uu = x - tol1
        else:
            uu = x + rat
        fu = _ev(uu, fx, line, rod, scratch, model)
        if fu > fx:
            if uu < x:
                a = uu
            else:
                b = uu
            if (fu <= fw) or (wb == x):
                v = wb
                wb = uu
                fv = fw
                fw = fu
            elif (fu <= fv) or (v == x) or (v == wb):
                v = uu
                fv = fu
        else:
            if uu >= x:
                a = x
            else:
                b = x
            v = wb
            wb = x
            x = uu
            fv = fw
            fw = fx
            fx = fu
        it += 1
    return x, fx


@njit(cache=True)
def _line_search(tol, line, rod, scratch, model):
    """scipy's ``bracket`` (xa=0, xb=1, grow_limit=110) then ``Brent`` (tol, maxiter 500).

    Returns (alpha_min, f_min). Trials are checked for admissibility only when they could
    become the best point (see module docstring).
    """
    scratch.ready[0] = False
    scratch.safe[0] = 0.0
    xa, xb, xc, fa, fb, fc, ok = _bracket(line, rod, scratch, model)
    cond1 = (fb < fc and fb <= fa) or (fb < fa and fb <= fc)
    cond2 = (xa < xb < xc) or (xc < xb < xa)
    cond3 = math.isfinite(xa) and math.isfinite(xb) and math.isfinite(xc)
    if not (ok and cond1 and cond2 and cond3):
        # scipy's _recover_from_bracket_error: best of the three points
        if fb < fa and fb <= fc:
            return xb, fb
        if fc < fa:
            return xc, fc
        return xa, fa
    return _brent(xa, xb, xc, fb, tol, line, rod, scratch, model)


# ----------------------------------------------------------------------------- Powell
@njit(cache=True)
def _nematic_sums(theta, pairs, k, tangent):
    """Nematic pairs whose angle a move of coordinate ``k`` changes: sums of ``cos 2 dtheta``
    and of ``sin 2 dtheta`` signed by which side turns. A ``TANGENT`` move turns segment ``k``
    alone; a ``BEND`` move turns every segment from ``k`` on (head-tail pairs)."""
    nc = 0.0
    ns = 0.0
    for q in range(pairs.shape[0]):
        ia = pairs[q, 0]
        ib = pairs[q, 1]
        if tangent:
            if ia == k or ib == k:
                ph = 2.0 * (theta[ia] - theta[ib])
                nc += math.cos(ph)
                ns += math.sin(ph) if ib == k else -math.sin(ph)
        elif ia < k <= ib:
            ph = 2.0 * (theta[ia] - theta[ib])
            nc += math.cos(ph)
            ns += math.sin(ph)
    return nc, ns


@njit(cache=True)
def _tangent_line(k, sign, fval, rod, scratch, model):
    n = rod.theta.shape[0]
    phi_k = rod.p[k]
    phi_k1 = rod.p[k + 1] if k < n - 1 else 0.0
    nc = 0.0
    ns = 0.0
    if model.u > 0.0:
        nc, ns = _nematic_sums(rod.theta, scratch.pairs, k, True)
    return Line(TANGENT, k, sign, fval, rod.tail_wx[k + 1], rod.tail_wy[k + 1],
                rod.tail_w[k + 1], phi_k, phi_k1, 2.0 - 2.0 * math.cos(phi_k),
                2.0 - 2.0 * math.cos(phi_k1), nc, ns, math.cos(rod.theta[k]),
                math.sin(rod.theta[k]))


@njit(cache=True)
def _bend_line(k, sign, fval, rod, scratch, model):
    rkx = rod.xy[k, 0]
    rky = rod.xy[k, 1]
    w1 = rod.tail_w[k + 1]
    vx = rod.tail_wx[k + 1] - w1 * rkx
    vy = rod.tail_wy[k + 1] - w1 * rky
    nc = 0.0
    ns = 0.0
    if model.u > 0.0:
        nc, ns = _nematic_sums(rod.theta, scratch.pairs, k, False)
    phi_k = rod.p[k]
    return Line(BEND, k, sign, fval, rkx * vx + rky * vy, rky * vx - rkx * vy, 0.0, phi_k, 0.0,
                2.0 - 2.0 * math.cos(phi_k), 0.0, nc, ns, 0.0, 0.0)


@njit(cache=True)
def _shift_line(axis, sign, fval, rod, scratch):
    moment = rod.tail_wx[0] if axis == 0 else rod.tail_wy[0]
    return Line(SHIFT, axis, sign, fval, moment, 0.0, rod.tail_w[0], 0.0, 0.0, 0.0, 0.0, 0.0,
                0.0, 0.0, 0.0)


@njit(cache=True)
def _general_line(direction, fval, scratch):
    """A line along ``direction``, copied to ``scratch.direction``."""
    d = scratch.direction
    for i in range(d.shape[0]):
        d[i] = direction[i]
    return Line(GENERAL, -1, 1.0, fval, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@njit(cache=True)
def _move_tangent(line, x, rod):
    """Turn segment ``k`` by ``x``: the tail translates."""
    n = rod.theta.shape[0]
    k = line.k
    rod.p[k] += x
    if k < n - 1:
        rod.p[k + 1] -= x
    rod.theta[k] += x
    vx, vy = _tail_shift(line, math.cos(x), math.sin(x), n)
    xy = rod.xy
    for j in range(k + 1, n + 1):
        xy[j, 0] += vx
        xy[j, 1] += vy
    _suffix(rod)


@njit(cache=True)
def _move_bend(line, x, rod):
    """Bend node ``k`` by ``x``: the tail rotates rigidly about it."""
    n = rod.theta.shape[0]
    k = line.k
    xy = rod.xy
    theta = rod.theta
    rkx = xy[k, 0]
    rky = xy[k, 1]
    rod.p[k] += x
    for j in range(k, n):
        theta[j] += x
    c = math.cos(x)
    s = math.sin(x)
    for j in range(k + 1, n + 1):
        dx = xy[j, 0] - rkx
        dy = xy[j, 1] - rky
        xy[j, 0] = rkx + c * dx - s * dy
        xy[j, 1] = rky + s * dx + c * dy
    _suffix(rod)


@njit(cache=True)
def _move_shift(line, x, rod):
    """Translate the rod by ``x`` along axis ``k``."""
    n = rod.theta.shape[0]
    rod.p[n + line.k] += x
    xy = rod.xy
    for j in range(n + 1):
        xy[j, line.k] += x
    _suffix(rod)


@njit(cache=True)
def _search_slot(slot, kind, sgn, dirs, fval, tol, tangent, rod, scratch, model):
    """Line search along direction slot ``slot`` from energy ``fval``; moves the rod to the
    minimum. Returns the energy there."""
    n = rod.theta.shape[0]
    kk = kind[slot]
    if 0 <= kk < n:
        if tangent:
            line = _tangent_line(kk, sgn[slot], fval, rod, scratch, model)
        else:
            line = _bend_line(kk, sgn[slot], fval, rod, scratch, model)
    elif kk >= n:
        line = _shift_line(kk - n, sgn[slot], fval, rod, scratch)
    else:
        line = _general_line(dirs[slot], fval, scratch)
    amin, fnew = _line_search(tol, line, rod, scratch, model)
    if amin != 0.0:
        if line.mode == GENERAL:
            d = scratch.direction
            for i in range(rod.p.shape[0]):
                rod.p[i] += amin * d[i]
            _sync(rod)
        else:
            x = line.sign * amin
            if line.mode == TANGENT:
                _move_tangent(line, x, rod)
            elif line.mode == BEND:
                _move_bend(line, x, rod)
            else:
                _move_shift(line, x, rod)
    return fnew


@njit(cache=True)
def _update_directions(fx, fval, delta, bigind, x1, d1, kind, sgn, dirs, tol, rod, scratch,
                       model):
    """Powell's extrapolation and direction-set update, as scipy: if the extrapolated point
    ``2 p - x1`` is lower and the test on ``delta`` (largest single-slot decrease) passes,
    search along ``p - x1`` and let it replace slot ``bigind``. Returns the energy."""
    m = rod.p.shape[0]
    for i in range(m):
        d1[i] = rod.p[i] - x1[i]
        x1[i] = rod.p[i]
    line = _general_line(d1, fval, scratch)
    fx2 = _ev(1.0, fx, line, rod, scratch, model)
    if not fx > fx2:
        return fval
    t = 2.0 * (fx + fx2 - 2.0 * fval)
    temp = fx - fval - delta
    t *= temp * temp
    temp = fx - fx2
    t -= delta * temp * temp
    if not t < 0.0:
        return fval
    scratch.stats[1] += 1
    amin, fnew = _line_search(tol, line, rod, scratch, model)
    if amin != 0.0:
        for i in range(m):
            rod.p[i] += amin * d1[i]
        _sync(rod)
        kind[bigind] = kind[m - 1]
        sgn[bigind] = sgn[m - 1]
        for i in range(m):
            dirs[bigind, i] = dirs[m - 1, i]
        kind[m - 1] = -1
        for i in range(m):
            dirs[m - 1, i] = amin * d1[i]
    return fnew


@njit(cache=True)
def powell_run(p, lam, kind, sgn, dirs, maxiter, xtol, ftol, u, cutoff, min_separation, wall,
               stats, hard_core=True, tangent=False):
    """One run of Powell's method from ``p`` (modified in place), as scipy's ``Powell``.

    Parameters
    ----------
    p : (N+2,) float64
        Bend angles ``phi_0 .. phi_{N-1}`` then ``x0, y0``; must be admissible.
    lam : float
        Confinement Lambda.
    kind : (N+2,) int64
        Per direction slot: the coordinate index (0..N+1), or -1 for a general direction held
        in ``dirs[slot]``. Updated in place by Powell's direction-set rule.
    sgn : (N+2,) float64
        Sign of each coordinate direction.
    dirs : (N+2, N+2) float64
        General direction vectors (rows where ``kind == -1``); updated in place.
    maxiter : int
        Powell iterations.
    xtol, ftol : float
        scipy's tolerances (line search ``tol = 100 xtol``; stop when ``2 (f_old - f) <=
        ftol (|f_old| + |f|)``).
    u : float
        Nematic self-contact strength; 0 disables the term.
    cutoff : float
        Contact distance of the nematic term (units of L).
    min_separation : int
        Segment pairs closer than this along the rod are not contacts.
    wall : float
        Hard-wall disk radius, ``inf`` for none.
    stats : (6,) int64
        Accumulates [evaluations, line searches, admissibility checks, iterations,
        explicit collision tests, checks settled by the clearance bound].
    hard_core : bool
        False disables the self-intersection test (for comparisons with scipy only).
    tangent : bool
        If true, coordinate slot ``k < N`` is the TANGENT angle ``theta_k`` (direction
        ``e_k - e_{k+1}`` in bend-angle space: segment k turns, the tail translates by at most
        ``2/N``); this is Powell's method in the parameters ``(theta, x0, y0)`` exactly (Powell
        is equivariant under the linear map theta <-> phi when the direction set is mapped).
        If false, slot ``k`` is the bend angle ``phi_k`` (the tail rotates about ``R_k``).

    Returns
    -------
    float
        Energy at the end (nematic term included when ``u > 0``).
    """
    m = p.shape[0]
    rod = _new_rod(p)
    scratch = _new_scratch(m - 2, stats)
    model = Model(lam, u, wall * wall, hard_core)
    tol = xtol * 100.0
    x1 = p.copy()
    d1 = np.empty(m)
    if u > 0.0:
        scratch.pairs = close_pairs(rod.xy, cutoff, min_separation)
    fval = _rod_energy(rod, model, scratch.pairs)
    it = 0
    while True:
        fx = fval
        bigind = 0
        delta = 0.0
        for slot in range(m):
            stats[1] += 1
            fnew = _search_slot(slot, kind, sgn, dirs, fval, tol, tangent, rod, scratch, model)
            if (fval - fnew) > delta:
                delta = fval - fnew
                bigind = slot
            fval = fnew
        it += 1
        stats[3] += 1
        _sync(rod)
        fval = _rod_energy(rod, model, scratch.pairs)
        bnd = ftol * (abs(fx) + abs(fval)) + 1e-20
        if 2.0 * (fx - fval) <= bnd or it >= maxiter:
            break
        fval = _update_directions(fx, fval, delta, bigind, x1, d1, kind, sgn, dirs, tol, rod,
                                  scratch, model)
        if u > 0.0:
            scratch.pairs = close_pairs(rod.xy, cutoff, min_separation)
            fval = _rod_energy(rod, model, scratch.pairs)
    return fval
