#!/usr/bin/env python
"""The default pipeline on the independent generator's scans altered as other scanners,
plates and users would alter them.

Each scene of ``benchmarks/independent_scenes.py`` (drawn once, or read from
OUT/independent_scenes as ``independent_sweep.py`` leaves it) is altered by one variation,
analysed with default settings (the scale, the calibration and the rod length given; the
hole given unless ``--hole-not-given``) and scored as in ``independent_sweep.py``:

======================  ===========================================================
none                    the scene as drawn
gradient_cast           illumination gradient +-15 % across the scan, colour cast 6 %
bluish_plate            the plate replaced by a grey-blue one (120, 132, 160), noisy
plate_R_G_B             the plate replaced by a flat one of that colour (noise 4): blue
                        plates that pass the ink's colour rule
textured_R_G_B          the same plate textured (+-10 %), then the whole scan under a
                        +-15 % gradient, a cast, 1 px of blur and noise 6
receding                light grey-blue receding surfaces beside every band (50 %)
vignette                the scan darkened by 35 % towards its corners
streaks                 six bright or dark columns of the scanner's sensor
faded_ink               the ink mixed 45 % with the paper
dark_scan, bright_scan  tone curves x^1.8 and x^0.6
rot90                   the scan turned a quarter turn (the truth turned with it)
black_border            a 40-px black frame (a scanner lid)
white_pad               200 px of white paper added around the scan
crop                    the scan cut through the hole (the hole reaches beyond it)
jpeg50                  JPEG at quality 50
noise20                 Gaussian noise of 20 grey levels
blur2                   Gaussian blur of 2 px
======================  ===========================================================

Usage: python benchmarks/scan_variations.py [--variations none,rot90,...]
       [--scenes typical:1-4,thick_dense:1,lowres:1] [--workers 2] [--out benchmarks/out]
       [--hole-not-given]
Writes OUT/scan_variations.csv (one row per scene and variation: the scores of
``independent_sweep.score``, the quality codes raised) and prints the median and the worst
score of every variation.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
import independent_scenes as gen  # noqa: E402  (the generator, deliberately not in the package)
import independent_sweep as sweep  # noqa: E402

VARIATIONS = ("none", "gradient_cast", "bluish_plate", "plate_100_120_190",
              "plate_150_170_215", "plate_60_90_170", "textured_90_115_185",
              "textured_140_160_210", "textured_60_90_170", "receding", "vignette", "streaks",
              "faded_ink", "dark_scan", "bright_scan", "rot90", "black_border", "white_pad",
              "crop", "jpeg50", "noise20", "blur2")
PAD_PX = 200


def _rgb_of(name: str) -> np.ndarray:
    return np.array([float(v) for v in name.split("_")[1:]], np.float32)


def alter(img: np.ndarray, variation: str, centre_xy, radius_px: float, rng) -> np.ndarray:
    """The scan ``img`` (uint8 RGB) altered by one variation of the module table."""
    import cv2

    img = img.astype(np.float32)
    H, W = img.shape[:2]
    yy, xx = np.mgrid[:H, :W]
    rr = np.hypot(xx - centre_xy[0], yy - centre_xy[1])
    outside = rr > radius_px + 0.5
    if variation == "gradient_cast":
        img = img * (1 + 0.15 * (2 * xx / W - 1))[..., None] * np.float32([1.06, 1.0, 0.94])
    elif variation == "bluish_plate" or variation.startswith("plate_"):
        col = np.float32([120, 132, 160]) if variation == "bluish_plate" else _rgb_of(variation)
        img[outside] = col + rng.normal(0, 4, (int(outside.sum()), 3)).astype(np.float32)
    elif variation.startswith("textured_"):
        tex = cv2.resize(rng.uniform(0.9, 1.1, (H // 60 + 2, W // 60 + 2)).astype(np.float32),
                         (W, H), interpolation=cv2.INTER_CUBIC)
        img[outside] = (_rgb_of(variation)[None, :] * tex[outside][:, None])
        img = img * (1 + 0.15 * (2 * xx / W - 1))[..., None] * np.float32([0.96, 1.0, 1.05])
        img = cv2.GaussianBlur(img, (0, 0), 1.0) + rng.normal(0, 6, img.shape)
    elif variation == "receding":
        ink = (img[..., 2] - img[..., :2].max(-1)) > 40
        near = cv2.dilate(ink.astype(np.uint8), np.ones((7, 7), np.uint8))
        side = np.roll(np.roll(near, 4, 0), 3, 1).astype(bool) & ~ink
        img[side] = 0.5 * img[side] + 0.5 * np.float32([165, 175, 200])
    elif variation == "vignette":
        d = np.hypot(xx - W / 2, yy - H / 2) / np.hypot(W / 2, H / 2)
        img = img * (1 - 0.35 * d ** 2)[..., None]
    elif variation == "streaks":
        for c in rng.integers(0, W - 2, 6):
            img[:, c:c + 2] *= rng.uniform(0.85, 1.1)
    elif variation == "faded_ink":
        img = 0.55 * img + 0.45 * np.median(img[rr < radius_px], axis=0)
    elif variation == "dark_scan":
        img = 255 * (img / 255) ** 1.8
    elif variation == "bright_scan":
        img = 255 * (img / 255) ** 0.6
    elif variation == "rot90":
        img = np.rot90(img).copy()
    elif variation == "black_border":
        for sl in (np.s_[:40], np.s_[-40:], np.s_[:, :40], np.s_[:, -40:]):
            img[sl] = 10
    elif variation == "white_pad":
        img = np.pad(img, ((PAD_PX, PAD_PX), (PAD_PX, PAD_PX), (0, 0)), constant_values=250)
    elif variation == "crop":
        img = img[:int(centre_xy[1] + 0.8 * radius_px)]
    elif variation == "jpeg50":
        ok, buf = cv2.imencode(".jpg", np.clip(img, 0, 255).astype(np.uint8),
                               [cv2.IMWRITE_JPEG_QUALITY, 50])
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR).astype(np.float32)
    elif variation == "noise20":
        img = img + rng.normal(0, 20, img.shape)
    elif variation == "blur2":
        img = cv2.GaussianBlur(img, (0, 0), 2.0)
    elif variation != "none":
        raise ValueError(f"unknown variation {variation!r}")
    return np.clip(img, 0, 255).astype(np.uint8)


def moved_truth(truth: dict, lines: dict, variation: str, width_px: int):
    """The truth and its lines in the altered scan's pixels (turned or shifted)."""
    if variation == "rot90":  # np.rot90: (x, y) -> (y, W - 1 - x)
        def move(x, y):
            return y, width_px - 1 - x
    elif variation == "white_pad":
        def move(x, y):
            return x + PAD_PX, y + PAD_PX
    else:
        return truth, lines
    truth = json.loads(json.dumps(truth))
    if variation == "white_pad":  # the canvas the bands are redrawn on for the medial forks
        truth["render"]["size"] = int(truth["render"]["size"]) + 2 * PAD_PX
    truth["hole_center_px"] = list(move(*truth["hole_center_px"]))
    for j in truth["junctions"]:
        j["x"], j["y"] = move(j["x"], j["y"])
    for s in truth["stacks"]:
        s["mid"] = list(move(*s["mid"]))
    for f in truth["forks"]:
        if "vis_px" in f:
            f["vis_px"] = list(move(*f["vis_px"]))
    lines = {k: np.stack(move(v[:, 0], v[:, 1]), axis=-1) for k, v in lines.items()}
    return truth, lines


def run_one(scene: str, variation: str, folder: str, work: str, hole_given: bool) -> dict:
    """Alter, analyse and score one scene; return its row."""
    import cv2

    import crosssection

    folder = Path(folder)
    truth = json.loads((folder / f"{scene}.json").read_text())
    with np.load(folder / f"{scene}_lines.npz") as z:
        lines = dict(z)
    img = cv2.imread(str(folder / f"{scene}.png"), cv2.IMREAD_COLOR)[..., ::-1]
    rng = np.random.default_rng(3)
    R = truth["hole_radius_mm"] * truth["px_per_mm"]
    out = alter(img, variation, truth["hole_center_px"], R, rng)
    truth, lines = moved_truth(truth, lines, variation, img.shape[1])
    path = Path(work) / f"{scene}_{variation}.png"
    cv2.imwrite(str(path), np.ascontiguousarray(out[..., ::-1]))
    row = {"scene": scene, "variation": variation}
    hole = (dict(hole_radius_mm=truth["hole_radius_mm"],
                 hole_center_px=tuple(truth["hole_center_px"])) if hole_given else {})
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = crosssection.analyze(
                str(path), px_per_mm=truth["px_per_mm"], thickness_mm=truth["thickness_mm"],
                calibration=str(folder / "calibration.csv"), rod_length_mm=truth["L_mm"],
                **hole)
    except crosssection.FoldstatError as exc:
        row.update(error=exc.one_line())
        return row
    row["analyze_s"] = time.perf_counter() - t0
    row.update(sweep.score(truth, lines, res))
    row["quality"] = ";".join(res.summary["quality"]["codes"])
    return row


def _scenes(spec: str) -> list[tuple[str, int]]:
    """``typical:1-4,lowres:1`` -> [(condition, seed), ...]."""
    out = []
    for part in (p for p in spec.split(",") if p):
        cond, _, seeds = part.partition(":")
        lo, _, hi = seeds.partition("-")
        out += [(cond, s) for s in range(int(lo), int(hi or lo) + 1)]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variations", default=",".join(VARIATIONS))
    ap.add_argument("--scenes", default="typical:1-4,thick_dense:1,lowres:1")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "out"))
    ap.add_argument("--hole-not-given", action="store_true")
    args = ap.parse_args(argv)
    variations = [v for v in args.variations.split(",") if v]
    bad = [v for v in variations
           if v not in VARIATIONS and not v.startswith(("plate_", "textured_"))]
    if bad:
        ap.error(f"unknown variation(s) {', '.join(bad)}; known: {', '.join(VARIATIONS)}")
    from crosssection.core.fileio import write_csv

    out = Path(args.out)
    folder = out / sweep.SCENE_DIR
    folder.mkdir(parents=True, exist_ok=True)
    gen.write_calibration(folder / "calibration.csv")
    scenes = []
    for cond, seed in _scenes(args.scenes):
        name = gen.scene_name(seed, cond)
        if not sweep._scene_on_disk(folder, name):
            gen.generate(seed, cond, folder)
        scenes.append(name)
    work = out / "scan_variations"
    work.mkdir(exist_ok=True)
    jobs = [(s, v) for v in variations for s in scenes]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as ex:
        rows = list(ex.map(run_one, *zip(*jobs), [str(folder)] * len(jobs),
                           [str(work)] * len(jobs), [not args.hole_not_given] * len(jobs)))
    df = pd.DataFrame(rows)
    stem = "scan_variations_nohole" if args.hole_not_given else "scan_variations"
    write_csv(out / f"{stem}.csv", df)
    ok = df[df.get("error", pd.Series(index=df.index, dtype=object)).isna()] \
        if "error" in df else df
    summary = ok.groupby("variation", sort=False).agg(
        rod_abs_med=("rod_length_rel_error", lambda v: np.median(np.abs(v))),
        rod_abs_max=("rod_length_rel_error", lambda v: np.max(np.abs(v))),
        f1_fork_min=("junction_f1_fork", "min"),
        nbr_min=("n_br_exact_length_fraction", "min"),
        energy_med=("total_energy_rel_error", "median"),
        flagged=("quality", lambda q: int(sum(bool(x) for x in q))))
    pd.set_option("display.width", 200)
    print(summary.to_string(float_format=lambda v: f"{v:.3f}"))
    if "error" in df:
        for _, r in df[df["error"].notna()].iterrows():
            print(f"{r['scene']} {r['variation']}: {r['error']}")
    print(f"{len(df)} analyses in {time.perf_counter() - t0:.0f} s -> {out / stem}.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
