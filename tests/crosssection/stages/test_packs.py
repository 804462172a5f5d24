"""Stage 7: packs at junctions, from pixel paths of known geometry (varied seeds/rotations)."""
from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from skimage.draw import line

from crosssection.stages.packs import compute_packs, end_tangent
from crosssection.truth.graphs import NetworkGraph


def star_graph(angles_deg, *, length=60, centre=(200.0, 200.0), loops=(), kink_px=0, seed=0):
    """A junction at ``centre`` with straight stacks leaving at ``angles_deg`` (row, col frame,
    angle measured from +col towards +row), each ending at a free end; ``loops`` are pairs of
    angles joined into one self-loop stack (out along the first, back along the second).
    ``kink_px`` adds a crooked start (skeleton distortion inside the junction blob)."""
    rng = np.random.default_rng(seed)
    c = np.asarray(centre)
    G = nx.MultiGraph()
    G.add_node(0)
    kinds, rc = {0: "junction"}, {0: c}
    paths, ends = [], []

    def ray(a):
        d = np.array([np.sin(np.radians(a)), np.cos(np.radians(a))])
        p1 = np.round(c + length * d).astype(int)
        p0 = np.round(c).astype(int)
        rr, cc = line(p0[0], p0[1], p1[0], p1[1])
        pts = np.column_stack([rr, cc])
        if kink_px:
            side = np.array([d[1], -d[0]]) * rng.choice([-1, 1])
            pts[1:kink_px + 1] += np.round(side * 2).astype(int)
        return pts

    for a in angles_deg:
        nid = len(kinds)
        kinds[nid] = "end"
        path = ray(a)
        rc[nid] = path[-1].astype(float)
        G.add_edge(0, nid, stack_id=len(paths))
        paths.append(path)
        ends.append((0, nid))
    for a1, a2 in loops:
        out, back = ray(a1), ray(a2)[::-1]
        rr, cc = line(*out[-1], *back[0])
        path = np.vstack([out, np.column_stack([rr, cc])[1:-1], back])
        G.add_edge(0, 0, stack_id=len(paths))
        paths.append(path)
        ends.append((0, 0))
    return NetworkGraph(G, rc, kinds, paths, ends)


def _sides(pack):
    return {frozenset(s for s, _ in pack.side_a), frozenset(s for s, _ in pack.side_b)}


@pytest.mark.parametrize("seed", range(6))
def test_y_junction_known_packs_any_rotation(seed):
    rng = np.random.default_rng(seed)
    rot = rng.uniform(0, 360)
    spread = rng.uniform(5, 40)  # half-angle between the two merging stacks
    angles = [rot, rot + 180 - spread, rot + 180 + spread]
    fg = star_graph(angles, kink_px=int(rng.integers(0, 3)), seed=seed)
    pack = compute_packs(fg, tangent_px=25, skip_px=4)[0]
    assert pack.side_a == [(0, 0)]  # the trunk alone, as the smaller pack
    assert sorted(pack.side_b) == [(1, 0), (2, 0)]
    assert not pack.ambiguous and not pack.reference_dependent
    assert pack.margin_deg > 45


def test_symmetric_y_is_reference_dependent():
    fg = star_graph([10, 130, 250])
    pack = compute_packs(fg, tangent_px=25)[0]
    assert pack.reference_dependent
    assert len(pack.candidates) == 3  # every 1|2 split is possible


@pytest.mark.parametrize("seed", range(4))
def test_reference_independence_random_clear_junctions(seed):
    """Packs confined within +-40 deg of an axis: every reference gives the same partition."""
    rng = np.random.default_rng(50 + seed)
    axis = rng.uniform(0, 360)
    k_a, k_b = int(rng.integers(1, 3)), int(rng.integers(1, 3))
    ang_a = axis + rng.uniform(-40, 40, k_a)
    ang_b = axis + 180 + rng.uniform(-40, 40, k_b)
    fg = star_graph(np.concatenate([ang_a, ang_b]), length=80)
    pack = compute_packs(fg, tangent_px=40)[0]
    assert not pack.reference_dependent
    assert _sides(pack) == {frozenset(range(k_a)), frozenset(range(k_a, k_a + k_b))}


@pytest.mark.parametrize("beta", [40, 70, 110, 150])
def test_x_crossing_two_two(beta):
    fg = star_graph([0, beta, 180, 180 + beta])
    pack = compute_packs(fg, tangent_px=30)[0]
    assert pack.degree == 4 and not pack.ambiguous
    # the acute pairs form the packs
    expect = {frozenset({0, 1}), frozenset({2, 3})} if beta < 90 else \
        {frozenset({1, 2}), frozenset({3, 0})}
    assert _sides(pack) == expect


def test_degree4_one_three():
    fg = star_graph([5, 160, 185, 205])
    pack = compute_packs(fg, tangent_px=30)[0]
    assert pack.side_a == [(0, 0)] and len(pack.side_b) == 3


def test_self_loop_counts_twice():
    # trunk to the right, a teardrop loop leaving and returning on the left side
    fg = star_graph([0], loops=[(165, 195)], length=70)
    pack = compute_packs(fg, tangent_px=30)[0]
    assert pack.side_a == [(0, 0)]
    assert sorted(pack.side_b) == [(1, 0), (1, 1)]


def test_all_on_one_side_is_ambiguous_but_two_sided():
    fg = star_graph([0, 25, 50])
    pack = compute_packs(fg, tangent_px=30)[0]
    assert pack.ambiguous
    assert pack.side_a and pack.side_b


def test_tangent_skips_junction_blob_and_orients_outwards():
    rng = np.random.default_rng(3)
    for _ in range(5):
        a = rng.uniform(0, 360)
        fg = star_graph([a], kink_px=3, length=50)
        for end in (0, 1):
            path = fg.paths[0] if end == 0 else fg.paths[0][::-1]
            t = end_tangent(path, fg.node_rc[0], end, tangent_px=30, skip_px=5)
            d = np.array([np.sin(np.radians(a)), np.cos(np.radians(a))])
            assert np.dot(t, d) > np.cos(np.radians(4))


def test_degenerate_inputs_do_not_crash():
    fg = star_graph([0])
    pack = compute_packs(fg, tangent_px=10)[0]
    assert pack.ambiguous
    t = end_tangent(np.zeros((0, 2), int), (0, 0), 0, tangent_px=5)
    assert np.all(np.isnan(t))


def _render_y(trunk_n, left_n, right_n, *, h_px=5.0, alpha_deg=25.0, size=400, seed=0):
    """Mask of a trunk of ``trunk_n`` layers splitting into two stacks that diverge at
    +-alpha: each branch stack's layers continue side by side into the trunk."""
    rng = np.random.default_rng(seed)
    rot = np.radians(rng.uniform(0, 360))
    rr, cc = np.mgrid[:size, :size].astype(float)
    y0 = rr - size / 2 + rng.uniform(-.5, .5)
    x0 = cc - size / 2 + rng.uniform(-.5, .5)
    x = x0 * np.cos(rot) + y0 * np.sin(rot)
    y = -x0 * np.sin(rot) + y0 * np.cos(rot)
    half = trunk_n * h_px / 2
    mask = (x <= 0) & (x >= -150) & (np.abs(y) <= half)
    for n, sgn, off in ((left_n, -1, -half + left_n * h_px / 2),
                        (right_n, 1, half - right_n * h_px / 2)):
        a = np.radians(alpha_deg) * sgn
        # branch centre line through (0, off) at angle a
        along = x * np.cos(a) + (y - off) * np.sin(a)
        perp = -x * np.sin(a) + (y - off) * np.cos(a)
        mask |= (along >= 0) & (along <= 150) & (np.abs(perp) <= n * h_px / 2)
    return mask, rot


@pytest.mark.parametrize("ns,seed", [((2, 1, 1), 0), ((5, 2, 3), 1), ((5, 3, 2), 2),
                                     ((4, 1, 3), 3)])
def test_stages_7_8_9_on_rendered_y(ns, seed):
    """Render a Y, skeletonize / junctions / graph (stages 4-6, if available), then packs,
    widths, calibration and the linear system recover the layer counts."""
    graph_mod = pytest.importorskip("crosssection.stages.graph")
    from scipy import ndimage

    from crosssection.stages.junctions import find_junctions
    from crosssection.linsys import solve_branch_counts
    from crosssection.stages.skeleton import skeletonize_mask
    from crosssection.core.calibration import Calibration
    from crosssection.stages.widths import stack_widths

    trunk, left, right = ns
    mask, rot = _render_y(trunk, left, right, seed=seed)
    mask = ndimage.binary_fill_holes(mask)  # stage 3 would fill the pixel holes of the wedge
    skel = skeletonize_mask(mask, l_min_px=50)
    sg = graph_mod.build_stack_graph(skel, find_junctions(skel))
    junc = [n for n, k in sg.node_kind.items() if k == "junction"]
    assert len(junc) == 1 and len(sg.paths) == 3
    packs = compute_packs(sg, tangent_px=40, skip_px=8)
    dist = ndimage.distance_transform_edt(mask)
    width_mm = stack_widths(sg, dist, px_per_mm=50, junction_margin_px=10)
    est = Calibration.linear(0.1).layers(width_mm)
    res = solve_branch_counts(sg, packs, est)
    # identify each stack by the direction from the junction to its far end
    c = sg.node_rc[junc[0]]
    truth = []
    for sid, (u, v) in enumerate(sg.ends):
        far = sg.node_rc[v if u == junc[0] else u] - c
        xr = far[1] * np.cos(rot) + far[0] * np.sin(rot)
        yr = -far[1] * np.sin(rot) + far[0] * np.cos(rot)
        truth.append(trunk if xr < 0 else (left if yr < 0 else right))
    np.testing.assert_array_equal(res.n_br, truth)
    assert np.abs(est - np.array(truth)).max() < 0.6
    assert res.conservation_residual == 0
