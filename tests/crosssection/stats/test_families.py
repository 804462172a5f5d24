"""The family registry, the power law with cutoff, and the rejection of degenerate fits."""
import numpy as np
import pytest
from scipy import integrate, stats

from crosssection.stats import families as FM
from crosssection.stats import fits as F
from crosssection.stats.families import FAMILIES

# one law per family, with a cut inside its bulk for the truncated checks
EXAMPLES = {
    "exponential": ({"mu": 2.0}, 0.5),
    "gamma": ({"alpha": 0.6, "chi": 3.0}, 0.2),
    "lognormal": ({"mu": 0.3, "sigma": 0.8}, 0.6),
    "gaussian": ({"mu": 1.0, "sigma": 0.4}, 0.7),
    "bose_einstein": ({"alpha": np.nan, "beta": 2.0, "x_lo": 0.05, "x_hi": 3.0}, 0.1),
    "powerlaw_cutoff": ({"tau": 1.6, "chi": 4.0, "x_min": 0.05}, 0.05),
}


def test_registry_is_complete_and_consistent():
    assert set(EXAMPLES) == set(FAMILIES)
    assert set(F.PAPER_FAMILIES) < set(FAMILIES)
    for name, fam in FAMILIES.items():
        assert fam.name == name and fam.title
        assert set(fam.free_names) <= set(fam.param_names)
        assert len(fam.log_params) == len(fam.free_names)
        assert fam.k(True) <= fam.k(False)
    assert F.MAX_PARAMS == 4  # Bose-Einstein: alpha, beta, x_lo, x_hi


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_density_integrates_to_one_and_sampler_matches_pit(name):
    fam = FAMILIES[name]
    params, cut = EXAMPLES[name]
    lo = params.get("x_lo", params.get("x_min", -np.inf if not fam.positive else 0.0))
    hi = params.get("x_hi", np.inf)
    total = integrate.quad(lambda v: fam.pdf(params, np.array([v]))[0], lo, hi, limit=400)[0]
    assert total == pytest.approx(1.0, rel=1e-6)
    rng = np.random.default_rng(len(name))
    for c in (None, cut):
        x = fam.sample(params, 4000, c, rng)
        assert np.all(np.isfinite(x)) and (c is None or np.all(x >= c))
        u = fam.pit(params, x, None if c is None else np.full(x.size, c))
        assert stats.kstest(u, "uniform").pvalue > 1e-3, (name, c)


@pytest.mark.parametrize("s", [-2.0, -1.0, -0.5, 0.0, 1e-9, 0.4, 1.0, 2.5])
def test_log_upper_gamma_matches_quadrature(s):
    z = np.array([1e-6, 0.05, 0.9, 1.0, 4.0, 60.0])
    got = FM.log_upper_gamma(s, z)
    for zi, g in zip(z, got):  # integral of t^(s-1) e^(-t) from z, with t = z e^u
        # far in the tail e^u overflows to inf, where the integrand is exactly 0 (e^-inf)
        with np.errstate(over="ignore"):
            ref = integrate.quad(lambda u: np.exp(s * (np.log(zi) + u) - zi * np.exp(u)), 0,
                                 np.inf, limit=400, epsrel=1e-12)[0]
        assert g == pytest.approx(np.log(ref), abs=1e-9)


@pytest.mark.parametrize("tau,chi,cut", [(1.5, 2.0, 0.01), (2.2, 50.0, 0.1), (3.0, 0.5, 0.02)])
def test_powerlaw_cutoff_recovers_known_parameters(tau, chi, cut):
    fam = FAMILIES["powerlaw_cutoff"]
    rng = np.random.default_rng(int(10 * tau))
    x = fam.sample({"tau": tau, "chi": chi, "x_min": cut}, 1500, cut, rng)
    r = F.fit_family(x, "powerlaw_cutoff", truncation=cut, n_boot=100, seed=1, gof=False)
    assert r.k == 2 and r.params["x_min"] == cut
    assert r.ci["tau"][0] <= tau <= r.ci["tau"][1]
    assert r.ci["chi"][0] <= chi <= r.ci["chi"][1]
    assert r.params["tau"] == pytest.approx(tau, abs=0.15)
    # without a detection limit the sample minimum is x_min, counted as a parameter
    free = F.fit_family(x, "powerlaw_cutoff", n_boot=0, gof=False)
    assert free.k == 3 and free.params["x_min"] == x.min()
    assert free.params["tau"] == pytest.approx(tau, abs=0.15)


def test_powerlaw_cutoff_is_selected_for_void_like_areas_and_passes_gof():
    rng = np.random.default_rng(21)
    fam = FAMILIES["powerlaw_cutoff"]
    x = fam.sample({"tau": 1.8, "chi": 0.02, "x_min": 1e-5}, 600, 1e-5, rng)
    fams = ("exponential", "gamma", "lognormal", "gaussian", "powerlaw_cutoff")
    s = F.fit_all(x, fams, truncation=1e-5, seed=2, n_boot=0, gof=False)
    assert s.best == "powerlaw_cutoff"
    pl = F.fit_family(x[:300], "powerlaw_cutoff", truncation=1e-5, n_boot=0, n_mc=19, seed=1)
    assert pl.pvalue > 0.05
    ex = F.fit_family(x, "exponential", truncation=1e-5, n_boot=0, n_mc=19, seed=1)
    assert ex.pvalue <= 1 / 20 and ex.p_text() == "p < 1/20"  # at the Monte-Carlo floor
    # the Gamma law cannot go below alpha = 0: rejected with the reason
    assert "alpha" in s.results["gamma"].rejected


def test_powerlaw_below_one_defers_to_the_truncated_gamma():
    rng = np.random.default_rng(8)
    x = rng.gamma(0.6, 2.0, 4000)
    x = x[x >= 0.1]
    s = F.fit_all(x, ("gamma", "powerlaw_cutoff"), truncation=0.1, seed=0, n_boot=0,
                  gof=False)
    pl, ga = s.results["powerlaw_cutoff"], s.results["gamma"]
    assert pl.params["tau"] == pytest.approx(1 - ga.params["alpha"], abs=1e-3)
    assert pl.loglik == pytest.approx(ga.loglik, abs=1e-4)
    assert "truncated Gamma" in pl.rejected and s.best == "gamma"


def test_degenerate_truncated_gaussian_is_rejected_not_selected():
    # positive, exponential-like data above a cut: the truncated Gaussian runs its mean far
    # below the data (the fitted law is a far Gaussian tail, an exponential in disguise)
    rng = np.random.default_rng(3)
    x = rng.gamma(0.8, 0.01, 1500)
    x = x[x >= 0.003]
    s = F.fit_all(x, ("gaussian", "exponential"), truncation=0.003, seed=0, n_boot=10,
                  n_mc=19)
    g = s.results["gaussian"]
    assert g.ok and "below the data" in g.rejected
    assert g.params["mu"] < 0.003 - 10 * g.params["sigma"] or \
        g.params["mu"] < 0.003 - 5 * np.ptp(x)
    assert g.ci == {} and np.isnan(g.pvalue) and g.p_text() == ""
    assert s.best == "exponential"
    row = s.table.set_index("family").loc["gaussian"]
    assert not row["selected"] and row["rejected"] == g.rejected
    # forcing selection among the degenerate fit alone names no law
    assert F.select_model({"gaussian": g}) is None


def test_degenerate_bose_einstein_is_rejected_and_reports_every_parameter():
    rng = np.random.default_rng(6)
    x = np.exp(rng.uniform(np.log(1e-3), np.log(10.0), 500))  # a 1/x law: beta x << 1
    r = F.fit_family(x, "bose_einstein", n_boot=0, gof=False)
    assert "beta" in r.rejected and not r.selectable
    assert set(r.params) == {"alpha", "beta", "x_lo", "x_hi"}
    good = F.fit_family(FM.be_ppf(rng.uniform(size=500), 3.0, 0.01, 2.0), "bose_einstein",
                        n_boot=20, seed=1, n_mc=19)
    assert not good.rejected and good.selectable
    assert set(good.ci) == {"alpha", "beta", "x_lo", "x_hi"}
    for name in ("alpha", "beta", "x_lo", "x_hi"):
        assert f"{name}=" in good.label()
    t = F.summary_table({"bose_einstein": good}, "bose_einstein").iloc[0]
    assert [t[f"p{i}_name"] for i in range(1, 5)] == ["alpha", "beta", "x_lo", "x_hi"]
    assert t["p2"] == good.params["beta"] and t["p4"] == good.params["x_hi"]


def test_p_text_floor_and_exact_values():
    def res(p, n_mc):
        return F.FitResult("gamma", {}, 0.0, 0.0, 0.0, 10, 2, pvalue=p, n_mc=n_mc)

    assert res(1 / 200, 199).p_text() == "p < 1/200"
    assert res(2 / 200, 199).p_text() == "p = 0.01"
    assert res(0.37, 99).p_text() == "p = 0.37"
    assert res(float("nan"), 0).p_text() == ""
    # the resamples actually used set the floor (here scipy's path: all n_mc)
    x = np.random.default_rng(2).lognormal(0.0, 1.0, 300)
    r = F.fit_family(x, "exponential", n_boot=0, n_mc=19, seed=0)
    assert r.n_mc == 19 and r.pvalue == pytest.approx(1 / 20) and r.p_text() == "p < 1/20"


@pytest.mark.parametrize("name, params", [
    ("exponential", {"mu": 2.5}), ("gamma", {"alpha": 0.4, "chi": 3.0}),
    ("lognormal", {"mu": 0.3, "sigma": 1.2}), ("gaussian", {"mu": 5.0, "sigma": 0.7})])
def test_a_bound_law_gives_its_frozen_distributions_numbers(name, params):
    """The families' laws with their parameters bound (``BoundLaw``, which scipy's frozen
    distributions are not, for speed) give every number the frozen distribution gives."""
    import scipy.stats as st

    from crosssection.stats.families import FAMILIES, BoundLaw

    law = FAMILIES[name].frozen(params)
    assert isinstance(law, BoundLaw)
    frozen = law.rv(*law.args, **law.kwds)
    assert isinstance(frozen, st._distn_infrastructure.rv_continuous_frozen)
    x = np.array([0.05, 0.5, 1.0, 3.0, 12.0])
    q = np.array([0.01, 0.3, 0.5, 0.9, 0.999])
    for method, arg in (("pdf", x), ("logpdf", x), ("cdf", x), ("sf", x), ("logsf", x),
                        ("ppf", q), ("isf", q)):
        np.testing.assert_array_equal(getattr(law, method)(arg), getattr(frozen, method)(arg))
    np.testing.assert_array_equal(law.rvs(size=7, random_state=np.random.default_rng(3)),
                                  frozen.rvs(size=7, random_state=np.random.default_rng(3)))
    assert law.mean() == frozen.mean() and law.support() == frozen.support()
