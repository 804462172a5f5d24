"""Full sweep of the statistics targets: run ``python benchmarks/bench_fits.py``.

1. Coverage: 95% percentile-bootstrap intervals contain the generating parameters at about
   the nominal rate, per family and n in (200, 1000, 5000).
2. Model selection among every registered family picks the generating one >= 90% of the
   time at n = 1000.
3. Detection limits: relative bias of naive vs truncation-aware fits (exponential, Gamma,
   log-normal) averaged over replicates.
4. Goodness of fit calibration: rejection rate at 5% under the null (scipy path and the
   hand-written truncated path).
5. Speed of the warm-started truncated refits against cold fits, measured in the same run.

Writes ``OUT/bench_fits.json`` and figures ``OUT/coverage.png``, ``OUT/truncation.png``.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from crosssection.core.fileio import save_figure, write_json
from crosssection.stats import fits as F
from crosssection.stats.families import FAMILIES

TRUE = {"exponential": {"mu": 2.5e-3}, "gamma": {"alpha": 0.4, "chi": 0.12},
        "lognormal": {"mu": -9.0, "sigma": 1.2}, "gaussian": {"mu": 0.19, "sigma": 0.037},
        "bose_einstein": {"beta": 3.0, "x_lo": 0.01, "x_hi": 2.0},
        "powerlaw_cutoff": {"tau": 1.6, "chi": 0.5, "x_min": 1e-3}}


def draw(family, n, rng):
    fam = FAMILIES[family]
    if hasattr(fam, "frozen"):
        return fam.frozen(TRUE[family]).rvs(size=n, random_state=rng)
    return fam.sample(TRUE[family], n, None, rng)


def coverage(reps, n_boot, sizes, seed):
    out = {}
    for fam in FAMILIES:
        names = list(FAMILIES[fam].free_names)
        for n in sizes:
            rng = np.random.default_rng([seed, n, len(fam)])
            hit = {k: 0 for k in names}
            for i in range(reps):
                r = F.fit_family(draw(fam, n, rng), fam, n_boot=n_boot, seed=i, gof=False)
                for k in names:
                    lo, hi = r.ci[k]
                    hit[k] += lo <= TRUE[fam][k] <= hi
            out[f"{fam}/n={n}"] = {k: v / reps for k, v in hit.items()}
            print("coverage", fam, n, out[f"{fam}/n={n}"], flush=True)
    return out


def selection(reps, n, seed):
    out = {}
    for fam in FAMILIES:
        rng = np.random.default_rng([seed, 7, len(fam)])
        picks = [F.fit_all(draw(fam, n, rng), tuple(FAMILIES), seed=i, n_boot=0,
                           gof=False).best
                 for i in range(reps)]
        out[fam] = {f: picks.count(f) / reps for f in set(picks)}
        print("selection", fam, out[fam], flush=True)
    return out


def truncation(reps, seed):
    cases = {"exponential": ({"mu": 2.0}, 1.0), "gamma": ({"alpha": 0.8, "chi": 2.0}, 0.8),
             "lognormal": ({"mu": 0.0, "sigma": 1.0}, 0.7)}
    out = {}
    for fam, (truth, cut) in cases.items():
        rng = np.random.default_rng([seed, 3, len(fam)])
        naive, trunc = {k: [] for k in truth}, {k: [] for k in truth}
        for _ in range(reps):
            x = FAMILIES[fam].frozen(truth).rvs(size=3000, random_state=rng)
            x = x[x >= cut]
            a = F.fit_family(x, fam, n_boot=0, gof=False)
            b = F.fit_family(x, fam, truncation=cut, n_boot=0, gof=False)
            for k, t in truth.items():
                scale = abs(t) if t else 1.0
                naive[k].append((a.params[k] - t) / scale)
                trunc[k].append((b.params[k] - t) / scale)
        out[fam] = {k: {"truth": truth[k], "cut": cut,
                        "naive_bias": float(np.mean(naive[k])),
                        "truncated_bias": float(np.mean(trunc[k])),
                        "truncated_sd": float(np.std(trunc[k]))} for k in truth}
        print("truncation", fam, out[fam], flush=True)
    return out


def gof_calibration(reps, n_mc, seed):
    rng = np.random.default_rng([seed, 11])
    p_scipy, p_trunc = [], []
    for i in range(reps):
        x = rng.gamma(0.4, 0.12, 500)
        p_scipy.append(F.fit_family(x, "gamma", n_boot=0, n_mc=n_mc, seed=i).pvalue)
        y = x[x >= 0.01]
        p_trunc.append(F.fit_family(y, "gamma", truncation=0.01, n_boot=0, n_mc=n_mc,
                                    seed=i).pvalue)
    res = {"scipy_reject_5pct": float(np.mean(np.array(p_scipy) <= 0.05)),
           "truncated_reject_5pct": float(np.mean(np.array(p_trunc) <= 0.05)), "reps": reps}
    print("gof", res, flush=True)
    return res


def warm_vs_cold(seed):
    rng = np.random.default_rng(seed)
    x = rng.gamma(0.8, 2.0, 3000)
    x = x[x >= 0.8]
    c = np.full(x.size, 0.8)
    gamma = FAMILIES["gamma"]
    th, _ = gamma.fit(x, c)
    idx = [rng.integers(0, x.size, x.size) for _ in range(30)]
    t = time.perf_counter()
    cold = [gamma.fit(x[i], c[i])[0] for i in idx]
    t_cold = time.perf_counter() - t
    t = time.perf_counter()
    warm = [gamma.fit(x[i], c[i], th)[0] for i in idx]
    t_warm = time.perf_counter() - t
    dev = float(np.max(np.abs(np.array(warm) / np.array(cold) - 1)))
    res = {"cold_s": t_cold / 30, "warm_s": t_warm / 30, "speedup": t_cold / t_warm,
           "max_rel_param_diff": dev}
    print("warm vs cold", res, flush=True)
    return res


def figures(res, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    labels, vals = [], []
    for key, d in res["coverage"].items():
        for k, v in d.items():
            labels.append(f"{key} {k}")
            vals.append(v)
    ax.barh(range(len(vals)), vals, color="tab:blue")
    ax.axvline(0.95, color="k", ls="--")
    ax.set_yticks(range(len(vals)), labels, fontsize=6)
    ax.set(xlim=(0.7, 1.0), xlabel="fraction of 95% bootstrap intervals covering the truth",
           title="bootstrap coverage (dashed: nominal 0.95)")
    fig.subplots_adjust(left=0.35, bottom=0.13)
    save_figure(fig, out / "coverage.png")
    fig, ax = plt.subplots(figsize=(7, 3.5))
    rows = [(f"{f} {k}", d["naive_bias"], d["truncated_bias"])
            for f, dd in res["truncation"].items() for k, d in dd.items()]
    y = np.arange(len(rows))
    ax.barh(y - 0.2, [r[1] for r in rows], 0.4, color="tab:red")
    ax.barh(y + 0.2, [r[2] for r in rows], 0.4, color="tab:green")
    for yi, r in zip(y, rows):
        ax.text(max(r[1], 0), yi - 0.2, f" naive {r[1]:+.2f}", va="center", fontsize=7,
                color="tab:red")
        ax.text(max(r[2], 0), yi + 0.2, f" truncated {r[2]:+.3f}", va="center", fontsize=7,
                color="tab:green")
    ax.set_yticks(y, [r[0] for r in rows])
    ax.axvline(0, color="k", lw=0.8)
    ax.set(xlabel="mean relative bias of the fitted parameter",
           title="detection limit: naive vs truncation-aware MLE")
    fig.subplots_adjust(left=0.22, right=0.85, bottom=0.15)
    save_figure(fig, out / "truncation.png")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out" / "fits"),
                    help="output folder")
    ap.add_argument("--reps", type=int, default=100)
    ap.add_argument("--n-boot", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="small sweep (about a minute)")
    ap.add_argument("--figures-only", action="store_true",
                    help="redraw the figures from an existing OUT/bench_fits.json")
    a = ap.parse_args(argv)
    out = Path(a.out)
    if a.figures_only:
        figures(json.loads((out / "bench_fits.json").read_text()), out)
        return
    reps = 20 if a.quick else a.reps
    t0 = time.perf_counter()
    res = {"coverage": coverage(reps, 100 if a.quick else a.n_boot,
                                (200, 1000) if a.quick else (200, 1000, 5000), a.seed),
           "selection_n1000": selection(reps, 1000, a.seed),
           "truncation": truncation(max(10, reps // 2), a.seed),
           "gof": gof_calibration(max(10, reps // 2), 99, a.seed),
           "warm_vs_cold": warm_vs_cold(a.seed)}
    res["wall_s"] = time.perf_counter() - t0
    write_json(out / "bench_fits.json", res)
    figures(res, out)
    print(f"wrote {out}/bench_fits.json, coverage.png, truncation.png in {res['wall_s']:.0f} s")


if __name__ == "__main__":
    main()
