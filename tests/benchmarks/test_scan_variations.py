"""The scan variations of ``benchmarks/scan_variations.py``: every one alters a scan (and only
the one that should moves or resizes it), and the truth follows a turned or padded scan."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def sv(load_script):
    return load_script("scan_variations")


def _scan():
    rng = np.random.default_rng(0)
    img = np.full((120, 150, 3), 245, np.uint8)
    img[40:50, 20:130] = (45, 75, 195)              # a band of ink
    img += rng.integers(0, 3, img.shape, dtype=np.uint8)
    yy, xx = np.mgrid[:120, :150]
    img[np.hypot(xx - 75, yy - 60) > 55] = (128, 125, 120)  # a grey plate
    return img


def test_every_variation_alters_the_scan(sv):
    img = _scan()
    for v in sv.VARIATIONS:
        out = sv.alter(img, v, (75.0, 60.0), 55.0, np.random.default_rng(1))
        assert out.dtype == np.uint8 and out.ndim == 3
        if v == "none":
            assert np.array_equal(out, img)
        elif v == "rot90":
            assert out.shape == (150, 120, 3) and np.array_equal(out, np.rot90(img))
        elif v == "white_pad":
            assert out.shape == (120 + 2 * sv.PAD_PX, 150 + 2 * sv.PAD_PX, 3)
        elif v == "crop":
            assert out.shape[0] < img.shape[0]
        elif v == "dpi600":  # 50 -> 23.62 px/mm
            assert out.shape == (57, 71, 3)
        else:
            assert out.shape == img.shape and not np.array_equal(out, img), v
    blue = sv.alter(img, "plate_60_90_170", (75.0, 60.0), 55.0, np.random.default_rng(1))
    assert abs(blue[2, 2].astype(int) - (60, 90, 170)).max() < 20   # the plate replaced
    assert np.array_equal(blue[45, 75], img[45, 75])                 # the hole untouched
    with pytest.raises(ValueError):
        sv.alter(img, "sepia", (75.0, 60.0), 55.0, np.random.default_rng(1))


def test_the_truth_follows_a_turned_or_padded_scan(sv):
    truth = {"hole_center_px": [75.0, 60.0], "junctions": [{"x": 30.0, "y": 45.0}],
             "stacks": [{"mid": [100.0, 45.0]}], "forks": [{"vis_px": [31.0, 44.0]}],
             "render": {"size": 150}}
    lines = {"s0": np.array([[20.0, 45.0], [130.0, 45.0]])}
    img = np.zeros((120, 150, 3), np.uint8)
    img[45, 30] = 255
    t, ln = sv.moved_truth(truth, lines, "rot90", 150)
    r, c = np.argwhere(np.rot90(img)[..., 0] == 255)[0]
    assert (t["junctions"][0]["x"], t["junctions"][0]["y"]) == (c, r)
    assert np.allclose(ln["s0"][0], [45.0, 150 - 1 - 20.0])
    t, ln = sv.moved_truth(truth, lines, "white_pad", 150)
    assert t["hole_center_px"] == [75.0 + sv.PAD_PX, 60.0 + sv.PAD_PX]
    assert t["render"]["size"] == 150 + 2 * sv.PAD_PX
    same, same_lines = sv.moved_truth(truth, lines, "jpeg50", 150)
    assert same is truth and same_lines is lines


@pytest.mark.parametrize("variation", ["rot7", "dpi600"])
def test_the_truth_follows_a_turned_or_resampled_scan(sv, variation):
    img = np.full((120, 150, 3), 250, np.uint8)
    img[40:47, 30:37] = 0                                   # a dark square centred (33, 43)
    truth = {"hole_center_px": [75.0, 60.0], "junctions": [{"x": 33.0, "y": 43.0}],
             "stacks": [{"mid": [33.0, 43.0]}], "forks": [], "px_per_mm": 50.0,
             "render": {"size": 150}}
    lines = {"s0": np.array([[33.0, 43.0], [75.0, 60.0]])}
    out = sv.alter(img, variation, (75.0, 60.0), 55.0, np.random.default_rng(1), 50.0)
    t, ln = sv.moved_truth(truth, lines, variation, 150, 120)
    dark = np.clip(200.0 - out[..., 0], 0, None)            # the square only
    yy, xx = np.mgrid[:out.shape[0], :out.shape[1]]
    centroid = ((dark * xx).sum() / dark.sum(), (dark * yy).sum() / dark.sum())
    assert np.allclose((t["junctions"][0]["x"], t["junctions"][0]["y"]), centroid, atol=0.15)
    assert np.allclose(ln["s0"][0], centroid, atol=0.15)
    if variation == "dpi600":
        assert t["px_per_mm"] == pytest.approx(600 / 25.4)
        assert t["render"]["size"] == 71 and truth["px_per_mm"] == 50.0
