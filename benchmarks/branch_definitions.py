#!/usr/bin/env python
"""What the definition of a branch does to the shapes of the simulated distributions.

The quench reproduces the paper's means (<e>, <l>/L, N_br per configuration) but not the
shapes of its laws: the branch-energy Gamma shape alpha_e, the branch-length Gamma shape
alpha_l and alpha_E / alpha_e. This script re-analyses one quench ensemble (the rods are
fixed; only the analysis changes) with other definitions of a contact, a stack and a branch,
and fits the laws each gives:

* the contact cut-off ``delta`` (``contact_distance``, 0.25 to 8 segments) and the shortest
  run of constant multiplicity kept (``min_run``, 0.01 to 3 delta) -- the two parameters of
  :func:`simulate.contacts.analyze_rod`;
* fold caps kept as their own branch, and junctions where only two stack ends meet kept as
  junctions (two stages of the analysis switched off: ``--structure``);
* the fit itself: maximum likelihood (``scipy.stats.gamma.fit``, what the project reports)
  against least squares on a histogram, linear or log-binned, as a paper figure is fitted.

Beside each law, the share of branches shorter than 1 and 3 segments (L/N) and of branch
energies below 10 and 50 is compared with what the paper's Gamma laws (alpha_l = 0.4, chi =
0.12; alpha_e = 0.31, chi = 728) put there.

Usage::

    foldstat quench --n-configs 120 --lambda 7e5 --noise 750 --segments 300 --seed 1 --out Q
    python benchmarks/branch_definitions.py Q --out OUT.csv [--workers 2] [--structure]

Without ``Q`` the quench is run first (``--n-configs``, default 120; ``--quick``: 12, and
the default cut-off grid only) into ``benchmarks/out/branch_definitions/quench_N`` (resumed
when already there); ``--out`` defaults to ``benchmarks/out/branch_definitions.csv``.
"""
from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import optimize, stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

PAPER = {"alpha_e": 0.31, "chi_e": 728.0, "alpha_l": 0.4, "chi_l": 0.12, "alpha_eb": 0.35,
         "alpha_ec": 0.23, "aE_ae": 200.0, "nbr_nl": 2.0, "n_br_per_config": 4676 / 252}
# (delta in segments, min_run in units of delta); the first is the default analysis
GRID = [(0.5, 3.0), (0.5, 1.0), (0.5, 0.01), (0.25, 0.01), (0.1, 0.01), (0.05, 0.01),
        (1.0, 3.0), (1.0, 0.01),
        (2.0, 0.01), (3.0, 0.01), (4.0, 1.0), (4.0, 0.01), (6.0, 0.01), (8.0, 0.01)]


def load_rods(folder: Path) -> tuple[list, float]:
    """Node positions of every configuration of a quench folder, and its Lambda."""
    lam = float(json.loads((folder / "params.json").read_text())["lam"])
    if (folder / "rods.npz").exists():
        with np.load(folder / "rods.npz") as d:
            return [d[k] for k in sorted(d.keys())], lam
    return [np.load(f)["xy"] for f in sorted((folder / "parts").glob("*.npz"))], lam


def _no_two_end_merge(runs, cls, smp):
    from simulate import contacts
    return contacts._Topology(runs, *contacts._topology(runs, cls, smp.pts, None))


def analyse(args) -> dict:
    """Branch energies and lengths, stack sizes of one rod under one definition."""
    from simulate import contacts
    xy, lam, delta, min_run, keep_caps, keep_two_end = args
    stages = contacts._split_fold_caps, contacts._merge_two_ended_junctions
    if keep_caps:
        contacts._split_fold_caps = lambda runs, cls, smp, d: (runs, cls)
    if keep_two_end:
        contacts._merge_two_ended_junctions = _no_two_end_merge
    try:
        # voids are not used here: rasterised at the default cut-off's resolution whatever
        # delta (at delta/6 a twentieth of a segment takes minutes per rod)
        r = contacts.analyze_rod(xy, lam=lam, contact_distance=delta, min_run=min_run,
                                 void_px=contacts.default_contact_distance(len(xy) - 1) / 6)
    finally:  # a worker process serves every definition in turn
        contacts._split_fold_caps, contacts._merge_two_ended_junctions = stages
    b = r.branches
    return {"e": b["energy"].to_numpy(), "eb": b["energy_bending"].to_numpy(),
            "ec": b["energy_confinement"].to_numpy(), "l": b["length"].to_numpy(),
            "n_br": r.stacks["n_br"].to_numpy() if len(r.stacks) else np.zeros(0, int)}


def gamma_ls(x: np.ndarray, bins: int, log_bins: bool) -> float:
    """Gamma shape fitted by least squares to a histogram (log-binned: on log densities)."""
    x = x[x > 0]
    edges = np.geomspace(x.min(), x.max(), bins + 1) if log_bins else np.linspace(0, x.max(), bins + 1)
    h, e = np.histogram(x, edges, density=True)
    c = np.sqrt(e[1:] * e[:-1]) if log_bins else 0.5 * (e[1:] + e[:-1])
    ok = h > 0

    def res(p):
        pdf = stats.gamma.pdf(c[ok], p[0], scale=np.exp(p[1]))
        return np.log(np.maximum(pdf, 1e-300)) - np.log(h[ok]) if log_bins else pdf - h[ok]

    a0, _, s0 = stats.gamma.fit(x, floc=0)
    return float(optimize.least_squares(res, [a0, np.log(s0)],
                                        bounds=([0.01, -30], [50, 30])).x[0])


def summarize(rows: list, n_segments: int) -> dict:
    """The laws' shapes and the short-branch shares of one definition."""
    cat = {k: np.concatenate([r[k] for r in rows]) for k in ("e", "eb", "ec", "l", "n_br")}
    e_tot = np.array([r["e"].sum() for r in rows])
    n_l = np.array([len(r["n_br"]) for r in rows])
    n_b = np.array([r["n_br"].sum() for r in rows])

    def mle(x):
        return stats.gamma.fit(x[x > 0], floc=0)

    a_e, _, chi_e = mle(cat["e"])
    out = {"alpha_e": a_e, "chi_e": chi_e, "mean_e": cat["e"].mean(),
           "alpha_eb": mle(cat["eb"])[0], "alpha_ec": mle(cat["ec"])[0],
           "alpha_l": mle(cat["l"])[0], "mean_l": cat["l"].mean(),
           "alpha_E": mle(e_tot)[0], "n_br_per_config": n_b.mean(), "n_l_per_config": n_l.mean(),
           "nbr_nl": float(np.mean(n_b / np.maximum(n_l, 1))),
           "stacks_one_branch": float(np.mean(cat["n_br"] == 1)),
           "l_below_1_segment": float(np.mean(cat["l"] < 1.0 / n_segments)),
           "l_below_3_segments": float(np.mean(cat["l"] < 3.0 / n_segments)),
           "e_below_10": float(np.mean(cat["e"] < 10)), "e_below_50": float(np.mean(cat["e"] < 50))}
    out["aE_ae"] = out["alpha_E"] / a_e
    for name in ("e", "l"):
        out[f"alpha_{name}_ls_lin"] = gamma_ls(cat[name], 20, False)
        out[f"alpha_{name}_ls_log"] = gamma_ls(cat[name], 20, True)
    return out


def paper_row(n_segments: int) -> dict:
    """What the paper's Gamma laws put below the same limits."""
    g_l = stats.gamma(PAPER["alpha_l"], scale=PAPER["chi_l"])
    g_e = stats.gamma(PAPER["alpha_e"], scale=PAPER["chi_e"])
    return {"definition": "paper (its Gamma laws)", "alpha_e": PAPER["alpha_e"],
            "chi_e": PAPER["chi_e"], "mean_e": g_e.mean(), "alpha_eb": PAPER["alpha_eb"],
            "alpha_ec": PAPER["alpha_ec"], "alpha_l": PAPER["alpha_l"], "mean_l": g_l.mean(),
            "aE_ae": PAPER["aE_ae"], "nbr_nl": PAPER["nbr_nl"],
            "n_br_per_config": PAPER["n_br_per_config"],
            "l_below_1_segment": g_l.cdf(1.0 / n_segments),
            "l_below_3_segments": g_l.cdf(3.0 / n_segments),
            "e_below_10": g_e.cdf(10), "e_below_50": g_e.cdf(50)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    out_dir = Path(__file__).resolve().parent / "out"
    ap.add_argument("quench", type=Path, nargs="?",
                    help="output folder of `foldstat quench` (default: run it)")
    ap.add_argument("--out", type=Path, default=out_dir / "branch_definitions.csv",
                    help="CSV of one row per definition (a chart beside it, .png)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--n-configs", type=int, default=120,
                    help="configurations of the quench run when none is given")
    ap.add_argument("--quick", action="store_true", help="12 configurations, default grid")
    ap.add_argument("--structure", action="store_true",
                    help="also keep fold caps / two-ended junctions (at the default delta)")
    args = ap.parse_args(argv)
    if args.quench is None:
        import subprocess
        n = 12 if args.quick else args.n_configs
        args.quench = out_dir / "branch_definitions" / f"quench_{n}"
        subprocess.run([sys.executable, "-m", "simulate", "quench", "--n-configs", str(n),
                        "--lambda", "7e5", "--noise", "750", "--segments", "300", "--seed", "1",
                        "--workers", str(max(1, args.workers)), "--out", str(args.quench)],
                       check=True)
    rods, lam = load_rods(args.quench)
    n_seg = rods[0].shape[0] - 1
    grid = GRID[:4] if args.quick else GRID
    plan = [(f"delta {f:g} seg, min_run {m:g} delta", f, m, False, False) for f, m in grid]
    if args.structure:
        plan += [(f"fold caps kept, min_run {m:g} delta", 0.5, m, True, False) for m in (3.0, 0.01)]
        plan += [(f"two-ended junctions kept, min_run {m:g} delta", 0.5, m, False, True)
                 for m in (3.0, 0.01)]
        plan += [(f"both kept, min_run {m:g} delta", 0.5, m, True, True) for m in (3.0, 0.01)]
    rows = [paper_row(n_seg)]
    with ProcessPoolExecutor(max(1, args.workers)) as ex:
        for name, f, m, caps, two in plan:
            delta = f / n_seg
            res = list(ex.map(analyse, [(xy, lam, delta, m * delta, caps, two) for xy in rods],
                              chunksize=4))
            row = {"definition": name, "contact_distance_segments": f, "min_run_delta": m,
                   "fold_caps_kept": caps, "two_ended_kept": two, "n_configs": len(rods),
                   **summarize(res, n_seg)}
            rows.append(row)
            print(f"{name}: alpha_e {row['alpha_e']:.2f}, alpha_l {row['alpha_l']:.2f}, "
                  f"N_br/N_l {row['nbr_nl']:.2f}, l < 3 segments {row['l_below_3_segments']:.3f}",
                  flush=True)
    df = pd.DataFrame(rows)
    tmp = args.out.with_suffix(".tmp")
    df.to_csv(tmp, index=False, float_format="%.4g")
    tmp.replace(args.out)
    chart(df, args.out.with_suffix(".png"))
    return 0


def chart(df: pd.DataFrame, path: Path) -> None:
    """The laws' shapes and the counts against the contact cut-off (every run kept), beside
    the paper's values."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from crosssection.core.fileio import save_figure

    paper = df.iloc[0]
    d = df[(df["min_run_delta"] < 0.1) & ~df["fold_caps_kept"].astype(bool)
           & ~df["two_ended_kept"].astype(bool)].sort_values("contact_distance_segments")
    default = df.iloc[1]
    x = d["contact_distance_segments"]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for col, name, colour in (("alpha_e", "branch energy", "C0"), ("alpha_eb", "bending alone", "C1"),
                              ("alpha_l", "branch length", "C2")):
        a1.plot(x, d[col], "o-", color=colour, label=f"{name}, every run kept")
        a1.axhline(paper[col], color=colour, ls="--", lw=1)
        a1.plot([0.5], [default[col]], "*", ms=13, color=colour, mec="k")
    a1.set(xscale="log", xlabel="contact cut-off delta (segments L/N)", ylabel="Gamma shape alpha",
           title="Shapes (dashed: paper; star: default analysis)")
    a1.legend(fontsize=8)
    for col, name, colour in (("n_br_per_config", "branches per configuration", "C3"),
                              ("mean_e", "<e>", "C4")):
        a2.plot(x, d[col] / paper[col], "o-", color=colour, label=name)
        a2.plot([0.5], [default[col] / paper[col]], "*", ms=13, color=colour, mec="k")
    a2.axhline(1.0, color="k", ls="--", lw=1)
    a2.axhspan(0.8, 1.2, color="0.9", zorder=0)
    a2.set(xscale="log", xlabel="contact cut-off delta (segments L/N)", ylabel="ratio to the paper",
           title="Counts and mean energy (grey: within 20 %)")
    a2.legend(fontsize=8)
    save_figure(fig, path)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
