"""Upper bounds of the quench and anneal options: a value beyond them is one error line naming
the option, before anything runs, and the bounds leave the protocol's working range open."""
from __future__ import annotations

import subprocess
import sys

import pytest

from crosssection.core.errors import ParameterError
from simulate.ensemble import checked_params
from simulate.noise import NOISE_PER_SEGMENT_MAX, initial_shape
from simulate.optimize import FTOL_MAX, MAXITER_MAX, N_RUNS_MAX, STAGES_MAX, XTOL_MAX


@pytest.mark.parametrize("argv, named, bound", [
    (["quench", "--ftol", "1e30"], "--ftol", f"<= {FTOL_MAX:g}"),
    (["quench", "--xtol", "1e30"], "--xtol", f"<= {XTOL_MAX:g}"),
    (["anneal", "--ftol", "1"], "--ftol", f"<= {FTOL_MAX:g}"),
    (["anneal", "--xtol", "0.01"], "--xtol", f"<= {XTOL_MAX:g}"),
    (["quench", "--nematic-cutoff", "1e30"], "--nematic-cutoff", "below the rod length 1"),
    (["quench", "--nematic-cutoff", "1"], "--nematic-cutoff", "below the rod length 1"),
    (["quench", "--noise", "1e30"], "--noise", f"<= {NOISE_PER_SEGMENT_MAX:g} N = 2000"),
    (["anneal", "--noise", "2001"], "--noise", f"<= {NOISE_PER_SEGMENT_MAX:g} N = 2000"),
    (["quench", "--runs", "1000000000"], "--runs", f"<= {N_RUNS_MAX}"),
    (["anneal", "--runs", str(N_RUNS_MAX + 1)], "--runs", f"<= {N_RUNS_MAX}"),
    (["anneal", "--stages", "100000000"], "--stages", f"from 1 to {STAGES_MAX}"),
    (["quench", "--maxiter", "1000000000"], "--maxiter", f"<= {MAXITER_MAX}"),
])
def test_options_beyond_their_bound_are_one_line(tmp_path, argv, named, bound):
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "simulate", *argv, "--n-configs", "1",
                        "--segments", "40", "--out", str(out)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert f"{named} must be {bound}" in r.stderr, r.stderr
    assert not out.exists()


@pytest.mark.parametrize("key, value", [("ftol", 1e30), ("xtol", 1e30), ("n_runs", 10 ** 9),
                                        ("nematic_cutoff", 1e30), ("noise", 1e30)])
def test_a_python_dict_is_bounded_as_the_command_line(key, value):
    with pytest.raises(ParameterError, match="must be"):
        checked_params({"command": "quench", "n_segments": 40, key: value})


def test_the_bounds_leave_the_working_range_open():
    p = checked_params({"command": "anneal", "n_segments": 40, "ftol": FTOL_MAX,
                        "xtol": XTOL_MAX, "n_runs": N_RUNS_MAX, "stages": STAGES_MAX,
                        "maxiter": MAXITER_MAX,
                        "noise": NOISE_PER_SEGMENT_MAX * 40})
    assert p["ftol"] == FTOL_MAX and p["stages"] == STAGES_MAX
    # at the largest noise a start shape is still drawn within initial_shape's redraws
    assert initial_shape(40, NOISE_PER_SEGMENT_MAX * 40, seed=0).shape == (41, 2)
