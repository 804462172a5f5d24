#!/usr/bin/env python
"""Coverage of the uncertainties of ``crosssection stats`` on ensembles of known truth.

Synthetic ensembles of G configurations: each configuration holds 20 + Poisson(30) stacks of
1 + Poisson(1.5 u) branches, branch lengths Gamma(2, 0.005 v) (units of L), branch energies
Gamma(0.5, 2 w), with u, v, w log-normal factors of the configuration (sigma 0.4, mean 1:
the branches of one rod are not independent draws), and a total energy E ~ Gamma(20, 1)
apart from them. Truth: N_l 50, pooled n_br 2.5, pooled l/L 0.01, pooled e 1, <E> 20,
alpha_E 20. For each G the share of ensembles whose ``± SE`` (``± 1.96 SE``) holds the
truth, and whose 95 % intervals of alpha_E and of alpha_E / alpha_e hold it (the latter's
truth is not 20 / 0.5 here: e is Gamma only within a configuration, so it is measured on
the pooled energies of a large ensemble).

Usage: python benchmarks/stats_coverage.py [--sizes 5,10,24,48] [--reps 100] [--seed 1]
"""
from __future__ import annotations

import argparse
import sys
import warnings

import numpy as np
import pandas as pd

TRUTH = {"N_l": 50.0, "n_br": 2.5, "l_L": 0.01, "e": 1.0, "E_tilde": 20.0, "alpha_E": 20.0}


def ensemble(G: int, rng):
    """One synthetic ensemble of G configurations (module docstring)."""
    from crosssection.stats import Ensemble

    cfg, br, st = [], [], []
    for c in range(G):
        u, v, w = np.exp(0.4 * rng.standard_normal(3) - 0.08)
        n_l = 20 + rng.poisson(30)
        n_br = 1 + rng.poisson(1.5 * u, n_l)
        n = int(n_br.sum())
        st.append(pd.DataFrame({"set": "syn", "config_id": str(c), "n_br": n_br,
                                "length_L": 0.02, "region": "none"}))
        km = rng.gamma(3.0, 10.0, n)
        br.append(pd.DataFrame({"set": "syn", "config_id": str(c),
                                "length_L": rng.gamma(2.0, 0.005 * v, n), "kappa_m_L": km,
                                "kappa_plus_L": km, "e": rng.gamma(0.5, 2.0 * w, n),
                                "region": "none", "n_br": np.repeat(n_br, n_br),
                                "l_min_L": 0.0}))
        cfg.append({"set": "syn", "config_id": str(c), "N_l": n_l, "N_br": n,
                    "n_voids": 0, "epsilon": 3.0, "E": rng.gamma(20.0, 1.0)})
    voids = pd.DataFrame(columns=["set", "config_id", "area_L2", "perimeter_L",
                                  "shape_ratio", "n_edges", "s_min_L2"])
    return Ensemble(pd.DataFrame(cfg), pd.concat(br, ignore_index=True),
                    pd.concat(st, ignore_index=True), voids)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="5,10,24,48")
    ap.add_argument("--reps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    from crosssection.stats import StatsOptions, compute_stats
    from crosssection.stats.tables import gamma_shape_mle

    big = ensemble(2000, np.random.default_rng(args.seed + 99))
    e = big.branches["e"].to_numpy(float)
    ratio_truth = 20.0 / float(gamma_shape_mle(e.mean(), np.log(e).mean()))
    print(f"alpha_E / alpha_e of the pooled energies (2000 configurations): {ratio_truth:.1f}")
    for G in (int(g) for g in args.sizes.split(",")):
        rows = []
        for i in range(args.reps):
            ens = ensemble(G, np.random.default_rng([args.seed, G, i]))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = compute_stats(ens, StatsOptions(seed=i, gof=False, quantities=("e", "E")))
            m, mi, d = r.macro.iloc[0], r.micro.iloc[0], r.dof.iloc[0]
            row = {k: src[k] for k, src in (("N_l", m), ("n_br", m), ("l_L", m), ("e", mi),
                                            ("E_tilde", mi))}
            row.update({f"{k}_se": src[f"{k}_se"] for k, src in (
                ("N_l", m), ("n_br", m), ("l_L", m), ("e", mi), ("E_tilde", mi))})
            row.update(aE_lo=mi["alpha_E_lo"], aE_hi=mi["alpha_E_hi"],
                       r_lo=d["alpha_E_over_alpha_e_lo"], r_hi=d["alpha_E_over_alpha_e_hi"])
            rows.append(row)
        df = pd.DataFrame(rows)
        out = [f"G = {G:3d} ({args.reps} ensembles):"]
        for k in ("N_l", "n_br", "l_L", "e", "E_tilde"):
            z = (df[k] - TRUTH[k]) / df[f"{k}_se"]
            out.append(f"{k} {np.mean(abs(z) < 1):.2f}/{np.mean(abs(z) < 1.96):.2f}")
        aE = (df["aE_lo"] <= TRUTH["alpha_E"]) & (TRUTH["alpha_E"] <= df["aE_hi"])
        rr = (df["r_lo"] <= ratio_truth) & (ratio_truth <= df["r_hi"])
        out.append(f"alpha_E 95 % {aE.mean():.2f}, alpha_E/alpha_e 95 % {rr.mean():.2f}")
        print("  ".join(out), flush=True)
    print("(pairs: share within 1 SE / within 1.96 SE; nominal 0.68 / 0.95)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
