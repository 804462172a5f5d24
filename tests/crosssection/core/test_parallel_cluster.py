"""A Dask scale-out that cannot go on fails in one line: a service at the ``--scheduler``
address that is not Dask's, a cluster lost in the middle of a batch or an ensemble, a cluster
without workers.

The clusters are in-process (``processes=False``) with a real TCP scheduler on loopback; the
services that are not Dask's are plain sockets.
"""
from __future__ import annotations

import logging
import socket
import threading
import time

import numpy as np
import pandas as pd
import pytest

from crosssection import batch as B
from crosssection.cli import main as crosssection_main
from crosssection.core import parallel
from crosssection.core.errors import ParameterError
from crosssection.core.parallel import ClusterLostError, get_executor, quiet_loggers

distributed = pytest.importorskip("distributed")


@pytest.fixture
def service():
    """Start a TCP service on loopback that greets (``banner``) or stays silent (None):
    yields a function of the banner that returns its address."""
    servers = []

    def start(banner: bytes | None) -> str:
        srv = socket.socket()
        srv.bind(("127.0.0.1", 0))
        srv.listen()
        srv.settimeout(0.2)
        stop = threading.Event()
        conns = []

        def serve():
            while not stop.is_set():
                try:
                    conn, _ = srv.accept()
                except OSError:
                    continue
                conns.append(conn)
                if banner is not None:
                    conn.sendall(banner)

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        servers.append((srv, stop, thread, conns))
        return f"tcp://127.0.0.1:{srv.getsockname()[1]}"

    yield start
    for srv, stop, thread, conns in servers:
        stop.set()
        thread.join(2)
        for c in conns:
            c.close()
        srv.close()


@pytest.fixture
def short_timeout(monkeypatch):
    monkeypatch.setattr(parallel, "SCHEDULER_TIMEOUT_S", 1)
    return 1


def _cluster(n_workers=1):
    return distributed.LocalCluster(n_workers=n_workers, threads_per_worker=2, processes=False,
                                    protocol="tcp://", host="127.0.0.1", dashboard_address=None)


# ------------------------------------------------------------- not a Dask scheduler


@pytest.mark.parametrize("banner", [None, b"SSH-2.0-OpenSSH_9.6\r\n"], ids=["silent", "greets"])
def test_a_service_that_is_not_dask_is_refused_in_time(service, short_timeout, banner):
    address = service(banner)
    t0 = time.monotonic()
    with pytest.raises(ParameterError) as err:
        with get_executor(scheduler=address):
            pass
    # the handshake is bounded too: the limit and its one-second margin, not forever
    assert time.monotonic() - t0 < short_timeout + 4
    assert err.value.path == f"--scheduler {address}"
    assert err.value.cause.startswith(f"no Dask scheduler answered within {short_timeout} s (")


def test_the_cause_of_an_unreachable_address_is_named(monkeypatch):
    seen = {}

    def refused(address, timeout):
        seen.update(address=address, timeout=timeout)
        raise OSError("Timed out trying to connect") from ConnectionRefusedError(
            111, "Connection refused")

    monkeypatch.setattr(parallel, "_probe_scheduler", refused)
    with pytest.raises(ParameterError) as err:
        with get_executor(scheduler="tcp://127.0.0.1:9"):
            pass
    assert seen == {"address": "tcp://127.0.0.1:9", "timeout": parallel.SCHEDULER_TIMEOUT_S}
    assert err.value.one_line() == ("--scheduler tcp://127.0.0.1:9: no Dask scheduler answered "
                                    f"within {parallel.SCHEDULER_TIMEOUT_S} s "
                                    "(Connection refused)")
    assert 0 < parallel.SCHEDULER_TIMEOUT_S <= 15


def test_batch_at_a_greeting_service_is_one_line_and_writes_nothing(tmp_path, capsys, service,
                                                                     short_timeout):
    from PIL import Image

    inp, out = tmp_path / "in", tmp_path / "out"
    inp.mkdir()
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(inp / "a.png")
    address = service(b"SSH-2.0-OpenSSH_9.6\r\n")
    status = crosssection_main(["batch", str(inp), "--out", str(out), "--scheduler", address,
                                "--quiet"])
    err = capsys.readouterr().err.splitlines()
    assert status == 2
    assert err == [f"error: --scheduler {address}: no Dask scheduler answered within 1 s "
                   "(what answered there does not speak Dask's protocol)"]
    assert not out.exists()


def test_quench_at_a_silent_service_is_one_line_and_writes_nothing(tmp_path, capsys, service,
                                                                   short_timeout):
    from simulate.cli import main as simulate_main

    address = service(None)
    out = tmp_path / "q"
    status = simulate_main(["quench", "--n-configs", "2", "--segments", "40", "--no-progress",
                            "--scheduler", address, "--out", str(out)])
    err = capsys.readouterr().err.splitlines()
    assert status == 2
    assert len(err) == 1 and err[0].startswith(f"error: --scheduler {address}: no Dask "
                                               "scheduler answered within 1 s (")
    assert not out.exists()


# ------------------------------------------------------------------ a lost cluster


def _close_when(cluster, ready, after=0.0, timeout=30):
    """Close ``cluster`` from a thread ``after`` seconds once ``ready()`` holds."""
    def run():
        deadline = time.monotonic() + timeout
        while not ready() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(after)
        cluster.close()

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


def _quick_or_slow(task):
    """Stand-in image task: images named slow* outlast the cluster, the others are quick."""
    if "slow" in task.rel:
        time.sleep(3)
    return B._row(task, "ok", {"n_junctions": 1})


def test_a_cluster_lost_mid_batch_leaves_its_images_for_the_rerun(tmp_path, capfd):
    from PIL import Image

    inp, out = tmp_path / "in", tmp_path / "out"
    inp.mkdir()
    for name in ["a", "b", "slow1", "slow2"]:
        Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(inp / f"{name}.png")
    cl = _cluster()
    # the quick images are done well within a second of the start, the slow ones are not
    closer = _close_when(cl, lambda: (out / "batch.json").exists(), after=1.5)
    try:
        with pytest.raises(ClusterLostError, match="cluster was lost"):
            B.run_batch(inp, out, scheduler=cl.scheduler_address, progress=False,
                        task_fn=_quick_or_slow)
    finally:
        closer.join(30)
        cl.close()
    index = pd.read_csv(out / "index.csv")
    # the slow images were neither done nor failed: pending, a re-run does them
    assert list(index["image"]) == ["a.png", "b.png", "slow1.png", "slow2.png"]
    assert list(index["status"]) == ["ok", "ok", "pending", "pending"]
    assert pd.read_csv(out / "failures.csv").empty
    err = capfd.readouterr().err
    assert "Traceback" not in err and "ERROR" not in err


def _sleepy_config(config_id, seed, params, out):
    """Stand-in configuration that outlasts the cluster."""
    time.sleep(3)
    return config_id


def test_a_cluster_lost_mid_quench_records_nothing(tmp_path, capfd):
    from simulate.ensemble import run_ensemble

    out = tmp_path / "ens"
    cl = _cluster()
    closer = _close_when(cl, lambda: (out / "params.json").exists())
    try:
        with pytest.raises(ClusterLostError, match="cluster was lost"):
            run_ensemble({"command": "quench", "n_configs": 3, "seed": 1}, out,
                         scheduler=cl.scheduler_address, task=_sleepy_config, progress=False)
    finally:
        closer.join(30)
        cl.close()
    # the configurations the cluster had are neither failures nor results
    assert sorted(p.name for p in out.iterdir()) == ["params.json"]
    err = capfd.readouterr().err
    assert "Traceback" not in err and "ERROR" not in err


def test_a_lost_task_is_not_a_cancelled_one_but_a_closed_client_s_are(tmp_path):
    cl = _cluster()
    try:
        with get_executor(scheduler=cl.scheduler_address) as ex:
            fut = ex.submit(time.sleep, 3)
            cl.close()
            with pytest.raises(ClusterLostError):
                fut.result(timeout=20)
            with pytest.raises(ClusterLostError):
                ex.submit(time.sleep, 0)
    finally:
        cl.close()


@pytest.mark.parametrize("address, why", [
    ("tcp://127.0.0.1:8799x", "its port is not a whole number from 1 to 65535"),
    ("tcp://127.0.0.1:99999", "its port is not a whole number from 1 to 65535"),
    ("tcp://:8786", "it names no host")])
def test_a_malformed_scheduler_address_is_refused_at_once(address, why):
    """It waited out the whole timeout, then gave Dask's "invalid literal for int()"."""
    t0 = time.monotonic()
    with pytest.raises(ParameterError) as err:
        with get_executor(scheduler=address):
            pass
    assert time.monotonic() - t0 < 2.0
    assert err.value.one_line() == (f"--scheduler {address}: not a scheduler address: {why} "
                                    "(expected tcp://HOST:PORT)")


@pytest.mark.parametrize("address, why", [("notanaddress", "missing port number"),
                                          ("http://127.0.0.1:8799", "unknown address scheme"),
                                          ("", "it is empty"), ("  ", "it is empty")])
def test_an_address_dask_cannot_parse_or_an_empty_one_is_not_a_scheduler_address(address,
                                                                                 why):
    """Dask's own parse of the address failed at once, but was reported as no scheduler
    answering within the timeout; an empty address ran the batch here, silently."""
    with pytest.raises(ParameterError) as err:
        with get_executor(scheduler=address):
            pass
    line = err.value.one_line()
    assert "not a scheduler address: " in line and why in line
    assert "answered" not in line and line.endswith(")")


# ---------------------------------------------------------------- no worker


def test_a_cluster_without_workers_is_named_and_an_interrupt_says_nothing_ran(short_timeout):
    cl = _cluster(n_workers=0)
    told = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with get_executor(scheduler=cl.scheduler_address, on_wait=told.append) as ex:
                fut = ex.submit(time.sleep, 0)
                deadline = time.monotonic() + 10
                while not told and time.monotonic() < deadline:
                    time.sleep(0.1)
                assert not fut.done()  # still waiting for a worker
                raise KeyboardInterrupt
    finally:
        cl.close()
    where = f"--scheduler {cl.scheduler_address}"
    assert told == [f"{where}: no worker has joined; waiting",
                    f"{where}: no worker had joined: nothing ran"]


def test_a_cluster_whose_every_worker_left_is_named(short_timeout):
    """The batch waited for a worker without a word once its only worker died."""
    cl = _cluster(n_workers=1)
    told = []
    try:
        with get_executor(scheduler=cl.scheduler_address, on_wait=told.append) as ex:
            assert ex.submit(sum, [1, 2]).result(timeout=20) == 3
            ex.submit(time.sleep, 0.5)
            time.sleep(1.0)  # the watch has seen the worker
            cl.scale(0)
            ex.submit(sum, [3, 4])  # a task for a worker that is no more
            deadline = time.monotonic() + 15
            while not told and time.monotonic() < deadline:
                time.sleep(0.1)
    finally:
        cl.close()
    where = f"--scheduler {cl.scheduler_address}"
    assert told == [f"{where}: every worker has left; waiting for one (interrupt to stop: a "
                    "re-run resumes)"]


def test_an_idle_cluster_retiring_its_workers_gets_no_notice(short_timeout):
    cl = _cluster(n_workers=1)
    told = []
    try:
        with get_executor(scheduler=cl.scheduler_address, on_wait=told.append) as ex:
            assert ex.submit(sum, [1, 2]).result(timeout=20) == 3
            time.sleep(1.0)
            cl.scale(0)  # nothing waits: an adaptive cluster may do this
            time.sleep(3.0)
    finally:
        cl.close()
    assert told == []


def test_a_cluster_with_workers_gets_no_waiting_notice(short_timeout):
    cl = _cluster(n_workers=1)
    told = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with get_executor(scheduler=cl.scheduler_address, on_wait=told.append) as ex:
                assert ex.submit(sum, [1, 2]).result(timeout=10) == 3
                time.sleep(short_timeout + 1)
                raise KeyboardInterrupt
    finally:
        cl.close()
    assert told == []


def test_the_default_notice_is_a_cluster_warning(short_timeout):
    cl = _cluster(n_workers=0)
    try:
        with pytest.warns(parallel.ClusterWarning, match="no worker has joined; waiting"):
            with get_executor(scheduler=cl.scheduler_address):
                time.sleep(short_timeout + 1.5)
    finally:
        cl.close()


# ------------------------------------------------------------------- loggers


def test_quiet_loggers_silence_dask_below_critical_and_restore_levels():
    child = logging.getLogger("distributed.client")
    child.setLevel(logging.WARNING)  # Dask's configuration sets levels of its own
    other = logging.getLogger("crosssection")
    before = (child.level, logging.getLogger("tornado").level, other.level)
    with quiet_loggers():
        assert not child.isEnabledFor(logging.ERROR)
        assert child.isEnabledFor(logging.CRITICAL)
        assert not logging.getLogger("tornado.application").isEnabledFor(logging.ERROR)
        assert other.level == before[2]
    assert (child.level, logging.getLogger("tornado").level, other.level) == before


def test_batch_tells_the_wait_for_a_worker_as_it_happens(tmp_path, capsys, short_timeout,
                                                         monkeypatch):
    import signal

    from PIL import Image

    inp, out = tmp_path / "in", tmp_path / "out"
    inp.mkdir()
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(inp / "a.png")
    cl = _cluster(n_workers=0)
    main = threading.main_thread().ident
    # the user interrupts once told of the wait: on a loaded machine a fixed delay could
    # fall while Dask's client starts, which takes the interrupt for its own
    waiting, done = threading.Event(), threading.Event()
    watch = parallel._watch_workers

    def told_watch(client, stop, joined, on_none, *rest):
        def told():
            on_none()
            waiting.set()
        return watch(client, stop, joined, told, *rest)

    monkeypatch.setattr(parallel, "_watch_workers", told_watch)

    def interrupt():
        waiting.wait(60)  # told, or the batch would wait for ever: interrupted either way
        if not done.wait(0.5):
            signal.pthread_kill(main, signal.SIGINT)

    # Python's own SIGINT handler, whatever an earlier test of this process left: the command
    # line keeps an inherited SIG_IGN (a run under nohup), and the interrupt would be lost
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    interrupter = threading.Thread(target=interrupt, daemon=True)
    interrupter.start()
    try:
        status = crosssection_main(["batch", str(inp), "--out", str(out), "--scheduler",
                                    cl.scheduler_address, "--quiet"])
    finally:
        done.set()
        signal.signal(signal.SIGINT, previous)
        cl.close()
    where = f"--scheduler {cl.scheduler_address}"
    assert status == 130
    assert capsys.readouterr().err.splitlines() == [
        f"warning: {where}: no worker has joined; waiting",
        f"warning: {where}: no worker had joined: nothing ran",
        "error: interrupted (re-run the same command to resume)"]
    assert set(pd.read_csv(out / "index.csv")["status"]) == {"pending"}
