"""Width error model: how much each stack's width equation is trusted.

``e_i`` is the continuous layer estimate of stack ``i`` from its width (widths stage) and
``sigma_i = s (noise_layers + noise_growth (e_i - 1))`` its error: the error grows with the
stack thickness (the paper's thick stacks are the ones with +-1 errors), and the scale ``s``
is measured on the data (:func:`estimate_noise_scale`). The weight of the width equation is
``w_i = r_i / sigma_i^2`` with a user reliability ``r_i``, so that every width contributes to
the integer least squares in proportion to its reliability.

Measured with an error that does not grow (``noise_growth = 0``): where the widths are
calibrated and sharp, thick stacks are as good as thin ones (renders of rods compacted to
epsilon 14-19: estimates of matched 5-19-layer stacks within 0.15 of the truth), and the
growth lets the solve shift whole chains of thick stacks by one layer rather than violate one
junction (exact n_br there 0.81 -> 0.87 at epsilon 19, 0.88 -> 0.94 at 14, thick stacks
wrong 24/96 -> 12/96; an independent generator's worst scene 0.91 -> 0.98; the robust
sweep's 48 scenes unchanged). But where the widths are systematically off, the growth is what
keeps conservation in charge: without a calibration a simulator render fell from 0.85 to
0.35 exact, and at blur 3 px with h = 2-4 px network scenes fell by 0.14-0.23 (validation
atlas, ``variants`` and ``map_h_blur``). Not kept: the default stays :data:`NOISE_GROWTH`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WidthWeights", "estimate_noise_scale", "width_weights", "NOISE_LAYERS",
           "NOISE_GROWTH"]

#: Width error of a one-layer stack before scaling (layers).
NOISE_LAYERS = 0.3
#: Growth of the width error per layer beyond the first (module docstring).
NOISE_GROWTH = 0.05


@dataclass(frozen=True)
class WidthWeights:
    """Width estimates and their weights, ready for the least squares.

    Attributes
    ----------
    layers : (M,) array
        Estimates, 1 where the input is not finite.
    sigma : (M,) array
        Error of each estimate (layers), scale included.
    weights : (M,) array
        ``reliability / sigma^2``, 0 where the estimate is not finite.
    weights_eff : (M,) array
        ``weights`` floored at ``1e-6 max(weights)``: keeps every problem bounded and the
        least-squares system positive definite.
    noise_scale : float
        The scale ``s`` applied to the model.
    """

    layers: np.ndarray
    sigma: np.ndarray
    weights: np.ndarray
    weights_eff: np.ndarray
    noise_scale: float


def estimate_noise_scale(layers_est, sigma_model, *, lo: float = 0.25,
                         hi: float = 1.0) -> float:
    """Scale of the width error model measured on the data.

    The distance of each estimate to the nearest integer, ``r = e - round(e)``, is the width
    error wherever it is below half a layer.  ``1.4826 median(|r| / sigma_model)`` is 1 for
    Gaussian errors that follow the model and smaller for better widths (clean scans);
    systematic offsets count (``|r|`` about zero, not about its median), and errors of half
    a layer or more saturate it near 1, so the model is never trusted *more* than the data
    allow.  Clipped to ``[lo, hi]``; 1 with fewer than 5 finite estimates.

    Parameters
    ----------
    layers_est, sigma_model : (M,) arrays
    lo, hi : float
        Clipping range.

    Returns
    -------
    float
    """
    e = np.asarray(layers_est, float)
    s = np.asarray(sigma_model, float)
    ok = np.isfinite(e) & np.isfinite(s) & (s > 0)
    if ok.sum() < 5:
        return 1.0
    r = np.abs(e[ok] - np.round(e[ok])) / s[ok]
    return float(np.clip(1.4826 * np.median(r), lo, hi))


def width_weights(layers_est: np.ndarray, *, reliability=None,
                  noise_layers: float = NOISE_LAYERS, noise_growth: float = NOISE_GROWTH,
                  noise_scale="auto") -> WidthWeights:
    """Errors and weights of the width estimates under the model of the module docstring.

    Parameters
    ----------
    layers_est : (M,) array
        Continuous layer estimates (NaN allowed: weight 0).
    reliability : (M,) array, optional
        Non-negative multiplier of each weight; non-finite values count as 0.
    noise_layers, noise_growth : float
        ``sigma = noise_layers + noise_growth (e - 1)`` before scaling.
    noise_scale : float or "auto"
        ``s``; "auto" measures it with :func:`estimate_noise_scale`.

    Returns
    -------
    WidthWeights

    Raises
    ------
    ValueError
        On an unknown ``noise_scale`` string or a ``reliability`` of the wrong length.
    """
    e_raw = np.asarray(layers_est, dtype=float).reshape(-1)
    finite = np.isfinite(e_raw)
    e = np.where(finite, e_raw, 1.0)
    sigma = noise_layers + noise_growth * np.maximum(e - 1.0, 0.0)
    if isinstance(noise_scale, str):
        if noise_scale != "auto":
            raise ValueError(f"noise_scale must be a number or 'auto', got {noise_scale!r}")
        noise_scale = estimate_noise_scale(e_raw, sigma)
    sigma = sigma * float(noise_scale)
    w = 1.0 / sigma ** 2
    if reliability is not None:
        r = np.asarray(reliability, dtype=float).reshape(-1)
        if len(r) != len(e_raw):
            raise ValueError(f"reliability has {len(r)} values for {len(e_raw)} stacks")
        w = w * np.clip(np.where(np.isfinite(r), r, 0.0), 0.0, None)
    w = np.where(finite, w, 0.0)
    w_floor = 1e-6 * (np.max(w) if np.any(w > 0) else 1.0)
    return WidthWeights(layers=e, sigma=sigma, weights=w,
                        weights_eff=np.maximum(w, w_floor), noise_scale=float(noise_scale))
