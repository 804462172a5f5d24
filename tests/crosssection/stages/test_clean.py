"""Low-resolution cleaning: specks judged by their extent, single-sheet stacks kept."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from crosssection.core.errors import ParameterError
from crosssection.stages import clean as cl
from crosssection.stages.clean import clean_mask


@pytest.mark.parametrize("h_px", [2.0, 2.5, 3.0])
def test_specks_above_area_filter_removed_by_extent(h_px):
    # at h = 2-3 px a dust speck of 7x7 px has more area than the area filter (10 h^2 = 40 to
    # 90 px^2 would keep it at h = 2) but is far shorter than l_min = 10 h
    rng = np.random.default_rng(int(h_px * 10))
    size = 400
    m = np.zeros((size, size), np.uint8)
    l_min = 10 * h_px
    stacks = []
    for k in range(6):  # single-sheet stacks of length 1.2 l_min .. 3 l_min
        r = 30 + 60 * k
        length = l_min * rng.uniform(1.2, 3.0)
        cv2.line(m, (20, r), (int(20 + length), r), 1, thickness=max(1, int(round(h_px))))
        stacks.append((r, 20 + length / 2))
    specks = []
    for k in range(8):
        r, c = 30 + 45 * k, 300
        cv2.circle(m, (c, r), int(rng.integers(3, 5)), 1, -1)
        specks.append((r, c))
    mask = m.astype(bool)
    speck_px = min((10 * h_px) ** 2, l_min * h_px)
    out = clean_mask(mask, s_min_px=(10 * h_px) ** 2, speck_px=speck_px, min_extent_px=l_min)
    for r, c in specks:
        assert not out[r - 5:r + 6, c - 5:c + 6].any()
    for r, c in stacks:
        assert out[r - 2:r + 3, int(c)].any()
    # the area filter alone keeps some of the specks (why the extent filter exists)
    area_only = clean_mask(mask, s_min_px=(10 * h_px) ** 2, speck_px=speck_px)
    assert any(area_only[r - 5:r + 6, c - 5:c + 6].any() for r, c in specks) or h_px > 2.0


def test_ring_around_a_void_is_kept():
    # a ring around a void of area >= s_min spans more than l_min: never a speck
    h = 2.5
    m = np.zeros((100, 100), np.uint8)
    cv2.circle(m, (50, 50), 8, 1, 3)
    out = clean_mask(m.astype(bool), s_min_px=0, speck_px=10 * h * h,
                     min_extent_px=10 * h)
    assert out.sum() == m.sum()


def test_min_extent_validated():
    with pytest.raises(ParameterError):
        clean_mask(np.zeros((5, 5), bool), s_min_px=1, min_extent_px=-1)


def _lens_scene(gap_px: float, *, h: float = 5.0, length: int = 160):
    """Two single-sheet bands that part along ``length`` px and meet again: a lens hole whose
    sides are ``gap_px + h`` apart at its middle (cv2's strokes are wider than h: the paper
    between them is about ``gap_px - 3`` px wide); a compact pinhole in a wide band and a
    one-pixel slit along another wide band (both below s_min, the slit longer than the lens)."""
    m = np.zeros((260, 260), np.uint8)
    x = np.arange(40, 40 + length + 1)
    t = (x - x[0]) / length
    bulge = (gap_px + h) / 2 * np.sin(np.pi * t)
    for sign in (1, -1):
        pts = np.stack([x, 60 + sign * bulge], 1).round().astype(np.int32)
        cv2.polylines(m, [pts], False, 1, thickness=int(h))
    cv2.line(m, (10, 60), (40, 60), 1, thickness=int(h))
    cv2.line(m, (40 + length, 60), (250, 60), 1, thickness=int(h))
    m[130:180, 20:240] = 1
    cv2.circle(m, (60, 155), 9, 0, -1)  # pinhole: 250 px^2, 57 px of half-perimeter
    m[200:240, 20:240] = 1
    m[220, 40:220] = 0  # a slit between layers, 180 px long, 1 px wide
    return m.astype(bool)


@pytest.mark.parametrize("gap_px", [12.0, 16.0])
def test_a_resolved_sliver_between_two_stacks_is_kept(gap_px):
    h = 5.0
    m = _lens_scene(gap_px, h=h)
    lens = ~m[55:66, 120]
    assert lens.any()
    kw = dict(s_min_px=(10 * h) ** 2, speck_px=10 * h * h, min_extent_px=10 * h)
    _, lab = cv2.connectedComponents((~m).view(np.uint8), connectivity=4)
    assert np.count_nonzero(lab == lab[60, 120]) < (10 * h) ** 2  # the lens is below s_min
    filled = clean_mask(m, **kw)
    kept = clean_mask(m, **kw, sliver_length_px=10 * h, sliver_width_px=1.5 * h)
    assert filled[55:66, 120].all()  # the paper's rule alone merges the two stacks
    assert not kept[60, 120]  # the gap between them stays
    for out in (filled, kept):
        assert out[150:161, 55:66].all()  # the pinhole is filled: compact
        assert out[220, 40:220].all()  # the slit is filled: narrower than the sheets
    # the fallback by labelling (ink on the scan's edge) decides the same
    edge = m.copy()
    edge[0, :] = True
    assert not cl._borders_settle(edge, (10 * h) ** 2)
    assert np.array_equal(clean_mask(edge, **kw, sliver_length_px=10 * h,
                                     sliver_width_px=1.5 * h)[1:], kept[1:])


def test_a_narrow_gap_is_filled():
    # a gap of one sheet thickness: passes in contact, read as one stack
    h = 5.0
    m = _lens_scene(6.0, h=h)
    out = clean_mask(m, s_min_px=(10 * h) ** 2, sliver_length_px=10 * h,
                     sliver_width_px=1.5 * h)
    assert out[55:66, 120].all()


def test_is_sliver_measures_length_and_width():
    strip = np.zeros((20, 120), np.uint8)
    strip[5:14, 10:110] = 1  # 100 x 9 px
    assert cl.is_sliver(strip, length_px=100, width_px=9)
    assert not cl.is_sliver(strip, length_px=120, width_px=9)
    assert not cl.is_sliver(strip, length_px=50, width_px=10)
    square = np.zeros((40, 40), np.uint8)
    square[5:35, 5:35] = 1  # long enough and wide enough, but compact
    assert not cl.is_sliver(square, length_px=20, width_px=5)


def test_sliver_parameters_validated():
    with pytest.raises(ParameterError):
        clean_mask(np.zeros((5, 5), bool), s_min_px=1, sliver_length_px=-1)
    with pytest.raises(ParameterError):
        clean_mask(np.zeros((5, 5), bool), s_min_px=1, sliver_width_px=np.nan)
