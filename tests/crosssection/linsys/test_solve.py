"""solve_branch_counts: n_br per stack, flags and diagnostics, component by component."""
from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from crosssection.linsys import rod_end_junctions, solve_branch_counts
from crosssection.stages.packs import Pack
from crosssection.truth.graphs import NetworkGraph, random_network


def test_exact_widths_recovered_exactly():
    fg = random_network(1, n_junctions=40)
    res = solve_branch_counts(fg, fg.packs, fg.n_true.astype(float))
    np.testing.assert_array_equal(res.n_br, fg.n_true)
    assert res.conservation_residual == 0
    assert not res.changed_from_width.any()


@pytest.mark.parametrize("tree", [False, True])
def test_noisy_widths_recover_integers(tree, assert_conserved):
    """sigma = 0.3 layers on every stack: >= 90% of stacks exact (rounding alone ~ 90%)."""
    exact, total, rounding_exact = 0, 0, 0
    for seed in range(100, 112):
        fg = random_network(seed, n_junctions=30, tree=tree, n_free=4)
        rng = np.random.default_rng(seed + 7)
        est = fg.n_true + rng.normal(0, 0.3, len(fg.n_true))
        res = solve_branch_counts(fg, fg.packs, est)
        assert np.all(res.n_br >= 1)
        assert_conserved(fg.packs, res.n_br)
        assert res.conservation_residual == 0
        exact += int(np.sum(res.n_br == fg.n_true))
        rounding_exact += int(np.sum(np.maximum(np.round(est), 1) == fg.n_true))
        total += len(fg.n_true)
    frac = exact / total
    assert frac >= 0.9, (frac, rounding_exact / total)
    assert frac > rounding_exact / total  # conservation must help


def _y_junction():
    """One junction, stack 0 in one pack against stacks 1 and 2 in the other."""
    G = nx.MultiGraph()
    G.add_edges_from([(0, 1, {"stack_id": 0}), (0, 2, {"stack_id": 1}),
                      (0, 3, {"stack_id": 2})])
    kind = {0: "junction", 1: "end", 2: "end", 3: "end"}
    fg = NetworkGraph(G, {k: np.zeros(2) for k in kind}, kind,
                      [np.zeros((2, 2), int)] * 3, [(0, 1), (0, 2), (0, 3)])
    return fg, {0: Pack(0, [(0, 0)], [(1, 0), (2, 0)])}


def test_y_junction_splits():
    """n=2 splits into 1+1, 5 into 2+3 (trunk on one pack, two branches on the other)."""
    for trunk, left, right in [(2, 1, 1), (5, 2, 3), (7, 3, 4)]:
        fg, packs = _y_junction()
        rng = np.random.default_rng(trunk)
        est = np.array([trunk, left, right]) + rng.normal(0, 0.15, 3)
        res = solve_branch_counts(fg, packs, est)
        np.testing.assert_array_equal(res.n_br, [trunk, left, right])
        # a thick trunk badly measured is corrected by its thin, reliable branches
        res = solve_branch_counts(fg, packs, np.array([trunk + 0.6, left, right], float))
        np.testing.assert_array_equal(res.n_br, [trunk, left, right])
        assert res.changed_from_width.tolist() == [True, False, False]


def test_inconsistent_system_flagged_not_crash(tiny_graph):
    # theta graph: stacks 0,1,2 between junctions 0 and 1; packs say a = b + c and b = a + c
    fg = tiny_graph([(0, 1), (0, 1), (0, 1)], {0: "junction", 1: "junction"})
    packs = {0: Pack(0, [(0, 0)], [(1, 0), (2, 0)]), 1: Pack(1, [(1, 1)], [(0, 1), (2, 1)])}
    res = solve_branch_counts(fg, packs, np.array([2.0, 2.0, 1.0]))
    assert np.all(res.n_br >= 1)
    assert any("inconsistent" in f for f in res.flags)
    assert res.conservation_residual > 0


def test_rod_ends_at_junctions_leave_the_widths_in_charge(tiny_graph):
    # theta: a 3-layer stack and two single sheets between two junctions; 3 = 1 + 1 + one
    # rod end at each junction. Exact conservation made the 3-layer stack 2 layers.
    fg = tiny_graph([(0, 1), (0, 1), (0, 1)], {0: "junction", 1: "junction"})
    packs = {0: Pack(0, [(0, 0)], [(1, 0), (2, 0)]), 1: Pack(1, [(0, 1)], [(1, 1), (2, 1)])}
    est = np.array([3.04, 0.98, 1.03])
    res = solve_branch_counts(fg, packs, est, noise_scale=0.25)
    np.testing.assert_array_equal(res.n_br, [3, 1, 1])
    assert res.components[0].rod_end_junctions == [0, 1]
    assert any("rod-end-junctions" in f for f in res.flags)
    old = solve_branch_counts(fg, packs, est, noise_scale=0.25, rod_ends=0)
    np.testing.assert_array_equal(old.n_br, [2, 1, 1])
    sigma = np.full(3, 0.1)
    assert rod_end_junctions(fg, packs, est, sigma, hidden_ends=2) == [0, 1]
    # more such junctions than hidden rod ends: the widths are wrong, not the equations
    assert rod_end_junctions(fg, packs, est, sigma, hidden_ends=1) == []
    # widths that do not contradict conservation clearly (z <= z_max), or are missing
    assert rod_end_junctions(fg, packs, est, np.full(3, 0.3), hidden_ends=2) == []
    assert rod_end_junctions(fg, packs, np.array([3.04, np.nan, 1.03]), sigma,
                             hidden_ends=2) == []
    # an even number of layer ends (4 = 1 + 1 + 2 ends): no single rod end explains it
    assert rod_end_junctions(fg, packs, np.array([4.0, 1.0, 1.0]), sigma,
                             hidden_ends=2) == []


def test_singular_and_isolated_components(tiny_graph):
    # component 1: an isolated loop (no junction); component 2: an open free segment;
    # component 3: a junction whose only equation is a self-loop on opposite packs (0 = 0)
    kinds = {0: "loop", 1: "end", 2: "end", 3: "junction", 4: "end"}
    fg = tiny_graph([(0, 0), (1, 2), (3, 3), (3, 4)], kinds)
    packs = {3: Pack(3, [(2, 0)], [(2, 1), (3, 0)])}  # loop cancels: n3 = 0 impossible
    est = np.array([3.2, 1.9, 2.4, np.nan])
    res = solve_branch_counts(fg, packs, est)
    assert res.n_components == 3
    assert res.flags[0] == "disconnected"
    assert [c.stacks.tolist() for c in res.components] == [[0], [1], [2, 3]]
    assert res.n_br[0] == 3 and res.n_br[1] == 2
    assert np.all(res.n_br >= 1)
    assert any("fallback-to-width" in f for f in res.flags)


def test_stacks_missing_from_the_graph_are_alone(tiny_graph):
    """A stack without ends in the graph is its own component, solved by its width."""
    fg = tiny_graph([(0, 1)], {0: "end", 1: "end"})
    fg.paths.append(np.zeros((2, 2), int))
    res = solve_branch_counts(fg, {}, np.array([2.2, 3.9]))
    assert res.n_components == 2
    np.testing.assert_array_equal(res.n_br, [2, 4])
    assert res.components[1].stacks.tolist() == [1]


def test_underdetermined_cycle_flags_and_uses_widths(tiny_graph):
    # a ring of degree-2 "junctions" (1|1): conservation leaves one free unknown
    k = 6
    kinds = {i: "junction" for i in range(k)}
    fg = tiny_graph([(i, (i + 1) % k) for i in range(k)], kinds)
    packs = {i: Pack(i, [(i, 0)], [((i - 1) % k, 1)]) for i in range(k)}
    est = np.array([3.3, 2.8, 3.1, 2.6, 3.4, 2.9])
    res = solve_branch_counts(fg, packs, est, width_fraction=0.0)
    np.testing.assert_array_equal(res.n_br, 3)
    assert res.rank == k
    assert res.fixed_by_width.sum() == 1
    assert res.components[0].rank_conservation == k - 1
    res = solve_branch_counts(fg, packs, est)
    assert res.fixed_by_width.sum() == 2  # ceil(6/3)
    assert np.isfinite(res.condition_number)


def test_ill_conditioned_large_weights_never_crash():
    fg = random_network(7, n_junctions=40)
    M = len(fg.paths)
    rng = np.random.default_rng(3)
    est = fg.n_true + rng.normal(0, 0.3, M)
    rel = np.where(rng.random(M) < 0.5, 0.0, 1e6)  # half the widths ignored, half absurdly sure
    est[rng.random(M) < 0.1] = np.nan
    robust = solve_branch_counts(fg, fg.packs, est, reliability=rel)  # may reject equations
    assert robust.n_br.shape == (M,) and np.all(robust.n_br >= 1)
    # exact conservation (robust_penalty=None: every geometric equation is hard)
    res = solve_branch_counts(fg, fg.packs, est, reliability=rel, robust_penalty=None)
    assert res.n_br.shape == (M,) and np.all(res.n_br >= 1)
    assert res.conservation_residual == 0
    s = res.summary()
    assert set(s) >= {"rank", "residual", "condition_number", "flags"}
    assert s["n_unknowns"] == M


def test_one_wrong_equation_is_rejected_not_propagated(y_chain):
    """A Y chain with exact widths and one wrong geometric partition (trunk swapped with a
    branch, as seen at blurred junctions): the robust solve violates that one equation and
    keeps every n_br; with every equation hard (robust_penalty=None) n_br changes."""
    fg, packs, n_true = y_chain(9)
    for p in packs.values():
        assert sum(n_true[s] for s, _ in p.side_a) == sum(n_true[s] for s, _ in p.side_b)
    rng = np.random.default_rng(2)
    est = n_true + rng.normal(0, 0.05, len(n_true))
    p = packs[4]
    packs[4] = Pack(4, p.side_b[:1], p.side_a + p.side_b[1:])  # trunk swapped: wrong
    res = solve_branch_counts(fg, packs, est, switch_llr=None)
    np.testing.assert_array_equal(res.n_br, n_true)
    assert res.components[0].violated_junctions == [4]
    hard = solve_branch_counts(fg, packs, est, switch_llr=None, robust_penalty=None)
    assert np.any(hard.n_br != n_true) and hard.conservation_residual == 0
    # with the width evidence (default) the junction is repartitioned instead
    p = packs[4]
    packs[4] = Pack(4, p.side_a, p.side_b, candidates=[(p.side_a, p.side_b),
                                                       (p.side_b[:1], p.side_a + p.side_b[1:])])
    res = solve_branch_counts(fg, packs, est)
    np.testing.assert_array_equal(res.n_br, n_true)
    assert any("repartitioned" in f for f in res.flags)


def test_bad_arguments_raise(tiny_graph):
    fg = tiny_graph([(0, 1)], {0: "end", 1: "end"})
    with pytest.raises(ValueError, match="method"):
        solve_branch_counts(fg, {}, np.ones(1), method="exact")
    with pytest.raises(ValueError, match="layers_est"):
        solve_branch_counts(fg, {}, np.ones(2))


def test_without_integer_refinement_the_rounding_stays_unbalanced():
    """A Y junction (trunk = two branches) whose least squares round to 3 = 1 + 1: the
    integer steps balance it, without them it stays violated and is reported."""
    fg, packs = _y_junction()
    est = np.array([2.6, 1.4, 1.4])
    on = solve_branch_counts(fg, packs, est)
    off = solve_branch_counts(fg, packs, est, integer_refinement=False)
    np.testing.assert_array_equal(on.n_br, [2, 1, 1])
    assert on.conservation_residual == 0 and on.components[0].method == "search"
    np.testing.assert_array_equal(off.n_br, [3, 1, 1])
    assert off.conservation_residual == 1
    assert off.components[0].violated_junctions == [0]
    assert off.components[0].method == "rounded"
    assert "inconsistent:component=0" in off.flags


def test_integer_refinement_is_what_balances_noisy_networks():
    """sigma = 0.3 layers on random networks: the rounding alone leaves junctions
    unbalanced and fewer stacks exact; the default balances every one."""
    exact = {True: 0, False: 0}
    unbalanced = {True: 0, False: 0}
    total = 0
    for seed in range(100, 112):
        fg = random_network(seed, n_junctions=30, n_free=4)
        est = fg.n_true + np.random.default_rng(seed + 7).normal(0, 0.3, len(fg.n_true))
        for refine in (True, False):
            res = solve_branch_counts(fg, fg.packs, est, integer_refinement=refine)
            assert np.all(res.n_br >= 1)
            exact[refine] += int(np.sum(res.n_br == fg.n_true))
            unbalanced[refine] += res.conservation_residual > 0
        total += len(fg.n_true)
    assert unbalanced[True] == 0 and unbalanced[False] > 0
    assert exact[True] > exact[False]


def test_milp_needs_integer_refinement(tiny_graph):
    fg = tiny_graph([(0, 1)], {0: "end", 1: "end"})
    with pytest.raises(ValueError, match="integer_refinement"):
        solve_branch_counts(fg, {}, np.ones(1), method="milp", integer_refinement=False)


@pytest.mark.parametrize("big", [1e12, 1e19, 1e300, -1e19])
def test_absurd_estimates_are_missing_not_counts(big, tiny_graph):
    """An estimate beyond any scan's band (1e19 layers, cast to integers, wrapped round to a
    negative count; 1e12 sent the MILP out of memory) is missing data, as a NaN is: alone it
    reads one layer, at a junction the others' conservation fills it."""
    fg = tiny_graph([(0, 1)], {0: "end", 1: "end"})
    res = solve_branch_counts(fg, {}, np.array([big]))
    assert res.n_br.tolist() == [1]
    fg, packs = _y_junction()
    res = solve_branch_counts(fg, packs, np.array([big, 2.0, 3.0]))
    nan = solve_branch_counts(fg, packs, np.array([np.nan, 2.0, 3.0]))
    assert res.n_br.tolist() == nan.n_br.tolist() == [5, 2, 3]
    assert res.conservation_residual == 0
