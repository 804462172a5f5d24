"""What an output was computed from: input files by path and SHA-256, a calibration's table,
and the versions of the numerical libraries.

One record for every output that names its inputs: ``analyze`` (command line and API) writes
it as ``summary.json``'s ``inputs`` and ``libraries``, a batch as the same ``inputs`` (and
``batch.inputs``), the simulator's ``params.json`` as ``libraries``.

Paths follow one rule: a file is recorded by its path as given (``path``) and by its path
absolute and resolved, links followed (``resolved``, :func:`resolved_path`), so that the
record leads to the file from any folder and says which file a link stood for.
"""
from __future__ import annotations

import functools
import hashlib
import os

__all__ = ["file_sha256", "sha256_in_background", "resolved_path", "file_record", "image_record",
           "calibration_record", "input_record", "library_versions", "timestamp",
           "ANALYSIS_LIBRARIES"]

#: the libraries whose releases can move an analysis' numbers (``summary.json`` ``libraries``)
#: (the image decoders included: Pillow, tifffile and imagecodecs read the scans)
ANALYSIS_LIBRARIES = ("numpy", "scipy", "scikit-image", "opencv", "numba", "pandas", "pillow",
                      "tifffile", "imagecodecs")

#: a library -> the module whose ``__version__`` is the one imported: OpenCV comes as one of
#: four wheels that all provide ``cv2``, and the module is what the analysis runs
_MODULES = {"opencv": "cv2"}


def file_sha256(path, chunk: int = 1 << 20) -> str:
    """The SHA-256 of a file's content.

    Parameters
    ----------
    path : str or Path
    chunk : int
        Bytes read at a time.

    Returns
    -------
    str
        64 hex digits.

    Raises
    ------
    OSError
        The file cannot be read.
    """
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def _identity(path):
    """What changes when a file is written or replaced: device, inode, size, modification
    time (None when it cannot be read)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


def sha256_in_background(path):
    """Start hashing a file (:func:`file_sha256`) on a thread, for the record of an analysis
    that reads it meanwhile.

    ``hashlib`` releases the GIL while it hashes, so the analysis goes on: hashing the 7.9 MB
    PNG of a dense 2000x2000 scan takes 7.5-11 ms of the analysis' 0.27 s when done in line.
    The hash is of a second read of the file: it is kept only when the file is the same
    (device, inode, size, modification time) from before the analysis read it to after.

    Parameters
    ----------
    path : str or Path
        The file the analysis reads.

    Returns
    -------
    callable
        Called once the analysis has read the file: waits for the hash and returns
        ``(sha256, problem)``, the hex digest and None, or None and why there is none (the
        file changed or could not be read, or is no regular file: a named pipe or a device
        is not opened, since opening one waits for a writer, and what it holds is not there
        to be read again).
    """
    import stat
    import threading

    path = os.path.expanduser(os.fspath(path))
    before = _identity(path)
    out = {}
    try:
        regular = stat.S_ISREG(os.stat(path).st_mode)
    except OSError as exc:
        problem = f"the file could not be read again to hash it ({exc.strerror or exc})"
        return lambda: (None, problem)
    if not regular:
        return lambda: (None, "it is not a regular file")

    def work():
        try:
            out["sha256"] = file_sha256(path)
        except OSError as exc:
            out["problem"] = f"the file could not be read again to hash it ({exc.strerror or exc})"

    thread = threading.Thread(target=work, name="foldstat-sha256", daemon=True)
    thread.start()

    def result():
        thread.join()
        if "problem" in out:
            return None, out["problem"]
        if before is None or _identity(path) != before:
            return None, "the file changed while it was analysed"
        return out["sha256"], None

    return result


def resolved_path(path) -> str:
    """``path`` absolute, ``~`` expanded and symbolic links followed (the file it names from
    any working folder)."""
    return os.path.realpath(os.path.expanduser(os.fspath(path)))


def file_record(path, *, given=None, sha256: str | None = None, hashed: bool = False) -> dict:
    """``{"path", "resolved", "sha256"}`` of one input file.

    Parameters
    ----------
    path : str or Path
        The file read.
    given : str or Path, optional
        The path as the user named it (default ``path``).
    sha256 : str, optional
        Its SHA-256 when already computed; null when the file cannot be read (a
        calibration that ``steps``, which does not read it, was given and is missing).
    hashed : bool
        The hash was attempted already: ``sha256`` is recorded as given, null included.

    Returns
    -------
    dict
    """
    if sha256 is None and not hashed:
        try:
            sha256 = file_sha256(os.path.expanduser(os.fspath(path)))
        except OSError:
            sha256 = None
    return {"path": os.fspath(given if given is not None else path),
            "resolved": resolved_path(path), "sha256": sha256}


def image_record(image, *, given=None, sha256: str | None = None,
                 hashed: bool = False) -> dict:
    """The record of a scan.

    Parameters
    ----------
    image : str, Path or ndarray
    given, sha256, hashed
        As :func:`file_record`.

    Returns
    -------
    dict
        A file's :func:`file_record`; for an array, ``path``, ``resolved`` and ``sha256``
        null, with its ``shape`` and ``dtype`` as given.
    """
    if isinstance(image, (str, os.PathLike)):
        return file_record(image, given=given, sha256=sha256, hashed=hashed)
    import numpy as np

    a = np.asarray(image)
    return {"path": None, "resolved": None, "sha256": None, "shape": list(a.shape),
            "dtype": str(a.dtype)}


def calibration_record(calibration, table=None) -> dict | None:
    """The record of a calibration: a file's :func:`file_record` (null fields for a table
    given in memory) and ``widths``, its table ``{"n_layers": [...], "width_mm": [...]}`` at
    full precision; None without a calibration (the law ``n h``).

    Parameters
    ----------
    calibration : str, Path, Calibration, DataFrame or None
        As the analysis parameters hold it.
    table : Calibration, optional
        The table read from it (read here when not given); ``widths`` is null when it cannot
        be read.
    """
    from crosssection.core.calibration import Calibration
    from crosssection.core.errors import FoldstatError

    if calibration is None:
        return None
    if isinstance(calibration, (str, os.PathLike)):
        record = file_record(calibration)
    else:
        record = {"path": None, "resolved": None, "sha256": None}
    try:
        table = table if table is not None else Calibration.of(calibration)
        record["widths"] = {"n_layers": [int(n) for n in table.n_layers],
                            "width_mm": [float(w) for w in table.width_mm]}
    except (FoldstatError, OSError, TypeError, ValueError, AttributeError):  # a law, no table
        record["widths"] = None
    return record


def input_record(image, calibration=None, *, given=None, image_sha256: str | None = None,
                 image_hashed: bool = False, table=None) -> dict:
    """What an analysis read: ``{"image": image_record, "calibration": calibration_record}``.

    Parameters
    ----------
    image : str, Path or ndarray
        The scan as given to ``analyze``.
    calibration : str, Path, Calibration, DataFrame or None
        The calibration parameter.
    given : str or Path, optional
        The scan's path as the user named it (a batch's ``INPUT_DIR/rel``).
    image_sha256 : str, optional
        The scan's SHA-256 when already computed.
    image_hashed : bool
        The scan's hash was attempted already: ``image_sha256`` is recorded as given, null
        included (a file that changed while it was analysed).
    table : Calibration, optional
        The calibration's table when already read.

    Returns
    -------
    dict
    """
    return {"image": image_record(image, given=given, sha256=image_sha256, hashed=image_hashed),
            "calibration": calibration_record(calibration, table)}


@functools.lru_cache(maxsize=None)
def _version(name: str) -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    if name in _MODULES:
        import importlib

        try:
            return str(importlib.import_module(_MODULES[name]).__version__)
        except (ImportError, AttributeError):
            return None
    try:
        return version(name)
    except PackageNotFoundError:
        return None


def library_versions(names=ANALYSIS_LIBRARIES) -> dict:
    """The installed version of each library of ``names`` (None for one not installed).

    A new release of numpy, scipy, scikit-image, OpenCV or numba can move the last bits of
    a result (and a chaotic quench to another rod): an output records them beside the
    package version.

    Parameters
    ----------
    names : iterable of str
        Distribution names (``"opencv"``: the version of the ``cv2`` module imported).

    Returns
    -------
    dict
        name -> version string or None.
    """
    return {name: _version(name) for name in names}


def timestamp() -> str:
    """The time now, ISO 8601 in UTC with its offset (``2026-12-06T05:00:08+00:00``): a
    record read on another machine, or after a change of daylight-saving time, places it
    without knowing where it was written."""
    from datetime import datetime, timezone

    return datetime.now(timezone.utc).isoformat(timespec="seconds")
