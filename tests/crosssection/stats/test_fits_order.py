"""The same sample in another row order gives the same fit, intervals and p-value: the
bootstrap and goodness-of-fit draws pick observations and groups by position, so the
observations are put in a canonical order first."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from crosssection.stats import fits as F


@pytest.mark.parametrize("grouped", [False, True])
def test_row_order_changes_nothing(grouped):
    rng = np.random.default_rng(4)
    x = rng.gamma(2.0, 0.5, 80)
    groups = np.repeat(np.arange(40), 2) if grouped else None
    if grouped:  # a scan's branches repeat their stack's value
        x = np.repeat(x[:40], 2)
    perm = rng.permutation(x.size)
    kw = dict(n_boot=40, seed=3, n_mc=19)
    a = F.fit_family(x, "gamma", groups=groups, **kw)
    b = F.fit_family(x[perm], "gamma", groups=None if groups is None else groups[perm] + 7,
                     **kw)
    assert a.params == pytest.approx(b.params, rel=1e-12)
    assert a.ci == b.ci and a.pvalue == b.pvalue
    ci = F.bootstrap_ci(x, "gamma", n_boot=40, seed=3)
    assert ci == F.bootstrap_ci(x[perm], "gamma", n_boot=40, seed=3)


def test_an_infinite_length_leaves_its_configuration_mean_finite():
    from crosssection.stats.data import BRANCH_COLS, CONFIG_COLS, STACK_COLS, VOID_COLS
    from crosssection.stats import Ensemble
    from crosssection.stats.tables import per_config_table

    br = pd.DataFrame({"set": "s", "config_id": "c0", "length_L": [0.01, 0.03, np.inf],
                       "e": [1.0, 2.0, 3.0], "region": "all", "n_br": 1})
    cf = pd.DataFrame({"set": ["s"], "config_id": ["c0"], "N_l": [3], "N_br": [3],
                       "epsilon": [2.0]})
    vo = pd.DataFrame({"set": "s", "config_id": "c0", "area_L2": [1e-4, 4e-4]})
    ens = Ensemble(cf.reindex(columns=CONFIG_COLS), br.reindex(columns=BRANCH_COLS),
                   pd.DataFrame(columns=STACK_COLS), vo.reindex(columns=VOID_COLS))
    pc = per_config_table(ens)
    assert pc["l_bar"].iloc[0] == pytest.approx(0.02)
    assert np.isfinite(pc["eq12_x"].iloc[0]) and pc["eq12_x"].iloc[0] > 0


def test_a_count_fit_that_never_left_its_stand_in_likelihood_is_rejected():
    x = np.array([1e300, 2e300, 3e300, 1e300, 5e300] * 4)
    s = F.fit_all(x, ("gamma", "lognormal", "gaussian"), discrete=True, n_boot=0, gof=False)
    assert s.best is None
    assert all("did not converge" in r.rejected for r in s.results.values())
