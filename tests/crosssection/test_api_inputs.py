"""The Python API given what notebook users pass: integer images of any width, their own
arrays, paths with ``~``, a mistaken ``params``, outputs that cannot be written."""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

import crosssection as cs
from crosssection.core.calibration import Calibration
from crosssection.core.errors import OutputError, ParameterError
from crosssection.pipeline import preprocess
from crosssection.quality import NetworkWarning
from crosssection.testing import generated_scan

KW = dict(px_per_mm=50.0, thickness_mm=0.1)


@pytest.fixture(scope="module")
def scan():
    return generated_scan(5)


@pytest.fixture(scope="module")
def result(scan):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return cs.analyze(scan, **KW)


@pytest.mark.parametrize("dtype", [np.int16, np.int32, np.int64, np.uint16, np.uint32])
def test_an_8_bit_image_in_a_wider_integer_type_reads_as_8_bit(scan, result, dtype):
    """numpy arithmetic or astype(int) widens an 8-bit scan: read as 16 bits it is black."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        wide = cs.analyze(scan.astype(dtype), **KW)
    assert wide.summary["n_branches"] == result.summary["n_branches"]
    assert wide.summary["total_energy"] == result.summary["total_energy"]


def test_a_float_image_takes_its_fixed_bounds_in_its_own_scale(scan):
    fixed = dict(KW, threshold_method="fixed")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = cs.analyze(scan, **fixed, blue_min=100, rg_max=130)
        own = cs.analyze(scan / 255.0, **fixed, blue_min=100 / 255, rg_max=130 / 255)
    assert own.summary["n_branches"] == ref.summary["n_branches"] > 0
    assert own.summary["thresholds"]["blue_min"] == pytest.approx(100 * 257)
    # the record re-runs the same analysis
    again = cs.analyze(scan / 255.0, cs.AnalysisParams(**own.summary["parameters"]), warn=False)
    assert again.summary["n_branches"] == own.summary["n_branches"]
    # preprocess takes the parameters of analyze
    pre = preprocess(scan / 255.0, **fixed, blue_min=100 / 255, rg_max=130 / 255)
    ref_mask = preprocess(scan, **fixed, blue_min=100, rg_max=130).mask_clean
    assert (pre.mask_clean == ref_mask).all() and ref_mask.any()


def test_the_result_holds_its_own_copy_of_the_scan(scan, result):
    assert not np.shares_memory(result.rgb, scan)


def test_write_leaves_the_result_as_analysed(result, tmp_path):
    before = dict(result.summary)
    result.write(tmp_path / "out")
    assert result.summary == before


def test_a_write_that_fails_leaves_no_empty_folder_it_made(result, tmp_path, monkeypatch):
    import errno

    from crosssection.core import schema

    def full(*args, **kw):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(schema, "write_tables", full)
    with pytest.raises(OutputError, match="No space left"):
        result.write(tmp_path / "new" / "out", figure=False)
    assert not (tmp_path / "new" / "out").exists()
    (tmp_path / "mine").mkdir()  # a folder the user made stays
    with pytest.raises(OutputError):
        result.write(tmp_path / "mine", figure=False)
    assert (tmp_path / "mine").is_dir()


def test_write_removes_the_temporary_files_a_killed_write_left(result, tmp_path):
    """A write killed midway leaves hidden temporary files; the next write removes them, and
    no hidden file of the user's."""
    out = tmp_path / "out"
    out.mkdir()
    left = [".summary.json.x1y2z3a4.json", ".stacks.csv.qwer5678.csv"]
    for name in left:
        (out / name).write_text("cut short")
    (out / ".notes.txt.abcd1234.txt").write_text("the user's")
    result.write(out, figure=False)
    assert [name for name in left if (out / name).exists()] == []
    assert (out / ".notes.txt.abcd1234.txt").read_text() == "the user's"
    assert (out / "summary.json").is_file()


@pytest.mark.parametrize("where", ["file", "under_file"])
def test_write_where_a_file_is_in_the_way_is_one_error(result, tmp_path, where):
    blocker = tmp_path / "blocker.txt"
    blocker.write_text("x")
    target = blocker if where == "file" else blocker / "sub"
    with pytest.raises(OutputError, match="a file is in the way"):
        result.write(target)
    assert isinstance(OutputError("x"), OSError)  # callers catching OSError still do


def test_write_needs_a_path(result):
    with pytest.raises(ParameterError, match="folder path"):
        result.write(None)


def test_a_hole_too_small_for_a_rod_is_a_parameter_error(scan):
    with pytest.raises(ParameterError, match="a radius below 5 sheet thicknesses"):
        cs.analyze(scan, **KW, hole_radius_mm=0.01, hole_center_px=(200.0, 200.0))


@pytest.mark.parametrize("name, value", [("px_per_mm", 10 ** 400), ("px_per_mm", -10 ** 400),
                                         ("smooth_px", 10 ** 400),
                                         ("hole_center_px", (10 ** 400, 5.0))],
                         ids=["px_per_mm", "negative", "smooth_px", "hole_center_px"])
def test_a_number_beyond_the_float_range_is_a_parameter_error(scan, name, value):
    with pytest.raises(ParameterError) as err:
        cs.analyze(scan, **{**KW, name: value})
    msg = err.value.one_line()
    assert msg.startswith(name) and msg.endswith("got a number beyond the floating-point range")
    assert len(msg) < 120 and "-inf" not in msg  # not the number's 400 digits


@pytest.mark.parametrize("value", [np.True_, np.False_])
def test_numpy_booleans_are_switches(value):
    """A parameter grid built with numpy gives np.True_: it was refused."""
    params = cs.AnalysisParams(**KW, layer_steps=value, hole_correction=value)
    assert params.layer_steps is bool(value) and type(params.hole_correction) is bool


def test_a_crop_whose_found_hole_is_no_hole_names_the_hole_found():
    """A crop of a sample scan, no hole given: the hole found was refused as if the user had
    given a wrong hole_radius_mm."""
    from pathlib import Path

    from PIL import Image

    from crosssection.core.errors import AnalysisError

    root = Path(__file__).resolve().parents[2] / "sample_images"
    crop = np.asarray(Image.open(root / "scan_01_sparse.png"))[100:500, 100:500]
    with pytest.raises(AnalysisError) as err:
        cs.analyze(crop, warn=False)
    line = err.value.one_line()
    assert "the hole found in the scan is no hole of it" in line
    assert "give the hole (hole_radius_mm and hole_center_px)" in line
    assert "check hole_radius_mm" not in line


def test_params_given_as_text_is_a_parameter_error(scan):
    with pytest.raises(ParameterError, match="AnalysisParams or a dict"):
        cs.analyze(scan, "px_per_mm=50")


def test_a_path_with_a_tilde_is_the_home_folder(scan, result, tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    cv2.imwrite(str(tmp_path / "scan.png"), np.ascontiguousarray(scan[..., ::-1]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cs.analyze("~/scan.png", **KW)
    assert res.summary["n_branches"] == result.summary["n_branches"]
    result.write("~/out", figure=False)
    assert (tmp_path / "out" / "summary.json").is_file() and not Path("~").exists()


def test_a_scan_without_junctions_is_flagged_where_it_was_analysed():
    """A closed ring of ink: no junction, which no folded sheet gives; the warning points at
    the caller's line, not the package's."""
    img = np.full((400, 400, 3), 245, np.uint8)
    cv2.circle(img, (200, 200), 150, (170, 70, 40), thickness=10)  # BGR: blue ink
    rgb = np.ascontiguousarray(img[..., ::-1])
    # the ring is drawn n h wide: with that calibration the missing junction is the only flag
    with pytest.warns(NetworkWarning, match="no junction found") as caught:
        res = cs.analyze(rgb, **KW, calibration=Calibration.linear(KW["thickness_mm"]))
    assert "no_junction" in res.summary["quality"]["codes"]
    assert any(Path(w.filename).resolve() == Path(__file__).resolve() for w in caught
               if issubclass(w.category, NetworkWarning))
    assert os.path.basename(__file__) in {os.path.basename(w.filename) for w in caught}


def test_a_calibration_table_given_in_memory_is_recorded_whole(scan):
    """Recorded at full precision, in a form AnalysisParams takes back: the parameters of
    summary.json analyse the scan again into the same tables."""
    import json

    import pandas as pd

    # widths of more digits than a rounded record keeps
    cal = pd.DataFrame({"n_layers": [1, 2, 3],
                        "width_mm": [0.1123456789012345, 0.2051234567890123, 0.3000000000000004]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cs.analyze(scan, **KW, calibration=cal)
    pairs = [[int(n), float(w)] for n, w in zip(cal["n_layers"], cal["width_mm"])]
    assert res.summary["calibration"] == pairs
    assert res.summary["parameters"]["calibration"] == pairs
    assert res.summary["inputs"]["calibration"]["widths"] == {
        "n_layers": [1, 2, 3], "width_mm": cal["width_mm"].tolist()}
    # through JSON, as a user reads summary.json back
    recorded = json.loads(json.dumps(res.summary))["parameters"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = cs.analyze(scan, cs.AnalysisParams(**recorded))
    assert again.summary["parameters"] == res.summary["parameters"]
    for name, table in res.tables.items():
        pd.testing.assert_frame_equal(again.tables[name], table, check_exact=True, obj=name)


def test_the_recorded_calibration_forms_are_parameters():
    """Pairs (a list or an array) and columns: a table typed by hand, or a batch's record."""
    from crosssection.core.errors import ConfigError

    pairs = [[1, 0.11], [2, 0.205], [3, 0.3]]
    want = cs.AnalysisParams(calibration=pairs).calibration
    assert isinstance(want, Calibration) and want.width_mm == (0.11, 0.205, 0.3)
    assert cs.AnalysisParams(calibration=np.array(pairs)).calibration == want
    columns = {"n_layers": [1, 2, 3], "width_mm": [0.11, 0.205, 0.3]}
    assert cs.AnalysisParams(calibration=columns).calibration == want
    assert cs.AnalysisParams(calibration=pairs).to_dict()["calibration"] == pairs
    with pytest.raises(ParameterError, match=r"\[\[n_layers, width_mm\]"):
        cs.AnalysisParams(calibration=[1, 2, 3])
    with pytest.raises(ParameterError, match="strictly increasing"):
        cs.AnalysisParams(calibration=[[1, 0.3], [2, 0.2]])
    with pytest.raises(ConfigError):
        Calibration.of(object())


def test_a_calibration_table_is_copied_into_the_frozen_parameters():
    """The caller's DataFrame changed afterwards changes neither the parameters nor what they
    analyse again; the parameters stay hashable."""
    import pandas as pd

    cal = pd.DataFrame({"n_layers": [1, 2, 3], "width_mm": [0.14, 0.25, 0.36]})
    params = cs.AnalysisParams(calibration=cal)
    cal["width_mm"] = cal["n_layers"] * 0.1
    assert isinstance(params.calibration, Calibration)
    assert params.calibration.width_mm == (0.14, 0.25, 0.36)
    assert params.to_dict()["calibration"] == [[1, 0.14], [2, 0.25], [3, 0.36]]
    assert hash(params) == hash(cs.AnalysisParams(calibration=[[1, 0.14], [2, 0.25], [3, 0.36]]))
    with pytest.raises(ParameterError, match="strictly increasing"):
        cs.AnalysisParams(calibration=pd.DataFrame({"n_layers": [1, 2], "width_mm": [0.3, 0.2]}))


def test_a_calibration_file_given_relative_is_recorded_absolute(scan, tmp_path, monkeypatch):
    """summary.json is read from elsewhere than the caller's folder: the path it records must
    lead to the file from anywhere (links followed, as the command line records it)."""
    import hashlib

    import pandas as pd

    pd.DataFrame({"n_layers": [1, 2, 3], "width_mm": [0.11, 0.205, 0.3]}).to_csv(
        tmp_path / "cal.csv", index=False)
    os.symlink(tmp_path / "cal.csv", tmp_path / "link.csv")
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cs.analyze(scan, **KW, calibration="link.csv")
    real = str((tmp_path / "cal.csv").resolve())
    assert res.summary["calibration"] == real
    assert res.summary["parameters"]["calibration"] == real
    # the file's content and table, as a batch records them
    rec = res.summary["inputs"]["calibration"]
    assert rec["path"] == "link.csv" and rec["resolved"] == real
    assert rec["sha256"] == hashlib.sha256((tmp_path / "cal.csv").read_bytes()).hexdigest()
    assert rec["widths"] == {"n_layers": [1, 2, 3], "width_mm": [0.11, 0.205, 0.3]}


def test_the_summary_records_the_smoothing_window_used(result):
    """Derived from h by default, like the tangent length: the value used, not null."""
    from crosssection.stages.curvature import default_smooth_px
    from crosssection.tables import recorded_parameters

    assert result.summary["parameters"]["smooth_px"] == default_smooth_px(5.0) == 11
    assert result.summary["parameters"]["tangent_mm"] == 0.3  # 3 h, not 0.30000000000000004
    assert recorded_parameters(cs.AnalysisParams(smooth_px=7))["smooth_px"] == 7


def test_the_summary_records_what_the_analysis_read(scan, result, tmp_path, monkeypatch):
    """The scan by path and SHA-256 (an array by shape and dtype) and the library
    versions."""
    import hashlib

    from crosssection.core.provenance import ANALYSIS_LIBRARIES

    s = result.summary
    assert s["inputs"]["image"] == {"path": None, "resolved": None, "sha256": None,
                                    "shape": list(scan.shape), "dtype": "uint8"}
    assert s["inputs"]["calibration"] is None and s["image"]["path"] is None
    assert set(s["libraries"]) == set(ANALYSIS_LIBRARIES)
    assert s["libraries"]["numpy"] == np.__version__ and s["libraries"]["opencv"]
    cv2.imwrite(str(tmp_path / "scan.png"), scan[..., ::-1])
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cs.analyze("scan.png", **KW)
    real = str((tmp_path / "scan.png").resolve())
    assert res.summary["image"]["path"] == real
    assert res.summary["inputs"]["image"] == {
        "path": "scan.png", "resolved": real,
        "sha256": hashlib.sha256((tmp_path / "scan.png").read_bytes()).hexdigest()}


def test_a_scan_replaced_while_it_is_analysed_is_not_recorded_by_the_new_content(
        scan, tmp_path, monkeypatch):
    """The hash is of a second read of the file: a file that changed meanwhile is recorded
    without it, and said; a hash the caller gives is recorded as given."""
    import time

    from crosssection.core import provenance
    from crosssection.quality import InputWarning

    path = tmp_path / "scan.png"
    cv2.imwrite(str(path), scan[..., ::-1])
    hash_file = provenance.file_sha256

    def replaced_while_hashed(p, chunk=1 << 20):
        os.utime(p, ns=(time.time_ns(), time.time_ns() + 10**9))  # written again
        return hash_file(p, chunk)

    monkeypatch.setattr(provenance, "file_sha256", replaced_while_hashed)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = cs.analyze(path, **KW)
    assert res.summary["inputs"]["image"]["sha256"] is None
    said = [w for w in caught if issubclass(w.category, InputWarning)]
    assert len(said) == 1 and "changed while it was analysed" in str(said[0].message)
    assert any("SHA-256 not recorded" in w for w in res.summary["warnings"])
    monkeypatch.setattr(provenance, "file_sha256", hash_file)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        given = cs.analyze(path, **KW, image_sha256="ab" * 32)
    assert given.summary["inputs"]["image"]["sha256"] == "ab" * 32


def test_a_calibration_object_that_is_no_table_serves_and_is_recorded_as_such(scan):
    """An object with ``layers`` and ``width`` methods is a width law: it analyses as given;
    the record names it instead of passing its type for a file path."""
    class Law:
        def layers(self, width_mm):
            return np.asarray(width_mm, float) / 0.1 - 0.4

        def width(self, n):
            return 0.1 * (np.asarray(n, float) + 0.4)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cs.analyze(scan, **KW, calibration=Law())
    assert len(res.tables["stacks"]) > 0
    assert res.summary["parameters"]["calibration"] == {"object": "Law"}
    with pytest.raises(ParameterError, match="a Law object, which a record cannot hold"):
        cs.AnalysisParams(**res.summary["parameters"])


def test_the_default_smoothing_window_of_any_sheet_is_accepted_back():
    from crosssection.tables import recorded_parameters

    p = cs.AnalysisParams(px_per_mm=100, thickness_mm=52.0)
    assert cs.AnalysisParams(**recorded_parameters(p)).smooth_px == 10401


def test_a_parameter_file_with_a_misspelt_key_is_refused(tmp_path):
    # a misspelt key read as "not a parameter" would analyse every scan at the default scale
    from crosssection import AnalysisParams
    from crosssection.core.errors import ParameterError

    typo = tmp_path / "typo.toml"
    typo.write_text("px_per_m = 25\nthickness_mm = 0.2\n")
    with pytest.raises(ParameterError, match="px_per_m'") as info:
        AnalysisParams.from_toml(typo)
    assert "typo.toml" in str(info.value)
    good = tmp_path / "set.toml"
    good.write_text('name = "a"\npx_per_mm = 25\n[images."x.png"]\nhole_radius_mm = 5\n')
    assert AnalysisParams.from_toml(good).px_per_mm == 25


@pytest.mark.parametrize("px_per_mm, thickness_mm", [("50", 0.1), (-1, 0.1), (50, 0),
                                                      (float("nan"), 0.1), (50, True)])
def test_a_scan_scale_refuses_what_analysis_parameters_refuse(px_per_mm, thickness_mm):
    with pytest.raises(ParameterError):
        cs.ScanScale(px_per_mm, thickness_mm)
    assert cs.ScanScale(25, 0.2).to_px(2) == 50.0


@pytest.mark.parametrize("name", ["rod_length_mm", "kappa_c_per_mm", "tangent_mm"])
def test_values_beyond_any_scan_are_refused_before_they_overflow(name):
    with pytest.raises(ParameterError, match=f"^{name} = 1e\\+300 is beyond any scan"):
        cs.AnalysisParams(**{name: 1e300})
    ok = 2.0 if name == "tangent_mm" else 1000.0  # a tangent is at most 20 h
    assert getattr(cs.AnalysisParams(**{name: ok}), name) == ok


def test_a_tangent_beyond_twenty_sheet_thicknesses_is_refused():
    # 100 mm on a 15-mm hole turned 201 branches into 293, and no warning named it
    from crosssection.core.errors import ParameterError

    with pytest.raises(ParameterError, match="tangent_mm = 2.1 mm is more than 20 sheet"):
        cs.AnalysisParams(thickness_mm=0.1, tangent_mm=2.1)
    assert cs.AnalysisParams(thickness_mm=0.2, tangent_mm=2.1).tangent_mm == 2.1


def test_a_smoothing_window_beyond_ten_sheet_thicknesses_is_refused():
    from crosssection.core.errors import ParameterError

    assert cs.AnalysisParams(px_per_mm=50, thickness_mm=0.1, smooth_px=50).smooth_px == 50
    with pytest.raises(ParameterError, match="smooth_px = 51 px is more than 10 sheet"):
        cs.AnalysisParams(px_per_mm=50, thickness_mm=0.1, smooth_px=51)
    # the bound follows h
    assert cs.AnalysisParams(px_per_mm=100, thickness_mm=0.1, smooth_px=51).smooth_px == 51


@pytest.mark.parametrize("name, value, cause", [
    ("bending_rigidity_J", 1e308, "beyond any scan"),
    ("kappa_c_per_mm", 1e-300, "below any scan"),
    ("sliver_width_h", 1e300, "beyond any scan"),
    ("tangent_mm", 1e-9, "a tangent is fitted on one pixel or more"),
])
def test_values_no_scan_can_mean_are_refused(name, value, cause):
    # such values give an energy in J that overflows, energies of 1e-296, or fits on a
    # billionth of a pixel
    from crosssection.core.errors import ParameterError

    with pytest.raises(ParameterError, match=cause) as err:
        cs.AnalysisParams(px_per_mm=50, thickness_mm=0.1, **{name: value})
    assert err.value.one_line().startswith(name)
    # values a sheet can have pass
    typical = {"bending_rigidity_J": 1e-4, "kappa_c_per_mm": 1e-3, "sliver_width_h": 3.0,
               "tangent_mm": 0.05}[name]
    assert getattr(cs.AnalysisParams(px_per_mm=50, thickness_mm=0.1, **{name: typical}),
                   name) == typical


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64])
def test_a_float_image_is_converted_in_blocks_as_in_one_piece(monkeypatch, dtype):
    """In one piece the float64 copy of a 4000 x 4000 scan and its temporaries took 1.1 GB."""
    from crosssection.core.errors import ImageError
    from crosssection.stages import load

    monkeypatch.setattr(load, "_FLOAT_CHUNK", 60)  # blocks of 4 rows of 5 x 3 values
    a = np.random.default_rng(1).random((13, 5, 3)).astype(dtype)
    ref = np.round(a.astype(np.float64) * 65535.0).astype(np.uint16)
    assert np.array_equal(load._float_to_uint16(a), ref)
    a[12, 4, 2] = 1.5  # in the last block
    with pytest.raises(ImageError, match=r"values .*\.\.1\.5: they must lie in \[0, 1\]"):
        load._float_to_uint16(a)
    a[12, 4, 2] = np.nan
    with pytest.raises(ImageError, match="NaN or infinite"):
        load._float_to_uint16(a)


@pytest.mark.parametrize("make, says", [
    (lambda a: np.moveaxis(a, -1, 0), "numpy.moveaxis"),
    (lambda a: a.astype(np.float32), "divide by 255"),
    (lambda a: a.astype(np.int16) - 128, "negative pixel values"),
])
def test_an_array_in_a_common_wrong_form_is_refused_with_the_fix(scan, make, says):
    from crosssection.core.errors import ImageError

    with pytest.raises(ImageError, match=says):
        cs.analyze(make(scan), **KW)


def test_an_image_object_is_refused_with_the_fix(scan):
    from PIL import Image

    from crosssection.core.errors import ImageError

    with pytest.raises(ImageError, match=r"numpy\.asarray"):
        cs.analyze(Image.fromarray(scan), **KW)


def test_results_compare_by_identity(result):
    import pickle

    again = pickle.loads(pickle.dumps(result))
    assert result == result and result != again
    assert again.summary["n_branches"] == result.summary["n_branches"]


def test_a_scan_without_junctions_has_the_tables_dtypes_of_one_with_them(result):
    img = np.full((400, 400, 3), 245, np.uint8)
    img[195:205, 50:350] = (31, 57, 167)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lone = cs.analyze(img, **KW, hole_radius_mm=3.8, hole_center_px=[200, 200])
    assert len(lone.junctions) == 0 and len(result.junctions) > 0
    assert lone.junctions.dtypes.to_dict() == result.junctions.dtypes.to_dict()


def test_the_paper_method_records_no_share_of_energy_on_the_fork_zone_model(scan):
    """The paper's method estimates no per-stack uncertainty: its total is unknown, not 1."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = cs.analyze(scan, **KW, curvature_method="paper")
    assert res.stacks["energy_rel_uncertainty"].isna().all()
    assert res.summary["total_energy_rel_uncertainty"] is None


def test_an_empty_image_path_is_named_so(tmp_path, capsys):
    """Path("") is the working folder: an empty path is named as such, not as a folder."""
    import crosssection.cli
    from crosssection.core.errors import ImageError

    with pytest.raises(ImageError, match="empty image path"):
        cs.analyze("")
    for command in ("analyze", "steps"):
        assert crosssection.cli.main([command, "", "--out", str(tmp_path / command)]) == 2
        assert capsys.readouterr().err == "error: empty image path: give the scan's file\n"


def test_a_parameter_table_inherits_the_top_level_and_a_missing_one_is_refused(tmp_path):
    # a table misspelt read as empty gave every default: the top level's scale lost with it
    from crosssection import AnalysisParams
    from crosssection.core.errors import ParameterError
    from crosssection.setconfig import load_set_config

    f = tmp_path / "p.toml"
    f.write_text("px_per_mm = 40\n[dense]\ns_min_mm2 = 0.02\n")
    p = AnalysisParams.from_toml(f, table="dense")
    assert (p.px_per_mm, p.s_min_mm2) == (40, 0.02)
    with pytest.raises(ParameterError, match=r"no parameter table \[nope\].*dense"):
        AnalysisParams.from_toml(f, table="nope")
    s = tmp_path / "set.toml"
    s.write_text('px_per_mm = 40\n[images."a.png"]\nhole_radius_mm = 5\n')
    with pytest.raises(ParameterError, match="params_for"):
        AnalysisParams.from_toml(s, table="images")
    # an image named as the set.toml names it, or by a path the caller reaches it by
    cfg = load_set_config(s)
    assert cfg.params_for("a.png")["hole_radius_mm"] == 5
    assert cfg.params_for(tmp_path / "a.png")["hole_radius_mm"] == 5
    with pytest.raises(ParameterError, match="outside the set folder"):
        cfg.params_for(tmp_path.parent / "b.png")
