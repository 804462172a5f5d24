"""The scene contract: one Scene, its folder written and read back, params.json checked, the
shared calibration, colours, degradations and truth voids."""
import json

import cv2
import numpy as np
import pandas as pd
import pytest

from crosssection.core.calibration import Calibration
from crosssection.core.errors import ConfigError, ImageError
from crosssection.truth import degrade, ink
from crosssection.truth.scene import read_scene, read_scene_params, write_scene
from crosssection.truth.voids import truth_voids


def _threshold(rgb):
    r, g, b = (np.asarray(rgb, float)[..., i] for i in range(3))
    return (b >= 100) & (r <= 130) & (g <= 130)


def test_scene_folder_round_trip(scene_folder):
    folder, scene = scene_folder
    back = read_scene(folder)
    assert np.array_equal(back.rgb, scene.rgb)
    from crosssection._version import __version__

    # the parameters, and the version that drew the scene
    assert back.params == {**json.loads(json.dumps(scene.params)), "version": __version__}
    assert back.summary["n_stacks"] == scene.summary["n_stacks"]
    for name, table in scene.tables.items():
        assert list(back.tables[name].columns[:len(table.columns)]) == list(table.columns)
        assert len(back.tables[name]) == len(table)
    n = scene.tables["stacks"]["n_br"].to_numpy()
    assert np.allclose(back.calibration.width(n), scene.calibration.width(n), atol=1e-6)
    rows = len(pd.read_csv(folder / "calibration.csv"))
    assert rows == max(12, int(n.max()) + 3)
    no_image = read_scene(folder, image=False)
    assert no_image.rgb is None and no_image.summary == back.summary


def test_a_scene_folder_holds_the_set_file_a_batch_reads(scene_folder):
    # `foldstat batch` on scene folders reads each with its own scale, hole and calibration
    from crosssection.setconfig import load_set_config

    folder, scene = scene_folder
    got = load_set_config(folder / "set.toml", root=folder.parent)
    assert got.warnings == []
    assert got.params_for(folder / "image.png") == {
        "px_per_mm": scene.params["px_per_mm"], "thickness_mm": scene.params["thickness_mm"],
        "hole_radius_mm": scene.params["hole_radius_mm"],
        "hole_center_px": list(scene.params["hole_center_px"]),
        "calibration": str((folder / "calibration.csv").resolve())}


def test_layer_pieces_round_trip_and_leave_with_a_scene_without_them(scene_folder, tmp_path):
    import dataclasses

    from crosssection.truth.scene import LAYER_PIECES

    _, scene = scene_folder
    st = scene.tables["stacks"]
    pieces = st[["stack_id", "n_br", "length_mm", "mid_x_px", "mid_y_px"]]
    with_pieces = dataclasses.replace(scene, tables={**scene.tables, LAYER_PIECES: pieces})
    folder = write_scene(with_pieces, tmp_path / "s")
    assert read_scene(folder, image=False).tables[LAYER_PIECES].equals(pieces)
    # a scene without pieces written over it: the earlier pieces must not be scored
    write_scene(scene, folder)
    assert LAYER_PIECES not in read_scene(folder, image=False).tables


def test_write_scene_refuses_an_unwritable_image(scene_folder, tmp_path):
    _, scene = scene_folder
    for rgb in (np.zeros((8, 8, 3), np.float64) + 0.5, np.zeros((0, 8, 3), np.uint8),
                np.zeros((8, 8), np.uint8)):
        bad = scene.__class__(rgb, scene.summary, scene.tables, scene.params, scene.calibration)
        with pytest.raises(ImageError, match="cannot write image"):
            write_scene(bad, tmp_path / "bad", image_name="image.jpg")
        assert not list((tmp_path / "bad").iterdir())  # nothing half-written


def test_an_image_the_disk_cannot_take_names_the_image_and_the_cause(tmp_path, monkeypatch):
    """A full disk was "cannot write image (OSError)", its cause dropped."""
    import errno
    from pathlib import Path

    from crosssection.core.errors import OutputError
    from crosssection.truth.scene import write_image

    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device", str(self))

    monkeypatch.setattr(Path, "write_bytes", full)
    with pytest.raises(OutputError) as err:
        write_image(np.zeros((8, 8, 3), np.uint8), tmp_path / "image.png")
    assert err.value.one_line() == (f"{tmp_path / 'image.png'}: cannot write (No space left "
                                    "on device)")


@pytest.mark.parametrize("content, message", [
    (None, "file not found"),
    ("{px_per_mm: 50", "malformed JSON"),
    ("[50, 0.1]", "JSON object"),
    ('{"thickness_mm": 0.1}', "lacks px_per_mm"),
    ('{"px_per_mm": -5, "thickness_mm": 0.1}', "px_per_mm must be a positive number"),
    ('{"px_per_mm": 50, "thickness_mm": "thin"}', "thickness_mm must be a positive number"),
    ('{"px_per_mm": 50, "thickness_mm": 0.1, "hole_center_px": [1]}', "hole_center_px"),
])
def test_read_scene_params_errors_name_the_file(tmp_path, content, message):
    if content is not None:
        (tmp_path / "params.json").write_text(content)
    with pytest.raises(ConfigError, match=message) as exc:
        read_scene_params(tmp_path)
    assert exc.value.path == str(tmp_path / "params.json")


def test_read_scene_params_accepts_null_hole(tmp_path):
    (tmp_path / "params.json").write_text(
        '{"px_per_mm": 50, "thickness_mm": 0.1, "hole_radius_mm": null, "hole_center_px": null}')
    assert read_scene_params(tmp_path)["hole_radius_mm"] is None


def test_calibration_nonlinear_law_and_csv_round_trip(tmp_path):
    cal = Calibration.nonlinear(0.1, n_max=20)
    n = np.arange(1, 21)
    assert np.array_equal(cal.width(n), 0.1 * (n + 0.4 * np.sqrt(n)))  # the table itself
    assert np.allclose(cal.layers(cal.width(n)), n)
    assert cal.width(25) == pytest.approx(cal.width(20) + 5 * (cal.width(20) - cal.width(19)))
    back = Calibration.from_csv(cal.to_csv(tmp_path / "cal.csv", n_max=30))
    m = np.arange(1, 31)
    assert np.allclose(back.width(m), cal.width(m), atol=1e-6)
    assert list(cal.to_frame().columns) == ["n_layers", "width_mm"] and len(cal.to_frame()) == 20
    with pytest.raises(ConfigError, match="lacks column"):
        Calibration.from_frame(pd.DataFrame({"n": [1, 2], "w": [0.1, 0.2]}))


def test_palette_sits_on_the_right_side_of_the_paper_threshold():
    rng = np.random.default_rng(0)
    inks = np.array([ink.ink_rgb(rng) for _ in range(500)])
    others = np.array([ink.paper_rgb(rng) for _ in range(200)]
                      + [ink.receding_rgb(rng) for _ in range(500)]
                      + [ink.smear_rgb(rng) for _ in range(500)])
    assert _threshold(inks).all()
    assert not _threshold(others).any()


def test_degradations_draw_nothing_when_not_asked():
    img = np.full((60, 60, 3), 240, np.float32)
    rng = np.random.default_rng(3)
    state = rng.bit_generator.state
    degrade.add_smears(img, rng, count=0, centre_xy=(30, 30), radius_px=25)
    degrade.add_specks(img, rng, count=0, background=np.ones((60, 60), bool), ink_rgb=ink.INK_RGB)
    degrade.add_pinholes(img, rng, count=0, paths_xy=[np.zeros((3, 2))], widths_px=[20.0])
    out = degrade.finish_scan(img, rng)
    assert rng.bit_generator.state == state
    assert (out == 240).all() and out.dtype == np.uint8


def test_specks_keep_away_from_ink_and_pinholes_stay_in_wide_bands():
    rng = np.random.default_rng(5)
    band = np.zeros((120, 120), bool)
    band[50:70, :] = True  # a 20 px band along the rows
    img = np.full((120, 120, 3), 245, np.float32)
    img[band] = ink.INK_RGB
    degrade.add_specks(img, rng, count=40, background=~band, ink_rgb=ink.INK_RGB)
    changed = np.abs(img - 245).max(axis=2) > 1
    assert changed[~band].any()
    near = cv2.dilate(band.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & ~band
    assert not changed[near].any()  # specks never touch the band
    before = img.copy()
    path = np.column_stack([np.arange(5, 115, 1.0), np.full(110, 59.5)])
    degrade.add_pinholes(img, rng, count=10, paths_xy=[path, path], widths_px=[20.0, 4.0])
    holes = np.abs(img - before).max(axis=2) > 1
    assert holes.any() and band[holes].all()


def test_truth_voids_definition():
    """Enclosed background >= s_min is a void; background reaching the border or leaving the
    hole circle is not; smaller enclosed regions are counted apart."""
    ink_mask = np.zeros((200, 200), np.uint8)
    labels = np.zeros((200, 200), np.int32)
    cv2.rectangle(ink_mask, (20, 20), (100, 100), 1, 6)    # square ring, enclosed 70x70
    cv2.rectangle(labels, (20, 20), (100, 100), 1, 6)
    cv2.rectangle(ink_mask, (40, 120), (50, 130), 1, 2)    # tiny enclosed 7x7
    cv2.rectangle(labels, (40, 120), (50, 130), 2, 2)
    cv2.rectangle(ink_mask, (110, 20), (190, 100), 1, 6)   # enclosed, but crosses the hole edge
    cv2.rectangle(labels, (110, 20), (190, 100), 3, 6)
    common = dict(s_min_px=400, px_per_mm=50, stack_labels=labels,
                  stack_ends=[(0, 0), (1, 1), (2, 2)], stack_widths_px=[6, 2, 6],
                  min_contact_px=2)
    free = truth_voids(ink_mask, **common)
    assert len(free.table) == 2 and free.n_small == 1
    holed = truth_voids(ink_mask, hole_center_xy=(60, 80), hole_radius_px=70, **common)
    assert len(holed.table) == 1 and holed.n_small == 1
    v = holed.table.iloc[0]
    side = 100 - 20 - 6 - 1  # inside of a 6 px thick outline drawn on 20 and 100
    assert v["area_mm2"] == pytest.approx(side * side / 50 ** 2)
    assert (v["centroid_x_px"], v["centroid_y_px"]) == pytest.approx((60, 60))
    # the outline through the boundary pixel centres, offset by half a pixel to the edge
    assert v["perimeter_mm"] == pytest.approx((4 * (side - 1) + np.pi) / 50)
    assert v["n_edges"] == 1  # one stack, one junction at both of its ends
    assert holed.enclosed[60, 60] and not holed.enclosed[5, 5] and not holed.enclosed[60, 150]


@pytest.mark.parametrize("suffix", [".png", ".tif"])
def test_a_scene_image_records_its_resolution_as_a_scanner_does(tmp_path, suffix):
    # an analysis at another scale than the scene's then says so (scale_mismatch)
    from crosssection.stages.load import load_image, recorded_header
    from crosssection.truth.scene import write_image

    rgb = (np.random.default_rng(0).random((40, 50, 3)) * 255).astype(np.uint8)
    path = write_image(rgb, tmp_path / f"scan{suffix}", px_per_mm=25.0)
    px_per_mm, pages, dpi_xy = recorded_header(path)
    assert px_per_mm == pytest.approx(25.0, rel=1e-6) and pages == 1 and dpi_xy is None
    assert np.array_equal(load_image(path), rgb)
    assert recorded_header(write_image(rgb, tmp_path / f"bare{suffix}"))[0] is None
