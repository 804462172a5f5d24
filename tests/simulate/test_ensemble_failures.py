"""A configuration whose computation raises is recorded and the ensemble goes on; a re-run
tries it again; the statistics leave it out with a warning."""
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from crosssection.quality import QualityWarning
from crosssection.stats.data import load_any
from simulate.ensemble import report_failures, run_ensemble, write_part


def _task(config_id, seed, params, out):
    """A stand-in configuration: fails while fail_<id> exists beside OUT (the output folder
    holds nothing but the ensemble's files), else writes a small rod and ran_<id> there."""
    if (Path(out).parent / f"fail_{config_id}").exists():
        raise FloatingPointError(f"diverged at step {config_id}")
    xy = np.column_stack([np.linspace(0, 1, 5), np.full(5, 0.1 * config_id)])
    row = {"config_id": config_id, "seed": seed, "epsilon": 2.0, "energy_total": 10.0 + config_id,
           "energy_bending": 10.0, "energy_confinement": 0.0, "rg": 0.3, "n_stacks": 1,
           "n_branches": 1, "n_voids": 1}
    branches = [{"branch_id": 0, "length": 0.5, "kappa_plus": 1.0, "kappa_pm": 0.5,
                 "energy_bending": 2.0, "energy": 2.0, "stack_id": 0}]
    voids = [{"area": 0.01, "perimeter": 0.4, "shape_ratio": 0.25, "n_edges": 3}]
    stacks = [{"stack_id": 0, "n_br": 1, "length": 0.5}]
    (Path(out).parent / f"ran_{config_id}").write_text("x")
    write_part(out, config_id, row, xy, xy, branches, voids, stacks)
    return config_id


PARAMS = {"command": "quench", "n_configs": 4, "seed": 3}


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failed_configuration_is_recorded_and_the_others_finish(tmp_path, workers):
    out = tmp_path / "ens"
    out.mkdir()
    (tmp_path / "fail_1").write_text("")
    tables = run_ensemble(PARAMS, out, workers=workers, task=_task, progress=False)
    assert tables["failed"]["config_id"].tolist() == [1]
    assert "FloatingPointError: diverged at step 1" in tables["failed"]["error"].iloc[0]
    assert pd.read_csv(out / "failures.csv")["config_id"].tolist() == [1]
    cfg = pd.read_csv(out / "configs.csv")
    assert cfg["config_id"].tolist() == [0, 1, 2, 3]  # every configuration has its row
    assert cfg["error"].notna().tolist() == [False, True, False, False]
    assert np.isnan(cfg.loc[1, "energy_total"]) and cfg.loc[2, "energy_total"] == 12.0
    with np.load(out / "rods.npz") as z:
        assert sorted(z.files) == ["config_00000", "config_00002", "config_00003"]
    # the counts of the others stay whole numbers in the file (not 10.0), the failed row empty
    lines = (out / "configs.csv").read_text().splitlines()
    header = lines[0].split(",")
    for c in ("n_stacks", "n_branches"):
        k = header.index(c)
        assert [ln.split(",")[k] for ln in lines[1:]] == [
            str(int(v)) if i != 1 else "" for i, v in enumerate(cfg[c].fillna(0))]
    from simulate.load import load_ensemble

    assert "3 configurations (1 failed" in repr(load_ensemble(out))


def test_a_rerun_tries_the_failed_configuration_again_and_only_it(tmp_path):
    out = tmp_path / "ens"
    out.mkdir()
    (tmp_path / "fail_2").write_text("")
    run_ensemble(PARAMS, out, task=_task, progress=False)
    for f in tmp_path.glob("ran_*"):
        f.unlink()
    (tmp_path / "fail_2").unlink()
    tables = run_ensemble(PARAMS, out, task=_task, progress=False)
    assert sorted(p.name for p in tmp_path.glob("ran_*")) == ["ran_2"]
    assert len(tables["failed"]) == 0 and len(pd.read_csv(out / "failures.csv")) == 0
    cfg = pd.read_csv(out / "configs.csv")
    assert "error" not in cfg.columns or cfg["error"].isna().all()


def test_failures_are_warning_lines_and_exit_status_3(tmp_path, capsys):
    out = tmp_path / "ens"
    out.mkdir()
    (tmp_path / "fail_0").write_text("")
    tables = run_ensemble(PARAMS, out, task=_task, progress=False)
    assert report_failures(tables, out) == 3
    err = capsys.readouterr().err.splitlines()
    assert err == [f"warning: {out}: configuration 0 (seed {tables['failed']['seed'][0]}) "
                   "failed: FloatingPointError: diverged at step 0"]
    (tmp_path / "fail_0").unlink()
    assert report_failures(run_ensemble(PARAMS, out, task=_task, progress=False), out) == 0


def test_statistics_leave_failed_configurations_out_with_a_warning(tmp_path):
    out = tmp_path / "ens"
    out.mkdir()
    (tmp_path / "fail_3").write_text("")
    run_ensemble(PARAMS, out, task=_task, progress=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ens = load_any(out)
    assert sorted(ens.configs["config_id"]) == ["0", "1", "2"]
    msgs = [str(w.message) for w in caught if issubclass(w.category, QualityWarning)]
    assert len(msgs) == 1 and "1 of 4 configurations failed" in msgs[0]


def test_the_workers_are_given_the_output_folder_absolute(tmp_path, monkeypatch):
    """A Dask worker runs in its own working folder: a relative --out sent as it was wrote the
    parts there, and the client found none."""
    seen = []

    def task(config_id, seed, params, out):
        seen.append(out)
        return _task(config_id, seed, params, out)

    monkeypatch.chdir(tmp_path)
    tables = run_ensemble(PARAMS, "ens", task=task, progress=False)
    assert len(tables["configs"]) == 4
    assert seen and all(Path(o).is_absolute() and Path(o) == tmp_path / "ens" for o in seen)


def _full_disk_task(config_id, seed, params, out):
    """A configuration whose part file the disk cannot take (after configuration 1)."""
    import errno

    if config_id >= 2:
        (Path(out).parent / f"ran_{config_id}").write_text("x")
        raise OSError(errno.ENOSPC, "No space left on device", str(Path(out) / "parts"))
    return _task(config_id, seed, params, out)


def test_a_full_disk_stops_the_run_and_leaves_the_tables_of_the_last_one(tmp_path,
                                                                          monkeypatch):
    """A disk filling during a longer run went on computing every configuration (each
    failing to save) and left configs.csv of the new run beside the old branches.csv."""
    from crosssection.core.errors import OutputError

    out = tmp_path / "ens"
    out.mkdir()
    run_ensemble({**PARAMS, "n_configs": 2}, out, task=_task, progress=False)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.suffix in (".csv", ".npz")}
    with pytest.raises(OutputError, match="No space left on device"):
        run_ensemble({**PARAMS, "n_configs": 6}, out, task=_full_disk_task, progress=False)
    assert sorted(p.name for p in tmp_path.glob("ran_*")) == ["ran_0", "ran_1", "ran_2"]
    # the tables are written as one: a disk full on the third leaves all as they were
    orig = pd.DataFrame.to_csv

    def full_on_branches(self, path=None, *args, **kwargs):
        import errno

        if path is not None and ".branches.csv." in str(path):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return orig(self, path, *args, **kwargs)

    monkeypatch.setattr(pd.DataFrame, "to_csv", full_on_branches)
    with pytest.raises(OSError):
        run_ensemble({**PARAMS, "n_configs": 4}, out, task=_task, progress=False)
    after = {p.name: p.read_bytes() for p in out.iterdir() if p.suffix in (".csv", ".npz")}
    assert {k: after[k] for k in before if k != "failures.csv"} == \
        {k: v for k, v in before.items() if k != "failures.csv"}
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
