"""Generated scans and scan folders for tests of the batch workflow.

``make_scan_tree`` lays out a folder the way a lab keeps scans (a set with ``set.toml``, a
calibration and a per-image override, loose images, and optionally broken inputs), so that a
test can run :func:`crosssection.batch.run_batch` on it and check what succeeded and failed.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from crosssection import batch as B

__all__ = ["drawn_scan", "generated_scan", "write_png", "write_calibration", "make_scan_tree",
           "index_numbers", "partial_outputs"]


def drawn_scan(seed: int, size: int = 420, *, ring_frac: float = 0.45, ring_px: int = 10,
               chord_px: tuple = (5, 16)) -> np.ndarray:
    """A drawn RGB scan, uint8 (size, size, 3): a ring of blue ink and four chords across it
    of random widths in ``chord_px`` (px, upper bound excluded), on white paper. Draws in
    milliseconds, for tests that need many scans."""
    import cv2

    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), 250, np.uint8)
    c = size // 2
    r = int(size * ring_frac)
    ink = (190, 70, 40)  # BGR for cv2
    cv2.circle(img, (c, c), r, ink, thickness=ring_px)
    for _ in range(4):
        a, b = rng.uniform(0, 2 * np.pi, 2)
        p = (int(c + r * np.cos(a)), int(c + r * np.sin(a)))
        q = (int(c + r * np.cos(b)), int(c + r * np.sin(b)))
        cv2.line(img, p, q, ink, thickness=int(rng.integers(*chord_px)))
    return np.ascontiguousarray(img[:, :, ::-1])


def generated_scan(seed: int, size: int = 420) -> np.ndarray:
    """A small RGB scan (about 12 stacks of 1-4 layers in a disk), uint8 (size, size, 3).

    The network generator's scene when it finds a layout in 5 tries, else :func:`drawn_scan`.
    """
    from crosssection.truth.network import SceneGenerationError, make_scene

    try:
        return make_scene(seed=seed, n_stacks=12, max_layers=4, image_size=size,
                          max_tries=5).rgb
    except SceneGenerationError:
        return drawn_scan(seed, size)


def write_png(path: Path, rgb: np.ndarray):
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(rgb).save(path)


def write_calibration(path: Path, h=0.1):
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = "\n".join(f"{n},{n * h * 1.1:.4f}" for n in range(1, 13))
    path.write_text("n_layers,width_mm\n" + rows + "\n")


def make_scan_tree(root: Path, seed: int, *, bad=True) -> dict:
    """An input tree: a good set (with calibration and an override), loose images, and
    (``bad``) a corrupt file, a grayscale scan, a set with a bad set.toml and a set whose
    calibration is missing."""
    rng = np.random.default_rng(seed)
    seeds = rng.integers(0, 2**31, 6)
    good = root / "setA"
    write_calibration(good / "cal.csv")
    (good / "set.toml").write_text(
        'name = "alpha"\npx_per_mm = 50\nthickness_mm = 0.1\ncalibration = "cal.csv"\n'
        'bending_rigidity_J = 1e-4\n\n[images."s1.png"]\nrod_length_mm = 200.0\n')
    write_png(good / "s0.png", generated_scan(int(seeds[0])))
    write_png(good / "s1.png", generated_scan(int(seeds[1])))
    write_png(good / "sub" / "s2.png", generated_scan(int(seeds[2])))
    write_png(root / "loose.png", generated_scan(int(seeds[3])))
    expect_ok = ["loose.png", "setA/s0.png", "setA/s1.png", "setA/sub/s2.png"]
    expect_failed = {}
    if bad:
        (root / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"garbage" * 20)
        expect_failed["corrupt.png"] = None
        gray = generated_scan(int(seeds[4]))[:, :, 2]
        from PIL import Image

        Image.fromarray(gray).save(root / "gray.png")
        expect_failed["gray.png"] = None
        (root / "badset").mkdir()
        (root / "badset" / "set.toml").write_text('name = "beta"\npx_per_mm = "fifty"\n')
        write_png(root / "badset" / "b0.png", generated_scan(int(seeds[5])))
        expect_failed["badset/b0.png"] = "px_per_mm"
        (root / "nocal").mkdir()
        (root / "nocal" / "set.toml").write_text('name = "gamma"\ncalibration = "missing.csv"\n')
        write_png(root / "nocal" / "c0.png", generated_scan(int(seeds[0]) + 1))
        expect_failed["nocal/c0.png"] = "calibration"
    return {"ok": expect_ok, "failed": expect_failed}


def index_numbers(index: pd.DataFrame) -> pd.DataFrame:
    ok = index[index["status"] != "failed"].set_index("image").sort_index()
    return ok[["set", "output"] + B.SUMMARY_NUMBERS]


def partial_outputs(out: Path) -> list[Path]:
    return [p for p in out.rglob("*") if B.PARTIAL_TAG in p.name or p.name.endswith(".tmp")
            or (p.name.startswith(".") and p.is_file())]
