"""The scene contract: a synthetic scan with its exact truth, and its folder on disk.

Both generators (``crosssection.truth.network.make_scene``, ``simulate.render``) return a
:class:`Scene`; the scorers read scene folders back through :func:`read_scene` and
:func:`read_scene_params`. Scene folder layout::

    image.png          the scan (RGB, 8 bit)
    params.json        px_per_mm, thickness_mm, hole_radius_mm or null, hole_center_px [x, y]
                       or null, seed, rod_length_mm, and the generator's options
    calibration.csv    n_layers,width_mm: the width law the bands were drawn with
    truth/             summary.json, junctions.csv, stacks.csv, branches.csv, voids.csv
                       (crosssection.core.schema)
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from crosssection.core import schema
from crosssection.core.calibration import Calibration
from crosssection.core.errors import ConfigError, ImageError, output_error
from crosssection.core.fileio import (atomic_path, png_with_chunks, read_json_object, write_csv,
                                      write_json)

__all__ = ["Scene", "write_scene", "read_scene", "read_scene_params", "read_truth_tables",
           "write_image", "write_set_file", "LAYER_PIECES", "LAYER_PIECE_COLUMNS"]

#: Fewest rows of a written ``calibration.csv`` (more when the scene has thicker stacks).
MIN_CALIBRATION_ROWS = 12
#: An optional truth table: the stacks as the bands are drawn, a band that narrows where a
#: layer ends inside it (a rendered rod end) as its pieces of one layer count, which the
#: analysis reads as stacks cut at a layer step (written by ``simulate.render``, scored by
#: :func:`crosssection.truth.scoring.score` in place of ``stacks`` when present).
LAYER_PIECES = "layer_pieces"
LAYER_PIECE_COLUMNS = ("stack_id", "n_br", "length_mm", "mid_x_px", "mid_y_px")


@dataclass(frozen=True)
class Scene:
    """A synthetic scan and its exact truth.

    Attributes
    ----------
    rgb : np.ndarray or None
        (H, W, 3) uint8 image (after the degradations); None when read without the image.
    summary : dict
        Truth summary with :data:`crosssection.core.schema.SUMMARY_KEYS`.
    tables : dict of DataFrame
        ``junctions``, ``stacks``, ``branches``, ``voids`` in the schema's columns.
    params : dict
        What ``params.json`` holds: everything needed to analyse and to regenerate the scene.
    calibration : Calibration or None
        The width law the bands were drawn with (None for a folder without
        ``calibration.csv``).
    paths_rc : list of np.ndarray
        Truth centreline of every stack, (P, 2) float (row, col) in pixels, junction a -> b
        (empty when read from a folder).
    packs : list of (list of int, list of int)
        Per junction, the stack ids of its two packs A | B, when the generator knows them
        (empty otherwise).
    ink_mask : np.ndarray, optional
        (H, W) bool, the noise-free ink as drawn, when the generator provides it.
    """

    rgb: np.ndarray | None
    summary: dict
    tables: dict
    params: dict
    calibration: Calibration | None
    paths_rc: list = field(default_factory=list)
    packs: list = field(default_factory=list)
    ink_mask: np.ndarray | None = field(default=None, repr=False)


def _png_with_resolution(data: bytes, px_per_mm: float) -> bytes:
    """A PNG's bytes with a ``pHYs`` chunk (pixels per metre), as a scanner records its
    resolution."""
    import struct

    ppm = int(round(px_per_mm * 1000.0))
    return png_with_chunks(data, [(b"pHYs", struct.pack(">IIB", ppm, ppm, 1))])


def write_image(rgb: np.ndarray, path, *, px_per_mm: float | None = None) -> Path:
    """Write an RGB array atomically (PNG/JPEG via OpenCV, TIFF via tifffile, 8 or 16 bit).

    Parameters
    ----------
    rgb : (H, W, 3) uint8 or uint16 array
    path : str or Path
        ``.png`` (default for unknown suffixes), ``.jpg``/``.jpeg`` (quality 90) or
        ``.tif``/``.tiff`` (zlib).
    px_per_mm : float, optional
        The scan's resolution, recorded in the file as a scanner records it (PNG ``pHYs``,
        TIFF resolution tags; not in JPEG, whose OpenCV encoder writes no density), so that
        an analysis at another scale says so (``crosssection.quality``, ``scale_mismatch``).

    Returns
    -------
    Path

    Raises
    ------
    ImageError
        Not a non-empty (H, W, 3) uint8 or uint16 array, or the file could not be written.
    """
    path = Path(path)
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.size == 0 \
            or rgb.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"cannot write image: need a non-empty (H, W, 3) uint8 or uint16 "
                         f"array, got {rgb.shape} {rgb.dtype}", path)
    suffix = path.suffix.lower()
    with atomic_path(path) as tmp:
        try:
            if suffix in (".tif", ".tiff"):
                import tifffile

                res = {} if px_per_mm is None else dict(
                    resolution=(10.0 * px_per_mm, 10.0 * px_per_mm), resolutionunit="CENTIMETER")
                tifffile.imwrite(tmp, rgb, photometric="rgb", compression="zlib", **res)
                ok = True
            elif suffix in (".jpg", ".jpeg"):
                ok = cv2.imwrite(str(tmp), np.ascontiguousarray(rgb[..., ::-1]),
                                 [cv2.IMWRITE_JPEG_QUALITY, 90])
            else:
                ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]),
                                       [cv2.IMWRITE_PNG_COMPRESSION, 9])
                if ok:
                    data = buf.tobytes()
                    if px_per_mm is not None:
                        data = _png_with_resolution(data, px_per_mm)
                    Path(tmp).write_bytes(data)
        except OSError as exc:  # a full disk, no permission: the system's words, naming
            # the image rather than its hidden temporary file
            raise output_error(OSError(exc.errno, exc.strerror), path) from None
        except (ValueError, cv2.error) as exc:
            raise ImageError(f"cannot write image ({type(exc).__name__})", path) from None
        if not ok:
            raise ImageError("cannot write image", path)
    return path


def write_scene(scene: Scene, folder, *, image_name: str = "image.png",
                set_name: str | None = None) -> Path:
    """Write a scene folder: the image, ``params.json`` (the scene's parameters and the
    package version), ``calibration.csv``, ``set.toml`` (:func:`write_set_file`), ``truth/``.

    Parameters
    ----------
    scene : Scene
    folder : str or Path
        Created if needed.
    image_name : str
        File name of the image (``.png``, ``.jpg`` or ``.tif``; PNG by default).
    set_name : str, optional
        The set the scene belongs to (:func:`write_set_file`).

    Returns
    -------
    Path
        The folder.

    Raises
    ------
    ImageError
        The image could not be written.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    write_image(scene.rgb, folder / image_name, px_per_mm=scene.params.get("px_per_mm"))
    stacks = scene.tables["stacks"]
    n_rows = max(MIN_CALIBRATION_ROWS, int(stacks["n_br"].max()) + 3 if len(stacks) else 0)
    scene.calibration.to_csv(folder / "calibration.csv", n_rows)
    from crosssection._version import __version__

    # the generator's parameters and the version that drew the scene: its truth is that
    # version's
    write_json(folder / "params.json", {**scene.params, "version": __version__})
    write_set_file(folder, scene.params, image_name=image_name, set_name=set_name)
    pieces = scene.tables.get(LAYER_PIECES)
    (folder / "truth").mkdir(parents=True, exist_ok=True)
    if pieces is not None:
        # before the tables: their summary.json marks a complete truth folder
        write_csv(folder / "truth" / f"{LAYER_PIECES}.csv", pieces)
    else:
        # an earlier scene's pieces would be scored against this one's truth
        (folder / "truth" / f"{LAYER_PIECES}.csv").unlink(missing_ok=True)
    schema.write_tables(folder / "truth", scene.summary, scene.tables)
    return folder


def write_set_file(folder, params: dict, *, image_name: str = "image.png",
                   set_name: str | None = None) -> Path:
    """Write ``folder/set.toml``: the analysis parameters of a scene folder, as
    :func:`crosssection.truth.scoring.analyze_scene_folder` takes them from its
    ``params.json`` (the scale, the hole when it has one, ``calibration.csv``), so that a
    batch of scene folders analyses each as ``validate`` does.

    The hole is the image's own (``[images."image.png"]``): scenes of one render that share
    a ``set_name`` and a scale are then one set of a batch, one ensemble for ``stats``, each
    with its hole.

    Parameters
    ----------
    folder : str or Path
        The scene folder (its ``calibration.csv`` is named relative to it).
    params : dict
        The scene's parameters (:attr:`crosssection.truth.scene.Scene.params`).
    image_name : str
        The scene's image file.
    set_name : str, optional
        The set's ``name`` (:func:`crosssection.setconfig.valid_set_name`); without it the
        set is named by the folder's path.

    Returns
    -------
    Path
        The file.
    """
    from crosssection.core.fileio import write_text
    from crosssection.setconfig import SET_FILE, valid_set_name

    lines = ["# the analysis parameters of this scene, for `foldstat batch`"]
    if set_name is not None:
        lines.append(f'name = "{valid_set_name(set_name, Path(folder) / SET_FILE)}"')
    lines += [f"px_per_mm = {float(params['px_per_mm'])!r}",
              f"thickness_mm = {float(params['thickness_mm'])!r}",
              'calibration = "calibration.csv"']
    if params.get("hole_radius_mm"):
        lines += ["", f"[images.{json.dumps(image_name)}]",
                  f"hole_radius_mm = {float(params['hole_radius_mm'])!r}"]
        if params.get("hole_center_px"):
            x, y = (float(v) for v in params["hole_center_px"])
            lines.append(f"hole_center_px = [{x!r}, {y!r}]")
    return write_text(Path(folder) / SET_FILE, "\n".join(lines) + "\n")


def _check_number(params: dict, key: str, path, *, required: bool) -> None:
    value = params.get(key)
    if value is None:
        if required:
            raise ConfigError(f"lacks {key}", path)
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or value <= 0:
        raise ConfigError(f"{key} must be a positive number, got {value!r}", path)


def read_scene_params(folder) -> dict:
    """Read and check a scene folder's ``params.json``.

    Parameters
    ----------
    folder : str or Path
        The scene folder.

    Returns
    -------
    dict
        The parameters as written: ``px_per_mm`` and ``thickness_mm`` (positive),
        ``hole_radius_mm`` (positive or None), ``hole_center_px`` ([x, y] or None), and the
        generator's other entries.

    Raises
    ------
    ConfigError
        Missing or malformed file, or a missing or invalid entry; the message names the file.
    """
    path = Path(folder) / "params.json"
    params = read_json_object(path)
    _check_number(params, "px_per_mm", path, required=True)
    _check_number(params, "thickness_mm", path, required=True)
    _check_number(params, "hole_radius_mm", path, required=False)
    centre = params.get("hole_center_px")
    if centre is not None and not (
            isinstance(centre, list) and len(centre) == 2
            and all(isinstance(c, (int, float)) and math.isfinite(c) for c in centre)):
        raise ConfigError(f"hole_center_px must be [x, y] or null, got {centre!r}", path)
    return params


def read_truth_tables(truth_dir) -> tuple[dict, dict]:
    """A scene's ``truth/`` folder: ``summary.json``, the four schema tables
    (:func:`crosssection.core.schema.read_tables`) and the optional :data:`LAYER_PIECES`.

    Parameters
    ----------
    truth_dir : str or Path

    Returns
    -------
    (summary, tables) : (dict, dict of DataFrame)

    Raises
    ------
    ConfigError
        Naming the file: as :func:`~crosssection.core.schema.read_tables`, or a
        ``layer_pieces.csv`` that is unreadable or lacks a column.
    """
    import pandas as pd

    truth_dir = Path(truth_dir)
    summary, tables = schema.read_tables(truth_dir)
    # the truth's summary and tables are written together: another count is a table cut
    # short or edited, whose scores would be scores against a part of the truth (the tables
    # scored row by row; the totals of branches.csv come from the summary)
    for name, key in (("junctions", "n_junctions"), ("stacks", "n_stacks"),
                      ("voids", "n_voids")):
        counted = summary.get(key)
        if (isinstance(counted, (int, float)) and not isinstance(counted, bool)
                and math.isfinite(counted) and len(tables[name]) != counted):
            raise ConfigError(f"holds {len(tables[name])} rows where summary.json counts "
                              f"{counted:g} {name} (truncated or edited): not scored",
                              truth_dir / f"{name}.csv")
    path = truth_dir / f"{LAYER_PIECES}.csv"
    if path.exists():
        try:
            df = pd.read_csv(path)
        except (OSError, ValueError) as exc:
            raise ConfigError(f"unreadable table ({exc})", path) from None
        missing = [c for c in LAYER_PIECE_COLUMNS if c not in df.columns]
        if missing:
            raise ConfigError(f"lacks column(s) {missing}", path)
        # every stack holds one piece at least (the pieces between its layer steps)
        absent = sorted(set(tables["stacks"]["stack_id"]) - set(df["stack_id"]))
        if absent:
            shown = ", ".join(map(str, absent[:5])) + (", ..." if len(absent) > 5 else "")
            raise ConfigError(f"holds no piece of {len(absent)} of the "
                              f"{len(tables['stacks'])} stacks (stack_id {shown}; truncated "
                              "or edited): not scored", path)
        tables[LAYER_PIECES] = df
    return summary, tables


def read_scene(folder, *, image_name: str | None = None, image: bool = True) -> Scene:
    """Read a scene folder written by :func:`write_scene`.

    Parameters
    ----------
    folder : str or Path
    image_name : str, optional
        File name of the image; default ``params["image"]`` if present, else ``image.png``.
    image : bool
        Read the image (``Scene.rgb`` is None otherwise).

    Returns
    -------
    Scene
        Without ``paths_rc``, ``packs`` and ``ink_mask`` (not stored in the folder);
        ``calibration`` is None when the folder has no ``calibration.csv``; ``tables``
        holds :data:`LAYER_PIECES` when ``truth/`` has it.

    Raises
    ------
    ConfigError
        Missing or malformed ``params.json`` or ``truth/``, malformed ``calibration.csv``.
    ImageError
        Missing or unreadable image.
    """
    from crosssection.stages.load import load_image

    folder = Path(folder)
    params = read_scene_params(folder)
    truth = folder / "truth"
    if not (truth / "summary.json").exists():
        raise ConfigError("no truth/summary.json (not a scene folder)", folder)
    summary, tables = read_truth_tables(truth)
    cal_path = folder / "calibration.csv"
    calibration = Calibration.from_csv(cal_path) if cal_path.exists() else None
    rgb = None
    if image:
        rgb = load_image(folder / (image_name or params.get("image") or "image.png"))
    return Scene(rgb, summary, tables, params, calibration)
