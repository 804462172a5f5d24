"""Low-resolution cleaning: specks judged by their extent, single-sheet stacks kept."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from crosssection.core.errors import ParameterError
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
