#!/usr/bin/env python
"""How far each stack's final count lies from the count its own width reads, on scenes with
exact truth: the measurement behind the quality check ``count_width``
(``crosssection.quality.COUNT_WIDTH_LIMIT``).

For every scene: the scores against the truth and, over the stacks at least four widths long,
the largest ``|n_br - layers_est|`` and the stacks at or beyond the limit; the same over the
shorter stacks (``COUNT_WIDTH_SHORT_LIMIT``), and the stacks with both ends free (the
``isolated_stacks`` check). Scenes: the
network generator's conditions of ``robust_sweep.py`` (typical, thick dense, 25 px/mm,
tangential, quench renders) and the independent generator's of ``independent_scenes.py``.

Usage: python benchmarks/count_width_check.py [--per-condition 4] [--workers 2] [--out DIR]
Writes OUT/count_width_check.csv and prints it.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import warnings
from multiprocessing import Pool
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))

import independent_scenes as gen  # noqa: E402
import independent_sweep as ind  # noqa: E402
import robust_sweep as rs  # noqa: E402


def _stack_numbers(stacks: pd.DataFrame) -> dict:
    from crosssection.quality import COUNT_WIDTH_LIMIT, COUNT_WIDTH_SHORT_LIMIT

    long_ = stacks["length_mm"] >= 4.0 * stacks["width_mm"]
    off = (stacks["n_br"] - stacks["layers_est"]).abs()
    free = (stacks["junction_a"] < 0) & (stacks["junction_b"] < 0)
    return {"largest_off_layers": float(off[long_].max()) if long_.any() else 0.0,
            "stacks_at_limit": int((long_ & (off >= COUNT_WIDTH_LIMIT)).sum()),
            "largest_off_short": float(off[~long_].max()) if (~long_).any() else 0.0,
            "short_stacks": int((~long_).sum()),
            "short_at_limit": int((~long_ & (off >= COUNT_WIDTH_SHORT_LIMIT)).sum()),
            "free_stacks": int(free.sum())}


def network_row(args) -> dict:
    """One scene of ``robust_sweep.py``'s generator (hole given), analysed and scored."""
    import crosssection
    from crosssection.truth.scoring import score

    condition, seed = args
    opts = rs.scene_options(condition, seed)
    scene = rs._render_scene(seed) if condition == "renders" else rs.make_network_scene(seed, opts)
    p = scene.params
    kw = dict(px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
              calibration=scene.calibration)
    if opts["hole_given"] and p.get("hole_radius_mm"):
        kw.update(hole_radius_mm=p["hole_radius_mm"], hole_center_px=tuple(p["hole_center_px"]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(scene.rgb, warn=False, **kw)
    s = score((res.summary, res.tables), (scene.summary, scene.tables),
              match_px=3 * p["thickness_mm"] * p["px_per_mm"])
    return {"generator": "network", "condition": condition, "seed": seed,
            "rod_length_rel_error": s["rod_length_rel_error"], "junction_f1": s["junction_f1"],
            "n_br_exact_length_fraction": s["n_br_exact_length_fraction"],
            "total_energy_rel_error": s["total_energy_rel_error"],
            **_stack_numbers(res.stacks)}


def independent_row(args) -> dict:
    """One scene of the independent generator (hole given), analysed and scored."""
    import crosssection

    condition, seed, folder = args
    folder = Path(folder)
    name = gen.scene_name(seed, condition)
    if not (folder / f"{name}.png").exists():
        gen.generate(seed, condition, folder)
    truth = json.loads((folder / f"{name}.json").read_text())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(
            str(folder / f"{name}.png"), px_per_mm=truth["px_per_mm"],
            thickness_mm=truth["thickness_mm"], calibration=str(folder / "calibration.csv"),
            hole_radius_mm=truth["hole_radius_mm"],
            hole_center_px=tuple(truth["hole_center_px"]), warn=False)
    with np.load(folder / f"{name}_lines.npz") as lines:
        s = ind.score(truth, lines, res)
    return {"generator": "independent", "condition": condition, "seed": seed,
            "rod_length_rel_error": s.get("rod_length_rel_error"),
            "junction_f1": s.get("junction_f1"),
            "n_br_exact_length_fraction": s.get("n_br_exact_length_fraction"),
            "total_energy_rel_error": s.get("total_energy_rel_error"),
            **_stack_numbers(res.stacks)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--per-condition", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    args = ap.parse_args(argv)
    k = args.per_condition
    network = [(c, 300 + i) for c in ("typical", "thick_dense", "lowres", "tangential")
               for i in range(k)] + [("renders", 200 + i) for i in range(4 * k)]
    with tempfile.TemporaryDirectory() as tmp:
        gen.write_calibration(Path(tmp) / "calibration.csv")
        independent = [(c, 1 + i, tmp) for c in gen.CONDITIONS for i in range(k)]
        with Pool(args.workers) as pool:
            rows = pool.map(network_row, network) + pool.map(independent_row, independent)
    df = pd.DataFrame(rows)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "count_width_check.csv", index=False)
    with pd.option_context("display.width", 200, "display.max_rows", 500):
        print(df.round(3).to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
