import argparse
import json

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ConfigError
from simulate import ensemble

BASE = ["--n-configs", "3", "--segments", "60", "--lambda", "2e4", "--noise", "300",
        "--no-progress"]
# a short Powell protocol (lbfgs takes none of these options)
ARGS = [*BASE, "--runs", "2", "--maxiter", "3", "--nematic-runs", "0"]


def _run(argv):
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="command", required=True)
    ensemble.add_subparser(sub)
    a = p.parse_args(argv)
    return a.func(a)


def _configs(path):
    return pd.read_csv(path / "configs.csv").drop(columns=["wall_s"])


@pytest.fixture(scope="module")
def first(tmp_path_factory):
    out = tmp_path_factory.mktemp("ens") / "a"
    assert _run(["quench", *ARGS, "--seed", "11", "--out", str(out)]) == 0
    return out


def test_outputs_and_schema(first):
    c = pd.read_csv(first / "configs.csv")
    for col in ensemble.CONFIG_COLUMNS:
        assert col in c.columns
    assert list(c.config_id) == [0, 1, 2]
    assert (c.method == "powell").all()
    assert np.allclose(c.energy_total, c.energy_bending + c.energy_confinement)
    assert np.allclose(c.epsilon, 1 / (2 * np.pi * c.rg))
    b = pd.read_csv(first / "branches.csv")
    v = pd.read_csv(first / "voids.csv")
    assert list(b.columns) == ensemble.BRANCH_COLUMNS
    assert list(v.columns) == ensemble.VOID_COLUMNS
    rods = np.load(first / "rods.npz")
    assert sorted(rods.files) == ["config_00000", "config_00001", "config_00002"]
    assert rods["config_00001"].shape == (61, 2)
    params = json.loads((first / "params.json").read_text())
    assert params["lam"] == 2e4 and params["seed"] == 11 and "version" in params
    assert params["libraries"]["numpy"] == np.__version__  # a chaotic run depends on them


def test_stacks_table_consistent_with_branches(first):
    c = pd.read_csv(first / "configs.csv").set_index("config_id")
    s = pd.read_csv(first / "stacks.csv")
    b = pd.read_csv(first / "branches.csv")
    assert list(s.columns) == ensemble.STACK_COLUMNS
    assert (s.n_br >= 1).all()
    per_config = s.groupby("config_id")
    # N_l and N_br = sum of n_br per configuration, as in configs.csv
    assert (per_config.size() == c.n_stacks.loc[per_config.size().index]).all()
    assert (per_config.n_br.sum() == c.n_branches.loc[per_config.size().index]).all()
    # every branch points at an existing stack of its configuration
    keys = set(zip(s.config_id, s.stack_id))
    assert all((ci, si) in keys for ci, si in zip(b.config_id, b.stack_id))


def test_determinism_and_workers(first, tmp_path):
    again = tmp_path / "b"
    assert _run(["quench", *ARGS, "--seed", "11", "--out", str(again)]) == 0
    pd.testing.assert_frame_equal(_configs(first), _configs(again))
    two = tmp_path / "c"
    assert _run(["quench", *ARGS, "--seed", "11", "--workers", "2", "--out", str(two)]) == 0
    pd.testing.assert_frame_equal(_configs(first), _configs(two))
    a, b = np.load(first / "rods.npz"), np.load(two / "rods.npz")
    assert all(np.array_equal(a[k], b[k]) for k in a.files)
    other = tmp_path / "d"
    assert _run(["quench", *ARGS, "--seed", "12", "--out", str(other)]) == 0
    assert not np.allclose(_configs(first).energy_total, _configs(other).energy_total)


def test_resume_after_deleting_parts(first, tmp_path):
    import shutil

    out = tmp_path / "r"
    shutil.copytree(first, out)
    (out / "configs.csv").unlink()
    (out / "parts" / "config_00001.npz").unlink()
    stamp = (out / "parts" / "config_00000.npz").stat().st_mtime_ns
    assert _run(["quench", *ARGS, "--seed", "11", "--out", str(out)]) == 0
    assert (out / "parts" / "config_00000.npz").stat().st_mtime_ns == stamp  # skipped
    pd.testing.assert_frame_equal(_configs(first), _configs(out))


def test_refuses_different_parameters(first, tmp_path):
    import shutil

    out = tmp_path / "x"
    shutil.copytree(first, out)
    with pytest.raises(ConfigError):
        _run(["quench", *ARGS, "--seed", "99", "--out", str(out)])


@pytest.mark.parametrize("command,argv", [("quench", [*BASE, "--method", "lbfgs"]),
                                          ("quench", [*ARGS, "--parametrization", "bend"]),
                                          ("anneal", [*ARGS, "--stages", "3",
                                                      "--lambda-start", "500"]),
                                          ("anneal", [*BASE, "--stages", "2",
                                                      "--lambda-start", "500",
                                                      "--method", "lbfgs"])])
def test_other_methods(command, argv, first, tmp_path):
    out = tmp_path / "m"
    assert _run([command, *argv, "--seed", "11", "--out", str(out)]) == 0
    c = pd.read_csv(out / "configs.csv")
    rods = np.load(out / "rods.npz")
    from simulate.intersect import has_intersection

    assert all(not has_intersection(rods[k], "brute") for k in rods.files)
    assert np.allclose(c.energy_total, c.energy_bending + c.energy_confinement)
    # same starts as the default powell ensemble, another minimiser: other energies
    assert not np.allclose(c.energy_total, _configs(first).energy_total)
    params = json.loads((out / "params.json").read_text())
    assert params["command"] == command
    # the record holds what the minimiser used: L-BFGS-B takes no Powell parameter
    powell = {k: params[k] for k in ("n_runs", "maxiter", "nematic_runs", "u", "ftol", "xtol")}
    if "lbfgs" in argv:
        assert set(powell.values()) == {None}
    else:
        assert powell == dict(n_runs=2, maxiter=3, nematic_runs=[0], u=100.0, ftol=1e-4,
                              xtol=1e-4)


def test_a_folder_of_lbfgs_resumes_whatever_it_recorded_of_powell(first, tmp_path):
    """L-BFGS-B's rods do not depend on the Powell protocol's parameters: a folder that
    recorded them (None or values) is the same ensemble."""
    out = tmp_path / "l"
    argv = ["quench", *BASE, "--method", "lbfgs", "--seed", "11", "--out", str(out)]
    assert _run(argv) == 0
    pfile = out / "params.json"
    params = json.loads(pfile.read_text())
    pfile.write_text(json.dumps({**params, "n_runs": 10, "maxiter": 30, "u": 100.0}))
    stamp = (out / "parts" / "config_00000.npz").stat().st_mtime_ns
    assert _run(argv) == 0
    assert (out / "parts" / "config_00000.npz").stat().st_mtime_ns == stamp  # resumed
    with pytest.raises(ConfigError, match="seed"):
        _run([*argv[:-4], "--seed", "12", "--out", str(out)])


def test_cli_quench_stderr_holds_no_progress_bar_when_not_a_terminal(tmp_path):
    """Run from a script (stderr not a terminal), quench prints no progress bar."""
    import subprocess
    import sys

    argv = [a for a in ARGS if a != "--no-progress"]
    argv[argv.index("--n-configs") + 1] = "1"
    r = subprocess.run([sys.executable, "-m", "simulate", "quench", *argv, "--out",
                        str(tmp_path / "q")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    # nothing but the one line on the short rod used for speed
    assert [line for line in r.stderr.splitlines()
            if "segments is below the 300" not in line] == []


def test_nematic_cutoff_reaches_the_minimiser(first, tmp_path):
    # one segment (1/60 L) is the default: the same rods; a wider touching distance lets the
    # nematic term act on other pairs: other rods, recorded in params.json
    same = tmp_path / "same"
    assert _run(["quench", *ARGS, "--seed", "11", "--nematic-cutoff", repr(1 / 60),
                 "--out", str(same)]) == 0
    a, b = np.load(first / "rods.npz"), np.load(same / "rods.npz")
    assert all(np.array_equal(a[k], b[k]) for k in a.files)
    wide = tmp_path / "wide"
    assert _run(["quench", *ARGS, "--seed", "11", "--nematic-cutoff", "0.1",
                 "--out", str(wide)]) == 0
    c = np.load(wide / "rods.npz")
    assert not all(np.array_equal(a[k], c[k]) for k in a.files)
    assert json.loads((wide / "params.json").read_text())["nematic_cutoff"] == 0.1
    # a folder of the default ensemble is not resumed with another cutoff
    with pytest.raises(ConfigError, match="nematic_cutoff"):
        _run(["quench", *ARGS, "--seed", "11", "--nematic-cutoff", "0.1", "--out", str(first)])


@pytest.mark.parametrize("extra", [["--nematic-cutoff", "0"], ["--nematic-cutoff", "nan"],
                                   ["--nematic-cutoff", "0.1", "--method", "lbfgs"]])
def test_nematic_cutoff_checked(tmp_path, extra):
    from crosssection.core.errors import ParameterError
    with pytest.raises(ParameterError, match="nematic-cutoff"):
        _run(["quench", *ARGS, "--seed", "11", *extra, "--out", str(tmp_path / "x")])


def test_a_part_of_other_parameters_is_not_kept(first, tmp_path):
    # a stopped Dask run's configuration finishing on a worker after its folder was emptied
    # for a run of other parameters wrote its part there, and that run took it as its own
    import shutil

    other = tmp_path / "lam"
    assert _run(["quench", *ARGS[:5], "3e4", *ARGS[6:], "--seed", "11",
                 "--out", str(other)]) == 0
    out = tmp_path / "o"
    (out / "parts").mkdir(parents=True)
    shutil.copy(other / "parts" / "config_00001.npz", out / "parts")
    assert _run(["quench", *ARGS, "--seed", "11", "--out", str(out)]) == 0
    pd.testing.assert_frame_equal(_configs(first), _configs(out))


def test_a_part_written_over_during_the_run_is_computed_again(first, tmp_path, monkeypatch):
    import shutil

    other = tmp_path / "lam"
    assert _run(["quench", *ARGS[:5], "3e4", *ARGS[6:], "--seed", "11",
                 "--out", str(other)]) == 0
    out = tmp_path / "w"
    task = ensemble.run_config

    def late_orphan(config_id, seed, params, where):
        done = task(config_id, seed, params, where)
        if config_id == 2 and not getattr(late_orphan, "done", False):
            late_orphan.done = True  # the orphan lands once, after this run wrote its part
            shutil.copy(other / "parts" / "config_00002.npz", out / "parts")
        return done

    monkeypatch.setattr(ensemble, "run_config", late_orphan)
    assert _run(["quench", *ARGS, "--seed", "11", "--out", str(out)]) == 0
    pd.testing.assert_frame_equal(_configs(first), _configs(out))


def test_every_warning_names_the_folder_as_given(tmp_path, capsys):
    # one run's lines name one folder: "out/" throughout, not "out" in some and "out/" in others
    from crosssection.console import main

    out = f"{tmp_path / 'q'}/"
    assert main(["quench", *ARGS, "--seed", "11", "--out", out]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert any("segments" in ln for ln in lines)  # N = 60: the coarse-segments warning
    assert lines and all(ln.startswith(f"warning: {out}: ") for ln in lines), lines
