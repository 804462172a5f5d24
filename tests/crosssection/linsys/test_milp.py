"""Exact MILP of the integer least squares."""
from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp

from crosssection.linsys.milp import milp_solve
from crosssection.linsys.search import objective


def test_milp_is_the_brute_force_optimum():
    """Theta graph a = b + c, b = a + c (inconsistent unless violated): the MILP minimum of
    widths + penalties equals the minimum over every n in 1..8 (window covers it)."""
    C = sp.csr_matrix(np.array([[1.0, -1.0, -1.0], [-1.0, 1.0, -1.0]]))
    pen = np.array([3.0, 5.0])
    rng = np.random.default_rng(0)
    for _ in range(5):
        e = rng.uniform(1, 5, 3)
        w = rng.uniform(0.5, 2, 3)
        n, status = milp_solve(C, pen, e, w, e, np.full(3, 0.3), window=3, time_limit_s=10)
        assert status == 0 and np.all(n >= 1)
        best = min(objective(np.array(v), e, w, C, pen)
                   for v in itertools.product(range(1, 9), repeat=3))
        assert objective(n, e, w, C, pen) == best
