"""The records that mark a folder as the output of a foldstat command.

``batch``, ``stats``, ``analyze``, ``steps``, ``render`` and ``validate`` write a JSON record at
the top of their output folder, and a simulation (``quench``, ``anneal``, ``compact``) its
``configs.csv``. Three commands read that mark: ``batch`` does not search such a folder for
scans (its figures are not scans), ``analyze`` and ``steps`` do not write into another
command's output, and ``samples`` does not copy scans into one.

A file of a record's name that another tool wrote (a scanner's ``summary.json`` with a
``version`` of its own) marks nothing: each record is known by keys only foldstat writes
together.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

#: (file, command, keys the record holds, and values some of them must have), in the order
#: they are looked for: a validate report's summary.json is told from an analysis' by its keys
RECORDS = (
    ("batch.json", "foldstat batch", {"package": "foldstat", "version": None}),
    ("stats.json", "foldstat stats", {"package": "foldstat", "version": None}),
    ("summary.json", "foldstat analyze", {"version": None, "parameters": None}),
    ("summary.json", "foldstat validate", {"package": "foldstat", "version": None,
                                           "scenes_dir": None}),
    ("steps.json", "foldstat steps", {"command": "steps", "version": None,
                                      "parameters": None}),
    ("render.json", "foldstat render", {"command": "render", "version": None}),
)
#: the table a simulation (quench, anneal, compact) writes at the top of its output folder
SIMULATION_TABLE = "configs.csv"
#: the keys of the ``params.json`` beside a simulation's table: a ``configs.csv`` alone may be
#: a user's own table beside their scans (``batch`` would skip them)
SIMULATION_KEYS = ("command", "n_configs", "seed")
#: the largest file read as a record: foldstat's are kilobytes; a file of megabytes of that
#: name is someone else's, and would be read whole for every folder a batch searches
RECORD_MAX_BYTES = 4 << 20


def read_record(path, keys) -> dict | None:
    """The record foldstat wrote at ``path``: a JSON object holding ``keys``, else None.

    Parameters
    ----------
    path : str or Path
    keys : iterable of str, or mapping of str to a value or None
        The keys the record holds; where a mapping gives a value, the key holds that value.

    Returns
    -------
    dict or None
        None too for anything but a regular file of at most :data:`RECORD_MAX_BYTES` (a
        named pipe would block the read).
    """
    import stat

    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_size > RECORD_MAX_BYTES:
            return None
        record = json.loads(Path(path).read_bytes())
    except (OSError, ValueError, RecursionError):
        return None
    if not isinstance(record, dict):
        return None
    wanted = keys if isinstance(keys, dict) else dict.fromkeys(keys)
    if all(k in record and (v is None or record[k] == v) for k, v in wanted.items()):
        return record
    return None


def is_record(path, keys) -> bool:
    """Whether ``path`` is a record foldstat wrote (:func:`read_record`)."""
    return read_record(path, keys) is not None


def output_of(folder) -> tuple[str, str] | None:
    """The command whose output ``folder`` is, by the record it holds.

    Parameters
    ----------
    folder : str or Path

    Returns
    -------
    (str, str) or None
        The record's file name and the command (``"foldstat batch"``, ...; ``"a
        simulation"`` for a folder with ``configs.csv`` and a simulation's ``params.json``),
        or None for any other folder.
    """
    folder = Path(folder).expanduser()
    for name, command, keys in RECORDS:
        if is_record(folder / name, keys):
            return name, command
    if _is_file(folder / SIMULATION_TABLE) and is_record(folder / "params.json",
                                                         SIMULATION_KEYS):
        return SIMULATION_TABLE, "a simulation"
    return None


def _is_file(path: Path) -> bool:
    """Whether ``path`` is a file; False too where it cannot be looked at (a folder without
    read or search permission), which then holds no record this reader could use."""
    try:
        return path.is_file()
    except OSError:
        return False
