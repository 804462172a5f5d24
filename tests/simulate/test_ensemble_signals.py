"""An interrupted or terminated quench stops at once: its queued configurations are not run,
its workers are terminated, one ``error:`` line, exit status 130 (SIGINT) or 143 (SIGTERM),
and a re-run resumes from the parts written.

The signal goes to the command's process alone, as ``kill PID``, ``timeout -s INT`` and job
runners send it.
"""
from __future__ import annotations

import json
import signal

import pytest

from simulate.cli import main as simulate_main

#: the command line of the simulator, whose configurations after the first two each take a
#: minute (in the spawned workers too, which import this script as their main module)
SLOW_QUENCH = '''
import os
import sys
import time
from pathlib import Path

from simulate.ensemble import run_config


def slow(config_id, seed, params, out):
    if config_id < 2:
        return run_config(config_id, seed, params, out)
    Path(os.environ["MARKS"], str(os.getpid())).touch()  # this worker is at a slow one
    time.sleep(60)


if __name__ == "__main__":
    from simulate import ensemble
    from simulate.cli import main

    ensemble.run_config = slow
    sys.exit(main(sys.argv[1:]))
'''

QUENCH = ["quench", "--segments", "60", "--runs", "2", "--maxiter", "3", "--nematic-runs", "0",
          "--no-progress", "--seed", "4"]


@pytest.mark.parametrize("sig, status, word", [(signal.SIGINT, 130, "interrupted"),
                                               (signal.SIGTERM, 143, "terminated")])
def test_a_signalled_quench_stops_its_workers_and_exits_at_once(tmp_path, signalled_run, sig,
                                                                status, word):
    out, marks = tmp_path / "q", tmp_path / "marks"
    marks.mkdir()
    script = tmp_path / "slow_quench.py"
    script.write_text(SLOW_QUENCH)
    r = signalled_run([script, *QUENCH, "--n-configs", "8", "--workers", "2", "--out", out],
                      sig, lambda pid: len(list(marks.iterdir())) == 2,
                      env={"MARKS": str(marks)})
    assert r.returncode == status
    # the last line says why it stopped; before it only the run's doubts, as warnings (the
    # rods are shorter than the validated ones)
    *doubts, last = r.stderr.splitlines()
    assert last == f"error: {word} (re-run the same command to resume)"
    assert all(line.startswith("warning: ") and "segments is below" in line for line in doubts)
    assert {int(p.name) for p in marks.iterdir()} <= set(r.children)
    assert r.left == []
    assert json.loads((out / "params.json").read_text())["n_configs"] == 8
    # both workers were at their slow configurations: the first two are written, and a
    # re-run of the same ensemble's first two takes them as they are
    parts = {p.name: p.read_bytes() for p in (out / "parts").glob("config_*.npz")}
    assert sorted(parts) == ["config_00000.npz", "config_00001.npz"]
    assert simulate_main([*QUENCH, "--n-configs", "2", "--out", str(out)]) == 0
    assert all((out / "parts" / name).read_bytes() == data for name, data in parts.items())
    assert len((out / "configs.csv").read_text().splitlines()) == 3
