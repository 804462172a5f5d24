"""Cleaning from the ink's border hierarchy gives the mask that labelling gives.

:func:`crosssection.stages.clean.clean_mask` decides holes and specks from the borders of
``cv2.findContours`` and flood fills, and falls back on labelling the background and the ink
(the way it replaced) when the borders cannot settle a case. The labelling is the reference
here, on random masks of every density and on a generated scan.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from crosssection.stages import clean as cl
from crosssection.stages.clean import clean_mask


def _by_labelling(m, s_min, speck, extent):
    """The labelling way: small background components filled, then small or short ink
    components removed."""
    out = m.copy()
    if s_min > 0:
        out |= cl._small_components((~m).view(np.uint8), 4, s_min)
    if speck > 0 or extent > 0:
        out = cl._drop_components(out.view(np.uint8), speck, extent)
    return out


def _random_mask(rng, shape):
    m = rng.random(shape) < rng.uniform(0.05, 0.9)
    kind = rng.integers(0, 4)
    if kind == 1:
        m = cv2.dilate(m.view(np.uint8), np.ones((2, 2), np.uint8)).view(bool)
    elif kind == 2:
        m = cv2.morphologyEx(m.view(np.uint8), cv2.MORPH_OPEN, np.ones((2, 2), np.uint8)
                             ).view(bool)
    elif kind == 3:  # rings with holes, islands in the holes, specks in the islands' holes
        m = np.zeros(shape, bool)
        for _ in range(rng.integers(1, 6)):
            c = (int(rng.integers(0, shape[1])), int(rng.integers(0, shape[0])))
            for r in range(int(rng.integers(2, 20)), 0, -3):
                cv2.circle(m.view(np.uint8), c, r, 1, 1)
    if rng.random() < 0.7:  # ink off the image's edge: the borders decide
        b = int(rng.integers(1, 4))
        m[:b] = m[-b:] = False
        m[:, :b] = m[:, -b:] = False
    return np.ascontiguousarray(m)


@pytest.mark.parametrize("seed", range(4))
def test_borders_match_labelling_on_random_masks(seed):
    rng = np.random.default_rng(seed)
    n_borders = 0
    for _ in range(400):
        m = _random_mask(rng, tuple(int(v) for v in rng.integers(3, 90, 2)))
        s_min = float(rng.choice([0, 1, 2, 3, 5, 10, 30, 100])) + float(rng.choice([0, 0.5]))
        speck = float(rng.choice([0, 1, 2, 4, 9, 25, 80]))
        extent = float(rng.choice([0, 0, 1.5, 3, 7]))
        want = _by_labelling(m, s_min, speck, extent)
        got = clean_mask(m, s_min_px=s_min, speck_px=speck, min_extent_px=extent)
        assert np.array_equal(got, want)
        if cl._borders_settle(m, s_min):
            n_borders += 1
            assert np.array_equal(cl._clean_by_borders(m, s_min, speck, extent), want)
    assert n_borders > 100  # the border path was exercised, not only the fallback


def test_borders_match_labelling_on_a_scan():
    from crosssection.stages.threshold import threshold_rgb
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=3, n_stacks=40, max_layers=5, noise_sigma=8.0, specks=20,
                    pinholes=20)
    m = threshold_rgb(sc.rgb).mask
    m[:2] = m[-2:] = False
    m[:, :2] = m[:, -2:] = False
    for s_min, speck, extent in [(2500, 250, 50), (100, 25, 10), (2500, 0, 0), (0, 250, 0)]:
        assert cl._borders_settle(m, s_min)
        assert np.array_equal(clean_mask(m, s_min_px=s_min, speck_px=speck,
                                         min_extent_px=extent),
                              _by_labelling(m, s_min, speck, extent))


def test_ink_on_the_edge_and_salt_and_pepper_fall_back():
    rng = np.random.default_rng(7)
    edge = np.zeros((40, 50), bool)
    edge[0, 10:20] = edge[1:4, 10] = edge[1:4, 19] = True  # a pocket of background on the edge
    assert not cl._borders_settle(edge, 5.0)
    assert np.array_equal(clean_mask(edge, s_min_px=50.0), _by_labelling(edge, 50.0, 50.0, 0.0))
    noise = np.zeros((300, 300), bool)
    noise[1:-1, 1:-1] = rng.random((298, 298)) < 0.3
    assert cl._clean_by_borders(noise, 5.0, 3.0, 0.0) is None  # too many borders
    assert np.array_equal(clean_mask(noise, s_min_px=5.0, speck_px=3.0),
                          _by_labelling(noise, 5.0, 3.0, 0.0))


def test_empty_and_full_masks():
    for m in (np.zeros((30, 40), bool), np.ones((30, 40), bool)):
        for s_min in (0.0, 10.0, 5000.0):
            assert np.array_equal(clean_mask(m, s_min_px=s_min, speck_px=4.0),
                                  _by_labelling(m, s_min, 4.0, 0.0))


def test_thin_holes_with_large_boxes():
    # an L-shaped and a diagonal hole, one pixel wide: their boxes hold more than s_min pixels,
    # their areas fewer (measured, then filled); a wide hole beside them stays
    m = np.zeros((60, 80), bool)
    m[5:35, 5:35] = True
    m[8:31, 10] = False
    m[30, 10:31] = False
    m[40:58, 40:75] = True
    for k in range(15):
        m[41 + k, 42 + 2 * k:44 + 2 * k] = False
    m[10:30, 50:75] = True
    m[13:27, 53:72] = False
    l_area = int(np.count_nonzero(~m[5:35, 5:35]))
    assert l_area < 20 * 20
    for s_min in (30.0, l_area, l_area + 0.5, l_area + 1.0, 100.0, 400.0):
        got = clean_mask(m, s_min_px=s_min, speck_px=5.0)
        assert np.array_equal(got, _by_labelling(m, s_min, 5.0, 0.0))
        assert got[30, 20] == (l_area < s_min)  # the L is filled only below s_min
        assert got[20, 60] == (14 * 19 < s_min)  # the wide hole too


@pytest.mark.parametrize("seed", range(3))
def test_slivers_same_by_borders_and_by_labelling(seed, monkeypatch):
    # random bands with lenses, slits and discs between and inside them: the border path keeps
    # the same slivers as the labelling fallback, and keeps some (the case is exercised)
    rng = np.random.default_rng(seed)
    kept_any = 0
    for _ in range(40):
        m = np.zeros((160, 200), np.uint8)
        for _ in range(int(rng.integers(2, 6))):
            y0, y1 = (int(v) for v in rng.integers(20, 140, 2))
            gap = float(rng.uniform(0, 14))
            x = np.arange(10, 190)
            t = (x - 10) / 180.0
            for sign in (1, -1):
                y = y0 + (y1 - y0) * t + sign * gap / 2 * np.sin(np.pi * t)
                pts = np.stack([x, y], 1).round().astype(np.int32)
                cv2.polylines(m, [pts], False, 1, thickness=int(rng.integers(3, 8)))
        for _ in range(int(rng.integers(0, 4))):
            cv2.circle(m, (int(rng.integers(20, 180)), int(rng.integers(20, 140))),
                       int(rng.integers(2, 8)), 0, -1)
        m = m.view(bool)
        kw = dict(s_min_px=float(rng.choice([300, 600, 700])), speck_px=30.0,
                  min_extent_px=20.0, sliver_length_px=float(rng.choice([20, 50])),
                  sliver_width_px=float(rng.choice([3, 5, 7.5])))
        assert cl._borders_settle(m, kw["s_min_px"])
        got = clean_mask(m, **kw)
        with monkeypatch.context() as mp:
            mp.setattr(cl, "_borders_settle", lambda *a: False)
            want = clean_mask(m, **kw)
        assert np.array_equal(got, want)
        kept_any += int((~got & ~clean_mask(m, s_min_px=kw["s_min_px"], speck_px=30.0,
                                             min_extent_px=20.0)).any())
    assert kept_any > 3, kept_any


def test_a_texture_of_pixels_is_labelled_not_traced():
    # a checkerboard of ink and paper inside a disk: its border hierarchy grows faster than
    # the square of its ~10^5 borders (seconds), the labelling takes milliseconds
    n = 600
    yy, xx = np.indices((n, n))
    m = ((yy + xx) % 2 == 0) & (np.hypot(yy - n / 2, xx - n / 2) < 0.45 * n)
    assert cl._pixel_texture(m)
    got = clean_mask(m, s_min_px=2500.0, speck_px=40.0)
    assert np.array_equal(got, _by_labelling(m, 2500.0, 40.0, 0.0))
    # bands, however many, are traced: two transitions per row across each
    bands = np.zeros((n, n), bool)
    for c in range(10, n - 10, 12):
        bands[10:-10, c:c + 5] = True
    assert not cl._pixel_texture(bands)


@pytest.mark.parametrize("fraction", [0.6, 0.75, 0.9])
def test_dense_random_ink_is_a_texture(fraction):
    # ink covering most of a disk at random: its pinholes are the borders (10^5 on 1500 px,
    # seconds of border following), fewer than one transition per ink pixel
    rng = np.random.default_rng(int(fraction * 100))
    n = 400
    yy, xx = np.indices((n, n))
    m = (np.hypot(yy - n / 2, xx - n / 2) < 0.45 * n) & (rng.random((n, n)) < fraction)
    rows = m[::8]
    assert np.count_nonzero(rows[:, 1:] != rows[:, :-1]) < np.count_nonzero(rows)
    assert cl._pixel_texture(m)
    got = clean_mask(m, s_min_px=2500.0, speck_px=40.0, sliver_length_px=50.0,
                     sliver_width_px=7.5)
    assert np.array_equal(got, _by_labelling(m, 2500.0, 40.0, 0.0))


def test_bands_with_narrow_gaps_are_traced():
    # paper gaps of 3 px between 5-px bands (slivers between stacks) are no pinholes
    n = 600
    bands = np.zeros((n, n), bool)
    for c in range(10, n - 10, 8):
        bands[10:-10, c:c + 5] = True
    assert not cl._pixel_texture(bands)


def _disk(n):
    yy, xx = np.indices((n, n))
    return yy, xx, np.hypot(yy - n / 2, xx - n / 2) < 0.45 * n


@pytest.mark.parametrize("pattern", ["rows_every_8", "bricks_3x1", "blocks_2x2"])
def test_textures_that_the_row_counts_miss_are_labelled(pattern):
    # a checkerboard with every eighth row inked (rows read at one phase would see solid ink),
    # and checkerboards of 3 x 1 and 2 x 2 blocks (one transition per ink pixel, paper runs of
    # 2-3 px): 10^5-10^6 borders, tens of seconds of border following at 1000-2000 px
    n = 400
    yy, xx, disk = _disk(n)
    if pattern == "rows_every_8":
        m = (yy + xx) % 2 == 0
        m[::8] = True
    elif pattern == "bricks_3x1":
        m = (yy + xx // 3) % 2 == 0
    else:
        m = (yy // 2 + xx // 2) % 2 == 0
    m &= disk
    assert cl._pixel_texture(m)
    got = clean_mask(m, s_min_px=2500.0, speck_px=40.0)
    assert np.array_equal(got, _by_labelling(m, 2500.0, 40.0, 0.0))


def test_band_scans_are_no_texture():
    # bands 5-9 px wide at all angles, gaps of 6-30 px: the tiles read pieces of hundreds of px
    rng = np.random.default_rng(3)
    n = 800
    m = np.zeros((n, n), np.uint8)
    for _ in range(400):
        p = rng.integers(0, n, 2)
        a = rng.uniform(0, np.pi)
        q = (p + 60 * np.array([np.cos(a), np.sin(a)])).astype(int)
        cv2.line(m, tuple(int(v) for v in p), tuple(int(v) for v in q), 1,
                 int(rng.integers(5, 10)))
    m = m.view(bool)
    rows = m[cl._sampled_rows(n)]
    assert 8 * np.count_nonzero(rows[:, 1:] != rows[:, :-1]) > 2 * cl.MAX_BORDERS
    assert not cl._pixel_texture(m)


@pytest.mark.parametrize("seed", range(4))
def test_slivers_among_many_holes_are_the_same_found_from_the_wide_ones(seed):
    """Keeping to the holes wide enough to be slivers first (a texture's millions of holes)
    finds the same slivers: bands with paper gaps of 1-12 px between them, and pinholes."""
    rng = np.random.default_rng(seed)
    n = 300
    m = np.ones((n, n), np.uint8)
    for _ in range(12):
        r, c = (int(v) for v in rng.integers(10, n - 60, 2))
        cv2.rectangle(m, (c, r), (c + int(rng.integers(20, 60)), r + int(rng.integers(1, 13))),
                      0, -1)
        cv2.ellipse(m, (c, r), (int(rng.integers(3, 40)), int(rng.integers(1, 7))),
                    float(rng.uniform(0, 180)), 0, 360, 0, -1)
    m[rng.random((n, n)) < 0.05] = 0
    holes = cl._small_components(1 - m, 4, 2500.0)
    for sliver in [(20.0, 3.0), (50.0, 7.5), (30.0, 5.0)]:
        want = cl._slivers(holes, sliver)
        assert np.array_equal(cl._slivers(holes, sliver, wide_only=True), want)
    assert want.any()


@pytest.mark.parametrize("share", [0.2, 0.4])
def test_a_texture_beside_solid_ink_on_every_row_is_labelled(share):
    """Each row a 1-px checkerboard over its first ``share`` of the disk, then solid ink, then
    paper, and a wall band of 8 px (mean paper runs of 2.7 px: the tiles are read): tiles
    about each row's middle ink pixel all sat on the solid ink, and border following took 30 s
    at 2000 px."""
    n = 1000
    yy, xx = np.indices((n, n))
    c, r = (n - 1) / 2, n / 2 - 20
    rr = np.hypot(xx - c, yy - c)
    half = np.sqrt(np.maximum(r * r - (yy - c) ** 2, 0))
    u = (xx - c + half) / np.maximum(2 * half, 1)
    m = np.where(u < share, (xx + yy) % 2 == 0, u < share + 0.26)
    m[np.abs(yy - c) > 0.85 * r] = True
    m = (m & (rr <= r)) | ((rr <= r) & (rr > r - 8))
    assert cl._pixel_texture(m)
    got = clean_mask(m, s_min_px=2500.0, speck_px=40.0)
    assert np.array_equal(got, _by_labelling(m, 2500.0, 40.0, 0.0))
