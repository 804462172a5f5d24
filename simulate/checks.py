"""Checks of the arguments of the simulator's Python API.

Each check returns the value in the type the computation uses, or raises a
:class:`~crosssection.core.errors.ParameterError` whose one line names the argument, the range
it must lie in and the value given. They run once per call, never inside a minimiser's loop.
"""
from __future__ import annotations

import math
import numbers
import reprlib

import numpy as np

from crosssection.core.errors import ParameterError

__all__ = ["check_real", "check_whole", "check_seed"]


def _short(value) -> str:
    """``repr`` of an argument cut to one short line."""
    return reprlib.repr(value)


def check_real(name: str, value, *, low: float | None = None, high: float | None = None,
               low_open: bool = False, high_open: bool = False, why: str = "",
               also: str = "") -> float:
    """``value`` as a float if it is a finite real number in the given range.

    Parameters
    ----------
    name : str
        The argument's name, first in the message.
    value : object
        What the caller passed. A bool is refused (True would be read as 1), so is text.
    low, high : float, optional
        Bounds of the range (none when None).
    low_open, high_open : bool
        Whether the bound itself is excluded.
    why : str
        Why the range is what it is, appended to the message.
    also : str
        The other values the argument takes, named after the range (checked by the caller).

    Returns
    -------
    float

    Raises
    ------
    ParameterError
        Naming ``name``, the range and the value.
    """
    ok = (isinstance(value, numbers.Real) and not isinstance(value, bool)
          and math.isfinite(value))
    if ok and low is not None:
        ok = value > low if low_open else value >= low
    if ok and high is not None:
        ok = value < high if high_open else value <= high
    if not ok:
        rng = []
        if low is not None:
            rng.append(f"{'>' if low_open else '>='} {low:g}")
        if high is not None:
            rng.append(f"{'<' if high_open else '<='} {high:g}")
        what = ("a finite number" + (" " + " and ".join(rng) if rng else "")
                + (f", {also}" if also else ""))
        raise ParameterError(f"{name} must be {what}{f' ({why})' if why else ''}, "
                             f"got {_short(value)}")
    return float(value)


def check_whole(name: str, value, *, low: int) -> int:
    """``value`` as an int if it is a whole number ``>= low`` (``3`` or ``3.0``, not ``3.5``).

    Parameters
    ----------
    name : str
        The argument's name.
    value : object
        A bool is refused: True would be read as 1.
    low : int
        Smallest value accepted.

    Returns
    -------
    int

    Raises
    ------
    ParameterError
        Naming ``name``, the bound and the value.
    """
    ok = (isinstance(value, numbers.Real) and not isinstance(value, bool)
          and math.isfinite(value) and float(value).is_integer() and value >= low)
    if not ok:
        raise ParameterError(f"{name} must be a whole number >= {low}, got {_short(value)}")
    return int(value)


def check_seed(seed, *, generator: bool = True, name: str = "seed"):
    """``seed`` unchanged if numpy's random generators take it.

    Parameters
    ----------
    seed : object
        None, an integer >= 0 (or a sequence of them), a ``numpy.random.SeedSequence`` and,
        where ``generator``, a ``numpy.random.Generator`` or ``BitGenerator``.
    generator : bool
        Whether a generator is accepted (a function that spawns child seeds needs a seed).
    name : str
        The argument's name.

    Returns
    -------
    object
        ``seed`` itself.

    Raises
    ------
    ParameterError
        Naming ``name``, what it may be and the value.
    """
    if seed is None or isinstance(seed, np.random.SeedSequence):
        return seed
    if generator and isinstance(seed, (np.random.Generator, np.random.BitGenerator)):
        return seed
    ok = not isinstance(seed, (bool, float, str, bytes))
    if ok:
        try:
            np.random.SeedSequence(seed)
        except (TypeError, ValueError):
            ok = False
    if not ok:
        what = "None, an integer >= 0, a numpy.random.SeedSequence" + (
            " or a numpy.random.Generator" if generator else "")
        raise ParameterError(f"{name} must be {what}, got {_short(seed)}")
    return seed
