"""The backdrop of real scans on generated ones (crosssection.truth.backdrop)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from crosssection.core.errors import ParameterError
from crosssection.truth.backdrop import PLATES, apply_backdrop, plate_rgb
from crosssection.truth.network import make_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene(seed=5, n_stacks=25, max_layers=4, receding_fraction=1.0)


def _geometry(scene):
    c = np.array(scene.params["hole_center_px"][::-1])
    R = scene.params["hole_radius_mm"] * scene.params["px_per_mm"]
    rr, cc = np.mgrid[:scene.rgb.shape[0], :scene.rgb.shape[1]]
    return c, R, np.hypot(rr - c[0], cc - c[1])


def _ink(rgb):
    return (rgb[..., 2] >= 100) & (rgb[..., 0] <= 130) & (rgb[..., 1] <= 130)


def test_plate_outside_paper_inside_ink_kept(scene):
    c, R, d = _geometry(scene)
    ink = _ink(scene.rgb)
    out = apply_backdrop(scene.rgb, ink_mask=ink, hole_center_rc=c, hole_radius_px=R,
                         rng=np.random.default_rng(0), plate="grey", texture=6.0)
    assert out.dtype == np.uint8 and out.shape == scene.rgb.shape
    inside = d < R - 1
    np.testing.assert_array_equal(out[inside], scene.rgb[inside])
    np.testing.assert_array_equal(out[ink], scene.rgb[ink])
    outside = out[d > R + 2].astype(float)
    np.testing.assert_allclose(outside.mean(axis=0), PLATES["grey"], atol=2.0)
    assert 3.0 < outside[:, 0].std() < 9.0          # textured, not flat
    # ink pressed against the wall reaches it: some ink pixels lie within 1 px of the edge
    assert np.count_nonzero(ink & (d > R - 1.5)) > 50


def test_rim_is_darker_than_plate(scene):
    c, R, d = _geometry(scene)
    out = apply_backdrop(scene.rgb, ink_mask=_ink(scene.rgb), hole_center_rc=c,
                         hole_radius_px=R, rng=np.random.default_rng(1), plate="beige",
                         rim_px=2.0, rim_gain=0.4)
    lum = out.astype(float).sum(axis=2)
    rim = (d > R + 0.6) & (d < R + 1.8) & ~_ink(scene.rgb)
    far = d > R + 6
    assert lum[rim].mean() < 0.6 * lum[far].mean()


def test_illumination_and_cast_bounds():
    flat = np.full((200, 300, 3), 200, np.uint8)
    no_ink = np.zeros((200, 300), bool)
    lit = apply_backdrop(flat, ink_mask=no_ink, hole_center_rc=(100, 150), hole_radius_px=90,
                         rng=np.random.default_rng(2), plate=None, illumination=0.15)
    g = lit[..., 1].astype(float) / 200
    assert g.min() >= 0.845 and g.max() <= 1.155
    assert g.max() - g.min() > 0.28                 # the extremes reach about +-15 %
    cast = apply_backdrop(flat, ink_mask=no_ink, hole_center_rc=(100, 150), hole_radius_px=90,
                          rng=np.random.default_rng(3), plate=None, cast=0.06)
    gains = cast.reshape(-1, 3).mean(axis=0) / 200
    assert np.all(np.abs(gains - 1) <= 0.061) and np.ptp(gains) > 0.005


def test_uint16_seeded_and_errors(scene):
    c, R, _ = _geometry(scene)
    ink = _ink(scene.rgb)
    kw = dict(ink_mask=ink, hole_center_rc=c, hole_radius_px=R, plate="coloured",
              illumination=0.1, cast=0.05)
    a = apply_backdrop(scene.rgb, rng=np.random.default_rng(4), **kw)
    b = apply_backdrop(scene.rgb, rng=np.random.default_rng(4), **kw)
    np.testing.assert_array_equal(a, b)
    wide = apply_backdrop(scene.rgb.astype(np.uint16) * 257, rng=np.random.default_rng(4), **kw)
    assert wide.dtype == np.uint16
    assert np.abs(wide.astype(float) / 257 - a).max() <= 1.0
    with pytest.raises(ParameterError):
        apply_backdrop(scene.rgb, rng=np.random.default_rng(0), **{**kw, "plate": "chrome"})
    with pytest.raises(ParameterError):
        apply_backdrop(scene.rgb, rng=np.random.default_rng(0), **{**kw, "ink_mask": ink[:5]})


@pytest.mark.parametrize("seed", range(4))
def test_coloured_plates_are_not_blue(seed):
    col = plate_rgb("coloured", np.random.default_rng(seed))
    # blue dominance well below the ink's (~120): only a blue plate would pass as ink
    assert col[2] - max(col[0], col[1]) < 60


def test_receding_surfaces_are_light_grey_blue():
    """The generator's receding surfaces look as the paper describes them: light, grey-blue."""
    with_r = make_scene(seed=8, n_stacks=25, max_layers=3, receding_fraction=1.0).rgb.astype(int)
    without = make_scene(seed=8, n_stacks=25, max_layers=3, receding_fraction=0.0).rgb.astype(int)

    def receding(img):
        lo = img.min(axis=2)
        dom = img[..., 2] - np.maximum(img[..., 0], img[..., 1])
        m = (lo >= 185) & (img.max(axis=2) <= 240) & (dom >= 5) & (dom <= 20)
        # patches, not the anti-aliased rims of the ink bands
        return binary_erosion(m, np.ones((5, 5), bool))

    assert receding(with_r).sum() > 2000
    assert receding(without).sum() < 50
