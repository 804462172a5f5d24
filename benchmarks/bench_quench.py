"""Energy reached against wall time per configuration, for every minimiser (same run).

    python benchmarks/bench_quench.py [--configs 3] [--scipy-configs 1] [--n 300]
        [--lam 7e5] [--noise 750]

Methods: ``powell`` (the paper's protocol, numba), ``lbfgs`` (gradient + smooth barrier),
``anneal`` (Lambda ramp + Powell), and the reference ``scipy.optimize.minimize(method="Powell")``
on the same energy. For a like-for-like speed ratio the reference and the numba engine both run
ONE Powell run of ``--scipy-maxiter`` iterations from the same start with scipy's default
(identity) direction set; ``speedup`` is scipy time / numba time for that run.
"""
from __future__ import annotations

import argparse

import numpy as np

from simulate.geometry import radius_of_gyration
from simulate.noise import initial_shape
from simulate.optimize import anneal, lbfgs_quench, powell_protocol, scipy_powell


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configs", type=int, default=3)
    ap.add_argument("--scipy-configs", type=int, default=1)
    ap.add_argument("--scipy-maxiter", type=int, default=3)
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--lam", type=float, default=7e5)
    ap.add_argument("--noise", type=float, default=750.0)
    a = ap.parse_args(argv)
    # compile outside the timings
    powell_protocol(initial_shape(30, 100, seed=0), 1e3, seed=0, n_runs=3, maxiter=2,
                    nematic_runs=(1,))
    rows = []
    print(f"{'method':14s} {'cfg':>3s} {'wall_s':>8s} {'E':>8s} {'E_bend':>8s} {'E_conf':>8s} "
          f"{'Rg':>7s}")
    for c in range(a.configs):
        xy0 = initial_shape(a.n, a.noise, seed=1000 + c)
        runs = {"powell": lambda: powell_protocol(xy0, a.lam, seed=c),
                "lbfgs": lambda: lbfgs_quench(xy0, a.lam),
                "anneal": lambda: anneal(xy0, a.lam, seed=c)}
        for name, fn in runs.items():
            r = fn()
            rows.append((name, r.wall_s, r.energy_total))
            print(f"{name:14s} {c:3d} {r.wall_s:8.2f} {r.energy_total:8.0f} "
                  f"{r.energy_bending:8.0f} {r.energy_confinement:8.0f} "
                  f"{radius_of_gyration(r.xy):7.4f}", flush=True)
    for name in ("powell", "lbfgs", "anneal"):
        w = [r[1] for r in rows if r[0] == name]
        e = [r[2] for r in rows if r[0] == name]
        print(f"mean {name:9s} wall {np.mean(w):7.2f} s/config ({60 / np.mean(w):6.1f} "
              f"configs/min/core)  <E> = {np.mean(e):7.0f}")
    print(f"2 sqrt(Lambda) = {2 * np.sqrt(a.lam):.0f} (spiral ground state)")
    for c in range(a.scipy_configs):
        xy0 = initial_shape(a.n, a.noise, seed=1000 + c)
        ref = scipy_powell(xy0, a.lam, maxiter=a.scipy_maxiter)
        num = powell_protocol(xy0, a.lam, n_runs=1, maxiter=a.scipy_maxiter, nematic_runs=(),
                              first_identity=True)
        print(f"one Powell run, {a.scipy_maxiter} iterations, cfg {c}: scipy {ref.wall_s:.2f} s "
              f"E={ref.energy_total:.0f} ({ref.stats['evaluations']} evaluations) | numba "
              f"{num.wall_s:.3f} s E={num.energy_total:.0f} ({num.stats['evaluations']} "
              f"evaluations) | speedup {ref.wall_s / num.wall_s:.0f}x")


if __name__ == "__main__":
    main()
