"""Bad and doubtful inputs of the statistics API (fits, tables, figures, loaders): a
ParameterError or ConfigError naming the argument or the file, never numpy's or scipy's own
exception nor a leaked RuntimeWarning; values left out of a fit are counted in a warning."""
import json
import math
import warnings

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from crosssection.core.errors import ConfigError, ParameterError
from crosssection.core.schema import write_tables
from crosssection.quality import QualityWarning
from crosssection.stats import (Ensemble, StatsOptions, bootstrap_ci, cli, compute_stats, demo,
                                detect_kind, fit_all, fit_family, goodness_of_fit, load_any,
                                load_report, plot_pdf, select_model, truncation_bias)
from crosssection.cli import main as cli_main
from crosssection.stats.data import BRANCH_COLS, load_image_output, load_inputs
from crosssection.stats.fits import bootstrap_draws

G = stats.gamma(0.5, scale=2).rvs(200, random_state=1)
QUICK = {"n_boot": 0, "gof": False}


def _recorded(fn):
    """(result, warnings) of ``fn()`` with every warning recorded."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn()
    return out, caught


def _of(caught, category):
    return [w for w in caught if issubclass(w.category, category)]


# ------------------------------------------------------------------ non-finite values
@pytest.mark.parametrize("family", ["gamma", "gaussian", "lognormal", "powerlaw_cutoff",
                                    "bose_einstein", "exponential"])
def test_fit_family_leaves_out_nan_with_a_warning(family):
    clean = fit_family(G, family, **QUICK)
    res, caught = _recorded(lambda: fit_family(np.r_[G, np.nan], family, **QUICK))
    (w,) = _of(caught, QualityWarning)
    assert "1 of 201" in str(w.message) and "not finite" in str(w.message)
    assert not _of(caught, RuntimeWarning)
    assert res.n == 200 and res.params == clean.params and res.rejected == clean.rejected


@pytest.mark.parametrize("values", [pd.Series(np.r_[G, np.nan]),
                                    pd.array(np.r_[G, np.nan], dtype="Float64"),
                                    list(np.r_[G, np.inf])])
def test_series_and_lists_with_missing_values_fit_the_same(values):
    with pytest.warns(QualityWarning, match="1 of 201"):
        res = fit_family(values, "gamma", **QUICK)
    assert res.params == fit_family(G, "gamma", **QUICK).params


def test_every_fit_entry_point_warns_about_the_values_it_leaves_out():
    x = np.r_[G, np.nan, np.nan]
    params = fit_family(G, "gamma", **QUICK).params
    with pytest.warns(QualityWarning, match="2 of 202"):
        ci = bootstrap_ci(x, "gamma", n_boot=5, seed=1)
    assert ci == bootstrap_ci(G, "gamma", n_boot=5, seed=1)
    with pytest.warns(QualityWarning, match="2 of 202"):
        gof = goodness_of_fit(x, "gamma", params, n_mc=9, seed=1)
    assert gof == goodness_of_fit(G, "gamma", params, n_mc=9, seed=1)
    with pytest.warns(QualityWarning, match="2 of 202"):
        s = fit_all(x, ["gamma", "exponential"], **QUICK)
    assert s.n_dropped == 2 and s.results["gamma"].n == 200
    with pytest.warns(QualityWarning, match="2 of 202"):
        t = truncation_bias(x, 0.01)
    assert (t["n"] == np.sum(G >= 0.01)).all()
    # an observation whose own cut is not finite is left out the same way
    cuts = np.full(G.size, 0.01)
    cuts[0] = np.nan
    with pytest.warns(QualityWarning, match="1 with a cut that is not finite"):
        r = fit_family(G[G >= 0.01][:150], "gamma", truncation=cuts[:150], **QUICK)
    assert r.n == 149


# ------------------------------------------------------------------ shapes and types
@pytest.mark.parametrize("x, cause", [
    (G.reshape(20, 10), "1-D array of observations, got an array of shape (20, 10)"),
    (3.0, "1-D array of observations, got a single number"),
    (["a", "b", "c"], "must be numbers, got text"),
    ("1 2 3", "must be numbers, got the string"),
    ([[1.0, 2.0], [3.0]], "1-D array of numbers"),
    ([True, False, True], "must be numbers, got booleans"),
    ([1.0, None, "x"], "must be numbers"),
])
def test_fits_need_one_dimensional_numbers(x, cause):
    for call in (lambda: fit_family(x, "gamma", **QUICK),
                 lambda: fit_all(x, **QUICK),
                 lambda: bootstrap_ci(x, "gamma", n_boot=2),
                 lambda: goodness_of_fit(x, "gamma", {"alpha": 1.0, "chi": 1.0}),
                 lambda: truncation_bias(x, 0.1)):
        with pytest.raises(ParameterError) as err:
            call()
        assert err.value.one_line().startswith("x ") and cause in err.value.one_line()


@pytest.mark.parametrize("kwargs, name", [
    ({"n_boot": -1}, "n_boot"), ({"n_boot": 1.5}, "n_boot"),
    ({"n_mc": 0}, "n_mc"), ({"n_mc": -3, "gof": False}, "n_mc"),
    ({"ci_level": 2}, "ci_level"), ({"ci_level": 0.0}, "ci_level"),
    ({"ci_level": float("nan")}, "ci_level"),
    ({"seed": "a"}, "seed"), ({"seed": -1}, "seed"), ({"seed": 0.5}, "seed"),
    ({"family": ["gamma"]}, "family"),
])
def test_absurd_options_are_parameter_errors_naming_them(kwargs, name):
    kw = {"n_boot": 3, "n_mc": 9, "family": "gamma", **kwargs}
    family = kw.pop("family")
    with pytest.raises(ParameterError, match=name):
        fit_family(G, family, **kw)
    if "family" not in kwargs:
        with pytest.raises(ParameterError, match=name):
            fit_all(G, ["gamma"], **kw)


def test_absurd_options_of_the_other_entry_points():
    with pytest.raises(ParameterError, match="level"):
        bootstrap_ci(G, "gamma", level=1.5)
    with pytest.raises(ParameterError, match="n_boot"):
        bootstrap_draws(G, "gamma", n_boot=-1)
    with pytest.raises(ParameterError, match="seed"):
        bootstrap_ci(G, "gamma", n_boot=2, seed="a")
    with pytest.raises(ParameterError, match="n_mc"):
        goodness_of_fit(G, "gamma", fit_family(G, "gamma", **QUICK).params, n_mc=0)
    with pytest.raises(ParameterError, match="n_boot"):
        truncation_bias(G, 0.1, n_boot=-2)
    with pytest.raises(ParameterError, match="delta"):
        select_model(fit_all(G, **QUICK).results, delta=0)


# ------------------------------------------------------------------ degenerate samples
@pytest.mark.parametrize("call, cause", [
    (lambda: bootstrap_ci([], "gamma"), "too few observations (0)"),
    (lambda: bootstrap_ci([1.0], "gamma"), "too few observations (1)"),
    (lambda: bootstrap_ci(np.r_[G, -1.0], "gamma", n_boot=5), "needs x > 0 (1 value <= 0)"),
    (lambda: goodness_of_fit([], "gamma", {"alpha": 0.5, "chi": 2.0}), "too few"),
    (lambda: select_model({"a": 1}), "results['a'] must be a FitResult"),
    (lambda: select_model([1, 2]), "results must be a dict"),
    (lambda: truncation_bias([], 0.1), "x holds no observation"),
    (lambda: truncation_bias(G, 100.0), "no observation at or above its cut"),
    (lambda: truncation_bias(G, None), "truncation is required"),
    (lambda: truncation_bias(G, 0.1, families="weibull"), "unknown family 'weibull'"),
])
def test_degenerate_samples_are_one_line_parameter_errors(call, cause):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # none may leak
        with pytest.raises(ParameterError) as err:
            call()
    assert cause in err.value.one_line() and "\n" not in err.value.one_line()


def test_truncation_bias_on_a_few_values_is_a_table_without_leaked_warnings():
    t, caught = _recorded(lambda: truncation_bias([0.5, 0.7], 0.1))
    assert not _of(caught, RuntimeWarning)
    assert t["truncated"].isna().all() and (t["n"] == 2).all()


# ------------------------------------------------------------------ truncation
@pytest.mark.parametrize("cut", [np.nan, np.inf, -np.inf])
def test_a_non_finite_truncation_is_refused(cut):
    with pytest.raises(ParameterError, match="truncation must be a finite number"):
        fit_family(G, "gamma", truncation=cut, n_boot=10, gof=False)
    with pytest.raises(ParameterError, match="truncation"):
        fit_all(G, truncation=cut, **QUICK)


def test_cuts_outside_a_positive_laws_support_make_it_inapplicable():
    # below 0 a positive law has no mass to truncate: fitted anyway, the exponential would
    # fit x - c and the log-normal reach a log-likelihood of -1e300
    for family in ("exponential", "lognormal", "gamma"):
        r = fit_family(G, family, truncation=-1.0, **QUICK)
        assert not r.ok and "needs a truncation >= 0" in r.note
    # a cut of 0 is no limit for the Gamma law, but none for the power law (x_min > 0)
    assert fit_family(G, "gamma", truncation=0.0, **QUICK).ok
    r = fit_family(G, "powerlaw_cutoff", truncation=0.0, **QUICK)
    assert not r.ok and "needs a truncation > 0" in r.note


# ------------------------------------------------------------------ goodness of fit
def test_goodness_of_fit_tests_the_parameters_it_is_given():
    fitted = fit_family(G, "gamma", **QUICK).params
    own = goodness_of_fit(G, "gamma", fitted, n_mc=19, seed=0)
    other = goodness_of_fit(G, "gamma", {"alpha": 50.0, "chi": 100.0}, n_mc=19, seed=0)
    assert other.statistic > 100 * own.statistic
    assert other.pvalue == pytest.approx(1 / 20)  # at the floor: not that law
    # the fitted parameters still take scipy's path, unchanged
    ref = stats.goodness_of_fit(stats.gamma, G, known_params={"loc": 0.0}, statistic="ad",
                                n_mc_samples=19, random_state=np.random.default_rng(0))
    assert own.statistic == ref.statistic and own.pvalue == ref.pvalue


@pytest.mark.parametrize("params, cause", [
    ({"foo": 1}, "params names ['foo'], not parameters of gamma"),
    ({"alpha": 0.5, "chi": 2.0, "mu": 1.0}, "params names ['mu']"),
    ({"alpha": 0.5}, "params lacks ['chi']"),
    ({"alpha": 0.5, "chi": float("nan")}, "params['chi'] must be a finite number"),
    ({"alpha": "0.5", "chi": 2.0}, "params['alpha'] must be a finite number"),
    ([0.5, 2.0], "params must be a dict"),
])
def test_goodness_of_fit_refuses_parameters_the_family_does_not_have(params, cause):
    with pytest.raises(ParameterError) as err:
        goodness_of_fit(G, "gamma", params, n_mc=9)
    assert cause in err.value.one_line()


# ------------------------------------------------------------------ fit_all
def test_fit_all_says_once_why_the_positive_laws_were_left_out():
    s, caught = _recorded(lambda: fit_all(np.r_[G, -1.0], **QUICK))
    assert s.best == "gaussian"
    (w,) = _of(caught, QualityWarning)
    msg = str(w.message)
    assert "exponential, gamma, lognormal, bose_einstein" in msg
    assert "1 value <= 0" in msg and "gaussian is selected among the others" in msg
    # positive data: not a word
    _, caught = _recorded(lambda: fit_all(G, **QUICK))
    assert not _of(caught, QualityWarning)


def test_fit_all_takes_one_family_name_or_a_list():
    s = fit_all(G, families="gamma", **QUICK)
    assert list(s.results) == ["gamma"] and s.best == "gamma"
    s = fit_all(G, ["gamma", "exponential"], select_from="exponential", **QUICK)
    assert s.best == "exponential"
    with pytest.raises(ParameterError, match="select_from names \\['lognormal'\\]"):
        fit_all(G, ["gamma", "exponential"], select_from=["lognormal"], **QUICK)
    with pytest.raises(ParameterError, match="families must be a family name"):
        fit_all(G, families=3, **QUICK)
    with pytest.raises(ParameterError, match="families is empty"):
        fit_all(G, families=[], **QUICK)


# ------------------------------------------------------------------ tables and figures
def _ensemble(e):
    """One set of branches with energies ``e`` (and the configuration they belong to)."""
    n = len(e)
    br = pd.DataFrame({"set": "s", "config_id": "c0", "length_L": np.linspace(0.01, 0.02, n),
                       "kappa_m_L": 10.0, "kappa_plus_L": 10.0, "e": e, "region": "none",
                       "n_br": np.nan, "l_min_L": np.nan}).reindex(columns=BRANCH_COLS)
    cfg = pd.DataFrame({"set": ["s"], "config_id": ["c0"], "N_l": [n], "N_br": [n],
                        "n_voids": [0], "epsilon": [1.0], "E": [float(np.nansum(e))]})
    return Ensemble.concat([Ensemble(cfg, br, pd.DataFrame(), pd.DataFrame())])


def test_compute_stats_and_plot_pdf_count_the_values_they_leave_out():
    e = np.r_[G, np.nan, np.nan, -1.0, 0.0]
    ens = _ensemble(e)
    opts = StatsOptions(n_boot=0, gof=False, quantities=("e",))
    res, caught = _recorded(lambda: compute_stats(ens, opts))
    (w,) = [w for w in _of(caught, QualityWarning) if "left out" in str(w.message)]
    assert "set s: e: 4 of 204 values left out" in str(w.message)
    assert "2 not finite" in str(w.message) and "2 <= 0" in str(w.message)
    assert (res.fits["n_dropped"] == 4).all()
    import matplotlib

    matplotlib.use("Agg")
    with pytest.warns(QualityWarning, match="4 of 204 values left out"):
        plot_pdf(ens, "e")
    # clean data: no warning
    _, caught = _recorded(lambda: compute_stats(_ensemble(G), opts))
    assert not [w for w in caught if "left out" in str(w.message)]


def test_curvatures_left_out_say_why():
    # 21 % of a compaction's branches at epsilon 30 have no curvature, shorter than a segment:
    # "not finite" alone did not say that the fits then lean to the longer branches
    ens = _ensemble(G)
    ens.branches.loc[:2, "kappa_m_L"] = np.nan
    opts = StatsOptions(n_boot=0, gof=False, quantities=("kappa_m_L",))
    _, caught = _recorded(lambda: compute_stats(ens, opts))
    (w,) = [w for w in _of(caught, QualityWarning) if "left out" in str(w.message)]
    assert "3 not finite (NaN or inf: branches too short to hold a curvature" in str(w.message)
    # the means leave them out too (they keep the values <= 0): the warning says so
    assert "left out of the means as well" in str(w.message)


def test_plot_pdf_bad_arguments_are_parameter_errors():
    ens = _ensemble(G)
    for call, cause in ((lambda: plot_pdf(ens, "weight"), "quantity must be one of"),
                        (lambda: plot_pdf(ens, "e", set_name="nope"), "set_name must be one of"),
                        (lambda: plot_pdf(ens, "E"), "too few positive values of E"),
                        (lambda: plot_pdf(ens, "e", seed="a"), "seed"),
                        (lambda: plot_pdf(None, "e"), "folder must be a folder path")):
        with pytest.raises(ParameterError, match=cause):
            call()
    # callers that caught the ValueError plot_pdf raised before still catch it
    with pytest.raises(ValueError):
        plot_pdf(ens, "weight")


@pytest.mark.parametrize("kwargs, name", [
    ({"n_boot": -1}, "n_boot"), ({"n_mc": 0}, "n_mc"), ({"seed": "a"}, "seed"),
    ({"min_n": 0}, "min_n"), ({"quantities": ("e", "weight")}, "quantities"),
])
def test_stats_options_name_the_absurd_value(kwargs, name):
    with pytest.raises(ParameterError, match=name):
        StatsOptions(**kwargs)


def test_compute_stats_checks_its_arguments():
    with pytest.raises(ParameterError, match="ens must be an Ensemble"):
        compute_stats("batch/")
    with pytest.raises(ParameterError, match="opts must be a StatsOptions"):
        compute_stats(_ensemble(G), {"n_boot": 0})
    opts = StatsOptions(n_boot=0, gof=False, quantities="e")  # one name
    assert opts.quantities == ("e",)
    opts.n_boot = -5  # changed after construction: checked again
    with pytest.raises(ParameterError, match="n_boot"):
        compute_stats(_ensemble(G), opts)


def test_compute_stats_refuses_a_hand_built_ensemble_without_sets_or_with_negative_sizes():
    """A set of NaN gave pandas' merge error; a negative void area a leaked RuntimeWarning."""
    from dataclasses import replace

    ens = _ensemble(G)
    opts = StatsOptions(n_boot=0, gof=False, quantities=("e",))
    with pytest.raises(ParameterError, match=r"ens.configs has 1 row\(s\) without a set"):
        compute_stats(replace(ens, configs=ens.configs.assign(set=np.nan)), opts)
    with pytest.raises(ParameterError, match="ens.branches.length_L holds 1 negative"):
        compute_stats(replace(ens, branches=ens.branches.assign(
            length_L=np.r_[-1.0, np.ones(len(ens.branches) - 1)])), opts)


def test_cli_refuses_zero_gof_resamples(tmp_path):
    import argparse

    p = argparse.ArgumentParser()
    cli.add_subparser(p.add_subparsers(dest="command"))
    args = p.parse_args(["stats", "d", "--out", str(tmp_path / "r"), "--n-mc", "0"])
    with pytest.raises(ParameterError) as err:
        cli.check_options(args)
    assert err.value.one_line().startswith("--n-mc: ")
    cli.check_options(p.parse_args(["stats", "d", "--out", "r", "--no-gof"]))
    # --n-mc with --no-gof would be recorded and nothing done with it: refused as quench does
    for n in ("0", "10"):
        with pytest.raises(ParameterError, match="no effect with --no-gof"):
            cli.check_options(p.parse_args(["stats", "d", "--out", "r", "--n-mc", n,
                                            "--no-gof"]))
    # an explicit value wins over --fast's, so --fast does not make 0 resamples usable
    with pytest.raises(ParameterError, match="--n-mc"):
        cli.check_options(p.parse_args(["stats", "d", "--out", "r", "--n-mc", "0", "--fast"]))


# ------------------------------------------------------------------ loaders
@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    return demo.write_demo_batch(tmp_path_factory.mktemp("b") / "batch", n_images=2, seed=2,
                                 sets={"s1": {"n_stacks": 15}})


@pytest.mark.parametrize("call", [
    lambda b: load_any(None), lambda b: load_any(3), lambda b: load_any(""),
    lambda b: detect_kind(None), lambda b: load_report(None),
    lambda b: load_inputs([b, None]),
])
def test_loaders_refuse_what_is_not_a_path(call, batch):
    with pytest.raises(ParameterError, match="must be a folder path|empty string"):
        call(batch)


@pytest.mark.parametrize("value", ["x", -1.0, math.nan, math.inf, True])
@pytest.mark.parametrize("name", ["l_min_mm", "s_min_mm2"])
def test_detection_limits_must_be_finite_and_not_negative(batch, name, value):
    with pytest.raises(ParameterError) as err:
        load_any(batch, **{name: value})
    assert err.value.one_line().startswith(f"{name} must be None or a finite number >= 0")


def test_detection_limits_none_and_zero_mean_none(batch):
    for v in (None, 0, 0.0):
        assert load_any(batch, l_min_mm=v).branches["l_min_L"].isna().all()
    assert load_any(batch, l_min_mm=np.float64(2.0)).branches["l_min_L"].notna().all()


def _scan_folder(root, rng):
    """A folder laid out like the sample scans: scans, a set.toml, and generated scenes
    whose ``truth/`` holds the tables of an analysis output."""
    root.mkdir(parents=True)
    (root / "set.toml").write_text("px_per_mm = 50\n")
    for i in range(2):
        (root / f"scan_{i}.png").write_bytes(b"\x89PNG\r\n\x1a\n")
        scene = root / "scenes" / f"scan_{i}"
        summary, tables = demo.demo_image_tables(rng, n_stacks=10)
        write_tables(scene / "truth", summary, tables)
        (scene / "params.json").write_text(json.dumps({"px_per_mm": 50}))
    return root


def test_a_folder_of_scans_is_not_a_batch(tmp_path):
    scans = _scan_folder(tmp_path / "scans", np.random.default_rng(0))
    with pytest.raises(ConfigError) as err:
        load_any(scans)
    msg = err.value.one_line()
    assert "holds 2 scan(s)" in msg and "run foldstat batch" in msg
    with pytest.raises(ConfigError, match="truth of generated scenes"):
        load_any(scans / "scenes")
    # a batch output written inside it is read as before, its truth folders left aside
    b = demo.write_demo_batch(scans / "out", n_images=2, seed=1, sets={"s1": {"n_stacks": 10}})
    assert load_any(b).sets == ["s1"]
    (b / "index.csv").unlink()  # found by its summaries alone
    assert sorted(load_any(b).configs["config_id"]) == ["img000", "img001"]


def test_a_validation_report_is_named_as_such(sample_dir, tmp_path, capsys):
    from simulate.validate import validate_scenes

    report = tmp_path / "V"
    with warnings.catch_warnings():  # the scans' own quality is not what is tested
        warnings.simplefilter("ignore")
        validate_scenes(sample_dir / "scenes", report, progress=False)
    assert (report / "scores.csv").is_file() and (report / "summary.json").is_file()
    for load in (load_any, lambda f: load_image_output(f, set_name="v")):
        with pytest.raises(ConfigError) as err:
            load(report)
        assert err.value.one_line().startswith(f"{report}: is a validation report")
    assert cli_main(["stats", str(report), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a validation report" in err[0] and "rod_length" not in err[0]


def test_the_sample_scans_are_not_a_batch(sample_dir):
    with pytest.raises(ConfigError, match="scan\\(s\\).*not analysis outputs"):
        load_any(sample_dir)


def test_scene_truth_beside_analysis_outputs_is_left_out(tmp_path):
    rng = np.random.default_rng(1)
    b = demo.write_demo_batch(tmp_path / "b", n_images=2, seed=1, sets={"s1": {"n_stacks": 10}})
    (b / "index.csv").unlink()
    summary, tables = demo.demo_image_tables(rng, n_stacks=10)
    write_tables(b / "s1" / "scene" / "truth", summary, tables)
    (b / "s1" / "scene" / "params.json").write_text("{}")
    ens = load_any(b)
    assert sorted(ens.configs["config_id"]) == ["img000", "img001"]


@pytest.mark.parametrize("statuses", [("failed", "failed"), ("pending", "pending"),
                                      ("ok", "failed")])
def test_a_batch_index_is_trusted_when_it_lists_no_scan_as_done(tmp_path, statuses):
    """A re-run that failed every scan (or was stopped before its first) left the earlier
    run's folders beside an index that lists none as done: they are not read as finished."""
    b = demo.write_demo_batch(tmp_path / "b", n_images=2, seed=1, sets={"s1": {"n_stacks": 10}})
    lines = (b / "index.csv").read_text().splitlines()
    rows = [line.replace(",ok,", f",{st},") for line, st in zip(lines[1:], statuses)]
    (b / "index.csv").write_text("\n".join([lines[0], *rows]) + "\n")
    if "ok" not in statuses:
        with pytest.raises(ConfigError, match="index.csv lists no scan as done"):
            load_any(b)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert list(load_any(b).configs["config_id"]) == ["img000"]


@pytest.mark.parametrize("table, what", [("branches.csv", "branches"), ("voids.csv", "voids")])
def test_a_simulation_table_cut_short_is_named(tmp_path, table, what):
    """A simulation's branches.csv cut to its first rows was read without a word, although
    configs.csv counts every configuration's branches, stacks and voids."""
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=4, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", QualityWarning)
        whole = load_any(sim)
    lines = (sim / table).read_text().splitlines()
    (sim / table).write_text("\n".join(lines[:len(lines) // 2]) + "\n")
    with pytest.warns(QualityWarning, match=f"{table}: holds .* {what} of .* where configs.csv "
                      "counts"):
        cut = load_any(sim)
    assert "truncated, edited" in cut.configs["table_note"].iloc[0]
    assert (whole.configs["table_note"] == "").all()


def test_a_batch_json_marks_a_batch(tmp_path):
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "batch.json").write_text(json.dumps({"complete": False}))
    assert detect_kind(tmp_path / "b") == "batch"
    with pytest.raises(ConfigError, match="no finished image"):
        load_any(tmp_path / "b")


def test_load_inputs_takes_one_folder(batch):
    assert load_inputs(batch).sets == load_any(batch).sets
    with pytest.raises(ParameterError, match="names gives 2 names for 1 folders"):
        load_inputs([batch], names=["a", "b"])
