"""Stage 2: threshold on RGB values (paper Fig. 2).

Paper, section "Image analysis procedure": "only pixels of blue values larger than a given
threshold but of red and green values smaller than another given threshold are kept, allowing
to distinguish the cut edge from back receding surfaces and to remove noise".

Two methods:

- ``"fixed"`` (default): ``blue >= blue_min`` and ``red <= rg_max`` and ``green <= rg_max``;
  defaults for uint8 ``blue_min = 100``, ``rg_max = 130`` (scaled by 257 for uint16). They
  separate the ink (~ (40, 70, 190)) from grey-blue receding surfaces (red, green >= 190),
  light-blue smears (green >= 170) and white paper.
- ``"otsu"``: Otsu's threshold on the blue-dominance channel ``blue - max(red, green)``
  (ink ~ +120, paper and grey surfaces ~ 0-10, light-blue smears ~ +50), combined with the
  ``rg_max`` condition (default as above) which rejects the light smears that dominance alone
  may keep. Useful when the scanner's exposure differs from the defaults' scans. The Otsu
  threshold is reported as ``dominance_min``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crosssection.core.errors import ParameterError

BLUE_MIN_U8 = 100
RG_MAX_U8 = 130
METHODS = ("fixed", "otsu")


@dataclass
class ThresholdResult:
    """Binary mask and the thresholds used (native units of the image dtype).

    Attributes
    ----------
    mask : (H, W) bool array
    blue_min : float or None
        Blue lower bound (``None`` for ``"otsu"``, which thresholds dominance instead).
    rg_max : float
        Red and green upper bound.
    method : str
        ``"fixed"`` or ``"otsu"``.
    dominance_min : float or None
        ``"otsu"``: threshold on ``blue - max(red, green)``.
    scale : float
        1 for uint8 images, 257 for uint16 (the factor applied to the uint8 defaults).
    """

    mask: np.ndarray
    blue_min: float | None
    rg_max: float
    method: str
    dominance_min: float | None = None
    scale: float = 1.0

    def as_summary(self) -> dict:
        """JSON-friendly thresholds for ``summary.json``."""
        return {"method": self.method, "blue_min": self.blue_min, "rg_max": self.rg_max,
                "dominance_min": self.dominance_min, "dtype_scale": self.scale,
                "foreground_fraction": float(self.mask.mean()) if self.mask.size else 0.0}


def _scale(rgb) -> float:
    if rgb.dtype == np.uint8:
        return 1.0
    if rgb.dtype == np.uint16:
        return 257.0
    raise ParameterError(f"threshold needs a uint8 or uint16 RGB image, got {rgb.dtype}")


def _check_value(name, value, vmax):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}") from None
    if not (0 <= v <= vmax):
        raise ParameterError(f"{name}={value} outside the image range 0..{vmax:g}")
    return v


def threshold_rgb(rgb, *, blue_min=None, rg_max=None, method: str = "fixed") -> ThresholdResult:
    """Binary mask of the blue-inked cut edge.

    Parameters
    ----------
    rgb : (H, W, 3) uint8 or uint16 array
    blue_min : float, optional
        Minimum blue (native units); default 100 for uint8, 100 * 257 for uint16. Ignored by
        ``"otsu"``.
    rg_max : float, optional
        Maximum red and green (native units); default 130 (uint8), 130 * 257 (uint16).
    method : {"fixed", "otsu"}
        See the module docstring.

    Returns
    -------
    ThresholdResult
    """
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ParameterError(f"threshold needs an (H, W, 3) RGB array, got shape {rgb.shape}")
    if method not in METHODS:
        raise ParameterError(f"threshold method must be one of {METHODS}, got {method!r}")
    scale = _scale(rgb)
    vmax = 255.0 * scale
    rg = RG_MAX_U8 * scale if rg_max is None else _check_value("rg_max", rg_max, vmax)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    rg_t = rgb.dtype.type(min(int(np.floor(rg)), int(vmax)))
    if method == "fixed":
        bm = BLUE_MIN_U8 * scale if blue_min is None else _check_value("blue_min", blue_min,
                                                                         vmax)
        b_t = int(np.ceil(bm))
        if b_t > vmax:
            mask = np.zeros(rgb.shape[:2], bool)
        else:
            mask = (b >= rgb.dtype.type(b_t)) & (r <= rg_t) & (g <= rg_t)
        return ThresholdResult(mask, float(bm), float(rg), "fixed", None, scale)
    from skimage.filters import threshold_otsu

    dom = b.astype(np.int32) - np.maximum(r, g).astype(np.int32)
    if dom.min() == dom.max():
        t = float(dom.max()) + 1.0  # uniform image: nothing dominates
    else:
        # Otsu on the positive part: the image is mostly neutral paper (dominance ~ 0)
        t = float(threshold_otsu(dom))
        t = max(t, 1.0)
    mask = (dom >= t) & (r <= rg_t) & (g <= rg_t)
    return ThresholdResult(mask, None, float(rg), "otsu", t, scale)
