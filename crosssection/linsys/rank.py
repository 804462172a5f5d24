"""Rank and conditioning of the paper's M x M system ``[C; I_S]``.

Every stack touches at most two junctions, so the conservation matrix ``C`` is the incidence
matrix of a signed graph (rows = junctions, columns = stacks).  Its rank follows from the
graph: :func:`incidence_rank`.  The stacks that conservation cannot determine, and must take
their value from the width (the paper's "M/3 stacks with the best estimation of the
thickness"), follow from a matroid greedy: :func:`width_fixed_stacks`.  The condition number
and least-squares residual of the assembled system are reported by :func:`system_diagnostics`.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.linalg import splu

from crosssection.core.unionfind import find_root, union_roots

__all__ = ["incidence_rank", "width_fixed_stacks", "system_diagnostics"]


def _columns(rows: list, keep) -> dict:
    """stack -> list of (row, coefficient) over the non-zero entries of the kept columns."""
    col_rows: dict[int, list] = {}
    for j, r in enumerate(rows):
        for s, c in r.items():
            if s in keep and c != 0:
                col_rows.setdefault(s, []).append((j, c))
    return col_rows


def incidence_rank(rows: list, columns) -> int:
    """Exact rank of a conservation matrix whose columns have at most two non-zeros.

    A left null vector ``y`` obeys ``y_u c_us + y_v c_vs = 0`` along each two-junction
    stack, and ``y_u = 0`` at a junction with a one-junction column (a free end, or a loop on
    the same pack).  Hence ``rank = #rows - #(components that are balanced and have no
    one-junction column)``, found by parity propagation in O(M).  Rows at the same node are
    not expected (one per junction).

    Parameters
    ----------
    rows : list of dict stack_id -> coefficient
    columns : iterable of stack ids
        Only these columns are kept.

    Returns
    -------
    int
    """
    col_rows = _columns(rows, set(int(c) for c in columns))
    adj: list[list] = [[] for _ in rows]
    absorbing = [False] * len(rows)
    for lst in col_rows.values():
        if len(lst) == 1:
            absorbing[lst[0][0]] = True
        elif len(lst) == 2:
            (j1, c1), (j2, c2) = lst
            # y_j2 = -(c1/c2) y_j1 ; track magnitude ratio and sign
            adj[j1].append((j2, -c1 / c2))
            adj[j2].append((j1, -c2 / c1))
        else:  # more than two junctions: not a stack column; be conservative
            for j, _ in lst:
                absorbing[j] = True
    value = [None] * len(rows)
    null_dim = 0
    for start in range(len(rows)):
        if value[start] is not None:
            continue
        value[start] = 1.0
        stack = [start]
        ok = not absorbing[start]
        while stack:
            j = stack.pop()
            for k, ratio in adj[j]:
                want = value[j] * ratio
                if value[k] is None:
                    value[k] = want
                    ok = ok and not absorbing[k]
                    stack.append(k)
                elif abs(value[k] - want) > 1e-9 * max(1.0, abs(want)):
                    ok = False
        null_dim += ok
    return len(rows) - null_dim


def _greedy_general(rows: list, order: list) -> tuple[list, int]:
    """Matroid greedy by repeated exact rank, for columns that are not signed-graph edges."""
    fixed, kept = [], []
    for s in order:
        if incidence_rank(rows, kept + [s]) == len(kept) + 1:
            kept.append(s)
        else:
            fixed.append(s)
    return fixed, len(kept)


def _signed_greedy(order, col_rows, flips, n_rows):
    """Kept flags of the stacks taken in ``order`` (see :func:`width_fixed_stacks`).

    ``col_rows[s]`` are the (<= 2) rows of column ``s`` (-1: none), ``flips[s]`` is 1 when its
    two coefficients have the same sign (``y`` changes sign along the stack).  A plain
    Python loop on lists: a few milliseconds for a thousand stacks, nothing to compile.
    """
    parts = list(range(n_rows))
    cover = list(range(2 * n_rows))
    full = [False] * n_rows  # per root: already an unbalanced cycle / half-edge
    kept = [False] * len(order)
    rows = col_rows.tolist()
    flips = flips.tolist()
    for i, s in enumerate(order.tolist()):
        j1, j2 = rows[s]
        if j1 < 0:
            continue
        r1 = find_root(parts, j1)
        if j2 < 0:
            if not full[r1]:
                full[r1] = kept[i] = True
            continue
        f = flips[s]
        r2 = find_root(parts, j2)
        if r1 != r2:
            if not (full[r1] and full[r2]):
                merged = full[r1] or full[r2]
                full[union_roots(parts, r1, r2)] = merged
                union_roots(cover, 2 * j1, 2 * j2 + f)
                union_roots(cover, 2 * j1 + 1, 2 * j2 + 1 - f)
                kept[i] = True
        elif not full[r1] and find_root(cover, 2 * j1) == find_root(cover, 2 * j2 + 1 - f):
            full[r1] = kept[i] = True  # unbalanced cycle closes: still independent
    return np.array(kept, np.bool_)


def width_fixed_stacks(rows: list, stacks, score) -> tuple[list, int]:
    """Stacks that conservation cannot determine, choosing the least reliable to determine.

    Matroid greedy on the columns of the conservation matrix (a signed-graph incidence
    matrix): stacks are taken in order of *increasing* reliability and kept as "determined by
    conservation" while the kept columns stay linearly independent, i.e. while each connected
    part of the kept stacks is a tree, or a tree plus one unbalanced cycle or one
    one-junction column.  Connectivity is a union-find on the junctions; balance a
    union-find on the signed double cover (``2j`` stands for ``+y_j``, ``2j + 1`` for
    ``-y_j``), where a cycle is unbalanced exactly when it joins ``+y_j`` to ``-y_j``.  The
    stacks left over must come from widths: the set of most reliable stacks of minimal size
    that makes ``[C; I_S]`` non-singular.  The greedy runs on the toolkit's union-find
    functions over Python lists: with ``scipy.cluster.hierarchy.DisjointSet`` it took
    15-18 ms on a 951-stack network, as a compiled kernel 2 ms plus a second of compilation
    on a first run.

    Parameters
    ----------
    rows : list of dict stack_id -> coefficient
    stacks : list of int
    score : (M,) array
        Reliability (higher = better).

    Returns
    -------
    fixed : list of int
        Stacks to fix by width.
    rank_c : int
        Rank of the conservation matrix restricted to ``stacks``.
    """
    stacks = list(stacks)
    col_rows = {s: [] for s in stacks}
    col_rows.update(_columns(rows, col_rows))
    order = sorted(stacks, key=lambda s: score[s])
    if any(len(v) > 2 or (len(v) == 2 and abs(v[0][1]) != abs(v[1][1]))
           for v in col_rows.values()):
        return _greedy_general(rows, order)
    local = {s: i for i, s in enumerate(stacks)}
    ends = np.full((len(stacks), 2), -1, np.int64)
    flips = np.zeros(len(stacks), np.int64)
    for s, lst in col_rows.items():
        for q, (j, _) in enumerate(lst):
            ends[local[s], q] = j
        flips[local[s]] = len(lst) == 2 and lst[0][1] * lst[1][1] > 0
    kept = _signed_greedy(np.array([local[s] for s in order], np.int64), ends, flips,
                          len(rows))
    return [s for s, k in zip(order, kept) if not k], int(kept.sum())


def _dense_diagnostics(A: sp.csr_matrix, b: np.ndarray, residual: bool):
    m = A.shape[1]
    Ad = A.toarray()
    s = np.linalg.svd(Ad, compute_uv=False)
    cond = float("inf") if (len(s) < m or s[-1] <= s[0] * 1e-12) else float(s[0] / s[-1])
    res = 0.0
    if residual:
        x = np.linalg.lstsq(Ad, b, rcond=None)[0]
        res = float(np.linalg.norm(Ad @ x - b))
    return cond, res


def _rayleigh_limit(apply, v, tol: float, max_iter: int) -> float:
    """Largest eigenvalue of the SPD operator ``apply`` by power iteration from ``v``.

    Returns ``nan`` if an iterate vanishes or overflows.
    """
    value = 0.0
    for _ in range(max_iter):
        g = apply(v)
        new = float(v @ g)
        # np.linalg.norm's own arithmetic, without its checks (up to 500 calls)
        nrm = math.sqrt(g.dot(g))
        if not math.isfinite(nrm) or nrm == 0:
            return float("nan")
        v = g / nrm
        if abs(new - value) <= tol * new:
            return new
        value = new
    return value


@njit(cache=True)
def _power_limit_csc(indptr, indices, data, v, tol, max_iter):  # pragma: no cover - numba
    """:func:`_rayleigh_limit` of the operator ``G @ u`` of a square CSC matrix (``indptr``,
    ``indices``, ``data``), bit for bit: the product accumulated as scipy's ``csc_matvec``
    accumulates it, the dot products by BLAS as numpy's.

    The power iteration takes some 250 products on a dense scan's largest component;
    through scipy's ``G @ u``, whose call costs several times the product on 250 stacks,
    they took about 3 ms of the analysis, here 0.9 ms.
    """
    n = v.size
    v = v.copy()
    g = np.empty(n)
    value = 0.0
    for _ in range(max_iter):
        for i in range(n):
            g[i] = 0.0
        for j in range(n):
            xj = v[j]
            for ii in range(indptr[j], indptr[j + 1]):
                g[indices[ii]] += data[ii] * xj
        new = np.dot(v, g)
        nrm = math.sqrt(np.dot(g, g))
        if not math.isfinite(nrm) or nrm == 0:
            return np.nan
        for i in range(n):
            v[i] = g[i] / nrm
        if abs(new - value) <= tol * new:
            return new
        value = new
    return value


def system_diagnostics(A: sp.csr_matrix, b: np.ndarray, dense_max: int, *,
                       residual: bool = True, tol: float = 1e-10,
                       max_iter: int = 500) -> tuple[float, float]:
    """2-norm condition number and least-squares residual of ``A x = b``.

    Dense SVD up to ``dense_max`` columns.  Beyond, from one sparse LU of ``G = A^T A``:
    the residual from the normal equations, ``lambda_max(G)`` by power iteration and
    ``lambda_min(G)`` by inverse iteration (Rayleigh quotients, relative change < ``tol``);
    ``cond = sqrt(lambda_max / lambda_min)``.  Written by hand because ARPACK (``eigsh``)
    and LSQR take ~45 ms on a 244-stack component, this ~2 ms.

    Parameters
    ----------
    A : (R, m) sparse
    b : (R,) array
    dense_max : int
    residual : bool
        Compute ``min_x ||A x - b||`` (else 0).
    tol, max_iter : float, int
        Stopping rule of the eigenvalue iterations.

    Returns
    -------
    condition_number, residual : float
        ``inf`` condition number for a singular system.
    """
    m = A.shape[1]
    if m == 0 or A.shape[0] == 0:
        return (1.0 if m == 0 else float("inf")), 0.0
    if m <= dense_max:
        return _dense_diagnostics(A, b, residual)
    G = (A.T @ A).tocsc()
    try:
        lu = splu(G)
    except RuntimeError:  # singular
        return float("inf"), float("nan")
    res = 0.0
    if residual:
        x = lu.solve(A.T @ b)
        res = float(np.linalg.norm(A @ x - b))
    rng = np.random.default_rng(0)
    v = rng.standard_normal(m)
    lmax = _power_limit_csc(G.indptr, G.indices, G.data, v / np.linalg.norm(v), float(tol),
                            int(max_iter))
    v = rng.standard_normal(m)
    inv = _rayleigh_limit(lu.solve, v / np.linalg.norm(v), tol, max_iter)
    if not inv > 0 or not np.isfinite(inv):
        return float("inf"), res
    return float(math.sqrt(lmax * inv)), res
