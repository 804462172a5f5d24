#!/usr/bin/env python
"""Start-up: the first analysis of a sample scan on a fresh install, cold and warm.

Each run is a fresh Python process: it imports ``crosssection.analyze`` and analyses one scan
(default ``sample_images/scan_02_medium.png``), timing the import and the analysis separately
(wall time, and the process's CPU time user + sys). *Cold*: an empty temporary
``NUMBA_CACHE_DIR``, so every numba kernel the analysis needs is compiled, as on a fresh
install. *Warm*: the same cache directory again, now filled by the cold run. As a reference
for the machine's speed, the time of ``python -c "import numpy"`` is measured in the same run.
Warm runs and the reference are the best of ``--repeat``; the cold run is repeated with a new
empty cache each time, best kept. Target: the cold first analysis (import + analyze) <= 5 s.

The line "numba imported by the analysis" says whether any JIT compiler was loaded at all.
The whole command ``foldstat analyze SCAN --out DIR`` (process start, import, analysis,
tables and the overlay figure) is timed the same way, cold and warm.
``--kernels`` lists, for one cold run, the compile time of every numba function compiled
(inclusive of the functions it calls, from numba's ``numba:compile`` events), longest first.

Usage: python benchmarks/bench_startup.py [--scan PATH] [--repeat 3] [--kernels]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# run in the child: timings of the import and of the first analysis, as JSON on stdout
_CHILD = r"""
import json, os, sys, time, warnings
scan, want_kernels = sys.argv[1], sys.argv[2] == "1"
kernels = {}
if want_kernels:
    from numba.core import event

    class _Listener(event.Listener):
        def __init__(self):
            self.t0 = {}

        def on_start(self, ev):
            self.t0[id(ev.data["dispatcher"]), str(ev.data["args"])] = time.perf_counter()

        def on_end(self, ev):
            key = id(ev.data["dispatcher"]), str(ev.data["args"])
            name = ev.data["dispatcher"].py_func.__module__ + "." + \
                ev.data["dispatcher"].py_func.__qualname__
            kernels[name] = kernels.get(name, 0.0) + time.perf_counter() - self.t0.pop(key)

    event.register("numba:compile", _Listener())
c0 = time.process_time(); t0 = time.perf_counter()
from crosssection import analyze
c1 = time.process_time(); t1 = time.perf_counter()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    res = analyze(scan)
c2 = time.process_time(); t2 = time.perf_counter()
print(json.dumps(dict(import_s=t1 - t0, import_cpu_s=c1 - c0, analyze_s=t2 - t1,
                      analyze_cpu_s=c2 - c1, n_stacks=int(res.summary["n_stacks"]),
                      numba_loaded="numba" in sys.modules, kernels=kernels)))
"""


def _child(scan: str, cache: str, kernels: bool = False) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    proc = subprocess.run([sys.executable, "-c", _CHILD, scan, "1" if kernels else "0"], env=env, capture_output=True,
                          text=True, cwd=str(ROOT))
    if proc.returncode:
        sys.stderr.write(proc.stderr[-3000:])
        raise SystemExit(f"analysis of {scan} failed (exit {proc.returncode})")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _numpy_import_s(repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import numpy"], check=True)
        best = min(best, time.perf_counter() - t0)
    return best


def _best(runs: list[dict]) -> dict:
    """Per field, the minimum over the runs (each field measured independently)."""
    keys = ("import_s", "import_cpu_s", "analyze_s", "analyze_cpu_s")
    return {k: min(r[k] for r in runs) for k in keys}


def _line(name: str, r: dict) -> str:
    total = r["import_s"] + r["analyze_s"]
    return (f"{name:5s}  import {r['import_s']:6.2f} s (cpu {r['import_cpu_s']:6.2f})   "
            f"first analysis {r['analyze_s']:6.2f} s (cpu {r['analyze_cpu_s']:6.2f})   "
            f"total {total:6.2f} s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scan", default=str(ROOT / "sample_images" / "scan_02_medium.png"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--kernels", action="store_true",
                    help="list the numba compile time per function (one cold run)")
    args = ap.parse_args(argv)
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"scan: {args.scan}")
    print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} "
          f"({os.cpu_count()} cpus)")
    t_np = _numpy_import_s(args.repeat)
    print(f"reference: python -c 'import numpy' {t_np:.2f} s (best of {args.repeat}, "
          "process start included)")
    cold, warm = [], []
    for _ in range(args.repeat):
        cache = tempfile.mkdtemp(prefix="numba-cache-")
        try:
            cold.append(_child(args.scan, cache))
            for _ in range(args.repeat):
                warm.append(_child(args.scan, cache))
        finally:
            shutil.rmtree(cache, ignore_errors=True)
    print(f"({len(cold)} cold runs, {len(warm)} warm runs; best of each field)")
    c, w = _best(cold), _best(warm)
    print(_line("cold", c))
    print(_line("warm", w))
    print(f"cold first analysis (import + analyze) = {c['import_s'] + c['analyze_s']:.2f} s "
          "(target <= 5 s)")
    print("numba imported by the analysis: "
          + ("yes" if any(r["numba_loaded"] for r in cold) else "no"))
    # the whole command a user types: import, analysis, tables and the overlay figure
    cmd_cold, cmd_warm = [], []
    for _ in range(args.repeat):
        cache = tempfile.mkdtemp(prefix="numba-cache-")
        out = tempfile.mkdtemp(prefix="startup-out-")
        try:
            for runs in (cmd_cold, cmd_warm):
                env = dict(os.environ, NUMBA_CACHE_DIR=cache)
                t0 = time.perf_counter()
                subprocess.run([sys.executable, "-m", "crosssection.console", "analyze", args.scan,
                                "--out", out], env=env, capture_output=True, check=True,
                               cwd=str(ROOT))
                runs.append(time.perf_counter() - t0)
        finally:
            shutil.rmtree(cache, ignore_errors=True)
            shutil.rmtree(out, ignore_errors=True)
    print(f"command 'foldstat analyze SCAN --out DIR' (tables and overlay figure): cold "
          f"{min(cmd_cold):.2f} s, warm {min(cmd_warm):.2f} s (best of {args.repeat})")
    if args.kernels:
        cache = tempfile.mkdtemp(prefix="numba-cache-")
        try:
            r = _child(args.scan, cache, kernels=True)
        finally:
            shutil.rmtree(cache, ignore_errors=True)
        ker = r["kernels"]
        print(f"numba compile time per function, one cold run ({len(ker)} functions, "
              "inclusive of callees):")
        for name, t in sorted(ker.items(), key=lambda kv: -kv[1]):
            print(f"  {t:7.2f} s  {name}")
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"load average after: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
