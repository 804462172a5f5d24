"""Stage 8a: the width law read from the scan itself, when no calibration is given.

Paper, section "Image analysis procedure": a stack's width gives its number of layers through
a calibration measured on cut stacks of known counts, because the hot-wire cut thickens a
stack. Without that measurement the law ``w = n h`` miscounts: a cut layer is 1.1-1.4 h wide
(the paper's calibration), so two layers read as three and the rod comes out about a quarter
too long (measured on generated scans: rod length +17 to +31 %, ``docs/validation``).

A scan holds its own calibration in two ways, and the fit uses both:

- **The widths' lattice fixes the step.** Stacks hold whole layers, so the widths ``w = a + b
  n`` sit on a lattice of step ``b``: ``b`` maximises the lattice contrast ``|sum_i l_i exp(2
  pi i w_i / b)| / sum_i l_i`` (stack lengths ``l_i`` as weights), and the phase of that sum
  gives ``a`` up to a whole step. Every ``b / k`` fits a lattice ``b`` fits, so the widest
  multiple of the best step whose contrast is near the best is the layer. The step is looked
  for between 0.8 and 2 h: n sheets are at least n h thick (0.8 leaves room for a scale or
  thickness off by a fifth), and a layer twice its thickness would be half air.
- **Conservation fixes which step is one layer.** A junction whose packs read ``sum_A n =
  sum_B n`` gives ``sum_A w - sum_B w = a (|A| - |B|)``: every Y junction measures ``a``
  whatever ``b`` is. Their median picks, among the offsets the lattice allows (a whole step
  apart), the nearest one: it needs to be right to half a layer only.

The two parameters are then refitted by least squares on the whole numbers found. Two
parameters are what the thin stacks support: on the generators' law ``h (n + 0.4 sqrt n)``
the affine law fitted to 1-6 layers reads 12 layers as 12.1; beyond that the junction
equations of the linear system correct what the widths miss. Where the scan shows no lattice
(contrast below :data:`MIN_CONTRAST`), too few junctions measure the offset, or the law found
gives a layer outside 0.5-2.5 h, the fit is refused and the analysis falls back to
``w = n h``, saying why.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from crosssection.core.calibration import Calibration

__all__ = ["WidthLawFit", "fit_width_law", "junction_offsets_mm", "lattice_contrast",
           "MIN_CONTRAST", "MIN_JUNCTIONS", "ONE_LAYER_RANGE_H", "STEP_RANGE_H"]

#: Lowest lattice contrast accepted: half the length of stacks within a sixth of a layer of a
#: whole number (noise of 0.17 b in width gives a contrast of about 0.55).
MIN_CONTRAST = 0.5
#: Fewest junctions measuring the offset (Y junctions or any with unequal packs).
MIN_JUNCTIONS = 3
#: Stacks up to this many sheet thicknesses wide enter the lattice (the thick ones follow a
#: law that bends away from the thin ones' line).
LATTICE_MAX_WIDTH_H = 10.0
#: A multiple of the best step is the layer when its contrast is at least this share of the
#: best one (``b / k`` fits every lattice ``b`` fits).
HARMONIC_SHARE = 0.8
#: Range of a plausible one-layer width, in sheet thicknesses (the paper's: 1.1-1.4 h).
ONE_LAYER_RANGE_H = (0.5, 2.5)
#: Range of the step a layer adds to a stack's width, in sheet thicknesses.
STEP_RANGE_H = (0.8, 2.0)


@dataclass(frozen=True)
class WidthLawFit:
    """The affine width law ``w = offset_mm + step_mm n`` read from a scan.

    Attributes
    ----------
    ok : bool
        The law was found; otherwise ``reason`` says why and the analysis uses ``w = n h``.
    offset_mm, step_mm : float
        ``a`` and ``b`` (NaN when not found).
    contrast : float
        Lattice contrast at the step (1: every stack on a whole number of layers).
    n_stacks, n_junctions : int
        Stacks in the lattice and junctions measuring the offset.
    reason : str
        Empty when ``ok``.
    """

    ok: bool
    offset_mm: float
    step_mm: float
    contrast: float
    n_stacks: int
    n_junctions: int
    reason: str = ""

    @property
    def one_layer_mm(self) -> float:
        """Width of a stack of one layer under the law."""
        return self.offset_mm + self.step_mm

    def calibration(self, n_max: int = 50) -> Calibration:
        """The law as a :class:`Calibration` of ``n = 1..n_max`` (extended linearly beyond)."""
        n = np.arange(1, int(n_max) + 1, dtype=float)
        return Calibration(tuple(n), tuple(self.offset_mm + self.step_mm * n),
                           source="fitted to the scan")

    def describe(self) -> str:
        """One line for messages and ``summary.json``."""
        if not self.ok:
            return f"no width law found in the scan ({self.reason})"
        return (f"w = {self.offset_mm:.4f} mm + {self.step_mm:.4f} mm x n (one layer "
                f"{self.one_layer_mm:.3f} mm; lattice contrast {self.contrast:.2f} on "
                f"{self.n_stacks} stacks, offset from {self.n_junctions} junctions)")

    def record(self) -> dict:
        """The fit as ``summary.json`` records it."""
        return {"ok": bool(self.ok), "offset_mm": _num(self.offset_mm),
                "step_mm": _num(self.step_mm), "contrast": _num(self.contrast),
                "n_stacks": int(self.n_stacks), "n_junctions": int(self.n_junctions),
                "reason": self.reason}


def _num(x: float):
    return None if not np.isfinite(x) else round(float(x), 6)


def junction_offsets_mm(width_mm, rows) -> np.ndarray:
    """The offset ``a`` each conservation row measures: ``sum c_k w_k / sum c_k``.

    Parameters
    ----------
    width_mm : (M,) array
        Stack widths.
    rows : iterable of dict
        Conservation rows ``{stack_id: coefficient}`` (``sum_A n - sum_B n``); rows whose
        coefficients sum to 0 (as many stacks on both sides) measure nothing and are skipped.

    Returns
    -------
    (J,) array of float
    """
    w = np.asarray(width_mm, float)
    out = []
    for row in rows:
        s = sum(row.values())
        if s == 0:
            continue
        vals = [c * w[k] for k, c in row.items()]
        if all(np.isfinite(vals)):
            out.append(sum(vals) / s)
    return np.asarray(out, float)


def lattice_contrast(widths, weights, steps) -> np.ndarray:
    """``sum_i weights_i exp(2 pi i widths_i / step) / sum_i weights_i`` for every step
    (complex: its modulus is the contrast, its phase the lattice's offset)."""
    u = np.asarray(widths, float)[None, :]
    wt = np.asarray(weights, float)
    c = np.exp(2j * np.pi * u / np.asarray(steps, float)[:, None]) @ wt
    return c / max(float(wt.sum()), 1e-300)


def fit_width_law(width_mm, length_mm, rows, *, thickness_mm: float) -> WidthLawFit:
    """Read the affine width law of a scan from its stacks and junctions.

    Parameters
    ----------
    width_mm, length_mm : (M,) arrays
        Each stack's width and length.
    rows : iterable of dict
        The junctions' conservation rows ``{stack_id: coefficient}``
        (:func:`crosssection.linsys.equations.conservation_equations`, the clear ones).
    thickness_mm : float
        Sheet thickness h: bounds the step searched (:data:`STEP_RANGE_H`).

    Returns
    -------
    WidthLawFit
    """
    h = float(thickness_mm)
    w_all = np.asarray(width_mm, float)
    ell = np.asarray(length_mm, float)
    good = np.isfinite(w_all) & np.isfinite(ell) & (w_all > 0) & (ell > 0)
    w, ell = w_all[good], ell[good]
    offsets = junction_offsets_mm(w_all, rows)
    nj = len(offsets)
    thin = w <= LATTICE_MAX_WIDTH_H * h
    w, ell = w[thin], ell[thin]
    fail = dict(ok=False, offset_mm=np.nan, step_mm=np.nan, contrast=np.nan,
                n_stacks=int(len(w)), n_junctions=nj)
    if nj < MIN_JUNCTIONS:
        return WidthLawFit(**fail, reason=f"{nj} junctions measure the offset, "
                                          f"fewer than {MIN_JUNCTIONS}")
    if len(w) < MIN_JUNCTIONS:
        return WidthLawFit(**fail, reason=f"{len(w)} stacks thin enough to show the layers")
    lo, hi = (f * h for f in STEP_RANGE_H)
    steps = np.linspace(lo, hi, 241)
    con = np.abs(lattice_contrast(w, ell, steps))
    k = int(np.argmax(con))
    best = float(con[k])
    # b / m fits every lattice b fits: the layer is the widest multiple of the best step
    # whose contrast is near the best
    b = b0 = float(steps[k])
    for m in range(2, 4):
        if m * b0 > hi:
            break
        if float(np.abs(lattice_contrast(w, ell, [m * b0])[0])) >= HARMONIC_SHARE * best:
            b = m * b0
    phase = float(np.angle(lattice_contrast(w, ell, [b])[0]))
    a_lattice = b * phase / (2.0 * np.pi)
    a_junctions = float(np.median(offsets))
    a = a_lattice + b * np.round((a_junctions - a_lattice) / b)
    # refined together on the whole numbers found (stacks of 1 layer and more)
    n = np.round((w - a) / b)
    keep = n >= 1
    if np.count_nonzero(keep) >= 3 and len(np.unique(n[keep])) >= 2:
        sw = np.sqrt(ell[keep])
        A = np.column_stack([np.ones(np.count_nonzero(keep)), n[keep]]) * sw[:, None]
        (a, b), *_ = np.linalg.lstsq(A, w[keep] * sw, rcond=None)
        a, b = float(a), float(b)
    contrast = float(np.abs(lattice_contrast(w - a, ell, [b])[0]))
    fit = WidthLawFit(ok=True, offset_mm=a, step_mm=b, contrast=contrast,
                      n_stacks=int(len(w)), n_junctions=nj)
    if contrast < MIN_CONTRAST:
        return replace(fit, ok=False, reason=f"the widths show no layers (lattice contrast "
                                             f"{contrast:.2f}, below {MIN_CONTRAST})")
    lo1, hi1 = ONE_LAYER_RANGE_H
    if not lo1 * h <= fit.one_layer_mm <= hi1 * h or not lo <= b <= hi:
        return replace(fit, ok=False, reason=f"one layer would be {fit.one_layer_mm:.3g} mm "
                                             f"wide and each more {b:.3g} mm, not "
                                             f"{lo1:g}-{hi1:g} h and {STEP_RANGE_H[0]:g}-"
                                             f"{STEP_RANGE_H[1]:g} h")
    return fit
