"""``set.toml``: the parameters shared by the scans of one experimental set.

A *set* is a folder holding a ``set.toml``; every image below it (recursively, down to the next
folder with its own ``set.toml``) belongs to it. Example::

    name = "confined_r20"
    px_per_mm = 50
    thickness_mm = 0.1
    hole_radius_mm = 20.0
    rod_length_mm = 1500.0
    calibration = "calibration.csv"     # relative to the set folder
    bending_rigidity_J = 1.2e-4          # B, J*m: turns e into physical energy (paper, "Energetical properties")
    kappa_c_per_mm = 5.0                 # plastic threshold kappa_c

    [images."scan_03.png"]               # per-image overrides (path relative to the set folder)
    hole_radius_mm = 19.5

``name`` is optional: a set is named by its folder's path under the batch's input folder
(``eps8/day1``), which no other set has. Two folders may declare one ``name`` only when their
parameters are the same: their scans are then one set (a set split over several folders);
a batch refuses two folders of one name whose parameters differ, whose scans would
otherwise be pooled as one set.

Unknown keys are errors (a typo such as ``px_per_m`` would otherwise silently fall back to a
default and bias every length of the set). Values are checked for type and sign; the calibration
file must exist and hold the columns ``n_layers,width_mm``.
"""
from __future__ import annotations

import math
import re
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path

from crosssection.core.errors import ConfigError, FoldstatError, ParameterError
from crosssection.core.fileio import read_toml
from crosssection.params import (CHOICE_PARAMS, PARAM_NAMES, SET_META_KEYS, AnalysisParams,
                                 check_param)

SET_FILE = "set.toml"

#: keys describing the set rather than one analysis; never passed to the analysis as-is
META_KEYS = SET_META_KEYS
PARAM_KEYS = PARAM_NAMES
ALLOWED_KEYS = META_KEYS + PARAM_KEYS + ("images",)

#: parameters of images outside any set beyond the AnalysisParams defaults
DEFAULT_PARAMS: dict = {}
DEFAULT_SET_NAME = "default"

_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


@dataclass
class SetConfig:
    """One set of scans.

    Attributes
    ----------
    name : str
        Output sub-folder name (``OUT_DIR/<name>/``): the ``name`` of ``set.toml``, else the
        set folder's path under the input folder (posix, possibly nested).
    folder : Path
        The folder holding ``set.toml`` (or the input root for images outside any set).
    params : dict
        Analysis parameters of the set (calibration resolved to an absolute path).
    overrides : dict
        Image path relative to ``folder`` (posix) -> dict of parameters overriding ``params``.
    source : Path or None
        The ``set.toml`` read, None for the default set.
    error : str or None
        Why the set cannot be used (bad ``set.toml``, missing calibration); its images fail
        with this reason.
    warnings : list of str
        Non-fatal remarks (an override naming no image, ...).
    """

    name: str
    folder: Path
    params: dict = field(default_factory=dict)
    overrides: dict = field(default_factory=dict)
    source: Path | None = None
    error: str | None = None
    warnings: list = field(default_factory=list)

    def params_for(self, image_path) -> dict:
        """Parameters of one image of the set: the set's, updated by its override table.

        Parameters
        ----------
        image_path : str or Path
            The image: a path as the caller reaches it, or relative to the set folder
            (``"scan_03.png"``, as the set.toml names it).

        Returns
        -------
        dict
            Keyword parameters of :func:`crosssection.analyze`.

        Raises
        ------
        ParameterError
            The image lies outside the set folder.
        """
        folder = self.folder.resolve()
        path = Path(image_path)
        candidates = [path.resolve()]
        if not path.is_absolute():
            candidates.append((folder / path).resolve())
        for cand in candidates:
            if cand.is_relative_to(folder):
                rel = cand.relative_to(folder).as_posix()
                break
        else:
            raise ParameterError(f"the image lies outside the set folder {self.folder}",
                                 image_path)
        out = dict(self.params)
        out.update(self.override_of(rel))
        return out

    def override_of(self, rel: str) -> dict:
        """The override table of the image at ``rel`` (a path relative to the set folder),
        names compared in one Unicode form: a file copied from a Mac keeps its accents
        decomposed (NFD), a set.toml typed elsewhere holds them composed (NFC)."""
        return self.overrides.get(unicodedata.normalize("NFC", rel), {})


def _check_value(key, value, path, where, origin=None):
    """Validate one parameter value (the checks of :class:`AnalysisParams`); return it
    normalised (floats, absolute calibration path). ``origin`` names where the value was
    given in a calibration's errors (default: ``path``)."""
    ctx = f"{where}{key}"
    if key not in PARAM_KEYS:
        raise ConfigError(f"unknown key {ctx!r}; allowed: {', '.join(ALLOWED_KEYS)}", path)
    if key == "calibration":
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{ctx} must be a file path (string), got {value!r}", path)
        cal = Path(value)
        if not cal.is_absolute():
            cal = Path(path).parent / cal
        check_calibration(cal, origin=path if origin is None else origin)
        return str(cal.resolve())
    if isinstance(value, str) and key not in CHOICE_PARAMS:
        raise ConfigError(f"{ctx} must be a number, got {value!r}", path)
    try:
        value = check_param(key, value)
    except ParameterError as exc:
        raise ConfigError(f"{where}{exc.cause}", path) from None
    return list(value) if isinstance(value, tuple) else value


def check_calibration(cal_path, origin=None) -> Path:
    """Check that a calibration CSV reads as a calibration (the checks of
    :meth:`crosssection.core.calibration.Calibration.from_csv`, in its words).

    Parameters
    ----------
    cal_path : str or Path
        The calibration file.
    origin : str or Path, optional
        The file that named it (named in the error).

    Returns
    -------
    Path

    Raises
    ------
    ConfigError
        Missing, unreadable or malformed file.
    """
    from crosssection.core.calibration import Calibration

    cal_path = Path(cal_path)
    try:
        Calibration.from_csv(cal_path)
    except ConfigError as exc:
        if not origin:
            raise
        raise ConfigError(f"{exc.cause} (named in {origin})", cal_path) from None
    return cal_path


def check_params(params: dict, path=None, where: str = "", origin=None) -> dict:
    """Validate a dict of analysis parameters (the keys of :data:`PARAM_KEYS`).

    Parameters
    ----------
    params : dict
        Raw values (from TOML or the command line). ``None`` values are dropped.
    path : str or Path, optional
        File the values come from; relative calibration paths are resolved against its folder.
    where : str
        Prefix naming the table in messages (``'images."a.png".'``).
    origin : str, optional
        Where the values were given, named in a calibration's errors (default: ``path``;
        ``"--calibration"`` for the command line).

    Returns
    -------
    dict
        Normalised parameters.
    """
    return {k: _check_value(k, v, path if path is not None else Path.cwd() / "cli", where,
                            origin)
            for k, v in params.items() if v is not None}


def default_set_name(folder, root=None) -> str:
    """The name of a set whose ``set.toml`` gives none: its folder's path under ``root``
    (posix; unique among the sets of one input folder, unlike the folder's own name, which
    two experiments' ``day1/`` folders share), or the folder's name when it is ``root`` or
    ``root`` is not given; characters a set name does not take become ``_``.

    Parameters
    ----------
    folder : str or Path
        The set folder.
    root : str or Path, optional
        The input folder of the batch.

    Returns
    -------
    str
    """
    folder = Path(folder)
    parts = [folder.name]
    if root is not None:
        try:
            rel = folder.relative_to(Path(root))
        except ValueError:
            rel = Path(".")
        if rel.parts:
            parts = list(rel.parts)
    return "/".join(_safe_part(q) for q in parts)


def _safe_part(text: str) -> str:
    """A folder name made of the characters a set name takes (accents dropped, others become
    ``_``; a name must start with a letter or a digit): ``exp A`` -> ``exp_A``, ``série à``
    -> ``serie_a``."""
    # letters with accents keep their base letter (NFKD splits off the combining marks)
    text = "".join(c for c in unicodedata.normalize("NFKD", text)
                   if not unicodedata.combining(c))
    safe = re.sub(r"[^A-Za-z0-9._+-]", "_", text)
    safe = re.sub(r"^[^A-Za-z0-9]+", "", safe)
    return safe or "set"


def valid_set_name(name, toml_path) -> str:
    """``name`` when it is a set name: folder names of ASCII letters, digits and
    ``. _ + -``, starting with a letter or a digit, joined by ``/`` (``eps8/day1``, as a set
    is named by its path), else a ConfigError naming ``toml_path``."""
    parts = name.split("/") if isinstance(name, str) else [name]
    # fullmatch: "$" alone would let a name end in a line break
    if not all(isinstance(p, str) and _SAFE_NAME.fullmatch(p) and p not in (".", "..")
               for p in parts):
        raise ConfigError(f"name must be folder names (ASCII letters, digits, . _ + -, each "
                          f"starting with a letter or a digit) joined by '/', got {name!r}",
                          toml_path)
    return name


def load_set_config(toml_path, *, defaults: dict | None = None,
                    given: dict | None = None, root=None) -> SetConfig:
    """Read and validate a ``set.toml``.

    Parameters
    ----------
    toml_path : str or Path
        The file.
    defaults : dict, optional
        Parameters used where the set is silent (the command-line values).
    given : dict, optional
        The values given on the command line: one the set's file replaces is named in a
        warning.
    root : str or Path, optional
        The input folder of the batch: a set without ``name`` is named by its folder's path
        under it (:func:`default_set_name`).

    Returns
    -------
    SetConfig

    Raises
    ------
    ConfigError
        Unreadable TOML, unknown key, wrong type or sign, missing or malformed calibration,
        unsafe set name.
    """
    toml_path = Path(toml_path)
    data = read_toml(toml_path)
    folder = toml_path.parent
    if "name" in data:
        name = valid_set_name(data["name"], toml_path)
    else:
        name = valid_set_name(default_set_name(folder, root), toml_path)
    images = data.get("images", {})
    if not isinstance(images, dict) or any(not isinstance(v, dict) for v in images.values()):
        raise ConfigError("[images] must hold one table per image, e.g. "
                          "[images.\"scan_03.png\"]", toml_path)
    top = {k: v for k, v in data.items() if k not in ("name", "images")}
    params = dict(defaults or {})
    checked = check_params(top, toml_path)
    params.update(checked)
    overrides, warnings = {}, []
    # a set's file wins over the command line (its values belong to its scans): say so
    for key, value in checked.items():
        if key in (given or {}) and given[key] != value:
            warnings.append(f"{toml_path}: sets {key} = {value!r}, which replaces "
                            f"--{key.replace('_', '-')} {given[key]!r} for the scans of "
                            f"this set")
    for rel, table in images.items():
        bad = [k for k in table if k not in PARAM_KEYS]
        if bad:
            raise ConfigError(f"unknown key {bad[0]!r} in [images.{rel!r}]; allowed: "
                              f"{', '.join(PARAM_KEYS)}", toml_path)
        key = unicodedata.normalize("NFC", Path(rel).as_posix())
        overrides[key] = check_params(table, toml_path, where=f"images.{rel!r}.")
        replaced = [k for k, v in overrides[key].items()
                    if k in (given or {}) and given[k] != v]
        if replaced:
            warnings.append(f"{toml_path}: [images.{rel!r}] sets "
                            + ", ".join(f"{k} = {overrides[key][k]!r}" for k in replaced)
                            + ", which replaces " + ", ".join(
                                f"--{k.replace('_', '-')} {given[k]!r}" for k in replaced)
                            + " for that scan")
        if not any((folder / unicodedata.normalize(form, key)).is_file()
                   for form in ("NFC", "NFD")):
            warnings.append(f"{toml_path}: [images.{rel!r}] names no image of the set")
    return SetConfig(name=name, folder=folder, params=params, overrides=overrides,
                     source=toml_path, warnings=warnings)


def failed_set(toml_path, error: str, root=None) -> SetConfig:
    """A placeholder set whose images all fail with ``error`` (named after its folder,
    :func:`default_set_name`)."""
    toml_path = Path(toml_path)
    name = default_set_name(toml_path.parent, root)
    try:
        valid_set_name(name, toml_path)
    except ConfigError:
        name = "invalid_set"
    return SetConfig(name=name, folder=toml_path.parent, source=toml_path, error=error)


__all__ = ["SetConfig", "load_set_config", "default_set_name", "valid_set_name", "check_params",
           "check_calibration", "failed_set", "set_not_read",
           "SET_FILE", "DEFAULT_PARAMS", "DEFAULT_SET_NAME", "PARAM_KEYS", "ALLOWED_KEYS"]


def _shown(path: Path) -> Path:
    """``path`` relative to the working folder where it lies below it (as a user typed it)."""
    try:
        return path.relative_to(Path.cwd().resolve())
    except (ValueError, OSError):  # not below it, or the working folder is gone
        return path


def _same(a, b) -> bool:
    """Equal parameter values: numbers to a part in 10^4 (a set.toml records a hole to the
    hundredth of a pixel; a scene's truth holds it to the bit), sequences element by element."""
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=1e-4, abs_tol=1e-9)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def _same_calibration(a, b) -> bool:
    """Two calibration values (paths, tables) that hold the same table: a copy of the set's
    ``calibration.csv`` elsewhere is the same calibration."""
    from crosssection.core.calibration import Calibration

    if a is None or b is None:
        return False
    try:
        ca, cb = Calibration.of(a), Calibration.of(b)
    except (FoldstatError, OSError, ValueError):
        return False
    return (_same(list(ca.n_layers), list(cb.n_layers))
            and _same(list(ca.width_mm), list(cb.width_mm)))


def set_not_read(image, params: AnalysisParams) -> str | None:
    """Why the scan's own set would analyse it differently, or None.

    ``analyze`` reads only its parameters; the ``set.toml`` of the set a scan belongs to (the
    nearest one in its folder or above) is read by ``batch``. Where that file sets values
    other than the ones used (a calibration, the scale, the hole), the same scan gives other
    numbers in a batch: the user most likely meant them. Without a ``set.toml``, a
    ``calibration.csv`` beside an uncalibrated scan is named the same way.

    Parameters
    ----------
    image : str or Path
        The scan.
    params : AnalysisParams
        The parameters the analysis uses.

    Returns
    -------
    str or None
        A ``FILE: ...`` message, None when nothing differs.
    """
    from crosssection.batch import loose_calibration

    image = Path(image)
    try:
        parents = image.resolve().parents
    except (OSError, RuntimeError):  # a loop of symbolic links: the loader names it
        return None
    for folder in parents:
        toml = folder / SET_FILE
        if not toml.is_file():
            continue
        shown, where = _shown(toml), _shown(folder)
        try:
            wanted = load_set_config(toml).params_for(image)
        except (FoldstatError, OSError, ValueError):
            return f"{image}: {shown} is not read by analyze (and it is not valid: run batch " \
                   "on its folder to see why)"
        used = {k: getattr(params, k, None) for k in wanted}
        # a calibration given as a table (a DataFrame, pairs) is compared by its values
        differ = [k for k, v in wanted.items()
                  if not (_same_calibration(v, used[k]) if k == "calibration"
                          else _same(v, used[k]))]
        if not differ:
            return None
        plural = len(differ) > 1
        return (f"{image}: {shown} is not read by analyze; its {', '.join(differ)} for this "
                f"scan {'differ from the ones' if plural else 'differs from the one'} used: "
                f"pass {'them' if plural else 'it'} (options of the command line, "
                f"parameters of analyze in Python), or run batch on {where}")
    cal = loose_calibration(image, params.calibration)
    if cal is not None:
        return (f"{image}: {cal} beside it is not used (no calibration given): pass "
                f"--calibration {cal} (calibration= in Python)")
    return None
