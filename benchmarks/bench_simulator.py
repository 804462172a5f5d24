"""Simulator convergence: segments N and Powell budget against CPU time and ensemble statistics.

    python benchmarks/bench_simulator.py [--plan full|quick] [--workers 2] [--seed 1]
        [--work benchmarks/out/simulator] [--out docs/validation/simulator] [--report-only]

Sweep (``--plan full``; ``quick`` is a one-minute smoke run):

==========  ======================  ===================  =========
N           maxiter per Powell run  runs (snapshots)     configs
==========  ======================  ===================  =========
100 - 300   15, 30, 60              4, 10, 20            24
600         30                      4, 10, 20            8
600         60                      4, 10, 20            4
1000        30                      4, 10, 20            4
2000        30                      4                    1
==========  ======================  ===================  =========

(Sized for about an hour on 2 shared cores: the large N are few configurations, and N = 2000
is one 4-run configuration, a cost point only.) ``--paper-ensemble K`` times configurations
0..K-1 of the paper's ensemble instead (CPU s per configuration, split, and the 250-config
extrapolation to 2 cores).

Physics held fixed: Lambda = 7e5 (the code's energy is a trapezoid integral in units of L, so
Lambda needs no scaling with N) and the continuum law of the initial shapes. The code's noise D
is per segment (the angle steps between segments have variance ``2 D ds^2``, see
:mod:`simulate.noise`), so the tangent angle diffuses as ``var theta(s) = 2 D s / N``; the
sweep uses ``D = 2.5 N`` (750 at N = 300), which keeps ``var theta(s) = 5 s`` for every N. The
contact cut-off of the analysis is held at its N = 300 value, ``delta = 1/600`` L (the code's
default ``0.5/N`` would change the definition of a contact with N). The Powell protocol keeps
its own N-dependent knobs (nematic cut-off one segment, 10-segment separation).

Configuration ``c`` of size N starts from the shape and Powell seed that ``python -m simulate
quench --seed SEED`` gives configuration ``c`` (``spawn_seeds``, split as in
:func:`simulate.ensemble.run_config`), the same start for every budget of that N. A budget is
(``maxiter``, ``runs``); the protocol with R runs is the first R runs of a longer one (same
direction resets, nematic runs 1 and 2), so one protocol of 20 runs gives the 4-, 10- and
20-run snapshots: this is checked at start-up against :func:`simulate.optimize.powell_protocol`
(bit-identical node positions). The point N = 300, maxiter 30, runs 10 is the default
ensemble exactly.

Per snapshot: energy reached Ẽ (bending + confinement), CPU seconds of the minimisation up to
that run (``time.process_time`` in the worker: what one core spends whatever the load), and the
contact analysis (:func:`simulate.contacts.analyze_rod`): Rg, N_br, N_l (stacks), branch
energies, void shape ratios sqrt(s)/p. Per point: <Ẽ>, <Rg>, <N_br/N_l> (per configuration,
configurations with N_l > 0), alpha_e (Gamma shape of the pooled branch energies,
``scipy.stats.gamma.fit(floc=0)``, the project's fit), <sqrt(s)/p> (pooled voids), mean CPU s.

Comparison with a reference point: two-sample KS p-values (``scipy.stats.ks_2samp``: Ẽ, Rg
and N_br/N_l per configuration, branch energies and void ratios pooled) and a 95 % bootstrap
interval of the difference of each statistic (configurations resampled with their branches and
voids, 1000 resamples per point, independent between the two points). A point *agrees* when
all five intervals contain 0. References: the global one (N = 600 at 30 x 20, the largest N
with 8 configurations at its largest budget) and, per N, that N's largest budget.

Resumable: every (N, maxiter, configuration) is written to ``WORK/parts/`` and skipped when
run again. Writes ``OUT/simulator_sweep.csv`` (one row per snapshot and configuration),
``OUT/simulator_points.csv`` (per point: statistics, bootstrap intervals, comparisons with both
references) and ``OUT/simulator_<statistic>.png`` (statistic against CPU s per configuration).
Results and their reading: ``docs/validation/simulator/README.md``.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).resolve().parent
LAM = 7e5
NOISE_PER_N = 2.5          # D = 2.5 N: 750 at N = 300
CONTACT_DISTANCE = 1.0 / 600.0
DEFAULT = (300, 30, 10)    # N, maxiter, runs of the CLI defaults

PLANS = {
    # (N, maxiters, run snapshots, configurations), run in this order
    "full": [(100, (15, 30, 60), (4, 10, 20), 24),
             (200, (15, 30, 60), (4, 10, 20), 24),
             (300, (15, 30, 60), (4, 10, 20), 24),
             (600, (30,), (4, 10, 20), 8),
             (1000, (30,), (4, 10, 20), 4),
             (600, (60,), (4, 10, 20), 4),
             (2000, (30,), (4,), 1)],
    "quick": [(100, (15, 30), (4, 10), 4),
              (300, (30,), (4, 10), 4)],
}
GLOBAL_REFERENCE = (600, 30, 20)
STATS = {  # column of the points table: label of the chart
    "energy": "mean energy reached Ẽ",
    "rg": "mean radius of gyration Rg / L",
    "nbr_nl": "mean branches per stack N_br / N_l",
    "alpha_e": "Gamma shape of branch energies α_e",
    "shape_ratio": "mean void shape ratio √s / p",
}


# ----------------------------------------------------------------------------- one task
def snapshots(xy0, lam, seed, run_marks, maxiter):
    """The default Powell protocol (:func:`simulate.optimize.powell_protocol` with its
    defaults, tangent coordinates) stopped after ``max(run_marks)`` runs, with the node
    positions and the cumulative CPU seconds after every run in ``run_marks``.

    Returns
    -------
    dict
        ``{runs: (xy, cpu_s)}``.
    """
    from simulate.optimize import from_params, to_params
    from simulate.powell import powell_run

    t0 = time.process_time()
    xy0 = np.asarray(xy0, dtype=np.float64)
    n = xy0.shape[0] - 1
    m = n + 2
    rng = np.random.default_rng(seed)
    p = to_params(xy0)
    stats = np.zeros(6, np.int64)
    dirs = np.zeros((m, m))
    nem = {1, 2}
    out = {}
    for run in range(max(run_marks)):
        kind = rng.permutation(m).astype(np.int64)
        sgn = rng.choice([-1.0, 1.0], size=m)
        powell_run(p, float(lam), kind, sgn, dirs, int(maxiter), 1e-4, 1e-4,
                   100.0 if run in nem else 0.0, 1.0 / n, 10, np.inf, stats, True, True)
        if run + 1 in run_marks:
            out[run + 1] = (from_params(p), time.process_time() - t0)
    return out


def check_snapshots():
    """The 4-run snapshot of a 6-run protocol is ``powell_protocol(n_runs=4)`` bit for bit."""
    from simulate.noise import initial_shape
    from simulate.optimize import powell_protocol

    xy0 = initial_shape(60, 150.0, seed=3)
    ref = powell_protocol(xy0, LAM, seed=5, n_runs=4, maxiter=6)
    snap = snapshots(xy0, LAM, 5, (4, 6), 6)
    if not np.array_equal(snap[4][0], ref.xy):
        raise RuntimeError("snapshot protocol differs from simulate.optimize.powell_protocol")


def part_file(work, n, maxiter, c):
    return Path(work) / "parts" / f"n{n:05d}_it{maxiter:03d}_c{c:03d}.json"


def run_task(n, maxiter, run_marks, c, seed, work):
    """One start of size ``n`` under ``maxiter``: protocol, snapshots, analyses; writes its
    part file. Returns its path."""
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    from crosssection.core.fileio import write_text
    from simulate.contacts import analyze_rod
    from simulate.energy import bending_energy, confinement_energy
    from simulate.noise import initial_shape

    shape_ss, opt_ss = np.random.SeedSequence(seed).spawn(2)
    xy0 = initial_shape(n, NOISE_PER_N * n, seed=np.random.default_rng(shape_ss))
    opt_seed = int(opt_ss.generate_state(1, dtype=np.uint32)[0])
    snaps = snapshots(xy0, LAM, opt_seed, run_marks, maxiter)
    rows = []
    for runs, (xy, cpu_s) in sorted(snaps.items()):
        eb = bending_energy(xy)
        ec = confinement_energy(xy, LAM)
        t = time.process_time()
        row = dict(n=n, maxiter=maxiter, runs=runs, config=c, seed=seed, cpu_s=cpu_s,
                   energy=eb + ec, energy_bending=eb, energy_confinement=ec)
        try:
            an = analyze_rod(xy, lam=LAM, contact_distance=CONTACT_DISTANCE)
            row.update(rg=float(an.rg), n_branches=int(an.n_branches),
                       n_stacks=int(an.n_stacks), n_voids=int(an.n_voids),
                       branch_energy=[float(e) for e in an.branches.energy],
                       shape_ratio=[float(s) for s in an.voids.shape_ratio])
        except Exception as exc:  # noqa: BLE001 - recorded, the sweep goes on
            row.update(analysis_error=f"{type(exc).__name__}: {exc}")
        row["analysis_cpu_s"] = time.process_time() - t
        rows.append(row)
    path = part_file(work, n, maxiter, c)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(rows))
    return str(path)


def run_plan(plan, seed, work, workers):
    from crosssection.core.parallel import get_executor, spawn_seeds

    tasks = []
    for n, maxiters, marks, k in plan:
        seeds = spawn_seeds(seed, k)
        for c in range(k):
            for it in maxiters:
                if not part_file(work, n, it, c).exists():
                    tasks.append((n, it, tuple(marks), c, seeds[c], str(work)))
    print(f"{len(tasks)} tasks to run", flush=True)
    t0 = time.perf_counter()
    with get_executor(workers) as ex:
        futs = [ex.submit(run_task, *t) for t in tasks]
        for i, f in enumerate(futs):
            f.result()
            print(f"  {i + 1}/{len(tasks)} {tasks[i][:2]} config {tasks[i][3]} "
                  f"({time.perf_counter() - t0:.0f} s wall)", flush=True)


# ----------------------------------------------------------------------------- paper ensemble
def time_paper_ensemble(k, out_dir):
    """CPU seconds per configuration of the paper's ensemble (``quench --lambda 7e5 --noise 750
    --segments 300 --seed 1``, defaults otherwise), configurations 0 .. k-1 in this process,
    split into start shape, minimisation, and analysis + part file; returns a DataFrame."""
    import tempfile

    from crosssection.core.parallel import spawn_seeds
    from simulate import ensemble
    from simulate.contacts import analyze_rod
    from simulate.noise import initial_shape

    params = dict(command="quench", n_configs=250, n_segments=300, lam=LAM, noise=750.0, seed=1,
                  method="powell", n_runs=10, maxiter=30, nematic_runs=[1, 2], u=100.0,
                  ftol=1e-4, xtol=1e-4, wall_radius=None, contact_distance=None,
                  parametrization=None)
    seeds = spawn_seeds(1, 250)
    # compile / load the numba caches outside the timings
    small = initial_shape(30, 100.0, seed=0)
    ensemble.minimize_config(small, {**params, "n_runs": 4, "maxiter": 2}, 0)
    analyze_rod(small, lam=LAM)
    rows = []
    with tempfile.TemporaryDirectory(dir=out_dir) as tmp:
        for c in range(k):
            t0 = time.process_time()
            shape_ss, opt_ss = np.random.SeedSequence(seeds[c]).spawn(2)
            initial_shape(300, 750.0, seed=np.random.default_rng(shape_ss))
            t1 = time.process_time()
            ensemble.run_config(c, seeds[c], params, tmp)  # shape again, minimise, analyse, write
            t2 = time.process_time()
            meta = json.loads(str(np.load(ensemble.part_path(tmp, c))["meta"]))["row"]
            rows.append(dict(config=c, shape_cpu_s=t1 - t0, total_cpu_s=t2 - t1,
                             energy=meta["energy_total"], iterations=meta["n_iterations"],
                             evaluations=meta["n_evaluations"]))
    df = pd.DataFrame(rows)
    return df


def report_paper_ensemble(df, workers=2):
    m = df.total_cpu_s.mean()
    se = df.total_cpu_s.std(ddof=1) / np.sqrt(len(df))
    print(f"paper ensemble, configurations 0-{len(df) - 1}: CPU s per configuration "
          f"{m:.2f} +- {se:.2f} (shape {df.shape_cpu_s.mean():.3f}), <E> = {df.energy.mean():.0f}")
    print(f"extrapolated: 250 configurations on {workers} cores = 250 x {m:.2f} / {workers} = "
          f"{250 * m / workers:.0f} s (+- {250 * 1.96 * se / workers:.0f} s, 95 %), "
          f"target 300 s: {'met' if 250 * m / workers <= 300 else 'NOT met'}")


# ----------------------------------------------------------------------------- statistics
def load_parts(work, plan):
    rows = []
    for n, maxiters, marks, k in plan:
        for it in maxiters:
            for c in range(k):
                f = part_file(work, n, it, c)
                if f.exists():
                    rows += json.loads(f.read_text())
    return pd.DataFrame(rows)


def point_stats(g):
    """Statistics of one point from its configurations' rows."""
    from scipy import stats

    br = np.concatenate([np.asarray(x, float) for x in g.branch_energy])
    vr = np.concatenate([np.asarray(x, float) for x in g.shape_ratio])
    ratio = (g.n_branches / g.n_stacks)[g.n_stacks > 0]
    br = br[br > 0]
    alpha = stats.gamma.fit(br, floc=0)[0] if br.size > 2 else np.nan
    return dict(energy=g.energy.mean(), rg=g.rg.mean(), nbr_nl=ratio.mean(), alpha_e=alpha,
                shape_ratio=vr.mean() if vr.size else np.nan)


def bootstrap(g, n_boot, rng):
    """``n_boot`` x 5 bootstrap statistics (configurations resampled)."""
    idx = np.arange(len(g))
    out = np.empty((n_boot, len(STATS)))
    for b in range(n_boot):
        s = point_stats(g.iloc[rng.choice(idx, size=idx.size)])
        out[b] = [s[k] for k in STATS]
    return out


def compare(g, gref, boot, bref):
    from scipy import stats

    ratio = lambda d: (d.n_branches / d.n_stacks)[d.n_stacks > 0]  # noqa: E731
    cat = lambda d, col: np.concatenate([np.asarray(x, float) for x in d[col]])  # noqa: E731
    out = dict(p_energy=stats.ks_2samp(g.energy, gref.energy).pvalue,
               p_rg=stats.ks_2samp(g.rg, gref.rg).pvalue,
               p_nbr_nl=stats.ks_2samp(ratio(g), ratio(gref)).pvalue,
               p_branch_energy=stats.ks_2samp(cat(g, "branch_energy"),
                                              cat(gref, "branch_energy")).pvalue,
               p_shape_ratio=stats.ks_2samp(cat(g, "shape_ratio"),
                                            cat(gref, "shape_ratio")).pvalue)
    diff = boot - bref
    agree = True
    for j, k in enumerate(STATS):
        lo, hi = np.nanpercentile(diff[:, j], [2.5, 97.5])
        out[f"d_{k}_lo"], out[f"d_{k}_hi"] = lo, hi
        agree &= bool(lo <= 0.0 <= hi)
    out["agrees"] = agree
    return out


def report(df, out, n_boot=1000, plan_name="full"):
    from crosssection.core.fileio import write_csv

    ok = df[df.analysis_error.isna()] if "analysis_error" in df else df
    keys = ["n", "maxiter", "runs"]
    rng = np.random.default_rng(12345)
    points, boots, groups = [], {}, {}
    for key, g in ok.groupby(keys):
        g = g.reset_index(drop=True)
        s = point_stats(g)
        b = bootstrap(g, n_boot, rng)
        boots[key], groups[key] = b, g
        row = dict(zip(keys, key), budget=key[1] * key[2], configs=len(g),
                   cpu_s=g.cpu_s.mean(), cpu_s_sd=g.cpu_s.std(),
                   analysis_cpu_s=g.analysis_cpu_s.mean(),
                   energy_bending=g.energy_bending.mean(),
                   energy_confinement=g.energy_confinement.mean(),
                   n_branches=g.n_branches.mean(), n_stacks=g.n_stacks.mean(),
                   n_branch_energies=int(sum(len(x) for x in g.branch_energy)),
                   n_voids=int(sum(len(x) for x in g.shape_ratio)), **s)
        for j, k in enumerate(STATS):
            row[f"{k}_lo"], row[f"{k}_hi"] = np.nanpercentile(b[:, j], [2.5, 97.5])
        points.append(row)
    pts = pd.DataFrame(points)
    ref = GLOBAL_REFERENCE if GLOBAL_REFERENCE in groups else max(
        groups, key=lambda k: (k[0], k[1] * k[2]))
    for i, r in pts.iterrows():
        key = (r.n, r.maxiter, r.runs)
        own = max((k for k in groups if k[0] == r.n), key=lambda k: (k[1] * k[2], k[1]))
        for tag, rk in (("ref", ref), ("own", own)):
            for c, v in compare(groups[key], groups[rk], boots[key], boots[rk]).items():
                pts.loc[i, f"{tag}_{c}"] = v
        pts.loc[i, "reference"] = "N={}, {}x{}".format(*ref)
        pts.loc[i, "own_reference"] = "{}x{}".format(*own[1:])
    out = Path(out)
    sweep = ok.drop(columns=["branch_energy", "shape_ratio"], errors="ignore")
    sweep = sweep.assign(n_branch_energies=ok.branch_energy.map(len),
                         mean_shape_ratio=ok.shape_ratio.map(
                             lambda x: float(np.mean(x)) if len(x) else np.nan))
    write_csv(out / "simulator_sweep.csv", sweep.sort_values(keys + ["config"]))
    write_csv(out / "simulator_points.csv", pts)
    charts(pts, ref, out)
    return pts, ref


def charts(pts, ref, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from crosssection.core.fileio import save_figure

    ns = sorted(pts.n.unique())
    colors = {n: f"C{i}" for i, n in enumerate(ns)}
    markers = {15: "v", 30: "o", 60: "s"}
    refrow = pts[(pts.n == ref[0]) & (pts.maxiter == ref[1]) & (pts.runs == ref[2])].iloc[0]
    for k, label in STATS.items():
        fig, ax = plt.subplots(figsize=(8, 5), layout="constrained")
        ax.axhspan(refrow[f"{k}_lo"], refrow[f"{k}_hi"], color="0.85",
                   label="reference N={}, {}x{} (95 % interval)".format(*ref))
        for (n, it), g in pts.groupby(["n", "maxiter"]):
            g = g.sort_values("runs")
            ax.errorbar(g.cpu_s, g[k], yerr=[g[k] - g[f"{k}_lo"], g[f"{k}_hi"] - g[k]],
                        color=colors[n], marker=markers.get(it, "D"), ms=5, lw=1, capsize=2,
                        label=f"N={n}, {it} iterations per run ({g.configs.iloc[0]} configs)")
            for _, r in g.iterrows():
                ax.annotate(f"{r.runs}", (r.cpu_s, r[k]), textcoords="offset points",
                            xytext=(4, 3), fontsize=7, color=colors[n])
        d = pts[(pts.n == DEFAULT[0]) & (pts.maxiter == DEFAULT[1]) & (pts.runs == DEFAULT[2])]
        if len(d):
            ax.plot(d.cpu_s, d[k], marker="*", ms=18, mfc="none", mec="k", ls="none",
                    label="default N=300, 30 iterations x 10 runs")
        ax.set_xscale("log")
        ax.set_xlabel("CPU seconds per configuration (minimisation; one core)")
        ax.set_ylabel(label)
        ax.set_title(f"{label} against CPU time\nnumbers: Powell runs; bars: 95 % bootstrap "
                     "interval", fontsize=10)
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
        save_figure(fig, out / f"simulator_{k}.png")


def print_table(pts):
    cols = ["n", "maxiter", "runs", "configs", "cpu_s", "energy", "rg", "nbr_nl", "alpha_e",
            "shape_ratio", "ref_agrees", "own_agrees", "ref_p_energy", "ref_p_rg"]
    with pd.option_context("display.width", 200, "display.max_columns", 30,
                           "display.float_format", "{:.4g}".format):
        print(pts[cols].to_string(index=False))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plan", choices=sorted(PLANS), default="full")
    ap.add_argument("--quick", action="store_true", help="same as --plan quick")
    ap.add_argument("--seed", type=int, default=1, help="ensemble seed (the README's: 1)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--work", default=None, help="part files (default benchmarks/out/simulator"
                                                 "[_quick])")
    ap.add_argument("--out", default=None,
                    help="tables and charts (default docs/validation/simulator for the full "
                         "plan, benchmarks/out/simulator_quick otherwise)")
    ap.add_argument("--report-only", action="store_true", help="no new runs: tables and charts "
                                                               "from the part files")
    ap.add_argument("--bootstrap", type=int, default=1000)
    ap.add_argument("--paper-ensemble", type=int, default=0, metavar="K",
                    help="instead of the sweep: time configurations 0..K-1 of the paper's "
                         "ensemble (N=300, seed 1) in this process and extrapolate to 250 "
                         "configurations on 2 cores")
    a = ap.parse_args(argv)
    if a.paper_ensemble:
        df = time_paper_ensemble(a.paper_ensemble, HERE / "out")
        print(df.to_string(index=False))
        report_paper_ensemble(df)
        return
    name = "quick" if a.quick else a.plan
    plan = PLANS[name]
    work = Path(a.work or HERE / "out" / ("simulator" if name == "full" else "simulator_quick"))
    out = Path(a.out or (HERE.parent / "docs" / "validation" / "simulator" if name == "full"
                         else HERE / "out" / "simulator_quick"))
    if not a.report_only:
        check_snapshots()
        run_plan(plan, a.seed, work, a.workers)
    df = load_parts(work, plan)
    pts, ref = report(df, out, a.bootstrap, name)
    print(f"reference: N={ref[0]}, maxiter {ref[1]}, runs {ref[2]}")
    print_table(pts)
    print("written:", out)


if __name__ == "__main__":
    main()
