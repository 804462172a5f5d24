"""What quench, anneal and compact record and report: the defaults written out in
params.json (and an older record holding None resumed), the bound on --lambda, the summary
line of a run in which no configuration succeeded."""
import argparse
import json
import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ConfigError, ParameterError
from simulate import ensemble
from simulate.cli import main as simulate_main
from simulate.contacts import default_contact_distance
from simulate.energy import LAMBDA_MAX
from simulate.optimize import default_contact_cutoff

N = 40
BASE = ["--n-configs", "1", "--segments", str(N), "--lambda", "2e4", "--noise", "300",
        "--seed", "4", "--no-progress"]
POWELL = [*BASE, "--runs", "2", "--maxiter", "2", "--nematic-runs", "0"]


def _parse(argv):
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="command", required=True)
    ensemble.add_subparser(sub)
    return p.parse_args(argv)


def _run(argv):
    a = _parse(argv)
    return a.func(a)


def _params(folder):
    return json.loads((folder / "params.json").read_text())


@pytest.mark.parametrize("command,argv,parametrization,cutoff", [
    ("quench", POWELL, "tangent", default_contact_cutoff(N)),
    ("quench", [*POWELL, "--method", "scipy-powell"], "tangent", None),
    ("quench", [*BASE, "--method", "lbfgs"], None, None),
    ("anneal", [*POWELL, "--stages", "2", "--lambda-start", "500"], "bend", None),
])
def test_params_json_records_the_defaults_the_run_used(command, argv, parametrization, cutoff,
                                                       tmp_path):
    out = tmp_path / "e"
    assert _run([command, *argv, "--out", str(out)]) == 0
    params = _params(out)
    assert params["contact_distance"] == default_contact_distance(N) == 0.5 / N
    # only the methods that use them hold the Powell search coordinates and the nematic cut-off
    assert params["parametrization"] == parametrization
    assert params["nematic_cutoff"] == cutoff


def test_an_explicit_default_gives_the_same_record():
    implicit = ensemble.params_from_args(_parse(["quench", *POWELL, "--out", "x"]))
    explicit = ensemble.params_from_args(_parse(
        ["quench", *POWELL, "--parametrization", "tangent", "--contact-distance", repr(0.5 / N),
         "--nematic-cutoff", repr(1 / N), "--out", "x"]))
    assert implicit == explicit


def test_resolve_defaults_leaves_given_values_and_other_commands_alone():
    given = dict(command="quench", method="powell", n_segments=N, contact_distance=0.01,
                 parametrization="bend", nematic_cutoff=0.2)
    assert ensemble.resolve_defaults(given) == given
    compact = dict(command="compact", n_segments=N, contact_distance=None)
    assert ensemble.resolve_defaults(compact) == compact
    anneal = ensemble.resolve_defaults(dict(command="anneal", method="powell", n_segments=N))
    assert anneal["parametrization"] == "bend" and "nematic_cutoff" not in anneal


@pytest.mark.parametrize("command,argv", [
    ("quench", POWELL), ("anneal", [*POWELL, "--stages", "2", "--lambda-start", "500"])])
def test_a_folder_that_recorded_none_for_the_defaults_resumes(command, argv, tmp_path):
    """A params.json holding None for the defaults is the ensemble of the values they stood
    for: a re-run resumes it (nothing recomputed) and writes the values out."""
    out = tmp_path / "old"
    assert _run([command, *argv, "--out", str(out)]) == 0
    pfile = out / "params.json"
    resolved = _params(out)
    old = {**resolved, "contact_distance": None, "parametrization": None}
    if command == "quench":
        old["nematic_cutoff"] = None
    pfile.write_text(json.dumps(old))
    part = out / "parts" / "config_00000.npz"
    stamp = part.stat().st_mtime_ns
    assert _run([command, *argv, "--out", str(out)]) == 0
    assert part.stat().st_mtime_ns == stamp  # resumed, not recomputed
    assert _params(out) == resolved
    # None stands for the default, not for anything: another value is another ensemble
    pfile.write_text(json.dumps(old))
    other = "tangent" if command == "anneal" else "bend"
    with pytest.raises(ConfigError, match="parametrization"):
        _run([command, *argv, "--parametrization", other, "--out", str(out)])
    with pytest.raises(ConfigError, match="contact_distance"):
        _run([command, *argv, "--contact-distance", "0.001", "--out", str(out)])


@pytest.mark.parametrize("lam", ["1e30", repr(LAMBDA_MAX * 1.01), "inf"])
def test_lambda_above_the_bound_is_refused_in_one_line(lam, tmp_path):
    out = tmp_path / "never"
    r = subprocess.run([sys.executable, "-m", "simulate", "quench", "--lambda", lam,
                        "--out", str(out)], capture_output=True, text=True)
    assert r.returncode == 2
    err = r.stderr.strip().splitlines()
    assert len(err) == 1 and "--lambda" in err[0] and str(out) in err[0]
    assert r.stdout == "" and not out.exists()


def test_no_confinement_and_a_noise_beyond_the_segments_name_their_options():
    # Lambda 0 relaxed the rod straight (epsilon 0.35, one stack) without a word; at
    # --segments 3 the default noise was refused as if the user had given it
    with pytest.raises(ParameterError, match=r"--lambda must be a finite number > 0"):
        ensemble.params_from_args(_parse(["quench", "--lambda", "0", "--out", "x"]))
    with pytest.raises(ParameterError, match=r"--noise must be <= 50 N = 150 at --segments 3 "
                                             r"\(its default, 750.*lower --noise or raise "
                                             r"--segments, got 750"):
        ensemble.params_from_args(_parse(["quench", "--segments", "3", "--out", "x"]))


def test_lambda_bound_is_inclusive_and_documented():
    for command in ("quench", "anneal"):
        params = ensemble.params_from_args(_parse([command, "--lambda", repr(LAMBDA_MAX),
                                                   "--out", "x"]))
        assert params["lam"] == LAMBDA_MAX
    with pytest.raises(ParameterError, match=re.escape(f"<= {LAMBDA_MAX:g}") + ".*got 1e\\+11"):
        ensemble.params_from_args(_parse(["anneal", "--lambda", "1e11", "--out", "x"]))
    help_text = subprocess.run([sys.executable, "-m", "simulate", "quench", "--help"],
                               capture_output=True, text=True).stdout
    assert f"at most {LAMBDA_MAX:g}" in " ".join(help_text.split())


def _tables(n, failed_ids):
    configs = pd.DataFrame({"config_id": range(n), "energy_total": np.arange(n, dtype=float),
                            "energy_bending": 1.0, "energy_confinement": 0.0, "rg": 0.1})
    configs.loc[list(failed_ids), ["energy_total", "rg"]] = np.nan
    failed = pd.DataFrame({"config_id": list(failed_ids), "seed": 0, "error": "E: x"})
    return {"configs": configs, "failed": failed}


def test_summary_head_counts_the_failed_and_says_when_none_succeeded():
    head, done = ensemble.summary_head(_tables(3, []), "o")
    assert head == "3 configurations -> o" and len(done) == 3
    head, done = ensemble.summary_head(_tables(3, [1]), "o")
    assert head == "3 configurations -> o (1 failed)"
    assert done.config_id.tolist() == [0, 2] and done.energy_total.mean() == 1.0
    head, done = ensemble.summary_head(_tables(2, [0, 1]), "o")
    assert done.empty and "none succeeded" in head and "nan" not in head


def test_summary_head_names_parts_an_earlier_larger_run_left(tmp_path):
    (tmp_path / "parts").mkdir()
    for i in (0, 1, 2, 3):
        (tmp_path / "parts" / f"config_{i:05d}.npz").write_bytes(b"")
    (tmp_path / "parts" / "config_x.npz").write_bytes(b"")
    head, _ = ensemble.summary_head(_tables(2, []), tmp_path)
    assert head.endswith("(2 more configurations of an earlier run kept in parts/, not in "
                         "the tables)")
    head, _ = ensemble.summary_head(_tables(4, []), tmp_path)
    assert head == f"4 configurations -> {tmp_path}"


def test_quench_in_which_every_configuration_failed_says_so(tmp_path, monkeypatch, capsys):
    def failing(*a, **k):
        raise FloatingPointError("diverged")

    monkeypatch.setattr(ensemble, "run_config", failing)
    out = tmp_path / "q"
    assert _run(["quench", *POWELL, "--n-configs", "2", "--out", str(out)]) == 3
    cap = capsys.readouterr()
    assert cap.out.strip() == (f"2 configurations -> {out}: none succeeded, no results "
                               f"(errors in {out / 'failures.csv'})")
    assert "nan" not in cap.out
    assert len(cap.err.strip().splitlines()) == 2  # one warning line per configuration


def test_compact_in_which_every_configuration_failed_says_so(tmp_path, capsys):
    """--max-iter 1 stops the wall long before its radius: every configuration fails, the
    summary says so (no averages of nothing) and the exit status is quench's, 3."""
    out = tmp_path / "c"
    argv = ["compact", "--epsilon", "1.2", "--segments", "32", "--n-configs", "2", "--max-iter",
            "1", "--no-progress", "--out", str(out)]
    assert simulate_main(argv) == 3
    cap = capsys.readouterr()
    assert "none succeeded" in cap.out and "nan" not in cap.out
    err = cap.err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith(f"warning: {out}: configuration ") for e in err)


def test_a_default_quench_is_not_too_coarse_for_its_stacks():
    # the paper's N = 300: no branch shorter than a segment, no warning
    import pandas as pd

    from simulate.ensemble import coarse_rod_doubt

    short = pd.DataFrame({"length": [0.5 / 300] * 3 + [0.02] * 7})
    assert coarse_rod_doubt({"branches": short}, 300) is not None  # 30 % > 25 %
    long = pd.DataFrame({"length": [0.5 / 300] * 2 + [0.02] * 8})
    assert coarse_rod_doubt({"branches": long}, 300) is None


def test_a_fold_within_one_node_is_counted_and_warned_of(tmp_path, capsys):
    """A node turning back by nearly 180 degrees is counted in configs.csv and named."""
    from simulate.ensemble import HAIRPIN_NODE_DEG, hairpin_doubt
    from simulate.geometry import positions, sharp_nodes

    theta = np.zeros(20)
    theta[10:] = np.pi - 1e-3  # back along itself at node 10
    hairpin = positions(theta)
    assert sharp_nodes(hairpin, HAIRPIN_NODE_DEG) == 1
    bend = positions(np.linspace(0.0, 2.0, 20))  # a smooth arc of 2 rad
    assert sharp_nodes(bend, HAIRPIN_NODE_DEG) == 0
    assert hairpin_doubt(pd.DataFrame({"n_hairpin_nodes": [0, 0]})) is None
    assert hairpin_doubt(pd.DataFrame({"config_id": [0]})) is None  # an older folder
    doubt = hairpin_doubt(pd.DataFrame({"n_hairpin_nodes": [0, 2, 1]}))
    assert doubt.startswith("2 of 3 configurations") and "3 node(s)" in doubt

    out = tmp_path / "q"
    assert simulate_main(["quench", *POWELL, "--out", str(out)]) == 0
    c = pd.read_csv(out / "configs.csv")
    with np.load(out / "rods.npz") as z:
        assert c.n_hairpin_nodes[0] == sharp_nodes(z["config_00000"], HAIRPIN_NODE_DEG)
    said = "fold back at a single node" in capsys.readouterr().err
    assert said == bool(c.n_hairpin_nodes[0])


def _computed_by(out, run):
    """Make the folder's ensemble look computed by ``run`` ({"version", "libraries"}): its
    record and every part file (``run`` None: parts without ``computed_by``)."""
    if run is not None:
        (out / "params.json").write_text(json.dumps({**_params(out), **run}, indent=2))
    for part in sorted((out / "parts").iterdir()):
        with np.load(part) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays["meta"]))
        meta.pop("computed_by")
        if run is not None:
            meta["computed_by"] = run
        arrays["meta"] = np.array(json.dumps(meta))
        with open(part, "wb") as fh:
            np.savez(fh, **arrays)


OLD_RUN = {"version": "0.0.1", "libraries": {"numpy": "1.0.0"}}


def test_a_resume_keeps_the_versions_that_computed_the_rods(tmp_path, capsys):
    """A re-run computing nothing leaves params.json as it is (its version is that of the
    rods); one adding configurations under another version lists both and says so."""
    from crosssection._version import __version__

    out = tmp_path / "q"
    argv = ["quench", *POWELL, "--out", str(out)]
    assert simulate_main(argv) == 0
    assert ensemble._read_part(ensemble.part_path(out, 0))[0]["computed_by"] == \
        ensemble.computing_versions()
    _computed_by(out, OLD_RUN)
    before = {f: (out / f).read_bytes() for f in ("params.json", "configs.csv", "rods.npz")}
    capsys.readouterr()
    assert simulate_main(argv) == 0
    assert {f: (out / f).read_bytes() for f in before} == before
    assert "mixes versions" not in capsys.readouterr().err
    # a configuration more, computed by this version
    more = [a if a != "1" else "2" for a in argv]
    assert more[more.index("--n-configs") + 1] == "2"
    assert simulate_main(more) == 0
    err = capsys.readouterr().err.splitlines()
    said = [line for line in err if "mixes versions" in line]
    assert len(said) == 1 and said[0].startswith(
        f"warning: {out}: the ensemble mixes versions: its configurations were computed by "
        f"foldstat 0.0.1 (numpy 1.0.0); foldstat {__version__} (")
    rec = _params(out)
    assert (rec["version"], rec["libraries"]) == ("0.0.1", {"numpy": "1.0.0"})
    assert rec["versions"] == [{"version": "0.0.1", "libraries": {"numpy": "1.0.0"}},
                               {"version": __version__,
                                "libraries": ensemble.library_versions()}]
    # the API says it with its own category
    with pytest.warns(ensemble.MixedVersionsWarning, match="mixes versions"):
        ensemble.run_ensemble({**ensemble.params_from_args(_parse(more)), "n_configs": 3},
                              out, progress=False)
    assert len(_params(out)["versions"]) == 2  # this version's runs are listed once


def test_a_run_stopped_before_its_first_configuration_leaves_the_versions(tmp_path, capsys,
                                                                             monkeypatch):
    """The versions listed are those of the part files on disk: a run under another version
    stopped before it finished a configuration leaves no trace of its version."""
    out = tmp_path / "q"
    argv = ["quench", *POWELL, "--out", str(out)]
    assert simulate_main(argv) == 0
    _computed_by(out, OLD_RUN)
    more = [a if a != "1" else "2" for a in argv]

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(ensemble, "run_config", stopped)
    with pytest.raises(KeyboardInterrupt), pytest.warns(ensemble.MixedVersionsWarning):
        ensemble.run_ensemble(ensemble.params_from_args(_parse(more)), out, progress=False)
    rec = _params(out)
    assert (rec["version"], rec["libraries"]) == (OLD_RUN["version"], OLD_RUN["libraries"])
    assert "versions" not in rec
    # parts without computed_by count as the record's
    _computed_by(out, None)
    monkeypatch.undo()
    capsys.readouterr()
    with pytest.warns(ensemble.MixedVersionsWarning):
        ensemble.run_ensemble(ensemble.params_from_args(_parse(more)), out, progress=False)
    assert _params(out)["versions"] == [OLD_RUN, ensemble.computing_versions()]


def test_parts_that_do_not_say_keep_the_versions_the_record_lists(tmp_path, capsys):
    # a folder listing two versions whose parts do not say which computed them: a re-run
    # that computes nothing leaves the record as it is
    out = tmp_path / "q"
    argv = ["quench", *POWELL, "--out", str(out)]
    assert simulate_main(argv) == 0
    other = {"version": "0.0.2", "libraries": {"numpy": "1.0.1"}}
    _computed_by(out, None)
    (out / "params.json").write_text(json.dumps(
        {**_params(out), **OLD_RUN, "versions": [OLD_RUN, other]}, indent=2))
    before = (out / "params.json").read_bytes()
    assert simulate_main(argv) == 0
    assert (out / "params.json").read_bytes() == before
    assert "mixes versions" not in capsys.readouterr().err


def test_a_run_computing_every_configuration_records_its_own_version(tmp_path):
    # a folder whose earlier run was stopped before any configuration finished
    from crosssection._version import __version__

    out = tmp_path / "q"
    assert simulate_main(["quench", *POWELL, "--out", str(out)]) == 0
    (out / "params.json").write_text(json.dumps({**_params(out), "version": "0.0.1"}))
    for part in (out / "parts").iterdir():
        part.unlink()
    assert simulate_main(["quench", *POWELL, "--out", str(out)]) == 0
    rec = _params(out)
    assert rec["version"] == __version__ and "versions" not in rec


def test_a_quench_coarser_than_the_validated_segments_is_a_warning(tmp_path, capsys):
    from simulate.noise import VALIDATED_QUENCH_SEGMENTS
    from simulate.render import VALIDATED_QUENCH_SEGMENTS as RENDERED

    assert VALIDATED_QUENCH_SEGMENTS == RENDERED == 300  # one documented limit
    out = tmp_path / "q"
    assert simulate_main(["quench", *POWELL, "--out", str(out)]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "segments" in line]
    assert said == [f"warning: {out}: N = {N} segments is below the 300 the simulator's "
                    "ensemble statistics are validated from (docs/validation/simulator/"
                    "README.md: N = 100 and 200 disagree with the reference): its energies, "
                    "Rg and branch statistics are the discretisation's"]
    params = ensemble.params_from_args(_parse(["quench", *POWELL, "--out", str(out)]))
    with pytest.warns(ensemble.CoarseSegmentsWarning, match=f"N = {N} segments"):
        ensemble.run_ensemble(params, out, progress=False)
    assert ensemble.coarse_segments_doubt({**params, "n_segments": 300}) is None
    # a compaction's segments are judged by its own checks
    assert ensemble.coarse_segments_doubt({"command": "compact", "n_segments": 64}) is None
