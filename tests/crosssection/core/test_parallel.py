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
from crosssection.core.parallel import get_executor, spawn_seeds

from crosssection.testing import index_numbers as numbers
from crosssection.testing import make_scan_tree as make_tree


def _draw(seed: int) -> float:
    """A task whose result depends only on its seed (module level: picklable)."""
    return float(np.random.default_rng(seed).standard_normal(1000).sum())


def _pid(_):
    return os.getpid()


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
