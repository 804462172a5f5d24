"""The outer-face reading of fork zones (``benchmarks/outer_face_zones.py``): the edge is found
at the band's half width along a normal, and a band's centreline rebuilt from one face has the
band's curvature.
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest


@pytest.fixture(scope="module")
def face(load_script):
    return load_script("outer_face_zones")


def _annulus(radius_px, half_width_px, size=400):
    """Distance transform of a drawn ring band of centre radius ``radius_px``."""
    yy, xx = np.mgrid[:size, :size].astype(float)
    r = np.hypot(yy - size / 2, xx - size / 2)
    mask = (np.abs(r - radius_px) <= half_width_px).astype(np.uint8)
    return cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


@pytest.mark.parametrize("half_width", [3.0, 6.5, 12.0])
def test_the_edge_lies_half_a_width_along_each_normal(face, half_width):
    R = 120.0
    dist = _annulus(R, half_width)
    a = np.linspace(0.2, 1.4, 30)
    pts = 200.0 + R * np.stack([np.sin(a), np.cos(a)], axis=1)
    outward = np.stack([np.sin(a), np.cos(a)], axis=1)
    for normals in (outward, -outward):
        d = face.edge_distance_px(dist, pts, normals, max_px=4 * half_width + 10)
        assert np.all(np.abs(d - half_width) < 0.8), d


def test_a_band_rebuilt_from_its_outer_face_has_its_curvature(face):
    from crosssection.stages.curvature import stack_curvature

    R, half_width, h = 150.0, 7.0, 5.0
    dist = _annulus(R, half_width, size=420)
    a = np.linspace(0.1, 1.5, 220)
    centre = 210.0 + R * np.stack([np.sin(a), np.cos(a)], axis=1)
    normals = face.unit_normals(centre)
    # the side whose normal points out of the ring is the outer (convex) face
    radial = (centre - 210.0) / R
    sign = np.sign(np.sum(normals * radial, axis=1))[:, None]
    d = face.edge_distance_px(dist, centre, sign * normals, max_px=40)
    outer = centre + sign * normals * d[:, None]
    rebuilt = face.face_centreline(outer, -sign * normals, half_width, smooth_px=9)
    assert np.median(np.abs(np.hypot(*(rebuilt - 210.0).T) - R)) < 0.5
    prof = stack_curvature(rebuilt, n_br=2, thickness_px=h, px_per_mm=50.0, closed=False,
                           trim_px=0, method="paper", ends="truncate")
    k = np.abs(prof.kappa_per_mm[20:-20])
    assert np.median(k) == pytest.approx(50.0 / R, rel=0.05)
