"""Atomic writes: an output that cannot be written is named as the user gave it, never by the
hidden temporary file it is written through."""
from __future__ import annotations

import errno
from pathlib import Path

import pandas as pd
import pytest

from crosssection.core import fileio


@pytest.mark.parametrize("write", [
    lambda p: fileio.write_csv(p, pd.DataFrame({"a": [1]})),
    lambda p: fileio.write_json(p, {"a": 1}),
    lambda p: fileio.write_text(p, "a"),
    lambda p: fileio.write_npz(p, a=[1]),
])
def test_a_folder_in_the_way_names_the_output(tmp_path, write):
    target = tmp_path / "stacks.csv"
    target.mkdir()
    with pytest.raises(IsADirectoryError) as info:
        write(target)
    assert info.value.filename == str(target) and info.value.filename2 is None
    assert info.value.errno == errno.EISDIR
    assert [p.name for p in tmp_path.iterdir()] == ["stacks.csv"]  # no temporary file left


def test_an_error_about_another_file_is_left_as_it_is(tmp_path):
    with pytest.raises(FileNotFoundError) as info:
        with fileio.atomic_path(tmp_path / "out.csv"):
            open(tmp_path / "missing.csv")
    assert info.value.filename == str(tmp_path / "missing.csv")
    assert list(tmp_path.iterdir()) == []


def test_the_command_line_names_the_output(tmp_path, capsys):
    from crosssection.cli import main
    from crosssection.testing import drawn_scan, write_png

    scan = tmp_path / "scan.png"
    write_png(scan, drawn_scan(2))
    out = tmp_path / "inway"
    (out / "stacks.csv").mkdir(parents=True)
    assert main(["analyze", str(scan), "--out", str(out), "--px-per-mm", "50",
                 "--thickness-mm", "0.1", "--no-figure"]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {out / 'stacks.csv'}: cannot write (Is a directory)\n"


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO])
def test_a_full_disk_names_the_output(tmp_path, code):
    """A write that fails for lack of room raises an error naming no file (from the write or
    the close of the temporary file): it is the output's."""
    target = tmp_path / "index.csv"
    with pytest.raises(OSError) as info:
        with fileio.atomic_path(target):
            raise OSError(code, "No space left on device")
    assert info.value.errno == code and info.value.filename == str(target)
    assert list(tmp_path.iterdir()) == []
    # any other error naming no file is the writer's own, left as it is
    with pytest.raises(OSError) as info:
        with fileio.atomic_path(target):
            raise OSError(errno.EINVAL, "Invalid argument")
    assert info.value.filename is None


def test_the_temporary_files_of_atomic_writes_are_found(tmp_path):
    (tmp_path / ".index.csv.ab12cd34.csv").write_text("half")
    (tmp_path / ".batch.json.k3j2l1ab.json").write_text("{")
    (tmp_path / ".index.csv.ab12cd34.json").write_text("not one")
    (tmp_path / "index.csv").write_text("whole")
    assert [p.name for p in fileio.temporary_files(tmp_path, ["index.csv", "batch.json"])] == [
        ".batch.json.k3j2l1ab.json", ".index.csv.ab12cd34.csv"]
    assert fileio.temporary_files(tmp_path / "none", ["index.csv"]) == []


def test_a_users_hidden_file_of_the_same_stem_is_no_temporary_file(tmp_path):
    # only mkstemp's eight random characters stand between the name and the suffix
    for name in (".overlay.png.orig.png", ".stacks.csv.my-notes.csv", ".stacks.csv.ab12cd345.csv"):
        (tmp_path / name).write_text("mine")
    (tmp_path / ".stacks.csv.a_2b9xyz.csv").write_text("half")
    found = fileio.temporary_files(tmp_path, ["overlay.png", "stacks.csv"])
    assert [p.name for p in found] == [".stacks.csv.a_2b9xyz.csv"]
    with fileio.atomic_path(tmp_path / "stacks.csv") as tmp:
        # what the writer itself makes is found
        assert Path(tmp) in fileio.temporary_files(tmp_path, ["stacks.csv"])
        Path(tmp).write_text("whole")


def test_foreign_entry_names_the_first_entry_a_command_does_not_write(tmp_path):
    from crosssection.core.fileio import foreign_entry

    (tmp_path / "a.csv").write_text("")
    (tmp_path / ".a.csv.x1y2z3a4.csv").write_text("")  # an atomic write cut short
    (tmp_path / ".DS_Store").write_text("")
    assert foreign_entry(tmp_path, {"a.csv"}) is None
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "x.png").write_text("")
    assert foreign_entry(tmp_path, {"a.csv"}) == "sub"  # no rule: every subfolder is foreign
    assert foreign_entry(tmp_path, {"a.csv"}, lambda p: None) is None
    assert foreign_entry(tmp_path, {"a.csv"}, lambda p: f"{p.name}/x.png") == "sub/x.png"
    (tmp_path / "b.txt").write_text("")
    assert foreign_entry(tmp_path, {"a.csv"}, lambda p: None) == "b.txt"


@pytest.mark.parametrize("exists", [True, False])
def test_an_unwritable_output_is_named_as_given(tmp_path, monkeypatch, capsys, exists):
    import tempfile

    import crosssection.cli

    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied", str(tmp_path / ".foldstat-probe-x"))

    out = tmp_path / "samples"
    if exists:
        out.mkdir()
    monkeypatch.setattr(tempfile, "NamedTemporaryFile", refused)
    assert crosssection.cli.main(["samples", str(out)]) == 2
    err = capsys.readouterr().err
    # the folder given is named; where it does not exist yet, so is the parent that refused
    if exists:
        assert err == f"error: {out}: cannot write (Permission denied)\n"
    else:
        assert err == (f"error: {out}: cannot be created: {tmp_path} cannot be written "
                       "(Permission denied)\n")
    assert list(tmp_path.iterdir()) == ([out] if exists else [])


def test_files_written_together_appear_together(tmp_path):
    (tmp_path / "a.csv").write_text("old a")
    with fileio.renamed_together():
        fileio.write_text(tmp_path / "a.csv", "new a")
        fileio.write_json(tmp_path / "b.json", {"b": 1})
        with fileio.renamed_together():  # nested: the outer block's
            fileio.write_text(tmp_path / "c.txt", "c")
        # nothing is in place before the block ends
        assert (tmp_path / "a.csv").read_text() == "old a"
        assert not (tmp_path / "b.json").exists() and not (tmp_path / "c.txt").exists()
    assert (tmp_path / "a.csv").read_text() == "new a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.json", "c.txt"]


@pytest.mark.parametrize("stop", [KeyboardInterrupt, ValueError])
def test_a_block_stopped_midway_leaves_the_earlier_files(tmp_path, stop):
    (tmp_path / "a.csv").write_text("old a")
    with pytest.raises(stop):
        with fileio.renamed_together():
            fileio.write_text(tmp_path / "a.csv", "new a")
            fileio.write_text(tmp_path / "b.txt", "b")
            raise stop()
    # no temporary file is left, the earlier file is whole
    assert [p.name for p in tmp_path.iterdir()] == ["a.csv"]
    assert (tmp_path / "a.csv").read_text() == "old a"


def test_a_nested_block_that_fails_publishes_nothing(tmp_path):
    (tmp_path / "a.csv").write_text("old a")
    with fileio.renamed_together():
        fileio.write_text(tmp_path / "b.txt", "b")
        with pytest.raises(ValueError):
            with fileio.renamed_together():
                fileio.write_text(tmp_path / "a.csv", "new a")
                raise ValueError
    # the outer block's file lands, the failed inner block's does not, no temporary is left
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.txt"]
    assert (tmp_path / "a.csv").read_text() == "old a"


def test_a_failed_rename_leaves_no_temporary_file(tmp_path, monkeypatch):
    real = fileio.os.replace
    calls = []

    def replace(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise KeyboardInterrupt  # an interrupt among the renames
        return real(src, dst)

    monkeypatch.setattr(fileio.os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        with fileio.renamed_together():
            for name in ("a.txt", "b.txt", "c.txt"):
                fileio.write_text(tmp_path / name, name)
    # a.txt, renamed before the interrupt, replaced nothing: it goes too
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_rename_refused_midway_puts_the_earlier_files_back(tmp_path, monkeypatch):
    """A re-run whose summary.json could not be replaced (made immutable) left the new run's
    overlay and tables beside the old run's summary: stats then pooled 77 branches where the
    summary counted 64. The files renamed before the refusal go back to the earlier run's."""
    for name in ("a.csv", "b.csv", "summary.json"):
        (tmp_path / name).write_text(f"old {name}")
    real = fileio.os.replace

    def replace(src, dst):
        if Path(dst).name == "summary.json" and Path(src).name.startswith(".summary"):
            raise PermissionError(1, "Operation not permitted", str(src), None, str(dst))
        return real(src, dst)

    monkeypatch.setattr(fileio.os, "replace", replace)
    with pytest.raises(PermissionError, match="summary.json"):
        with fileio.renamed_together():
            fileio.write_text(tmp_path / "a.csv", "new a")
            fileio.write_text(tmp_path / "new.csv", "new")
            fileio.write_text(tmp_path / "b.csv", "new b")
            fileio.write_text(tmp_path / "summary.json", "new summary")
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {
        "a.csv": "old a.csv", "b.csv": "old b.csv", "summary.json": "old summary.json"}


def test_a_loop_of_symbolic_links_as_the_output_is_named_so(tmp_path):
    """Not a file in the way of a folder: the message says what it is."""
    from crosssection.core.errors import ParameterError
    from crosssection.core.fileio import check_out

    (tmp_path / "one").symlink_to(tmp_path / "two")
    (tmp_path / "two").symlink_to(tmp_path / "one")
    with pytest.raises(ParameterError, match="loop of symbolic links"):
        check_out(tmp_path / "one")
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    check_out(tmp_path / "link")  # a link to a folder is that folder


def test_a_folder_that_takes_no_files_is_not_said_to_be_missing(tmp_path, monkeypatch):
    # /proc exists but refuses new files with ENOENT: "No such file or directory" about a
    # folder that exists contradicts itself
    import tempfile

    def refuse(*args, **kwargs):
        raise FileNotFoundError(errno.ENOENT, "No such file or directory")

    monkeypatch.setattr(tempfile, "NamedTemporaryFile", refuse)
    from crosssection.core.errors import OutputError

    with pytest.raises(OutputError) as info:
        fileio.check_writable(tmp_path / "out")
    assert "takes no new files" in str(info.value)
    assert "No such file" not in str(info.value)


def test_a_folder_under_a_read_only_parent_is_locked_inside(tmp_path, monkeypatch):
    """Two runs into an existing folder whose parent takes no file both ran unlocked: the
    lock is then taken inside the folder, where it is no one's entry."""
    from crosssection.core.errors import OutputError, ParameterError

    out = tmp_path / "ro" / "out"
    out.mkdir(parents=True)
    lock = fileio.exclusive_lock

    def read_only_parent(path, **kw):  # the permissions as an unprivileged user meets them
        if Path(path).parent == out.parent:
            raise OutputError("cannot be created (Permission denied)", path)
        return lock(path, **kw)

    monkeypatch.setattr(fileio, "exclusive_lock", read_only_parent)
    with fileio.folder_lock(out, "simulation", where=out, busy="busy") as token:
        assert token is not None and (out / ".simulation.lock").is_file()
        assert fileio.foreign_entry(out, ("configs.csv",)) is None
        with pytest.raises(ParameterError, match="busy"):
            with fileio.folder_lock(out, "simulation", where=out, busy="busy"):
                pass
    assert list(out.iterdir()) == []
    # a new folder there cannot be made: it runs unlocked (its command names the fault)
    with fileio.folder_lock(out.parent / "new", "simulation", where=out, busy="b") as token:
        assert token is None
