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
from crosssection.core.errors import ParameterError
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
def _unreachable(workers=1, scheduler=None):
    raise ParameterError(f"no Dask scheduler reached at {scheduler!r}", "--scheduler")
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
    assert status == 2 and len(err) == 1 and err[0].startswith("error: --scheduler: ")
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
    # the same options resume in silence
    status, err = _batch(capsys, inp, out)
    assert status == 0 and _notices(err) == []
    assert (pd.read_csv(out / "index.csv")["status"] == "skipped").all()
    # another value of an option: the images it concerns are redone, and the batch says so
    status, err = _batch(capsys, inp, out, "--l-min-mm", "2")
    assert status == 0
    again = [line for line in err if "analysed again" in line]
    assert len(again) == 1 and again[0].startswith(f"warning: {out}: 2 images analysed again")
    assert "(l_min_mm)" in again[0]
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
