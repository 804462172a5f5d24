"""Bad input to the Python API of the simulator (``simulate.load``, ``render_configuration``)
is refused with the package's own errors, one line naming the argument; doubtful input is
warned about with a package warning category."""
import warnings

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from crosssection.core.errors import ConfigError, ParameterError
from crosssection.quality import QualityWarning, ResolutionWarning
from simulate.contacts import analyze_rod
from simulate.load import ConfigurationNotFound, load_ensemble, plot_configuration
from simulate.render import ScanRangeWarning, render_configuration
from simulate.shapes import hairpin, resample

# short rods, below the segment count the renders' truth is validated from, on purpose
pytestmark = pytest.mark.filterwarnings(
    "ignore:.*the render's truth is validated from:simulate.render.ScanRangeWarning")

#: a short folded rod: a small clean scene
XY = resample(hairpin(0.01, arm=0.3), 60)
LAM = 2e4
#: small clean scans at the validated range's coarsest resolution (h = 2.5 px): a render there
#: gives no warning unless something is wrong
FAST = {"lam": LAM, "px_per_mm": 25.0, "clean": True}


def _folder(root, *, rods=True):
    """A simulation folder of two configurations (the tables are not read by ``rod``)."""
    root.mkdir()
    pd.DataFrame({"config_id": [0, 1], "n_stacks": [1, 1]}).to_csv(root / "configs.csv",
                                                                 index=False)
    for name in ("branches", "voids"):
        pd.DataFrame({"config_id": [0]}).to_csv(root / f"{name}.csv", index=False)
    if rods:
        np.savez(root / "rods.npz", config_00000=XY, config_00001=XY[::-1])
    return root


@pytest.fixture
def ens(tmp_path):
    return load_ensemble(_folder(tmp_path / "sim"))


# --- simulate.load ---------------------------------------------------------------------------

@pytest.mark.parametrize("config", [5, -1, "x"])
def test_a_missing_configuration_is_a_parameter_error_and_still_a_key_error(ens, config):
    with pytest.raises(ConfigurationNotFound) as info:
        ens.rod(config)
    assert isinstance(info.value, ParameterError) and isinstance(info.value, KeyError)
    # one plain line, not the quoted repr KeyError shows
    assert str(info.value) == (f"no configuration {config!r} in {ens.folder / 'rods.npz'} "
                               "(2 configurations)")
    with pytest.raises(ParameterError, match="no configuration"):
        ens.plot(config)


@pytest.mark.parametrize("config", [None, 1.7, True, [0], float("nan")])
def test_rod_refuses_a_config_that_is_not_a_whole_number_or_a_key(ens, config):
    with pytest.raises(ParameterError, match="^config must be a whole number"):
        ens.rod(config)


def test_rod_takes_whole_numbers_of_any_type(ens):
    for config in (1, np.int64(1), 1.0, "config_00001"):
        assert np.array_equal(ens.rod(config), XY[::-1])


def test_rod_of_a_folder_without_rods_says_rods_npz_is_missing(tmp_path):
    ens = load_ensemble(_folder(tmp_path / "sim", rods=False))
    for call in (lambda: ens.rod(0), lambda: ens.plot(0)):
        with pytest.raises(ConfigError, match=r"rods\.npz: missing"):
            call()


def test_rod_of_a_rods_file_removed_after_loading_is_a_config_error(ens):
    (ens.folder / "rods.npz").unlink()
    with pytest.raises(ConfigError, match=r"rods\.npz: unreadable rods file"):
        ens.rod(0)


@pytest.mark.parametrize("xy, cause", [
    (np.zeros((0, 2)), r"got shape \(0, 2\)"),
    (np.zeros(5), r"got shape \(5,\)"),
    (np.zeros((1, 2)), r"got shape \(1, 2\)"),
    (XY.T, r"got shape \(2, 61\) \(transposed\? pass xy\.T\)"),
    (np.where(np.arange(61)[:, None] == 3, np.nan, XY), r"got 2 non-finite coordinate\(s\)"),
    ("abc", "got 'abc'"),
    ([[0, 0], [1]], r"got \[\[0, 0\], \[1\]\]"),
])
def test_plot_configuration_refuses_what_is_not_a_rod(xy, cause):
    for stacks in (True, False):
        with pytest.raises(ParameterError, match=r"^xy must be an \(N\+1, 2\) array of finite "
                                                 rf"numbers with N >= 1, {cause}$"):
            plot_configuration(xy, stacks=stacks)


def test_a_one_segment_rod_is_drawn_but_has_no_stacks_analysis():
    two = np.array([[0.0, 0.0], [1.0, 0.0]])
    assert isinstance(plot_configuration(two, stacks=False), Figure)
    with pytest.raises(ParameterError, match="needs N >= 2 .stacks=False draws it"):
        plot_configuration(two)


def test_plot_draws_a_compactions_wall_on_the_origin_not_about_the_centre_of_mass(tmp_path):
    # a rod off the origin inside a wall of radius 0.4 centred on the origin (where the
    # simulators put it); the configuration's row of configs holds its own radius
    root = _folder(tmp_path / "sim")
    pd.DataFrame({"config_id": [0, 1], "wall_radius": [0.4, 0.45]}).to_csv(
        root / "configs.csv", index=False)
    (root / "params.json").write_text('{"command": "compact", "wall_radius": 0.4}')
    shifted = XY - XY.mean(axis=0) + [0.05, -0.03]
    np.savez(root / "rods.npz", config_00000=shifted, config_00001=shifted)
    ens = load_ensemble(root)
    for config, radius in ((0, 0.4), (1, 0.45)):
        ax = ens.plot(config, stacks=False).axes[0]
        (circle,) = [p for p in ax.patches if type(p).__name__ == "Circle"]
        assert circle.center == pytest.approx((0.0, 0.0))
        assert circle.radius == pytest.approx(radius)
        # the legend says what the markers and the dashed circle are
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert labels[:2] == ["first node", "last node"] and labels[2].startswith("wall")
    with pytest.raises(ParameterError, match="^wall_center must be two finite numbers"):
        plot_configuration(XY, stacks=False, wall_radius=0.4, wall_center=(0.0, np.nan))


def test_plot_tick_labels_do_not_run_into_each_other():
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    # a rod folded five times, spanning x -0.08 .. 0.11 beside its colour bar: matplotlib's
    # default ticks there (-0.075, -0.050, ...) run into each other
    arm, gap = 0.195, 0.004
    legs = [np.c_[np.linspace(0, arm, 40)[::1 - 2 * (k % 2)], np.full(40, k * gap)]
            for k in range(5)]
    xy = resample(np.concatenate(legs), 120) + [0.015, 0.0]
    fig = plot_configuration(xy)
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    ax = fig.axes[0]
    boxes = [t.get_window_extent(renderer) for t in ax.get_xticklabels()
             if t.get_visible() and t.get_text()]
    boxes.sort(key=lambda b: b.x0)
    assert len(boxes) >= 3
    assert all(a.x1 < b.x0 for a, b in zip(boxes, boxes[1:]))


# --- simulate.render.render_configuration ---------------------------------------------------

@pytest.mark.parametrize("xy, cause", [
    (XY.T, r"got shape \(2, 61\) \(transposed\? pass xy\.T\)"),
    (np.zeros((0, 2)), r"got shape \(0, 2\)"),
    # one segment: the contact analysis needs two
    (XY[:2], r"got shape \(2, 2\)"),
    (np.where(np.arange(61)[:, None] == 3, np.nan, XY), r"got 2 non-finite coordinate\(s\)"),
    (np.where(np.arange(61)[:, None] == 3, np.inf, XY), r"got 2 non-finite coordinate\(s\)"),
    ("abc", "got 'abc'"),
])
def test_render_refuses_what_is_not_a_rod(xy, cause):
    with pytest.raises(ParameterError, match=r"^xy must be an \(N\+1, 2\) array of finite "
                                             rf"numbers with N >= 2, {cause}$"):
        render_configuration(xy, **FAST)


@pytest.mark.parametrize("name, value", [
    ("px_per_mm", "50"), ("px_per_mm", float("inf")), ("px_per_mm", True),
    ("thickness_mm", "0.1"), ("lam", "x"), ("lam", -1.0), ("contact_distance", "x"),
    ("contact_distance", -1.0), ("margin_mm", "x"), ("margin_mm", -1.0), ("gap_px", "x"),
    ("gap_px", -1.0), ("max_size_px", "x"), ("max_size_px", -5), ("rod_length_mm", "5"),
    ("rod_thickness", "0.01"), ("hole_radius_mm", -1.0), ("hole_radius_mm", "3"),
])
def test_render_refuses_an_option_that_is_not_a_number_in_range(name, value):
    with pytest.raises(ParameterError, match=f"^{name} must be a finite number [>=]+ 0"):
        render_configuration(XY, **{**FAST, name: value})


def test_render_refuses_a_bad_wall_centre_and_analysis():
    with pytest.raises(ParameterError, match="^wall_center_xy must be two finite numbers"):
        render_configuration(XY, wall_radius=1.0, wall_center_xy="ab", **FAST)
    with pytest.raises(ParameterError, match="^analysis must be a RodAnalysis"):
        render_configuration(XY, "an analysis", **FAST)


def test_render_options_of_any_number_type_give_the_same_scene():
    a = render_configuration(XY, **FAST)
    b = render_configuration(XY, **{**FAST, "px_per_mm": np.float32(25.0), "lam": int(LAM)},
                             max_size_px=np.int64(2500), margin_mm=2)
    assert np.array_equal(a.rgb, b.rgb)


def test_a_size_cap_the_scene_cannot_keep_is_a_resolution_warning():
    an = analyze_rod(XY, lam=LAM)
    free = render_configuration(XY, an, **FAST)
    # the margins alone exceed 10 px: the scene is drawn as without the cap
    with pytest.warns(ResolutionWarning, match="margins alone exceed 10 px") as caught:
        tiny = render_configuration(XY, an, max_size_px=10, **FAST)
    assert all(issubclass(w.category, QualityWarning) for w in caught)
    assert np.array_equal(tiny.rgb, free.rgb)
    # a cap the margins leave room for shortens the rod
    side = max(free.rgb.shape[:2]) - 40
    with pytest.warns(ResolutionWarning, match="rod length capped"):
        capped = render_configuration(XY, an, max_size_px=side, **FAST)
    assert max(capped.rgb.shape[:2]) < side
    # passes beyond the contact distance may then touch: its truth is flagged, so that
    # validate leaves it out of the means, and the uncapped scene's is not
    assert not capped.params["gap_guaranteed"]
    assert any("rod length capped" in m for m in capped.summary["truth_warnings"])
    assert not any("rod length capped" in m for m in free.summary["truth_warnings"])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # the short rod's own range warning is not the size cap's
        warnings.filterwarnings("ignore", ".*the render's truth is validated from",
                                ScanRangeWarning)
        render_configuration(XY, an, **FAST)


@pytest.mark.parametrize("folder", [None, 3, ""])
def test_load_ensemble_needs_a_folder_path(folder):
    from crosssection.core.errors import ParameterError
    from simulate.load import load_ensemble

    with pytest.raises(ParameterError, match="simulation folder's path"):
        load_ensemble(folder)


@pytest.mark.parametrize("factor", [3.0, 1 / 50])
def test_a_rod_in_other_units_than_its_length_is_refused(factor):
    with pytest.raises(ParameterError, match=r"units of the rod length L .* pass xy / "):
        analyze_rod(XY * factor, lam=LAM)
    assert len(analyze_rod(XY, lam=LAM).branches)
