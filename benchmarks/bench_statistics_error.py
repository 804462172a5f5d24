#!/usr/bin/env python
"""Does the image analysis move the ensemble statistics by more than their own uncertainty?

An ensemble of quenched simulator rods (or, with ``--generator network``, of the network
generator's typical scans of ``benchmarks/robust_sweep.py``) (the atlas's short quench: 300 segments, 10 Powell
runs, Lambda = 7e5), each rendered as a scan (:func:`simulate.atlas.render_rod`) and analysed
with default settings (scale and calibration given, and the hole where the render has one). The same statistics are computed
from the truth tables and from the analysis tables:

- ``alpha_e``: the Gamma shape of the branch energies (paper Eq. (3); maximum likelihood,
  :func:`crosssection.stats.fits.fit_family`), with its 95 % bootstrap interval;
- ``alpha_l``: the Gamma shape of the branch lengths;
- ``<e>``: the mean branch energy;
- ``<n_br>``: the mean number of branches per stack;
- ``N_br / N_l``: branches per stack summed over configurations (the slope of paper
  Eq. (12) through the origin).

Intervals of the means and ratios are percentile bootstraps over configurations (the unit
that is independent). The question (the validation atlas's): is the analysis' value inside
the interval the truth's own fit gives, i.e. is the image-analysis error smaller than the
statistical uncertainty of an ensemble of this size?

Usage: python benchmarks/bench_statistics_error.py [--n-configs 24] [--seed 200]
       [--workers 2] [--generator renders|network] [--out benchmarks/out]
Writes OUT/statistics_error_GENERATOR.csv (one row per statistic) and
OUT/statistics_error_GENERATOR_configs.csv (one row per configuration).
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

N_BOOT = 500


def one_config(seed: int, generator: str = "renders") -> dict:
    """Make and analyse one scene; the per-branch and per-stack arrays of both sides."""
    import crosssection

    if generator == "renders":
        from simulate.atlas import quench_rod, render_rod

        scene = render_rod(quench_rod(seed), seed)
    else:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import robust_sweep

        scene = robust_sweep.make_network_scene(seed, robust_sweep.scene_options("typical", seed))
    p = scene.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=scene.calibration)
    if p.get("hole_radius_mm") and p.get("hole_center_px"):
        kw.update(hole_radius_mm=p["hole_radius_mm"], hole_center_px=tuple(p["hole_center_px"]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(scene.rgb, **kw)
    out = {"seed": seed}
    for side, tables in (("truth", scene.tables), ("image", res.tables)):
        br, st = tables["branches"], tables["stacks"]
        out[side] = {"energy": br["energy"].to_numpy(float),
                     "length_mm": br["length_mm"].to_numpy(float),
                     "n_br": st["n_br"].to_numpy(int)}
    return out


def _boot_ci(configs, stat, rng, n_boot=N_BOOT):
    """Percentile 95 % interval of ``stat(list of configs)`` resampling configurations."""
    n = len(configs)
    draws = [stat([configs[i] for i in rng.integers(0, n, n)]) for _ in range(n_boot)]
    return tuple(np.nanpercentile(draws, [2.5, 97.5]))


def _gamma_alpha(x, seed):
    from crosssection.stats.fits import fit_family

    x = np.asarray(x, float)
    x = x[x > 0]
    r = fit_family(x, "gamma", n_boot=N_BOOT, seed=seed, gof=False)
    lo, hi = r.ci.get("alpha", (np.nan, np.nan)) if r.ci else (np.nan, np.nan)
    return float(r.params["alpha"]), float(lo), float(hi)


def statistics(configs, side, seed) -> list[dict]:
    """Rows (statistic, value, ci_lo, ci_hi) of one side."""
    rng = np.random.default_rng(seed)
    sides = [c[side] for c in configs]
    e = np.concatenate([s["energy"] for s in sides])
    ell = np.concatenate([s["length_mm"] for s in sides])
    rows = []
    for name, x in (("alpha_e", e), ("alpha_l", ell)):
        v, lo, hi = _gamma_alpha(x, seed)
        rows.append({"statistic": name, "value": v, "ci_lo": lo, "ci_hi": hi})

    def mean_e(cs):
        return float(np.mean(np.concatenate([c["energy"] for c in cs])))

    def mean_nbr(cs):
        return float(np.mean(np.concatenate([c["n_br"] for c in cs])))

    def ratio(cs):
        return float(sum(c["n_br"].sum() for c in cs) / sum(len(c["n_br"]) for c in cs))

    def per_config_ratio(cs):
        return float(np.mean([c["n_br"].sum() / max(len(c["n_br"]), 1) for c in cs]))

    for name, f in (("mean_e", mean_e), ("mean_n_br", mean_nbr), ("N_br/N_l", ratio),
                    ("N_br/N_l per configuration", per_config_ratio)):
        lo, hi = _boot_ci(sides, f, rng)
        rows.append({"statistic": name, "value": f(sides), "ci_lo": lo, "ci_hi": hi})
    for r in rows:
        r["side"] = side
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n-configs", type=int, default=24)
    ap.add_argument("--seed", type=int, default=200)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--generator", choices=("renders", "network"), default="renders",
                    help="simulator renders, or the network generator's typical scans "
                         "(benchmarks/robust_sweep.py)")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = list(range(args.seed, args.seed + args.n_configs))
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as ex:
        configs = list(ex.map(one_config, seeds, [args.generator] * len(seeds)))
    rows = statistics(configs, "truth", args.seed) + statistics(configs, "image", args.seed)
    df = pd.DataFrame(rows)
    wide = df.pivot(index="statistic", columns="side", values=["value", "ci_lo", "ci_hi"])
    table = pd.DataFrame({
        "truth": wide["value"]["truth"], "truth_ci_lo": wide["ci_lo"]["truth"],
        "truth_ci_hi": wide["ci_hi"]["truth"], "image": wide["value"]["image"],
        "image_ci_lo": wide["ci_lo"]["image"], "image_ci_hi": wide["ci_hi"]["image"]})
    table["rel_error"] = table["image"] / table["truth"] - 1.0
    table["half_ci_rel"] = (table["truth_ci_hi"] - table["truth_ci_lo"]) / 2 / table["truth"]
    table["image_inside_truth_ci"] = ((table["image"] >= table["truth_ci_lo"])
                                      & (table["image"] <= table["truth_ci_hi"]))
    table.insert(0, "n_configs", len(configs))
    table.insert(0, "generator", args.generator)
    table.to_csv(out / f"statistics_error_{args.generator}.csv")
    per = pd.DataFrame([{"seed": c["seed"], **{f"{side}_{k}": v for side in ("truth", "image")
                                                for k, v in (
        ("n_stacks", len(c[side]["n_br"])), ("n_branches", int(c[side]["n_br"].sum())),
        ("total_energy", float(c[side]["energy"].sum())))}} for c in configs])
    per.to_csv(out / f"statistics_error_{args.generator}_configs.csv", index=False)
    pd.set_option("display.width", 200)
    print(table.round(3).to_string())
    print(f"{len(configs)} configurations in {time.perf_counter() - t0:.0f} s -> "
          f"{out / f'statistics_error_{args.generator}.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
