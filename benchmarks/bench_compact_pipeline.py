"""The pipeline on renders of compacted rods, where the experiments are (epsilon 14-30).

    python benchmarks/bench_compact_pipeline.py [--epsilon 19:4,14:3,30:3] [--segments 2000]
        [--n-configs 4] [--seed 1] [--conditions scan,clean,polyline]
        [--work benchmarks/out/compact_pipeline] [--out benchmarks/out] [--overlays]

For every epsilon E (``E:K``: K configurations, default ``--n-configs``):
``python -m simulate compact --epsilon E --segments N --n-configs K --seed S`` into
``WORK/epsE/sim`` (kept when already there), then every configuration rendered by
:func:`simulate.render.render_configuration` as ``python -m simulate render`` does (the wall is
the hole, h = 0.1 mm = 5 px at 50 px/mm, the generators' nonlinear calibration) under each
condition:

=========  ================================================================================
scan       the defaults: a real scan's defects and plate (``simulate.render.SCAN_DEFECTS``)
clean      ``--clean``: the drawing alone
polyline   clean, the stacks drawn as the analysis' polylines (``smooth="none"``): what the
           corners of an unsmoothed drawing do to the measured energy
passes     the defaults, the rod itself drawn (``draw="passes"``: every pass a stroke, the
           passes of a stack pressed together) instead of one band per stack
passes_    ``passes``, clean
clean
passes_    ``passes`` with the pressing smoothed over one rod segment (``pass_smooth=1``): the
smooth     drawn passes bend as the rod does (1.00-1.01 times its energy at epsilon = 19)
passes_    ``passes_smooth``, clean
smooth_
clean
=========  ================================================================================

Each scene is analysed with the calibration and the hole given, as a user who measured them
would (:func:`crosssection.truth.scoring.analyze_scene_folder`), and scored against its truth
(:func:`crosssection.truth.scoring.score`, junctions matched within 3 h). Per scene: exact n_br
fraction of the truth stack length, junction F1 (precision, recall), rod length and total
energy errors, and where the errors are: the share of the truth stack length left unmatched or
matched with a wrong n_br, n_br errors (of +-1) among the thick stacks (n_br >= 5), truth
stacks shorter than twice their band width (lumps in junction zones rather than bands) and the
missed truth junctions at one of them, the energy of matched stacks by n_br (truth and
measured) and of unmatched ones, and the share of the rod's energy at nodes turning more than
90 degrees (collapsed folds, drawn as band ends), and how much rod the bands draw (the sum of
n_br times the drawn stack length, over the rod length) and how much bending: the drawn
centrelines' ``sum n_br int kappa^2 ds`` over the rod's energy, in all and outside discs of
the widest band's width around every truth junction (``drawn_energy_ratio``, ``drawn_energy_ratio_outside``: the bending the
image holds, where the truth is the rod's). Times (wall): compaction
(``configs.csv`` wall_s), contact analysis, render, analysis.

Writes ``OUT/compact_pipeline.csv`` (one row per scene) and, with ``--overlays``,
``WORK/epsE/overlays/<config>_<condition>.png`` (the scan with missed truth junctions, extra
output junctions and stacks whose n_br is wrong). Prints the table of
``docs/validation/compact.md``.
"""
from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.fileio import write_csv
from crosssection.truth.scene import read_scene, write_scene
from crosssection.truth.scoring import (analyze_scene_folder, match_points, medial_fork_points,
                                         score)
from simulate.cli import main as simulate_main
from simulate.contacts import analyze_rod
from simulate.render import render_configuration

CONDITIONS = {"scan": {}, "clean": {"clean": True},
              "polyline": {"clean": True, "smooth": "none"},
              "passes": {"draw": "passes"}, "passes_clean": {"clean": True, "draw": "passes"},
              "passes_smooth": {"draw": "passes", "pass_smooth": 1.0},
              "passes_smooth_clean": {"clean": True, "draw": "passes", "pass_smooth": 1.0}}
TARGETS = {"n_br_exact_length_fraction": 0.85, "junction_f1": 0.90, "rod_length": 0.05,
           "total_energy": 0.25}
PX_PER_MM, THICKNESS_MM = 50.0, 0.1
THICK = 5  # n_br from which a stack counts as thick in the error breakdown


def _fold_share(xy) -> float:
    """Share of the discrete bending energy at nodes turning more than 90 degrees."""
    d = np.diff(xy, axis=0)
    dth = np.abs(np.diff(np.unwrap(np.arctan2(d[:, 1], d[:, 0]))))
    e = dth ** 2
    return float(e[dth > np.pi / 2].sum() / e.sum()) if e.sum() > 0 else 0.0


def _junction_discs(scene) -> tuple[np.ndarray, np.ndarray]:
    """Truth junctions (row, col) px and the widest band width meeting at each, px."""
    st = scene.tables["stacks"].reset_index(drop=True)
    jt = scene.tables["junctions"]
    width_px = st["width_mm"].to_numpy(float) * scene.params["px_per_mm"]
    widest = np.zeros(len(jt))
    row = {int(j): i for i, j in enumerate(jt["junction_id"].to_numpy(int))}
    for end in ("junction_a", "junction_b"):
        for j, wd in zip(st[end].to_numpy(int), width_px):
            if j in row:
                widest[row[j]] = max(widest[row[j]], wd)
    return jt[["y_px", "x_px"]].to_numpy(float), widest


def _drawn_energy(scene) -> tuple[float, float]:
    """The drawn bands' ``sum n_br int kappa^2 ds`` over the rod's energy: in all, and outside
    discs of the widest band's width around every truth junction.

    The curvature of each drawn centreline (``scene.paths_rc``, about one point per px) is its
    turning angle per unit arc; the rod's energy is the truth's ``total_energy`` (``L int
    kappa^2 ds`` summed over branches) over L.
    """
    from scipy.spatial.distance import cdist

    st = scene.tables["stacks"].reset_index(drop=True)
    px = scene.params["px_per_mm"]
    junctions, widest = _junction_discs(scene)
    total = outside = 0.0
    for k, path in enumerate(scene.paths_rc):
        p = np.asarray(path, float).reshape(-1, 2)
        d = np.diff(p, axis=0)
        ds = np.hypot(d[:, 0], d[:, 1])
        p, d, ds = p[1:][ds > 1e-9], d[ds > 1e-9], ds[ds > 1e-9]
        if len(ds) < 5:
            continue
        theta = np.unwrap(np.arctan2(d[:, 0], d[:, 1]))
        w = 0.5 * (ds[:-1] + ds[1:])
        f = (np.diff(theta) / w) ** 2 * w * px * int(st["n_br"][k])  # 1/mm
        total += f.sum()
        inside = (cdist(p[:-1], junctions) < widest).any(axis=1)
        outside += f[~inside].sum()
    rod = scene.summary["total_energy"] / scene.summary["rod_length_mm"]
    return total / rod, outside / rod


def _measured_outside(scene, result) -> float:
    """The analysis' ``sum n_br int kappa^2 ds`` outside the discs of :func:`_drawn_energy`
    (its curvature profiles, fork zones included, before the noise floor is removed), over
    the rod's energy."""
    from scipy.spatial.distance import cdist

    junctions, widest = _junction_discs(scene)
    outside = 0.0
    for prof, n in zip(result.profiles, result.stacks["n_br"].to_numpy(int)):
        if len(prof.s_mm) < 2:
            continue
        e = n * prof.kappa_per_mm ** 2 * np.gradient(prof.s_mm)
        outside += e[~(cdist(prof.rc_px, junctions) < widest).any(axis=1)].sum()
    return outside / (scene.summary["total_energy"] / scene.summary["rod_length_mm"])


def _rod_outside(xy, scene) -> float:
    """Share of the rod's discrete energy (``sum dtheta^2 / ds`` over its nodes, equal
    segments) at nodes outside the discs of :func:`_drawn_energy`, the rod placed as the
    render placed it (``origin_xy``, ``margin_px``, px per unit L)."""
    from scipy.spatial.distance import cdist

    p = scene.params
    px = ((np.asarray(xy, float) - np.asarray(p["origin_xy"], float))
          * p["rod_length_mm"] * p["px_per_mm"] + p["margin_px"])[:, ::-1]  # (row, col)
    d = np.diff(np.asarray(xy, float), axis=0)
    e = np.angle(np.exp(1j * np.diff(np.arctan2(d[:, 1], d[:, 0])))) ** 2
    junctions, widest = _junction_discs(scene)
    inside = (cdist(px[1:-1], junctions) < widest).any(axis=1)
    return float(e[~inside].sum() / e.sum()) if e.sum() > 0 else float("nan")


def _fork_f1(scene, pair, h_px: float) -> float:
    """Junction F1 against the truth junctions moved to where the drawn bands separate (the
    medial-axis forks of the bands drawn without defects,
    :func:`crosssection.truth.scoring.medial_fork_points`): the targets' placement, where the
    contact analysis' points lie inside merged ink."""
    st, jt = scene.tables["stacks"], scene.tables["junctions"]
    forks = medial_fork_points(scene.paths_rc, st["width_mm"] * scene.params["px_per_mm"],
                               st[["junction_a", "junction_b"]].to_numpy(int),
                               jt["junction_id"].to_numpy(int),
                               jt[["y_px", "x_px"]].to_numpy(float), scene.rgb.shape)
    out = pair[1]["junctions"][["x_px", "y_px"]].to_numpy(float)
    r, _ = match_points(out, forks[:, ::-1], 3 * h_px)
    return 2.0 * len(r) / (len(out) + len(forks)) if len(out) + len(forks) else 1.0


def _breakdown(pair, truth, h_px: float) -> dict:
    """Where the errors are (the scorer's matching rules): n_br errors, unmatched stacks,
    missed junctions, and the energy by kind of stack."""
    (_, out_t), (_, tru_t) = pair, truth
    so, st = out_t["stacks"], tru_t["stacks"]
    lim = np.maximum(3 * h_px, 0.25 * st["length_mm"].to_numpy(float) * PX_PER_MM)
    r, c = match_points(so[["mid_x_px", "mid_y_px"]].to_numpy(float),
                        st[["mid_x_px", "mid_y_px"]].to_numpy(float), lim)
    nbr_t = st["n_br"].to_numpy(int)
    length = st["length_mm"].to_numpy(float)
    # a stack shorter than twice its band's width is a lump in a junction zone, not a band
    stubby = length < 2.0 * st["width_mm"].to_numpy(float)
    err = so["n_br"].to_numpy(int)[r] - nbr_t[c]
    thick = nbr_t[c] >= THICK
    unmatched = np.setdiff1d(np.arange(len(st)), c)
    jo, jt = out_t["junctions"], tru_t["junctions"]
    rj, cj = match_points(jo[["x_px", "y_px"]].to_numpy(float),
                          jt[["x_px", "y_px"]].to_numpy(float), 3 * h_px)
    missed = np.setdiff1d(np.arange(len(jt)), cj)
    at_stubby = set()
    for k, (ja, jb) in enumerate(st[["junction_a", "junction_b"]].to_numpy(int)):
        if stubby[k]:
            at_stubby.update(j for j in (ja, jb) if j >= 0)
    jid = jt["junction_id"].to_numpy(int)
    # energy per stack: truth (the rod's) and measured, on matched stacks by thickness and
    # on the stacks the other side does not have
    e_t = tru_t["branches"].groupby("stack_id")["energy"].sum().reindex(range(len(st)),
                                                                        fill_value=0.0)
    e_o = out_t["branches"].groupby("stack_id")["energy"].sum().reindex(range(len(so)),
                                                                        fill_value=0.0)
    e_t, e_o = e_t.to_numpy(float), e_o.to_numpy(float)
    cls = np.where(nbr_t[c] == 1, "1", np.where(nbr_t[c] < THICK, "2-4", "5+"))
    energy = {}
    for name in ("1", "2-4", "5+"):
        m = cls == name
        energy[f"energy_truth_nbr{name}"] = float(e_t[c[m]].sum())
        energy[f"energy_out_nbr{name}"] = float(e_o[r[m]].sum())
    energy["energy_truth_unmatched"] = float(e_t[unmatched].sum())
    energy["energy_out_unmatched"] = float(np.delete(e_o, r).sum())
    return {
        "truth_stacks": len(st), "matched_stacks": len(c),
        "nbr_wrong_matched": int((err != 0).sum()),
        "nbr_wrong_pm1": int((np.abs(err) == 1).sum()),
        "thick_matched": int(thick.sum()), "thick_wrong": int((err[thick] != 0).sum()),
        "thick_wrong_pm1": int((np.abs(err[thick]) == 1).sum()),
        "nbr_wrong_length_fraction": float(length[c[err != 0]].sum() / length.sum()),
        "unmatched_stacks": len(unmatched),
        "unmatched_length_fraction": float(length[unmatched].sum() / length.sum()),
        "unmatched_stubby": int(stubby[unmatched].sum()),
        "stubby_stacks": int(stubby.sum()),
        "stubby_length_fraction": float(length[stubby].sum() / length.sum()),
        "missed_junctions": len(missed),
        "missed_at_stubby": int(sum(int(jid[j]) in at_stubby for j in missed)),
        "junctions_at_stubby": int(sum(int(j) in at_stubby for j in jid)),
        "extra_junctions": int(len(jo) - len(rj)),
        **energy,
        "_missed": missed, "_extra": np.setdiff1d(np.arange(len(jo)), rj),
        "_wrong": [(int(c[i]), int(err[i])) for i in np.flatnonzero(err != 0)],
        "_unmatched": unmatched,
    }


def _overlay(path, scene, pair, b):
    """The scan with the scoring's failures drawn on it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, out_t = pair
    jt, jo = scene.tables["junctions"], out_t["junctions"]
    fig, ax = plt.subplots(figsize=(12, 12))
    ax.imshow(scene.rgb)
    for sid, e in b["_wrong"]:
        p = scene.paths_rc[sid] if scene.paths_rc else None
        row = scene.tables["stacks"].iloc[sid]
        ax.annotate(f"{int(row.n_br)}{e:+d}", (row.mid_x_px, row.mid_y_px), color="red",
                    fontsize=7, ha="center")
        if p is not None:
            ax.plot(p[:, 1], p[:, 0], "r-", lw=0.6)
    for sid in b["_unmatched"]:
        row = scene.tables["stacks"].iloc[sid]
        ax.plot(row.mid_x_px, row.mid_y_px, "x", color="orange", ms=5)
    ax.plot(jt["x_px"].to_numpy()[b["_missed"]], jt["y_px"].to_numpy()[b["_missed"]], "o",
            mfc="none", mec="red", ms=8, label="truth junction missed")
    ax.plot(jo["x_px"].to_numpy()[b["_extra"]], jo["y_px"].to_numpy()[b["_extra"]], "s",
            mfc="none", mec="magenta", ms=8, label="output junction unmatched")
    ax.plot([], [], "r-", label="stack with wrong n_br (truth n_br and error)")
    ax.plot([], [], "x", color="orange", label="truth stack unmatched")
    ax.legend(loc="lower left", fontsize=8)
    ax.set_axis_off()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def run(epsilons, *, segments, seed, conditions, work, overlays):
    """Compact, render, analyse and score; ``epsilons`` holds (epsilon, configurations)."""
    rows = []
    h_px = THICKNESS_MM * PX_PER_MM
    for eps, n_configs in epsilons:
        base = Path(work) / f"eps{eps:g}"
        sim = base / "sim"
        if not (sim / "rods.npz").exists():
            status = simulate_main(["compact", "--epsilon", f"{eps:g}", "--segments",
                                    str(segments), "--n-configs", str(n_configs), "--seed",
                                    str(seed), "--out", str(sim), "--no-progress"])
            if status:
                raise SystemExit(f"compaction at epsilon {eps:g} failed (status {status})")
        p = json.loads((sim / "params.json").read_text())
        configs = pd.read_csv(sim / "configs.csv")
        with np.load(sim / "rods.npz") as rods:
            keys = sorted(rods.files)[:n_configs]
            xys = {k: np.asarray(rods[k], float) for k in keys}
        for i, key in enumerate(keys):
            xy = xys[key]
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                an = analyze_rod(xy, lam=0.0, contact_distance=p["contact_distance"])
            contacts_s = time.perf_counter() - t0
            for cond in conditions:
                folder = base / cond / key
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    scene = render_configuration(
                        xy, an, px_per_mm=PX_PER_MM, thickness_mm=THICKNESS_MM,
                        rod_thickness=p["thickness"], wall_radius=p["wall_radius"],
                        hole_radius_mm="auto", seed=seed + i, **CONDITIONS[cond])
                render_s = time.perf_counter() - t0
                write_scene(scene, folder)
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    result, pair = analyze_scene_folder(folder)
                analyze_s = time.perf_counter() - t0
                truth = read_scene(folder, image=False)
                tpair = (truth.summary, truth.tables)
                s = score(pair, tpair, px_per_mm=PX_PER_MM, thickness_mm=THICKNESS_MM)
                b = _breakdown(pair, tpair, h_px)
                if overlays:
                    _overlay(base / "overlays" / f"{key}_{cond}.png", scene, pair, b)
                row = {"epsilon": eps, "config": key, "condition": cond,
                       "n_br_exact": s["n_br_exact_length_fraction"],
                       "junction_f1": s["junction_f1"],
                       "junction_precision": s["junction_precision"],
                       "junction_recall": s["junction_recall"],
                       "junction_f1_fork": _fork_f1(scene, pair, h_px),
                       "rod_length_error": s["rod_length_rel_error"],
                       "total_energy_error": s["total_energy_rel_error"],
                       "total_energy_rel_uncertainty": pair[0].get(
                           "total_energy_rel_uncertainty"),
                       "quality": ";".join(pair[0]["quality"]["codes"]),
                       "total_energy_out": s["total_energy"],
                       "total_energy_truth": s["total_energy_truth"],
                       "n_br_mean_abs_error": s["n_br_mean_abs_error"],
                       "truth_junctions": s["junction_truth"],
                       "out_junctions": s["junction_out"],
                       "fold_energy_share": _fold_share(xy),
                       # how much rod the bands draw: sum n_br x drawn stack length over L
                       "drawn_rod_ratio": float((truth.tables["stacks"]["n_br"]
                                                 * truth.tables["stacks"]["length_mm"]).sum()
                                                / truth.summary["rod_length_mm"]),
                       **dict(zip(("drawn_energy_ratio", "drawn_energy_ratio_outside"),
                                  _drawn_energy(scene))),
                       "measured_energy_ratio_outside": _measured_outside(scene, result),
                       "rod_energy_share_outside": _rod_outside(xy, scene),
                       "compact_s": float(configs.loc[configs["config_id"] == i, "wall_s"]
                                          .iloc[0]) if "wall_s" in configs else np.nan,
                       "contacts_s": contacts_s, "render_s": render_s,
                       "analyze_s": analyze_s, "image_px": int(np.prod(scene.rgb.shape[:2]))}
                row.update({k: v for k, v in b.items() if not k.startswith("_")})
                row["pass"] = (row["n_br_exact"] >= TARGETS["n_br_exact_length_fraction"]
                               and row["junction_f1"] >= TARGETS["junction_f1"]
                               and abs(row["rod_length_error"]) <= TARGETS["rod_length"]
                               and abs(row["total_energy_error"]) <= TARGETS["total_energy"])
                rows.append(row)
                print(_line(row), flush=True)
    return pd.DataFrame(rows)


def _line(r) -> str:
    return (f"| {r['epsilon']:g} | {r['config'][-1]} | {r['condition']} | {r['n_br_exact']:.3f} | "
            f"{r['junction_f1']:.3f} ({r['junction_precision']:.2f}/{r['junction_recall']:.2f}) | "
            f"{r['junction_f1_fork']:.3f} | "
            f"{100 * r['rod_length_error']:+.1f} % | {100 * r['total_energy_error']:+.0f} % | "
            f"{100 * r['unmatched_length_fraction']:.0f} % + "
            f"{100 * r['nbr_wrong_length_fraction']:.0f} % | "
            f"{r['thick_wrong']}/{r['thick_matched']} ({r['thick_wrong_pm1']}) | "
            f"{r['missed_junctions']}/{r['truth_junctions']} ({r['missed_at_stubby']}) | "
            f"{r['render_s']:.0f} | {r['analyze_s']:.1f} |")


HEADER = ("| epsilon | config | condition | exact n_br | junction F1 (P/R) | F1 fork | "
          "rod length | total energy | stack length unmatched + n_br wrong | "
          "thick stacks wrong (+-1) | junctions missed (at a stack < 2 widths) | render s | "
          "analyze s |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--epsilon", default="19",
                    help="comma-separated compaction rates, each E or E:K with K "
                         "configurations (default 19)")
    ap.add_argument("--segments", type=int, default=2000)
    ap.add_argument("--n-configs", type=int, default=4)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--conditions", default="scan,clean,polyline",
                    help=f"comma-separated, of {', '.join(CONDITIONS)}")
    ap.add_argument("--work", default=str(Path(__file__).parent / "out" / "compact_pipeline"),
                    help="compactions, scenes and overlays")
    ap.add_argument("--out", default=str(Path(__file__).parent / "out"))
    ap.add_argument("--overlays", action="store_true",
                    help="draw the failures of every scene into WORK/epsE/overlays/")
    a = ap.parse_args(argv)
    conditions = [c.strip() for c in a.conditions.split(",") if c.strip()]
    bad = [c for c in conditions if c not in CONDITIONS]
    if bad:
        ap.error(f"unknown condition {bad[0]!r}")
    epsilons = []
    for item in a.epsilon.split(","):
        eps, _, k = item.partition(":")
        epsilons.append((float(eps), int(k) if k else a.n_configs))
    print(HEADER, flush=True)
    df = run(epsilons, segments=a.segments, seed=a.seed, conditions=conditions, work=a.work,
             overlays=a.overlays)
    write_csv(Path(a.out) / "compact_pipeline.csv", df)
    print(f"\n{len(df)} scenes; targets met by {int(df['pass'].sum())}; "
          f"{Path(a.out) / 'compact_pipeline.csv'}")


if __name__ == "__main__":
    main()
