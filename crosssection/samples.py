"""The sample scans of the demo (``sample_images/`` of the source tree), also after a plain
``pip install``: ``foldstat samples DIR`` copies them out.

Five synthetic scans (PNG, JPEG, 16-bit TIFF; 50 px/mm, h = 0.1 mm) with ``set.toml``,
``calibration.csv`` and their exact truth in ``scenes/<stem>/``, about 3.4 MB, written by
``scripts/make_sample_images.py``. A wheel carries them as ``crosssection/_samples``; a source
checkout (editable install) reads ``sample_images/`` next to the package.

>>> from crosssection.samples import copy_samples
>>> copy_samples("samples")  # doctest: +SKIP
>>> # then: foldstat batch samples --out batch/ ; foldstat stats batch/ --out report/
"""
from __future__ import annotations

import argparse
import os
import shlex
import shutil
from pathlib import Path

from crosssection.core.errors import ConfigError, OutputError, ParameterError, output_error
from crosssection.core.fileio import check_out
from crosssection.core.records import output_of

__all__ = ["samples_path", "copy_samples", "add_subparser"]


def samples_path() -> Path:
    """The folder of the bundled sample scans.

    Returns
    -------
    Path
        ``crosssection/_samples`` of an installed wheel, else ``sample_images/`` of the source
        tree the package runs from.

    Raises
    ------
    ConfigError
        When neither exists (a build without the samples).
    """
    here = Path(__file__).resolve().parent
    for cand in (here / "_samples", here.parent / "sample_images"):
        if (cand / "set.toml").is_file():
            return cand
    raise ConfigError("the sample scans are not installed (reinstall foldstat from its wheel "
                      "or source tree)", here / "_samples")


def copy_samples(dest, *, overwrite: bool = False) -> list[Path]:
    """Copy the sample scans, their ``set.toml``, calibration and truth into ``dest``.

    Parameters
    ----------
    dest : str or Path
        A folder, created if needed.
    overwrite : bool
        Replace files already in ``dest``; otherwise an existing file is an error and nothing
        is copied.

    Returns
    -------
    list of Path
        The written files.

    Raises
    ------
    ParameterError
        ``dest`` is not a path, or an empty one (the current folder would take the files).
    ConfigError
        A file to write exists (and not ``overwrite``), or the samples are missing.
    OutputError
        ``dest`` is a file or the output folder of a command (a batch would read its
        figures as scans, and its next run would not know the scans), or a file or folder
        cannot be written there.
    """
    if not isinstance(dest, (str, os.PathLike)):
        raise ParameterError(f"dest must be a folder path, got {type(dest).__name__}")
    check_out(dest, "dest")
    src = samples_path()
    dest = Path(dest).expanduser()
    if dest.exists() and not dest.is_dir():
        raise OutputError("is a file, not a folder: give a folder to copy the samples into",
                          dest)
    held = output_of(dest)
    if held is not None:
        raise OutputError(f"holds the output of {held[1]} ({held[0]}): copy the samples into "
                          "a folder of their own", dest)
    files = sorted(p for p in src.rglob("*") if p.is_file() and "__pycache__" not in p.parts)
    targets = [dest / p.relative_to(src) for p in files]
    if not overwrite:
        for t in targets:
            if t.exists():
                raise ConfigError("exists already (use --force to overwrite)", t)
    try:
        for p, t in zip(files, targets):
            t.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(p, t)
    except OSError as exc:
        raise output_error(exc, dest) from None
    return targets


def add_subparser(sub) -> argparse.ArgumentParser:
    """Register ``samples``: ``foldstat samples DIR [--force]``."""
    p = sub.add_parser("samples", help="copy the bundled sample scans (with their truth) "
                                       "into a folder",
                       description=__doc__.split("\n\n")[0].replace("``", ""))
    p.add_argument("dest", metavar="DIR", help="destination folder (created)")
    p.add_argument("--force", action="store_true",
                   help="overwrite files already there (default: refuse)")
    p.set_defaults(func=run)
    return p


def run(args) -> int:
    """Copy the samples and say what to run next."""
    check_out(args.dest, "DIR")
    written = copy_samples(args.dest, overwrite=args.force)
    scans = [p for p in written if p.parent == Path(args.dest).expanduser()
             and p.suffix in (".png", ".jpg", ".tif")]
    # the batch's output beside the scans, never in their own folder
    dest = Path(args.dest).expanduser()
    out = "batch/" if dest.resolve() != Path("batch").resolve() else f"{dest.name}_out/"
    print(f"{len(scans)} sample scans and their truth -> {args.dest} "
          f"(next: foldstat batch {shlex.quote(str(args.dest))} --out {out})")
    return 0
