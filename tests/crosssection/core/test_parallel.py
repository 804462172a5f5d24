"""The shared executor: local processes, inline, and a Dask cluster give the same results.

A Dask ``LocalCluster`` on loopback runs a batch through ``--scheduler`` and its index must
equal the local run's, number for number.
"""
from __future__ import annotations

import os

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ParameterError

from crosssection import batch as B
from crosssection.core.parallel import get_executor, in_background, spawn_seeds, wait_all

from crosssection.testing import index_numbers as numbers
from crosssection.testing import make_scan_tree as make_tree


def _draw(seed: int) -> float:
    """A task whose result depends only on its seed (module level: picklable)."""
    return float(np.random.default_rng(seed).standard_normal(1000).sum())


def _pid(_):
    return os.getpid()


def _warns(_):
    import warnings

    warnings.warn("Glyph 25195 missing from font(s) DejaVu Sans.", UserWarning)
    return 1


def test_a_worker_prints_no_library_warning(capfd):
    # a worker process's warnings reached the user's stderr as raw lines (a glyph a font
    # lacks, drawing a scan named in CJK characters, with --workers 2)
    capfd.readouterr()
    with get_executor(2) as ex:
        assert list(ex.map(_warns, range(2))) == [1, 1]
    assert "Glyph" not in capfd.readouterr().err


def test_in_background_returns_the_result_or_raises_the_error():
    import threading

    names = []

    def work(x, *, y):
        names.append(threading.current_thread().name)
        return x + y

    assert in_background(work, 2, y=3)() == 5
    assert names and names[0] != threading.main_thread().name

    def fails():
        raise ValueError("bad input")

    wait = in_background(fails)
    with pytest.raises(ValueError, match="bad input"):
        wait()
    wait_all(wait, None, 3)  # its error dropped, the rest skipped

    # the caller's numpy error state goes with the work
    with np.errstate(divide="raise"):
        divide = in_background(lambda: np.float64(1.0) / np.float64(0.0))
    with pytest.raises(FloatingPointError):
        divide()


def test_spawn_seeds_are_stable_and_independent():
    a = spawn_seeds(42, 50)
    assert a == spawn_seeds(42, 50) and len(set(a)) == 50
    assert a[:10] == spawn_seeds(42, 10)          # task i keeps its seed when n grows
    assert a != spawn_seeds(43, 50)
    assert all(isinstance(s, int) and 0 <= s < 2**32 for s in a)


def test_process_pool_matches_inline_and_uses_other_processes():
    seeds = spawn_seeds(7, 6)
    with get_executor(1) as ex:
        inline = [ex.submit(_draw, s).result() for s in seeds]
        assert ex.submit(_pid, 0).result() == os.getpid()
    with get_executor(2) as ex:
        pooled = list(ex.map(_draw, seeds))
        pids = set(ex.map(_pid, range(6)))
    assert pooled == inline
    assert os.getpid() not in pids
    with pytest.raises(ParameterError):
        with get_executor(0):
            pass


def _mark_and_sleep(marks):
    """A long task that first leaves the id of its worker process in the folder ``marks``."""
    import time
    from pathlib import Path

    Path(marks, str(os.getpid())).touch()
    time.sleep(60)


def _wait_for(check, seconds=60.0):
    import time

    end = time.monotonic() + seconds
    while not check():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.02)


@pytest.mark.parametrize("handle", [True, False])
def test_an_interrupt_stops_the_pool_at_once(tmp_path, handle):
    """Leaving the block by an interrupt terminates the workers and ends every task, without
    waiting for the running ones (a minute each here); ``handle=False``: a pool that does not
    expose its worker processes (a private attribute of CPython's)."""
    import time

    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with get_executor(2) as ex:
            futures = [ex.submit(_mark_and_sleep, str(tmp_path)) for _ in range(4)]
            _wait_for(lambda: len(list(tmp_path.iterdir())) == 2)
            if not handle:
                del ex._processes
            raise KeyboardInterrupt
    assert time.monotonic() - t0 < 20  # a hang check: the tasks would take 2 minutes
    assert all(f.done() for f in futures)
    for pid in (int(p.name) for p in tmp_path.iterdir()):
        with pytest.raises(ProcessLookupError):  # terminated and reaped
            os.kill(pid, 0)


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    # in-process workers (threads) but a real TCP scheduler on loopback
    cl = distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  protocol="tcp://", host="127.0.0.1", dashboard_address=None)
    try:
        yield cl
    finally:
        cl.close()


def test_dask_executor_matches_inline(cluster):
    seeds = spawn_seeds(3, 5)
    with get_executor(scheduler=cluster.scheduler_address) as ex:
        got = [f.result() for f in [ex.submit(_draw, s) for s in seeds]]
    assert got == [_draw(s) for s in seeds]


def test_an_interrupt_cancels_the_tasks_queued_on_a_cluster(cluster):
    import time

    with pytest.raises(KeyboardInterrupt):
        with get_executor(scheduler=cluster.scheduler_address) as ex:
            futures = [ex.submit(time.sleep, 0.5) for _ in range(8)]  # 2 threads: 2 s of work
            raise KeyboardInterrupt
    _wait_for(lambda: all(f.done() for f in futures), 10)
    assert sum(f.cancelled() for f in futures) >= 6


# the in-process cluster runs two tasks on two threads of this process: the flags of these
# scans stay in their summaries (no warning reaches the test, which the suite would fail)
@pytest.mark.parametrize("seed", [4, 9])
def test_batch_on_dask_equals_local_run(tmp_path, cluster, seed):
    inp = tmp_path / "in"
    expect = make_tree(inp, seed=seed)
    local = B.run_batch(inp, tmp_path / "local", workers=1, seed=seed, progress=False)
    dask = B.run_batch(inp, tmp_path / "dask", scheduler=cluster.scheduler_address, seed=seed,
                       progress=False)
    a = pd.read_csv(tmp_path / "local" / "index.csv")
    b = pd.read_csv(tmp_path / "dask" / "index.csv")
    assert (a["status"] == "ok").sum() == len(expect["ok"])
    pd.testing.assert_frame_equal(numbers(a), numbers(b))
    assert list(a["status"]) == list(b["status"]) and list(a["seed"]) == list(b["seed"])
    assert list(a["reason"].fillna("")) == list(b["reason"].fillna(""))
    assert len(local) == len(dask)
    for out in a["output"][a["status"] == "ok"]:
        for t in ("junctions", "stacks", "branches", "voids"):
            assert ((tmp_path / "local" / out / f"{t}.csv").read_text()
                    == (tmp_path / "dask" / out / f"{t}.csv").read_text())


def _crashing_task(task):
    """Stand-in task: the worker process dies on images named crash*, others succeed."""
    import time

    if "crash" in task.rel:
        time.sleep(0.05)
        os._exit(3)
    time.sleep(0.2)  # innocent images are still in flight when a worker dies
    return B._row(task, "ok", {"n_junctions": len(task.rel)})


def test_dead_worker_is_replaced_and_its_image_recorded(tmp_path):
    from PIL import Image

    inp = tmp_path / "in"
    inp.mkdir()
    for name in ["a0", "a1", "crash", "a2", "a3", "crash2", "a4"]:
        Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(inp / f"{name}.png")
    idx = B.run_batch(inp, tmp_path / "out", workers=2, progress=False, task_fn=_crashing_task)
    st = dict(zip(idx["image"], idx["status"]))
    assert st.pop("crash.png") == "failed" and st.pop("crash2.png") == "failed"
    assert set(st.values()) == {"ok"} and len(st) == 5      # no innocent image blamed
    assert list(idx["n_junctions"].dropna()) == [len(f"a{i}.png") for i in range(5)]
    reason = idx.set_index("image").loc["crash.png", "reason"]
    assert "worker process died" in reason
    fails = pd.read_csv(tmp_path / "out" / "failures.csv")
    assert list(fails["image"]) == ["crash.png", "crash2.png"]


#: the module of test_one_worker_compiles_and_the_other_loads: three numba kernels cached
#: beside it, and the two workers (in a module of their own, which spawned processes import)
TURN_KERNELS = '''
import json
import time

from numba import njit

from crosssection.core.parallel import compiling_in_turn


@njit(cache=True)
def first(x):
    return x + 1


@njit(cache=True)
def shared(x):
    return x * 2


@njit(cache=True)
def own(x):
    return x - 3


def _misses_and_hits(kernel):
    return sum(kernel.stats.cache_misses.values()), sum(kernel.stats.cache_hits.values())


def compiles_first(lock, holding, out):
    with compiling_in_turn(lock):
        first(1)              # a cache miss: the lock is taken and kept to the block's end
        holding.set()
        time.sleep(1.0)       # the other worker meets its own kernel meanwhile
        shared(1)
    with open(out, "w") as fh:
        json.dump(_misses_and_hits(shared), fh)


def comes_second(lock, holding, out):
    holding.wait(60)
    with compiling_in_turn(lock):
        own(1)                # a cache miss: waits until the first worker's block ends
        shared(1)             # compiled by the first worker: loaded from the cache
    with open(out, "w") as fh:
        json.dump(_misses_and_hits(shared), fh)
'''


def test_one_worker_compiles_and_the_other_loads(tmp_path, monkeypatch):
    import importlib
    import json
    import multiprocessing as mp
    import sys

    (tmp_path / "turn_kernels.py").write_text(TURN_KERNELS)
    monkeypatch.syspath_prepend(str(tmp_path))  # the spawned workers import it too
    monkeypatch.delitem(sys.modules, "turn_kernels", raising=False)
    kernels = importlib.import_module("turn_kernels")
    ctx = mp.get_context("spawn")
    holding = ctx.Event()
    outs = [tmp_path / "first.json", tmp_path / "second.json"]
    procs = [ctx.Process(target=kernels.compiles_first, args=(str(tmp_path), holding, outs[0])),
             ctx.Process(target=kernels.comes_second, args=(str(tmp_path), holding, outs[1]))]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0, 0]
    assert json.loads(outs[0].read_text()) == [1, 0]   # compiled by the first worker
    assert json.loads(outs[1].read_text()) == [0, 1]   # loaded by the second


def _lock_of(task):
    """Stand-in task: reports the compile lock it was given."""
    return B._row(task, "ok", reason=task.compile_lock or "")


@pytest.mark.parametrize("workers", [1, 2])
def test_local_workers_share_the_output_folder_as_compile_lock(tmp_path, workers):
    from PIL import Image

    inp = tmp_path / "in"
    inp.mkdir()
    for name in ["a", "b", "c"]:
        Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(inp / f"{name}.png")
    idx = B.run_batch(inp, tmp_path / "out", workers=workers, progress=False, task_fn=_lock_of)
    want = str((tmp_path / "out").resolve()) if workers > 1 else ""
    assert list(idx["reason"].fillna("")) == [want] * 3


def test_an_unreachable_scheduler_is_given_up_after_the_timeout(monkeypatch):
    # Dask waits 30 s by default on a mistyped address; the package gives it its own limit
    from crosssection.core import parallel
    from crosssection.core.errors import ParameterError

    seen = {}

    def refusing(address, timeout):
        seen.update(timeout=timeout, address=address)
        raise OSError(f"Timed out trying to connect to {address} after {timeout} s")

    monkeypatch.setattr(parallel, "_probe_scheduler", refusing)
    with pytest.raises(ParameterError, match="no Dask scheduler answered within"):
        with parallel.get_executor(scheduler="tcp://127.0.0.1:9"):
            pass
    assert seen == {"address": "tcp://127.0.0.1:9", "timeout": parallel.SCHEDULER_TIMEOUT_S}
    assert 0 < parallel.SCHEDULER_TIMEOUT_S <= 15


def test_local_workers_are_capped_at_the_cpus_and_said(monkeypatch):
    from crosssection.core.parallel import capped_workers

    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    assert capped_workers(2) == (2, None)
    assert capped_workers(None) == (None, None)
    n, message = capped_workers(1000)
    assert n == 4 and "--workers 1000" in message and "4 CPUs" in message
    # a cluster sets its own parallelism
    assert capped_workers(1000, "tcp://127.0.0.1:8786") == (1000, None)
