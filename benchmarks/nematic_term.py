#!/usr/bin/env python
"""What the Powell protocol's nematic term does to the simulated distributions.

The paper models self-contacts "temporarily" as a nematic interaction ``u sin^2 alpha``
between touching segments, with ``u`` in 50-150 ("its precise value did not affect the
resulting configurations"), in 2 early runs of 10 and never in the last (section "Numerical
simulations", "Search for local minima"): it lets branches in contact align and slide along
one another. Whether it is a lever for the shapes of the laws that the default quench misses
(alpha_e, alpha_l, N_br/N_l; docs/validation/simulator/README.md, "Fidelity") is measured here:
the paper's ensemble (Lambda = 7e5, D = 750, N = 300) quenched from the same starts (same
``--seed``: configuration ``c`` starts from the same shape in every variant) with

==============  ===================================================================
variant         nematic term
==============  ===================================================================
default         runs 1 and 2, u = 100 (the package's default, the paper's protocol)
none            never (u = 0)
u 50, u 150     runs 1 and 2, the ends of the paper's range
u 1000          runs 1 and 2, ten times the paper's
runs 0-8        u = 100 in every run but the last
touching 0.5,   runs 1 and 2, segments "touching" within half a segment or 3 segments
3 segments      instead of one (``--nematic-cutoff``), u = 100 and, for 3, u = 1000
==============  ===================================================================

Each variant is ``python -m simulate quench ... --nematic-runs R --u U`` into ``WORK/<name>``
(resumed when there), analysed by the default contact analysis (the quench's own tables).
Per variant: the paper's simulation statistics (set 5 of its tables, and Rg = 0.05 from its
text): <E~>, Rg, N_br per configuration, N_br/N_l, <e>, alpha_e and chi_e (Gamma, maximum
likelihood, ``floc=0``), the branch-length Gamma shape alpha_l, alpha_E, <kappa_m> L, <s>/L^2,
<sqrt(s)/p> and <S>/L^2 (the summed area of a configuration's voids, the paper's "surface
occupied by the open rod"), with 95 % bootstrap intervals over configurations (their branches, stacks and
voids resampled with them); and per configuration the change from the default variant (the
same start): the energy reached and N_br/N_l, paired. Beside them, the share of the rod's
convex hull that its voids fill (median over configurations) and the stack length bounding
them per configuration (the sum of the void perimeters), to set <s>/L^2 against the area the
rods span.

Usage::

    python benchmarks/nematic_term.py [--n-configs 120] [--seed 1] [--workers 2]
        [--work benchmarks/out/nematic_term] [--out docs/validation/simulator/nematic_term.csv]
        [--quick]

Writes the CSV (one row per variant and the paper's) and a chart beside it (``.png``).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats
from scipy.spatial import ConvexHull

from crosssection.core.fileio import atomic_path
from crosssection.stats.tables import PAPER_MACRO, PAPER_MICRO

HERE = Path(__file__).resolve().parent
#: (name, Powell runs with the nematic term, u, touching distance in segments: None = one)
VARIANTS = [("default", "1,2", 100.0, None), ("none", "", 0.0, None),
            ("u 50", "1,2", 50.0, None), ("u 150", "1,2", 150.0, None),
            ("u 1000", "1,2", 1000.0, None), ("runs 0-8", "0,1,2,3,4,5,6,7,8", 100.0, None),
            ("touching 0.5 segment", "1,2", 100.0, 0.5), ("touching 3 segments", "1,2", 100.0, 3.0),
            ("touching 3 segments, u 1000", "1,2", 1000.0, 3.0)]
N_SEGMENTS = 300
_SIM_MACRO, _SIM_MICRO = PAPER_MACRO.iloc[-1], PAPER_MICRO.iloc[-1]  # set 5: simulations
#: The paper's simulations: its tables' set 5, and from its text Rg, the branch count (4676
#: branches in 252 configurations), alpha_l and S, the area its voids fill per configuration
PAPER = {"E": float(_SIM_MICRO["E_tilde"]), "rg": 0.05, "n_br_per_config": 4676 / 252,
         "nbr_nl": float(_SIM_MACRO["n_br"]), "e": float(_SIM_MICRO["e"]),
         "alpha_e": float(_SIM_MICRO["alpha_e"]), "chi_e": float(_SIM_MICRO["chi_e"]),
         "alpha_l": 0.4, "alpha_E": float(_SIM_MICRO["alpha_E"]),
         "kappa_m_L": float(_SIM_MICRO["kappa_m_L"]), "s_L2": float(_SIM_MACRO["s_L2"]),
         "S_L2": 4e-3, "sqrt_s_over_p": float(_SIM_MACRO["sqrt_s_over_p"])}
STATS = list(PAPER)
LABELS = {"E": r"$\langle\tilde E\rangle$", "rg": r"$R_g$", "n_br_per_config": r"$N_{br}$",
          "nbr_nl": r"$N_{br}/N_l$", "e": r"$\langle e\rangle$", "alpha_e": r"$\alpha_e$",
          "chi_e": r"$\chi_e$", "alpha_l": r"$\alpha_\ell$", "alpha_E": r"$\alpha_E$",
          "kappa_m_L": r"$\langle\kappa_m\rangle L$", "s_L2": r"$\langle s\rangle/L^2$",
          "S_L2": r"$\langle S\rangle/L^2$",
          "sqrt_s_over_p": r"$\langle\sqrt{s}/p\rangle$"}


def run_variant(work: Path, name: str, runs: str, u: float, touch, *, n_configs: int,
                seed: int, workers: int) -> Path:
    """Quench one variant into ``work/<name>`` (resumed when already there)."""
    out = work / name.replace(" ", "_").replace(",", "")
    cmd = [sys.executable, "-m", "simulate", "quench", "--n-configs", str(n_configs),
           "--lambda", "7e5", "--noise", "750", "--segments", str(N_SEGMENTS), "--seed",
           str(seed), "--nematic-runs", runs, "--u", repr(u), "--workers", str(workers),
           "--out", str(out), "--no-progress"]
    if touch is not None:
        cmd += ["--nematic-cutoff", repr(touch / N_SEGMENTS)]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return out


def load(folder: Path) -> dict:
    """The quench's tables, keyed by configuration."""
    t = {"configs": pd.read_csv(folder / "configs.csv").set_index("config_id")}
    for k in ("branches", "stacks", "voids"):
        t[k] = pd.read_csv(folder / f"{k}.csv")
    # how much of the area the rod spans its voids fill, and how much stack bounds them
    with np.load(folder / "rods.npz") as rods:
        hull = {int(k.split("_")[-1]): ConvexHull(rods[k]).volume for k in rods.files}
    cfg = t["configs"]
    cfg["hull_area"] = pd.Series(hull).reindex(cfg.index)
    for col in ("area", "perimeter"):
        cfg[f"void_{col}"] = t["voids"].groupby("config_id")[col].sum().reindex(
            cfg.index, fill_value=0.0)
    t["by_config"] = {k: dict(tuple(t[k].groupby("config_id")))
                      for k in ("branches", "stacks", "voids")}
    return t


def _gamma(x: np.ndarray) -> tuple[float, float]:
    """Gamma shape and scale of the positive values (maximum likelihood, ``floc=0``); NaN when
    they do not vary (a resample of one configuration's total energy)."""
    x = x[x > 0]
    if len(x) < 2 or np.ptp(x) <= 1e-12 * np.max(x):
        return np.nan, np.nan
    a, _, scale = stats.gamma.fit(x, floc=0)
    return float(a), float(scale)


def statistics(t: dict, ids: np.ndarray) -> dict:
    """The paper's statistics over configurations ``ids`` (repeats allowed: a bootstrap)."""
    cfg = t["configs"].loc[ids]
    by = t["by_config"]
    empty = {k: t[k].iloc[0:0] for k in by}
    pick = {k: pd.concat([by[k].get(i, empty[k]) for i in ids]) for k in by}
    br, st, vo = pick["branches"], pick["stacks"], pick["voids"]
    e = br["energy"].to_numpy()
    length = br["length"].to_numpy()
    a_e, chi_e = _gamma(e)
    a_l, _ = _gamma(length)
    a_E, _ = _gamma(cfg["energy_total"].to_numpy())
    n_l = cfg["n_stacks"].to_numpy(float)
    n_b = cfg["n_branches"].to_numpy(float)
    return {"E": cfg["energy_total"].mean(), "rg": cfg["rg"].mean(), "n_br_per_config": n_b.mean(),
            "nbr_nl": float(np.mean(n_b[n_l > 0] / n_l[n_l > 0])), "e": e.mean(),
            "alpha_e": a_e, "chi_e": chi_e, "alpha_l": a_l, "alpha_E": a_E,
            "kappa_m_L": br["kappa_pm"].abs().mean(), "s_L2": vo["area"].mean(),
            "sqrt_s_over_p": vo["shape_ratio"].mean(),
            "S_L2": cfg["void_area"].mean(),
            "void_share_of_hull": float(np.median(cfg["void_area"] / cfg["hull_area"])),
            "void_perimeter_per_config": cfg["void_perimeter"].mean(),
            "stacks_one_branch": float(np.mean(st["n_br"] == 1))}


def summarize(t: dict, *, n_boot: int, seed: int) -> dict:
    """Statistics of a variant with 95 % bootstrap intervals over configurations."""
    ids = t["configs"].index.to_numpy()
    row = statistics(t, ids)
    rng = np.random.default_rng(seed)
    boot = [statistics(t, rng.choice(ids, len(ids))) for _ in range(n_boot)]
    for k in STATS:
        lo, hi = np.percentile([b[k] for b in boot], [2.5, 97.5])
        row[f"{k}_lo"], row[f"{k}_hi"] = lo, hi
    return row


def paired(t: dict, ref: dict) -> dict:
    """Per-configuration change from the default variant (same starts): energy, N_br/N_l."""
    a, b = t["configs"], ref["configs"]
    ids = a.index.intersection(b.index)
    dE = (a.loc[ids, "energy_total"] - b.loc[ids, "energy_total"]) / b.loc[ids, "energy_total"]
    r = lambda c: c.loc[ids, "n_branches"] / c.loc[ids, "n_stacks"].clip(lower=1)
    return {"paired_energy_change_median": float(np.median(dE)),
            "paired_nbr_nl_change_mean": float(np.mean(r(a) - r(b))),
            "same_stacks_share": float(np.mean(a.loc[ids, "n_stacks"].to_numpy()
                                               == b.loc[ids, "n_stacks"].to_numpy()))}


def chart(df: pd.DataFrame, path: Path) -> None:
    """Each statistic over the paper's, per variant, with its bootstrap interval."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sims = df[df["variant"] != "paper"]
    fig, ax = plt.subplots(figsize=(12, 5.5), constrained_layout=True)
    x = np.arange(len(STATS))
    width = 0.8 / len(sims)
    for i, (_, r) in enumerate(sims.iterrows()):
        val = np.array([r[k] / PAPER[k] for k in STATS])
        lo = np.array([r[f"{k}_lo"] / PAPER[k] for k in STATS])
        hi = np.array([r[f"{k}_hi"] / PAPER[k] for k in STATS])
        ax.errorbar(x - 0.4 + (i + 0.5) * width, val, yerr=[val - lo, hi - val], fmt="o",
                    ms=4, capsize=2, label=r["variant"])
    ax.axhspan(0.8, 1.2, color="0.9", zorder=0)
    ax.axhline(1.0, color="0.4", lw=0.8)
    ax.set_yscale("log")
    ax.set_xticks(x, [LABELS[k] for k in STATS])
    ax.set_ylabel("simulation / paper (grey: within 20 %)")
    ax.set_title("Nematic term of the Powell protocol: the paper's simulation statistics\n"
                 f"({int(sims['n_configs'].iloc[0])} configurations per variant, same starts, "
                 "95 % bootstrap over configurations)")
    ax.legend(title="nematic term", fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n-configs", type=int, default=120)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--n-boot", type=int, default=200)
    ap.add_argument("--work", type=Path, default=HERE / "out" / "nematic_term")
    ap.add_argument("--out", type=Path, default=HERE / "out" / "nematic_term.csv")
    ap.add_argument("--quick", action="store_true",
                    help="6 configurations, 20 resamples, default and none only")
    args = ap.parse_args(argv)
    variants = VARIANTS[:2] if args.quick else VARIANTS
    n_configs = 6 if args.quick else args.n_configs
    n_boot = 20 if args.quick else args.n_boot
    tables = {}
    for name, runs, u, touch in variants:
        folder = run_variant(args.work, name, runs, u, touch, n_configs=n_configs,
                             seed=args.seed, workers=args.workers)
        tables[name] = load(folder)
    rows = [{"variant": "paper", **PAPER}]
    for name, runs, u, touch in variants:
        row = {"variant": name, "nematic_runs": runs or "none", "u": u,
               "touching_segments": 1.0 if touch is None else touch,
               "n_configs": len(tables[name]["configs"]),
               **summarize(tables[name], n_boot=n_boot, seed=args.seed),
               **paired(tables[name], tables["default"])}
        rows.append(row)
        print(f"{name:28s} <E> {row['E']:6.0f}  Rg {row['rg']:.4f}  N_br/N_l {row['nbr_nl']:.2f}  "
              f"alpha_e {row['alpha_e']:.2f} [{row['alpha_e_lo']:.2f}, {row['alpha_e_hi']:.2f}]  "
              f"alpha_l {row['alpha_l']:.2f}  <e> {row['e']:.0f}  N_br {row['n_br_per_config']:.1f}  "
              f"paired dE {row['paired_energy_change_median']:+.3f}", flush=True)
    df = pd.DataFrame(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out) as tmp:
        df.to_csv(tmp, index=False, float_format="%.4g")
    chart(df, args.out.with_suffix(".png"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
