"""Rank of the conservation matrix, stacks fixed by width, conditioning of [C; I_S]."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from crosssection.linsys import (conservation_equations, incidence_rank, solve_branch_counts,
                                 width_fixed_stacks)
from crosssection.linsys.rank import system_diagnostics
from crosssection.truth.graphs import random_network


def test_incidence_rank_matches_numpy(dense_rows):
    for seed in range(8):
        fg = random_network(200 + seed, n_junctions=15, n_free=2 * (seed % 3))
        hard, soft, dropped, _ = conservation_equations(fg, fg.packs)
        rows = [r for _, r in hard + soft]
        M = len(fg.paths)
        rng = np.random.default_rng(seed)
        cols = sorted(rng.choice(M, size=max(1, M // 2), replace=False).tolist())
        A = dense_rows(rows, M)
        for c in (range(M), cols):
            assert incidence_rank(rows, c) == np.linalg.matrix_rank(A[:, list(c)])


def test_width_fixed_stacks_minimal_and_nonsingular(dense_rows):
    for seed in range(8):
        fg = random_network(300 + seed, n_junctions=20, n_free=2 * (seed % 3), tree=seed == 7)
        hard, soft, _, _ = conservation_equations(fg, fg.packs)
        rows = [r for _, r in hard + soft]
        M = len(fg.paths)
        score = np.random.default_rng(seed).random(M)
        fixed, rank_c = width_fixed_stacks(rows, range(M), score)
        A = dense_rows(rows, M)
        assert rank_c == np.linalg.matrix_rank(A)
        assert len(fixed) == M - rank_c
        E = np.zeros((len(fixed), M))
        E[np.arange(len(fixed)), fixed] = 1
        assert np.linalg.matrix_rank(np.vstack([A, E])) == M
        # matroid greedy: every fixed stack is spanned by the determined (kept) stacks that
        # are less reliable than it, so no more reliable choice of S exists
        kept = sorted(set(range(M)) - set(fixed))
        for f in fixed:
            low = [k for k in kept if score[k] < score[f]]
            assert np.linalg.matrix_rank(A[:, low + [f]]) == np.linalg.matrix_rank(A[:, low])


@pytest.mark.parametrize("seed", range(6))
def test_width_fixed_stacks_equals_dense_greedy(seed, dense_rows):
    """The union-find greedy (signed double cover) picks exactly the stacks a dense greedy
    by ``np.linalg.matrix_rank`` picks, on networks with degree-4 junctions, self-loops and
    non-orientable packs (unbalanced cycles)."""
    fg = random_network(500 + seed, n_junctions=[6, 12, 25][seed % 3], p_deg4=0.3,
                        n_free=seed % 3)
    hard, soft, _, _ = conservation_equations(fg, fg.packs)
    rows = [r for _, r in hard + soft]
    M = len(fg.paths)
    score = np.random.default_rng(seed).permutation(M).astype(float)
    A = dense_rows(rows, M)
    kept, expect = [], []
    for s in np.argsort(score):
        if np.linalg.matrix_rank(A[:, kept + [s]]) == len(kept) + 1:
            kept.append(int(s))
        else:
            expect.append(int(s))
    fixed, rank_c = width_fixed_stacks(rows, range(M), score)
    assert fixed == expect
    assert rank_c == len(kept)


def test_unbalanced_cycle_needs_no_width():
    """Two junctions joined by stacks a, b with packs a|b at one and (a, b)|c at the other:
    the cycle a-b is unbalanced (y_0 = y_1 and y_0 = -y_1), so the three columns have rank 2
    and a single stack is fixed by width."""
    rows = [{0: 1, 1: -1}, {0: 1, 1: 1, 2: -1}]
    fixed, rank_c = width_fixed_stacks(rows, [0, 1, 2], np.array([0.0, 1.0, 2.0]))
    assert rank_c == 2 == incidence_rank(rows, [0, 1, 2])
    assert fixed == [2]


def test_condition_number_sparse_estimate_matches_numpy(dense_rows):
    fg = random_network(11, n_junctions=60)
    M = len(fg.paths)
    est = fg.n_true + np.random.default_rng(0).normal(0, 0.3, M)
    sparse = solve_branch_counts(fg, fg.packs, est, dense_max=0)
    dense = solve_branch_counts(fg, fg.packs, est, dense_max=10**6)
    hard, soft, _, _ = conservation_equations(fg, fg.packs, est, np.full(M, 0.3))
    A = dense_rows([r for _, r in hard + soft], M)
    A /= np.linalg.norm(A, axis=1, keepdims=True)
    sel = np.flatnonzero(dense.fixed_by_width)
    E = np.zeros((len(sel), M))
    E[np.arange(len(sel)), sel] = 1
    ref = np.linalg.cond(np.vstack([A, E]))
    assert sparse.n_components == 1
    assert dense.condition_number == pytest.approx(ref, rel=1e-6)
    assert sparse.condition_number == pytest.approx(ref, rel=1e-4)
    assert sparse.residual == pytest.approx(dense.residual, abs=1e-8)
    np.testing.assert_array_equal(sparse.n_br, dense.n_br)


@pytest.mark.parametrize("dense_max", [0, 10])
def test_singular_and_inconsistent_systems(dense_max):
    import scipy.sparse as sp

    A = sp.csr_matrix(np.array([[1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 0.0, 1.0]]))
    cond, _ = system_diagnostics(A, np.zeros(3), dense_max)
    assert cond == np.inf
    A = sp.csr_matrix(np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]))
    cond, res = system_diagnostics(A, np.array([1.0, 1.0, 0.0]), dense_max)
    assert cond == pytest.approx(np.linalg.cond(A.toarray()), rel=1e-6)
    assert res == pytest.approx(2 / np.sqrt(3), rel=1e-6)  # distance of b to range(A)


def test_compiled_power_iteration_is_the_operators_own():
    """The power iteration on a CSC matrix's arrays returns, bit for bit, what the same
    iteration on scipy's ``G @ u`` returns: sparse normal matrices of conservation-like
    systems (entries -1, 0, 1, 2), square and rectangular, down to two unknowns."""
    from crosssection.linsys.rank import _power_limit_csc, _rayleigh_limit

    rng = np.random.default_rng(4)
    for _ in range(150):
        rows, m = int(rng.integers(2, 600)), int(rng.integers(2, 300))
        A = sp.random(rows, m, density=min(1.0, 3.0 / m + 0.01), format="csr",
                      random_state=int(rng.integers(2**31)))
        A.data = np.round(3.0 * A.data) - 1.0
        G = (A.T @ A).tocsc()
        v = rng.standard_normal(m)
        v /= np.linalg.norm(v)
        want = _rayleigh_limit(lambda u: G @ u, v, 1e-10, 500)
        got = _power_limit_csc(G.indptr, G.indices, G.data, v, 1e-10, 500)
        assert got == want or (np.isnan(got) and np.isnan(want))
