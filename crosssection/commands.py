"""The ``analyze`` and ``steps`` subcommands of ``python -m crosssection``.

``python -m crosssection analyze IMAGE [analysis options] [--no-figure] [--steps] --out DIR``
writes ``summary.json``, ``junctions.csv``, ``stacks.csv``, ``branches.csv``, ``voids.csv``
and ``overlay.png`` into DIR. The analysis options are generated from
:class:`crosssection.params.AnalysisParams` (``--help`` lists them with units and defaults).

``python -m crosssection steps IMAGE [analysis options] --out DIR`` writes the step images of
paper Fig. 2: ``step1_raw.png``, ``step2_threshold.png``, ``step3_clean.png``,
``step4_skeleton.png`` and ``steps.png`` (the four side by side), and ``steps.json``: the
parameters, the package version and the input file they were made with.

A run leaves DIR describing itself alone: when DIR holds the record of an earlier run
(``summary.json`` or ``steps.json``), the files of the command that this run does not write
(``overlay.png`` and ``steps.png`` under ``--no-figure``, the step images without
``--steps``) are removed from DIR once the new outputs are written; the step
images of a ``steps`` run of the same scan, which its ``steps.json`` describes, stay beside
an ``analyze`` without ``--steps``. Only those names are: nothing else in DIR is touched, a
folder with no such record keeps its files (they are the user's), and a run that fails
leaves the previous outputs whole. Every file is written
to a hidden temporary file and renamed; those that a run killed while writing left in DIR
(``.overlay.png.XXXX.png``) are removed when the next run starts (:func:`clear_temporary`).
DIR may not be the scan's own folder: a batch of that folder would read the outputs as scans.
"""
from __future__ import annotations

from pathlib import Path

from crosssection import quality
from crosssection.core import schema
from crosssection.core.errors import OutputError, one_line_path, output_error
from crosssection.core.fileio import check_out, temporary_files
from crosssection.core.records import is_record, output_of, read_record
from crosssection.params import AnalysisParams, add_analysis_arguments

#: the step images of paper Fig. 2, and the figure of the four side by side
#: (:func:`crosssection.result.write_step_images`)
STEP_IMAGES = ("step1_raw.png", "step2_threshold.png", "step3_clean.png",
               "step4_skeleton.png")
STEPS_FIGURE = "steps.png"
#: the record of a ``steps`` run: parameters, version, input file
STEPS_RECORD = "steps.json"
OVERLAY = "overlay.png"
#: per command, the files of its output folder that a run writes or not by its options;
#: ``analyze`` describes the step images it writes in summary.json, so a steps.json there
#: would describe others
OPTIONAL_OUTPUTS = {
    "analyze": (OVERLAY, *STEP_IMAGES, STEPS_FIGURE, STEPS_RECORD),
    "steps": (STEPS_FIGURE,),
}


#: the record that marks a folder as the output of an earlier run of each command
RUN_RECORDS = {"analyze": "summary.json", "steps": STEPS_RECORD}
#: per command, the files every run of it writes
_ALWAYS_WRITTEN = {"analyze": ("summary.json", *(f"{name}.csv" for name in schema.TABLES)),
                   "steps": (*STEP_IMAGES, STEPS_RECORD)}
#: per command, every file it may write into its output folder
OWN_FILES = {command: (*always, *OPTIONAL_OUTPUTS[command])
             for command, always in _ALWAYS_WRITTEN.items()}


def clear_temporary(out_dir, command: str) -> list[Path]:
    """Remove the temporary files that a run of ``command`` killed while writing left in
    ``out_dir`` (``.overlay.png.XXXX.png``: every file is written to one and renamed,
    :func:`crosssection.core.fileio.atomic_path`). No run removes them otherwise, and they
    are hidden. Only the temporary names of :data:`OWN_FILES` are taken.

    Parameters
    ----------
    out_dir : str or Path
    command : str
        ``"analyze"`` or ``"steps"``.

    Returns
    -------
    list of Path
        The files removed (none when ``out_dir`` does not exist).

    Raises
    ------
    OutputError
        A file cannot be removed.
    """
    return _unlinked(temporary_files(Path(out_dir).expanduser(), OWN_FILES[command]))


def _unlinked(paths) -> list[Path]:
    """Remove the files ``paths``; return those removed (one already gone is skipped).

    Raises
    ------
    OutputError
        A file cannot be removed.
    """
    removed = []
    for path in paths:
        try:
            path.unlink()
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise output_error(exc, path) from None
        removed.append(path)
    return removed


def earlier_run(out_dir) -> bool:
    """Whether ``out_dir`` holds the record of an earlier ``analyze`` or ``steps`` run: a
    JSON object with the package version and the parameters, as both records hold (a file of
    the same name that is not one leaves the folder the user's, whose files no run
    removes)."""
    out = Path(out_dir).expanduser()
    return any(is_record(out / name, ("version", "parameters"))
               for name in RUN_RECORDS.values())


def run_files(command: str, *, figure: bool = True, steps: bool = False) -> tuple:
    """The files a run of ``command`` writes into its output folder: ``analyze`` its record
    and tables, ``overlay.png`` with ``figure`` and the step images with ``steps``; ``steps``
    its images, ``steps.png`` with ``figure``, and its record."""
    if command == "steps":
        optional = (STEPS_FIGURE,) if figure else ()
    else:
        optional = (((OVERLAY,) if figure else ()) + (STEP_IMAGES if steps else ())
                    + ((STEPS_FIGURE,) if steps and figure else ()))
    return (*_ALWAYS_WRITTEN[command], *optional)


def check_not_other_output(out_dir, image=None, command="analyze", *, given_as="--out",
                           writes=None) -> None:
    """Refuse an output folder that holds the output of another command, or that of the
    other of ``analyze`` and ``steps`` for another scan.

    Parameters
    ----------
    out_dir : str or Path
    image : str or Path, optional
        The scan this run reads: an analysis in the folder of a ``steps`` run, or step images
        in the folder of an ``analyze`` run, must be of the same file (by path, links
        followed, or by content). A run of the same command replaces every file of the
        earlier one, whatever its scan.
    command : {"analyze", "steps"}
    given_as : str
        How the folder was given, named in the error (the option, or the API's argument).
    writes : iterable of str, optional
        The files this run writes (:func:`run_files`; default: every file ``command`` may
        write): in a folder of no earlier run, one of them that foldstat did not write is
        refused, the others are left.

    Raises
    ------
    ParameterError
        ``out_dir`` holds the record of a batch, a stats report, a render, a validate
        report or a simulation: one scan's tables beside it would be read as part of it (a
        batch's summary, a report's tables), and a re-run of that command would not know
        them. Or it holds the other command's output for another scan: ``steps`` would
        leave its images beside another scan's tables, ``analyze`` would remove another
        scan's step images.
    """
    from crosssection.core.errors import ParameterError

    out = Path(out_dir).expanduser()
    held = output_of(out_dir)
    if held is None:
        # (steps writes no table: a user's stacks.csv beside its images is left alone)
        foreign = None if earlier_run(out) else _foreign_file(
            out, command, OWN_FILES[command] if writes is None else tuple(writes))
        if foreign:
            raise ParameterError(f"{out_dir} holds {foreign}, which foldstat did not write "
                                 "(a run would replace it): give a folder of its own", given_as)
        return
    if held[1] not in ("foldstat analyze", "foldstat steps"):
        raise ParameterError(f"{out_dir} holds the output of {held[1]} ({held[0]}): give a "
                             "folder of its own", given_as)
    if image is None:
        return
    for other_command, name in RUN_RECORDS.items():
        if other_command == command:
            continue  # this run replaces that record and every file it describes
        other = _recorded_scan(Path(out_dir).expanduser() / name)
        if other is not None and not _same_scan(image, *other):
            raise ParameterError(f"{out_dir} holds the output of foldstat {other_command} "
                                 f"for another scan ({other[0]}): give a folder of its own",
                                 given_as)


def check_not_inside_other_output(out_dir, *, given_as="--out") -> None:
    """Refuse a scene folder, or a folder inside a batch's output, as the output folder of
    ``analyze`` or ``steps`` (:func:`_scene_or_batch_output`).

    Raises
    ------
    ParameterError
    """
    from crosssection.core.errors import ParameterError

    why = _scene_or_batch_output(Path(out_dir).expanduser())
    if why:
        raise ParameterError(f"{out_dir} {why}: give a folder of its own", given_as)


def _scene_or_batch_output(out: Path) -> str | None:
    """Why ``out`` belongs to another command's output below its top: a scene folder (its
    ``truth/``, which validate and batch read as a scene), or a folder inside a batch's
    output (a per-scan folder: the batch's index would describe another scan there)."""
    if (out / "truth" / "summary.json").is_file() and (out / "params.json").is_file():
        return "is a scene folder (its truth/ and params.json: batch and validate read it)"
    try:
        # a scan's folder is <out>/<set>/<stem>, a set's name up to a few folders deep
        parents = list(out.resolve().parents)[:6]
    except (OSError, RuntimeError):
        return None
    for parent in parents:
        if is_record(parent / "batch.json", {"package": "foldstat", "version": None}):
            return f"lies inside the output of foldstat batch ({parent})"
    return None


def _foreign_file(out: Path, command: str, writes) -> str | None:
    """The first file of ``out`` that a run of ``command`` writing ``writes`` would replace
    and that foldstat did not write: an analysis' table whose columns are not the table's,
    an image of the run's names without foldstat's ``Software`` text (a scan named
    overlay.png), a record (``summary.json``, ``steps.json``) that is not one."""
    for name in writes:
        path = out / name
        if name.endswith(".png") and path.is_file() and not _png_by_foldstat(path):
            return name
        if name == STEPS_RECORD and path.is_file() and not is_record(
                path, ("version", "parameters")):
            return name
    return _foreign_table(out) if command == "analyze" else None


#: Bytes of a PNG read for its ``Software`` text: foldstat's images write it before their
#: pixels, right after the header.
_PNG_HEAD_BYTES = 4096


def _png_by_foldstat(path: Path) -> bool:
    """Whether the PNG at ``path`` holds the ``Software`` text foldstat writes
    (:func:`crosssection.core.fileio.save_figure`, the step images)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(_PNG_HEAD_BYTES)
    except OSError:
        return True  # unreadable: nothing to tell, and nothing a run could replace either
    return b"tEXtSoftware\x00foldstat " in head


def _foreign_table(out: Path) -> str | None:
    """The first file of ``out`` named as an analysis' table whose columns are not the
    table's, or a ``summary.json`` that is not an analysis' record: a user's file that an
    analysis would replace."""
    for name, columns in schema.TABLES.items():
        path = out / f"{name}.csv"
        if not path.is_file():
            continue
        try:
            with open(path, encoding="utf-8", errors="replace") as fh:
                head = fh.readline().strip().split(",")
        except OSError:
            continue
        if head[:len(columns)] != list(columns):
            return path.name
    summary = out / "summary.json"
    if summary.is_file() and not is_record(summary, ("version", "parameters")):
        return summary.name
    return None


def _recorded_scan(record_path: Path):
    """``(resolved path, sha256)`` of the scan a run's record names, or None."""
    record = read_record(record_path, ("version", "parameters"))
    if record is None:
        return None
    try:
        image = record["inputs"]["image"]
        if image.get("resolved") is None:  # an image given to the API as an array
            return "an image given as an array", None
        return str(image["resolved"]), image.get("sha256")
    except (KeyError, TypeError, AttributeError):  # a record of another shape
        return None


def _same_scan(image, resolved: str, sha256) -> bool:
    """Whether ``image`` is the scan recorded as ``resolved`` with ``sha256``: the same file,
    or one of the same content (the scans' folder moved)."""
    from crosssection.core.fileio import special_file_reason
    from crosssection.core.provenance import file_sha256, resolved_path

    if resolved_path(image) == resolved or special_file_reason(image):
        return True  # (a pipe or a device: the loader refuses it, unread)
    try:
        return sha256 is not None and file_sha256(image) == sha256
    except OSError:
        return True  # unreadable: the loader names it


def check_not_beside(image, out_dir, *, given_as="--out") -> None:
    """Refuse an output folder that is the scan's own folder.

    Raises
    ------
    ParameterError
        ``out_dir`` is the folder holding ``image``: the outputs (PNG images among them)
        would lie beside the scan, and a batch of that folder would read them as scans.
    """
    from crosssection.core.errors import ParameterError

    try:
        same = Path(out_dir).expanduser().resolve() == Path(image).expanduser().resolve().parent
    except (OSError, RuntimeError):  # a loop of symbolic links: the loader names it
        return
    if same:
        raise ParameterError(f"{out_dir} is the scan's own folder: the outputs would lie "
                             "beside the scan, where a batch reads their images as scans and "
                             "takes the folder for an analysis'; give another folder",
                             given_as)


def remove_stale(out_dir, command: str, written) -> list[Path]:
    """Remove the files of ``command`` in ``out_dir`` that this run did not write.

    Parameters
    ----------
    out_dir : str or Path
        The output folder.
    command : str
        ``"analyze"`` or ``"steps"`` (a key of :data:`OPTIONAL_OUTPUTS`).
    written : iterable of Path
        The files this run wrote.

    Returns
    -------
    list of Path
        The files removed (only names of :data:`OPTIONAL_OUTPUTS`; folders are left).

    Raises
    ------
    OutputError
        A file cannot be removed.
    """
    out = Path(out_dir)
    kept = {Path(p).name for p in written}
    names = OPTIONAL_OUTPUTS[command]
    if command == "analyze" and not kept & set(STEP_IMAGES) and _steps_record(out):
        # the step images a steps run made of the same scan (another scan's output is
        # refused before any work), described by its own record: that run's, kept
        names = tuple(n for n in names if n not in (*STEP_IMAGES, STEPS_FIGURE, STEPS_RECORD))
    return _unlinked(out / name for name in names
                     if name not in kept and ((out / name).is_file() or (out / name).is_symlink()))


def _check_image_given(image) -> None:
    """An empty IMAGE is one line naming it (``Path("")`` is the working folder)."""
    if not str(image).strip():
        from crosssection.core.errors import ImageError

        raise ImageError("empty image path: give the scan's file")


def _steps_record(out: Path) -> bool:
    """Whether ``out`` holds the record of a ``steps`` run."""
    from crosssection.core.records import RECORDS

    keys = next(k for f, c, k in RECORDS if f == STEPS_RECORD)
    return is_record(out / STEPS_RECORD, keys)


def _removed_note(removed) -> str:
    if not removed:
        return ""
    return (f" (removed {len(removed)} file(s) of an earlier run: "
            f"{', '.join(p.name for p in removed)})")


def add_subparser(subparsers) -> None:
    """Register ``analyze`` and ``steps`` on the ``python -m crosssection`` parser."""
    pa = subparsers.add_parser(
        "analyze", help="analyse one scan into junctions, stacks, branches and voids",
        description="Analyse one scan of a cut cross-section (paper, 'Image analysis "
                    "procedure') and write summary.json, junctions.csv, stacks.csv, "
                    "branches.csv, voids.csv and overlay.png.")
    pa.add_argument("image", help=f"scan ({schema.IMAGE_FORMATS})")
    pa.add_argument("--out", required=True,
                    help="output folder (created; the outputs of an earlier analyze there "
                         "that this run does not write are removed)")
    pa.add_argument("--no-figure", action="store_true", help="do not draw overlay.png")
    pa.add_argument("--steps", action="store_true",
                    help="also save the step images of paper Fig. 2")
    add_analysis_arguments(pa)
    pa.set_defaults(func=run)
    ps = subparsers.add_parser(
        "steps", help="save the image-processing steps of one scan (paper Fig. 2)",
        description="Save the raw scan, the thresholded and cleaned masks and the skeleton "
                    "with its junctions as PNG images (paper Fig. 2), and steps.json: the "
                    "parameters, version and input file they were made with.")
    ps.add_argument("image", help=f"scan ({schema.IMAGE_FORMATS})")
    ps.add_argument("--out", required=True,
                    help="output folder (created; a steps.png of an earlier run there is "
                         "removed under --no-figure)")
    ps.add_argument("--no-figure", action="store_true",
                    help="only the four single images, not the combined steps.png")
    add_analysis_arguments(ps)
    ps.set_defaults(func=run_steps)


def run(args) -> int:
    """``analyze``: run the pipeline and write the output folder."""
    from crosssection.pipeline import analyze
    from crosssection.result import rod_length_text

    _check_image_given(args.image)
    check_out(args.out)
    check_not_beside(args.image, args.out)
    check_not_inside_other_output(args.out)
    check_not_other_output(args.out, args.image,
                           writes=run_files("analyze", figure=not args.no_figure,
                                            steps=args.steps))
    clear_temporary(args.out, "analyze")
    params = AnalysisParams.from_cli_args(args, path=args.image)
    # it names a set.toml whose values it does not use
    result = analyze(args.image, params, scale_given=args.px_per_mm is not None)
    out = Path(args.out).expanduser()
    earlier = earlier_run(out)
    written = result.write(out, figure=not args.no_figure, steps=args.steps)
    removed = remove_stale(out, "analyze", written.values()) if earlier else []
    s = result.summary
    print(f"{one_line_path(args.image)}: {s['n_junctions']} junctions, {s['n_stacks']} "
          f"stacks, {s['n_branches']} branches, {s['n_voids']} voids, {rod_length_text(s)}"
          f" -> {one_line_path(args.out)}{_removed_note(removed)}")
    return 0


def _warn_frame(pre, params, image, scale_given=True) -> None:
    """The warnings of ``analyze`` that stages 1-6 decide (the file, the scale, the threshold,
    the hole; a set.toml beside the scan that is not read): the step images show that
    frame."""
    import warnings

    from crosssection.pipeline import frame_flags
    from crosssection.setconfig import set_not_read

    note = set_not_read(image, params)
    if note:
        warnings.warn(note, quality.SetWarning, stacklevel=2)
    for f in frame_flags(pre, params, scale_given=scale_given):
        warnings.warn(f"{pre.path or image}: {f.message}", f.category, stacklevel=2)


def run_steps(args) -> int:
    """``steps``: stages 1-6 only, then the step images and their record ``steps.json``."""
    from crosssection.core.fileio import renamed_together, write_json
    from crosssection.figures import step_titles
    import json

    from crosssection.core.provenance import resolved_path
    from crosssection.pipeline import preprocess, write_step_images
    from crosssection.result import _remove_if_empty
    from crosssection.tables import recorded_parameters

    _check_image_given(args.image)
    check_out(args.out)
    check_not_beside(args.image, args.out)
    check_not_inside_other_output(args.out)
    check_not_other_output(args.out, args.image, "steps",
                           writes=run_files("steps", figure=not args.no_figure))
    clear_temporary(args.out, "steps")
    params = AnalysisParams.from_cli_args(args, path=args.image)
    pre = preprocess(args.image, params)
    _warn_frame(pre, params, args.image, scale_given=args.px_per_mm is not None)
    out = Path(args.out).expanduser()
    earlier = earlier_run(out)
    created = not out.exists()
    try:
        with renamed_together():  # never one run's images beside another's
            made_from = {"image": None if pre.path is None else resolved_path(pre.path),
                         "parameters": recorded_parameters(params)}
            paths = write_step_images(out, pre.rgb, pre.threshold.mask, pre.mask_clean,
                                      pre.skeleton, pre.junctions.centers_rc,
                                      figure=not args.no_figure,
                                      titles=step_titles(pre.threshold.as_summary()),
                                      px_per_mm=params.px_per_mm, hole=pre.hole,
                                      description=json.dumps(made_from, default=str,
                                                             sort_keys=True))
            # written last, as summary.json is: its presence marks the images complete
            record = write_json(out / STEPS_RECORD, steps_record(pre, params, paths.values()))
    except OutputError:
        _remove_if_empty(out, created)
        raise
    except OSError as exc:
        _remove_if_empty(out, created)
        raise output_error(exc, out) from None
    removed = remove_stale(out, "steps", [*paths.values(), record]) if earlier else []
    n_steps = sum(1 for name in paths.values() if Path(name).name != STEPS_FIGURE)
    shown = f"{n_steps} step images" + (f" and {STEPS_FIGURE}" if n_steps < len(paths) else "")
    print(f"{one_line_path(args.image)}: {shown} -> "
          f"{one_line_path(args.out)}{_removed_note(removed)}")
    return 0


def steps_record(pre, params: AnalysisParams, written) -> dict:
    """``steps.json``: what the step images of one scan were made with.

    Parameters
    ----------
    pre : crosssection.pipeline.Preprocessed
        Stages 1-6 of the scan.
    params : AnalysisParams
        The parameters used.
    written : iterable of Path
        The step images written.

    Returns
    -------
    dict
        ``command``, ``version``, ``libraries`` (versions of the numerical libraries),
        ``image`` (path, absolute with links followed, size, dtype), ``inputs`` (the scan
        and the calibration by path and SHA-256, as in summary.json), ``parameters`` (as in
        summary.json, with the ``s_min_mm2``, ``tangent_mm`` and ``smooth_px`` used),
        ``thresholds``, ``hole`` (as in summary.json), ``warnings`` and ``outputs`` (the file
        names).
    """
    from crosssection._version import __version__
    from crosssection.core.provenance import input_record, library_versions, resolved_path
    from crosssection.tables import hole_record, recorded_parameters

    h, w = pre.rgb.shape[:2]
    return {
        "command": "steps",
        "version": __version__,
        "libraries": library_versions(),
        "image": {"path": None if pre.path is None else resolved_path(pre.path),
                  "height_px": int(h), "width_px": int(w), "dtype": str(pre.rgb.dtype)},
        "inputs": input_record(pre.path if pre.path is not None else pre.rgb,
                               params.calibration),
        "parameters": recorded_parameters(params),
        "thresholds": pre.threshold.as_summary(),
        "hole": hole_record(pre, params),
        "warnings": list(pre.warnings),
        "outputs": sorted(Path(p).name for p in written),
    }
