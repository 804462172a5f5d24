#!/usr/bin/env python
"""Where the bending-energy error of the network generator's scans lies: fitted parts or
fork zones.

For the scenes of ``benchmarks/robust_sweep.py`` (network generator conditions, same seeds),
every stack the analysis finds is matched to a truth stack by its mid point (as
:func:`crosssection.truth.scoring.score` matches them). Along the truth centreline
(``Scene.paths_rc``, the generator's curve), the samples within ``--near-px`` of the stack's
*fitted* centreline (``CurvatureProfile.fit_start:fit_stop``) are the fitted part, the others
its fork zones and ends. Per scene, summed over matched stacks and weighted by n_br:

* ``fitted_ratio``: measured ``int kappa^2 ds`` over the fitted part (the scan's noise floor
  removed) / the truth's there;
* ``zone_ratio``: the same for the rest of each stack;
* ``window_truth_ratio``: the truth's curvature averaged over the paper's window (a box of
  ``5 n_br h``) / the truth, on the fitted part: what the window's averaging alone keeps;
* ``design_on_truth``: the estimator's design applied to the truth's own curvature (no
  pixels, no noise, no gate): the curvature averaged over the window in the fitted part, and
  at each fork end the line through those averages over ``w/2 .. 3 w/2`` from the fitted
  end, continued over the first ``w/2`` and the zone; over the whole matched stacks, / the
  truth there. What the design loses by itself, apart from the measurement;
* ``restored``: the total energy error once ``mu2 int kappa'^2`` is added over each fitted
  part (``mu2 = w^2 / 28`` for a least-squares parabola over ``w``, plus ``(m^2 - 1) / 12``
  px^2 for the ``m``-point sliding average before it; ``kappa'`` from the profile, its own noise
  floor measured by :func:`crosssection.stages.curvature.noise_variance` on it): the
  averaging restored to second order.

Usage: python benchmarks/energy_split.py [--conditions typical,thick_dense] [--per-condition 8]
       [--seed 100] [--near-px 3]
"""
from __future__ import annotations

import argparse
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fork_energy_share  # noqa: E402  (truth curvature of the generator's curves)
import robust_sweep  # noqa: E402  (the scene definitions are shared)

#: Second moment of the least-squares parabola's kernel on the curvature, over w^2.
PARABOLA_MU2 = 1.0 / 28.0


def _window_average(k, w_step, width):
    """``k`` averaged over a box of ``width`` (same units as the cumulative steps)."""
    s = np.cumsum(w_step)
    c = np.concatenate([[0.0], np.cumsum(k * w_step)])
    lo = np.searchsorted(s, s - width / 2)
    hi = np.searchsorted(s, s + width / 2, side="right")
    span = np.maximum(s[np.minimum(hi, len(s)) - 1] - s[lo] + w_step[lo], 1e-12)
    return (c[hi] - c[lo]) / span


def _design_on_truth(k, u, f0, f1, w):
    """``int kappa^2`` of the estimator's design applied to the true curvature ``k`` at arc
    ``u`` (mm) of a stack whose fitted part is ``[f0, f1]``, window ``w`` (module docstring)."""
    du = np.gradient(u)
    kb = _window_average(k, du, w)
    fitted = (u >= f0) & (u <= f1)
    inner = (u >= f0 + w / 2) & (u <= f1 - w / 2)
    est = np.where(fitted, kb, 0.0)
    for zone, d in ((u < f0 + w / 2, u - f0), (u > f1 - w / 2, f1 - u)):
        sel = (d >= w / 2) & (d <= 1.5 * w) & inner
        if sel.sum() >= 3:
            slope, icpt = np.polyfit(d[sel], kb[sel], 1)
            est[zone] = icpt + slope * d[zone]
        else:  # no centred fit: the fitted part's mean, as the estimator's nearest value
            est[zone] = kb[fitted].mean() if fitted.any() else 0.0
    return float((est * est * du).sum())


def split_scene(condition: str, seed: int, near_px: float = 3.0) -> dict:
    """The ratios of the module docstring for one scene."""
    import crosssection
    from crosssection.stages.curvature import default_smooth_px, noise_variance
    from crosssection.truth.scoring import match_stacks

    options = robust_sweep.scene_options(condition, seed)
    scene = robust_sweep.make_network_scene(seed, options)
    p = scene.params
    px, h = float(p["px_per_mm"]), float(p["thickness_mm"] * p["px_per_mm"])
    kw = dict(px_per_mm=px, thickness_mm=p["thickness_mm"], calibration=scene.calibration)
    if options["hole_given"]:
        kw.update(hole_radius_mm=p["hole_radius_mm"], hole_center_px=tuple(p["hole_center_px"]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(scene.rgb, **kw)
    so, st = res.stacks, scene.tables["stacks"].reset_index(drop=True)
    r, c = match_stacks(so, st, match_px=3 * h, px_per_mm=px)
    n_out = so["n_br"].to_numpy(int)
    # the derivative's noise floor, measured as the curvature's is
    dprofs = []
    for prof in res.profiles:
        t0, t1 = prof.fit_start, prof.fit_stop
        kd = np.zeros_like(prof.kappa_per_mm)
        if t1 - t0 >= 5:
            kd[t0:t1] = np.gradient(prof.kappa_per_mm[t0:t1], prof.s_mm[t0:t1])
        dprofs.append(replace(prof, kappa_per_mm=kd))
    vd = noise_variance(dprofs, n_out, thickness_px=h, px_per_mm=px)
    m = default_smooth_px(h)
    acc = dict.fromkeys(("t_fit", "m_fit", "t_rest", "m_rest", "t_win", "restore", "t_all",
                         "design"), 0.0)
    for ro, ct in zip(r, c):
        prof, nb = res.profiles[ro], max(1, int(n_out[ro]))
        t0, t1 = prof.fit_start, prof.fit_stop
        path = np.asarray(scene.paths_rc[ct], float)
        if t1 - t0 < 5 or len(path) < 8:
            continue
        _, k, _, w, pts = fork_energy_share._curvature(path)
        k, w, pts = k[2:-2] * px, w[2:-2] / px, pts[2:-2]  # 1/mm, mm (the two end samples:
        # a wall stack's drawn path ends with a corner onto its junction point)
        near = cKDTree(prof.rc_px[t0:t1]).query(pts)[0] < near_px
        n_true = int(st["n_br"][ct])
        s_mm, kap = prof.s_mm, prof.kappa_per_mm
        f = kap * kap
        fitted_len = float(s_mm[t1 - 1] - s_mm[t0])
        m_fit = float(np.trapezoid(f[t0:t1], s_mm[t0:t1])) - prof.noise_var_per_mm2 * fitted_len
        m_all = float(np.trapezoid(f, s_mm)) - prof.noise_var_per_mm2 * prof.length_mm
        win_mm = 5.0 * nb * h / px
        k_win = _window_average(k, w, win_mm)
        acc["t_fit"] += n_true * float((k[near] ** 2 * w[near]).sum())
        acc["t_rest"] += n_true * float((k[~near] ** 2 * w[~near]).sum())
        acc["t_win"] += n_true * float((k_win[near] ** 2 * w[near]).sum())
        u = np.cumsum(w)
        idx = np.flatnonzero(near)
        if len(idx) >= 5:
            f0, f1 = u[idx[0]], u[idx[-1]]
            w_des = min(5.0 * nb * h, 0.5 * (f1 - f0) * px) / px
            acc["design"] += n_true * _design_on_truth(k, u, f0, f1, w_des)
            acc["t_all"] += n_true * float((k * k * w).sum())
        acc["m_fit"] += nb * m_fit
        acc["m_rest"] += nb * (m_all - m_fit)
        w_fit = min(5.0 * nb * h, 0.5 * fitted_len * px) / px
        mu2 = PARABOLA_MU2 * w_fit ** 2 + (m * m - 1) / 12.0 / px ** 2
        kd = dprofs[ro].kappa_per_mm[t0:t1]
        acc["restore"] += nb * mu2 * max(float(np.trapezoid(kd * kd, s_mm[t0:t1]))
                                         - vd[nb] * fitted_len, 0.0)
    e_true = float(scene.summary["total_energy"])
    e_out = float(res.summary["total_energy"])
    L = float(res.summary["rod_length_used_mm"] if res.summary.get("rod_length_used_mm")
              else res.summary["rod_length_mm"])
    return {"condition": condition, "seed": seed,
            "fitted_ratio": acc["m_fit"] / acc["t_fit"] if acc["t_fit"] else np.nan,
            "zone_ratio": acc["m_rest"] / acc["t_rest"] if acc["t_rest"] else np.nan,
            "window_truth_ratio": acc["t_win"] / acc["t_fit"] if acc["t_fit"] else np.nan,
            "design_on_truth": acc["design"] / acc["t_all"] if acc["t_all"] else np.nan,
            "truth_share_zones": acc["t_rest"] / (acc["t_fit"] + acc["t_rest"]),
            "energy_error": e_out / e_true - 1.0,
            "restored": (e_out + L * acc["restore"]) / e_true - 1.0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conditions", default="typical,thick_dense")
    ap.add_argument("--per-condition", type=int, default=8)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--near-px", type=float, default=3.0)
    args = ap.parse_args(argv)
    rows = [split_scene(cond, seed, args.near_px)
            for cond in args.conditions.split(",")
            for seed in range(args.seed, args.seed + args.per_condition)]
    df = pd.DataFrame(rows)
    pd.set_option("display.width", 200)
    print(df.round(3).to_string(index=False))
    print(df.drop(columns="seed").groupby("condition", sort=False).median().round(3)
          .to_string())
    return 0


if __name__ == "__main__":
    sys.exit(main())
