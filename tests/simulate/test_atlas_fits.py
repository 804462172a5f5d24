"""The fits sweep of the atlas (``simulate/atlas_fits.py``): sample size against model
selection, bootstrap coverage, detection-limit bias, and its hook into ``benchmark``."""
import math

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ParameterError
from simulate import atlas
from simulate import atlas_fits as A
from simulate.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def fits_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("fits")
    return out, A.run_fits(out, A.FitsConfig.tiny(), seed=3, command="test command")


def test_tables_are_sane(fits_report):
    out, res = fits_report
    cfg = A.FitsConfig.tiny()
    raw = pd.read_csv(out / "fits_sample_size.csv")
    assert len(raw) == len(cfg.cases) * len(cfg.sizes) * cfg.reps
    assert set(raw["case"]) == set(cfg.cases) and set(raw["n"]) == set(cfg.sizes)
    for c in ("correct", "aic_correct", "bic_correct", "within_2", "true_rejected"):
        assert raw[c].isin([True, False]).all(), c
    # the selected family is always one of the quantity's candidates (or none)
    for case, g in raw.groupby("case"):
        assert set(g["selected"].fillna("")) <= set(A.CASES[case].candidates) | {""}
    # a correct pick is a pick of the true family
    assert (raw["correct"] == (raw["selected"] == raw["family"])).all()
    cov = raw["covered"].dropna()
    assert cov.isin([0.0, 1.0]).all()
    assert (raw.loc[raw["rep"] >= cfg.ci_reps, "covered"].isna()).all()
    ok = raw.dropna(subset=["param_lo"])
    assert (ok["param_lo"] <= ok["param_hi"]).all()

    s = pd.read_csv(out / "fits_sample_size_summary.csv")
    assert len(s) == len(cfg.cases) * len(cfg.sizes)
    for c in ("rate_selected", "rate_aic", "rate_bic", "rate_within_2", "coverage"):
        v = s[c].dropna()
        assert len(v) and v.between(0, 1).all(), c
    assert (s["rate_selected_lo"] <= s["rate_selected"]).all()
    assert (s["rate_selected"] <= s["rate_selected_hi"]).all()
    # the module's rule picks among the fits within BIC 2 of the best: it can only pick the
    # true family when the true family is within 2
    assert (s["rate_selected"] <= s["rate_within_2"] + 1e-12).all()

    t = pd.read_csv(out / "fits_truncation_summary.csv")
    assert len(t) == len(cfg.trunc_cases) * len(cfg.trunc_levels)
    assert t["hidden_fraction"].between(0, 1).all()
    assert (t.loc[t["level"] == 0, "hidden_fraction"] == 0).all()
    assert (t.loc[t["level"] > 0, "hidden_fraction"] > 0).all()
    # no cut: the naive and the truncation-aware fit are the same fit
    z = t[t["level"] == 0]
    assert np.allclose(z["naive_rel_bias"], z["truncated_rel_bias"])


def test_charts_and_index(fits_report):
    out, res = fits_report
    assert set(res["charts"]) == {"fits_selection", "fits_coverage", "fits_truncation"}
    index = (out / "index.md").read_text()
    for name in res["charts"]:
        data = (out / f"{name}.png").read_bytes()
        assert data[:8] == PNG_MAGIC and len(data) > 20_000, name
        assert f"]({name}.png)" in index
    for name in res["tables"]:
        assert f"]({name}.csv)" in index
    assert "test command" in index
    assert res["reading"] and res["reading"] in index
    # the section for the atlas index points into the subfolder
    assert "](fits/fits_selection.png)" in A.index_section(res)


def test_lines_of_equal_rates_stay_told_apart(fits_report):
    # two cases of equal coverage and selection rates at every n: one line hid the other
    _, res = fits_report
    s = res["tables"]["fits_sample_size_summary"].copy()
    assert s["case"].nunique() == 2
    s["coverage"], s["rate_selected"] = 0.75, 1.0
    for fig, gid in ((A._coverage_chart(s), "coverage:{}"),
                     (A._selection_chart(s), "rate:rate_selected:{}")):
        lines = [next(ln for ln in fig.axes[0].lines if ln.get_gid() == gid.format(c))
                 for c in s["case"].unique()]
        a, b = lines
        assert np.array_equal(a.get_ydata(), b.get_ydata())
        assert a.get_linestyle() != b.get_linestyle()
        # the markers sit side by side, not on top of each other
        assert (np.asarray(a.get_xdata()) != np.asarray(b.get_xdata())).all()


def test_selection_rate_grows_with_n_in_a_separable_case():
    # Gamma alpha = 0.31 against the paper's five laws: hard at n = 20, easy at n = 1000
    rows = (A.sample_size_rows("e_sim", 20, seed=5, reps=12, ci_reps=0, n_boot=0)
            + A.sample_size_rows("e_sim", 1000, seed=5, reps=12, ci_reps=0, n_boot=0))
    s = A.summarize_sample_size(pd.DataFrame(rows)).set_index("n")
    assert s.loc[1000, "rate_selected"] >= 11 / 12
    assert s.loc[20, "rate_selected"] < s.loc[1000, "rate_selected"]
    assert s.loc[1000, "rate_within_2"] == 1.0
    # the fitted shape converges on the truth
    assert abs(s.loc[1000, "rel_bias"]) < 0.05
    assert s.loc[1000, "rel_sd"] < s.loc[20, "rel_sd"]


def test_naive_truncation_bias_has_the_expected_sign():
    # exponential: memoryless, the naive mu is mu + c, so its bias is the cut level itself;
    # the truncation-aware fit is unbiased
    e = pd.DataFrame(A.truncation_rows("length_exp", 0.2, seed=2, reps=4, n=800,
                                       select=False))
    assert 0.14 < e["naive_rel_bias"].mean() < 0.26
    assert abs(e["truncated_rel_bias"].mean()) < 0.06
    assert np.allclose(e["naive_mean"], e["sample_mean"])  # naive exponential mu = <x>
    # Gamma alpha < 1: cutting the divergent small values makes the law look less divergent
    g = pd.DataFrame(A.truncation_rows("length_sim", 0.2, seed=2, reps=3, n=800,
                                       select=False))
    assert g["naive_rel_bias"].mean() > 0.3
    assert abs(g["truncated_rel_bias"].mean()) < g["naive_rel_bias"].mean() / 3
    # log-normal: the cut narrows ln s (sigma down) and raises the sample mean
    ln = pd.DataFrame(A.truncation_rows("area_exp", 0.2, seed=2, reps=3, n=800,
                                        select=False))
    assert ln["naive_rel_bias"].mean() < -0.03
    assert (ln["sample_mean_rel_error"] > 0).all()
    assert abs(ln["truncated_rel_bias"].mean()) < abs(ln["naive_rel_bias"].mean())


def test_truncated_case_is_fitted_above_its_cut():
    case = A.CASES["length_exp"]
    x = A.draw_case(case, 500, np.random.default_rng(0))
    assert x.min() >= case.cut and case.cut > 0
    (row,) = A.sample_size_rows("length_exp", 40, seed=1, reps=1, ci_reps=1, n_boot=10)
    assert row["selected"] in case.candidates
    assert row["covered"] in (0.0, 1.0)
    assert row["param_lo"] < row["param_hi"]


def test_counts_and_positive_draws():
    x = A.draw_case(A.CASES["n_br"], 4000, np.random.default_rng(1))
    assert (x >= 1).all() and np.array_equal(x, np.round(x))
    # exponential mu = 1/ln(4/3) discretised on n >= 1 is geometric with mean 4
    assert abs(x.mean() - 4.0) < 0.2
    y = A.draw_case(A.CASES["shape_ratio"], 2000, np.random.default_rng(1))
    assert (y > 0).all() and abs(y.mean() - 0.19) < 0.005


def test_law_mean_matches_draws():
    rng = np.random.default_rng(4)
    for name in ("e_sim", "length_sim", "area_exp"):
        case = A.CASES[name]
        x = A.draw_case(case, 200_000, rng, cut=0)
        assert math.isclose(x.mean(), A.law_mean(case.family, case.law), rel_tol=0.03), name


def test_stable_n():
    s = pd.DataFrame({"case": ["a"] * 4 + ["b"] * 3,
                      "n": [20, 50, 100, 200, 20, 50, 100],
                      "rate_selected": [0.95, 0.85, 0.92, 0.97, 0.5, 0.6, 0.7]})
    assert A.stable_n(s, "a") == 100  # the dip at 50 moves it past 20
    assert A.stable_n(s, "b") is None
    assert A.stable_n(s, "b", rate=0.6) == 50


def test_points_are_seeded_by_their_key():
    a = A.sample_size_rows("shape_ratio", 30, seed=7, reps=2, ci_reps=1, n_boot=15)
    b = A.sample_size_rows("shape_ratio", 30, seed=7, reps=3, ci_reps=1, n_boot=15)
    c = A.sample_size_rows("shape_ratio", 30, seed=8, reps=2, ci_reps=1, n_boot=15)
    drop = lambda rows: [{k: v for k, v in r.items() if k != "fit_s"} for r in rows]  # noqa: E731
    assert drop(a) == drop(b)[:2]  # a repetition does not depend on how many there are
    assert drop(a) != drop(c)


def test_config_is_checked():
    with pytest.raises(ParameterError, match="unknown fits case"):
        A.FitsConfig("x", cases=("nope",)).check()
    with pytest.raises(ParameterError, match="mean"):
        A.FitsConfig("x", trunc_cases=("area_sim",)).check()
    with pytest.raises(ParameterError):
        A.FitsConfig("x", trunc_levels=(1.5,)).check()
    assert A.FitsConfig.for_atlas("quick").name == "quick"
    assert A.FitsConfig.for_atlas("full").name == "full"
    assert A.FitsConfig.for_atlas("tiny").name == "tiny"


def test_redraw_rebuilds_the_report(fits_report, tmp_path):
    out, res = fits_report
    for name in ("fits_sample_size", "fits_truncation"):
        (tmp_path / f"{name}.csv").write_bytes((out / f"{name}.csv").read_bytes())
    again = A.redraw(tmp_path)
    pd.testing.assert_frame_equal(again["tables"]["fits_sample_size_summary"],
                                  res["tables"]["fits_sample_size_summary"])
    assert again["reading"] == res["reading"]


def test_benchmark_cli_runs_the_fits_sweep(tmp_path, monkeypatch, capsys):
    # the quick sizes, cut to the tiny ones so that the test stays short
    monkeypatch.setattr(A.FitsConfig, "quick", classmethod(lambda cls: A.FitsConfig.tiny()))
    out = tmp_path / "report"
    assert main(["benchmark", "--out", str(out), "--quick", "--sweeps", "fits"]) == 0
    # the charts it says are those it wrote, the fits sweep's included
    pngs = list(out.rglob("*.png"))
    assert len(pngs) == 3
    assert f"; 3 charts (3 under {out / 'fits'}), index in" in capsys.readouterr().out
    index = (out / "index.md").read_text()
    assert "## fits" in index and "](fits/fits_selection.png)" in index
    assert "--sweeps fits" in index
    for name in ("fits_sample_size", "fits_truncation", "fits_sample_size_summary",
                 "fits_truncation_summary"):
        assert len(pd.read_csv(out / "fits" / f"{name}.csv"))
    # no scene sweep ran
    assert not list(out.glob("resolution.*"))
    fits_index = (out / "fits" / "index.md").read_text()
    assert "python -m simulate benchmark" in fits_index


def test_fits_is_a_known_sweep_name():
    assert "fits" in atlas.ALL_SWEEPS and "fits" not in atlas.SWEEPS
    assert atlas._check_sweeps("fits,noise") == ("fits", "noise")
    with pytest.raises(ParameterError, match="fits"):
        atlas._check_sweeps("nonsense")  # the message lists the known sweeps, fits included
