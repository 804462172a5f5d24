"""Exact integer least squares by mixed-integer linear programming (HiGHS).

The reference solver of the integer problem, and the fallback of the search
(:mod:`crosssection.linsys.search`) on small components whose hard junction equations the
search leaves violated.  Exact but slow: 3-13 s on the 244-stack benchmark scan, against
~10 ms for the search.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["milp_solve"]


def milp_solve(C: sp.csr_matrix, penalties: np.ndarray, e: np.ndarray, w: np.ndarray,
               x: np.ndarray, sigma: np.ndarray, *, window: int, time_limit_s: float):
    """Integer ``n >= 1`` minimising ``sum w (n - e)^2 + sum_j pen_j |(C n)_j|`` exactly.

    ``n_i = lo_i + sum_k y_ik + up_i - down_i`` with binary unit increments ``y_ik`` whose
    costs ``w_i[(lo+k-e)^2 - (lo+k-1-e)^2]`` increase with ``k`` (the convex quadratic is
    exact at integers), ``lo_i, hi_i`` bracketing ``e_i`` and ``x_i`` by ``window + 2 sigma``
    layers, ``up_i, down_i`` linear beyond; junction rows get slacks with penalty
    ``penalties``.

    Parameters
    ----------
    C : (K, m) sparse
        Conservation rows.
    penalties : (K,) array
        Cost per branch of violation of each row.
    e, w : (m,) arrays
        Width estimates and weights.
    x : (m,) array
        Continuous least-squares solution (widens the exact range).
    sigma : (m,) array
        Width errors (layers).
    window : int
        Exact quadratic cost within ``window + 2 sigma`` layers, linear beyond.
    time_limit_s : float
        HiGHS time limit; on expiry the best integer solution found is returned.

    Returns
    -------
    n : (m,) int64 array or None
        None when HiGHS found no integer solution.
    status : int
        ``scipy.optimize.milp`` status (0 = optimal).
    """
    # imported here: scipy.optimize takes about 0.3 s to import and most scans never get here
    from scipy.optimize import Bounds, LinearConstraint

    from crosssection.core.quiet import milp

    m = len(e)
    k = C.shape[0]
    reach = window + np.ceil(2.0 * sigma).astype(int)
    lo = np.maximum(1, np.floor(np.minimum(e, x)).astype(int) - reach)
    hi = np.maximum(np.ceil(np.maximum(e, x)).astype(int) + reach, lo + 1)
    W = hi - lo
    owner = np.repeat(np.arange(m), W)
    step = np.arange(W.sum()) - np.repeat(np.cumsum(W) - W, W) + 1       # k = 1..W_i
    level = lo[owner] + step                                            # value after step

    def f(i, n):
        return w[i] * (n - e[i]) ** 2

    c_y = f(owner, level) - f(owner, level - 1)
    c_up = f(np.arange(m), hi + 1) - f(np.arange(m), hi)
    c_down = f(np.arange(m), lo - 1) - f(np.arange(m), lo)
    c = np.concatenate([c_y, c_up, c_down, penalties, penalties])
    Ccsc = C.tocsc()
    A = sp.hstack([Ccsc[:, owner], Ccsc, -Ccsc, sp.identity(k), -sp.identity(k)], format="csr")
    rhs = -(C @ lo.astype(float))
    n_y = len(owner)
    lb = np.zeros(len(c))
    ub = np.concatenate([np.ones(n_y), np.full(m, np.inf), (lo - 1).astype(float),
                         np.full(2 * k, np.inf)])
    integrality = np.concatenate([np.ones(n_y + 2 * m), np.zeros(2 * k)])
    res = milp(c, integrality=integrality, bounds=Bounds(lb, ub),
               constraints=LinearConstraint(A, rhs, rhs),
               options={"time_limit": float(time_limit_s), "disp": False})
    if res.x is None:
        return None, res.status
    z = np.round(res.x).astype(np.int64)
    n = lo + np.bincount(owner, weights=z[:n_y], minlength=m).astype(np.int64) \
        + z[n_y:n_y + m] - z[n_y + m:n_y + 2 * m]
    return np.maximum(n, 1), res.status
