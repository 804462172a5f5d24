"""Layer steps: a stack cut where its width steps by whole layers (layers ending in the band)."""
from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from crosssection import analyze
from crosssection.core.calibration import Calibration
from crosssection.stages.graph import split_stacks, stack_graph
from crosssection.stages.skeleton import skeletonize_mask
from crosssection.stages.widths import layer_steps


def stepped_mask(levels, lengths_px, *, h_px=5.0, theta=0.3, bend_px=None, rough_px=0.0,
                 seed=0):
    """A band along a straight (or circular, radius ``bend_px``) centre line whose layer
    count is ``levels[i]`` over ``lengths_px[i]``; each part lies flush with one edge of the
    previous one, alternately the left and the right edge (a Z fold: ``[1, 3, 1]``).

    Returns the mask and, per step, its position along the line (px) and its (row, col)."""
    rng = np.random.default_rng(seed)
    total = float(sum(lengths_px))
    pad = int(3 * max(levels) * h_px + 30)
    size = int(total + 2 * pad) if bend_px is None else int(2 * (bend_px + pad))
    rr, cc = np.mgrid[:size, :size].astype(float)
    if bend_px is None:
        c0 = np.array([size / 2, size / 2]) + rng.uniform(-0.5, 0.5, 2)
        t = np.array([np.sin(theta), np.cos(theta)])
        along = (rr - c0[0]) * t[0] + (cc - c0[1]) * t[1] + total / 2
        perp = -(rr - c0[0]) * t[1] + (cc - c0[1]) * t[0]

        def point(s, q):
            return c0 + t * (s - total / 2) + q * np.array([-t[1], t[0]])
    else:
        c0 = np.array([size / 2, size / 2]) + rng.uniform(-0.5, 0.5, 2)
        ang = np.arctan2(rr - c0[0], cc - c0[1]) + np.pi
        along = ang * bend_px
        perp = np.hypot(rr - c0[0], cc - c0[1]) - bend_px
        assert total < 2 * np.pi * bend_px * 0.9

        def point(s, q):
            a = s / bend_px - np.pi
            return c0 + (bend_px + q) * np.array([np.sin(a), np.cos(a)])
    if rough_px:
        perp = perp + rough_px * cv2.GaussianBlur(rng.normal(size=(size, size)), (0, 0), 3) * 3
    mask = np.zeros((size, size), bool)
    edge_side, off, s0, steps = 1.0, 0.0, 0.0, []
    for i, (n, ell) in enumerate(zip(levels, lengths_px)):
        w = n * h_px
        if i:
            w_prev = levels[i - 1] * h_px
            # flush with the previous part's edge on this side
            off = off + edge_side * (w_prev - w) / 2
            steps.append((s0, point(s0, off)))
            edge_side = -edge_side
        mask |= (along >= s0) & (along < s0 + ell) & (np.abs(perp - off) <= w / 2)
        s0 += ell
    return mask, steps


def _graph(mask, h_px=5.0):
    dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    skel = skeletonize_mask(mask, l_min_px=10 * h_px, distance_px=dist)
    _, sg, _ = stack_graph(skel, dist, thickness_px=h_px)
    return sg, dist


def _cuts(mask, h_px=5.0):
    sg, dist = _graph(mask, h_px)
    return sg, dist, layer_steps(sg, dist, lambda w: np.asarray(w) / h_px, thickness_px=h_px)


@pytest.mark.parametrize("levels, bend", [([3, 1], None), ([1, 3], None), ([5, 1], None),
                                          ([2, 1], None), ([4, 2], None), ([3, 1], 260.0),
                                          ([1, 6], 300.0)])
def test_one_step_is_found_where_the_width_steps(levels, bend):
    h = 5.0
    mask, steps = stepped_mask(levels, [260.0, 260.0], h_px=h, bend_px=bend)
    sg, _, cuts = _cuts(mask, h)
    assert sg.n_stacks == 1
    assert list(cuts) == [0] and len(cuts[0]) == 1
    at = sg.paths[0][cuts[0][0]]
    # within one width of the wider part of where the drawn layers end
    assert np.hypot(*(at - steps[0][1])) <= max(levels) * h


def test_z_fold_gives_two_steps_and_split_stacks_partitions_the_path():
    h = 5.0
    mask, steps = stepped_mask([1, 3, 1], [200.0, 240.0, 200.0], h_px=h)
    sg, _, cuts = _cuts(mask, h)
    assert len(cuts[0]) == 2
    split = split_stacks(sg, cuts)
    assert split.n_stacks == 3 and sg.n_stacks == 1  # the input graph is left as it was
    kinds = sorted(split.node_kind.values())
    assert kinds.count("step") == 2 and kinds.count("end") == 2
    # the parts hold every pixel once, the cut pixels twice, in order
    order = [0, 1, 2] if split.ends[0][1] == split.ends[1][0] else [0, 2, 1]
    joined = np.concatenate([split.paths[order[0]]]
                            + [split.paths[k][1:] for k in order[1:]])
    assert np.array_equal(joined, sg.paths[0])
    assert split.graph.number_of_edges() == 3
    for sid, (u, v) in enumerate(split.ends):
        assert split.graph.has_edge(u, v, key=sid)
    assert abs(split.length_px.sum() - sg.length_px[0]) < 3.0
    for node in (n for n, k in split.node_kind.items() if k == "step"):
        assert min(np.hypot(*(split.node_rc[node] - p)) for _, p in steps) <= 3 * h


@pytest.mark.parametrize("n", [1, 2, 3, 8])
def test_no_step_in_a_rough_band_or_a_short_bulge(n):
    h = 5.0
    mask, _ = stepped_mask([n], [600.0], h_px=h, rough_px=0.6, seed=n)
    assert _cuts(mask, h)[2] == {}
    # a bulge a layer wider than the band but shorter than 3 widths is not a level
    sg, _ = _graph(mask, h)
    mid = sg.paths[0][len(sg.paths[0]) // 2]
    rr, cc = np.mgrid[:mask.shape[0], :mask.shape[1]]
    bulged = mask | (np.hypot(rr - mid[0], cc - mid[1]) <= (n + 1) * h / 2)
    assert _cuts(bulged, h)[2] == {}


@settings(max_examples=15, deadline=None)
@given(n=st.integers(1, 6), theta=st.floats(0.05, 1.5), seed=st.integers(0, 10_000))
def test_a_band_of_one_layer_count_is_never_cut(n, theta, seed):
    h = 4.0
    mask, _ = stepped_mask([n], [500.0], h_px=h, theta=theta, rough_px=0.5, seed=seed)
    assert _cuts(mask, h)[2] == {}


def _scan(mask):
    rgb = np.full(mask.shape + (3,), 245, np.uint8)
    rgb[mask] = (40, 60, 170)
    return rgb


def test_pipeline_counts_each_side_of_a_step():
    """A Z fold drawn at h = 5 px: read with its steps, the rod is the sum over the three
    parts; as one stack (the paper's), the band's two extra layers are lost."""
    h, ell = 5.0, (300.0, 360.0, 300.0)
    mask, _ = stepped_mask([1, 3, 1], list(ell), h_px=h, theta=0.2)
    rgb = _scan(mask)
    cy, cx = (np.asarray(mask.shape) - 1) / 2
    kw = dict(px_per_mm=50.0, thickness_mm=0.1, calibration=Calibration.linear(0.1, n_max=20),
              hole_center_px=(cx, cy), hole_radius_mm=0.5 * max(mask.shape) / 50.0)
    truth_mm = (ell[0] + 3 * ell[1] + ell[2]) / 50.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = analyze(rgb, **kw)
        paper = analyze(rgb, layer_steps=False, **kw)
    assert sorted(res.stacks["n_br"]) == [1, 1, 3]
    assert set(res.stacks["kind"]) == {"step"}
    assert res.summary["n_layer_steps"] == 2
    assert abs(res.summary["rod_length_mm"] / truth_mm - 1) < 0.03
    assert paper.summary["n_layer_steps"] == 0 and len(paper.stacks) == 1
    assert abs(paper.summary["rod_length_mm"] / truth_mm - 1) > 0.2
    assert "specks" not in res.summary["quality"]["codes"]
    # the overlay marks the steps, and says so in its legend only when there are some
    from crosssection.figures import overlay_figure

    def legend(r):
        return [x.get_text() for x in overlay_figure(rgb, r).legends[0].get_texts()]
    assert "layer step" in legend(res) and "layer step" not in legend(paper)


def _rolled_ring(h_px=5.0, radius_px=150.0, size=400):
    """A rolled sheet's cross-section: a ring of 2 layers over half the turn and 3 over the
    other half (the two rod ends lie in the band, at angles 0 and pi), the inner edge whole."""
    rr, cc = np.mgrid[:size, :size].astype(float)
    c = (size - 1) / 2
    r = np.hypot(rr - c, cc - c)
    n = np.where(np.arctan2(rr - c, cc - c) >= 0, 2, 3)
    mask = (r >= radius_px) & (r <= radius_px + n * h_px)
    rod_px = 2 * np.pi * (radius_px + h_px) + 3 * np.pi * (radius_px + 1.5 * h_px)
    return mask, rod_px


def test_a_rolled_ring_is_cut_at_its_two_steps():
    h = 5.0
    mask, rod_px = _rolled_ring(h)
    sg, _, cuts = _cuts(mask, h)
    assert sg.n_stacks == 1 and sg.node_kind[sg.ends[0][0]] == "loop"
    assert len(cuts[0]) == 2
    split = split_stacks(sg, cuts)
    assert "loop" not in split.node_kind.values()
    assert sorted(split.node_kind.values()) == ["step", "step"]
    assert split.n_stacks == 2 and split.ends[0] == split.ends[1][::-1]
    # the arcs hold the ring's pixels once each, the steps twice
    assert sum(len(p) for p in split.paths) == len(sg.paths[0]) - 1 + 2
    assert abs(split.length_px.sum() - sg.length_px[0]) < 3.0
    c = (np.asarray(mask.shape) - 1) / 2
    angles = sorted(np.arctan2(*(split.node_rc[n] - c)) for n in split.node_kind)
    # the steps lie where the outer edge steps: at 0 and at +-pi, within one wide width
    assert min(abs(angles[0] + np.pi), abs(angles[0])) * 150 < 3 * h
    assert min(abs(angles[1] - np.pi), abs(angles[1])) * 150 < 3 * h


def test_pipeline_reads_a_rolled_ring_by_its_two_parts():
    mask, rod_px = _rolled_ring()
    rgb = _scan(mask)
    cy, cx = (np.asarray(mask.shape) - 1) / 2
    kw = dict(px_per_mm=50.0, thickness_mm=0.1, calibration=Calibration.linear(0.1, n_max=20),
              hole_center_px=(cx, cy), hole_radius_mm=0.5 * max(mask.shape) / 50.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = analyze(rgb, **kw)
        paper = analyze(rgb, layer_steps=False, **kw)
    assert sorted(res.stacks["n_br"]) == [2, 3] and set(res.stacks["kind"]) == {"step"}
    assert abs(res.summary["rod_length_mm"] / (rod_px / 50.0) - 1) < 0.03
    assert list(paper.stacks["kind"]) == ["loop"]
    assert abs(paper.summary["rod_length_mm"] / (rod_px / 50.0) - 1) > 0.1
