"""Fault tests: a batch whose parent is killed with SIGKILL mid-run.

Its workers must stop within seconds (they die with their parent), and the re-run must resume
and end with the same results as an uninterrupted batch.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pandas as pd
import psutil
import pytest
from PIL import Image

N_IMAGES = 8


def _batch(inp, out, workers=2):
    return [sys.executable, "-m", "crosssection", "batch", str(inp), "--out", str(out),
            "--workers", str(workers), "--quiet", "--no-figure", "--seed", "5",
            "--px-per-mm", "20", "--thickness-mm", "0.1"]


def _results(out):
    """Per-image numbers of a finished batch, sorted, without timings."""
    idx = pd.read_csv(out / "index.csv")
    keep = [c for c in idx.columns if c not in ("wall_s", "peak_rss_mb", "status", "reason")]
    return idx[keep].sort_values("image").reset_index(drop=True)


def _running(p) -> bool:
    # an exited worker stays a zombie until whoever adopted it reaps it: that is gone
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _wait_gone(procs, timeout):
    """The processes of ``procs`` still running after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        alive = [p for p in procs if _running(p)]
        if not alive:
            return []
        time.sleep(0.1)
    return [p for p in procs if _running(p)]


@pytest.mark.slow
def test_kill_9_of_batch_parent_stops_workers_and_resume_is_exact(tmp_path, fuzz_tools):
    inp = tmp_path / "scans"
    inp.mkdir()
    for i in range(N_IMAGES):
        Image.fromarray(fuzz_tools.small_scan(100 + i, size=200)).save(inp / f"s{i}.png")
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    ref = tmp_path / "ref"
    run = subprocess.run(_batch(inp, ref), capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, run.stderr

    out = tmp_path / "killed"
    parent = subprocess.Popen(_batch(inp, out), stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, env=env)
    proc = psutil.Process(parent.pid)
    deadline = time.monotonic() + 120
    workers = []
    # kill once the workers run: the pool's processes (spawn: the resource tracker is not
    # a worker, it exits on its own once its pipe closes)
    while time.monotonic() < deadline and parent.poll() is None:
        workers = [c for c in proc.children(recursive=True)
                   if "resource_tracker" not in " ".join(c.cmdline())]
        if len(workers) >= 2:
            break
        time.sleep(0.05)
    assert parent.poll() is None, "the batch finished before it could be killed"
    time.sleep(0.5)  # let the workers pick up tasks
    parent.send_signal(signal.SIGKILL)
    parent.wait(timeout=10)
    alive = _wait_gone(workers, timeout=10)
    for p in alive:  # clean up before failing
        p.kill()
    assert not alive, f"{len(alive)} worker(s) still running 10 s after the parent's kill -9"

    rerun = subprocess.run(_batch(inp, out), capture_output=True, text=True, timeout=300,
                           env=env)
    assert rerun.returncode == 0, rerun.stderr
    pd.testing.assert_frame_equal(_results(out), _results(ref))
    for i in range(N_IMAGES):
        rows = list(out.rglob(f"s{i}/summary.json"))
        assert len(rows) == 1, f"s{i}: {rows}"
    assert not list(out.rglob(".*partial*")), "a staging folder was left behind"
