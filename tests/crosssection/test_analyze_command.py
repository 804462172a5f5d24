"""``analyze`` (command and API) names the set.toml or calibration.csv it does not read (only
``batch`` does);
``analyze`` and ``steps`` refuse an empty ``--out`` and leave their output folder describing
the last run alone."""
from __future__ import annotations

import dataclasses
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import crosssection.cli
import crosssection
from crosssection.commands import (OPTIONAL_OUTPUTS, OVERLAY, STEP_IMAGES, STEPS_FIGURE,
                                   STEPS_RECORD, remove_stale)
from crosssection.params import AnalysisParams
from crosssection.quality import QualityWarning, SetWarning
from crosssection.setconfig import set_not_read
from crosssection.samples import samples_path

SCAN = "scan_01_sparse.png"


@pytest.fixture
def set_folder(tmp_path):
    """A set: one sample scan, its calibration and a set.toml naming it and the scale."""
    src = samples_path()
    for name in (SCAN, "calibration.csv"):
        shutil.copy(src / name, tmp_path / name)
    (tmp_path / "set.toml").write_text('px_per_mm = 50\nthickness_mm = 0.1\n'
                                       'calibration = "calibration.csv"\n')
    return tmp_path


def test_a_set_toml_whose_values_are_not_used_is_named(set_folder):
    note = set_not_read(set_folder / SCAN, AnalysisParams())
    assert note is not None and "set.toml is not read by analyze" in note
    assert "calibration" in note and "px_per_mm" not in note  # the scale is the same


def test_a_set_toml_whose_values_are_passed_is_not_named(set_folder):
    params = AnalysisParams(calibration=str(set_folder / "calibration.csv"))
    assert set_not_read(set_folder / SCAN, params) is None


def test_a_calibration_given_as_a_table_is_compared_by_its_values(set_folder):
    """A DataFrame calibration crashed the comparison with the set's (the truth value of a
    DataFrame is ambiguous), and with no set.toml, the look for a calibration.csv beside."""
    table = pd.read_csv(set_folder / "calibration.csv")
    assert set_not_read(set_folder / SCAN, AnalysisParams(calibration=table)) is None
    other = table.assign(width_mm=table["width_mm"] * 1.1)
    note = set_not_read(set_folder / SCAN, AnalysisParams(calibration=other))
    assert note is not None and "its calibration for this scan differs" in note
    (set_folder / "set.toml").unlink()
    assert set_not_read(set_folder / SCAN, AnalysisParams(calibration=table)) is None


def test_a_value_rounded_as_a_set_toml_records_it_is_the_same(set_folder):
    (set_folder / "set.toml").write_text('px_per_mm = 50\nthickness_mm = 0.1\n'
                                         'hole_radius_mm = 7.5742\n'
                                         'hole_center_px = [428.06, 426.92]\n')
    params = AnalysisParams(hole_radius_mm=7.574174774219351,
                            hole_center_px=(428.0562755100713, 426.9233176459393))
    assert set_not_read(set_folder / SCAN, params) is None
    note = set_not_read(set_folder / SCAN, AnalysisParams(hole_radius_mm=7.58,
                                                          hole_center_px=(428.06, 426.92)))
    assert note is not None and "hole_radius_mm for this scan differs" in note


def test_a_copy_of_the_sets_calibration_is_the_same_calibration(set_folder, tmp_path_factory):
    copy = tmp_path_factory.mktemp("elsewhere") / "widths.csv"
    shutil.copy(set_folder / "calibration.csv", copy)
    assert set_not_read(set_folder / SCAN, AnalysisParams(calibration=str(copy))) is None
    # another table is named
    table = pd.read_csv(copy)
    table.loc[0, "width_mm"] *= 1.1
    table.to_csv(copy, index=False)
    note = set_not_read(set_folder / SCAN, AnalysisParams(calibration=str(copy)))
    assert note is not None and "calibration" in note


def test_the_nearest_set_above_the_scan_is_the_one_read(set_folder):
    sub = set_folder / "day1"
    sub.mkdir()
    shutil.move(set_folder / SCAN, sub / SCAN)
    note = set_not_read(sub / SCAN, AnalysisParams(px_per_mm=40.0))
    assert "set.toml" in note and "px_per_mm" in note and "calibration" in note


def test_a_calibration_beside_a_loose_scan_is_named(set_folder):
    (set_folder / "set.toml").unlink()
    note = set_not_read(set_folder / SCAN, AnalysisParams())
    assert "calibration.csv beside it is not used" in note
    params = AnalysisParams(calibration=str(set_folder / "calibration.csv"))
    assert set_not_read(set_folder / SCAN, params) is None


def test_the_cli_prints_it_as_one_warning_line(set_folder, capsys):
    out = set_folder / "out"
    assert crosssection.cli.main(["analyze", str(set_folder / SCAN), "--out", str(out),
                                  "--no-figure"]) == 0
    err = capsys.readouterr().err.splitlines()
    named = [line for line in err if "set.toml is not read by analyze" in line]
    assert len(named) == 1 and named[0].startswith(f"warning: {set_folder / SCAN}: ")
    assert crosssection.cli.main(["analyze", str(set_folder / SCAN), "--out", str(out),
                                  "--no-figure", "--calibration",
                                  str(set_folder / "calibration.csv")]) == 0
    assert "set.toml" not in capsys.readouterr().err


@pytest.mark.filterwarnings("ignore::crosssection.quality.CalibrationWarning")
def test_the_api_warns_with_its_own_category(set_folder):
    scan = set_folder / SCAN
    with pytest.warns(SetWarning, match="set.toml is not read by analyze") as caught:
        crosssection.analyze(scan)
    assert [w.filename for w in caught if w.category is SetWarning] == [__file__]
    with warnings.catch_warnings():  # the set's values passed, or warnings left to the caller
        warnings.simplefilter("error", SetWarning)
        crosssection.analyze(scan, calibration=str(set_folder / "calibration.csv"))
        quiet = crosssection.analyze(scan, warn=False)
    # warnings left to the caller: the note is in the result
    assert any("set.toml is not read by analyze" in n for n in quiet.summary["warnings"])


# ---------------------------------------------------------------- the output folder


@pytest.fixture(scope="module")
def small_scan(tmp_path_factory):
    """A generated scan of 20 stacks (399 px), written as PNG."""
    from crosssection.truth.network import make_scene
    from crosssection.truth.scene import write_image

    path = tmp_path_factory.mktemp("scan") / "scan.png"
    write_image(make_scene(seed=21, n_stacks=20, max_layers=3).rgb, path)
    return path


@pytest.mark.parametrize("command", ["analyze", "steps"])
@pytest.mark.parametrize("out", ["", "  "])
def test_an_empty_out_is_refused_and_nothing_is_written(small_scan, tmp_path, monkeypatch,
                                                         capsys, command, out):
    monkeypatch.chdir(tmp_path)
    assert crosssection.cli.main([command, str(small_scan), "--out", out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --out: empty path: give the output folder"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", [["crosssection", "batch", "IN"],
                                     ["crosssection", "stats", "IN"],
                                     ["simulate", "validate", "IN"]])
def test_every_command_refuses_an_empty_out(tmp_path, command):
    """An empty --out is the current folder: every command refuses it before reading."""
    inp = tmp_path / "in"
    inp.mkdir()
    work = tmp_path / "work"
    work.mkdir()
    argv = [str(inp) if a == "IN" else a for a in command]
    run = subprocess.run([sys.executable, "-m", *argv, "--out", ""], cwd=work,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert run.stderr.splitlines() == ["error: --out: empty path: give the output folder"]
    assert list(work.iterdir()) == []


def _names(folder):
    return sorted(p.name for p in folder.iterdir())


def test_a_rerun_removes_the_outputs_it_does_not_write(small_scan, tmp_path, capsys):
    out = tmp_path / "out"
    main = crosssection.cli.main
    assert main(["steps", str(small_scan), "--out", str(out)]) == 0
    assert (out / STEPS_RECORD).is_file()
    # the user's own files, even of names close to the outputs', stay
    (out / "notes.txt").write_text("mine")
    (out / "overlay.png.orig").write_text("mine")
    assert main(["analyze", str(small_scan), "--out", str(out), "--steps"]) == 0
    tables = {"summary.json", "junctions.csv", "stacks.csv", "branches.csv", "voids.csv"}
    # the step images are analyze's now: the steps.json of the earlier run no longer
    # describes them
    assert set(_names(out)) == tables | {OVERLAY, *STEP_IMAGES, STEPS_FIGURE, "notes.txt",
                                         "overlay.png.orig"}
    capsys.readouterr()
    assert main(["analyze", str(small_scan), "--out", str(out), "--no-figure"]) == 0
    assert set(_names(out)) == tables | {"notes.txt", "overlay.png.orig"}
    assert "removed 6 file(s) of an earlier run" in capsys.readouterr().out


def test_steps_records_what_it_was_made_with(small_scan, tmp_path):
    import json

    from crosssection._version import __version__

    out = tmp_path / "steps"
    main = crosssection.cli.main
    assert main(["steps", str(small_scan), "--out", str(out), "--px-per-mm", "50"]) == 0
    record = json.loads((out / STEPS_RECORD).read_text())
    assert record["command"] == "steps" and record["version"] == __version__
    assert record["image"]["path"] == str(small_scan)
    assert record["image"]["height_px"] == record["image"]["width_px"] == 399
    assert record["parameters"]["px_per_mm"] == 50.0
    assert record["parameters"]["thickness_mm"] == AnalysisParams().thickness_mm
    assert record["outputs"] == sorted([*STEP_IMAGES, STEPS_FIGURE])
    assert _names(out) == sorted([*STEP_IMAGES, STEPS_FIGURE, STEPS_RECORD])  # no temp file
    # the hole as analyze records it, how it was set included
    assert main(["analyze", str(small_scan), "--out", str(tmp_path / "an"), "--px-per-mm",
                 "50", "--no-figure"]) == 0
    summary = json.loads((tmp_path / "an" / "summary.json").read_text())
    assert record["hole"] == summary["hole"] and "found_by" in record["hole"]
    # without the figure, the steps.png of the earlier run goes and the record says so
    assert main(["steps", str(small_scan), "--out", str(out), "--no-figure"]) == 0
    assert _names(out) == sorted([*STEP_IMAGES, STEPS_RECORD])
    assert json.loads((out / STEPS_RECORD).read_text())["outputs"] == sorted(STEP_IMAGES)


def test_the_optional_outputs_are_the_names_the_writers_use(small_scan, tmp_path):
    from crosssection.pipeline import analyze

    with pytest.warns(QualityWarning):  # no calibration
        res = analyze(small_scan)
    written = {p.name for p in res.write(tmp_path, figure=True, steps=True).values()}
    assert set(OPTIONAL_OUTPUTS["analyze"]) - {STEPS_RECORD} <= written
    steps = {p.name for p in res.write_steps(tmp_path / "s").values()}
    assert steps == {*STEP_IMAGES, STEPS_FIGURE} and set(OPTIONAL_OUTPUTS["steps"]) <= steps


def test_remove_stale_leaves_folders_and_other_names(tmp_path):
    (tmp_path / OVERLAY).mkdir()
    (tmp_path / STEPS_FIGURE).write_text("old")
    (tmp_path / "summary.json").write_text("{}")
    removed = remove_stale(tmp_path, "analyze", [tmp_path / "summary.json"])
    assert removed == [tmp_path / STEPS_FIGURE]
    assert _names(tmp_path) == sorted([OVERLAY, "summary.json"])


@pytest.mark.parametrize("command", ["analyze", "steps"])
def test_a_folder_with_no_earlier_run_keeps_the_users_files(command, tmp_path, capsys):
    """A user's own overlay.png or steps.png in a folder no analysis wrote is not an
    output of an earlier run: --no-figure leaves it."""
    from PIL import Image

    from crosssection.cli import main

    scan = Path(__file__).resolve().parents[2] / "sample_images" / "scan_01_sparse.png"
    out = tmp_path / "mine"
    out.mkdir()
    Image.new("RGB", (4, 4)).save(out / "overlay.png")
    Image.new("RGB", (4, 4)).save(out / "steps.png")
    assert main([command, str(scan), "--no-figure", "--out", str(out)]) == 0
    assert (out / "overlay.png").is_file() and (out / "steps.png").is_file()
    assert "removed" not in capsys.readouterr().out


@pytest.mark.parametrize("command", ["analyze", "steps"])
def test_the_scans_own_folder_is_refused_as_output(command, tmp_path, capsys):
    from crosssection.cli import main

    scan = tmp_path / "s.png"
    scan.write_bytes((Path(__file__).resolve().parents[2] / "sample_images"
                      / "scan_01_sparse.png").read_bytes())
    assert main([command, str(scan), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the scan's own folder" in err[0] and "--out" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.png"]


def test_an_output_folder_that_cannot_be_written_is_refused_before_the_analysis(tmp_path,
                                                                               capsys,
                                                                               monkeypatch):
    """The probe file cannot be made (a read-only folder): one line naming the folder, exit
    2, and the analysis never runs."""
    import tempfile

    import crosssection.pipeline
    from crosssection.cli import main

    ran = []
    monkeypatch.setattr(crosssection.pipeline, "analyze", lambda *a, **k: ran.append(1))

    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied", str(kwargs.get("dir")))

    monkeypatch.setattr(tempfile, "NamedTemporaryFile", refuse)
    scan = Path(__file__).resolve().parents[2] / "sample_images" / "scan_01_sparse.png"
    assert main(["analyze", str(scan), "--out", str(tmp_path / "new" / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(tmp_path) in err[0] and "Permission denied" in err[0]
    assert ran == [] and not (tmp_path / "new").exists()


def test_a_given_rod_length_is_printed_beside_the_measured_one():
    from crosssection.result import rod_length_text

    assert rod_length_text({"rod_length_mm": 287.94, "rod_length_used_mm": 287.94}) == \
        "L = 287.9 mm"
    assert rod_length_text({"rod_length_mm": 287.94}) == "L = 287.9 mm"
    # epsilon and the energies use the given one: the line says which is which
    assert rod_length_text({"rod_length_mm": 287.94, "rod_length_used_mm": 320.0}) == \
        "L = 287.9 mm measured, 320.0 mm given"
    assert rod_length_text({"rod_length_mm": 287.94, "rod_length_used_mm": 1e-6}) == \
        "L = 287.9 mm measured, 1e-06 mm given"


@pytest.mark.parametrize("command", ["analyze", "steps"])
def test_the_temporary_files_of_a_killed_run_are_removed(command, small_scan, tmp_path):
    """A run killed while writing leaves its hidden temporary file; the next run removes the
    command's own, and no other hidden file."""
    out = tmp_path / "out"
    out.mkdir()
    left = {"analyze": [".overlay.png.abcd1234.png", ".summary.json.x1y2z3a4.json",
                        ".stacks.csv.qwer5678.csv"],
            "steps": [".step1_raw.png.abcd1234.png", ".steps.json.x1y2z3a4.json"]}[command]
    for name in left:
        (out / name).write_text("cut short")
    (out / ".notes.txt.abcd1234.txt").write_text("the user's")
    assert crosssection.cli.main([command, str(small_scan), "--out", str(out),
                                  "--no-figure"]) == 0
    assert [name for name in left if (out / name).exists()] == []
    assert (out / ".notes.txt.abcd1234.txt").read_text() == "the user's"


def test_an_analysis_stopped_while_writing_leaves_the_earlier_one_whole(small_scan, tmp_path,
                                                                        monkeypatch):
    from crosssection.core import schema

    out = tmp_path / "out"
    main = crosssection.cli.main
    assert main(["analyze", str(small_scan), "--out", str(out), "--steps"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def interrupted(*args, **kwargs):  # the figures are written, the tables not yet
        raise KeyboardInterrupt

    monkeypatch.setattr(schema, "write_tables", interrupted)
    assert main(["analyze", str(small_scan), "--out", str(out), "--steps",
                 "--px-per-mm", "40"]) == 130
    # the earlier run's files, all of them and only them: no new figure beside old tables
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_file_named_like_a_record_is_not_an_earlier_run(small_scan, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    for name in ("notes.txt", OVERLAY, STEP_IMAGES[0]):
        (out / name).write_text("mine")
    (out / "summary.json").write_text("x")  # not a record: the folder is the user's
    # ... and a run would replace that summary.json: refused
    assert crosssection.cli.main(["analyze", str(small_scan), "--out", str(out),
                                  "--no-figure"]) == 2
    assert (out / "summary.json").read_text() == "x"
    (out / "summary.json").unlink()
    assert crosssection.cli.main(["analyze", str(small_scan), "--out", str(out),
                                  "--no-figure"]) == 0
    assert all((out / name).read_text() == "mine" for name in ("notes.txt", OVERLAY,
                                                               STEP_IMAGES[0]))


def test_the_overlay_records_the_version_and_what_it_was_made_from(small_scan, tmp_path):
    import json

    from PIL import Image

    from crosssection._version import __version__

    out = tmp_path / "out"
    assert crosssection.cli.main(["analyze", str(small_scan), "--out", str(out),
                                  "--px-per-mm", "40"]) == 0
    text = Image.open(out / OVERLAY).text
    assert text["Software"].startswith(f"foldstat {__version__} ")
    made_from = json.loads(text["Description"])
    assert made_from["parameters"]["px_per_mm"] == 40.0
    assert made_from["image"]["path"] == str(small_scan)


@pytest.mark.parametrize("command", ["analyze --steps", "steps"])
def test_the_step_images_record_the_version_and_what_they_were_made_from(small_scan,
                                                                          tmp_path, command):
    """The four step images carried no text, steps.png only the version."""
    import json

    from PIL import Image

    from crosssection._version import __version__

    out = tmp_path / "out"
    assert crosssection.cli.main([*command.split(), str(small_scan), "--out", str(out),
                                  "--px-per-mm", "40"]) == 0
    for name in (*STEP_IMAGES, "steps.png"):
        text = Image.open(out / name).text
        assert text["Software"].startswith(f"foldstat {__version__}")
        assert json.loads(text["Description"])["parameters"]["px_per_mm"] == 40.0


@pytest.mark.parametrize("command", ["analyze", "steps"])
@pytest.mark.parametrize("record, text, held", [
    ("batch.json", '{"package": "foldstat", "version": "0"}', "foldstat batch"),
    ("stats.json", '{"package": "foldstat", "version": "0"}', "foldstat stats"),
    ("render.json", '{"command": "render", "version": "0"}', "foldstat render"),
    ("summary.json", '{"package": "foldstat", "version": "0", "scenes_dir": "s"}',
     "foldstat validate"),
    ("configs.csv", "config_id\n", "a simulation")])
def test_another_commands_output_folder_is_refused(small_scan, tmp_path, capsys, command,
                                                   record, text, held):
    out = tmp_path / "theirs"
    out.mkdir()
    (out / record).write_text(text)
    if held == "a simulation":  # its table beside the parameters it records
        (out / "params.json").write_text('{"command": "quench", "n_configs": 2, "seed": 1, '
                                         '"version": "0"}')
    before = sorted(p.name for p in out.iterdir())
    assert crosssection.cli.main([command, str(small_scan), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: --out: {out} holds the output of {held} ({record}): give a "
                   "folder of its own"]
    assert sorted(p.name for p in out.iterdir()) == before


def test_steps_beside_another_scans_analysis_and_back_are_refused(small_scan, tmp_path,
                                                                  capsys):
    """steps of one scan beside another scan's tables mixed the two; analyze into another
    scan's step images removed them."""
    from crosssection.truth.network import make_scene
    from crosssection.truth.scene import write_image

    other = write_image(make_scene(seed=22, n_stacks=20, max_layers=3).rgb,
                        tmp_path / "other.png")
    copy = tmp_path / "copy" / "scan.png"  # the same bytes elsewhere: the same scan
    copy.parent.mkdir()
    shutil.copy(small_scan, copy)
    for first, second in (("analyze", "steps"), ("steps", "analyze")):
        out = tmp_path / first
        assert crosssection.cli.main([first, str(small_scan), "--out", str(out),
                                      "--no-figure"]) == 0
        before = {p.name: p.read_bytes() for p in out.iterdir()}
        capsys.readouterr()
        assert crosssection.cli.main([second, str(other), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"holds the output of foldstat {first} for another scan" \
            in err[0]
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before
        assert crosssection.cli.main([second, str(copy), "--out", str(out),
                                      "--no-figure"]) == 0
    # the same command replaces every file of the earlier run, whatever its scan
    out = tmp_path / "again"
    for scan in (small_scan, other):
        assert crosssection.cli.main(["analyze", str(scan), "--out", str(out),
                                      "--no-figure"]) == 0


def test_the_api_write_refuses_what_the_command_refuses(small_scan, tmp_path):
    """result.write into a batch's output made its statistics those of the stray analysis;
    into the scan's own folder, the next batch read overlay.png as a scan."""
    from crosssection.core.errors import ParameterError

    res = crosssection.analyze(str(small_scan), warn=False)
    batch = tmp_path / "batch"
    batch.mkdir()
    (batch / "batch.json").write_text('{"package": "foldstat", "version": "0"}')
    with pytest.raises(ParameterError, match="out_dir: .* holds the output of foldstat batch"):
        res.write(batch)
    with pytest.raises(ParameterError, match="the scan's own folder"):
        res.write(small_scan.parent)
    assert [p.name for p in batch.iterdir()] == ["batch.json"]
    assert "summary.json" in {p.name for p in res.write(tmp_path / "mine").values()} or \
        (tmp_path / "mine" / "summary.json").is_file()


def test_analyze_keeps_the_step_images_of_a_steps_run_of_the_same_scan(small_scan, tmp_path,
                                                                      capsys):
    """steps then analyze into one folder: analyze's re-run clean-up took the steps run's
    images and record for its own."""
    out = tmp_path / "both"
    assert crosssection.cli.main(["steps", str(small_scan), "--out", str(out)]) == 0
    steps = {p.name: p.read_bytes() for p in out.iterdir()}
    assert "steps.json" in steps
    assert crosssection.cli.main(["analyze", str(small_scan), "--out", str(out),
                                  "--no-figure"]) == 0
    assert "removed" not in capsys.readouterr().out
    assert {n: (out / n).read_bytes() for n in steps} == steps
    assert (out / "summary.json").is_file()
    # analyze --steps writes its own step images: the steps run's record no longer
    # describes them
    assert crosssection.cli.main(["analyze", str(small_scan), "--out", str(out),
                                  "--no-figure", "--steps"]) == 0
    assert not (out / "steps.json").exists()
    # without figures: the step images, not their figure (as ``steps --no-figure``)
    assert all((out / n).is_file() for n in STEP_IMAGES) and not (out / "steps.png").exists()


def test_analyze_refuses_a_scene_a_batch_folder_and_a_users_tables(tmp_path, capsys):
    """analyze wrote into a render's scene folder (a later batch then skipped the scene as an
    analysis), into a batch's per-scan folder (another scan's results there), and over a
    user's stacks.csv: each is refused in one line, exit 2, nothing written."""
    import json

    from crosssection.cli import main

    scan = Path(__file__).resolve().parents[2] / "sample_images" / "scan_01_sparse.png"
    scene = tmp_path / "scene"
    (scene / "truth").mkdir(parents=True)
    (scene / "truth" / "summary.json").write_text("{}")
    (scene / "params.json").write_text("{}")
    batch = tmp_path / "b"
    (batch / "set" / "scan").mkdir(parents=True)
    (batch / "batch.json").write_text(json.dumps({"package": "foldstat", "version": "0"}))
    user = tmp_path / "user"
    user.mkdir()
    (user / "stacks.csv").write_text("a,b\n1,2\n")
    for out, word in ((scene, "is a scene folder"), (batch / "set" / "scan",
                                                      "lies inside the output of foldstat batch"),
                      (user, "holds stacks.csv, which foldstat did not write")):
        capsys.readouterr()
        assert main(["analyze", str(scan), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and word in err[0], err
        assert not (out / "summary.json").exists()
    assert (user / "stacks.csv").read_text() == "a,b\n1,2\n"


@pytest.mark.parametrize("command, name", [("analyze", "overlay.png"),
                                           ("steps", "steps.png"),
                                           ("steps", "steps.json")])
def test_a_users_image_or_record_named_as_an_output_is_not_replaced(tmp_path, capsys,
                                                                     command, name):
    """A folder of scans holding one named overlay.png lost it to analyze without a word
    (a later batch over the folder then read the overlay as a scan); steps replaced a
    user's steps.png and steps.json. Refused in one line, exit 2, the file kept; a folder
    of an earlier run is written again."""
    from crosssection.cli import main

    scan = Path(__file__).resolve().parents[2] / "sample_images" / "scan_01_sparse.png"
    user = tmp_path / "user"
    user.mkdir()
    content = scan.read_bytes() if name.endswith(".png") else b'{"a": 1}'
    (user / name).write_bytes(content)
    capsys.readouterr()
    assert main([command, str(scan), "--out", str(user), "--px-per-mm", "50"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: --out: {user} holds {name}, which foldstat did not write (a run "
                   "would replace it): give a folder of its own"]
    assert (user / name).read_bytes() == content
    ours = tmp_path / "ours"
    for _ in range(2):
        assert main([command, str(scan), "--out", str(ours), "--px-per-mm", "50"]) == 0


def test_steps_warns_of_its_frame_as_analyze_does(small_scan, tmp_path, capfd):
    # a scale that makes h 2 px, and a scan with transparent pixels: analyze warned of both,
    # steps of neither, its images drawn on the same doubtful frame
    import numpy as np
    from PIL import Image

    rgba = np.asarray(Image.open(small_scan).convert("RGBA")).copy()
    rgba[150:250, 150:250, 3] = 0
    scan = tmp_path / "see_through.png"
    Image.fromarray(rgba).save(scan)
    capfd.readouterr()
    assert subprocess.run([sys.executable, "-m", "crosssection", "steps", str(scan), "--out",
                           str(tmp_path / "s"), "--px-per-mm", "20"]).returncode == 0
    err = capfd.readouterr().err.splitlines()
    assert all(ln.startswith(f"warning: {scan}: ") for ln in err)
    assert any("sheet thickness is 2.00 px" in ln for ln in err)
    assert any("transparent" in ln for ln in err)


def test_a_file_without_a_resolution_read_at_the_default_scale_is_flagged(small_scan, tmp_path,
                                                                         capfd):
    # a 1200-dpi scan saved without its resolution and read without --px-per-mm: lengths
    # 5.5 % short, no check could tell
    from crosssection import analyze

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assumed = analyze(str(small_scan))
        given = analyze(str(small_scan), px_per_mm=50)
        # a parameters object that leaves the scale out (the README's own style,
        # AnalysisParams(calibration=...)) is flagged, also once other fields are replaced;
        # one given the default scale is not
        default_object = analyze(str(small_scan), AnalysisParams())
        replaced = analyze(str(small_scan),
                           dataclasses.replace(AnalysisParams(), thickness_mm=0.1))
        as_object = analyze(str(small_scan), AnalysisParams(px_per_mm=49.5))
        at_default = analyze(str(small_scan), AnalysisParams(px_per_mm=50))
        told = analyze(str(small_scan), AnalysisParams(), scale_given=True)
        # an array records no resolution: read at the default, it is flagged as a file is
        from PIL import Image

        pixels = np.asarray(Image.open(small_scan).convert("RGB"))
        from_array = analyze(pixels)
        array_given = analyze(pixels, px_per_mm=50)
    for r in (assumed, default_object, replaced, from_array):
        assert "scale_assumed" in r.summary["quality"]["codes"]
    assert any(issubclass(w.category, crosssection.quality.ScaleAssumedWarning)
               and "a 1200-dpi scan reads -5.5 %" in str(w.message) for w in caught)
    for r in (given, as_object, at_default, told, array_given):
        assert "scale_assumed" not in r.summary["quality"]["codes"]
    # the record gives the same analysis back, the scale it was read at given
    again = AnalysisParams(**default_object.summary["parameters"])
    assert again.px_per_mm == 50 and not crosssection.params.scale_left_out(again)
    capfd.readouterr()
    main = crosssection.cli.main
    assert main(["analyze", str(small_scan), "--out", str(tmp_path / "a"), "--no-figure"]) == 0
    assert "no resolution given and the scan records none that a scanner writes" in \
        capfd.readouterr().err
    assert main(["analyze", str(small_scan), "--out", str(tmp_path / "b"), "--no-figure",
                 "--px-per-mm", "50"]) == 0
    assert "no resolution given" not in capfd.readouterr().err


def test_a_line_break_in_a_file_name_keeps_each_message_on_one_line(small_scan, tmp_path,
                                                                   capfd):
    scan = tmp_path / "a\nb.png"
    shutil.copy(small_scan, scan)
    capfd.readouterr()
    main = crosssection.cli.main
    assert main(["analyze", str(scan), "--out", str(tmp_path / "o\nut"), "--no-figure",
                 "--px-per-mm", "50"]) == 0
    out = capfd.readouterr().out
    assert out.count("\n") == 1 and out.startswith(f"{tmp_path}/a b.png: ")
    assert out.rstrip().endswith(f"-> {tmp_path}/o ut")
    assert main(["steps", str(scan), "--out", str(tmp_path / "s"), "--no-figure",
                 "--px-per-mm", "50"]) == 0
    assert capfd.readouterr().out.count("\n") == 1


def test_steps_that_cannot_write_leave_no_empty_folder(small_scan, tmp_path, capfd,
                                                       monkeypatch):
    import errno

    import crosssection.core.fileio as fileio

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "s" / "x"))

    monkeypatch.setattr(fileio, "write_json", full)
    capfd.readouterr()
    assert crosssection.cli.main(["steps", str(small_scan), "--out", str(tmp_path / "s"),
                                  "--no-figure", "--px-per-mm", "50"]) == 2
    err = capfd.readouterr().err.splitlines()
    assert err[-1].endswith("cannot write (No space left on device)")
    assert not (tmp_path / "s").exists()
