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
misregistered           colour channels misregistered as a scanner's sensor rows are:
                        red shifted +1 px and blue -1 px along the rows (x), coloured
                        fringes at every band edge
chroma420               JPEG at quality 75 with 4:2:0 chroma subsampling (Pillow
                        ``subsampling=2``), most cameras' and many scanners' default
ink_bleed               ink bled into the paper: every band edge widened by 1 px with a
                        half-way colour (the ink mask dilated by 1 px, blended 50 %
                        towards the ink colour there)
yellowed_paper          old paper: the paper in the hole (not the ink) tinted
                        (235, 225, 190) with a smooth low-frequency mottle of +-5 %
rot7                    the scan turned 7 degrees about its centre, bilinear, white
                        outside (the truth turned with it)
dpi600                  the scan resampled to 600 dpi (23.62 px/mm) by area
                        interpolation (the truth, the hole and the scale given to the
                        analysis scaled with it)
dust                    200 dark grey specks of 1-3 px radius and 5 grey hairs (1 px wide,
                        2-8 mm long, curved) over the whole scan, the hole included
======================  ===========================================================

Usage: python benchmarks/scan_variations.py [--variations none,rot90,...]
       [--scenes typical:1-4,thick_dense:1,lowres:1] [--workers 2] [--out benchmarks/out]
       [--hole-not-given]
Writes OUT/scan_variations.csv (one row per scene and variation: the scores of
``independent_sweep.score``, the quality codes raised) and prints the median and the worst
score of every variation (rod length, fork F1, exact n_br, void count, energy), the number of
scenes flagged and the quality codes raised.
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
              "crop", "jpeg50", "noise20", "blur2", "misregistered", "chroma420", "ink_bleed",
              "yellowed_paper", "rot7", "dpi600", "dust")
PAD_PX = 200
ROT_DEG = 7.0
DPI600_PX_PER_MM = 600 / 25.4


def _rotation(width_px: int, height_px: int) -> np.ndarray:
    """The 2x3 affine matrix of ``rot7`` (source x, y -> altered x, y; cv2's pixel centres)."""
    import cv2

    return cv2.getRotationMatrix2D(((width_px - 1) / 2, (height_px - 1) / 2), ROT_DEG, 1.0)


def _resampled_shape(width_px: int, height_px: int, px_per_mm: float) -> tuple[int, int]:
    """Width and height of the ``dpi600`` scan."""
    f = DPI600_PX_PER_MM / px_per_mm
    return max(1, int(round(width_px * f))), max(1, int(round(height_px * f)))


def _ink_and_paper(img: np.ndarray, inside: np.ndarray):
    """Ink weight (0 paper .. 1 full ink), the ink colour and the paper colour of a scan."""
    blue = img[..., 2] - img[..., :2].max(-1)
    core = blue > 40
    ink_rgb = np.median(img[core], axis=0) if core.any() else np.float32([40, 50, 140])
    ink_blue = max(float(ink_rgb[2] - ink_rgb[:2].max()), 1.0)
    weight = np.clip(blue / ink_blue, 0, 1)
    paper = inside & (weight < 0.1)
    paper_rgb = np.median(img[paper], axis=0) if paper.any() else np.float32([250, 250, 250])
    return weight.astype(np.float32), ink_rgb.astype(np.float32), paper_rgb.astype(np.float32)


def _rgb_of(name: str) -> np.ndarray:
    return np.array([float(v) for v in name.split("_")[1:]], np.float32)


def alter(img: np.ndarray, variation: str, centre_xy, radius_px: float, rng,
          px_per_mm: float = 50.0) -> np.ndarray:
    """The scan ``img`` (uint8 RGB, ``px_per_mm``) altered by one variation of the module
    table."""
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
    elif variation == "misregistered":
        img[..., 0] = np.roll(img[..., 0], 1, axis=1)
        img[..., 2] = np.roll(img[..., 2], -1, axis=1)
    elif variation == "chroma420":
        import io

        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(
            buf, "JPEG", quality=75, subsampling=2)
        img = np.asarray(Image.open(io.BytesIO(buf.getvalue())).convert("RGB"), np.float32)
    elif variation == "ink_bleed":
        weight, ink_rgb, _ = _ink_and_paper(img, ~outside)
        ink = (weight >= 0.5).astype(np.uint8)
        rim = cv2.dilate(ink, np.ones((3, 3), np.uint8)).astype(bool) & ~ink.astype(bool)
        img[rim] = 0.5 * img[rim] + 0.5 * ink_rgb
    elif variation == "yellowed_paper":
        weight, _, paper_rgb = _ink_and_paper(img, ~outside)
        mottle = cv2.resize(rng.uniform(-1, 1, (H // 150 + 3, W // 150 + 3)).astype(np.float32),
                            (W, H), interpolation=cv2.INTER_CUBIC)
        mottle = 1 + 0.05 * mottle / max(float(np.abs(mottle).max()), 1e-6)
        gain = np.float32([235, 225, 190]) / paper_rgb  # the paper's colour -> the tint
        paperness = ((1 - weight) * ~outside)[..., None]
        img = img * (1 + paperness * (gain * mottle[..., None] - 1))
    elif variation == "rot7":
        img = cv2.warpAffine(img, _rotation(W, H), (W, H), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=(255, 255, 255))
    elif variation == "dpi600":
        img = cv2.resize(img, _resampled_shape(W, H, px_per_mm), interpolation=cv2.INTER_AREA)
    elif variation == "dust":
        for _ in range(200):
            grey = float(rng.uniform(45, 95))
            centre = (int(rng.integers(0, W)), int(rng.integers(0, H)))
            cv2.circle(img, centre, int(rng.integers(1, 4)), (grey, grey, grey), -1, cv2.LINE_AA)
        for _ in range(5):
            n = 60
            step = rng.uniform(2, 8) * px_per_mm / n
            turn = np.cumsum(rng.normal(rng.normal(0, 0.03), 0.03, n))  # a slowly bending hair
            ang = rng.uniform(0, 2 * np.pi) + turn
            x0, y0 = rng.uniform(0, W), rng.uniform(0, H)
            pts = np.stack([x0 + np.cumsum(step * np.cos(ang)),
                            y0 + np.cumsum(step * np.sin(ang))], -1)
            grey = float(rng.uniform(90, 140))
            cv2.polylines(img, [np.round(pts * 16).astype(np.int32)], False, (grey, grey, grey),
                          1, cv2.LINE_AA, 4)
    elif variation != "none":
        raise ValueError(f"unknown variation {variation!r}")
    return np.clip(img, 0, 255).astype(np.uint8)


def moved_truth(truth: dict, lines: dict, variation: str, width_px: int,
                height_px: int | None = None):
    """The truth and its lines in the altered scan's pixels (turned, shifted or rescaled)."""
    height_px = width_px if height_px is None else height_px
    if variation == "rot7":
        m = _rotation(width_px, height_px)

        def move(x, y):
            return m[0, 0] * x + m[0, 1] * y + m[0, 2], m[1, 0] * x + m[1, 1] * y + m[1, 2]
    elif variation == "dpi600":  # cv2.resize: pixel centres (x + 0.5) * f - 0.5
        new_w, new_h = _resampled_shape(width_px, height_px, truth["px_per_mm"])
        fx, fy = new_w / width_px, new_h / height_px

        def move(x, y):
            return (np.asarray(x) + 0.5) * fx - 0.5, (np.asarray(y) + 0.5) * fy - 0.5
    elif variation == "rot90":  # np.rot90: (x, y) -> (y, W - 1 - x)
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
    if variation == "dpi600":  # the canvas, and the scale given to the analysis
        truth["render"]["size"] = max(new_w, new_h)
        truth["px_per_mm"] = DPI600_PX_PER_MM
    truth["hole_center_px"] = [float(v) for v in move(*truth["hole_center_px"])]
    for j in truth["junctions"]:
        j["x"], j["y"] = (float(v) for v in move(j["x"], j["y"]))
    for s in truth["stacks"]:
        s["mid"] = [float(v) for v in move(*s["mid"])]
    for f in truth["forks"]:
        if "vis_px" in f:
            f["vis_px"] = [float(v) for v in move(*f["vis_px"])]
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
    out = alter(img, variation, truth["hole_center_px"], R, rng, truth["px_per_mm"])
    truth, lines = moved_truth(truth, lines, variation, img.shape[1], img.shape[0])
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
    def worst(v):  # the signed score farthest from 0
        v = np.asarray(v, float)
        return v[np.argmax(np.abs(v))]

    def codes(q):
        return ";".join(sorted({c for x in q if isinstance(x, str) for c in x.split(";") if c}))

    summary = ok.groupby("variation", sort=False).agg(
        rod_abs_med=("rod_length_rel_error", lambda v: np.median(np.abs(v))),
        rod_abs_max=("rod_length_rel_error", lambda v: np.max(np.abs(v))),
        f1_fork_med=("junction_f1_fork", "median"),
        f1_fork_min=("junction_f1_fork", "min"),
        nbr_med=("n_br_exact_length_fraction", "median"),
        nbr_min=("n_br_exact_length_fraction", "min"),
        voids_med=("n_voids_rel_error", "median"),
        voids_worst=("n_voids_rel_error", worst),
        energy_med=("total_energy_rel_error", "median"),
        energy_worst=("total_energy_rel_error", worst),
        flagged=("quality", lambda q: int(sum(isinstance(x, str) and bool(x) for x in q))),
        codes=("quality", codes))
    pd.set_option("display.width", 250)
    print(summary.to_string(float_format=lambda v: f"{v:.3f}"))
    if "error" in df:
        for _, r in df[df["error"].notna()].iterrows():
            print(f"{r['scene']} {r['variation']}: {r['error']}")
    print(f"{len(df)} analyses in {time.perf_counter() - t0:.0f} s -> {out / stem}.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
