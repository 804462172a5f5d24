"""The vectorised integer search against the original loops, kept here as a reference.

``_improve_reference`` is the loop implementation that :mod:`crosssection.linsys.search` used
before (compiled by numba), unchanged but for a counter of forbidden cycles.  The numpy
version relaxes whole groups of edges at once yet reproduces its in-place order, so both
must give the same ``n`` and the same number of moves on every input: random stack networks
(degree-4 junctions, trees, free ends), widths on a coarse grid (many ties and near-ties
between path costs), and random conservation matrices with coefficients 0, +-1, +-2, 3 and
one-entry columns.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from crosssection.linsys import conservation_equations
from crosssection.linsys.equations import sparse_rows
from crosssection.linsys.search import (_first_min, _improve, _running_min, _start,
                                        integer_refine, objective)
from crosssection.truth.graphs import random_network


def _improve_reference(n, e, w, ent_row, ent_coef, n_ent, R, pen, max_moves, dist, par,
                       par_s, par_d, mark, ban_start, ban_end, ban_stack, d, vis, dR,
                       stats):
    """Apply improving moves to ``n`` and ``R = C n`` in place (the original loops).

    ``stats["bans"]`` counts the non-improving cycles whose cause was forbidden (the only
    line added to the original).

    One function with the caller's work arrays (states ``V = 1 + 8 K``: ``dist``, ``par``,
    ``par_s``, ``par_d``, ``mark``; bans per junction and stack; ``d``, ``vis`` per stack,
    ``dR`` per junction): only loops and scalar arithmetic, as it was compiled by numba.

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
                stats["bans"] += 1
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


def integer_refine_reference(C, pen, e, w, n0, *, max_moves=100000):
    """:func:`~crosssection.linsys.search.integer_refine` on the original loops; also
    returns the number of forbidden cycles."""
    n, ent_row, ent_coef, n_ent, R = _start(C, e, w, n0)
    m, K = len(n), len(R)
    V = 1 + 8 * K
    stats = {"bans": 0}
    moves = _improve_reference(
        n, np.asarray(e, float), np.asarray(w, float), ent_row, ent_coef, n_ent, R,
        np.asarray(pen, float), int(max_moves), np.zeros(V), np.full(V, -1, np.int64),
        np.full(V, -1, np.int64), np.zeros(V, np.int64), np.full(V, -1, np.int64),
        np.zeros(K, np.bool_), np.zeros(K, np.bool_), np.zeros(m, np.bool_),
        np.zeros(m, np.int64), np.zeros(m, np.int64), np.zeros(K, np.int64), stats)
    return n, int(moves), stats["bans"]


def _network_problems(seed):
    """Integer problems of one random network: hard or robust penalties, starts from the
    rounded widths (repairs) and from a perturbed rounding; half of the networks get widths
    on a 0.1 grid and unit weights, whose path costs tie often."""
    rng = np.random.default_rng(seed)
    fg = random_network(seed, n_junctions=int(rng.choice([3, 6, 12, 20])),
                        p_deg4=float(rng.choice([0.0, 0.2, 0.5])), tree=bool(seed % 7 == 3),
                        n_free=int(rng.integers(0, 6)))
    M = len(fg.paths)
    est = fg.n_true + rng.normal(0, float(rng.choice([0.25, 0.5])), M) * np.sqrt(fg.n_true)
    sig = 0.3 + 0.05 * np.maximum(est - 1, 0)
    w = 1 / sig ** 2
    if seed % 2:
        est = np.round(np.maximum(est, 0.2), 1)
        w = np.ones(M)
    hard, soft, _, _ = conservation_equations(fg, fg.packs, est, sig)
    rows = hard + soft
    if not rows:
        return []
    C = sparse_rows(rows, {s: s for s in range(M)}, M)
    pen = np.r_[np.full(len(hard), float(rng.choice([1.5 / 0.09, 1e4 * w.max()]))),
                np.full(len(soft), 4.0 * float(np.median(w)))]
    n0 = np.maximum(np.round(est), 1)
    return [(C, pen, est, w, n0),
            (C, pen, est, w, np.maximum(n0 + rng.integers(-1, 2, M), 1))]


def _matrix_problem(seed):
    """A random conservation matrix: columns with 0, 1 or 2 entries, coefficients in
    {0, +-1, +-2, 3} (0: the two ends of a stack cancelled at one junction, 3: no move)."""
    rng = np.random.default_rng(10_000 + seed)
    K, m = int(rng.integers(2, 12)), int(rng.integers(3, 30))
    rows, cols, vals = [], [], []
    for s in range(m):
        k = rng.choice([0, 1, 2, 2, 2, 2], 1)[0]
        for j in rng.choice(K, size=min(k, K), replace=False):
            rows.append(j)
            cols.append(s)
            vals.append(rng.choice([-1, 1, -1, 1, -2, 2, 0, 3]))
    C = sp.csr_matrix((np.array(vals, float), (rows, cols)), shape=(K, m))
    e = rng.uniform(0.3, 6, m)
    if seed % 2:
        e = np.round(e, 1)
    w = rng.choice([1.0, 0.5, 4.0], m)
    pen = rng.choice([0.5, 3.0, 50.0], K)
    return C, pen, e, w, np.maximum(np.round(e) + rng.integers(-1, 2, m), 1)


def _compare(problems):
    """Both implementations on ``problems``: counts of moves and forbidden cycles seen."""
    total_moves = total_bans = stopped = 0
    for C, pen, e, w, n0 in problems:
        n_ref, moves_ref, bans = integer_refine_reference(C, pen, e, w, n0)
        n_new, moves_new = integer_refine(C, pen, e, w, n0)
        np.testing.assert_array_equal(n_new, n_ref)
        assert moves_new == moves_ref
        total_moves += max(moves_ref, 0)
        total_bans += bans
        stopped += moves_ref < 0
    return total_moves, total_bans, stopped


def test_search_matches_the_loops_on_random_networks():
    problems = [p for seed in range(80) for p in _network_problems(seed)]
    moves, bans, _ = _compare(problems)
    assert len(problems) >= 150
    assert moves >= 500 and bans >= 20  # the inputs exercise moves and forbidden cycles


def test_search_matches_the_loops_on_random_matrices():
    problems = [_matrix_problem(seed) for seed in range(150)]
    moves, bans, stopped = _compare(problems)
    assert moves >= 500 and bans >= 1


def _raw_entries(C):
    """Entries with explicit zero coefficients kept: each enters the move graph as a change
    it does not make, so walks through it are found, evaluated exactly, rejected and
    forbidden -- inputs that exercise every ban and the stop."""
    Cc = C.tocsc()
    Cc.sum_duplicates()
    n_ent = np.minimum(np.diff(Cc.indptr), 2).astype(np.int64)
    ent_row = np.full((C.shape[1], 2), -1, np.int64)
    ent_coef = np.zeros((C.shape[1], 2), np.int64)
    for q in range(2):
        has = n_ent > q
        pos = Cc.indptr[:-1][has] + q
        ent_row[has, q] = Cc.indices[pos]
        ent_coef[has, q] = np.round(Cc.data[pos]).astype(np.int64)
    return ent_row, ent_coef, n_ent


def test_search_matches_the_loops_on_entries_with_zero_coefficients():
    total_bans = stopped = 0
    for seed in range(150):
        C, pen, e, w, n0 = _matrix_problem(seed)
        ent_row, ent_coef, n_ent = _raw_entries(C)
        runs = []
        for impl in ("new", "reference"):
            n = np.maximum(np.asarray(n0, np.int64), 1).copy()
            R = np.asarray(np.round(C @ n.astype(float)), np.int64).reshape(-1)
            if impl == "new":
                moves = _improve(n, e, w, ent_row, ent_coef, n_ent, R, pen, 100000)
                bans = 0
            else:
                m, K, V = len(n), len(R), 1 + 8 * len(R)
                stats = {"bans": 0}
                moves = _improve_reference(
                    n, e, w, ent_row, ent_coef, n_ent, R, pen, 100000, np.zeros(V),
                    np.full(V, -1, np.int64), np.full(V, -1, np.int64), np.zeros(V, np.int64),
                    np.full(V, -1, np.int64), np.zeros(K, np.bool_), np.zeros(K, np.bool_),
                    np.zeros(m, np.bool_), np.zeros(m, np.int64), np.zeros(m, np.int64),
                    np.zeros(K, np.int64), stats)
                bans = stats["bans"]
            runs.append((n, int(moves), bans))
        np.testing.assert_array_equal(runs[0][0], runs[1][0])
        assert runs[0][1] == runs[1][1]
        total_bans += runs[1][2]
        stopped += runs[1][1] < 0
    assert total_bans >= 200 and stopped >= 5


def test_search_matches_the_loops_on_a_long_chain():
    """Long walks: a chain of 40 junctions, each with a free branch of one layer measured
    well; the chain stacks (41 down to 1 layers) are measured badly, and conservation along
    the chain corrects them (up to 11 passes in a round)."""
    rng = np.random.default_rng(3)
    k = 40
    A = np.zeros((k, 2 * k + 1))
    for i in range(k):
        A[i, 2 * i] = 1.0           # chain stack into junction i
        A[i, 2 * i + 1] = -1.0      # its free branch
        A[i, 2 * i + 2] = -1.0      # chain stack out of it
    C = sp.csr_matrix(A)
    n_true = np.ones(2 * k + 1)
    n_true[0::2] = np.arange(k + 1, 0, -1)
    e = n_true + rng.normal(0, 0.8, len(n_true))
    e[1::2] = n_true[1::2] + rng.normal(0, 0.05, k)
    w = np.ones(len(e))
    w[1::2] = 25.0
    moves, _, _ = _compare([(C, np.full(k, 1e3), e, w, np.round(e))])
    assert moves >= 20
    np.testing.assert_array_equal(integer_refine(C, np.full(k, 1e3), e, w, np.round(e))[0],
                                  n_true)


def test_search_on_no_junction_or_no_stack():
    C = sp.csr_matrix((0, 3))
    n, moves = integer_refine(C, np.zeros(0), np.array([0.2, 2.6, 4.0]), np.ones(3),
                              np.array([0, 3, 4]))
    np.testing.assert_array_equal(n, [1, 3, 4])
    assert moves == 0
    n, moves = integer_refine(sp.csr_matrix((2, 0)), np.ones(2), np.zeros(0), np.zeros(0),
                              np.zeros(0))
    assert len(n) == 0 and moves == 0


def test_search_with_non_finite_inputs_matches_the_loops():
    """A NaN width (never relaxing any edge of its stack) with a zero weight, infinite
    penalties (distances of -inf, candidates -inf + inf = NaN that never relax) or an
    infinite weight (seed 877: a NaN candidate of the ground that must not hide the others)."""
    for seed in [*range(60), 877]:
        C, pen, e, w, n0 = _matrix_problem(seed)
        pen, e, w = pen.copy(), e.copy(), w.copy()
        rng = np.random.default_rng(seed)
        if seed % 4 == 0:
            e[rng.integers(len(e))] = np.nan
            w[rng.integers(len(w))] = 0.0
        elif seed % 4 == 1:
            pen[rng.random(len(pen)) < 0.5] = np.inf
        elif seed % 4 == 2:
            pen[rng.integers(len(pen))] = np.inf
        else:
            w[rng.integers(len(w))] = np.inf
        with np.errstate(invalid="ignore", over="ignore"):
            n_ref, moves_ref, _ = integer_refine_reference(C, pen, e, w, n0)
        n_new, moves_new = integer_refine(C, pen, e, w, n0)
        np.testing.assert_array_equal(n_new, n_ref)
        assert moves_new == moves_ref


def test_search_stops_after_max_moves_like_the_loops():
    hit = 0
    for seed in range(20):
        C, pen, e, w, n0 = _matrix_problem(seed)
        for max_moves in (0, 1, 3):
            n_ref, moves_ref, _ = integer_refine_reference(C, pen, e, w, n0,
                                                           max_moves=max_moves)
            n_new, moves_new = integer_refine(C, pen, e, w, n0, max_moves=max_moves)
            np.testing.assert_array_equal(n_new, n_ref)
            assert moves_new == moves_ref <= max_moves
            hit += moves_ref == max_moves > 0
    assert hit >= 10


def _relax_loop(c, start):
    """The ``_TOL`` relaxation of one state, candidate by candidate (the original loops)."""
    cur, last, after = start, -1, [start]
    for i, x in enumerate(c):
        if x < cur - 1e-12:
            cur, last = x, i
        after.append(cur)
    return np.array(after), last


@pytest.mark.parametrize("scale", [1e-3, 1.0, 37.0, 4096.0, 1e5, 3e7])
def test_running_and_first_minimum_follow_the_loop(scale):
    """Candidates drawn from a few values, each moved by a few units in the last place or
    by about ``_TOL`` (the near-ties of sums in another order), at several magnitudes; below
    ~8000 (a unit in the last place below ``_TOL``) the ``_TOL`` rule differs from a plain
    cumulative minimum."""
    rng = np.random.default_rng(int(scale * 10) % 1000)
    differs = 0
    for _ in range(400):
        base = -scale * rng.uniform(0.5, 2, int(rng.integers(1, 4)))
        c = rng.choice(base, int(rng.integers(1, 30)))
        kind = rng.integers(0, 3, len(c))
        ulp = np.spacing(np.abs(c))
        c = np.where(kind == 1, c + rng.integers(-3, 4, len(c)) * ulp, c)
        c = np.where(kind == 2, c + rng.choice([-1.0, -0.5, 0.5, 1.0], len(c)) * 1e-12, c)
        start = float(rng.choice([0.0, c.max(), c.min() + 1e-12 * rng.uniform(0, 3)]))
        after, last = _relax_loop(c.tolist(), start)
        got_after, got_last = _running_min(c, start)
        np.testing.assert_array_equal(got_after, after)
        assert got_last == last
        assert _first_min(c, start) == last
        differs += not np.array_equal(np.minimum.accumulate(np.r_[start, c]), after)
    assert differs >= 20 if scale < 8000 else differs == 0


def test_search_objective_never_above_the_start_on_matrices():
    for seed in range(20):
        C, pen, e, w, n0 = _matrix_problem(seed)
        n, _ = integer_refine(C, pen, e, w, n0)
        assert objective(n, e, w, C, pen) <= objective(np.maximum(n0, 1), e, w, C, pen) + 1e-9
