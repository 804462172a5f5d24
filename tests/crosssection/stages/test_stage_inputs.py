"""The stages' own functions refuse what they cannot read with the package's ParameterError,
named, instead of an error from deep inside numpy or OpenCV or a silent, meaningless result
(cases found by fuzzing the array-level API)."""
from __future__ import annotations

import numpy as np
import pytest

from crosssection.core.errors import ParameterError
from crosssection.stages.branches import bending_energy, energy_density, rod_length_mm
from crosssection.stages.clean import clean_mask
from crosssection.stages.curvature import stack_curvature
from crosssection.stages.hole import fit_hole
from crosssection.stages.skeleton import neighbour_count
from crosssection.stages.threshold import threshold_rgb


def _arc(n=40, r=20.0):
    t = np.linspace(0, 1.5, n)
    return np.c_[50 + r * np.sin(t), 50 + r * np.cos(t)]


@pytest.mark.parametrize("kw", [{"radius_px": -1.0}, {"radius_px": 0.0},
                                {"radius_px": np.inf}, {"radius_px": np.nan},
                                {"center_rc": (np.inf, 3.0)}, {"center_rc": (np.nan, 40.0)},
                                {"center_rc": (1.0, 2.0, 3.0)}])
def test_a_given_hole_must_be_a_circle(kw):
    mask = np.zeros((80, 80), bool)
    mask[20:60, 20:60] = True
    with pytest.raises(ParameterError, match="hole"):
        fit_hole(mask, **{"center_rc": (40.0, 40.0), "radius_px": 30.0, **kw})


@pytest.mark.parametrize("path", [np.zeros((40, 3)), np.zeros((2, 20, 2)), np.zeros(10)])
def test_a_path_must_be_points_of_two_coordinates(path):
    # an (N, 3) array was read as a path of 1.5 N points
    with pytest.raises(ParameterError, match=r"\(N, 2\)"):
        stack_curvature(path, n_br=1, thickness_px=5.0, px_per_mm=50.0)


@pytest.mark.parametrize("kw", [{"smooth_px": np.nan}, {"smooth_px": np.inf},
                                {"smooth_px": -1}, {"smooth_px": 0},
                                {"thickness_px": 1e-9}, {"max_window_frac": -1.0},
                                {"max_window_frac": np.nan}, {"max_window_frac": 2.0},
                                {"trim_px": np.nan}, {"trim_px": (3.0, -1.0)}])
def test_curvature_settings_out_of_range_are_refused(kw):
    args = {"n_br": 1, "thickness_px": 5.0, "px_per_mm": 50.0, **kw}
    with pytest.raises(ParameterError):
        stack_curvature(_arc(), **args)
    # and the arc itself reads its curvature (1/20 px at 50 px/mm: 2.5 /mm)
    prof = stack_curvature(_arc(), n_br=1, thickness_px=5.0, px_per_mm=50.0)
    assert prof.kappa_plus == pytest.approx(2.5, rel=0.1)


def test_empty_images_are_refused_by_name():
    with pytest.raises(ParameterError, match="mask"):
        clean_mask(np.zeros((0, 0), bool), s_min_px=10)
    with pytest.raises(ParameterError, match="RGB"):
        threshold_rgb(np.zeros((0, 0, 3), np.uint8))
    assert neighbour_count(np.zeros((0, 0), bool)).shape == (0, 0)


@pytest.mark.parametrize("dtype, on", [(bool, True), (np.uint8, 255), (np.float64, 0.5),
                                       (np.int8, -1)])
def test_neighbour_count_counts_pixels_not_values(dtype, on):
    line = np.zeros((3, 7), dtype)
    line[1, 1:6] = on
    assert neighbour_count(line)[1, 1:6].tolist() == [1, 2, 2, 2, 1]


def test_bending_energy_refuses_what_no_branch_has():
    k, s = np.array([0.1, 0.5, 1.0]), np.array([0.0, 1.0, 2.0])
    assert bending_energy(k, s, rod_length_mm=10.0) > 0
    for bad in (-1.0, np.nan, np.inf):
        with pytest.raises(ParameterError, match="rod_length_mm"):
            bending_energy(k, s, rod_length_mm=bad)
    with pytest.raises(ParameterError, match="increasing"):
        bending_energy(k, s[::-1], rod_length_mm=10.0)
    with pytest.raises(ParameterError, match="shapes"):
        rod_length_mm([1.0, 2.0], [1])
    with pytest.raises(ParameterError, match="NaN"):
        energy_density(k, np.nan)
    assert np.array_equal(energy_density(k, np.inf), k * k)


@pytest.mark.parametrize("bad", [-1.0, np.nan, np.inf, None, "3"])
def test_detection_limits_of_the_stages_are_numbers(bad):
    from crosssection.stages.graph import stack_graph
    from crosssection.stages.junctions import find_junctions
    from crosssection.stages.skeleton import skeletonize_mask
    from crosssection.stages.voids import void_labels

    mask = np.zeros((30, 30), bool)
    mask[5:25, 5:25] = True
    mask[10:20, 10:20] = False
    with pytest.raises(ParameterError, match="s_min_px"):
        clean_mask(mask, s_min_px=bad)
    with pytest.raises(ParameterError, match="s_min_px"):
        void_labels(mask, s_min_px=bad)
    with pytest.raises(ParameterError, match="l_min_px"):
        skeletonize_mask(mask, l_min_px=bad)
    skel = skeletonize_mask(mask, l_min_px=0)
    with pytest.raises(ParameterError, match="merge_px"):
        find_junctions(skel, merge_px=bad)
    if bad is not None:  # thickness_px None: no junction moved to the centrelines
        with pytest.raises(ParameterError, match="thickness_px"):
            stack_graph(skel, np.ones(skel.shape), thickness_px=bad)
