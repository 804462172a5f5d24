"""The on-disk table schema shared by the pipeline output and the simulator's ground truth.

External checks read these names; more columns may be appended, never renamed. ``simulate``
imports this module so that its ``truth/`` folders compare column by column with
``python -m crosssection analyze`` output.

Conventions
-----------
- Pixel coordinates are (row, col) internally; CSV columns say ``x_px`` (column) and
  ``y_px`` (row).
- ``junction_a`` / ``junction_b`` of a stack are junction ids, or ``-1`` for a free rod end,
  a closed loop without any junction, or a layer step (the stack's ``kind`` column says
  which: ``"free_end"``, ``"loop"`` or ``"step"``, where its band's layer count steps with
  no junction, :func:`crosssection.stages.widths.layer_steps`).
- ``region`` is ``"bulk"`` or ``"periphery"`` (paper, section "Two sub-systems").
- Curvatures are in 1/mm, lengths in mm, areas in mm^2; ``energy`` is dimensionless,
  e = L * integral(kappa^2 ds) with L the rod length (paper, section "Energetical properties").
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from crosssection.core.errors import ConfigError, why_unreadable
from crosssection.core.fileio import read_json_object, write_csv, write_json

#: The file suffixes of the scans ``batch`` finds in a folder (any case); ``analyze`` reads the
#: same formats (:mod:`crosssection.stages.load`, which tells them by content)
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".webp")
#: The formats in words, for help texts
IMAGE_FORMATS = "PNG, TIFF, JPEG, BMP or WebP; 8 or 16 bits per channel, or float TIFF"

JUNCTION_COLUMNS = ["junction_id", "x_px", "y_px", "n_stacks"]
STACK_COLUMNS = ["stack_id", "junction_a", "junction_b", "length_mm", "width_mm", "n_br",
                 "region", "mid_x_px", "mid_y_px"]
BRANCH_COLUMNS = ["branch_id", "stack_id", "length_mm", "kappa_pm", "kappa_plus", "kappa_m",
                  "energy", "region"]
VOID_COLUMNS = ["void_id", "area_mm2", "perimeter_mm", "shape_ratio", "n_edges",
                "centroid_x_px", "centroid_y_px"]
SUMMARY_KEYS = ["n_junctions", "n_stacks", "n_branches", "n_voids", "mean_branches_per_stack",
                "rod_length_mm", "epsilon", "total_energy", "hole", "timings_s"]
#: Keys with which an analysis' ``summary.json`` (not a truth's) records what it was computed
#: from (:func:`crosssection.tables.summary`): the parameters used (derived defaults
#: resolved, accepted back by ``AnalysisParams``), the package and library versions, the
#: scan (path absolute with links followed, size, dtype) and ``inputs`` (scan and calibration
#: by path as given, path resolved and SHA-256, the calibration's widths:
#: :func:`crosssection.core.provenance.input_record`).
PROVENANCE_KEYS = ["parameters", "calibration", "version", "libraries", "image", "inputs"]
HOLE_KEYS = ["center_x_px", "center_y_px", "radius_px"]

TABLES = {
    "junctions": JUNCTION_COLUMNS,
    "stacks": STACK_COLUMNS,
    "branches": BRANCH_COLUMNS,
    "voids": VOID_COLUMNS,
}
NO_JUNCTION = -1


def empty_table(name: str) -> pd.DataFrame:
    """An empty DataFrame with the required columns of table ``name``."""
    return pd.DataFrame({c: pd.Series(dtype=object) for c in TABLES[name]})


def check_table(name: str, df: pd.DataFrame) -> pd.DataFrame:
    """Return ``df`` with the required columns first; raise ``ValueError`` if one is missing."""
    required = TABLES[name]
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise ValueError(f"table {name!r} lacks columns {missing}")
    extra = [c for c in df.columns if c not in required]
    return df[required + extra]


def write_tables(out_dir, summary: dict, tables: dict[str, pd.DataFrame]) -> dict[str, Path]:
    """Write ``summary.json`` and the four CSV tables into ``out_dir`` atomically.

    Parameters
    ----------
    out_dir : str or Path
        Destination folder (created).
    summary : dict
        Must contain the keys of :data:`SUMMARY_KEYS`.
    tables : dict of DataFrame
        ``junctions``, ``stacks``, ``branches``, ``voids``.

    Returns
    -------
    dict
        Name -> written path.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    missing = [k for k in SUMMARY_KEYS if k not in summary]
    if missing:
        raise ValueError(f"summary lacks keys {missing}")
    paths = {}
    for name in TABLES:
        df = tables.get(name)
        df = empty_table(name) if df is None else check_table(name, df)
        paths[name] = write_csv(out / f"{name}.csv", df)
    # summary last: its presence marks a complete output folder (used to resume batches)
    paths["summary"] = write_json(out / "summary.json", summary)
    return paths


def read_table(path, name: str) -> pd.DataFrame:
    """Read one CSV table written by :func:`write_tables`, checked against the schema.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    name : str
        Its table in :data:`TABLES` (``"junctions"``, ``"stacks"``, ``"branches"``,
        ``"voids"``).

    Returns
    -------
    DataFrame
        The table, its required columns first (:func:`check_table`).

    Raises
    ------
    ConfigError
        Naming ``path``: the file is missing, unreadable, empty or malformed, or lacks one of
        the columns of ``TABLES[name]``.
    """
    required = TABLES[name]
    try:
        df = pd.read_csv(path)
    except FileNotFoundError:
        raise ConfigError("file not found", path) from None
    except pd.errors.EmptyDataError:
        raise ConfigError("empty file (no header line)", path) from None
    except OSError as exc:
        raise ConfigError(f"cannot read ({exc.strerror or type(exc).__name__})",
                          path) from None
    except ValueError as exc:  # parser and decoding errors
        raise ConfigError(f"malformed CSV ({why_unreadable(exc)})", path) from None
    missing = [c for c in required if c not in df.columns]
    if len(missing) == len(required):
        # no column of the schema: most likely another file under this name
        raise ConfigError(f"not a {name} table (expected the header {','.join(required)})",
                          path)
    if missing:
        raise ConfigError(f"lacks column(s) {', '.join(missing)}", path)
    return check_table(name, df)


def read_tables(folder) -> tuple[dict, dict[str, pd.DataFrame]]:
    """Read ``summary.json`` and the four tables written by :func:`write_tables`.

    Parameters
    ----------
    folder : str or Path
        An ``analyze`` output folder or a scene's ``truth/`` folder.

    Returns
    -------
    (summary, tables) : (dict, dict of DataFrame)
        The summary, and each table of :data:`TABLES` with its required columns first.

    Raises
    ------
    ConfigError
        Naming the file: ``summary.json`` is missing, unreadable or not a JSON object, or a
        table is missing, unreadable, malformed or lacks a column (:func:`read_table`).
    """
    folder = Path(folder)
    summary = read_json_object(folder / "summary.json")
    tables = {name: read_table(folder / f"{name}.csv", name) for name in TABLES}
    return summary, tables
