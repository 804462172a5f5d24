"""Options of quench, anneal and compact as users give them: absurd values are one error line
naming the option, and what is accepted does what it says."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from simulate.energy import bending_energy, confinement_energy
from simulate.noise import initial_shape
from simulate.optimize import anneal, powell_protocol


def test_one_stage_anneal_is_a_quench_at_the_target_lambda():
    """A single stage is the last one, the target: numpy's one-point ramp is its start."""
    xy0 = initial_shape(40, 100.0, seed=3)
    kw = dict(seed=1, n_runs=2, maxiter=5, nematic_runs=())
    one = anneal(xy0, 2e4, lam_start=10.0, stages=1, **kw)
    # the stage minimised the energy at the target: it is the quench at the target
    ref = powell_protocol(xy0, 2e4, seed=np.random.SeedSequence(1).spawn(1)[0], n_runs=2,
                          maxiter=5, nematic_runs=(), parametrization="bend")
    assert one.energy_total == pytest.approx(ref.energy_total)
    assert one.energy_total == pytest.approx(bending_energy(one.xy)
                                             + confinement_energy(one.xy, 2e4))


@pytest.mark.parametrize("argv, named", [
    (["anneal", "--lambda-start", "1e9"], "--lambda-start"),
    (["quench", "--scheduler", "nowhere"], "--scheduler"),
    # below the analysis' range: every configuration's analysis would fail on it
    (["quench", "--contact-distance", "1e-9"], "--contact-distance"),
    (["anneal", "--contact-distance", "1"], "--contact-distance"),
    # the whole rod one stack (0.99 was taken silently)
    (["quench", "--contact-distance", "0.99"], "--contact-distance"),
    # passes touching across their gaps: one rod of 300 segments read as one stack at 0.1
    (["quench", "--contact-distance", "0.1"], "--contact-distance"),
    # the straight start is a stationary point, which a gradient method never leaves
    (["quench", "--noise", "0", "--method", "lbfgs"], "--noise 0 with --method lbfgs"),
    (["compact", "--epsilon", "1.5", "--thickness", "1e-6"], "--thickness"),
])
def test_absurd_simulation_options_are_one_line(tmp_path, argv, named):
    """Each named by the option at fault."""
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "simulate", *argv, "--n-configs", "1",
                        "--segments", "40", "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and named in r.stderr and "Traceback" not in r.stderr


def test_the_default_contact_distance_of_a_coarse_rod_is_taken(tmp_path):
    """Half a segment of 3 segments is beyond the largest contact distance one may give: the
    default is taken all the same, and no option that was not given is named."""
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "simulate", "quench", "--segments", "3",
                        "--noise", "2", "--n-configs", "1", "--no-progress", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and (out / "configs.csv").is_file()


def test_too_many_segments_for_the_default_contact_distance_names_segments(tmp_path):
    """It named --contact-distance, which was not given."""
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "simulate", "quench", "--segments", "50001",
                        "--n-configs", "1", "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert r.stderr.startswith("error: --segments 50001: the default contact distance")
    assert "use at most 50000 segments or give --contact-distance" in r.stderr


@pytest.mark.parametrize("command", ["quench", "compact"])
def test_an_empty_out_is_refused(tmp_path, command):
    extra = ["--epsilon", "4"] if command == "compact" else []
    r = subprocess.run([sys.executable, "-m", "simulate", command, "--n-configs", "1",
                        "--segments", "200", *extra, "--out", ""], capture_output=True,
                       text=True, cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.startswith("error: --out: empty path")
    assert list(tmp_path.iterdir()) == []


def test_a_smaller_rerun_records_the_configurations_its_tables_hold(tmp_path):
    import json

    import pandas as pd

    from simulate.ensemble import run_ensemble

    params = dict(command="quench", n_configs=3, n_segments=30, lam=2e4, noise=75.0, seed=2,
                  method="lbfgs", wall_radius=None, contact_distance=None)
    run_ensemble(params, tmp_path, progress=False)
    run_ensemble({**params, "n_configs": 2}, tmp_path, progress=False)
    assert json.loads((tmp_path / "params.json").read_text())["n_configs"] == 2
    assert len(pd.read_csv(tmp_path / "configs.csv")) == 2


@pytest.mark.parametrize("argv, says", [
    (["quench", "--runs", "1", "--out", "q"],
     "--runs 1: the default --nematic-runs '1,2' (the paper's, for 10 runs) does not fit it"),
    (["quench", "--runs", "2", "--out", "q"], "give --nematic-runs 0 or --nematic-runs ''"),
    (["quench", "--runs", "3", "--out", "q"], "the default --nematic-runs '1,2'"),
    (["quench", "--runs", "1", "--nematic-runs", "0", "--out", "q"],
     "--runs 1 has only the last"),
    (["compact", "--epsilon", "1.5", "--segments", "1000", "--out", "c"],
     "the thickness that epsilon 1.5 implies"),
])
def test_an_error_names_the_option_the_user_gave(tmp_path, argv, says):
    """A default that cannot hold with the value given is explained by that value."""
    r = subprocess.run([sys.executable, "-m", "simulate", *argv, "--n-configs", "1"],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2 and says in r.stderr and r.stderr.count("\n") == 1


@pytest.mark.parametrize("command, radius", [("quench", "1e-6"), ("quench", "0.0125"),
                                             ("anneal", "0.01")])
def test_a_wall_too_small_for_one_segment_is_refused(tmp_path, command, radius):
    """--segments 40: a segment is 1/40 long, so no disk of radius <= 1/80 holds the rod."""
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "simulate", command, "--n-configs", "1",
                        "--segments", "40", "--wall-radius", radius, "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr == (f"error: {out}: --wall-radius must be above half a segment 1/(2N) = "
                        f"0.0125 (a disk no wider than one segment cannot hold the rod), got "
                        f"{float(radius)!r}\n")
    assert not out.exists()


def test_a_wall_just_wider_than_a_segment_is_taken_as_given():
    from simulate.cli import build_parser
    from simulate.ensemble import params_from_args

    args = build_parser(["quench"]).parse_args(
        ["quench", "--segments", "40", "--wall-radius", "0.0126", "--out", "o"])
    assert params_from_args(args)["wall_radius"] == 0.0126


@pytest.mark.parametrize("command, extra, says", [
    ("quench", ["--u", "1e9"], "--u must be <= 1000 (the paper's range is 50-150)"),
    ("anneal", ["--u", "1001"], "--u must be <= 1000 (the paper's range is 50-150)"),
    ("quench", ["--u", "0"], "--u must be > 0 with the default --nematic-runs '1,2': give "
                             "--nematic-runs '' for no nematic term, got 0"),
    ("quench", ["--u", "0", "--nematic-runs", "0"], "--u must be > 0 with --nematic-runs '0'"),
])
def test_a_nematic_strength_outside_its_range_is_refused(tmp_path, command, extra, says):
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "simulate", command, "--n-configs", "1",
                        "--segments", "40", *extra, "--out", str(out)], capture_output=True,
                       text=True)
    assert r.returncode == 2 and r.stderr.startswith(f"error: {out}: {says}")
    assert r.stderr.count("\n") == 1 and not out.exists()


@pytest.mark.parametrize("extra, u, runs", [(["--u", "1000"], 1000.0, [1, 2]),
                                            (["--u", "50"], 50.0, [1, 2]),
                                            (["--u", "0", "--nematic-runs", ""], 0.0, [])])
def test_a_nematic_strength_in_its_range_is_taken_as_given(extra, u, runs):
    """Up to ten times the paper's u, the strongest measured; 0 with no nematic run is the
    protocol without the term."""
    from simulate.cli import build_parser
    from simulate.ensemble import params_from_args

    args = build_parser(["quench"]).parse_args(["quench", *extra, "--out", "o"])
    params = params_from_args(args)
    assert (params["u"], params["nematic_runs"]) == (u, runs)


def _quench_params(**kw):
    """The parameters :func:`simulate.ensemble.minimize_config` reads, for a short quench."""
    return {**dict(command="quench", method="powell", lam=20.0, n_runs=3, maxiter=4,
                   nematic_runs=[1], u=100.0, ftol=1e-4, xtol=1e-4, wall_radius=None,
                   parametrization=None, nematic_cutoff=None), **kw}


@pytest.mark.parametrize("method", ["powell", "scipy-powell"])
def test_a_quench_keeps_every_node_within_the_wall(method):
    """A weak confinement lets the rod unfold beyond a wall that barely holds the start: with
    --wall-radius every minimiser of quench keeps the rod inside it."""
    from simulate.ensemble import minimize_config
    from simulate.intersect import has_intersection

    xy0 = initial_shape(40, 750.0, seed=2)
    wall = 1.001 * np.max(np.hypot(*xy0.T))
    free = minimize_config(xy0, _quench_params(method=method), seed=2)
    held = minimize_config(xy0, _quench_params(method=method, wall_radius=wall), seed=2)
    assert np.max(np.hypot(*free.xy.T)) > wall
    assert np.max(np.hypot(*held.xy.T)) <= wall
    assert not has_intersection(held.xy, "brute")
    assert held.energy_total < bending_energy(xy0) + confinement_energy(xy0, 20.0)


def test_scipy_powell_takes_the_protocol_options_of_quench():
    """--u, --nematic-runs and --parametrization reach scipy's Powell as they reach powell's."""
    from simulate.ensemble import minimize_config

    xy0 = initial_shape(40, 750.0, seed=4)
    base = minimize_config(xy0, _quench_params(method="scipy-powell", lam=2e4), seed=1)
    for change in ({"u": 0.0}, {"nematic_runs": []}, {"parametrization": "bend"}):
        other = minimize_config(xy0, _quench_params(method="scipy-powell", lam=2e4, **change),
                                seed=1)
        assert not np.allclose(other.xy, base.xy), change


def test_scipy_powell_refuses_a_start_outside_the_wall():
    from crosssection.core.errors import ParameterError
    from simulate.optimize import scipy_protocol

    xy0 = initial_shape(20, 300.0, seed=1)
    with pytest.raises(ParameterError, match="leaves the hard-wall disk"):
        scipy_protocol(xy0, 1e3, n_runs=1, maxiter=1,
                       wall_radius=0.9 * np.max(np.hypot(*xy0.T)))


def test_anneal_refuses_scipy_powell_before_writing(tmp_path):
    """anneal ramps Lambda through powell or lbfgs only: scipy-powell is one line naming the
    command and the option, not a failure of every configuration."""
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "simulate", "anneal", "--method", "scipy-powell",
                        "--n-configs", "1", "--segments", "40", "--out", str(out)],
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert r.stderr.startswith("error: python -m simulate anneal: argument --method: "
                               "invalid choice: 'scipy-powell'")
    assert not out.exists()


def test_the_options_defaults_are_those_of_the_functions_they_reach():
    """One source: quench's, anneal's and compact's defaults are the minimisers', the initial
    shape's and the compaction's own."""
    import inspect

    from simulate.cli import build_parser
    from simulate.compact import CompactParams
    from simulate.ensemble import params_from_args

    def defaults(fn, *names):
        sig = inspect.signature(fn).parameters
        return tuple(sig[k].default for k in names)

    q = params_from_args(build_parser(["quench"]).parse_args(["quench", "--out", "o"]))
    assert (q["n_runs"], q["maxiter"], tuple(q["nematic_runs"]), q["u"], q["ftol"],
            q["xtol"]) == defaults(powell_protocol, "n_runs", "maxiter", "nematic_runs", "u",
                                   "ftol", "xtol")
    assert (q["n_segments"], q["noise"]) == defaults(initial_shape, "n_segments", "noise")
    a = params_from_args(build_parser(["anneal"]).parse_args(["anneal", "--out", "o"]))
    assert (a["lam_start"], a["stages"], a["ramp"]) == defaults(anneal, "lam_start", "stages",
                                                                "ramp")
    c = build_parser(["compact"]).parse_args(["compact", "--epsilon", "8", "--out", "o"])
    assert (c.segments, c.noise, c.max_iter, c.wall_rate) == (
        CompactParams.n_segments, CompactParams.noise, CompactParams.max_iter,
        CompactParams.rate)


@pytest.mark.parametrize("argv, named, where", [
    (["quench", "--method", "lbfgs", "--maxiter", "100"], "--maxiter",
     "it is an option of --method powell or scipy-powell"),
    # given at its default value, an option is still given: it would still do nothing
    (["quench", "--method", "lbfgs", "--runs", "10"], "--runs", None),
    (["quench", "--method", "lbfgs", "--nematic-runs", ""], "--nematic-runs", None),
    (["quench", "--method", "lbfgs", "--u", "50"], "--u", None),
    (["quench", "--method", "lbfgs", "--ftol", "1e-3"], "--ftol", None),
    (["quench", "--method", "lbfgs", "--xtol", "1e-3"], "--xtol", None),
    (["quench", "--method", "lbfgs", "--parametrization", "bend"], "--parametrization", None),
    (["quench", "--method", "lbfgs", "--maxiter", "5", "--u", "50"], "--maxiter, --u", None),
    (["quench", "--method", "scipy-powell", "--nematic-cutoff", "0.05"], "--nematic-cutoff",
     "it is an option of --method powell"),
    (["anneal", "--method", "lbfgs", "--runs", "3"], "--runs",
     "it is an option of --method powell"),
    (["anneal", "--method", "lbfgs", "--parametrization", "tangent"], "--parametrization",
     None),
    (["anneal", "--nematic-cutoff", "0.05"], "--nematic-cutoff",
     "it is an option of quench --method powell"),
])
def test_an_option_the_method_does_not_use_is_refused(tmp_path, capsys, argv, named, where):
    """Accepted, it would be recorded in params.json and change nothing."""
    from simulate.cli import main

    out = tmp_path / "out"
    method = argv[argv.index("--method") + 1] if "--method" in argv else "powell"
    status = main([*argv, "--n-configs", "1", "--segments", "40", "--no-progress",
                   "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    verb = "has" if "," not in named else "have"
    assert err.startswith(f"error: {out}: {named} {verb} no effect on {argv[0]} --method "
                          f"{method}: "), err
    assert where is None or err.endswith(f"{where}\n"), err
    assert not out.exists()


def test_the_help_shows_the_defaults_the_protocol_options_resolve_to():
    """The Powell options are None until resolved (so lbfgs can tell the given ones): their
    help still gives the values the protocol runs with."""
    from simulate.cli import build_parser
    from simulate.optimize import FTOL, MAXITER, N_RUNS, NEMATIC_U, XTOL

    sub = build_parser(["quench"])._subparsers._group_actions[0].choices["quench"]
    text = " ".join(sub.format_help().split())
    for default in (f"(default {N_RUNS};", f"(default {MAXITER};",
                    "(default 1,2, the paper's, which needs --runs 4 or more",
                    f"(default {NEMATIC_U:g};", f"(default {FTOL:g}, scipy's;",
                    f"(default {XTOL:g}, scipy's;"):
        assert default in text, default


def _start_radii(n_configs, n_segments, noise, seed):
    """Largest node distance from the origin of every configuration's start shape."""
    from crosssection.core.parallel import spawn_seeds
    from simulate.ensemble import start_shape

    return np.array([np.max(np.hypot(*start_shape(s, n_segments, noise).T))
                     for s in spawn_seeds(seed, n_configs)])


@pytest.mark.parametrize("method", ["powell", "lbfgs"])
def test_a_wall_that_holds_no_start_is_refused_before_any_configuration_runs(tmp_path, capsys,
                                                                             method):
    from simulate.cli import main

    radii = _start_radii(3, 40, 750.0, 5)
    wall = float(0.9 * radii.min())
    out = tmp_path / "out"
    status = main(["quench", "--method", method, "--n-configs", "3", "--segments", "40",
                   "--seed", "5", "--wall-radius", repr(wall), "--no-progress",
                   "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert err.startswith(f"error: {out}: --wall-radius {wall!r} holds none of the 3 start "
                          "shapes"), err
    # the radius it names holds one start, and is the smallest to 3 digits
    smallest = float(err.split("the smallest radius that holds one is ")[1].split(",")[0])
    assert radii.min() <= smallest <= radii.min() * 1.01
    assert not out.exists()


def test_a_wall_that_holds_some_starts_warns_and_runs_those(tmp_path, capsys):
    import pandas as pd

    from simulate.cli import main

    radii = _start_radii(4, 40, 750.0, 5)
    wall = float(np.sort(radii)[1:3].mean())  # two starts fit, two do not
    out = tmp_path / "out"
    status = main(["quench", "--n-configs", "4", "--segments", "40", "--seed", "5",
                   "--runs", "1", "--nematic-runs", "", "--maxiter", "1",
                   "--wall-radius", repr(wall), "--no-progress", "--out", str(out)])
    # (40 segments for speed: below the validated count, which one line says, and folded
    # back at single nodes, which another may say)
    lines = [line for line in capsys.readouterr().err.splitlines()
             if "segments is below the" not in line and "at a single node" not in line]
    assert status == 3
    said = [line for line in lines if "start shapes" in line]
    assert len(said) == 1 and said[0].startswith(
        f"warning: {out}: --wall-radius {wall!r}: 2 of the 4 start shapes leave the hard-wall "
        "disk, their configurations will fail (all fit within "), lines
    holds_all = float(said[0].rsplit(" ", 1)[1].rstrip(")"))
    assert radii.max() <= holds_all <= radii.max() * 1.01
    assert sum("failed: ParameterError" in line for line in lines) == 2 == len(lines) - 1
    failed = pd.read_csv(out / "failures.csv")
    assert sorted(failed.config_id) == sorted(np.flatnonzero(radii > wall))
    # the check drew the starts the configurations run from
    from simulate.ensemble import part_path

    for i in np.flatnonzero(radii <= wall):
        with np.load(part_path(out, i)) as z:
            assert np.max(np.hypot(*z["xy0"].T)) == radii[i]


def test_the_wall_check_draws_the_first_starts_of_a_large_ensemble():
    """Every start of the paper's ensemble is checked; of a larger one, the first ones."""
    from simulate.ensemble import wall_check

    paper = dict(n_configs=250, n_segments=300, noise=750.0, seed=1, wall_radius=0.45)
    msg = wall_check(paper)
    assert msg.startswith("--wall-radius 0.45: ") and " of the 250 start shapes " in msg
    big = wall_check({**paper, "n_configs": 10**6})
    assert f" of the first {100_000 // 301} start shapes (of 1000000) " in big
    assert wall_check({**paper, "wall_radius": 1.0}) is None
    assert wall_check({**paper, "wall_radius": None}) is None


def test_lbfgs_refuses_a_start_outside_the_wall():
    """Every trial would be rejected: the start would come back, outside the wall."""
    from crosssection.core.errors import ParameterError
    from simulate.optimize import lbfgs_quench

    xy0 = initial_shape(20, 300.0, seed=1)
    with pytest.raises(ParameterError, match="leaves the hard-wall disk"):
        lbfgs_quench(xy0, 1e3, wall_radius=0.9 * np.max(np.hypot(*xy0.T)))


@pytest.mark.parametrize("command, extra", [
    ("quench", ["--segments", "40"]),
    ("compact", ["--epsilon", "2", "--segments", "60"]),
])
def test_more_workers_than_cpus_are_capped_in_one_warning_line(tmp_path, command, extra):
    asked = 4 * (os.cpu_count() or 1)
    r = subprocess.run([sys.executable, "-m", "simulate", command, *extra, "--n-configs", "1",
                        "--workers", str(asked), "--no-progress", "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if f"--workers {asked}" in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: ")


def test_a_dict_typed_in_python_takes_the_command_lines_defaults_and_checks():
    """run_ensemble's parameters given in Python: missing keys are the command line's
    defaults, and what the command line refuses is one ParameterError naming it."""
    from crosssection.core.errors import ParameterError
    from simulate.cli import build_parser
    from simulate.ensemble import checked_params, params_from_args

    partial = checked_params({"command": "quench", "n_configs": 2, "n_segments": 40,
                              "seed": 1})
    full = params_from_args(build_parser().parse_args(
        ["quench", "--n-configs", "2", "--segments", "40", "--seed", "1", "--out", "."]))
    assert partial == full and partial["wall_radius"] is None and partial["n_runs"] >= 1
    # a dict the command line made goes through unchanged
    assert checked_params(full) == full
    with pytest.raises(ParameterError, match="no effect on quench --method lbfgs"):
        checked_params({"command": "quench", "method": "lbfgs", "n_runs": 2})
    for bad, named in [({"seed": -1}, "--seed"), ({"lam": -5.0}, "--lambda"),
                       ({"noise": float("nan")}, "--noise"), ({"method": "bogus"}, "method"),
                       ({"n_segments": 2}, "--segments"), ({"n_configs": 0}, "--n-configs"),
                       ({"seed": 1.5}, "seed"), ({"lamda": 1.0}, "lamda"),
                       ({"command": "compact"}, "command")]:
        with pytest.raises(ParameterError, match=named):
            checked_params({"command": "quench", **bad})


def test_run_ensemble_refuses_a_bad_dict_before_writing(tmp_path):
    from crosssection.core.errors import ParameterError
    from simulate.ensemble import run_ensemble

    with pytest.raises(ParameterError, match="--seed"):
        run_ensemble({"command": "quench", "n_configs": 1, "seed": -1}, tmp_path / "e",
                     progress=False)
    assert not (tmp_path / "e").exists()
