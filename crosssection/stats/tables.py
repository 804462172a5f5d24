"""The paper's per-set tables, relations (Eqs. (12)-(16)), correlations and distribution fits.

Everything is computed from an :class:`~crosssection.stats.data.Ensemble` (units of L):

- macro (the paper's table of averages over all realizations): <N_l>, <N_br>, <n_br>,
  <s>/L^2, <sqrt(s)/p>, <l>/L;
- micro (the paper's table of curvatures and energies): <kappa_m>L, <l>/L, <E~>, <e>,
  alpha_e, chi_e, alpha_E, chi_E
  (Gamma fits of the paper's Eq. (3), chi = scale);
- degrees of freedom (the paper's table of alpha_E/alpha_e): alpha_E/alpha_e against <N_l>;
- relations (section "Stacking"): Eq. (12) constant, slope of sqrt(s_bar) vs l_bar, Eq. (14) slope,
  Eq. (16) ratio, n_br exponential;
- correlations (Pearson r): l with 1/kappa_m (paper 0.45), e with l kappa_m^2 (0.6),
  E with N_br (0.75);
- fits of every distribution with model selection, truncation-aware where a detection limit
  applies (l >= l_min, s >= s_min), with the naive fit alongside.

Bulk and periphery are tabulated apart and together when the data carry regions (images);
simulations have region ``"none"`` and only the ``"all"`` rows.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from crosssection.core.errors import ParameterError
from crosssection.quality import QualityWarning
from crosssection.stats import fits as F
from crosssection.stats.data import SIM_REGION, Ensemble, branch_groups
from crosssection.stats.families import SPREAD_RTOL, binary_exponent, no_spread

# Eq. (12): N_br = (2 sqrt(pi)/sqrt(3)) eps (sqrt(s)/l) sqrt(N_l)
EQ12_CONST = 2 * np.sqrt(np.pi) / np.sqrt(3)
EQ16_PAPER = 2.2 * np.sqrt(np.pi / 3)  # Eq. (16)
PAPER_SLOPE_S_L = 1.1  # Fig. topolo_macro b
PAPER_CORR = {"l_vs_inv_kappa_m": 0.45, "e_vs_l_kappa_m2": 0.6, "E_vs_N_br": 0.75}

# The paper's averages per set (experimental sets 1-4, simulations 5), shown beside ours;
# for the simulations the paper gives N_l, N_br and n_br only as ~10, ~20 and ~2.
# Macroscopic table: <N_l>, <N_br>, <n_br>, <s>/L^2, <sqrt(s)/p>, <l>/L
PAPER_MACRO = pd.DataFrame({
    "paper set": ["1", "2", "3", "4", "5 (simulations; N_l, N_br, n_br about)"],
    "N_l": [90, 80, 40, 80, 10], "N_br": [380, 310, 100, 330, 20],
    "n_br": [5, 4, 3, 5, 2], "s_L2": [6.6e-6, 1.4e-5, 1.1e-4, 2.6e-5, 3.4e-4],
    "sqrt_s_over_p": [0.19, 0.18, 0.18, 0.18, 0.19],
    "l_L": [2.5e-3, 3.4e-3, 10e-3, 4.4e-3, 0.05]})
# Microscopic table: <kappa_m>L, <l>/L, <E~>, <e>, alpha_e, chi_e, alpha_E, chi_E
PAPER_MICRO = pd.DataFrame({
    "paper set": ["1", "2", "3", "4", "5 (simulations)"],
    "kappa_m_L": [330, 260, 100, 200, 37], "l_L": [2.5e-3, 3.4e-3, 10e-3, 4.4e-3, 0.05],
    "E_tilde": [13e4, 11e4, 1.3e4, 7.3e4, 0.43e4], "e": [330, 340, 130, 220, 230],
    "alpha_e": [0.16, 0.19, 0.41, 0.31, 0.31], "chi_e": [2000, 1800, 330, 720, 730],
    "alpha_E": [10.8, 12.7, 15.9, 5.72, 61], "chi_E": [1.2e4, 8.3e3, 8.4e2, 1.3e4, 70]})
# Degrees of freedom: <N_l> and alpha_E/alpha_e (the paper's table "tab_res"; its
# simulations' N_l is given as ~10)
PAPER_DOF = pd.DataFrame({"paper set": ["1", "2", "3", "4", "5 (simulations; N_l about)"],
                          "N_l": [90, 80, 40, 80, 10],
                          "alpha_E_over_alpha_e": [68, 55, 56, 23, 200]})

# quantity -> (table, column, families, truncation column or None, label)
_SHORT = ("exponential", "gamma", "lognormal", "gaussian")
QUANTITIES = {
    "length_L": ("branches", "length_L", F.PAPER_FAMILIES, "l_min_L", r"$\ell/L$"),
    "kappa_m_L": ("branches", "kappa_m_L", F.PAPER_FAMILIES, None, r"$\kappa_m L$"),
    "kappa_plus_L": ("branches", "kappa_plus_L", F.PAPER_FAMILIES, None, r"$\kappa_+ L$"),
    "e": ("branches", "e", F.PAPER_FAMILIES, None, r"$e$"),
    "E": ("configs", "E", _SHORT, None, r"$E$"),
    "n_br": ("stacks", "n_br", _SHORT, None, r"$n_{br}$"),
    # the paper calls the simulations' void-area law "closer to a power law"
    "area_L2": ("voids", "area_L2", (*_SHORT, "powerlaw_cutoff"), "s_min_L2", r"$s/L^2$"),
    "shape_ratio": ("voids", "shape_ratio", ("gamma", "lognormal", "gaussian"), None,
                    r"$\sqrt{s}/p$"),
}
#: integer quantities, fitted as counts (:func:`crosssection.stats.fits.fit_family`)
COUNT_QUANTITIES = {"n_br"}
POSITIVE_QUANTITIES = {"length_L", "kappa_m_L", "kappa_plus_L", "e", "E", "n_br", "area_L2",
                       "shape_ratio"}
#: Fewest configurations for a relation of Eqs. (12)-(16) fitted across configurations: a line
#: through the origin passes exactly through one point, and R^2 of two to four points says
#: little about the relation
N_RELATION_MIN = 5
#: Fewest pairs of values a correlation coefficient is computed from (two always give +-1).
CORRELATION_MIN_PAIRS = 3
#: the relations fitted across configurations (a slope or ratio per set)
SLOPE_RELATIONS = ("eq12_const", "slope_sqrt_s_vs_l", "eq12_eps_sqrtNl", "eq14_slope")
#: the relations computed across configurations, the slopes and the means over
#: configurations: each is indicative only below :data:`N_RELATION_MIN` configurations (a
#: mean of two configurations says as little as a slope through two points);
#: ``n_br_exp_mu``, a parameter of the law of n_br, follows the laws' rule instead
CONFIG_RELATIONS = SLOPE_RELATIONS + ("eq15_fluct", "eq16")
#: columns of the report's tables that hold counts (of configurations, branches, voids,
#: values, resamples, parameters): printed as integers, never rounded (:func:`to_markdown`)
COUNT_COLUMNS = ("n_configs", "n_branches", "n_voids", "n", "n_groups", "n_dropped", "n_mc",
                 "k")
#: the relation that is a law's parameter (the mean of the exponential law of n_br): its
#: ``n`` counts the stacks, indicative below the values model selection needs
LAW_RELATION = "n_br_exp_mu"


def relation_note(relation: str, n, fitted) -> str:
    """Why a row of the relations table is indicative only, in the report's words
    (:func:`small_sample_note`), or "" when it is not (or was not computed)."""
    try:
        if not np.isfinite(float(fitted)):
            return ""
    except (TypeError, ValueError):
        return ""
    if relation in CONFIG_RELATIONS:
        return small_sample_note(n, N_RELATION_MIN, "configurations a fitted relation needs")
    if relation == LAW_RELATION:
        return small_sample_note(n, F.N_SELECT_MIN, "samples model selection needs")
    return ""


def small_sample_note(n, minimum: int, what: str, n_groups=None) -> str:
    """The words that follow a sample size below its minimum, as the report prints them
    ("n = 6: below the 50 samples model selection needs"); "" when ``n`` is enough.

    ``n_groups``, the independent stacks among ``n`` branches, is what is compared with
    ``minimum`` when given and unlike ``n`` ("n = 60 (20 stacks): below ...")."""
    if n_groups is None or not np.isfinite(n_groups) or n_groups == n:
        if not (np.isfinite(n) and n < minimum):
            return ""
        return f"n = {int(n)}: below the {minimum} {what}"
    if not n_groups < minimum:
        return ""
    return f"n = {int(n)} ({int(n_groups)} stacks): below the {minimum} {what}"


def n_text(r) -> str:
    """The values a fit rests on, as the warnings and notes give them: ``n = 40``, or
    ``n = 120 (40 stacks)`` for branches grouped by stack."""
    if r.n_independent == r.n:
        return f"n = {r.n}"
    return f"n = {r.n} ({r.n_independent} stacks)"


def _where(q: str, reg: str) -> str:
    """A quantity as the warnings name it: with its region unless it is the whole set's."""
    return q if reg in ("all", SIM_REGION) else f"{q} ({reg})"


def _warn_small_samples(summaries: dict, relations: pd.DataFrame, too_few: dict,
                        min_n: int) -> None:
    """One :class:`~crosssection.stats.fits.SmallSampleWarning` per set naming the quantities
    whose law was selected on fewer than :data:`~crosssection.stats.fits.N_SELECT_MIN`
    values, the relations fitted on fewer than :data:`N_RELATION_MIN` configurations and
    the quantities not fitted at all for having fewer than ``min_n`` values (``too_few``:
    set -> ["E n = 3", ...])."""
    small = {s: [[], [], items] for s, items in too_few.items()}
    for (s, reg, q), summ in summaries.items():
        r = summ.results.get(summ.best) if summ.best else None
        if r is not None and r.n_independent < F.N_SELECT_MIN:
            small.setdefault(s, [[], [], []])[0].append(f"{_where(q, reg)} {n_text(r)}")
    for row in relations.itertuples(index=False):
        # n_br_exp_mu is named with the laws (its law of n_br)
        if row.relation in CONFIG_RELATIONS and relation_note(row.relation, row.n, row.fitted):
            small.setdefault(row.set, [[], [], []])[1].append(f"{row.relation} n = {row.n}")
    for s, (laws, rels, unfitted) in small.items():
        parts = []
        if unfitted:
            parts.append(f"not fitted, fewer than the {min_n} values a fit needs (min_n): "
                         f"{', '.join(unfitted)}")
        if laws:
            parts.append(f"laws selected on fewer than the {F.N_SELECT_MIN} samples model "
                         f"selection needs ({', '.join(laws)})")
        if rels:
            parts.append(f"relations fitted on fewer than {N_RELATION_MIN} configurations "
                         f"({', '.join(rels)})")
        tail = ": indicative only" if laws or rels else ""
        warnings.warn(f"set {s}: {'; '.join(parts)}{tail}", F.SmallSampleWarning,
                      stacklevel=3)


@dataclass
class StatsOptions:
    """Knobs of the statistics (all random choices derive from ``seed``).

    Attributes
    ----------
    seed : int or None
        An integer >= 0 (None: fresh entropy, a different result every run). Each set draws
        from its own stream, :func:`set_seed` of this seed and the set's name: the same data
        under another set name gives other intervals and p-values, so reproducing a result
        takes the same seed and the same set names (``load_any(..., set_name=...)``, ``stats
        --name``); ``stats.json`` records each set's derived seed (``sets.NAME.seed``).
    n_boot : int
        Bootstrap resamples of the parameter intervals (0: none).
    gof : bool
        Compute goodness-of-fit p-values.
    n_mc : int
        Resamples of each p-value (at least 1 with ``gof``).
    quantities : str or tuple of str
        Keys of :data:`QUANTITIES` to fit (one name or several).
    min_n : int
        Fewest values (at least 1) for a quantity to be fitted.

    Raises
    ------
    ParameterError
        Naming the attribute whose value is absurd (checked again by
        :func:`compute_stats`, since the attributes may be changed afterwards).
    """

    seed: int = 0
    n_boot: int = F.N_BOOT
    gof: bool = True
    n_mc: int = F.N_MC
    quantities: tuple = tuple(QUANTITIES)
    min_n: int = 5

    def __post_init__(self):
        self.check()

    def check(self) -> None:
        """Raise a ParameterError naming the first absurd attribute."""
        if self.seed is not None:  # None: fresh entropy, as numpy takes it
            F._count(self.seed, "seed")
        F._count(self.n_boot, "n_boot")
        F._check_mc(self.n_mc, self.gof)
        F._count(self.min_n, "min_n", 1)
        if isinstance(self.quantities, str):  # one name, not its letters
            self.quantities = (self.quantities,)
        try:
            qs = tuple(self.quantities)
        except TypeError:
            raise ParameterError(f"quantities must be names of {tuple(QUANTITIES)}, got "
                                 f"{self.quantities!r}") from None
        unknown = [q for q in qs if not isinstance(q, str) or q not in QUANTITIES]
        if unknown:
            raise ParameterError(f"quantities holds unknown {unknown}; choose from "
                                 f"{tuple(QUANTITIES)}")


@dataclass
class StatsResult:
    """All tables of a run, plus the fit objects (for figures)."""

    macro: pd.DataFrame
    micro: pd.DataFrame
    dof: pd.DataFrame
    fits: pd.DataFrame
    truncation: pd.DataFrame
    relations: pd.DataFrame
    correlations: pd.DataFrame
    per_config: pd.DataFrame
    summaries: dict = field(default_factory=dict)  # (set, region, quantity) -> FitSummary


def regions_of(ens: Ensemble) -> list[str]:
    """``["all"]`` plus ``bulk``/``periphery`` when the branches carry them."""
    present = set(ens.branches["region"].dropna().astype(str)) - {SIM_REGION, "nan", ""}
    return ["all"] + [r for r in ("bulk", "periphery") if r in present]


def table_regions(ens: Ensemble) -> list[str]:
    """The rows of the macro and micro tables: ``["all"]``, and both sub-systems when the
    branches carry either (a scan whose every stack touches the wall has a bulk of no stack,
    a measurement its row of zero counts states)."""
    regions = regions_of(ens)
    return ["all", "bulk", "periphery"] if len(regions) > 1 else regions


def _in_region(df, region):
    if region == "all" or "region" not in df.columns:
        return df
    return df[df["region"].astype(str) == region]


def _mean(v):
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else np.nan


def _se(v):
    """Standard error of the mean of the finite values (NaN below two)."""
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return float(np.std(v, ddof=1) / np.sqrt(v.size)) if v.size >= 2 else np.nan


def _pooled_se(values, groups):
    """Standard error of the mean pooled over every value, with the values of one group (a
    configuration) not independent: the cluster-robust error of a ratio estimator,
    ``sqrt(G / (G - 1) sum_g (S_g - m n_g)^2) / N`` for G groups of n_g values summing to S_g
    and the pooled mean m (NaN below two groups). Branches of one rod, or of one scan's
    stack, are not independent draws: the error over values alone would be too small."""
    v = np.asarray(values, float)
    g = np.asarray(groups)
    k = np.isfinite(v)
    v, g = v[k], g[k]
    if v.size == 0:
        return np.nan
    _, inv = np.unique(g.astype(str), return_inverse=True)
    n_g = np.bincount(inv)
    if n_g.size < 2:
        return np.nan
    s_g = np.bincount(inv, weights=v)
    m = v.sum() / v.size
    G = n_g.size
    return float(np.sqrt(G / (G - 1) * np.sum((s_g - m * n_g) ** 2)) / v.size)


def per_config_table(ens: Ensemble) -> pd.DataFrame:
    """Per configuration: N_l, N_br, n_br_bar = N_br/N_l, epsilon, E, s_bar, l_bar, e_bar.

    s_bar and l_bar are the configuration means of void area and branch length (units of L),
    the quantities of Eq. (12).
    """
    c = ens.configs.copy()
    key = ["set", "config_id"]

    def finite_mean(df, col, name):
        # of the finite values, as the fits take them (an infinite length would make l_bar
        # inf and the configuration's Eq. (12) abscissa 0, kept in the relation)
        v = df[col].where(np.isfinite(df[col].astype(float)))
        return v.groupby([df[k] for k in key]).mean().rename(name)

    lb = finite_mean(ens.branches, "length_L", "l_bar")
    eb = finite_mean(ens.branches, "e", "e_bar")
    sb = finite_mean(ens.voids, "area_L2", "s_bar")
    c = c.join(lb, on=key).join(eb, on=key).join(sb, on=key)
    c["n_br_bar"] = c["N_br"] / c["N_l"].where(c["N_l"] > 0)
    c["sqrt_s_bar"] = np.sqrt(c["s_bar"])
    c["eq12_x"] = c["epsilon"] * c["sqrt_s_bar"] / c["l_bar"] * np.sqrt(c["N_l"])
    return c


def macro_table(ens: Ensemble) -> pd.DataFrame:
    """The paper's table of averages (stacks, branches, voids) per set and region.

    ``N_l`` and ``N_br`` of the whole system are the means of the configurations' counts,
    those of a sub-system the means of its rows per configuration (so that bulk and
    periphery add up to the whole system); ``n_voids`` (integers, missing for the
    sub-systems: voids have no region) is the set's total. ``N_l_se``, ``N_br_se``,
    ``n_br_se`` and ``l_L_se`` are standard errors (:func:`_se`, :func:`_pooled_se`).
    """
    rows = []
    for s in ens.sets:
        e = ens.subset(s)
        for reg in table_regions(e):
            br, st = _in_region(e.branches, reg), _in_region(e.stacks, reg)
            if reg == "all":
                n_l, n_b = e.configs["N_l"], e.configs["N_br"]
                s_mean = _mean(e.voids["area_L2"])
                sp = _mean(e.voids["shape_ratio"])
            else:  # counts of this sub-system per configuration; voids have no region
                cids = e.configs["config_id"]
                n_l = st.groupby("config_id").size().reindex(cids, fill_value=0)
                n_b = br.groupby("config_id").size().reindex(cids, fill_value=0)
                s_mean = sp = np.nan
            rows.append({"set": s, "region": reg, "n_configs": len(e.configs),
                         "N_l": _mean(n_l), "N_br": _mean(n_b), "n_br": _mean(st["n_br"]),
                         "s_L2": s_mean, "sqrt_s_over_p": sp, "l_L": _mean(br["length_L"]),
                         "n_branches": len(br),
                         # voids are counted for the whole system only
                         "n_voids": len(e.voids) if reg == "all" else None,
                         "N_l_se": _se(n_l), "N_br_se": _se(n_b),
                         "n_br_se": _pooled_se(st["n_br"], st["config_id"]),
                         "l_L_se": _pooled_se(br["length_L"], br["config_id"])})
    out = pd.DataFrame(rows)
    if not out.empty:  # a count: 103, not 103.0, with the sub-systems' cells missing
        out["n_voids"] = out["n_voids"].astype("Int64")
    return out


def _clean(x, positive=True):
    x = np.asarray(x, float)
    keep = np.isfinite(x)
    if positive:
        keep &= x > 0
    return x[keep], keep


def _warn_left_out(ens: Ensemble, quantity: str, values, positive: bool) -> None:
    """One warning giving how many values of ``quantity`` the fits leave out and why (not
    finite, which the means leave out too; <= 0 where the laws fitted live on x > 0, which
    the means keep); none when every value is used."""
    v = np.asarray(values, float)
    n_nan = int(np.sum(~np.isfinite(v)))
    n_low = int(np.sum(np.isfinite(v) & (v <= 0))) if positive else 0
    if not (n_nan or n_low):
        return
    # a mean curvature is NaN on a branch too short to hold one (shorter than one segment of
    # a simulated rod): say so, as the fits then lean to the longer branches
    why = (": branches too short to hold a curvature, shorter than one segment of a simulated "
           "rod, so the fits lean to the longer ones" if quantity.startswith("kappa") else "")
    parts = ([f"{n_nan} not finite (NaN or inf{why}; left out of the means as well)"]
             if n_nan else []) + (
        [f"{n_low} <= 0 (the laws fitted live on x > 0)"] if n_low else [])
    where = f"set {', '.join(map(str, ens.sets))}: " if len(ens.sets) else ""
    warnings.warn(f"{where}{quantity}: {n_nan + n_low} of {v.size} values left out of the "
                  f"fits: {' and '.join(parts)}", QualityWarning, stacklevel=4)


def fit_quantity(ens: Ensemble, quantity: str, region: str, opts: StatsOptions, seed):
    """Fit every family of ``quantity`` in one set and region.

    The branches of one stack of a scan repeat its length, curvature and energy: the fits
    of branch quantities take the stacks as groups
    (:func:`~crosssection.stats.data.branch_groups`), so that their intervals, p-values and
    model selection rest on the independent stacks while the laws stay those of branches.

    Values that are not finite, and values <= 0 of the quantities fitted with laws of
    x > 0 (all of :data:`POSITIVE_QUANTITIES`), are left out, counted in the third element
    and, for the whole system (region ``"all"``; a sub-system's are among them), told in one
    :class:`~crosssection.quality.QualityWarning`. Values that are all equal (zero spread,
    :func:`~crosssection.stats.families.no_spread`) have no law: nothing is fitted, and one
    QualityWarning names the set, region and quantity.

    Returns
    -------
    (FitSummary or None, truncation-bias DataFrame or None, n_nonpositive_dropped)
    """
    table, col, fams, tcol, _ = QUANTITIES[quantity]
    df = _in_region(getattr(ens, table), region)
    if region == "all":
        _warn_left_out(ens, quantity, df[col], quantity in POSITIVE_QUANTITIES)
    x, keep = _clean(df[col], quantity in POSITIVE_QUANTITIES)
    if x.size < opts.min_n:
        return None, None, int((~keep).sum())
    if no_spread(x):
        # no law of a continuous variable puts all its mass at one value: every family
        # would only say "zero spread", and the quantity would leave the fits unnoticed
        where = f"set {', '.join(map(str, ens.sets))}: " if len(ens.sets) else ""
        reg = "" if region in ("all", SIM_REGION) else f" ({region})"
        warnings.warn(f"{where}{quantity}{reg}: zero spread (all {x.size} values equal "
                      f"{float(np.mean(x)):.4g} to a relative {SPREAD_RTOL:g}): no law "
                      f"fitted", QualityWarning, stacklevel=3)
        return None, None, int((~keep).sum())
    cuts = None
    if tcol is not None:
        c = np.asarray(df[tcol], float)[keep]
        if np.all(np.isfinite(c)):
            cuts = c
    groups = branch_groups(df)[keep] if table == "branches" else None
    # the small-sample warnings are given by the callers, once per set (compute_stats) or
    # per figure (plot_pdf), not once per fit
    summ = F._fit_all(x, fams, truncation=cuts, seed=seed, n_boot=opts.n_boot, gof=opts.gof,
                      n_mc=opts.n_mc, select_from=None, ci_level=0.95,
                      discrete=quantity in COUNT_QUANTITIES, warn_small=False, stacklevel=3,
                      groups=groups)
    bias = None
    # with every value below its cut, nothing is left to compare the fits on
    if cuts is not None and np.any(x >= cuts):
        bias = F.truncation_bias(x, cuts, families=tuple(f for f in fams
                                                          if f in ("exponential", "gamma",
                                                                   "lognormal")))
        # the truncation-aware fits are those of ``summ`` (same sample, same cuts): their
        # bootstrap intervals, computed there, fill the table's interval columns
        for i, row in bias.iterrows():
            r = summ.results.get(row["family"]) if summ is not None else None
            if r is not None and r.ci and row["param"] in r.ci:
                bias.loc[i, ["truncated_lo", "truncated_hi"]] = r.ci[row["param"]]
    return summ, bias, int((~keep).sum())


def _n_fittable(ens: Ensemble, quantity: str, region: str) -> int:
    """How many values of ``quantity`` in ``region`` a fit would use (finite, and > 0 for
    the laws of x > 0), as :func:`fit_quantity` counts them."""
    table, col, *_ = QUANTITIES[quantity]
    x, _ = _clean(_in_region(getattr(ens, table), region)[col],
                  quantity in POSITIVE_QUANTITIES)
    return int(x.size)


def fits_columns() -> list:
    """The columns of :attr:`StatsResult.fits`, also when nothing was fitted."""
    return ["set", "region", "quantity", *F.summary_table({}, None).columns, "n_dropped",
            "indicative"]


def _gamma_fit(summ):
    """The Gamma fit of ``summ`` whose parameters the tables take, or None (no summary, no
    Gamma fit, or a degenerate one)."""
    if summ is None or "gamma" not in summ.results or not summ.results["gamma"].selectable:
        return None
    return summ.results["gamma"]


def _gamma_small(summ) -> bool:
    """Whether the Gamma parameters taken from ``summ`` (see :func:`_gamma_params`) rest on
    fewer than :data:`~crosssection.stats.fits.N_SELECT_MIN` independent values (stacks,
    for the branches of scans)."""
    r = _gamma_fit(summ)
    return r is not None and r.n_independent < F.N_SELECT_MIN


def _gamma_params(summ):
    r = _gamma_fit(summ)
    return (np.nan, np.nan) if r is None else (r.params["alpha"], r.params["chi"])


def _gamma_alpha_ci(summ) -> tuple[float, float]:
    """The 95 % interval of the Gamma shape of ``summ`` (the fits table's), NaN without
    one."""
    r = _gamma_fit(summ)
    lo, hi = (np.nan, np.nan) if r is None else r.ci.get("alpha", (np.nan, np.nan))
    return float(lo), float(hi)


def gamma_shape_mle(mean, mean_log):
    """The maximum-likelihood Gamma shape (location 0) of samples with these means of x and
    of log x: the root of ``log a - digamma(a) = log(mean) - mean_log``, from Minka's
    closed-form start and Newton's steps; element-wise over arrays (one shape per pair of
    means). The same shape as ``scipy.stats.gamma.fit(x, floc=0)``, which runs a general
    optimiser: thousands of samples' shapes take milliseconds here."""
    from scipy import special

    s = np.log(np.asarray(mean, float)) - np.asarray(mean_log, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = (3 - s + np.sqrt((s - 3) ** 2 + 24 * s)) / (12 * s)
        for _ in range(6):
            a = a - (np.log(a) - special.digamma(a) - s) / (1 / a - special.polygamma(1, a))
    return np.where(s > 0, a, np.nan)


def dof_ratio_interval(alpha_E, alpha_E_ci, alpha_e, alpha_e_ci) -> tuple[float, float]:
    """An interval of alpha_E / alpha_e from the two shapes' intervals, their distances from
    the shapes added in quadrature on a log scale (the two fits' errors taken as
    independent: E is one value per configuration, the branch energies many).

    alpha_E's interval is the one of its scale-free statistic
    (:func:`crosssection.stats.fits.gamma_shape_interval`), which holds at a handful of
    configurations; the ratio's uncertainty is mostly its. A percentile bootstrap over
    configurations, tried first, kept the upward bias of alpha_E's maximum-likelihood
    estimate over a few dozen values: 59 % coverage at 5 configurations, 90 % at 48
    (``benchmarks/stats_coverage.py``). Where E's errors are those of its own branches' energies
    (E their sum) the two errors go together and the interval is wider than it need be:
    0.99-1.00 coverage at 2 branches per configuration, 0.93-0.97 at 20. A bound a shape's
    interval leaves open (0 or inf) stays open; NaN where either interval is missing.
    """
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        r = alpha_E / alpha_e
        d_lo = np.hypot(np.log(alpha_E / alpha_E_ci[0]), np.log(alpha_e_ci[1] / alpha_e))
        d_hi = np.hypot(np.log(alpha_E_ci[1] / alpha_E), np.log(alpha_e / alpha_e_ci[0]))
        lo, hi = float(r * np.exp(-d_lo)), float(r * np.exp(d_hi))
    return (lo, hi) if not (np.isnan(lo) or np.isnan(hi)) and np.isfinite(r) else (np.nan, np.nan)


def set_seed(seed: int | None, name: str) -> int | None:
    """The seed of one set's bootstrap and goodness of fit, from the run's ``seed`` and the
    set's name alone: a set's intervals then do not depend on which other sets are computed
    with it, nor in which order.

    Parameters
    ----------
    seed : int or None
        The run's seed (None: fresh entropy, and None is returned).
    name : str
        The set's name; a stable hash of it (SHA-256, not Python's salted ``hash``) enters
        ``numpy.random.SeedSequence([seed, hash])``.

    Returns
    -------
    int or None
        An integer in [0, 2**63).
    """
    import hashlib

    if seed is None:
        return None
    digest = int.from_bytes(hashlib.sha256(str(name).encode("utf-8")).digest()[:8], "little")
    state = np.random.SeedSequence([int(seed), digest]).generate_state(1, np.uint64)[0]
    return int(state >> np.uint64(1))


def compute_stats(ens: Ensemble, opts: StatsOptions | None = None, *,
                  progress: bool | None = False) -> StatsResult:
    """Every table of the report.

    Parameters
    ----------
    ens : Ensemble
        Values the fits leave out (not finite, or <= 0, or below the detection limit of a
        truncated fit) are counted in the ``n_dropped`` column of ``fits``; those not finite
        or <= 0 are also told in one warning per set and quantity (:func:`fit_quantity`).
    opts : StatsOptions, optional
    progress : bool or None
        A tqdm bar on stderr over the fits (set, region, quantity: the slow part, bootstrap
        and goodness of fit); None shows it only when stderr is a terminal.

    Returns
    -------
    StatsResult
        Each set's fits draw from their own stream (:func:`set_seed` of ``opts.seed`` and
        the set's name), so a set's intervals are the same computed alone or with others,
        and differ under another set name (renaming a set, or its folder, draws anew).
        A law selected on fewer than :data:`~crosssection.stats.fits.N_SELECT_MIN` values,
        and a relation fitted on fewer than :data:`N_RELATION_MIN` configurations, are kept
        and named in one :class:`~crosssection.stats.fits.SmallSampleWarning` per set; an
        ``n_boot`` from 1 to :data:`~crosssection.stats.fits.N_BOOT_MIN` - 1 gives one too,
        and so do the quantities left unfitted for having fewer than ``opts.min_n`` values
        (one per set, naming them). The ``indicative`` column of ``fits``, ``micro``, ``dof``,
        ``relations`` and ``correlations`` marks the rows resting on fewer values or
        configurations than those minima (for ``correlations``, fewer than
        :data:`N_RELATION_MIN` pairs); in ``micro`` and ``dof``, where a row holds the
        parameters of two Gamma fits, ``indicative_e`` marks those of the fit of e
        (alpha_e, chi_e) and ``indicative_E`` those of the fit of E (alpha_E, chi_E), both
        alpha_E/alpha_e, and ``indicative`` either; ``fits`` and ``truncation`` keep their
        columns when nothing was fitted.

    Raises
    ------
    ParameterError
        ``ens`` is not an :class:`Ensemble` (or has rows without a set name) or ``opts``
        not a valid :class:`StatsOptions`.
    """
    if not isinstance(ens, Ensemble):
        raise ParameterError(f"ens must be an Ensemble (from crosssection.stats.load_any), "
                             f"got {type(ens).__name__}")
    if opts is not None and not isinstance(opts, StatsOptions):
        raise ParameterError(f"opts must be a StatsOptions, got {type(opts).__name__}")
    opts = opts or StatsOptions()
    opts.check()
    for name in ("configs", "branches", "stacks", "voids"):
        # every row belongs to a set: a missing name would be matched against nothing
        df = getattr(ens, name)
        if "set" in df.columns and len(df) and df["set"].isna().any():
            raise ParameterError(f"ens.{name} has {int(df['set'].isna().sum())} row(s) without "
                                 "a set name (column 'set')")
    for name, column in (("branches", "length_L"), ("voids", "area_L2"),
                         ("voids", "perimeter_L")):
        values = np.asarray(getattr(ens, name).get(column, []), float)
        if (values < 0).any():  # as the loaders refuse them in the tables on disk
            raise ParameterError(f"ens.{name}.{column} holds {int((values < 0).sum())} "
                                 "negative value(s): a length or an area is >= 0")
    if F.few_boot_text(opts.n_boot):
        warnings.warn(F.few_boot_text(opts.n_boot), F.SmallSampleWarning, stacklevel=2)
    per_cfg = per_config_table(ens)
    macro = macro_table(ens)
    fit_rows, trunc_rows, summaries, too_few = [], [], {}, {}
    subsets = {s: ens.subset(s) for s in ens.sets}
    jobs, seeds = [], []
    for s in ens.sets:
        own = [(s, reg, q) for reg in regions_of(subsets[s]) for q in opts.quantities
               if not (reg != "all" and QUANTITIES[q][0] in ("configs", "voids"))]
        jobs += own
        # each set its own stream: its intervals do not depend on the other sets
        seeds += np.random.SeedSequence(set_seed(opts.seed, s)).spawn(len(own))
    from tqdm import tqdm

    # disable=None is tqdm's "only on a terminal"
    bar = tqdm(total=len(jobs), desc="stats fits", unit="fit", leave=False,
               disable=None if progress is None else not progress)
    try:
        for (s, reg, q), sd in zip(jobs, seeds):
            bar.set_postfix_str(f"{s} {reg} {q}", refresh=False)
            summ, bias, ndrop = fit_quantity(subsets[s], q, reg, opts, sd)
            bar.update(1)
            if summ is None:
                n_q = _n_fittable(subsets[s], q, reg)
                if n_q < opts.min_n:  # else all values equal, told by fit_quantity
                    too_few.setdefault(s, []).append(f"{_where(q, reg)} n = {n_q}")
                continue
            summaries[(s, reg, q)] = summ
            n_fit = int(summ.table["n"].max()) if len(summ.table) else 0
            if summ.best is None and n_fit < opts.min_n:
                # a detection limit given above most values leaves too few to fit
                too_few.setdefault(s, []).append(
                    f"{_where(q, reg)} n = {n_fit} ({summ.n_dropped + ndrop} below the "
                    "detection limit or not finite)")
            t = summ.table.copy()
            t.insert(0, "quantity", q)
            t.insert(0, "region", reg)
            t.insert(0, "set", s)
            t["n_dropped"] = summ.n_dropped + ndrop
            t["indicative"] = t["n_groups"] < F.N_SELECT_MIN
            fit_rows.append(t)
            if bias is not None:
                bias.insert(0, "quantity", q)
                bias.insert(0, "region", reg)
                bias.insert(0, "set", s)
                trunc_rows.append(bias)
    finally:
        bar.close()
    # with nothing fitted the table keeps its columns: res.fits[res.fits.selected] works
    fits_df = (pd.concat(fit_rows, ignore_index=True) if fit_rows
               else pd.DataFrame(columns=fits_columns()))
    trunc_df = (pd.concat(trunc_rows, ignore_index=True) if trunc_rows
                else pd.DataFrame(columns=["set", "region", "quantity",
                                           *F.TRUNCATION_COLUMNS]))

    micro_rows, dof_rows = [], []
    for s in ens.sets:
        e = subsets[s]
        aE, cE = _gamma_params(summaries.get((s, "all", "E")))
        aE_ci = _gamma_alpha_ci(summaries.get((s, "all", "E")))
        small_E = _gamma_small(summaries.get((s, "all", "E")))
        for reg in table_regions(e):
            br = _in_region(e.branches, reg)
            ae, ce = _gamma_params(summaries.get((s, reg, "e")))
            ae_ci = _gamma_alpha_ci(summaries.get((s, reg, "e")))
            small_e = _gamma_small(summaries.get((s, reg, "e")))
            whole = reg == "all"
            micro_rows.append({
                "set": s, "region": reg, "kappa_m_L": _mean(br["kappa_m_L"]),
                "l_L": _mean(br["length_L"]),
                "E_tilde": _mean(e.configs["E"]) if whole else np.nan,
                "e": _mean(br["e"]), "alpha_e": ae, "chi_e": ce,
                "alpha_E": aE if whole else np.nan,
                "chi_E": cE if whole else np.nan,
                # which values rest on a small fit, as the report marks its cells:
                # alpha_e, chi_e on the e fit; alpha_E, chi_E on the E fit
                "indicative": small_e or (whole and small_E),
                "indicative_e": small_e, "indicative_E": whole and small_E,
                "E_tilde_se": _se(e.configs["E"]) if whole else np.nan,
                "e_se": _pooled_se(br["e"], br["config_id"]),
                "alpha_e_lo": ae_ci[0], "alpha_e_hi": ae_ci[1],
                "alpha_E_lo": aE_ci[0] if whole else np.nan,
                "alpha_E_hi": aE_ci[1] if whole else np.nan})
        e_all = summaries.get((s, "all", "e"))
        small_e = _gamma_small(e_all)
        ae, _ = _gamma_params(e_all)
        ratio_ci = dof_ratio_interval(aE, aE_ci, ae, _gamma_alpha_ci(e_all))
        dof_rows.append({"set": s, "N_l": _mean(e.configs["N_l"]),
                         "N_br": _mean(e.configs["N_br"]), "alpha_E": aE, "alpha_e": ae,
                         "alpha_E_over_alpha_e": aE / ae if ae else np.nan,
                         "indicative": small_E or small_e,
                         "indicative_e": small_e, "indicative_E": small_E,
                         "alpha_E_over_alpha_e_lo": ratio_ci[0],
                         "alpha_E_over_alpha_e_hi": ratio_ci[1]})
    micro = pd.DataFrame(micro_rows)
    dof = pd.DataFrame(dof_rows)
    relations = relations_table(ens, per_cfg, summaries)
    relations["indicative"] = (pd.Series([bool(relation_note(r, n, f)) for r, n, f in zip(
        relations["relation"], relations["n"], relations["fitted"])], dtype=bool,
        index=relations.index) if not relations.empty else pd.Series(dtype=bool))
    _warn_small_samples(summaries, relations, too_few, opts.min_n)
    correlations = correlations_table(ens)
    return StatsResult(macro, micro, dof, fits_df, trunc_df, relations, correlations, per_cfg,
                       summaries)


def slope_through_origin(x, y, what: str = "slope"):
    """Least-squares slope of y = a x and R^2 = 1 - SS_res/SS_tot about the mean of y (negative
    when the line through the origin does worse than the mean), ignoring non-finite pairs.

    x and y are each scaled by a power of two to order one first (exact), so that their
    products and squares neither overflow nor underflow.

    Parameters
    ----------
    x, y : array_like
    what : str
        The relation's name in the warning below.

    Returns
    -------
    (a, r2, n)
        ``a`` is NaN, with a :class:`~crosssection.quality.QualityWarning` naming ``what``,
        when the slope exceeds the floating-point range.
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    k = np.isfinite(x) & np.isfinite(y)
    x, y = x[k], y[k]
    if x.size == 0 or not np.any(x):
        return np.nan, np.nan, int(x.size)
    ex, ey = binary_exponent(x), binary_exponent(y)
    xs, ys = np.ldexp(x, -ex), np.ldexp(y, -ey)
    a_s = float(np.sum(xs * ys) / np.sum(xs * xs))
    ss_res = float(np.sum((ys - a_s * xs) ** 2))
    ss_tot = float(np.sum((ys - ys.mean()) ** 2))
    r2 = (1 - ss_res / ss_tot) if ss_tot > 0 else np.nan
    with np.errstate(over="ignore", under="ignore"):
        a = float(np.ldexp(a_s, ey - ex))
    if not np.isfinite(a) or (a == 0 and a_s != 0):
        warnings.warn(f"{what}: the slope {a_s:.4g} x 2^{ey - ex} lies outside the "
                      f"floating-point range (x and y differ by hundreds of decades): left "
                      f"undefined",
                      QualityWarning, stacklevel=2)
        return np.nan, r2, int(x.size)
    return a, r2, int(x.size)


def _geometric_mean(mu):
    """Mean of the exponential of scale ``mu`` discretised on the integers k >= 1."""
    with np.errstate(all="ignore"):
        return float(1.0 / -np.expm1(-1.0 / mu)) if np.isfinite(mu) and mu > 0 else np.nan


def relations_table(ens: Ensemble, per_cfg: pd.DataFrame, summaries: dict) -> pd.DataFrame:
    """Fitted constants of the paper's Eqs. (12)-(16) per set.

    Rows (relation, fitted, expected):

    - ``eq12_const``: C in N_br = C eps (sqrt(s_bar)/l_bar) sqrt(N_l), expected 2 sqrt(pi/3);
    - ``slope_sqrt_s_vs_l``: sqrt(s_bar) = a l_bar through the origin, paper 1.1;
    - ``eq12_eps_sqrtNl``: K in N_br = K eps sqrt(N_l), expected 2 sqrt(pi/3) x slope;
    - ``eq14_slope``: N_br = a N_l through the origin, expected <n_br>;
    - ``eq15_fluct``: <n_br_bar/<n_br> - 1> (paper: a few percent);
    - ``eq16``: <n_br> sqrt(<N_l>)/<eps>, paper 2.2 sqrt(pi/3);
    - ``n_br_exp_mu``: mean of the exponential law of n_br (fitted as counts: the geometric
      law's mean, = <n_br> at the maximum of the likelihood, so ``expected`` is empty: an
      identity, not a test), with its interval and the selected family.

    The paper's <E> = <N_br><e> is not a row: a configuration's E is the sum of its
    branches' energies, in scans and simulations alike, so it holds by construction.
    """
    rows = []
    for s in ens.sets:
        pc = per_cfg[per_cfg["set"] == s]
        # a configuration without a branch is no point of a relation between branch counts:
        # at (0, 0) it adds to the spread that R^2 measures, not to the fit (a hand-made
        # empty scan took R^2 of eq14_slope from 0.00 to 0.97)
        empty = pc["N_br"].fillna(0).to_numpy(float) <= 0
        if empty.any():
            warnings.warn(f"set {s}: {int(empty.sum())} of {len(pc)} configurations hold no "
                          "branch and are left out of the relations (Eqs. 12-16)",
                          QualityWarning, stacklevel=2)
            pc = pc[~empty]
        e = ens.subset(s)
        nbr_mean = _mean(e.stacks["n_br"])
        c1, r1, n1 = slope_through_origin(pc["eq12_x"], pc["N_br"], f"set {s}: eq12_const")
        a, ra, na = slope_through_origin(pc["l_bar"], pc["sqrt_s_bar"],
                                         f"set {s}: slope_sqrt_s_vs_l")
        k, rk, nk = slope_through_origin(pc["epsilon"] * np.sqrt(pc["N_l"]), pc["N_br"],
                                         f"set {s}: eq12_eps_sqrtNl")
        a3, r3, n3 = slope_through_origin(pc["N_l"], pc["N_br"], f"set {s}: eq14_slope")
        fl = _mean(pc["n_br_bar"] / nbr_mean - 1) if np.isfinite(nbr_mean) else np.nan
        eps_mean = _mean(pc["epsilon"])
        eq16 = (nbr_mean * np.sqrt(_mean(pc["N_l"])) / eps_mean
                if np.isfinite(eps_mean) and eps_mean > 0 else np.nan)
        nsum = summaries.get((s, "all", "n_br"))
        mu = nsum.results["exponential"].params["mu"] if nsum else np.nan
        ci = nsum.results["exponential"].ci.get("mu", (np.nan, np.nan)) if nsum else (np.nan,) * 2
        if nsum and nsum.results["exponential"].discrete:
            # a count fit: the exponential discretised on the integers is the geometric law,
            # whose mean 1/(1 - exp(-1/mu)) (support k >= 1) is the number to compare
            mu, ci = _geometric_mean(mu), tuple(_geometric_mean(v) for v in ci)
        rows += [
            {"set": s, "relation": "eq12_const", "fitted": c1, "expected": EQ12_CONST,
             "r2": r1, "n": n1, "note": "N_br = C eps sqrt(s_bar)/l_bar sqrt(N_l)"},
            {"set": s, "relation": "slope_sqrt_s_vs_l", "fitted": a, "expected": PAPER_SLOPE_S_L,
             "r2": ra, "n": na, "note": "sqrt(s_bar) = a l_bar (paper 1.1)"},
            {"set": s, "relation": "eq12_eps_sqrtNl", "fitted": k,
             "expected": EQ12_CONST * a if np.isfinite(a) else np.nan, "r2": rk, "n": nk,
             "note": "N_br = K eps sqrt(N_l); expected C*a"},
            {"set": s, "relation": "eq14_slope", "fitted": a3, "expected": nbr_mean, "r2": r3,
             "n": n3, "note": "N_br = <n_br> N_l"},
            {"set": s, "relation": "eq15_fluct", "fitted": fl, "expected": 0.0, "r2": np.nan,
             "n": int(pc["n_br_bar"].notna().sum()), "note": "<n_br_bar/<n_br> - 1>"},
            {"set": s, "relation": "eq16", "fitted": eq16, "expected": EQ16_PAPER, "r2": np.nan,
             "n": len(pc), "note": "<n_br> sqrt(<N_l>)/<eps> (paper 2.2 sqrt(pi/3))"},
            # the geometric law's maximum-likelihood mean is the sample mean: no test of
            # the law, whose information is its interval and whether it is selected
            {"set": s, "relation": "n_br_exp_mu", "fitted": mu, "expected": np.nan,
             "r2": np.nan, "n": len(e.stacks),
             "note": (f"CI [{ci[0]:.3g}, {ci[1]:.3g}]; selected: "
                      f"{nsum.best if nsum else 'n/a'}")},
        ]
    return pd.DataFrame(rows)


def _corr(x, y) -> dict:
    """Pearson's r with its 95 % interval (Fisher's z, as scipy gives it) and the p-value of
    r = 0, Spearman's r, and the number of pairs."""
    from scipy import stats

    x, y = np.asarray(x, float), np.asarray(y, float)
    k = np.isfinite(x) & np.isfinite(y)
    out = {"pearson_r": np.nan, "spearman_r": np.nan, "n": int(k.sum()), "pearson_lo": np.nan,
           "pearson_hi": np.nan, "pearson_p": np.nan}
    if k.sum() < CORRELATION_MIN_PAIRS or np.ptp(x[k]) == 0 or np.ptp(y[k]) == 0:
        return out
    res = stats.pearsonr(x[k], y[k])
    out.update(pearson_r=float(res.statistic), spearman_r=float(stats.spearmanr(x[k], y[k])[0]),
               pearson_p=float(res.pvalue))
    if k.sum() > 3:  # Fisher's z has a standard error of 1 / sqrt(n - 3)
        ci = res.confidence_interval(0.95)
        out.update(pearson_lo=float(ci.low), pearson_hi=float(ci.high))
    return out


def correlations_table(ens: Ensemble) -> pd.DataFrame:
    """Pearson (and Spearman) coefficients the paper quotes, per set and region.

    Returns
    -------
    DataFrame
        set, region, pair, pearson_r, spearman_r, n (pairs of values), paper, pearson_lo and
        pearson_hi (95 % interval of r, Fisher's z, from 4 pairs), pearson_p (p-value of
        r = 0), and ``indicative``: a coefficient of fewer than :data:`N_RELATION_MIN`
        pairs, as a relation fitted on fewer configurations (three points give r = 1 or
        near it).
    """
    rows = []
    for s in ens.sets:
        e = ens.subset(s)
        for reg in regions_of(e):
            br = _in_region(e.branches, reg)
            km = np.asarray(br["kappa_m_L"], float)
            inv = np.where(km > 0, 1 / np.where(km > 0, km, 1), np.nan)
            for pair, (x, y) in {
                    "l_vs_inv_kappa_m": (br["length_L"], inv),
                    "e_vs_l_kappa_m2": (br["e"], br["length_L"] * km ** 2)}.items():
                rows.append({"set": s, "region": reg, "pair": pair, **_corr(x, y),
                             "paper": PAPER_CORR[pair]})
        rows.append({"set": s, "region": "all", "pair": "E_vs_N_br",
                     **_corr(e.configs["E"], e.configs["N_br"]),
                     "paper": PAPER_CORR["E_vs_N_br"]})
    out = pd.DataFrame(rows, columns=["set", "region", "pair", "pearson_r", "spearman_r", "n",
                                      "paper", "pearson_lo", "pearson_hi", "pearson_p"])
    out["indicative"] = ((out["n"] < N_RELATION_MIN)
                         & np.isfinite(out["pearson_r"].astype(float))).astype(bool)
    return out


def count_text(v) -> str:
    """A cell of a count column (:data:`COUNT_COLUMNS`) as text: an integer exactly (1906,
    not 1.91e+03), "" where missing, anything else (a note) as it is.

    Parameters
    ----------
    v : object
        The cell.

    Returns
    -------
    str
    """
    if v is None or v is pd.NA:
        return ""
    if isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            return ""
        return str(int(v)) if float(v).is_integer() else format(float(v), ".4g")
    return str(v)


def to_markdown(df: pd.DataFrame, floatfmt: str = ".4g") -> str:
    """A GitHub-flavoured Markdown table (no extra dependency); the counts
    (:data:`COUNT_COLUMNS`) exactly, other numbers to ``floatfmt``."""
    def fmt(v, col):
        if col in COUNT_COLUMNS:
            return count_text(v).replace("|", "\\|")
        if v is None or v is pd.NA:
            return ""
        if isinstance(v, (float, np.floating)):
            return "" if not np.isfinite(v) else format(float(v), floatfmt)
        return str(v).replace("|", "\\|")
    head = "| " + " | ".join(map(str, df.columns)) + " |"
    sep = "|" + "|".join("---" for _ in df.columns) + "|"
    body = ["| " + " | ".join(fmt(v, c) for v, c in zip(row, df.columns)) + " |"
            for row in df.itertuples(index=False)]
    return "\n".join([head, sep, *body]) + "\n"
