"""Synthetic inputs of known statistics for the ``stats`` subcommand (tests, benchmarks, demos).

``write_demo_batch`` writes a batch output (``index.csv`` and ``<set>/<stem>/`` folders in the
schema of :mod:`crosssection.core.schema`, lengths in mm); ``write_demo_simulation`` writes a
``simulate quench`` ensemble (``configs.csv``, ``branches.csv``, ``voids.csv``, units of L).
The laws are the paper's: exponential branch lengths (experiments) above l_min, Gamma branch
energies, log-normal void areas above s_min, Gaussian shape ratios, n_br >= 1 with geometric
(discrete exponential) law.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.fileio import write_csv
from crosssection.core.schema import write_tables


def _trunc_exp(rng, mu, cut, n):
    return cut + rng.exponential(mu, n)  # memoryless: exponential above the cut


def demo_image_tables(rng, *, rod_length_mm=2000.0, n_stacks=40, nbr_mean=3.0,
                      length_mu_L=3e-3, l_min_mm=1.0, e_alpha=0.3, e_chi=700.0,
                      area_mu=-11.0, area_sigma=1.0, s_min_mm2=1.0, p_bulk=0.4,
                      epsilon=10.0):
    """Summary dict and schema tables of one synthetic image.

    Returns
    -------
    (summary, tables)
    """
    L = float(rod_length_mm)
    n_br = rng.geometric(1.0 / nbr_mean, n_stacks)  # >= 1, mean nbr_mean (discrete exponential)
    stack_region = np.where(rng.uniform(size=n_stacks) < p_bulk, "bulk", "periphery")
    stacks = pd.DataFrame({
        "stack_id": np.arange(n_stacks), "junction_a": -1, "junction_b": -1,
        "length_mm": rng.exponential(length_mu_L * L, n_stacks) + l_min_mm,
        "width_mm": 0.1 * n_br, "n_br": n_br, "region": stack_region,
        "mid_x_px": 0.0, "mid_y_px": 0.0})
    sid = np.repeat(np.arange(n_stacks), n_br)
    nb = sid.size
    length_mm = _trunc_exp(rng, length_mu_L * L, l_min_mm, nb)
    kappa_m = rng.exponential(1.0 / (length_mu_L * L), nb) * (1 + 0.3 * rng.uniform(size=nb))
    energy = rng.gamma(e_alpha, e_chi, nb)
    branches = pd.DataFrame({
        "branch_id": np.arange(nb), "stack_id": sid, "length_mm": length_mm,
        "kappa_pm": kappa_m * rng.choice([-1, 1], nb), "kappa_plus": kappa_m, "kappa_m": kappa_m,
        "energy": energy, "region": stack_region[sid]})
    n_voids = max(3, n_stacks // 3)
    s_min_L2 = s_min_mm2 / L ** 2
    area_L2 = np.exp(rng.normal(area_mu, area_sigma, 4 * n_voids))
    area_L2 = area_L2[area_L2 >= s_min_L2][:n_voids]
    if area_L2.size < 3:
        area_L2 = s_min_L2 * (1 + rng.exponential(1.0, 3))
    area_mm2 = area_L2 * L ** 2
    ratio = rng.normal(0.19, 0.037, area_mm2.size)
    voids = pd.DataFrame({
        "void_id": np.arange(area_mm2.size), "area_mm2": area_mm2,
        "perimeter_mm": np.sqrt(area_mm2) / ratio, "shape_ratio": ratio,
        "n_edges": 3 + rng.poisson(2, area_mm2.size), "centroid_x_px": 0.0,
        "centroid_y_px": 0.0})
    junctions = pd.DataFrame({"junction_id": [], "x_px": [], "y_px": [], "n_stacks": []})
    summary = {"n_junctions": 0, "n_stacks": int(n_stacks), "n_branches": int(nb),
               "n_voids": int(area_mm2.size), "mean_branches_per_stack": float(nb / n_stacks),
               "rod_length_mm": L, "epsilon": float(epsilon),
               "total_energy": float(energy.sum()), "hole": None, "timings_s": {}}
    return summary, {"junctions": junctions, "stacks": stacks, "branches": branches,
                     "voids": voids}


def write_demo_batch(out_dir, *, sets=None, n_images=8, seed=0) -> Path:
    """Write a synthetic batch output.

    Parameters
    ----------
    out_dir : path
    sets : dict, optional
        Set name -> keyword arguments of :func:`demo_image_tables` (default: two sets).
    n_images : int
        Images per set.
    seed : int

    Returns
    -------
    Path
        ``out_dir``.
    """
    out = Path(out_dir)
    sets = sets or {"set1": {"nbr_mean": 4.0, "n_stacks": 60, "length_mu_L": 2.5e-3},
                    "set3": {"nbr_mean": 2.5, "n_stacks": 30, "length_mu_L": 1e-2,
                             "e_alpha": 0.4, "e_chi": 330.0}}
    rng = np.random.default_rng(seed)
    rows = []
    for name, kw in sets.items():
        for i in range(n_images):
            kw_i = dict(kw)
            kw_i.setdefault("rod_length_mm", float(rng.uniform(1500, 2500)))
            kw_i["n_stacks"] = int(kw.get("n_stacks", 40) * rng.uniform(0.7, 1.3))
            kw_i.setdefault("epsilon", kw_i["rod_length_mm"] / (2 * np.pi * 20.0))
            summary, tables = demo_image_tables(rng, **kw_i)
            folder = out / name / f"img{i:03d}"
            write_tables(folder, summary, tables)
            rows.append({"image": f"img{i:03d}.png", "set": name, "status": "ok",
                         "output": f"{name}/img{i:03d}",
                         **{k: summary[k] for k in ("n_stacks", "n_branches", "n_voids",
                                                    "rod_length_mm", "epsilon")}})
    write_csv(out / "index.csv", pd.DataFrame(rows))
    return out


def write_demo_simulation(out_dir, *, n_configs=30, seed=0, length_alpha=0.4,
                          length_chi=0.12, e_alpha=0.31, e_chi=728.0) -> Path:
    """Write a synthetic ``simulate quench`` ensemble (units of L).

    Parameters
    ----------
    out_dir : path
    n_configs : int
    seed : int
    length_alpha, length_chi, e_alpha, e_chi : float
        Gamma laws of branch length and energy (paper, simulations).

    Returns
    -------
    Path
    """
    out = Path(out_dir)
    rng = np.random.default_rng(seed)
    cfg, brs, vos = [], [], []
    for k in range(n_configs):
        n_l = int(rng.integers(6, 14))
        n_br = int(2 * n_l + rng.integers(-1, 2))
        ln = rng.gamma(length_alpha, length_chi, n_br)
        kp = rng.gamma(2.5, 14.8, n_br)
        eb = rng.gamma(e_alpha, e_chi / 2, n_br)
        ec = rng.gamma(e_alpha, e_chi / 2, n_br)
        brs.append(pd.DataFrame({
            "config_id": k, "branch_id": np.arange(n_br), "length": ln, "kappa_plus": kp,
            "kappa_pm": kp * rng.uniform(-1, 1, n_br), "energy_bending": eb,
            "energy_confinement": ec, "energy": eb + ec}))
        nv = int(rng.integers(3, 8))
        area = np.exp(rng.normal(-7.5, 1.0, nv))
        ratio = rng.normal(0.17, 0.04, nv)
        vos.append(pd.DataFrame({"config_id": k, "area": area, "perimeter": np.sqrt(area) / ratio,
                                 "shape_ratio": ratio, "n_edges": 3 + rng.poisson(2, nv)}))
        e_tot = float((eb + ec).sum())
        cfg.append({"config_id": k, "seed": int(rng.integers(1 << 30)),
                    "rg": float(rng.uniform(0.05, 0.07)), "epsilon": float(rng.normal(2.3, 0.2)),
                    "energy_total": e_tot, "energy_bending": float(eb.sum()),
                    "energy_confinement": float(ec.sum()), "n_stacks": n_l,
                    "n_branches": n_br, "n_voids": nv, "method": "powell", "wall_s": 1.0})
    write_csv(out / "configs.csv", pd.DataFrame(cfg))
    write_csv(out / "branches.csv", pd.concat(brs, ignore_index=True))
    write_csv(out / "voids.csv", pd.concat(vos, ignore_index=True))
    return out
