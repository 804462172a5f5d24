"""Benchmark of the three self-intersection detectors (ratios against brute force, same run).

    python benchmarks/bench_intersect.py [--n 300] [--shapes 200]

Shapes: raw noise shapes at D = 750 (extended) and quenched-like compact shapes (a noise shape
shrunk into a disk by a few Powell runs), the inputs the minimiser actually tests.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from simulate.geometry import positions
from simulate.intersect import (has_intersection_brute, has_intersection_grid,
                                has_intersection_skip)
from simulate.noise import initial_shape
from simulate.optimize import powell_protocol

DETECTORS = {"brute": has_intersection_brute, "skip": has_intersection_skip,
             "grid": has_intersection_grid}


def _time(fn, shapes, repeat=3):
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        for xy in shapes:
            fn(xy)
        best = min(best, time.perf_counter() - t)
    return best / len(shapes)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--shapes", type=int, default=200)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    sets = {
        "noise D=750": [positions(np.cumsum(np.sqrt(1500) / a.n * rng.standard_normal(a.n)))
                        for _ in range(a.shapes)],
        "compact (quenched)": [powell_protocol(initial_shape(a.n, 750, seed=s), 7e5, seed=s,
                                               n_runs=2, maxiter=5, nematic_runs=()).xy
                               for s in range(5)],
    }
    for fn in DETECTORS.values():  # compile
        fn(sets["noise D=750"][0])
    print(f"N = {a.n}")
    for name, shapes in sets.items():
        t = {k: _time(fn, shapes) for k, fn in DETECTORS.items()}
        print(f"{name:20s} " + "  ".join(f"{k}: {v * 1e6:8.1f} us ({t['brute'] / v:5.1f}x)"
                                         for k, v in t.items()))


if __name__ == "__main__":
    main()
