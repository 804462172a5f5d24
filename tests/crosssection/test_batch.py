"""Batch processing: set.toml, discovery, failures, resume, atomic outputs, CLI.

The end-to-end tests run the real pipeline (``crosssection.analyze``) on small generated scans
(``crosssection.testing``).
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest

from crosssection import batch as B
from crosssection.core import fileio
from crosssection.params import AnalysisParams
from crosssection.core.errors import ConfigError
from crosssection.setconfig import check_params, load_set_config
from crosssection.testing import generated_scan as draw_scan
from crosssection.testing import index_numbers as numbers
from crosssection.testing import make_scan_tree as make_tree
from crosssection.testing import partial_outputs as leftovers
from crosssection.testing import write_calibration as write_cal
from crosssection.testing import write_png as save_png



# ----------------------------------------------------------------------------- helpers


# ----------------------------------------------------------------------------- set.toml


def test_set_toml_valid_with_override(tmp_path):
    write_cal(tmp_path / "c" / "cal.csv")
    (tmp_path / "x.png").write_bytes(b"")
    (tmp_path / "set.toml").write_text(
        'name = "run-1"\npx_per_mm = 40\nthickness_mm = 0.12\nhole_radius_mm = 20\n'
        'calibration = "c/cal.csv"\nkappa_c_per_mm = 3.5\nbending_rigidity_J = 2e-4\n'
        '[images."x.png"]\nhole_radius_mm = 19.5\npx_per_mm = 41\n')
    cfg = load_set_config(tmp_path / "set.toml", defaults={"px_per_mm": 50.0, "rod_length_mm": 9})
    assert cfg.name == "run-1" and cfg.error is None and cfg.warnings == []
    assert cfg.params["px_per_mm"] == 40.0 and cfg.params["rod_length_mm"] == 9.0
    assert Path(cfg.params["calibration"]) == (tmp_path / "c" / "cal.csv").resolve()
    p = cfg.params_for(tmp_path / "x.png")
    assert p["hole_radius_mm"] == 19.5 and p["px_per_mm"] == 41.0
    assert p["thickness_mm"] == 0.12 and p["kappa_c_per_mm"] == 3.5


def test_an_image_table_replacing_an_option_is_named(tmp_path):
    """A per-image value replaced a command-line option without a word (only the set's
    top-level values were named); a BOM (Notepad's) no longer makes the file invalid."""
    (tmp_path / "x.png").write_bytes(b"")
    (tmp_path / "set.toml").write_bytes(
        b'\xef\xbb\xbfpx_per_mm = 40\n[images."x.png"]\nhole_radius_mm = 19.5\n')
    cfg = load_set_config(tmp_path / "set.toml", given={"hole_radius_mm": 7.0})
    assert cfg.error is None and len(cfg.warnings) == 1
    assert ("[images.'x.png'] sets hole_radius_mm = 19.5, which replaces --hole-radius-mm "
            "7.0 for that scan") in cfg.warnings[0]
    assert load_set_config(tmp_path / "set.toml", given={"hole_radius_mm": 19.5}).warnings == []


@pytest.mark.parametrize("text, word", [
    ('px_per_m = 50\n', "unknown key"),
    ('px_per_mm = -3\n', "> 0"),
    ('thickness_mm = "thin"\n', "must be a number"),
    ('name = "../escape"\n', "name"),
    ('px_per_mm = 50\n[images."a.png"]\nfoo = 1\n', "foo"),
    ('calibration = "nowhere.csv"\n', "not found"),
    ('hole_center_px = [1, 2, 3]\n', "[x, y]"),
    ('this is = = not toml\n', "invalid TOML"),
    ('px_per_mm = 99999999999999999999999999\n', "beyond any scanner"),
])
def test_set_toml_errors_are_clear(tmp_path, text, word):
    (tmp_path / "set.toml").write_text(text)
    with pytest.raises(ConfigError) as err:
        load_set_config(tmp_path / "set.toml")
    msg = err.value.one_line()
    assert word in msg and "set.toml" in msg and "\n" not in msg


def test_a_set_without_name_is_named_by_its_path_in_the_input(tmp_path):
    folder = tmp_path / "eps8" / "day1"
    folder.mkdir(parents=True)
    (folder / "set.toml").write_text("thickness_mm = 0.1\n")
    assert load_set_config(folder / "set.toml", root=tmp_path).name == "eps8/day1"
    assert load_set_config(folder / "set.toml").name == "day1"  # no input folder: its own
    (tmp_path / "set.toml").write_text("")
    assert load_set_config(tmp_path / "set.toml", root=tmp_path).name == tmp_path.name
    # a folder name a set name does not take is made one; a name given is checked
    spaced = tmp_path / "exp A" / ".day 1"
    spaced.mkdir(parents=True)
    (spaced / "set.toml").write_text("")
    assert load_set_config(spaced / "set.toml", root=tmp_path).name == "exp_A/day_1"
    # accented letters keep their base letter: été and àtè stay apart
    for name, made in (("série à", "serie_a"), ("été", "ete"), ("àtè", "ate"), ("☃", "set")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "set.toml").write_text("")
        assert load_set_config(tmp_path / name / "set.toml", root=tmp_path).name == made
    (spaced / "set.toml").write_text('name = "eps8/day1"\n')
    assert load_set_config(spaced / "set.toml", root=tmp_path).name == "eps8/day1"
    (spaced / "set.toml").write_text('name = "my set"\n')
    with pytest.raises(ConfigError, match="folder names"):
        load_set_config(spaced / "set.toml", root=tmp_path)


@pytest.mark.parametrize("name", ["Größe", "a\\n"])
def test_a_set_name_of_other_than_ascii_letters_is_refused_in_those_words(tmp_path, name):
    # Größe is made of letters: the message says which letters a name may hold
    (tmp_path / "set.toml").write_text(f'name = "{name}"\n')
    with pytest.raises(ConfigError, match=r"name must be folder names \(ASCII letters, "
                                          r"digits, \. _ \+ -, each starting"):
        load_set_config(tmp_path / "set.toml")


def test_calibration_columns_checked(tmp_path):
    (tmp_path / "cal.csv").write_text("layers,w\n1,0.1\n")
    (tmp_path / "set.toml").write_text('calibration = "cal.csv"\n')
    with pytest.raises(ConfigError, match="n_layers"):
        load_set_config(tmp_path / "set.toml")


@pytest.mark.parametrize("table, cause", [
    ("n_layers,width_mm\n1,abc\n2,0.2\n", "calibration contains non-numeric or missing values"),
    ("n_layers,width_mm\n1,0.1\n2.5,0.2\n", "is not a whole number of layers"),
    ("n_layers,width_mm\n1,0.2\n2,0.1\n", "strictly increasing")])
def test_a_set_calibration_is_checked_as_the_command_line_checks_it(tmp_path, table, cause):
    """Through a set.toml the same file read "needs numeric rows", and a fractional count or
    widths going down passed."""
    from crosssection.core.calibration import Calibration

    (tmp_path / "cal.csv").write_text(table)
    (tmp_path / "set.toml").write_text('calibration = "cal.csv"\n')
    with pytest.raises(ConfigError, match=cause) as via_set:
        load_set_config(tmp_path / "set.toml")
    with pytest.raises(ConfigError) as direct:
        Calibration.from_csv(tmp_path / "cal.csv")
    assert via_set.value.cause == f"{direct.value.cause} (named in {tmp_path / 'set.toml'})"


def test_override_naming_no_image_is_a_warning(tmp_path):
    (tmp_path / "set.toml").write_text('[images."ghost.png"]\npx_per_mm = 30\n')
    cfg = load_set_config(tmp_path / "set.toml")
    assert cfg.error is None and any("ghost.png" in w for w in cfg.warnings)


def test_cli_params_checked():
    assert check_params({"px_per_mm": 20, "hole_radius_mm": None}) == {"px_per_mm": 20.0}
    with pytest.raises(ConfigError):
        check_params({"thickness_mm": 0})


# ----------------------------------------------------------------------------- planning


@pytest.mark.parametrize("seed", [1, 2])
def test_plan_assigns_sets_seeds_and_outputs(tmp_path, seed):
    inp, out = tmp_path / "in", tmp_path / "in" / "results"  # output inside the input
    make_tree(inp, seed)
    save_png(inp / "setA" / "s0.tif", draw_scan(seed))          # stem collision with s0.png
    save_png(out / "alpha" / "s0" / "overlay.png", draw_scan(seed))  # must not be picked up
    tasks, sets = B.plan_batch(inp, out, seed=seed)
    by = {t.rel: t for t in tasks}
    assert "results/alpha/s0/overlay.png" not in by
    assert by["setA/sub/s2.png"].set_name == "alpha"
    assert by["loose.png"].set_name == "default"
    assert AnalysisParams.from_mapping(by["loose.png"].params).px_per_mm == 50
    assert by["setA/s1.png"].params["rod_length_mm"] == 200.0
    assert "rod_length_mm" not in by["setA/s0.png"].params
    assert by["badset/b0.png"].error and "px_per_mm" in by["badset/b0.png"].error
    assert by["nocal/c0.png"].error and "missing.csv" in by["nocal/c0.png"].error
    outs = [t.out_rel for t in tasks]
    assert len(set(outs)) == len(outs)                        # collisions disambiguated
    assert by["setA/s0.png"].out_rel != by["setA/s0.tif"].out_rel
    assert by["setA/s1.png"].out_rel == "alpha/s1"
    # seeds: one per task from SeedSequence.spawn, distinct, and the same on a re-plan
    seeds = [t.seed for t in tasks]
    assert len(set(seeds)) == len(seeds)
    assert seeds == [t.seed for t in B.plan_batch(inp, out, seed=seed)[0]]
    assert seeds != [t.seed for t in B.plan_batch(inp, out, seed=seed + 100)[0]]
    # the hash follows the image content and the parameters
    h0 = by["setA/s0.png"].params_hash
    save_png(inp / "setA" / "s0.png", draw_scan(seed + 7))
    assert B.plan_batch(inp, out, seed=seed)[0][tasks.index(by["setA/s0.png"])].params_hash != h0
    t2 = {t.rel: t for t in B.plan_batch(inp, out, seed=seed, cli_params={"px_per_mm": 51})[0]}
    assert t2["loose.png"].params_hash != by["loose.png"].params_hash


def test_a_calibration_beside_scans_without_one_is_named(tmp_path):
    inp = tmp_path / "in"
    save_png(inp / "loose.png", draw_scan(1))
    save_png(inp / "setA" / "s0.png", draw_scan(2))
    (inp / "calibration.csv").write_text("n_layers,width_mm\n1,0.1\n2,0.2\n")
    (inp / "setA" / "calibration.csv").write_text("n_layers,width_mm\n1,0.1\n2,0.2\n")
    (inp / "setA" / "set.toml").write_text('name = "alpha"\ncalibration = "calibration.csv"\n')
    _, sets = B.plan_batch(inp, tmp_path / "out")
    remarks = [w for s in sets.values() for w in s.warnings]
    # the loose scan's neighbour is named; the set's own calibration is used, not named
    assert len(remarks) == 1 and str(inp / "calibration.csv") in remarks[0]
    assert "--calibration" in remarks[0]
    # given on the command line, it is used for the loose scan: only the set's own file,
    # which replaces it for the set's scans, is named
    _, sets = B.plan_batch(inp, tmp_path / "out",
                           cli_params={"calibration": str(inp / "calibration.csv")})
    remarks = [w for s in sets.values() for w in s.warnings]
    assert len(remarks) == 1 and remarks[0].startswith(str(inp / "setA" / "set.toml"))
    assert "replaces --calibration" in remarks[0]


def test_missing_or_empty_input(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        B.plan_batch(tmp_path / "nope", tmp_path / "out")
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("x")
    with pytest.raises(ConfigError, match="no image"):
        B.plan_batch(tmp_path / "empty", tmp_path / "out")


# ----------------------------------------------------------------------------- end to end


def test_batch_records_failures_and_finishes_good_images(tmp_path):
    inp, out = tmp_path / "in", tmp_path / "out"
    expect = make_tree(inp, seed=11)
    index = B.run_batch(inp, out, workers=1, seed=5, progress=False)
    idx = pd.read_csv(out / "index.csv")
    assert list(idx.columns[:4]) == ["image", "set", "status", "output"]
    assert set(B.SUMMARY_NUMBERS + ["wall_s"]) <= set(idx.columns)
    st = dict(zip(idx["image"], idx["status"]))
    assert all(st[i] == "ok" for i in expect["ok"]), idx[["image", "status", "reason"]]
    assert all(st[i] == "failed" for i in expect["failed"])
    assert len(idx) == len(index) == len(expect["ok"]) + len(expect["failed"])
    fails = pd.read_csv(out / "failures.csv")
    assert list(fails.columns) == ["image", "set", "reason"]
    reasons = dict(zip(fails["image"], fails["reason"]))
    assert set(reasons) == set(expect["failed"])
    for img, word in expect["failed"].items():
        assert "\n" not in reasons[img]
        # the reason names the file concerned: the image itself, or the set's set.toml
        named = "set.toml" if word else img
        assert named in reasons[img], reasons[img]
        if word:
            assert word in reasons[img]
    assert "RGB" in reasons["gray.png"] or "gray" in reasons["gray.png"].lower()
    # outputs in the analyze layout, under OUT/<set name>/<stem>
    for img in expect["ok"]:
        row = idx[idx["image"] == img].iloc[0]
        folder = out / row["output"]
        for f in ("summary.json", "junctions.csv", "stacks.csv", "branches.csv", "voids.csv",
                  "overlay.png"):
            assert (folder / f).is_file(), folder / f
        s = json.loads((folder / "summary.json").read_text())
        assert s["batch"]["params_hash"] == row["params_hash"]
        assert s["n_junctions"] == row["n_junctions"]
    assert (out / "alpha" / "s1").is_dir() and (out / "default" / "loose").is_dir()
    # output folders get the usual permissions (not the 0700 of a temporary folder)
    assert (out / "alpha" / "s1").stat().st_mode & 0o777 == 0o777 & ~fileio.UMASK
    s1 = json.loads((out / "alpha" / "s1" / "summary.json").read_text())
    assert s1["batch"]["params"]["rod_length_mm"] == 200.0
    assert s1["batch"]["params"]["bending_rigidity_J"] == 1e-4
    meta = json.loads((out / "batch.json").read_text())
    assert meta["version"] and meta["seed"] == 5 and meta["counts"]["failed"] == len(expect["failed"])
    assert leftovers(out) == []


def test_resume_redoes_only_missing_images(tmp_path):
    inp, out = tmp_path / "in", tmp_path / "out"
    expect = make_tree(inp, seed=23, bad=False)
    B.run_batch(inp, out, workers=1, progress=False)
    first = pd.read_csv(out / "index.csv")
    assert (first["status"] == "ok").all()
    before = {p: p.stat().st_mtime_ns for p in out.rglob("summary.json")}
    tables = {p: p.read_text() for p in out.rglob("*.csv") if p.parent != out}
    # lose one output folder; a killed worker left a staging folder and a temp file
    victim = out / first.set_index("image").loc["setA/s1.png", "output"]
    shutil.rmtree(victim)
    stale = victim.parent / f".{victim.name}{fileio.PARTIAL_TAG}dead"
    stale.mkdir()
    (stale / "junctions.csv").write_text("junction_id,x_px\n1,")
    (victim.parent / ".index.csv.tmpjunk.tmp").write_text("half")
    # the re-run uses 2 worker processes: same numbers as the inline first run
    second = B.run_batch(inp, out, workers=2, progress=False)
    st = dict(zip(second["image"], second["status"]))
    assert st.pop("setA/s1.png") == "ok"
    assert set(st.values()) == {"skipped"}
    assert not stale.exists()
    for p, t in before.items():
        if p.parent != victim:
            assert p.stat().st_mtime_ns == t      # untouched
    pd.testing.assert_frame_equal(numbers(first), numbers(pd.read_csv(out / "index.csv")))
    # the per-image tables are identical too, the redone image's included
    assert len(tables) == 4 * len(expect["ok"])
    for p, text in tables.items():
        assert p.read_text() == text, p
    # changed parameters redo the affected images only
    with pytest.warns(B.BatchWarning) as caught:
        third = B.run_batch(inp, out, workers=1, progress=False, cli_params={"px_per_mm": 40})
    said = [str(w.message) for w in caught]
    # the set's own scale replaces the command line's; only the image outside it is redone
    assert any("which replaces --px-per-mm 40.0" in m for m in said)
    again = [m for m in said if "analysed again" in m]
    assert again == [f"{(inp / 'loose.png').resolve()}: analysed again: its parameters "
                     "differ from the recorded ones (px_per_mm); its earlier results are "
                     "replaced if it succeeds"]
    st3 = dict(zip(third["image"], third["status"]))
    assert st3["loose.png"] == "ok" and st3["setA/s0.png"] == "skipped"


def test_failed_write_leaves_no_partial_folder(tmp_path, monkeypatch):
    inp, out = tmp_path / "in", tmp_path / "out"
    make_tree(inp, seed=3, bad=False)
    B.run_batch(inp, out, workers=1, progress=False)
    good = (out / "alpha" / "s0" / "stacks.csv").read_text()
    calls = {"n": 0}
    real_write_json = B.write_json

    def flaky_write_json(path, data):
        if Path(path).name == "summary.json":
            calls["n"] += 1
            raise OSError("disk full")
        return real_write_json(path, data)

    monkeypatch.setattr(B, "write_json", flaky_write_json)
    idx = B.run_batch(inp, out, workers=1, progress=False, force=True)
    assert calls["n"] == 4 and (idx["status"] == "failed").all()
    assert idx["reason"].str.contains("disk full").all()
    # the previous complete outputs are intact, no staging folder is left
    assert (out / "alpha" / "s0" / "stacks.csv").read_text() == good
    assert leftovers(out) == []


def test_cli_exit_status(tmp_path, capsys):
    import argparse

    parser = argparse.ArgumentParser()
    B.add_subparser(parser.add_subparsers())
    inp, out = tmp_path / "in", tmp_path / "out"
    expect = make_tree(inp, seed=7)
    args = parser.parse_args(["batch", str(inp), "--out", str(out), "--workers", "1",
                              "--no-figure", "--quiet", "--px-per-mm", "48"])
    with pytest.warns(B.BatchWarning, match="which replaces --px-per-mm 48.0"):
        assert args.func(args) == B.EXIT_SOME_FAILED  # finished, some images failed
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert f"{len(expect['failed'])} failed" in line
    assert not list(out.rglob("overlay.png"))
    s = json.loads((out / "default" / "loose" / "summary.json").read_text())
    assert s["batch"]["params"]["px_per_mm"] == 48.0
    with pytest.raises(ConfigError):
        args = parser.parse_args(["batch", str(tmp_path / "nope"), "--out", str(out)])
        args.func(args)


def test_cli_batch_stderr_holds_no_progress_bar_when_not_a_terminal(tmp_path):
    """A batch run from a script or a pipe writes nothing but warnings and errors on stderr."""
    import subprocess
    import sys

    inp = tmp_path / "in"
    inp.mkdir()
    from crosssection.testing import drawn_scan, write_png

    write_png(inp / "a.png", drawn_scan(3))
    r = subprocess.run([sys.executable, "-m", "crosssection", "batch", str(inp), "--out",
                        str(tmp_path / "out"), "--workers", "1", "--no-figure",
                        "--px-per-mm", "50", "--thickness-mm", "0.1"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "img/s" not in r.stderr and "batch:" not in r.stderr
    assert all(line.startswith("warning: ") for line in r.stderr.splitlines())


# ----------------------------------------------------------------------------- what users bring


def test_scans_whose_names_merge_get_their_own_folders(tmp_path):
    """"a b.png" and "a_b.png" make one safe name, "A_b.png" the same folder on a case-blind
    disk, sub/a_b.png the same stem: every scan gets its own folder."""
    inp = tmp_path / "in"
    (inp / "sub").mkdir(parents=True)
    for name in ("a b.png", "a_b.png", "A_b.png", "sub/a_b.png", "c.png"):
        (inp / name).write_bytes(b"")
    tasks, _ = B.plan_batch(inp, tmp_path / "out")
    names = [t.out_rel.lower() for t in tasks]
    assert len(set(names)) == len(tasks) == 5
    assert {t.rel: t.out_rel for t in tasks}["c.png"] == "default/c"


@pytest.mark.parametrize("broken", ["", "garbage\n", "id\n1\n", "\xff\xfe\x00bad",
                                    "stack_id,junction_a\n1,2\n", None])
def test_resume_redoes_a_scan_whose_table_is_missing_empty_or_corrupt(tmp_path, broken):
    """A table emptied, overwritten or deleted since the image was done: the re-run redoes
    the image (stats would refuse the whole batch for one unreadable table)."""
    task, folder = _recorded_folder(tmp_path, rows=0)
    assert B.completed_row(task)["status"] == "skipped"
    if broken is None:
        (folder / "stacks.csv").unlink()
    else:
        (folder / "stacks.csv").write_bytes(broken.encode("latin-1"))
    assert B.completed_row(task) is None


def test_output_folders_inside_the_input_are_not_scans(tmp_path):
    records = {"batch.json": '{"package": "foldstat", "version": "0"}',
               "stats.json": '{"package": "foldstat", "version": "0"}',
               "summary.json": '{"version": "0", "parameters": {}}',
               "steps.json": '{"command": "steps", "version": "0", "parameters": {}}'}
    inp = tmp_path / "in"
    (inp / "old_batch" / "default" / "s").mkdir(parents=True)
    (inp / "old_batch" / "batch.json").write_text(records["batch.json"])
    (inp / "old_batch" / "default" / "s" / "overlay.png").write_bytes(b"")
    for folder, names in (("result", ("summary.json", "junctions.csv", "overlay.png")),
                          ("steps", ("steps.json", "step1_raw.png", "steps.png")),
                          ("report", ("stats.json", "figures/micro.png"))):
        for name in names:
            (inp / "one" / folder / name).parent.mkdir(parents=True, exist_ok=True)
            (inp / "one" / folder / name).write_text(records.get(name, ""))
    (inp / "one" / "scan.png").write_bytes(b"")
    # a user's folder holding a file of a record's name that is no record is searched
    (inp / "mine").mkdir()
    (inp / "mine" / "summary.json").write_text('{"version": 2, "operator": "lab scanner"}')
    (inp / "mine" / "scan.png").write_bytes(b"")
    assert [p.relative_to(inp).as_posix() for p in B.find_images(inp)] == ["mine/scan.png",
                                                                           "one/scan.png"]


def test_a_set_file_replacing_a_command_line_value_says_so(tmp_path):
    (tmp_path / "set.toml").write_text("px_per_mm = 50\nthickness_mm = 0.1\n")
    cfg = load_set_config(tmp_path / "set.toml", defaults={"px_per_mm": 45.0},
                          given={"px_per_mm": 45.0, "thickness_mm": 0.1})
    assert cfg.params["px_per_mm"] == 50.0
    assert len(cfg.warnings) == 1 and "replaces --px-per-mm 45.0" in cfg.warnings[0]


@pytest.mark.parametrize("option, named", [(["--seed", "-1"], "--seed"),
                                           (["--px-per-mm", "0"], "--px-per-mm"),
                                           (["--thickness-mm", "nan"], "--thickness-mm"),
                                           (["--workers", "0"], "--workers")])
def test_cli_batch_absurd_options_name_the_option(tmp_path, option, named):
    import subprocess
    import sys

    inp = tmp_path / "in"
    inp.mkdir()
    (inp / "a.png").write_bytes(b"")
    r = subprocess.run([sys.executable, "-m", "crosssection", "batch", str(inp), "--out",
                        str(tmp_path / "out"), *option], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith(f"error: {named}: ")
    assert not (tmp_path / "out").exists()


def test_every_format_analyze_reads_is_a_scan_of_a_batch(tmp_path):
    # a BMP or WebP scan is analysed by `analyze`; a batch must not pass it over in silence
    from PIL import Image

    inp = tmp_path / "in"
    inp.mkdir()
    rgb = draw_scan(3)
    for suffix in B.IMAGE_SUFFIXES:
        kind = {".webp": dict(lossless=True)}.get(suffix, {})
        Image.fromarray(rgb).save(inp / f"scan{suffix.replace('.', '_')}{suffix}", **kind)
    tasks, _ = B.plan_batch(inp, tmp_path / "out", seed=0)
    assert sorted(Path(t.rel).suffix for t in tasks) == sorted(B.IMAGE_SUFFIXES)
    assert {".bmp", ".webp"} <= set(B.IMAGE_SUFFIXES)


def _recorded_folder(tmp_path, rows: int = 4):
    """A planned scan whose output folder looks complete: a summary counting ``rows`` rows of
    every table, and the four tables holding them (the analysis is not run)."""
    from crosssection.core.schema import TABLES

    inp = tmp_path / "in"
    inp.mkdir()
    (inp / "a.png").write_bytes(b"\x89PNG")
    (task,), _ = B.plan_batch(inp, tmp_path / "out", figure=False)
    folder = Path(task.out_dir)
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({
        "n_junctions": rows, "n_stacks": rows, "n_branches": rows, "n_voids": rows,
        "batch": {"params_hash": task.params_hash}}))
    for name, columns in TABLES.items():
        lines = [",".join(columns)] + [",".join(["1"] * len(columns))] * rows
        (folder / f"{name}.csv").write_text("\n".join(lines) + "\n")
    return task, folder


@pytest.mark.parametrize("cut, said", [
    (lambda text: text[:text.index("\n") + 1], "0 of the 4 rows summary.json counts"),
    (lambda text: text[:-2], "3 of the 4 rows summary.json counts, its last line cut off"),
    (lambda text: text[:text.index("\n", text.index("\n") + 1) + 3],
     "1 of the 4 rows summary.json counts, its last line cut off")])
def test_resume_redoes_a_scan_whose_table_was_cut_short(tmp_path, cut, said):
    """A table whose header is whole but whose rows were cut (a copy or a full disk that
    stopped mid-file) is redone, and the reason names it; its lines are counted against the
    summary's counts."""
    task, folder = _recorded_folder(tmp_path)
    assert B.completed_row(task)["status"] == "skipped" and B.redo_reason(task) is None
    table = folder / "voids.csv"
    table.write_text(cut(table.read_text()))
    assert B.completed_row(task) is None
    assert B.redo_reason(task) == f"voids.csv in {folder} is cut short ({said})"


def test_resume_redoes_a_scan_whose_summary_was_cut_short_and_says_so(tmp_path):
    task, folder = _recorded_folder(tmp_path)
    text = (folder / "summary.json").read_text()
    (folder / "summary.json").write_text(text[:len(text) // 2])
    assert B.completed_row(task) is None
    assert B.redo_reason(task) == (f"summary.json in {folder} is unreadable (cut short or "
                                   "overwritten)")
    (folder / "summary.json").unlink()
    assert B.redo_reason(task) == f"summary.json in {folder} is missing"
    shutil.rmtree(folder)
    assert B.redo_reason(task) is None  # a scan never analysed


def test_resume_redoes_a_scan_whose_overlay_was_cut_short(tmp_path):
    task, folder = _recorded_folder(tmp_path)
    from dataclasses import replace

    from crosssection.testing import drawn_scan

    task = replace(task, figure=True)

    save_png(folder / "overlay.png", drawn_scan(1)[:40, :40])
    assert B.completed_row(task) is not None
    data = (folder / "overlay.png").read_bytes()
    (folder / "overlay.png").write_bytes(data[:len(data) // 2])
    assert B.completed_row(task) is None
    assert B.redo_reason(task) == f"overlay.png in {folder} is cut short"


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="named pipes are POSIX")
def test_a_named_pipe_named_like_a_record_does_not_block_the_search(tmp_path):
    import os

    (tmp_path / "sub").mkdir()
    os.mkfifo(tmp_path / "sub" / "summary.json")
    (tmp_path / "sub" / "scan.png").write_bytes(b"")
    assert [p.name for p in B.find_images(tmp_path)] == ["scan.png"]


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="named pipes are POSIX")
def test_a_named_pipe_named_like_a_scan_is_a_failed_image_not_a_hang(tmp_path):
    """Hashing the scans while planning read the pipe, and the batch waited for ever."""
    import os

    inp, out = tmp_path / "in", tmp_path / "out"
    save_png(inp / "a.png", draw_scan(3))
    os.mkfifo(inp / "pipe.png")
    index = B.run_batch(inp, out, workers=1, progress=False)
    rows = dict(zip(index["image"], index["status"]))
    assert rows == {"a.png": "ok", "pipe.png": "failed"}
    failures = (out / "failures.csv").read_text()
    assert "pipe.png" in failures and "named pipe" in failures


def test_a_scan_of_a_long_legal_name_is_analysed(tmp_path):
    """A stem of 245 characters: its staging folder's name passed the file system's 255."""
    inp, out = tmp_path / "in", tmp_path / "out"
    long_a, long_b = "z" * 245, "z" * 244 + "y"
    save_png(inp / f"{long_a}.png", draw_scan(3))
    save_png(inp / f"{long_b}.png", draw_scan(4))
    index = B.run_batch(inp, out, workers=1, progress=False, figure=False)
    assert list(index["status"]) == ["ok", "ok"]
    folders = [p.name for p in (out / "default").iterdir() if p.is_dir()]
    assert len(folders) == 2 and all(len(f) <= B.FOLDER_NAME_MAX for f in folders)


def test_an_override_finds_its_scan_in_either_unicode_form(tmp_path):
    # médium.png stored decomposed (NFD, as a Mac copy leaves it), its table typed composed:
    # the hole was not applied, and the set said the table named no image
    import unicodedata

    inp, out = tmp_path / "in", tmp_path / "out"
    (inp / "s").mkdir(parents=True)
    nfd = unicodedata.normalize("NFD", "médium.png")
    (inp / "s" / nfd).write_bytes(b"")
    (inp / "s" / "set.toml").write_text('[images."médium.png"]\nhole_radius_mm = 7.9\n'
                                        'hole_center_px = [10, 20]\n', encoding="utf-8")
    tasks, sets = B.plan_batch(inp, out)
    assert [t.params.get("hole_radius_mm") for t in tasks] == [7.9]
    assert not any("names no image" in w for s in sets.values() for w in s.warnings)
