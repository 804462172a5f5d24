"""``analyze`` names the set.toml or calibration.csv it does not read (only ``batch`` does)."""
from __future__ import annotations

import shutil

import pytest

import crosssection.cli
from crosssection.commands import set_not_read
from crosssection.params import AnalysisParams
from crosssection.samples import samples_path

SCAN = "scan_01_sparse.png"


@pytest.fixture
def set_folder(tmp_path):
    """A set: one sample scan, its calibration and a set.toml naming it and the scale."""
    src = samples_path()
    for name in (SCAN, "calibration.csv"):
        shutil.copy(src / name, tmp_path / name)
    (tmp_path / "set.toml").write_text('px_per_mm = 50\nthickness_mm = 0.1\n'
                                       'calibration = "calibration.csv"\n')
    return tmp_path


def test_a_set_toml_whose_values_are_not_used_is_named(set_folder):
    note = set_not_read(set_folder / SCAN, AnalysisParams())
    assert note is not None and "set.toml is not read by analyze" in note
    assert "calibration" in note and "px_per_mm" not in note  # the scale is the same


def test_a_set_toml_whose_values_are_passed_is_not_named(set_folder):
    params = AnalysisParams(calibration=str(set_folder / "calibration.csv"))
    assert set_not_read(set_folder / SCAN, params) is None


def test_the_nearest_set_above_the_scan_is_the_one_read(set_folder):
    sub = set_folder / "day1"
    sub.mkdir()
    shutil.move(set_folder / SCAN, sub / SCAN)
    note = set_not_read(sub / SCAN, AnalysisParams(px_per_mm=40.0))
    assert "set.toml" in note and "px_per_mm" in note and "calibration" in note


def test_a_calibration_beside_a_loose_scan_is_named(set_folder):
    (set_folder / "set.toml").unlink()
    note = set_not_read(set_folder / SCAN, AnalysisParams())
    assert "calibration.csv beside it is not used" in note
    params = AnalysisParams(calibration=str(set_folder / "calibration.csv"))
    assert set_not_read(set_folder / SCAN, params) is None


def test_the_cli_prints_it_as_one_warning_line(set_folder, capsys):
    out = set_folder / "out"
    assert crosssection.cli.main(["analyze", str(set_folder / SCAN), "--out", str(out),
                                  "--no-figure"]) == 0
    err = capsys.readouterr().err.splitlines()
    named = [line for line in err if "set.toml is not read by analyze" in line]
    assert len(named) == 1 and named[0].startswith(f"warning: {set_folder / SCAN}: ")
    assert crosssection.cli.main(["analyze", str(set_folder / SCAN), "--out", str(out),
                                  "--no-figure", "--calibration",
                                  str(set_folder / "calibration.csv")]) == 0
    assert "set.toml" not in capsys.readouterr().err
