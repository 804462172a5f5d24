"""Benchmark of ``python -m crosssection batch``: speedup, memory per worker, kill and resume.

Usage::

    python benchmarks/bench_batch.py [--n 200] [--size 480] [--workers 2] [--no-figure]
                                     [--skip-kill] [--json results.json] [--keep DIR]

In one run, on N small generated scans (``crosssection.truth.network.make_scene`` when it succeeds,
else blue bands drawn with OpenCV):

1. the batch on 1 worker (inline) and on ``--workers`` worker processes, each as a
   ``python -m crosssection batch`` subprocess; speedup = t(1) / t(W) (target >= 1.7 for W=2);
   both indexes must agree number for number;
2. peak memory per worker: each task reports its process's ``ru_maxrss`` (index column
   ``peak_rss_mb``); compared with the worker's RSS after its first image and with the size of
   one decoded image (memory must not grow with the number of images);
3. kill and resume: a W-worker batch is killed (SIGKILL to its process group: main process and
   workers) once about 40 % of the images are done, then re-run; the re-run must redo exactly
   the images without a complete output folder and give the reference numbers.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

NUMBERS = ["n_junctions", "n_stacks", "n_branches", "n_voids", "mean_branches_per_stack",
           "rod_length_mm", "epsilon", "total_energy"]


def draw_scan(seed: int, size: int) -> np.ndarray:
    """One generated RGB scan (uint8)."""
    try:
        from crosssection.truth.network import make_scene

        return make_scene(seed=seed, n_stacks=15, max_layers=4, image_size=size, max_tries=5).rgb
    except Exception:  # noqa: BLE001 - fall back to a simple drawing
        pass
    import cv2

    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), 250, np.uint8)
    c, r = size // 2, int(size * 0.45)
    ink = (190, 70, 40)  # BGR
    cv2.circle(img, (c, c), r, ink, thickness=10)
    for _ in range(int(rng.integers(3, 7))):
        a, b = rng.uniform(0, 2 * np.pi, 2)
        p = (int(c + r * np.cos(a)), int(c + r * np.sin(a)))
        q = (int(c + r * np.cos(b)), int(c + r * np.sin(b)))
        cv2.line(img, p, q, ink, thickness=int(rng.integers(5, 16)))
    return img[:, :, ::-1].copy()


def make_inputs(folder: Path, n: int, size: int, seed: int = 0) -> int:
    """Write ``n`` scans into two sets of ``folder``; return the bytes of one decoded image."""
    from PIL import Image

    from crosssection.core.parallel import spawn_seeds

    for k, name in enumerate(("setA", "setB")):
        (folder / name).mkdir(parents=True, exist_ok=True)
        (folder / name / "set.toml").write_text(
            f'name = "{name.lower()}"\npx_per_mm = 50\nthickness_mm = 0.1\n')
    rgb = None
    for i, s in enumerate(spawn_seeds(seed, n)):
        rgb = draw_scan(s, size)
        Image.fromarray(rgb).save(folder / ("setA", "setB")[i % 2] / f"scan_{i:04d}.png")
    return int(rgb.nbytes)


def batch_cmd(inp, out, workers, figure):
    cmd = [sys.executable, "-m", "crosssection", "batch", str(inp), "--out", str(out),
           "--workers", str(workers), "--quiet"]
    return cmd + ([] if figure else ["--no-figure"])


def timed_batch(inp, out, workers, figure) -> float:
    t = time.perf_counter()
    subprocess.run(batch_cmd(inp, out, workers, figure), check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def numbers(index: pd.DataFrame) -> pd.DataFrame:
    return index.set_index("image").sort_index()[["status"] + NUMBERS].replace(
        {"status": {"skipped": "ok"}})


def complete_outputs(out: Path) -> set[str]:
    return {p.parent.relative_to(out).as_posix() for p in out.glob("*/*/summary.json")
            if not p.parent.name.startswith(".")}  # staging folders hold one too


def kill_and_resume(inp, out, workers, figure, n, ref: pd.DataFrame) -> dict:
    """Kill a running batch at ~40 %, re-run it, check what the re-run did."""
    proc = subprocess.Popen(batch_cmd(inp, out, workers, figure), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    target = max(1, int(0.4 * n))
    while proc.poll() is None and len(complete_outputs(out)) < target:
        time.sleep(0.05)
    killed = proc.poll() is None
    if killed:
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    time.sleep(0.5)  # let orphaned workers notice (their pipe closed) and exit
    done_before = complete_outputs(out)
    partial = [p for p in out.rglob("*") if ".partial-" in p.name]
    t = time.perf_counter()
    subprocess.run(batch_cmd(inp, out, workers, figure), check=True, stdout=subprocess.DEVNULL)
    t_resume = time.perf_counter() - t
    idx = pd.read_csv(out / "index.csv")
    redone = set(idx.loc[idx["status"] == "ok", "output"])
    skipped = set(idx.loc[idx["status"] == "skipped", "output"])
    same = numbers(idx).equals(numbers(ref))
    left = [p for p in out.rglob("*") if ".partial-" in p.name]
    return {"killed_mid_run": killed, "complete_at_kill": len(done_before),
            "partial_folders_at_kill": len(partial), "resume_redone": len(redone),
            "resume_skipped": len(skipped),
            "only_missing_redone": skipped == done_before and redone.isdisjoint(done_before)
            and len(redone) + len(skipped) == n,
            "results_identical": bool(same), "partial_left_after_resume": len(left),
            "resume_s": round(t_resume, 2)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200, help="number of scans (default 200)")
    ap.add_argument("--size", type=int, default=480, help="scan side in pixels")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-figure", action="store_true")
    ap.add_argument("--skip-kill", action="store_true")
    ap.add_argument("--json", default=None, help="write the figures here")
    ap.add_argument("--keep", default=None, help="work in this folder and keep it")
    a = ap.parse_args(argv)
    figure = not a.no_figure
    work = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="bench_batch_"))
    work.mkdir(parents=True, exist_ok=True)
    inp = work / "in"
    t = time.perf_counter()
    image_bytes = make_inputs(inp, a.n, a.size)
    print(f"generated {a.n} scans of {a.size}x{a.size} px in {time.perf_counter() - t:.1f} s "
          f"-> {inp}")

    load_before = os.getloadavg()[0]
    t1 = timed_batch(inp, work / "out1", 1, figure)
    tw = timed_batch(inp, work / f"out{a.workers}", a.workers, figure)
    load_after = os.getloadavg()[0]
    i1 = pd.read_csv(work / "out1" / "index.csv")
    iw = pd.read_csv(work / f"out{a.workers}" / "index.csv")
    ok = int((i1["status"] == "ok").sum())
    rss = iw.loc[iw["status"] == "ok", "peak_rss_mb"]
    res = {
        "n_images": a.n, "size_px": a.size, "figure": figure, "workers": a.workers,
        "n_ok": ok, "n_failed": int((i1["status"] == "failed").sum()),
        "t_1_worker_s": round(t1, 2), f"t_{a.workers}_workers_s": round(tw, 2),
        "speedup": round(t1 / tw, 2),
        # the machine is shared: a load above ~0.5 before the run means fewer free cores
        "loadavg_1min_before_after": [round(load_before, 2), round(load_after, 2)],
        "per_image_1_worker_s": round(t1 / a.n, 3),
        "identical_1_vs_w": bool(numbers(i1).equals(numbers(iw))),
        "one_image_mb": round(image_bytes / 2**20, 2),
        "worker_rss_first_image_mb": float(rss.iloc[:a.workers].max()) if len(rss) else None,
        "worker_peak_rss_mb": float(rss.max()) if len(rss) else None,
        "worker_peak_rss_first_10pct_mb": float(rss.iloc[: max(1, len(rss) // 10)].max())
        if len(rss) else None,
    }
    if not a.skip_kill:
        res["kill_resume"] = kill_and_resume(inp, work / "outkill", a.workers, figure, a.n, i1)
    print(json.dumps(res, indent=2))
    if a.json:
        Path(a.json).write_text(json.dumps(res, indent=2) + "\n")
    if not a.keep:
        import shutil

        shutil.rmtree(work, ignore_errors=True)
    return res


if __name__ == "__main__":
    main()
