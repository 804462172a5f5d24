"""Stages 12-13: hole fit, bulk/periphery classification, voids (crosssection.stages.hole, .voids)."""
from __future__ import annotations

from dataclasses import dataclass, field

import networkx as nx
import numpy as np
import pytest
from skimage.draw import polygon

from crosssection.core.errors import AnalysisError
from crosssection.stages.hole import (Hole, classify_regions, fit_hole, kasa_fit,
                                     wall_gap_max_px, wall_gaps_px, wall_tolerance_px)
from crosssection.core.schema import VOID_COLUMNS
from crosssection.stages.voids import contour_perimeter_px, find_voids, void_labels

H = 5.0


@dataclass
class FakeGraph:
    """StackGraph-shaped stand-in (docs/design.md) until crosssection.stages.graph exists."""
    graph: nx.MultiGraph
    node_rc: dict
    node_kind: dict
    paths: list
    ends: list = field(default_factory=list)


def _make_graph(nodes, kinds, edges):
    g = nx.MultiGraph()
    paths, ends = [], []
    for sid, (u, v) in enumerate(edges):
        g.add_edge(u, v, stack_id=sid)
        a, b = np.asarray(nodes[u]), np.asarray(nodes[v])
        t = np.linspace(0, 1, 20)[:, None]
        paths.append(np.round(a + t * (b - a)).astype(int))
        ends.append((u, v))
    return FakeGraph(g, {k: np.asarray(v, float) for k, v in nodes.items()}, kinds, paths, ends)


def _walled_scene(seed, size=600):
    """Ink ring pressed against a wall of radius R (outer edge), with gaps, plus chords."""
    rng = np.random.default_rng(seed)
    R = rng.uniform(200, 270)
    c = np.array([size / 2, size / 2]) + rng.uniform(-20, 20, 2)
    rr, cc = np.mgrid[0:size, 0:size]
    d = np.hypot(rr - c[0], cc - c[1])
    ang = np.arctan2(rr - c[0], cc - c[1])
    ring = (d <= R) & (d >= R - rng.uniform(H, 3 * H))
    # gaps: a few angular sectors where the rod leaves the wall (about 30 % of the circle)
    for _ in range(4):
        a0 = rng.uniform(-np.pi, np.pi)
        w = rng.uniform(0.2, 0.6)
        ring &= ~(np.mod(ang - a0, 2 * np.pi) < w)
    mask = ring.copy()
    # chords inside, not reaching the wall
    for _ in range(5):
        p, q = rng.uniform(-0.7, 0.7, (2, 2)) * R + c
        t = np.linspace(0, 1, 400)[:, None]
        pts = np.round(p + t * (q - p)).astype(int)
        for dr in range(-2, 3):
            for dc in range(-2, 3):
                mask[pts[:, 0] + dr, pts[:, 1] + dc] = True
    return mask, c, R


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_fit_hole_envelope_with_gaps(seed):
    mask, c, R = _walled_scene(seed)
    hole = fit_hole(mask)
    assert hole.fitted
    assert np.hypot(*(hole.center_rc - c)) < 1.0
    assert abs(hole.radius_px - R) < 1.0
    # partially given parameters
    h2 = fit_hole(mask, center_rc=c)
    assert abs(h2.radius_px - R) < 1.0 and np.allclose(h2.center_rc, c)
    h3 = fit_hole(mask, radius_px=R)
    assert np.hypot(*(h3.center_rc - c)) < 1.0 and h3.radius_px == R
    h4 = fit_hole(mask, center_rc=c, radius_px=R)
    assert not h4.fitted


def test_fit_hole_empty_and_kasa():
    with pytest.raises(AnalysisError):
        fit_hole(np.zeros((30, 30), bool))
    t = np.linspace(0, 2, 50)
    c, r = kasa_fit(np.c_[3 + 7 * np.sin(t), -2 + 7 * np.cos(t)])
    assert np.allclose(c, [3, -2]) and r == pytest.approx(7)


def test_classify_regions_by_end_junctions():
    hole = Hole(np.array([100.0, 100.0]), 80.0, False)
    nodes = {0: (100, 100), 1: (100, 23), 2: (60, 100), 3: (100, 150), 4: (30, 130),
             5: (100, 177.5)}
    kinds = {0: "junction", 1: "junction", 2: "junction", 3: "junction", 4: "end", 5: "loop"}
    jc = np.array([nodes[i] for i in range(4)], float)
    # stack 0: centre - wall junction -> periphery; 1: centre - inner; 2: inner - inner
    # 3: inner - free end near the wall (distance 80 - 76.2 = 3.8) -> periphery
    # 4: loop node whose path runs along the wall
    g = _make_graph(nodes, kinds, [(0, 1), (0, 2), (2, 3), (2, 4), (5, 5)])
    g.paths[4] = np.array([[100 + 77 * np.sin(a), 100 + 77 * np.cos(a)]
                           for a in np.linspace(0, 2 * np.pi, 100)]).astype(int)
    reg = classify_regions(g, jc, hole, tol_px=5.0)
    assert reg == ["periphery", "bulk", "bulk", "periphery", "periphery"]
    # tolerance per stack: tighter on stack 0 makes it bulk (junction 3 px inside the wall)
    reg2 = classify_regions(g, jc, hole, tol_px=np.array([2.0, 5, 5, 5, 5]))
    assert reg2[0] == "bulk"
    assert classify_regions(g, jc, None, tol_px=5) == ["bulk"] * 5
    tol = wall_tolerance_px(g, np.array([10.0, 4, 4, 6, 5]), H)
    assert tol[0] == pytest.approx(0.5 * 10 + 2 * H)
    assert tol[2] == pytest.approx(0.5 * 6 + 2 * H)   # node 2 meets stacks 1, 2, 3


def _inset_ring_scene(gap_px, size=500, R=220.0, ring_w=2 * H, arm_w=1.4 * H):
    """A wall band lining half the circle ``gap_px`` inside it, four radial arms from a
    central junction: two end on the band, two (on the other half) in the open."""
    c = np.array([size / 2, size / 2])
    rr, cc = np.mgrid[0:size, 0:size]
    d = np.hypot(rr - c[0], cc - c[1])
    ang = np.arctan2(rr - c[0], cc - c[1])
    r_mid = R - gap_px - ring_w / 2
    mask = (np.abs(d - r_mid) <= ring_w / 2) & (ang < 0)
    nodes = {0: tuple(c)}
    edges = []
    for k, a in enumerate((-2.0, -1.0, 1.0, 2.0)):
        end_r = r_mid if a < 0 else R - 12 * H
        u = np.array([np.sin(a), np.cos(a)])
        t = (rr - c[0]) * u[0] + (cc - c[1]) * u[1]
        off = np.abs(-(rr - c[0]) * u[1] + (cc - c[1]) * u[0])
        mask |= (t >= 0) & (t <= end_r) & (off <= arm_w / 2)
        nodes[k + 1] = tuple(c + end_r * u)
        edges.append((0, k + 1))
    kinds = {i: "junction" for i in nodes}
    g = _make_graph(nodes, kinds, edges)
    return mask, g, np.array([nodes[i] for i in range(len(nodes))], float), Hole(c, R, False)


#: The widest gap not counted in a scan whose widest stack is 8 h wide (6 h).
GAP_MAX = wall_gap_max_px(np.array([8 * H, 2 * H, np.nan]), H)


def test_wall_gap_max_px():
    assert GAP_MAX == pytest.approx(6 * H)
    assert wall_gap_max_px(np.array([np.nan]), H) == pytest.approx(2 * H)


@pytest.mark.parametrize("gap_h", [0.0, 1.5, 3.0, 5.5])
def test_periphery_across_a_gap_between_wall_band_and_wall(gap_h):
    # a wall band lying a few sheet thicknesses inside the circle (a hole given a little wide,
    # or a band whose thin stretches lie inside its widest one): the arms ending on it touch
    # the wall, the arms ending in the open do not
    mask, g, jc, hole = _inset_ring_scene(gap_h * H)
    tol = wall_tolerance_px(g, np.full(4, 2 * H), H)
    reg = classify_regions(g, jc, hole, tol_px=tol, mask=mask, gap_max_px=GAP_MAX)
    assert reg == ["periphery", "periphery", "bulk", "bulk"]
    # measured to the circle alone, a gap beyond the tolerance's 2 h reads the band as bulk
    alone = classify_regions(g, jc, hole, tol_px=tol)
    assert alone[:2] == (["periphery"] * 2 if gap_h <= 1.5 else ["bulk"] * 2)


def test_a_gap_wider_than_its_limit_is_distance():
    mask, g, jc, hole = _inset_ring_scene(1.2 * GAP_MAX)
    tol = wall_tolerance_px(g, np.full(4, 2 * H), H)
    reg = classify_regions(g, jc, hole, tol_px=tol, mask=mask, gap_max_px=GAP_MAX)
    assert reg == ["bulk"] * 4


def test_wall_gaps_px_reads_the_outermost_ink_on_each_ray():
    mask, g, jc, hole = _inset_ring_scene(4 * H)
    gaps = wall_gaps_px(mask, hole, jc[1:], reach_px=10 * H)
    # arms 1-2 end on the band, whose outer edge lies 4 h inside the wall (to the half pixel)
    assert np.allclose(gaps[:2], 4 * H, atol=1.0)
    # arms 3-4 end 12 h inside the wall with paper beyond: no ink within the reach
    assert np.all(np.isinf(gaps[2:]))
    # read from 3 px inside the open arms' ends: their own ink is the outermost, 12 h inside
    inner = jc[3:] - 3 * (jc[3:] - jc[0]) / np.linalg.norm(jc[3:] - jc[0], axis=1)[:, None]
    assert np.isinf(wall_gaps_px(mask, hole, inner, reach_px=11 * H)).all()
    assert wall_gaps_px(mask, hole, inner, reach_px=14 * H) == pytest.approx([12 * H] * 2,
                                                                            abs=1.0)
    assert wall_gaps_px(mask, hole, np.zeros((0, 2)), reach_px=H).shape == (0,)


def _teardrop(n=2000, scale=60.0, m=2):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    x = scale * np.sin(t / 2) ** m * np.sin(t)
    y = scale * np.cos(t)
    return np.c_[y, x]


def _shape_cases(rng):
    cases = []
    r = rng.uniform(28, 90)
    t = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    cases.append(("disk", np.c_[r * np.sin(t), r * np.cos(t)]))
    a = rng.uniform(50, 150)
    th = rng.uniform(0, np.pi / 2)
    sq = np.array([[-1, -1], [-1, 1], [1, 1], [1, -1]]) * a / 2
    rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    cases.append(("square", sq @ rot.T))
    cases.append(("teardrop", _teardrop(scale=rng.uniform(50, 90))))
    return cases


def _poly_area_perimeter(v):
    x, y = v[:, 1], v[:, 0]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    per = np.hypot(*np.diff(np.vstack([v, v[:1]]), axis=0).T).sum()
    return area, per


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_void_area_perimeter_shape(seed):
    rng = np.random.default_rng(seed)
    s_min = (10 * H) ** 2
    for name, verts in _shape_cases(rng):
        size = 400
        c = np.array([size / 2, size / 2]) + rng.uniform(-0.5, 0.5, 2)
        v = verts + c
        mask = np.ones((size, size), bool)
        rr, cc = polygon(v[:, 0], v[:, 1], mask.shape)
        mask[rr, cc] = False
        hole = Hole(np.array([size / 2, size / 2]), size / 2 - 2, False)
        area, per = _poly_area_perimeter(v)
        df = find_voids(mask, hole=hole, s_min_px=s_min, px_per_mm=50.0,
                        junction_centers_rc=np.zeros((0, 2)), touch_px=5)
        assert list(df.columns) == VOID_COLUMNS
        assert len(df) == 1, name
        row = df.iloc[0]
        assert row.area_mm2 * 2500 == pytest.approx(area, rel=0.02), name
        assert row.perimeter_mm * 50 == pytest.approx(per, rel=0.03), name
        assert row.centroid_y_px == pytest.approx(rr.mean(), abs=1e-6)
        assert row.centroid_x_px == pytest.approx(cc.mean(), abs=1e-6)
        if name == "disk":
            assert row.shape_ratio == pytest.approx(1 / (2 * np.sqrt(np.pi)), rel=0.02)


def test_voids_exclusions_and_edges():
    """Outside background and small or border-touching regions are not voids; junctions
    near a void's contour are counted."""
    size = 300
    mask = np.zeros((size, size), bool)
    rr, cc = np.mgrid[0:size, 0:size]
    c = np.array([150.0, 150.0])
    d = np.hypot(rr - c[0], cc - c[1])
    mask |= (d <= 120) & (d >= 110)                 # closed ring at the wall
    mask[145:156, 30:270] = True                    # a diameter: two half-disk voids
    mask[60:64, 140:144] = False                    # too small: not a void (but inside ink)
    hole = Hole(c, 120.0, False)
    s_min = 2500
    # a junction where the diameter meets the ring on the left, one in the middle of nowhere
    jc = np.array([[150.0, 35.0], [150.0, 265.0], [20.0, 20.0]])
    df = find_voids(mask, hole=hole, s_min_px=s_min, px_per_mm=50, junction_centers_rc=jc,
                    touch_px=12)
    assert len(df) == 2
    assert np.all(df.n_edges == 2)
    half = np.pi * 110**2 / 2 - 110 * 5.5 * 2
    assert np.allclose(df.area_mm2 * 2500, half, rtol=0.03)
    # an opening in the ring connects the lower void to the outside: excluded by default,
    # kept with wall_voids=True
    mask2 = mask.copy()
    mask2[255:275, 145:156] = False
    df2 = find_voids(mask2, hole=hole, s_min_px=s_min, px_per_mm=50, junction_centers_rc=jc,
                     touch_px=12)
    assert len(df2) == 1
    df3 = find_voids(mask2, hole=hole, s_min_px=s_min, px_per_mm=50, junction_centers_rc=jc,
                     touch_px=12, wall_voids=True)
    assert len(df3) == 2
    # no hole: only the border bounds the background
    df4 = find_voids(mask, hole=None, s_min_px=s_min, px_per_mm=50, junction_centers_rc=jc,
                     touch_px=12)
    assert len(df4) == 2
    empty = find_voids(np.ones((50, 50), bool), hole=None, s_min_px=10, px_per_mm=50,
                       junction_centers_rc=jc, touch_px=3)
    assert len(empty) == 0 and list(empty.columns) == VOID_COLUMNS


def test_contour_perimeter_square_axis_aligned():
    sq = np.zeros((120, 120), bool)
    sq[10:110, 10:110] = True
    assert contour_perimeter_px(sq) == pytest.approx(400, rel=0.02)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_voids_match_labelling_reference(seed):
    """The contour-based void extraction equals a plain 4-connected labelling of the
    background (areas, centroids, order) on random ink textures with islands, spurs and
    diagonal pinches; junction counts equal a brute-force distance check."""
    from scipy import ndimage as ndi

    rng = np.random.default_rng(seed)
    size = 300
    field = ndi.gaussian_filter(rng.normal(size=(size, size)), rng.uniform(2, 5))
    mask = field > -rng.uniform(0.4, 0.6) * field.std()
    mask |= rng.random((size, size)) < 0.01            # isolated ink pixels (islands, spurs)
    hole = Hole(np.array([150.0, 150.0]) + rng.uniform(-5, 5, 2), rng.uniform(100, 140), False)
    s_min = 30
    lab, n = ndi.label(~mask)
    rr, cc = np.mgrid[0:size, 0:size]
    outside = (rr - hole.center_rc[0]) ** 2 + (cc - hole.center_rc[1]) ** 2 > hole.radius_px ** 2
    bad = set(np.unique(lab[outside & ~mask])) | set(np.unique(lab[0])) | \
        set(np.unique(lab[-1])) | set(np.unique(lab[:, 0])) | set(np.unique(lab[:, -1]))
    ref = [i for i in range(1, n + 1) if i not in bad and (lab == i).sum() >= s_min]
    jc = rng.uniform(20, 280, (30, 2))
    df = find_voids(mask, hole=hole, s_min_px=s_min, px_per_mm=50.0, junction_centers_rc=jc,
                    touch_px=6.0)
    assert len(df) == len(ref) > 5
    for row, i in zip(df.itertuples(), ref):
        pr, pc = np.nonzero(lab == i)
        assert row.area_mm2 * 2500 == pytest.approx(len(pr))
        assert row.centroid_y_px == pytest.approx(pr.mean(), abs=1e-9)
        assert row.centroid_x_px == pytest.approx(pc.mean(), abs=1e-9)
        d2 = (pr[None, :] - jc[:, :1]) ** 2 + (pc[None, :] - jc[:, 1:]) ** 2
        assert row.n_edges == int((d2.min(axis=1) <= 36.0).sum())
    vl = void_labels(mask, hole=hole, s_min_px=s_min)
    assert vl.max() == len(ref)
    assert all(np.array_equal(vl == j + 1, lab == i) for j, i in enumerate(ref))


def test_junction_count_equals_a_kd_tree_ball_query():
    """The compiled count of junctions near each void's border equals the distinct
    (junction, void) pairs of a KD-tree ball query (distance <= touch), on random borders
    with junctions at exactly ``touch`` from border pixels and a hair either side."""
    from scipy.spatial import cKDTree

    from crosssection.stages.voids import _count_junctions

    rng = np.random.default_rng(11)
    for trial in range(300):
        borders = [rng.integers(0, 80, (int(rng.integers(1, 60)), 2))
                   for _ in range(int(rng.integers(1, 8)))]
        touch = float(rng.choice([1.0, 2.5, 5.0, np.sqrt(50.0), 13.0]))
        jc = rng.uniform(-10, 90, (int(rng.integers(1, 25)), 2))
        if trial % 2:  # on the circle of radius touch around a border pixel, or just off it
            p = borders[0][0].astype(float)
            ang = rng.uniform(0, 2 * np.pi, 3)
            ring = p + touch * np.column_stack([np.cos(ang), np.sin(ang)])
            jc = np.vstack([jc, ring, np.nextafter(ring, ring + 1), p + [3.0, 4.0]])
            touch = 5.0 if trial % 4 == 1 else touch
        pts = np.concatenate(borders).astype(float)
        vid = np.repeat(np.arange(len(borders)), [len(b) for b in borders])
        hits = cKDTree(pts).query_ball_point(jc, touch)
        want = np.zeros(len(borders), np.int64)
        for v in {(j, int(vid[i])) for j, h in enumerate(hits) for i in h}:
            want[v[1]] += 1
        np.testing.assert_array_equal(_count_junctions(borders, jc, touch), want)
    assert len(_count_junctions(borders, np.zeros((0, 2)), 5.0)) == len(borders)


def _pieces_scene(seed, size=260, ink_in_holes=True):
    """Ink rings (voids inside), islands in them (some with holes, and with
    ``ink_in_holes`` some holding ink in their holes), rings crossing rings, and pieces on
    the open paper."""
    import cv2

    rng = np.random.default_rng(seed)
    img = np.zeros((size, size), np.uint8)
    for _ in range(rng.integers(3, 7)):
        c = tuple(int(v) for v in rng.integers(30, size - 30, 2))
        r = int(rng.integers(14, 40))
        cv2.circle(img, c, r, 1, int(rng.integers(1, 4)))
        for _ in range(rng.integers(0, 4)):  # pieces inside the ring
            dc = rng.normal(0, 0.35 * r, 2).astype(int)
            p = (c[0] + int(dc[0]), c[1] + int(dc[1]))
            kind = rng.integers(0, 3 if ink_in_holes else 2)
            if kind == 0:
                cv2.circle(img, p, int(rng.integers(1, 4)), 1, -1)
            elif kind == 1:  # a piece with a hole
                cv2.circle(img, p, int(rng.integers(4, 8)), 1, 1)
            else:  # a piece whose hole holds ink
                cv2.circle(img, p, 7, 1, 1)
                img[p[1], p[0]] = 1
    for _ in range(rng.integers(0, 6)):  # pieces on the open paper
        img[tuple(rng.integers(0, size, 2))] = 1
    return img.astype(bool)


@pytest.mark.parametrize("seed", range(40))
def test_voids_read_again_where_pieces_are_removed_equal_a_new_scan(seed):
    """The pipeline scans the voids before the skeleton drops isolated pieces of ink from the
    mask, then reads again only the voids that held them (:func:`without_pieces`): every
    number is the new mask's scan, to the bit, whichever pieces go (in a void, on the open
    paper, with holes, with ink in their holes, in another piece's hole), with or without
    the hole's circle."""
    import cv2

    from crosssection.stages.voids import scan_voids, without_pieces

    mask = _pieces_scene(seed, ink_in_holes=seed % 4 == 0)
    rng = np.random.default_rng(1000 + seed)
    n, lab = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
    gone = [k for k in range(1, n) if rng.random() < 0.5]
    seeds = []
    after = mask.copy()
    for k in gone:
        rr, cc = np.nonzero(lab == k)
        j = int(rng.integers(len(rr)))
        seeds.append((int(rr[j]), int(cc[j])))
        after[lab == k] = False
    hole = Hole(np.array([130.0, 128.0]), 118.0, True) if seed % 2 else None
    for s_min in (0.0, 30.0):
        for wall in ((False, True) if hole is not None else (False,)):
            before = scan_voids(mask, hole=hole, s_min_px=s_min, wall_voids=wall)
            got = without_pieces(before, after, seeds)
            want = scan_voids(after, hole=hole, s_min_px=s_min, wall_voids=wall)
            for name in ("area_px", "perimeter_px", "centroid_rc"):
                np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
            assert len(got.borders_rc) == len(want.borders_rc)
            for a, b in zip(got.borders_rc, want.borders_rc):
                np.testing.assert_array_equal(a, b)


def test_voids_are_read_again_only_where_a_piece_lay(monkeypatch):
    """Pieces in voids and on the open paper, none with ink in its holes: the voids are
    read again from their borders, the mask is not scanned again."""
    import cv2

    from crosssection.stages import voids as V

    changed = 0
    for seed in range(12):
        mask = _pieces_scene(seed, ink_in_holes=False)
        n, lab = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
        sizes = np.bincount(lab.ravel())
        gone = [k for k in range(1, n) if sizes[k] < 80]  # the pieces, not the rings
        after = mask & ~np.isin(lab, gone)
        seeds = [tuple(int(v) for v in np.argwhere(lab == k)[0]) for k in gone]
        before = V.scan_voids(mask, hole=None, s_min_px=0.0)
        want = V.scan_voids(after, hole=None, s_min_px=0.0)
        with monkeypatch.context() as m:
            m.setattr(V, "scan_voids", lambda *a, **k: pytest.fail("scanned again"))
            got = V.without_pieces(before, after, seeds)
        np.testing.assert_array_equal(got.area_px, want.area_px)
        np.testing.assert_array_equal(got.perimeter_px, want.perimeter_px)
        changed += not np.array_equal(got.area_px, before.area_px)
    assert changed >= 6
