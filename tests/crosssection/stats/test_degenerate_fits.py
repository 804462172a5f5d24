"""Fits of samples at the edge of what a law can describe: constant or nearly constant values,
values hundreds of decades apart, counts a narrow law only splits, out-of-domain parameters."""
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from crosssection.core.errors import ParameterError
from crosssection.quality import QualityWarning
from crosssection.stats import data as D
from crosssection.stats import fits as F
from crosssection.stats import tables as T
from crosssection.stats.families import FAMILIES, SPREAD_RTOL, no_spread

ALL = (*F.PAPER_FAMILIES, "powerlaw_cutoff")


def _quiet(fn, *args, **kw):
    """``fn(*args, **kw)`` with every warning an error (numpy's RuntimeWarnings included),
    except the SmallSampleWarning of the few resamples these tests use to stay fast."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", category=F.SmallSampleWarning)
        return fn(*args, **kw)


# ------------------------------------------------------------------ zero spread
def _near_constant(rel):
    return 1.0 + rel * np.random.default_rng(0).uniform(size=60)


@pytest.mark.parametrize("x", [
    np.array([sum([0.1] * k) / k for k in range(1, 61)]),  # rounding noise only
    _near_constant(1e-15), _near_constant(1e-10), _near_constant(1e-8),
    np.full(60, 2.0)], ids=["rounding", "1e-15", "1e-10", "1e-8", "equal"])
def test_constant_samples_are_zero_spread_for_every_family(x):
    summ = _quiet(F.fit_all, x, ALL, n_boot=5, n_mc=5)
    assert summ.best is None
    for f, r in summ.results.items():
        assert (r.ok, r.note) == (False, "zero spread"), f


def test_spread_above_the_tolerance_is_fitted():
    x = _near_constant(1e-4)
    assert not no_spread(x)
    summ = _quiet(F.fit_all, x, ALL, n_boot=0, gof=False)
    assert all(r.ok for r in summ.results.values())
    assert summ.best is not None


def test_zero_spread_is_scale_free():
    x = np.random.default_rng(1).gamma(2.0, 1.0, 50)
    assert not any(no_spread(x * s) for s in (1e-300, 1.0, 1e300))
    assert all(no_spread(np.full(5, v)) for v in (1e-310, 3.0, 1e308))
    assert no_spread(3.0 * (1 + 0.5 * SPREAD_RTOL * np.array([-1.0, 1.0])))


def test_constant_exponential_and_counts_are_not_fitted():
    r = _quiet(F.fit_family, np.full(60, 2.0), "exponential", n_boot=5, n_mc=5)
    assert (r.ok, r.note, r.selectable) == (False, "zero spread", False)
    summ = _quiet(F.fit_all, np.ones(80), discrete=True, n_boot=5, n_mc=5)
    assert summ.best is None
    assert summ.table["note"].eq("zero spread").all()
    assert not summ.table["selected"].any()
    with pytest.raises(ParameterError, match="exponential.*zero spread"):
        F.bootstrap_ci(np.full(50, 2.0), "exponential")


# ------------------------------------------------------------------ far-off values
@pytest.mark.parametrize("family", ALL)
def test_one_value_hundreds_of_decades_away_does_not_crash(family):
    x = np.r_[np.random.default_rng(0).gamma(2.0, 1.0, 60), 1e300]
    r = _quiet(F.fit_family, x, family, n_boot=10, n_mc=9)
    assert r.n == 61
    # either a law with finite numbers or a fit set aside with its reason
    assert r.rejected or all(np.isfinite(v) for v in r.params.values())
    if family == "powerlaw_cutoff":
        assert "cutoff is not seen" in r.rejected


def test_trunc_likelihood_of_far_off_parameters_is_a_large_penalty():
    from crosssection.stats.families import _trunc_nll, log_upper_gamma
    with pytest.raises(OverflowError):  # the normalisation itself is not representable
        log_upper_gamma(-999.0, np.array([1e-3]))
    fam = FAMILIES["powerlaw_cutoff"]
    cut = np.array([0.1])
    assert _trunc_nll(fam, (1000.0, 100.0), np.array([0.2, 0.3]), cut, np.array([2])) == 1e300


@pytest.mark.parametrize("scale", [1e-200, 1e200])
def test_gaussian_fit_is_scale_free(scale):
    x = np.random.default_rng(0).gamma(2.0, 1.0, 60)
    r1 = _quiet(F.fit_family, x, "gaussian", n_boot=20, n_mc=19)
    rs = _quiet(F.fit_family, x * scale, "gaussian", n_boot=20, n_mc=19)
    assert rs.rejected == "" and r1.rejected == ""
    for k in ("mu", "sigma"):
        assert rs.params[k] == pytest.approx(r1.params[k] * scale, rel=1e-12)
        assert rs.ci[k][0] == pytest.approx(r1.ci[k][0] * scale, rel=1e-9)
    assert rs.statistic == pytest.approx(r1.statistic, rel=1e-9)
    assert rs.pvalue == r1.pvalue


def test_gaussian_fit_of_ordinary_data_is_scipys():
    x = np.random.default_rng(3).normal(0.19, 0.037, 200)
    m, s = stats.norm.fit(x)
    assert FAMILIES["gaussian"].naive_theta(x) == (m, s)  # bit for bit


# ------------------------------------------------------------------ goodness of fit
X = np.random.default_rng(0).gamma(2.0, 1.0, 60)


@pytest.mark.parametrize("family,params,name", [
    ("gaussian", {"mu": 1.0, "sigma": -1.0}, "sigma"),
    ("gaussian", {"mu": 1.0, "sigma": 0.0}, "sigma"),
    ("exponential", {"mu": 0.0}, "mu"),
    ("lognormal", {"mu": 0.0, "sigma": -0.5}, "sigma"),
    ("gamma", {"alpha": 1e300, "chi": 1.0}, "alpha"),  # a spike
    ("gamma", {"alpha": 2.0, "chi": -1.0}, "chi"),
    ("powerlaw_cutoff", {"tau": 1.5, "chi": 0.0, "x_min": 0.1}, "chi"),
    ("bose_einstein", {"alpha": 1.0, "beta": 1.0, "x_lo": 5.0, "x_hi": 1.0}, "x_lo"),
])
def test_goodness_of_fit_refuses_parameters_outside_the_domain(family, params, name):
    with pytest.raises(ParameterError, match=rf"params\['{name}'\]"):
        _quiet(F.goodness_of_fit, X, family, params, n_mc=9)


def test_goodness_of_fit_of_far_off_parameters_is_quiet():
    g = _quiet(F.goodness_of_fit, X, "gamma", {"alpha": 1e9, "chi": 1e-9}, n_mc=9)
    assert g.statistic > 100  # every observation far in the law's tails


# ------------------------------------------------------------------ spikes
@pytest.mark.parametrize("p2", [0.49, 0.3, 0.1])
def test_counts_split_by_a_narrow_law_are_degenerate(p2):
    # counts 1 and 2 only: a law narrower than one count reproduces any split between them
    # (a Gamma with alpha ~ 180 at 1.5 fitted the bulk n_br of a set so)
    x = np.where(np.random.default_rng(3).uniform(size=300) < p2, 2.0, 1.0)
    summ = _quiet(F.fit_all, x, discrete=True, n_boot=0, n_mc=19)
    for f in ("gamma", "lognormal", "gaussian"):
        r = summ.results[f]
        assert "spike" in r.rejected and "one count" in r.rejected, f
        assert not r.selectable and np.isnan(r.pvalue)
    assert summ.best == "exponential"


def test_counts_of_a_broad_law_are_not_spikes():
    rng = np.random.default_rng(3)
    for x in (rng.geometric(0.4, 300), rng.poisson(5, 300) + 1):
        summ = _quiet(F.fit_all, x.astype(float), discrete=True, n_boot=0, gof=False)
        assert not any("spike" in r.rejected for r in summ.results.values())


def test_continuous_spike_is_degenerate():
    x = np.random.default_rng(0).normal(0.0, 1.0, 100)
    fam = FAMILIES["gaussian"]
    assert "spike" in F._spike(fam, {"mu": 0.0, "sigma": 0.05}, x, False)
    assert F._spike(fam, {"mu": 0.0, "sigma": 0.5}, x, False) == ""
    assert F._spike(FAMILIES["exponential"], {"mu": 1e-9}, x, True) == ""  # no width


def test_one_far_value_makes_no_broad_law_a_spike():
    rng = np.random.default_rng(3)
    y = np.append(rng.lognormal(0.0, 1.5, 299), 1e5)  # a void far larger than the others
    summ = _quiet(F.fit_all, y, n_boot=0, gof=False)
    assert summ.results["lognormal"].rejected == ""
    assert summ.best == "lognormal"
    x = np.append(rng.exponential(1.0, 299), 1e3)
    summ = _quiet(F.fit_all, x, n_boot=0, gof=False)
    assert not any("spike" in r.rejected for r in summ.results.values())
    # a narrow law under most of the data is still one
    z = np.append(rng.normal(10.0, 1.0, 299), 1e3)
    assert "spike" in F._spike(FAMILIES["gaussian"], {"mu": 10.0, "sigma": 0.01}, z, False)


# ------------------------------------------------------------------ tables
def _ensemble(e):
    rng = np.random.default_rng(0)
    n = 60
    cfg = pd.DataFrame({"set": "A", "config_id": ["c0", "c1"], "N_l": [10.0, 12.0],
                        "N_br": [30.0, 33.0], "n_voids": 2, "epsilon": [8.0, 9.0],
                        "E": [1e3, 2e3], "rod_length_mm": np.nan, "source": ""})
    br = pd.DataFrame({"set": "A", "config_id": ["c0", "c1"] * (n // 2),
                       "length_L": rng.gamma(2, 0.01, n), "kappa_m_L": rng.gamma(2, 5, n),
                       "kappa_plus_L": rng.gamma(2, 5, n), "e": e(n), "region": "none",
                       "n_br": 2.0, "l_min_L": np.nan})
    st = pd.DataFrame({"set": "A", "config_id": ["c0", "c1"] * 10,
                       "n_br": rng.integers(1, 5, 20).astype(float), "length_L": 0.01,
                       "region": "none"})
    vo = pd.DataFrame({"set": "A", "config_id": ["c0", "c1"] * 5,
                       "area_L2": rng.gamma(2, 1e-4, 10), "perimeter_L": 0.1,
                       "shape_ratio": 0.18, "n_edges": 4, "s_min_L2": np.nan})
    return D.Ensemble(cfg, br, st, vo)


def test_constant_quantity_is_left_out_with_a_warning():
    ens = _ensemble(lambda n: np.full(n, 4.0))
    opts = T.StatsOptions(n_boot=0, gof=False, quantities=("e", "length_L"))
    with pytest.warns(QualityWarning, match=r"set A: e: zero spread \(all 60 values equal 4"):
        res = T.compute_stats(ens, opts)
    assert set(res.fits["quantity"]) == {"length_L"}


def test_varied_quantity_gives_no_zero_spread_warning():
    ens = _ensemble(lambda n: np.random.default_rng(5).gamma(0.5, 100, n))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = T.compute_stats(ens, T.StatsOptions(n_boot=0, gof=False,
                                                  quantities=("e", "length_L")))
    assert not [w for w in caught if "zero spread" in str(w.message)]
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)]
    assert set(res.fits["quantity"]) == {"e", "length_L"}


@pytest.mark.parametrize("scale", [1e-200, 1e-100, 1e100, 1e200])
def test_slope_through_origin_is_scale_free(scale):
    rng = np.random.default_rng(4)
    x = rng.uniform(1, 2, 10)
    y = 1.3 * x + rng.normal(0, 0.05, 10)
    a, r2, n = T.slope_through_origin(x, y)
    # bit for bit the plain formula on ordinary numbers
    assert a == float(np.sum(x * y) / np.sum(x * x))
    a_s, r2_s, n_s = _quiet(T.slope_through_origin, x * scale, y)
    assert a_s == pytest.approx(a / scale, rel=1e-12)
    assert r2_s == pytest.approx(r2, rel=1e-12) and n_s == n


def test_slope_beyond_the_float_range_is_nan_with_a_warning():
    x, y = np.array([1e-300, 2e-300]), np.array([1e300, 2e300])
    with pytest.warns(QualityWarning, match="eq14_slope: the slope"):
        a, r2, n = T.slope_through_origin(x, y, "eq14_slope")
    assert np.isnan(a) and r2 == pytest.approx(1.0) and n == 2


def test_a_fit_whose_interval_reaches_its_degenerate_limit_is_not_named():
    """A Bose-Einstein beta of 0.003 whose bootstrap interval ran down to 6e-8 (beta x << 1,
    where the law is 1/x and beta is undetermined) was selected as the law of e: a share of
    degenerate resamples beyond the interval's tail makes the fit undetermined."""
    from crosssection.stats.families import FAMILIES

    fam = FAMILIES["bose_einstein"]
    x = np.linspace(10.0, 400.0, 200)
    row = {"alpha": 1.0, "beta": 0.003, "x_lo": 10.0, "x_hi": 400.0}
    assert fam.degeneracy(row, x) == ""  # the point estimate passes

    def draws(n_degenerate):
        out = np.tile([row[k] for k in fam.param_names], (100, 1)).astype(float)
        out[:n_degenerate, fam.param_names.index("beta")] = 6e-8
        return out

    said = F._degenerate_resamples(fam, draws(10), x, None, 0.95)
    assert said.startswith("10 % of the bootstrap resamples fit its degenerate limit")
    assert "beta x << 1" in said and said.endswith("the data do not determine it")
    assert F._degenerate_resamples(fam, draws(2), x, None, 0.95) == ""  # within the tail
    assert F._degenerate_resamples(fam, None, x, None, 0.95) == ""


def test_a_fit_whose_log_likelihood_is_not_finite_is_not_selectable():
    """One value of 5e-324 beside a Gamma sample gave the Gamma fit a log-likelihood of +inf,
    returned as a fit."""
    x = np.append(np.random.default_rng(0).gamma(0.5, 1.0, 200), 5e-324)
    r = F.fit_family(x, "gamma", n_boot=0, gof=False)
    assert "log-likelihood not finite" in r.rejected and not r.selectable


def test_bootstrap_intervals_let_no_refit_warning_out():
    """bootstrap_ci leaked a RuntimeWarning of every resample's refit that fit_family
    silences."""
    g = np.random.default_rng(0).gamma(0.3, 1.0, 100)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for family, x in (("powerlaw_cutoff", g), ("bose_einstein", g * 1e-310)):
            ci = F.bootstrap_ci(x, family, n_boot=40)
            assert set(ci) == set(F.FAMILIES[family].param_names)


def test_a_count_fit_whose_resamples_fall_below_the_smallest_count_is_not_named():
    """A Gaussian of counts with mu 1.2 was selected for n_br while a third of its bootstrap
    fits had mu below 1 (the geometric law in disguise, which the point estimate's own rule
    rejects)."""
    from crosssection.stats.families import FAMILIES

    fam = FAMILIES["gaussian"]
    x = np.array([1.0] * 30 + [2.0] * 15 + [3.0] * 8 + [4.0] * 4)

    def draws(n_below):
        out = np.tile([1.2, 1.4], (100, 1))
        out[:n_below, 0] = -0.5
        return out

    said = F._degenerate_resamples(fam, draws(30), x, None, 0.95, discrete=True)
    assert said.startswith("30 % of the bootstrap resamples") and "in disguise" in said
    assert F._degenerate_resamples(fam, draws(30), x, None, 0.95) == ""  # not counts
    assert F._degenerate_resamples(fam, draws(2), x, None, 0.95, discrete=True) == ""


def test_the_count_test_keeps_its_samples_of_one_count():
    # five stacks, four of one layer: a third of the null samples hold one count only; they
    # were left out (n_mc 123 of 199) and the p-value rose to 1
    from crosssection.stats.families import FAMILIES

    x = np.array([1.0, 1.0, 1.0, 1.0, 2.0])
    fam = FAMILIES["exponential"]
    r = F.fit_family(x, "exponential", discrete=True, n_boot=0, gof=False)
    test = F._gof_counts(x, fam, r.params, 199, np.random.default_rng(0))
    assert test.n_mc == 199 and test.pvalue < 1.0
