"""Stages 1-6 alone, on generated images: load, threshold, clean, skeleton,
junctions, stack graph."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import tifffile
from PIL import Image
from skimage.morphology import skeletonize

from crosssection.stages.clean import clean_mask
from crosssection.core.errors import ImageError, ParameterError
from crosssection.stages.graph import build_stack_graph, path_length_px
from crosssection.stages.load import load_image
from crosssection.stages.junctions import find_junctions, merge_junctions
from crosssection.stages.skeleton import neighbour_count, skeletonize_mask, thin_mask
from crosssection.stages.threshold import threshold_rgb

INK = (40, 70, 190)


def _scene_rgb(rng, size=64, dtype=np.uint8):
    """Paper-white image with a blue band, a grey-blue and a light-blue patch."""
    img = np.full((size, size, 3), 245, np.uint8)
    img[10:20, 5:60] = INK
    img[30:40, 5:30] = (210, 215, 225)   # receding surface
    img[30:40, 35:60] = (160, 185, 240)  # light-blue smear
    noise = rng.integers(-10, 11, img.shape)
    img = np.clip(img.astype(int) + noise, 0, 255).astype(np.uint8)
    if dtype == np.uint16:
        wide = img.astype(np.int64) * 257 + rng.integers(-128, 129, img.shape)
        return np.clip(wide, 0, 65535).astype(np.uint16)
    return img


def _truth_mask(size=64):
    m = np.zeros((size, size), bool)
    m[10:20, 5:60] = True
    return m


# ----------------------------------------------------------------------------- stage 1
@pytest.mark.parametrize("fmt,dtype", [("png", np.uint8), ("png", np.uint16),
                                        ("tif", np.uint8), ("tif", np.uint16)])
def test_load_native_dtype_roundtrip(tmp_path, fmt, dtype):
    rng = np.random.default_rng(hash((fmt, np.dtype(dtype).name)) % 2**32)
    img = _scene_rgb(rng, dtype=dtype)
    p = tmp_path / f"scan.{fmt}"
    if fmt == "png":
        cv2.imwrite(str(p), img[..., ::-1])
    else:
        tifffile.imwrite(p, img)
    out = load_image(p)
    assert out.dtype == dtype
    assert out.shape == img.shape
    np.testing.assert_array_equal(out, img)


def test_load_jpeg_is_rgb_uint8_close(tmp_path):
    img = _scene_rgb(np.random.default_rng(3))
    p = tmp_path / "scan.jpg"
    Image.fromarray(img).save(p, quality=95)
    out = load_image(p)
    assert out.dtype == np.uint8 and out.shape == img.shape
    # channel order kept: the ink stays blue
    assert out[15, 30, 2] > 150 and out[15, 30, 0] < 100


def test_load_rgba_opaque_dropped_transparent_over_white(tmp_path):
    img = _scene_rgb(np.random.default_rng(4))
    rgba = np.dstack([img, np.full(img.shape[:2], 255, np.uint8)])
    p = tmp_path / "opaque.png"
    Image.fromarray(rgba, "RGBA").save(p)
    np.testing.assert_array_equal(load_image(p), img)
    rgba[:5, :5, 3] = 0
    p2 = tmp_path / "transparent.png"
    Image.fromarray(rgba, "RGBA").save(p2)
    out = load_image(p2)
    assert np.all(out[:5, :5] == 255)
    np.testing.assert_array_equal(out[10:, 10:], img[10:, 10:])


def test_load_palette_expanded(tmp_path):
    img = _scene_rgb(np.random.default_rng(5))
    p = tmp_path / "pal.png"
    Image.fromarray(img).quantize(16).save(p)
    out = load_image(p)
    assert out.shape == img.shape and out.dtype == np.uint8
    assert out[15, 30, 2] > out[15, 30, 0] + 80


@pytest.mark.parametrize("kind", ["gray", "tiny", "text", "truncated", "missing", "gray16"])
def test_load_bad_inputs_raise_image_error(tmp_path, kind):
    img = _scene_rgb(np.random.default_rng(6))
    p = tmp_path / f"{kind}.png"
    if kind == "gray":
        Image.fromarray(img[..., 2]).save(p)
    elif kind == "gray16":
        cv2.imwrite(str(p), img[..., 2].astype(np.uint16) * 257)
    elif kind == "tiny":
        Image.fromarray(img[:10, :40]).save(p)
    elif kind == "text":
        p.write_text("this is not an image\n")
    elif kind == "truncated":
        Image.fromarray(img).save(p)
        p.write_bytes(p.read_bytes()[: len(p.read_bytes()) // 2])
    with pytest.raises(ImageError) as exc:
        load_image(p)
    assert p.name in exc.value.one_line()
    assert "\n" not in exc.value.one_line()


# ----------------------------------------------------------------------------- stage 2
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("method", ["auto", "fixed", "otsu"])
def test_threshold_keeps_ink_only(dtype, method):
    rng = np.random.default_rng(7 + (dtype == np.uint16))
    img = _scene_rgb(rng, dtype=dtype)
    res = threshold_rgb(img, method=method)
    np.testing.assert_array_equal(res.mask, _truth_mask())
    assert res.method == method
    scale = 257 if dtype == np.uint16 else 1
    if method == "auto":
        # data-chosen: half way between the ink's red-green level (~70) and the paper's (~250)
        assert 140 * scale < res.rg_max < 180 * scale
    else:
        assert res.rg_max == 130 * scale
    if method == "fixed":
        assert res.blue_min == 100 * scale
    else:
        assert res.dominance_min is not None and res.dominance_min > 0


def test_threshold_user_values_and_validation():
    img = _scene_rgb(np.random.default_rng(8))
    # rg_max below the ink's red/green keeps nothing
    assert not threshold_rgb(img, rg_max=20).mask.any()
    assert not threshold_rgb(img, method="fixed", rg_max=20).mask.any()
    # the paper's rule with loose bounds takes the smear; "auto" treats bounds as extra limits
    loose = threshold_rgb(img, method="fixed", blue_min=50, rg_max=250).mask.sum()
    assert loose > _truth_mask().sum()
    assert threshold_rgb(img, blue_min=50, rg_max=250).mask.sum() < loose
    with pytest.raises(ParameterError):
        threshold_rgb(img, blue_min=300)
    with pytest.raises(ParameterError):
        threshold_rgb(img, method="magic")


# ----------------------------------------------------------------------------- stage 3
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clean_fills_small_voids_keeps_large_removes_specks(seed):
    rng = np.random.default_rng(seed)
    m = np.zeros((200, 200), bool)
    m[20:180, 20:180] = True
    small = int(rng.integers(5, 9))       # void of small^2 px < s_min
    big = int(rng.integers(30, 40))       # void of big^2 px > s_min
    m[40:40 + small, 40:40 + small] = False
    m[100:100 + big, 100:100 + big] = False
    speck_r, speck_c = rng.integers(2, 15, 2)
    m[speck_r:speck_r + 3, speck_c:speck_c + 3] = True  # 9 px speck outside the square
    out = clean_mask(m, s_min_px=400, speck_px=50)
    assert out[40:40 + small, 40:40 + small].all()
    assert not out[100:100 + big, 100:100 + big].any()
    assert not out[:18, :18].any()
    assert out[20:40, 20:180].all()


def test_clean_matches_skimage():
    from skimage.morphology import remove_small_holes, remove_small_objects

    rng = np.random.default_rng(11)
    m = rng.random((120, 120)) < 0.55
    ours = clean_mask(m, s_min_px=10, speck_px=6)
    ref = remove_small_objects(remove_small_holes(m, max_size=9), max_size=5, connectivity=2)
    np.testing.assert_array_equal(ours, ref)


# ----------------------------------------------------------------------------- stage 4
def _draw(shape, lines, width):
    img = np.zeros(shape, np.uint8)
    for (c0, r0), (c1, r1) in lines:
        cv2.line(img, (c0, r0), (c1, r1), 1, width)
    return img.astype(bool)


def _n_components(mask):
    from scipy import ndimage as ndi

    return ndi.label(mask, structure=np.ones((3, 3)))[1]


@pytest.mark.parametrize("seed", range(4))
def test_skeleton_one_pixel_same_topology_close_to_skimage(seed):
    rng = np.random.default_rng(seed)
    lines = [tuple(map(tuple, rng.integers(10, 190, (2, 2)))) for _ in range(5)]
    m = _draw((200, 200), lines, int(rng.integers(3, 12)))
    sk = thin_mask(m)
    from skimage.measure import euler_number

    assert euler_number(sk, connectivity=2) == euler_number(m, connectivity=2)
    assert _n_components(sk) == _n_components(m)
    assert not (sk & ~m).any()
    # one pixel thick: no 2x2 block
    blocks = sk[:-1, :-1] & sk[1:, :-1] & sk[:-1, 1:] & sk[1:, 1:]
    assert not blocks.any()
    # close to scikit-image's skeleton
    ref = skeletonize(m)
    d = cv2.distanceTransform((~ref).view(np.uint8), cv2.DIST_L2, 3)
    assert np.percentile(d[sk], 95) <= 2.0


def test_skeleton_no_redundant_staircase_pixels():
    # an oblique band: Zhang-Suen leaves staircase corners that look like junctions
    rng = np.random.default_rng(12)
    for _ in range(3):
        ang = rng.uniform(0, np.pi)
        c = np.array([100, 100])
        d = np.array([np.cos(ang), np.sin(ang)]) * 80
        m = _draw((200, 200), [(tuple((c - d).astype(int)), tuple((c + d).astype(int)))], 7)
        sk = skeletonize_mask(m, l_min_px=0)
        cnt = neighbour_count(sk)
        assert (cnt[sk] >= 3).sum() == 0
        assert (cnt[sk] == 1).sum() == 2


@pytest.mark.parametrize("spur_len,kept", [(15, False), (70, True)])
def test_spur_pruning(spur_len, kept):
    # a long band with a side branch of given length; l_min = 40 px
    m = _draw((200, 240), [((20, 100), (220, 100))], 7)
    m |= _draw((200, 240), [((120, 100), (120, 100 - spur_len))], 5)
    sk = skeletonize_mask(m, l_min_px=40)
    j = find_junctions(sk)
    assert len(j) == (1 if kept else 0)
    if not kept:
        assert not sk[:92, 110:130].any()
    # the main stack is never shortened to nothing
    assert sk[100, 40:200].sum() > 100


def test_junction_free_segment_never_pruned():
    m = _draw((100, 100), [((20, 50), (40, 50))], 5)  # 20 px long, l_min 50 px
    sk = skeletonize_mask(m, l_min_px=50)
    assert sk.sum() >= 15


# ----------------------------------------------------------------------------- stage 5
@pytest.mark.parametrize("seed", range(3))
def test_y_skeleton_one_junction_degree_3(seed):
    rng = np.random.default_rng(seed)
    c = rng.integers(80, 120, 2)
    angs = rng.uniform(0, 2 * np.pi) + np.array([0, 2.1, 4.2]) + rng.normal(0, 0.1, 3)
    ends = [(int(c[0] + 70 * np.cos(a)), int(c[1] + 70 * np.sin(a))) for a in angs]
    img = np.zeros((200, 200), np.uint8)
    for e in ends:
        cv2.line(img, (int(c[0]), int(c[1])), e, 1, 1)
    sk = skeletonize_mask(img > 0, l_min_px=5)
    j = find_junctions(sk)
    assert len(j) == 1
    assert np.hypot(*(j.centers_rc[0] - c[::-1])) <= 2
    g = build_stack_graph(sk, j)
    assert g.degree(0) == 3
    assert g.n_stacks == 3


@pytest.mark.parametrize("ang_deg", [90, 60, 45])
def test_x_crossing_one_junction_degree_4(ang_deg):
    img = np.zeros((200, 200), np.uint8)
    for a in (0.3, 0.3 + np.radians(ang_deg)):
        d = 80 * np.array([np.cos(a), np.sin(a)])
        cv2.line(img, tuple((100 - d).astype(int)), tuple((100 + d).astype(int)), 1, 1)
    sk = skeletonize_mask(img > 0, l_min_px=5)
    j = find_junctions(sk)
    assert len(j) == 1
    g = build_stack_graph(sk, j)
    assert g.degree(0) == 4


def test_find_junctions_fast_path_matches_convolution():
    rng = np.random.default_rng(13)
    lines = [tuple(map(tuple, rng.integers(5, 295, (2, 2)))) for _ in range(15)]
    sk = thin_mask(_draw((300, 300), lines, 4))
    j = find_junctions(sk, merge_px=0)
    from scipy import ndimage as ndi

    k = np.ones((3, 3), int)
    k[1, 1] = 0
    ref = sk & (ndi.convolve(sk.astype(int), k, mode="constant") >= 3)
    found = j.label_image > 0
    assert (found >= ref).all()
    # extra pixels are bridge pixels: fewer than 3 neighbours, all in one junction
    extra = np.argwhere(found & ~ref)
    for r, c in extra:
        win = j.label_image[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
        nb = sk[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
        assert len(set(win[nb].tolist())) == 1
    lab, n = ndi.label(ref, structure=np.ones((3, 3)))
    assert len(j) <= n and len(j) >= n - len(extra)
    assert len(j) > 5


def test_merge_junctions_combines_ids_and_pixels():
    img = np.zeros((100, 160), np.uint8)
    # two Y junctions 40 px apart joined by a bridge
    cv2.line(img, (40, 50), (120, 50), 1, 1)
    for x in (40, 120):
        cv2.line(img, (x, 50), (x - 20 if x == 40 else x + 20, 20), 1, 1)
        cv2.line(img, (x, 50), (x - 20 if x == 40 else x + 20, 80), 1, 1)
    sk = skeletonize_mask(img > 0, l_min_px=5)
    j = find_junctions(sk)
    assert len(j) == 2
    g = build_stack_graph(sk, j)
    bridge = [s for s, (u, v) in enumerate(g.ends) if {u, v} == {0, 1}]
    assert len(bridge) == 1
    j2 = merge_junctions(j, [g.ends[bridge[0]]], [g.paths[bridge[0]]])
    assert len(j2) == 1
    g2 = build_stack_graph(sk, j2)
    assert g2.degree(0) == 4 and g2.n_stacks == 4
    assert abs(j2.centers_rc[0][1] - 80) < 3


# ----------------------------------------------------------------------------- stage 6
@pytest.mark.parametrize("radius", [25, 40, 60])
def test_ring_is_one_loop_stack(radius):
    img = np.zeros((160, 160), np.uint8)
    cv2.circle(img, (80, 80), radius, 1, 5)
    sk = skeletonize_mask(img > 0, l_min_px=20)
    j = find_junctions(sk)
    g = build_stack_graph(sk, j)
    assert len(j) == 0 and g.n_stacks == 1
    (u, v), = g.ends
    assert u == v and g.node_kind[u] == "loop"
    p = g.paths[0]
    assert (p[0] == p[-1]).all()
    assert abs(g.length_px[0] - 2 * np.pi * radius) / (2 * np.pi * radius) < 0.02


def test_graph_parallel_edges_self_loop_and_free_ends():
    img = np.zeros((200, 260), np.uint8)
    # theta shape: a ring crossed by a diameter -> 2 junctions, 3 parallel stacks
    cv2.circle(img, (70, 100), 50, 1, 1)
    cv2.line(img, (20, 100), (120, 100), 1, 1)
    # a lollipop: a loop at a junction with a long tail ending freely
    cv2.circle(img, (200, 60), 25, 1, 1)
    cv2.line(img, (200, 85), (200, 180), 1, 1)
    sk = skeletonize_mask(img > 0, l_min_px=5)
    j = find_junctions(sk)
    g = build_stack_graph(sk, j)
    assert len(j) == 3
    pairs = sorted(tuple(sorted(e)) for e in g.ends)
    multi = [p for p in set(pairs) if pairs.count(p) == 3]
    assert len(multi) == 1
    selfloops = [e for e in g.ends if e[0] == e[1]]
    assert len(selfloops) == 1
    ends = [n for n, k in g.node_kind.items() if k == "end"]
    assert len(ends) == 1
    # every skeleton pixel is in a junction or a stack path; paths are 8-connected chains
    cover = j.label_image > 0
    for p in g.paths:
        cover[p[:, 0], p[:, 1]] = True
        assert np.abs(np.diff(p, axis=0)).max() <= 1
    assert (cover == sk).all()
    # paths start at their start node (junction pixel or end pixel)
    for (u, v), p in zip(g.ends, g.paths):
        for node, pix in ((u, p[0]), (v, p[-1])):
            if g.node_kind[node] == "junction":
                assert j.label_image[pix[0], pix[1]] == node + 1
            else:
                assert np.allclose(g.node_rc[node], pix)


@pytest.mark.parametrize("ang_deg", [0, 10, 22.5, 30, 45, 67, 80])
def test_path_length_of_oblique_lines(ang_deg):
    a = np.radians(ang_deg)
    n = 200
    pts = np.round(np.stack([np.arange(n) * np.sin(a), np.arange(n) * np.cos(a)], 1))
    pts = pts[np.r_[True, np.any(np.diff(pts, axis=0) != 0, axis=1)]]
    true = np.hypot(*(pts[-1] - pts[0]))
    assert abs(path_length_px(pts) - true) / true < 0.01


@pytest.mark.parametrize("seed", range(3))
def test_graph_lengths_equal_reference_smoothing(seed):
    rng = np.random.default_rng(100 + seed)
    lines = [tuple(map(tuple, rng.integers(5, 195, (2, 2)))) for _ in range(6)]
    img = _draw((200, 200), lines, 5).astype(np.uint8)
    cv2.circle(img, tuple(map(int, rng.integers(50, 150, 2))), int(rng.integers(15, 40)), 1, 3)
    sk = skeletonize_mask(img > 0, l_min_px=10)
    g = build_stack_graph(sk, find_junctions(sk))
    assert g.n_stacks > 3
    for sid, ((u, v), p) in enumerate(zip(g.ends, g.paths)):
        if g.node_kind[u] == "loop":
            ref = path_length_px(p, closed=True)
        else:
            ref = path_length_px(np.vstack([g.node_rc[u], p, g.node_rc[v]]))
        assert abs(g.length_px[sid] - ref) < 1e-9 * max(ref, 1.0)
