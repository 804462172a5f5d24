"""The ``validate`` command: option checks, failed scenes, truth tables, the report's record."""
import json
import shutil
import warnings
from pathlib import Path

import pandas as pd
import pytest

from crosssection._version import __version__
from crosssection.core.errors import ConfigError, ParameterError
from simulate.cli import main
from simulate.validate import read_truth, validate_scenes


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """One quenched rod rendered into a SCENES folder (about 1 s): ``(scenes, scene)``."""
    root = tmp_path_factory.mktemp("validate")
    assert main(["quench", "--n-configs", "1", "--segments", "100", "--seed", "1",
                 "--workers", "1", "--out", str(root / "sim")]) == 0
    assert main(["render", str(root / "sim"), "--out", str(root / "scenes"),
                 "--no-progress"]) == 0
    scenes = root / "scenes"
    return scenes, sorted(scenes.iterdir())[0]


@pytest.fixture
def scenes(rendered, tmp_path):
    """A fresh copy of the rendered SCENES folder: ``(scenes, scene)`` to damage at will."""
    src, scene = rendered
    dst = tmp_path / "scenes"
    shutil.copytree(src, dst)
    return dst, dst / scene.name


def run(scenes, out, *extra):
    return main(["validate", str(scenes), "--out", str(out), "--no-progress", *extra])


def not_analysed(err: str) -> list[str]:
    return [line for line in err.splitlines() if ": not analysed: " in line]


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf"])
def test_match_px_must_be_finite_and_positive(scenes, tmp_path, capsys, value):
    folder, _ = scenes
    assert run(folder, tmp_path / "rep", "--match-px", value) == 2
    assert capsys.readouterr().err == \
        f"error: --match-px: must be a finite number > 0, got {value}\n"
    assert not (tmp_path / "rep").exists()
    with pytest.raises(ParameterError, match="match_px"):
        validate_scenes(folder, tmp_path / "rep", match_px=float(value))


def test_a_match_radius_of_a_whole_scene_is_refused(scenes, tmp_path, capsys):
    """1e9 px would match every junction to every other, and the scores mean nothing."""
    folder, _ = scenes
    assert run(folder, tmp_path / "rep", "--match-px", "1e9") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("error: --match-px: must be at most 1000 px")
    assert not (tmp_path / "rep").exists()
    with pytest.raises(ParameterError, match="match_px"):
        validate_scenes(folder, tmp_path / "rep", match_px=1001.0)


def damage_image(scene):
    (scene / "image.png").write_bytes(b"not a png")
    return "image.png"


def damage_summary(scene):
    (scene / "truth" / "summary.json").write_text("{bad")
    return "summary.json"


def damage_params(scene):
    (scene / "params.json").write_text("{bad")
    return "params.json"


def damage_calibration(scene):
    (scene / "calibration.csv").write_text("x\n")
    return "calibration.csv"


def lose_calibration(scene):
    # read without the law it was drawn with, the scene was scored on another's counts
    (scene / "calibration.csv").unlink()
    return "calibration.csv, the calibration its set.toml names, is missing"


def test_a_calibration_of_another_name_that_its_set_names_is_read(scenes, tmp_path):
    folder, scene = scenes
    (scene / "calibration.csv").rename(scene / "law.csv")
    toml = (scene / "set.toml").read_text()
    (scene / "set.toml").write_text(toml.replace('calibration = "calibration.csv"',
                                                 'calibration = "law.csv"'))
    assert 'calibration = "law.csv"' in (scene / "set.toml").read_text()
    assert run(folder, tmp_path / "rep") == 0


@pytest.mark.parametrize("damage", [damage_image, damage_summary, damage_params,
                                    damage_calibration, lose_calibration])
def test_failed_scene_is_a_warning_and_exit_3(scenes, tmp_path, capsys, damage):
    folder, scene = scenes
    name = damage(scene)
    assert run(folder, tmp_path / "rep") == 3
    lines = not_analysed(capsys.readouterr().err)
    assert len(lines) == 1
    assert lines[0].startswith(f"warning: {scene}: not analysed: ") and name in lines[0]
    failures = pd.read_csv(tmp_path / "rep" / "failures.csv")
    assert failures["scene"].tolist() == [scene.name]
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert summary["n_failed"] == 1 and summary["failed"] == [scene.name]


def test_scene_without_truth_is_failed_not_skipped(scenes, tmp_path, capsys):
    folder, scene = scenes
    bare = folder / "config_99999"
    shutil.copytree(scene, bare)
    shutil.rmtree(bare / "truth")
    assert run(folder, tmp_path / "rep") == 3
    lines = not_analysed(capsys.readouterr().err)
    # the scene folder named once: the line starts with it
    assert lines == [f"warning: {bare}: not analysed: no truth/summary.json "
                     f"(not a scene folder)"]
    failures = pd.read_csv(tmp_path / "rep" / "failures.csv")
    assert failures["error"].tolist() == ["no truth/summary.json (not a scene folder)"]
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert (summary["n_scenes"], summary["n_scored"], summary["n_failed"]) == (2, 1, 1)


def test_report_folder_inside_scenes_is_not_a_scene(scenes, capsys):
    folder, _ = scenes
    assert run(folder, folder / "rep") == 0
    # a second run sees rep/ among the subfolders: still not a failed scene
    assert run(folder, folder / "rep") == 0
    assert not_analysed(capsys.readouterr().err) == []


def test_a_batch_and_a_stats_report_inside_scenes_are_not_scenes(scenes, tmp_path, capsys):
    """A batch of the scenes and its stats report written into the scenes folder were
    counted as failed scenes (exit 3); batch skips such folders, and so does validate."""
    import json

    folder, _ = scenes
    for name, record in (("b", "batch.json"), ("rep", "stats.json")):
        (folder / name).mkdir()
        (folder / name / record).write_text(json.dumps({"package": "foldstat",
                                                         "version": "0"}))
    assert run(folder, tmp_path / "val") == 0
    assert not_analysed(capsys.readouterr().err) == []


def test_a_report_inside_scenes_is_no_scene_of_a_run_reporting_elsewhere(scenes, tmp_path,
                                                                        capsys):
    folder, _ = scenes
    assert run(folder, folder / "validation") == 0
    assert run(folder, tmp_path / "rep") == 0
    assert not_analysed(capsys.readouterr().err) == []
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert (summary["n_scenes"], summary["n_failed"]) == (1, 0)


@pytest.mark.parametrize("inside", [("config_00000", "rep"), ("reports", "v1")])
def test_a_report_deeper_inside_scenes_is_refused(scenes, capsys, inside):
    """Deeper than a subfolder of SCENES, the report would lie in a folder taken for a scene
    (the scene's own, or one the next run lists as a failed scene)."""
    folder, _ = scenes
    out = folder.joinpath(*inside)
    before = sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))
    assert run(folder, out) == 2
    assert capsys.readouterr().err == (
        f"error: {out}: lies inside {folder / inside[0]}, which validate takes for a scene: "
        f"give a folder outside {folder} or directly in it\n")
    assert sorted(str(p.relative_to(folder)) for p in folder.rglob("*")) == before
    with pytest.raises(ConfigError, match="which validate takes for a scene"):
        validate_scenes(folder, out)


@pytest.mark.parametrize("where", ["junk", "scenes"])
def test_a_report_folder_holding_other_files_is_refused(scenes, tmp_path, capsys, where):
    folder, _ = scenes
    if where == "junk":
        out = tmp_path / "junk"
        out.mkdir()
        (out / "notes.txt").write_text("hi\n")
        foreign = "notes.txt"
    else:
        # the scenes' own folder: the report would sit beside the scenes and their render.json
        out, foreign = folder, "config_00000"
    before = sorted(p.name for p in out.iterdir())
    assert run(folder, out) == 2
    err = capsys.readouterr().err
    assert err == (f"error: {out}: holds {foreign}, which is no part of a validate report: "
                   "give a new folder, an empty one or one an earlier validate wrote\n")
    assert sorted(p.name for p in out.iterdir()) == before
    with pytest.raises(ConfigError, match=f"holds {foreign}"):
        validate_scenes(folder, out)


def test_corrupt_truth_table_fails_its_scene(scenes, tmp_path, capsys):
    folder, scene = scenes
    (scene / "truth" / "stacks.csv").write_text("x\n")
    assert run(folder, tmp_path / "rep") == 3
    lines = not_analysed(capsys.readouterr().err)
    assert len(lines) == 1 and "truth/stacks.csv: not a stacks table" in lines[0]
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert (summary["n_scored"], summary["n_failed"]) == (0, 1)


@pytest.mark.parametrize("table", ["junctions", "stacks", "voids", "layer_pieces"])
def test_a_truth_table_cut_short_fails_its_scene(scenes, tmp_path, capsys, table):
    """A junctions.csv cut to two rows scored F1 0.21 (and a layer_pieces.csv cut short
    raised exact n_br) with exit 0: the summary's counts, and a piece for every stack, are
    checked."""
    folder, scene = scenes
    path = scene / "truth" / f"{table}.csv"
    lines = path.read_text().splitlines()
    assert len(lines) > 2
    path.write_text("\n".join(lines[:2]) + "\n")
    assert run(folder, tmp_path / "rep") == 3
    (line,) = not_analysed(capsys.readouterr().err)
    assert f"{table}.csv: holds" in line and "not scored" in line


def test_missing_truth_table_fails_its_scene_naming_the_file(scenes, tmp_path, capsys):
    folder, scene = scenes
    (scene / "truth" / "branches.csv").unlink()
    assert run(folder, tmp_path / "rep") == 3
    err = capsys.readouterr().err
    assert err.splitlines() == [f"warning: {scene}: not analysed: "
                                f"{Path('truth') / 'branches.csv'}: file not found"]


@pytest.mark.parametrize("file, content, cause", [
    ("branches.csv", None, "file not found"),
    ("summary.json", "{bad", "malformed JSON"),
    ("stacks.csv", "x\n", "not a stacks table"),
    ("junctions.csv", "junction_id,x_px\n0,1.0\n", "lacks column(s) y_px, n_stacks"),
    ("voids.csv", "", "empty file"),
    ("summary.json", "[1, 2]", "must hold a JSON object"),
    ("summary.json", '{"rod_length_mm": "long"}', "rod_length_mm must be a finite number"),
])
def test_read_truth_checks_the_tables(rendered, tmp_path, file, content, cause):
    _, scene = rendered
    truth = tmp_path / "truth"
    shutil.copytree(scene / "truth", truth)
    if content is None:
        (truth / file).unlink()
    else:
        (truth / file).write_text(content)
    with pytest.raises(ConfigError) as err:
        read_truth(truth)
    assert err.value.path == str(truth / file) and cause in err.value.cause


def test_read_truth_rejects_text_in_a_scored_column(rendered, tmp_path):
    _, scene = rendered
    truth = tmp_path / "truth"
    shutil.copytree(scene / "truth", truth)
    stacks = pd.read_csv(truth / "stacks.csv").astype({"n_br": object})
    stacks.loc[0, "n_br"] = "many"
    stacks.to_csv(truth / "stacks.csv", index=False)
    with pytest.raises(ConfigError, match="column n_br must hold finite numbers"):
        read_truth(truth)


def test_read_truth_reads_an_intact_folder(rendered):
    _, scene = rendered
    summary, tables = read_truth(scene / "truth")
    assert summary["n_stacks"] == len(tables["stacks"])
    assert set(tables) == {"junctions", "stacks", "branches", "voids", "layer_pieces"}
    # a band without a layer ending inside it is its own piece
    pieces = tables["layer_pieces"]
    assert set(pieces["stack_id"]) == set(tables["stacks"]["stack_id"])
    whole = pieces.groupby("stack_id").size() == 1
    assert whole.sum() >= 1
    one = tables["stacks"].set_index("stack_id").loc[whole[whole].index, "n_br"]
    assert (pieces.set_index("stack_id").loc[one.index, "n_br"] == one).all()


def test_summary_records_version_options_and_input(scenes, tmp_path):
    folder, _ = scenes
    assert run(folder, tmp_path / "rep", "--match-px", "4.5") == 0
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert summary["version"] == __version__
    assert summary["options"] == {"match_px": 4.5}
    assert summary["scenes_dir"] == str(folder.resolve())
    assert pd.read_csv(tmp_path / "rep" / "scores.csv")["match_px"].tolist() == [4.5]


def test_summary_records_the_default_match_px_used(scenes, tmp_path):
    """By default each scene's 3 h: the value the scores used, not null."""
    folder, scene = scenes
    assert run(folder, tmp_path / "rep") == 0
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    params = json.loads((scene / "params.json").read_text())
    used = pd.read_csv(tmp_path / "rep" / "scores.csv")["match_px"].tolist()
    assert summary["options"]["match_px"] == used[0] == pytest.approx(
        3 * params["thickness_mm"] * params["px_per_mm"])
    assert used[0] == float(f"{used[0]:.12g}")  # 15, not 15.000000000000002


def test_unusable_out_is_one_error_line(scenes, tmp_path, capsys):
    folder, _ = scenes
    (tmp_path / "rep").write_text("a file")
    assert run(folder, tmp_path / "rep") == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {tmp_path / 'rep'}: ") and err.count("\n") == 1


def test_the_bundled_samples_validate(tmp_path):
    """The samples keep each scan beside its set and its truth in scenes/<stem>/: validate
    finds the scan two folders up and scores all five."""
    from crosssection.samples import copy_samples
    from simulate.validate import validate_scenes

    copy_samples(tmp_path / "samples")
    scores = validate_scenes(tmp_path / "samples" / "scenes", tmp_path / "v")
    assert len(scores) == 5 and (scores["n_br_exact_length_fraction"] > 0.95).all()


def _flag(scene, messages, rod_factor=1.0):
    """Record ``messages`` as the render's truth warnings of ``scene`` (and scale its truth's
    rod length, so that its scores differ from an unflagged copy's)."""
    path = scene / "truth" / "summary.json"
    summary = json.loads(path.read_text())
    summary["truth_warnings"] = messages
    summary["rod_length_mm"] *= rod_factor
    path.write_text(json.dumps(summary))


def test_a_truth_flagged_by_its_render_is_warned_counted_and_left_out_of_the_means(
        scenes, tmp_path, capsys):
    folder, scene = scenes
    _flag(scene, [])
    flagged = folder / "config_99999"
    shutil.copytree(scene, flagged)
    _flag(flagged, ["the truth's stacks hold 682.2 mm of rod", "junction 0 lay 210 px away"],
          rod_factor=2.0)
    assert run(folder, tmp_path / "rep") == 0
    out, err = capsys.readouterr()
    assert "2 scenes scored (1 with a truth flagged by its render, left out of the means)" in out
    lines = [line for line in err.splitlines() if "flagged by its render" in line]
    assert lines == [f"warning: {flagged}: its truth is flagged by its render: the truth's "
                     "stacks hold 682.2 mm of rod; junction 0 lay 210 px away (scored, left "
                     "out of the means)"]
    scores = pd.read_csv(tmp_path / "rep" / "scores.csv").set_index("scene")
    assert scores["truth_warnings"].to_dict() == {scene.name: 0, flagged.name: 2}
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert summary["n_flagged"] == 1 and summary["flagged"] == [flagged.name]
    key = "rod_length_rel_error"
    assert scores.loc[flagged.name, key] != pytest.approx(scores.loc[scene.name, key])
    assert summary["mean"][key] == pytest.approx(scores.loc[scene.name, key])
    assert summary["mean_all"][key] == pytest.approx(scores[key].mean())
    assert summary["mean_abs_all"][key] == pytest.approx(scores[key].abs().mean())


def test_the_api_warns_a_flagged_truth(scenes, tmp_path):
    from simulate.render import TruthWarning

    folder, scene = scenes
    _flag(scene, ["the bands of junction 3 do not touch"])
    with warnings.catch_warnings(record=True) as caught:
        # the scan's own quality warnings too: only the truth's matter here
        warnings.simplefilter("always")
        scores = validate_scenes(folder, tmp_path / "rep")
    assert [str(w.message) for w in caught if w.category is TruthWarning] == [
        f"{scene}: its truth is flagged by its render: the bands of junction 3 do not touch "
        "(scored, left out of the means)"]
    assert scores["truth_warnings"].tolist() == [1]
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    # every scene flagged: no mean of the unflagged ones, the means of all kept
    assert summary["mean"] == {} and summary["n_flagged"] == 1
    assert "rod_length_rel_error" in summary["mean_all"]


def test_unflagged_scenes_have_a_zero_count_and_equal_means(scenes, tmp_path):
    folder, scene = scenes
    _flag(scene, [])
    assert run(folder, tmp_path / "rep") == 0
    scores = pd.read_csv(tmp_path / "rep" / "scores.csv")
    assert scores["truth_warnings"].tolist() == [0]
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert summary["n_flagged"] == 0 and summary["mean"] == summary["mean_all"]


def test_malformed_truth_warnings_fail_the_scene(scenes, tmp_path, capsys):
    folder, scene = scenes
    _flag(scene, "not a list")
    assert run(folder, tmp_path / "rep") == 3
    lines = not_analysed(capsys.readouterr().err)
    assert len(lines) == 1 and "truth_warnings must be a list of messages" in lines[0]



def test_scenes_of_a_coarse_rod_are_named_once_and_kept_in_the_means(scenes, tmp_path):
    from simulate.render import ScanRangeWarning

    folder, scene = scenes
    _flag(scene, [])
    truth = json.loads((scene / "truth" / "summary.json").read_text())
    # the fixture's rod has 100 segments, below the 300 a quench's render truth is validated at
    assert "validated from 300 segments" in truth["truth_range"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        validate_scenes(folder, tmp_path / "rep")
    said = [str(w.message) for w in caught if w.category is ScanRangeWarning]
    assert said == [f"{folder}: 1 scene(s): {truth['truth_range']}"]
    summary = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert summary["beyond_validated"] == [scene.name]
    assert summary["n_flagged"] == 0 and summary["mean"] == summary["mean_all"] != {}


def test_every_truth_flagged_says_where_the_means_are(scenes, tmp_path, capsys):
    # the default renders at epsilon 19 are all flagged: an empty mean with no word read as
    # no scores at all
    folder, scene = scenes
    _flag(scene, ["the truth has 23 voids, the rod 22"])
    assert run(folder, tmp_path / "rep") == 0
    out = capsys.readouterr().out
    assert ("1 scenes scored (every one with a truth flagged by its render: summary.json's "
            "mean is empty, mean_all holds their means)") in out


def test_the_energy_of_folds_within_one_node_is_listed_beside_the_error(scenes, tmp_path):
    """A fold within one rod node holds up to 4 / ds of the truth's energy, which no drawing
    shows: scores.csv lists its share and the total's error without it; a scene rendered
    before the share was recorded reads NaN there."""
    import math

    folder, scene = scenes
    summary_path = scene / "truth" / "summary.json"
    summary = json.loads(summary_path.read_text())
    assert summary["hairpin_energy_share"] >= 0.0  # every render records it
    summary["hairpin_energy_share"] = 0.5
    summary_path.write_text(json.dumps(summary))
    assert run(folder, tmp_path / "rep") == 0
    row = pd.read_csv(tmp_path / "rep" / "scores.csv").iloc[0]
    assert row["hairpin_energy_share"] == 0.5
    assert row["total_energy_rel_error_without_hairpins"] == pytest.approx(
        (1.0 + row["total_energy_rel_error"]) / 0.5 - 1.0)
    del summary["hairpin_energy_share"]
    summary_path.write_text(json.dumps(summary))
    assert run(folder, tmp_path / "rep2") == 0
    row = pd.read_csv(tmp_path / "rep2" / "scores.csv").iloc[0]
    assert math.isnan(row["hairpin_energy_share"])
    assert math.isnan(row["total_energy_rel_error_without_hairpins"])
