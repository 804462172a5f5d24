"""Maximum-likelihood fits of the paper's laws, with detection-limit truncation.

The families (exponential, Gamma, log-normal, Gaussian, Bose-Einstein, power law with
exponential cutoff) are the classes of :mod:`crosssection.stats.families`, registered in
:data:`FAMILIES` by name. This module fits any of them the same way: MLE, percentile
bootstrap intervals, an Anderson-Darling goodness of fit with a parametric-bootstrap p-value,
and model selection.

Detection limits (paper "Statistical distributions in the folding of elastic structures",
Adda-Bedia, Boudaoud, Boué, Deboeuf; note on <l> against mu): an observation below the cut c
is never seen, so the likelihood of an observed x >= c is f(x)/S(c), S the survival function.
``c`` may be a scalar or one cut per observation (images of different rod lengths L have
different l_min/L).

Degenerate fits: a fit whose parameters sit at a bound of their domain or far outside the data
(a Gaussian whose mean lies hundreds of standard deviations below the cut, a Bose-Einstein law
with beta x << 1 everywhere) describes no law of the data; it keeps its row, with the reason in
``rejected``, but is never selected and carries no interval nor p-value.

Model selection: the min-BIC family among the non-degenerate fits, except that a family with
fewer parameters whose BIC is within ``DELTA_BIC_SIMPLER`` = 2 of the minimum is preferred
("the simplest law the data support": a BIC difference below 2 is "not worth more than a bare
mention", Kass & Raftery 1995). Ties in parameter count go to the lower BIC.

Counts (the number of branches per stack n_br, an integer >= 1) are fitted as counts
(``discrete=True``): observation k stands for the interval [k - 1/2, k + 1/2] of the continuous
law, which is normalised on [1/2, inf), so P(k) = [S(k - 1/2) - S(k + 1/2)] / S(1/2). A
continuous density fitted to the integers themselves is ill-posed (the likelihood rewards
spikes at the integers) and its curve cannot be compared with the fraction of stacks at each
k. The discretised exponential is the geometric law. The goodness of fit of counts uses the
likelihood-ratio statistic G = 2 sum_k c_k ln(c_k / (n P_k)) instead of Anderson-Darling
(which needs a continuous law), with the same parametric bootstrap and refits.

Bootstrap replicates of the parameters are kept in :attr:`FitResult.boot` so that figures can
draw a confidence band of the fitted density without refitting.

P-values come from n Monte-Carlo resamples, so the smallest one is 1/(n + 1); a p-value at that
floor only says p < 1/(n + 1) and is printed so (:meth:`FitResult.p_text`).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
from scipy import optimize, stats

from crosssection.core.errors import ParameterError
from crosssection.stats.families import FAMILIES

DELTA_BIC_SIMPLER = 2.0
PAPER_FAMILIES = ("exponential", "gamma", "lognormal", "gaussian", "bose_einstein")
MAX_PARAMS = max(len(f.param_names) for f in FAMILIES.values())
#: counts start at 1: the discretised law lives on [COUNT_MIN - 1/2, inf)
COUNT_MIN = 1


def _seedseq(seed) -> np.random.SeedSequence:
    """A SeedSequence from an int, None or an existing SeedSequence."""
    return seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)


def _as_cuts(truncation, n):
    if truncation is None:
        return None
    c = np.asarray(truncation, dtype=float)
    if c.ndim == 0:
        return np.full(n, float(c))
    if c.shape != (n,):
        raise ParameterError(f"truncation has shape {c.shape}, expected a scalar or ({n},)")
    return c


def _family(name: str):
    try:
        return FAMILIES[name]
    except KeyError:
        raise ParameterError(f"unknown family {name!r}; choose from {tuple(FAMILIES)}") from None


def anderson_darling(u) -> float:
    """Anderson-Darling statistic of PIT values ``u`` against the uniform law."""
    u = np.clip(np.sort(np.asarray(u, float)), 1e-300, 1 - 1e-16)
    n = u.size
    i = np.arange(1, n + 1)
    return float(-n - np.mean((2 * i - 1) * (np.log(u) + np.log1p(-u[::-1]))))


# ------------------------------------------------------------------ results
@dataclass(frozen=True)
class FitResult:
    """One fitted family.

    Attributes
    ----------
    family : str
    params : dict
        Every parameter of the family in the paper's notation (``param_names`` of the
        family, e.g. alpha, beta, x_lo, x_hi for Bose-Einstein).
    loglik, aic, bic : float
    n : int
        Number of observations used.
    k : int
        Number of parameters counted in AIC/BIC.
    ci : dict
        Parameter name -> (low, high) percentile bootstrap interval (``ci_level``).
    pvalue : float
        Goodness-of-fit p-value (Anderson-Darling, parametric bootstrap with refits), NaN if
        not computed.
    statistic : float
        Anderson-Darling statistic of the data (the G statistic for count fits).
    truncated : bool
        Whether the likelihood was truncated at the detection limit.
    ok : bool
        False when the family does not apply (e.g. non-positive data for a positive law).
    note : str
        Why the family does not apply.
    n_mc : int
        Monte-Carlo resamples behind ``pvalue`` (0: none); the smallest p-value is
        1/(n_mc + 1).
    rejected : str
        Why the fit is degenerate ("" when it is not); a rejected fit is never selected.
    discrete : bool
        Whether the law was fitted to counts (see the module docstring); its probability
        masses are :meth:`pmf`.
    boot : numpy.ndarray or None
        Bootstrap replicates of the parameters, shape (n_boot, len(param_names)), rows that
        could not be refitted are NaN; None without bootstrap. Not compared nor printed.
    """

    family: str
    params: dict
    loglik: float
    aic: float
    bic: float
    n: int
    k: int
    ci: dict = field(default_factory=dict)
    pvalue: float = float("nan")
    statistic: float = float("nan")
    truncated: bool = False
    ok: bool = True
    note: str = ""
    n_mc: int = 0
    rejected: str = ""
    discrete: bool = False
    boot: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def selectable(self) -> bool:
        """Whether the fit may be named as the law of the data."""
        return self.ok and not self.rejected and bool(np.isfinite(self.bic))

    def label(self, digits: int = 3) -> str:
        """Short text with every parameter, such as ``gamma alpha=0.31 chi=728``."""
        ps = " ".join(f"{k}={self.params[k]:.{digits}g}"
                      for k in FAMILIES[self.family].param_names if k in self.params)
        return f"{self.family} {ps}"

    def p_text(self) -> str:
        """The p-value as printed: ``p < 1/200`` at the Monte-Carlo floor, else
        ``p = 0.035``; "" when there is none."""
        if not np.isfinite(self.pvalue) or self.n_mc <= 0:
            return ""
        floor = 1.0 / (self.n_mc + 1)
        if self.pvalue <= floor * (1 + 1e-9):
            return f"p < 1/{self.n_mc + 1}"
        return f"p = {self.pvalue:.2g}"

    def pdf(self, x):
        """Density of the fitted law (untruncated shape; Bose-Einstein and the power law are
        zero outside their range)."""
        return FAMILIES[self.family].pdf(self.params, np.asarray(x, float))

    def pmf(self, k, params: dict | None = None):
        """Probability of each integer ``k`` >= :data:`COUNT_MIN` under the law discretised
        on [k - 1/2, k + 1/2] and normalised over the counts (``params`` overrides the
        fitted parameters, e.g. with a bootstrap replicate)."""
        return count_pmf(self.family, self.params if params is None else params, k)

    def replicates(self):
        """The bootstrap replicates as parameter dicts (empty without bootstrap)."""
        if self.boot is None:
            return []
        names = FAMILIES[self.family].param_names
        return [dict(zip(names, map(float, row))) for row in self.boot
                if np.all(np.isfinite(row))]


def count_pmf(family: str, params: dict, k):
    """P(k) = [S(k - 1/2) - S(k + 1/2)] / S(COUNT_MIN - 1/2) of a continuous family.

    Parameters
    ----------
    family : str
    params : dict
    k : array_like
        Integers (those below :data:`COUNT_MIN` get 0).

    Returns
    -------
    numpy.ndarray
    """
    fam = _family(family)
    k = np.asarray(k, float)
    with np.errstate(all="ignore"):
        norm = fam.sf(params, COUNT_MIN - 0.5)
        p = (fam.sf(params, k - 0.5) - fam.sf(params, k + 0.5)) / norm
    return np.where(k >= COUNT_MIN, p, 0.0)


def _count_logp(fam, theta, ks):
    """log P(k) of the discretised law from the family's log survival function (scipy.special,
    no frozen distributions: the bootstrap and the goodness of fit refit hundreds of times)."""
    lo = fam.logsf_theta(theta, ks - 0.5)
    hi = fam.logsf_theta(theta, ks + 0.5)
    ln = fam.logsf_theta(theta, np.array([COUNT_MIN - 0.5]))[0]
    with np.errstate(all="ignore"):
        return lo + np.log(-np.expm1(hi - lo)) - ln


def _fit_counts(fam, x, theta0=None):
    """MLE ``(theta, loglik)`` of the discretised law on counts ``x``.

    The exponential is the geometric law in closed form (q = exp(-1/mu) = 1 - 1/(<k> - k0 + 1),
    k0 = COUNT_MIN); the others by Nelder-Mead on the free parameters, positive ones on a log
    scale, started at ``theta0`` or at the continuous fit.
    """
    ks, cnt = np.unique(np.round(x), return_counts=True)
    if fam.name == "exponential":
        m = float(np.mean(x)) - COUNT_MIN + 1
        mu = -1.0 / np.log1p(-1.0 / m) if m > 1 else 0.0
        ll = (float(np.sum(cnt * _count_logp(fam, (mu,), ks))) if mu > 0 else 0.0)
        return (float(mu),), ll
    logp = np.asarray(fam.log_params, bool)
    th0 = np.asarray(theta0 if theta0 is not None else fam.fit(x)[0], float)
    z0 = np.where(logp, np.log(np.abs(th0)), th0)

    def nll(z):
        lp = _count_logp(fam, np.where(logp, np.exp(z), z), ks)
        v = -float(np.sum(cnt * lp))
        return v if np.isfinite(v) else 1e300

    res = optimize.minimize(nll, z0, method="Nelder-Mead",
                            options={"xatol": 1e-5, "fatol": 1e-7, "maxiter": 1000})
    th = np.where(logp, np.exp(res.x), res.x)
    return tuple(map(float, th)), float(-res.fun)


def _g_statistic(p, ks, cnt) -> float:
    """Likelihood-ratio statistic of counts ``cnt`` at ``ks`` against masses ``p``."""
    n = cnt.sum()
    with np.errstate(all="ignore"):
        g = 2.0 * np.sum(cnt * np.log(cnt / (n * p)))
    return float(g) if np.isfinite(g) else np.inf


def _gof_counts(x, fam, params, n_mc, rng) -> "GoodnessOfFit":
    """Parametric-bootstrap p-value of the G statistic of a count fit (refit per sample)."""
    ks, cnt = np.unique(np.round(x), return_counts=True)
    stat0 = _g_statistic(count_pmf(fam.name, params, ks), ks, cnt)
    theta_hat = fam.theta(params)
    cut = np.full(x.size, COUNT_MIN - 0.5)
    null = np.full(n_mc, np.nan)
    for i in range(n_mc):
        # rounding a draw of the law truncated at 1/2 is a draw of the discretised law
        xs = np.round(fam.sample(params, x.size, cut, rng))
        if not np.all(np.isfinite(xs)) or np.ptp(xs) <= 0:
            continue
        th, _ = _fit_counts(fam, xs, theta_hat)
        kb, cb = np.unique(xs, return_counts=True)
        null[i] = _g_statistic(count_pmf(fam.name, fam.params(th, xs), kb), kb, cb)
    null = null[np.isfinite(null)]
    if null.size == 0:
        return GoodnessOfFit(stat0, float("nan"), 0)
    return GoodnessOfFit(stat0, float((np.sum(null >= stat0) + 1) / (null.size + 1)),
                         int(null.size))


@dataclass(frozen=True)
class FitSummary:
    """All families fitted to one sample.

    Attributes
    ----------
    results : dict
        family -> :class:`FitResult`.
    best : str or None
        Selected family (see module docstring for the rule).
    table : pandas.DataFrame
        One row per family (see :func:`summary_table`).
    n_dropped : int
        Observations below the cut (or non-finite) that were discarded.
    """

    results: dict
    best: str | None
    table: pd.DataFrame
    n_dropped: int = 0


@dataclass(frozen=True)
class GoodnessOfFit:
    """Anderson-Darling statistic, its p-value and the resamples behind it."""

    statistic: float
    pvalue: float
    n_mc: int


def _applicability(fam, x, c, k) -> str:
    """Why ``fam`` cannot be fitted to ``x`` ("" when it can)."""
    n = x.size
    if n < max(3, k + 1):
        return f"too few observations ({n})"
    if fam.positive and np.any(x <= 0):
        return "needs x > 0"
    if c is not None and np.any(x < c):
        raise ParameterError("observations below the truncation cut; drop them first")
    if fam.needs_spread and np.ptp(x) <= 0:
        return "zero spread"
    return ""


def fit_family(x, family: str, *, truncation=None, n_boot: int = 200, seed=0,
               gof: bool = True, n_mc: int = 199, ci_level: float = 0.95,
               discrete: bool = False) -> FitResult:
    """Maximum-likelihood fit of one family, with bootstrap intervals and a GOF p-value.

    Parameters
    ----------
    x : array_like
        Observations (finite). For a truncated fit, all must be >= their cut.
    family : str
        A key of :data:`FAMILIES`.
    truncation : float or array_like, optional
        Detection limit: observations below it are never seen. Scalar or one per observation.
    n_boot : int
        Bootstrap resamples for the percentile intervals (0: no intervals).
    seed : int or numpy.random.SeedSequence
        Seed of every random choice (bootstrap, goodness of fit).
    gof : bool
        Compute the goodness-of-fit p-value.
    n_mc : int
        Parametric-bootstrap samples for the p-value (99 is a fast option).
    ci_level : float
        Coverage of the percentile intervals.
    discrete : bool
        ``x`` are counts >= :data:`COUNT_MIN`: fit the discretised law (module docstring);
        only the families backed by ``scipy.stats`` and no truncation.

    Returns
    -------
    FitResult
        Degenerate fits (see the module docstring) carry the reason in ``rejected`` and
        neither intervals nor p-value.
    """
    fam = _family(family)
    x = np.asarray(x, float)
    n = x.size
    c = _as_cuts(truncation, n)
    truncated = c is not None
    k = fam.k(truncated)
    why = _applicability(fam, x, c, k)
    if not why and discrete:
        if truncated or getattr(fam, "frozen", None) is None:
            why = "no count (discrete) fit of this family"
        elif np.any(x < COUNT_MIN) or np.any(x != np.round(x)):
            why = f"counts must be integers >= {COUNT_MIN}"
    if why:
        return FitResult(family, {p: float("nan") for p in fam.param_names}, float("nan"),
                         float("nan"), float("nan"), n, k, truncated=truncated, ok=False,
                         note=why, discrete=discrete)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        theta, ll = _fit_counts(fam, x) if discrete else fam.fit(x, c)
        params = fam.params(theta, x, c)
        res = FitResult(family, params, float(ll), float(2 * k - 2 * ll),
                        float(k * np.log(n) - 2 * ll), n, k, truncated=truncated,
                        discrete=discrete)
        if not all(np.isfinite(v) for v in params.values()):
            return replace(res, rejected="the fit did not converge (non-finite parameter)")
        rejected = fam.degeneracy(params, x, c)
        if rejected:
            return replace(res, rejected=rejected)
        s_boot, s_gof = _seedseq(seed).spawn(2)
        draws = (bootstrap_draws(x, family, truncation=c, n_boot=n_boot, seed=s_boot,
                                 discrete=discrete) if n_boot else None)
        ci = _percentile_ci(draws, fam.param_names, ci_level) if n_boot else {}
        if not gof:
            g = GoodnessOfFit(float("nan"), float("nan"), 0)
        elif discrete:
            g = _gof_counts(x, fam, params, n_mc, np.random.default_rng(s_gof))
        else:
            g = goodness_of_fit(x, family, params, truncation=c, n_mc=n_mc, seed=s_gof)
    return replace(res, ci=ci, pvalue=g.pvalue, statistic=g.statistic, n_mc=g.n_mc,
                   boot=draws)


def bootstrap_draws(x, family: str, *, truncation=None, n_boot: int = 200, seed=0,
                    discrete: bool = False) -> np.ndarray:
    """Bootstrap replicates of every parameter of a family (refits of resampled data).

    Parameters
    ----------
    x : array_like
    family : str
    truncation : float or array_like, optional
        Cuts move with their observations when resampling.
    n_boot : int
    seed : int or SeedSequence
    discrete : bool
        Refit as counts (see :func:`fit_family`).

    Returns
    -------
    numpy.ndarray
        Shape (n_boot, len(param_names)); NaN rows where a resample could not be refitted.
    """
    fam = _family(family)
    x = np.asarray(x, float)
    c = _as_cuts(truncation, x.size)
    rng = np.random.default_rng(seed)
    names = fam.param_names
    draws = np.full((n_boot, len(names)), np.nan)
    # warm start of the numerical refits
    theta_hat = _fit_counts(fam, x)[0] if discrete else fam.fit(x, c)[0]
    for b in range(n_boot):
        idx = rng.integers(0, x.size, x.size)
        xb = x[idx]
        cb = None if c is None else c[idx]
        if np.ptp(xb) <= 0:
            continue
        try:
            th, _ = _fit_counts(fam, xb, theta_hat) if discrete else fam.fit(xb, cb, theta_hat)
        except (ValueError, FloatingPointError, RuntimeError):
            continue
        p = fam.params(th, xb, cb)
        draws[b] = [p[nm] for nm in names]
    return draws


def _percentile_ci(draws, names, level) -> dict:
    q = (1 - level) / 2
    out = {}
    for j, nm in enumerate(names):
        d = draws[:, j][np.isfinite(draws[:, j])]
        out[nm] = ((float(np.quantile(d, q)), float(np.quantile(d, 1 - q))) if d.size
                   else (float("nan"), float("nan")))
    return out


def bootstrap_ci(x, family: str, *, truncation=None, n_boot: int = 200, seed=0,
                 level: float = 0.95, discrete: bool = False) -> dict:
    """Percentile bootstrap intervals of every parameter of a family.

    Parameters
    ----------
    x : array_like
    family : str
    truncation : float or array_like, optional
        Cuts move with their observations when resampling.
    n_boot : int
    seed : int or SeedSequence
    level : float
    discrete : bool
        Refit as counts (see :func:`fit_family`).

    Returns
    -------
    dict
        Parameter name -> (low, high).
    """
    draws = bootstrap_draws(x, family, truncation=truncation, n_boot=n_boot, seed=seed,
                            discrete=discrete)
    return _percentile_ci(draws, _family(family).param_names, level)


def goodness_of_fit(x, family: str, params: dict, *, truncation=None, n_mc: int = 199,
                    seed=0) -> GoodnessOfFit:
    """Anderson-Darling goodness of fit with a p-value that accounts for fitted parameters.

    Untruncated fits of the families backed by ``scipy.stats`` (exponential, Gamma,
    log-normal, Gaussian) use ``scipy.stats.goodness_of_fit`` (parametric bootstrap,
    parameters refitted on every sample, loc fixed at 0 for the positive laws). Truncated fits
    and the other families use the same procedure written here: samples drawn from the fitted
    (truncated) law with the same cuts, refitted, and the statistic computed on the
    probability integral transform.

    Parameters
    ----------
    x : array_like
    family : str
    params : dict
        The fitted parameters of ``x``.
    truncation : float or array_like, optional
    n_mc : int
        Monte Carlo samples (the p-value resolution is 1/(n_mc + 1)).
    seed : int or SeedSequence

    Returns
    -------
    GoodnessOfFit
        ``n_mc`` there counts the resamples that could be refitted.
    """
    fam = _family(family)
    x = np.asarray(x, float)
    c = _as_cuts(truncation, x.size)
    rng = np.random.default_rng(seed)
    if c is None and getattr(fam, "rv", None) is not None:
        res = stats.goodness_of_fit(fam.rv, x, known_params=fam.known, statistic="ad",
                                    n_mc_samples=n_mc, random_state=rng)
        return GoodnessOfFit(float(res.statistic), float(res.pvalue), n_mc)
    stat0 = anderson_darling(fam.pit(params, x, c))
    theta_hat = fam.theta(params)
    null = np.full(n_mc, np.nan)
    for i in range(n_mc):
        xs = fam.sample(params, x.size, c, rng)
        if not np.all(np.isfinite(xs)):
            continue
        try:
            th, _ = fam.fit(xs, c, theta_hat)
        except (ValueError, FloatingPointError, RuntimeError):
            continue
        null[i] = anderson_darling(fam.pit(fam.params(th, xs, c), xs, c))
    null = null[np.isfinite(null)]
    if null.size == 0:
        return GoodnessOfFit(stat0, float("nan"), 0)
    return GoodnessOfFit(stat0, float((np.sum(null >= stat0) + 1) / (null.size + 1)),
                         int(null.size))


def select_model(results: dict, *, delta: float = DELTA_BIC_SIMPLER) -> str | None:
    """The simplest family the data support.

    The family of minimum BIC among the selectable (applicable, non-degenerate) fits, unless
    a family with fewer parameters has BIC - BIC_min < ``delta``; among those the fewest
    parameters win, then the lower BIC.

    Parameters
    ----------
    results : dict
        family -> FitResult.
    delta : float

    Returns
    -------
    str or None
    """
    ok = {f: r for f, r in results.items() if r.selectable}
    if not ok:
        return None
    bmin = min(r.bic for r in ok.values())
    cands = [r for r in ok.values() if r.bic - bmin < delta]
    return min(cands, key=lambda r: (r.k, r.bic)).family


def fit_all(x, families=PAPER_FAMILIES, *, truncation=None, seed=0, n_boot: int = 200,
            gof: bool = True, n_mc: int = 199, select_from=None,
            ci_level: float = 0.95, discrete: bool = False) -> FitSummary:
    """Fit several families to one sample and select the simplest supported law.

    Parameters
    ----------
    x : array_like
        Observations; non-finite values are dropped, and with a truncation the observations
        below their cut are dropped (counted in ``n_dropped``).
    families : sequence of str
        Keys of :data:`FAMILIES` (default: the paper's five laws).
    truncation : float or array_like, optional
        Detection limit (scalar or one per observation).
    seed : int
    n_boot, gof, n_mc, ci_level
        See :func:`fit_family`.
    select_from : sequence of str, optional
        Families taking part in model selection (default: all fitted).
    discrete : bool
        The observations are counts (see :func:`fit_family`).

    Returns
    -------
    FitSummary
    """
    families = tuple(families)
    for f in families:
        _family(f)
    x = np.asarray(x, float)
    c = _as_cuts(truncation, x.size)
    keep = np.isfinite(x)
    if c is not None:
        keep &= np.isfinite(c) & (x >= np.where(np.isfinite(c), c, -np.inf))
    n_dropped = int(x.size - keep.sum())
    x = x[keep]
    c = None if c is None else c[keep]
    seeds = _seedseq(seed).spawn(len(families))
    results = {f: fit_family(x, f, truncation=c, n_boot=n_boot, seed=s, gof=gof, n_mc=n_mc,
                             ci_level=ci_level, discrete=discrete)
               for f, s in zip(families, seeds)}
    sel = {f: results[f] for f in (select_from or families) if f in results}
    best = select_model(sel)
    return FitSummary(results, best, summary_table(results, best), n_dropped)


def summary_table(results: dict, best: str | None) -> pd.DataFrame:
    """One row per family.

    Columns: family, n, k, truncated, counts (fitted as a law on the integers);
    p1_name, p1, p1_lo, p1_hi, ... for every parameter
    (up to :data:`MAX_PARAMS`); loglik, aic, bic, delta_bic (to the best selectable fit),
    ad_statistic, pvalue, n_mc, p_text, selected, rejected, note.
    """
    rows = []
    finite = [r.bic for r in results.values() if r.selectable]
    bmin = min(finite) if finite else np.nan
    for f, r in results.items():
        row = {"family": f, "n": r.n, "k": r.k, "truncated": r.truncated,
               "counts": bool(r.discrete)}
        for i, nm in enumerate(FAMILIES[f].param_names, 1):
            lo, hi = r.ci.get(nm, (np.nan, np.nan))
            row.update({f"p{i}_name": nm, f"p{i}": r.params.get(nm, np.nan),
                        f"p{i}_lo": lo, f"p{i}_hi": hi})
        row.update({"loglik": r.loglik, "aic": r.aic, "bic": r.bic,
                    "delta_bic": r.bic - bmin, "ad_statistic": r.statistic,
                    "pvalue": r.pvalue, "n_mc": r.n_mc, "p_text": r.p_text(),
                    "selected": f == best, "rejected": r.rejected, "note": r.note})
        rows.append(row)
    pcols = [f"p{i}{s}" for i in range(1, MAX_PARAMS + 1) for s in ("_name", "", "_lo", "_hi")]
    cols = ["family", "n", "k", "truncated", "counts", *pcols, "loglik", "aic", "bic", "delta_bic",
            "ad_statistic", "pvalue", "n_mc", "p_text", "selected", "rejected", "note"]
    return pd.DataFrame(rows).reindex(columns=cols)


def truncation_bias(x, truncation, families=("exponential", "gamma", "lognormal"), *,
                    n_boot: int = 0, seed=0) -> pd.DataFrame:
    """Naive against truncation-aware fits of the same sample, side by side.

    Parameters
    ----------
    x : array_like
        Observations (those below their cut are dropped first).
    truncation : float or array_like
        Detection limit.
    families : sequence of str
    n_boot : int
        Bootstrap resamples for intervals of the truncated fit (0: none).
    seed : int

    Returns
    -------
    pandas.DataFrame
        Columns family, param, naive, truncated, naive_bias_rel = naive/truncated - 1
        (the relative bias a naive fit would have had), and for the exponential the paper's
        check mean(x) - mean(cut) which equals mu exactly.
    """
    x = np.asarray(x, float)
    c = _as_cuts(truncation, x.size)
    keep = np.isfinite(x) & (x >= c)
    x, c = x[keep], c[keep]
    rows = []
    seeds = _seedseq(seed).spawn(len(families))
    for f, s in zip(families, seeds):
        rn = fit_family(x, f, n_boot=0, gof=False)
        rt = fit_family(x, f, truncation=c, n_boot=n_boot, gof=False, seed=s)
        for nm in FAMILIES[f].param_names:
            a, b = rn.params[nm], rt.params[nm]
            lo, hi = rt.ci.get(nm, (np.nan, np.nan))
            rows.append({"family": f, "param": nm, "naive": a, "truncated": b,
                         "truncated_lo": lo, "truncated_hi": hi,
                         "naive_bias_rel": a / b - 1 if b else np.nan, "n": x.size,
                         "cut_mean": float(np.mean(c)),
                         "mean_minus_cut": (float(np.mean(x) - np.mean(c))
                                            if f == "exponential" else np.nan)})
    return pd.DataFrame(rows)
