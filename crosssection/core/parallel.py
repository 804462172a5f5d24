"""One code path for parallelism: a ``concurrent.futures`` executor.

Local processes by default; a Dask distributed cluster when a scheduler address is given
(``Client.get_executor()``). Batches and simulation ensembles both use :func:`get_executor`;
:func:`compiling_in_turn` keeps a pool's workers from compiling the same numba kernels at once.
"""
from __future__ import annotations

import os
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np


class _InlineExecutor(Executor):
    """Runs tasks in the calling process (``workers=1``): simplest to debug, no pickling."""

    def submit(self, fn, /, *args, **kwargs):
        from concurrent.futures import Future

        fut = Future()
        try:
            fut.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - forwarded to the caller through the future
            fut.set_exception(exc)
        return fut


def _die_with_parent(parent_pid: int) -> None:
    """Stop this worker when the process that started it dies (kill -9 included).

    Linux delivers SIGTERM to the worker at its parent's death (``prctl(PR_SET_PDEATHSIG)``);
    a daemon thread also polls the parent's pid every second for platforms without it. Either
    way no worker goes on with queued work after a killed batch or quench: the re-run resumes
    from what was written.
    """
    import signal
    import threading
    import time

    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass

    def watch():
        while True:
            time.sleep(1.0)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _init_worker(parent_pid: int):
    """Worker-process initializer: one compute thread per worker, and die with the parent.

    Each worker is one core's worth of work; letting OpenCV or numba start their own thread
    pools in every worker would oversubscribe the cores (2 workers x 2 threads on 2 cores)
    and make the speedup depend on the libraries' defaults.
    """
    _die_with_parent(parent_pid)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                "NUMBA_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    try:
        import cv2

        cv2.setNumThreads(1)
    except Exception:  # noqa: BLE001 - optional
        pass


@contextmanager
def get_executor(workers: int | None = 1, scheduler: str | None = None):
    """Yield a ``concurrent.futures.Executor``.

    Parameters
    ----------
    workers : int, optional
        Number of local worker processes; 1 runs inline, ``None`` uses ``os.cpu_count()``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``); when given, tasks go to
        that cluster through ``Client.get_executor()`` and ``workers`` is ignored.

    Yields
    ------
    concurrent.futures.Executor
    """
    if scheduler:
        from distributed import Client

        try:
            client = Client(scheduler)
        except (ValueError, OSError, TimeoutError) as exc:
            from crosssection.core.errors import ParameterError

            raise ParameterError(f"no Dask scheduler reached at {scheduler!r}: "
                                 f"{' '.join(str(exc).split())}", "--scheduler") from None
        try:
            yield client.get_executor(pure=False)
        finally:
            client.close()
        return
    if workers is None:
        workers = os.cpu_count() or 1
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        from crosssection.core.errors import ParameterError

        raise ParameterError(f"workers must be a whole number >= 1, got {workers!r}")
    if workers == 1:
        yield _InlineExecutor()
        return
    import multiprocessing as mp

    # 'spawn' keeps workers free of the parent's threads (numba, BLAS) and matches Dask.
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                             initializer=_init_worker, initargs=(os.getpid(),)) as ex:
        yield ex


@contextmanager
def compiling_in_turn(lock_path: str | None):
    """Let one worker process at a time compile numba kernels, the others load them.

    numba caches compiled kernels on disk, but workers that start on an empty cache would
    each compile every kernel, all at the same time. Inside this block, a process that has to
    compile (a cache miss) first takes an exclusive lock on ``lock_path`` and keeps it to the
    end of the block. Another process that meets a kernel to compile meanwhile waits there,
    then compiles that one kernel and loads from the cache the others the first compiled. A
    process that finds every kernel in the cache never takes the lock: a warm cache costs
    nothing.

    Parameters
    ----------
    lock_path : str or None
        File or folder the pool's workers share, locked with ``flock`` (which the system
        releases when a process dies). None, or a platform without ``flock``, leaves the
        block as it is.

    Yields
    ------
    None

    Notes
    -----
    For worker processes that run one task at a time: the wait happens inside numba's
    compiler, whose lock is the process's, so threads of one process must not share it.
    """
    if lock_path is None:
        yield
        return
    try:
        import fcntl
    except ImportError:  # no flock (Windows): each worker compiles what it needs
        yield
        return
    from numba.core import event

    taken = []  # the locked descriptor, or None when the lock could not be had

    class _TakeTurn(event.Listener):
        def on_start(self, ev):
            if taken:
                return
            try:
                fd = os.open(lock_path, os.O_RDONLY)
            except OSError:  # gone: compiling twice beats failing the task
                taken.append(None)
                return
            taken.append(fd)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX)
            except OSError:  # a file system without locks: the same
                pass

        def on_end(self, ev):
            pass

    try:
        with event.install_listener("numba:compile", _TakeTurn()):
            yield
    finally:
        if taken and taken[0] is not None:
            os.close(taken[0])  # releases the lock


def spawn_seeds(seed: int | None, n: int) -> list[int]:
    """``n`` independent integer seeds derived from ``seed`` by ``SeedSequence.spawn``.

    Task ``i`` always gets the same seed, whatever the number of workers or the order of
    completion, so results do not depend on the executor.
    """
    children = np.random.SeedSequence(seed).spawn(n)
    return [int(c.generate_state(1, dtype=np.uint32)[0]) for c in children]


__all__ = ["get_executor", "compiling_in_turn", "spawn_seeds", "ThreadPoolExecutor"]
