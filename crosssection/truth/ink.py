"""Colours of a scan (uint8 RGB), one source for every scene generator.

The paper's scans show blue ink on white paper, and, through the voids, the light grey-blue
back of the sheet ("receding surfaces"): the reason the paper thresholds the RGB channels
(blue >= 100, red and green <= 130) rather than one intensity (section "Image analysis
procedure"). Light-blue smears are ink wiped thin across the paper. The ranges below keep every
colour on its side of that threshold, with margin for noise, blur and JPEG.
"""
from __future__ import annotations

import numpy as np

__all__ = ["INK_RGB", "INK_JITTER", "PAPER_RGB", "PAPER_JITTER", "RECEDING_GREY",
           "SMEAR_LOW", "SMEAR_HIGH", "ink_rgb", "paper_rgb", "receding_rgb", "smear_rgb"]

#: Nominal ink; a scan's ink is drawn within +-INK_JITTER of it (:func:`ink_rgb`).
INK_RGB = np.array([40.0, 70.0, 190.0])
INK_JITTER = np.array([20.0, 20.0, 25.0])
#: Paper (slightly warm white); a scan's paper varies by PAPER_JITTER (standard deviation).
PAPER_RGB = np.array([246.0, 245.0, 240.0])
PAPER_JITTER = 1.5
#: Grey level range of receding surfaces (blue a little above red and green).
RECEDING_GREY = (190.0, 228.0)
#: Light-blue smears: red, green above 130 (rejected), blue high.
SMEAR_LOW = np.array([140.0, 170.0, 230.0])
SMEAR_HIGH = np.array([180.0, 200.0, 255.0])


def ink_rgb(rng: np.random.Generator) -> np.ndarray:
    """One scan's ink colour: uniform within ``INK_RGB +- INK_JITTER`` (3 draws)."""
    return INK_RGB + rng.uniform(-1, 1, 3) * INK_JITTER


def paper_rgb(rng: np.random.Generator) -> np.ndarray:
    """One scan's paper colour: ``PAPER_RGB`` plus a Gaussian shade (3 draws), float32."""
    return PAPER_RGB.astype(np.float32) + rng.normal(0, PAPER_JITTER, 3).astype(np.float32)


def receding_rgb(rng: np.random.Generator) -> tuple[float, float, float]:
    """A receding surface's colour: grey level g, then green g..g+6, blue g+8..g+16 (3 draws)."""
    g = rng.uniform(*RECEDING_GREY)
    return (g, g + rng.uniform(0, 6), g + rng.uniform(8, 16))


def smear_rgb(rng: np.random.Generator) -> np.ndarray:
    """A smear's colour, uniform between ``SMEAR_LOW`` and ``SMEAR_HIGH`` (3 draws)."""
    return rng.uniform(SMEAR_LOW, SMEAR_HIGH)
