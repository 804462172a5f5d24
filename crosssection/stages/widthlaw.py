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
  for between 0.6 and 2.5 h (:data:`STEP_RANGE_H`): n sheets are at least n h thick, and the
  range reaches beyond by what a scale or a thickness given wrong by a third moves it.
- **Conservation fixes which step is one layer.** A junction whose packs read ``sum_A n =
  sum_B n`` gives ``sum_A w - sum_B w = a (|A| - |B|)``: every Y junction measures ``a``
  whatever ``b`` is. Their median picks, among the offsets the lattice allows (a whole step
  apart), the nearest one: it needs to be right to half a layer only.

The two parameters are then refitted by least squares on the whole numbers found, and the law
is followed out to the wide stacks range after range (:func:`_followed_out`), bending by a
term in ``n^2`` or ``sqrt(n)`` where the wide stacks ask for it: on the generators' law ``h
(n + 0.4 sqrt n)`` the thin stacks' line reads 17 layers as 16.3.

**The junctions judge the law.** The share of the clear junctions that the counts read through
it conserve (:func:`junction_closure`) is set against the share under ``w = n h``. The law is
refused where it closes fewer junctions than ``w = n h``, or, its lattice faint (contrast
below :data:`MIN_CONTRAST`), fewer than :data:`FAINT_MARGIN` junctions more; also where fewer
than :data:`MIN_JUNCTIONS` junctions measure the offset, one layer would be outside
:data:`ONE_LAYER_RANGE_H`, or every candidate law reads more than :data:`MAX_EMPTY_SHARE` of
the stacks' length as no layer (a drawing of single sheets only, whose junctions measure an
offset as wide as the sheets) or bends back within the widths. Then
the analysis reads ``w = n h`` and the ``no_calibration`` flag says why. A faint lattice is
no reason alone: widths scattered by 10 % from stack to stack (a cut's rim varies) fade the
lattice to a contrast of 0.2-0.56 while the law found still gives the calibration's counts,
the junction equations correcting what the scatter blurs.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from crosssection.core.calibration import Calibration

__all__ = ["WidthLawFit", "fit_width_law", "junction_offsets_mm", "lattice_contrast",
           "junction_closure", "MIN_CONTRAST", "FAINT_MARGIN", "MIN_JUNCTIONS",
           "ONE_LAYER_RANGE_H", "STEP_RANGE_H", "PLAUSIBLE_STEP_H"]

#: A lattice fainter than this is accepted only where the junctions prefer its law to w = n h
#: (noise of 0.17 b in width gives a contrast of about 0.55).
MIN_CONTRAST = 0.5
#: Junctions more conserved under a law of faint lattice than under w = n h for the law to be
#: kept (widths scattered by 10 % from stack to stack fade the lattice to 0.2-0.56).
FAINT_MARGIN = 2
#: Fewest junctions measuring the offset (Y junctions or any with unequal packs).
MIN_JUNCTIONS = 3
#: Stacks up to this many sheet thicknesses wide enter the lattice (the thick ones follow a
#: law that bends away from the thin ones' line).
LATTICE_MAX_WIDTH_H = 10.0
#: Widths (sheet thicknesses) up to which the law is followed out, range after range, from
#: the thin stacks' lattice (:func:`_followed_out`).
WIDENING_H = (15.0, 22.0, 33.0, 50.0, np.inf)
#: Largest share of the stacks' length a law may read as holding no layer (a sliver of ink).
MAX_EMPTY_SHARE = 0.05
#: Local maxima of the lattice contrast tried as the step; the junctions choose among them.
CANDIDATE_STEPS = 5
#: Among the laws whose counts conserve the most junctions, the widest step whose lattice
#: contrast is at least this share of the clearest one's is the layer (``b / k`` fits every
#: lattice ``b`` fits, and twice the counts conserve as well as the counts).
HARMONIC_SHARE = 0.8
#: Range of a one-layer width accepted, in sheet thicknesses (the paper's: 1.1-1.4 h; a
#: strongly melted rim, h (n + 2 sqrt n), makes it 3 h).
ONE_LAYER_RANGE_H = (0.3, 4.0)
#: Range of the step a layer adds to a stack's width, in sheet thicknesses: n sheets are at
#: least n h thick, and the search reaches below and above that by what a scale or a
#: thickness given wrong by a third moves it.
STEP_RANGE_H = (0.6, 2.5)
#: Steps outside this range (sheet thicknesses) are named in the flag as a scale or a
#: thickness likely wrong: a layer adding less than 0.9 h to a stack, or a cut adding more
#: than 0.8 h of rim per layer.
PLAUSIBLE_STEP_H = (0.9, 1.8)


@dataclass(frozen=True)
class WidthLawFit:
    """The width law ``w = offset_mm + step_mm n + quadratic_mm n^2 + root_mm sqrt(n)`` read
    from a scan (at most one of the last two terms).

    Attributes
    ----------
    ok : bool
        The law was found; otherwise ``reason`` says why and the analysis uses ``w = n h``.
    offset_mm, step_mm : float
        ``a`` and ``b`` (NaN when not found).
    contrast : float
        Lattice contrast of the thin stacks at the step (1: every stack on a whole number of
        layers).
    n_stacks, n_junctions : int
        Stacks in the lattice and junctions measuring the offset.
    reason : str
        Empty when ``ok``.
    quadratic_mm, root_mm : float
        ``c`` of a term ``c n^2`` or ``r`` of a term ``r sqrt(n)``, where the wide stacks bend
        the law away from the thin ones' line (at most one of them; 0 where they do not, or
        where there are none).
    closure, closure_linear : float
        Share of the clear junctions whose stacks' counts, read through the law and rounded,
        are conserved; the same under ``w = n h``.
    """

    ok: bool
    offset_mm: float
    step_mm: float
    contrast: float
    n_stacks: int
    n_junctions: int
    reason: str = ""
    quadratic_mm: float = 0.0
    root_mm: float = 0.0
    closure: float = float("nan")
    closure_linear: float = float("nan")

    @property
    def one_layer_mm(self) -> float:
        """Width of a stack of one layer under the law."""
        return self.width_mm(1.0)

    def width_mm(self, n):
        """Width of a stack of ``n`` layers under the law."""
        n = np.asarray(n, float)
        return (self.offset_mm + self.step_mm * n + self.quadratic_mm * n * n
                + self.root_mm * np.sqrt(np.maximum(n, 0.0)))

    def layers(self, width_mm):
        """Continuous layer count of a width under the law (its increasing branch)."""
        if self.root_mm:
            return _inverse_root(self.offset_mm, self.step_mm, self.root_mm, width_mm)
        return _inverse(self.offset_mm, self.step_mm, self.quadratic_mm, width_mm)

    @property
    def rising_layers(self) -> float:
        """Layers up to which the law rises at half its slope at one layer or more (infinite
        for a law that does not bend down; 0 for one that falls from the start)."""
        first = self.step_mm + 2.0 * self.quadratic_mm + 0.5 * self.root_mm
        if not first > 0:
            return 0.0
        if self.root_mm:
            # b + r / (2 sqrt n): rising for good where b > 0
            return float("inf") if self.step_mm > 0 else 0.0
        if self.quadratic_mm >= 0:
            return float("inf")
        # b + 2 c n = first / 2
        return (0.5 * first - self.step_mm) / (2.0 * self.quadratic_mm)

    def calibration(self, n_max: int = 50) -> Calibration:
        """The law as a :class:`Calibration` of ``n = 1..n_max``, extended linearly beyond,
        and beyond :attr:`rising_layers` for a law bending down (a fit refuses a law that
        bends down within the widths it was read from).

        Raises
        ------
        ConfigError
            The law falls from one layer on (no calibration of it exists).
        """
        n = np.arange(1, int(n_max) + 1, dtype=float)
        n = n[n <= max(self.rising_layers, 2.0)]
        return Calibration(tuple(n), tuple(self.width_mm(n)), source="fitted to the scan")

    @classmethod
    def from_record(cls, record: dict) -> "WidthLawFit":
        """The fit from its ``summary.json`` record (:meth:`record`; null read as NaN)."""
        return cls(**{k: (float("nan") if v is None else v) for k, v in record.items()})

    def formula(self) -> str:
        """The law as an equation, in mm: ``w = a + b n (+ c n^2 or + r sqrt(n)) mm``."""
        def term(x, fmt):  # a sign spaced as an operator: "+ 0.0495", "- 1.00e-03"
            return f" {'-' if x < 0 else '+'} {abs(x):{fmt}}"

        bend = (term(self.quadratic_mm, ".2e") + " n^2" if self.quadratic_mm else
                term(self.root_mm, ".4f") + " sqrt(n)" if self.root_mm else "")
        return f"w = {self.offset_mm:.4f} + {self.step_mm:.4f} n{bend} mm"

    def describe(self) -> str:
        """One line for messages and ``summary.json``."""
        if not self.ok:
            return f"no width law found in the scan ({self.reason})"
        return (f"{self.formula()} (one layer "
                f"{self.one_layer_mm:.3f} mm; lattice contrast {self.contrast:.2f} on "
                f"{self.n_stacks} stacks, offset from {self.n_junctions} junctions, counts "
                f"conserved at {self.closure:.0%} of them)")

    def record(self) -> dict:
        """The fit as ``summary.json`` records it."""
        return {"ok": bool(self.ok), "offset_mm": _num(self.offset_mm),
                "step_mm": _num(self.step_mm), "quadratic_mm": _num(self.quadratic_mm, 10),
                "root_mm": _num(self.root_mm, 8),
                "contrast": _num(self.contrast), "n_stacks": int(self.n_stacks),
                "n_junctions": int(self.n_junctions), "closure": _num(self.closure, 4),
                "closure_linear": _num(self.closure_linear, 4), "reason": self.reason}


def _inverse_root(a, b, r, w):
    """``n`` of ``w = a + b n + r sqrt(n)`` (b > 0), signed below ``a``."""
    x = np.asarray(w, float) - a
    s = 2.0 * x / (r + np.sqrt(np.maximum(r * r + 4.0 * b * x, 0.0)))
    return s * np.abs(s)


def _inverse(a, b, c, w):
    w = np.asarray(w, float)
    if c == 0.0:
        return (w - a) / b
    disc = np.maximum(b * b + 4.0 * c * (w - a), 0.0)
    # the root on the rising branch, written to stay exact as c -> 0
    return 2.0 * (w - a) / (b + np.sqrt(disc))


def _num(x: float, digits: int = 6):
    return None if not np.isfinite(x) else round(float(x), digits)


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
    """The lattice sum of the widths at every step.

    Parameters
    ----------
    widths, weights : (M,) arrays
        Stack widths (mm) and their weights (stack lengths).
    steps : (S,) array
        Lattice steps (mm).

    Returns
    -------
    (S,) complex array
        ``sum_i weights_i exp(2 pi i widths_i / step) / sum_i weights_i``: its modulus is
        the contrast (1: every width a whole number of steps), its phase the lattice's offset.
    """
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
    rows = list(rows)
    h = float(thickness_mm)
    w_all = np.asarray(width_mm, float)
    ell = np.asarray(length_mm, float)
    good = np.isfinite(w_all) & np.isfinite(ell) & (w_all > 0) & (ell > 0)
    w_good, ell_good = w_all[good], ell[good]
    offsets = junction_offsets_mm(w_all, rows)
    nj = len(offsets)
    thin = w_good <= LATTICE_MAX_WIDTH_H * h
    w, ell = w_good[thin], ell_good[thin]
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
    a_junctions = float(np.median(offsets))
    # the lattice's strongest steps and their multiples (b / m fits every lattice b fits) are
    # candidates, and the junctions choose among them: a cut whose rim varies blurs the
    # lattice until a wrong peak can be the highest
    cands = sorted({round(m * p, 12) for p in _peaks(steps, con) for m in range(1, 5)
                    if m * p <= hi})
    fits = [_law_at_step(b, w, ell, a_junctions, w_good, ell_good, h, nj) for b in cands]
    # a law bending back within the widths it was read from counts no stack twice over
    # (and a law whose one layer is no width is none)
    fits = [f for f in fits if f.one_layer_mm > 0
            and f.rising_layers >= float(np.max(f.layers(w_good)))]
    # judged through the table the analysis reads its counts from
    finite = np.isfinite(w_all)
    read = []
    for f in fits:
        r = np.full(len(w_all), np.nan)
        r[finite] = f.calibration().layers(w_all[finite])
        read.append(r)
    # every stack holds a layer: a law that reads stacks as none is no law of this scan
    empty = [float(ell_good[np.round(r[good]) < 1].sum() / ell_good.sum()) for r in read]
    fits = [replace(f, closure=junction_closure(r, rows))
            for f, r, e in zip(fits, read, empty) if e <= MAX_EMPTY_SHARE]
    if not fits:
        return WidthLawFit(**fail, reason=f"every law of the widths' lattice reads more than "
                                          f"{MAX_EMPTY_SHARE:.0%} of the stacks' length as no "
                                          "layer, or bends back within them")
    top = max(f.closure for f in fits)
    best = [f for f in fits if f.closure == top]
    # twice the counts conserve as well as the counts: among the laws the junctions like
    # best, the widest step whose lattice is about as clear as the clearest
    clear = max(f.contrast for f in best)
    widest = max(f.step_mm for f in best if f.contrast >= HARMONIC_SHARE * clear)
    # ... and of the laws near that step (a harmonic is 1.5 times off or more), the clearest
    fit = max((f for f in best if abs(f.step_mm / widest - 1.0) < 0.25),
              key=lambda f: f.contrast)
    # the share of the junctions that the counts it reads conserve, against the share under
    # w = n h (the law an analysis without one falls back to)
    closes, contrast = fit.closure, fit.contrast
    closes_nh = junction_closure(w_all / h, rows)
    fit = replace(fit, closure_linear=closes_nh)
    lo1, hi1 = ONE_LAYER_RANGE_H
    if not lo1 * h <= fit.one_layer_mm <= hi1 * h:
        return replace(fit, ok=False, reason=f"one layer would be {fit.one_layer_mm:.3g} mm "
                                             f"wide, not {lo1:g}-{hi1:g} h")
    # a faint lattice needs the junctions' clear preference: two of them more conserved
    margin = (closes - closes_nh) * len(rows)
    if closes < closes_nh or (contrast < MIN_CONTRAST and margin < FAINT_MARGIN - 1e-9):
        return replace(fit, ok=False, reason=(
            f"the widths show no layers the junctions confirm (lattice contrast "
            f"{contrast:.2f}; counts conserved at {closes:.0%} of the junctions under it, "
            f"{closes_nh:.0%} under w = n h)"))
    return fit


def _peaks(steps, con, k: int = CANDIDATE_STEPS) -> list[float]:
    """The steps of the ``k`` highest local maxima of the lattice contrast."""
    inner = np.flatnonzero((con[1:-1] >= con[:-2]) & (con[1:-1] >= con[2:])) + 1
    ends = [i for i in (0, len(con) - 1) if len(con) > 1 and
            con[i] >= con[1 if i == 0 else i - 1]]
    idx = np.concatenate([inner, np.asarray(ends, int)])
    idx = idx[np.argsort(-con[idx], kind="stable")][:k]
    return [float(steps[i]) for i in idx] or [float(steps[int(np.argmax(con))])]


def _law_at_step(b, w, ell, a_junctions, w_good, ell_good, h, nj) -> WidthLawFit:
    """The law of one candidate step: the offset from the lattice's phase and the junctions,
    both refitted on the whole numbers found and followed out to the wide stacks."""
    phase = float(np.angle(lattice_contrast(w, ell, [b])[0]))
    a_lattice = b * phase / (2.0 * np.pi)
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
    return _followed_out(WidthLawFit(ok=True, offset_mm=a, step_mm=b, contrast=contrast,
                                     n_stacks=int(len(w)), n_junctions=nj), w_good, ell_good, h)


def junction_closure(layers, rows) -> float:
    """Share of the conservation rows that the rounded counts satisfy exactly.

    Parameters
    ----------
    layers : (M,) array
        Continuous layer counts per stack (rounded here, at least 1).
    rows : iterable of dict
        Conservation rows ``{stack_id: coefficient}``.

    Returns
    -------
    float
        NaN without rows.
    """
    n = np.maximum(np.round(np.nan_to_num(np.asarray(layers, float), nan=1.0)), 1.0)
    rows = list(rows)
    if not rows:
        return float("nan")
    ok = sum(1 for row in rows if sum(c * n[k] for k, c in row.items()) == 0)
    return ok / len(rows)


def _followed_out(fit: WidthLawFit, w, ell, h: float) -> WidthLawFit:
    """The law followed out from the thin stacks to the wide ones.

    Stacks up to :data:`WIDENING_H` sheet thicknesses wide are taken in turn, each range
    read through the law of the narrower ones (which drifts from a bending law by less than
    half a layer over one range) and the law refitted on all stacks taken so far, with a
    term in ``n^2`` or ``sqrt(n)`` (the one that fits better) where the Bayesian information
    criterion asks for it: a cut's rim that grows with the stack bends the law one way or
    the other, and a square bends too much at 20 layers where a root follows. On the compacted
    renders' stacks of 10-25 layers the thin stacks' line reads 17 layers as 16.3.
    """
    law = replace(fit, quadratic_mm=0.0, root_mm=0.0)
    done = LATTICE_MAX_WIDTH_H
    for limit in WIDENING_H:
        if not np.any((w > done * h) & (w <= limit * h)):
            continue
        done = limit
        sel = w <= limit * h
        n = np.round(law.layers(w[sel]))
        keep = n >= 1
        m = int(np.count_nonzero(keep))
        if m < 6 or len(np.unique(n[keep])) < 3:
            break
        nk, wk, sw = n[keep], w[sel][keep], np.sqrt(ell[sel][keep])
        one = np.ones(m)
        fits = {}
        for term, col in (("line", None), ("quadratic_mm", nk * nk), ("root_mm", np.sqrt(nk))):
            X = np.column_stack([one, nk] + ([] if col is None else [col]))
            coef, rss, *_ = np.linalg.lstsq(X * sw[:, None], wk * sw, rcond=None)
            fits[term] = (coef, float(rss[0]) if len(rss) else 0.0)
        line, r1 = fits["line"]
        term = min(("quadratic_mm", "root_mm"), key=lambda t: fits[t][1])
        bent, r2 = fits[term]
        law = replace(law, offset_mm=float(line[0]), step_mm=float(line[1]), quadratic_mm=0.0,
                      root_mm=0.0)
        # one more parameter where the Bayesian information criterion asks for it
        if r2 > 0 and m * np.log(r1 / r2) > np.log(m):
            bent_law = replace(law, offset_mm=float(bent[0]), step_mm=float(bent[1]),
                               **{term: float(bent[2])})
            if bent_law.step_mm > 0 or term == "quadratic_mm":
                law = bent_law
    return law
