"""Quench methods side by side: energy reached against wall time, and ensemble statistics.

    python benchmarks/bench_quench.py [--configs 16] [--scipy-configs 2] [--n 300]
        [--lam 7e5] [--noise 750] [--out benchmarks/out]

Methods, all from the same starts (``initial_shape(seed=1000 + c)``) in the same run:
``powell`` (the paper's protocol, numba, tangent coordinates), ``lbfgs`` (L-BFGS-B with a smooth
contact barrier), ``anneal`` (Lambda ramp, Powell in bend coordinates), and the reference
``scipy-powell`` (the same protocol with ``scipy.optimize.minimize(method="Powell")``, on the
first ``--scipy-configs`` starts; its speed ratio to ``powell`` is measured on those starts).

Prints (1) energy reached and wall time per configuration per method, (2) ensemble statistics
per method with two-sample KS tests (``scipy.stats.ks_2samp``) against ``powell`` on Ẽ, Rg and
the branch energies; writes ``OUT/quench_methods.png`` (energy against wall time, every run or
stage of every configuration) and ``OUT/quench_methods.csv``.

Measured (16 starts, N = 300, Lambda = 7e5, D = 750, 2 shared cores under load ~4; before the
clearance speed-up of simulate/powell.py, which cut powell's CPU time 1.54x with identical results):

============  ========  =====  =====  ======  ======  ====  =======  =======  ========
method        s/config  <E>    bend   conf    <Rg>    N_br  p(E)     p(Rg)    p(e_br)
============  ========  =====  =====  ======  ======  ====  =======  =======  ========
powell          2.7     4151   1799   2352    0.0575  22.4  --       --       --
lbfgs           6.8     2506   1316   1190    0.0411  27.1  1.1e-7   1.7e-6   2.7e-3
anneal          4.0     1817    777   1040    0.0385  31.9  3.3e-9   3.3e-9   9.3e-14
scipy-powell  127       4314   1844   2469    0.0594  19.0  0.37     0.94     0.43
============  ========  =====  =====  ======  ======  ====  =======  =======  ========

(scipy-powell on 2 starts only; 28x slower than the numba engine (28-38x over two runs) on the same starts.)
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from crosssection.core.fileio import save_figure, write_csv
from simulate.contacts import analyze_rod
from simulate.geometry import radius_of_gyration
from simulate.noise import initial_shape
from simulate.optimize import anneal, lbfgs_quench, powell_protocol, scipy_protocol


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configs", type=int, default=16)
    ap.add_argument("--scipy-configs", type=int, default=2)
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--lam", type=float, default=7e5)
    ap.add_argument("--noise", type=float, default=750.0)
    ap.add_argument("--out", default=str(Path(__file__).parent / "out"))
    a = ap.parse_args(argv)
    # compile outside the timings
    small = initial_shape(30, 100, seed=0)
    powell_protocol(small, 1e3, seed=0, n_runs=3, maxiter=2, nematic_runs=(1,))
    anneal(small, 1e3, seed=0, stages=2, n_runs=2, maxiter=2, nematic_runs=())
    lbfgs_quench(small, 1e3)
    methods = {"powell": lambda xy0, c: powell_protocol(xy0, a.lam, seed=c),
               "lbfgs": lambda xy0, c: lbfgs_quench(xy0, a.lam),
               "anneal": lambda xy0, c: anneal(xy0, a.lam, seed=c),
               "scipy-powell": lambda xy0, c: scipy_protocol(xy0, a.lam, seed=c)}
    rows, brows, curves = [], [], []
    print(f"{'method':13s} {'cfg':>3s} {'wall_s':>8s} {'E':>7s} {'E_bend':>7s} {'E_conf':>7s} "
          f"{'Rg':>7s} {'N_br':>5s}")
    for c in range(a.configs):
        xy0 = initial_shape(a.n, a.noise, seed=1000 + c)
        for name, fn in methods.items():
            if name == "scipy-powell" and c >= a.scipy_configs:
                continue
            r = fn(xy0, c)
            an = analyze_rod(r.xy, lam=a.lam)
            rows.append(dict(method=name, config=c, wall_s=r.wall_s, energy=r.energy_total,
                             bending=r.energy_bending, confinement=r.energy_confinement,
                             rg=radius_of_gyration(r.xy), n_branches=an.n_branches,
                             n_voids=an.n_voids))
            brows += [dict(method=name, config=c, energy=e) for e in an.branches.energy]
            curves.append((name, c, [0.0] + [h[0] for h in r.history],
                           [np.nan] + [h[1] for h in r.history]))
            print(f"{name:13s} {c:3d} {r.wall_s:8.2f} {r.energy_total:7.0f} "
                  f"{r.energy_bending:7.0f} {r.energy_confinement:7.0f} {rows[-1]['rg']:7.4f} "
                  f"{an.n_branches:5d}", flush=True)
    df = pd.DataFrame(rows)
    br = pd.DataFrame(brows)
    out = Path(a.out)
    write_csv(out / "quench_methods.csv", df)

    print(f"\nenergy reached vs wall time (2 sqrt(Lambda) = {2 * np.sqrt(a.lam):.0f}, the "
          "spiral ground state)")
    print(f"{'method':13s} {'n':>3s} {'s/config':>9s} {'configs/min':>11s} {'<E>':>7s} "
          f"{'<E_bend>':>8s} {'<E_conf>':>8s}")
    for name, g in df.groupby("method", sort=False):
        print(f"{name:13s} {len(g):3d} {g.wall_s.mean():9.2f} {60 / g.wall_s.mean():11.1f} "
              f"{g.energy.mean():7.0f} {g.bending.mean():8.0f} {g.confinement.mean():8.0f}")
    both = df[df.config < a.scipy_configs].pivot(index="config", columns="method",
                                                  values="wall_s")
    if "scipy-powell" in both:
        ratio = (both["scipy-powell"] / both["powell"]).mean()
        print(f"speed: scipy-powell / powell wall time on the same starts = {ratio:.1f}x")

    print("\nensemble statistics per method; KS p-values against powell (ks_2samp)")
    ref = df[df.method == "powell"]
    print(f"{'method':13s} {'<E>':>7s} {'<Rg>':>7s} {'<eps>':>6s} {'<N_br>':>6s} "
          f"{'<e_br>':>7s} {'p(E)':>8s} {'p(Rg)':>8s} {'p(e_br)':>8s}")
    for name, g in df.groupby("method", sort=False):
        b = br[br.method == name].energy
        pe = stats.ks_2samp(g.energy, ref.energy).pvalue
        pr = stats.ks_2samp(g.rg, ref.rg).pvalue
        pb = stats.ks_2samp(b, br[br.method == "powell"].energy).pvalue
        print(f"{name:13s} {g.energy.mean():7.0f} {g.rg.mean():7.4f} "
              f"{np.mean(1 / (2 * np.pi * g.rg)):6.2f} {g.n_branches.mean():6.1f} "
              f"{b.mean():7.1f} {pe:8.1e} {pr:8.1e} {pb:8.1e}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    colors = {"powell": "C0", "lbfgs": "C1", "anneal": "C2", "scipy-powell": "C3"}
    for name, c, t, e in curves:
        if name == "anneal":  # intermediate stages are at lower Lambda: final point only
            ax.plot(t[-1], e[-1], "s", ms=4, alpha=0.7, color=colors[name],
                    label=name + " (final)" if c == 0 else None)
            continue
        ax.plot(np.maximum(t, 1e-2), e, "-o", ms=2, lw=0.8, alpha=0.6, color=colors[name],
                label=name if c == 0 else None)
    ax.axhline(2 * np.sqrt(a.lam), color="k", ls="--", lw=0.8, label="2√Λ (spiral)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time per configuration (s)")
    ax.set_ylabel("energy Ẽ (after each Powell run)")
    ax.set_title(f"N={a.n}, Λ={a.lam:.0e}, D={a.noise:.0f}")
    ax.legend()
    print("chart:", save_figure(fig, out / "quench_methods.png"))


if __name__ == "__main__":
    main()
