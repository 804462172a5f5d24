"""The faster ways of the pipeline's stages give what the plain ways give.

Each test sets a stage's faster computation against the plain one it replaced (kept here as
the reference when it is short), on random inputs and generated scans.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from crosssection.stages import graph as gr
from crosssection.stages import hole as hs
from crosssection.stages import voids as vd
from crosssection.stages.junctions import find_junctions
from crosssection.stages.skeleton import nonzero_rc, skeletonize_mask


@pytest.fixture(scope="module")
def scene_skeleton():
    """Mask, skeleton and distance transform of a generated scan."""
    from crosssection.stages.clean import clean_mask
    from crosssection.stages.threshold import threshold_rgb
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=4, n_stacks=50, max_layers=5, noise_sigma=4.0, specks=5)
    h = sc.params["thickness_mm"] * sc.params["px_per_mm"]
    mask = clean_mask(threshold_rgb(sc.rgb).mask, s_min_px=(10 * h) ** 2, speck_px=10 * h * h)
    skel = skeletonize_mask(mask, l_min_px=10 * h)
    dist = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return sc, mask, skel, dist, h


def _random_skeleton(rng, shape=(60, 70)):
    m = rng.random(shape) < 0.5
    m = cv2.morphologyEx(m.view(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    return skeletonize_mask(m.view(bool), l_min_px=float(rng.choice([0, 3, 8])))


# ----------------------------------------------------------------------------- skeleton
def test_nonzero_rc_is_raster_order_nonzero():
    rng = np.random.default_rng(0)
    for _ in range(50):
        img = (rng.random((int(rng.integers(1, 80)), int(rng.integers(1, 80)))) < 0.1)
        img = img * rng.integers(1, 256, img.shape)
        for a in (img.astype(np.uint8), img.astype(bool), img.astype(np.uint8)[::2, 1::3]):
            r, c = nonzero_rc(a)
            rr, cc = np.nonzero(a)
            assert r.dtype == c.dtype == np.int64
            assert np.array_equal(r, rr) and np.array_equal(c, cc)
    r, c = nonzero_rc(np.zeros((5, 7), np.uint8))
    assert r.shape == c.shape == (0,)


# ----------------------------------------------------------------------------- graph
def _stack_lengths_plain(paths, u_rc, v_rc, is_loop, window_px):
    """The assembly the scatter replaced: one array per path, stacked."""
    from crosssection.core import polyline

    pts, offs = [], [0]
    for i, p in enumerate(paths):
        q = p.astype(np.float64) if is_loop[i] else np.vstack([u_rc[i], p, v_rc[i]])
        pts.append(q)
        offs.append(offs[-1] + len(q))
    return polyline.smoothed_lengths(np.vstack(pts), np.asarray(offs), is_loop,
                                     window_px=window_px)


def test_graph_paths_and_lengths(scene_skeleton):
    _sc, _mask, skel, dist, h = scene_skeleton
    junc, sg, _merged = gr.stack_graph(skel, dist, thickness_px=h)
    assert sg.n_stacks > 20
    # a path is its own (P, 2) int64 array of skeleton pixels
    for p in sg.paths:
        assert p.dtype == np.int64 and p.ndim == 2 and p.shape[1] == 2 and p.flags.c_contiguous
        assert skel[p[:, 0], p[:, 1]].all()
    # the graph's lengths are those of the fork-to-fork paths (before the junctions move)
    g0 = gr.build_stack_graph(skel, find_junctions(skel))
    is_loop = np.array([g0.node_kind[u] == "loop" for u, _ in g0.ends])
    u_rc = np.array([g0.node_rc[u] for u, _ in g0.ends])
    v_rc = np.array([g0.node_rc[v] for _, v in g0.ends])
    assert np.array_equal(g0.length_px, _stack_lengths_plain(g0.paths, u_rc, v_rc, is_loop, 5))
    assert [d["stack_id"] for *_, d in g0.graph.edges(keys=True, data=True)] == \
        sorted(d["stack_id"] for *_, d in g0.graph.edges(keys=True, data=True))
    # junction radius: the largest distance over each junction's pixels
    want = np.array([float(dist[p[:, 0], p[:, 1]].max()) for p in junc.pixels])
    assert np.array_equal(gr._junction_radius(junc, dist), want)


def test_graph_on_random_skeletons_is_consistent():
    rng = np.random.default_rng(2)
    for _ in range(60):
        skel = _random_skeleton(rng)
        dd = cv2.distanceTransform(skel.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        junc, sg, _ = gr.stack_graph(skel, dd + 1.0, thickness_px=2.0)
        covered = junc.label_image > 0
        for sid, p in enumerate(sg.paths):
            covered[p[:, 0], p[:, 1]] = True
            u, v = sg.ends[sid]
            assert sg.graph.has_edge(u, v, key=sid)
        # every skeleton pixel with a neighbour lies on some stack or junction
        lonely = cv2.filter2D(skel.view(np.uint8), -1, np.ones((3, 3), np.float32),
                              borderType=cv2.BORDER_CONSTANT) == 1
        assert np.array_equal(covered | (skel & lonely), skel)


# ----------------------------------------------------------------------------- voids
def _count_junctions_plain(borders, jc, touch_px):
    from scipy.spatial import cKDTree

    counts = np.zeros(len(borders), np.int64)
    pts = np.concatenate(borders).astype(np.float64)
    vid = np.repeat(np.arange(len(borders)), [len(b) for b in borders])
    for hit in cKDTree(pts).query_ball_point(jc, touch_px):
        if hit:
            counts[np.unique(vid[hit])] += 1
    return counts


def test_count_junctions_matches_per_junction_count():
    rng = np.random.default_rng(3)
    for _ in range(40):
        borders = [rng.integers(0, 200, (int(rng.integers(1, 60)), 2)) for _ in range(8)]
        jc = rng.uniform(-10, 210, (int(rng.integers(1, 30)), 2))
        for touch in (0.0, 1.0, 4.5, 12.0, 500.0):
            assert np.array_equal(vd._count_junctions(borders, jc, touch),
                                  _count_junctions_plain(borders, jc, touch))
    assert np.array_equal(vd._count_junctions([np.array([[5, 5]])], np.array([[50.0, 50.0]]),
                                              3.0), [0])


def _void_areas_plain(mask, hole, s_min_px):
    """Areas, in raster order of the first pixel, of the 4-connected background components
    off the image's edge, inside the circle and of area >= s_min."""
    from scipy import ndimage as ndi

    lab, n = ndi.label(~mask)
    edge = set(np.unique(np.r_[lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    rr, cc = np.indices(mask.shape)
    out = (rr - hole.center_rc[0]) ** 2 + (cc - hole.center_rc[1]) ** 2 > hole.radius_px ** 2
    outside = set(np.unique(lab[out]))
    first = {}
    for k, idx in zip(lab.ravel(), range(lab.size)):
        if k and k not in first:
            first[k] = idx
    areas = np.bincount(lab.ravel(), minlength=n + 1)
    keep = [k for k in range(1, n + 1) if k not in edge and k not in outside
            and areas[k] >= s_min_px]
    return [int(areas[k]) for k in sorted(keep, key=first.get)]


def test_voids_near_the_wall():
    # cells cut by the circle at every angle: the box test leaves the border test to them
    rng = np.random.default_rng(4)
    for _ in range(12):
        m = np.zeros((160, 170), bool)
        m[::int(rng.integers(9, 16))] = True
        m[:, ::int(rng.integers(9, 16))] = True
        m[rng.random(m.shape) < 0.02] = True
        hole = hs.Hole(np.array(rng.uniform(60, 100, 2)), float(rng.uniform(40, 75)), True)
        v = vd.find_voids(m, hole=hole, s_min_px=20.0, px_per_mm=1.0,
                          junction_centers_rc=np.zeros((0, 2)), touch_px=3.0)
        assert v["area_mm2"].astype(int).tolist() == _void_areas_plain(m, hole, 20.0)


# ----------------------------------------------------------------------------- hole
def _wall_points_plain(rgb, ink_mask, c0, r0, n_rays):
    """The ray sampling with every sector's rays gathered by index (what the slices
    replaced)."""
    H, W = ink_mask.shape
    ang = np.linspace(-np.pi, np.pi, n_rays, endpoint=False)
    rad = np.arange(0.7 * r0, 1.2 * r0 + 10.0, 1.0)
    rr = c0[0] + np.sin(ang)[:, None] * rad[None, :]
    cc = c0[1] + np.cos(ang)[:, None] * rad[None, :]
    valid = (rr >= 0) & (rr <= H - 1) & (cc >= 0) & (cc <= W - 1)
    mc, mr = cc.astype(np.float32), rr.astype(np.float32)
    col = cv2.remap(np.ascontiguousarray(rgb), mc, mr, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE).astype(np.float32)
    col = cv2.blur(col, (3, 3))
    ink = cv2.remap(ink_mask.view(np.uint8), mc, mr, cv2.INTER_NEAREST,
                    borderMode=cv2.BORDER_REPLICATE) > 0
    inner = (rad <= 0.95 * r0)[None, :] & valid & ~ink
    outer = (rad >= 1.06 * r0 + 4.0)[None, :] & valid
    sector = ((ang + np.pi) / (2 * np.pi) * 16).astype(int) % 16
    pts = []
    for s in range(16):
        rays = np.flatnonzero(sector == s)
        if inner[rays].sum() < 20 or outer[rays].sum() < 20:
            continue
        cin = col[rays][inner[rays]]
        lum = cin.sum(axis=1)
        paper = np.median(cin[lum >= np.percentile(lum, 80)], axis=0)
        plate = np.median(col[rays][outer[rays]], axis=0)
        axis = plate - paper
        spread = np.median(np.abs(col[rays][outer[rays]] - plate), axis=0)
        if np.linalg.norm(axis) < max(25.0, 6.0 * np.linalg.norm(spread)) \
                or plate.sum() >= paper.sum():
            continue
        proj = (col[rays] - paper) @ axis / (axis @ axis)
        proj[ink[rays]] = 0.0
        plate_like = (proj >= 0.5) | ~valid[rays]
        n = plate_like.shape[1]
        j = n - 1 - np.argmax(~plate_like[:, ::-1], axis=1)
        ok = (~plate_like).any(axis=1) & (j < n - 1)
        ok &= valid[rays, np.minimum(j + 1, n - 1)] & (valid[rays].sum(axis=1) > n // 2)
        i = np.flatnonzero(ok)
        j = j[ok]
        p0, p1 = proj[i, j], proj[i, j + 1]
        f = np.clip((0.5 - p0) / np.maximum(p1 - p0, 1e-6), 0.0, 1.0)
        f[ink[rays[i], j]] = 0.5
        rw = rad[j] + f  # samples 1 px apart
        a = ang[rays[i]]
        pts.append(np.column_stack([c0[0] + np.sin(a) * rw, c0[1] + np.cos(a) * rw]))
    return np.concatenate(pts) if pts else np.zeros((0, 2))


@pytest.mark.parametrize("seed", [1, 2])
def test_wall_points_and_hole_on_a_plate(seed):
    from crosssection.stages.threshold import threshold_rgb
    from crosssection.truth.backdrop import apply_backdrop
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=seed, n_stacks=40, max_layers=5, noise_sigma=4.0)
    p = sc.params
    cx, cy = p["hole_center_px"]
    r = p["hole_radius_mm"] * p["px_per_mm"]
    rgb = apply_backdrop(sc.rgb, ink_mask=np.zeros(sc.rgb.shape[:2], bool),
                         hole_center_rc=(cy, cx), hole_radius_px=r,
                         rng=np.random.default_rng(seed), plate="grey", illumination=0.1,
                         cast=0.04)
    ink = threshold_rgb(rgb).mask
    hole = hs.find_hole(rgb, ink)
    assert hole.confidence > 0.5 and abs(hole.radius_px - r) < 3
    # around the ink's envelope (a little inside the wall, where the search starts), off
    # centre, and with fewer rays
    for dc, scale, n_rays in [((0.0, 0.0), 0.97, 720), ((3.3, -2.1), 0.95, 500),
                              ((0.0, 0.0), 0.9, 90)]:
        c0 = hole.center_rc + np.asarray(dc)
        got = hs._wall_points(rgb, ink, c0, scale * hole.radius_px, n_rays)
        assert len(got) > 0.5 * n_rays
        assert np.array_equal(got, _wall_points_plain(rgb, ink, c0, scale * hole.radius_px,
                                                      n_rays))


def test_envelope_reach_is_the_farthest_ink_pixel():
    """Without a plate the circle grows to the farthest ink pixel: read on the outer borders,
    it is the distance over all ink pixels."""
    rng = np.random.default_rng(5)
    for it in range(300):
        m = rng.random(tuple(int(v) for v in rng.integers(3, 80, 2))) < rng.uniform(0.05, 0.9)
        if it % 2:
            m = cv2.dilate(m.view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
        if not m.any():
            continue
        c = rng.uniform(-10, 90, 2)
        border = hs._boundary_points(m)
        assert np.sqrt(((border - c) ** 2).sum(axis=1).max()) == \
            np.sqrt(((np.argwhere(m) - c) ** 2).sum(axis=1).max())


def test_classify_regions_per_stack(scene_skeleton):
    sc, _mask, skel, dist, h = scene_skeleton
    junc, sg, _ = gr.stack_graph(skel, dist, thickness_px=h)
    p = sc.params
    cx, cy = p["hole_center_px"]
    rng = np.random.default_rng(6)
    kinds = set()
    for scale in (0.9, 1.0, 1.05):
        hole = hs.Hole(np.array([cy, cx]), scale * p["hole_radius_mm"] * p["px_per_mm"], False)
        tol = rng.uniform(0, 4 * h, sg.n_stacks)
        want = []
        for sid, (u, v) in enumerate(sg.ends):
            if sg.node_kind[u] == "loop":
                d = hole.distance_to_wall(sg.paths[sid]).min()
            else:
                pu = junc.centers_rc[u] if sg.node_kind[u] == "junction" else sg.node_rc[u]
                pv = junc.centers_rc[v] if sg.node_kind[v] == "junction" else sg.node_rc[v]
                d = hole.distance_to_wall(np.vstack([pu, pv])).min()
            want.append("periphery" if d <= tol[sid] else "bulk")
        got = hs.classify_regions(sg, junc.centers_rc, hole, tol_px=tol)
        assert got == want
        kinds.update(got)
    assert kinds == {"periphery", "bulk"}


# ----------------------------------------------------------------------------- threshold, load
def test_foreground_fraction_is_the_mean():
    from crosssection.stages.threshold import threshold_rgb
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=2, n_stacks=20, max_layers=3)
    thr = threshold_rgb(sc.rgb)
    frac = thr.as_summary()["foreground_fraction"]
    assert type(frac) is float and frac == float(thr.mask.mean())


def test_rgb_png_decoded_in_rgb_order(tmp_path):
    from PIL import Image

    from crosssection.stages.load import load_image

    rng = np.random.default_rng(8)
    rgb = rng.integers(0, 256, (37, 53, 3), np.uint8)
    rgb[..., 0] = 255  # red plane saturated: a swapped channel order would show
    Image.fromarray(rgb).save(tmp_path / "rgb.png")
    got = load_image(tmp_path / "rgb.png")
    assert got.dtype == np.uint8 and np.array_equal(got, rgb)
    rgb16 = rng.integers(0, 65536, (37, 53, 3), np.uint16)
    assert cv2.imwrite(str(tmp_path / "rgb16.png"), rgb16[..., ::-1])
    got16 = load_image(tmp_path / "rgb16.png")
    assert got16.dtype == np.uint16 and np.array_equal(got16, rgb16)


# ----------------------------------------------------------------------------- distance
def _random_masks(rng, n):
    """Masks of random pixels, of thick lines (some leaving the image) and nearly full ones."""
    for i in range(n):
        h, w = int(rng.integers(1, 60)), int(rng.integers(1, 60))
        kind = i % 3
        if kind == 0:
            m = rng.random((h, w)) < rng.random()
        elif kind == 1:
            m = np.zeros((h, w), np.uint8)
            for _ in range(4):
                a, b = (tuple(int(v) for v in rng.integers(-10, 70, 2)) for _ in range(2))
                cv2.line(m, a, b, 1, int(rng.integers(1, 15)))
            m = m.view(bool)
        else:
            m = rng.random((h, w)) > 0.01
        yield m if i % 5 else m[:, ::-1]  # and not contiguous


def test_distance_map_is_the_exact_transform():
    from scipy import ndimage

    from crosssection.stages.widths import distance_map

    rng = np.random.default_rng(3)
    for m in _random_masks(rng, 600):
        d = distance_map(m)
        assert d.dtype == np.float32 and d.shape == m.shape
        if m.all():
            continue
        # the exact distances, rounded once to float32
        assert np.array_equal(d, ndimage.distance_transform_edt(m).astype(np.float32))
    assert distance_map(np.zeros((0, 4), bool)).shape == (0, 4)


def test_distance_map_is_correctly_rounded_beyond_4096_px():
    from scipy import ndimage

    from crosssection.stages.widths import distance_map

    # squared distances beyond 2^24 are not float32 numbers: the root is of the exact integer
    m = np.ones((300, 6000), bool)
    m[150, 0] = False
    assert np.array_equal(distance_map(m), ndimage.distance_transform_edt(m).astype(np.float32))


def test_trapezoid_is_numpys():
    from crosssection.stages.branches import _trapezoid

    rng = np.random.default_rng(5)
    for n in (2, 3, 7, 64, 1001):
        y, s = rng.normal(size=n), np.cumsum(rng.uniform(0.1, 2.0, n))
        assert _trapezoid(y, np.diff(s)) == np.trapezoid(y, s)


def test_padded_values_read_the_padded_copy():
    from crosssection.stages.skeleton import _PaddedValues

    rng = np.random.default_rng(6)
    img = rng.uniform(0, 9, (37, 53)).astype(np.float32)
    padded = np.zeros((39, 55), np.float32)
    padded[1:-1, 1:-1] = img
    flat = padded.reshape(-1)
    inside = np.flatnonzero(np.pad(np.ones(img.shape, bool), 1))
    v = _PaddedValues(img)
    assert np.array_equal(v[inside], flat[inside])
    assert all(v[int(p)] == flat[p] for p in inside[::97])
    assert v.max(initial=0.0) == flat.max(initial=0.0)


def test_distance_map_is_opencv_precise_on_a_scan(scene_skeleton):
    from crosssection.stages.widths import distance_map

    _sc, mask, _skel, dist, _h = scene_skeleton
    if mask.size >= 1 << 14 and cv2.getNumThreads() > 1:  # OpenCV's own code (else IPP's)
        assert np.array_equal(distance_map(mask), dist)
    wide = cv2.dilate(mask.view(np.uint8), np.ones((25, 25), np.uint8))  # larger distances
    n = cv2.getNumThreads()
    try:
        cv2.setNumThreads(max(n, 2))
        ref = cv2.distanceTransform(wide, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    finally:
        cv2.setNumThreads(n)
    assert np.array_equal(distance_map(wide.view(bool)), ref)


def test_border_pixels_are_argwhere_on_the_frame():
    from crosssection.pipeline import _border_pixels

    rng = np.random.default_rng(4)
    for _ in range(300):
        m = rng.random(tuple(int(v) for v in rng.integers(1, 9, 2))) < rng.random()
        edge = np.zeros_like(m)
        edge[[0, -1], :] = edge[:, [0, -1]] = True
        got = _border_pixels(m)
        assert got.dtype == np.intp and np.array_equal(got, np.argwhere(m & edge))


# ----------------------------------------------------------------------------- tables, hole
def test_mid_points_are_polyline_mid_points():
    from crosssection import tables as tb
    from crosssection.core.polyline import mid_point

    rng = np.random.default_rng(6)
    for _ in range(300):
        paths = []
        for _ in range(int(rng.integers(0, 6))):
            n = int(rng.integers(0, 30))
            kind = int(rng.integers(0, 3))
            paths.append(rng.integers(0, 50, (n, 2)) if kind == 0 else
                         np.cumsum(rng.integers(-1, 2, (n, 2)), axis=0) if kind == 1 else
                         np.repeat(rng.integers(0, 9, (1, 2)), n, axis=0))
        ref = np.array([mid_point(np.asarray(p, float)) if len(p) else [np.nan, np.nan]
                        for p in paths]).reshape(-1, 2)
        assert np.array_equal(tb._mid_points(paths), ref, equal_nan=True)


def test_outermost_is_the_last_of_each_bin_in_sorted_order():
    rng = np.random.default_rng(7)
    for i in range(300):
        n = int(rng.integers(1, 200))
        pts = (rng.integers(0, 40, (n, 2)).astype(float) if i % 2 else
               rng.normal(size=(n, 2)) * 50)  # ties in distance, or none
        c, n_bins = rng.normal(size=2), int(rng.integers(1, 60))
        d = pts - c
        rad = np.hypot(d[:, 0], d[:, 1])
        b = np.clip(((np.arctan2(d[:, 0], d[:, 1]) + np.pi) / (2 * np.pi) * n_bins)
                    .astype(np.int64), 0, n_bins - 1)
        order = np.lexsort((rad, b))
        sel = order[np.r_[b[order][1:] != b[order][:-1], True]]
        got_pts, got_rad = hs._outermost(pts, c, n_bins)
        assert np.array_equal(got_pts, pts[sel]) and np.array_equal(got_rad, rad[sel])
