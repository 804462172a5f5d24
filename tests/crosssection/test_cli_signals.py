"""An interrupted or terminated command line stops at once: one ``error:`` line, exit status
130 (SIGINT) or 143 (SIGTERM), no worker process left behind, and a re-run resumes.

The signal goes to the command's process alone, as ``kill PID``, ``timeout -s INT`` and job
runners send it (Ctrl-C in a terminal reaches the workers as well).
"""
from __future__ import annotations

import argparse
import json
import signal

import numpy as np
import pandas as pd
import pytest

from crosssection.cli import INTERRUPTED, TERMINATED, Terminated, run_parsed

#: a batch whose images each take a minute: the command line of crosssection, its analysis
#: replaced (in the spawned workers too, which import this script as their main module)
SLOW_BATCH = '''
import os
import sys
import time
from pathlib import Path


def slow(task):
    from crosssection.core.fileio import staging_folder

    (staging_folder(task.out_dir) / "table.csv").write_text("half")  # as an analysis writes
    Path(os.environ["MARKS"], str(os.getpid())).touch()  # this worker is at work
    time.sleep(60)


if __name__ == "__main__":
    from crosssection import batch
    from crosssection.cli import main

    batch.process_image = slow
    sys.exit(main(sys.argv[1:]))
'''


@pytest.mark.parametrize("sig, status, word", [(signal.SIGINT, 130, "interrupted"),
                                               (signal.SIGTERM, 143, "terminated")])
def test_a_signalled_batch_stops_its_workers_and_exits_at_once(tmp_path, signalled_run, sig,
                                                               status, word):
    from PIL import Image

    inp, marks = tmp_path / "in", tmp_path / "marks"
    inp.mkdir()
    marks.mkdir()
    for i in range(6):
        Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(inp / f"a{i}.png")
    script = tmp_path / "slow_batch.py"
    script.write_text(SLOW_BATCH)
    out = tmp_path / "out"
    r = signalled_run([script, "batch", inp, "--out", out, "--workers", "2", "--no-progress"],
                      sig, lambda pid: len(list(marks.iterdir())) == 2,
                      env={"MARKS": str(marks)})
    assert r.returncode == status
    assert r.stderr == f"error: {word} (re-run the same command to resume)\n"
    workers = {int(p.name) for p in marks.iterdir()}
    assert workers <= set(r.children)
    assert r.left == []
    # nothing half-written stays behind: the stopped workers' staging folders are gone
    assert not [p for p in out.rglob("*") if ".partial-" in p.name]
    # the batch's records are written as on Ctrl-C (nothing was done: every image pending)
    assert set(pd.read_csv(out / "index.csv")["status"]) == {"pending"}
    assert json.loads((out / "batch.json").read_text())["complete"] is False


def _parser(func):
    p = argparse.ArgumentParser()
    p.set_defaults(func=func)
    return p


def test_sigterm_is_an_interrupt_while_a_command_runs_and_the_handler_is_put_back(capsys):
    before = signal.getsignal(signal.SIGTERM)
    seen = []

    def command(args):
        handler = signal.getsignal(signal.SIGTERM)
        seen.append(handler)
        handler(signal.SIGTERM, None)  # what the signal does

    assert run_parsed(_parser(command), []) == TERMINATED
    assert seen and seen[0] is not before
    assert signal.getsignal(signal.SIGTERM) is before
    assert capsys.readouterr().err == "error: terminated (re-run the same command to resume)\n"


def test_a_command_reporting_its_own_interrupt_exits_143_on_sigterm(capsys):
    def command(args):  # as stats does: its own line, status 130
        try:
            signal.getsignal(signal.SIGTERM)(signal.SIGTERM, None)
        except KeyboardInterrupt:
            return INTERRUPTED

    assert run_parsed(_parser(command), []) == TERMINATED
    assert run_parsed(_parser(lambda args: INTERRUPTED), []) == INTERRUPTED


def test_terminated_stops_what_an_interrupt_stops():
    assert issubclass(Terminated, KeyboardInterrupt)
    assert not issubclass(Terminated, Exception)  # per-task `except Exception` lets it through


def test_an_interrupt_while_the_modules_load_is_one_line(capsys):
    """Ctrl-C before the command runs (the subcommands' modules still importing, numba
    compiling at import) is one line and exit 130, as once it runs."""
    from crosssection.cli import started

    def build(argv):
        raise KeyboardInterrupt

    assert started(build, ["batch"]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: interrupted before the command started"]


@pytest.mark.parametrize("package", ["crosssection", "simulate"])
def test_an_interrupt_while_python_m_imports_is_one_line(package):
    """``python -m PACKAGE`` interrupted while it imports its CLI: the __main__ module turns
    the KeyboardInterrupt into the one line (the import is made to raise it here)."""
    import subprocess
    import sys
    from pathlib import Path

    code = ("import builtins, runpy\n"
            "_imp = builtins.__import__\n"
            "def _raise(name, *a, **k):\n"
            f"    if name == '{package}.cli':\n"
            "        raise KeyboardInterrupt\n"
            "    return _imp(name, *a, **k)\n"
            "builtins.__import__ = _raise\n"
            f"runpy.run_module('{package}', run_name='__main__')\n")
    repo = Path(__file__).resolve().parents[2]
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=repo, timeout=120)
    assert proc.returncode == 130
    assert proc.stderr.strip().splitlines() == ["error: interrupted before the command started"]


def _batch_with_python_sigint(inp, out) -> int:
    """``batch INP --out OUT --workers 1 --quiet`` under Python's own SIGINT handler, as a
    terminal's job has it (a suite started in the background of a non-interactive shell
    inherits SIG_IGN, which the command keeps); its exit status."""
    from crosssection.cli import main

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return main(["batch", str(inp), "--out", str(out), "--workers", "1", "--quiet"])
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("swallowed", [False, True])
@pytest.mark.parametrize("sig, status, word", [(signal.SIGINT, 130, "interrupted"),
                                               (signal.SIGTERM, 143, "terminated")])
def test_an_interrupt_the_analysis_catches_still_stops_the_batch(tmp_path, monkeypatch, capsys,
                                                                 sig, status, word, swallowed):
    """An interrupt that lands in a scan run inline and that the analysis catches (matplotlib
    raises another error in its place while it draws; one raised in a garbage collector's
    callback is swallowed) stops the batch all the same, and that scan is not recorded as
    failed: the re-run analyses it."""
    from PIL import Image

    from crosssection import batch

    inp, out = tmp_path / "in", tmp_path / "out"
    inp.mkdir()
    for i in range(3):
        Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(inp / f"a{i}.png")
    ran = []

    def caught(task):
        ran.append(task.rel)
        try:
            signal.raise_signal(sig)
        except KeyboardInterrupt:
            if swallowed:
                return batch._row(task, "ok")
            return batch._row(task, "failed", reason="unexpected ValueError: Invalid bounding "
                                                     "box (at backend_agg.py:196)")
        return batch._row(task, "ok")

    monkeypatch.setattr(batch, "process_image", caught)
    assert _batch_with_python_sigint(inp, out) == status
    assert capsys.readouterr().err == f"error: {word} (re-run the same command to resume)\n"
    assert ran == ["a0.png"]  # no scan started after the interrupt
    assert pd.read_csv(out / "failures.csv").empty
    index = pd.read_csv(out / "index.csv")
    done = index[index["status"] != "pending"]
    assert done["image"].tolist() == (["a0.png"] if swallowed else [])
    assert json.loads((out / "batch.json").read_text())["interrupted"] is True


def test_a_reader_gone_away_does_not_fail_the_command(tmp_path):
    """``analyze ... | head -0`` wrote its outputs and then exited 2 on a broken pipe
    ("error: output: Broken pipe"), and ``2>&1 | head -1`` exited 1 ("a bug"): the messages
    to a closed pipe are dropped and the command's status is its work's."""
    import subprocess
    import sys
    from pathlib import Path

    scan = Path(__file__).resolve().parents[2] / "sample_images" / "scan_01_sparse.png"
    out = tmp_path / "o"
    proc = subprocess.Popen([sys.executable, "-m", "crosssection", "analyze", str(scan),
                             "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)
    proc.stdout.close()  # the reader is gone before the command writes a line
    assert proc.wait(timeout=300) == 0
    assert (out / "summary.json").is_file()


def test_an_interrupted_forced_batch_says_what_a_re_run_does():
    # "re-run the same command to resume" redid every scan of a --force batch again
    import argparse

    from crosssection.cli import _resume_hint

    assert _resume_hint(argparse.Namespace(force=False)) == "re-run the same command to resume"
    assert "with --force it redoes every scan again" in _resume_hint(
        argparse.Namespace(force=True))
    assert _resume_hint(None) == "re-run the same command to resume"
    # one scan's run writes its files together at its end: nothing to resume
    for command in ("analyze", "steps"):
        assert _resume_hint(argparse.Namespace(command=command)) == (
            "no file was written; re-run the same command")


@pytest.mark.parametrize("sig, status, word", [(signal.SIGINT, 130, "interrupted"),
                                               (signal.SIGTERM, 143, "terminated")])
def test_a_stopped_batch_names_the_failures_and_doubts_of_the_scans_it_finished(
        tmp_path, monkeypatch, capsys, sig, status, word):
    """The lines a finished batch prints for its failed and flagged scans were lost when it
    was stopped: the re-run skips those scans, so they are printed before the error line."""
    from PIL import Image

    from crosssection import batch

    inp, out = tmp_path / "in", tmp_path / "out"
    inp.mkdir()
    for i in range(4):
        Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(inp / f"a{i}.png")

    def task(t):
        if t.rel == "a0.png":
            return batch._row(t, "failed", reason="not an image")
        if t.rel == "a1.png":
            return batch._row(t, "ok", summary={"quality": {"codes": ["no_calibration"]}})
        signal.raise_signal(sig)
        return batch._row(t, "ok")

    monkeypatch.setattr(batch, "process_image", task)
    assert _batch_with_python_sigint(inp, out) == status
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 3
    assert lines[0] == f"warning: {inp / 'a0.png'}: not analysed: not an image"
    assert lines[1].startswith(f"warning: {inp / 'a1.png'}: doubtful results (no_calibration;")
    assert lines[2] == f"error: {word} (re-run the same command to resume)"
