"""Fits of observations in groups: the branches of a scan's stack repeat one value.

A sample of G independent values, each repeated by its group's size, holds G values of
information, not as many as its rows: the intervals resample whole groups, the p-value draws
one value per group, and model selection counts groups (:mod:`crosssection.stats.fits`).
"""
import warnings

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ParameterError
from crosssection.stats import fits as F
from crosssection.stats.data import Ensemble, branch_groups
from crosssection.stats.tables import StatsOptions, fit_quantity

ALPHA, CHI = 0.6, 2.0


def _repeated(seed, n_groups=150):
    """Gamma values of ``n_groups`` stacks, each repeated 1-4 times, and the stack labels."""
    rng = np.random.default_rng(seed)
    sizes = rng.integers(1, 5, n_groups)
    x = np.repeat(rng.gamma(ALPHA, CHI, n_groups), sizes)
    return x, np.repeat(np.arange(n_groups), sizes), sizes


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", F.SmallSampleWarning)
        yield


def test_cluster_bootstrap_is_wider_by_the_root_of_the_design_effect():
    # repeats of one value are no new information: the spread of the estimates is that of
    # the weighted mean of n_groups values, sqrt(sum s^2 / sum s) times that of the rows
    for seed in (0, 1):
        x, g, sizes = _repeated(seed)
        rows = F.bootstrap_draws(x, "gamma", n_boot=150, seed=seed)
        stacks = F.bootstrap_draws(x, "gamma", n_boot=150, seed=seed, groups=g)
        ratio = np.nanstd(stacks, axis=0) / np.nanstd(rows, axis=0)
        expected = np.sqrt(np.sum(sizes ** 2) / np.sum(sizes))
        assert np.all((ratio > 0.7 * expected) & (ratio < 1.4 * expected)), (ratio, expected)
        lo_r, hi_r = F.bootstrap_ci(x, "gamma", n_boot=150, seed=seed)["alpha"]
        lo_s, hi_s = F.bootstrap_ci(x, "gamma", n_boot=150, seed=seed, groups=g)["alpha"]
        assert hi_s - lo_s > 1.2 * (hi_r - lo_r)


def test_goodness_of_fit_of_the_true_law_is_not_rejected_on_repeated_values():
    grouped, rows = [], []
    for seed in range(4):
        x, g, _ = _repeated(10 + seed)
        grouped.append(F.fit_family(x, "gamma", n_boot=0, n_mc=39, seed=seed,
                                    groups=g).pvalue)
        rows.append(F.fit_family(x, "gamma", n_boot=0, n_mc=39, seed=seed).pvalue)
    # treated as independent rows the repeats look like a misfit (p near its floor 1/40)
    assert np.median(rows) <= 0.1
    assert np.median(grouped) > 0.15 and min(grouped) > 1 / 40, grouped


def test_groups_none_is_the_ungrouped_procedure():
    x, _, _ = _repeated(3, n_groups=60)
    kw = dict(n_boot=40, n_mc=19, seed=5)
    a, b = F.fit_family(x, "gamma", **kw), F.fit_family(x, "gamma", groups=None, **kw)
    assert a == b and a.n_groups == a.n == x.size
    np.testing.assert_array_equal(a.boot, b.boot)
    assert a.bic == a.k * np.log(a.n) - 2 * a.loglik


@pytest.mark.parametrize("truncated", [False, True])
def test_distinct_groups_are_no_groups(truncated):
    x, _, _ = _repeated(4, n_groups=60)
    cut = np.quantile(x, 0.1) if truncated else None
    kw = dict(n_boot=40, n_mc=19, seed=7, truncation=cut)
    labels = [f"b{i}" for i in range(x.size)]
    a = F.fit_all(x, ("exponential", "gamma"), **kw)
    b = F.fit_all(x, ("exponential", "gamma"), groups=labels, **kw)
    pd.testing.assert_frame_equal(a.table, b.table)
    for f in a.results:
        np.testing.assert_array_equal(a.results[f].boot, b.results[f].boot)
    xs = x[x >= cut] if truncated else x
    assert F.goodness_of_fit(xs, "gamma", a.results["gamma"].params, truncation=cut, n_mc=19,
                             groups=np.arange(xs.size)) == F.goodness_of_fit(
        xs, "gamma", a.results["gamma"].params, truncation=cut, n_mc=19)


@pytest.mark.parametrize("call", [
    lambda x, g: F.fit_family(x, "gamma", n_boot=0, gof=False, groups=g),
    lambda x, g: F.fit_all(x, n_boot=0, gof=False, groups=g),
    lambda x, g: F.bootstrap_draws(x, "gamma", n_boot=2, groups=g),
    lambda x, g: F.bootstrap_ci(x, "gamma", n_boot=2, groups=g),
    lambda x, g: F.goodness_of_fit(x, "gamma", {"alpha": 1.0, "chi": 1.0}, n_mc=2, groups=g),
])
def test_groups_of_another_length_are_refused(call):
    x = np.random.default_rng(0).gamma(2.0, 1.0, 30)
    with pytest.raises(ParameterError, match="groups has 29 labels, expected 30"):
        call(x, np.arange(29))
    with pytest.raises(ParameterError, match="groups"):
        call(x, "abc")


def test_model_selection_counts_groups():
    # every value repeated three times: the composite likelihood (scaled by n_groups / n)
    # and n_groups give the BIC of the values themselves
    v = np.random.default_rng(2).gamma(ALPHA, CHI, 40)
    rep = F.fit_all(np.repeat(v, 3), ("exponential", "gamma"), n_boot=0, gof=False,
                    groups=np.repeat(np.arange(40), 3))
    one = F.fit_all(v, ("exponential", "gamma"), n_boot=0, gof=False)
    for f in one.results:
        assert rep.results[f].bic == pytest.approx(one.results[f].bic, rel=1e-6)
        assert rep.results[f].params == pytest.approx(one.results[f].params, rel=1e-6)
    assert rep.results["gamma"].n == 120 and rep.results["gamma"].n_groups == 40
    assert list(rep.table["n_groups"]) == [40, 40]
    # 120 rows but 40 stacks: fewer than the values model selection needs
    with pytest.warns(F.SmallSampleWarning, match="120 values in 40 independent groups"):
        F.fit_all(np.repeat(v, 3), ("exponential", "gamma"), n_boot=0, gof=False,
                  groups=np.repeat(np.arange(40), 3))


def _branches(stack_id, n=30):
    n = n if stack_id is None else len(stack_id)
    rng = np.random.default_rng(0)
    e = rng.gamma(ALPHA, CHI, n)
    return pd.DataFrame({"set": "s", "config_id": "c1", "length_L": e, "kappa_m_L": e,
                         "kappa_plus_L": e, "e": e, "region": "none", "n_br": 1.0,
                         "l_min_L": np.nan, **({} if stack_id is None else
                                               {"stack_id": stack_id})})


def test_branch_groups_are_the_stacks_of_scans_and_each_branch_elsewhere():
    br = pd.DataFrame({"set": ["a", "a", "a", "b", "a"], "config_id": ["1", "1", "2", "1", "1"],
                       "stack_id": [0, 0, 0, 0, np.nan]})
    g = branch_groups(br)
    assert g[0] == g[1] and len({g[0], g[2], g[3]}) == 3 and g[4] is None
    # a hand-built ensemble without the column: each branch its own group
    ens = Ensemble(pd.DataFrame(), _branches(None), pd.DataFrame(), pd.DataFrame())
    assert ens.branches["stack_id"].isna().all()
    assert all(v is None for v in branch_groups(ens.branches))


def test_fits_of_scan_branches_rest_on_their_stacks():
    sid = np.repeat(np.arange(60), 2)
    br = _branches(sid)
    br["e"] = np.repeat(br["e"].to_numpy()[::2], 2)  # a stack's branches share its energy
    ens = Ensemble(pd.DataFrame(), br, pd.DataFrame(), pd.DataFrame())
    opts = StatsOptions(n_boot=0, gof=False, quantities=("e",))
    summ, _, _ = fit_quantity(ens, "e", "all", opts, np.random.SeedSequence(0))
    assert set(summ.table["n"]) == {120} and set(summ.table["n_groups"]) == {60}
