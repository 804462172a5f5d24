"""``render`` refuses bad input with one ``error:`` line and exit status 2, and never mixes two
renders in one output folder (simulate.render)."""
import json
import os
import shutil
from pathlib import Path

import numpy as np
from PIL import Image
import pytest

from crosssection._version import __version__
from crosssection.core.calibration import Calibration
from crosssection.core.errors import ParameterError
from simulate import render
from simulate.cli import main
from simulate.render import render_configuration, render_directory

#: the truth checks of these scenes (test_render_truth.py) are not what is tested here
# short rods, below the segment count the renders' truth is validated from, on purpose
pytestmark = [pytest.mark.filterwarnings("ignore::simulate.render.TruthWarning"),
              pytest.mark.filterwarnings("ignore:.*the render's truth is validated from:"
                                         "simulate.render.ScanRangeWarning")]

#: small clean scans at the validated range's coarsest resolution (h = 2.5 px), so that a
#: render says nothing unless something is wrong
FAST = ["--px-per-mm", "25", "--clean"]


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """A quench ensemble of two short rods."""
    out = tmp_path_factory.mktemp("quench") / "sim"
    assert main(["quench", "--n-configs", "2", "--segments", "100", "--seed", "1",
                 "--workers", "1", "--runs", "2", "--nematic-runs", "0", "--maxiter", "5",
                 "--no-progress", "--out", str(out)]) == 0
    return out


def _render(capsys, *argv):
    """Exit status and stderr of ``render *argv``, without the scenes' truth checks (the
    short rods here lie outside the validated range; tests/simulate/test_render_truth.py)."""
    capsys.readouterr()
    status = main(["render", *map(str, argv)])
    truth = ("from the drawn ink", "the drawn rod is cut", "do not all touch there",
             "allowing for the bands' width", "the truth's stacks hold",
             "touch in the drawing", "length 0:", "the render's truth is validated from")
    return status, "".join(line for line in capsys.readouterr().err.splitlines(True)
                           if not any(t in line for t in truth))


def _short_rod(w) -> bool:
    """Whether a warning is the short rods' own (their segment count is below the validated
    one; tests/simulate/test_render_ranges.py)."""
    return "the render's truth is validated from" in str(w.message)


def _one_error(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err and "unexpected" not in err, err
    return lines[0]


def test_negative_seed_exits_2_naming_the_option(sim, tmp_path, capsys):
    status, err = _render(capsys, sim, "--out", tmp_path / "s", "--seed", "-1", "--limit", "1")
    assert status == 2
    assert _one_error(err).startswith("error: --seed: must be a whole number >= 0")
    assert not (tmp_path / "s").exists()
    xy = np.load(sim / "rods.npz")["config_00000"]
    with pytest.raises(ParameterError, match="seed"):
        render_configuration(xy, seed=-1)


@pytest.mark.parametrize("option", ["--smears", "--specks", "--pinholes"])
def test_marks_beyond_a_scan_are_refused_before_drawing(sim, tmp_path, capsys, option):
    """A hundred million smears would be drawn one by one for minutes: refused at once."""
    status, err = _render(capsys, sim, "--out", tmp_path / "s", option, "100000000",
                          "--limit", "1")
    assert status == 2
    assert _one_error(err).startswith(f"error: {option}: must be at most 1000")
    assert not (tmp_path / "s").exists()


def test_a_size_cap_reaches_the_command_line_and_flags_the_scene(sim, tmp_path, capsys):
    """``render`` passes on the size cap's warning with the truth checks of each scene, and
    the capped scene's truth is flagged."""
    status, err = _render(capsys, sim, "--out", tmp_path / "s", "--limit", "1", "--clean",
                          "--thickness-mm", "1")
    assert status == 0
    assert "rod length capped" in err and err.startswith("warning: ")
    assert "beyond the contact distance" in err and "delta" not in err  # no symbol unexplained
    summary = json.loads((tmp_path / "s" / "config_00000" / "truth" / "summary.json")
                         .read_text())
    assert any("rod length capped" in m for m in summary["truth_warnings"])


@pytest.mark.parametrize("content", ["garbage", "truncated", "npy"])
@pytest.mark.parametrize("limit", [[], ["--limit", "1"]])
def test_unreadable_rods_exit_2_with_or_without_limit(sim, tmp_path, capsys, content, limit):
    bad = tmp_path / "bad"
    bad.mkdir()
    shutil.copy(sim / "params.json", bad)
    data = (sim / "rods.npz").read_bytes()
    if content == "garbage":
        (bad / "rods.npz").write_bytes(b"not an archive\n")
    elif content == "truncated":
        (bad / "rods.npz").write_bytes(data[: len(data) // 3])
    else:
        with open(bad / "rods.npz", "wb") as f:  # one bare array under the archive's name
            np.save(f, np.zeros((5, 2)))
    status, err = _render(capsys, bad, "--out", tmp_path / "s", *limit, *FAST)
    assert status == 2
    assert _one_error(err).startswith(f"error: {bad / 'rods.npz'}: unreadable rods file (")


@pytest.mark.parametrize("limit", [[], ["--limit", "1"]])
def test_a_file_given_as_the_input_is_not_a_simulation_folder(tmp_path, capsys, limit):
    afile = tmp_path / "afile"
    afile.write_text("hello\n")
    status, err = _render(capsys, afile, "--out", tmp_path / "s", *limit)
    assert status == 2
    line = _one_error(err)
    assert line.startswith(f"error: {afile}: not a simulation folder")
    assert "--out" not in line


@pytest.mark.parametrize("flags", [["--px-per-mm", "1e6"], ["--thickness-mm", "100"],
                                   ["--rod-length-mm", "1e5"]])
def test_a_scene_over_the_pixel_budget_is_refused_before_drawing(sim, tmp_path, capsys,
                                                                 monkeypatch, flags):
    def drawn(*args, **kwargs):
        raise AssertionError("drawn")

    # the first steps whose memory grows with the image
    for f in ("_hooked_lines", "_stack_lines", "_draw_bands", "_draw_passes"):
        monkeypatch.setattr(render, f, drawn)
    status, err = _render(capsys, sim, "--out", tmp_path / "s", "--limit", "1", *flags)
    assert status == 2
    line = _one_error(err)
    assert line.startswith("error: --px-per-mm: the scene would be ")
    w, h = (int(v) for v in line.split("would be ")[1].split(" px")[0].split(" x "))
    assert w * h > render.MAX_SCENE_PX
    assert "(> 10000 x 10000 px)" in line
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("flags", [["--px-per-mm", "0.01"], ["--thickness-mm", "0.005"]])
def test_a_sheet_thinner_than_a_pixel_is_refused(sim, tmp_path, capsys, flags):
    status, err = _render(capsys, sim, "--out", tmp_path / "s", "--limit", "1", *flags)
    assert status == 2
    assert _one_error(err).startswith("error: --px-per-mm: a sheet would be ")
    assert not (tmp_path / "s").exists()


def test_margins_over_the_size_cap_do_not_mirror_the_rod():
    """Margins alone wider than max_size_px leave no positive rod length under the cap: the
    gap's length is kept (a negative one would draw the rod mirrored)."""
    xy = np.c_[np.linspace(0.0, 0.2, 11), np.zeros(11)]
    with pytest.warns(UserWarning, match="margins alone"):
        length, gap_ok = render._rod_length_mm(
            xy, 0.01, Calibration.nonlinear(0.1), 1, rod_length_mm=None, px_per_mm=50.0,
            gap_px=2.0, margin_mm=30.0, max_size_px=2500)
    assert length > 0 and gap_ok


@pytest.mark.parametrize("out", ["", "  "])
def test_an_empty_out_is_refused(sim, tmp_path, capsys, monkeypatch, out):
    monkeypatch.chdir(tmp_path)
    status, err = _render(capsys, sim, "--out", out, "--limit", "1", *FAST)
    assert status == 2
    assert _one_error(err) == "error: --out: empty path: give the output folder"
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ParameterError, match="empty path"):
        render_directory(sim, out, configs=["config_00000"])
    assert list(tmp_path.iterdir()) == []


def test_the_input_folder_is_not_an_output(sim, capsys):
    before = sorted(p.name for p in sim.iterdir())
    status, err = _render(capsys, sim, "--out", sim / ".", "--limit", "1", *FAST)
    assert status == 2
    assert _one_error(err).startswith("error: --out: ")
    assert "simulation folder" in err
    assert sorted(p.name for p in sim.iterdir()) == before


def test_a_rerun_resumes_only_with_the_same_parameters_and_source(sim, tmp_path, capsys):
    out = tmp_path / "scenes"
    base = ["--out", out, "--seed", "1", *FAST]
    assert _render(capsys, sim, *base, "--limit", "1") == (0, "")
    record = json.loads((out / "render.json").read_text())
    assert record["version"] == __version__
    assert record["source"] == str(sim.resolve())
    assert record["params"]["seed"] == 1 and record["params"]["px_per_mm"] == 25.0
    assert record["params"]["clean"] is True and record["source_params"]["seed"] == 1
    first = (out / "config_00000" / "image.png").read_bytes()

    # the same parameters (a defect given at the value it has anyway): resume
    assert _render(capsys, sim, *base, "--noise", "0") == (0, "")
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["config_00000",
                                                                   "config_00001"]

    for flags, named in ((["--seed", "2", *FAST], "--seed"),
                         (["--seed", "1", "--px-per-mm", "30", "--clean"], "--px-per-mm"),
                         (["--seed", "1", "--px-per-mm", "25"], "--clean"),
                         (["--seed", "1", *FAST, "--draw", "passes"], "--draw")):
        status, err = _render(capsys, sim, "--out", out, *flags)
        assert status == 2, flags
        line = _one_error(err)
        assert line.startswith(f"error: {out}: output folder holds scenes of another render "
                               "(parameters differ: ")
        assert line.split("differ: ")[1].split(")")[0] == named, line
    # another ensemble, even with the same rods
    other = tmp_path / "other"
    shutil.copytree(sim, other)
    status, err = _render(capsys, other, *base)
    assert status == 2 and "source folder" in _one_error(err)
    assert (out / "config_00000" / "image.png").read_bytes() == first


def test_a_changed_source_ensemble_is_refused(sim, tmp_path, capsys):
    src = tmp_path / "sim"
    shutil.copytree(sim, src)
    out = tmp_path / "scenes"
    assert _render(capsys, src, "--out", out, "--limit", "1", *FAST)[0] == 0
    p = json.loads((src / "params.json").read_text())
    (src / "params.json").write_text(json.dumps({**p, "seed": 99}))
    status, err = _render(capsys, src, "--out", out, *FAST)
    assert status == 2 and "source ensemble" in _one_error(err)
    assert not (out / "config_00001").exists()


def test_an_ensemble_recording_its_defaults_as_null_is_the_same_source(sim, tmp_path, capsys):
    # an older ensemble folder recorded None for its defaults; resumed, it writes them out:
    # the scenes rendered from it before resume, and the other way round
    src = tmp_path / "sim"
    shutil.copytree(sim, src)
    p = json.loads((src / "params.json").read_text())
    assert p["contact_distance"] is not None and p["parametrization"] == "tangent"
    nulls = {**p, "contact_distance": None, "parametrization": None, "nematic_cutoff": None}
    for first, then in ((nulls, p), (p, nulls)):
        out = tmp_path / f"scenes_{first is p}"
        (src / "params.json").write_text(json.dumps(first))
        assert _render(capsys, src, "--out", out, "--limit", "1", *FAST)[0] == 0
        (src / "params.json").write_text(json.dumps(then))
        assert _render(capsys, src, "--out", out, *FAST)[0] == 0
        assert (out / "config_00001" / "image.png").exists()


def test_a_folder_holding_other_files_is_refused(sim, tmp_path, capsys):
    # a finished ensemble: scenes written beside its tables would stop it resuming
    ens = tmp_path / "ens"
    shutil.copytree(sim, ens)
    before = sorted(p.name for p in ens.iterdir())
    status, err = _render(capsys, sim, "--out", ens, "--limit", "1", *FAST)
    assert status == 2
    assert _one_error(err) == (f"error: {ens}: holds branches.csv, which is no part of a render "
                               "output: give a new folder, an empty one or one an earlier "
                               "render wrote")
    assert sorted(p.name for p in ens.iterdir()) == before
    assert main(["quench", "--n-configs", "2", "--segments", "100", "--seed", "1",
                 "--workers", "1", "--runs", "2", "--nematic-runs", "0", "--maxiter", "5",
                 "--no-progress", "--out", str(ens)]) == 0
    # a user's folder
    junk = tmp_path / "junk"
    junk.mkdir()
    (junk / "notes.txt").write_text("hi\n")
    status, err = _render(capsys, sim, "--out", junk, "--limit", "1", *FAST)
    assert status == 2 and "holds notes.txt, which is no part of a render output" in err
    assert sorted(p.name for p in junk.iterdir()) == ["notes.txt"]
    with pytest.raises(render.ConfigError, match="holds notes.txt"):
        render_directory(sim, junk, px_per_mm=25, clean=True)


def test_a_render_resumes_beside_its_own_report_and_half_written_scene(sim, tmp_path,
                                                                     capsys):
    out = tmp_path / "scenes"
    assert _render(capsys, sim, "--out", out, "--limit", "1", *FAST) == (0, "")
    # a validate report written inside, a scene a killed render left with its image alone,
    # the leftover of an atomic write and a browser's file
    (out / "rep").mkdir()
    (out / "rep" / "scores.csv").write_text("scene\n")
    (out / "begun").mkdir()  # a validate report begun: validate makes its folder first
    (out / "config_00001").mkdir()
    (out / "config_00001" / "image.png").write_bytes(b"")
    (out / ".render.json.abc123.json").write_text("")
    (out / ".DS_Store").write_text("")
    assert _render(capsys, sim, "--out", out, *FAST) == (0, "")
    assert (out / "config_00001" / "truth" / "summary.json").exists()


def test_a_render_is_one_set_a_batch_analyses_as_validate_does(sim, tmp_path, capsys):
    """Each scene's set.toml gives the analysis validate runs, its hole its image's own; the
    scenes of one render share the set's name, so that a batch of them is one ensemble
    (each scene its own set gave stats nothing to fit)."""
    from crosssection.setconfig import load_set_config
    from crosssection.truth.scene import read_scene_params

    out = tmp_path / "scenes"
    assert _render(capsys, sim, "--out", out, "--limit", "1", *FAST) == (0, "")
    scene = out / "config_00000"
    params = read_scene_params(scene)
    assert params["hole_radius_mm"] and params["hole_center_px"]
    got = load_set_config(scene / "set.toml", root=out)
    assert got.name == "scenes" and got.warnings == []
    # what validate passes the analysis (crosssection.truth.scoring.analyze_scene_folder)
    assert got.params_for(scene / "image.png") == {
        "px_per_mm": params["px_per_mm"], "thickness_mm": params["thickness_mm"],
        "hole_radius_mm": params["hole_radius_mm"],
        "hole_center_px": params["hole_center_px"],
        "calibration": str((scene / "calibration.csv").resolve())}
    # a scene rendered without it (an older version) gets it when the render resumes
    (scene / "set.toml").unlink()
    assert _render(capsys, sim, "--out", out, *FAST) == (0, "")
    assert load_set_config(scene / "set.toml", root=out).params == got.params
    assert (out / "config_00001" / "set.toml").exists()
    import pandas as pd

    from crosssection.cli import main as foldstat

    assert foldstat(["batch", str(out), "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    index = pd.read_csv(tmp_path / "b" / "index.csv")
    assert len(index) == 2 and set(index["set"]) == {"scenes"}


def test_scenes_without_a_record_are_refused(sim, tmp_path, capsys):
    out = tmp_path / "scenes"
    assert _render(capsys, sim, "--out", out, "--limit", "1", *FAST)[0] == 0
    (out / "render.json").unlink()
    status, err = _render(capsys, sim, "--out", out, *FAST)
    assert status == 2
    assert _one_error(err).startswith(f"error: {out}: output folder holds scenes but no "
                                      "render.json")
    assert not (out / "config_00001").exists()
    (out / "render.json").write_text("{not json")
    status, err = _render(capsys, sim, "--out", out, *FAST)
    assert status == 2 and "render.json: unreadable render.json" in _one_error(err)


def test_a_missing_params_json_is_a_warning(sim, tmp_path, capsys):
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(sim / "rods.npz", bare)
    status, err = _render(capsys, bare, "--out", tmp_path / "s", "--limit", "1", *FAST)
    assert status == 0
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"warning: {bare / 'params.json'}: missing: the rods are drawn "
                               "as a quench's (no wall, default scale")
    # with its params.json the same render says nothing
    assert _render(capsys, sim, "--out", tmp_path / "t", "--limit", "1", *FAST) == (0, "")


def test_the_default_render_says_nothing(sim, tmp_path, capsys):
    """The defaults lie within the ranges the image analysis is validated on."""
    import warnings

    assert _render(capsys, sim, "--out", tmp_path / "s", "--limit", "1") == (0, "")
    xy = np.load(sim / "rods.npz")["config_00000"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        render_configuration(xy)
        render_directory(sim, tmp_path / "api", configs=["config_00000"])
    assert [w for w in caught if issubclass(w.category, render.ScanRangeWarning)
            and not _short_rod(w)] == []


@pytest.mark.parametrize("flags, says", [
    (["--px-per-mm", "20"], "a sheet 2 px thick (--px-per-mm x --thickness-mm) is below 2.5 px"),
    (["--thickness-mm", "0.04"], "a sheet 2 px thick (--px-per-mm x --thickness-mm) is below "
                                 "2.5 px"),
    (["--blur", "2"], "--blur 2 is above 1.5 px"),
    (["--noise", "12"], "--noise 12 is above 10 grey levels"),
    (["--jpeg", "60"], "--jpeg 60 is below 75"),
])
def test_an_option_beyond_the_validated_range_is_one_warning_per_run(sim, tmp_path, capsys,
                                                                    flags, says):
    out = tmp_path / "s"
    status, err = _render(capsys, sim, "--out", out, *flags)
    assert status == 0
    assert err == (f"warning: {out}: scans beyond the range the image analysis is validated "
                   f"on: {says}\n")
    assert len([p for p in out.iterdir() if p.is_dir()]) == 2  # two scenes, one line


def test_every_option_beyond_the_range_is_named_in_the_one_line(sim, tmp_path, capsys):
    out = tmp_path / "s"
    status, err = _render(capsys, sim, "--out", out, "--px-per-mm", "20", "--blur", "2",
                          "--noise", "12", "--jpeg", "60")
    assert status == 0 and len(err.splitlines()) == 1
    assert err == (f"warning: {out}: scans beyond the range the image analysis is validated "
                   "on: a sheet 2 px thick (--px-per-mm x --thickness-mm) is below 2.5 px; "
                   "--blur 2 is above 1.5 px; --noise 12 is above 10 grey levels; --jpeg 60 is "
                   "below 75\n")


def test_the_validated_limits_themselves_say_nothing(sim, tmp_path, capsys):
    assert _render(capsys, sim, "--out", tmp_path / "s", "--limit", "1", "--px-per-mm", "25",
                   "--blur", "1.5", "--noise", "10", "--jpeg", "75") == (0, "")
    assert _render(capsys, sim, "--out", tmp_path / "t", "--limit", "1",
                   "--jpeg", "none") == (0, "")
    # 0 is no JPEG, as the API's jpeg_quality=0: the same bytes as 'none'
    assert _render(capsys, sim, "--out", tmp_path / "u", "--limit", "1",
                   "--jpeg", "0") == (0, "")
    scans = [sorted(tmp_path.glob(f"{d}/*/image.png")) for d in ("t", "u")]
    assert scans[0] and [p.read_bytes() for p in scans[0]] == [p.read_bytes() for p in scans[1]]


def test_the_api_warns_with_its_own_category(sim, tmp_path):
    import warnings

    from crosssection.quality import QualityWarning

    xy = np.load(sim / "rods.npz")["config_00000"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        render_configuration(xy, blur_px=2.0, clean=True)
    assert [str(w.message) for w in caught if issubclass(w.category, render.ScanRangeWarning)
            and not _short_rod(w)] == ["scans beyond the range the image analysis is "
                                       "validated on: blur_px 2 is above 1.5 px"]
    assert issubclass(render.ScanRangeWarning, QualityWarning)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        render_directory(sim, tmp_path / "s", px_per_mm=20.0, clean=True)
    mine = [str(w.message) for w in caught if issubclass(w.category, render.ScanRangeWarning)
            and not _short_rod(w)]
    assert mine == [f"{tmp_path / 's'}: scans beyond the range the image analysis is validated "
                    "on: a sheet 2 px thick (px_per_mm x thickness_mm) is below 2.5 px"]


def test_the_scale_defaults_are_those_of_render_configuration():
    import inspect

    from simulate.cli import build_parser

    sig = inspect.signature(render_configuration).parameters
    args = build_parser(["render"]).parse_args(["render", "d", "--out", "s"])
    assert args.px_per_mm == sig["px_per_mm"].default
    assert args.thickness_mm == sig["thickness_mm"].default
    # the defaults lie within the validated range: a sheet of at least VALIDATED_SHEET_PX
    assert args.px_per_mm * args.thickness_mm >= render.VALIDATED_SHEET_PX


def test_a_hole_smaller_than_the_rod_is_refused(sim, tmp_path, capsys):
    # the hole holds the cut: a scene whose ink lies on the plate is no scan of one
    out = tmp_path / "scenes"
    status, err = _render(capsys, sim, "--out", out, "--hole", "0.5", *FAST)
    assert status == 2 and "smaller than the rod" in _one_error(err) and "--hole" in err
    assert not out.exists()
    # it says where a given hole is centred and the least radius it takes, which holds the rod
    import re

    assert "centred on the rod's centroid" in err
    least = re.search(r"give at least ([0-9.e+]+) mm", err).group(1)
    status, err = _render(capsys, sim, "--out", out, "--hole", least, "--limit", "1", *FAST)
    assert status == 0, err


@pytest.mark.parametrize("plate, ok", [("200,120,60", True), ("10,20", False),
                                       ("300,20,1", False), ("a,b,c", False)])
def test_a_plate_is_given_on_the_command_line_as_a_triple(sim, tmp_path, capsys, plate, ok):
    out = tmp_path / "scenes"
    status, err = _render(capsys, sim, "--out", out, "--plate", plate, "--limit", "1", *FAST)
    if ok:
        assert status == 0
        img = np.asarray(Image.open(out / "config_00000" / "image.png").convert("RGB"))
        assert np.abs(img[2, 2].astype(int) - (200, 120, 60)).max() <= 12  # the corner: plate
    else:
        assert status == 2 and "--plate" in _one_error(err)


@pytest.mark.parametrize("limit", ["0", "-1"])
def test_a_limit_below_one_is_refused(sim, tmp_path, capsys, limit):
    status, err = _render(capsys, sim, "--out", tmp_path / "s", "--limit", limit, *FAST)
    assert status == 2
    assert _one_error(err) == f"error: --limit: must be >= 1, got {limit}"
    assert not (tmp_path / "s").exists()


def test_an_ensemble_whose_every_configuration_failed_is_refused(sim, tmp_path, capsys):
    """Its rods.npz holds no configuration: rendering nothing would read as a finished
    render."""
    failed = tmp_path / "failed"
    failed.mkdir()
    shutil.copy(sim / "params.json", failed)
    np.savez(failed / "rods.npz")
    (failed / "failures.csv").write_text("config_id,seed,error\n0,1,AnalysisError: x\n")
    status, err = _render(capsys, failed, "--out", tmp_path / "s", *FAST)
    assert status == 2
    assert _one_error(err) == (f"error: {failed}: no finished configuration to render in "
                               f"rods.npz (see {failed / 'failures.csv'})")
    assert not (tmp_path / "s").exists()
    with pytest.raises(render.ConfigError, match="no finished configuration"):
        render_directory(failed, tmp_path / "s", px_per_mm=25, clean=True)


def test_the_failed_configurations_of_an_ensemble_are_named(sim, tmp_path, capsys):
    """A render of the finished configurations said nothing of the failed ones."""
    some = tmp_path / "some"
    shutil.copytree(sim, some)
    (some / "failures.csv").write_text("config_id,seed,error\n2,1,AnalysisError: x\n")
    status, err = _render(capsys, some, "--out", tmp_path / "s", "--limit", "1", *FAST)
    assert status == 0
    assert (f"warning: {some}: 1 configuration(s) of the simulation failed and are not "
            f"rendered (see {some / 'failures.csv'})") in err.splitlines()
    status, err = _render(capsys, sim, "--out", tmp_path / "t", "--limit", "1", *FAST)
    assert status == 0 and "failed" not in err


@pytest.mark.parametrize("content, cause", [
    (b"junk\n", "not a NumPy .npz archive"),
    (b"", "empty file, not a NumPy .npz archive"),
    # numpy reads a file of no known format as a pickle
    (b"\x80\x04K\x01.", "not a NumPy .npz archive"),
])
def test_a_rods_file_of_another_format_is_named_so(sim, tmp_path, capsys, content, cause):
    bad = tmp_path / "bad"
    bad.mkdir()
    shutil.copy(sim / "params.json", bad)
    (bad / "rods.npz").write_bytes(content)
    status, err = _render(capsys, bad, "--out", tmp_path / "s", *FAST)
    assert status == 2
    assert _one_error(err) == f"error: {bad / 'rods.npz'}: unreadable rods file ({cause})"
    assert "pickle" not in err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_rods_file_that_is_a_named_pipe_is_refused_not_read(sim, tmp_path, capsys):
    bad = tmp_path / "bad"
    bad.mkdir()
    shutil.copy(sim / "params.json", bad)
    os.mkfifo(bad / "rods.npz")
    status, err = _render(capsys, bad, "--out", tmp_path / "s", *FAST)
    assert status == 2 and "is a named pipe, not a file" in _one_error(err)


def test_a_stopped_render_leaves_no_scene_folder_without_its_scene(sim, tmp_path,
                                                                  monkeypatch):
    """Writing a scene's image takes seconds: a stop meanwhile leaves no folder that validate
    would take for a failed scene, and the next run renders the scene."""
    out = tmp_path / "s"
    real = render.write_scene

    def stopped(scene, folder, **kw):
        Path(folder).mkdir(parents=True)
        (Path(folder) / "image.png").write_bytes(b"half")
        raise KeyboardInterrupt

    monkeypatch.setattr(render, "write_scene", stopped)
    with pytest.raises(KeyboardInterrupt):
        render_directory(sim, out, configs=["config_00000"], px_per_mm=25, clean=True)
    assert sorted(p.name for p in out.iterdir()) == [render.RENDER_RECORD]
    monkeypatch.setattr(render, "write_scene", real)
    # a killed render's hidden folder is no foreign file, and is replaced
    partial = out / ".config_00000.partial"
    partial.mkdir()
    (partial / "image.png").write_bytes(b"half")
    assert render_directory(sim, out, configs=["config_00000"], px_per_mm=25,
                            clean=True) == [out / "config_00000"]
    assert (out / "config_00000" / "truth" / "summary.json").is_file()
    assert sorted(p.name for p in out.iterdir()) == ["config_00000", render.RENDER_RECORD]


def test_a_quench_held_by_a_wall_renders_as_a_quench(sim, tmp_path, capsys):
    # quench --wall-radius records wall_radius without a thickness: render took it for a
    # compaction and failed on "thickness must be a number > 0 ... got None"
    src = tmp_path / "walled"
    shutil.copytree(sim, src)
    p = json.loads((src / "params.json").read_text())
    (src / "params.json").write_text(json.dumps({**p, "wall_radius": 0.5}))
    status, err = _render(capsys, src, "--out", tmp_path / "scenes", "--limit", "1", *FAST)
    assert status == 0 and "error" not in err
    # a compaction's record without its wall is still refused
    (src / "params.json").write_text(json.dumps({**p, "thickness": 1e-4}))
    status, err = _render(capsys, src, "--out", tmp_path / "other", *FAST)
    assert status == 2 and "wall_radius must be a number > 0" in _one_error(err)
