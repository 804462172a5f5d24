"""Junction conservation rows and the width equations of the paper's system."""
from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
import scipy.sparse as sp

from crosssection.linsys import conservation_equations, reliability_score, solve_branch_counts
from crosssection.linsys.equations import paper_system, select_width_stacks, sparse_rows
from crosssection.stages.packs import Pack
from crosssection.truth.graphs import NetworkGraph, random_network


@pytest.mark.parametrize("seed", range(6))
def test_generator_is_conserved(seed, assert_conserved):
    fg = random_network(seed, n_junctions=25)
    assert len(fg.paths) > 10
    assert_conserved(fg.packs, fg.n_true)


@pytest.mark.parametrize("seed", range(4))
def test_rows_vanish_on_the_truth(seed):
    """Every hard row is ``sum_A n - sum_B n``: zero on the true n_br, one row per junction."""
    fg = random_network(40 + seed, n_junctions=30, p_deg4=0.2)
    hard, soft, dropped, repart = conservation_equations(fg, fg.packs)
    assert soft == [] and repart == []
    assert len(hard) + len(dropped) <= len(fg.packs)
    C = sparse_rows(hard, {s: s for s in range(len(fg.paths))}, len(fg.paths))
    assert C.shape == (len(hard), len(fg.paths))
    np.testing.assert_array_equal(C @ fg.n_true, 0)
    assert np.all(np.diff(C.tocsc().indptr) <= 2)  # a stack has two ends


def _symmetric_y():
    G = nx.MultiGraph()
    G.add_edges_from([(0, 1, {"stack_id": 0}), (0, 2, {"stack_id": 1}),
                      (0, 3, {"stack_id": 2})])
    kinds = {0: "junction", 1: "end", 2: "end", 3: "end"}
    fg = NetworkGraph(G, {k: np.zeros(2) for k in kinds}, kinds, [np.zeros((2, 2), int)] * 3,
                      [(0, 1), (0, 2), (0, 3)])
    cands = [([(0, 0)], [(1, 0), (2, 0)]), ([(1, 0)], [(0, 0), (2, 0)]),
             ([(2, 0)], [(0, 0), (1, 0)])]
    packs = {0: Pack(0, [(0, 0)], [(1, 0), (2, 0)], reference_dependent=True, candidates=cands)}
    return fg, packs


def test_reference_dependent_junction_uses_width_choice():
    """Symmetric Y: geometry cannot tell the trunk; the widths (1, 1, 2) can."""
    fg, packs = _symmetric_y()
    hard, soft, dropped, _ = conservation_equations(fg, packs, np.array([1.1, 0.9, 2.3]),
                                                    np.full(3, 0.3))
    assert hard == [] and dropped == [] and soft == [(0, {2: 1, 0: -1, 1: -1})]
    res = solve_branch_counts(fg, packs, np.array([1.1, 0.9, 2.3]))
    np.testing.assert_array_equal(res.n_br, [1, 1, 2])
    assert any("soft-junctions" in f for f in res.flags)
    # no clear winner -> dropped
    res = solve_branch_counts(fg, packs, np.array([1.0, 1.0, 1.0]))
    assert any("dropped-junctions" in f for f in res.flags)
    np.testing.assert_array_equal(res.n_br, [1, 1, 1])


def _misread_junction():
    """A random network whose one degree-3 junction lists a wrong partition (a member of the
    larger pack moved to the other), the right one among its candidates; thin exact widths.
    Returns (graph, width estimates, node, right partition)."""
    fg = random_network(21, n_junctions=30)
    est = fg.n_true + np.random.default_rng(5).normal(0, 0.1, len(fg.paths))
    node = next(nd for nd, p in fg.packs.items() if len(p.side_a) == 1 and len(p.side_b) == 2
                and len({s for s, _ in p.side_a + p.side_b}) == 3
                and abs(sum(fg.n_true[s] for s, _ in p.side_b[1:]) * 2) >= 4)
    p = fg.packs[node]
    right = (list(p.side_a), list(p.side_b))
    fg.packs[node] = Pack(node, p.side_a + p.side_b[1:], p.side_b[:1],
                          candidates=[right, (p.side_a + p.side_b[1:], p.side_b[:1])])
    return fg, est, node, right


def test_wrong_geometric_pack_is_repartitioned_by_widths():
    """A clear (not flagged) junction with the wrong partition, contradicted by thin exact
    widths, is switched to the candidate the widths support."""
    fg, est, node, _ = _misread_junction()
    _, _, _, repart = conservation_equations(fg, fg.packs, est, np.full(len(est), 0.3))
    assert repart == [node]
    _, _, _, repart = conservation_equations(fg, fg.packs, est, np.full(len(est), 0.3),
                                             switch_llr=None)
    assert repart == [node]  # contradicted beyond z_max: switched without the prior too
    res = solve_branch_counts(fg, fg.packs, est)
    np.testing.assert_array_equal(res.n_br, fg.n_true)
    assert any("repartitioned" in f for f in res.flags)


def test_reliability_prefers_thin_and_integer_widths():
    e = np.array([1.02, 1.45, 3.02, np.nan])
    w = 1 / (0.3 + 0.05 * (np.nan_to_num(e, nan=1.0) - 1)) ** 2
    score = reliability_score(e, w)
    assert score[0] > score[2] > score[1]
    assert score[3] == -np.inf


def test_width_stacks_complete_the_needed_ones_by_reliability():
    score = np.array([0.5, 3.0, 1.0, 2.0, 0.1])
    sel = select_width_stacks([4], np.arange(5), score, 3)
    assert sel == [4, 1, 3]
    assert select_width_stacks([4, 0, 2, 3], np.arange(5), score, 3) == [4, 0, 2, 3]


def test_paper_system_rows():
    """[C_hat; I_S] with unit-norm junction rows and b = [0; max(round(e_S), 1)]."""
    C = sp.csr_matrix(np.array([[1.0, -1.0, -1.0], [0.0, 2.0, -1.0]]))
    A, b = paper_system(C, np.array([2]), np.array([3.2, 1.6, 0.2]))
    A = A.toarray()
    np.testing.assert_allclose(np.linalg.norm(A[:2], axis=1), 1.0)
    np.testing.assert_array_equal(A[2], [0, 0, 1])
    np.testing.assert_array_equal(b, [0, 0, 1])
    assert np.linalg.matrix_rank(A) == 3


def _junction_rows(fg, packs, res):
    from crosssection.stages.junctions import Junctions
    from crosssection.tables import junction_table

    class Degrees:
        def degree(self, j):
            return fg.graph.degree(j) if j in fg.graph else 0

    k = max(packs) + 1
    js = Junctions(np.zeros((k, 2)), [np.zeros((1, 2), int)] * k, np.zeros((1, 1), np.int32))
    return junction_table(js, Degrees(), packs, res.n_br, res)


def test_junction_table_reports_the_partition_the_system_used():
    """The symmetric Y's geometric packs (0 | 1 2) do not conserve the counts (1, 1, 2) the
    widths chose with the partition (2 | 0 1): the table lists that partition, its zero
    residual, and how it was chosen; without a clear choice no equation is used and the
    junction conserves under some candidate."""
    fg, packs = _symmetric_y()
    res = solve_branch_counts(fg, packs, np.array([1.1, 0.9, 2.3]))
    row = _junction_rows(fg, packs, res).iloc[0]
    assert (row["pack_a"], row["pack_b"]) == ("2:0", "0:0 1:0")
    assert row["equation"] == "widths" and row["conservation_residual"] == 0
    assert row["conservation_ok"] and not row["repartitioned"]
    res = solve_branch_counts(fg, packs, np.array([1.0, 1.0, 1.0]))
    row = _junction_rows(fg, packs, res).iloc[0]
    assert row["equation"] == "dropped" and row["pack_a"] == "0:0"
    assert row["conservation_residual"] == -1 and not row["conservation_ok"]


def test_junction_table_marks_repartitioned_junctions_conserved():
    fg, est, node, right = _misread_junction()
    res = solve_branch_counts(fg, fg.packs, est)
    table = _junction_rows(fg, fg.packs, res).set_index("junction_id")
    assert table.loc[node, "equation"] == "repartitioned" and table.loc[node, "repartitioned"]
    assert table.loc[node, "pack_a"] == " ".join(f"{s}:{e}" for s, e in right[0])
    assert table["conservation_ok"].loc[list(fg.packs)].all()
    assert set(table["equation"].loc[list(fg.packs)]) <= {"packs", "repartitioned", "none"}


def test_zscore_is_the_numpy_formula():
    """The z-score on lists equals ``|c.e| / sqrt(sum c^2 sigma^2 + 1e-12)`` computed with
    numpy's dot and sum on the row's arrays, bit for bit, for rows of 1 to 10 stacks with
    coefficients +-1, +-2, estimates over nine decades, missing widths (inf) and NaN or
    zero errors."""
    from crosssection.linsys.equations import _zscore

    rng = np.random.default_rng(8)
    for trial in range(3000):
        est = rng.uniform(0.2, 12.0, 20) * 10.0 ** rng.integers(-4, 5, 20)
        sig = rng.uniform(0.05, 2.0, 20) * 10.0 ** rng.integers(-4, 5, 20)
        if trial % 7 == 0:
            est[rng.integers(20)] = rng.choice([np.nan, np.inf])
        if trial % 11 == 0:
            sig[rng.integers(20)] = rng.choice([np.nan, 0.0])
        ids = rng.choice(20, int(rng.integers(1, 11)), replace=False)
        row = {int(s): int(c) for s, c in zip(ids, rng.choice([-2, -1, 1, 2], len(ids)))}
        c = np.array(list(row.values()), float)
        e, s = est[list(row)], sig[list(row)]
        want = (np.inf if not np.all(np.isfinite(e))
                else abs(c @ e) / np.sqrt(float(np.sum(c ** 2 * s ** 2)) + 1e-12))
        got = _zscore(row, est.tolist(), sig.tolist())
        assert got == want or (np.isnan(got) and np.isnan(want))
