"""Maximum-likelihood fits, bootstrap intervals, goodness of fit, model selection, truncation."""
import warnings

import numpy as np
import pytest
from scipy import integrate

from crosssection.core.errors import ParameterError
from crosssection.quality import QualityWarning
from crosssection.stats import fits as F
from crosssection.stats import families as FM
from crosssection.stats.families import FAMILIES

TRUE = {
    "exponential": {"mu": 2.5e-3},
    "gamma": {"alpha": 0.4, "chi": 0.12},
    "lognormal": {"mu": -9.0, "sigma": 1.2},
    "gaussian": {"mu": 0.19, "sigma": 0.037},
}
BE_TRUE = {"beta": 3.0, "x_lo": 0.01, "x_hi": 2.0}


def draw(family, n, rng):
    if family == "bose_einstein":
        return FM.be_ppf(rng.uniform(size=n), BE_TRUE["beta"], BE_TRUE["x_lo"], BE_TRUE["x_hi"])
    return FAMILIES[family].frozen(TRUE[family]).rvs(size=n, random_state=rng)


@pytest.mark.parametrize("beta,lo,hi", [(3.0, 0.01, 2.0), (0.002, 1.0, 5000.0), (50.0, 1e-4, 0.3)])
def test_bose_einstein_normalisation_cdf_ppf(beta, lo, hi):
    z = integrate.quad(lambda e: 1 / np.expm1(beta * e), lo, hi, limit=200, points=[lo * 10])[0]
    assert np.exp(FM.be_log_norm(beta, lo, hi)) == pytest.approx(z, rel=1e-6)
    u = np.linspace(0.01, 0.99, 7)
    x = FM.be_ppf(u, beta, lo, hi)
    assert np.all((x >= lo) & (x <= hi))
    np.testing.assert_allclose(FM.be_cdf(x, beta, lo, hi), u, rtol=1e-9, atol=1e-12)
    # density integrates to one
    tot = integrate.quad(lambda e: np.exp(FM.be_logpdf(e, beta, lo, hi)), lo, hi, limit=200,
                         points=[lo * 10])[0]
    assert tot == pytest.approx(1.0, rel=1e-6)


@pytest.mark.parametrize("family", ["exponential", "gamma", "lognormal", "gaussian",
                                    "bose_einstein"])
def test_bootstrap_interval_covers_truth_at_nominal_rate(family):
    # 95% percentile intervals from n = 300 samples; 24 replicates (fail if < 19 cover:
    # P(X <= 18 | p = 0.95) ~ 1e-3)
    rng = np.random.default_rng(sum(map(ord, family)))
    truth = BE_TRUE if family == "bose_einstein" else TRUE[family]
    cover, reps = 0, 24
    for i in range(reps):
        x = draw(family, 300, rng)
        r = F.fit_family(x, family, n_boot=80 if family == "bose_einstein" else 150,
                         seed=i, gof=False)
        key = FAMILIES[family].free_names[-1]
        lo, hi = r.ci[key]
        cover += lo <= truth[key] <= hi
        # point estimate sits inside its own interval
        assert lo <= r.params[key] <= hi
    assert cover >= 19, f"{family}: {cover}/{reps}"


def test_gamma_parameters_in_paper_notation():
    rng = np.random.default_rng(7)
    x = rng.gamma(2.5, 14.8, 5000)
    r = F.fit_family(x, "gamma", n_boot=0, gof=False)
    assert r.params["alpha"] == pytest.approx(2.5, rel=0.06)
    assert r.params["chi"] == pytest.approx(14.8, rel=0.06)  # chi is the scale, mean = alpha chi
    assert r.params["alpha"] * r.params["chi"] == pytest.approx(x.mean(), rel=1e-3)


@pytest.mark.parametrize("family", ["exponential", "gamma", "lognormal", "gaussian",
                                    "bose_einstein"])
def test_model_selection_picks_generating_family(family):
    rng = np.random.default_rng(1000 + len(family))
    hits = 0
    for i in range(10):
        x = draw(family, 1000, rng)
        hits += F.fit_all(x, seed=i, n_boot=0, gof=False).best == family
    assert hits >= 9, f"{family}: {hits}/10"


def test_select_model_prefers_fewer_parameters_within_two_bic():
    def res(f, bic, k, **kw):
        return F.FitResult(f, {}, 0.0, 0.0, bic, 100, k, **kw)

    assert F.select_model({"exponential": res("exponential", 101.5, 1),
                           "gamma": res("gamma", 100.0, 2)}) == "exponential"
    assert F.select_model({"exponential": res("exponential", 102.5, 1),
                           "gamma": res("gamma", 100.0, 2)}) == "gamma"
    bad = res("lognormal", -1e9, 2, ok=False)
    assert F.select_model({"gamma": res("gamma", 100.0, 2), "lognormal": bad}) == "gamma"
    degenerate = res("exponential", 50.0, 1, rejected="mu at its bound")
    assert F.select_model({"gamma": res("gamma", 100.0, 2),
                           "exponential": degenerate}) == "gamma"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_truncated_exponential_mean_minus_cut_is_mu(seed):
    rng = np.random.default_rng(seed)
    mu, cut = 2.0, rng.uniform(0.5, 3.0)
    x = rng.exponential(mu, 4000)
    x = x[x >= cut]
    r = F.fit_family(x, "exponential", truncation=cut, n_boot=200, seed=seed, gof=False)
    assert r.params["mu"] == pytest.approx(x.mean() - cut, rel=1e-12)  # paper's note
    lo, hi = r.ci["mu"]
    assert lo <= mu <= hi
    naive = F.fit_family(x, "exponential", n_boot=0, gof=False)
    assert naive.params["mu"] > hi  # the naive fit is biased by the cut


@pytest.mark.parametrize("family,truth,cut", [
    ("gamma", {"alpha": 0.8, "chi": 2.0}, 0.8),
    ("lognormal", {"mu": 0.0, "sigma": 1.0}, 0.7),
])
def test_truncation_aware_fit_removes_naive_bias(family, truth, cut):
    rng = np.random.default_rng(11)
    x = FAMILIES[family].frozen(truth).rvs(size=6000, random_state=rng)
    x = x[x >= cut]
    tb = F.truncation_bias(x, cut, families=(family,), n_boot=60, seed=3)
    for _, row in tb.iterrows():
        t = truth[row["param"]]
        assert row["truncated_lo"] <= t <= row["truncated_hi"], row.to_dict()
        # naive estimate lies outside the truncation-aware interval and is farther from truth
        assert not (row["truncated_lo"] <= row["naive"] <= row["truncated_hi"])
        assert abs(row["naive"] - t) > 3 * abs(row["truncated"] - t)
        assert row["rejected"] == "" and np.isfinite(row["naive_bias_rel"])


def test_truncation_bias_gives_no_bias_against_a_rejected_fit():
    # truncated log-normal areas: the truncated Gamma runs to alpha -> 0 (rejected)
    rng = np.random.default_rng(11)
    a = rng.lognormal(np.log(2e-5), 1.5, 4000)
    a = a[a >= 1e-5][:800]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tb = F.truncation_bias(a, 1e-5, n_boot=0).set_index(["family", "param"])
    gamma = tb.loc["gamma"]
    assert (gamma["rejected"] != "").all() and gamma["naive_bias_rel"].isna().all()
    assert (tb.loc["lognormal", "rejected"] == "").all()
    assert np.isfinite(tb.loc["lognormal", "naive_bias_rel"]).all()


def test_per_observation_cuts():
    # images of different rod lengths: l_min/L differs from image to image
    rng = np.random.default_rng(5)
    xs, cs = [], []
    for L in rng.uniform(1000, 3000, 12):
        c = 1.0 / L
        x = rng.gamma(0.8, 4e-3, 800)
        x = x[x >= c]
        xs.append(x)
        cs.append(np.full(x.size, c))
    x, c = np.concatenate(xs), np.concatenate(cs)
    r = F.fit_family(x, "gamma", truncation=c, n_boot=40, seed=1, gof=False)
    assert r.ci["alpha"][0] <= 0.8 <= r.ci["alpha"][1]
    e = F.fit_family(x, "exponential", truncation=c, n_boot=0, gof=False)
    assert e.params["mu"] == pytest.approx(np.mean(x - c))
    with pytest.raises(ParameterError):
        F.fit_family(x, "gamma", truncation=c[:-1])
    with pytest.raises(ParameterError):
        F.fit_family(x - 1.0, "gaussian", truncation=c)


def test_goodness_of_fit_rejects_wrong_law_and_matches_scipy_path():
    rng = np.random.default_rng(3)
    x = rng.lognormal(0.0, 1.0, 400)
    wrong = F.fit_family(x, "exponential", n_boot=0, n_mc=49, seed=1)
    right = F.fit_family(x, "lognormal", n_boot=0, n_mc=49, seed=1)
    assert wrong.pvalue <= 0.02
    assert right.pvalue > 0.02
    # the hand-written parametric bootstrap (used for truncated fits) with a cut of 0 is the
    # same test as scipy.stats.goodness_of_fit: same statistic, compatible p-value
    cut0 = F.fit_family(x, "lognormal", truncation=0.0, n_boot=0, n_mc=49, seed=1)
    assert cut0.statistic == pytest.approx(right.statistic, rel=1e-6)
    assert abs(cut0.pvalue - right.pvalue) < 0.3


def test_truncated_gof_detects_wrong_law():
    rng = np.random.default_rng(9)
    x = rng.lognormal(0.0, 0.6, 1500)
    x = x[x >= 0.5]
    r = F.fit_family(x, "exponential", truncation=0.5, n_boot=0, n_mc=39, seed=2)
    assert r.pvalue <= 0.05
    ok = F.fit_family(x, "lognormal", truncation=0.5, n_boot=0, n_mc=39, seed=2)
    assert ok.pvalue > 0.05


def test_fit_all_table_and_drops():
    rng = np.random.default_rng(4)
    x = np.concatenate([rng.exponential(1.0, 300), [np.nan]])
    with pytest.warns(F.LeftOutWarning, match=r"1 of 301 observations left out of the fit: "
                                            r"1 not finite"):
        s = F.fit_all(x, truncation=0.1, seed=0, n_boot=20, n_mc=19)
    assert s.n_dropped == 1 + int(np.sum(x[:-1] < 0.1))
    t = s.table
    assert set(t["family"]) == set(F.PAPER_FAMILIES)
    assert t["selected"].sum() == 1 and t.loc[t["selected"], "family"].item() == s.best
    assert t["delta_bic"].min() == 0.0
    assert (t.loc[t["family"] == "bose_einstein", "k"] == 2).all()  # beta + x_hi with a cut
    # positive laws do not apply to non-positive data
    y = rng.normal(0.0, 1.0, 200)
    with pytest.warns(QualityWarning, match=r"laws of x > 0 were not fitted .*"
                                            r"gaussian is selected"):
        s2 = F.fit_all(y, seed=0, n_boot=0, gof=False)
    assert s2.best == "gaussian" and not s2.results["gamma"].ok


def test_seeded_results_are_reproducible():
    x = np.random.default_rng(8).gamma(0.5, 1.0, 300)
    a = F.fit_family(x, "gamma", n_boot=30, n_mc=19, seed=42)
    b = F.fit_family(x, "gamma", n_boot=30, n_mc=19, seed=42)
    assert a.ci == b.ci and a.pvalue == b.pvalue


def test_fit_all_on_small_samples_warns_once_naming_the_law():
    import warnings

    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        summ = F.fit_all([0.1, 0.2, 0.35], n_boot=10, n_mc=9)
    small = [str(w.message) for w in rec if w.category is F.SmallSampleWarning]
    # one for the selection on 3 values, one for the 10 resamples (not one per family)
    assert len(small) == 2, small
    assert any(f"3 values, fewer than the {F.N_SELECT_MIN} samples" in m
               and f"({summ.best}) is indicative only" in m for m in small)
    assert any(m.startswith("n_boot 10: fewer than the 40") for m in small)
    assert all(w.filename == __file__ for w in rec if w.category is F.SmallSampleWarning)


def test_fit_all_on_enough_values_gives_no_small_samples_warning():
    import warnings

    x = np.random.default_rng(0).exponential(1.0, F.N_SELECT_MIN)
    with warnings.catch_warnings():
        warnings.simplefilter("error", F.SmallSampleWarning)
        F.fit_all(x, ("exponential", "gamma"), n_boot=F.N_BOOT_MIN, gof=False)
        F.bootstrap_ci(x, "gamma", n_boot=0)
        F.fit_family(x, "gamma", n_boot=0, gof=False)


@pytest.mark.parametrize("call", [
    lambda x: F.bootstrap_ci(x, "gamma", n_boot=1),
    lambda x: F.fit_family(x, "gamma", n_boot=F.N_BOOT_MIN - 1, gof=False),
])
def test_few_bootstrap_resamples_small_samples_warning(call):
    x = np.random.default_rng(0).gamma(2.5, 0.004, 30)
    with pytest.warns(F.SmallSampleWarning, match=r"n_boot \d+: fewer than the 40 bootstrap"):
        call(x)


@pytest.mark.parametrize("counts", [
    {1: 98, 2: 60, 3: 17, 4: 6},  # a Gaussian fit puts mu near 0.5
    {1: 151, 2: 89, 3: 33, 4: 12, 5: 4, 7: 1, 9: 1},  # ... and near -6
])
def test_count_gaussian_with_its_mean_below_every_count_is_rejected(counts):
    x = np.repeat(list(counts), list(counts.values())).astype(float)
    r = F.fit_family(x, "gaussian", n_boot=0, gof=False, discrete=True)
    assert r.params["mu"] < F.COUNT_MIN
    assert "below the smallest count" in r.rejected and not r.selectable
    summ = F.fit_all(x, ("exponential", "gaussian"), n_boot=0, gof=False, discrete=True)
    assert summ.best == "exponential"


def test_count_gaussian_around_a_typical_count_is_kept():
    x = 1.0 + np.random.default_rng(3).poisson(6.0, 300)
    r = F.fit_family(x, "gaussian", n_boot=0, gof=False, discrete=True)
    assert r.params["mu"] > F.COUNT_MIN and r.rejected == ""


@pytest.mark.parametrize("shape, n", [(0.4, 5), (20.0, 5), (3.0, 30)])
def test_the_gamma_shape_interval_holds_the_shape_as_often_as_it_says(shape, n):
    from crosssection.stats.tables import gamma_shape_mle

    # T = log(mean) - mean(log) has a law of the shape alone: the interval's coverage does not
    # fall at a handful of values, where the percentile bootstrap's is about 0.6
    rng = np.random.default_rng(11)
    hits = []
    for _ in range(300):
        x = rng.gamma(shape, 7.0, n)
        lo, hi = F.gamma_shape_interval(x, 0.9)
        assert lo < gamma_shape_mle(x.mean(), np.log(x).mean()) < hi
        hits.append(lo <= shape <= hi)
    # 300 draws of a 0.9 coverage: 0.90 +- 0.017 (1 sd)
    assert 0.85 < np.mean(hits) < 0.95
    # no scale in it
    assert F.gamma_shape_interval(3.5 * x, 0.9) == pytest.approx((lo, hi), rel=1e-9)


@pytest.mark.parametrize("family, n", [("lognormal", 5), ("lognormal", 40), ("gaussian", 8),
                                       ("exponential", 4), ("exponential", 40)])
def test_normal_intervals_hold_as_often_as_they_say(family, n):
    # the percentile bootstrap held the log-normal sigma in 82 % of samples of 40 values at
    # the 95 % level; these intervals' laws do not depend on the parameters
    rng = np.random.default_rng(13)
    hits = {}
    for _ in range(300):
        if family == "exponential":
            x = rng.exponential(2.5, n)
            ci = {"mu": F.exponential_mean_interval(x, 0.9)}
            truth = {"mu": 2.5}
        else:
            y = rng.normal(1.5, 0.7, n)
            ci = F.normal_intervals(y, 0.9)
            truth = {"mu": 1.5, "sigma": 0.7}
            mle = {"mu": y.mean(), "sigma": y.std()}
            assert all(ci[k][0] < mle[k] < ci[k][1] for k in ci)
        for k, (lo, hi) in ci.items():
            hits.setdefault(k, []).append(lo <= truth[k] <= hi)
    for k, h in hits.items():
        # 300 draws of a 0.9 coverage: 0.90 +- 0.017 (1 sd)
        assert 0.85 < np.mean(h) < 0.95, (k, np.mean(h))


def test_fits_of_independent_values_take_the_exact_intervals():
    rng = np.random.default_rng(4)
    x = rng.lognormal(0.3, 0.8, 30)
    r = F.fit_family(x, "lognormal", n_boot=100, seed=1, gof=False)
    assert r.ci["mu"] == pytest.approx(F.normal_intervals(np.log(x))["mu"])
    assert r.ci["sigma"] == pytest.approx(F.normal_intervals(np.log(x))["sigma"])
    y = rng.normal(5.0, 2.0, 30)
    r = F.fit_family(y, "gaussian", n_boot=100, seed=1, gof=False)
    assert r.ci["sigma"] == pytest.approx(F.normal_intervals(y)["sigma"])
    e = rng.exponential(3.0, 30)
    r = F.fit_family(e, "exponential", n_boot=100, seed=1, gof=False)
    assert r.ci["mu"] == pytest.approx(F.exponential_mean_interval(e))
    # grouped values keep the cluster bootstrap
    g = np.repeat(np.arange(15), 2)
    rg = F.fit_family(x, "lognormal", n_boot=100, seed=1, gof=False, groups=g)
    assert rg.ci["sigma"] != pytest.approx(F.normal_intervals(np.log(x))["sigma"])
    assert np.isnan(F.normal_intervals([2.0, 2.0, 2.0])["sigma"]).all()
    assert np.isnan(F.exponential_mean_interval([0.0, 0.0])).all()


def test_the_gamma_fit_of_independent_values_takes_the_shape_interval():
    x = np.random.default_rng(2).gamma(20.0, 1.0, 6)
    r = F.fit_family(x, "gamma", n_boot=200, seed=1)
    assert r.ci["alpha"] == pytest.approx(F.gamma_shape_interval(x))
    # grouped values keep the cluster bootstrap (their groups are not independent draws)
    g = np.repeat(np.arange(3), 2)
    rg = F.fit_family(x, "gamma", n_boot=200, seed=1, groups=g)
    assert rg.ci["alpha"] != pytest.approx(F.gamma_shape_interval(x))
    assert np.isnan(F.gamma_shape_interval([2.0, 2.0, 2.0])).all()
    # values all but equal: the shape is bounded below only, and says so
    lo, hi = F.gamma_shape_interval([10.0, 10.0 + 1e-7])
    assert lo >= 1e5 and hi == np.inf
