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


#: Seconds a terminated worker gets to exit before it is killed, and the pool's manager thread
#: to notice it
STOP_GRACE_S = 3.0


def stop_pool(ex: ProcessPoolExecutor, known=(), grace: float = STOP_GRACE_S) -> None:
    """Stop a process pool at once: cancel its queued tasks and terminate its workers.

    ``shutdown(wait=True)`` (what leaving a ``with`` block does) lets every task in flight
    finish, and the interpreter's exit waits for the pool's manager thread as well: an
    interrupted batch would go on for as long as its running tasks take. Here the queued
    tasks are cancelled, the workers get SIGTERM (then SIGKILL after ``grace`` seconds), and
    the manager thread, which sees them die, is given ``grace`` seconds to finish.

    Parameters
    ----------
    ex : ProcessPoolExecutor
    known : iterable of multiprocessing.Process
        Child processes that existed before the pool: left alone when the pool does not
        expose its workers (``ex._processes``, the only handle CPython offers), in which case
        every other live child started through ``multiprocessing`` is taken for a worker.
    grace : float
        Seconds to wait for the workers to exit, and again for the manager thread.
    """
    import multiprocessing as mp
    import time
    from multiprocessing.connection import wait as ready

    procs = getattr(ex, "_processes", None)
    if isinstance(procs, dict):
        procs = list(procs.values())
    else:
        known = set(known)
        procs = [p for p in mp.active_children() if p not in known]
    manager = getattr(ex, "_executor_manager_thread", None)
    try:
        ex.shutdown(wait=False, cancel_futures=True)
    finally:
        alive = {}
        for p in procs:
            try:
                p.terminate()
                alive[p.sentinel] = p
            except (OSError, ValueError, AttributeError):  # gone, closed or never started
                pass
        # a process's sentinel is ready once it has exited, whoever reaps it (the pool's
        # manager thread joins its workers too)
        deadline = time.monotonic() + grace
        while alive and time.monotonic() < deadline:
            for s in ready(list(alive), max(0.0, deadline - time.monotonic())):
                alive.pop(s, None)
        for p in alive.values():
            try:
                p.kill()
            except (OSError, ValueError, AttributeError):
                pass
        for p in procs:
            try:
                p.join(1.0)
            except (OSError, ValueError, AttributeError, AssertionError):
                pass
        if manager is not None and hasattr(manager, "join"):
            manager.join(grace)


#: Seconds to wait for a Dask scheduler's answer before the address is refused (Dask's own
#: default, 30 s, keeps a mistyped address waiting; a reachable scheduler, even through a
#: tunnel, answers within a second or two).
SCHEDULER_TIMEOUT_S = 10


@contextmanager
def get_executor(workers: int | None = 1, scheduler: str | None = None):
    """Yield a ``concurrent.futures.Executor``.

    Parameters
    ----------
    workers : int, optional
        Number of local worker processes; 1 runs inline, ``None`` uses ``os.cpu_count()``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``); when given, tasks go to
        that cluster through ``Client.get_executor()`` and ``workers`` is ignored. One that
        does not answer within :data:`SCHEDULER_TIMEOUT_S` is a ``ParameterError``.

    Yields
    ------
    concurrent.futures.Executor

    Notes
    -----
    Leaving the block normally waits for the submitted tasks. Leaving it by an exception (an
    interrupt included) does not: local workers are terminated and queued tasks cancelled
    (:func:`stop_pool`), a cluster's queued tasks are cancelled, so that an interrupted
    command exits at once and its re-run resumes from what was written.
    """
    if scheduler:
        from distributed import Client

        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT_S)
        except (ValueError, OSError, TimeoutError) as exc:
            from crosssection.core.errors import ParameterError

            raise ParameterError(f"no Dask scheduler reached at {scheduler!r}: "
                                 f"{' '.join(str(exc).split())}", "--scheduler") from None
        try:
            yield client.get_executor(pure=False)
        finally:
            # closing the client releases its futures: on an interrupt the scheduler cancels
            # the tasks no client wants any more (a task already running in a worker thread
            # ends on its own)
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
    before = set(mp.active_children())
    ex = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                             initializer=_init_worker, initargs=(os.getpid(),))
    try:
        yield ex
    except BaseException:
        # an interrupt (SIGINT, or SIGTERM raised as one by the command line) or a failure:
        # waiting for the tasks in flight would take as long as they do, so they are stopped,
        # the re-run redoing them
        stop_pool(ex, known=before)
        raise
    ex.shutdown(wait=True)


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


__all__ = ["get_executor", "stop_pool", "compiling_in_turn", "spawn_seeds", "ThreadPoolExecutor"]
