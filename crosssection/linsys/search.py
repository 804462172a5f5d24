"""Integer search: exact moves that keep junctions balanced (numba).

The integer problem of the linear system,

    minimise  sum_i w_i (n_i - e_i)^2 + sum_j pen_j |(C n)_j|,   n_i >= 1 integer,

is started from the rounded continuous least squares and improved by *moves*: +-1 changes
of the stacks along a walk through the junctions that keeps every junction it passes
balanced, applied while they lower the objective.  A rounding that breaks conservation is
repaired by the same moves (a violated junction's penalty drops).  This is cycle cancelling
for a bidirected flow with convex costs: exact on balanced (orientable) networks, a strong
local search otherwise (a void bounded by an odd number of cusps makes the packs
non-orientable and the conservation matrix not totally unimodular).  On 40 random networks
with degree-4 junctions it reached the MILP optimum on 37, with the same accuracy against
the truth (0.862 vs 0.863 of stacks; tests/crosssection/linsys/test_search.py).

The walks are cycles through a "ground" state of a small graph searched by Bellman-Ford:
state 0 is the ground; for junction row ``j``, state ``1 + 8 j + k`` with ``k = 0..3`` means
"the next stack must change ``R_j`` by ``rho = (-2, -1, 1, 2)[k]``" and ``k = 4..7`` "a stack
arrived changing ``R_j`` by ``a = (-2, -1, 1, 2)[k - 4]``".
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

__all__ = ["integer_refine", "objective"]


@njit(cache=True)
def _ridx(v):  # pragma: no cover - numba
    """Slot 0..3 of a residual change v in (-2, -1, 1, 2)."""
    return v + 2 if v < 0 else v + 1


@njit(cache=True)
def _rho(k):  # pragma: no cover - numba
    """Residual change of slot k (inverse of :func:`_ridx`)."""
    return k - 2 if k < 2 else k - 1


@njit(cache=True)
def _tau(R, pen, j, a):  # pragma: no cover - numba
    """Penalty change when the residual of row j changes by a."""
    return pen[j] * (abs(R[j] + a) - abs(R[j]))


@njit(cache=True)
def _dcost(n, e, w, s, d):  # pragma: no cover - numba
    """Width-cost change of stack s moved by d (inf below one layer)."""
    v = n[s] + d
    if v < 1:
        return np.inf
    return w[s] * ((v - e[s]) ** 2 - (n[s] - e[s]) ** 2)


@njit(cache=True)
def _relax_starts(R, pen, ban_start, dist, par, par_s):  # pragma: no cover - numba
    """Ground -> start at junction j, paying the residual change there."""
    changed = False
    for j in range(R.shape[0]):
        if ban_start[j]:
            continue
        for k in range(4):
            c = dist[0] + _tau(R, pen, j, _rho(k))
            st = 1 + 8 * j + k
            if c < dist[st] - 1e-12:
                dist[st] = c
                par[st] = 0
                par_s[st] = -1
                changed = True
    return changed


@njit(cache=True)
def _relax_arrivals(R, pen, ban_end, dist, par, par_s):  # pragma: no cover - numba
    """Arrivals at a junction: pass through it balanced, or stop there (unbalanced by a)."""
    changed = False
    for j in range(R.shape[0]):
        for k in range(4):
            a = _rho(k)
            st = 1 + 8 * j + 4 + k
            if dist[st] >= 1e300:
                continue
            nxt = 1 + 8 * j + _ridx(-a)
            if dist[st] < dist[nxt] - 1e-12:
                dist[nxt] = dist[st]
                par[nxt] = st
                par_s[nxt] = -1
                changed = True
            if ban_end[j]:
                continue
            c = dist[st] + _tau(R, pen, j, a)
            if c < dist[0] - 1e-12:
                dist[0] = c
                par[0] = st
                par_s[0] = -1
                changed = True
    return changed


@njit(cache=True)
def _stack_states(ent_row, ent_coef, ne, s, o, dd):  # pragma: no cover - numba
    """Source and target states of stack s moved by dd, entered by its end o (-1: none).

    With two junctions the walk enters at entry ``o`` and leaves at the other; with one,
    ``o = 0`` starts from that junction and ends at the ground, ``o = 1`` the reverse.
    """
    if ne == 2:
        j0, c0 = ent_row[s, o], ent_coef[s, o]
        j1, c1 = ent_row[s, 1 - o], ent_coef[s, 1 - o]
    elif o == 0:
        j0, c0 = ent_row[s, 0], ent_coef[s, 0]
        j1, c1 = -1, 0
    else:
        j0, c0 = -1, 0
        j1, c1 = ent_row[s, 0], ent_coef[s, 0]
    src = 0
    if j0 >= 0:
        rho = c0 * dd
        if rho < -2 or rho > 2:
            return -1, -1
        src = 1 + 8 * j0 + _ridx(rho)
    dst = 0
    if j1 >= 0:
        a = c1 * dd
        if a < -2 or a > 2:
            return -1, -1
        dst = 1 + 8 * j1 + 4 + _ridx(a)
    return src, dst


@njit(cache=True)
def _relax_stacks(n, e, w, ent_row, ent_coef, n_ent, ban_stack, dist, par, par_s,
                  par_d):  # pragma: no cover - numba
    """Edges of the stacks: +-1 on a stack, from its entry state to its exit state."""
    changed = False
    for s in range(n.shape[0]):
        ne = n_ent[s]
        if ne == 0 or ban_stack[s]:
            continue
        for dd in (-1, 1):
            cost = _dcost(n, e, w, s, dd)
            if cost >= 1e300:
                continue
            for o in range(2):
                src, dst = _stack_states(ent_row, ent_coef, ne, s, o, dd)
                if src < 0 or dist[src] >= 1e300:
                    continue
                c = dist[src] + cost
                if c < dist[dst] - 1e-12:
                    dist[dst] = c
                    par[dst] = src
                    par_s[dst] = s
                    par_d[dst] = dd
                    changed = True
    return changed


@njit(cache=True)
def _parent_cycle(par, mark):  # pragma: no cover - numba
    """A state on a cycle of the parent graph (its cycles are negative), or -1."""
    mark[:] = -1
    for v0 in range(par.shape[0]):
        if mark[v0] != -1:
            continue
        v = v0
        while v != -1 and mark[v] == -1:
            mark[v] = v0
            v = par[v]
        if v != -1 and mark[v] == v0:
            return v
    return -1


@njit(cache=True)
def _negative_cycle(n, e, w, ent_row, ent_coef, n_ent, R, pen, bans, work):  # pragma: no cover
    """Bellman-Ford rounds, checking the parent graph after each; a state on the cycle or -1."""
    ban_start, ban_end, ban_stack = bans
    dist, par, par_s, par_d, mark = work
    dist[:] = 0.0
    par[:] = -1
    for _ in range(dist.shape[0] + 1):
        changed = _relax_starts(R, pen, ban_start, dist, par, par_s)
        changed = _relax_arrivals(R, pen, ban_end, dist, par, par_s) or changed
        changed = _relax_stacks(n, e, w, ent_row, ent_coef, n_ent, ban_stack, dist, par,
                                par_s, par_d) or changed
        if not changed:
            return -1
        found = _parent_cycle(par, mark)
        if found >= 0:
            return found
    return -1


@njit(cache=True)
def _cycle_move(found, par, par_s, par_d, d, vis):  # pragma: no cover - numba
    """Stack changes ``d`` (and visit counts ``vis``) along the cycle through ``found``."""
    d[:] = 0
    vis[:] = 0
    v = found
    steps = 0
    while True:
        if par_s[v] >= 0:
            d[par_s[v]] += par_d[v]
            vis[par_s[v]] += 1
        v = par[v]
        steps += 1
        if v == found or steps > par.shape[0] + 1:
            break


@njit(cache=True)
def _move_delta(n, e, w, ent_row, ent_coef, n_ent, R, pen, d):  # pragma: no cover - numba
    """Exact objective change of the move ``d`` (a stack used twice counts +-2) and dR."""
    delta = 0.0
    for s in range(n.shape[0]):
        if d[s] != 0:
            delta += _dcost(n, e, w, s, d[s])
    dR = np.zeros(R.shape[0], np.int64)
    for s in range(n.shape[0]):
        if d[s] != 0:
            for q in range(n_ent[s]):
                dR[ent_row[s, q]] += ent_coef[s, q] * d[s]
    for j in range(R.shape[0]):
        if dR[j] != 0:
            delta += pen[j] * (abs(R[j] + dR[j]) - abs(R[j]))
    return delta, dR


@njit(cache=True)
def _ban_for_retry(found, par, par_s, vis, bans):  # pragma: no cover - numba
    """After a cycle that is not improving once evaluated exactly, forbid its cause.

    Either a walk that runs twice through a stack (around an unbalanced cycle), whose convex
    cost the graph then underestimates: that stack is forbidden; or a walk that starts and
    ends at the same violated junction, each end claiming the same unit of repair: starting
    (else ending) there is forbidden.  Returns False when nothing is left to forbid.
    """
    ban_start, ban_end, ban_stack = bans
    for s in range(vis.shape[0]):
        if vis[s] > 1:
            ban_stack[s] = True
            return True
    V = par.shape[0]
    first, last = -1, par[0]
    v = found
    for _ in range(V + 1):
        if par[v] == 0:
            first = v
            break
        v = par[v]
        if v == found:
            break
    if first > 0 and par_s[first] < 0 and not ban_start[(first - 1) // 8]:
        ban_start[(first - 1) // 8] = True
        return True
    if last > 0 and not ban_end[(last - 1) // 8]:
        ban_end[(last - 1) // 8] = True
        return True
    return False


@njit(cache=True)
def _improve(n, e, w, ent_row, ent_coef, n_ent, R, pen, max_moves):  # pragma: no cover
    """Apply improving moves (module docstring) to ``n`` and ``R = C n`` in place.

    Returns
    -------
    moves : int
        Number of moves applied; ``-1`` if the last cycle found was not improving once
        evaluated exactly and nothing was left to forbid (the search stops there).
    """
    m = n.shape[0]
    K = R.shape[0]
    V = 1 + 8 * K
    work = (np.zeros(V), np.full(V, -1, np.int64), np.full(V, -1, np.int64),
            np.zeros(V, np.int64), np.full(V, -1, np.int64))
    bans = (np.zeros(K, np.bool_), np.zeros(K, np.bool_), np.zeros(m, np.bool_))
    d = np.zeros(m, np.int64)
    vis = np.zeros(m, np.int64)
    moves = 0
    while moves < max_moves:
        found = _negative_cycle(n, e, w, ent_row, ent_coef, n_ent, R, pen, bans, work)
        if found < 0:
            return moves
        _, par, par_s, par_d, _ = work
        _cycle_move(found, par, par_s, par_d, d, vis)
        delta, dR = _move_delta(n, e, w, ent_row, ent_coef, n_ent, R, pen, d)
        if not (delta < -1e-9):
            if _ban_for_retry(found, par, par_s, vis, bans):
                continue
            return -1
        n += d
        R += dR
        for ban in bans:
            ban[:] = False
        moves += 1
    return moves


def _entries(C: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column (stack) its <= 2 non-zero rows and coefficients (signed-graph columns)."""
    Cc = C.tocsc()
    Cc.sum_duplicates()
    m = C.shape[1]
    # a stack has two ends, so at most two junction entries
    n_ent = np.minimum(np.diff(Cc.indptr), 2).astype(np.int64)
    ent_row = np.full((m, 2), -1, np.int64)
    ent_coef = np.zeros((m, 2), np.int64)
    for q in range(2):
        has = n_ent > q
        pos = Cc.indptr[:-1][has] + q
        ent_row[has, q] = Cc.indices[pos]
        ent_coef[has, q] = np.round(Cc.data[pos]).astype(np.int64)
    return ent_row, ent_coef, n_ent


def integer_refine(C: sp.csr_matrix, pen: np.ndarray, e: np.ndarray, w: np.ndarray,
                   n0: np.ndarray, *, max_moves: int = 100000) -> tuple[np.ndarray, int]:
    """Integer ``n >= 1`` minimising ``sum w (n - e)^2 + sum_j pen_j |(C n)_j|`` from ``n0``.

    Parameters
    ----------
    C : (K, m) sparse
        Conservation rows (one per junction; a column has at most two non-zeros).
    pen : (K,) float
        Penalty per branch of violation (large for hard junctions).
    e, w : (m,) float
        Width estimates and weights.
    n0 : (m,) int
        Start (the rounded continuous solution).
    max_moves : int

    Returns
    -------
    n : (m,) int64
    moves : int
        Moves applied; negative when the search stopped on a non-improving cycle (a walk
        using a stack twice; rare, see :func:`_ban_for_retry`).
    """
    n = np.maximum(np.asarray(n0, np.int64), 1).copy()
    ent_row, ent_coef, n_ent = _entries(C)
    R = np.asarray(np.round(C @ n.astype(float)), np.int64).reshape(-1)
    moves = _improve(n, np.asarray(e, float), np.asarray(w, float), ent_row, ent_coef, n_ent,
                     R, np.asarray(pen, float), int(max_moves))
    return n, int(moves)


def objective(n: np.ndarray, e: np.ndarray, w: np.ndarray, C: sp.csr_matrix,
              pen: np.ndarray) -> float:
    """``sum w (n - e)^2 + sum_j pen_j |(C n)_j|``, the cost both integer solvers minimise.

    Parameters
    ----------
    n, e, w : (m,) arrays
    C : (K, m) sparse
    pen : (K,) array

    Returns
    -------
    float
    """
    return float(np.sum(w * (n - e) ** 2) + pen @ np.abs(C @ n.astype(float)))
