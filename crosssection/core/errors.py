"""Errors that reach the user as one clear line (file and cause), never a traceback."""
from __future__ import annotations

import os


def printable(path) -> str:
    """``path`` as text that every UTF-8 file and figure can hold: bytes of a file name that
    are not UTF-8 (held by Python as lone surrogates) are shown as ``\\xff`` escapes, as
    Python's stderr shows them.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    str
    """
    text = os.fsdecode(path)
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # a lone surrogate that stands for no byte (from JSON, say)
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def why_unreadable(exc: BaseException) -> str:
    """What an exception raised while reading a file says of that file, in words and on one
    line: a user reads "not a text file", not ``UnicodeDecodeError``.

    Parameters
    ----------
    exc : BaseException

    Returns
    -------
    str
    """
    import json

    if isinstance(exc, UnicodeDecodeError):
        return "not a text file"
    if isinstance(exc, json.JSONDecodeError):
        if not exc.doc.strip():
            return "empty file"
        return f"malformed JSON: {exc.msg} at line {exc.lineno}"
    if isinstance(exc, IsADirectoryError):
        return "a folder, not a file"
    if isinstance(exc, OSError):
        return exc.strerror or type(exc).__name__
    if type(exc).__name__ == "EmptyDataError":  # pandas: no header, no row
        return "empty file"
    if isinstance(exc, EOFError) or type(exc).__name__ == "BadZipFile":
        return "cut short or not of its format"
    words = " ".join(str(exc).split())
    if "pickle" in words:  # numpy's advice to unpickle a file it cannot read: not for users
        return "not a NumPy archive of arrays"
    return words[:200] if words else type(exc).__name__


def one_line_path(path) -> str:
    """``path`` printable (:func:`printable`) and on one line: a line break in a file name
    becomes a space, so that a message naming the file stays one line.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    str
    """
    return " ".join(printable(path).splitlines())


class FoldstatError(Exception):
    """Base class of every expected failure of the toolkit.

    Parameters
    ----------
    cause : str
        What went wrong, in one short sentence.
    path : str or os.PathLike, optional
        The file the failure concerns; it is named first in the message.
    """

    def __init__(self, cause: str, path=None):
        self.cause = str(cause)
        self.path = None if path is None else str(path)
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The message shown to the user: ``"<file>: <cause>"``."""
        msg = " ".join(printable(self.cause).split())
        # a file name holding a line break stays on the one line, as in warnings
        return f"{one_line_path(self.path)}: {msg}" if self.path else msg


class ImageError(FoldstatError):
    """The image cannot be read or is not an RGB scan."""


class ParameterError(FoldstatError):
    """A parameter is absurd (negative scale, s_min larger than the image, ...)."""


class AnalysisError(FoldstatError):
    """The scan was read but cannot be analysed (empty mask, nothing left after cleaning, ...)."""


class ConfigError(FoldstatError):
    """A set.toml, calibration file or other configuration is missing or malformed."""


class OutputError(FoldstatError, OSError):
    """An output folder or file cannot be written (a file in the way, no permission, a
    read-only or full disk). Also an ``OSError``, which it replaces."""


def output_error(exc: OSError, path) -> OutputError:
    """``exc`` as an :class:`OutputError` naming ``path`` and the cause in one line."""
    why = exc.strerror or " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, (FileExistsError, NotADirectoryError)):
        why = f"{why}: a file is in the way of a folder"
    return OutputError(f"cannot write ({why})", exc.filename or path)
