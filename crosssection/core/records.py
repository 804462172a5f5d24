"""The records that mark a folder as the output of a foldstat command.

Every command writes one record at the top of its output folder. Three commands read that
mark: ``batch`` does not search such a folder for scans (its figures are not scans),
``analyze`` and ``steps`` do not write into another command's output, and ``samples`` does
not copy scans into one.
"""
from __future__ import annotations

import json
from pathlib import Path

#: the record each command writes at the top of its output folder, and the command
RECORDS = {"batch.json": "foldstat batch", "stats.json": "foldstat stats",
           "summary.json": "foldstat analyze", "steps.json": "foldstat steps"}
#: the table a simulation (quench, anneal, compact) writes at the top of its output folder
SIMULATION_TABLE = "configs.csv"


def is_record(path, keys=("version",)) -> bool:
    """Whether ``path`` is a record foldstat wrote: a JSON object holding ``keys``.

    A file of the same name that is not one (a user's own notes) marks nothing.
    """
    try:
        record = json.loads(Path(path).read_bytes())
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(record, dict) and all(k in record for k in keys)


def output_of(folder) -> tuple[str, str] | None:
    """The command whose output ``folder`` is, by the record it holds.

    Parameters
    ----------
    folder : str or Path

    Returns
    -------
    (str, str) or None
        The record's file name and the command (``"foldstat batch"``, ...; ``"a
        simulation"`` for a folder with ``configs.csv``), or None for any other folder.
    """
    folder = Path(folder).expanduser()
    for name, command in RECORDS.items():
        if is_record(folder / name):
            return name, command
    if (folder / SIMULATION_TABLE).is_file():
        return SIMULATION_TABLE, "a simulation"
    return None
