"""The parameters of one analysis, in one place: :class:`AnalysisParams` and :class:`ScanScale`.

Every default of the scan analysis is a field default of :class:`AnalysisParams`; every entry
point (``analyze``, the ``analyze``/``steps``/``batch`` commands, ``set.toml``, scoring and
validation) builds one through :meth:`AnalysisParams.from_mapping`,
:meth:`AnalysisParams.from_toml` or :meth:`AnalysisParams.from_cli_args`, so values are
validated once, with errors naming the parameter and the file they came from. The command-line
options are generated from the fields (:func:`add_analysis_arguments`), so ``analyze`` and
``batch`` accept the same options with the same help, unit and default.

:class:`ScanScale` owns every conversion between millimetres and pixels.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields
from pathlib import Path

from crosssection.core.errors import FoldstatError, ParameterError
from crosssection.core.fileio import read_toml
from crosssection.core.provenance import resolved_path

__all__ = ["ScanScale", "AnalysisParams", "add_analysis_arguments", "check_param", "PARAM_NAMES",
           "DEFAULT_PX_PER_MM", "DEFAULT_THICKNESS_MM", "scale_left_out",
           "THRESHOLD_METHODS", "CURVATURE_METHODS", "SKELETON_METHODS", "WIDTH_STATISTICS",
           "WIDTH_LAWS", "CHOICE_PARAMS",
           "SWITCHES", "switched_off"]

#: The parameters that are on by default, each turned off by ``--no-<name>`` on the command
#: line (its help text here).
SWITCHES = {
    "merge_thick_crossings": "keep the two junctions of a crossing of thick stacks apart",
    "integer_refinement": "branch counts: the rounded least squares, without the integer "
                          "search and the MILP fallback",
    "layer_steps": "one stack between two junctions even where its width steps by whole "
                   "layers (the paper's stacks)",
    "hole_correction": "use a given hole as given even where the ink crosses its circle",
}

THRESHOLD_METHODS = ("auto", "fixed", "otsu")
#: the first is the default (crosssection.stages.curvature, step 3)
CURVATURE_METHODS = ("walls", "missing", "paper")
SKELETON_METHODS = ("thinning", "skimage")
WIDTH_STATISTICS = ("median", "mean")
#: Width law of an analysis without a calibration; the first is the default
#: (crosssection.stages.widthlaw)
WIDTH_LAWS = ("fitted", "linear")
#: The parameters whose value is one of a few names, with those names.
CHOICE_PARAMS = {"threshold_method": THRESHOLD_METHODS, "curvature_method": CURVATURE_METHODS,
                 "skeleton_method": SKELETON_METHODS, "width_statistic": WIDTH_STATISTICS,
                 "width_law": WIDTH_LAWS}
#: Sheet thickness in pixels below which a scan is low resolution: one pixel of width is a
#: third of a layer or more, and a curvature window of one layer spans under 15 px
#: (``crosssection.quality``, ``low_resolution``)
LOW_RESOLUTION_H_PX = 3.0

# Sanity limits that turn absurd values into one clear error rather than a hang or a
# MemoryError: a sheet thinner than a pixel cannot be resolved, and a scan of more than
# 2 000 px per mm (a 0.5 um pixel, 50 800 dpi) is beyond any scanner or microscope scan.
_MAX_PX_PER_MM = 2000.0
_MIN_THICKNESS_PX = 1.0
#: A hole whose radius is below this many sheet thicknesses holds no folded rod (the
#: experiments' holes are 200 h wide and more).
MIN_HOLE_SHEETS = 5.0


#: How an analysis without a calibration names its width law (``summary.json``
#: ``calibration``): one layer is h wide, n layers n h.
LINEAR_CALIBRATION = "linear n*h"
#: Longest ``smooth_px`` accepted: the default window of any scan that holds its sheet
#: thickness h (h < half the image side) stays below it.
SMOOTH_PX_MAX = 20_001
#: Longest ``smooth_px`` accepted, in sheet thicknesses h (the default is 2 floor(h) + 1)
SMOOTH_H_MAX = 10
#: Longest ``tangent_mm`` accepted, in sheet thicknesses h (default 3 h; 1.5-12 h measured):
#: a tangent of 100 mm on a 15 mm hole turned 201 branches into 293 with no warning of it
TANGENT_H_MAX = 20
#: Key of the record of a calibration object that is no table (``{key: type name}``).
UNRECORDED_CALIBRATION = "object"


class _DefaultScale(float):
    """The default ``px_per_mm``, a float that says it was not given: an
    ``AnalysisParams(px_per_mm=50)`` holds a plain 50.0, one that left it out this object,
    so that a scan read at a scale nobody gave is flagged (``scale_assumed``) and one read
    at the same scale given is not. It survives ``dataclasses.replace`` of other fields."""

    __slots__ = ()

    def __reduce__(self):
        return (_DefaultScale, (float(self),))


#: the default scan resolution, px/mm (50 px/mm, 1270 dpi: the paper's scans)
DEFAULT_PX_PER_MM = _DefaultScale(50.0)
#: The paper's polyester sheet: h = 0.1 mm ("Experimental set-up")
DEFAULT_THICKNESS_MM = 0.1


def scale_left_out(params) -> bool:
    """Whether ``params`` (an :class:`AnalysisParams`) holds the default ``px_per_mm``
    because none was given, rather than a scale given (at the default value or not)."""
    return isinstance(getattr(params, "px_per_mm", None), _DefaultScale)


@dataclass(frozen=True)
class ScanScale:
    """Resolution and sheet thickness of a scan; every mm <-> px conversion.

    Parameters
    ----------
    px_per_mm : float
        Scan resolution (the paper's scans: 50 px/mm).
    thickness_mm : float
        Sheet thickness h (the paper's polyester: 0.1 mm).

    Raises
    ------
    ParameterError
        A value that is not a positive number in the range ``AnalysisParams`` accepts.
    """

    px_per_mm: float = float(DEFAULT_PX_PER_MM)
    thickness_mm: float = DEFAULT_THICKNESS_MM

    def __post_init__(self):
        # the same checks as AnalysisParams': a string or a negative scale would convert
        # without an error ("50" * 2 is "5050")
        for name in ("px_per_mm", "thickness_mm"):
            object.__setattr__(self, name, float(check_param(name, getattr(self, name))))

    @property
    def thickness_px(self) -> float:
        """Sheet thickness h in pixels."""
        return self.thickness_mm * self.px_per_mm

    def to_px(self, length_mm):
        """Length in mm -> px."""
        return length_mm * self.px_per_mm

    def to_mm(self, length_px):
        """Length in px -> mm."""
        return length_px / self.px_per_mm

    def area_to_px2(self, area_mm2):
        """Area in mm^2 -> px^2."""
        return area_mm2 * self.px_per_mm ** 2

    def area_to_mm2(self, area_px2):
        """Area in px^2 -> mm^2."""
        return area_px2 / self.px_per_mm ** 2


def _opt(help_text: str, unit: str = "", *, cli: bool = True, choices=None, nargs=None,
         metavar=None):
    return {"help": help_text, "unit": unit, "cli": cli, "choices": choices, "nargs": nargs,
            "metavar": metavar}


@dataclass(frozen=True)
class AnalysisParams:
    """Every parameter of the analysis of one scan, validated on construction.

    Lengths are in mm, areas in mm^2, pixel positions as (x, y) = (column, row). ``None``
    means "derived" (from the scan, the sheet thickness, or measured); the value used is
    recorded in ``summary.json``, whose ``parameters`` give this class back the same analysis
    (``AnalysisParams(**summary["parameters"])``).

    ``calibration`` is a CSV path, a :class:`~crosssection.core.calibration.Calibration`, a
    DataFrame with columns ``n_layers`` and ``width_mm``, or ``[[n_layers, width_mm], ...]``
    pairs (the form ``summary.json`` records a table given in memory in, at full precision;
    turned into a ``Calibration``).
    """

    px_per_mm: float = field(default=DEFAULT_PX_PER_MM,
                             metadata=_opt("scan resolution", "px/mm"))
    thickness_mm: float = field(default=DEFAULT_THICKNESS_MM,
                                metadata=_opt("sheet thickness h", "mm"))
    hole_radius_mm: float | None = field(default=None, metadata=_opt(
        "hole radius R; nothing outside the hole is analysed (default: found in the scan)",
        "mm"))
    hole_center_px: tuple | None = field(default=None, metadata=_opt(
        "hole centre, x = column, y = row (default: found in the scan)", "px", nargs=2,
        metavar=("X", "Y")))
    calibration: object = field(default=None, metadata=_opt(
        "CSV n_layers,width_mm: width of a cut stack of n layers (default: the law "
        "width_law, with a warning)"))
    width_law: str = field(default=WIDTH_LAWS[0], metadata=_opt(
        "without a calibration: fitted (width = a + b n, a read at the junctions, b from "
        "the widths' lattice of whole layers, bent by a term in n^2 or sqrt(n) where wide "
        "stacks ask for it; w = n h where the scan shows none) or linear "
        "(width = n h); a calibration given overrides it", choices=WIDTH_LAWS))
    rod_length_mm: float | None = field(default=None, metadata=_opt(
        "known rod length L for the dimensionless energies and epsilon (default: measured "
        "sum n_br l)", "mm"))
    threshold_method: str = field(default="auto", metadata=_opt(
        "ink threshold: auto (blue dominance, cut chosen from the scan), fixed (the paper's "
        "blue >= blue_min, red and green <= rg_max) or otsu", choices=THRESHOLD_METHODS))
    blue_min: float | None = field(default=None, metadata=_opt(
        "minimum blue, native units: the fixed threshold's cut (default 100 for 8-bit, "
        "100 * 257 for 16-bit and float files; for a float array in [0, 1] given to "
        "analyze, in its scale); given with auto, an extra bound on the automatic cut; not "
        "with otsu"))
    rg_max: float | None = field(default=None, metadata=_opt(
        "maximum red and green, native units: the fixed threshold's cut (default 130 for "
        "8-bit, 130 * 257 for 16-bit and float files, also otsu's bound; for a float array "
        "in [0, 1] given to analyze, in its scale); given with auto, an extra bound on the "
        "automatic cut"))
    s_min_mm2: float | None = field(default=None, metadata=_opt(
        "smallest void (default (10 h)^2, the paper's)", "mm^2"))
    sliver_width_h: float = field(default=1.5, metadata=_opt(
        "a hole below s_min at least this many h wide, l_min long and 4 times longer than "
        "wide is kept as the gap between two stacks (0: every hole below s_min is filled, the "
        "paper's rule)"))
    skeleton_method: str = field(default="thinning", metadata=_opt(
        "thinning step of the skeleton: thinning (the package's Zhang-Suen thinning) or "
        "skimage (skimage.morphology.skeletonize); both followed by the same removal of "
        "redundant pixels and spur pruning", choices=SKELETON_METHODS))
    l_min_mm: float = field(default=1.0, metadata=_opt(
        "detection limit (paper: 1 mm): skeleton spurs ending free and isolated pieces of ink "
        "shorter than this are removed; stacks between two junctions are kept whatever their "
        "length", "mm"))
    kappa_c_per_mm: float | None = field(default=None, metadata=_opt(
        "plastic curvature threshold of the bending energy (default: none)", "1/mm"))
    width_statistic: str = field(default="median", metadata=_opt(
        "width of a stack from its width profile away from its ends: median or mean",
        choices=WIDTH_STATISTICS))
    tangent_mm: float | None = field(default=None, metadata=_opt(
        "length of the stack-tangent fit at junctions (default 3 h, at most 20 h)", "mm"))
    bending_rigidity_J: float | None = field(default=None, metadata=_opt(
        "bending rigidity B; adds total_energy_J = e B / (2 L) to the summary", "J m"))
    smooth_px: int | None = field(default=None, metadata=_opt(
        "sliding-average window of the centrelines (default 2 floor(h) + 1, at most 10 h)", "px"))
    merge_px: float = field(default=2.0, metadata=_opt(
        "junction pixels closer than this are one junction", "px"))
    merge_thick_crossings: bool = field(default=True, metadata=_opt(
        "merge junctions joined by a stack inside one ink blob", cli=False))
    curvature_method: str = field(default=CURVATURE_METHODS[0], metadata=_opt(
        "curvature estimator: paper (parabolic fits over 5 n_br h; fork zones take the nearest "
        "fitted curvature), missing (the same fits; fork zones as missing data, the "
        "curvature trend continued to the junction where it exceeds the noise; the scan's "
        "curvature noise removed from the energy; curvature bounded by 2 / (n_br h)) or walls "
        "(as missing, but a fork zone whose arm runs along the merged ink's outer wall is "
        "measured there, at the arm's half width from that wall)",
        choices=CURVATURE_METHODS))
    integer_refinement: bool = field(default=True, metadata=_opt(
        "improve the rounded least-squares branch counts by exact integer moves, and by the "
        "MILP on small components the moves leave unbalanced; off: the rounding is the "
        "result", cli=False))
    hole_correction: bool = field(default=True, metadata=_opt(
        "when the ink crosses a given hole's circle (a radius or centre given a little off "
        "cuts the wall band), use the hole found in the scan if it lies near the given one "
        "and frames the ink; off: the given hole as given (both flagged)", cli=False))
    layer_steps: bool = field(default=True, metadata=_opt(
        "cut a stack where its width steps by whole layers along it (layers ending inside "
        "the band: a rod end, or folds at a band's end while a layer goes on); off: one "
        "stack between two junctions, the paper's", cli=False))

    # ------------------------------------------------------------------ validation
    def __post_init__(self):
        left_out = scale_left_out(self)
        for f in fields(self):
            object.__setattr__(self, f.name, check_param(f.name, getattr(self, f.name)))
        if left_out:  # the default stays marked as not given
            object.__setattr__(self, "px_per_mm", DEFAULT_PX_PER_MM)
        if self.thickness_px < _MIN_THICKNESS_PX:
            raise ParameterError(
                f"sheet thickness h = {self.thickness_mm:g} mm is {self.thickness_px:.3g} px at "
                f"{self.px_per_mm:g} px/mm: below one pixel it cannot be resolved (check "
                "px_per_mm and thickness_mm)")
        if self.threshold_method == "otsu" and self.blue_min is not None:
            # Otsu's method chooses the blue cut itself; only rg_max bounds it
            raise ParameterError(f"blue_min = {self.blue_min:g} is not used by the otsu "
                                 "threshold, which chooses the blue cut itself: leave it out, "
                                 "or use threshold_method fixed or auto")
        if (self.hole_center_px is None) != (self.hole_radius_mm is None) \
                and self.hole_center_px is not None:
            raise ParameterError("hole_center_px needs hole_radius_mm")
        if self.tangent_mm is not None and self.tangent_mm * self.px_per_mm < 1.0:
            raise ParameterError(f"tangent_mm = {self.tangent_mm:g} mm is "
                                 f"{self.tangent_mm * self.px_per_mm:.3g} px at "
                                 f"{self.px_per_mm:g} px/mm: a tangent is fitted on one pixel "
                                 "or more (default 3 h)")
        if self.tangent_mm is not None and self.tangent_mm > TANGENT_H_MAX * self.thickness_mm:
            # a stack's direction at a junction is read over tangent_mm: beyond a few sheet
            # thicknesses it reads the bends of the stacks, not their directions
            raise ParameterError(f"tangent_mm = {self.tangent_mm:g} mm is more than "
                                 f"{TANGENT_H_MAX} sheet thicknesses (h = "
                                 f"{self.thickness_mm:g} mm): a stack's direction at a "
                                 "junction would be read over its bends (default 3 h)")
        if self.smooth_px is not None and self.smooth_px > SMOOTH_H_MAX * self.thickness_px:
            # averaged over more than a bend: on generated scans (h = 5 px) the total energy
            # read -12 % at the default 11 px, -25 to -33 % at 21 px and -40 to +183 % at
            # 51-101 px
            raise ParameterError(
                f"smooth_px = {self.smooth_px} px is more than {SMOOTH_H_MAX} sheet "
                f"thicknesses (h = {self.thickness_px:.3g} px): the centrelines would be "
                "averaged over their bends (default 2 floor(h) + 1)")

    # ------------------------------------------------------------------ derived values
    @property
    def scale(self) -> ScanScale:
        """Resolution and thickness as a :class:`ScanScale`."""
        return ScanScale(self.px_per_mm, self.thickness_mm)

    @property
    def thickness_px(self) -> float:
        return self.thickness_mm * self.px_per_mm

    @property
    def s_min_used_mm2(self) -> float:
        """Smallest void: the given value or the paper's (10 h)^2."""
        return self.s_min_mm2 if self.s_min_mm2 is not None else (10.0 * self.thickness_mm) ** 2

    @property
    def tangent_used_mm(self) -> float:
        # 3 h: measured best of 1.5-12 h on 6 generated scenes (1-12 layers, noise, blur,
        # JPEG): exact n_br on 100 % of the stack length, against 82-93 % at 2 h and 60-84 %
        # with twice the median width
        return self.tangent_mm if self.tangent_mm is not None else 3.0 * self.thickness_mm

    @property
    def hole_given(self) -> bool:
        return self.hole_radius_mm is not None

    def calibration_source(self) -> str:
        """How the calibration was given, for messages: the default law, the file (absolute,
        links followed), or the object type with its table (rounded)."""
        record = self.calibration_record()
        if record is None:
            return LINEAR_CALIBRATION
        if isinstance(record, str):
            return record
        if isinstance(record, dict):
            return f"{record[UNRECORDED_CALIBRATION]} object"
        law = ", ".join(f"({n:g}, {w:g})" for n, w in record)
        return f"{type(self.calibration).__name__} (n_layers, width_mm): {law}"

    def calibration_record(self):
        """The calibration as ``summary.json`` records it, in a form this class accepts back:
        None for the default law, the file's path (absolute, links followed: the output is
        read from other folders than the caller's), or a table given in memory as
        ``[[n_layers, width_mm], ...]`` pairs at full precision (the width law is part of the
        result: ``AnalysisParams(**summary["parameters"])`` analyses with the same table).
        An object that is no table (one with a ``layers`` method only) is recorded as
        ``{"object": its type's name}``, which this class refuses back with that reason.

        Returns
        -------
        None, str, list of [int, float] or dict
        """
        c = self.calibration
        if c is None:
            return None
        if isinstance(c, (str, Path)):
            return resolved_path(c)
        try:
            table = self._calibration_table()
        except FoldstatError:
            return {UNRECORDED_CALIBRATION: type(c).__name__}
        return [[int(n), float(w)] for n, w in zip(table.n_layers, table.width_mm)]

    def _calibration_table(self):
        from crosssection.core.calibration import Calibration

        return Calibration.of(self.calibration)

    # ------------------------------------------------------------------ constructors
    def replace(self, **changes) -> "AnalysisParams":
        """A copy with some fields changed (validated)."""
        _reject_unknown(changes)
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_mapping(cls, values: dict | None = None, *, path=None, base=None,
                     relative_to=None, **overrides) -> "AnalysisParams":
        """Parameters from a dict (``None`` values mean the default).

        Parameters
        ----------
        values : dict, optional
            Field name -> value; unknown names are errors.
        path : str or Path, optional
            The file the values concern (an image or a parameter file): named in errors.
        relative_to : str or Path, optional
            A file whose folder a relative ``calibration`` path is resolved against (a
            ``set.toml``); by default it is relative to the working directory.
        base : AnalysisParams, optional
            Values used where ``values`` is silent (default: the field defaults).
        **overrides
            More values, applied after ``values``.
        """
        merged = {k: v for k, v in {**(values or {}), **overrides}.items() if v is not None}
        try:
            _reject_unknown(merged)
            cal = merged.get("calibration")
            if isinstance(cal, (str, Path)) and relative_to is not None \
                    and not Path(cal).is_absolute():
                merged["calibration"] = str(Path(relative_to).parent / cal)
            return dataclasses.replace(base, **merged) if base is not None else cls(**merged)
        except FoldstatError as exc:
            raise type(exc)(exc.cause, path if path is not None else exc.path) from None

    @classmethod
    def from_toml(cls, path, *, table: str | None = None) -> "AnalysisParams":
        """Parameters from a TOML file: its top level, updated by one of its tables.

        Its tables (a set.toml's ``[images."..."]``) and a set's ``name`` are not parameters
        and are passed over; any other key must be a parameter: a misspelt one is an error,
        not a default silently used. The parameters of one image of a set.toml, its override
        table included, are ``crosssection.setconfig.load_set_config(toml_path).params_for(image)``.

        Parameters
        ----------
        path : str or Path
            The TOML file.
        table : str, optional
            A top-level table whose keys update the top level's (``[dense]`` in a file of
            ``px_per_mm = 50`` and ``[dense] s_min_mm2 = 0.02``).

        Returns
        -------
        AnalysisParams

        Raises
        ------
        ParameterError
            An unknown key (its name, the file), a value out of range, or a table the file
            does not hold (a table misspelt would otherwise give the defaults).
        """
        path = Path(path)
        data = read_toml(path)
        values = {k: v for k, v in data.items()
                  if not isinstance(v, dict) and k not in SET_META_KEYS}
        if table is not None:
            tables = sorted(k for k, v in data.items() if isinstance(v, dict) and k != "images")
            sub = data.get(table)
            if table == "images" or not isinstance(sub, dict):
                hint = (f"its tables: {', '.join(tables)}" if tables else "it holds none")
                if "images" in data:
                    hint += ("; an image's table of a set.toml is read by crosssection."
                             "setconfig.load_set_config(path).params_for(image)")
                raise ParameterError(f"no parameter table [{table}] ({hint})", path)
            values.update({k: v for k, v in sub.items() if not isinstance(v, dict)})
        return cls.from_mapping(values, path=path, relative_to=path)

    @classmethod
    def from_cli_args(cls, args, *, path=None) -> "AnalysisParams":
        """Parameters from ``argparse`` options added by :func:`add_analysis_arguments`."""
        values = {name: getattr(args, name, None) for name in PARAM_NAMES}
        if values.get("calibration") and values.get("width_law") is not None:
            # both on one command line: the law stands in for a calibration and would be
            # ignored (a set's calibration overrides a batch's --width-law, which serves the
            # sets without one)
            raise ParameterError(f"{values['width_law']} is not used with --calibration (the "
                                 "calibration gives the widths of n layers): leave one of "
                                 "them out", "--width-law")
        if values.get("calibration"):
            values["calibration"] = str(Path(values["calibration"]).resolve())
        values.update(switched_off(args))
        return cls.from_mapping(values, path=path)

    def to_dict(self) -> dict:
        """JSON-ready parameters (for ``summary.json`` and the batch's resume hash)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "calibration":
                v = self.calibration_record()
            elif isinstance(v, tuple):
                v = list(v)
            elif isinstance(v, _DefaultScale):  # the record holds the scale the scan was read at
                v = float(v)
            out[f.name] = v
        return out

    # ------------------------------------------------------------------ per image
    def check_image(self, shape, path=None, *, file_px_per_mm=None) -> None:
        """Errors for parameters absurd against the scan's size (``shape`` = (H, W, ...)).

        Parameters
        ----------
        shape : tuple
        path : str or Path, optional
            Named in the error.
        file_px_per_mm : float, optional
            The resolution the file records; named in the error when ``px_per_mm`` differs
            from it (every check here is a size in mm read at ``px_per_mm``).

        Raises
        ------
        ParameterError
            s_min larger than the image, h not small against it, l_min beyond it, a hole
            more than twice the scan's size.
        """
        h, w = int(shape[0]), int(shape[1])
        hint = ""
        if file_px_per_mm and abs(self.px_per_mm / file_px_per_mm - 1.0) > 0.02:
            hint = (f" (px_per_mm = {self.px_per_mm:g}, but the file records "
                    f"{25.4 * file_px_per_mm:.0f} dpi = {file_px_per_mm:.2f} px/mm)")
        s_min_px = self.scale.area_to_px2(self.s_min_used_mm2)
        l_min_px = self.scale.to_px(self.l_min_mm)
        if s_min_px >= h * w:
            given = ("s_min_mm2" if self.s_min_mm2 is not None
                     else "thickness_mm (s_min = (10 h)^2)")
            raise ParameterError(f"s_min = {self.s_min_used_mm2:g} mm^2 = {s_min_px:.6g} px at "
                                 f"px_per_mm = {self.px_per_mm:g} is not smaller than the "
                                 f"image ({w}x{h} px): check px_per_mm and {given}" + hint,
                                 path)
        if self.thickness_px >= min(h, w) / 2:
            raise ParameterError(f"sheet thickness {self.thickness_mm:g} mm = "
                                 f"{self.thickness_px:.1f} px is not small against the image "
                                 f"({w}x{h} px); check px_per_mm and thickness_mm" + hint, path)
        if l_min_px >= max(h, w):
            raise ParameterError(f"l_min = {self.l_min_mm:g} mm = {l_min_px:.6g} px exceeds the "
                                 f"image size ({w}x{h} px)" + hint, path)
        if self.hole_radius_mm is not None:
            r_px = self.scale.to_px(self.hole_radius_mm)
            if 2 * r_px > 2 * max(h, w):
                raise ParameterError(f"hole radius {self.hole_radius_mm:g} mm = {r_px:.0f} px: "
                                     f"the hole is more than twice the scan ({w}x{h} px); "
                                     "check hole_radius_mm and px_per_mm" + hint, path)
            if r_px < MIN_HOLE_SHEETS * self.thickness_px:
                raise ParameterError(f"hole radius {self.hole_radius_mm:g} mm = {r_px:.1f} px: "
                                     f"a radius below {MIN_HOLE_SHEETS:g} sheet thicknesses "
                                     f"({self.thickness_mm:g} mm), no rod fits in it; check "
                                     "hole_radius_mm and px_per_mm" + hint, path)
            if self.hole_center_px is not None:
                x, y = self.hole_center_px
                if not (-r_px < x < w + r_px and -r_px < y < h + r_px):
                    raise ParameterError(f"hole centre ({x:g}, {y:g}) px with radius "
                                         f"{r_px:.0f} px does not meet the scan ({w}x{h} px)"
                                         + hint, path)


PARAM_NAMES = tuple(f.name for f in fields(AnalysisParams))


#: Keys of a set.toml that name the set rather than set a parameter
#: (:mod:`crosssection.setconfig`)
SET_META_KEYS = ("name",)


def _reject_unknown(values: dict) -> None:
    bad = [k for k in values if k not in PARAM_NAMES]
    if bad:
        raise ParameterError(f"unknown parameter {bad[0]!r}; known: {', '.join(PARAM_NAMES)}")


def _number(name, value, *, minimum=0.0, allow_equal=False, integer=False,
            maximum=math.inf):
    if isinstance(value, bool) or not isinstance(value, (int, float)) and \
            not hasattr(value, "__float__"):
        raise ParameterError(f"{name} must be a number, got {value!r}")
    bound = (f" {'>=' if allow_equal else '>'} {minimum:g}" if math.isfinite(minimum)
             else "") + (f" and <= {maximum:g}" if math.isfinite(maximum) else "")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}") from None
    except OverflowError:
        # an int (or Fraction) beyond the float range: its repr may run to any length
        raise ParameterError(f"{name} must be a finite number{bound}, got a number beyond "
                             "the floating-point range") from None
    if not math.isfinite(v) or v < minimum or (v == minimum and not allow_equal) or v > maximum:
        raise ParameterError(f"{name} must be a finite number{bound}, got {value!r}")
    if integer:
        if v != int(v):
            raise ParameterError(f"{name} must be a whole number, got {value!r}")
        return int(v)
    return v


# field -> checker; None values (derived) are accepted for the optional fields
_POSITIVE = ("px_per_mm", "thickness_mm", "hole_radius_mm", "rod_length_mm", "kappa_c_per_mm",
             "tangent_mm", "bending_rigidity_J")
_NON_NEGATIVE = ("s_min_mm2", "l_min_mm", "merge_px", "blue_min", "rg_max", "sliver_width_h")
#: Upper bounds of values that no scan reaches, beyond which the arithmetic overflows or the
#: numbers printed are meaningless: 10 km of sheet; a curvature of a 0.1 um radius, a thousand
#: times below any sheet's thickness; a tangent fit 10 m long (the fit is cut at the stack's
#: own length, and the length in pixels must stay an integer the kernels can hold); a bending
#: rigidity 50 000 times a steel plate's; a sliver rule wider than any hole it applies to.
_BEYOND = {"rod_length_mm": (1e7, "mm of sheet (10 km)"),
           "kappa_c_per_mm": (1e4, "1/mm (a radius of 0.1 um)"),
           "tangent_mm": (1e4, "mm (10 m)"),
           "bending_rigidity_J": (1e9, "J m (a steel plate 1 cm thick and 1 m wide: 2e4)"),
           "sliver_width_h": (1e3, "h (a gap wider than any hole below s_min)")}
#: Lower bounds of the same kind: a plastic threshold at a curvature of a 10 km radius is no
#: threshold (every bend of a scan exceeds it), and the energies it leaves underflow
_BELOW = {"kappa_c_per_mm": (1e-7, "1/mm (a radius of 10 km)")}


def check_param(name: str, value):
    """Validate and normalise one parameter value (``ParameterError`` naming it)."""
    if value is None:
        if name in ("px_per_mm", "thickness_mm", "l_min_mm", "merge_px", "sliver_width_h",
                    *CHOICE_PARAMS, *SWITCHES):
            raise ParameterError(f"{name} is required")
        return None
    if name in _POSITIVE:
        v = _number(name, value)
        _check_range(name, v)
        if name == "px_per_mm" and v > _MAX_PX_PER_MM:
            raise ParameterError(f"px_per_mm = {v:g} is beyond any scanner "
                                 f"(at most {_MAX_PX_PER_MM:g})")
        return v
    if name in _NON_NEGATIVE:
        v = _number(name, value, allow_equal=True)
        _check_range(name, v)
        if name == "merge_px" and v > 50:
            raise ParameterError(f"merge_px = {v:g} px would merge distant junctions "
                                 "(at most 50 px)")
        return v
    if name == "smooth_px":
        v = _number(name, value, integer=True)
        # the default, 2 floor(h) + 1, stays below it for any h a scan can hold: h is less
        # than half the image's shorter side, under 9 500 px within Pillow's pixel budget
        if v > SMOOTH_PX_MAX:
            raise ParameterError(f"smooth_px = {v} is longer than any stack (at most "
                                 f"{SMOOTH_PX_MAX})")
        return v
    if name == "hole_center_px":
        try:
            x, y = value
        except (TypeError, ValueError):
            raise ParameterError(f"hole_center_px must be two numbers [x, y] in pixels, got "
                                 f"{value!r}") from None
        return (_number("hole_center_px x", x, minimum=-math.inf),
                _number("hole_center_px y", y, minimum=-math.inf))
    if name in CHOICE_PARAMS:
        return _choice(name, value, CHOICE_PARAMS[name])
    if name in SWITCHES:
        import numpy as np

        # numpy's booleans too (a parameter grid built with numpy or pandas)
        if not isinstance(value, (bool, np.bool_)):
            raise ParameterError(f"{name} must be true or false, got {value!r}")
        return bool(value)
    if name == "calibration":
        return _check_calibration(value)
    raise ParameterError(f"unknown parameter {name!r}")


def _check_range(name: str, v: float) -> None:
    if name in _BEYOND and v > _BEYOND[name][0]:
        top, what = _BEYOND[name]
        raise ParameterError(f"{name} = {v:g} is beyond any scan (at most {top:g} {what})")
    if name in _BELOW and v < _BELOW[name][0]:
        bottom, what = _BELOW[name]
        raise ParameterError(f"{name} = {v:g} is below any scan (at least {bottom:g} {what})")


def _choice(name, value, allowed):
    if value not in allowed:
        raise ParameterError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")
    return value


def _calibration_class():
    from crosssection.core.calibration import Calibration

    return Calibration


def _check_calibration(value):
    if isinstance(value, (str, Path)):
        if not str(value):
            raise ParameterError("calibration must be a file path")
        return str(value)
    if hasattr(value, "columns") or (hasattr(value, "to_frame")
                                     and not isinstance(value, _calibration_class())):
        # a table is copied into a Calibration: the caller's DataFrame may change later,
        # and these parameters are frozen (and hashable)
        try:
            return _calibration_class().of(value)
        except FoldstatError as exc:
            raise ParameterError(exc.cause) from None
    if hasattr(value, "layers"):
        return value
    if isinstance(value, dict) and UNRECORDED_CALIBRATION in value:
        raise ParameterError(f"the calibration was a {value[UNRECORDED_CALIBRATION]} object, "
                             "which a record cannot hold: give it again (or its table)")
    if isinstance(value, (list, tuple, dict)) or hasattr(value, "__array__"):
        # the form summary.json records a table given in memory in
        # (AnalysisParams.calibration_record), or the columns of a table
        try:
            return _calibration_class().of(value)
        except FoldstatError as exc:
            raise ParameterError(exc.cause) from None
    raise ParameterError(f"calibration must be a CSV path, a Calibration, a table with "
                         f"columns n_layers and width_mm or [[n_layers, width_mm], ...] "
                         f"pairs, got {type(value).__name__}")


def add_analysis_arguments(parser, *, exclude=()) -> None:
    """Add one command-line option per analysis parameter (help, unit and default from the
    fields of :class:`AnalysisParams`); every default is None so that a ``set.toml`` can
    fill what the command line leaves out."""
    group = parser.add_argument_group("analysis parameters")
    for f in fields(AnalysisParams):
        meta = f.metadata
        if not meta.get("cli", True) or f.name in exclude:
            continue
        default = f.default
        unit = f" [{meta['unit']}]" if meta.get("unit") else ""
        shown = "" if default is None else f" (default {default})"
        kwargs = dict(default=None, help=f"{meta['help']}{unit}{shown}".replace("%", "%%"))
        if meta.get("choices"):
            kwargs["choices"] = meta["choices"]
        elif f.name == "calibration":
            kwargs["metavar"] = "CSV"
        elif f.name in ("smooth_px",):
            kwargs["type"] = int
        else:
            kwargs["type"] = float
        if meta.get("nargs"):
            kwargs["nargs"] = meta["nargs"]
            kwargs["metavar"] = meta["metavar"]
        group.add_argument("--" + f.name.replace("_", "-"), dest=f.name, **kwargs)
    for name, help_text in SWITCHES.items():
        if name not in exclude:
            group.add_argument("--no-" + name.replace("_", "-"), action="store_true",
                               help=help_text)


def switched_off(args) -> dict:
    """``{name: False}`` for every :data:`SWITCHES` parameter whose ``--no-`` option is set."""
    return {name: False for name in SWITCHES if getattr(args, "no_" + name, False)}
