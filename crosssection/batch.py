"""Batch processing: every scan under a folder analysed in parallel, resumable.

``python -m crosssection batch INPUT_DIR --out OUT_DIR [--workers W] [--scheduler ADDRESS]``

Layout of ``OUT_DIR``::

    index.csv          one row per image (:data:`INDEX_COLUMNS`): image, set, status (ok /
                       failed / skipped, or pending while the run that analyses it has not
                       reached it: a run stopped midway leaves no row of an earlier run's
                       results for a scan it was redoing), output folder (empty for a
                       failed image), summary numbers (n_junctions ... total_energy, with
                       the rod length and hole radius that make its epsilon), quality (the
                       failed checks' codes), wall_s, seed, params_hash, peak_rss_mb, reason
    failures.csv       image, set, reason   (one line per failed image)
    batch.json         parameters, sets, package version, counts
    <set>/<stem>/      the ``analyze`` layout: summary.json, junctions.csv, stacks.csv,
                       branches.csv, voids.csv, overlay.png

Design choices
--------------
- One code path for parallelism: :func:`crosssection.core.parallel.get_executor` (local processes,
  or a Dask cluster with ``--scheduler``). Tasks receive paths and parameters, write their own
  outputs and return a small dict (never arrays), so memory stays at about one image per worker.
- The analysis draws no random numbers: its results depend neither on ``--seed`` nor on the
  number of workers or the order of completion. Each image is still given a seed
  (:func:`image_seed`, from the base seed and the image's path in ``INPUT_DIR``, so adding or
  removing other scans does not change it), recorded in ``summary.json`` (``batch.seed``) and
  index.csv for an analysis that would draw some; it is not part of the parameters hash.
- Sets: a folder holding ``set.toml`` is a set, named by its ``name`` or, without one, by its
  path under ``INPUT_DIR`` (``eps8/day1``), so two experiments' ``day1/`` folders stay two
  sets. Two folders that declare one ``name`` are one set when their parameters are the same
  (a set split over several folders) and are refused, before anything is written, when they
  differ: their scans would be pooled as one set by ``stats``.
- Output folders keep their names: a scan whose folder index.csv records keeps that folder
  on a re-run, so a scan of the same stem added elsewhere in the set is named by its path
  rather than the two being renamed (and the first analysed again). Output folders that no
  scan of the batch names (a set renamed, a scan moved or deleted) are named in one
  ``warning:`` line and left where they are.
- Local workers share numba's disk cache of compiled kernels. On an empty cache (a fresh
  install) the first worker to compile does so for all; the others wait and load the kernels
  (:func:`crosssection.core.parallel.compiling_in_turn`) instead of each compiling them
  at the same time.
- Atomic outputs: a task writes into a hidden staging folder ``.<stem>.partial-XXXX`` next to
  its output folder and renames it into place when complete. A killed run leaves at most
  staging folders and the temporary files of the batch's records, which the next run removes
  (those beside a scan it skips included); an output folder is therefore always complete.
  ``summary.json`` carries ``batch.params_hash``; an image whose folder holds a summary with
  the same hash, its four tables readable with their schema's columns (their header lines
  are read) and holding the rows the summary counts (their lines are counted), and a whole
  ``overlay.png`` when figures are wanted is skipped on a re-run. Each image analysed again
  over an earlier result is named in a ``warning:`` line with the reason (its parameters,
  the package version, the files' content, its summary, a table or the overlay lost or cut
  short).
- One batch at a time writes into ``OUT_DIR``: it holds a lock (``flock`` on
  ``OUT_DIR/.batch.lock``, released by the system when the process dies, so that a batch
  killed does not block its re-run), and a second batch is refused in one line.
- The parameters hash covers the effective analysis parameters (:func:`effective_params`:
  every default filled in, derived ones such as ``s_min`` computed; a scale left to its
  default counts apart from the same scale given, which the ``scale_assumed`` check tells
  apart), the SHA-256 of the image and of the calibration file, and the package version:
  changing any of them redoes the image, which replaces its earlier results; a re-run with
  the same options is silent.
  ``summary.json`` records the image's and the calibration's SHA-256, their paths as given
  and resolved, and the calibration's widths (``inputs``, the record ``analyze`` writes,
  with the scan's path as the batch was given it; the same in ``batch.inputs``), so that an
  output names what it was computed from.
- ``OUT_DIR`` belongs to one input folder: it must be new, empty, or hold an earlier batch of
  the same ``INPUT_DIR`` (which the batch resumes). The batch of another input folder, or
  files that no batch wrote, are refused before anything is written, as is a ``--scheduler``
  that cannot be reached. ``OUT_DIR`` may lie inside ``INPUT_DIR``.
- Symbolic links: a link to an image is analysed like a file, named by the link's own path
  in ``INPUT_DIR`` (its set, its ``[images]`` table and its output folder are those of
  where the link lies, not of its target); a broken link is a failed image. A link to a
  folder is not searched, and is named in a ``warning:`` line: it may lead back into its
  own tree, to scans the batch already holds, or out of ``INPUT_DIR``; run a batch on its
  target, or link its scans one by one.
- Failures never stop the batch: a corrupt or non-RGB image, an analysis error, a bad
  ``set.toml`` or a missing calibration fail only the images concerned, each with a one-line
  reason in ``failures.csv``. A worker process that dies (crash, out-of-memory kill) is
  replaced; the images that were in flight are re-run one at a time, and the one whose worker
  dies alone is recorded as failed. A scan whose output cannot be written (a full disk) fails
  with the file named in its output folder. A Dask cluster that goes away stops the batch
  (one ``error:`` line): the images it had are left out of the index, neither done nor
  failed, and a re-run analyses them. So do the batch's own records (index.csv,
  failures.csv, batch.json) that cannot be written, naming the file: the scans done are in
  their folders, and the re-run resumes from them.
- An interrupt (Ctrl-C, SIGTERM) stops the batch; the scan it landed in is left out of the
  index, for the re-run, even when the analysis caught the interrupt and failed with
  another error in its place (matplotlib does while it draws): the command line tells the
  batch that it was sent one (``run_batch(signalled=...)``).
- A calibration is used only when a ``set.toml`` or ``--calibration`` names it. A
  ``calibration.csv`` lying beside scans that are analysed without one is named in a
  ``warning:`` line (and in batch.json): every such scan would otherwise read its layer counts
  through the width law read from itself and be flagged ``no_calibration``.
"""
from __future__ import annotations

import argparse
import hashlib
import io
import json
import math
import os
import re
import shutil
import sys
import time
import traceback
import warnings
from collections import deque
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

import pandas as pd

from crosssection._version import __version__
from crosssection.core import provenance, schema
from crosssection.core.errors import (ConfigError, FoldstatError, ImageError, OutputError,
                                      ParameterError, output_error, printable)
from crosssection.core.fileio import (BROWSER_FILES, PARTIAL_TAG, check_out, clear_stale_folders,
                                      exclusive_lock, lock_holds,
                                      is_working_folder, missing_file_reason, read_json_object,
                                      special_file_reason, staging_folder, swap_in_folder,
                                      temporary_files, write_csv, write_json)
from crosssection.core.parallel import (ClusterLostError, capped_workers, compiling_in_turn,
                                        get_executor)
from crosssection.params import (PARAM_NAMES, AnalysisParams, add_analysis_arguments,
                                 check_param, switched_off)
from crosssection.quality import QualityWarning
from crosssection.setconfig import (DEFAULT_PARAMS, DEFAULT_SET_NAME, SET_FILE, SetConfig,
                                    check_params, failed_set, load_set_config)

IMAGE_SUFFIXES = schema.IMAGE_SUFFIXES
#: ``rod_length_used_mm`` and ``hole_radius_mm`` beside ``epsilon``: epsilon = L / (2 pi R)
#: with the L used (a given ``--rod-length-mm``, else the measured ``rod_length_mm``)
SUMMARY_NUMBERS = ["n_junctions", "n_stacks", "n_branches", "n_voids", "mean_branches_per_stack",
                   "rod_length_mm", "rod_length_used_mm", "hole_radius_mm", "epsilon",
                   "total_energy", "total_energy_rel_uncertainty"]
INDEX_COLUMNS = (["image", "set", "status", "output"] + SUMMARY_NUMBERS
                 + ["quality", "wall_s", "seed", "params_hash", "peak_rss_mb", "reason"])
FAILURE_COLUMNS = ["image", "set", "reason"]
#: exit status of a batch that finished but could not analyse every image
EXIT_SOME_FAILED = 3
#: how often (s) at most the index is rewritten while the batch runs, so a killed batch
#: leaves one (it is also written before the first analysis and after each failure)
INDEX_EVERY_S = 2.0


@dataclass
class ImageTask:
    """One image to analyse (everything a worker needs; small and picklable)."""

    image: str            # absolute path
    rel: str              # path relative to INPUT_DIR (posix), the index key
    set_name: str
    out_dir: str          # absolute output folder OUT_DIR/<set>/<stem>
    out_rel: str          # relative to OUT_DIR
    given: str = ""       # the image's path as the user named it (INPUT_DIR as given / rel)
    params: dict = field(default_factory=dict)
    seed: int = 0
    params_hash: str = ""
    image_sha: str = ""
    figure: bool = True
    error: str | None = None
    compile_lock: str | None = None  # shared by the local workers (compiling_in_turn)
    run_token: str | None = None  # the batch's lock token: results are kept while it holds


# --------------------------------------------------------------------------- discovery


def is_output_folder(folder) -> bool:
    """Whether ``folder`` holds the output of a foldstat command (a batch, an analysis, step
    images, a stats report: :func:`crosssection.core.records.output_of`), whose figures are
    not scans."""
    from crosssection.core.records import output_of

    return output_of(folder) is not None


def find_images(input_dir, *, exclude=()) -> list[Path]:
    """Image files under ``input_dir`` (recursive, sorted; hidden files and folders skipped,
    and foldstat's output folders, :func:`is_output_folder`).

    A symbolic link to an image is an image, named by its own path (a broken one is listed
    too: the batch records it as a failed image). A symbolic link to a folder is not searched
    (:func:`_walk_scans` says why).

    Parameters
    ----------
    input_dir : str or Path
    exclude : iterable of Path
        Folders not to descend into (the output folder when it lies inside the input).

    Returns
    -------
    list of Path
    """
    return _walk_scans(input_dir, exclude=exclude)[0]


def _walk_scans(input_dir, *, exclude=()) -> tuple[list[Path], list[Path], list]:
    """:func:`find_images`, the symbolic links to folders met on the way, and the folders
    that could not be listed.

    Linked folders are not followed: one may lead back into its own tree (a loop), to scans
    the batch already holds (each analysed twice, under two names) or out of the input
    folder, which the batch's output would then no longer describe. The batch names them in
    a warning; a linked folder's scans are analysed as a batch of their own, or linked one
    by one. A folder that cannot be listed (no read or search permission) is passed over,
    its scans unseen; the batch names it in a warning too.

    Returns
    -------
    images : list of Path
        Sorted by their path relative to ``input_dir``.
    linked_folders : list of Path
        Sorted.
    unreadable : list of (Path, str)
        Each folder that could not be listed and the cause, sorted.
    """
    root = Path(input_dir).resolve()
    excluded = [Path(e).resolve() for e in exclude]
    found, linked, missed = [], [], []

    def cannot_list(exc: OSError) -> None:
        missed.append((Path(exc.filename), exc.strerror or type(exc).__name__))

    for dirpath, dirnames, filenames in os.walk(root, onerror=cannot_list):
        here = Path(dirpath)
        keep = []
        for d in sorted(dirnames):
            try:
                if d.startswith(".") or (here / d).resolve() in excluded:
                    continue
                if (here / d).is_symlink():
                    linked.append(here / d)
                elif not is_output_folder(here / d):
                    keep.append(d)
            except OSError as exc:
                missed.append((here / d, exc.strerror or type(exc).__name__))
        dirnames[:] = keep
        for fn in filenames:
            if not fn.startswith(".") and fn.lower().endswith(IMAGE_SUFFIXES):
                found.append(here / fn)
    return (sorted(found, key=lambda p: p.relative_to(root).as_posix()), sorted(linked),
            sorted(missed))


def _broken_link(image: Path) -> str | None:
    """The one-line reason of an image that is a symbolic link to nothing, or a named pipe,
    a socket or a device named like a scan (hashing it while planning would block or never
    end), else None."""
    if image.is_symlink() and not image.exists():
        return ImageError(missing_file_reason(image), image).one_line()
    special = special_file_reason(image)
    if special:
        return ImageError(special, image).one_line()
    return None


def _not_utf8(image: Path, rel: str) -> str | None:
    """The one-line reason of an image whose name is not UTF-8 text, else None: the batch's
    tables and records name each scan, and a later run must find it by that name."""
    if printable(rel) == rel:
        return None
    return ImageError("file name or folder name is not UTF-8 text: rename it (the batch's "
                      "tables name every scan)", image).one_line()


def effective_params(params: dict) -> dict:
    """The parameters an analysis runs with: every default filled in, the derived ones
    (``s_min_mm2``, ``tangent_mm``) computed, a calibration file replaced by its SHA-256.

    Two ways of asking for one analysis (a value given or left to its default, a calibration
    file moved or copied) give one result.

    Parameters
    ----------
    params : dict
        Analysis parameters as given (a set's, the command line's).

    Returns
    -------
    dict

    Raises
    ------
    FoldstatError
        The parameters are not valid.
    """
    p = AnalysisParams.from_mapping(params)
    out = p.to_dict()
    out["s_min_mm2"] = p.s_min_used_mm2
    out["tangent_mm"] = p.tangent_used_mm
    cal = params.get("calibration")
    if isinstance(cal, (str, Path)) and Path(cal).is_file():
        out["calibration"] = provenance.file_sha256(cal)
    # 12 digits: 3 h computed (0.30000000000000004) and 0.3 given are one value
    return {k: _rounded(v) for k, v in out.items()}


def _rounded(value):
    if isinstance(value, float):
        return float(f"{value:.12g}")
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


def params_hash(params: dict, image_sha: str, *, seed=None) -> str:
    """Hash of everything that determines an image's results.

    Parameters
    ----------
    params : dict
        Analysis parameters: hashed as :func:`effective_params` resolves them, so that the
        hash follows the analysis run, not the way its options were given.
    image_sha : str
        SHA-256 of the image file.
    seed : int, optional
        Included only when the analysis consumes a seed.

    Returns
    -------
    str
        16 hex digits.
    """
    payload = {"params": effective_params(params), "image": image_sha, "version": __version__,
               "seed": seed}
    if params.get("px_per_mm") is None:
        # read at the default scale and flagged so: giving that scale later redoes the image,
        # whose summary would otherwise keep the flag (the hash of a given scale is unchanged)
        payload["scale_assumed"] = True
    blob = json.dumps(payload, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def image_seed(seed: int | None, rel: str) -> int:
    """The seed of one image: derived from the base ``seed`` and the image's path ``rel`` in
    the input folder (``SeedSequence``), so that it stays the same when other scans are
    added, removed or renamed.

    Parameters
    ----------
    seed : int or None
        Base seed (None: fresh entropy).
    rel : str
        The image's path relative to the input folder (posix).

    Returns
    -------
    int
        A 32-bit seed.
    """
    import numpy as np

    base = np.random.SeedSequence(seed).entropy
    digest = hashlib.sha256(rel.encode("utf-8", "surrogateescape")).digest()
    key = int.from_bytes(digest[:8], "little")
    return int(np.random.SeedSequence([base, key]).generate_state(1, dtype=np.uint32)[0])


#: the batch's own files at the top of OUT_DIR: no set folder may take these names
RESERVED_NAMES = ("index.csv", "failures.csv", "batch.json")


def _set_folder(set_name: str) -> str:
    """Output folder of a set: its name, unless that would collide with the batch's files."""
    return f"set_{set_name}" if set_name.lower() in RESERVED_NAMES else set_name


#: the longest output folder name a scan's stem gives (characters): its staging folder adds
#: a prefix and a suffix, and a name of 255 bytes, the usual limit, would fail as it is written
FOLDER_NAME_MAX = 100


def _safe_component(text: str) -> str:
    safe = "".join(c if (c.isalnum() or c in "-_+") else "_" for c in text)
    if len(safe.encode("utf-8", "surrogateescape")) <= FOLDER_NAME_MAX:
        return safe
    # a long name keeps its start, and a hash of the whole keeps it apart from its kin
    digest = hashlib.sha256(text.encode("utf-8", "surrogateescape")).hexdigest()[:12]
    head = safe.encode("utf-8", "surrogateescape")[:FOLDER_NAME_MAX - 13]
    return head.decode("utf-8", "ignore") + "-" + digest


def _clashing(names: list[str], taken: list[str]) -> list[bool]:
    """Per name of ``names``: whether it is one folder with another name of ``names`` or of
    ``taken``, or holds one (compared case-blind: a.png and A.png share a folder on macOS and
    Windows; the folder of a scan ``b`` of a set ``a`` holds the scans of a set ``a/b``)."""
    low = [n.lower() for n in names]
    counts: dict[str, int] = {}
    for n in low + [t.lower() for t in taken]:
        counts[n] = counts.get(n, 0) + 1
    parents = {"/".join(n.split("/")[:k]) for n in counts for k in range(1, n.count("/") + 1)}
    return [counts[n] > 1 or n in parents for n in low]


def _unique_out_rels(tasks, kept: dict[str, str] | None = None) -> None:
    """Give every task its own output folder, in place.

    A scan keeps the folder ``kept`` records for it (an earlier run's index.csv), when that
    is a folder of its set. Otherwise its folder is its stem; two scans of one set with one
    stem (a.png and a.tif, or sub/a.png), or a stem whose folder another scan keeps, are named
    by their paths, and names that the safe characters still merge ("a b.png" and
    "a_b.png") get a hash of the path as well.
    """
    kept = kept or {}
    pinned, free = [], []
    for t in tasks:
        k = kept.get(t.rel, "")
        head, _, leaf = k.rpartition("/")
        if (head == _set_folder(t.set_name) and leaf and _safe_component(leaf) == leaf
                and k.lower() not in {p.out_rel.lower() for p in pinned}):
            t.out_rel = k
            pinned.append(t)
        else:
            free.append(t)
    taken = [t.out_rel for t in pinned]
    for rename in (lambda t: f"{_set_folder(t.set_name)}/"
                             f"{_safe_component(t.rel.replace('/', '__'))}",
                   lambda t: t.out_rel + "-" + hashlib.sha256(t.rel.encode()).hexdigest()[:8]):
        clash = _clashing([t.out_rel for t in free], taken)
        for t, c in zip(free, clash):
            if c:
                t.out_rel = rename(t)


CALIBRATION_FILE = "calibration.csv"


def plan_batch(input_dir, out_dir, *, cli_params: dict | None = None, seed: int | None = 0,
               figure: bool = True) -> tuple[list[ImageTask], dict[str, SetConfig]]:
    """Find the images and sets under ``input_dir`` and build one task per image.

    Parameters
    ----------
    input_dir, out_dir : str or Path
    cli_params : dict, optional
        Parameters from the command line: used for images outside any set and where a
        ``set.toml`` is silent.
    seed : int, optional
        Base seed; each image gets :func:`image_seed` of it and its path.
    figure : bool
        Whether tasks draw ``overlay.png``.

    Returns
    -------
    tasks : list of ImageTask
        Sorted by relative image path.
    sets : dict
        Set folder (posix, relative to ``input_dir``) -> SetConfig.

    Raises
    ------
    ConfigError
        ``input_dir`` is not a folder, or holds no image; two set folders declare one
        ``name`` with different parameters (:func:`check_set_names`).
    """
    given_root = Path(input_dir)
    root = given_root
    if not root.is_dir():
        raise ConfigError("not a folder (batch reads a folder of scans; analyze reads one "
                          "scan)" if root.exists() else "input folder does not exist", root)
    root = root.resolve()
    try:
        (root / SET_FILE).exists()
    except OSError as exc:  # listed, perhaps, but not searched: nothing in it can be read
        raise ConfigError(f"cannot search the folder ({exc.strerror or type(exc).__name__})",
                          given_root) from None
    from crosssection.core.records import output_of

    made_by = output_of(root)
    # the records of outputs whose images are figures of scans (a steps run's, an overlay):
    # a render's scenes are scans, and a configs.csv may be a user's own table
    if made_by is not None and made_by[1] not in ("foldstat render", "a simulation"):
        raise ConfigError(f"holds the output of {made_by[1]} ({made_by[0]}), not scans: "
                          "batch reads a folder of scans", given_root)
    out = Path(out_dir).resolve()
    defaults = dict(DEFAULT_PARAMS)
    given = check_params(cli_params or {}, Path.cwd() / "command line",
                         origin="--calibration")
    defaults.update(given)
    images, linked_folders, unreadable = _walk_scans(root, exclude=[out])
    for folder, cause in unreadable:
        if folder == root:
            raise ConfigError(f"cannot list the folder ({cause})", given_root)
    if not images:
        more = (f" ({len(unreadable)} folder(s) could not be listed: "
                f"{printable(given_root / unreadable[0][0].relative_to(root))}, "
                f"{unreadable[0][1]})" if unreadable else "")
        raise ConfigError(f"no image ({', '.join(IMAGE_SUFFIXES)}) found{more}", root)

    # sets: the nearest folder (at or above the image, within root) holding set.toml
    sets: dict[str, SetConfig] = {}
    default_set = SetConfig(name=DEFAULT_SET_NAME, folder=root, params=defaults)

    def set_of(folder: Path) -> SetConfig:
        for cand in [folder, *folder.parents]:
            key = cand.relative_to(root).as_posix() if cand != root else "."
            if key in sets:
                return sets[key]
            toml = cand / SET_FILE
            try:
                is_set = toml.is_file()
            except OSError as exc:
                # a folder that can be listed but not searched: neither its set file nor its
                # scans can be read, and its scans fail with this cause
                sets[key] = failed_set(toml, ConfigError(
                    f"cannot search the folder ({exc.strerror or type(exc).__name__}): its "
                    "files cannot be read; give it search permission and re-run",
                    cand).one_line(), root=root)
                return sets[key]
            if is_set:
                try:
                    sets[key] = load_set_config(toml, defaults=defaults, given=given,
                                                root=root)
                except FoldstatError as exc:
                    sets[key] = failed_set(toml, exc.one_line(), root=root)
                return sets[key]
            if cand == root:
                break
        return default_set

    tasks = []
    for img in images:
        cfg = set_of(img.parent)
        rel = img.relative_to(root).as_posix()
        out_rel = f"{_set_folder(cfg.name)}/{_safe_component(img.stem)}"
        params = {} if cfg.error else _params_in_set(cfg, img)
        tasks.append(ImageTask(image=str(img), rel=printable(rel), set_name=cfg.name,
                               out_dir="", out_rel=out_rel,
                               given=printable(given_root / rel), params=params,
                               seed=image_seed(seed, rel), figure=figure,
                               error=cfg.error or _broken_link(img) or _not_utf8(img, rel)))
    # the scans outside any set first: a set file taking their name is the one named
    check_set_names(([default_set] if any(t.set_name == DEFAULT_SET_NAME and not t.error
                                          for t in tasks) else []) + [*sets.values()], root)
    _unique_out_rels(tasks, recorded_outputs(out))
    for t in tasks:
        t.out_dir = str(out / t.out_rel)
        if t.error is None:
            try:
                AnalysisParams.from_mapping(t.params, path=t.image)
            except FoldstatError as exc:
                t.error = exc.one_line()
                continue
            try:
                t.image_sha = provenance.file_sha256(t.image)
            except OSError as exc:
                t.error = ImageError(f"cannot read ({exc.strerror or type(exc).__name__})",
                                     t.image).one_line()
                continue
            # the analysis draws no random numbers: the seed is recorded, not hashed
            t.params_hash = params_hash(t.params, t.image_sha)
    default_set.warnings.extend(_unused_calibrations(tasks))

    def shown(folder: Path) -> str:
        return printable(given_root / folder.relative_to(root))

    default_set.warnings.extend(
        f"{shown(d)}: a symbolic link to a folder, not searched: run a batch on the folder "
        f"it links to, or link its scans one by one" for d in linked_folders)
    default_set.warnings.extend(
        f"{shown(d)}: cannot list the folder ({cause}): its scans are not in the batch; "
        "give read and search permission and re-run" for d, cause in unreadable)
    # the batch's own warnings (not any set's) ride with the default set, listed even when
    # no scan lies outside a set
    if default_set.warnings or any(t.set_name == DEFAULT_SET_NAME and t.error is None
                                   for t in tasks):
        sets.setdefault("<no set.toml>", default_set)
    return tasks, sets


def check_set_names(sets, root) -> None:
    """Refuse two sets of one name whose parameters differ.

    A set is named by its folder's path unless its ``set.toml`` gives a ``name``; two folders
    giving one name are one set when their effective parameters (:func:`effective_params`)
    are the same, a set split over several folders. When they differ, their scans would be
    pooled as one set although they were not analysed alike.

    Parameters
    ----------
    sets : iterable of SetConfig
        The sets of the batch (those that failed to load are left out).
    root : Path
        The input folder: named when the scans outside any set (set "default") are the
        ones that clash.

    Raises
    ------
    ConfigError
        Naming the second ``set.toml`` of the name, the first and what differs.
    """
    first: dict[str, tuple[SetConfig, dict]] = {}
    for cfg in sets:
        if cfg.error:
            continue
        try:
            eff = effective_params(cfg.params)
        except FoldstatError:
            continue  # its scans fail, each with the reason
        if cfg.name not in first:
            first[cfg.name] = (cfg, eff)
            continue
        other, eff0 = first[cfg.name]
        differ = [k for k in dict.fromkeys([*eff0, *eff]) if eff0.get(k) != eff.get(k)]
        if not differ:
            continue
        # the values the set files give, before those derived from them (s_min from h)
        given = [k for k in differ if other.params.get(k) != cfg.params.get(k)]
        first_set = ("the scans outside any set" if other.source is None
                     else str(other.source))
        raise ConfigError(f"set name {cfg.name!r} is also that of {first_set}, whose "
                          f"parameters differ ({', '.join(given or differ)}): give each set "
                          "its own name (sets are never pooled)",
                          cfg.source if cfg.source is not None else root)


def recorded_outputs(out_dir) -> dict[str, str]:
    """Image (relative path) -> output folder, as the ``index.csv`` of an earlier batch in
    ``out_dir`` records them (empty when there is none, or it cannot be read: the folders
    are then named afresh)."""
    try:
        index = pd.read_csv(Path(out_dir) / "index.csv", dtype=str, keep_default_na=False,
                            usecols=["image", "output"])
    except (OSError, ValueError):
        return {}
    return {i: o for i, o in zip(index["image"], index["output"]) if i and o}


def _params_in_set(cfg: SetConfig, image: Path) -> dict:
    """Parameters of one scan of a set: the set's, updated by the override table of the
    scan's path in the set folder.

    The path is taken as it is, links not followed (unlike :meth:`SetConfig.params_for`):
    a linked scan belongs to the folder holding the link and is named by it, wherever its
    target lies.
    """
    rel = image.relative_to(cfg.folder).as_posix()
    return {**cfg.params, **cfg.override_of(rel)}


def loose_calibration(image, calibration) -> Path | None:
    """The ``calibration.csv`` lying beside a scan analysed without any calibration (the user
    most likely meant it: only a ``set.toml`` or ``--calibration`` names one), or None."""
    cal = Path(image).parent / CALIBRATION_FILE
    return cal if calibration is None and cal.is_file() else None


def _unused_calibrations(tasks) -> list[str]:
    """:func:`loose_calibration` of the scans outside any set, each file once."""
    found = []
    for t in tasks:
        if t.set_name != DEFAULT_SET_NAME or t.error is not None:
            continue
        cal = loose_calibration(t.image, t.params.get("calibration"))
        if cal is not None and str(cal) not in found:
            found.append(str(cal))
    return [f"{c}: not used (its scans have no calibration): name it in a {SET_FILE} "
            f"(calibration = \"{CALIBRATION_FILE}\") or pass --calibration" for c in found]


# --------------------------------------------------------------------------- worker side


def _row(task: ImageTask, status: str, summary: dict | None = None, reason: str = "",
         wall_s: float = math.nan) -> dict:
    summary = summary or {}
    # a failed image has no output folder (an earlier one, if any, is not its result)
    row = {"image": task.rel, "set": task.set_name, "status": status,
           "output": "" if status == "failed" else task.out_rel}
    hole = summary.get("hole")
    numbers = {**summary, "hole_radius_mm": hole.get("radius_mm") if isinstance(hole, dict)
               else None}
    for k in SUMMARY_NUMBERS:
        v = numbers.get(k)
        row[k] = math.nan if v is None else v
    quality = summary.get("quality") or {}
    row.update(quality=";".join(quality.get("codes", [])), wall_s=wall_s, seed=task.seed,
               params_hash=task.params_hash, peak_rss_mb=math.nan, reason=reason)
    return row


def _peak_rss_mb() -> float:
    """Peak resident memory of this process so far (MB; Linux reports ru_maxrss in kB)."""
    try:
        import resource

        kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return round(kb / (1024 * 1024 if sys.platform == "darwin" else 1024), 1)
    except Exception:  # noqa: BLE001 - not on every platform
        return math.nan


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, FoldstatError):
        return exc.one_line()
    tb = traceback.extract_tb(exc.__traceback__)
    where = f" (at {Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
    return " ".join(f"unexpected {type(exc).__name__}: {exc}{where}".split())


def process_image(task: ImageTask) -> dict:
    """Analyse one image and write its output folder atomically (runs in a worker).

    Parameters
    ----------
    task : ImageTask

    Returns
    -------
    dict
        The image's index row (status ``ok`` or ``failed`` with a one-line reason). Never
        raises for a bad image.
    """
    t0 = time.perf_counter()
    final = Path(task.out_dir)
    if task.error:
        return _row(task, "failed", reason=task.error)
    staging = None
    try:
        from crosssection.pipeline import analyze

        clear_stale_folders(final)
        params = AnalysisParams.from_mapping(task.params, path=task.image)
        with compiling_in_turn(task.compile_lock):
            # the flags are in the summary; the driver prints them once per image
            result = analyze(task.image, params, warn=False, image_sha256=task.image_sha or None,
                             scale_given=task.params.get("px_per_mm") is not None)
        info = {"params_hash": task.params_hash, "image": task.rel, "set": task.set_name,
                "seed": task.seed, "params": task.params, "version": __version__,
                "inputs": input_record(task)}
        if isinstance(getattr(result, "summary", None), dict):
            # the scan named as the batch was given it, as batch.inputs does
            result.summary["inputs"] = info["inputs"]
            result.summary["batch"] = dict(info)
        try:
            staging = staging_folder(final)
            result.write(staging, figure=task.figure)
            summary_path = staging / "summary.json"
            summary = json.loads(summary_path.read_text())
            info["wall_s"] = time.perf_counter() - t0
            info["peak_rss_mb"] = _peak_rss_mb()  # kept for the index of a re-run
            summary["batch"] = info
            write_json(summary_path, summary)
            if not lock_holds(_out_root(task) / LOCK_FILE, task.run_token):
                # the batch stopped (or another took the folder) while this task ran on a
                # cluster's worker: its index says pending, and a re-run may be writing here
                return _row(task, "failed", reason="the batch stopped before this scan's "
                            "results were written: not kept", wall_s=time.perf_counter() - t0)
            # the complete folder takes the place of an old one (other parameters)
            swap_in_folder(staging, final)
        except OutputError:
            raise
        except OSError as exc:  # a full disk, no permission: one line naming the file
            raise output_error(exc, final) from None
        staging = None
        row = _row(task, "ok", summary, wall_s=info["wall_s"])
        row["peak_rss_mb"] = info["peak_rss_mb"]
        return row
    except Exception as exc:  # noqa: BLE001 - a bad image is recorded, the batch goes on
        # a file that could not be written is named where it was to go: the hidden staging
        # folder is removed below and means nothing to the user
        reason = re.sub(re.escape(str(final.parent / f".{final.name}{PARTIAL_TAG}"))
                        + r"[a-z0-9_]*", lambda m: str(final), _one_line(exc))
        return _row(task, "failed", reason=reason, wall_s=time.perf_counter() - t0)
    finally:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)


def _out_root(task: ImageTask) -> Path:
    """The batch's output folder of ``task``: its ``out_dir`` less the ``out_rel`` parts."""
    root = Path(task.out_dir)
    for _ in Path(task.out_rel).parts:
        root = root.parent
    return root


def input_record(task: ImageTask) -> dict:
    """What an image's results were computed from: the scan and the calibration file, each
    by its path as given, its path resolved (absolute, links followed) and its SHA-256, and
    the calibration's widths (:func:`crosssection.core.provenance.input_record`, the record
    ``analyze`` writes, with the scan's path as the batch was given it).

    Parameters
    ----------
    task : ImageTask

    Returns
    -------
    dict
        ``{"image": {...}, "calibration": {...} or None}``.
    """
    cal = task.params.get("calibration")
    return provenance.input_record(task.image, cal if cal else None,
                                   given=task.given or task.image,
                                   image_sha256=task.image_sha or None)


def _recorded_info(task: ImageTask) -> dict | None:
    """The ``summary.json`` of the image's output folder when it holds a ``batch`` record,
    else None (no folder, no summary, an unreadable one, or one ``analyze`` wrote)."""
    try:
        summary = json.loads((Path(task.out_dir) / "summary.json").read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(summary, dict) or not isinstance(summary.get("batch"), dict):
        return None
    return summary


#: the count ``summary.json`` keeps of the rows of each table (n_branches = sum n_br, which
#: branches.csv has a row each of)
TABLE_COUNTS = {"junctions": "n_junctions", "stacks": "n_stacks", "branches": "n_branches",
                "voids": "n_voids"}


def _table_damage(path: Path, name: str, counted) -> str | None:
    """What a re-run finds wrong with table ``name`` at ``path``, or None when it is whole.

    Its header line is parsed and its lines counted, no more: a re-run checks every table
    of every scan.

    Parameters
    ----------
    path : Path
    name : str
        Its table in :data:`crosssection.core.schema.TABLES`.
    counted : int or None
        Its rows as ``summary.json`` counts them (:data:`TABLE_COUNTS`); None: not checked.

    Returns
    -------
    str or None
        ``"lost"`` (missing, unreadable, empty, malformed or lacking its schema's columns),
        or how it was cut short: fewer whole lines than ``counted`` rows, or a last line
        without its end (a copy or a disk that stopped mid-file), as
        ``"28 of the 57 rows summary.json counts, its last line cut off"``.
    """
    try:
        data = path.read_bytes()
        schema.check_table(name, pd.read_csv(io.BytesIO(data), nrows=0))
    except (OSError, ValueError):
        return "lost"
    rows = data.count(b"\n") - 1  # whole lines below the header
    cut = []
    if isinstance(counted, int) and not isinstance(counted, bool) and rows < counted:
        cut.append(f"{rows} of the {counted} rows summary.json counts")
    if not data.endswith(b"\n"):
        cut.append("its last line cut off")
    return ", ".join(cut) or None


def _damaged_tables(final: Path, summary: dict) -> tuple[list[str], list[str]]:
    """The tables of the output folder ``final`` lost and cut short (:func:`_table_damage`).

    Returns
    -------
    lost : list of str
        File names (``stacks.csv``).
    cut : list of (str, str)
        File name and how it was cut (``28 of the 57 rows summary.json counts``).
    """
    lost, cut = [], []
    for name in schema.TABLES:
        damage = _table_damage(final / f"{name}.csv", name, summary.get(TABLE_COUNTS[name]))
        if damage == "lost":
            lost.append(f"{name}.csv")
        elif damage:
            cut.append((f"{name}.csv", damage))
    return lost, cut


#: the last bytes of every whole PNG file: its IEND chunk (length 0, type, CRC)
PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"


def _overlay_damage(final: Path) -> str | None:
    """``"missing"`` or ``"cut short"`` (it lacks the PNG's closing chunk) for the
    ``overlay.png`` of the output folder ``final``, None when it is whole (its last bytes
    only are read)."""
    try:
        with open(final / "overlay.png", "rb") as fh:
            fh.seek(0, os.SEEK_END)
            fh.seek(max(fh.tell() - len(PNG_END), 0))
            end = fh.read()
    except OSError:
        return "missing"
    return None if end == PNG_END else "cut short"


def completed_row(task: ImageTask) -> dict | None:
    """The index row of an image already done with the same parameters hash, else None.

    Done means: its ``summary.json`` records this hash, ``overlay.png`` is there and whole
    when figures are wanted, and every table of :data:`crosssection.core.schema.TABLES` is
    readable with its schema's columns and holds the rows the summary counts (a table
    deleted, emptied, cut short or overwritten since, by hand, by a copy or by a disk that
    filled up, has the image redone rather than ``stats`` refuse the batch or count what is
    left).
    """
    summary = _recorded_info(task)
    if summary is None:
        return None
    final = Path(task.out_dir)
    info = summary["batch"]
    if info.get("params_hash") != task.params_hash:
        return None
    if task.figure and _overlay_damage(final) is not None:
        return None
    if any(_damaged_tables(final, summary)):
        return None
    row = _row(task, "skipped", summary, wall_s=info.get("wall_s", math.nan))
    row["seed"] = info.get("seed", task.seed)  # the seed the image was analysed with
    peak = info.get("peak_rss_mb")  # as the analysis measured it (None: not recorded)
    row["peak_rss_mb"] = float(peak) if isinstance(peak, (int, float)) else math.nan
    return row


def _resolved_params(params) -> dict | None:
    """``params`` with every default filled in (:meth:`AnalysisParams.to_dict`), so that a
    value given and the same value by default compare equal; None if they are not valid
    (a record written by another version)."""
    try:
        return AnalysisParams.from_mapping(params or {}).to_dict()
    except (FoldstatError, TypeError, ValueError):
        return None


def changed_inputs(task: ImageTask) -> list[str]:
    """What differs between the image's recorded analysis and the one the task would run.

    Parameters
    ----------
    task : ImageTask

    Returns
    -------
    list of str
        The names of the analysis parameters that differ, ``"package version"``, or, when
        neither does, ``"image or calibration file content"``; empty when the output folder
        records no analysis, or one with the task's parameters hash.
    """
    summary = _recorded_info(task)
    if summary is None or task.error:
        return []
    info = summary["batch"]
    if not info.get("params_hash") or info["params_hash"] == task.params_hash:
        return []
    before, after = _resolved_params(info.get("params")), _resolved_params(task.params)
    if before is None or after is None:
        before, after = info.get("params") or {}, task.params
    changed = [k for k in dict.fromkeys([*after, *before])
               if before.get(k) != after.get(k)]
    given_before = (info.get("params") or {}).get("px_per_mm") is not None
    if "px_per_mm" not in changed and given_before != (task.params.get("px_per_mm") is not None):
        changed.append("px_per_mm given" if not given_before else "px_per_mm left to its default")
    if info.get("version") != __version__:
        changed.append("package version")
    return changed or ["image or calibration file content"]


def redo_reason(task: ImageTask) -> str | None:
    """Why an image whose output folder records an analysis is analysed again, or None.

    Parameters
    ----------
    task : ImageTask

    Returns
    -------
    str or None
        What differs (:func:`changed_inputs`), else what the folder lacks (its
        ``summary.json`` unreadable or missing, a table missing, unreadable or cut short,
        ``overlay.png`` missing or cut short when figures are wanted); None when there is no
        output folder (a new scan) or it is complete with the task's parameters hash.
    """
    if task.error:
        return None
    final = Path(task.out_dir)
    summary = _recorded_info(task)
    if summary is None:
        return _summary_damage(final)
    changed = changed_inputs(task)
    if changed:
        params = [c for c in changed if c not in ("package version",
                                                  "image or calibration file content")]
        why = []
        if params:
            why.append(f"its parameters differ from the recorded ones ({', '.join(params)})")
        if "package version" in changed:
            why.append("another package version analysed it")
        if "image or calibration file content" in changed:
            why.append("its recorded parameters hash differs (the image or calibration file "
                       "changed)")
        return "; ".join(why)
    lost, cut = _damaged_tables(final, summary)
    why = [f"{', '.join(lost)} in {final} {'is' if len(lost) == 1 else 'are'} missing or "
           "unreadable"] if lost else []
    why += [f"{name} in {final} is cut short ({how})" for name, how in cut]
    if why:
        return "; ".join(why)
    if task.figure and (damage := _overlay_damage(final)) is not None:
        return f"overlay.png in {final} is {damage}"
    return None


def _summary_damage(final: Path) -> str | None:
    """Why the output folder ``final``, which records no batch analysis, is analysed again:
    its ``summary.json`` unreadable (cut short, overwritten), written by another command, or
    missing beside the rest of the folder; None when there is no folder (a new scan)."""
    path = final / "summary.json"
    if path.is_file():
        try:
            json.loads(path.read_text())
        except (OSError, ValueError):
            return f"summary.json in {final} is unreadable (cut short or overwritten)"
        return f"summary.json in {final} records no analysis of a batch"
    if final.is_dir():
        return f"summary.json in {final} is missing"
    return None


def stale_outputs(out_dir, tasks) -> list[str]:
    """Output folders under ``out_dir`` (holding a ``summary.json``) that no task writes: left
    by a scan since moved, renamed or deleted, or a set renamed. Posix paths relative to
    ``out_dir``, sorted; hidden folders (staging) are not counted."""
    out = Path(out_dir)
    if not out.is_dir():
        return []
    mine = {t.out_rel.lower() for t in tasks}
    found = []
    for summary in out.rglob("summary.json"):
        rel = summary.parent.relative_to(out)
        if rel.parts and not any(p.startswith(".") for p in rel.parts) \
                and rel.as_posix().lower() not in mine:
            found.append(rel.as_posix())
    return sorted(found)


# --------------------------------------------------------------------------- driver


class BatchWarning(QualityWarning):
    """A doubt about the batch as a whole, raised before its images are analysed: a set's
    ``set.toml`` or ``calibration.csv`` values that are not used, a linked folder not
    searched, an image analysed again over a recorded result (and why), output folders that
    no scan names (the command line prints each as a ``warning:`` line)."""



def _warning_line(text: str) -> None:
    """``warning: text`` on stderr as one line (a file name holding a line break
    included), as the command line prints the analysis' warnings."""
    print(f"warning: {' '.join(text.split())}", file=sys.stderr)


def _write_record(path: Path, write, data) -> None:
    """Write one of the batch's own records (``write(path, data)``).

    Raises
    ------
    OutputError
        Naming ``path`` and the cause (a full disk): the batch cannot go on without its
        records, and a re-run resumes from the images' folders.
    """
    try:
        write(path, data)
    except OSError as exc:
        # the atomic writes name the file already (OutputError); other errors get named here
        err = exc if isinstance(exc, OutputError) else output_error(exc, path)
        raise OutputError(f"{err.cause}; the batch stops: re-run the same command to resume",
                          err.path or path) from None


def _write_tables(out: Path, rows: dict, tasks: list[ImageTask], pending=()):
    """``index.csv`` and ``failures.csv`` of the rows so far; the tasks of ``pending`` not
    yet in ``rows`` are listed as pending, with their output folder and no numbers."""
    waiting = {t.rel: t for t in pending}
    ordered = [rows[t.rel] if t.rel in rows else _row(waiting[t.rel], "pending")
               for t in tasks if t.rel in rows or t.rel in waiting]
    index = pd.DataFrame(ordered, columns=INDEX_COLUMNS)
    for c in ("n_junctions", "n_stacks", "n_branches", "n_voids", "seed"):
        index[c] = pd.to_numeric(index[c], errors="coerce").astype("Int64")  # ints, blank if none
    _write_record(out / "index.csv", write_csv, index)
    failed = index[index["status"] == "failed"][FAILURE_COLUMNS]
    _write_record(out / "failures.csv", write_csv, failed)
    return index


#: the file a running batch locks in OUT_DIR (holding its process id), removed when it ends
LOCK_FILE = ".batch.lock"


@contextmanager
def batch_lock(out: Path):
    """Hold an exclusive lock on the output folder ``out`` while a batch writes into it.

    Two batches writing into one folder would each remove the other's staging folders as a
    killed run's, and each write an index of its own. The lock is
    :func:`~crosssection.core.fileio.exclusive_lock` on :data:`LOCK_FILE`.

    Parameters
    ----------
    out : Path
        The output folder (existing).

    Yields
    ------
    str or None
        The run's token (:func:`~crosssection.core.fileio.lock_holds`): each task keeps its
        results only while the lock file holds it.

    Raises
    ------
    ParameterError
        Another batch holds the lock (named by its process id).
    OutputError
        The lock file cannot be created.
    """
    def unlocked():
        warnings.warn(f"{out}: its file system takes no lock: a second batch into it "
                      "would not be refused (run one batch at a time there)",
                      BatchWarning, stacklevel=4)

    with exclusive_lock(out / LOCK_FILE, where=out, busy="another batch is writing into it",
                        unlocked=unlocked) as token:
        yield token


def clear_leftovers(out: Path, tasks) -> None:
    """Remove what killed runs left in the output folder ``out``: the temporary files of the
    batch's records (:data:`RESERVED_NAMES`) and the staging folders beside the scans'
    output folders, those of scans skipped as done included (a ``--force`` run killed while
    it redid one). Called with the batch's lock held (:func:`batch_lock`): no other batch is
    writing them.

    Parameters
    ----------
    out : Path
    tasks : list of ImageTask
    """
    found = temporary_files(out, RESERVED_NAMES)
    for parent in sorted({Path(t.out_dir).parent for t in tasks}):
        if parent.is_dir():
            found.extend(p for p in parent.iterdir() if is_working_folder(p.name))
    for p in found:
        try:
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
        except OSError:
            pass  # tried again by the next run


def _executor_slots(ex, workers: int) -> int:
    client = getattr(ex, "_client", None)  # Dask ClientExecutor
    if client is not None:
        try:
            return max(2, 2 * sum(client.nthreads().values()))
        except Exception:  # noqa: BLE001
            return 64
    return max(1, 2 * workers)


def check_out_dir(input_dir, out_dir, *, force: bool = False) -> None:
    """Refuse an output folder that a batch of ``input_dir`` must not write into.

    ``out_dir`` may be missing (it is created), empty, or hold an earlier batch of the same
    input folder (which the batch resumes). It may lie inside the input folder. The files a
    batch killed before its first record left (its lock file, the temporary file of a
    record) count as nothing.

    Parameters
    ----------
    input_dir, out_dir : str or Path
    force : bool
        The batch redoes every scan: a ``batch.json`` that cannot be read, beside the batch's
        ``index.csv``, is taken for this input folder's, and rewritten.

    Raises
    ------
    ParameterError
        Naming ``out_dir``: it holds the batch of another input folder (whose outputs the
        new batch would mix with its own and leave out of its index), or files that are no
        batch's (a folder of scans, a report, a simulation).
    ConfigError
        Its ``batch.json`` cannot be read (without ``force``).
    """
    out = Path(out_dir)
    if not out.is_dir():
        return  # created (a file in the way is named when it is)
    record = out / "batch.json"
    if record.is_file():
        try:
            data = read_json_object(record)
        except ConfigError as exc:
            if force and (out / "index.csv").is_file():
                # a batch's folder (its index beside the record): every scan is redone,
                # nothing of the lost record is needed
                return
            raise ConfigError(f"{exc.cause}: the batch's record is damaged; re-run with "
                              "--force to redo every scan and write it anew", record) from None
        recorded = data.get("input_dir")
        if recorded is not None and Path(recorded) != Path(input_dir).resolve():
            raise ParameterError(f"holds the batch of another input folder ({recorded}): "
                                 "give another --out", out)
        return
    names = sorted(p.name for p in out.iterdir())
    if names:
        # a file browser's own files, or what a batch killed before its first record left,
        # do not make a folder someone else's
        own = {LOCK_FILE, *(p.name for p in temporary_files(out, RESERVED_NAMES))}
        names = [n for n in names if n not in BROWSER_FILES and n not in own]
    if names:
        raise ParameterError(f"neither empty nor a batch's output (it holds {names[0]}): give "
                             "a new or empty --out, or the one of an earlier batch of this "
                             "input", out)


def run_batch(input_dir, out_dir, *, workers: int | None = 1, scheduler: str | None = None,
              seed: int | None = 0, figure: bool = True, cli_params: dict | None = None,
              force: bool = False, progress: bool | None = None, task_fn=None,
              on_wait=None, signalled=None) -> pd.DataFrame:
    """Analyse every image under ``input_dir`` into ``out_dir`` (see module docstring).

    Parameters
    ----------
    input_dir, out_dir : str or Path
    workers : int or None
        Local worker processes (1 runs inline, None = all cores). Ignored with ``scheduler``.
    scheduler : str, optional
        Dask scheduler address; tasks run on that cluster.
    seed : int, optional
        Base seed of the per-image seeds (:func:`image_seed`); recorded only, the analysis
        drawing no random numbers.
    figure : bool
        Draw ``overlay.png`` for each image.
    cli_params : dict, optional
        Analysis parameters for images outside any set (and defaults under a ``set.toml``).
    force : bool
        Redo images even when their output is complete.
    progress : bool or None
        Show a tqdm progress bar (with ETA) on stderr; None: only when stderr is a terminal,
        so that logs and pipes get nothing but warnings and errors.
    task_fn : callable, optional
        Replaces :func:`process_image` (a module-level function, for tests).
    on_wait : callable, optional
        Told, in one line, that a cluster has no worker yet (see
        :func:`~crosssection.core.parallel.get_executor`).
    signalled : callable, optional
        Returns the interrupt the process was sent (an exception to raise), or None
        (:func:`crosssection.cli.interrupt_received`). Once it returns one, the batch stops
        with it, and a scan that failed meanwhile is left out of the index, for the re-run:
        code inside the analysis may catch an interrupt and raise another error in its place
        (matplotlib does while it draws) or swallow it.

    Returns
    -------
    pandas.DataFrame
        The index (also written to ``out_dir/index.csv``).

    Raises
    ------
    ConfigError
        The input folder does not exist or holds no image.
    ParameterError
        ``out_dir`` holds another input folder's batch or files no batch wrote
        (:func:`check_out_dir`), another batch is writing into it (:func:`batch_lock`), or
        the Dask scheduler cannot be reached. Nothing is written then.
    OutputError
        The batch's own records (``index.csv``, ``failures.csv``, ``batch.json``) cannot be
        written (a full disk): the batch stops, naming the file. The images done so far are
        in their folders, and a re-run resumes from them.
    ClusterLostError
        The Dask cluster went away during the batch. The images it had are left out of the
        index (neither done nor failed): a re-run analyses them.
    """
    from tqdm.auto import tqdm

    t_start = time.time()
    out = Path(out_dir)
    tasks, sets = plan_batch(input_dir, out, cli_params=cli_params, seed=seed, figure=figure)
    check_out_dir(input_dir, out, force=force)

    # the executor before any write: a scheduler that cannot be reached is refused with
    # nothing left behind (an empty batch would read as a finished one)
    pool = ExitStack()
    ex = pool.enter_context(get_executor(workers, scheduler, on_wait=on_wait))
    held = ExitStack()  # the batch's lock on out, to the end of the run
    try:
        out.mkdir(parents=True, exist_ok=True)
        token = held.enter_context(batch_lock(out))
        # this batch alone writes into out now: what killed runs left there can go
        clear_leftovers(out, tasks)
        stale = stale_outputs(out, tasks)
        rows: dict[str, dict] = {}
        todo, redone = [], []
        # local worker processes share one numba disk cache: on an empty one, the first to
        # compile does so for all, the output folder being their lock (a cluster's workers do
        # not share this disk, and threads must not wait inside numba's compiler)
        local_pool = scheduler is None and (workers or os.cpu_count() or 1) > 1
        lock = str(out.resolve()) if local_pool else None
        for t in tasks:
            if t.error:
                rows[t.rel] = _row(t, "failed", reason=t.error)
                continue
            done = None if force else completed_row(t)
            if done is not None:
                rows[t.rel] = done
                continue
            todo.append(replace(t, compile_lock=lock, run_token=token))
            why = None if force else redo_reason(t)
            if why:
                redone.append((t.given or t.image, why))
        # the local processes used (None: one per CPU); a cluster's are its own
        used = workers if workers is not None or scheduler else os.cpu_count() or 1
        meta = _start(out, input_dir, tasks, sets, redone, stale, {
            "workers": used, "scheduler": scheduler, "seed": seed, "figure": figure,
            "force": force, "cli_params": cli_params or {}})
        # before any analysis: an earlier run's rows of the scans redone now must not
        # outlive their folders if this run is killed
        _write_tables(out, rows, tasks, pending=todo)
    except BaseException:
        held.close()
        pool.close()
        raise

    def interrupt():
        return signalled() if signalled is not None else None

    bar = tqdm(total=len(tasks), initial=len(rows), unit="img", desc="batch",
               disable=None if progress is None else not progress,
               dynamic_ncols=True)
    last_write, failed_now = time.monotonic(), False
    fn = task_fn or process_image
    queue, suspects = deque(todo), deque()
    interrupted, stopped = False, False
    stop_exc = None
    try:
        while queue or suspects:
            if ex is None:  # the previous pool broke
                pool = ExitStack()
                ex = pool.enter_context(get_executor(workers, scheduler, on_wait=on_wait))
            with pool:
                slots = _executor_slots(ex, workers or os.cpu_count() or 1)
                inflight, broken = {}, False
                while True:
                    # suspects (in flight when a worker died) run alone, so that a death
                    # names its image for sure; the others fill the free slots, until an
                    # interrupt (the inline executor runs a task as it is submitted: the
                    # next would start although the interrupt was swallowed)
                    stop = interrupt()
                    while not broken and stop is None:
                        if suspects:
                            if inflight:
                                break
                            t, alone = suspects.popleft(), True
                        elif queue and len(inflight) < slots:
                            t, alone = queue.popleft(), False
                        else:
                            break
                        try:
                            inflight[ex.submit(fn, t)] = (t, alone)
                        except (BrokenProcessPool, RuntimeError):
                            (suspects if alone else queue).appendleft(t)
                            broken = True
                        stop = interrupt()
                    if not inflight:
                        if stop is not None:
                            raise stop
                        break
                    done, _ = wait(list(inflight), return_when=FIRST_COMPLETED)
                    lost = None
                    for fut in done:
                        t, alone = inflight.pop(fut)
                        try:
                            row = fut.result()
                        except ClusterLostError as exc:
                            # not the image's failure: left out of the index, for the re-run
                            lost = exc
                            continue
                        except BrokenProcessPool:
                            # a worker process died (killed, out of memory, crash)
                            broken = True
                            if not alone:
                                suspects.append(t)
                                continue
                            row = _row(t, "failed",
                                       reason="worker process died while analysing this image")
                        except Exception as exc:  # noqa: BLE001 - lost task (cluster error)
                            row = _row(t, "failed", reason=_one_line(exc))
                        if row["status"] == "failed" and interrupt() is not None:
                            # the interrupt, caught inside the analysis and raised as another
                            # error: not the image's failure, left for the re-run
                            continue
                        rows[t.rel] = row
                        failed_now = failed_now or row["status"] == "failed"
                        bar.update(1)
                    if lost is not None:
                        raise lost
                    stop = interrupt()
                    if stop is not None:  # an interrupt that the analysis swallowed
                        raise stop
                    if failed_now or time.monotonic() - last_write > INDEX_EVERY_S:
                        _write_tables(out, rows, tasks, pending=todo)
                        last_write, failed_now = time.monotonic(), False
            ex = None
    except (KeyboardInterrupt, ClusterLostError) as exc:
        # an interrupt landing once every image is done stops nothing: the batch is complete
        if len(rows) < len(tasks):
            interrupted = stopped = True
            stop_exc = exc
            raise
    except BaseException as exc:
        stopped, stop_exc = True, exc
        raise
    finally:
        pool.close()  # the first pool, when no image was left to analyse
        bar.close()
        if stopped and scheduler is None:
            # the local workers, terminated mid-scan, left their staging folders: removed now
            # rather than by the re-run (a cluster's tasks in flight may still be writing)
            clear_leftovers(out, tasks)
        try:
            index = _write_tables(out, rows, tasks, pending=todo)
            counts = index["status"].value_counts().to_dict()
            meta.update(finished=provenance.timestamp(),
                        elapsed_s=time.time() - t_start,
                        counts={k: int(counts.get(k, 0))
                                for k in ("ok", "skipped", "failed", "pending")},
                        complete=len(rows) == len(tasks), interrupted=interrupted)
            _write_record(out / "batch.json", write_json, meta)
            if stop_exc is not None:
                # the rows done before the stop, for the caller to report (``run``)
                stop_exc.batch_index = index
        except OutputError:
            # a batch that stops for another reason (an interrupt, the same full disk) is
            # told by that reason: these records are written where they can be
            if not stopped:
                raise
        finally:
            held.close()
    return index


def _start(out: Path, input_dir, tasks, sets, redone: list, stale: list,
           options: dict) -> dict:
    """Create ``out``, print the batch's warnings and write its ``batch.json``.

    Parameters
    ----------
    out : Path
    input_dir : str or Path
    tasks : list of ImageTask
    sets : dict
        As returned by :func:`plan_batch`.
    redone : list of (str, str)
        The images analysed again over a recorded analysis, and why (:func:`redo_reason`).
    stale : list of str
        Output folders no scan writes (:func:`stale_outputs`).
    options : dict
        The options of :func:`run_batch` the record keeps (workers, scheduler, seed, figure,
        force, cli_params).

    Returns
    -------
    dict
        The record written.
    """
    out.mkdir(parents=True, exist_ok=True)
    meta = {
        "package": "foldstat", "version": __version__, "python": sys.version.split()[0],
        "input_dir": str(Path(input_dir).resolve()), "out_dir": str(out.resolve()),
        **options,
        "sets": {k: {"name": s.name, "folder": str(s.folder),
                     "source": None if s.source is None else str(s.source),
                     "params": s.params, "overrides": s.overrides, "error": s.error,
                     "warnings": s.warnings} for k, s in sets.items()},
        "n_images": len(tasks), "stale_outputs": stale,
        "started": provenance.timestamp(),
    }
    for s in sets.values():
        for w in s.warnings:
            warnings.warn(w, BatchWarning, stacklevel=3)
    for image, why in redone:
        # the old folder stays until the new analysis is written: a failed redo keeps it
        warnings.warn(f"{image}: analysed again: {why}; its earlier results are replaced if "
                      "it succeeds", BatchWarning, stacklevel=3)
    if stale:
        n = len(stale)
        shown = ", ".join(stale[:5]) + (f" and {n - 5} more" if n > 5 else "")
        they = "they are left as they are and stay" if n > 1 else "it is left as it is and stays"
        warnings.warn(f"{out}: {n} output folder{'s' if n > 1 else ''} match"
                      f"{'' if n > 1 else 'es'} no scan of this batch: {shown} (a scan "
                      f"moved, renamed or deleted, or a set renamed); {they} out of "
                      "index.csv", BatchWarning, stacklevel=3)
    _write_record(out / "batch.json", write_json, meta)
    return meta


# --------------------------------------------------------------------------- CLI


def add_subparser(sub):
    """Register the ``batch`` subcommand on an ``argparse`` subparsers object."""
    p = sub.add_parser(
        "batch", help="analyse every image under a folder, in parallel, resumable",
        description=f"Analyse every image ({', '.join(x[1:] for x in IMAGE_SUFFIXES)}; "
                    "recursive) under "
                    "INPUT_DIR into OUT_DIR/<set>/<image stem>/. A folder with a set.toml is "
                    "a set; finished images are skipped on a re-run; bad images are listed in "
                    "OUT_DIR/failures.csv and the batch goes on. A symbolic link to a scan is "
                    "analysed under its own name; a link to a folder is not searched (a "
                    "warning names it).")
    p.add_argument("input_dir", metavar="INPUT_DIR",
                   help="folder of scans (searched recursively; a folder with set.toml is a set)")
    p.add_argument("--out", required=True, metavar="OUT_DIR",
                   help="output folder: new, empty, or an earlier batch of the same INPUT_DIR "
                        "(finished images are skipped on a re-run)")
    p.add_argument("--workers", type=int, default=None,
                   help="local worker processes (default: all cores; 1 runs inline)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler address, e.g. tcp://127.0.0.1:8786")
    p.add_argument("--seed", type=int, default=0,
                   help="base seed of the per-image seeds recorded in index.csv and "
                        "summary.json (each from this seed and the scan's path in INPUT_DIR). "
                        "The analysis draws no random numbers: its results do not depend on "
                        "it")
    p.add_argument("--no-figure", action="store_true", help="skip overlay.png")
    p.add_argument("--force", action="store_true", help="redo images already complete")
    bar = p.add_mutually_exclusive_group()
    bar.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar on stderr (default: only when stderr is a terminal)")
    bar.add_argument("--quiet", action="store_true", help="no progress bar (= --no-progress)")
    add_analysis_arguments(p)
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """Entry point of ``python -m crosssection batch``; returns the exit status (0 all images
    done, 3 finished with some images failed, 2 bad arguments)."""
    check_out(args.out)
    if args.workers is not None and args.workers < 1:
        raise ParameterError(f"must be >= 1, got {args.workers}", "--workers")
    if args.seed is not None and args.seed < 0:
        raise ParameterError(f"must be >= 0, got {args.seed}", "--seed")
    for name in PARAM_NAMES:
        value = getattr(args, name, None)
        if value is not None and name != "calibration":
            try:
                check_param(name, value)
            except ParameterError as exc:
                # many scans: the option is named (analyze names its one scan)
                raise ParameterError(exc.cause, "--" + name.replace("_", "-")) from None
    cli_params = {k: v for k, v in AnalysisParams.from_cli_args(args).to_dict().items()
                  if getattr(args, k, None) is not None}
    cli_params.update(switched_off(args))
    workers, lowered = capped_workers(args.workers, args.scheduler)
    if lowered:
        print(f"warning: {lowered}", file=sys.stderr)
    from crosssection.cli import interrupt_received

    try:
        index = run_batch(args.input_dir, args.out, workers=workers,
                          scheduler=args.scheduler, seed=args.seed, figure=not args.no_figure,
                          cli_params=cli_params, force=args.force,
                          progress=False if args.quiet else args.progress,
                          on_wait=lambda message: print(f"warning: {message}",
                                                        file=sys.stderr),
                          signalled=interrupt_received)
    except KeyboardInterrupt as exc:
        # a stopped batch names the failures and doubts of the scans it finished, before
        # the error line, as a finished one does (the re-run skips those scans)
        done = getattr(exc, "batch_index", None)
        if done is not None:
            _report_rows(done, args)
        raise
    _report_rows(index, args)
    n = index["status"].value_counts()
    n_failed = int(n.get("failed", 0))
    print(f"batch: {len(index)} images: {int(n.get('ok', 0))} done, "
          f"{int(n.get('skipped', 0))} skipped, {n_failed} failed"
          + (f" (see {Path(args.out) / 'failures.csv'})" if n_failed else ""))
    return EXIT_SOME_FAILED if n_failed else 0


def _report_rows(index, args) -> None:
    """A ``warning:`` line for every image of ``index`` that failed or whose results are
    doubtful."""
    for _, row in index[index["status"] == "failed"].iterrows():
        shown = Path(args.input_dir) / row["image"]
        reason = str(row["reason"])
        # the reason names the scan by its full path: said once, at the start of the line
        full = f"{(Path(args.input_dir) / row['image']).absolute()}: "
        reason = reason[len(full):] if reason.startswith(full) else reason
        _warning_line(f"{shown}: not analysed: {reason}")
    for _, row in index[index["quality"].fillna("") != ""].iterrows():
        _warning_line(f"{Path(args.input_dir) / row['image']}: doubtful results "
                      f"({row['quality'].replace(';', ', ')}; see "
                      f"{Path(args.out) / row['output'] / 'summary.json'})")


__all__ = ["run_batch", "BatchWarning", "plan_batch", "process_image", "completed_row",
           "changed_inputs", "redo_reason", "stale_outputs", "check_set_names",
           "recorded_outputs", "effective_params", "image_seed", "input_record",
           "check_out_dir", "find_images", "params_hash", "ImageTask", "add_subparser", "run",
           "batch_lock", "clear_leftovers"]
