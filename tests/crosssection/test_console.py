"""The ``foldstat`` console command: every subcommand of both tools, help texts, a light
start-up, one-line errors, and the bundled samples."""
import argparse
import subprocess
import sys

import pytest

import crosssection.cli
import simulate.cli
from crosssection import console
from crosssection.core.errors import FoldstatError, ParameterError
from crosssection.samples import copy_samples, samples_path


def _subparsers(parser):
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def test_every_registered_subcommand_is_listed_with_a_one_line_help(capsys):
    expected = list(dict.fromkeys([*crosssection.cli.SUBCOMMANDS, *simulate.cli.SUBCOMMANDS,
                                   "samples"]))
    with pytest.raises(SystemExit) as exc:
        console.main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    listed = {a.dest: a.help for a in _subparsers(console.build_parser([]))._choices_actions}
    assert list(listed) == expected
    for name in expected:
        assert listed[name].strip() and f"    {name}" in out
    for code in ("0 ", "2 ", "3 ", "130", "143"):  # the exit status table in the epilog
        assert f"\n  {code}" in out
    assert "unavailable" not in out


def test_source_reading_agrees_with_the_imported_tables():
    # the fast path (no import for --help) must see what importing sees
    for source, module in (("crosssection.cli", crosssection.cli),
                           ("simulate.cli", simulate.cli)):
        table = console._literal_table(source)
        assert table is None or table == module.SUBCOMMANDS
    commands, broken = console.registered_subcommands()
    assert not broken
    for name in [*crosssection.cli.SUBCOMMANDS, *simulate.cli.SUBCOMMANDS]:
        assert name in commands


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        console.main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"foldstat {crosssection.__version__}"


def test_help_imports_no_heavy_library():
    code = ("import sys\nfrom crosssection import console\n"
            "try:\n    console.main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print([m for m in ('numpy', 'pandas', 'matplotlib', 'skimage', 'scipy', 'cv2') "
            "if m in sys.modules])")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip().splitlines()[-1] == "[]"


def test_every_option_has_help_with_its_default():
    commands, _ = console.registered_subcommands()
    checked = 0
    for name in commands:
        sub = _subparsers(console.build_parser([name])).choices[name]
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            where = f"{name} {'/'.join(action.option_strings) or action.dest}"
            assert action.help and action.help.strip(), f"{where}: no help"
            if (action.option_strings and not action.required
                    and action.default not in (None, False)):
                assert "default" in action.help.lower(), f"{where}: default not stated"
            checked += 1
    assert checked > 60


def test_a_missing_module_leaves_the_others_working(monkeypatch, capsys):
    monkeypatch.setattr(console, "CONSOLE_SUBCOMMANDS",
                        {**console.CONSOLE_SUBCOMMANDS, "ghost": "simulate.no_such_module"})
    with pytest.raises(SystemExit):
        console.main(["--help"])
    out = capsys.readouterr().out
    assert "unavailable here:" in out and "ghost" in out and "    render" in out
    assert console.main(["ghost"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: foldstat ghost: unavailable")


def test_bad_input_is_one_line_and_status_2(tmp_path, capsys):
    assert console.main(["stats", str(tmp_path / "missing"), "--out",
                         str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "missing" in err[0]
    with pytest.raises(SystemExit) as exc:
        console.main(["quench", "--n-configs", "many", "--out", str(tmp_path)])
    assert exc.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_the_next_command_samples_suggest_writes_beside_the_scans(tmp_path, capsys,
                                                                  monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert console.main(["samples", "scans"]) == 0
    assert "(next: foldstat batch scans --out batch/)" in capsys.readouterr().out
    assert console.main(["samples", "batch"]) == 0  # never the scans' own folder
    assert "(next: foldstat batch batch --out batch_out/)" in capsys.readouterr().out


def test_samples_are_copied_out_and_not_overwritten(tmp_path, capsys):
    src = samples_path()
    dest = tmp_path / "samples"
    assert console.main(["samples", str(dest)]) == 0
    files = sorted(p.relative_to(src) for p in src.rglob("*") if p.is_file())
    assert len(files) >= 10 and (dest / "set.toml").is_file()
    for rel in files:
        assert (dest / rel).read_bytes() == (src / rel).read_bytes(), rel
    assert "5 sample scans" in capsys.readouterr().out
    (dest / "set.toml").write_text("changed")
    assert console.main(["samples", str(dest)]) == 2  # refuses, names a file
    err = capsys.readouterr().err
    assert err.startswith(f"error: {dest}") and "exists already" in err
    assert (dest / "set.toml").read_text() == "changed"
    assert len(copy_samples(dest, overwrite=True)) == len(files)
    assert (dest / "set.toml").read_bytes() == (src / "set.toml").read_bytes()


@pytest.mark.parametrize("tool", [crosssection.cli, simulate.cli])
def test_module_clis_register_only_the_subcommand_that_runs(tool):
    every = set(tool.SUBCOMMANDS)
    assert set(_subparsers(tool.build_parser([])).choices) == every
    for name, module in tool.SUBCOMMANDS.items():
        shared = {n for n, m in tool.SUBCOMMANDS.items() if m == module}
        assert set(_subparsers(tool.build_parser([name, "--help"])).choices) == shared


def test_python_m_crosssection_analyze_does_not_import_stats_or_simulator():
    code = ("import sys; from crosssection.cli import build_parser; "
            "build_parser(['analyze', 'scan.png']); "
            "print(sorted(m for m in ('scipy.stats', 'simulate', 'numba') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]"


def test_samples_into_a_file_or_an_empty_path_is_one_line(tmp_path, capsys, monkeypatch):
    a_file = tmp_path / "set.toml"
    a_file.write_text("x")
    assert console.main(["samples", str(a_file)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {a_file}: is a file, not a folder: give a folder to copy the "
                   "samples into"]
    with pytest.raises(FoldstatError, match="is a file, not a folder"):
        copy_samples(a_file)
    monkeypatch.chdir(tmp_path)
    assert console.main(["samples", ""]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: DIR: empty path: give the output folder"]
    with pytest.raises(ParameterError, match="empty path"):
        copy_samples("")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["set.toml"]


RECORDS = {"batch.json": '{"package": "foldstat", "version": "0"}',
           "stats.json": '{"package": "foldstat", "version": "0"}',
           "summary.json": '{"version": "0", "parameters": {}}',
           "steps.json": '{"command": "steps", "version": "0", "parameters": {}}',
           "render.json": '{"command": "render", "version": "0"}'}


@pytest.mark.parametrize("record", sorted(RECORDS))
def test_samples_into_a_commands_output_folder_is_one_line(tmp_path, capsys, record):
    (tmp_path / record).write_text(RECORDS[record])
    assert console.main(["samples", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {tmp_path}: holds the output of ")
    assert f"({record})" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == [record]


def test_samples_beside_a_users_file_named_like_a_record(tmp_path):
    # no record, nor another tool's metadata with a version: the folder is the user's
    (tmp_path / "summary.json").write_text("my notes")
    (tmp_path / "batch.json").write_text('{"version": 2, "operator": "scanner export"}')
    assert console.main(["samples", str(tmp_path)]) == 0
    assert (tmp_path / "set.toml").is_file()
    assert (tmp_path / "summary.json").read_text() == "my notes"


def test_python_m_crosssection_offers_samples(tmp_path, capsys):
    from crosssection.cli import build_parser, main

    names = set(_subparsers(build_parser(["--help"])).choices)
    assert "samples" in names and names == set(crosssection.cli.SUBCOMMANDS)
    assert main(["samples", str(tmp_path / "in_process")]) == 0
    assert (tmp_path / "in_process" / "set.toml").is_file()
    run = subprocess.run([sys.executable, "-m", "crosssection", "samples", str(tmp_path / "s")],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stderr == "", run.stderr
    assert (tmp_path / "s" / "set.toml").is_file() and "5 sample scans" in run.stdout


class _FullDisk:
    """A standard output whose every write fails as on a full disk."""

    def write(self, text):
        raise OSError(28, "No space left on device")

    def flush(self):
        pass


@pytest.mark.parametrize("main", [console.main, crosssection.cli.main, simulate.cli.main])
@pytest.mark.parametrize("argv", [["--version"], ["--help"], ["analyze", "--help"]])
def test_help_or_version_that_cannot_be_written_is_an_error(main, argv, monkeypatch, capsys):
    if main is simulate.cli.main and argv[0] == "analyze":
        argv = ["quench", "--help"]
    monkeypatch.setattr(sys, "stdout", _FullDisk())
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == "error: output: No space left on device\n"


def test_no_help_text_shows_docstring_markup():
    # a terminal shows ``literal`` as typed: the descriptions and helps drop the backquotes
    commands, _ = console.registered_subcommands()
    for name in commands:
        sub = _subparsers(console.build_parser([name])).choices[name]
        assert "``" not in (sub.description or ""), name
        for action in sub._actions:
            assert "``" not in (action.help or ""), f"{name} {action.dest}"
