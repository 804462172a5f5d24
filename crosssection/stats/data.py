"""Read batch outputs, single analyze outputs and simulation ensembles into one long format.

Three kinds of input folders are detected automatically:

- a simulation ensemble (``configs.csv`` + ``branches.csv`` + ``voids.csv``, from
  ``python -m simulate quench``, ``anneal`` or ``compact``): lengths already in units of L,
  one set;
- a single ``analyze`` output (``summary.json`` + the schema tables): one configuration;
- a batch output (``index.csv``, ``batch.json`` and/or per-image folders
  ``<set>/<stem>/summary.json``): the set is the one ``index.csv`` records for each image,
  else its summary's ``batch.set``, else its first folder level under the batch root (the
  folder name when images sit directly under it; :func:`load_batch`). The ``truth/`` folder of a generated
  scene (beside its ``params.json``, :mod:`crosssection.truth.scene`) holds the same tables
  but is no analysis; a folder of scans is refused (``foldstat batch`` reads those).

Image lengths are in mm (schema.py) and are normalised by each image's rod length L
(paper, section "Experimental set-up": lengths become independent of the cut position once
divided by L); areas by L^2; curvatures times L. L is the one the analysis used for its
energies e = L int kappa^2 ds, E and epsilon: ``summary["rod_length_used_mm"]`` (the
``--rod-length-mm`` given to ``analyze``, else the measured ``sum n_br l``), or
``summary["rod_length_mm"]`` (measured) in outputs that do not record it, so that every
quantity of a scan is in units of the same L.

Common representation (:class:`Ensemble`):

- ``configs``: set, config_id, N_l, N_br, n_voids (the configuration's stacks, branches and
  voids: the rows of its tables, also for a scan whose tables hold another number than its
  summary.json counts, so that every count of a scan has one source), epsilon, E,
  rod_length_mm (the L of the normalisation, in mm; NaN for simulations), source,
  quality (the image analysis' quality warning codes joined by ";", "" when none; NaN for
  simulations), E_model_share (the analysis' ``total_energy_rel_uncertainty``: the share of E
  not measured on a free centreline; NaN for simulations), input (the folder given to
  :func:`load_inputs` it was read from, as given; NaN from the other loaders),
  l_min_mm_analysis and s_min_mm2_analysis (the detection limits the scan's analysis pruned
  and filled at, from its summary.json; NaN for simulations), analysis (JSON text
  ``{"version": ..., "parameters": {...}}``: what made the configuration, from the
  analysis' summary.json or the simulation's params.json; NaN when unknown), batch_note (why
  the configuration's batch or simulation ensemble is incomplete: images its batch did not
  finish or could not analyse, configurations whose simulation failed; "" when none),
  table_note (a scan's tables holding another number of rows than its summary.json counts,
  "" when they agree)
- ``branches``: set, config_id, length_L, kappa_m_L, kappa_plus_L, e, region, n_br (of the
  branch's stack, NaN if unknown), l_min_L (detection limit in units of L, NaN if none),
  stack_id (the branch's stack within its configuration, for scans: a scan gives every
  branch of a stack the stack's length, curvature and energy, so the fits treat the
  branches of one (set, config_id, stack_id) as one independent value,
  :func:`branch_groups`; NaN where each branch is its own: simulations, whose branches
  have their own lengths, and tables that do not say; optional in a hand-built ensemble)

Detection limits: by default an image's are those its analysis used (``l_min_mm`` and
``s_min_mm2`` of the parameters in its summary.json), since below them the analysis pruned
branches and filled voids; a limit given explicitly wins (:data:`RECORDED` is the default
that reads them). Simulations have none.

:class:`Ensemble` checks its tables on construction: a missing column or an identifier
column of another type than text is a ParameterError naming the table and the column
(integer identifiers, as simulations write them, are turned into text).
- ``stacks``: set, config_id, n_br, length_L, region
- ``voids``: set, config_id, area_L2, perimeter_L, shape_ratio, n_edges, s_min_L2
"""
from __future__ import annotations

import csv
import io
import json
import math
import os
import reprlib
import warnings
from collections import Counter
from dataclasses import dataclass
from numbers import Real
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.errors import ConfigError, ParameterError, why_unreadable
from crosssection.params import AnalysisParams
from crosssection.quality import QualityWarning

CONFIG_COLS = ["set", "config_id", "N_l", "N_br", "n_voids", "epsilon", "E", "rod_length_mm",
               "source", "quality", "E_model_share", "input", "l_min_mm_analysis",
               "s_min_mm2_analysis", "analysis", "batch_note", "table_note"]
#: the cause of the error of a table an output should hold and does not
MISSING_TABLE = "missing table"
#: configs columns that a hand-built ensemble may leave out (NaN: unknown)
OPTIONAL_CONFIG_COLS = ("rod_length_mm", "source", "quality", "E_model_share", "input",
                        "l_min_mm_analysis", "s_min_mm2_analysis", "analysis", "batch_note",
                        "table_note")
BRANCH_COLS = ["set", "config_id", "length_L", "kappa_m_L", "kappa_plus_L", "e", "region",
               "n_br", "l_min_L", "stack_id"]
#: branches columns that a hand-built ensemble may leave out (NaN: each branch its own
#: stack, see :func:`branch_groups`)
OPTIONAL_BRANCH_COLS = ("stack_id",)
STACK_COLS = ["set", "config_id", "n_br", "length_L", "region"]
VOID_COLS = ["set", "config_id", "area_L2", "perimeter_L", "shape_ratio", "n_edges", "s_min_L2"]
#: Default detection limits of image data: the analysis' own (paper: branches shorter than
#: l_min = 1 mm pruned, voids below s_min = (10 h)^2 = 1 mm^2 filled at h = 0.1 mm)
L_MIN_MM = AnalysisParams().l_min_mm
S_MIN_MM2 = AnalysisParams().s_min_used_mm2
#: default of the loaders' ``l_min_mm`` and ``s_min_mm2``: the limits each scan's analysis
#: recorded in its summary.json
RECORDED = "recorded"
SIM_REGION = "none"  # quench and anneal have no wall: no bulk/periphery split (paper, "Two sub-systems"); compact writes its own regions
TEXT_COLS = {"set", "config_id", "region", "source", "quality", "input", "analysis",
             "batch_note", "table_note"}
ID_COLS = ("set", "config_id")


class DetectionLimitWarning(QualityWarning):
    """A detection limit given to the statistics lies below the one the analysis of the
    scans used: the values between the two are missing from the data, not rare, and the
    fits truncated at the lower limit are biased; or a limit given for a simulation, whose
    lengths have no scale in mm, is not applied to it."""


class FlaggedScanWarning(QualityWarning):
    """A scan whose analysis raised quality flags (``quality.ok`` false in its
    summary.json) enters the statistics."""


class DuplicateScanWarning(QualityWarning):
    """Two scans of a batch hold the same bytes (the same SHA-256 in their summary.json):
    one cut analysed twice under two names weighs twice in the statistics."""


class HairpinNodesWarning(QualityWarning):
    """Configurations of a simulation ensemble fold back at a single node (``n_hairpin_nodes``
    of its configs.csv): the discrete rod caps such a fold's bending at ``4 / ds``, and the
    branches holding it, whose energies are that cap, enter the statistics."""


class MixedParametersWarning(QualityWarning):
    """The configurations of one set were made with different analysis (or simulation)
    parameters, beyond those each scan has its own of (its hole, its rod length, its
    calibration file): their statistics are pooled although they were not measured alike."""


#: parameters each scan of a set may have its own of (``[images]`` of its set.toml): a set
#: differing in these alone is one measurement
PER_SCAN_PARAMETERS = ("hole_radius_mm", "hole_center_px", "hole_given", "rod_length_mm",
                       "calibration")


class IncompleteBatchWarning(QualityWarning):
    """A batch output that did not finish, or that could not analyse some of its images
    (``failures.csv``), or a simulation ensemble some of whose configurations failed (a
    ``configs.csv`` row with an ``error``): its statistics are those of the images or
    configurations done."""


def _text(name: str) -> str:
    """A file or folder name as text: bytes that are not UTF-8 (kept by the system as
    surrogates) become U+FFFD, so that a set or configuration named after them can be
    written into the report's tables."""
    return name.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


def _folder(folder, name: str = "folder") -> Path:
    """``folder`` as a Path, or a ParameterError naming ``name`` when it is no path (None, a
    number) or an empty string (which would read the working folder)."""
    if isinstance(folder, (str, os.PathLike)) and not isinstance(folder, bytes):
        path = Path(folder)
        if str(folder) == "":
            raise ParameterError(f"{name} is an empty string, not a folder")
        return path
    raise ParameterError(f"{name} must be a folder path (str or pathlib.Path), got "
                         f"{reprlib.repr(folder)}")


def _limit(value, name: str):
    """A detection limit: :data:`RECORDED`, None, or a finite number >= 0 (0 = none)."""
    if value is None or (isinstance(value, str) and value == RECORDED):
        return value
    if (isinstance(value, (bool, np.bool_)) or not isinstance(value, Real)
            or not (math.isfinite(value) and value >= 0)):
        raise ParameterError(f"{name} must be None or a finite number >= 0 (0 = no limit) "
                             f"or {RECORDED!r}, got {reprlib.repr(value)}")
    return value


def _set_name(value, name: str = "set_name", *, required: bool = False):
    """A set name or configuration id: a string (or None where it is optional)."""
    if value is None and not required:
        return None
    if not isinstance(value, str):
        raise ParameterError(f"{name} must be a string, got {reprlib.repr(value)}")
    return value


def _numeric(df: pd.DataFrame, cols) -> pd.DataFrame:
    """``df`` whose numeric columns among ``cols`` hold numbers: an empty table (a scan
    without voids gives a header-only ``voids.csv``) reads as object columns, on which
    numpy functions such as ``sqrt`` fail."""
    bad = [c for c in cols if c in df.columns and c not in TEXT_COLS and df[c].dtype == object]
    if not bad:
        return df
    df = df.copy()
    for c in bad:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype(float)
    return df


@dataclass
class Ensemble:
    """Long-format tables of one or more sets (see module docstring for the columns)."""

    configs: pd.DataFrame
    branches: pd.DataFrame
    stacks: pd.DataFrame
    voids: pd.DataFrame

    @property
    def sets(self) -> list[str]:
        """Set names in order of first appearance."""
        return list(dict.fromkeys(self.configs["set"].tolist()))

    def subset(self, name: str) -> "Ensemble":
        """The tables of one set."""
        return Ensemble(*(df[df["set"] == name].reset_index(drop=True)
                          for df in (self.configs, self.branches, self.stacks, self.voids)))

    @staticmethod
    def concat(parts) -> "Ensemble":
        """Concatenate ensembles (sets must have distinct names)."""
        parts = list(parts)
        cat = lambda name, cols: pd.concat(  # noqa: E731
            [getattr(p, name) for p in parts] or [pd.DataFrame(columns=cols)],
            ignore_index=True).reindex(columns=cols)
        return Ensemble(cat("configs", CONFIG_COLS), cat("branches", BRANCH_COLS),
                        cat("stacks", STACK_COLS), cat("voids", VOID_COLS))

    def __post_init__(self):
        self.configs = _numeric(_checked_table(self.configs, "configs", CONFIG_COLS,
                                               OPTIONAL_CONFIG_COLS), CONFIG_COLS)
        self.branches = _numeric(_checked_table(self.branches, "branches", BRANCH_COLS,
                                                OPTIONAL_BRANCH_COLS), BRANCH_COLS)
        self.stacks = _numeric(_checked_table(self.stacks, "stacks", STACK_COLS), STACK_COLS)
        self.voids = _numeric(_checked_table(self.voids, "voids", VOID_COLS), VOID_COLS)


def branch_groups(branches: pd.DataFrame) -> np.ndarray:
    """The stack of each branch as a group label for the fits (``groups`` of
    :func:`crosssection.stats.fits.fit_all`).

    Parameters
    ----------
    branches : pandas.DataFrame
        Rows of :attr:`Ensemble.branches` (set, config_id and, optionally, stack_id).

    Returns
    -------
    numpy.ndarray
        One label per row, object dtype: the tuple (set, config_id, stack_id) where
        stack_id is known (the branches of a scan's stack share one value), None where it
        is not (a group of its own: simulations, hand-built tables without the column).
    """
    n = len(branches)
    if "stack_id" not in branches.columns or n == 0:
        return np.full(n, None, dtype=object)
    sid = pd.to_numeric(branches["stack_id"], errors="coerce").to_numpy(float)
    sets = branches["set"].astype(str).to_numpy()
    cids = branches["config_id"].astype(str).to_numpy()
    out = np.full(n, None, dtype=object)
    for i in np.flatnonzero(np.isfinite(sid)):
        # the same stack number in two scans (or sets) is two stacks
        out[i] = (sets[i], cids[i], float(sid[i]))
    return out


def _checked_table(df, table: str, cols, optional=()) -> pd.DataFrame:
    """``df`` as a table of :class:`Ensemble`: every column of ``cols`` present (those of
    ``optional`` added as unknown), the identifiers as text.

    A table without any column (``pd.DataFrame()``) is an empty one. Integer identifiers (as
    the simulations' CSV files hold them) become text, so that tables join on them.

    Raises
    ------
    ParameterError
        ``df`` is no DataFrame, lacks a column, or holds identifiers that are neither text
        nor integers.
    """
    if not isinstance(df, pd.DataFrame):
        raise ParameterError(f"Ensemble.{table} must be a pandas DataFrame, got "
                             f"{type(df).__name__}")
    if df.empty and len(df.columns) == 0:
        return pd.DataFrame({c: pd.Series(dtype=object if c in TEXT_COLS else float)
                             for c in cols})
    missing = [c for c in cols if c not in df.columns and c not in optional]
    if missing:
        raise ParameterError(f"Ensemble.{table} lacks column(s) {missing} (columns "
                             f"{list(cols)}; see crosssection.stats.data)")
    df = df.reindex(columns=list(df.columns) + [c for c in cols if c not in df.columns])
    for c in ID_COLS:
        col = df[c]
        if col.dtype.kind in "iu":
            df[c] = col.astype(str)
        elif col.dtype.kind == "f" and col.dropna().map(float.is_integer).all():
            # an integer column with a missing value reads as floats: 3.0 is the id "3"
            df[c] = col.map(lambda v: v if pd.isna(v) else str(int(v)))
        elif col.dtype.kind not in "OSUT" or not all(
                isinstance(v, str) for v in col.dropna()):
            bad = next((v for v in col.dropna() if not isinstance(v, str)), None)
            raise ParameterError(f"Ensemble.{table} column {c!r} must hold text or integer "
                                 f"identifiers, got {col.dtype} ({reprlib.repr(bad)})")
    return df


def _cut_last_line(path: Path, n_columns: int) -> bool:
    """Whether a CSV file's last line was cut: no newline after it, and fewer fields than
    the header's ``n_columns`` (a table edited by hand may lack the final newline alone)."""
    import csv

    try:
        with open(path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            size = fh.tell()
            if size == 0:
                return False
            fh.seek(max(0, size - 65536))
            tail = fh.read()
    except OSError:
        return False
    if tail.endswith((b"\n", b"\r")):
        return False
    last = tail.rsplit(b"\n", 1)[-1].decode("utf-8", "replace")
    return len(next(csv.reader([last]), [])) < n_columns


def _read_csv(path: Path, required, *, numeric=(), nonempty: bool = False) -> pd.DataFrame:
    """A table with its ``required`` columns, and its ``numeric`` columns (those present) as
    floats.

    Raises
    ------
    ConfigError
        The file is missing or unreadable, lacks a required column, holds no row while
        ``nonempty``, or holds text in a numeric column (an empty cell is a missing value).
    """
    try:
        df = pd.read_csv(path)
    except FileNotFoundError:
        raise ConfigError(MISSING_TABLE, path) from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError,
            OSError) as exc:
        raise ConfigError(f"unreadable CSV ({why_unreadable(exc)})", path) from None
    if len(df) and _cut_last_line(path, len(df.columns)):
        # a last line short of fields and of its newline was cut while written (a full disk,
        # a copy stopped): no row
        df = df.iloc[:-1]
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise ConfigError(f"lacks columns {missing}", path)
    if nonempty and df.empty:
        raise ConfigError("holds no rows (header only)", path)
    for c in numeric:
        if c in df.columns:
            df[c] = _numbers(df[c], c, path)
    return df


#: the values a column of the tables read here can hold: (least value, whole numbers only).
#: A value outside, as a hand edit leaves, would enter the means of macro.csv and micro.csv
#: (the fits leave out values <= 0, the means did not): the table is refused instead
DOMAINS = {
    **dict.fromkeys(("length", "length_mm", "perimeter", "perimeter_mm", "area", "area_mm2",
                     "energy", "energy_total", "kappa_plus", "kappa_m", "epsilon",
                     "shape_ratio"), (0.0, False)),
    **dict.fromkeys(("n_stacks", "n_branches", "n_voids", "n_edges"), (0.0, True)),
    "n_br": (1.0, True),
}


def _numbers(col: pd.Series, name: str, path: Path) -> pd.Series:
    """``col`` as floats; a cell that is not a number, or a number outside the column's
    :data:`DOMAINS`, is a ``ConfigError`` naming the column, the cell and its row (1 = the
    first row under the header)."""
    if col.dtype.kind in "biuf":
        num = col.astype(float)
    else:
        num = pd.to_numeric(col, errors="coerce")
        bad = num.isna() & col.notna()
        if bad.any():
            pos = int(np.argmax(bad.to_numpy()))
            raise ConfigError(f"column {name} holds {str(col.iloc[pos])!r} in data row "
                              f"{pos + 1} where a number is expected", path)
        num = num.astype(float)
    if name in DOMAINS:
        least, whole = DOMAINS[name]
        v = num.to_numpy()
        with np.errstate(invalid="ignore"):  # an empty cell (NaN) is a missing value
            bad = (v < least) | np.isinf(v) | ((np.isfinite(v) & (v != np.round(v)))
                                               if whole else False)
        if bad.any():
            pos = int(np.argmax(bad))
            kind = "a finite whole number" if whole else "a finite number"
            raise ConfigError(f"column {name} holds {v[pos]:g} in data row {pos + 1} where "
                              f"{kind} >= {least:g} is expected", path)
    return num


#: summary.json entries read as numbers (null stands for unknown)
SUMMARY_NUMBERS = ("rod_length_mm", "rod_length_used_mm", "n_stacks", "n_branches", "n_voids",
                   "epsilon",
                   "total_energy", "total_energy_rel_uncertainty")


def _read_summary(path: Path) -> dict:
    """``summary.json`` of an ``analyze`` output, checked for the entries read here.

    Raises
    ------
    ConfigError
        The file is unreadable, is not a JSON object, or an entry has the wrong type.
    """
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"unreadable summary.json ({why_unreadable(exc)})", path) from None
    if not isinstance(summary, dict):
        raise ConfigError(f"holds a JSON {_json_kind(summary)}, not an object", path)
    for key in SUMMARY_NUMBERS:
        v = summary.get(key)
        # bool is an int in Python, but true/false is no count nor length
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
            raise ConfigError(f"{key} is {json.dumps(v)}, not a number", path)
    quality = summary.get("quality")
    codes = quality.get("codes", []) if isinstance(quality, dict) else None
    if quality is not None and not (isinstance(codes, list)
                                    and all(isinstance(c, str) for c in codes)):
        raise ConfigError("quality is not an object with a list of codes", path)
    return summary


def _json_kind(value) -> str:
    return {list: "list", str: "string", bool: "boolean", int: "number", float: "number",
            type(None): "null"}.get(type(value), type(value).__name__)


def _is_scene_truth(folder: Path) -> bool:
    """Whether ``folder`` is the ``truth/`` of a generated scene (a scene folder holds
    ``params.json`` and ``truth/``, :mod:`crosssection.truth.scene`): the exact tables of a
    generated scan, written like an analysis output but not one."""
    return folder.name == "truth" and (folder.parent / "params.json").is_file()


def _analysis_summaries(folder: Path, *, hidden: bool = False):
    """Every ``summary.json`` of an analysis output below ``folder`` (an iterator): not those
    of generated scenes' truth, nor, unless ``hidden``, those in hidden folders (the batch's
    ``.<stem>.partial-*`` staging folders of interrupted runs)."""
    for summ in folder.glob("**/summary.json"):
        rel = summ.parent.relative_to(folder)
        if not hidden and any(part.startswith(".") for part in rel.parts):
            continue
        if not _is_scene_truth(summ.parent):
            yield summ


def _validation_report(folder: Path) -> ConfigError | None:
    """The error for the report folder of ``simulate validate`` (``scores.csv`` beside its
    ``summary.json`` of means over scenes), which holds a summary.json but no analysis; None
    for any other folder."""
    if not ((folder / "scores.csv").is_file() and (folder / "summary.json").is_file()):
        return None
    return ConfigError("is a validation report (scores.csv, summary.json of simulate "
                       "validate), not an analysis output: give stats the analyze or batch "
                       "outputs, or read the report's scores.csv", folder)


def _not_an_output(folder: Path) -> ConfigError:
    """The error for a folder holding no foldstat output, saying what it holds instead
    when that is scans or generated scenes (a common mix-up: the input of ``batch``)."""
    # imported here: only this error needs the batch's idea of a scan and of an output
    from crosssection.batch import find_images
    from crosssection.core.records import output_of

    if (folder / "parts").is_dir() and (folder / "params.json").is_file():
        return ConfigError("an unfinished simulation (its params.json and parts/, no "
                           "configs.csv yet): re-run the command that made it to finish it",
                           folder)
    made_by = output_of(folder)
    if made_by is not None and made_by[1] == "foldstat steps":
        return ConfigError("holds the step images of foldstat steps (steps.json), not an "
                           "analysis: run foldstat analyze or batch on the scan", folder)
    scans = find_images(folder)
    if scans:
        return ConfigError(f"holds {len(scans)} scan(s) ({scans[0].name}, ...), not analysis "
                           "outputs: run foldstat batch on it first and load the batch's "
                           "output", folder)
    if any(_is_scene_truth(t.parent) for t in folder.glob("**/truth/summary.json")):
        return ConfigError("holds the truth of generated scenes (truth/ beside params.json), "
                           "not analysis outputs: run foldstat batch on the scans first",
                           folder)
    return ConfigError("neither a batch output (index.csv, batch.json, */summary.json), an "
                       "analyze output (summary.json) nor a simulation ensemble "
                       "(configs.csv)", folder)


def detect_kind(folder) -> str:
    """``"simulation"``, ``"image"`` (one analyze output) or ``"batch"``.

    A batch is recognised by foldstat's own files: its ``index.csv`` or ``batch.json``, or
    else the ``summary.json`` of analysis outputs below the folder. The ``truth/`` folders of
    generated scenes (such as the sample scans' ``scenes/*/truth``) hold the same tables but
    are no analysis: they do not make a batch.

    Raises
    ------
    ParameterError
        ``folder`` is not a path.
    ConfigError
        When the folder holds none of them (a folder of scans, of generated scenes, or a
        validation report, is named as such).
    """
    folder = _folder(folder)
    if not folder.is_dir():
        raise ConfigError("not a folder", folder)
    if (folder / "configs.csv").is_file():
        return "simulation"
    report = _validation_report(folder)
    if report is not None:
        raise report
    if (folder / "summary.json").is_file():
        return "image"
    if ((folder / "index.csv").is_file() or (folder / "batch.json").is_file()
            or any(_analysis_summaries(folder, hidden=True))):
        return "batch"
    raise _not_an_output(folder)


def load_simulation(folder, *, set_name=None) -> Ensemble:
    """Read a ``simulate quench`` ensemble (lengths in units of L already).

    Parameters
    ----------
    folder : path
    set_name : str, optional
        Defaults to the folder name.

    Returns
    -------
    Ensemble

    Raises
    ------
    ParameterError
        ``folder`` is not a path or ``set_name`` not a string.
    ConfigError
        A table is missing or malformed, or every configuration failed.
    """
    folder = _folder(folder)
    name = _set_name(set_name) or _text(folder.resolve().name)
    cfg = _read_csv(folder / "configs.csv", ["config_id", "epsilon", "energy_total", "n_stacks",
                                             "n_branches", "n_voids"], nonempty=True,
                    numeric=["epsilon", "energy_total", "n_stacks", "n_branches", "n_voids"])
    # configurations whose simulation raised, or whose rod's contact analysis did (a rod but
    # no network): no results
    stopped = pd.Series(False, index=cfg.index)
    kinds = []  # (configurations, what stopped them, where it is told)
    for col, what, see in (("error", "failed in the simulation", "failures.csv"),
                           ("analysis_error", "have no network (the contact analysis failed)",
                            "analysis_error in configs.csv")):
        if col in cfg.columns:
            # a configuration is named once, by what stopped it first
            bad = cfg[col].notna() & (cfg[col].astype(str).str.strip() != "") & ~stopped
            stopped |= bad
            if bad.any():
                kinds.append((bad, what, see))
    if kinds and stopped.all():  # as a batch with no finished image: no statistics to draw
        said = [f"{int(bad.sum())} {what}; see {see}" for bad, what, see in kinds]
        raise ConfigError("ensemble holds no finished configuration ("
                          + ("all " + said[0] if len(said) == 1 else "; ".join(said)) + ")",
                          folder)
    notes = []
    for bad, what, see in kinds:
        n = int(bad.sum())
        # the report records it as it records a batch's failed scans (batch_note)
        notes.append(f"{folder / 'configs.csv'}: {n} of {len(cfg)} configurations {what} "
                     f"(config_id {_listed(cfg.loc[bad, 'config_id'])}; see {see}) and "
                     f"{'is' if n == 1 else 'are'} not in the statistics")
        warnings.warn(notes[-1], IncompleteBatchWarning, stacklevel=2)
    params = _simulation_params(folder)
    asked = (params or {}).get("n_configs")
    if isinstance(asked, int) and not isinstance(asked, bool) and asked > 0 and len(cfg) < asked:
        # a run stopped before the end (killed, or a larger --n-configs begun): the tables
        # hold the configurations of the last run that finished
        notes.append(f"{folder / 'configs.csv'}: {len(cfg)} of the {asked} configurations "
                     "params.json asks for (a run stopped before the end: re-run the same "
                     "command to finish it)")
        warnings.warn(notes[-1], IncompleteBatchWarning, stacklevel=2)
    cfg = cfg[~stopped]
    if "n_hairpin_nodes" in cfg.columns:
        folds = pd.to_numeric(cfg["n_hairpin_nodes"], errors="coerce").fillna(0)
        k = int((folds > 0).sum())
        if k:
            # a fold within one node: the quench warned of it; the statistics say it again,
            # since those branches hold the ensemble's largest energies (a fifth of a
            # 6-configuration quench's bending in two branches)
            notes.append(f"{folder / 'configs.csv'}: {k} of {len(cfg)} configurations fold "
                         "back at a single node (n_hairpin_nodes): the discrete rod caps such "
                         "a fold's bending at 4 / ds, and the branches holding it, whose "
                         "energies are that cap, are in the statistics")
            warnings.warn(notes[-1], HairpinNodesWarning, stacklevel=2)
    note = "; ".join(notes)
    br = _read_csv(folder / "branches.csv", ["config_id", "length", "kappa_plus", "kappa_pm",
                                             "energy"],
                   numeric=["length", "kappa_plus", "kappa_pm", "energy", "n_br"])
    vo = _read_csv(folder / "voids.csv", ["config_id", "area", "shape_ratio", "n_edges"],
                   numeric=["area", "perimeter", "shape_ratio", "n_edges"])
    st = None
    if (folder / "stacks.csv").is_file():  # optional: per-stack branch counts
        st = _read_csv(folder / "stacks.csv", ["config_id", "n_br"], numeric=["n_br", "length"])
    # the simulator writes configs.csv's counts and the tables from the same analysis: a
    # difference is a table truncated or edited (or tables of two runs mixed)
    table_note = "; ".join(filter(None, (
        *(_check_config_counts(folder / table, df, cfg, key, what)
          for table, df, key, what in (("branches.csv", br, "n_branches", "branches"),
                                       ("stacks.csv", st, "n_stacks", "stacks"),
                                       ("voids.csv", vo, "n_voids", "voids"))),
        _check_lengths(folder / "branches.csv", br["length"]))))
    configs = pd.DataFrame({
        "set": name, "config_id": cfg["config_id"].astype(str), "N_l": cfg["n_stacks"],
        "N_br": cfg["n_branches"], "n_voids": cfg["n_voids"], "epsilon": cfg["epsilon"],
        "E": cfg["energy_total"], "rod_length_mm": np.nan, "source": str(folder),
        "analysis": _simulation_provenance(params), "batch_note": note,
        "table_note": table_note})
    n_br = br["n_br"] if "n_br" in br.columns else _stack_counts(br, st)
    branches = pd.DataFrame({
        "set": name, "config_id": br["config_id"].astype(str), "length_L": br["length"],
        "kappa_m_L": br["kappa_pm"].abs(), "kappa_plus_L": br["kappa_plus"],
        "e": br["energy"], "region": br["region"] if "region" in br.columns else SIM_REGION,
        "n_br": n_br, "l_min_L": np.nan})
    if st is not None:
        stacks = pd.DataFrame({"set": name, "config_id": st["config_id"].astype(str),
                               "n_br": st["n_br"],
                               "length_L": st["length"] if "length" in st else np.nan,
                               "region": st["region"] if "region" in st else SIM_REGION})
    else:
        stacks = pd.DataFrame(columns=STACK_COLS)
    voids = pd.DataFrame({
        "set": name, "config_id": vo["config_id"].astype(str), "area_L2": vo["area"],
        "perimeter_L": vo["perimeter"] if "perimeter" in vo else np.nan,
        "shape_ratio": vo["shape_ratio"], "n_edges": vo["n_edges"], "s_min_L2": np.nan})
    return Ensemble(configs.reindex(columns=CONFIG_COLS), branches.reindex(columns=BRANCH_COLS),
                    stacks.reindex(columns=STACK_COLS), voids.reindex(columns=VOID_COLS))


def _simulation_params(folder: Path) -> dict | None:
    """A simulation's ``params.json`` as a dict, or None when it has none or it cannot be
    read."""
    try:
        params = json.loads((folder / "params.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return params if isinstance(params, dict) else None


def _simulation_provenance(params: dict | None):
    """The ``analysis`` cell of a simulation's configurations: the version and parameters
    of its ``params.json`` (:func:`_simulation_params`; NaN without one)."""
    if params is None:
        return np.nan
    params = dict(params)
    version = params.pop("version", None)
    libraries = params.pop("libraries", None)
    # an ensemble resumed under other versions lists every run's (simulate.ensemble's
    # params_record): a record of the code, not a parameter
    runs = params.pop("versions", None)
    text = json.loads(_provenance(version, params))
    if isinstance(libraries, dict):
        text["libraries"] = libraries
    if isinstance(runs, list):
        text["runs"] = [r for r in runs if isinstance(r, dict)]
    return json.dumps(text, sort_keys=True, default=str)


def _stack_counts(br: pd.DataFrame, st: pd.DataFrame | None):
    """Each branch's ``n_br``, the count of its stack (``stack_id`` within its configuration
    in ``stacks.csv``); NaN where the tables do not say (no stacks.csv, no stack_id)."""
    if st is None or "stack_id" not in br.columns or "stack_id" not in st.columns:
        return np.nan
    key = ["config_id", "stack_id"]
    counts = st[key + ["n_br"]].astype({"config_id": str}).drop_duplicates(key)
    return br[key].astype({"config_id": str}).merge(counts, on=key, how="left")["n_br"].to_numpy()


def _rod_length(summary: dict, path: Path) -> float:
    """The rod length L (mm) that the analysis used for the scan's e, E and epsilon: its
    ``rod_length_used_mm`` (a given ``--rod-length-mm`` differs from the measured
    ``rod_length_mm``), or ``rod_length_mm`` where the summary does not record it.
    Normalising lengths by another L than the energies would mix two units in one scan.

    Raises
    ------
    ConfigError
        Neither entry is a positive number.
    """
    for key in ("rod_length_used_mm", "rod_length_mm"):
        L = summary.get(key)
        if L is not None:
            if not (np.isfinite(L) and L > 0):
                raise ConfigError(f"{key} is {L!r}, not a positive length", path)
            return float(L)
    raise ConfigError("summary.json has no positive rod_length_mm", path)


def _recorded_limits(summary: dict) -> tuple[float | None, float | None]:
    """``(l_min_mm, s_min_mm2)`` the analysis of a scan used, from the parameters its
    summary.json records, None for one it does not record (s_min unset is (10 h)^2 of the
    recorded thickness h, as the analysis takes it)."""
    params = summary.get("parameters")
    params = params if isinstance(params, dict) else {}

    def number(key):
        v = params.get(key)
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        return float(v) if ok and v >= 0 else None

    s_min = number("s_min_mm2")
    if s_min is None and "s_min_mm2" in params and number("thickness_mm"):
        s_min = (10.0 * number("thickness_mm")) ** 2
    return number("l_min_mm"), s_min


def _provenance(version, parameters) -> str:
    """The ``analysis`` cell: JSON text of what made a configuration."""
    return json.dumps({"version": version if isinstance(version, str) else None,
                       "parameters": parameters if isinstance(parameters, dict) else {}},
                      sort_keys=True, default=str)


def load_image_output(folder, *, set_name: str, config_id: str | None = None,
                      l_min_mm: float | str | None = RECORDED,
                      s_min_mm2: float | str | None = RECORDED,
                      warn: bool = True) -> Ensemble:
    """Read one ``analyze`` output folder and normalise it by its rod length L.

    L is the rod length the analysis used for its energies and epsilon
    (``rod_length_used_mm`` of ``summary.json``: a given ``--rod-length-mm``, else the
    measured one), so that lengths, curvatures, areas, e, E and epsilon share one L.

    Parameters
    ----------
    folder : path
        Holds ``summary.json``, ``stacks.csv``, ``branches.csv``, ``voids.csv``.
    set_name : str
    config_id : str, optional
        Defaults to the folder name.
    l_min_mm, s_min_mm2 : float, None or :data:`RECORDED`
        Detection limits in mm and mm^2, recorded per observation in units of L / L^2:
        :data:`RECORDED` (default) those the scan's analysis used (its summary.json; the
        analysis' defaults, l_min = 1 mm and s_min = 1 mm^2, where it records none); a
        number wins over them; None or 0: none.
    warn : bool
        Give the warnings about this scan alone (a :class:`FlaggedScanWarning` when its
        analysis flagged it, a :class:`DetectionLimitWarning` for a limit given below the
        analysis' own); :func:`load_batch` gives them once per set instead.

    Returns
    -------
    Ensemble

    Raises
    ------
    ParameterError
        ``folder`` is not a path, a name not a string, or a detection limit not a finite
        number >= 0.
    ConfigError
        A file is missing or malformed, or the folder is a validation report.
    """
    folder = _folder(folder)
    _set_name(set_name, required=True)
    _set_name(config_id, "config_id")
    _limit(l_min_mm, "l_min_mm")
    _limit(s_min_mm2, "s_min_mm2")
    cid = config_id or _text(folder.name)
    report = _validation_report(folder)
    if report is not None:
        raise report
    summary = _read_summary(folder / "summary.json")
    L = _rod_length(summary, folder / "summary.json")
    br = _read_csv(folder / "branches.csv", ["stack_id", "length_mm", "kappa_plus", "kappa_m",
                                             "energy", "region"],
                   numeric=["stack_id", "length_mm", "kappa_plus", "kappa_m", "energy"])
    st = _read_csv(folder / "stacks.csv", ["stack_id", "n_br", "length_mm", "region"],
                   numeric=["stack_id", "n_br", "length_mm"])
    vo = _read_csv(folder / "voids.csv", ["area_mm2", "perimeter_mm", "shape_ratio", "n_edges"],
                   numeric=["area_mm2", "perimeter_mm", "shape_ratio", "n_edges"])
    # a table cut short (or edited) is used as it is: its rows are the scan's counts too,
    # so that N_br of the whole system is that of bulk and periphery (and the fits' values)
    table_note = "; ".join(filter(None, (
        *(_check_count(folder / table, len(df), summary.get(key), what)
          for table, df, key, what in (("stacks.csv", st, "n_stacks", "stacks"),
                                       ("branches.csv", br, "n_branches", "branches"),
                                       ("voids.csv", vo, "n_voids", "voids"))),
        _check_lengths(folder / "branches.csv", br["length_mm"] / L, f", L = {L:.4g} mm"))))
    n_br_map = dict(zip(st["stack_id"], st["n_br"]))
    rec_l, rec_s = _recorded_limits(summary)
    # a summary that does not record its limits (written by other tools) gets the
    # analysis' defaults, and no recorded limit to compare a given one with
    if l_min_mm == RECORDED:
        l_min_mm = L_MIN_MM if rec_l is None else rec_l
    if s_min_mm2 == RECORDED:
        s_min_mm2 = S_MIN_MM2 if rec_s is None else rec_s
    configs = pd.DataFrame([{
        "set": set_name, "config_id": str(cid), "N_l": len(st), "N_br": len(br),
        "n_voids": len(vo),
        "epsilon": summary.get("epsilon", np.nan), "E": summary.get("total_energy", np.nan),
        "rod_length_mm": L, "source": str(folder),
        "quality": ";".join((summary.get("quality") or {}).get("codes", [])),
        "E_model_share": summary.get("total_energy_rel_uncertainty", np.nan),
        "l_min_mm_analysis": np.nan if rec_l is None else rec_l,
        "s_min_mm2_analysis": np.nan if rec_s is None else rec_s,
        "analysis": _provenance(summary.get("version"), summary.get("parameters")),
        "batch_note": "", "table_note": table_note}])
    branches = pd.DataFrame({
        "set": set_name, "config_id": str(cid), "length_L": br["length_mm"] / L,
        "kappa_m_L": br["kappa_m"] * L, "kappa_plus_L": br["kappa_plus"] * L,
        "e": br["energy"], "region": br["region"].astype(str),
        "n_br": br["stack_id"].map(n_br_map),
        "l_min_L": (l_min_mm / L) if l_min_mm else np.nan,
        # its branches repeat the stack's values: one independent value per stack
        "stack_id": br["stack_id"]})
    stacks = pd.DataFrame({"set": set_name, "config_id": str(cid), "n_br": st["n_br"],
                           "length_L": st["length_mm"] / L, "region": st["region"].astype(str)})
    voids = pd.DataFrame({
        "set": set_name, "config_id": str(cid), "area_L2": vo["area_mm2"] / L ** 2,
        "perimeter_L": vo["perimeter_mm"] / L, "shape_ratio": vo["shape_ratio"],
        "n_edges": vo["n_edges"], "s_min_L2": (s_min_mm2 / L ** 2) if s_min_mm2 else np.nan})
    ens = Ensemble(configs.reindex(columns=CONFIG_COLS), branches.reindex(columns=BRANCH_COLS),
                   stacks.reindex(columns=STACK_COLS), voids.reindex(columns=VOID_COLS))
    if warn:
        warn_flagged(ens, stacklevel=3)
        warn_limits_below(ens, folder, stacklevel=3)
    return ens


#: flagged scans of one set named one per line up to this many, beyond it in one line
MAX_FLAGGED_LINES = 5


def warn_flagged(ens: Ensemble, *, stacklevel: int = 2) -> None:
    """One :class:`FlaggedScanWarning` per scan of ``ens`` whose analysis flagged it
    (``summary.json: flagged by the analysis: codes``), or one per set listing them when a
    set holds more than :data:`MAX_FLAGGED_LINES`; the report names the same scans."""
    c = ens.configs
    q = c["quality"].astype(object).where(c["quality"].notna(), "").astype(str)
    bad = c[q != ""].assign(quality=q[q != ""])
    for s, g in bad.groupby("set", sort=False):
        files = [Path(str(src)) / "summary.json" if isinstance(src, str) and src else cid
                 for src, cid in zip(g["source"], g["config_id"])]
        codes = [v.replace(";", ", ") for v in g["quality"]]
        if len(g) <= MAX_FLAGGED_LINES:
            for f, cds in zip(files, codes):
                warnings.warn(f"{f}: flagged by the analysis: {cds}", FlaggedScanWarning,
                              stacklevel=stacklevel + 1)
        else:
            listed = "; ".join(f"{cid} ({cds})" for cid, cds in zip(g["config_id"], codes))
            warnings.warn(f"set {s}: {len(g)} of {int((c['set'] == s).sum())} scans flagged by "
                          f"the analysis: {listed}", FlaggedScanWarning,
                          stacklevel=stacklevel + 1)


def warn_limits_below(ens: Ensemble, where, *, stacklevel: int = 2) -> None:
    """One :class:`DetectionLimitWarning` per set and limit of ``ens`` whose scans are
    truncated below the limit their analysis used (a limit given to the loaders, or 0):
    the fits then treat the missing values between the two as rare ones and are biased."""
    key = ["set", "config_id"]
    for table, col, rec, name, unit, power in (
            ("branches", "l_min_L", "l_min_mm_analysis", "l_min", "mm", 1),
            ("voids", "s_min_L2", "s_min_mm2_analysis", "s_min", "mm^2", 2)):
        c = ens.configs
        rec_v = c[rec].to_numpy(float)
        if not np.isfinite(rec_v).any():  # simulations: no limit recorded
            continue
        df = getattr(ens, table)
        # the limit each scan's observations carry, in mm (mm^2), back from units of L
        first = df.groupby(key, sort=False)[col].first()
        idx = pd.MultiIndex.from_frame(c[key].astype(str))
        has_rows = np.asarray(idx.isin(first.index), bool)
        used = (first.reindex(idx).to_numpy(float)
                * c["rod_length_mm"].to_numpy(float) ** power)
        # no limit (NaN) counts as 0; 1e-9 absorbs the rounding of x / L * L
        low = has_rows & np.isfinite(rec_v) & (np.nan_to_num(used) < rec_v * (1 - 1e-9))
        for s in dict.fromkeys(c.loc[low, "set"]):
            k = low & (c["set"] == s).to_numpy()
            given = np.unique(np.round(np.nan_to_num(used[k]), 9))
            warnings.warn(
                f"{where}: {name} = {_values(given)} {unit} given for set {s} is below the "
                f"{_values(np.unique(rec_v[k]))} {unit} its analysis used ({int(k.sum())} "
                f"scan(s)): below that limit the analysis removed branches ending free and "
                f"filled voids, so the values in between are missing, not rare, and the "
                f"truncated fits are biased; give at least the analysis' "
                f"limit, or leave the option out to use it", DetectionLimitWarning,
                stacklevel=stacklevel + 1)


def _values(v) -> str:
    v = [f"{x:g}" for x in v]
    return v[0] if len(v) == 1 else f"{v[0]}-{v[-1]}"


def _check_count(path: Path, rows: int, counted, what: str) -> str:
    """Warn when a table holds another number of rows than ``summary.json`` counts: the
    analysis writes both from the same tables, so a difference is a truncated or edited
    file, whose statistics (counts included) are then those of the rows left.

    Returns
    -------
    str
        The warning's text (the report records it), "" when the counts agree.
    """
    if counted is None or not np.isfinite(counted) or rows == counted:
        return ""
    text = (f"{path}: holds {rows} {what} where summary.json counts {counted:g} "
            f"(truncated or edited?); the {rows} rows are used")
    warnings.warn(text, QualityWarning, stacklevel=4)
    return text


def _check_lengths(path: Path, length_L, of_rod: str = "") -> str:
    """Warn when branches are longer than the rod they are parts of (``l / L > 1``): a table
    edited, or read with another rod's length; such values dominate the means and fits
    they enter, which use them as read.

    Returns
    -------
    str
        The warning's text (the report records it), "" when every branch fits in its rod.
    """
    v = np.asarray(length_L, float)
    with np.errstate(invalid="ignore"):
        over = v > 1.0 + 1e-9
    if not over.any():
        return ""
    n = int(over.sum())
    text = (f"{path}: {n} branch{'es' if n > 1 else ''} longer than the rod (l / L up to "
            f"{np.nanmax(v[over]):.3g}{of_rod}): the table or the rod length is wrong; "
            f"{'they are' if n > 1 else 'it is'} used as read")
    warnings.warn(text, QualityWarning, stacklevel=4)
    return text


def _check_config_counts(path: Path, table, cfg, key: str, what: str) -> str:
    """:func:`_check_count` for a simulation's table: its rows of each configuration against
    ``configs.csv``'s ``key`` (configurations whose count is not a number are not checked).

    Returns
    -------
    str
        The warning's text, "" when every configuration's count agrees.
    """
    if table is None or key not in cfg.columns or "config_id" not in table.columns:
        return ""
    counted = pd.to_numeric(cfg[key], errors="coerce")
    rows = table["config_id"].astype(str).value_counts()
    held = rows.reindex(cfg["config_id"].astype(str)).fillna(0).to_numpy()
    bad = np.isfinite(counted.to_numpy(float)) & (held != counted.to_numpy(float))
    if not bad.any():
        return ""
    ids = cfg["config_id"].astype(str).to_numpy()[bad]
    text = (f"{path}: holds {int(held[bad].sum())} {what} of {len(ids)} configuration(s) "
            f"(config_id {_listed(ids)}) where configs.csv counts "
            f"{counted.to_numpy(float)[bad].sum():g} (truncated, edited, or tables of two "
            "runs?); the rows held are used")
    warnings.warn(text, QualityWarning, stacklevel=4)
    return text


def _listed(items, limit: int = 5) -> str:
    items = [str(i) for i in items]
    return ", ".join(items[:limit]) + (", ..." if len(items) > limit else "")


def _read_index(index: Path, folder: Path):
    """Rows of a batch's ``index.csv`` as dicts, or None when the file cannot be used.

    A line that cannot be parsed (another number of fields than the header) is left out; a
    file that cannot be used at all makes the caller read every ``summary.json`` instead.
    Either gives one warning naming the file.
    """
    fallback = f"every */summary.json below {folder} is read instead"
    try:
        text = index.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        warnings.warn(f"{index}: unreadable ({why_unreadable(exc)}); {fallback}", QualityWarning,
                      stacklevel=3)
        return None
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader, [])
    except csv.Error:
        header = []
    missing = [c for c in ("set", "status", "output") if c not in header]
    if missing:
        warnings.warn(f"{index}: lacks columns {missing}; {fallback}", QualityWarning,
                      stacklevel=3)
        return None
    rows, bad = [], []
    while True:
        try:
            row = next(reader)
        except StopIteration:
            break
        except csv.Error:
            bad.append(reader.line_num)
            continue
        if not row:  # a blank line
            continue
        if len(row) != len(header):
            bad.append(reader.line_num)
            continue
        rows.append(dict(zip(header, row)))
    if bad:
        warnings.warn(f"{index}: cannot parse line(s) {_listed(bad)} (not one field per "
                      "column); the images listed there are left out", QualityWarning,
                      stacklevel=3)
    return rows


def _batch_image_folders(folder: Path, notes=None):
    """(set, config_id, folder) of every finished image of a batch output; what is left out
    is said in ``notes`` (a list, appended to) as well as warned.

    ``index.csv`` (columns set, status, output) is used when present: rows with status ``ok``
    or ``skipped`` (done in an earlier run) whose folder holds a summary, none when no row
    is (every scan failed or still pending). Without a usable index every
    ``summary.json`` below ``folder`` counts, in the set its ``batch.set`` records (else its
    first path component), except in hidden folders (the batch's ``.<stem>.partial-*``
    staging folders of interrupted runs), generated scenes' truth and the folders
    ``batch.json`` lists as stale. A scan's ``config_id`` is its folder's name.
    """
    notes = [] if notes is None else notes
    index = folder / "index.csv"
    if index.is_file():
        rows = _read_index(index, folder)
        out, lost = [], []
        for row in rows or ():
            output = row["output"].strip()
            if row["status"].strip() not in ("ok", "skipped") or not output:
                continue
            img = folder / output
            if not (img / "summary.json").is_file():
                lost.append(output)
                continue
            # a scan's folder is one name inside its set's folder, however deep that is
            out.append((row["set"] or _text(Path(output).parts[0]), _text(Path(output).name),
                        img))
        if lost:
            note = (f"{index}: {len(lost)} image(s) listed as done have no summary.json "
                    f"({_listed(lost, 3)}) and are left out")
            notes.append(note)
            warnings.warn(note, QualityWarning, stacklevel=2)
        if rows is not None:
            # a usable index is the batch's word: its failed and pending scans' folders (an
            # earlier run's results, or another option's) are not finished images
            return out
    stale = _stale_outputs(folder)
    out = []
    for summ in sorted(_analysis_summaries(folder)):
        img = summ.parent
        rel = img.relative_to(folder)
        if rel.as_posix() in stale:
            continue
        # the set a batch recorded in the scan's summary (a nested set's name is a path)
        recorded = _recorded_set(summ)
        if recorded:
            out.append((recorded, _text(rel.name), img))
        elif len(rel.parts) >= 2:
            out.append((_text(rel.parts[0]), _text("/".join(rel.parts[1:])), img))
        else:
            out.append((_text(folder.resolve().name), _text(rel.parts[0]), img))
    # a folder holding several batches' outputs (of one set's name) holds one scan's name
    # several times: those are named by their path, a configuration being one per set
    seen = Counter((s, c) for s, c, _ in out)
    return [(s, c if seen[(s, c)] == 1 else img.relative_to(folder).as_posix(), img)
            for s, c, img in out]


def _recorded_set(summary_path: Path) -> str | None:
    """The set ``batch`` recorded in a scan's summary.json (``batch.set``), None without."""
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    info = summary.get("batch") if isinstance(summary, dict) else None
    name = info.get("set") if isinstance(info, dict) else None
    return name if isinstance(name, str) and name else None


def _stale_outputs(folder: Path) -> set[str]:
    """The output folders a batch's ``batch.json`` names as no scan's (left from an earlier
    run whose sets or scans moved)."""
    try:
        meta = json.loads((folder / "batch.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return set()
    stale = meta.get("stale_outputs") if isinstance(meta, dict) else None
    return {str(s).strip("/") for s in stale} if isinstance(stale, list) else set()


def _check_finished(folder: Path, n_found: int) -> str:
    """Warn when the batch's ``batch.json`` does not mark it complete: an interrupted (or
    still running) batch lacks images, and its statistics are those of the images done.

    Returns
    -------
    str
        What the warning says after the file name (the report records it), "" when the
        batch finished or has no ``batch.json``.
    """
    path = folder / "batch.json"
    if not path.is_file():  # not written by ``batch`` (copied or generated folders)
        return ""
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:  # JSON and Unicode decoding errors are ValueErrors
        note = (f"unreadable ({why_unreadable(exc)}), so whether the batch finished is "
                f"unknown; its {n_found} finished image(s) are used")
        warnings.warn(f"{path}: {note}", IncompleteBatchWarning, stacklevel=3)
        return note
    if isinstance(meta, dict) and meta.get("complete") is True:
        return ""
    n = meta.get("n_images") if isinstance(meta, dict) else None
    of = f" of its {n}" if isinstance(n, int) and not isinstance(n, bool) else ""
    note = (f"the batch did not finish (interrupted, or still running): only {n_found}{of} "
            "images are done and used")
    warnings.warn(f"{path}: {note}", IncompleteBatchWarning, stacklevel=3)
    return note


def _clipped(text: str, most: int = 80) -> str:
    """One line of at most ``most`` characters (a failure's reason, in a warning)."""
    text = " ".join(str(text).split())
    return text if len(text) <= most else text[:most - 3] + "..."


def _unnamed(reason: str, image: str) -> str:
    """A failure's reason without the file name it starts with (the image is named
    beside it)."""
    head, sep, rest = reason.partition(": ")
    return rest if sep and Path(head).name == Path(image).name else reason


def _check_failures(folder: Path) -> str:
    """Warn when the batch's ``failures.csv`` lists images: the batch could not analyse
    them, and the statistics leave them out (a re-run of the batch tries them again).

    Returns
    -------
    str
        The ``failures.csv: ...`` sentence the report records, "" when none failed.
    """
    path = folder / "failures.csv"
    try:
        rows = list(csv.reader(io.StringIO(path.read_text(encoding="utf-8"), newline="")))
    except (OSError, UnicodeDecodeError, csv.Error):
        return ""  # none, or unreadable: index.csv already says which images are done
    listed = [row for row in rows[1:] if any(cell.strip() for cell in row)]
    n = len(listed)
    if not n:
        return ""
    col = rows[0].index("image") if rows and "image" in rows[0] else None
    why = rows[0].index("reason") if rows and "reason" in rows[0] else None
    names = [row[col] + (f": {_clipped(_unnamed(row[why], row[col]))}"
                         if why is not None and why < len(row) and row[why].strip() else "")
             for row in listed if col is not None and col < len(row)]
    shown = (f" ({'; '.join(names[:5])}{'; ...' if len(names) > 5 else ''})" if names else "")
    try:
        total = json.loads((folder / "batch.json").read_text(encoding="utf-8"))["n_images"]
    except (OSError, ValueError, TypeError, KeyError):
        total = None
    of = (f" of {total}" if isinstance(total, int) and not isinstance(total, bool)
          and total >= n else "")
    one = n == 1
    text = (f"{path}: {n}{of} images{shown} {'was' if one else 'were'} not analysed and "
            f"{'is' if one else 'are'} not in the statistics")
    warnings.warn(text, IncompleteBatchWarning, stacklevel=3)
    return text


def _enclosing_batch(folder: Path) -> Path | None:
    """The batch output a folder of per-image folders lies in (a set's folder, ``OUT/<set>``,
    or one level of a nested set's), when the folder holds no ``index.csv`` or
    ``batch.json`` of its own: its nearest parent that does, None without one."""
    if (folder / "index.csv").is_file() or (folder / "batch.json").is_file():
        return None
    # the path as given names the batch's files in the warnings, where it can
    plain = bool(folder.parts) and ".." not in folder.parts
    for parent in folder.parents if plain else folder.resolve().parents:
        if (parent / "index.csv").is_file() or (parent / "batch.json").is_file():
            return parent
    return None


def load_batch(folder, *, l_min_mm=RECORDED, s_min_mm2=RECORDED) -> Ensemble:
    """Read every per-image folder of a batch output.

    The set of an image folder is the one ``index.csv`` (or, without it, its summary's
    ``batch.set``) records, else its first path component under ``folder``; an image folder
    directly under ``folder`` belongs to the set named after ``folder``. Folders without a
    ``summary.json`` (unfinished or failed images, see ``failures.csv``) are skipped.
    Doubtful inputs that are still used give a :class:`~crosssection.quality.QualityWarning`
    naming the file: a ``batch.json`` that does not mark the batch complete, images that
    ``failures.csv`` lists (the batch could not analyse them), a line of
    ``index.csv`` that cannot be parsed, a table shorter or longer than its ``summary.json``
    says, scans the analysis flagged (one :class:`FlaggedScanWarning` per scan, or per set
    when many) and a detection limit given below the analysis' own (one
    :class:`DetectionLimitWarning` per set).

    A folder inside a batch output (a set's folder, ``OUT/<set>``) is read through that
    batch's ``index.csv`` and ``batch.json``, keeping the images below the folder: scans the
    batch failed, still had pending or no longer has (an earlier run's folders) stay out, and
    an unfinished batch is said, as for the whole batch.

    Parameters
    ----------
    folder : path
    l_min_mm, s_min_mm2 : float, None or :data:`RECORDED`
        Detection limits (see :func:`load_image_output`).

    Returns
    -------
    Ensemble
        An unfinished batch, and one whose ``failures.csv`` lists images, say so in the
        ``batch_note`` of its configurations (the report names them).

    Raises
    ------
    ParameterError
        ``folder`` is not a path, or a detection limit is not a finite number >= 0.
    ConfigError
        No finished image, or a malformed file.
    """
    folder = _folder(folder)
    _limit(l_min_mm, "l_min_mm")
    _limit(s_min_mm2, "s_min_mm2")
    parts, notes = [], []
    given, root = folder, _enclosing_batch(folder)
    if root is None:
        found = _batch_image_folders(folder, notes)
    else:
        inside = folder.resolve()
        found = [(s, c, img) for s, c, img in _batch_image_folders(root, notes)
                 if img.resolve().is_relative_to(inside)]
        folder = root
    for set_name, cid, img in found:
        try:
            parts.append(load_image_output(img, set_name=set_name, config_id=cid,
                                           l_min_mm=l_min_mm, s_min_mm2=s_min_mm2, warn=False))
        except ConfigError as exc:
            if exc.cause != MISSING_TABLE:
                raise  # a malformed table is an error to see, not data to drop
            # a table deleted by hand leaves its scan out, as a missing summary.json does,
            # not the batch
            note = f"{exc.one_line()}: this image is left out"
            notes.append(note)
            warnings.warn(note, QualityWarning, stacklevel=2)
    if not parts:
        why = ("its index.csv lists no scan as done (ok or skipped)"
               if (folder / "index.csv").is_file() else "no */summary.json")
        if root is not None:
            why = f"the batch's index.csv at {root} lists none below it as done"
        raise ConfigError(f"batch output holds no finished image ({why})", given)
    note = _check_finished(folder, len(found))
    failed = _check_failures(folder)
    ens = Ensemble.concat(parts)
    notes += _warn_duplicates([(set_name, img) for set_name, _, img in found])
    ens.configs["batch_note"] = "; ".join(
        ([f"{folder / 'batch.json'}: {note}"] if note else []) + ([failed] if failed else [])
        + notes)
    warn_flagged(ens, stacklevel=2)
    warn_limits_below(ens, folder, stacklevel=2)
    return ens


def _warn_duplicates(image_folders) -> list[str]:
    """One :class:`DuplicateScanWarning` per group of image outputs of one set whose scans
    hold the same bytes (``inputs.image.sha256`` of their summary.json), and its text
    returned (the report's note); sets are analysed apart, so one scan in two sets weighs
    once in each."""
    notes = []
    by_hash = {}
    for set_name, img in image_folders:
        try:
            sha = json.loads((Path(img) / "summary.json").read_text(encoding="utf-8"))[
                "inputs"]["image"]["sha256"]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if isinstance(sha, str) and sha:
            by_hash.setdefault((set_name, sha), []).append(Path(img))
    for (_, sha), same in by_hash.items():
        if len(same) > 1:
            others = ", ".join(str(p) for p in same[1:])
            note = (f"{same[0]}: the same scan (SHA-256 {sha[:12]}...) as {others}: one cut "
                    f"analysed {len(same)} times weighs {len(same)} times in its set's "
                    "statistics")
            notes.append(note)
            warnings.warn(note, DuplicateScanWarning, stacklevel=3)
    return notes


def load_any(folder, *, set_name=None, l_min_mm=RECORDED, s_min_mm2=RECORDED) -> Ensemble:
    """Load any supported folder (see :func:`detect_kind`).

    Parameters
    ----------
    folder : path
    set_name : str, optional
        Overrides the set name: the name of the one set of a simulation, an analyze output
        or a batch of one set; a batch of several sets keeps them apart as
        ``set_name/<set>`` (sets ``A`` and ``B`` given ``exp`` become ``exp/A``, ``exp/B``).
    l_min_mm, s_min_mm2 : float, None or :data:`RECORDED`
        Image detection limits, in mm and mm^2: :data:`RECORDED` (default) those each
        scan's analysis used, else None or a finite number >= 0 (0 = none), which wins (a
        :class:`DetectionLimitWarning` when it is below the analysis' own). Simulations
        have none (a limit given is not applied to them, with a
        :class:`DetectionLimitWarning`).

    Returns
    -------
    Ensemble

    Raises
    ------
    ParameterError
        ``folder`` is not a path, ``set_name`` not a string, or a detection limit not a
        finite number >= 0.
    ConfigError
        The folder is none of the three kinds (a folder of scans is named as such: run
        ``foldstat batch`` on it first), or a file is missing or malformed.
    """
    folder = _folder(folder)
    _set_name(set_name)
    _limit(l_min_mm, "l_min_mm")
    _limit(s_min_mm2, "s_min_mm2")
    kind = detect_kind(folder)
    if kind == "simulation":
        given = [f"{k} = {v:g}" for k, v in (("l_min_mm", l_min_mm), ("s_min_mm2", s_min_mm2))
                 if v is not RECORDED and v]
        if given:
            warnings.warn(f"{folder}: a simulation's lengths are in units of its rod length, "
                          f"with no scale in mm: the image detection limits "
                          f"({', '.join(given)}) are not applied to it",
                          DetectionLimitWarning, stacklevel=2)
        return load_simulation(folder, set_name=set_name)
    if kind == "image":
        return load_image_output(folder, set_name=set_name or _text(Path(folder).resolve().name),
                                 l_min_mm=l_min_mm, s_min_mm2=s_min_mm2)
    ens = load_batch(folder, l_min_mm=l_min_mm, s_min_mm2=s_min_mm2)
    if set_name:
        sets = ens.sets
        # the sets of a batch are different experiments: a name labels them, never pools them
        rename = ({sets[0]: set_name} if len(sets) == 1 else
                  {s: f"{set_name}/{s}" for s in sets})
        for df in (ens.configs, ens.branches, ens.stacks, ens.voids):
            df["set"] = df["set"].map(rename)
    return ens


def load_inputs(folders, *, names=None, l_min_mm=RECORDED, s_min_mm2=RECORDED) -> Ensemble:
    """Load several folders (``foldstat stats DIR...``) into one ensemble, each counted once.

    A folder given twice (under any spelling of its path) is read once, and an image output
    already read through another folder (a batch and one of its image folders) is left out
    of the later one; either gives a :class:`~crosssection.quality.QualityWarning`. Sets of
    the same name from different folders are kept apart as ``name#k`` (k = the folder's
    position).

    Parameters
    ----------
    folders : path or sequence of path
    names : sequence of str, optional
        Set name of each folder (see :func:`load_any`).
    l_min_mm, s_min_mm2 : float, None or :data:`RECORDED`
        Image detection limits (see :func:`load_any`).

    Returns
    -------
    Ensemble
        Its ``configs`` name in ``input`` the folder each configuration was read from.

    Raises
    ------
    ParameterError
        A folder is not a path, ``names`` is not one name per folder, or a detection limit
        is not a finite number >= 0.
    ConfigError
        As :func:`load_any`.
    """
    # one path is one folder, not a sequence of one-letter folders
    folders = [folders] if isinstance(folders, (str, os.PathLike)) else list(folders)
    for d in folders:
        _folder(d, "folders")
    names = list(names) if names else [None] * len(folders)
    if len(names) != len(folders):
        raise ParameterError(f"names gives {len(names)} names for {len(folders)} folders")
    _limit(l_min_mm, "l_min_mm")
    _limit(s_min_mm2, "s_min_mm2")
    parts, seen_sets, seen_dirs, seen_images = [], set(), {}, {}
    for i, (d, name) in enumerate(zip(folders, names)):
        key = Path(d).resolve()
        if key in seen_dirs:
            warnings.warn(f"{d}: given twice (also as {seen_dirs[key]}); counted once",
                          QualityWarning, stacklevel=2)
            continue
        seen_dirs[key] = d
        kind = detect_kind(d)
        ens = load_any(d, set_name=name, l_min_mm=l_min_mm, s_min_mm2=s_min_mm2)
        if kind != "simulation":
            ens = _drop_images_seen(ens, d, seen_images)
            if ens is None:
                continue
        for s in ens.sets:  # two DIRs with the same folder name: keep the sets apart
            if s in seen_sets:
                new = f"{s}#{i + 1}"
                for df in (ens.configs, ens.branches, ens.stacks, ens.voids):
                    df.loc[df["set"] == s, "set"] = new
                s = new
            seen_sets.add(s)
        ens.configs["input"] = str(d)
        parts.append(ens)
    return Ensemble.concat(parts)


def _drop_images_seen(ens: Ensemble, folder, seen: dict) -> Ensemble | None:
    """``ens`` without the image outputs already read from another input folder (recorded
    in ``seen``: resolved image folder -> input folder), or None when none is left."""
    src = [Path(v).resolve() for v in ens.configs["source"]]
    dup = np.array([p in seen for p in src], bool)
    if dup.any():
        first = _listed(dict.fromkeys(seen[p] for p, k in zip(src, dup) if k), 3)
        what = ("its image outputs were" if dup.all() else
                f"{int(dup.sum())} of its {len(src)} image outputs were")
        warnings.warn(f"{folder}: {what} already read from {first}; counted once",
                      QualityWarning, stacklevel=3)
    for p in src:
        seen.setdefault(p, folder)
    if not dup.any():
        return ens
    if dup.all():
        return None
    drop = set(zip(ens.configs.loc[dup, "set"], ens.configs.loc[dup, "config_id"]))
    keep = lambda df: df[[k not in drop for k in zip(df["set"], df["config_id"])]]  # noqa: E731
    return Ensemble(*(keep(df).reset_index(drop=True)
                      for df in (ens.configs, ens.branches, ens.stacks, ens.voids)))


#: the tables of a ``stats`` report folder (CSV files of the same names)
REPORT_TABLES = ("macro", "micro", "fits", "relations", "dof", "truncation", "correlations",
                 "per_config")


@dataclass
class Report:
    """A ``stats`` report folder read back (:func:`load_report`).

    Attributes
    ----------
    macro, micro, fits, relations, dof, truncation, correlations, per_config : DataFrame
        The report's tables (empty when a table was empty).
    meta : dict
        ``stats.json``: version, inputs, options and per-set selected laws with their
        parameters and intervals.
    folder : Path
    """

    macro: pd.DataFrame
    micro: pd.DataFrame
    fits: pd.DataFrame
    relations: pd.DataFrame
    dof: pd.DataFrame
    truncation: pd.DataFrame
    correlations: pd.DataFrame
    per_config: pd.DataFrame
    meta: dict
    folder: Path

    def __repr__(self) -> str:
        sets = sorted({str(x) for x in self.macro.get("set", pd.Series(dtype=str))})
        return (f"Report({self.folder}: {len(sets)} set(s) {', '.join(sets)}; "
                f"{len(self.per_config)} configurations, {len(self.selected())} selected laws, "
                f"foldstat {self.meta.get('version', 'n/a')})")

    def selected(self) -> pd.DataFrame:
        """The selected law of every set, region and quantity (rows of ``fits``)."""
        if self.fits.empty or "selected" not in self.fits.columns:
            return self.fits
        return self.fits[self.fits["selected"].astype(bool)].reset_index(drop=True)


def load_report(folder) -> Report:
    """Read a report folder written by ``foldstat stats`` (``python -m crosssection stats``).

    Parameters
    ----------
    folder : str or Path
        Holds ``stats.json`` and the CSV tables.

    Returns
    -------
    Report

    Raises
    ------
    ParameterError
        ``folder`` is not a path.
    ConfigError
        No ``stats.json`` (not a report folder), or an unreadable file.
    """
    folder = _folder(folder)
    meta_path = folder / "stats.json"
    try:
        meta = json.loads(meta_path.read_text())
    except FileNotFoundError:
        raise ConfigError("not a stats report folder (no stats.json)", folder) from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"unreadable stats.json ({why_unreadable(exc)})", meta_path) from None
    tables = {}
    for name in REPORT_TABLES:
        path = folder / f"{name}.csv"
        try:
            tables[name] = pd.read_csv(path)
        except pd.errors.EmptyDataError:  # an empty table is written without a header
            tables[name] = pd.DataFrame()
        except FileNotFoundError:
            raise ConfigError(MISSING_TABLE, path) from None
        except (pd.errors.ParserError, UnicodeDecodeError) as exc:
            raise ConfigError(f"unreadable CSV ({why_unreadable(exc)})", path) from None
    return Report(**tables, meta=meta, folder=folder)
