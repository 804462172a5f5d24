"""scipy's MILP solver without the lines HiGHS prints on its own.

HiGHS 1.12 (scipy 1.17) prints ``HighsMipSolverData::transformNewIntegerFeasibleSolution
tmpSolver.run();`` with C's ``printf`` whenever it repairs an integer solution, whatever its
``disp``/``output_flag`` option says (HiGHS issue 2783). It goes to file descriptor 1, out of
reach of ``sys.stdout``: a generated scene printed 26 such lines into a command's output.
"""
from __future__ import annotations

import ctypes
import os
import sys
import threading
from contextlib import contextmanager

__all__ = ["milp", "c_stdout_silenced"]

_FD1_LOCK = threading.Lock()


def _flush_c_stdio() -> None:
    """Flush C's stdio buffers (what ``printf`` holds back when fd 1 is a file or a pipe)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no C library to ask (not on POSIX)
        pass


@contextmanager
def c_stdout_silenced():
    """Send file descriptor 1 to the null device while C code runs, then restore it."""
    with _FD1_LOCK:
        try:
            sys.stdout.flush()
            saved = os.dup(1)
        except (OSError, ValueError, AttributeError):  # no usable fd 1: nothing to silence
            yield
            return
        try:
            null = os.open(os.devnull, os.O_WRONLY)
        except OSError:
            os.close(saved)
            yield
            return
        os.dup2(null, 1)
        os.close(null)
        try:
            yield
        finally:
            _flush_c_stdio()  # what printf buffered goes to the null device, not after it
            os.dup2(saved, 1)
            os.close(saved)


def milp(*args, **kwargs):
    """:func:`scipy.optimize.milp`, with what HiGHS prints on fd 1 discarded."""
    from scipy.optimize import milp as _milp

    with c_stdout_silenced():
        return _milp(*args, **kwargs)
