"""Junction placement at thick forks and crossings (stages 5-6 with the fork refinement)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from crosssection.stages.clean import clean_mask
from crosssection.stages.graph import stack_graph
from crosssection.stages.junctions import (FORK_REACH_H, find_junctions, fork_points,
                                           merge_junctions)
from crosssection.stages.skeleton import skeletonize_mask
from crosssection.stages.threshold import threshold_rgb


def _bands(shape, bands):
    """Binary mask of straight bands ((r0, c0), (r1, c1), width_px) drawn at 1/16 px."""
    m = np.zeros(shape, np.uint8)
    for p0, p1, w in bands:
        pts = (np.array([p0, p1], float)[:, ::-1] * 16).round().astype(np.int32)
        cv2.polylines(m, [pts.reshape(-1, 1, 2)], False, 1, thickness=int(round(w)),
                      lineType=cv2.LINE_8, shift=4)
    return m.astype(bool)


def _graph(mask, h_px, refine=True):
    skel = skeletonize_mask(mask, l_min_px=10 * h_px)
    dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return stack_graph(skel, dist, thickness_px=h_px if refine else None)


@pytest.mark.parametrize("n_trunk", [8, 16, 25])
def test_thick_t_junction_placed_at_centreline_meeting(n_trunk):
    # a thick trunk continuing as n_trunk - 1 layers while one sheet leaves at a right angle:
    # the skeleton forks off the centreline meeting point, the refined junction does not
    h = 5.0
    w_trunk = h * (n_trunk + 0.4 * np.sqrt(n_trunk))
    w_cont = h * (n_trunk - 1 + 0.4 * np.sqrt(n_trunk - 1))
    w_one = 1.4 * h
    size = 600
    node = np.array([300.0, 300.0])
    mask = _bands((size, size), [((300, 20), (300, 300), w_trunk),
                                 ((300, 300), (300, 580), w_cont),
                                 ((300, 300), (20, 300), w_one)])
    junc, sg, _ = _graph(mask, h)
    assert len(junc) == 1
    d = np.hypot(*(junc.centers_rc - node).T).min()
    assert d <= 3 * h
    assert sg.degree(0) == 3


def test_degree4_crossing_kept_and_centred():
    h = 5.0
    w = h * 12
    mask = _bands((500, 500), [((250, 10), (250, 490), w), ((10, 200), (490, 300), w * 0.8)])
    junc, sg, merged = _graph(mask, h)
    assert len(junc) == 1 and sg.degree(0) == 4
    cross = np.array([250.0, 250.0])
    assert np.hypot(*(junc.centers_rc[0] - cross)) <= 3 * h


def test_fork_points_lines_and_fallbacks():
    # three lines through (50, 50): the least-squares point is that point
    ang = np.radians([0, 120, 240])
    paths = [np.column_stack([np.round(50 + np.arange(40) * np.sin(a)),
                              np.round(50 + np.arange(40) * np.cos(a))]).astype(int)
             for a in ang]
    out = fork_points(np.array([[46.0, 47.0]]), np.array([4.0]), paths, [0, 0, 0],
                      thickness_px=2.0)
    assert np.hypot(*(out[0] - 50)) < 1.0
    # a single line cannot place a junction: unchanged
    out = fork_points(np.array([[46.0, 47.0]]), np.array([4.0]), paths[:1], [0],
                      thickness_px=2.0)
    np.testing.assert_allclose(out[0], [46.0, 47.0])


def _line_path(start_rc, angle, n=60):
    a = np.radians(angle)
    return np.column_stack([np.round(start_rc[0] + np.arange(n) * np.sin(a)),
                            np.round(start_rc[1] + np.arange(n) * np.cos(a))]).astype(int)


def test_fork_points_tangential_fork_moves_at_most_reach():
    # two branches leaving a trunk 15 degrees either side of it, their tangents meeting 60 px
    # back along the trunk from the skeleton's fork: the junction moves toward that point
    # by FORK_REACH_H h, not the 28 px the least squares would take it
    h, fork = 5.0, np.array([100.0, 100.0])
    meet = fork - [0.0, 60.0]
    paths = [_line_path(meet + 75.0 / np.cos(np.radians(a))
                        * np.array([np.sin(np.radians(a)), np.cos(np.radians(a))]), a)
             for a in (15.0, -15.0)]
    paths.append(_line_path(fork - [0.0, 10.0], 180.0))  # the trunk
    out = fork_points(fork[None], np.array([40.0]), paths, [0, 0, 0], thickness_px=h)
    np.testing.assert_allclose(out[0], fork - [0.0, FORK_REACH_H * h], atol=0.1)
    free = fork_points(fork[None], np.array([40.0]), paths, [0, 0, 0], thickness_px=h,
                       reach_h=np.inf)
    assert np.hypot(*(free[0] - fork)) > 25.0
    # lines meeting at a right angle (a T) move it the whole way, beyond FORK_REACH_H h
    t_paths = [_line_path([100, 130], 0.0), _line_path([100, 68], 180.0),
               _line_path([70, 80], -90.0)]
    out = fork_points(fork[None], np.array([40.0]), t_paths, [0, 0, 0], thickness_px=h)
    assert np.hypot(*(out[0] - [100.0, 80.0])) < 3.0  # the prior keeps it 2.6 px short
    assert np.hypot(*(out[0] - fork)) > FORK_REACH_H * h + 2.0


@pytest.fixture(scope="module")
def thick_scene():
    from crosssection.truth.network import make_scene

    return make_scene(seed=3, n_stacks=40, max_layers=25, mean_layers=8, px_per_mm=50.0,
                      noise_sigma=5.0, blur_px=1.0)


def _match(out_rc, truth_rc, radius):
    from crosssection.truth.scoring import match_points

    r, _ = match_points(out_rc[:, ::-1], truth_rc[:, ::-1], radius)
    return len(r)


def test_generated_thick_trunks_junctions_within_3h(thick_scene):
    # trunks of 8-25 layers (mean 8): every junction within 3 h of the truth, no extra one
    sc = thick_scene
    h = 0.1 * sc.params["px_per_mm"]
    mask = clean_mask(threshold_rgb(sc.rgb).mask, s_min_px=(10 * h) ** 2, speck_px=10 * h * h)
    truth = sc.tables["junctions"][["y_px", "x_px"]].to_numpy(float)
    junc, sg, _ = _graph(mask, h)
    matched = _match(junc.centers_rc, truth, 3 * h)
    f1 = 2 * matched / (len(junc) + len(truth))
    assert f1 >= 0.95
    assert abs(len(junc) - len(truth)) <= 1
    # the skeleton's own forks are measurably worse on the same scan
    junc0, _, _ = _graph(mask, h, refine=False)
    assert matched >= _match(junc0.centers_rc, truth, 3 * h)


def test_generated_tangential_forks_junctions_where_the_bands_separate():
    # 30 degree forks of thick trunks (8-25 layers): the branches leave the generator's node
    # side by side inside the trunk's band and bend apart; the junctions lie where the bands
    # separate (the medial-axis forks, F1 0.96), not at the nodes (0.58)
    from crosssection.truth.network import make_scene
    from crosssection.truth.scoring import medial_fork_points

    sc = make_scene(seed=3, n_stacks=40, max_layers=25, mean_layers=8, px_per_mm=50.0,
                    noise_sigma=5.0, blur_px=1.0, fan_deg=30.0)
    h = 0.1 * sc.params["px_per_mm"]
    mask = clean_mask(threshold_rgb(sc.rgb).mask, s_min_px=(10 * h) ** 2, speck_px=10 * h * h)
    nodes = sc.tables["junctions"][["y_px", "x_px"]].to_numpy(float)
    junc, _, _ = _graph(mask, h)
    st = sc.tables["stacks"]
    forks = medial_fork_points(sc.paths_rc, st["width_mm"] * sc.params["px_per_mm"],
                               st[["junction_a", "junction_b"]].to_numpy(int),
                               sc.tables["junctions"]["junction_id"], nodes, sc.rgb.shape,
                               stride=2)
    at_fork = _match(junc.centers_rc, forks, 3 * h)
    at_node = _match(junc.centers_rc, nodes, 3 * h)
    assert 2 * at_fork / (len(junc) + len(nodes)) >= 0.9
    assert at_fork > at_node


def test_low_resolution_junction_counts():
    # h = 2.5 px (25 px/mm): junction count and placement of a 60-stack network
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=5, n_stacks=60, max_layers=10, px_per_mm=25.0, noise_sigma=5.0,
                    blur_px=1.0, specks=20)
    h = 2.5
    mask = clean_mask(threshold_rgb(sc.rgb).mask, s_min_px=(10 * h) ** 2, speck_px=10 * h * h,
                      min_extent_px=10 * h)
    truth = sc.tables["junctions"][["y_px", "x_px"]].to_numpy(float)
    junc, _, _ = _graph(mask, h)
    matched = _match(junc.centers_rc, truth, 3 * h)
    assert 2 * matched / (len(junc) + len(truth)) >= 0.95


def test_own_band_span_skips_only_the_crossing_of_a_thicker_band():
    from crosssection.stages.graph import _own_band_span

    h = 5.0
    dist = np.zeros((200, 200))
    dist[100, :] = 3.0           # a thin band along row 100 ...
    dist[100, :40] = 30.0        # ... that starts inside a thick band (40 px)
    dist[150, :] = 30.0          # a thick band, uniform
    dist[50, :] = np.where(np.arange(200) % 2, 3.0, 3.5)  # a thin band with pixel noise
    paths = [np.column_stack([np.full(200, r), np.arange(200)]) for r in (100, 150, 50)]
    first, last = _own_band_span(paths, dist, h)
    assert first.tolist() == [40, 0, 0]
    assert last.tolist() == [199, 199, 199]
    # from the other end the thin band is its own all the way to the thick one
    first, last = _own_band_span([p[::-1] for p in paths], dist, h)
    assert first.tolist() == [0, 0, 0] and last.tolist() == [159, 199, 199]


# ----------------------------------------------------------------------------- merging
def _merge_reference(junc, groups, extra_pixels):
    """:func:`merge_junctions` junction by junction: each merged junction's unique pixels,
    renumbered in raster order of their first pixel (ties in order of the first junction),
    written one after the other over a copy of the label image. Also returns the number of
    such ties."""
    parent = list(range(len(junc)))

    def find(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for a, b in groups:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    members = {}
    for j, pix in enumerate(junc.pixels):
        members.setdefault(find(j), []).append(pix)
    for (a, _b), pix in zip(groups, extra_pixels):
        pix = pix[junc.label_image[pix[:, 0], pix[:, 1]] == 0]
        members[find(a)].append(pix)
    clusters = [np.unique(np.concatenate(parts), axis=0) for parts in members.values()]
    clusters.sort(key=lambda p: tuple(p[0]))
    ties = sum(tuple(p[0]) == tuple(q[0]) for p, q in zip(clusters[:-1], clusters[1:]))
    lab = junc.label_image.copy()
    for j, pix in enumerate(clusters):
        lab[pix[:, 0], pix[:, 1]] = j + 1
    centres = np.array([p.mean(axis=0) for p in clusters]).reshape(-1, 2)
    return clusters, centres, lab, ties


def _random_skeleton(rng):
    m = cv2.morphologyEx((rng.random((50, 60)) < 0.5).view(np.uint8), cv2.MORPH_CLOSE,
                         np.ones((3, 3), np.uint8)).view(bool)
    return skeletonize_mask(m, l_min_px=float(rng.choice([0, 3, 8])))


def test_merge_junctions_matches_junction_by_junction_reference():
    """Random merges whose extra pixels are shared between merged junctions, sometimes as
    their first pixel (a tie in the numbering)."""
    rng = np.random.default_rng(21)
    n_ties = n_merges = 0
    for _ in range(150):
        skel = _random_skeleton(rng)
        junc = find_junctions(skel)
        k = len(junc)
        if k < 4:
            continue
        groups = [tuple(int(i) for i in rng.integers(0, k, 2)) for _ in range(rng.integers(1, 5))]
        pool = np.argwhere(skel)
        extras = [pool[rng.integers(0, len(pool), rng.integers(0, 6))] for _ in groups]
        if len(groups) >= 2 and rng.random() < 0.5:
            shared = np.array([[0, 0]]) if rng.random() < 0.5 else extras[0][:2]
            extras[0] = np.concatenate([shared, extras[0]])
            extras[1] = np.concatenate([extras[1], shared])
        merged = merge_junctions(junc, groups, extras)
        pixels, centres, lab, ties = _merge_reference(junc, groups, extras)
        assert len(merged) == len(pixels)
        assert all(np.array_equal(a, b) for a, b in zip(merged.pixels, pixels))
        assert np.array_equal(merged.centers_rc, centres)
        assert np.array_equal(merged.label_image, lab)
        n_ties += ties
        n_merges += len(junc) > len(merged)
    assert n_ties >= 5 and n_merges >= 50


def test_stack_graph_finds_the_junctions_of_find_junctions():
    rng = np.random.default_rng(22)
    for _ in range(60):
        skel = _random_skeleton(rng)
        merge_px = float(rng.choice([0.0, 1.0, 2.0, 3.5]))
        junc, _, _ = stack_graph(skel, np.ones(skel.shape, np.float32), merge_px=merge_px,
                                 merge_thick_crossings=False)
        ref = find_junctions(skel, merge_px=merge_px)
        assert np.array_equal(junc.centers_rc, ref.centers_rc)
        assert all(np.array_equal(a, b) for a, b in zip(junc.pixels, ref.pixels))
        assert len(junc.pixels) == len(ref.pixels)
        assert np.array_equal(junc.label_image, ref.label_image)


@pytest.mark.parametrize("merge_px", [4.5, 7.0, 12.0, 1000.0])
def test_a_wide_merge_joins_the_junction_pixels_within_it(merge_px):
    # a merge wider than a few pixels takes its pairs from a k-d tree instead of one pass
    # over the junction pixels per offset of the disc (minutes for a merge of 1000 px):
    # junction pixels (3 neighbours or more) closer than the merge share a cluster, and
    # clusters lie farther apart than it
    from crosssection.stages.skeleton import neighbour_count

    rng = np.random.default_rng(int(merge_px * 10))
    skel = np.zeros((120, 120), bool)
    for _ in range(14):  # random straight strokes: crossings make junction pixels
        r0, c0, r1, c1 = rng.integers(5, 115, 4)
        n = max(abs(r1 - r0), abs(c1 - c0)) + 1
        skel[np.linspace(r0, r1, n).round().astype(int),
             np.linspace(c0, c1, n).round().astype(int)] = True
    skel = skeletonize_mask(skel, l_min_px=0)
    junc = find_junctions(skel, merge_px=merge_px)
    jr, jc = np.nonzero(skel & (neighbour_count(skel) >= 3))
    assert len(jr) >= 10
    own = junc.label_image[jr, jc] - 1
    assert np.all(own >= 0)
    d2 = (jr[:, None] - jr[None, :]) ** 2 + (jc[:, None] - jc[None, :]) ** 2
    near = d2 <= max(merge_px ** 2, 2.0)
    # closer than the merge: one cluster; every cluster joined through such links
    assert np.all(own[:, None] == own[None, :], where=near)
    from scipy.sparse.csgraph import connected_components

    n_links, _ = connected_components(near.astype(np.int8), directed=False)
    assert len(junc) == n_links == len(np.unique(own))
    if merge_px == 1000.0:
        assert len(junc) == 1
