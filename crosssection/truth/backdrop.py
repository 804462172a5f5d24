"""What a real scan adds around a generated cross-section: the plate, its shadow, the light.

A generated scene is the cut cross-section on white paper. A real scan also shows

- the *plate* around the hole (the rod is pulled through a circular hole in a plate): grey,
  dark, brown or beige, bluish or any saturated colour, textured and noisy, sometimes with a
  dark rim of 1-3 px (shadow or bevel) just outside the hole's edge;
- uneven illumination: a smooth multiplicative gradient across the scanner bed;
- a colour cast: a gain per channel (white balance).

:func:`apply_backdrop` adds these to any generated RGB scan. Ink pressed against the wall stays
ink: the pixels of ``ink_mask`` are never replaced by the plate (illumination and cast apply
to them as to everything else, as on the scanner).
"""
from __future__ import annotations

import cv2
import numpy as np

from crosssection.core.errors import ParameterError

__all__ = ["PLATES", "apply_backdrop", "plate_rgb"]

#: Plate colours (uint8 RGB). "coloured" draws a saturated hue at random, away from the ink's
#: blue: a blue plate would be ink to any colour rule, only the hole's frame can exclude it.
PLATES = {
    "grey": (128.0, 125.0, 120.0),
    "dark": (42.0, 40.0, 38.0),
    "brown": (120.0, 85.0, 55.0),
    "beige": (200.0, 185.0, 155.0),
    "bluish": (120.0, 132.0, 160.0),
}
PLATE_NAMES = tuple(PLATES) + ("coloured",)


def plate_rgb(plate, rng) -> np.ndarray:
    """uint8-scale RGB of a plate name (see :data:`PLATES`, or ``"coloured"``) or an RGB triple."""
    if isinstance(plate, str):
        if plate == "coloured":
            # hue in degrees, 300 through red and yellow to 170: away from the ink's blue
            hue = rng.uniform(-60.0, 170.0) % 360.0
            hsv = np.array([[[hue / 2.0, rng.uniform(150, 230), rng.uniform(140, 220)]]], np.uint8)
            return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0].astype(np.float64)
        if plate not in PLATES:
            raise ParameterError(f"plate must be one of {PLATE_NAMES}, an RGB triple "
                                 f"(uint8 scale) or None (no plate), got {plate!r}")
        return np.array(PLATES[plate], np.float64)
    col = np.asarray(plate, np.float64).reshape(-1)
    if col.size != 3:
        raise ParameterError(f"plate RGB must have 3 values, got {plate!r}")
    if not (np.all(np.isfinite(col)) and col.min() >= 0.0 and col.max() <= 255.0):
        raise ParameterError(f"plate RGB values must lie in 0-255 (uint8 scale), got {plate!r}")
    return col


def _illumination_field(shape, amplitude, rng) -> np.ndarray:
    """Smooth multiplicative field with values in [1 - amplitude, 1 + amplitude].

    A linear gradient in a random direction plus a radial fall-off (lamp vignetting),
    rescaled so that the extreme deviation is exactly ``amplitude``.
    """
    H, W = shape
    rr, cc = np.mgrid[0:H, 0:W].astype(np.float32)
    rr = (rr - H / 2) / max(H, W)
    cc = (cc - W / 2) / max(H, W)
    ang = rng.uniform(0, 2 * np.pi)
    f = np.cos(ang) * cc + np.sin(ang) * rr
    f = f + rng.uniform(-1.0, 1.0) * (rr ** 2 + cc ** 2)
    f = f - 0.5 * (f.max() + f.min())
    span = float(np.abs(f).max())
    return (1.0 + amplitude * f / span if span > 0 else np.ones_like(f)).astype(np.float32)


def apply_backdrop(rgb, *, ink_mask, hole_center_rc, hole_radius_px, rng, plate="grey",
                   texture=8.0, rim_px=0.0, rim_gain=0.45, illumination=0.0,
                   cast=0.0) -> np.ndarray:
    """Put a plate around the hole, then uneven illumination and a colour cast.

    Parameters
    ----------
    rgb : (H, W, 3) uint8 or uint16 array
        A generated scan (paper, ink, receding surfaces).
    ink_mask : (H, W) bool array
        The ink; these pixels keep their colour where the plate would cover them.
    hole_center_rc : (2,) float
        Hole centre (row, col), px.
    hole_radius_px : float
        Hole radius, px; outside it the plate replaces the paper (anti-aliased edge).
    rng : numpy.random.Generator
        Every random choice (texture, coloured plate, gradient direction, cast).
    plate : str or (3,) float or None
        A name of :data:`PLATES`, ``"coloured"``, an RGB triple (uint8 scale), or None for no
        plate (white paper all around, as the generators draw it).
    texture : float
        Standard deviation (uint8 units) of the plate's texture: half a smooth grain (sigma
        2 px), half pixel noise.
    rim_px : float
        Width of a dark rim just outside the hole's edge (0: none; real scans 1-3 px).
    rim_gain : float
        Brightness factor of the rim.
    illumination : float
        Largest relative deviation of the multiplicative illumination field (0.15: +-15 %).
    cast : float
        Largest relative gain deviation per channel (0.06: +-6 %).

    Returns
    -------
    (H, W, 3) array of the input dtype
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype not in (np.uint8, np.uint16):
        raise ParameterError(f"apply_backdrop needs an (H, W, 3) uint8 or uint16 array, got "
                             f"{rgb.dtype} {rgb.shape}")
    ink = np.asarray(ink_mask, bool)
    if ink.shape != rgb.shape[:2]:
        raise ParameterError(f"ink_mask shape {ink.shape} differs from the image's {rgb.shape[:2]}")
    if not (0 <= illumination < 1 and 0 <= cast < 1 and rim_px >= 0 and hole_radius_px > 0):
        raise ParameterError("need 0 <= illumination, cast < 1, rim_px >= 0, hole_radius_px > 0")
    scale = 257.0 if rgb.dtype == np.uint16 else 1.0
    H, W = rgb.shape[:2]
    img = rgb.astype(np.float32) / scale
    if plate is not None:
        col = plate_rgb(plate, rng)
        rr, cc = np.ogrid[0:H, 0:W]
        d = np.hypot(rr - hole_center_rc[0], cc - hole_center_rc[1]).astype(np.float32)
        # fraction of each pixel outside the hole (linear ramp: anti-aliased edge)
        out = np.clip(d - hole_radius_px + 0.5, 0.0, 1.0)
        grain = cv2.GaussianBlur(rng.normal(0, 1, (H, W)).astype(np.float32), (0, 0), 2.0)
        grain *= texture / max(float(grain.std()), 1e-6) / np.sqrt(2)
        noise = rng.normal(0, texture / np.sqrt(2), (H, W, 3)).astype(np.float32)
        surface = col[None, None, :].astype(np.float32) + grain[..., None] + noise
        if rim_px > 0:
            # the rim lies outside the wall: R .. R + rim_px, with soft outer edge
            rim = np.clip(hole_radius_px + rim_px - d + 0.5, 0.0, 1.0) * (out > 0)
            surface *= (1.0 - (1.0 - rim_gain) * rim)[..., None]
        out = np.where(ink, 0.0, out)[..., None]
        img = img * (1.0 - out) + surface * out
    if illumination > 0:
        img *= _illumination_field((H, W), illumination, rng)[..., None]
    if cast > 0:
        img *= (1.0 + rng.uniform(-cast, cast, 3)).astype(np.float32)
    vmax = 65535 if scale > 1 else 255
    return np.clip(np.rint(img * scale), 0, vmax).astype(rgb.dtype)
