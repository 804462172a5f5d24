"""Bad arguments to the helpers of ``crosssection.testing`` are refused up front with the
package's own errors, one line naming the argument (and the range, or the keywords taken)."""
import numpy as np
import pytest

from crosssection.core.errors import ConfigError, ParameterError
from crosssection.testing import (DEFAULT_SCAN, drawn_scan, generated_scan, make_generated_scan,
                                  scan_grid)
from crosssection.truth.network import SceneGenerationError


@pytest.mark.parametrize("args, kwargs, message", [
    ((0, 0), {}, "size must be a whole number >= 1, got 0"),
    ((0, "a"), {}, "size must be a whole number >= 1, got 'a'"),
    ((0, 42.5), {}, "size must be a whole number >= 1, got 42.5"),
    ((-1,), {}, "seed must be a whole number >= 0, got -1"),
    ((0.5,), {}, "seed must be a whole number >= 0, got 0.5"),
    ((0,), {"ring_frac": 0.0}, "ring_frac must be a finite number > 0, got 0.0"),
    ((0,), {"ring_px": 0}, "ring_px must be a whole number >= 1, got 0"),
    ((0,), {"chord_px": (5, 5)}, "chord_px must be a pair (low, high) of whole numbers with "
                                 "1 <= low < high (px), got (5, 5)"),
    ((0,), {"chord_px": (0, 3)}, "chord_px must be a pair (low, high) of whole numbers with "
                                 "1 <= low < high (px), got (0, 3)"),
])
def test_drawn_scan_refuses_bad_arguments(args, kwargs, message):
    with pytest.raises(ParameterError) as info:
        drawn_scan(*args, **kwargs)
    assert str(info.value) == message


def test_drawn_scan_of_good_arguments_is_drawn():
    img = drawn_scan(3, 64, chord_px=(1, 2))
    assert img.shape == (64, 64, 3) and img.dtype == np.uint8
    assert np.array_equal(img, drawn_scan(np.int64(3), 64, chord_px=(1, 2)))


@pytest.mark.parametrize("args, message", [((-1,), "seed must be a whole number >= 0"),
                                           ((0, 0), "size must be a whole number >= 1")])
def test_generated_scan_refuses_bad_arguments(args, message):
    with pytest.raises(ParameterError, match=f"^{message}"):
        generated_scan(*args)


@pytest.mark.parametrize("options, message", [
    ({"px_per_mm": 0}, "px_per_mm must be a finite number > 0, got 0"),
    ({"px_per_mm": "50"}, "px_per_mm must be a finite number > 0, got '50'"),
    ({"px_per_mm": float("nan")}, "px_per_mm must be a finite number > 0, got nan"),
    ({"px_per_mm": 10 ** 400}, "px_per_mm must be a finite number > 0, got a number beyond "
                               "the floating-point range"),
    ({"n_stacks": 0}, "n_stacks must be a whole number in 10-300, got 0"),
    ({"n_stacks": -5}, "n_stacks must be a whole number in 10-300, got -5"),
    ({"n_stacks": 1000}, "n_stacks must be a whole number in 10-300, got 1000"),
    ({"max_layers": 0}, "max_layers must be a whole number in 2-12, got 0"),
    # one layer per stack has no layout (a junction of three stacks needs a = b + c): refused
    # at once, not after the generator's search
    ({"max_layers": 1}, "max_layers must be a whole number in 2-12, got 1"),
    ({"max_layers": 100}, "max_layers must be a whole number in 2-12, got 100"),
    ({"seed": -1}, "seed must be a whole number >= 0, got -1"),
    ({"seed": "a"}, "seed must be a whole number >= 0, got 'a'"),
    ({"degradation": []}, "degradation must be one of ['clean', 'defects', 'jpeg', 'noisy'], "
                          "got []"),
    ({"thickness_mm": "x"}, "thickness_mm must be a finite number > 0, got 'x'"),
    ({"image_size": 0}, "image_size must be a whole number >= 1, got 0"),
])
def test_make_generated_scan_refuses_bad_options_before_generating(tmp_path, options, message):
    with pytest.raises(ParameterError) as info:
        make_generated_scan(tmp_path / "scan", **options)
    assert str(info.value) == message
    assert not (tmp_path / "scan").exists()


def test_make_generated_scan_names_an_unknown_keyword_and_the_ones_it_takes(tmp_path):
    with pytest.raises(ParameterError, match=r"^unknown keyword noise_sigm \(did you mean "
                                             r"noise_sigma\?\): make_generated_scan takes "
                                             r"seed, px_per_mm, n_stacks, max_layers, "
                                             r"degradation and make_scene's .*noise_sigma"):
        make_generated_scan(tmp_path / "scan", noise_sigm=3)


def test_make_generated_scan_refuses_a_folder_it_cannot_write(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError) as info:
        make_generated_scan(tmp_path / "file")
    assert str(info.value) == (f"{tmp_path / 'file'}: exists and is not a folder (a scene "
                               "folder is written there)")
    with pytest.raises(ConfigError, match="is a file, not a folder"):
        make_generated_scan(tmp_path / "file" / "sub")
    with pytest.raises(ParameterError, match="^folder must be a non-empty path"):
        make_generated_scan("")


def test_no_layout_names_the_options_that_gave_none(tmp_path):
    # 10 stacks give 3 Voronoi cells: no seed finds a layout
    with pytest.raises(SceneGenerationError, match=r"^no scan for n_stacks=10, max_layers=4, "
                                                   r"px_per_mm=50, seed=0 \(.*Voronoi cells"):
        make_generated_scan(tmp_path / "scan", n_stacks=10)


def test_scan_grid_checks_its_conditions_up_front():
    with pytest.raises(ParameterError, match=r"^degradation must be one of .*got 'nope'"):
        scan_grid(degradations=["nope"])
    with pytest.raises(ParameterError, match="^degradations must be a sequence"):
        scan_grid(degradations="clean")
    with pytest.raises(ParameterError, match="^resolutions must be a sequence"):
        scan_grid(resolutions=50)
    with pytest.raises(ParameterError, match="^resolutions must be a finite number > 0"):
        scan_grid(resolutions=["a"])
    with pytest.raises(ParameterError, match="^layers must be a whole number in 2-12"):
        scan_grid(layers=[100])
    with pytest.raises(ParameterError, match="^layers must be a whole number in 2-12"):
        scan_grid(layers=[1.5])
    with pytest.raises(ParameterError, match="^densities must be a whole number in 10-300"):
        scan_grid(densities=[5])
    with pytest.raises(ParameterError, match="^seed must be a whole number >= 0"):
        scan_grid(seed=-1)
    # whole floats are counts as before
    assert scan_grid(layers=[4.0])[0].values[0]["max_layers"] == 4


def test_the_default_scan_is_accepted(tmp_path):
    scan = make_generated_scan(tmp_path / "scan", **DEFAULT_SCAN)
    again = make_generated_scan(tmp_path / "again", **{**DEFAULT_SCAN, "n_stacks": 20.0})
    assert np.array_equal(scan.scene.rgb, again.scene.rgb)


def test_a_scene_too_large_to_draw_is_refused_before_drawing():
    from crosssection.core.errors import ParameterError
    from crosssection.truth.network import make_scene

    with pytest.raises(ParameterError, match="the scene would be about"):
        make_scene(seed=1, px_per_mm=1e4)
