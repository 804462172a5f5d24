"""One code path for parallelism: a ``concurrent.futures`` executor.

Local processes by default; a Dask distributed cluster when a scheduler address is given
(``Client.get_executor()``). Batches and simulation ensembles both use :func:`get_executor`;
:func:`compiling_in_turn` keeps a pool's workers from compiling the same numba kernels at once.
"""
from __future__ import annotations

import contextvars
import logging
import os
import threading
import time
import warnings
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

from crosssection.core.errors import FoldstatError, ParameterError


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
    # a worker's results carry its quality flags; a library's warning printed from it (a
    # glyph a font lacks, drawing a scan's name) reached the user's stderr as raw lines
    warnings.simplefilter("ignore")
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
#: tunnel, answers within a second or two); also how long a cluster may go without any worker
#: before a warning says that the command is waiting for one.
SCHEDULER_TIMEOUT_S = 10

#: Loggers of the Dask client's machinery, quieted below CRITICAL while a client runs: a lost
#: scheduler or an interrupt makes them print tracebacks of the client's event loop, which
#: the user is told in one line instead.
CLIENT_LOGGERS = ("distributed", "tornado", "asyncio")


class ClusterLostError(FoldstatError):
    """The Dask cluster went away (its scheduler stopped, or the connection to it broke)
    before every task was done: the tasks it had are neither results nor failures."""


class ClusterWarning(UserWarning):
    """The Dask cluster has no worker: the command waits for one."""


@contextmanager
def quiet_loggers(names=CLIENT_LOGGERS, level: int = logging.CRITICAL):
    """Raise the loggers ``names``, and every logger below them, to ``level`` in the block.

    Loggers below ``names`` are set one by one: Dask gives some of them levels of their own,
    which a parent's level would not override. Their levels are put back on leaving.

    Parameters
    ----------
    names : iterable of str
        Top-level logger names.
    level : int
        Least level let through.

    Yields
    ------
    None
    """
    names = tuple(names)
    chosen = [logging.getLogger(n) for n in names]
    chosen += [lg for key, lg in list(logging.Logger.manager.loggerDict.items())
               if isinstance(lg, logging.Logger) and key.split(".")[0] in names]
    saved = {lg: lg.level for lg in chosen}
    for lg in saved:
        lg.setLevel(max(level, lg.level))
    try:
        yield
    finally:
        for lg, old in saved.items():
            lg.setLevel(old)


def _probe_scheduler(address: str, timeout: float) -> None:
    """Return once a Dask scheduler has answered the handshake at ``address``, else raise.

    ``distributed.Client`` bounds the TCP connection by its ``timeout`` but not the handshake
    that follows: a service that accepts the connection and stays silent (a web server)
    keeps it waiting forever, and one that greets first (SSH) has its greeting read as a
    message length. Here the whole handshake has ``timeout`` seconds, in a thread of its own
    so that a running event loop (a notebook's) does not stand in the way.

    Parameters
    ----------
    address : str
        The scheduler's address (``tcp://host:port``, or another Dask scheme).
    timeout : float
        Seconds for the connection, and one more for the handshake.

    Raises
    ------
    TimeoutError
        The connection was made but nothing answered the handshake in time (``timeout``
        plus one second: Dask's own limit on the connection comes first).
    Exception
        Whatever the connection raised (``OSError``: unreachable; ``ValueError``: a
        malformed address; ``MemoryError`` and others: a reply that is not Dask's).
    """
    import asyncio

    from distributed.comm import connect
    from distributed.security import Security

    args = Security().get_connection_args("client")

    async def handshake():
        # Dask's own limit covers the connection (and its retries, which end in an OSError
        # naming the cause); a second later, the handshake is given up
        comm = await asyncio.wait_for(connect(address, timeout=timeout, **args), timeout + 1)
        await comm.close()

    outcome = []

    def probe():
        try:
            asyncio.run(handshake())
            outcome.append(None)
        except BaseException as exc:  # noqa: BLE001 - raised in the caller's thread
            outcome.append(exc)

    # a daemon thread: an interrupt of the caller neither waits for the probe nor for it at exit
    thread = threading.Thread(target=probe, name="scheduler-probe", daemon=True)
    thread.start()
    thread.join(timeout + 5)
    if not outcome:
        raise TimeoutError
    if outcome[0] is not None:
        raise outcome[0]


def _address_problem(address: str) -> str | None:
    """What is wrong with a ``tcp://`` or ``tls://`` scheduler address, or None (other
    schemes are left to Dask): a malformed one waited out the whole timeout before Dask's
    own words ("invalid literal for int()")."""
    from urllib.parse import urlsplit

    if not address.startswith(("tcp://", "tls://")):
        return None
    try:
        parts = urlsplit(address)
        port = parts.port
    except ValueError:
        return "its port is not a whole number from 1 to 65535 (expected tcp://HOST:PORT)"
    if not parts.hostname:
        return "it names no host (expected tcp://HOST:PORT)"
    if port is not None and not 1 <= port <= 65535:  # no port: Dask's default, or its words
        return "its port is not a whole number from 1 to 65535 (expected tcp://HOST:PORT)"
    return None


def _why_no_scheduler(exc: BaseException) -> str:
    """One line on why ``exc`` means no usable scheduler."""
    if type(exc) is TimeoutError:  # the probe's own limit (Dask's are OSErrors)
        return "the connection was accepted, but no Dask handshake came back"
    if isinstance(exc, OSError):
        # Dask's "timed out" wraps the cause (refused, unknown host) in connector reprs
        root = exc
        while isinstance(root.__cause__, OSError):
            root = root.__cause__
        if root is not exc and getattr(root, "strerror", None):
            return root.strerror
        return " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, ValueError):
        return " ".join(str(exc).split()) or "malformed address"
    return "what answered there does not speak Dask's protocol"


class _ClusterExecutor(Executor):
    """A Dask client's executor whose tasks end in :class:`ClusterLostError` when the cluster
    goes away.

    Dask cancels the futures of a client that loses its scheduler: a cancelled task would
    read as one the caller had cancelled, or (as an exception) as a failure of the task
    itself. Cancellations after :meth:`close` are the caller's and stay cancellations.
    """

    def __init__(self, client, where: str):
        self._client = client  # read for the cluster's size (crosssection.batch)
        self._inner = client.get_executor(pure=False)
        self._where = where
        self._closing = False
        self._pending = set()  # the outer futures not done: the watch says "waiting" only then

    @property
    def busy(self) -> bool:
        """Whether a task submitted here is not done yet."""
        return bool(self._pending)

    def lost(self) -> ClusterLostError:
        """The error of a task the cluster lost."""
        return ClusterLostError("the Dask cluster was lost (its scheduler stopped answering) "
                                "before every task was done; re-run the same command to "
                                "resume", self._where)

    def submit(self, fn, /, *args, **kwargs):
        from concurrent.futures import Future, InvalidStateError

        if self._client.status != "running":
            raise self.lost()
        inner = self._inner.submit(fn, *args, **kwargs)
        outer = Future()  # left pending until done, so that the caller may cancel it

        def forward(f):
            try:
                if f.cancelled():
                    if self._closing:
                        outer.cancel()
                    else:
                        outer.set_exception(self.lost())
                elif f.exception() is not None:
                    outer.set_exception(f.exception())
                else:
                    outer.set_result(f.result())
            except InvalidStateError:  # cancelled by the caller meanwhile
                pass

        def back(f):
            self._pending.discard(f)
            if f.cancelled():
                inner.cancel()

        self._pending.add(outer)
        outer.add_done_callback(back)
        inner.add_done_callback(forward)
        return outer

    def close(self) -> None:
        """Mark the cancellations to come as the caller's (the client is about to close)."""
        self._closing = True

    def shutdown(self, wait=True, *, cancel_futures=False):
        self._closing = True
        self._inner.shutdown(wait=wait)


def _watch_workers(client, stop, joined, on_wait, grace: float, on_lost=None,
                   busy=lambda: True) -> None:
    """Set ``joined`` once the cluster has a worker; call ``on_wait`` once if it has none
    after ``grace`` seconds, and ``on_lost`` once each time every worker has left for
    ``grace`` seconds after one had joined while ``busy()`` says tasks wait (they would wait
    without a word; an idle cluster may retire its workers). Returns when ``stop`` is set."""
    deadline = time.monotonic() + grace
    warned = False
    while not stop.is_set():
        if _has_workers(client, grace):
            joined.set()
            deadline, warned = time.monotonic() + grace, False
        elif joined.is_set() and not busy():
            deadline = time.monotonic() + grace
        elif not warned and time.monotonic() >= deadline and not stop.is_set():
            warned = True
            (on_lost if joined.is_set() and on_lost is not None else on_wait)()
        stop.wait(0.5)


def _has_workers(client, timeout: float) -> bool:
    """Whether the cluster has a worker; True when that cannot be learnt within ``timeout``
    seconds (a closing or lost client, whose tasks tell what became of them)."""
    try:
        return bool(client.nthreads(callback_timeout=timeout))
    except Exception:  # noqa: BLE001
        return True


def _warn(message: str) -> None:
    warnings.warn(message, ClusterWarning, stacklevel=2)


@contextmanager
def _cluster_executor(address: str, on_wait=None):
    """The executor of a Dask cluster (see :func:`get_executor`)."""
    import distributed  # its loggers are configured on import, before they are quieted

    where = f"--scheduler {address}"
    notify = _warn if on_wait is None else on_wait
    problem = _address_problem(address)
    if problem:
        raise ParameterError(f"not a scheduler address: {problem}", where)
    with quiet_loggers():
        try:
            _probe_scheduler(address, SCHEDULER_TIMEOUT_S)
            client = distributed.Client(address, timeout=SCHEDULER_TIMEOUT_S)
        except ValueError as exc:  # Dask's parse of the address: nothing was waited for
            raise ParameterError(f"not a scheduler address: {_why_no_scheduler(exc)} "
                                 "(expected tcp://HOST:PORT)", where) from None
        except Exception as exc:  # noqa: BLE001 - whatever answered is no usable scheduler
            raise ParameterError(f"no Dask scheduler answered within {SCHEDULER_TIMEOUT_S} s "
                                 f"({_why_no_scheduler(exc)})", where) from None
        ex = _ClusterExecutor(client, where)
        stop, joined = threading.Event(), threading.Event()
        watcher = threading.Thread(
            target=_watch_workers, name="cluster-workers", daemon=True,
            args=(client, stop, joined, lambda: notify(f"{where}: no worker has joined; "
                                                       "waiting"), SCHEDULER_TIMEOUT_S,
                  lambda: notify(f"{where}: every worker has left; waiting for one "
                                 "(interrupt to stop: a re-run resumes)"),
                  lambda: ex.busy))
        watcher.start()
        try:
            yield ex
        except KeyboardInterrupt:
            if not joined.is_set() and not _has_workers(client, 1.0):
                notify(f"{where}: no worker had joined: nothing ran")
            raise
        finally:
            stop.set()
            ex.close()
            # closing the client releases its futures: on an interrupt the scheduler cancels
            # the tasks no client wants (a task already running in a worker thread
            # ends on its own)
            try:
                client.close(timeout=SCHEDULER_TIMEOUT_S)
            except Exception:  # noqa: BLE001 - a lost scheduler: nothing left to release
                pass
            watcher.join(1.0)  # a daemon: one stuck on a lost scheduler is left behind


def capped_workers(workers: int | None, scheduler: str | None = None) -> tuple[int | None, str | None]:
    """Local worker processes capped at the machine's CPUs.

    Parameters
    ----------
    workers : int or None
        Workers asked for (``None``: one per CPU).
    scheduler : str, optional
        A Dask scheduler's address: its cluster sets the parallelism, nothing is capped.

    Returns
    -------
    workers : int or None
        ``min(workers, os.cpu_count())`` for local processes, else ``workers``.
    message : str or None
        One line for the command's ``warning:`` output when the count was lowered: each
        worker holds one task's memory (about 0.5 GB for a 2000 x 2000 scan or a compaction),
        and more processes than CPUs only share the same cores.
    """
    n_cpu = os.cpu_count() or 1
    if scheduler or workers is None or workers <= n_cpu:
        return workers, None
    return n_cpu, (f"--workers {workers}: this machine has {n_cpu} CPUs; {n_cpu} workers "
                   "are used")


@contextmanager
def get_executor(workers: int | None = 1, scheduler: str | None = None, *, on_wait=None):
    """Yield a ``concurrent.futures.Executor``.

    Parameters
    ----------
    workers : int, optional
        Number of local worker processes; 1 runs inline, ``None`` uses ``os.cpu_count()``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``); when given, tasks go to
        that cluster through ``Client.get_executor()`` and ``workers`` is ignored. One that
        does not answer within :data:`SCHEDULER_TIMEOUT_S` (unreachable, or a service that is
        not Dask's) is a ``ParameterError`` naming ``--scheduler ADDRESS``.
    on_wait : callable, optional
        Called with a one-line message (``"--scheduler ADDRESS: ..."``) when the cluster has
        had no worker for :data:`SCHEDULER_TIMEOUT_S` (the tasks wait for one), before any
        joined or after every one left, and when the block is interrupted before any worker
        joined (nothing ran). Default: a :class:`ClusterWarning`.

    Yields
    ------
    concurrent.futures.Executor
        On a cluster, the futures of tasks lost with it raise :class:`ClusterLostError`, and
        so does ``submit`` once it is lost.

    Notes
    -----
    Leaving the block normally waits for the submitted tasks. Leaving it by an exception (an
    interrupt included) does not: local workers are terminated and queued tasks cancelled
    (:func:`stop_pool`), a cluster's queued tasks are cancelled, so that an interrupted
    command exits at once and its re-run resumes from what was written. While a cluster's
    client runs, the loggers of Dask and its event loop (:data:`CLIENT_LOGGERS`) let only
    CRITICAL records through.
    """
    if scheduler is not None and not str(scheduler).strip():
        raise ParameterError("not a scheduler address: it is empty (expected tcp://HOST:PORT; "
                             "leave --scheduler out to run on this machine)",
                             f"--scheduler {scheduler!r}")
    if scheduler:
        with _cluster_executor(scheduler, on_wait) as ex:
            yield ex
        return
    if workers is None:
        workers = os.cpu_count() or 1
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
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


def in_background(fn, /, *args, **kwargs):
    """Start ``fn(*args, **kwargs)`` on a thread; return a callable that waits for it.

    For work that releases the interpreter (OpenCV's calls, compiled kernels declared
    ``nogil``) run beside other such work of the same analysis: the two share the
    machine's cores instead of taking turns. ``fn`` runs in a copy of the caller's context
    (numpy's error state with it). The warnings filters are the process's: a caller that
    sets them waits for ``fn`` (:func:`wait_all`) before it restores them, also when it
    fails.

    Returns
    -------
    callable
        Called with no argument: waits for ``fn`` and returns its result, or raises what it
        raised.
    """
    out = {}
    context = contextvars.copy_context()

    def work():
        try:
            out["value"] = context.run(fn, *args, **kwargs)
        except BaseException as exc:  # handed to the caller, which raises it
            out["error"] = exc

    thread = threading.Thread(target=work, name=f"foldstat-{getattr(fn, '__name__', 'work')}",
                              daemon=True)
    thread.start()

    def result():
        thread.join()
        if "error" in out:
            raise out["error"]
        return out["value"]

    return result


def wait_all(*waiting) -> None:
    """Wait for every :func:`in_background` step given (None and finished values are
    skipped), dropping what they return or raise: on a failure's way out, so that none of
    them runs on, or warns, after its caller has given up."""
    for w in waiting:
        if callable(w):
            try:
                w()
            except BaseException:  # the caller's own failure is the one raised
                pass


def spawn_seeds(seed: int | None, n: int) -> list[int]:
    """``n`` independent integer seeds derived from ``seed`` by ``SeedSequence.spawn``.

    Task ``i`` always gets the same seed, whatever the number of workers or the order of
    completion, so results do not depend on the executor.
    """
    children = np.random.SeedSequence(seed).spawn(n)
    return [int(c.generate_state(1, dtype=np.uint32)[0]) for c in children]


__all__ = ["get_executor", "ClusterLostError", "ClusterWarning", "quiet_loggers",
           "SCHEDULER_TIMEOUT_S", "stop_pool", "compiling_in_turn", "spawn_seeds", "in_background",
           "wait_all",
           "ThreadPoolExecutor"]
