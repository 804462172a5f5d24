"""scipy's MILP solver without the lines HiGHS prints on its own.

HiGHS 1.12 (scipy 1.17) prints ``HighsMipSolverData::transformNewIntegerFeasibleSolution
tmpSolver.run();`` with C's ``printf`` whenever it repairs an integer solution, whatever its
``disp``/``output_flag`` option says (reported upstream as HiGHS issue 2783). It goes to file
descriptor 1, out of reach of ``sys.stdout``: a generated scene printed 26 such lines into a
command's output.
"""
from __future__ import annotations

import ctypes
import os
import sys
import threading
from contextlib import contextmanager

__all__ = ["milp", "c_stdout_silenced"]

# re-entrant: a silenced block may call another (each level saves and restores fd 1)
_FD1_LOCK = threading.RLock()


def _flush_c_stdio() -> None:
    """Flush C's stdio buffers (what ``printf`` holds back when fd 1 is a file or a pipe)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no C library to ask (not on POSIX)
        pass


@contextmanager
def c_stdout_silenced():
    """Send file descriptor 1 to the null device while C code runs, then restore it.

    What C and Python wrote before the block is flushed first; what is written to fd 1
    inside it is discarded, Python's writes included once flushed (``print(...,
    flush=True)``; unflushed ones come out after the block). fd 1 belongs to the process:
    another thread writing to it meanwhile is silenced too, so the package runs only its MILP
    calls inside (the command line writes its progress and warnings to stderr).
    """
    with _FD1_LOCK:
        try:
            sys.stdout.flush()
        except (OSError, ValueError, AttributeError):  # a closed or absent sys.stdout
            pass
        _flush_c_stdio()
        try:
            saved = os.dup(1)
        except OSError:  # no usable fd 1: nothing to silence
            yield
            return
        try:
            null = os.open(os.devnull, os.O_WRONLY)
        except OSError:
            os.close(saved)
            yield
            return
        try:
            os.dup2(null, 1)
            os.close(null)
            yield
        finally:
            _flush_c_stdio()  # what printf buffered goes to the null device, not after it
            os.dup2(saved, 1)
            os.close(saved)


def milp(*args, **kwargs):
    """:func:`scipy.optimize.milp`, with what HiGHS prints on fd 1 discarded.

    Parameters
    ----------
    *args, **kwargs
        As :func:`scipy.optimize.milp` takes them.

    Returns
    -------
    scipy.optimize.OptimizeResult
    """
    from scipy.optimize import milp as _milp

    with c_stdout_silenced():
        return _milp(*args, **kwargs)
