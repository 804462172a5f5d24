"""Batch inputs and outputs a user brings: symbolic links, an output folder that is not the
batch's own, re-runs with other options, a corrupt table, an unreachable scheduler.

The command-line tests call ``crosssection.cli.main`` in this process and read its exit
status and stderr; the analysis is the real pipeline on drawn scans, except where only the
batch's bookkeeping matters (:func:`_quick`).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import pandas as pd
import pytest

from crosssection import batch as B
from crosssection.cli import main
from crosssection.core.errors import ConfigError, ParameterError
from crosssection.testing import drawn_scan, write_png

SCALE = ["--px-per-mm", "50", "--thickness-mm", "0.1"]


def _quick(task):
    """A stand-in for the analysis: the image's index row, nothing written."""
    return B._row(task, "ok")


def _scans(folder: Path, n: int = 1, seed: int = 3) -> Path:
    for i in range(n):
        write_png(folder / f"s{i}.png", drawn_scan(seed + i))
    return folder


def _batch(capsys, inp, out, *options):
    """Run ``crosssection batch`` in this process: (exit status, stderr lines)."""
    capsys.readouterr()
    status = main(["batch", str(inp), "--out", str(out), "--workers", "1", "--no-figure",
                   "--quiet", *SCALE, *options])
    return status, capsys.readouterr().err.splitlines()


def _notices(err: list[str]) -> list[str]:
    """The lines of stderr other than the drawn scans' quality flags."""
    return [line for line in err if "doubtful results" not in line]


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


# ----------------------------------------------------------------------------- symbolic links


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="needs symbolic links")
def test_linked_scans_are_analysed_under_their_own_names(tmp_path, capsys):
    """A link to a scan outside the input folder is analysed like a file, named and set up
    by where the link lies; a broken link fails alone; a linked folder is named, not
    searched."""
    elsewhere = _scans(tmp_path / "elsewhere", n=2)
    inp = tmp_path / "in"
    inp.mkdir()
    (inp / "set.toml").write_text('name = "linked"\npx_per_mm = 50\nthickness_mm = 0.1\n'
                                  '[images."scan.png"]\npx_per_mm = 48\n')
    (inp / "scan.png").symlink_to(elsewhere / "s0.png")
    (inp / "broken.png").symlink_to(tmp_path / "nowhere.png")
    (inp / "more").symlink_to(elsewhere, target_is_directory=True)
    out = tmp_path / "out"
    status, err = _batch(capsys, inp, out)
    assert status == B.EXIT_SOME_FAILED, err
    index = pd.read_csv(out / "index.csv")
    assert dict(zip(index["image"], index["status"])) == {"broken.png": "failed",
                                                         "scan.png": "ok"}
    assert dict(zip(index["image"], index["output"]))["scan.png"] == "linked/scan"
    summary = json.loads((out / "linked" / "scan" / "summary.json").read_text())
    assert summary["batch"]["params"]["px_per_mm"] == 48.0  # the link's override table
    failures = pd.read_csv(out / "failures.csv")
    assert failures["image"].tolist() == ["broken.png"]
    reason = failures["reason"].iloc[0]
    assert str(inp / "broken.png") in reason and "nowhere.png" in reason
    # the linked folder is named once; its scans are not in the batch
    linked = [line for line in err if str(inp / "more") in line]
    assert len(linked) == 1 and linked[0].startswith("warning: ") and "not searched" in linked[0]
    assert not any("s1" in line for line in err)
    assert all(line.startswith("warning: ") for line in err)


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="needs symbolic links")
def test_a_loop_of_links_is_bad_input_named_as_such(tmp_path, capsys):
    from crosssection.cli import main

    inp = tmp_path / "in"
    inp.mkdir()
    (inp / "a.png").symlink_to("b.png")
    (inp / "b.png").symlink_to("a.png")
    for command in ("analyze", "steps"):
        status = main([command, str(inp / "a.png"), "--out", str(tmp_path / command)])
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 2 and len(err) == 1, (command, err)
        assert "a.png" in err[0] and "loop of symbolic links" in err[0]
    status, err = _batch(capsys, inp, tmp_path / "out")
    assert status == B.EXIT_SOME_FAILED
    reasons = pd.read_csv(tmp_path / "out" / "failures.csv")["reason"]
    assert reasons.str.contains("loop of symbolic links").all() and len(reasons) == 2


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="needs symbolic links")
def test_an_unreadable_scan_fails_alone_in_the_plan(tmp_path):
    inp = _scans(tmp_path / "in")
    (inp / "loop.png").symlink_to(inp / "loop.png")  # a link to itself: no target
    tasks = {t.rel: t for t in B.plan_batch(inp, tmp_path / "out")[0]}
    assert tasks["s0.png"].error is None
    assert tasks["loop.png"].error.startswith(str(inp / "loop.png") + ": ")
    assert "\n" not in tasks["loop.png"].error


# ----------------------------------------------------------------------------- whose --out


def test_out_holding_another_inputs_batch_is_refused(tmp_path, capsys):
    first, second, out = tmp_path / "first", tmp_path / "second", tmp_path / "out"
    _scans(first)
    _scans(second, seed=9)
    B.run_batch(first, out, workers=1, progress=False, task_fn=_quick)
    before = _snapshot(out)
    status, err = _batch(capsys, second, out)
    assert status == 2
    assert len(err) == 1 and err[0].startswith(f"error: {out}: ")
    assert str(first.resolve()) in err[0] and "--out" in err[0]
    assert _snapshot(out) == before
    with pytest.raises(ParameterError, match="another input folder"):
        B.run_batch(second, out, workers=1, progress=False, task_fn=_quick)
    # the same input resumes, given by another path to the same folder
    index = B.run_batch(tmp_path / "." / "first", out, workers=1, progress=False,
                        task_fn=_quick)
    assert index["image"].tolist() == ["s0.png"]


@pytest.mark.parametrize("foreign", ["scans", "simulation"])
def test_out_holding_files_no_batch_wrote_is_refused(tmp_path, capsys, foreign):
    inp = _scans(tmp_path / "in")
    out = tmp_path / "out"
    if foreign == "scans":
        _scans(out, n=2)
    else:
        out.mkdir()  # a simulated ensemble: one of its tables has a batch's file name
        for name in ("configs.csv", "failures.csv", "stacks.csv", "params.json"):
            (out / name).write_text("x\n")
    before = _snapshot(out)
    status, err = _batch(capsys, inp, out)
    assert status == 2
    assert len(err) == 1 and err[0].startswith(f"error: {out}: ") and "--out" in err[0]
    assert _snapshot(out) == before and not (out / "batch.json").exists()


def test_out_empty_or_inside_the_input_is_used_and_resumed(tmp_path):
    inp = _scans(tmp_path / "in", n=2)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / ".DS_Store").write_bytes(b"")  # a file browser's, not a foreign file
    assert len(B.run_batch(inp, empty, workers=1, progress=False, task_fn=_quick)) == 2
    inside = inp / "results"
    for _ in range(2):  # created, then resumed: its own scans are never the batch's
        index = B.run_batch(inp, inside, workers=1, progress=False, task_fn=_quick)
        assert index["image"].tolist() == ["s0.png", "s1.png"]


# ----------------------------------------------------------------------------- scheduler


@contextmanager
def _unreachable(workers=1, scheduler=None, *, on_wait=None):
    raise ParameterError("no Dask scheduler answered", f"--scheduler {scheduler}")
    yield  # pragma: no cover


@pytest.mark.parametrize("earlier", [False, True])
def test_an_unreachable_scheduler_writes_nothing(tmp_path, capsys, monkeypatch, earlier):
    inp = _scans(tmp_path / "in", n=2)
    out = tmp_path / "out"
    if earlier:  # a batch to resume: its record stays as it was
        B.run_batch(inp, out, workers=1, progress=False, task_fn=_quick)
        (out / "default" / "s1").mkdir(parents=True)
    before = _snapshot(out) if earlier else None
    monkeypatch.setattr(B, "get_executor", _unreachable)
    status, err = _batch(capsys, inp, out, "--scheduler", "tcp://127.0.0.1:1")
    assert status == 2 and len(err) == 1
    assert err[0].startswith("error: --scheduler tcp://127.0.0.1:1: ")
    if earlier:
        assert _snapshot(out) == before
    else:
        assert not out.exists()


# ----------------------------------------------------------------------------- re-runs


def test_a_rerun_with_other_options_says_which_images_it_redoes(tmp_path, capsys):
    inp = _scans(tmp_path / "in", n=2)  # loose scans: they follow the command line
    fixed = _scans(inp / "fixed", seed=11)
    (fixed / "set.toml").write_text("px_per_mm = 50\nthickness_mm = 0.1\nl_min_mm = 1.5\n")
    out = tmp_path / "out"
    assert _batch(capsys, inp, out)[0] == 0
    first = pd.read_csv(out / "index.csv").set_index("image")
    # the same options resume in silence, keeping what the analyses measured
    status, err = _batch(capsys, inp, out)
    assert status == 0 and _notices(err) == []
    index = pd.read_csv(out / "index.csv").set_index("image")
    assert (index["status"] == "skipped").all()
    assert first["peak_rss_mb"].notna().all()
    assert index["peak_rss_mb"].equals(first["peak_rss_mb"])
    # another value of an option: the images it concerns are redone, and the batch says so
    status, err = _batch(capsys, inp, out, "--l-min-mm", "2")
    assert status == 0
    # one line per scan, naming it and what differs
    again = [line for line in err if "analysed again" in line]
    assert again == [f"warning: {inp / name}: analysed again: its parameters differ from the "
                     "recorded ones (l_min_mm); its earlier results are replaced if it succeeds"
                     for name in ("s0.png", "s1.png")]
    index = pd.read_csv(out / "index.csv")
    assert dict(zip(index["image"], index["status"])) == {
        "fixed/s0.png": "skipped", "s0.png": "ok", "s1.png": "ok"}
    assert json.loads((out / "default" / "s0" / "summary.json").read_text()
                      )["batch"]["params"]["l_min_mm"] == 2.0
    status, err = _batch(capsys, inp, out, "--l-min-mm", "2")
    assert status == 0 and not any("analysed again" in line for line in err)
    assert len(_notices(err)) == 1 and "replaces --l-min-mm" in _notices(err)[0]
    # --force redoes every image, as asked: nothing to say
    status, err = _batch(capsys, inp, out, "--force")
    assert status == 0 and not any("analysed again" in line for line in err)


def test_what_a_redone_image_changed_is_named(tmp_path):
    inp = _scans(tmp_path / "in")
    out = tmp_path / "out"
    B.run_batch(inp, out, workers=1, progress=False, figure=False,
                cli_params={"px_per_mm": 50, "thickness_mm": 0.1})
    (task,), _ = B.plan_batch(inp, out, figure=False,
                              cli_params={"px_per_mm": 50, "thickness_mm": 0.1})
    assert B.changed_inputs(task) == []
    (task,), _ = B.plan_batch(inp, out, figure=False,
                              cli_params={"px_per_mm": 40, "thickness_mm": 0.1})
    assert B.changed_inputs(task) == ["px_per_mm"]
    write_png(inp / "s0.png", drawn_scan(99))
    (task,), _ = B.plan_batch(inp, out, figure=False,
                              cli_params={"px_per_mm": 50, "thickness_mm": 0.1})
    assert B.changed_inputs(task) == ["image or calibration file content"]


def test_a_scale_given_after_the_default_redoes_the_image_and_clears_its_flag(tmp_path,
                                                                                capsys):
    """The default scale and the same scale given analyse alike, but only the first is
    flagged ``scale_assumed``: a re-run that gives it redoes the image rather than keep the
    flag, and says why."""
    inp = _scans(tmp_path / "in")  # PNGs that record no resolution
    out = tmp_path / "out"

    def run(*scale):
        capsys.readouterr()
        status = main(["batch", str(inp), "--out", str(out), "--workers", "1", "--no-figure",
                       "--quiet", "--thickness-mm", "0.1", *scale])
        return status, capsys.readouterr().err.splitlines()

    assert run()[0] == 0
    summary = out / "default" / "s0" / "summary.json"
    assert "scale_assumed" in json.loads(summary.read_text())["quality"]["codes"]
    status, err = run("--px-per-mm", "50")
    assert status == 0
    assert [line for line in err if "analysed again" in line] == [
        f"warning: {inp / 's0.png'}: analysed again: its parameters differ from the recorded "
        "ones (px_per_mm given); its earlier results are replaced if it succeeds"]
    assert "scale_assumed" not in json.loads(summary.read_text())["quality"]["codes"]
    assert "scale_assumed" not in str(pd.read_csv(out / "index.csv")["quality"][0])
    status, err = run("--px-per-mm", "50")
    assert status == 0 and (pd.read_csv(out / "index.csv")["status"] == "skipped").all()


# the sample scans carry no calibration, so their analysis flags them
@pytest.mark.filterwarnings("ignore::crosssection.stats.data.FlaggedScanWarning")
def test_a_rerun_redoes_a_scan_whose_table_is_corrupt(tmp_path, capsys):
    """The corrupt table is redone, and the batch reads as a whole again."""
    from crosssection.stats.data import load_batch

    inp = _scans(tmp_path / "in", n=2)
    out = tmp_path / "out"
    assert _batch(capsys, inp, out)[0] == 0
    good = (out / "default" / "s1" / "stacks.csv").read_text()
    (out / "default" / "s1" / "stacks.csv").write_text("garbage\n")
    status, err = _batch(capsys, inp, out)
    assert status == 0, err
    # the scan redone is named, with the table that made it so
    assert _notices(err) == [f"warning: {inp / 's1.png'}: analysed again: stacks.csv in "
                             f"{(out / 'default' / 's1').resolve()} is missing or unreadable; "
                             "its earlier results are replaced if it succeeds"]
    index = pd.read_csv(out / "index.csv")
    assert dict(zip(index["image"], index["status"])) == {"s0.png": "skipped", "s1.png": "ok"}
    assert (out / "default" / "s1" / "stacks.csv").read_text() == good
    load_batch(out)  # raises on an unreadable table


def test_a_copied_batch_resumes(tmp_path, capsys):
    """A batch folder copied elsewhere keeps its input: the copy resumes, it is not refused."""
    inp = _scans(tmp_path / "in")
    out = tmp_path / "out"
    assert _batch(capsys, inp, out)[0] == 0
    shutil.copytree(out, tmp_path / "copy")
    status, err = _batch(capsys, inp, tmp_path / "copy")
    assert status == 0 and _notices(err) == []
    assert (pd.read_csv(tmp_path / "copy" / "index.csv")["status"] == "skipped").all()


def test_progress_and_quiet_are_not_given_together(tmp_path):
    """--quiet is --no-progress: given with --progress the command line contradicts itself."""
    run = subprocess.run([sys.executable, "-m", "crosssection", "batch", str(tmp_path),
                          "--out", str(tmp_path / "out"), "--progress", "--quiet"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and len(run.stderr.splitlines()) == 1
    assert "--quiet: not allowed with argument --progress" in run.stderr
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- set names


def _set(folder: Path, text: str, *scans: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "set.toml").write_text(text)
    for name in scans:
        (folder / name).write_bytes(b"\x89PNG")
    return folder


def test_set_folders_of_one_name_in_two_experiments_stay_two_sets(tmp_path):
    inp = tmp_path / "in"
    _set(inp / "eps8" / "day1", "thickness_mm = 0.1\n", "scan_01.png")
    _set(inp / "eps14" / "day1", "thickness_mm = 0.1\n", "scan_01.png")
    tasks, sets = B.plan_batch(inp, tmp_path / "out")
    by = {t.rel: t for t in tasks}
    assert by["eps8/day1/scan_01.png"].set_name == "eps8/day1"
    assert by["eps14/day1/scan_01.png"].set_name == "eps14/day1"
    assert by["eps8/day1/scan_01.png"].out_rel == "eps8/day1/scan_01"
    assert by["eps14/day1/scan_01.png"].out_rel == "eps14/day1/scan_01"


def test_two_sets_naming_themselves_alike_with_other_parameters_are_refused(tmp_path, capsys):
    inp, out = tmp_path / "in", tmp_path / "out"
    _set(inp / "s", 'name = "bad"\nthickness_mm = 0.1\n', "a.png")
    _set(inp / "t", 'name = "bad"\nthickness_mm = 0.08\n', "a.png")
    status, err = _batch(capsys, inp, out)
    assert status == 2 and len(err) == 1
    assert err[0].startswith(f"error: {(inp / 't' / 'set.toml').resolve()}: set name 'bad'")
    assert str((inp / "s" / "set.toml").resolve()) in err[0] and "(thickness_mm)" in err[0]
    assert not out.exists()  # refused before anything is written


def test_two_sets_naming_themselves_alike_with_one_set_of_parameters_are_one_set(tmp_path):
    inp = tmp_path / "in"
    _set(inp / "s", 'name = "run"\nthickness_mm = 0.1\n', "a.png")
    _set(inp / "t", 'name = "run"\nthickness_mm = 0.1\n', "a.png", "b.png")
    tasks, _ = B.plan_batch(inp, tmp_path / "out")
    assert {t.set_name for t in tasks} == {"run"}
    outs = {t.rel: t.out_rel for t in tasks}
    assert len(set(outs.values())) == 3 and outs["t/b.png"] == "run/b"


def test_a_set_named_default_with_other_parameters_than_the_loose_scans_is_refused(tmp_path):
    inp = tmp_path / "in"
    (inp / "loose.png").parent.mkdir(parents=True)
    (inp / "loose.png").write_bytes(b"\x89PNG")
    _set(inp / "x", 'name = "default"\nthickness_mm = 0.2\n', "a.png")
    with pytest.raises(ConfigError, match=r"x/set.toml: set name .default. is also that of "
                       "the scans outside any set"):
        B.plan_batch(inp, tmp_path / "out", cli_params={"thickness_mm": 0.1})


# ----------------------------------------------------------------------------- folder names


def _summary_only(task):
    """A stand-in for the analysis that leaves a recorded output folder."""
    folder = Path(task.out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "summary.json").write_text(json.dumps({"batch": {
        "params_hash": task.params_hash, "params": task.params}}))
    return B._row(task, "ok")


def test_a_scan_keeps_its_folder_when_one_of_the_same_stem_appears(tmp_path):
    inp, out = tmp_path / "in", tmp_path / "out"
    _set(inp / "epsB", 'name = "B"\n', "scan_03.png")
    B.run_batch(inp, out, workers=1, progress=False, figure=False, task_fn=_quick)
    (inp / "epsB" / "day2").mkdir()
    (inp / "epsB" / "day2" / "scan_03.jpeg").write_bytes(b"\xff\xd8")
    tasks, _ = B.plan_batch(inp, out, figure=False)
    outs = {t.rel: t.out_rel for t in tasks}
    assert outs == {"epsB/scan_03.png": "B/scan_03", "epsB/day2/scan_03.jpeg":
                    "B/epsB__day2__scan_03_jpeg"}
    # a fresh batch names both by their paths
    fresh = {t.rel: t.out_rel for t in B.plan_batch(inp, tmp_path / "new", figure=False)[0]}
    assert fresh["epsB/scan_03.png"] == "B/epsB__scan_03_png"


def test_output_folders_no_scan_names_any_more_are_named_once(tmp_path, capsys):
    inp, out = tmp_path / "in", tmp_path / "out"
    _set(inp / "setA", 'name = "alpha"\n', "a.png", "b.png")
    B.run_batch(inp, out, workers=1, progress=False, figure=False, task_fn=_summary_only)
    (inp / "setA" / "set.toml").write_text('name = "beta"\n')  # the set renamed
    with pytest.warns(B.BatchWarning) as caught:
        B.run_batch(inp, out, workers=1, progress=False, figure=False, task_fn=_summary_only)
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and said[0].startswith(
        f"{out}: 2 output folders match no scan of this batch: alpha/a, alpha/b (")
    assert (out / "alpha" / "a" / "summary.json").is_file()  # left where they are
    (inp / "setA" / "b.png").unlink()  # a scan deleted
    with pytest.warns(B.BatchWarning, match="3 output folders match no scan of this batch: "
                      "alpha/a, alpha/b, beta/b"):
        B.run_batch(inp, out, workers=1, progress=False, figure=False, task_fn=_summary_only,
                    force=True)
    assert json.loads((out / "batch.json").read_text())["stale_outputs"] == [
        "alpha/a", "alpha/b", "beta/b"]


# ----------------------------------------------------------------------------- index and records


def test_a_failed_scan_has_no_output_folder_in_the_index(tmp_path):
    inp, out = tmp_path / "in", tmp_path / "out"
    _scans(inp)
    (inp / "corrupt.png").write_bytes(b"\x89PNG garbage")
    index = B.run_batch(inp, out, workers=1, progress=False, figure=False,
                        cli_params={"px_per_mm": 50, "thickness_mm": 0.1})
    rows = pd.read_csv(out / "index.csv", keep_default_na=False).set_index("image")
    assert rows.loc["corrupt.png", "status"] == "failed" and rows.loc["corrupt.png", "output"] == ""
    assert rows.loc["s0.png", "output"] == "default/s0" and (out / "default" / "s0").is_dir()
    assert len(index) == 2
    # each row says how its epsilon is made: L used / (2 pi R)
    import math

    row = rows.loc["s0.png"]
    assert {"rod_length_mm", "rod_length_used_mm", "hole_radius_mm"} <= set(rows.columns)
    assert float(row["epsilon"]) == pytest.approx(
        float(row["rod_length_used_mm"]) / (2 * math.pi * float(row["hole_radius_mm"])))
    # the summary names its inputs: the scan's path as given and resolved, and its SHA-256
    import hashlib

    inputs = json.loads((out / "default" / "s0" / "summary.json").read_text())["batch"]["inputs"]
    assert inputs["image"]["path"] == str(inp / "s0.png")
    assert inputs["image"]["resolved"] == str((inp / "s0.png").resolve())
    assert inputs["image"]["sha256"] == hashlib.sha256((inp / "s0.png").read_bytes()).hexdigest()
    assert inputs["calibration"] is None


def test_the_records_name_their_inputs_and_times_as_analyze_does(tmp_path):
    """One record of the inputs for analyze and batch; time stamps with their UTC offset."""
    from datetime import datetime, timedelta

    inp, out = tmp_path / "in", tmp_path / "out"
    _scans(inp)
    B.run_batch(inp, out, workers=1, progress=False, figure=False,
                cli_params={"px_per_mm": 50, "thickness_mm": 0.1})
    meta = json.loads((out / "batch.json").read_text())
    for key in ("started", "finished"):
        assert datetime.fromisoformat(meta[key]).utcoffset() == timedelta(0), meta[key]
    summary = json.loads((out / "default" / "s0" / "summary.json").read_text())
    assert summary["inputs"] == summary["batch"]["inputs"]
    assert summary["inputs"]["image"]["path"] == str(inp / "s0.png")
    assert summary["image"]["path"] == str((inp / "s0.png").resolve())
    assert summary["libraries"]["numpy"]


def test_the_summary_records_the_calibration_it_used(tmp_path):
    import hashlib

    inp = tmp_path / "in"
    folder = _set(inp / "setA", 'calibration = "cal.csv"\n', "a.png")
    (folder / "cal.csv").write_text("n_layers,width_mm\n1,0.1\n2,0.25\n")
    (task,), _ = B.plan_batch(inp, tmp_path / "out")
    cal = B.input_record(task)["calibration"]
    assert cal["sha256"] == hashlib.sha256((folder / "cal.csv").read_bytes()).hexdigest()
    assert cal["widths"] == {"n_layers": [1, 2], "width_mm": [0.1, 0.25]}
    assert cal["resolved"] == str((folder / "cal.csv").resolve())


def test_the_parameters_hash_follows_the_effective_parameters(tmp_path):
    inp = tmp_path / "in"
    _scans(inp)
    plain = B.plan_batch(inp, tmp_path / "out", cli_params={"thickness_mm": 0.1})[0][0]
    # (10 h)^2 and 3 h are the defaults of s_min and the tangent length: one analysis
    spelled = B.plan_batch(inp, tmp_path / "out", cli_params={
        "thickness_mm": 0.1, "s_min_mm2": 1.0, "tangent_mm": 0.3})[0][0]
    assert spelled.params_hash == plain.params_hash
    # the default scale given analyses alike but is not flagged scale_assumed: another hash
    scaled = [B.plan_batch(inp, tmp_path / "out", cli_params={
        "thickness_mm": 0.1, "px_per_mm": v})[0][0].params_hash for v in (50, 50.0)]
    assert scaled[0] == scaled[1] != plain.params_hash
    other = B.plan_batch(inp, tmp_path / "out", cli_params={"thickness_mm": 0.1,
                                                            "s_min_mm2": 2.0})[0][0]
    assert other.params_hash != plain.params_hash
    # one calibration, wherever its file lies
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "cal.csv").write_text("n_layers,width_mm\n1,0.1\n")
    h = [B.plan_batch(inp, tmp_path / "out", cli_params={
        "calibration": str(tmp_path / name / "cal.csv")})[0][0].params_hash for name in "ab"]
    assert h[0] == h[1] != plain.params_hash


def test_an_image_seed_follows_its_path_not_its_place_in_the_list(tmp_path, capsys):
    inp = tmp_path / "in"
    _set(inp / "x", "", "m.png")
    before = {t.rel: t.seed for t in B.plan_batch(inp, tmp_path / "out")[0]}
    (inp / "x" / "a.png").write_bytes(b"\x89PNG")  # sorts first
    after = {t.rel: t.seed for t in B.plan_batch(inp, tmp_path / "out")[0]}
    assert after["x/m.png"] == before["x/m.png"] != after["x/a.png"]
    assert B.plan_batch(inp, tmp_path / "out", seed=1)[0][0].seed != after["x/a.png"]
    # --help says the analysis does not use it
    with pytest.raises(SystemExit):
        main(["batch", "--help"])
    assert "draws no random numbers" in " ".join(capsys.readouterr().out.split())


# ----------------------------------------------------------------------------- interrupts


@pytest.mark.parametrize("n_scans, complete", [(1, True), (3, False)])
def test_an_interrupt_after_the_last_image_finishes_the_batch(tmp_path, monkeypatch, n_scans,
                                                              complete):
    inp, out = tmp_path / "in", tmp_path / "out"
    _set(inp / "x", "", *[f"s{i}.png" for i in range(n_scans)])
    real = B._write_tables
    calls = {"n": 0}

    def interrupted_once(*args, **kw):
        calls["n"] += 1
        # the first write lists every scan pending; the interrupt lands at the next, after
        # the first rows (two slots)
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(*args, **kw)

    monkeypatch.setattr(B, "INDEX_EVERY_S", -1.0)
    monkeypatch.setattr(B, "_write_tables", interrupted_once)
    if complete:
        index = B.run_batch(inp, out, workers=1, progress=False, task_fn=_quick)
        assert (index["status"] == "ok").all()
    else:
        with pytest.raises(KeyboardInterrupt):
            B.run_batch(inp, out, workers=1, progress=False, task_fn=_quick)
    meta = json.loads((out / "batch.json").read_text())
    assert meta["complete"] is complete and meta["interrupted"] is not complete


def test_the_record_names_the_workers_used(tmp_path, monkeypatch):
    # batch.json said "workers": null for a batch run with one worker per CPU
    from crosssection.core import parallel

    inp = tmp_path / "in"
    _set(inp / "x", "", "s0.png")
    asked = []

    def inline(workers, scheduler=None, **kw):
        asked.append(workers)
        return parallel.get_executor(1, None, **kw)

    monkeypatch.setattr(B, "get_executor", inline)
    for workers, out in ((None, tmp_path / "a"), (1, tmp_path / "b")):
        B.run_batch(inp, out, workers=workers, progress=False, task_fn=_quick)
        meta = json.loads((out / "batch.json").read_text())
        assert meta["workers"] == (os.cpu_count() or 1 if workers is None else workers)
    assert asked[0] is None  # the record says what None meant; the executor is asked the same


def test_a_rerun_killed_before_its_first_result_leaves_no_row_of_the_earlier_run(tmp_path):
    # the earlier run's rows of the scans being redone must not outlive their folders: a
    # run killed (SIGKILL, out of memory) before its first result lists them as pending
    inp, out = tmp_path / "in", tmp_path / "out"
    _set(inp / "x", "", "s0.png", "s1.png")
    B.run_batch(inp, out, workers=1, progress=False, task_fn=_quick)
    assert set(pd.read_csv(out / "index.csv")["status"]) == {"ok"}
    seen = {}

    def killed(task):
        seen["index"] = pd.read_csv(out / "index.csv", keep_default_na=False)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        B.run_batch(inp, out, workers=1, progress=False, task_fn=killed, force=True)
    first = seen["index"]
    assert set(first["status"]) == {"pending"} and first["total_energy"].eq("").all()
    assert list(first["output"]) == ["x/s0", "x/s1"]  # the folders keep their names


# ----------------------------------------------------------------------------- full disk, leftovers


def test_a_batch_whose_records_cannot_be_written_stops_naming_the_file(tmp_path, capsys,
                                                                       monkeypatch):
    """A disk that fills up under index.csv stops the batch in one line naming the file (not
    "output"); the scans done are in their folders, and the re-run resumes from them."""
    import errno

    from crosssection.core import fileio

    inp, out = _scans(tmp_path / "in", n=2), tmp_path / "out"
    real = B.write_csv
    calls = {"n": 0}

    def full(path, df):
        # the disk fills up after the first write, which lists the scans pending
        calls["n"] += Path(path).name == "index.csv"
        if Path(path).name == "index.csv" and calls["n"] > 1:
            with fileio.atomic_path(path):
                raise OSError(errno.ENOSPC, "No space left on device")  # as a write raises it
        return real(path, df)

    monkeypatch.setattr(B, "INDEX_EVERY_S", -1.0)
    monkeypatch.setattr(B, "write_csv", full)
    status, err = _batch(capsys, inp, out)
    assert status == 2
    assert err == [f"error: {out / 'index.csv'}: cannot write (No space left on device); the "
                   "batch stops: re-run the same command to resume"]
    assert json.loads((out / "batch.json").read_text()).get("complete") is not True
    monkeypatch.setattr(B, "write_csv", real)  # room again
    status, err = _batch(capsys, inp, out)
    assert status == 0 and _notices(err) == []
    assert set(pd.read_csv(out / "index.csv")["status"]) == {"skipped"}


def test_a_scan_that_cannot_be_written_is_named_by_its_output_folder(tmp_path, capsys,
                                                                     monkeypatch):
    """A scan whose table cannot be written fails naming the table in its output folder, not
    in the hidden staging folder it was written into (which is gone)."""
    import errno

    inp, out = _scans(tmp_path / "in"), tmp_path / "out"
    real = pd.DataFrame.to_csv

    def full(self, path=None, *args, **kwargs):
        if B.PARTIAL_TAG in str(path):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, path, *args, **kwargs)

    monkeypatch.setattr(pd.DataFrame, "to_csv", full)
    status, err = _batch(capsys, inp, out)
    assert status == 3
    folder = (out / "default" / "s0").resolve()
    assert _notices(err)[0] == (f"warning: {inp / 's0.png'}: not analysed: "
                                f"{folder / 'junctions.csv'}: cannot write (No space left on "
                                "device)")
    assert B.PARTIAL_TAG not in (out / "failures.csv").read_text()


def test_a_rerun_removes_what_killed_runs_left(tmp_path, capsys):
    """Staging folders (beside a scan the re-run skips as done, left by a killed --force
    run) and the temporary files of the batch's records are removed; such files alone do
    not make a folder someone else's."""
    from crosssection.testing import partial_outputs

    inp, out = _scans(tmp_path / "in"), tmp_path / "out"
    assert _batch(capsys, inp, out)[0] == 0
    staging = out / "default" / f".s0{B.PARTIAL_TAG}x1y2z3ab"
    staging.mkdir()
    (staging / ".overlay.png.k3j2l1ab.png").write_bytes(b"\x89PNG")
    for name in (".index.csv.abcd1234.csv", ".failures.csv.abcd1234.csv",
                 ".batch.json.k3j2l1ab.json"):
        (out / name).write_text("half")
    status, err = _batch(capsys, inp, out)
    assert status == 0 and _notices(err) == []
    assert pd.read_csv(out / "index.csv")["status"].tolist() == ["skipped"]
    assert partial_outputs(out) == []
    # a batch killed before it wrote its first record
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    (fresh / ".batch.json.k3j2l1ab.json").write_text("{")
    B.run_batch(inp, fresh, workers=1, progress=False, figure=False, task_fn=_quick)
    assert partial_outputs(fresh) == []


def test_a_second_batch_into_the_same_folder_is_refused(tmp_path, capsys):
    """While a batch writes into OUT_DIR, another is refused before it writes anything; the
    lock file left by a killed batch locks nothing."""
    inp, out = _scans(tmp_path / "in"), tmp_path / "out"
    out.mkdir()
    with B.batch_lock(out):
        status, err = _batch(capsys, inp, out)
        assert status == 2
        assert err == [f"error: {out}: another batch is writing into it (pid {os.getpid()}): "
                       "wait for it to end, or give another --out"]
        assert [p.name for p in out.iterdir()] == [B.LOCK_FILE]
    assert list(out.iterdir()) == []  # the lock file goes with the batch
    (out / B.LOCK_FILE).write_text("4194303\n")  # a batch killed with SIGKILL
    status, err = _batch(capsys, inp, out)
    assert status == 0 and _notices(err) == []
    assert not (out / B.LOCK_FILE).exists()


def test_a_task_that_outlives_its_batch_keeps_nothing(tmp_path):
    """A cluster's worker still analysing when the batch was stopped (its lock released, or
    taken by a re-run) must not write into the output: its results are dropped."""
    from dataclasses import replace

    inp, out = _scans(tmp_path / "in"), tmp_path / "out"
    out.mkdir()
    (task,), _ = B.plan_batch(inp, out, cli_params={"px_per_mm": 50.0, "thickness_mm": 0.1},
                              figure=False)
    with B.batch_lock(out) as token:
        assert token and token in (out / B.LOCK_FILE).read_text()
        mine = replace(task, run_token=token)
    row = B.process_image(mine)  # the batch has ended: no lock file
    assert row["status"] == "failed" and "batch stopped" in row["reason"]
    assert [p for p in out.rglob("*") if not p.is_dir() or any(p.iterdir())] == []
    with B.batch_lock(out):  # a re-run holds the folder now
        assert B.process_image(mine)["status"] == "failed"
        assert not Path(task.out_dir).exists()
        assert list(out.rglob(f"*{B.PARTIAL_TAG}*")) == []
    with B.batch_lock(out) as token:
        assert B.process_image(replace(task, run_token=token))["status"] == "ok"
    assert (Path(task.out_dir) / "summary.json").is_file()


@pytest.mark.filterwarnings("ignore::crosssection.stats.data.FlaggedScanWarning")
def test_stats_names_the_images_a_batch_could_not_analyse(tmp_path, capsys):
    from crosssection.stats.data import IncompleteBatchWarning, load_batch

    inp, out = _scans(tmp_path / "in"), tmp_path / "out"
    (inp / "corrupt.png").write_bytes(b"\x89PNG garbage")
    assert _batch(capsys, inp, out)[0] == B.EXIT_SOME_FAILED
    with pytest.warns(IncompleteBatchWarning) as caught:
        ens = load_batch(out)
    said = [str(w.message) for w in caught if w.category is IncompleteBatchWarning]
    assert said == [f"{out / 'failures.csv'}: 1 of 2 images (corrupt.png: not an image file "
                    "(unknown or corrupt format)) was not analysed and is not in the statistics"]
    # the report says it too, beside the unfinished batches
    from crosssection.stats.report import incomplete_batches

    assert incomplete_batches(ens) == said


def test_warning_lines_stay_one_line_and_name_the_scan_once(tmp_path, capsys):
    inp = _scans(tmp_path / "in", n=1)
    (inp / "s0.png").rename(inp / "new\nline.png")
    (inp / "bad.png").write_bytes(b"x")
    status, err = _batch(capsys, inp, tmp_path / "out")
    assert status == B.EXIT_SOME_FAILED
    assert all(line.startswith("warning: ") for line in err), err
    (bad,) = [line for line in err if "bad.png" in line]
    assert bad.count("bad.png") == 1 and ": not analysed: not an image file" in bad


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="needs symbolic links")
def test_a_lock_file_that_is_a_link_is_refused_and_its_target_left_alone(tmp_path, capsys):
    inp, out = _scans(tmp_path / "in"), tmp_path / "out"
    out.mkdir()
    precious = tmp_path / "precious.txt"
    precious.write_text("a user's data\n")
    (out / B.LOCK_FILE).symlink_to(precious)
    status, err = _batch(capsys, inp, out)
    assert status == 2 and len(err) == 1 and "symbolic link" in err[0]
    assert precious.read_text() == "a user's data\n"


def test_a_damaged_batch_record_says_how_to_recover_and_force_rebuilds_it(tmp_path, capsys):
    """A batch.json cut to nothing stopped every re-run, --force included, with no way out
    but deleting the whole output."""
    inp, out = _scans(tmp_path / "in"), tmp_path / "out"
    assert _batch(capsys, inp, out)[0] == 0
    (out / "batch.json").write_text("")
    status, err = _batch(capsys, inp, out)
    assert status == 2 and len(err) == 1
    assert err[0].startswith(f"error: {out / 'batch.json'}: malformed JSON")
    assert "--force" in err[0]
    status, err = _batch(capsys, inp, out, "--force")
    assert status == 0 and _notices(err) == []
    assert json.loads((out / "batch.json").read_text())["complete"] is True
    assert set(pd.read_csv(out / "index.csv")["status"]) == {"ok"}
    # a damaged record with no index beside it is no batch's: --force does not take it
    other = tmp_path / "other"
    other.mkdir()
    (other / "batch.json").write_text("{")
    (other / "mine.txt").write_text("a user's file")
    status, err = _batch(capsys, inp, other, "--force")
    assert status == 2 and len(err) == 1 and "malformed JSON" in err[0]
    assert sorted(p.name for p in other.iterdir()) == ["batch.json", "mine.txt"]


def test_a_steps_folder_is_no_folder_of_scans(tmp_path, capsys):
    """batch read the step images of a steps run as scans (three failed, one 'done'), and
    stats told to run batch on them."""
    scan = _scans(tmp_path / "in") / "s0.png"
    steps = tmp_path / "steps"
    assert main(["steps", str(scan), "--out", str(steps), *SCALE]) == 0
    status, err = _batch(capsys, steps, tmp_path / "b")
    assert status == 2 and err == [f"error: {steps}: holds the output of foldstat steps "
                                   "(steps.json), not scans: batch reads a folder of scans"]
    assert not (tmp_path / "b").exists()
    assert main(["stats", str(steps), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "step images of foldstat steps" in err[0]
    # a table of the user's named like a simulation's does not stop a batch of scans
    (tmp_path / "in" / "configs.csv").write_text("id,notes\n1,cut at 30 cm\n")
    status, err = _batch(capsys, tmp_path / "in", tmp_path / "b2")
    assert status == 0 and _notices(err) == []


def test_a_folder_that_cannot_be_listed_is_named_and_the_batch_goes_on(tmp_path, capsys,
                                                                       monkeypatch):
    """A subfolder without read or search permission stopped the whole batch with an error
    naming a file inside it (looking for a simulation's table there raised). It is passed
    over and named in one warning; the other scans are analysed."""
    import errno
    from pathlib import PosixPath

    inp = _scans(tmp_path / "in")
    _scans(inp / "locked", seed=5)
    _scans(inp / "half", seed=6)  # listed, not searched (read permission, no execute)
    # the folders that cannot be listed, and those whose entries cannot be looked at
    denied_list, denied_search = {(inp / "locked").resolve()}, {(inp / "locked").resolve(),
                                                               (inp / "half").resolve()}
    half = (inp / "half").resolve()

    def denied(path):
        return OSError(errno.EACCES, os.strerror(errno.EACCES), str(path))

    # the permissions as a user without them meets them (the tests may run as root)
    scandir, stat = os.scandir, PosixPath.stat

    def guarded_scandir(path="."):
        if Path(path).resolve() in denied_list:
            raise denied(path)
        return scandir(path)

    def guarded_stat(self, **kw):  # a folder's entries are looked at only with its search right
        if Path(os.path.realpath(self.parent)) in denied_search:
            raise denied(self)
        return stat(self, **kw)

    monkeypatch.setattr(os, "scandir", guarded_scandir)
    monkeypatch.setattr(PosixPath, "stat", guarded_stat)
    status, err = _batch(capsys, inp, tmp_path / "out")
    assert status == B.EXIT_SOME_FAILED, err
    named = [line for line in err if "locked" in line]
    assert named == [f"warning: {inp / 'locked'}: cannot list the folder (Permission denied): "
                     "its scans are not in the batch; give read and search permission and "
                     "re-run"]
    index = pd.read_csv(tmp_path / "out" / "index.csv")
    assert dict(zip(index["image"], index["status"])) == {"half/s0.png": "failed",
                                                         "s0.png": "ok"}
    reason = pd.read_csv(tmp_path / "out" / "failures.csv")["reason"].iloc[0]
    assert reason == (f"{half}: cannot search the folder (Permission denied): its files cannot "
                      "be read; give it search permission and re-run")
    # the input folder itself cannot be listed, or searched: one line naming it, exit 2
    denied_list, denied_search = {inp.resolve()}, set()
    status, err = _batch(capsys, inp, tmp_path / "out2")
    assert status == 2 and err == [f"error: {inp}: cannot list the folder (Permission denied)"]
    denied_list, denied_search = set(), {inp.resolve()}
    status, err = _batch(capsys, inp, tmp_path / "out3")
    assert status == 2 and err == [f"error: {inp}: cannot search the folder (Permission denied)"]


def test_a_users_table_named_like_a_simulations_does_not_hide_a_subfolders_scans(tmp_path,
                                                                                capsys):
    """A folder is a simulation's output only with its configs.csv and params.json: a
    user's configs.csv beside scans left them out of the batch, unnamed."""
    inp = _scans(tmp_path / "in")
    _scans(inp / "cut", seed=5)
    (inp / "cut" / "configs.csv").write_text("config,value\n1,2\n")
    (inp / "cut" / "params.json").write_text('{"scanner": "A4", "dpi": 1270}\n')
    sim = inp / "sim"
    _scans(sim, seed=7)  # a simulation's folder holds no scan; one put there is not searched
    (sim / "configs.csv").write_text("config_id\n0\n")
    (sim / "params.json").write_text(json.dumps({"command": "quench", "n_configs": 1,
                                                 "seed": 0, "version": "0"}))
    status, err = _batch(capsys, inp, tmp_path / "out")
    assert status == 0, err
    index = pd.read_csv(tmp_path / "out" / "index.csv")
    assert sorted(index["image"]) == ["cut/s0.png", "s0.png"]
