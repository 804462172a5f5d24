"""The ``fits`` sweep of the validation atlas: how many samples each law needs before the
statistics module's model selection is stable, whether its bootstrap intervals cover the
truth, and how far naive fits drift under the detection limits l_min and s_min.

Paper: "Statistical distributions in the folding of elastic structures" (Adda-Bedia, Boudaoud,
Boué, Deboeuf). Every sample is drawn from a known law with the paper's parameters and fitted
by the project's own code, exactly as ``python -m crosssection stats`` fits that quantity
(:data:`crosssection.stats.tables.QUANTITIES`: the candidate families, truncation-aware where
the pipeline has a detection limit, counts fitted as counts):

- **sample size** (``fits_sample_size.csv``, one row per case, n and repetition): n = 20-2000
  draws, :func:`crosssection.stats.fits.fit_all` over the quantity's candidates; the selected
  family (the module's rule: minimum BIC, a simpler law preferred within 2), the minimum-AIC
  and minimum-BIC families, the BIC gap of the true family to the best, the fitted parameter
  of the true family and (on the first ``ci_reps`` repetitions) its percentile-bootstrap 95 %
  interval (:func:`crosssection.stats.fits.fit_family`);
- **truncation** (``fits_truncation.csv``, one row per case, cut and repetition): n draws of
  the law truncated at a cut c (c / <x> = 0-0.5, <x> the mean of the untruncated law), fitted
  naively (the cut ignored) and truncation-aware (likelihood f(x)/S(c), the pipeline's fit
  above l_min and s_min), with the selection of both ways.

Summaries per point (``fits_sample_size_summary.csv``, ``fits_truncation_summary.csv``), three
charts and a reading (:func:`reading`) go beside them, in ``REPORT/fits/``. Every random choice
derives from the seed, the case name, n (or the cut) and the repetition, so a point does not
depend on the worker count or on the other points.
"""
from __future__ import annotations

import math
import time
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.errors import ParameterError
from crosssection.core.fileio import save_figure, write_csv, write_text

__all__ = ["Case", "CASES", "TRUNCATION_CASES", "SAMPLE_SIZE_CASES", "FitsConfig", "SWEEP",
           "sample_size_rows", "truncation_rows", "summarize_sample_size",
           "summarize_truncation", "stable_n", "stability_table", "run_fits",
           "write_fits_report", "redraw", "reading", "index_section", "draw_case", "law_mean"]

SWEEP = "fits"  # the name of this sweep in ``python -m simulate benchmark --sweeps``
STABLE_RATE = 0.9  # selection is "stable" from the n where it picks the true law this often
SUBDIR = "fits"

# the paper's experiments (table of experimental parameters, set 2 unless said): rod length L,
# detection limits l_min = 1 mm (branches) and s_min (voids; the pipeline's default 1 mm^2)
L_SET2_MM = 1900.0
L_MIN_MM = 1.0
S_MIN_MM2 = 1.0


@dataclass(frozen=True)
class Case:
    """A quantity of the paper with a known law.

    Attributes
    ----------
    name : str
        Key (seeds and tables).
    title : str
        Name in words.
    quantity : str
        Key of :data:`crosssection.stats.tables.QUANTITIES` (the candidate families).
    family : str
        The true family (a key of :data:`crosssection.stats.families.FAMILIES`).
    params : tuple of (str, float)
        Its parameters (every ``param_names`` entry).
    param : str
        The parameter whose bias and interval coverage are tracked (the shape where there is
        one).
    cut : float
        Detection limit in the quantity's units (0: none); the sample-size sweep draws the law
        truncated there and fits truncation-aware, as the pipeline does for scans.
    source : str
        Where the parameters come from.
    """

    name: str
    title: str
    quantity: str
    family: str
    params: tuple
    param: str
    cut: float = 0.0
    source: str = ""

    @property
    def law(self) -> dict:
        return dict(self.params)

    @property
    def candidates(self) -> tuple:
        from crosssection.stats.tables import QUANTITIES

        return tuple(QUANTITIES[self.quantity][2])

    @property
    def discrete(self) -> bool:
        from crosssection.stats.tables import COUNT_QUANTITIES

        return self.quantity in COUNT_QUANTITIES

    @property
    def positive(self) -> bool:
        from crosssection.stats.tables import POSITIVE_QUANTITIES

        return self.quantity in POSITIVE_QUANTITIES

    @property
    def truth(self) -> float:
        return float(self.law[self.param])


_AREA_SET2_L2 = 1.4e-5  # <s>/L^2, paper set 2
_SIGMA_AREA = 1.0  # not given by the paper: an assumption (the statistics demo's value)

CASES = {c.name: c for c in (
    Case("e_sim", "branch energy e (simulations)", "e", "gamma",
         (("alpha", 0.31), ("chi", 728.0)), "alpha",
         source="paper, simulations: Gamma, alpha = 0.31, chi = 728"),
    Case("e_exp", "branch energy e (experiments)", "e", "gamma",
         (("alpha", 0.19), ("chi", 1800.0)), "alpha",
         source="paper, set 2 (whole system): Gamma, alpha_e = 0.19, chi_e = 1800"),
    Case("length_sim", "branch length l/L (simulations)", "length_L", "gamma",
         (("alpha", 0.4), ("chi", 0.12)), "alpha",
         source="paper, simulations: Gamma, alpha = 0.4, chi = 0.12"),
    Case("length_exp", "branch length l/L (experiments, above l_min)", "length_L",
         "exponential", (("mu", 3.4e-3),), "mu", cut=L_MIN_MM / L_SET2_MM,
         source="paper, set 2: exponential, mu = 3.4e-3 L, L = 1.9 m, l_min = 1 mm"),
    Case("area_exp", "void area s/L^2 (experiments, above s_min)", "area_L2", "lognormal",
         (("mu", math.log(_AREA_SET2_L2) - _SIGMA_AREA ** 2 / 2), ("sigma", _SIGMA_AREA)),
         "sigma", cut=S_MIN_MM2 / L_SET2_MM ** 2,
         source="paper, set 2: log-normal, mean s = 1.4e-5 L^2; sigma = 1 assumed (not given); "
                "s_min = 1 mm^2 (the pipeline's default)"),
    Case("area_exp_wide", "void area s/L^2 (experiments, above s_min), wider", "area_L2",
         "lognormal", (("mu", math.log(_AREA_SET2_L2) - 1.5 ** 2 / 2), ("sigma", 1.5)),
         "sigma", cut=S_MIN_MM2 / L_SET2_MM ** 2,
         source="as area_exp with sigma = 1.5 (areas over 2-3 decades, as the paper "
                "describes them): how much the s_min bias depends on the unknown sigma"),
    Case("area_sim", "void area s/L^2 (simulations)", "area_L2", "powerlaw_cutoff",
         (("tau", 1.5), ("chi", 1e-3), ("x_min", 1e-6)), "tau",
         source="paper, simulations: 'closer to a power law' over 3 decades; tau = 1.5 and "
                "chi = 1000 x_min assumed"),
    Case("n_br", "branches per stack n_br (counts)", "n_br", "exponential",
         (("mu", 1.0 / math.log(4.0 / 3.0)),), "mu",
         source="paper, set 2: exponential, mean n_br = 4 (the geometric law on n >= 1)"),
    Case("shape_ratio", "void shape ratio sqrt(s)/p", "shape_ratio", "gaussian",
         (("mu", 0.19), ("sigma", math.sqrt(14e-4))), "sigma",
         source="paper: Gaussian, mu = 0.19, sigma^2 = 14e-4"),
)}
# the laws with a detection limit in the pipeline (and the Gamma law of the simulations'
# lengths: what l_min would do to a law with alpha < 1)
TRUNCATION_CASES = ("length_exp", "length_sim", "area_exp", "area_exp_wide")
# the sample-size sweep: every case but the sigma variant of the areas
SAMPLE_SIZE_CASES = ("e_sim", "e_exp", "length_sim", "length_exp", "area_exp", "area_sim",
                     "n_br", "shape_ratio")


def law_mean(family: str, params: dict) -> float:
    """Mean of the untruncated law (the scale the cuts are given against)."""
    p = params
    if family == "exponential":
        return float(p["mu"])
    if family == "gamma":
        return float(p["alpha"] * p["chi"])
    if family == "lognormal":
        return float(math.exp(p["mu"] + p["sigma"] ** 2 / 2))
    if family == "gaussian":
        return float(p["mu"])
    raise ParameterError(f"no mean of the {family} law here")


@dataclass(frozen=True)
class FitsConfig:
    """Sizes of the fits sweep.

    Attributes
    ----------
    name : str
    cases : tuple of str
        Keys of :data:`CASES` in the sample-size sweep.
    sizes : tuple of int
        Sample sizes n.
    reps : int
        Repetitions per (case, n).
    ci_reps : int
        Of these, how many also get a bootstrap interval of ``n_boot`` resamples.
    n_boot : int
    trunc_cases : tuple of str
        Keys of :data:`CASES` in the truncation sweep.
    trunc_levels : tuple of float
        Cuts c / <x>.
    trunc_n : int
        Observations above the cut per repetition.
    trunc_reps : int
    trunc_select : bool
        Also run the model selection (naive and truncation-aware) on the truncated samples.
    """

    name: str
    cases: tuple = SAMPLE_SIZE_CASES
    sizes: tuple = (20, 50, 100, 200, 500, 1000, 2000)
    reps: int = 60
    ci_reps: int = 30
    n_boot: int = 100
    trunc_cases: tuple = TRUNCATION_CASES
    trunc_levels: tuple = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5)
    trunc_n: int = 1000
    trunc_reps: int = 20
    trunc_select: bool = True

    @classmethod
    def full(cls) -> "FitsConfig":
        """The sweep of ``docs/validation/atlas/fits``."""
        return cls("full")

    @classmethod
    def quick(cls) -> "FitsConfig":
        """Every table and chart in a few seconds (``benchmark --quick``)."""
        return cls("quick", cases=("e_sim", "length_sim", "shape_ratio"),
                   sizes=(20, 100, 500), reps=8, ci_reps=4, n_boot=30,
                   trunc_cases=("length_exp", "length_sim"), trunc_levels=(0.0, 0.1, 0.5),
                   trunc_n=300, trunc_reps=4, trunc_select=False)

    @classmethod
    def tiny(cls) -> "FitsConfig":
        """The smallest sweep that still fills every table and chart (tests)."""
        return cls("tiny", cases=("e_sim", "shape_ratio"), sizes=(20, 300),
                   reps=4, ci_reps=2, n_boot=20, trunc_cases=("length_exp", "length_sim"),
                   trunc_levels=(0.0, 0.2), trunc_n=200, trunc_reps=3, trunc_select=False)

    @classmethod
    def for_atlas(cls, name: str) -> "FitsConfig":
        """The sizes that go with an :class:`simulate.atlas.AtlasConfig` of this name."""
        return {"full": cls.full, "quick": cls.quick}.get(name, cls.tiny)()

    def check(self) -> "FitsConfig":
        """Raise :class:`ParameterError` on unknown cases or impossible sizes."""
        bad = [c for c in (*self.cases, *self.trunc_cases) if c not in CASES]
        if bad:
            raise ParameterError(f"unknown fits case {bad[0]!r}; known: {', '.join(CASES)}")
        notrunc = [c for c in self.trunc_cases if CASES[c].family not in
                   ("exponential", "gamma", "lognormal", "gaussian")]
        if notrunc:
            raise ParameterError(f"case {notrunc[0]!r} has no mean to scale a cut by")
        if min(self.sizes, default=0) < 5 or self.reps < 1 or self.trunc_n < 5:
            raise ParameterError("fits sizes must be >= 5 and repetitions >= 1")
        if not 0 <= self.ci_reps <= self.reps or (self.ci_reps and self.n_boot < 10):
            raise ParameterError("ci_reps must be in [0, reps] with n_boot >= 10")
        if any(not 0 <= v < 1 for v in self.trunc_levels):
            raise ParameterError("truncation levels c/<x> must be in [0, 1)")
        return self


# ----------------------------------------------------------------------------- draws
def _seedseq(seed: int, *key) -> np.random.SeedSequence:
    return np.random.SeedSequence([int(seed), *(zlib.crc32(str(k).encode()) for k in key)])


def draw_case(case: Case, n: int, rng: np.random.Generator, cut: float | None = None):
    """``n`` observations of a case's law, as the pipeline would see them.

    Parameters
    ----------
    case : Case
    n : int
    rng : numpy.random.Generator
    cut : float, optional
        Detection limit (default the case's own; 0 or None: none). Only draws at or above it
        are seen (the law truncated there).

    Returns
    -------
    numpy.ndarray
        Counts are the law discretised on the integers >= 1.
    """
    from crosssection.stats.families import FAMILIES
    from crosssection.stats.fits import COUNT_MIN

    fam = FAMILIES[case.family]
    cut = case.cut if cut is None else cut
    if case.discrete:
        # rounding a draw of the law truncated at 1/2 is a draw of the discretised law
        return np.round(fam.sample(case.law, n, np.full(n, COUNT_MIN - 0.5), rng))
    x = fam.sample(case.law, n, np.full(n, float(cut)) if cut else None, rng)
    if case.positive:
        while np.any(x <= 0):  # a Gaussian below 0 (p ~ 1e-7): redrawn, as never observed
            bad = x <= 0
            x[bad] = fam.sample(case.law, int(bad.sum()), None, rng)
    return x


def _selectable_best(results: dict, key: str):
    ok = {f: r for f, r in results.items() if r.selectable}
    return min(ok, key=lambda f: getattr(ok[f], key)) if ok else None


def sample_size_rows(case_name: str, n: int, *, seed: int, reps: int, ci_reps: int,
                     n_boot: int) -> list:
    """One row per repetition of a (case, n) point of the sample-size sweep (a worker task).

    Parameters
    ----------
    case_name : str
        Key of :data:`CASES`.
    n : int
    seed : int
    reps, ci_reps, n_boot : int
        See :class:`FitsConfig`.

    Returns
    -------
    list of dict
        Columns: case, quantity, family, n, rep, selected, aic_best, bic_best, correct,
        aic_correct, bic_correct, delta_bic_true (BIC of the true family minus the smallest
        selectable BIC; NaN when the true fit is degenerate), within_2, true_rejected,
        param_name, param_true, param_fit, param_rel_error, param_lo, param_hi, covered (NaN
        without an interval), fit_s.
    """
    from crosssection.stats import fits as F

    case = CASES[case_name]
    rows = []
    for rep in range(reps):
        s_data, s_fit = _seedseq(seed, SWEEP, "n", case.name, n, rep).spawn(2)
        x = draw_case(case, n, np.random.default_rng(s_data))
        cuts = case.cut if case.cut else None
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            summ = F.fit_all(x, case.candidates, truncation=cuts, n_boot=0, gof=False,
                             discrete=case.discrete)
            tr = summ.results[case.family]
            lo = hi = np.nan
            if rep < ci_reps and tr.selectable:
                rb = F.fit_family(x, case.family, truncation=cuts, n_boot=n_boot, seed=s_fit,
                                  gof=False, discrete=case.discrete)
                lo, hi = rb.ci.get(case.param, (np.nan, np.nan))
        fit_s = time.perf_counter() - t0
        res = summ.results
        bmin = min((r.bic for r in res.values() if r.selectable), default=np.nan)
        dbic = tr.bic - bmin if tr.selectable else np.nan
        aic_best, bic_best = _selectable_best(res, "aic"), _selectable_best(res, "bic")
        fit = float(tr.params.get(case.param, np.nan)) if tr.ok else np.nan
        rows.append({
            "case": case.name, "quantity": case.quantity, "family": case.family, "n": int(n),
            "rep": rep, "selected": summ.best or "", "aic_best": aic_best or "",
            "bic_best": bic_best or "", "correct": summ.best == case.family,
            "aic_correct": aic_best == case.family, "bic_correct": bic_best == case.family,
            "delta_bic_true": dbic, "within_2": bool(np.isfinite(dbic) and dbic < 2.0),
            "true_rejected": not tr.selectable, "param_name": case.param,
            "param_true": case.truth, "param_fit": fit,
            "param_rel_error": fit / case.truth - 1.0, "param_lo": lo, "param_hi": hi,
            "covered": (float(lo <= case.truth <= hi) if np.isfinite(lo) and np.isfinite(hi)
                        else np.nan),
            "fit_s": fit_s})
    return rows


def truncation_rows(case_name: str, level: float, *, seed: int, reps: int, n: int,
                    select: bool = True) -> list:
    """One row per repetition of a (case, cut) point of the truncation sweep (a worker task).

    Parameters
    ----------
    case_name : str
        Key of :data:`CASES` (exponential, Gamma, log-normal or Gaussian).
    level : float
        Cut c / <x>, <x> the mean of the untruncated law (0: no cut).
    seed : int
    reps, n : int
        Repetitions; observations above the cut in each.
    select : bool
        Also run the model selection among the quantity's candidates, naive and
        truncation-aware (the slow part).

    Returns
    -------
    list of dict
        Columns: case, family, level, cut, hidden_fraction (share of the law below the cut),
        n, rep, param_name, param_true, naive, truncated (the fitted parameter),
        naive_rel_bias, truncated_rel_bias, mean_true, sample_mean, naive_mean, truncated_mean
        (means of the fitted untruncated laws), their relative errors, naive_selected,
        truncated_selected ("" when not run), fit_s.
    """
    from crosssection.stats import fits as F
    from crosssection.stats.families import FAMILIES

    case = CASES[case_name]
    fam = FAMILIES[case.family]
    m_true = law_mean(case.family, case.law)
    cut = float(level) * m_true
    hidden = float(1.0 - fam.sf(case.law, cut)) if cut > 0 else 0.0
    rows = []
    for rep in range(reps):
        (s_data,) = _seedseq(seed, SWEEP, "cut", case.name, f"{level:.6g}", rep).spawn(1)
        x = draw_case(case, n, np.random.default_rng(s_data), cut=cut)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rn = F.fit_family(x, case.family, n_boot=0, gof=False)
            rt = (F.fit_family(x, case.family, truncation=cut, n_boot=0, gof=False)
                  if cut > 0 else rn)
            sel_n = sel_t = ""
            if select:
                sel_n = F.fit_all(x, case.candidates, n_boot=0, gof=False).best or ""
                sel_t = (F.fit_all(x, case.candidates, truncation=cut, n_boot=0,
                                   gof=False).best or "") if cut > 0 else sel_n
        fit_s = time.perf_counter() - t0
        a, b = rn.params[case.param], rt.params[case.param]
        mn, mt = law_mean(case.family, rn.params), law_mean(case.family, rt.params)
        sm = float(np.mean(x))
        rows.append({
            "case": case.name, "family": case.family, "level": float(level), "cut": cut,
            "hidden_fraction": hidden, "n": int(n), "rep": rep, "param_name": case.param,
            "param_true": case.truth, "naive": a, "truncated": b,
            "naive_rel_bias": a / case.truth - 1.0, "truncated_rel_bias": b / case.truth - 1.0,
            "mean_true": m_true, "sample_mean": sm, "naive_mean": mn, "truncated_mean": mt,
            "sample_mean_rel_error": sm / m_true - 1.0, "naive_mean_rel_error": mn / m_true - 1.0,
            "truncated_mean_rel_error": mt / m_true - 1.0, "naive_selected": sel_n,
            "truncated_selected": sel_t, "fit_s": fit_s})
    return rows


# ----------------------------------------------------------------------------- summaries
def _wilson(k: float, n: int, z: float = 1.96):
    """Wilson score interval of a proportion k/n."""
    if n <= 0:
        return np.nan, np.nan
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return max(0.0, c - h), min(1.0, c + h)


def summarize_sample_size(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (case, n): selection rates, parameter bias and spread, coverage.

    Columns: case, family, n, reps, rate_selected (the module's rule picks the true law) with
    its Wilson 95 % interval (rate_selected_lo, _hi), rate_aic, rate_bic, rate_within_2,
    rate_true_rejected, most_confused (the most frequent wrong pick) and its rate, param_name,
    param_true, param_median, rel_bias (mean of fit/true - 1), rel_bias_median, rel_sd,
    ci_reps, coverage (of the 95 % bootstrap interval) with its Wilson interval, ci_rel_width
    (median interval width over the truth), fit_s_median.
    """
    rows = []
    for (case, n), g in df.groupby(["case", "n"], sort=False):
        reps = len(g)
        k = int(g["correct"].sum())
        lo, hi = _wilson(k, reps)
        wrong = g.loc[~g["correct"].astype(bool), "selected"].replace("", "none")
        conf = wrong.value_counts()
        rel = g["param_rel_error"].to_numpy(float)
        rel = rel[np.isfinite(rel)]
        cov = g["covered"].dropna()
        clo, chi = _wilson(float(cov.sum()), len(cov))
        width = ((g["param_hi"] - g["param_lo"]) / g["param_true"]).dropna()
        rows.append({
            "case": case, "family": g["family"].iloc[0], "n": int(n), "reps": reps,
            "rate_selected": k / reps, "rate_selected_lo": lo, "rate_selected_hi": hi,
            "rate_aic": float(g["aic_correct"].mean()),
            "rate_bic": float(g["bic_correct"].mean()),
            "rate_within_2": float(g["within_2"].mean()),
            "rate_true_rejected": float(g["true_rejected"].mean()),
            "most_confused": conf.index[0] if len(conf) else "",
            "most_confused_rate": float(conf.iloc[0] / reps) if len(conf) else 0.0,
            "param_name": g["param_name"].iloc[0], "param_true": g["param_true"].iloc[0],
            "param_median": float(np.nanmedian(g["param_fit"])) if rel.size else np.nan,
            "rel_bias": float(np.mean(rel)) if rel.size else np.nan,
            "rel_bias_median": float(np.median(rel)) if rel.size else np.nan,
            "rel_sd": float(np.std(rel, ddof=1)) if rel.size > 1 else np.nan,
            "ci_reps": int(len(cov)),
            "coverage": float(cov.mean()) if len(cov) else np.nan,
            "coverage_lo": clo, "coverage_hi": chi,
            "ci_rel_width": float(width.median()) if len(width) else np.nan,
            "fit_s_median": float(g["fit_s"].median())})
    return pd.DataFrame(rows)


def summarize_truncation(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (case, cut): mean relative bias (and its standard error) of the parameter and
    of the mean, naive against truncation-aware, and the selection rates of both ways.

    Columns: case, family, level, cut, hidden_fraction, n, reps, param_name, param_true,
    naive_rel_bias, naive_rel_bias_se, truncated_rel_bias, truncated_rel_bias_se, truncated_rel_sd,
    sample_mean_rel_error, naive_mean_rel_error, truncated_mean_rel_error (and _se),
    naive_rate_selected, truncated_rate_selected (NaN when the selection was not run).
    """
    rows = []
    for (case, level), g in df.groupby(["case", "level"], sort=False):
        reps = len(g)
        row = {"case": case, "family": g["family"].iloc[0], "level": float(level),
               "cut": g["cut"].iloc[0], "hidden_fraction": g["hidden_fraction"].iloc[0],
               "n": int(g["n"].iloc[0]), "reps": reps, "param_name": g["param_name"].iloc[0],
               "param_true": g["param_true"].iloc[0]}
        for col in ("naive_rel_bias", "truncated_rel_bias", "sample_mean_rel_error",
                    "naive_mean_rel_error", "truncated_mean_rel_error"):
            v = g[col].to_numpy(float)
            v = v[np.isfinite(v)]
            row[col] = float(np.mean(v)) if v.size else np.nan
            row[col + "_se"] = float(np.std(v, ddof=1) / math.sqrt(v.size)) if v.size > 1 \
                else np.nan
        row["truncated_rel_sd"] = float(np.std(g["truncated_rel_bias"], ddof=1)) if reps > 1 \
            else np.nan
        for way in ("naive", "truncated"):
            sel = g[f"{way}_selected"].fillna("")
            row[f"{way}_rate_selected"] = (float((sel == g["family"]).mean())
                                           if (sel != "").any() else np.nan)
        rows.append(row)
    return pd.DataFrame(rows)


def stable_n(summary: pd.DataFrame, case: str, col: str = "rate_selected",
             rate: float = STABLE_RATE):
    """The smallest swept n from which ``col`` stays >= ``rate`` at every larger n (None when
    it never does)."""
    g = summary[summary["case"] == case].sort_values("n")
    ok = (g[col] >= rate).to_numpy()
    ns = g["n"].to_numpy()
    for i in range(len(ns)):
        if ok[i:].all():
            return int(ns[i])
    return None


# ----------------------------------------------------------------------------- the run
def run_fits(out, config: FitsConfig | None = None, *, seed: int = 1, executor=None,
             command: str = "") -> dict:
    """Run both sweeps; write tables, charts and ``index.md`` into ``out``.

    Parameters
    ----------
    out : str or Path
        Folder (created); the atlas passes ``REPORT/fits``.
    config : FitsConfig, optional
        Default :meth:`FitsConfig.full`.
    seed : int
    executor : concurrent.futures.Executor, optional
        Runs the (case, n) and (case, cut) points in parallel (default: one after the other).
    command : str
        The command line named in ``index.md``.

    Returns
    -------
    dict
        See :func:`write_fits_report`.
    """
    config = (config or FitsConfig.full()).check()
    out = Path(out)
    t0 = time.perf_counter()
    jobs = [("n", c, n) for c in config.cases for n in config.sizes]
    jobs += [("cut", c, v) for c in config.trunc_cases for v in config.trunc_levels]
    # the slowest first (large n, truncation-aware fits) so a pool ends together
    jobs.sort(key=lambda j: -(j[2] if j[0] == "n" else config.trunc_n * 3)
              * (3 if CASES[j[1]].cut or j[0] == "cut" else 1))

    def call(kind, case, v):
        if kind == "n":
            return (sample_size_rows, case, v), dict(seed=seed, reps=config.reps,
                                                     ci_reps=config.ci_reps,
                                                     n_boot=config.n_boot)
        return (truncation_rows, case, v), dict(seed=seed, reps=config.trunc_reps,
                                                n=config.trunc_n, select=config.trunc_select)

    calls = [call(*j) for j in jobs]
    if executor is None:
        results = [fn(*a, **kw) for (fn, *a), kw in calls]
    else:
        futs = [executor.submit(fn, *a, **kw) for (fn, *a), kw in calls]
        results = [f.result() for f in futs]
    n_rows = [r for j, rs in zip(jobs, results) if j[0] == "n" for r in rs]
    c_rows = [r for j, rs in zip(jobs, results) if j[0] == "cut" for r in rs]
    return write_fits_report(out, pd.DataFrame(n_rows), pd.DataFrame(c_rows), config=config,
                             command=command, elapsed_s=time.perf_counter() - t0)


def _case_order(df: pd.DataFrame, by) -> pd.DataFrame:
    """Rows in the order of :data:`CASES`, then ``by``; floats to 6 significant digits (far
    below the spread between repetitions; keeps the tables small)."""
    order = {c: i for i, c in enumerate(CASES)}
    df = df.sort_values(by, key=lambda s: s.map(order) if s.name == "case" else s,
                        kind="stable").reset_index(drop=True)
    for c in df.columns:
        if df[c].dtype.kind == "f":
            df[c] = [float(f"{v:.6g}") for v in df[c].to_numpy()]
    return df


def write_fits_report(out, sample_size: pd.DataFrame, truncation: pd.DataFrame, *,
                      config: FitsConfig | None = None, command: str = "",
                      elapsed_s: float | None = None) -> dict:
    """Write the raw tables, their summaries, the charts and ``index.md`` of the fits sweep.

    Parameters
    ----------
    out : str or Path
        Folder (created).
    sample_size, truncation : DataFrame
        The rows of :func:`sample_size_rows` and :func:`truncation_rows`.
    config : FitsConfig, optional
        Named in ``index.md`` (the sizes behind the tables).
    command : str
        The command line named in ``index.md``.
    elapsed_s : float, optional

    Returns
    -------
    dict
        ``tables`` (name -> DataFrame, as written), ``charts`` (name -> PNG path),
        ``reading`` (str), ``elapsed_s``, ``config``.
    """
    out = Path(out)
    tables = {"fits_sample_size": _case_order(sample_size, ["case", "n", "rep"]),
              "fits_truncation": _case_order(truncation, ["case", "level", "rep"])}
    tables["fits_sample_size_summary"] = summarize_sample_size(tables["fits_sample_size"])
    tables["fits_truncation_summary"] = summarize_truncation(tables["fits_truncation"])
    out.mkdir(parents=True, exist_ok=True)
    for name, df in tables.items():
        write_csv(out / f"{name}.csv", df)
    charts = {"fits_selection": _selection_chart(tables["fits_sample_size_summary"]),
              "fits_coverage": _coverage_chart(tables["fits_sample_size_summary"]),
              "fits_truncation": _truncation_chart(tables["fits_truncation_summary"])}
    charts = {k: save_figure(fig, out / f"{k}.png") for k, fig in charts.items()}
    text = reading(tables["fits_sample_size_summary"], tables["fits_truncation_summary"])
    res = {"tables": tables, "charts": charts, "reading": text, "elapsed_s": elapsed_s,
           "config": config}
    took = "" if elapsed_s is None else f" ({elapsed_s / 60:.1f} min)"
    write_text(out / "index.md", "# Fits: sample size and detection limits\n\n"
               + (f"Command: `{command}`{took}.\n\n" if command else "")
               + index_section(res, prefix="", heading=False))
    return res


def redraw(out, *, config: FitsConfig | None = None, command: str = "",
           elapsed_s: float | None = None) -> dict:
    """Rebuild the summaries, charts and ``index.md`` of a fits folder from its two raw
    tables (``fits_sample_size.csv``, ``fits_truncation.csv``), without refitting."""
    out = Path(out)
    sel = ("selected", "aic_best", "bic_best", "naive_selected", "truncated_selected")
    dtype = {c: object for c in sel}
    sizes = pd.read_csv(out / "fits_sample_size.csv", dtype=dtype)
    trunc = pd.read_csv(out / "fits_truncation.csv", dtype=dtype)
    sizes = sizes.fillna({c: "" for c in sel if c in sizes})
    trunc = trunc.fillna({c: "" for c in sel if c in trunc})
    return write_fits_report(out, sizes, trunc, config=config, command=command,
                             elapsed_s=elapsed_s)


# ----------------------------------------------------------------------------- reading
def _case_label(name: str) -> str:
    c = CASES[name]
    law = ", ".join(f"{k} {v:.3g}" for k, v in c.params if k in
                    ("alpha", "sigma", "tau", "mu") and not (c.family == "lognormal"
                                                             and k == "mu"))
    return f"{c.title}: {c.family} {law}"


def stability_table(sizes: pd.DataFrame) -> pd.DataFrame:
    """Per case: the n from which the selection is stable, and the coverage there.

    Columns: case, law (true family and parameters), candidates, stable_n (the module's rule
    picks the true law in >= 90 % of repetitions from there on; "> n_max" when it never does),
    stable_n_within_2 (the true law within BIC 2 of the best), rate_at_n_max, most_confused at
    the smallest n, coverage_stable (pooled coverage of the 95 % intervals at n >= stable_n)
    and the fits behind it.
    """
    rows = []
    nmax = int(sizes["n"].max())
    for case in dict.fromkeys(sizes["case"]):
        g = sizes[sizes["case"] == case].sort_values("n")
        n0, n2 = stable_n(sizes, case), stable_n(sizes, case, "rate_within_2")
        inside = g[(g["n"] >= (n0 if n0 is not None else np.inf)) & g["coverage"].notna()]
        m = int(inside["ci_reps"].sum())
        k = float((inside["coverage"] * inside["ci_reps"]).sum())
        first = g.iloc[0]
        rows.append({
            "case": case, "law": _case_label(case).split(": ", 1)[1],
            "candidates": ", ".join(CASES[case].candidates),
            "stable_n": str(n0) if n0 is not None else f"> {nmax}",
            "stable_n_within_2": str(n2) if n2 is not None else f"> {nmax}",
            "rate_at_n_max": float(g["rate_selected"].iloc[-1]),
            "rate_at_n_min": float(first["rate_selected"]),
            "confused_at_n_min": first["most_confused"],
            "coverage_stable": k / m if m else np.nan, "coverage_stable_fits": m})
    return pd.DataFrame(rows)


def _pct(v, digits=0):
    return "" if not np.isfinite(v) else f"{100 * v:+.{digits}f} %"


def reading(sizes: pd.DataFrame, trunc: pd.DataFrame) -> str:
    """The reading of the fits sweep, computed from its two summaries (Markdown bullets)."""
    lines = []
    if len(sizes):
        st = stability_table(sizes)
        nmax = int(sizes["n"].max())
        ok = st[~st["stable_n"].str.startswith(">")]
        bad = st[st["stable_n"].str.startswith(">")]
        bits = [f"{r.case} from n = {r.stable_n}" for r in ok.itertuples()]
        text = (f"- **Selection** (the module's rule: min BIC, the simpler law within 2) picks "
                f"the true law in >= {STABLE_RATE:.0%} of repetitions at n and every larger n: "
                + (", ".join(bits) if bits else "for no case"))
        if len(bad):
            text += "; never up to n = {} for ".format(nmax) + ", ".join(
                f"{r.case} ({r.rate_at_n_max:.0%} at n = {nmax})" for r in bad.itertuples())
        lines.append(text + ".")
        worst = st.sort_values("rate_at_n_min").iloc[0]
        lines.append(f"- At n = {int(sizes['n'].min())} the true law is picked in "
                     f"{st['rate_at_n_min'].min():.0%}-{st['rate_at_n_min'].max():.0%} of "
                     f"repetitions (lowest: {worst['case']}, most often taken for "
                     f"{worst['confused_at_n_min'] or 'nothing'}).")
        cov = st.dropna(subset=["coverage_stable"])
        if len(cov):
            m = int(cov["coverage_stable_fits"].sum())
            k = float((cov["coverage_stable"] * cov["coverage_stable_fits"]).sum())
            lo = cov.sort_values("coverage_stable").iloc[0]
            wl, wh = _wilson(k, m)
            lines.append(f"- **Coverage**: inside the stable region the 95 % bootstrap "
                         f"intervals of the tracked parameter contain the truth in {k / m:.1%} "
                         f"of {m} fits (95 % interval of that rate {wl:.1%}-{wh:.1%}; per "
                         f"case {cov['coverage_stable'].min():.0%}-"
                         f"{cov['coverage_stable'].max():.0%}, lowest {lo['case']}).")
            small = sizes[(sizes["n"] == sizes["n"].min()) & sizes["coverage"].notna()]
            if len(small):
                w = small.sort_values("coverage").iloc[0]
                lines.append(f"  At n = {int(w['n'])} the lowest coverage is "
                             f"{w['coverage']:.0%} ({w['case']}).")
    for case in dict.fromkeys(trunc["case"]):
        g = trunc[(trunc["case"] == case) & (trunc["level"] > 0)].sort_values("level")
        if not len(g):
            continue
        p = g["param_name"].iloc[0]
        band = PAPER_L_CUTS if CASES[case].quantity == "length_L" else PAPER_S_CUTS
        at = g[g["level"].between(*band)]
        if not len(at):  # the swept cut nearest to the paper's
            at = g.iloc[[int(np.argmin(np.abs(g["level"] - np.mean(band))))]]
        at = pd.concat([at, g.iloc[[-1]]]).drop_duplicates("level")
        pts = "; ".join(f"c/mean = {r.level:g} ({100 * r.hidden_fraction:.2g} % of the law "
                        "hidden): "
                        f"naive {p} {_pct(r.naive_rel_bias)}, naive mean "
                        f"{_pct(r.naive_mean_rel_error)}, aware {p} "
                        f"{_pct(r.truncated_rel_bias, 1)}" for r in at.itertuples())
        what = "l_min / mu" if band is PAPER_L_CUTS else "s_min / mean s"
        lines.append(f"- **Cut, {case}** ({_case_label(case).split(': ', 1)[1]}; the paper's "
                     f"{what} is {band[0]:g}-{band[1]:g}): {pts}.")
    return "\n".join(lines)


def index_section(res: dict, *, prefix: str = f"{SUBDIR}/", heading: bool = True,
                  command: str = "") -> str:
    """The fits part of an ``index.md`` (charts, reading, tables), paths under ``prefix``;
    ``command`` is named when it differs from the page's."""
    t = res["tables"]
    cfg = res.get("config")
    sizes = ""
    if cfg is not None:
        sizes = (f" n = {', '.join(map(str, cfg.sizes))}, {cfg.reps} repetitions per point "
                 f"({cfg.ci_reps} with a {cfg.n_boot}-resample bootstrap interval); cuts "
                 f"c/mean = {', '.join(f'{v:g}' for v in cfg.trunc_levels)} (mean: of the "
                 f"untruncated law) with "
                 f"{cfg.trunc_n} observations above the cut, {cfg.trunc_reps} repetitions.")
    lines = ([f"## {SWEEP}", ""] if heading else []) + (
        [f"Command: `{command}`.", ""] if command else []) + [
        "Samples drawn from the paper's laws and fitted by `crosssection.stats` as the "
        "`stats` command fits that quantity (its candidate families; truncation-aware above "
        "l_min and s_min; n_br as counts)." + sizes, ""]
    present = [c for c in CASES if any(c in set(df["case"]) for df in t.values() if len(df))]
    in_sizes = set(t["fits_sample_size"]["case"]) if len(t.get("fits_sample_size", ())) \
        else set()
    if present:
        lines += ["Cases (the true law; its parameters):", ""]
        lines += [f"- `{c}`, {CASES[c].title}: {CASES[c].family}, "
                  + ", ".join(f"{k} = {v:.4g}" for k, v in CASES[c].params)
                  + (f", cut {CASES[c].cut:.3g}" + (" (fitted truncation-aware in the "
                                                      "sample-size sweep)" if c in in_sizes
                                                      else "") if CASES[c].cut else "")
                  + f". Source: {CASES[c].source}." for c in present]
        lines += [""]
    for name in ("fits_selection", "fits_coverage", "fits_truncation"):
        if name in res["charts"]:
            lines += [f"![{name}]({prefix}{Path(res['charts'][name]).name})", ""]
    lines += [res["reading"], ""]
    if len(t.get("fits_sample_size_summary", ())):
        from crosssection.stats.tables import to_markdown

        st = stability_table(t["fits_sample_size_summary"])
        lines += ["Sample size for a stable selection (stable_n: the true law picked in >= "
                  f"{STABLE_RATE:.0%} of repetitions from there on; coverage of the 95 % "
                  "intervals pooled over n >= stable_n):", "",
                  to_markdown(st, floatfmt=".2f")]
    if len(t.get("fits_truncation_summary", ())):
        from crosssection.stats.tables import to_markdown

        tr = t["fits_truncation_summary"]
        show = pd.DataFrame({
            "case": tr["case"], "param": tr["param_name"], "c/mean": tr["level"],
            "hidden": tr["hidden_fraction"].map(lambda v: f"{100 * v:.2g} %"),
            "naive param": tr["naive_rel_bias"].map(_pct),
            "aware param": tr["truncated_rel_bias"].map(lambda v: _pct(v, 1)),
            "naive mean": tr["naive_mean_rel_error"].map(_pct),
            "aware mean": tr["truncated_mean_rel_error"].map(lambda v: _pct(v, 1)),
            "naive picks true": tr["naive_rate_selected"],
            "aware picks true": tr["truncated_rate_selected"]})
        lines += ["Detection limits (mean relative error over repetitions; the last columns: "
                  "fraction of repetitions where the model selection picks the true law):",
                  "", to_markdown(show, floatfmt=".2f")]
    lines += ["Tables: " + ", ".join(f"[{k}.csv]({prefix}{k}.csv) ({len(v)} rows)"
                                     for k, v in t.items()) + ".", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- charts
_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown",
           "tab:pink", "tab:olive", "tab:cyan", "tab:grey")
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">")


_LINESTYLES = ("-", "--", "-.", ":")
#: shift between the cases' points along the log n axis of the rate panels, in decades
DODGE_DECADES = 0.02


def _style(case: str):
    i = list(CASES).index(case)
    return _COLORS[i % len(_COLORS)], _MARKERS[i % len(_MARKERS)]


def _linestyle(case: str, cases) -> str:
    """The line style of ``case`` by its place among the charted ``cases``: lines of equal
    values stay told apart (the one beneath shows through the gaps of the dashes above)."""
    return _LINESTYLES[list(cases).index(case) % len(_LINESTYLES)]


def _dodged(n, case: str, cases) -> np.ndarray:
    """The sample sizes ``n`` of ``case`` shifted a little along the log axis by its place
    among ``cases``: rates of a few repetitions often tie (two cases at 1.0 at every n), and
    tied lines drawn at the same n would hide one another."""
    i, k = list(cases).index(case), len(cases)
    return np.asarray(n, float) * 10.0 ** (DODGE_DECADES * (i - (k - 1) / 2))


def _figure(w, h):
    from matplotlib.figure import Figure

    return Figure(figsize=(w, h), layout="constrained")


def _n_axis(ax, ns):
    from matplotlib.ticker import NullFormatter

    ax.set_xscale("log")
    ax.set_xticks(ns, [f"{v:g}" for v in ns], fontsize=8)
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("sample size n (observations per fit)")
    ax.grid(alpha=0.3)


def _end_labels(ax, items, *, fontsize=8, gap=0.06):
    """Write each line's name right of the axes at the height of its last point, spread
    apart so that no two overlap (call once the limits are final).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    items : list of (x_last, y_last, text, colour)
    gap : float
        Smallest spacing of the names, in axes fractions.
    """
    to_frac = ax.transData + ax.transAxes.inverted()
    items = [(float(to_frac.transform((x, y))[1]), t, c) for x, y, t, c in items
             if np.isfinite(x) and np.isfinite(y)]
    if not items:
        return
    items.sort(key=lambda it: it[0])
    ys = [min(max(it[0], 0.0), 1.0) for it in items]
    for i in range(1, len(ys)):
        ys[i] = max(ys[i], ys[i - 1] + gap)
    over = ys[-1] - 1.0
    if over > 0:  # shift down as a block, keeping the spacing
        ys = [y - over for y in ys]
    for (y0, text, color), y in zip(items, ys):
        ax.annotate(text, xy=(1.0, y0), xycoords="axes fraction", xytext=(1.05, y),
                    textcoords="axes fraction", color=color, fontsize=fontsize, va="center",
                    ha="left", annotation_clip=False,
                    arrowprops=dict(arrowstyle="-", color=color, lw=0.6, alpha=0.6,
                                    relpos=(0.0, 0.5), shrinkA=0, shrinkB=0))


def _percent_ticks(ax):
    """Plain tick labels (1, 2, 5, 10, ...) on a logarithmic y axis."""
    from matplotlib.ticker import FixedLocator, NullFormatter

    lo, hi = ax.get_ylim()
    ticks = [m * 10.0 ** e for e in range(-3, 4) for m in (1, 2, 5) if lo <= m * 10.0 ** e <= hi]
    ax.yaxis.set_major_locator(FixedLocator(ticks))
    ax.set_yticklabels([f"{t:g}" for t in ticks])
    ax.yaxis.set_minor_formatter(NullFormatter())


def _selection_chart(s: pd.DataFrame):
    fig = _figure(14, 5.2)
    axes = fig.subplots(1, 3, sharey=True)
    ns = sorted(s["n"].unique())
    cols = (("rate_selected", "the module's rule picks the true law\n(min BIC; simpler law "
                              "within 2)"),
            ("rate_aic", "min AIC picks the true law"),
            ("rate_within_2", "true law within BIC 2 of the best"))
    ends = []
    cases = list(dict.fromkeys(s["case"]))
    for ax, (col, title) in zip(axes, cols):
        for case, g in s.groupby("case", sort=False):
            g = g.sort_values("n")
            color, marker = _style(case)
            ax.plot(_dodged(g["n"], case, cases), g[col], marker=marker, color=color, lw=1.5,
                    ms=5, ls=_linestyle(case, cases), gid=f"rate:{col}:{case}")
            if ax is axes[-1]:
                ends.append((g["n"].iloc[-1], g[col].iloc[-1], _case_label(case), color))
        ax.axhline(STABLE_RATE, color="crimson", ls="--", lw=1)
        _n_axis(ax, ns)
        ax.set_title(title, fontsize=10)
        ax.set_ylim(-0.03, 1.05)
    axes[0].set_ylabel("fraction of repetitions")
    _end_labels(axes[-1], ends)
    reps = int(s["reps"].median())
    lo, hi = _wilson(0.9 * reps, reps)
    fig.suptitle("Model selection against sample size: how often the law the sample was drawn "
                 f"from is chosen\n({reps} repetitions per point: a true rate of 90 % reads as "
                 f"{lo:.0%}-{hi:.0%}; dashed red line: {STABLE_RATE:.0%}, the 'stable' level)"
                 "\nthe cases' points are set a little apart in n and their lines dashed "
                 "apart: equal rates would hide one another", fontsize=11)
    return fig


def _coverage_chart(s: pd.DataFrame):
    fig = _figure(15, 5.4)
    axes = fig.subplots(1, 3)
    ns = sorted(s["n"].unique())
    ends = []
    cases = list(dict.fromkeys(s["case"]))
    for case, g in s.groupby("case", sort=False):
        g = g.sort_values("n")
        color, marker = _style(case)
        ls = _linestyle(case, cases)
        c = g.dropna(subset=["coverage"])
        # coverage is a fraction of a few fits: cases tie often, set apart in n
        axes[0].plot(_dodged(c["n"], case, cases), c["coverage"], marker=marker, color=color,
                     lw=1.5, ms=5, ls=ls, gid=f"coverage:{case}")
        axes[1].plot(g["n"], 100 * g["rel_bias"], marker=marker, color=color, lw=1.5, ms=5,
                     ls=ls)
        axes[2].plot(g["n"], 100 * g["rel_sd"], marker=marker, color=color, lw=1.5, ms=5, ls=ls)
        ends.append((g["n"].iloc[-1], 100 * g["rel_sd"].iloc[-1],
                     f"{_case_label(case)} (tracked: {g['param_name'].iloc[0]})", color))
    ci = int(s["ci_reps"].median()) if len(s) else 0
    lo, hi = _wilson(0.95 * ci, ci) if ci else (np.nan, np.nan)
    a = axes[0]
    a.axhline(0.95, color="crimson", ls="--", lw=1)
    if np.isfinite(lo):
        a.axhspan(lo, hi, color="crimson", alpha=0.08, lw=0)
    a.set_ylim(min(0.5, float(np.nanmin(s["coverage"])) - 0.05) if s["coverage"].notna().any()
               else 0.5, 1.02)
    a.set_ylabel("fraction of 95 % intervals containing the truth")
    a.set_title(f"coverage ({ci} fits per point; cases set apart in n)\ndashed red: 95 %; "
                f"band: the spread of {ci} fits", fontsize=10)
    b = axes[1]
    b.axhline(0, color="black", lw=0.8)
    b.set_ylabel("mean relative bias of the fitted parameter (%)")
    b.set_title("bias: mean of fitted / true - 1", fontsize=10)
    c = axes[2]
    c.set_yscale("log")
    c.set_ylabel("spread: standard deviation of fitted / true (%)")
    c.set_title("spread over repetitions", fontsize=10)
    _percent_ticks(c)
    for ax in axes:
        _n_axis(ax, ns)
    _end_labels(c, ends)
    fig.suptitle("Fitted parameter of the true law against sample size (the shape where the "
                 "law has one: alpha, sigma, tau; mu for the exponential laws)", fontsize=11)
    return fig


# the paper's cuts (table of experimental parameters; <l> and <s> per set): l_min = 1 mm
# against the exponential mu = <l> - l_min, s_min = (10 h)^2 or 1 mm^2 against <s>
PAPER_L_CUTS = (0.09, 0.29)
PAPER_S_CUTS = (0.005, 0.042)


def _ratio_ticks(ax):
    """Plain tick labels of a logarithmic ratio axis."""
    from matplotlib.ticker import FixedLocator, NullFormatter

    lo, hi = ax.get_ylim()
    ticks = [t for t in (0.2, 0.3, 0.5, 0.7, 0.8, 0.9, 1.0, 1.1, 1.25, 1.5, 2.0, 3.0, 5.0, 7.0,
                         10.0, 20.0) if lo <= t <= hi]
    ax.yaxis.set_major_locator(FixedLocator(ticks))
    ax.set_yticklabels([f"{t:g}" for t in ticks])
    ax.yaxis.set_minor_formatter(NullFormatter())


def _truncation_chart(t: pd.DataFrame):
    from matplotlib.lines import Line2D

    fig = _figure(14, 6.4)
    axes = fig.subplots(1, 3)
    levels = sorted(t["level"].unique())
    named = []
    sel = t["naive_rate_selected"].notna().any()
    for case, g in t.groupby("case", sort=False):
        g = g.sort_values("level")
        color, marker = _style(case)
        for ax, (nv, tv) in zip(axes[:2], (("naive_rel_bias", "truncated_rel_bias"),
                                           ("naive_mean_rel_error",
                                            "truncated_mean_rel_error"))):
            ax.plot(g["level"], 1 + g[nv], marker=marker, color=color, lw=1.5, ms=5)
            ax.plot(g["level"], 1 + g[tv], marker=marker, color=color, lw=1.2, ls="--",
                    ms=4, mfc="white")
        if sel:
            axes[2].plot(g["level"], g["naive_rate_selected"], marker=marker, color=color,
                         lw=1.5, ms=5)
            axes[2].plot(g["level"], g["truncated_rate_selected"], marker=marker, color=color,
                         lw=1.2, ls="--", ms=4, mfc="white")
        else:
            axes[2].plot(g["level"], 100 * g["hidden_fraction"], marker=marker, color=color,
                         lw=1.5, ms=5)
        named.append((f"{_case_label(case)}; tracked: {g['param_name'].iloc[0]}", color,
                      marker))
    for ax in axes[:2]:
        ax.set_yscale("log")
        ax.axhline(1.0, color="black", lw=0.8)
        _ratio_ticks(ax)
    for ax in axes:
        ax.set_xscale("symlog", linthresh=0.01, linscale=0.5)
        ax.set_xlim(-0.001, max(levels) * 1.15 if levels else 1)
        ax.set_xticks(levels, [f"{v:g}" for v in levels])
        ax.set_xlabel("detection limit c / mean of the untruncated law")
        ax.grid(alpha=0.3)
        ax.axvspan(*PAPER_L_CUTS, color="tab:blue", alpha=0.08, lw=0)
        ax.axvspan(*PAPER_S_CUTS, color="tab:green", alpha=0.10, lw=0)
    axes[0].set_ylabel("fitted / true parameter (log scale)")
    axes[0].set_title("the tracked parameter", fontsize=10)
    axes[1].set_ylabel("fitted / true mean of the law (log scale)")
    axes[1].set_title("the mean of the law (naive = the sample mean\nfor the exponential "
                      "and Gamma laws)", fontsize=10)
    if sel:
        axes[2].set_ylabel("fraction of repetitions picking the true law")
        axes[2].set_title("model selection on the truncated sample", fontsize=10)
        axes[2].set_ylim(-0.03, 1.05)
    else:
        axes[2].set_ylabel("share of the law below the cut (%)")
        axes[2].set_title("what the cut hides", fontsize=10)
    handles = [Line2D([], [], color=c, marker=m, label=label) for label, c, m in named]
    handles += [Line2D([], [], color="black", lw=1.5, label="solid: naive fit (cut ignored)"),
                Line2D([], [], color="black", lw=1.2, ls="--", marker="o", mfc="white",
                       label="dashed: truncation-aware fit (the pipeline's)"),
                Line2D([], [], color="tab:green", lw=6, alpha=0.3,
                       label="the paper's s_min / mean s (sets 1-4)"),
                Line2D([], [], color="tab:blue", lw=6, alpha=0.25,
                       label="the paper's l_min / mu, l_min = 1 mm (sets 1-4)")]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=9)
    n = int(t["n"].median())
    reps = int(t["reps"].median())
    fig.suptitle(f"Detection limits: fits of samples seen only above a cut c ({n} observations "
                 f"above it, {reps} repetitions per point; means over repetitions)",
                 fontsize=11)
    return fig
