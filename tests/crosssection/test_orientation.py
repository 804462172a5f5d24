"""The same scan turned, mirrored or saved again as JPEG reads the same.

A quarter turn or a mirror moves pixels without changing them, and a JPEG round trip at
quality 85-95 changes them by a few grey levels: the structure must not move, and the energy
must not jump with a decision that one pixel tips (``benchmarks/orientation_spread.py``
measures the spread on every condition of the robust sweep).
"""
from __future__ import annotations

import io
import warnings

import numpy as np
import pytest

import crosssection


def _analyze(rgb, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return crosssection.analyze(np.ascontiguousarray(rgb), **kw).summary


def test_structure_does_not_depend_on_the_orientation():
    # measured on 10 seeds of this kind and on the robust sweep's 16 scenes (typical, 25
    # px/mm, thick dense, renders): branch counts identical, rod length within 0.15 %
    from crosssection.truth.network import make_scene

    scene = make_scene(seed=3, n_stacks=40, max_layers=4, noise_sigma=3.0, image_size=800)
    kw = dict(px_per_mm=50.0, thickness_mm=0.1, calibration=scene.calibration)
    out = [_analyze(np.rot90(scene.rgb[:, ::-1] if m else scene.rgb, k), **kw)
           for m in (False, True) for k in range(4)]
    for key in ("n_branches", "n_stacks", "n_junctions", "n_voids"):
        assert len({s[key] for s in out}) == 1, key
    rods = np.array([s["rod_length_mm"] for s in out])
    assert rods.max() / rods.min() - 1.0 < 0.005


def test_energy_does_not_jump_when_the_scan_is_saved_as_jpeg(sample_dir):
    # the medium sample scan's curvature noise is measured at about 0, and at exactly 0 on its
    # JPEG copies. A measured 0 is known noise; read as "not measured", the short links fitted
    # whole keep their flat end fits: -26 % of the truth against -6 % for the PNG. Measured:
    # the copies read -1 to -7 % (the PNG -4 %)
    from PIL import Image

    rgb = np.array(Image.open(sample_dir / "scan_02_medium.png").convert("RGB"))
    kw = dict(px_per_mm=50.0, calibration=str(sample_dir / "calibration.csv"))
    ref = _analyze(rgb, **kw)
    for quality in (95, 90, 85):
        buf = io.BytesIO()
        Image.fromarray(rgb).save(buf, "JPEG", quality=quality)
        out = _analyze(np.array(Image.open(buf).convert("RGB")), **kw)
        assert out["n_branches"] == ref["n_branches"]
        assert out["total_energy"] == pytest.approx(ref["total_energy"], rel=0.08), quality


def test_energy_of_a_scan_turned_by_45_degrees(sample_dir):
    # the medium sample's curvature noise rests on one stack of about 5 mm fitted; turned by
    # 45 degrees its skeleton has fewer samples per mm. Counted in samples, that stack falls
    # below the pairs an estimate needs, the noise is unknown and the short links lose their
    # trends (-37 % of the truth against -6 %); counted in pixels of arc it reads -14.5 %
    # (the PNG -4 %)
    import cv2
    from PIL import Image

    rgb = np.array(Image.open(sample_dir / "scan_02_medium.png").convert("RGB"))
    h, w = rgb.shape[:2]
    turned = cv2.warpAffine(rgb, cv2.getRotationMatrix2D((w / 2, h / 2), 45.0, 1.0), (w, h),
                            flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    kw = dict(px_per_mm=50.0, calibration=str(sample_dir / "calibration.csv"))
    ref, out = _analyze(rgb, **kw), _analyze(turned, **kw)
    assert out["n_branches"] == ref["n_branches"]
    assert out["total_energy"] == pytest.approx(ref["total_energy"], rel=0.2)


def test_energy_spread_over_orientations_at_25_px_per_mm():
    # at h = 2.5 px the skeleton's staircases are a large part of a window's data, and they
    # depend on the direction of the thinning; the centreline between the band's walls does
    # not. Measured over the eight orientations of six small scenes (seeds 1-6): spread of the
    # energy error 0.03-0.71 (median 0.15) between the walls, 0.45-1.37 (0.63) on the
    # skeleton's centreline
    from crosssection.truth.network import make_scene

    spreads = []
    for seed in range(1, 7):
        scene = make_scene(seed=seed, n_stacks=40, max_layers=4, noise_sigma=3.0,
                           image_size=600, px_per_mm=25.0)
        kw = dict(px_per_mm=25.0, thickness_mm=0.1, calibration=scene.calibration)
        e = [_analyze(np.rot90(scene.rgb[:, ::-1] if m else scene.rgb, k), **kw)["total_energy"]
             for m in (False, True) for k in range(4)]
        spreads.append((max(e) - min(e)) / scene.summary["total_energy"])
    assert np.median(spreads) < 0.3, spreads
