"""File names as users have them: spaces, accents, bytes that are not UTF-8 (a name copied from
an old disk), a terminal that takes ASCII only. A name never stops a command."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

import crosssection.cli
from crosssection.core.errors import ImageError, printable
from crosssection.samples import samples_path

SCAN = "scan_01_sparse.png"


def test_printable_escapes_only_what_utf8_cannot_hold():
    assert printable("scan 5 ü日本.png") == "scan 5 ü日本.png"
    assert printable(os.fsdecode(b"bad\xffname.png")) == "bad\\xffname.png"
    assert printable(Path(os.fsdecode(b"a/\xfe.png"))) == "a/\\xfe.png"
    err = ImageError("cannot read", os.fsdecode(b"bad\xff.png"))
    assert err.one_line() == "bad\\xff.png: cannot read"
    err.one_line().encode("utf-8")  # every table can hold it
    assert printable("a\ud800b") == "a\\ud800b"  # a surrogate that stands for no byte


@pytest.fixture
def bad_name(tmp_path):
    """A copy of a sample scan under a name holding the byte 0xff (not UTF-8)."""
    folder = tmp_path / "scans"
    folder.mkdir()
    name = os.fsdecode(b"bad\xffname.png")
    try:
        (folder / name).write_bytes((samples_path() / SCAN).read_bytes())
    except (OSError, UnicodeEncodeError):  # a file system that holds UTF-8 names only
        pytest.skip("this file system refuses names that are not UTF-8")
    return folder / name


@pytest.mark.filterwarnings("ignore::crosssection.quality.QualityWarning")
def test_analyze_draws_and_records_a_name_that_is_not_utf8(bad_name, tmp_path, capsys):
    out = tmp_path / "out"
    assert crosssection.cli.main(["analyze", str(bad_name), "--out", str(out),
                                  "--calibration", str(samples_path() / "calibration.csv")]) == 0
    assert (out / "overlay.png").stat().st_size > 0 and (out / "summary.json").is_file()
    assert "error" not in capsys.readouterr().err
    # its warnings name it escaped (a surrogate could not be printed: "unexpected
    # UnicodeEncodeError", exit 1)
    assert crosssection.cli.main(["analyze", str(bad_name), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "error" not in err and "warning: " in err and "bad\\xffname.png" in err


def test_a_batch_records_a_name_that_is_not_utf8_and_goes_on(bad_name, tmp_path, capsys):
    folder = bad_name.parent
    (folder / SCAN).write_bytes((samples_path() / SCAN).read_bytes())
    out = tmp_path / "batch"
    argv = ["batch", str(folder), "--out", str(out), "--workers", "1", "--calibration",
            str(samples_path() / "calibration.csv")]
    assert crosssection.cli.main(argv) == 3  # some scans failed
    index = pd.read_csv(out / "index.csv")  # UTF-8 text, as every table
    assert dict(zip(index["image"], index["status"])) == {"bad\\xffname.png": "failed",
                                                          SCAN: "ok"}
    failures = pd.read_csv(out / "failures.csv")
    assert list(failures["image"]) == ["bad\\xffname.png"]
    assert "file name or folder name is not UTF-8 text" in failures["reason"].iloc[0]
    capsys.readouterr()
    assert crosssection.cli.main(argv) == 3  # a re-run resumes: the scan done is skipped
    assert "0 done, 1 skipped, 1 failed" in capsys.readouterr().out


def test_an_ascii_terminal_gets_escapes_not_a_failure(tmp_path):
    scan = tmp_path / "scan ü.png"
    scan.write_bytes((samples_path() / SCAN).read_bytes())
    env = {**os.environ, "PYTHONIOENCODING": "ascii"}
    r = subprocess.run([sys.executable, "-m", "crosssection", "analyze", str(scan), "--out",
                        str(tmp_path / "out"), "--no-figure", "--calibration",
                        str(samples_path() / "calibration.csv")],
                       capture_output=True, text=True, env=env, encoding="ascii")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"{tmp_path}/scan \\xfc.png: ")


@pytest.mark.parametrize("entry", ["crosssection", "foldstat"])
def test_a_name_starting_with_a_dash_gets_a_hint_in_its_one_line(entry, tmp_path, capsys):
    """argparse reads '-scan.png' as an option and then misses the scan, and reads options
    after '--' as file names: its one line says which, and how to name the file."""
    from crosssection.console import main as foldstat

    main = crosssection.cli.main if entry == "crosssection" else foldstat

    def run(argv):
        try:
            return main(argv)
        except SystemExit as exc:  # argparse's usage errors
            return exc.code
    out = str(tmp_path / "out")
    hints = {("analyze", "-scan.png", "--out", out):
             "the following arguments are required: image (-scan.png is read as an option: "
             "name a file starting with '-' as ./-scan.png)",
             ("analyze", "--", "-scan.png", "--out", out):
             "the following arguments are required: --out (every word after '--' is read as "
             "a file name: give the options before it)"}
    for argv, said in hints.items():
        assert run(list(argv)) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and err[0].startswith("error: ") and err[0].endswith(said), err
    # no hint where none applies: '--' used as it should be, another kind of error
    for argv, said in {("analyze", "--out", out): "required: image",
                       ("analyze", "--", "-scan.png"): "required: --out",
                       ("analyze", "--out", out, "--", "-a.png", "b.png"):
                       "unrecognized arguments: b.png",
                       ("analyze", "s.png", "--out", out, "--width-law", "x", "-q.png"):
                       "(choose from 'fitted', 'linear')"}.items():
        assert run(list(argv)) == 2
        err = capsys.readouterr().err.strip()
        assert err.endswith(said), err
    # the words are read once: an iterator of them is parsed as a list is
    from crosssection.cli import OneLineParser

    parser = OneLineParser(prog="x")
    parser.add_argument("a")
    assert parser.parse_args(iter(["v"])).a == "v"
