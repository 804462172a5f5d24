"""Write the statistics report: tables (CSV + Markdown), figures (PNG), stats.json, report.html.

Figures follow the paper's style: probability densities in linear and logarithmic scales, one
panel row per sub-system (all branches, bulk, periphery), every set overlaid in its own colour
(the same colour in every figure, :func:`set_colors`). The data are points with counting
error bars, sqrt(count) / (n * bin width), the count's Poisson error in whole stacks where
branches repeat their stack's value (:func:`_bin_errors`); the selected law is a line with its
95 % bootstrap band (the pointwise 2.5-97.5 % quantiles of the law over the bootstrap replicates of its
parameters). The number of branches per stack is an integer: it is drawn as a probability mass
function, the fraction of stacks at each k against the fitted law's mass at k.
"""
from __future__ import annotations

import errno
import functools
import html
import json
import os
import shutil
import textwrap
import warnings
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection._version import __version__
from crosssection.core.errors import OutputError, ParameterError
from crosssection.core.fileio import (BROWSER_FILES, clear_stale_folders, exclusive_lock,
                                      foreign_entry,
                                      save_figure, staging_folder, swap_in_folder, write_csv,
                                      write_json, write_text)
from crosssection.core.provenance import library_versions
from crosssection.stats import fits as F
from crosssection.stats.families import FAMILIES
from crosssection.stats.data import REPORT_TABLES, Ensemble, branch_groups
from crosssection.stats.tables import (CORRELATION_MIN_PAIRS, COUNT_COLUMNS, COUNT_QUANTITIES,
                                       EQ12_CONST, N_RELATION_MIN, PAPER_DOF, PAPER_MACRO,
                                       PAPER_MICRO, QUANTITIES, StatsOptions, StatsResult,
                                       compute_stats, count_text, regions_of, relation_note,
                                       n_text, set_seed, small_sample_note, to_markdown)

# Okabe-Ito colours (distinguishable with the common colour-vision deficiencies), in the
# order of the sets; the set's index in the ensemble fixes its colour in every figure.
PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000",
           "#F0E442")
BAND_LEVEL = 0.95
#: fewest and most histogram bins of a distribution figure; between them numpy's "auto" rule
#: (the larger of Sturges' and Freedman-Diaconis' counts), at most 2 sqrt(n), sets the number
#: from the values
BINS_MIN, BINS_MAX = 5, 50

#: axis labels in words with units (lengths in units of the rod length L)
LABELS = {
    "length_L": r"branch length $\ell/L$ (dimensionless)",
    "kappa_m_L": r"mean branch curvature $|\kappa_m| L$ (dimensionless)",
    "kappa_plus_L": r"mean absolute branch curvature $\kappa_+ L$ (dimensionless)",
    # a scan's e is its bending energy; a simulated branch's adds its confinement energy
    # (paper, Eq. of the energy over a domain Omega): the Methods paragraph says which
    "e": r"branch energy $e$ (dimensionless)",
    "E": r"total energy of a configuration $E$ (dimensionless)",
    "n_br": r"number of branches per stack $n_{br}$",
    "area_L2": r"void area $s/L^2$ (dimensionless)",
    "shape_ratio": r"void shape ratio $\sqrt{s}/p$ (dimensionless)",
}
#: the same quantities in plain words, for captions and tables
WORDS = {
    "length_L": "branch length l/L", "kappa_m_L": "mean branch curvature |κ_m| L",
    "kappa_plus_L": "mean absolute branch curvature κ₊ L",
    "e": "branch energy e", "E": "total energy E of a configuration",
    "n_br": "number of branches per stack n_br", "area_L2": "void area s/L²",
    "shape_ratio": "void shape ratio √s/p",
}
REGION_WORDS = {"all": "whole system", "bulk": "bulk (no wall contact)",
                "periphery": "periphery (touching the wall)"}

#: The libraries a report's numbers rest on, recorded in stats.json.
STATS_LIBRARIES = ("numpy", "scipy", "pandas", "matplotlib")


#: A BIC difference below which the selection between two laws is not decided by the data
#: ("not worth more than a bare mention", Kass & Raftery 1995, J. Am. Stat. Assoc. 90, 773)
BIC_UNDECIDED = 2.0


def _wrap_label(text: str, width: int) -> str:
    """``textwrap.fill`` that never breaks inside ``$...$`` (a split formula is printed raw)
    nor inside parentheses (a unit such as "(rod length L)" is not left with "L)" alone on
    the next line)."""
    out, math, depth = [], False, 0
    for ch in text:
        if ch == "$":
            math = not math
        elif not math and ch in "()":
            depth = max(depth + (1 if ch == "(" else -1), 0)
        out.append("\x00" if ch == " " and (math or depth) else ch)
    return textwrap.fill("".join(out), width, break_long_words=False,
                         break_on_hyphens=False).replace("\x00", " ")


def set_colors(sets) -> dict:
    """Colour of every set, by its position in ``sets`` (the ensemble's order), so that a set
    keeps its colour across all figures of a report."""
    return {s: PALETTE[i % len(PALETTE)] for i, s in enumerate(sets)}


def _subplots(nrows=1, ncols=1, figsize=(6, 4.5)):
    """A figure with constrained layout and its axes, without pyplot: no GUI backend is
    touched and a notebook's backend is left alone."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes


#: candidate mantissas of the labelled ticks of a log axis, densest first: the axis is
#: labelled at the densest whose labels keep apart (every whole multiple on a range of less
#: than a decade, then 1-2-5, 1-3, one mantissa per decade, then every 2nd, 3rd... power of
#: ten)
LOG_LABEL_SUBS = (tuple(float(k) for k in range(1, 10)), (1.0, 2.0, 5.0), (1.0, 3.0), (1.0,))
#: the least gap between two neighbouring tick labels of a log axis, in units of their font
#: size
LOG_LABEL_GAP_EM = 0.6
#: the drawn width of a label over the width of its glyphs' outlines (mathtext's spacing),
#: erring on the side of fewer labels
LOG_LABEL_WIDTH_MARGIN = 1.2


def _log_tick_values(lo: float, hi: float, subs, step: int = 1) -> np.ndarray:
    """``m 10^k`` for ``m`` in ``subs`` and every ``step``-th power ``k``, from the decade
    below ``lo`` to the one above ``hi``."""
    k0, k1 = int(np.floor(np.log10(lo))) - 1, int(np.ceil(np.log10(hi))) + 1
    return np.array(sorted(m * 10.0 ** k for k in range(k0, k1 + 1) if k % step == 0
                           for m in subs))


def _log_labels_fit(ticks, lo: float, hi: float, length_px: float, sizes) -> bool:
    """Whether the labels of the ``ticks`` inside ``[lo, hi]`` keep apart on a log axis
    ``length_px`` pixels long; ``sizes(values)`` gives their extents along the axis and the
    least gap between two, in pixels."""
    inside = ticks[(ticks >= lo * (1 - 1e-9)) & (ticks <= hi * (1 + 1e-9))]
    if inside.size < 2:
        return True
    pos = length_px * np.log(inside / lo) / np.log(hi / lo)
    size, gap = sizes(inside)
    return bool(np.all(np.diff(pos) >= (size[1:] + size[:-1]) / 2 + gap))


@functools.lru_cache(maxsize=4096)
def _label_extent(text: str, prop) -> tuple[float, float]:
    """(width, height) in points of a tick label's outline: measured once per text and font
    (a mathtext outline takes about a millisecond, and every draw of every log axis asks
    for the same few labels)."""
    from matplotlib.textpath import TextPath

    ext = TextPath((0, 0), text, prop=prop).get_extents()
    return float(ext.width), float(ext.height)


def _labelled_log_locator():
    """A matplotlib locator of the labelled (major) ticks of a log axis: the densest
    candidate of :data:`LOG_LABEL_SUBS`, then every 2nd, 3rd... power of ten, whose labels
    (:func:`_power_label`) keep apart.

    The choice is made each time the axis is drawn, from the length it then has (after the
    figure's layout) and the extent of each label's text: neither the panel's final width
    nor its span is known when the ticks are set up, and no fixed rule suits every span and
    width (labels at 1, 2 and 5 over two decades need a panel about six inches wide).
    """
    from matplotlib.ticker import Locator

    class LabelledLogLocator(Locator):
        def __call__(self):
            return self.tick_values(*self.axis.get_view_interval())

        def tick_values(self, vmin, vmax):
            lo, hi = sorted((float(vmin), float(vmax)))
            if not (lo > 0 and np.isfinite(hi) and hi > lo):
                return np.array([])
            along_x = self.axis.axis_name == "x"
            ax = self.axis.axes
            length_px = ax.bbox.width if along_x else ax.bbox.height
            prop = self.axis.majorTicks[0].label1.get_fontproperties()
            px = ax.figure.dpi / 72.0  # points to pixels

            em = prop.get_size_in_points() * px

            def sizes(values):
                if len(values) * (1.0 + LOG_LABEL_GAP_EM) * em > length_px:
                    # more labels than fit at one em each (a view of many decades): the
                    # outlines need not be measured
                    return np.full(len(values), length_px), LOG_LABEL_GAP_EM * em
                ext = [_label_extent(_power_label(v), prop) for v in values]
                size = np.array([w * LOG_LABEL_WIDTH_MARGIN if along_x else h
                                 for w, h in ext])
                return size * px, LOG_LABEL_GAP_EM * em

            decades = np.log10(hi / lo)
            # densest first; at one label per decade, the mantissa that puts the most labels
            # in view (a span of a decade and a half may hold one power of ten only)
            levels = [[(subs, 1)] for subs in LOG_LABEL_SUBS[(0 if decades < 1 else 1):]]
            levels[-1] += [((m,), 1) for m in (2.0, 3.0, 5.0)]
            levels += [[((1.0,), step)] for step in range(2, int(decades) + 2)]
            ticks = np.array([])
            for level in levels:
                fits = [t for t in (_log_tick_values(lo, hi, subs, step)
                                    for subs, step in level)
                        if _log_labels_fit(t, lo, hi, length_px, sizes)]
                if fits:
                    return max(fits, key=lambda t: np.sum((t >= lo * (1 - 1e-9))
                                                          & (t <= hi * (1 + 1e-9))))
                ticks = _log_tick_values(lo, hi, *level[0])
            return ticks

    return LabelledLogLocator()


def _log_ticks(axis):
    """Label a log axis at powers of ten and, where room allows, at 1-2-5 (or 1-3, or every
    whole) multiples of them, chosen when drawn so that no two labels meet
    (:func:`_labelled_log_locator`); the other ticks are unlabelled minor ticks.

    matplotlib's own log labels leave out the 2s and 5s of a range of one or two decades,
    which then shows one or two labels, and label every minor tick of a shorter range, where
    they overlap.
    """
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    axis.set_major_locator(_labelled_log_locator())
    axis.set_major_formatter(FuncFormatter(lambda v, _: _power_label(v)))
    # unlabelled ticks at every whole multiple, the powers of ten among them where the labels
    # skip some (ticks at a major tick's place are not drawn twice)
    axis.set_minor_locator(LogLocator(base=10, subs=tuple(float(k) for k in range(1, 10)),
                                      numticks=100))
    axis.set_minor_formatter(NullFormatter())


def _power_label(v: float) -> str:
    """``v`` as ``m×10^k`` in mathtext (``10^k`` for m = 1)."""
    if not (v > 0 and np.isfinite(v)):
        return ""
    k = int(np.floor(np.log10(v) + 1e-9))
    m = round(v / 10.0 ** k, 6)
    if m >= 10:
        m, k = m / 10, k + 1
    mant = "" if abs(m - 1) < 1e-6 else f"{m:g}\\times"
    return f"${mant}10^{{{k}}}$"


def _scaled_label(label: str, power: int) -> str:
    """An axis label whose ticks read the quantity in units of ``10^power``: its symbol
    times ``10^-power`` (E read 1-4 on ticks of 1e4-4e4 is labelled 10^-4 E), or the words
    "in units of 10^power" for a label without a symbol."""
    if not power:
        return label
    i = label.find("$")
    if i < 0:
        return f"{label}, in units of $10^{{{power}}}$"
    return f"{label[:i + 1]}10^{{{-power}}}\\,{label[i + 1:]}"


def _linear_ticks(axis, small: float = 1e-2) -> int:
    """At most 5 labels; for an axis reaching below ``small`` or beyond 1e4, labels in units
    of a power of ten, returned (0: none) for the axis label to name. Plain labels such as
    0.00015 on a 4-inch axis run into each other, and matplotlib's own "x10^k" beside the axis
    lies under the end of a two-line axis label."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    axis.set_major_locator(MaxNLocator(nbins=5))
    top = max(abs(v) for v in axis.get_view_interval())
    power = int(np.floor(np.log10(top))) if top > 0 and (top >= 1e4 or top < small) else 0
    scale = 10.0 ** power
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / scale:.6g}"))
    return power


#: the longest set name a figure's legend spells out (longer ones shrank the panels, clipped
#: their titles and ran their tick labels together)
LEGEND_NAME_MAX = 28


def _short(name: str) -> str:
    """``name`` whole up to :data:`LEGEND_NAME_MAX` characters, else its start and end
    around an ellipsis, :data:`LEGEND_NAME_MAX` characters in all."""
    name = str(name)
    if len(name) <= LEGEND_NAME_MAX:
        return name
    keep = (LEGEND_NAME_MAX - 1) // 2
    return f"{name[:keep]}…{name[-(LEGEND_NAME_MAX - 1 - keep):]}"


def legend_names(sets) -> dict:
    """Each set's name as a figure's legend gives it (the report's tables spell it out).

    Names up to :data:`LEGEND_NAME_MAX` characters are kept whole. Longer ones are shortened
    around an ellipsis (:func:`_short`); where two of them would read the same, each keeps
    the part that tells it from the others, with as much of its start and end as the length
    allows; where even that part is too long, every name is kept whole.

    Parameters
    ----------
    sets : iterable of str

    Returns
    -------
    dict
        Set -> its name in a legend.
    """
    import os

    names = list(dict.fromkeys(str(s) for s in sets))
    out = {s: _short(s) for s in names}
    groups = {}
    for n in names:
        groups.setdefault(out[n], []).append(n)
    for same in (g for g in groups.values() if len(g) > 1):
        pre = len(os.path.commonprefix(same))
        suf = len(os.path.commonprefix([n[::-1] for n in same]))
        for n in same:
            core = n[pre:len(n) - suf]
            budget = LEGEND_NAME_MAX - len(core) - 2
            if not core or budget < 2:
                return {m: m for m in names}
            head = min(pre, budget // 2)
            tail = min(suf, budget - head)
            out[n] = (n[:head] + ("…" if head < pre else "") + core
                      + ("…" if tail < suf else "") + (n[len(n) - tail:] if tail else ""))
    return out if len(set(out.values())) == len(names) else {m: m for m in names}


def bin_edges(x, log: bool = False) -> np.ndarray:
    """Histogram bin edges of the values ``x`` (finite; > 0 when ``log``).

    The number of bins follows the number and spread of the values: numpy's "auto" rule, at
    most 2 sqrt(n) (Freedman-Diaconis gives a long tail many nearly empty bins), held between
    :data:`BINS_MIN` and :data:`BINS_MAX`. A fixed count would leave a dozen values one to a
    bin, a flat row of single counts.

    Parameters
    ----------
    x : array of float
    log : bool
        Equal bins of log(x), for a logarithmic axis.

    Returns
    -------
    array of float
        Increasing edges from ``x.min()`` to ``x.max()``.
    """
    v = np.log(np.asarray(x, float)) if log else np.asarray(x, float)
    lo, hi = float(v.min()), float(v.max())
    if hi <= lo:  # one value: one bin around it
        edges = np.array([lo - 0.5, lo + 0.5]) if not log else np.array([lo - 0.05, lo + 0.05])
    else:
        k = min(len(np.histogram_bin_edges(v, bins="auto")) - 1, 2.0 * np.sqrt(v.size))
        edges = np.linspace(lo, hi, int(np.clip(k, BINS_MIN, BINS_MAX)) + 1)
    if not log:
        return edges
    edges = np.exp(edges)
    if hi > lo:  # exp(log(x)) rounds: the end edges are the values themselves, kept in
        edges[0], edges[-1] = np.min(x), np.max(x)
    return edges


def _nanmean(v) -> float:
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else float("nan")


def _count_mean(r: F.FitResult, top: int = 10_000) -> float:
    """Mean of a law fitted as counts: ``sum k P(k)`` over k = 1 .. ``top``."""
    kk = np.arange(1, top)
    return float(np.sum(kk * r.pmf(kk)))


def _fit_text(r: F.FitResult) -> str:
    p = r.p_text()
    return r.label() + (f", GOF {p}" if p else "")


def _curve(r: F.FitResult, params, xs, cut, count: bool):
    """The law ``r`` with ``params`` at ``xs``: masses at the integers for counts, else the
    density (renormalised above the detection limit ``cut`` of a truncated fit)."""
    if count:
        return r.pmf(xs, params)
    y = FAMILIES[r.family].pdf(params, xs)
    if r.truncated and cut is not None:
        y = np.where(xs >= cut, y / FAMILIES[r.family].sf(params, cut), np.nan)
    return y


def _band(r: F.FitResult, xs, cut, count: bool, level=BAND_LEVEL):
    """Pointwise ``level`` band of the law over its bootstrap replicates, or None.

    Drawn only where at least ``level`` of the replicates hold ``x`` in their support, from
    those replicates: a law bounded by its sample's extremes (Bose-Einstein's ``x_lo``,
    ``x_hi``) has a support that moves from replicate to replicate, and where some replicates
    are 0 the band would run from 0 to the law's height, a slab over decades of density on a
    log axis."""
    reps = r.replicates()
    if len(reps) < 10:  # too few replicates for a 95 % band
        return None
    with np.errstate(all="ignore"):
        ys = np.array([_curve(r, p, xs, cut, count) for p in reps], float)
    inside = np.isfinite(ys) & (ys > 0)
    ys = np.where(inside, ys, np.nan)
    q = (1 - level) / 2
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            lo, hi = np.nanquantile(ys, q, axis=0), np.nanquantile(ys, 1 - q, axis=0)
    shared = inside.mean(axis=0) >= level
    return np.where(shared, lo, np.nan), np.where(shared, hi, np.nan)


def _sample(ens: Ensemble, set_name, reg, quantity, summ):
    """The fitted values of one set and region, the mean detection limit (or None) and the
    range (smallest, largest) of the per-scan limits (or None).

    The mean renormalises the drawn law above one cut; the range is what is drawn as the
    detection limit, since the scans' limits (each in units of its own L) differ."""
    table, col, _, tcol, _ = QUANTITIES[quantity]
    df = getattr(ens.subset(set_name), table)
    if reg != "all" and "region" in df.columns:
        df = df[df["region"].astype(str) == reg]
    x = np.asarray(df[col], float)
    ok = np.isfinite(x) & (x > 0)
    cut = span = None
    r0 = next(iter(summ.results.values()))
    if tcol is not None and r0.truncated:
        c = np.asarray(df[tcol], float)
        cut = float(np.nanmean(c[ok]))
        span = (float(np.nanmin(c[ok])), float(np.nanmax(c[ok])))
        ok &= x >= c
    groups = (branch_groups(df) if table == "branches"
              else np.full(len(df), None, dtype=object))
    return x[ok], cut, span, groups[ok]


def _bin_errors(bins: np.ndarray, groups, n_bins: int) -> np.ndarray:
    """Counting error of each bin, sqrt(sum over its groups of their count squared): the
    branches of one stack repeat its value and fall in one bin together, so a bin's count
    varies by whole stacks (Poisson in the stacks); a value without a group counts alone,
    which is sqrt(count).

    Parameters
    ----------
    bins : (n,) int array
        The bin of each value (-1: none).
    groups : (n,) object array
        Group labels (:func:`~crosssection.stats.data.branch_groups`; None: its own group).
    n_bins : int
    """
    keep = bins >= 0
    labels = [g if g is not None else ("own", i) for i, g in enumerate(groups)]
    codes = pd.factorize(pd.Series(labels, dtype=object))[0]
    pairs = pd.DataFrame({"bin": bins[keep], "group": codes[keep]})
    sizes = pairs.groupby(["bin", "group"]).size()
    var = (sizes.astype(float) ** 2).groupby(level=0).sum()
    out = np.zeros(n_bins)
    out[var.index.to_numpy(int)] = var.to_numpy()
    return np.sqrt(out)


def _limits_label(name: str, span) -> str:
    """The legend entry of a set's detection limits ``span`` = (smallest, largest): a range
    where its ends differ at the two digits shown, one value where they do not (a range
    such as "0.0056-0.0056" reads as a misprint)."""
    lo, hi = f"{span[0]:.2g}", f"{span[1]:.2g}"
    if lo == hi:
        return f"{name}: detection limit {hi} (dotted)"
    return f"{name}: detection limits {lo}-{hi} (per scan, shaded; dotted: largest)"


def pdf_figure(res: StatsResult, ens: Ensemble, quantity: str, sets=None, colors=None):
    """Distribution of one quantity, every set overlaid, with the selected laws.

    One panel row per sub-system (whole system, bulk, periphery when present), linear and
    logarithmic density scales side by side. Points: fraction per unit of the quantity in
    :func:`bin_edges` bins (their number follows the number of values), with counting error
    bars sqrt(count) / (n * bin width), counted in stacks where branches repeat their stack's
    value (:func:`_bin_errors`); line: the selected law, shaded: its 95 % bootstrap
    band. For counts (``n_br``) the points are the fraction of stacks at each integer and the
    line the law's probability mass there. A set of ``sets`` without a fit (too few values, or
    all equal) is named in the legend of each row it is missing from.

    Parameters
    ----------
    res : StatsResult
    ens : Ensemble
    quantity : str
    sets : sequence of str, optional
        Sets to draw (default: every set of ``ens`` with a fit).
    colors : dict, optional
        Set -> colour (default :func:`set_colors` of ``ens.sets``).

    Returns
    -------
    matplotlib.figure.Figure or None
        None when nothing was fitted.
    """
    from matplotlib.lines import Line2D

    count = quantity in COUNT_QUANTITIES
    wanted = list(sets or ens.sets)
    sets = _fitted_sets(res, quantity, wanted)
    if not sets:
        return None
    colors = colors or set_colors(ens.sets)
    name = legend_names(ens.sets)
    regs = [r for r in ("all", "bulk", "periphery")
            if any(_has_fit(res, s, r, quantity) for s in sets)]
    fig, axes = _subplots(len(regs), 2, figsize=(12.5, 0.4 + 3.6 * len(regs)))
    label = LABELS.get(quantity, quantity)
    for row, reg in zip(axes, regs):
        # axis limits follow the points and the fitted laws; a bootstrap band of a small
        # sample can span many decades and is clipped to them
        ymin_log, ymax_log, ymax_lin, x_min = np.inf, 0.0, 0.0, np.inf
        for s in sets:
            summ = res.summaries.get((s, reg, quantity))
            if summ is None:
                continue
            x, cut, span, groups = _sample(ens, s, reg, quantity, summ)
            if x.size == 0:
                continue
            x_min = min(x_min, float(x.min()))
            c = colors[s]
            best = summ.results.get(summ.best) if summ.best else None
            n = x.size
            for ax, logscale in zip(row, (False, True)):
                if count:
                    ks = np.arange(max(1, int(x.min())), int(x.max()) + 1)
                    cnt = np.array([(x == k).sum() for k in ks], float)
                    bins = np.round(x).astype(int) - int(ks[0])
                    mids, width = ks.astype(float), np.ones(ks.size)
                    grid = np.arange(1, int(x.max()) + 3, dtype=float)
                else:
                    if logscale and x.max() / x.min() > 10:
                        edges = bin_edges(x, log=True)
                        ax.set_xscale("log")
                    else:
                        edges = bin_edges(x)
                    cnt, edges = np.histogram(x, bins=edges)
                    cnt = cnt.astype(float)
                    # np.histogram's bins: the last one closed on the right
                    bins = np.clip(np.searchsorted(edges, x, side="right") - 1, -1,
                                   len(cnt) - 1)
                    bins[(x < edges[0]) | (x > edges[-1])] = -1
                    width = np.diff(edges)
                    mids = (np.sqrt(edges[1:] * edges[:-1]) if ax.get_xscale() == "log"
                            else (edges[1:] + edges[:-1]) / 2)
                    grid = (np.geomspace(edges[0], edges[-1], 300) if ax.get_xscale() == "log"
                            else np.linspace(edges[0], edges[-1], 300))
                h = cnt / (n * width)
                err = _bin_errors(bins, groups, cnt.size) / (n * width)
                # an empty bin is a measured zero: drawn on the linear panel (a small sample
                # has many), left out only where a log axis cannot show it
                k = cnt > 0 if logscale else np.ones(cnt.size, bool)
                if logscale:  # a bar reaching 0 cannot be drawn on a log axis: stop it short
                    lo = np.minimum(err, 0.95 * h)
                    yerr = np.vstack([lo[k], err[k]])
                    ymin_log = min(ymin_log, float(np.min(h[k])) * 0.3)
                    ymax_log = max(ymax_log, float(np.max(h[k] + err[k])))
                else:
                    yerr = err[k]
                    ymax_lin = max(ymax_lin, float(np.max(h[k] + err[k])))
                # the stacks, not the branches repeating their values, are independent
                n_ind = min(r.n_independent for r in summ.results.values())
                n_shown = f"{n}" if n_ind == n else f"{n}, {n_ind} stacks"
                data_label = (f"{name[s]}: data (n = {n_shown})" if n_ind >= F.N_SELECT_MIN
                              else f"{name[s]}: data, indicative only "
                              f"(n = {n_shown} < {F.N_SELECT_MIN})")
                ax.errorbar(mids[k], h[k], yerr=yerr, fmt="o", ms=4, color=c, lw=1,
                            capsize=2, label=data_label, gid=f"points:{s}:{reg}")
                if best is None:
                    continue
                band = _band(best, grid, cut, count)
                band_label = f"{name[s]}: {int(BAND_LEVEL * 100)} % bootstrap band"
                if band is not None and count:  # masses live at the integers only
                    ax.vlines(grid, band[0], band[1], color=c, alpha=0.3, lw=7,
                              label=band_label)
                elif band is not None:
                    ax.fill_between(grid, band[0], band[1], color=c, alpha=0.2, lw=0,
                                    label=band_label)
                text = _fit_text(best)
                if count:  # the law's parameters are those of the continuous law: say its mean
                    text += f", mean {_count_mean(best):.3g}"
                law = _curve(best, best.params, grid, cut, count)
                ax.plot(grid, law, "s--" if count else "-", ms=4 if count else 0, mfc="none",
                        color=c, lw=1.6, label=f"{name[s]}: {text}", gid=f"law:{s}:{reg}")
                shown = np.asarray(law, float)
                shown = shown[np.isfinite(shown) & (shown > 0)]
                if logscale and shown.size:
                    ymax_log = max(ymax_log, float(shown.max()))
                    # the law below the points stays in view, down to a thousandth of its
                    # peak (its far tails would stretch the axis over many decades)
                    ymin_log = min(ymin_log, 0.5 * max(float(shown.min()),
                                                       1e-3 * float(shown.max())))
                if span is not None and span[1] > span[0] * (1 + 1e-9):
                    # scans of one set carry different limits (each in units of its own L):
                    # the band spans them, the line is the largest, below which some scan
                    # saw nothing
                    ax.axvspan(span[0], span[1], color=c, alpha=0.08, lw=0,
                               gid=f"limits:{s}:{reg}")
                    ax.axvline(span[1], color=c, ls=":", lw=1, gid=f"limit:{s}:{reg}",
                               label=_limits_label(name[s], span) if logscale else None)
                elif span is not None:
                    ax.axvline(span[1], color=c, ls=":", lw=1, gid=f"limit:{s}:{reg}",
                               label=_limits_label(name[s], span) if logscale else None)
        for ax, logscale in zip(row, (False, True)):
            if logscale:
                ax.set_yscale("log")
                if np.isfinite(ymin_log) and ymax_log > ymin_log:
                    ax.set_ylim(ymin_log, 3 * ymax_log)
            elif ymax_lin > 0:
                # a Gamma law with alpha < 1 diverges at 0: scale the axis to the data
                ax.set_ylim(0, 1.15 * ymax_lin)
            ylabel = "fraction of stacks $P(n_{br})$" if count else "probability density"
            scale = ("linear scale" if not logscale else
                     "log scales" if ax.get_xscale() == "log" else
                     "log density scale")
            ax.set_title(f"{REGION_WORDS.get(reg, reg)}: {scale}", fontsize=10)
            power = 0
            if count:
                ax.xaxis.get_major_locator().set_params(integer=True)
            elif ax.get_xscale() == "log":
                _log_ticks(ax.xaxis)
            else:
                if ax.get_xlim()[0] < 0 <= x_min:  # no negative ticks under positive data
                    ax.set_xlim(left=0)
                power = _linear_ticks(ax.xaxis)
            # long names on two lines: side-by-side panels' labels must not run together
            ax.set_xlabel(_wrap_label(_scaled_label(label, power), 36))
            if power and not count:
                # the ticks read the quantity in units of 10^power, the density is still per
                # unit of the quantity: said, so that its area is not read as 10^-power
                i = label.find("$")
                j = label.find("$", i + 1) if i >= 0 else -1
                per = label[i:j + 1] if j > i else "of the quantity"
                ylabel = f"probability density, per unit {per}"
            if not logscale and not count:
                # densities of 1e-4 per unit E read as 0.00012: in units of a power of ten,
                # below 1 too, so that the rows of one figure read alike
                ypower = _linear_ticks(ax.yaxis, small=1.0)
                if ypower:
                    ylabel += f", in units of $10^{{{ypower}}}$"
            ax.set_ylabel(_wrap_label(ylabel, 36))
        # one legend per row, outside the log panel: never over the data
        handles, labels = row[1].get_legend_handles_labels()
        # per set: its data, then its law, then the band and the detection limit
        order = sorted(range(len(labels)), key=lambda i: (
            sets.index(labels[i].split(": ")[0]) if labels[i].split(": ")[0] in sets else 0,
            0 if ": data" in labels[i] else 2 if "band" in labels[i] or "limit" in labels[i]
            else 1))
        handles, labels = [handles[i] for i in order], [labels[i] for i in order]
        # a set without a fit in this row is named here too: the figure is also read
        # without the report's caption
        for s in wanted:
            if not _has_fit(res, s, reg, quantity) and (
                    reg == "all" or reg in regions_of(ens.subset(s))):
                handles.append(Line2D([], [], ls="none", marker="x", color=colors[s]))
                labels.append(f"{name[s]}: not drawn (too few values to fit, or all equal)")
        if handles:
            row[1].legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0),
                          fontsize=8, frameon=False)
    return fig


class PlotPdfError(ParameterError, ValueError):
    """A bad argument of :func:`plot_pdf`: a ParameterError like every bad argument of the
    toolkit, and a ValueError as well, since plot_pdf raised ValueError before and code
    catching that must keep working."""


def plot_pdf(source, quantity: str = "e", *, set_name: str | None = None, seed: int = 0):
    """The probability density of one quantity of an ensemble with its fitted laws (the
    report's figure, from Python).

    The laws are fitted here by maximum likelihood, truncation-aware where a detection limit
    applies, without bootstrap intervals nor goodness of fit (run ``foldstat stats`` for
    those). Values that are not finite or are <= 0 are left out, with a
    :class:`~crosssection.quality.QualityWarning` giving their number.

    Parameters
    ----------
    source : Ensemble, str or Path
        An ensemble, or a batch output, ``analyze`` output or simulation folder
        (:func:`crosssection.stats.data.load_any`).
    quantity : str
        A key of :data:`crosssection.stats.tables.QUANTITIES`: ``length_L``, ``kappa_m_L``,
        ``kappa_plus_L``, ``e``, ``E``, ``n_br``, ``area_L2``, ``shape_ratio``.
    set_name : str, optional
        The only set to draw (default: every set, overlaid).
    seed : int
        Seed of the fits' random starts (an integer >= 0, or None for fresh entropy).

    Returns
    -------
    matplotlib.figure.Figure
        Linear and logarithmic panels, one row per sub-system (whole system, bulk,
        periphery) when the data carry them.

    Raises
    ------
    ParameterError
        Unknown quantity or set, or too few values to fit (a :class:`PlotPdfError`, also a
        ValueError); a bad seed, or a source that is neither an ensemble nor a path.
    ConfigError
        The folder cannot be read (:func:`crosssection.stats.data.load_any`).

    Warns
    -----
    SmallSampleWarning
        A law selected on fewer than :data:`~crosssection.stats.fits.N_SELECT_MIN` values
        (its data are labelled "indicative only" in the figure).
    """
    from crosssection.stats.data import load_any
    from crosssection.stats.tables import fit_quantity

    if not isinstance(quantity, str) or quantity not in QUANTITIES:
        raise PlotPdfError(f"quantity must be one of {sorted(QUANTITIES)}, got "
                           f"{quantity!r}")
    if seed is not None:
        F._count(seed, "seed")
    ens = source if isinstance(source, Ensemble) else load_any(source)
    if set_name is not None and set_name not in ens.sets:
        raise PlotPdfError(f"set_name must be one of {ens.sets}, got {set_name!r}")
    sets = ens.sets if set_name is None else [set_name]
    opts = StatsOptions(seed=seed, n_boot=0, gof=False, quantities=(quantity,))
    summaries = {}
    for s in sets:
        sub = ens.subset(s)
        regions = (["all"] if QUANTITIES[quantity][0] in ("configs", "voids")
                   else regions_of(sub))
        seeds = np.random.SeedSequence(seed).spawn(len(regions))
        for reg, sd in zip(regions, seeds):
            summ, _, _ = fit_quantity(sub, quantity, reg, opts, sd)
            if summ is not None:
                summaries[(s, reg, quantity)] = summ
    if not summaries:
        raise PlotPdfError(f"{', '.join(map(str, sets))}: too few positive values of "
                           f"{quantity} to fit (at least {opts.min_n})")
    small = [f"{s}{'' if reg == 'all' else f' ({reg})'} {n_text(summ.results[summ.best])}"
             for (s, reg, _), summ in summaries.items()
             if summ.best and summ.results[summ.best].n_independent < F.N_SELECT_MIN]
    if small:
        warnings.warn(f"{quantity}: laws selected on fewer than the {F.N_SELECT_MIN} samples "
                      f"model selection needs ({', '.join(small)}): indicative only",
                      F.SmallSampleWarning, stacklevel=2)
    empty = pd.DataFrame()
    fits_only = StatsResult(empty, empty, empty, empty, empty, empty, empty, empty, summaries)
    return pdf_figure(fits_only, ens, quantity, sets=sets)


#: relative difference below which two sets' Eq. (14)-(15) lines are drawn as one line of
#: alternating colours (two lines a pixel apart hide each other)
SAME_LINE_REL = 0.02


def _shared_dashes(values) -> list:
    """Per value, the dash pattern ``(offset, (on, off))`` of its line: the plain dashes of
    a line alone, and for lines whose values agree within :data:`SAME_LINE_REL`, dashes
    that alternate between them, so that every colour shows along the shared line."""
    values = [float(v) for v in values]
    groups = []  # indices of values drawn as one line
    for i, v in enumerate(values):
        for g in groups:
            w = values[g[0]]
            if np.isfinite(v) and abs(v - w) <= SAME_LINE_REL * max(abs(v), abs(w)):
                g.append(i)
                break
        else:
            groups.append([i])
    out = [None] * len(values)
    on = 4.0
    for g in groups:
        for j, i in enumerate(g):
            out[i] = (0.0, (on, on)) if len(g) == 1 else (j * on, (on, on * (len(g) - 1)))
    return out


def network_figure(res: StatsResult, colors=None):
    """The network relations of the paper per configuration, every set overlaid.

    Left: the number of branches N_br against the number of stacks N_l with Eq. (12), with
    the paper's constant through the set's means and, as crosses, with the constant fitted
    to the set and each configuration's own means, and Eq. (14); right: the
    mean number of branches per stack N_br/N_l with Eqs. (13) and (15). The legend gives one
    entry per set (its fitted constant and mean number of branches per stack) and names each
    line style once; where two sets' Eq. (14)-(15) lines coincide, their dashes alternate.

    Parameters
    ----------
    res : StatsResult
    colors : dict, optional
        Set -> colour (default :func:`set_colors` of the sets of ``res.per_config``).

    Returns
    -------
    matplotlib.figure.Figure or None
        None when no configuration has both counts.
    """
    from matplotlib.lines import Line2D

    pc = res.per_config
    colors = colors or set_colors(list(dict.fromkeys(pc["set"])))
    if not _pairs(pc, "N_l", "N_br").any():
        return None  # no configuration with a network: nothing to draw
    fig, axes = _subplots(1, 2, figsize=(12.5, 4.6))
    axes = axes[0]
    name = legend_names(pc["set"])
    groups = list(pc.groupby("set", sort=False))
    nbrs, rels = {}, {}
    for s, g in groups:
        rels[s] = res.relations[res.relations["set"] == s].set_index("relation")["fitted"]
        nbr = res.macro.query("set == @s and region == 'all'")["n_br"].iloc[0]
        if not np.isfinite(nbr):  # no per-stack counts (simulations): the Eq. (14) fitted slope
            nbr = rels[s].get("eq14_slope", np.nan)
        nbrs[s] = float(nbr)
    dashes = dict(zip(nbrs, _shared_dashes(nbrs.values())))
    handles, labels, styles = [], [], set()
    for s, g in groups:
        c, nbr, rel = colors[s], nbrs[s], rels[s]
        axes[0].plot(g["N_l"], g["N_br"], "o", color=c, ms=4, alpha=0.8)
        axes[1].plot(g["N_l"], g["n_br_bar"], "o", color=c, ms=4, alpha=0.8)
        words = [f"{name[s]}: configurations"]
        nl = np.linspace(max(1, g["N_l"].min() * 0.8), g["N_l"].max() * 1.2, 100)
        ratio = _nanmean(g["sqrt_s_bar"] / g["l_bar"])  # NaN for scans without voids
        eps = _nanmean(g["epsilon"])
        if np.isfinite(ratio) and np.isfinite(eps):
            eq12 = EQ12_CONST * eps * ratio * np.sqrt(nl)  # Eq. (12) with set means
            axes[0].plot(nl, eq12, "-", color=c,
                         label=f"{name[s]}: Eq. (12), paper's C = 2√(π/3) = "
                               f"{EQ12_CONST:.3g}, with the set means")
            axes[1].plot(nl, eq12 / nl, "-", color=c,
                         label=f"{name[s]}: Eq. (13), C = {EQ12_CONST:.3g}")
            styles.add("-")
            fitted = rel.get("eq12_const", np.nan)
            if np.isfinite(fitted):
                # the C of relations.csv with each configuration's own epsilon and
                # sqrt(s_bar)/l_bar, as it was fitted: a line through the set's means would
                # miss configurations of other epsilon however well the relation holds
                n_fit = int(res.relations.query("set == @s and relation == 'eq12_const'")
                            ["n"].iloc[0])
                own = fitted * g["epsilon"] * g["sqrt_s_bar"] / g["l_bar"] * np.sqrt(g["N_l"])
                axes[0].plot(g["N_l"], own, "x", color=c, ms=5, mew=1.0,
                             label=f"{name[s]}: Eq. (12), fitted C = {fitted:.3g}")
                styles.add("x")
                words.append(f"fitted C = {fitted:.3g}"
                             + (" (indicative only)" if n_fit < N_RELATION_MIN else ""))
        if np.isfinite(nbr):
            axes[0].plot(nl, nbr * nl, ls=dashes[s], color=c,
                         label=f"{name[s]}: Eq. (14), <n_br> = {nbr:.3g}")
            axes[1].axhline(nbr, ls=dashes[s], color=c,
                            label=f"{name[s]}: Eq. (15), <n_br> = {nbr:.3g}")
            styles.add("--")
            words.append(f"<n_br> = {nbr:.3g}")
        handles.append(Line2D([], [], ls="none", marker="o", ms=4, color=c))
        labels.append(", ".join(words))
    axes[0].set(xlabel="number of stacks per configuration $N_l$",
                ylabel="number of branches per configuration $N_{br}$",
                title="branches against stacks")
    axes[1].set(xlabel="number of stacks per configuration $N_l$",
                ylabel=r"mean branches per stack $\bar n_{br}=N_{br}/N_l$",
                title="mean branches per stack against stacks")
    # one legend for both panels, right of them: a set's points are the same in both and
    # take its colour, each line style is named once (in the sets' colours in the panels)
    key = {"-": f"Eq. (12) left, (13) right: paper's C = 2√(π/3) = {EQ12_CONST:.3g}, "
                "with the set's means",
           "x": "Eq. (12), left: the C fitted to the set, with each configuration's own "
                "ε and √s̄/l̄ (on its point where the relation holds)",
           "--": "Eq. (14) left, (15) right: the set's mean <n_br>"}
    # one set: its colour; several: grey, each set's lines in its own colour
    shade = colors[groups[0][0]] if len(groups) == 1 else "0.3"
    for ls in ("-", "x", "--"):
        if ls in styles:
            handles.append(Line2D([], [], ls="none", marker="x", ms=5, color=shade)
                           if ls == "x" else Line2D([], [], ls=ls, color=shade, lw=1.5))
            labels.append(key[ls])
    axes[1].legend(handles, [_wrap_label(t, 60) for t in labels], fontsize=8,
                   frameon=False, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def _pairs(df, x, y) -> np.ndarray:
    """Which rows of ``df`` hold finite values of both ``x`` and ``y``."""
    return np.isfinite(np.asarray(df[x], float)) & np.isfinite(np.asarray(df[y], float))


def _scatter_fig(res, x, y, xlabel, ylabel, title, *, through_origin=False, paper_slope=None,
                 colors=None):
    pc = res.per_config
    colors = colors or set_colors(list(dict.fromkeys(pc["set"])))
    if not _pairs(pc, x, y).any():
        return None  # no configuration has both (no void at all): nothing to draw
    fig, ax = _subplots(figsize=(8.5, 4.8))
    ax = ax[0, 0]
    name = legend_names(pc["set"])
    for s, g in pc.groupby("set", sort=False):
        c = colors[s]
        xv, yv = np.asarray(g[x], float), np.asarray(g[y], float)
        k = _pairs(g, x, y)
        if not k.any():
            continue
        txt = f"{name[s]}: configurations"
        if (k.sum() >= CORRELATION_MIN_PAIRS and not through_origin and np.ptp(xv[k]) > 0
                and np.ptp(yv[k]) > 0):
            txt += f", Pearson r = {np.corrcoef(xv[k], yv[k])[0, 1]:.2f} (n = {int(k.sum())}"
            # as correlations.csv marks it
            txt += ", indicative only)" if k.sum() < N_RELATION_MIN else ")"
        ax.plot(xv[k], yv[k], "o", color=c, ms=4, alpha=0.8, label=txt)
        if k.sum() >= 2 and through_origin:
            a = np.sum(xv[k] * yv[k]) / np.sum(xv[k] ** 2)
            xs = np.linspace(0, xv[k].max() * 1.1, 10)
            few = (f" (n = {int(k.sum())}, indicative only)" if k.sum() < N_RELATION_MIN
                   else "")
            ax.plot(xs, a * xs, "-", color=c,
                    label=f"{name[s]}: fit through 0, slope {a:.3g}{few}")
    if paper_slope is not None:
        xs = np.array([0, np.nanmax(np.asarray(pc[x], float)) * 1.1])
        ax.plot(xs, paper_slope * xs, ":", color="grey", label=f"paper: slope {paper_slope}")
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    ax.legend(fontsize=7, frameon=False, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def _means_by_count(branches: pd.DataFrame) -> pd.DataFrame:
    """Mean branch energy per n_br and its standard error over independent values.

    The branches of a scan's stack repeat the stack's energy (:func:`branch_groups`): each
    stack is one value, or the error would be too small by about the square root of n_br.
    Within one n_br every stack holds the same number of branches, so the mean over stacks
    is the mean over branches.
    """
    from crosssection.stats.data import branch_groups

    g = branch_groups(branches)
    own = np.array([x is None for x in g])
    unit = np.where(own, np.arange(len(g)).astype(object), g)
    per = (pd.DataFrame({"n_br": branches["n_br"].to_numpy(), "e": branches["e"].to_numpy(),
                         "unit": [str(u) for u in unit]})
           .groupby(["n_br", "unit"], sort=False)["e"].mean().reset_index())
    return per.groupby("n_br")["e"].agg(["mean", "sem", "size"])


def e_vs_nbr_figure(ens: Ensemble, colors=None):
    """Mean branch energy against the number of branches of its stack (paper fig energo_micro3)."""
    br = ens.branches.dropna(subset=["n_br", "e"])
    if br.empty:
        return None
    colors = colors or set_colors(ens.sets)
    fig, ax = _subplots(figsize=(8.5, 4.8))
    ax = ax[0, 0]
    name = legend_names(ens.sets)
    single = False
    for s in ens.sets:
        g = br[br["set"] == s]
        if g.empty:
            continue
        c = colors[s]
        # the whole system first: where one sub-system holds every stack of a size (the
        # largest stacks are all at the wall) its curve coincides with the whole system's
        # and must be drawn over it, not hidden under it
        for reg, ls in ((None, "-"), ("bulk", ":"), ("periphery", "--")):
            gg = g if reg is None else g[g["region"] == reg]
            if gg.empty:
                continue
            st = _means_by_count(gg)
            # every integer in the range: a stack size without branches is a gap (NaN),
            # where the line breaks instead of joining its neighbours across it
            st = st.reindex(np.arange(int(st.index.min()), int(st.index.max()) + 1))
            ms = 4 if reg is None else 2
            ax.errorbar(st.index, st["mean"], yerr=st["sem"].fillna(0), fmt="o" + ls, color=c,
                        ms=ms, lw=1, capsize=2, alpha=1 if reg is None else 0.6,
                        label=f"{name[s]}: {REGION_WORDS[reg or 'all']}")
            one = (st["size"] == 1).to_numpy()  # one value: a mean without an error
            # above every series: a sub-system's small filled marker at the same value
            # would fill the ring
            ax.plot(st.index[one], st["mean"].to_numpy()[one], "o", ms=ms, mfc="white",
                    mec=c, ls="none", alpha=1 if reg is None else 0.6,
                    zorder=4 if reg is None else 3)
            # said in the legend where the whole system's points are (the sub-systems' small
            # markers at the same values hide theirs)
            single = single or (reg is None and bool(one.any()))
    ax.set(xlabel="number of branches in the stack $n_{br}$",
           ylabel=r"mean branch energy $\langle e\rangle$ (dimensionless)",
           title="mean branch energy against $n_{br}$\n" r"(mean $\pm$ standard error over "
                 "a scan's stacks, a simulation's branches)")
    ax.xaxis.get_major_locator().set_params(integer=True)
    handles, labels = ax.get_legend_handles_labels()
    if single:
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], marker="o", mfc="white", mec="0.3", ls="none", ms=4))
        labels.append("hollow: a single value, no error bar")
    ax.legend(handles, labels, fontsize=7, frameon=False, loc="upper left",
              bbox_to_anchor=(1.01, 1.0))
    return fig


def write_report(ens: Ensemble, out_dir, *, opts: StatsOptions | None = None,
                 inputs=(), figures: bool = True, progress: bool | None = False,
                 limits_given: dict | None = None) -> dict:
    """Compute every statistic of ``ens`` and write the report folder.

    The folder appears whole: it is written into a hidden sibling folder, which then takes
    the place of ``out_dir`` (a previous report is renamed away first and deleted last). An
    interrupted or failed run leaves ``out_dir`` as it was, the previous report or nothing,
    and never a mix of two reports (such as the figures of an older one beside the tables of
    a run without figures).

    Parameters
    ----------
    ens : Ensemble
    out_dir : path
        Receives macro/micro/fits/relations/dof/truncation (.csv, .md), correlations.csv,
        per_config.csv, stats.json, figures/*.png and report.html. It is created, or
        replaced when it holds a previous report (see :func:`check_report_dir`).
    opts : StatsOptions, optional
    inputs : sequence of str
        Input folders, recorded (resolved) in stats.json; ``out_dir`` must not be nor hold
        one.
    figures : bool
        Draw the PNG figures.
    progress : bool or None
        tqdm bars on stderr over the fits and the figures; None shows them only when stderr
        is a terminal.
    limits_given : dict, optional
        The detection limits given explicitly (``l_min_mm``, ``s_min_mm2``), recorded as
        such; the others are those the scans' analyses used.

    Returns
    -------
    dict
        Name -> written path (inside ``out_dir``).

    Raises
    ------
    ParameterError, OSError
        ``out_dir`` cannot take the report (see :func:`check_report_dir`) or cannot be
        written.
    """
    opts = opts or StatsOptions()
    out = Path(out_dir)
    check_report_dir(out, inputs)
    res = compute_stats(ens, opts, progress=progress)
    seeds = {s: set_seed(opts.seed, s) for s in ens.sets}
    with _staged_folder(out) as stage:
        paths = _write_files(res, ens, stage, opts=opts, inputs=inputs, figures=figures,
                             progress=progress, seeds=seeds, limits_given=limits_given or {})
    return {k: out / p.relative_to(stage) for k, p in paths.items()}


#: the files of a report folder (figures/ holds PNG files only)
REPORT_FILES = frozenset(
    {f"{n}.csv" for n in REPORT_TABLES}
    | {f"{n}.md" for n in ("macro", "micro", "fits", "relations", "dof", "truncation")}
    | {"stats.json", "report.html", "figures"})


def _figures_rule(folder: Path) -> str | None:
    """:func:`~crosssection.core.fileio.foreign_entry`'s rule for a report's subfolders:
    ``figures`` holds PNG files only."""
    if folder.name != "figures":
        return folder.name
    for f in sorted(folder.iterdir()):
        if not (f.suffix == ".png" and f.is_file()) and f.name not in BROWSER_FILES:
            return f"figures/{f.name}"
    return None


def check_report_dir(out_dir, inputs=()) -> None:
    """Refuse a report folder that a report must not take the place of.

    ``out_dir`` may be missing (it is created), empty, or hold a previous report, which the
    new one replaces whole; nothing else is ever deleted.

    Parameters
    ----------
    out_dir : path
    inputs : sequence of path
        The input folders: ``out_dir`` must be none of them and hold none of them.

    Raises
    ------
    FileExistsError
        ``out_dir`` is a file.
    ParameterError
        ``out_dir`` is or holds an input folder, or holds files that are no part of a
        report.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(out))
    up = out.absolute().parent
    while not up.exists() and up != up.parent:
        up = up.parent
    if not up.is_dir():  # the folder cannot be created under a file
        raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(out))
    real = out.resolve()
    if real == real.parent:
        raise ParameterError("a file system root cannot be a report folder", out)
    for d in inputs:
        src = Path(d).resolve()
        if src == real or real in src.parents:
            raise ParameterError(f"{'is' if src == real else 'holds'} the input folder {d}, "
                                 "which the report would replace: give another --out", out)
    if out.is_dir():
        foreign = foreign_entry(out, REPORT_FILES, _figures_rule)
        if foreign is not None:
            raise ParameterError(
                f"holds {foreign}, which is no part of a stats report, and a report replaces "
                "the whole folder: give a new folder, an empty one or a previous report's",
                out)


def _named_error(exc: OSError, path) -> OSError:
    """``exc`` naming ``path`` (the report folder) rather than a hidden working folder."""
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path))


@contextmanager
def _staged_folder(out: Path):
    """Yield a new hidden folder beside ``out``; on success it takes the place of ``out``.

    One report at a time: the folder's lock (``.<name>.lock`` beside it,
    :func:`~crosssection.core.fileio.exclusive_lock`) refuses a second run in one line.

    Hidden working folders of a killed earlier run (``.<name>.partial-*``, ``.<name>.old-*``)
    are removed first. On failure or interrupt the working folder is removed and ``out`` is
    left as it was.
    """
    real = out.resolve()
    try:
        real.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _named_error(exc, out) from None
    # a second report into the same folder would remove this one's working folder as a
    # killed run's (both then end "written", the folder holding part of one report)
    with exclusive_lock(real.parent / f".{real.name}.lock", where=out,
                        busy="another stats run is writing this report"):
        try:
            clear_stale_folders(real)
            stage = staging_folder(real)
        except OSError as exc:
            raise _named_error(exc, out) from None
        try:
            try:
                yield stage
            except OSError as exc:
                # a file of the working folder that could not be written (a full disk): the
                # report folder is what the user gave and can act on
                where = getattr(exc, "path", None) or exc.filename
                if where is None or str(stage) not in str(where):
                    raise
                cause = (exc.cause if isinstance(exc, OutputError) else
                         f"cannot write ({exc.strerror or ' '.join(str(exc).split())})")
                raise OutputError(cause, out) from None
            try:
                swap_in_folder(stage, real)
            except OSError as exc:
                raise _named_error(exc, out) from None
        finally:
            if stage.exists():
                shutil.rmtree(stage, ignore_errors=True)


def _write_files(res: StatsResult, ens: Ensemble, out: Path, *, opts: StatsOptions, inputs,
                 figures: bool, progress: bool | None, seeds: dict | None = None,
                 limits_given: dict | None = None) -> dict:
    """Write the report's files into the folder ``out``; return name -> path."""
    from tqdm import tqdm

    paths = {}
    tables = {"macro": res.macro, "micro": res.micro, "fits": res.fits,
              "relations": res.relations, "dof": res.dof, "truncation": res.truncation}
    for name, df in tables.items():
        paths[f"{name}.csv"] = write_csv(out / f"{name}.csv", df)
        paths[f"{name}.md"] = write_text(out / f"{name}.md", to_markdown(df))
    paths["correlations.csv"] = write_csv(out / "correlations.csv", res.correlations)
    # what made each configuration is in stats.json, per set, not a JSON text per row
    paths["per_config.csv"] = write_csv(out / "per_config.csv",
                                        _integer_counts(res.per_config.drop(
                                            columns=["analysis"], errors="ignore"),
                                            PER_CONFIG_COUNTS))

    figs = []  # (title, relative path, one-sentence caption)
    empty = []  # the titles of figures with no value to draw
    if figures:
        fdir = out / "figures"
        colors = set_colors(ens.sets)
        qs = list(opts.quantities)
        for q in tqdm(qs, desc="stats figures", unit="fig", leave=False,
                      disable=None if progress is None else not progress):
            fig = pdf_figure(res, ens, q, colors=colors)
            if fig is not None:
                name = f"pdf_{q}.png"
                paths[name] = save_figure(fig, fdir / name)
                figs.append((f"Distribution of the {WORDS[q]}", f"figures/{name}",
                             _pdf_caption(q, ens) + _left_out(res, ens, q, opts.min_n)))
        scatter = [
            ("network_Nbr_vs_Nl.png", "Branches and stacks per configuration (Eqs. (12)-(15))",
             "Each point is one configuration; solid lines are Eqs. (12)-(13) with the paper's "
             "constant C = 2√(π/3) and the set's mean compaction, void size and branch length, "
             "crosses Eq. (12) with the C fitted to the set (relations.csv) and each "
             "configuration's own compaction, void size and branch length (on the point "
             "where the relation holds), dashed lines Eqs. (14)-(15) with its mean number "
             "of branches per stack.", lambda: network_figure(res, colors)),
            ("sqrt_s_vs_l.png", "Void size against branch length",
             "Each point is one configuration: the square root of its mean void area against "
             "its mean branch length (units of L), with a line through the origin per set and "
             "the paper's slope 1.1 dotted.", lambda: _scatter_fig(
                 res, "l_bar", "sqrt_s_bar", r"mean branch length $\bar\ell/L$",
                 r"root mean void area $\sqrt{\bar s}/L$",
                 "void size against branch length", through_origin=True, paper_slope=1.1,
                 colors=colors)),
            ("E_vs_Nbr.png", "Total energy against the number of branches",
             "Each point is one configuration: its total energy against its number of "
             "branches; the legend gives the Pearson correlation per set (paper: 0.75).",
             lambda: _scatter_fig(res, "N_br", "E",
                                  "number of branches per configuration $N_{br}$",
                                  "total energy $E$ (dimensionless)",
                                  "total energy against number of branches", colors=colors)),
            ("e_vs_nbr.png", "Branch energy against the size of its stack",
             "Mean energy of a branch against the number of branches of its stack, "
             "with standard errors, for the whole system (solid), bulk (dotted) and periphery "
             "(dashed), drawn over the whole system where they coincide with it; a stack size "
             "no branch has leaves a gap in the line. " + _e_vs_nbr_bars(ens),
             lambda: e_vs_nbr_figure(ens, colors)),
        ]
        for name, title, caption, make in scatter:
            fig = make()
            if fig is not None:
                paths[name] = save_figure(fig, fdir / name)
                figs.append((title, f"figures/{name}", caption))
            else:
                empty.append(title.lower())

    stats_json = {
        "package": "foldstat", "version": __version__,
        # the fits' bootstrap and likelihoods rest on these: a new release can move last bits
        "libraries": library_versions(STATS_LIBRARIES),
        "inputs": [_resolved(i) for i in inputs],
        "sets_of_inputs": {_resolved(d): v for d, v in input_sets(ens).items()},
        "detection_limits": detection_limits(ens),
        "detection_limits_given": dict(limits_given or {}),
        "incomplete_batches": incomplete_batches(ens),
        "tables_unlike_summary": tables_unlike_summary(ens),
        "options": {k: (list(v) if isinstance(v, tuple) else v)
                    for k, v in vars(opts).items()},
        "model_selection": f"min BIC; a family with fewer parameters within "
                           f"dBIC < {F.DELTA_BIC_SIMPLER} is preferred",
        "sets": {},
    }
    for s in ens.sets:
        sel = {}
        for (ss, reg, q), summ in res.summaries.items():
            if ss != s:
                continue
            sel.setdefault(reg, {})[q] = {
                "selected": summ.best,
                "fits": {f: {"params": r.params, "ci": r.ci, "bic": r.bic, "aic": r.aic,
                             "pvalue": r.pvalue, "n_mc": r.n_mc, "p_text": r.p_text(),
                             "n": r.n, "n_groups": r.n_independent,
                             "truncated": r.truncated, "counts": r.discrete,
                             "rejected": r.rejected}
                         for f, r in summ.results.items() if r.ok}}
        stats_json["sets"][s] = {
            "macro": res.macro[res.macro["set"] == s].to_dict("records"),
            "micro": res.micro[res.micro["set"] == s].to_dict("records"),
            "relations": res.relations[res.relations["set"] == s].to_dict("records"),
            "correlations": res.correlations[res.correlations["set"] == s].to_dict("records"),
            "dof": res.dof[res.dof["set"] == s].to_dict("records"),
            "fits": sel,
            "seed": (seeds or {}).get(s, opts.seed),
            "detection_limits": detection_limits(ens.subset(s)),
            "made_by": provenance(ens.subset(s))}
        _warn_mixed(s, stats_json["sets"][s]["made_by"])
    paths["stats.json"] = write_json(out / "stats.json", stats_json)
    absent = _not_drawn(res, ens, opts.quantities, opts.min_n) if figures else ""
    if empty:
        absent += (" " if absent else "") + ("Not drawn (no configuration with the values): "
                                             + "; ".join(empty) + ".")
    paths["report.html"] = write_text(out / "report.html",
                                      _html(res, figs, stats_json, ens, opts, absent))
    return paths


#: the counts of a configuration in per_config.csv
PER_CONFIG_COUNTS = ("N_l", "N_br", "n_voids")


def _integer_counts(df: pd.DataFrame, cols) -> pd.DataFrame:
    """``df`` with its columns ``cols`` as integers (missing cells kept missing) where
    every value is a whole number: a simulation's counts read from CSV as floats (20.0)."""
    df = df.copy()
    for c in cols:
        if c in df.columns:
            v = pd.to_numeric(df[c], errors="coerce")
            finite = v.dropna()
            if np.isfinite(finite).all() and (finite == np.round(finite)).all():
                df[c] = v.astype("Int64")
    return df


def _limit_used(values_L, L) -> float | list | None:
    """The detection limit in mm (mm^2 for areas: pass L^2) of the scans' observations, from
    each one's limit in units of L: one number when all share it, the distinct numbers
    otherwise, None when no observation carries one (simulations, or limit 0)."""
    v = np.asarray(values_L, float) * np.asarray(L, float)
    v = np.unique(np.round(v[np.isfinite(v)], 12))  # x/L*L is x to rounding
    if v.size == 0:
        return None
    return float(v[0]) if v.size == 1 else [float(x) for x in v]


def detection_limits(ens: Ensemble) -> dict:
    """The detection limits the fits of ``ens`` are truncated at, in mm and mm^2.

    Parameters
    ----------
    ens : Ensemble

    Returns
    -------
    dict
        ``{"l_min_mm": ..., "s_min_mm2": ...}``, each a number (one for every scan), a list
        (scans read with different limits) or None (no limit: simulations, or limit 0).
    """
    L = ens.configs.set_index(["set", "config_id"])["rod_length_mm"]

    def rod(df):
        return L.reindex(pd.MultiIndex.from_frame(df[["set", "config_id"]])).to_numpy(float)

    return {"l_min_mm": _limit_used(ens.branches["l_min_L"], rod(ens.branches)),
            "s_min_mm2": _limit_used(ens.voids["s_min_L2"], rod(ens.voids) ** 2)}


def _resolved(path) -> str:
    """``path`` absolute and resolved: a report is read from elsewhere than it was run."""
    return str(Path(path).resolve())


def incomplete_batches(ens: Ensemble) -> list:
    """What the loader said of every unfinished batch of ``ens``, and of every simulation
    ensemble with failed configurations (``batch_note``), once each."""
    return _notes(ens, "batch_note")


def tables_unlike_summary(ens: Ensemble) -> list:
    """What the loader said of every scan of ``ens`` whose tables hold another number of
    rows than its summary.json counts (``table_note``: cut short or edited), once each.

    Parameters
    ----------
    ens : Ensemble

    Returns
    -------
    list of str
        The notes, in the order of the configurations.
    """
    return _notes(ens, "table_note")


def _notes(ens: Ensemble, column: str) -> list:
    notes = ens.configs.get(column, pd.Series(dtype=object))
    return list(dict.fromkeys(str(n) for n in notes.dropna() if str(n)))


def provenance(ens: Ensemble) -> dict:
    """What made the configurations of ``ens``: their package versions, the analysis (or
    simulation) parameters they share and those that differ between them.

    Returns
    -------
    dict
        ``{"versions": [...], "parameters": {name: value}, "parameters_differing":
        {name: [values]}, "n_unknown": n}`` (n: configurations that record nothing).
    """
    records, unknown = [], 0
    for text in ens.configs.get("analysis", pd.Series(dtype=object)):
        try:
            rec = json.loads(text) if isinstance(text, str) else None
        except ValueError:
            rec = None
        if not isinstance(rec, dict):
            unknown += 1
            continue
        records.append(rec)
    # a simulation resumed under other versions records each run's (its "runs")
    runs = [x for r in records for x in (r, *(r.get("runs") or ())) if isinstance(x, dict)]
    versions = sorted({str(r.get("version")) for r in runs if r.get("version")})
    libs = {}
    for r in runs:
        for k, v in (r.get("libraries") or {}).items():
            libs.setdefault(k, set()).add(str(v))
    names = list(dict.fromkeys(k for r in records for k in (r.get("parameters") or {})))
    same, differ = {}, {}
    for k in names:
        vals = list(dict.fromkeys(json.dumps((r.get("parameters") or {}).get(k),
                                             sort_keys=True, default=str) for r in records))
        if len(vals) == 1:
            same[k] = json.loads(vals[0])
        else:
            differ[k] = [json.loads(v) for v in vals]
    out = {"versions": versions, "parameters": same, "parameters_differing": differ,
           "n_unknown": unknown}
    if libs:
        out["libraries"] = {k: sorted(v) for k, v in libs.items()}
    return out


def _warn_mixed(set_name: str, made_by: dict) -> None:
    """A :class:`~crosssection.stats.data.MixedParametersWarning` when a set pools
    configurations made with different parameters other than each scan's own
    (:data:`~crosssection.stats.data.PER_SCAN_PARAMETERS`)."""
    from crosssection.stats.data import PER_SCAN_PARAMETERS, MixedParametersWarning

    differ = {k: v for k, v in (made_by.get("parameters_differing") or {}).items()
              if k not in PER_SCAN_PARAMETERS}
    if differ:
        what = "; ".join(f"{k}: {', '.join(json.dumps(x) for x in vals)}"
                         for k, vals in differ.items())
        warnings.warn(f"set {set_name!r} pools configurations made with different parameters "
                      f"({what}): its statistics mix measurements not made alike (analyse "
                      "them again with one set of parameters, or give them different set "
                      "names)", MixedParametersWarning, stacklevel=3)


def input_sets(ens: Ensemble) -> dict:
    """Input folder -> the names of the sets read from it (``input`` of
    :func:`~crosssection.stats.data.load_inputs`); {} when the ensemble does not record it."""
    c = ens.configs
    if "input" not in c.columns:
        return {}
    c = c[c["input"].notna()]
    return {str(d): list(dict.fromkeys(g["set"])) for d, g in c.groupby("input", sort=False)}


def _limits_text(limits: dict) -> str:
    """How the methods paragraph names the detection limits used."""
    def one(v, unit):
        if v is None:
            return "none"
        if isinstance(v, list):
            return ", ".join(f"{x:g}" for x in v) + f" {unit} (scans read with different limits)"
        return f"{v:g} {unit}"
    return (f"l_min = {one(limits.get('l_min_mm'), 'mm')}, "
            f"s_min = {one(limits.get('s_min_mm2'), 'mm²')}")


def _inputs_text(meta) -> str:
    """The input folders, each with the sets read from it when recorded."""
    sets = meta.get("sets_of_inputs") or {}
    return ", ".join(f"{d} (set{'s' if len(sets[d]) > 1 else ''} {', '.join(sets[d])})"
                     if sets.get(d) else d for d in meta["inputs"])


def _seeds_text(meta) -> str:
    return "; ".join(f"{s}: {v.get('seed')}" for s, v in (meta.get("sets") or {}).items())


def _per_set_text(meta) -> str:
    """The paragraph giving, per set, its detection limits and what made its data."""
    given = meta.get("detection_limits_given") or {}
    how = (f"given to stats ({', '.join(f'{k} = {v:g}' for k, v in given.items())}) where "
           "named, the others as each scan was analysed" if given else
           "as each scan was analysed, from its summary.json; where a set's scans differ, each "
           "scan's values are truncated at its own limit")
    items = []
    for s, v in (meta.get("sets") or {}).items():
        made = v.get("made_by") or {}
        limits = v.get("detection_limits") or {}
        words = [_limits_text(limits)]
        if (any(given.values()) and limits.get("l_min_mm") is None
                and limits.get("s_min_mm2") is None):
            # a simulation: its lengths are in units of its rod length, with no mm scale
            words[0] += " (the limits given are not applied: no scale in mm)"
        if made.get("versions"):
            words.append("made by version " + ", ".join(made["versions"]))
        differ = made.get("parameters_differing") or {}
        if differ:
            words.append("parameters differing between its configurations: " + "; ".join(
                f"{k} ({', '.join(json.dumps(x) for x in vals)})" for k, vals in differ.items()))
        elif made.get("parameters"):
            words.append("one set of parameters for all its configurations")
        if made.get("n_unknown"):
            words.append(f"{made['n_unknown']} configuration(s) record no parameters")
        items.append(f"<li>{html.escape(s)}: {html.escape('; '.join(words))}</li>")
    if not items:
        return ""
    return (f"<p>Per set, the detection limits ({html.escape(how)}) and what made the data "
            "(all parameters are in stats.json):</p><ul>" + "".join(items) + "</ul>")


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(name))


def _scan_rows(ens: Ensemble, unknown: bool = False) -> pd.Series:
    """Which configurations of ``ens`` are scans: those that record the rod length of their
    normalisation (NaN for simulations; ``unknown`` for all where the column is absent)."""
    configs = ens.configs
    if "rod_length_mm" not in configs:
        return pd.Series(unknown, index=configs.index)
    return configs["rod_length_mm"].notna()


def _e_vs_nbr_bars(ens: Ensemble) -> str:
    """The sentence of the branch-energy figure's caption saying when a point has no error
    bar: a scan's branches share their stack's energy, a simulated rod's carry their own."""
    scans = _scan_rows(ens)
    scan_words = ("the branches of one stack share its energy, so the standard error is over "
                  "stacks and a point resting on a single stack has no error bar")
    sim_words = ("each branch carries its own energy, so a point resting on a single stack "
                 "of several branches has an error bar")
    if scans.all():
        return scan_words[0].upper() + scan_words[1:] + "."
    if not scans.any():
        return "In a simulated rod " + sim_words + "."
    return f"In a scan {scan_words}; in a simulated rod {sim_words}."


def _pdf_caption(q: str, ens: Ensemble | None = None) -> str:
    """One sentence saying what a distribution figure of ``ens`` shows: the stacks' shared
    counts where scans' branches are drawn, sub-system rows where the quantity has them, a
    detection limit where some configuration has one."""
    table, column, _, cut, _ = QUANTITIES[q]
    rows = (", one row per sub-system" if table in ("branches", "stacks") else "")
    if q in COUNT_QUANTITIES:
        return (f"Fraction of stacks with each {WORDS[q]} (points, error bars sqrt(count)/n) "
                f"against the selected law's probability mass at each integer (open squares) "
                f"with its 95 % bootstrap band, one colour per set{rows}.")
    scans = ens is None or bool(_scan_rows(ens).any())
    shared = (", with count squared summed over the stacks where a stack's branches share "
              "its value" if table == "branches" and scans else "")
    limited = cut is not None and (ens is None or bool(np.isfinite(
        np.asarray(getattr(ens, table)[cut], float)).any()))
    return (f"Probability density of the {WORDS[q]} (points, counting error bars "
            f"sqrt(count)/(n bin width){shared}) with the selected law (line) and its 95 % "
            f"bootstrap band, one colour per set{rows}, linear (left) and logarithmic (right) "
            f"density scales, the right panel's x axis logarithmic too where the values span "
            f"more than a decade (its title says which)"
            + ("; dotted: detection limit, below which the fit is truncated (where a set's "
               "scans differ, their range shaded and the largest dotted)." if limited else "."))


def _fitted_sets(res: StatsResult, q: str, sets) -> list:
    """The sets among ``sets`` with a fit of quantity ``q`` in some sub-system (a summary
    whose every law failed, as when a detection limit leaves no value, is none)."""
    return [s for s in sets
            if any(_has_fit(res, s, r, q) for r in ("all", "bulk", "periphery"))]


def _has_fit(res: StatsResult, s: str, region: str, q: str) -> bool:
    """Whether set ``s`` has a fit of ``q`` in ``region`` (a summary whose every law failed
    is none)."""
    summ = res.summaries.get((s, region, q))
    return summ is not None and any(r.ok for r in summ.results.values())


def _left_out(res: StatsResult, ens: Ensemble, q: str, min_n: int) -> str:
    """The sentence naming the sets a distribution figure leaves out (no fit: fewer than
    ``min_n`` positive values, or all equal), whole or from one of its sub-system rows, or
    ""."""
    fitted = _fitted_sets(res, q, ens.sets)
    missing = [s for s in ens.sets if s not in fitted]
    # rows drawn for some set, missing for another that is drawn in other rows
    rows = [r for r in ("all", "bulk", "periphery")
            if any(_has_fit(res, s, r, q) for s in fitted)]
    partial = [f"{s} ({REGION_WORDS.get(r, r)})" for s in fitted for r in rows
               if not _has_fit(res, s, r, q) and r in regions_of(ens.subset(s))]
    if not (missing or partial):
        return ""
    return (f" Not drawn (fewer than {min_n} positive values above any detection limit, or "
            f"all equal): {', '.join(missing + partial)}.")


def _not_drawn(res: StatsResult, ens: Ensemble, quantities, min_n: int) -> str:
    """The paragraph naming the distribution figures absent from the report (no set has
    {min_n} positive values of the quantity that are not all equal), or ""."""
    absent = [q for q in quantities if not _fitted_sets(res, q, ens.sets)]
    if not absent:
        return ""
    return ("Not drawn (fewer than {} positive values above any detection limit, or all "
            "equal, in every set): the "
            "distribution of the {}.".format(min_n, ", of the ".join(WORDS[q] for q in absent)))


#: report column -> heading in words with units (lengths in units of the rod length L)
COLUMN_NAMES = {
    "set": "set", "region": "sub-system", "n_configs": "configurations",
    "N_l": "<N_l> stacks per configuration", "N_br": "<N_br> branches per configuration",
    "n_br": "<n_br> branches per stack", "s_L2": "<s>/L² void area",
    "sqrt_s_over_p": "<√s/p> void shape ratio", "l_L": "<l>/L branch length",
    "n_branches": "branches", "n_voids": "voids",
    "kappa_m_L": "<|κ_m|> L mean curvature", "E_tilde": "<E> total energy",
    "e": "<e> branch energy", "alpha_e": "α_e (Gamma shape, e)", "chi_e": "χ_e (Gamma scale, e)",
    "alpha_E": "α_E (Gamma shape, E)", "chi_E": "χ_E (Gamma scale, E)",
    "alpha_E_over_alpha_e": "α_E/α_e", "paper set": "paper set",
    "relation": "relation", "fitted": "ours", "expected": "expected / paper",
    "r2": "R²", "n": "n", "note": "definition",
    "pair": "pair", "pearson_r": "Pearson r [95 % interval]", "spearman_r": "Spearman r",
    "paper": "paper", "pearson_p": "p-value of r = 0",
    "quantity": "quantity", "family": "law", "param": "parameter",
    "naive": "naive fit", "truncated": "truncation-aware fit",
    "truncated_lo": "truncation-aware 2.5 %", "truncated_hi": "truncation-aware 97.5 %",
    "naive_bias_rel": "relative bias of the naive fit", "cut_mean": "mean detection limit",
    "mean_minus_cut": "<x> - <cut> (= μ for the exponential)", "rejected": "why rejected",
}
RELATION_WORDS = {
    "eq12_const": "Eq. (12) constant C in N_br = C ε (√s̄/l̄) √N_l (expected 2√(π/3))",
    "slope_sqrt_s_vs_l": "slope of √s̄ against l̄ (paper 1.1)",
    "eq12_eps_sqrtNl": "K in N_br = K ε √N_l (expected 2√(π/3) × slope)",
    "eq14_slope": "Eq. (14) slope of N_br against N_l (expected <n_br>)",
    "eq15_fluct": "Eq. (15) mean relative deviation of n̄_br from <n_br>",
    "eq16": "Eq. (16) <n_br>√<N_l>/ε (paper 2.2√(π/3))",
    "n_br_exp_mu": "mean of the exponential (geometric) law of n_br (= <n_br> by its "
                   "maximum likelihood: not a test; its interval and the selected law)",
}
PAIR_WORDS = {"l_vs_inv_kappa_m": "branch length l vs 1/κ_m",
              "e_vs_l_kappa_m2": "branch energy e vs l κ_m²",
              "E_vs_N_br": "total energy E vs N_br"}


def _named(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` for reading: headings in words, codes of relations, pairs, sub-systems and
    quantities spelled out."""
    df = df.copy()
    if "relation" in df.columns:
        if "note" in df.columns:  # the words of the relation say it; keep the interval note
            df["note"] = df["note"].where(df["relation"] == "n_br_exp_mu", "")
            df = df.rename(columns={"note": "interval"})
        df["relation"] = df["relation"].map(lambda v: RELATION_WORDS.get(v, v))
    if "pair" in df.columns:
        df["pair"] = df["pair"].map(lambda v: PAIR_WORDS.get(v, v))
    if "region" in df.columns:
        df["region"] = df["region"].map(lambda v: REGION_WORDS.get(v, v))
    if "quantity" in df.columns:
        df["quantity"] = df["quantity"].map(lambda v: WORDS.get(v, v))
    return df.rename(columns=COLUMN_NAMES)


def _html_table(df: pd.DataFrame) -> str:
    """``df`` as an HTML table: numbers to 3 significant figures, counts
    (:data:`~crosssection.stats.tables.COUNT_COLUMNS`) exactly."""
    df = df.copy()
    for c in COUNT_COLUMNS:
        if c in df.columns:  # as text: pandas prints a nullable column's NA as "<NA>"
            df[c] = [count_text(v) for v in df[c]]
    return _named(df).to_html(index=False, float_format=lambda v: f"{v:.3g}", na_rep="",
                              border=0, classes="t")


def _with_errors(df: pd.DataFrame, n_configs=None) -> pd.DataFrame:
    """``df`` for the page with each value's uncertainty in its cell: ``X_se`` as
    "v ± se", ``X_lo`` and ``X_hi`` as "v [lo, hi]" (a cell already written out, marked
    indicative, keeps its mark after the interval); the error columns dropped. A standard
    error over fewer than :data:`N_RELATION_MIN` configurations (``n_configs``: set name ->
    count) is marked indicative, as a relation fitted on as few: it is itself uncertain."""
    few = pd.Series(False, index=df.index)
    if n_configs is not None and "set" in df.columns:
        few = df["set"].map(lambda s: n_configs.get(s, np.inf) < N_RELATION_MIN).astype(bool)
    df = df.copy()
    errs = [c for c in df.columns if c.endswith(("_se", "_lo", "_hi"))]
    bases = dict.fromkeys(c.rsplit("_", 1)[0] for c in errs)
    for b in bases:
        if b not in df.columns:
            continue
        se = df.get(f"{b}_se")
        lo, hi = df.get(f"{b}_lo"), df.get(f"{b}_hi")
        cells = []
        for i, v in zip(df.index, df[b]):
            if se is not None and np.isfinite(_num(se[i])) and not isinstance(v, str) \
                    and np.isfinite(_num(v)):
                k = n_configs.get(df.at[i, "set"]) if few[i] else None
                cells.append(_plus_minus(_num(v), _num(se[i])) + (
                    f" (n = {k} configurations: indicative only)" if few[i] else ""))
            elif lo is not None and np.isfinite(_num(lo[i])) and np.isfinite(_num(hi[i])) \
                    and (isinstance(v, str) or np.isfinite(_num(v))):
                extra = f" [{_num(lo[i]):.3g}, {_num(hi[i]):.3g}]"
                head, _, tail = (v if isinstance(v, str) else f"{v:.3g}").partition(" ")
                cells.append(f"{head}{extra} {tail}".rstrip())
            else:
                cells.append(v)
        df[b] = pd.Series(cells, index=df.index, dtype=object)
    return df.drop(columns=errs)


def _n_configs(res: StatsResult) -> dict:
    """Configurations per set (the macro table's ``n_configs``)."""
    m = res.macro
    if m.empty or "n_configs" not in m.columns:
        return {}
    return {s: int(n) for s, n in zip(m["set"], m["n_configs"])}


def _plus_minus(v: float, se: float) -> str:
    """``v ± se`` with the error to two significant figures and the value to the same
    decimal place (4093 ± 83, 0.0443 ± 0.0013); a value with no spread (every configuration
    alike, 0 stacks in each) alone."""
    if se == 0:
        return f"{v:.3g}"
    if not (1e-4 <= abs(v) < 1e6 or v == 0) or se >= 1e6:
        return f"{v:.3g} ± {se:.2g}"
    d = 1 - int(np.floor(np.log10(se)))
    if d < 0:  # an error of hundreds or more: both to its second digit (16400 ± 7400)
        q = 10.0 ** -d
        return f"{round(v / q) * q:.0f} ± {round(se / q) * q:.0f}"
    return f"{v:.{d}f} ± {se:.{d}f}"


def _num(v) -> float:
    """``v`` as a float, NaN where it is none."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return float("nan")


def _with_paper(ours: pd.DataFrame, paper: pd.DataFrame) -> pd.DataFrame:
    """Our rows followed by the paper's in the same columns (the paper's set in ``set``)."""
    p = paper.rename(columns={"paper set": "set"}).copy()
    p["set"] = "paper, set " + p["set"].astype(str)
    return pd.concat([ours, p.reindex(columns=[c for c in ours.columns if c in p.columns
                                               or c == "set"])], ignore_index=True)


#: parameters of a law that the sample sets rather than the fit (:mod:`..families`): shown
#: with what they are instead of a bootstrap interval
SAMPLE_BOUNDS = {"x_lo": "the sample's least value or the detection limit",
                 "x_hi": "the sample's largest value",
                 "x_min": "the detection limit or the sample's least value"}


def _selected_table(res: StatsResult) -> pd.DataFrame:
    """The selected law of every set, sub-system and quantity, parameters with intervals."""
    rows = []
    for (s, reg, q), summ in res.summaries.items():
        r = summ.results.get(summ.best) if summ.best else None
        if r is None:
            rows.append({"set": s, "region": reg, "quantity": q, "n": np.nan,
                         "selected law": "none selectable"})
            continue
        ps = []
        for nm in FAMILIES[r.family].param_names:
            if nm in SAMPLE_BOUNDS:
                # the sample's extreme or the detection limit, not a fitted value: its
                # resamples' spread is no confidence interval
                ps.append(f"{nm} = {r.params[nm]:.3g} ({SAMPLE_BOUNDS[nm]})")
                continue
            lo, hi = r.ci.get(nm, (np.nan, np.nan))
            ci = f" [{lo:.3g}, {hi:.3g}]" if np.isfinite(lo) and np.isfinite(hi) else ""
            ps.append(f"{nm} = {r.params[nm]:.3g}{ci}")
        if r.discrete:  # a count law's parameters are the continuous law's: say its mean
            ps.append(f"mean {_count_mean(r):.3g}")
        others = sorted((o.bic - r.bic, f) for f, o in summ.results.items()
                        if o.selectable and f != r.family)
        # a degenerate fit may reach a lower BIC (its shape parameters run off to a limit
        # law); it is never selected, but a reader must not think the selected law fits best
        aside = sorted((o.bic - r.bic, f) for f, o in summ.results.items()
                       if not o.selectable and np.isfinite(o.bic) and o.bic < r.bic)
        runner = (f"{FAMILIES[others[0][1]].title}, {others[0][0]:+.1f}" if others else "")
        if others and others[0][0] < BIC_UNDECIDED:
            # e.g. a Gamma law of shape 15-60 (the paper's E) against a Gaussian: 250
            # configurations select the true one 44-71 % of the time
            runner += f" (below {BIC_UNDECIDED:g}: the data do not tell the two laws apart)"
        if aside:
            lower = ", ".join(f"{FAMILIES[f].title}, {d:+.1f}" for d, f in aside)
            runner += (("; " if runner else "")
                       + f"lower, set aside as degenerate (see Degenerate fits): {lower}")
        small = small_sample_note(r.n, F.N_SELECT_MIN, "samples model selection needs",
                                  r.n_independent)
        shown = r.n if r.n_independent == r.n else f"{r.n} ({r.n_independent} stacks)"
        rows.append({
            "set": s, "region": reg, "quantity": q,
            "n": f"{small}: indicative only" if small else shown,
            "selected law": FAMILIES[r.family].title + (" (fitted as counts)" if r.discrete
                                                         else "")
            + (" (truncated at the detection limit)" if r.truncated else ""),
            "parameters [95 % interval]": "; ".join(ps),
            "runner-up law, BIC − BIC(selected)": runner,
            "goodness of fit": (r.p_text() or "not computed") + (
                f"; the data reject it at the {GAMMA_MISFIT_P:.0%} level"
                if np.isfinite(r.pvalue) and r.pvalue < GAMMA_MISFIT_P else "")})
    return pd.DataFrame(rows)


def _relations_shown(rel: pd.DataFrame) -> pd.DataFrame:
    """The relations table with the sample size of a relation computed on too few
    configurations (or a law's parameter on too few values) spelled out beside it
    (:func:`~crosssection.stats.tables.relation_note`)."""
    # the page says "indicative only" beside the number: the CSV's boolean column is not shown
    rel = rel.drop(columns=["indicative"], errors="ignore")
    if rel.empty:
        return rel
    notes = [relation_note(r, n, f) for r, n, f in zip(rel["relation"], rel["n"], rel["fitted"])]
    rel["n"] = [f"{t}: indicative only" if t else n for t, n in zip(notes, rel["n"])]
    return rel


def _correlations_shown(cor: pd.DataFrame) -> pd.DataFrame:
    """The correlations table with the number of pairs of a coefficient computed from too
    few spelled out beside it, as the relations table does."""
    # the page says "indicative only" beside the number: the CSV's boolean column is not shown
    cor = cor.drop(columns=["indicative"], errors="ignore")
    if cor.empty:
        return cor
    notes = [small_sample_note(n, N_RELATION_MIN, "pairs of values a correlation needs")
             if np.isfinite(r) else "" for n, r in zip(cor["n"], cor["pearson_r"])]
    cor["n"] = [f"{t}: indicative only" if t else n for t, n in zip(notes, cor["n"])]
    if "pearson_lo" in cor.columns:  # Pearson's r with its 95 % interval in one cell
        cor = _with_errors(cor.rename(columns={"pearson_lo": "pearson_r_lo",
                                               "pearson_hi": "pearson_r_hi"}))
    if "pearson_p" in cor.columns:
        cor["pearson_p"] = [f"{p:.2g}" if np.isfinite(_num(p)) else "" for p in cor["pearson_p"]]
    return cor


#: the Gamma fits behind the columns of the micro and dof tables: column -> (quantity,
#: sub-system, None for the row's own)
GAMMA_COLUMNS = {"alpha_e": (("e", None),), "chi_e": (("e", None),),
                 "alpha_E": (("E", "all"),), "chi_E": (("E", "all"),),
                 "alpha_E_over_alpha_e": (("E", "all"), ("e", "all"))}


def _gamma_n(res: StatsResult, s, reg, q) -> tuple:
    """Values of the Gamma fit of quantity ``q`` in set ``s`` and sub-system ``reg``, and
    the independent ones among them (stacks, for scan branches): ``(n, n_groups)``."""
    summ = res.summaries.get((s, reg, q))
    r = summ.results.get("gamma") if summ is not None else None
    return (float(r.n), float(r.n_independent)) if r is not None else (np.nan, np.nan)


#: goodness-of-fit p-value below which a law is marked as one the data reject (a Gamma law's
#: parameters in the tables, the selected law of every quantity; the fits table's test)
GAMMA_MISFIT_P = 0.05


def _gamma_misfit_note(res: StatsResult, s, reg, q) -> str:
    """Why the Gamma law of quantity ``q`` describes the data poorly: its goodness-of-fit
    test rejects it, or another law is selected; "" when neither (or no fit)."""
    summ = res.summaries.get((s, reg, q))
    r = summ.results.get("gamma") if summ is not None else None
    if r is None:
        return ""
    why = []
    if np.isfinite(r.pvalue) and r.pvalue < GAMMA_MISFIT_P:
        why.append(f"the Gamma law of {q} fails its goodness-of-fit test, {r.p_text()}")
    if summ.best and summ.best != "gamma":
        why.append(f"{FAMILIES[summ.best].title} is the law selected for {q}")
    return "; ".join(why)


def _small_fits_marked(df: pd.DataFrame, res: StatsResult) -> pd.DataFrame:
    """``df`` (the micro or dof table) with every value taken from a Gamma fit on fewer
    values than model selection needs marked "indicative only", as the other tables mark
    them."""
    # the page says "indicative only" beside the number: the CSV's boolean columns are not
    # shown
    df = df.drop(columns=["indicative", "indicative_e", "indicative_E"], errors="ignore")
    if df.empty or "set" not in df.columns:
        return df
    for col, sources in GAMMA_COLUMNS.items():
        if col not in df.columns:
            continue
        cells = []
        for _, row in df.iterrows():
            v = row[col]
            reg = row.get("region", "all")
            notes, misfits = [], []
            for q, r in sources:
                n, n_ind = _gamma_n(res, row["set"], r or reg, q)
                notes.append(small_sample_note(n, F.N_SELECT_MIN,
                                               f"samples model selection needs ({q})", n_ind))
                misfits.append(_gamma_misfit_note(res, row["set"], r or reg, q))
            notes = [n for n in notes if n]
            misfits = [m for m in misfits if m]
            if not (isinstance(v, (int, float)) and np.isfinite(v)) or not (notes or misfits):
                cells.append(v)
                continue
            # the value first: the page puts its interval right after it
            cells.append(f"{v:.3g}" + (f" ({'; '.join(notes)}: indicative only)" if notes
                                       else "")
                         + (f" ({'; '.join(misfits)})" if misfits else ""))
        df[col] = pd.Series(cells, index=df.index, dtype=object)
    return df


def _quality_rows(ens: Ensemble) -> pd.DataFrame:
    """Configurations whose image analysis raised quality warnings."""
    c = ens.configs
    if "quality" not in c.columns:
        return c.iloc[:0]
    q = c["quality"].astype(object).where(c["quality"].notna(), "").astype(str)
    bad = q != ""
    return pd.DataFrame({"set": c.loc[bad, "set"], "configuration": c.loc[bad, "config_id"],
                         "quality warnings": q[bad].str.replace(";", ", ")})


def _model_share_note(ens: Ensemble) -> str:
    """What the scans' bending energies rest on: the share of E not measured on a free
    centreline (``total_energy_rel_uncertainty`` of each analysis), '' without images."""
    share = pd.to_numeric(ens.configs.get("E_model_share"), errors="coerce").dropna()
    if share.empty:
        return ""
    return (f"<p>Bending energy of the scans: a median {share.median():.2f} of each scan's "
            f"total (range {share.min():.2f}-{share.max():.2f}, {len(share)} scans) lies where "
            "a band is merged with its neighbours and rests on the fork-zone model, not on a "
            "free centreline (<code>total_energy_rel_uncertainty</code>). Measured on "
            "generated scans with exact truth, one branch's e is good to about a factor 1.5 "
            "and a scan's E to within 5-30 % on the package's own typical scans (31-57 % too "
            "high on two generators written apart from the package's, whose arms meet their "
            "bands at drawn corners, 23 % too low on a third, whose branches bend hardest "
            "just after their bands part, and 4-47 % too low on a fourth); the "
            "largest energies tend to read low and "
            "nearly straight branches high, and α<sub>e</sub> (the Gamma shape of e) came "
            "out 3-15 % above the truth's on two generators, and the periphery's 14-32 % "
            "above it on the fourth (its stacks along the wall read high, those leaving it "
            "low: compare the sub-systems' α<sub>e</sub> with care). Every branch of a stack takes "
            "the stack's curvature (the paper's method), which alone narrows the law of e: on "
            "20 renders of quenched rods the rods' own branches read α<sub>e</sub> 0.45, the "
            "same branches given their stack's mean energy 0.55, the scans 0.55; compare a "
            "scan's α<sub>e</sub> with a simulation's read the same way. On rods compacted to "
            "the experiments' density and drawn as they lie, E read -2 to +9 % on clean "
            "drawings and +20 to +48 % with a scan's defects.</p>")


#: How each curvature method of the analysis reads κ, for the methods paragraph
#: (:data:`crosssection.params.CURVATURE_METHODS`)
_CURVATURE_TEXT = {
    "walls": "parabolic fits over 5 n<sub>br</sub> h along the centreline read between each "
             "band's two walls; near junctions, where a band is still merged with its "
             "neighbours, κ is read along the merged band's outer wall where a layer lies "
             "along it and otherwise continued from the nearest fitted windows (their trend "
             "where it exceeds the noise), and the scan's own fit noise is removed from e",
    "missing": "parabolic fits over 5 n<sub>br</sub> h along the centreline read between "
               "each band's two walls; near junctions, where a band is still merged with its "
               "neighbours, κ is continued from the nearest fitted windows (their trend where "
               "it exceeds the noise), and the scan's own fit noise is removed from e",
    "paper": "parabolic fits over 5 n<sub>br</sub> h along the smoothed skeleton, as in the "
             "paper; near junctions κ is the nearest fitted one, and the fit noise is not "
             "removed from e",
}


def _curvature_methods(ens) -> list:
    """The curvature methods the scans of ``ens`` were analysed with (their recorded
    parameters; the default for a record without one), in the order of
    :data:`_CURVATURE_TEXT`; [] without scans."""
    from crosssection.params import AnalysisParams

    if ens is None or "analysis" not in ens.configs:
        return []
    used = set()
    # scans only: a simulation's record holds its own parameters, no curvature method
    for cell in ens.configs.loc[_scan_rows(ens, unknown=True), "analysis"].dropna():
        try:
            rec = json.loads(cell)
        except (TypeError, ValueError):
            continue
        params = rec.get("parameters") if isinstance(rec, dict) else None
        if params:  # an analysis (a simulation records no image parameters)
            used.add(params.get("curvature_method") or AnalysisParams.curvature_method)
    return [m for m in _CURVATURE_TEXT if m in used] + sorted(used - set(_CURVATURE_TEXT))


def _curvature_text(methods) -> str:
    """`` (images: ...)`` naming how κ was read, per curvature method used."""
    if not methods:
        return ""
    parts = [f"<code>{html.escape(str(m))}</code>: {_CURVATURE_TEXT.get(m, 'see the analysis')}"
             for m in methods]
    if len(parts) == 1:
        return f" (images, curvature method {parts[0]})"
    return " (images, analysed with several curvature methods; " + "; ".join(parts) + ")"


def _methods(meta, opts: StatsOptions, ens=None) -> str:
    """The methods paragraph of the report."""
    methods = _curvature_methods(ens)
    n_mc = opts.n_mc
    gof = (f"Goodness of fit: Anderson-Darling statistic (for the counts n_br, the "
           f"likelihood-ratio statistic G) with a parametric-bootstrap p-value from {n_mc} "
           f"samples drawn from the fitted law and refitted; the smallest resolvable p-value "
           f"is 1/({n_mc}+1), and a p-value at that floor is printed as "
           f"\"p &lt; 1/{n_mc + 1}\"." if opts.gof else
           "Goodness-of-fit p-values were not computed for this report.")
    return (
        "<p><b>Methods.</b> Each scan is reduced to its skeleton: junction points split the "
        "rod into branches, branches in contact between the same junctions form a stack of "
        "n<sub>br</sub> branches, and the enclosed empty regions are voids. Per branch we "
        "measure its length l, mean curvature κ<sub>m</sub>, mean absolute curvature "
        "κ<sub>+</sub> and energy e: for scans the bending energy e = L∫κ²ds, for simulated "
        "rods the branch's bending energy plus its confinement energy, as in the paper's "
        f"simulations{_curvature_text(methods)}; per configuration the numbers of stacks "
        "N<sub>l</sub> and branches N<sub>br</sub>, the compaction ε and the total energy E; "
        "per void its area s and shape ratio √s/p. Lengths are in units of the rod length L. "
        "Branches touching the container wall form the periphery, the others the bulk "
        "(images only). Following Adda-Bedia, Boudaoud, Boué and Deboeuf, \"Statistical "
        "distributions in the folding of elastic structures\", each distribution is fitted by "
        "maximum likelihood with the exponential, Gamma, log-normal and Gaussian laws (and "
        "Bose-Einstein or a cut-off power law where the paper uses them); below the detection "
        "limits (branches shorter than l_min, voids smaller than s_min) nothing is seen, so "
        "the fits of the scans' lengths and areas are truncated there: here "
        f"{_limits_text(meta.get('detection_limits', {}))} (paper: 1 mm and 1 mm²; "
        "simulations have none). The number of branches per stack is an integer and is "
        "fitted as counts (the law integrated over [k-½, k+½]). Model selection: the law of "
        "lowest BIC, except that a law with fewer parameters within ΔBIC &lt; "
        f"{F.DELTA_BIC_SIMPLER:g} of the minimum is preferred (the simplest law the data "
        "support); AIC and BIC of every law are in fits.csv. Parameter intervals are 95 % "
        f"percentile bootstrap intervals from {opts.n_boot} resamples, except the Gamma shape "
        "of values fitted as independent (the total energies E, a simulation's branches): "
        "the interval of its scale-free statistic log(mean) − mean(log), which holds the "
        "shape of a Gamma law as often as it says at any number of values; the shaded bands "
        f"in the figures the pointwise 95 % range of the law over those resamples. {gof}</p>")


def _html(res: StatsResult, figs, meta, ens: Ensemble | None = None,
          opts: StatsOptions | None = None, not_drawn: str = "") -> str:
    opts = opts or StatsOptions()
    rej = (res.fits[res.fits["rejected"].fillna("").astype(str) != ""]
           if "rejected" in res.fits.columns else res.fits.iloc[:0])
    rej_cols = ["set", "region", "quantity", "family", "rejected"]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>foldstat statistics</title>",
        "<style>body{font-family:sans-serif;max-width:1200px;margin:auto;padding:0 1em;"
        "line-height:1.4}table.t{border-collapse:collapse;font-size:12px;margin-bottom:1em}"
        "table.t td,table.t th{border:1px solid #ccc;padding:2px 6px}"
        "table.t th{background:#f3f3f3;text-align:left;vertical-align:bottom}"
        "table.t td{text-align:left}img{max-width:100%}figure{margin:1em 0 2em}"
        "figcaption{font-size:14px;color:#333}.warn{color:#a00}</style></head><body>",
        "<h1>Folding statistics</h1>",
        f"<p>foldstat {html.escape(meta['version'])}; inputs: "
        f"{html.escape(_inputs_text(meta))}; seed {meta['options']['seed']} (each set draws "
        "from its own stream, derived from the seed and the set's name: "
        f"{html.escape(_seeds_text(meta))}).</p>",
    ]
    for note in meta.get("incomplete_batches") or ():
        parts.append(f"<p class='warn'><b>Incomplete input:</b> {html.escape(note)}.</p>")
    for note in meta.get("tables_unlike_summary") or ():
        parts.append(f"<p class='warn'><b>Table unlike its summary.json:</b> "
                     f"{html.escape(note)}: the scan's counts, tables and fits are those of "
                     "the rows; its E and ε are summary.json's.</p>")
    parts += [_methods(meta, opts, ens), _per_set_text(meta)]
    if ens is not None:
        qual = _quality_rows(ens)
        if len(qual):
            parts += [f"<h2 class='warn'>Input quality warnings ({len(qual)} of "
                      f"{len(ens.configs)} configurations)</h2><p>The image analysis flagged "
                      "these scans; their values enter every table and figure below.</p>",
                      _html_table(qual)]
        elif _scan_rows(ens).any():  # simulations have no image analysis
            parts.append("<p>Input quality: no scan carries an image-analysis quality "
                         "warning.</p>")
        parts.append(_model_share_note(ens))
    parts.append("<h2>Figures</h2><ul>" + "".join(
        f"<li><a href='#{html.escape(Path(rel).stem)}'>{html.escape(t)}</a></li>"
        for t, rel, _ in figs) + "</ul>")
    parts += [
        "<p>Tables as files: " + " ".join(
            f"<a href='{n}.csv'>{n}.csv</a> <a href='{n}.md'>(md)</a>"
            for n in ("macro", "micro", "fits", "relations", "dof", "truncation"))
        + " <a href='correlations.csv'>correlations.csv</a> "
          "<a href='per_config.csv'>per_config.csv</a> <a href='stats.json'>stats.json</a></p>",
        "<h2>Averages per set: stacks, branches and voids</h2><p>N<sub>l</sub> and "
        "N<sub>br</sub> are means over the configurations of a set; n<sub>br</sub>, s/L², "
        "√s/p and l/L are pooled means over all the set's stacks, voids and branches (see "
        "docs/report.md). ± a standard error: over the configurations, for a pooled mean "
        "with each configuration's values taken together (they are not independent draws). "
        "The paper's values below ours.</p>",
        _html_table(_with_paper(_with_errors(res.macro, _n_configs(res)), PAPER_MACRO)),
        "<h2>Averages per set: curvature and energy</h2><p>Means, and the shape α and scale χ "
        "of the Gamma law fitted to the branch energies e and to the total energies E "
        "(± a standard error as above; [ ] the 95 % interval of the fits table, "
        "whatever law is selected there); the paper's values below ours.</p>",
        _html_table(_with_paper(_with_errors(_small_fits_marked(res.micro, res),
                                             _n_configs(res)), PAPER_MICRO)),
        "<h2>Are branches the independent units? α_E/α_e against the number of stacks</h2>"
        "<p>A sum of m independent Gamma variables of shape α_e has shape m α_e, so "
        "α_E/α_e counts the effectively independent energy units of a configuration; the "
        "paper compares it with the number of stacks &lt;N<sub>l</sub>&gt; ([ ] a 95 % "
        "interval from the two shapes' intervals). The paper's "
        "values below ours.</p>",
        _html_table(_with_paper(_with_errors(_small_fits_marked(res.dof, res)), PAPER_DOF)),
        "<h2>Stacking relations (paper Eqs. (12)-(16))</h2>"
        "<p>The paper derives Eq. (12) from N<sub>br</sub> = L/l̄ (the branches tile the "
        "rod; exact where L is the sum of the branches' lengths, as on scans of no given rod "
        "length), N<sub>v</sub> = S/s̄ (the voids tile the hole) and N<sub>l</sub> = "
        "3 N<sub>v</sub>; a fitted C near 2√(π/3) tests the last two. "
        "r2 = 1 − SS<sub>res</sub>/SS<sub>tot</sub> about the mean of y: negative where the "
        "line through the origin describes the points worse than their mean, that is where "
        "the relation does not hold for the set.</p>",
        _html_table(_relations_shown(res.relations)),
        "<h2>Correlations</h2>", _html_table(_correlations_shown(res.correlations)),
        "<h2>Selected laws</h2>",
        _html_table(_selected_table(res)) if res.summaries else "<p>none</p>",
    ]
    if len(rej):
        parts += ["<h2>Degenerate fits (never selected)</h2><p>A fit whose parameters run to "
                  "a limit of its family (a Bose-Einstein law with βx ≪ 1 everywhere, that is "
                  "a 1/x law; a Gaussian whose mean lies far below the data) or whose law is a "
                  "spike the data cannot resolve describes no law of the data, whatever its "
                  "BIC: a limit fits as well as the family's best member and its parameters "
                  "are not determined. Its reason is in the last column; it is never selected "
                  "and carries no interval nor p-value.</p>", _html_table(rej[rej_cols])]
    if not res.truncation.empty:
        parts += ["<h2>Detection limits: naive against truncation-aware fits</h2>",
                  _html_table(res.truncation)]
    parts.append("<h2>Figures</h2>")
    if not_drawn:
        parts.append(f"<p>{html.escape(not_drawn)}</p>")
    for title, rel, caption in figs:
        parts.append(f"<figure id='{html.escape(Path(rel).stem)}'><h3>{html.escape(title)}"
                     f"</h3><a href='{rel}'><img src='{rel}' alt='{html.escape(title)}'></a>"
                     f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
