"""The output folder of quench, anneal and compact: nothing is written by a refused run, and a
folder holding anything but the same command's ensemble is refused (one line, exit status 2)
and left as it was; the command's own folder is resumed."""
from __future__ import annotations

import numpy as np
import pytest

from crosssection.core.errors import ParameterError
from simulate import ensemble
from simulate.cli import main as simulate_main

QUENCH = ["quench", "--n-configs", "2", "--segments", "40", "--runs", "2", "--maxiter", "3",
          "--nematic-runs", "0", "--no-progress"]
ANNEAL = ["anneal", "--n-configs", "1", "--segments", "40", "--method", "lbfgs", "--stages",
          "1", "--no-progress"]
COMPACT = ["compact", "--epsilon", "2", "--segments", "64", "--n-configs", "1", "--no-progress"]


def _listing(folder):
    return sorted((str(p.relative_to(folder)), p.stat().st_size) for p in folder.rglob("*"))


@pytest.mark.parametrize("argv", [QUENCH, COMPACT], ids=["quench", "compact"])
@pytest.mark.parametrize("exists", [False, True])
def test_an_unreachable_scheduler_leaves_nothing_behind(tmp_path, capsys, monkeypatch, argv,
                                                        exists):
    pytest.importorskip("distributed")
    from crosssection.core import parallel

    out = tmp_path / "out"
    if exists:
        out.mkdir()
    # nothing listens on port 1; a second is long enough to find that out
    monkeypatch.setattr(parallel, "SCHEDULER_TIMEOUT_S", 1)
    status = simulate_main([*argv, "--scheduler", "tcp://127.0.0.1:1", "--out", str(out)])
    assert status == 2
    err = capsys.readouterr().err
    # the cause is the refusal, or Dask's own time limit on a loaded machine
    assert err.startswith("error: --scheduler tcp://127.0.0.1:1: no Dask scheduler answered "
                          "within 1 s (")
    assert len(err.splitlines()) == 1
    assert (list(out.iterdir()) == []) if exists else not out.exists()


def _batch_output(folder):
    """What a finished ``crosssection batch`` leaves."""
    (folder / "samples" / "scan_01").mkdir(parents=True)
    (folder / "samples" / "scan_01" / "stacks.csv").write_text("stack_id\n0\n")
    (folder / "index.csv").write_text("image,status\nscan_01.png,ok\n")
    (folder / "failures.csv").write_text("image,reason\n")
    (folder / "batch.json").write_text("{}\n")
    return "batch.json"


def _scans(folder):
    from crosssection.testing import drawn_scan, write_png

    write_png(folder / "scan.png", drawn_scan(1, 40))
    return "scan.png"


def _stray_part(folder):
    (folder / "parts").mkdir()
    (folder / "parts" / "notes.txt").write_text("mine\n")
    return "parts/notes.txt"


@pytest.mark.parametrize("argv", [QUENCH, ANNEAL, COMPACT], ids=["quench", "anneal", "compact"])
@pytest.mark.parametrize("fill", [_batch_output, _scans, _stray_part])
def test_a_folder_of_another_kind_is_refused_and_left_as_it_was(tmp_path, capsys, argv, fill):
    out = tmp_path / "B"
    out.mkdir()
    entry = fill(out)
    before = _listing(out)
    assert simulate_main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith(f"error: {out}: holds {entry}, which is no part of a {argv[0]} ")
    assert _listing(out) == before


def test_the_library_refuses_it_too(tmp_path):
    (tmp_path / "index.csv").write_text("image\n")
    params = {"command": "quench", "n_configs": 1, "seed": 0}
    with pytest.raises(ParameterError, match="holds index.csv"):
        ensemble.run_ensemble(params, tmp_path, progress=False)


def test_a_file_in_the_way_is_refused_before_anything_runs(tmp_path, capsys):
    out = tmp_path / "B"
    out.write_text("a file\n")
    assert simulate_main([*QUENCH, "--out", str(out)]) == 2
    assert capsys.readouterr().err.startswith(f"error: {out}: File exists")
    assert out.read_text() == "a file\n"


def test_its_own_folder_is_resumed_with_browser_files_and_leftover_temporaries(tmp_path):
    out = tmp_path / "q"
    out.mkdir()
    (out / ".DS_Store").write_bytes(b"\0")
    assert simulate_main([*QUENCH, "--out", str(out)]) == 0
    rods = np.load(out / "rods.npz")["config_00001"]
    # what a killed run leaves: the temporary files of atomic writes
    (out / ".configs.csv.k2j4x0a.csv").write_text("")
    (out / "parts" / ".config_00001.npz.q8z1m3b.npz").write_bytes(b"")
    (out / "parts" / "config_00001.npz").unlink()
    assert simulate_main([*QUENCH, "--out", str(out)]) == 0
    assert np.array_equal(np.load(out / "rods.npz")["config_00001"], rods)
    # a different ensemble, of this command or another, is refused (its parameters differ)
    assert simulate_main([*QUENCH[:1], "--seed", "1", *QUENCH[1:], "--out", str(out)]) == 2
    assert simulate_main([*COMPACT, "--out", str(out)]) == 2


@pytest.mark.parametrize("argv", [QUENCH, COMPACT], ids=["quench", "compact"])
def test_a_second_run_into_the_same_folder_is_refused(tmp_path, capsys, argv):
    """Two runs started together into one folder each took it for theirs when the second
    read it before the first had written its params.json: the tables mixed both ensembles.
    The second is refused in one line while the first holds the folder's lock."""
    from crosssection.core.fileio import folder_lock

    out = tmp_path / "q"
    with folder_lock(out, "simulation", where=out, busy="held") as token:
        assert token is not None
        status = simulate_main([*argv, "--out", str(out)])
    err = capsys.readouterr().err.splitlines()
    assert status == 2 and len(err) == 1, err
    assert err[0].startswith(f"error: {out}: another {argv[0]} is writing into it (pid ")
    assert not out.exists()
    # released: the same run goes on, and leaves no lock file behind
    assert simulate_main([*argv, "--out", str(out)]) == 0
    assert (out / "configs.csv").is_file() and not list(tmp_path.glob(".q.*.lock"))


def test_a_file_system_without_locks_is_said_once(tmp_path, capsys, monkeypatch):
    """On a file system that takes no lock (some network disks) a second run would not be
    refused: the run says so in one warning line and goes on."""
    import fcntl

    def no_locks(fd, operation):
        raise OSError(38, "Function not implemented")

    monkeypatch.setattr(fcntl, "flock", no_locks)
    out = tmp_path / "q"
    assert simulate_main([*QUENCH, "--out", str(out)]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "lock" in line]
    assert err == [f"warning: {out}: its file system takes no lock: a second run into it "
                   "would not be refused (run one at a time there)"]
    assert (out / "configs.csv").is_file()
