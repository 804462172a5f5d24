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
def _improve(n, e, w, ent_row, ent_coef, n_ent, R, pen, max_moves, dist, par, par_s, par_d,
             mark, ban_start, ban_end, ban_stack, d, vis, dR):  # pragma: no cover - numba
    """Apply improving moves (module docstring) to ``n`` and ``R = C n`` in place.

    One function with the caller's work arrays (states ``V = 1 + 8 K``: ``dist``, ``par``,
    ``par_s``, ``par_d``, ``mark``; bans per junction and stack; ``d``, ``vis`` per stack,
    ``dR`` per junction): only loops and scalar arithmetic, which numba compiles several
    times faster than the same logic split into small functions that allocate.

    Each round: Bellman-Ford over the states, checking the parent graph for a cycle after
    each pass; the cycle's move ``d`` is evaluated exactly and applied if it lowers the
    objective. A cycle that does not, once evaluated exactly, has a cause forbidden before
    searching again: either a walk that runs twice through a stack (around an unbalanced
    cycle), whose convex cost the graph then underestimates: that stack is forbidden; or a
    walk that starts and ends at the same violated junction, each end claiming the same
    unit of repair: starting (else ending) there is forbidden.

    Returns
    -------
    moves : int
        Number of moves applied; ``-1`` if the last cycle found was not improving once
        evaluated exactly and nothing was left to forbid (the search stops there).
    """
    m = n.shape[0]
    K = R.shape[0]
    V = dist.shape[0]
    moves = 0
    while moves < max_moves:
        # Bellman-Ford rounds from all states at 0 (slot k of a junction: residual change
        # rho = (-2, -1, 1, 2)[k]; states 1 + 8 j + k "leave j changing R_j by rho",
        # 1 + 8 j + 4 + k "arrived at j having changed R_j by rho")
        for v in range(V):
            dist[v] = 0.0
            par[v] = -1
        found = -1
        for _ in range(V + 1):
            changed = False
            # ground -> start at junction j, paying the residual change there
            for j in range(K):
                if ban_start[j]:
                    continue
                for k in range(4):
                    rho = k - 2 if k < 2 else k - 1
                    c = dist[0] + pen[j] * (abs(R[j] + rho) - abs(R[j]))
                    st = 1 + 8 * j + k
                    if c < dist[st] - 1e-12:
                        dist[st] = c
                        par[st] = 0
                        par_s[st] = -1
                        changed = True
            # arrivals at a junction: pass through it balanced, or stop there (unbalanced)
            for j in range(K):
                for k in range(4):
                    a = k - 2 if k < 2 else k - 1
                    st = 1 + 8 * j + 4 + k
                    if dist[st] >= 1e300:
                        continue
                    nxt = 1 + 8 * j + (-a + 2 if -a < 0 else -a + 1)
                    if dist[st] < dist[nxt] - 1e-12:
                        dist[nxt] = dist[st]
                        par[nxt] = st
                        par_s[nxt] = -1
                        changed = True
                    if ban_end[j]:
                        continue
                    c = dist[st] + pen[j] * (abs(R[j] + a) - abs(R[j]))
                    if c < dist[0] - 1e-12:
                        dist[0] = c
                        par[0] = st
                        par_s[0] = -1
                        changed = True
            # the stacks: +-1 on a stack, from its entry state to its exit state; with two
            # junctions the walk enters at end o and leaves at the other, with one, o = 0
            # starts from that junction and ends at the ground, o = 1 the reverse
            for s in range(m):
                ne = n_ent[s]
                if ne == 0 or ban_stack[s]:
                    continue
                for t in range(2):
                    dd = -1 if t == 0 else 1
                    v1 = n[s] + dd
                    if v1 < 1:
                        continue  # below one layer: infinite cost
                    cost = w[s] * ((v1 - e[s]) ** 2 - (n[s] - e[s]) ** 2)
                    for o in range(2):
                        if ne == 2:
                            j0 = ent_row[s, o]
                            c0 = ent_coef[s, o]
                            j1 = ent_row[s, 1 - o]
                            c1 = ent_coef[s, 1 - o]
                        elif o == 0:
                            j0 = ent_row[s, 0]
                            c0 = ent_coef[s, 0]
                            j1 = -1
                            c1 = 0
                        else:
                            j0 = -1
                            c0 = 0
                            j1 = ent_row[s, 0]
                            c1 = ent_coef[s, 0]
                        src = 0
                        if j0 >= 0:
                            rho = c0 * dd
                            if rho < -2 or rho > 2:
                                continue
                            src = 1 + 8 * j0 + (rho + 2 if rho < 0 else rho + 1)
                        dst = 0
                        if j1 >= 0:
                            a = c1 * dd
                            if a < -2 or a > 2:
                                continue
                            dst = 1 + 8 * j1 + 4 + (a + 2 if a < 0 else a + 1)
                        if dist[src] >= 1e300:
                            continue
                        c = dist[src] + cost
                        if c < dist[dst] - 1e-12:
                            dist[dst] = c
                            par[dst] = src
                            par_s[dst] = s
                            par_d[dst] = dd
                            changed = True
            if not changed:
                break
            # a state on a cycle of the parent graph (its cycles are negative)
            for v in range(V):
                mark[v] = -1
            for v0 in range(V):
                if mark[v0] != -1:
                    continue
                v = v0
                while v != -1 and mark[v] == -1:
                    mark[v] = v0
                    v = par[v]
                if v != -1 and mark[v] == v0:
                    found = v
                    break
            if found >= 0:
                break
        if found < 0:
            return moves
        # stack changes d (and visit counts) along the cycle through `found`
        for s in range(m):
            d[s] = 0
            vis[s] = 0
        v = found
        steps = 0
        while True:
            if par_s[v] >= 0:
                d[par_s[v]] += par_d[v]
                vis[par_s[v]] += 1
            v = par[v]
            steps += 1
            if v == found or steps > V + 1:
                break
        # exact objective change of the move (a stack used twice counts +-2) and dR
        delta = 0.0
        for s in range(m):
            if d[s] != 0:
                v1 = n[s] + d[s]
                if v1 < 1:
                    delta += np.inf
                else:
                    delta += w[s] * ((v1 - e[s]) ** 2 - (n[s] - e[s]) ** 2)
        for j in range(K):
            dR[j] = 0
        for s in range(m):
            if d[s] != 0:
                for q in range(n_ent[s]):
                    dR[ent_row[s, q]] += ent_coef[s, q] * d[s]
        for j in range(K):
            if dR[j] != 0:
                delta += pen[j] * (abs(R[j] + dR[j]) - abs(R[j]))
        if not (delta < -1e-9):
            # not improving once evaluated exactly: forbid its cause and search again
            banned = False
            for s in range(m):
                if vis[s] > 1:
                    ban_stack[s] = True
                    banned = True
                    break
            if not banned:
                first = -1
                last = par[0]
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
                    banned = True
                elif last > 0 and not ban_end[(last - 1) // 8]:
                    ban_end[(last - 1) // 8] = True
                    banned = True
            if banned:
                continue
            return -1
        for s in range(m):
            n[s] += d[s]
        for j in range(K):
            R[j] += dR[j]
            ban_start[j] = False
            ban_end[j] = False
        for s in range(m):
            ban_stack[s] = False
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
    m, K = len(n), len(R)
    V = 1 + 8 * K
    moves = _improve(n, np.asarray(e, float), np.asarray(w, float), ent_row, ent_coef, n_ent,
                     R, np.asarray(pen, float), int(max_moves), np.zeros(V),
                     np.full(V, -1, np.int64), np.full(V, -1, np.int64), np.zeros(V, np.int64),
                     np.full(V, -1, np.int64), np.zeros(K, np.bool_), np.zeros(K, np.bool_),
                     np.zeros(m, np.bool_), np.zeros(m, np.int64), np.zeros(m, np.int64),
                     np.zeros(K, np.int64))
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
