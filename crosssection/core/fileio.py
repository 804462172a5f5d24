"""Atomic writing of outputs: write to a temporary file in the same folder, then rename.

A re-run never sees a half-written file: either the old one or the complete new one. Within
:func:`renamed_together` the renames wait for the end of the block, so a run stopped before
them leaves the folder's earlier files as they were.
"""
from __future__ import annotations

import contextvars
import errno
import json
import os
import re
import secrets
import shutil
import tempfile
import uuid
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# read once at import: os.umask can only be read by setting it, which is not thread-safe
UMASK = _current_umask()
#: infix of the hidden working folders beside an output folder: ``.<name>.partial-*`` being
#: written, ``.<name>.old-*`` the previous output on its way out
PARTIAL_TAG = ".partial-"
OLD_TAG = ".old-"
#: files that file browsers leave in the folders they show: no output folder counts them as
#: content of its own or of another's
BROWSER_FILES = frozenset({".DS_Store", "Thumbs.db", "desktop.ini"})
#: errors of a write that name no file (a full disk or quota, a disk failing): raised inside
#: :func:`atomic_path`, they are the temporary file's
_WRITE_ERRNOS = frozenset(e for e in (errno.ENOSPC, getattr(errno, "EDQUOT", None),
                                      errno.EFBIG, errno.EIO) if e is not None)


#: the renames :func:`atomic_path` leaves to the enclosing :func:`renamed_together` block
_PENDING: contextvars.ContextVar = contextvars.ContextVar("foldstat_pending_renames",
                                                         default=None)


@contextmanager
def renamed_together():
    """Hold back the renames of :func:`atomic_path` to the end of the block, and do them
    there in the order the files were written (a run's record, written last, lands last).

    A block stopped midway (an error, an interrupt) removes its temporary files and leaves
    the folder's files as they were: an output folder written again does not mix two runs
    (one run's figures beside another's tables). A rename refused among the renames puts the
    files already renamed back (each replaced file is hard-linked aside first; on a file
    system without hard links, what cannot be linked cannot be put back). A kill leaves
    only hidden temporary files (``.<name>.XXXX<suffix>``), which the next run removes. A
    nested block's files are renamed with its outer block's, or removed when the nested
    block fails. Per thread: another thread's writes are its own.
    """
    pending = _PENDING.get()
    if pending is not None:  # nested
        start = len(pending)
        try:
            yield
        except BaseException:
            _discard(tmp for tmp, _ in pending[start:])
            del pending[start:]
            raise
        return
    pending = []
    token = _PENDING.set(pending)
    try:
        yield
    except BaseException:
        _discard(tmp for tmp, _ in pending)
        raise
    finally:
        _PENDING.reset(token)
    done = []  # (path, a hard link to the file it replaced, or None)
    try:
        for tmp, path in pending:
            backup = _linked_aside(path)
            try:
                os.replace(tmp, path)
            except OSError as exc:
                _discard([backup] if backup else [])
                raise _renamed(exc, path) from None
            done.append((path, backup))
    except BaseException:
        # a rename refused midway (a file made read-only, a full quota) or an interrupt: the
        # files already renamed go back to the earlier run's, so the folder is one run's
        _put_back(done)
        raise
    finally:  # no temporary file left behind
        _discard(tmp for tmp, _ in pending[len(done):])
    _discard(b for _, b in done if b)


def _linked_aside(path: Path) -> Path | None:
    """A hard link to the file at ``path`` under a temporary name of :func:`atomic_path`'s
    pattern (a kill leaves it to the next run's :func:`temporary_files`), or None when there
    is no file or it cannot be linked (then a failed block cannot put it back)."""
    if not path.is_file():
        return None
    aside = path.with_name(f".{path.name}.{secrets.token_hex(4)}{path.suffix or '.tmp'}")
    try:
        os.link(path, aside)
    except OSError:
        return None
    return aside


def _put_back(done) -> None:
    """Undo the renames ``done`` (:func:`renamed_together`), last first: each file back to
    the one it replaced, a file that replaced none removed; what cannot be undone stays."""
    for path, backup in reversed(done):
        try:
            if backup is not None:
                os.replace(backup, path)
            else:
                path.unlink(missing_ok=True)
        except OSError:
            pass


def _discard(paths) -> None:
    """Remove temporary files, those already gone or that cannot be removed left (the next
    run's :func:`temporary_files` finds them)."""
    for p in paths:
        try:
            p.unlink(missing_ok=True)
        except OSError:
            pass


@contextmanager
def atomic_path(path, suffix=None):
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    Parameters
    ----------
    path : str or Path
        Final destination.
    suffix : str, optional
        Suffix of the temporary file (defaults to the destination's, so writers that
        infer the format from the extension, like matplotlib, keep working).

    Yields
    ------
    Path
        Where to write. Removed if the block raises.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.",
                                   suffix=suffix or path.suffix or ".tmp", dir=path.parent)
    except OSError as exc:  # names the temporary file it could not create
        raise _renamed(exc, path) from None
    os.close(fd)
    tmp = Path(tmp)
    pending = _PENDING.get()
    handed_over = False
    try:
        os.chmod(tmp, 0o666 & ~UMASK)  # mkstemp creates 0600; outputs get the usual mode
        yield tmp
        if pending is None:
            os.replace(tmp, path)
        else:  # renamed with the block's other files at its end
            pending.append((tmp, path))
            handed_over = True
    except OSError as exc:
        named = {os.fsdecode(n) for n in (exc.filename, exc.filename2)
                 if isinstance(n, (str, bytes, os.PathLike))}
        if str(tmp) not in named and (named or exc.errno not in _WRITE_ERRNOS):
            raise  # about another file: the writer's own error
        raise _renamed(exc, path) from None
    finally:
        if not handed_over and tmp.exists():
            tmp.unlink()


def check_out(path, name: str = "--out") -> None:
    """Refuse, before any work, an output path that cannot take the outputs (every
    command's ``--out``): an empty one (``Path("")`` is the current folder) or a folder that
    cannot be written (:func:`check_writable`).

    Parameters
    ----------
    path : str or Path
        The output folder given.
    name : str
        The option or parameter that gave it (named in the error).

    Raises
    ------
    ParameterError
        ``path`` is empty or blank.
    OutputError
        The folder, or its nearest existing parent, cannot be written.
    """
    if not str(path).strip():
        from crosssection.core.errors import ParameterError

        raise ParameterError("empty path: give the output folder", name)
    if _in_a_link_loop(Path(path).expanduser()):
        from crosssection.core.errors import ParameterError

        raise ParameterError(f"{path} is a loop of symbolic links: give another folder", name)
    check_writable(path)


def _in_a_link_loop(path: Path) -> bool:
    """Whether ``path`` is a loop of symbolic links (the system's ELOOP)."""
    import errno

    try:
        os.stat(path)
    except OSError as exc:
        return exc.errno == errno.ELOOP
    return False


def check_writable(path) -> None:
    """Refuse, before any work, an output folder that cannot be written: a file is written
    and removed in it, or in its nearest existing parent when it does not exist yet (nothing
    is created). Minutes of fitting or a sweep are then not lost to a folder found read-only
    at the end.

    Parameters
    ----------
    path : str or Path
        The output folder.

    Raises
    ------
    OutputError
        Naming the folder and the cause (the parent that cannot be written, when the folder
        does not exist yet).
    """
    import tempfile

    from crosssection.core.errors import output_error

    folder = Path(path).expanduser()
    probe = folder
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        return  # a file in the way: the command names it when it makes the folder
    try:
        with tempfile.NamedTemporaryFile(dir=probe, prefix=".foldstat-probe-"):
            pass
    except OSError as exc:
        # named by the folder: the probe's hidden name means nothing to the user
        if probe == folder:
            raise output_error(OSError(exc.errno, exc.strerror), probe) from None
        from crosssection.core.errors import OutputError

        why = exc.strerror or type(exc).__name__
        if exc.errno == errno.ENOENT:  # an existing folder that takes no files (/proc)
            why = "it takes no new files"
        raise OutputError(f"cannot be created: {probe} cannot be written ({why})",
                          folder) from None


def _renamed(exc: OSError, path: Path) -> OSError:
    """``exc`` naming ``path`` instead of the hidden temporary file of its atomic write: the
    user asked for ``path`` and never sees the other."""
    try:
        return type(exc)(exc.errno, exc.strerror or str(exc), str(path))
    except TypeError:  # a subclass with its own signature: the name matters less than the type
        return exc


def _json_default(obj):
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return None if not np.isfinite(obj) else float(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _clean_nonfinite(obj):
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _clean_nonfinite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean_nonfinite(v) for v in obj]
    return obj


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON atomically (NaN and inf become null)."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(_clean_nonfinite(data), indent=2, default=_json_default) + "\n")
    return Path(path)


def write_csv(path, df: pd.DataFrame) -> Path:
    """Write a DataFrame as CSV (no index) atomically, in UTF-8.

    A path whose bytes are not UTF-8 (the system keeps them as surrogates) is written with
    those bytes as ``\\udcXX`` escapes: the file stays UTF-8 for every reader."""
    with atomic_path(path) as tmp:
        df.to_csv(tmp, index=False, encoding="utf-8", errors="backslashreplace")
    return Path(path)


def write_text(path, text: str) -> Path:
    """Write text atomically, in UTF-8 (non-UTF-8 path bytes escaped as by
    :func:`write_csv`)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8", errors="backslashreplace")
    return Path(path)


#: Resolution figures are saved at (:func:`save_figure`), dots per inch.
SAVE_DPI = 120


def save_figure(fig, path, *, description: str | None = None, **kwargs) -> Path:
    """Save a matplotlib figure as PNG atomically and close it.

    zlib level 3 instead of PIL's default 6: on a 1200 x 1272 scan overlay 0.39 s against
    1.24 s of encoding, for a file 12 % larger (a dimmed scan's noise compresses poorly).
    The PNG's text records the package version (``Software``) and ``description`` (what the
    figure was made from, e.g. the parameters) when given.
    """
    import matplotlib
    import matplotlib.pyplot as plt

    from crosssection._version import __version__

    kwargs.setdefault("dpi", SAVE_DPI)
    kwargs.setdefault("pil_kwargs", {"compress_level": 3})
    metadata = {"Software": f"foldstat {__version__} (matplotlib {matplotlib.__version__})"}
    if description:
        metadata["Description"] = description
    kwargs["metadata"] = {**metadata, **kwargs.get("metadata", {})}
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", **kwargs)
    plt.close(fig)
    return Path(path)


def write_npz(path, **arrays) -> Path:
    """Write a compressed ``.npz`` atomically."""
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez_compressed(tmp, **arrays)
    return Path(path)


def special_file_reason(path) -> str | None:
    """Why ``path`` is no file to read, for a named pipe, a socket or a device (reading a
    pipe blocks until something writes to it; reading /dev/zero or /dev/random never ends);
    None for a regular file, a folder or a path that does not exist (which their own checks
    name)."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    kind = ("a named pipe" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode)
            else "a device")
    return f"is {kind}, not a file (reading it may block or never end): give a file"


def read_toml(path) -> dict:
    """A TOML file as a dict; unreadable or invalid files are one ``ConfigError`` naming it.

    A UTF-8 byte-order mark (Windows' Notepad writes one) is skipped, as in the CSV files
    read."""
    import tomllib

    from crosssection.core.errors import ConfigError

    special = special_file_reason(path)
    if special:
        raise ConfigError(special, path)
    try:
        return tomllib.loads(Path(path).read_text(encoding="utf-8-sig"))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read: {exc}", path) from None


def read_json_object(path) -> dict:
    """A JSON file holding one object, as a dict; a missing, unreadable or malformed file, or
    one holding anything but an object, is one ``ConfigError`` naming it."""
    from crosssection.core.errors import ConfigError

    try:
        data = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError("file not found", path) from None
    except OSError as exc:
        raise ConfigError(f"cannot read ({exc.strerror or type(exc).__name__})", path) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"malformed JSON ({getattr(exc, 'msg', exc)})", path) from None
    if not isinstance(data, dict):
        raise ConfigError("must hold a JSON object", path)
    return data


def staging_folder(final) -> Path:
    """A new hidden folder beside ``final`` (``.<name>.partial-*``, the parent created) with
    the mode of an ordinary new folder, to write an output folder into before
    :func:`swap_in_folder`."""
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{final.name}{PARTIAL_TAG}", dir=final.parent))
    os.chmod(stage, 0o777 & ~UMASK)  # mkdtemp makes 0700, which would hide it from others
    return stage


def clear_stale_folders(final) -> None:
    """Remove the hidden working folders (and files) a killed run left beside ``final``."""
    final = Path(final)
    if final.parent.is_dir():
        for tag in (PARTIAL_TAG, OLD_TAG):
            for p in final.parent.glob(f".{final.name}{tag}*"):
                if p.is_dir():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)


#: The random part of a name from ``tempfile.mkstemp`` (``tempfile._RandomNameSequence``:
#: eight of lower-case letters, digits and underscores).
_MKSTEMP_RANDOM = "[a-z0-9_]{8}"


def own_file(name: str, own) -> bool:
    """Whether the file ``name`` is one of ``own`` or the leftover temporary file of an atomic
    write of one (``.<name>.<random><suffix>``, :func:`atomic_path`)."""
    return name in own or (name.startswith(".") and
                           any(name.startswith(f".{k}.") for k in own))


#: :func:`folder_lock`'s lock file inside the folder it locks, by the command's kind
INSIDE_LOCK = ".{}.lock"
#: the kinds of :func:`folder_lock` (their locks inside a folder belong to no one's output)
LOCK_KINDS = ("render", "simulation")


def foreign_entry(folder, files=(), folder_rule=None) -> str | None:
    """The first entry of ``folder``, in name order, that the command writing it does not
    write, or None: what every command that refuses an ``--out`` holding other files checks.

    Browser files (:data:`BROWSER_FILES`) and locks of a running command
    (:func:`folder_lock`) are nobody's. A file is the command's when
    :func:`own_file` of ``files`` says so. A subfolder (not a link) is judged by
    ``folder_rule``; without one every subfolder is foreign.

    Parameters
    ----------
    folder : str or Path
        An existing folder.
    files : collection of str
        The names of the files the command writes there.
    folder_rule : callable, optional
        ``folder_rule(path)`` of a subfolder: None when it is the command's, else the name
        (relative to ``folder``) of what in it is not.

    Returns
    -------
    str or None
    """
    locks = {INSIDE_LOCK.format(kind) for kind in LOCK_KINDS}
    for p in sorted(Path(folder).iterdir()):
        if p.name in BROWSER_FILES or p.name in locks:
            continue
        if p.is_dir() and not p.is_symlink():
            inner = p.name if folder_rule is None else folder_rule(p)
            if inner is None:
                continue
            return inner
        if p.is_file() and own_file(p.name, files):
            continue
        return p.name
    return None


def temporary_files(folder, names) -> list[Path]:
    """The temporary files that :func:`atomic_path` writes of ``names`` in ``folder``
    (``.<name>.XXXX<suffix>``): only a process killed while writing one leaves it behind.

    Parameters
    ----------
    folder : str or Path
    names : iterable of str
        File names (``index.csv``).

    Returns
    -------
    list of Path
        Sorted; empty when ``folder`` does not exist.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    found = set()
    for name in names:
        suffix = Path(name).suffix or ".tmp"
        # mkstemp's random part only: a user's own hidden file of the same stem stays
        pattern = re.compile(re.escape(f".{name}.") + _MKSTEMP_RANDOM + re.escape(suffix))
        found.update(p for p in folder.glob(f".{name}.*{suffix}")
                     if pattern.fullmatch(p.name) and p.is_file())
    return sorted(found)


def is_working_folder(name: str) -> bool:
    """Whether ``name`` is one of the hidden working folders of :func:`staging_folder` and
    :func:`swap_in_folder` (``.<name>.partial-*``, ``.<name>.old-*``)."""
    return name.startswith(".") and (PARTIAL_TAG in name or OLD_TAG in name)


def swap_in_folder(stage, final) -> None:
    """Rename ``stage`` to ``final``: a previous ``final`` is moved away first and deleted
    last, and put back if the second rename fails, so ``final`` is the old folder or the new
    one, never a mix."""
    stage, final = Path(stage), Path(final)
    if not final.exists():
        os.replace(stage, final)
        return
    old = Path(tempfile.mkdtemp(prefix=f".{final.name}{OLD_TAG}", dir=final.parent))
    os.replace(final, old / final.name)
    try:
        os.replace(stage, final)
    except BaseException:
        os.replace(old / final.name, final)
        shutil.rmtree(old, ignore_errors=True)
        raise
    try:
        shutil.rmtree(old)
    except (OSError, KeyboardInterrupt):
        # the new folder is complete and in place: what is left of the old one is a hidden
        # folder that the next run removes (clear_stale_folders), not a failure
        pass


def missing_file_reason(path) -> str:
    """Why ``path``, which does not exist, cannot be read: ``"file not found"``, a symbolic
    link to nothing (naming its target), or a loop of symbolic links."""
    import errno

    path = Path(path)
    try:
        os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "a loop of symbolic links (it leads back to itself)"
    if path.is_symlink():
        return f"symbolic link to {os.readlink(path)}, which cannot be found"
    return "file not found"


def png_with_chunks(data: bytes, chunks) -> bytes:
    """A PNG's bytes with ``chunks`` (``(type, data)`` pairs of bytes, each given its length
    and CRC) inserted right after its ``IHDR``, where ancillary chunks such as ``pHYs`` and
    ``tEXt`` may stand (before the image data)."""
    import struct
    import zlib

    extra = b"".join(struct.pack(">I", len(body)) + kind + body
                     + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
                     for kind, body in chunks)
    end_ihdr = 8 + 8 + 13 + 4  # signature, IHDR's length and type, its data, its CRC
    return data[:end_ihdr] + extra + data[end_ihdr:]


def lock_holds(path, token) -> bool:
    """Whether the lock file ``path`` still holds the run ``token`` (:func:`exclusive_lock`):
    False once that run has ended (the file removed) or another holds it. A task that
    outlives its run (a cluster's worker, still analysing when the batch was stopped) must
    not write into an output another run may be writing; True when ``token`` is None."""
    if token is None:
        return True
    try:
        with open(path, encoding="ascii", errors="replace") as f:
            return token in f.read(64).split()
    except OSError:
        return False


@contextmanager
def exclusive_lock(path, *, where, busy: str, unlocked=None):
    """Hold an exclusive lock on the file ``path`` (created, holding the process id and a
    token of this run) while one command writes an output; a second is refused.

    The lock is ``flock``, which the system releases when the process dies: a run killed
    (``kill -9``, out of memory) leaves a file that locks nothing, and its re-run goes on. A
    file system without locks (some network disks), or a platform without ``flock``, runs
    unlocked (``unlocked()`` is called then).

    Parameters
    ----------
    path : Path
        The lock file; its folder exists.
    where : str or Path
        What a refusal names (the output).
    busy : str
        The refusal's cause (``"another batch is writing into it"``).
    unlocked : callable, optional
        Called once when the file system takes no lock.

    Yields
    ------
    str or None
        The run's token, which :func:`lock_holds` checks (None without ``flock``).

    Raises
    ------
    ParameterError
        Another process holds the lock (named by its process id).
    OutputError
        The lock file cannot be created.
    """
    from crosssection.core.errors import ParameterError, output_error

    try:
        import fcntl
    except ImportError:
        yield None
        return
    path = Path(path)
    if path.is_symlink():
        # writing the process id through it would overwrite a file that is not the lock
        raise ParameterError(f"{path.name} is a symbolic link (to {os.readlink(path)}), not "
                             "the lock file: remove it", where)
    while True:
        try:
            # O_NOFOLLOW: a link put there between the check above and this call
            fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o666)
        except OSError as exc:
            raise output_error(exc, path) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            words = os.read(fd, 64).decode("ascii", "replace").split()
            holder = words[0] if words else ""
            os.close(fd)
            raise ParameterError(busy + (f" (pid {holder})" if holder.isdigit() else "")
                                 + ": wait for it to end, or give another --out",
                                 where) from None
        except OSError:
            # no locks on this file system (a network disk without a lock service)
            if unlocked is not None:
                unlocked()
            break
        # a run that ends removes the file it locked: a lock taken on that file, now
        # nameless, would lock nothing, so the file is opened afresh
        try:
            if os.fstat(fd).st_ino == os.stat(path).st_ino:
                break
        except OSError:
            pass
        os.close(fd)
    token = uuid.uuid4().hex
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} {token}\n".encode())
    except OSError:
        pass  # only a second run's message names the process id
    try:
        yield token
    finally:
        try:
            os.unlink(path)  # before the lock is released (see above)
        except OSError:
            pass
        os.close(fd)


@contextmanager
def folder_lock(out, kind: str, *, where, busy: str, unlocked=None):
    """Hold :func:`exclusive_lock` on ``.<name>.<kind>.lock`` beside the output folder
    ``out`` while one command writes it, so that a second run into it is refused before it
    reads what the first is writing.

    The lock lies beside the folder, not in it: it is taken before the folder is checked or
    made, and a folder holding only a command's own files stays so. Where the parent takes
    no file (read-only), it lies in the folder (:data:`INSIDE_LOCK`, no one's entry for
    :func:`foreign_entry`). A folder that neither holds (a new folder under a read-only or
    missing parent, which the command names in its own words) is written unlocked.

    Parameters
    ----------
    out : str or Path
        The output folder.
    kind : str
        The command's kind, in the lock's name (``"render"``, ``"simulation"``).
    where : str or Path
        What a refusal names (the output as given).
    busy : str
        The refusal's cause.
    unlocked : callable, optional
        Called once when the file system takes no lock (:func:`exclusive_lock`).

    Yields
    ------
    str or None
        The run's token (None when unlocked).

    Raises
    ------
    ParameterError
        Another run holds the lock (named by its process id).
    """
    from contextlib import ExitStack

    from crosssection.core.errors import OutputError

    out = Path(out).expanduser().resolve()
    with ExitStack() as held:
        token = None
        # inside the folder where its parent takes no file (read-only): both runs into one
        # folder meet the same parent, so they take the same place
        for place in (out.parent / f".{out.name}.{kind}.lock", out / INSIDE_LOCK.format(kind)):
            if not place.parent.is_dir():
                continue
            try:
                token = held.enter_context(exclusive_lock(place, where=where, busy=busy,
                                                          unlocked=unlocked))
                break
            except OutputError:
                continue
        yield token
