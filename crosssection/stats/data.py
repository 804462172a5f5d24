"""Read batch outputs, single analyze outputs and simulation ensembles into one long format.

Three kinds of input folders are detected automatically:

- a simulation ensemble (``configs.csv`` + ``branches.csv`` + ``voids.csv``, from
  ``python -m simulate quench``): lengths already in units of L, one set;
- a single ``analyze`` output (``summary.json`` + the schema tables): one configuration;
- a batch output (``index.csv`` and/or per-image folders ``<set>/<stem>/summary.json``):
  the set is the first folder level under the batch root (or the folder name when images sit
  directly under it).

Image lengths are in mm (schema.py) and are normalised by each image's rod length
L = ``summary["rod_length_mm"]`` (paper, section "Experimental set-up": lengths become
independent of the cut position once divided by L); areas by L^2; curvatures times L.

Common representation (:class:`Ensemble`):

- ``configs``: set, config_id, N_l, N_br, n_voids, epsilon, E, rod_length_mm, source,
  quality (the image analysis' quality warning codes joined by ";", "" when none; NaN for
  simulations), E_model_share (the analysis' ``total_energy_rel_uncertainty``: the share of E
  not measured on a free centreline; NaN for simulations)
- ``branches``: set, config_id, length_L, kappa_m_L, kappa_plus_L, e, region, n_br (of the
  branch's stack, NaN if unknown), l_min_L (detection limit in units of L, NaN if none)
- ``stacks``: set, config_id, n_br, length_L, region
- ``voids``: set, config_id, area_L2, perimeter_L, shape_ratio, n_edges, s_min_L2
"""
from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.errors import ConfigError
from crosssection.quality import QualityWarning

CONFIG_COLS = ["set", "config_id", "N_l", "N_br", "n_voids", "epsilon", "E", "rod_length_mm",
               "source", "quality", "E_model_share"]
BRANCH_COLS = ["set", "config_id", "length_L", "kappa_m_L", "kappa_plus_L", "e", "region",
               "n_br", "l_min_L"]
STACK_COLS = ["set", "config_id", "n_br", "length_L", "region"]
VOID_COLS = ["set", "config_id", "area_L2", "perimeter_L", "shape_ratio", "n_edges", "s_min_L2"]
SIM_REGION = "none"  # simulations have no wall: no bulk/periphery split (paper, "Two sub-systems")
TEXT_COLS = {"set", "config_id", "region", "source", "quality"}


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
        self.configs = _numeric(self.configs, CONFIG_COLS)
        self.branches = _numeric(self.branches, BRANCH_COLS)
        self.stacks = _numeric(self.stacks, STACK_COLS)
        self.voids = _numeric(self.voids, VOID_COLS)


def _read_csv(path: Path, required, *, nonempty: bool = False) -> pd.DataFrame:
    try:
        df = pd.read_csv(path)
    except FileNotFoundError:
        raise ConfigError("missing table", path) from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ConfigError(f"unreadable CSV ({type(exc).__name__})", path) from None
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise ConfigError(f"lacks columns {missing}", path)
    if nonempty and df.empty:
        raise ConfigError("holds no rows (header only)", path)
    return df


def detect_kind(folder) -> str:
    """``"simulation"``, ``"image"`` (one analyze output) or ``"batch"``.

    Raises
    ------
    ConfigError
        When the folder holds none of them.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise ConfigError("not a folder", folder)
    if (folder / "configs.csv").is_file():
        return "simulation"
    if (folder / "summary.json").is_file():
        return "image"
    if (folder / "index.csv").is_file() or any(folder.glob("**/summary.json")):
        return "batch"
    raise ConfigError("neither a batch output (index.csv, */summary.json), an analyze "
                      "output (summary.json) nor a simulation ensemble (configs.csv)", folder)


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
    """
    folder = Path(folder)
    name = set_name or folder.resolve().name
    cfg = _read_csv(folder / "configs.csv", ["config_id", "epsilon", "energy_total", "n_stacks",
                                             "n_branches", "n_voids"], nonempty=True)
    if "error" in cfg.columns:  # configurations whose simulation raised: no results
        bad = cfg["error"].notna() & (cfg["error"].astype(str).str.strip() != "")
        if bad.any():
            warnings.warn(f"{folder / 'configs.csv'}: {int(bad.sum())} of {len(cfg)} "
                          "configurations failed in the simulation (see failures.csv) and "
                          "are left out", QualityWarning, stacklevel=2)
            cfg = cfg[~bad]
    br = _read_csv(folder / "branches.csv", ["config_id", "length", "kappa_plus", "kappa_pm",
                                             "energy"])
    vo = _read_csv(folder / "voids.csv", ["config_id", "area", "shape_ratio", "n_edges"])
    configs = pd.DataFrame({
        "set": name, "config_id": cfg["config_id"].astype(str), "N_l": cfg["n_stacks"],
        "N_br": cfg["n_branches"], "n_voids": cfg["n_voids"], "epsilon": cfg["epsilon"],
        "E": cfg["energy_total"], "rod_length_mm": np.nan, "source": str(folder)})
    n_br = br["n_br"] if "n_br" in br.columns else np.nan
    branches = pd.DataFrame({
        "set": name, "config_id": br["config_id"].astype(str), "length_L": br["length"],
        "kappa_m_L": br["kappa_pm"].abs(), "kappa_plus_L": br["kappa_plus"],
        "e": br["energy"], "region": br["region"] if "region" in br.columns else SIM_REGION,
        "n_br": n_br, "l_min_L": np.nan})
    if (folder / "stacks.csv").is_file():  # optional: per-stack branch counts
        st = _read_csv(folder / "stacks.csv", ["config_id", "n_br"])
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


def load_image_output(folder, *, set_name: str, config_id: str | None = None,
                      l_min_mm: float | None = 1.0, s_min_mm2: float | None = 1.0) -> Ensemble:
    """Read one ``analyze`` output folder and normalise it by its rod length L.

    Parameters
    ----------
    folder : path
        Holds ``summary.json``, ``stacks.csv``, ``branches.csv``, ``voids.csv``.
    set_name : str
    config_id : str, optional
        Defaults to the folder name.
    l_min_mm, s_min_mm2 : float or None
        Detection limits (paper: l_min = 1 mm, s_min = (10 h)^2 = 1 mm^2 for h = 0.1 mm),
        recorded per observation in units of L / L^2.

    Returns
    -------
    Ensemble
    """
    folder = Path(folder)
    cid = config_id or folder.name
    try:
        summary = json.loads((folder / "summary.json").read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ConfigError(f"unreadable summary.json ({type(exc).__name__})",
                          folder / "summary.json") from None
    L = summary.get("rod_length_mm")
    if L is None or not np.isfinite(L) or L <= 0:
        raise ConfigError("summary.json has no positive rod_length_mm", folder / "summary.json")
    L = float(L)
    br = _read_csv(folder / "branches.csv", ["stack_id", "length_mm", "kappa_plus", "kappa_m",
                                             "energy", "region"])
    st = _read_csv(folder / "stacks.csv", ["stack_id", "n_br", "length_mm", "region"])
    vo = _read_csv(folder / "voids.csv", ["area_mm2", "perimeter_mm", "shape_ratio", "n_edges"])
    n_stacks = summary.get("n_stacks", len(st))
    n_br_map = dict(zip(st["stack_id"], st["n_br"]))
    configs = pd.DataFrame([{
        "set": set_name, "config_id": str(cid), "N_l": n_stacks,
        "N_br": summary.get("n_branches", len(br)), "n_voids": summary.get("n_voids", len(vo)),
        "epsilon": summary.get("epsilon", np.nan), "E": summary.get("total_energy", np.nan),
        "rod_length_mm": L, "source": str(folder),
        "quality": ";".join((summary.get("quality") or {}).get("codes", [])),
        "E_model_share": summary.get("total_energy_rel_uncertainty", np.nan)}])
    branches = pd.DataFrame({
        "set": set_name, "config_id": str(cid), "length_L": br["length_mm"] / L,
        "kappa_m_L": br["kappa_m"] * L, "kappa_plus_L": br["kappa_plus"] * L,
        "e": br["energy"], "region": br["region"].astype(str),
        "n_br": br["stack_id"].map(n_br_map),
        "l_min_L": (l_min_mm / L) if l_min_mm else np.nan})
    stacks = pd.DataFrame({"set": set_name, "config_id": str(cid), "n_br": st["n_br"],
                           "length_L": st["length_mm"] / L, "region": st["region"].astype(str)})
    voids = pd.DataFrame({
        "set": set_name, "config_id": str(cid), "area_L2": vo["area_mm2"] / L ** 2,
        "perimeter_L": vo["perimeter_mm"] / L, "shape_ratio": vo["shape_ratio"],
        "n_edges": vo["n_edges"], "s_min_L2": (s_min_mm2 / L ** 2) if s_min_mm2 else np.nan})
    return Ensemble(configs.reindex(columns=CONFIG_COLS), branches.reindex(columns=BRANCH_COLS),
                    stacks.reindex(columns=STACK_COLS), voids.reindex(columns=VOID_COLS))


def _batch_image_folders(folder: Path):
    """(set, config_id, folder) of every finished image of a batch output.

    ``index.csv`` (columns set, status, output) is used when present: rows with status ``ok``
    or ``skipped`` (done in an earlier run) whose folder holds a summary. Otherwise every
    ``summary.json`` below ``folder`` counts, except in hidden folders (the batch's
    ``.<stem>.partial-*`` staging folders of interrupted runs).
    """
    index = folder / "index.csv"
    if index.is_file():
        try:
            idx = pd.read_csv(index)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError):
            idx = None
        if idx is not None and {"set", "status", "output"} <= set(idx.columns):
            out = []
            for row in idx.itertuples(index=False):
                if str(row.status) not in ("ok", "skipped") or not isinstance(row.output, str):
                    continue
                img = folder / row.output
                if (img / "summary.json").is_file():
                    cid = "/".join(Path(row.output).parts[1:]) or Path(row.output).name
                    out.append((str(row.set), cid, img))
            if out:
                return out
    out = []
    for summ in sorted(folder.glob("**/summary.json")):
        img = summ.parent
        rel = img.relative_to(folder)
        if any(part.startswith(".") for part in rel.parts):
            continue
        if len(rel.parts) >= 2:
            out.append((rel.parts[0], "/".join(rel.parts[1:]), img))
        else:
            out.append((folder.resolve().name, rel.parts[0], img))
    return out


def load_batch(folder, *, l_min_mm=1.0, s_min_mm2=1.0) -> Ensemble:
    """Read every per-image folder of a batch output.

    The set of an image folder is its first path component under ``folder``; an image folder
    directly under ``folder`` belongs to the set named after ``folder``. Folders without a
    ``summary.json`` (unfinished or failed images, see ``failures.csv``) are skipped.

    Parameters
    ----------
    folder : path
    l_min_mm, s_min_mm2 : float or None
        Detection limits (see :func:`load_image_output`).

    Returns
    -------
    Ensemble
    """
    folder = Path(folder)
    parts = []
    for set_name, cid, img in _batch_image_folders(folder):
        parts.append(load_image_output(img, set_name=set_name, config_id=cid,
                                       l_min_mm=l_min_mm, s_min_mm2=s_min_mm2))
    if not parts:
        raise ConfigError("batch output holds no finished image (no */summary.json)", folder)
    return Ensemble.concat(parts)


def load_any(folder, *, set_name=None, l_min_mm=1.0, s_min_mm2=1.0) -> Ensemble:
    """Load any supported folder (see :func:`detect_kind`).

    Parameters
    ----------
    folder : path
    set_name : str, optional
        Overrides the set name (all sets of a batch are then merged under it).
    l_min_mm, s_min_mm2 : float or None
        Image detection limits.

    Returns
    -------
    Ensemble
    """
    kind = detect_kind(folder)
    if kind == "simulation":
        return load_simulation(folder, set_name=set_name)
    if kind == "image":
        return load_image_output(folder, set_name=set_name or Path(folder).resolve().name,
                                 l_min_mm=l_min_mm, s_min_mm2=s_min_mm2)
    ens = load_batch(folder, l_min_mm=l_min_mm, s_min_mm2=s_min_mm2)
    if set_name:
        for df in (ens.configs, ens.branches, ens.stacks, ens.voids):
            df["set"] = set_name
    return ens


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
    ConfigError
        No ``stats.json`` (not a report folder), or an unreadable file.
    """
    folder = Path(folder)
    meta_path = folder / "stats.json"
    try:
        meta = json.loads(meta_path.read_text())
    except FileNotFoundError:
        raise ConfigError("not a stats report folder (no stats.json)", folder) from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"unreadable stats.json ({type(exc).__name__})", meta_path) from None
    tables = {}
    for name in REPORT_TABLES:
        path = folder / f"{name}.csv"
        try:
            tables[name] = pd.read_csv(path)
        except pd.errors.EmptyDataError:  # an empty table is written without a header
            tables[name] = pd.DataFrame()
        except FileNotFoundError:
            raise ConfigError("missing table", path) from None
        except (pd.errors.ParserError, UnicodeDecodeError) as exc:
            raise ConfigError(f"unreadable CSV ({type(exc).__name__})", path) from None
    return Report(**tables, meta=meta, folder=folder)
