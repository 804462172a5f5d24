"""What a scanner and a cutting table add to a clean drawing: defects, blur, noise, JPEG.

Written once for every scene generator, on float32 RGB images (0..255). Every function draws
from the generator's ``rng`` only as many numbers as its count asks (none for a count of 0), so
a scene without defects does not depend on this module's sampling.

- smears: light-blue ink wiped across the paper, drawn *under* the ink (the threshold must
  reject them: red and green above 130);
- specks: small dots of ink in the background, away from the bands (smaller than s_min: the
  cleaning stage removes them);
- pinholes: small paper-coloured holes inside wide bands (filled by the cleaning stage);
- :func:`finish_scan`: Gaussian blur, additive Gaussian noise, rounding to uint8, and an
  optional JPEG round trip, in that order (optics first, then sensor, then compression).
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from crosssection.truth.ink import PAPER_RGB, smear_rgb

__all__ = ["add_smears", "add_specks", "add_pinholes", "finish_scan"]

#: Specks keep this many pixels from any band (the erosion of the background by a 9x9 square),
#: so they never touch the ink and change neither a width nor a void.
SPECK_CLEARANCE_PX = 4
#: Only bands at least this wide get pinholes (a hole in a thin band would cut it).
PINHOLE_MIN_WIDTH_PX = 9.0


def add_smears(img: np.ndarray, rng: np.random.Generator, *, count: int, centre_xy,
               radius_px: float) -> None:
    """Paint ``count`` light-blue elliptic smears in place, inside 0.8 of a disc.

    Parameters
    ----------
    img : (H, W, 3) float32 array
        Modified in place; call before drawing the ink.
    rng : numpy.random.Generator
    count : int
    centre_xy : (float, float)
        Centre of the disc (x = column, y = row), e.g. the hole's.
    radius_px : float
        Radius of the disc.
    """
    for _ in range(int(count)):
        col = smear_rgb(rng)
        ang = rng.uniform(0, 2 * np.pi)
        rr = radius_px * math.sqrt(rng.uniform(0, 0.8))
        c = (int(centre_xy[0] + rr * math.cos(ang)), int(centre_xy[1] + rr * math.sin(ang)))
        axes = (int(rng.uniform(15, 60)), int(rng.uniform(3, 10)))
        cv2.ellipse(img, c, axes, float(rng.uniform(0, 180)), 0, 360,
                    tuple(float(x) for x in col), -1, cv2.LINE_AA)


def add_specks(img: np.ndarray, rng: np.random.Generator, *, count: int,
               background: np.ndarray, ink_rgb) -> None:
    """Paint ``count`` ink specks (radius 1-3 px) in place, in the background far from bands.

    Parameters
    ----------
    img : (H, W, 3) float32 array
        Modified in place.
    rng : numpy.random.Generator
    count : int
    background : (H, W) bool or uint8 array
        Pixels free of ink; specks are centred at least ``SPECK_CLEARANCE_PX`` inside it.
    ink_rgb : array-like (3,)
        The scan's ink colour; each speck varies by up to +-10 per channel.
    """
    if int(count) <= 0:
        return
    side = 2 * SPECK_CLEARANCE_PX + 1
    far = cv2.erode(np.asarray(background, np.uint8), np.ones((side, side), np.uint8))
    cand = np.argwhere(far > 0)
    for _ in range(int(count)):
        if not len(cand):
            break
        r, c = cand[rng.integers(len(cand))]
        col = tuple(float(x) for x in np.asarray(ink_rgb) + rng.uniform(-10, 10, 3))
        cv2.circle(img, (int(c), int(r)), int(rng.integers(1, 4)), col, -1, cv2.LINE_AA)


def add_pinholes(img: np.ndarray, rng: np.random.Generator, *, count: int, paths_xy,
                 widths_px) -> None:
    """Punch ``count`` paper-coloured pinholes in place, on the centrelines of wide bands.

    Parameters
    ----------
    img : (H, W, 3) float32 array
        Modified in place; call after drawing the ink.
    rng : numpy.random.Generator
    count : int
    paths_xy : list of (P, 2) float arrays
        Centreline of every band, (x = column, y = row) in pixels.
    widths_px : array-like
        Width of every band; bands narrower than ``PINHOLE_MIN_WIDTH_PX`` are spared, and a
        pinhole's radius is at most a fifth of its band's width (and 2 px).
    """
    widths_px = np.asarray(widths_px, float)
    wide = np.flatnonzero(widths_px >= PINHOLE_MIN_WIDTH_PX)
    for _ in range(int(count)):
        if not len(wide):
            break
        k = wide[rng.integers(len(wide))]
        p = paths_xy[k][rng.integers(len(paths_xy[k]))]
        rad = min(2.0, widths_px[k] / 5)
        # quarter-pixel centre and radius (shift=2): a sub-pixel hole
        cv2.circle(img, (int(round(p[0] * 4)), int(round(p[1] * 4))), max(1, int(round(rad * 4))),
                   tuple(float(x) for x in PAPER_RGB), -1, cv2.LINE_AA, shift=2)


def check_degradations(*, blur_px=0.0, noise_sigma=0.0, jpeg_quality=None, **counts) -> None:
    """Raise :class:`~crosssection.core.errors.ParameterError` for a degradation outside its
    range: ``blur_px`` and ``noise_sigma`` finite and >= 0, ``jpeg_quality`` None or a whole
    number in 1-100, every count in ``counts`` (specks, smears, pinholes) a whole number >= 0.
    Out of range, a degradation would not be applied (or OpenCV would clip it) while the
    scene's options record it."""
    from crosssection.core.errors import ParameterError

    for name, v in (("blur_px", blur_px), ("noise_sigma", noise_sigma)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not math.isfinite(float(v)) or v < 0:
            raise ParameterError(f"{name} must be a finite number >= 0, got {v!r}")
    if jpeg_quality is not None and (
            isinstance(jpeg_quality, bool)
            or not isinstance(jpeg_quality, (int, np.integer)) or not 1 <= jpeg_quality <= 100):
        raise ParameterError(f"jpeg_quality must be None or a whole number in 1-100, "
                             f"got {jpeg_quality!r}")
    for name, v in counts.items():
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ParameterError(f"{name} must be a whole number >= 0, got {v!r}")


def finish_scan(img: np.ndarray, rng: np.random.Generator, *, blur_px: float = 0.0,
                noise_sigma: float = 0.0, jpeg_quality: int | None = None) -> np.ndarray:
    """Blur, add noise, round to uint8 and optionally round-trip through JPEG.

    Parameters
    ----------
    img : (H, W, 3) float32 array
        The drawing (0..255 scale); not modified.
    rng : numpy.random.Generator
        Draws the noise (H * W * 3 numbers when ``noise_sigma > 0``).
    blur_px : float
        Gaussian blur sigma in pixels (0: none).
    noise_sigma : float
        Standard deviation of additive Gaussian noise, grey levels (0: none).
    jpeg_quality : int, optional
        JPEG quality of the round trip (None: none).

    Returns
    -------
    (H, W, 3) uint8 array

    Raises
    ------
    ParameterError
        A degradation outside its range (:func:`check_degradations`).
    """
    check_degradations(blur_px=blur_px, noise_sigma=noise_sigma, jpeg_quality=jpeg_quality)
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), float(blur_px))
    if noise_sigma > 0:
        img = img + rng.normal(0, noise_sigma, img.shape).astype(np.float32)
    rgb = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if jpeg_quality is not None:
        _, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        rgb = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()
    return rgb
