"""Where numba keeps the compiled kernels when neither the package nor the home folder can.

The kernels are compiled with ``cache=True``: numba writes them beside the package's source
(``__pycache__``), else in the user's cache folder (``~/.cache/numba``). An install that a
user cannot write to (a shared site-packages), run by a user whose home folder cannot be
written either (a service account, a cluster job with ``HOME`` unset or read-only), leaves
numba no place: every analysis failed on its first kernel with numba's "cannot cache
function ...: no locator available". Such a process is given a cache folder of its own in
the system's temporary folder, through numba's own ``NUMBA_CACHE_DIR`` (read when numba is
imported), unless that variable is set already.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

#: the packages whose kernels numba caches beside their source
PACKAGES = ("crosssection", "simulate")


def _writable(folder: Path, access=os.access) -> bool:
    """Whether ``folder``, or the nearest folder above it that exists, can be written."""
    for cand in (folder, *folder.parents):
        try:
            if cand.exists():
                return cand.is_dir() and access(cand, os.W_OK | os.X_OK)
        except OSError:  # a folder above that cannot be entered (HOME of another user)
            return False
    return False


def _user_cache() -> Path:
    """numba's user-wide cache folder on this system (XDG on Linux, as numba's appdirs)."""
    base = os.environ.get("XDG_CACHE_HOME")
    try:
        return (Path(base) if base else Path.home() / ".cache") / "numba"
    except RuntimeError:  # no home folder at all
        return Path("/nonexistent")


def numba_cache_dir(environ=None, *, package_dirs=None, user_cache=None,
                    access=os.access) -> str | None:
    """The cache folder to give numba, or None when it has one (``NUMBA_CACHE_DIR`` set, the
    packages' folders writable, or the user's cache folder).

    Parameters
    ----------
    environ : mapping, optional
        The environment (default ``os.environ``).
    package_dirs : sequence of Path, optional
        The folders of :data:`PACKAGES` (default: where they are installed).
    user_cache : Path, optional
        numba's user-wide cache folder (default :func:`_user_cache`).
    access : callable
        ``os.access``, for tests.

    Returns
    -------
    str or None
    """
    environ = os.environ if environ is None else environ
    if environ.get("NUMBA_CACHE_DIR"):
        return None
    here = Path(__file__).resolve().parents[2]
    dirs = package_dirs if package_dirs is not None else [here / p for p in PACKAGES]
    if all(_writable(Path(d) / "__pycache__", access) for d in dirs):
        return None
    if _writable(user_cache if user_cache is not None else _user_cache(), access):
        return None
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    return str(Path(tempfile.gettempdir()) / f"foldstat-numba-cache-{uid}")


def use_writable_cache() -> None:
    """Set ``NUMBA_CACHE_DIR`` when numba would have no writable cache folder
    (:func:`numba_cache_dir`); called before numba is first imported."""
    folder = numba_cache_dir()
    if folder is not None:
        os.environ["NUMBA_CACHE_DIR"] = folder
