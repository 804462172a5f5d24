"""The ``stats`` subcommand end to end on small synthetic batch outputs and simulations."""
import argparse
import json

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ConfigError, ParameterError
from crosssection.stats import cli, demo


def _run(argv):
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="command", required=True)
    cli.add_subparser(sub)
    args = p.parse_args(["stats", *argv])
    return args.func(args)


@pytest.mark.parametrize("seed", [3])
def test_stats_report_on_batch_and_simulation(tmp_path, seed):
    b = demo.write_demo_batch(tmp_path / "batch", n_images=3, seed=seed,
                              sets={"s1": {"n_stacks": 25}, "s2": {"n_stacks": 15,
                                                                    "nbr_mean": 2.0}})
    s = demo.write_demo_simulation(tmp_path / "sim", n_configs=8, seed=seed)
    out = tmp_path / "rep"
    assert _run([str(b), str(s), "--out", str(out), "--n-boot", "5", "--n-mc", "9",
                 "--seed", str(seed)]) == 0
    for name in ("macro", "micro", "fits", "relations", "dof", "truncation"):
        assert (out / f"{name}.csv").is_file() and (out / f"{name}.md").is_file()
    assert (out / "correlations.csv").is_file()
    macro = pd.read_csv(out / "macro.csv")
    assert set(macro["set"]) == {"s1", "s2", "sim"}
    assert set(macro.loc[macro["set"] == "sim", "region"]) == {"all"}
    assert {"bulk", "periphery"} <= set(macro.loc[macro["set"] == "s1", "region"])
    meta = json.loads((out / "stats.json").read_text())
    assert meta["version"] and meta["options"]["seed"] == seed
    assert set(meta["libraries"]) == {"numpy", "scipy", "pandas", "matplotlib"}
    assert meta["libraries"]["numpy"] == np.__version__
    assert meta["sets"]["s1"]["fits"]["all"]["length_L"]["selected"]
    html = (out / "report.html").read_text()
    # the page says what Eq. (12) tests and what a negative r2 means
    assert "the branches tile the rod" in html and "worse than their mean" in html
    # some of this ensemble's fits are degenerate: the page says why they are set aside
    assert "<h2>Degenerate fits (never selected)</h2><p>" in html
    assert "describes no law of the data, whatever its BIC" in html
    figs = sorted((out / "figures").glob("*.png"))
    assert len(figs) >= 10
    for f in figs:  # the page links every figure
        assert f"figures/{f.name}" in html
    for name in ("pdf_length_L.png", "pdf_e.png", "pdf_n_br.png", "network_Nbr_vs_Nl.png",
                 "sqrt_s_vs_l.png", "E_vs_Nbr.png", "e_vs_nbr.png"):
        assert (out / "figures" / name).is_file(), name
    # atomic writes leave no temporary files behind
    assert not [p for p in out.rglob(".*")]


def test_counts_are_printed_exactly_in_the_macro_and_per_configuration_tables(tmp_path):
    # about 20 branches per configuration: more than 1000 in the set
    s = demo.write_demo_simulation(tmp_path / "sim", n_configs=60, seed=1)
    out = tmp_path / "rep"
    assert _run([str(s), "--out", str(out), "--n-boot", "0", "--no-gof", "--no-figures"]) == 0
    m = pd.read_csv(out / "macro.csv", dtype=str).iloc[0]
    n_br, n_voids = m["n_branches"], m["n_voids"]
    assert int(n_br) > 1000 and n_voids.isdigit()  # an integer count, not "300.0"
    page = (out / "report.html").read_text()
    averages = page.split("<h2>Averages per set: stacks")[1].split("<h2>")[0]
    assert f"<td>{n_br}</td>" in averages and f"<td>{n_voids}</td>" in averages
    assert f"| {n_br} | {n_voids} |" in (out / "macro.md").read_text()
    pc = (out / "per_config.csv").read_text().splitlines()
    assert pc[0].startswith("set,config_id,N_l,N_br,n_voids,")
    assert all(c.isdigit() for row in pc[1:] for c in row.split(",")[2:5])


def test_stats_same_seed_same_tables(tmp_path):
    s = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    for k in ("a", "b"):
        _run([str(s), "--out", str(tmp_path / k), "--n-boot", "8", "--n-mc", "9",
              "--no-figures"])
    assert (tmp_path / "a" / "fits.csv").read_text() == (tmp_path / "b" / "fits.csv").read_text()
    # a report of simulations alone says nothing of scans' quality nor of image curvature
    page = (tmp_path / "a" / "report.html").read_text()
    assert "Input quality" not in page and "curvature method" not in page


def test_stats_bad_inputs(tmp_path):
    with pytest.raises(ConfigError):
        _run([str(tmp_path), "--out", str(tmp_path / "r")])
    s = demo.write_demo_simulation(tmp_path / "sim", n_configs=4, seed=1)
    with pytest.raises(ParameterError):
        _run([str(s), "--out", str(tmp_path / "r"), "--name", "a", "--name", "b"])
    assert not (tmp_path / "r").exists()


def test_names_and_duplicate_sets(tmp_path):
    a = demo.write_demo_simulation(tmp_path / "x" / "sim", n_configs=5, seed=1)
    b = demo.write_demo_simulation(tmp_path / "y" / "sim", n_configs=5, seed=2)
    _run([str(a), str(b), "--out", str(tmp_path / "r1"), "--fast", "--no-gof", "--no-figures"])
    assert set(pd.read_csv(tmp_path / "r1" / "macro.csv")["set"]) == {"sim", "sim#2"}
    _run([str(a), str(b), "--out", str(tmp_path / "r2"), "--name", "quench", "--name", "anneal",
          "--fast", "--no-gof", "--no-figures"])
    assert set(pd.read_csv(tmp_path / "r2" / "macro.csv")["set"]) == {"quench", "anneal"}


def test_a_set_too_small_to_fit_is_named_under_the_figure(tmp_path):
    """A set whose values are too few to fit is absent from that distribution's figure, and
    its caption says so rather than leaving the reader to wonder."""
    b = demo.write_demo_batch(tmp_path / "batch", n_images=6, seed=2)
    s = demo.write_demo_simulation(tmp_path / "few", n_configs=3, seed=2)
    out = tmp_path / "rep"
    assert _run([str(b), str(s), "--out", str(out), "--fast"]) == 0
    html = (out / "report.html").read_text()
    # three configurations give three total energies: fewer than the 5 a fit needs
    assert ("Not drawn (fewer than 5 positive values above any detection limit, or all "
            "equal): few.") in html
    # its branches are many and draw it; it has no stacks.csv, so no n_br to draw either
    assert html.count("Not drawn") == 2
    e_part = html.split("Distribution of the branch energy e")[1].split("<h3")[0]
    assert "Not drawn" not in e_part


def test_small_samples_are_named_in_a_warning_and_in_the_report(tmp_path, capfd):
    import warnings

    from crosssection.cli import main
    from crosssection.stats import SmallSampleWarning, compute_stats, load_any
    from crosssection.stats.fits import N_SELECT_MIN
    from crosssection.stats.tables import N_RELATION_MIN, StatsOptions

    sim = demo.write_demo_simulation(tmp_path / "tiny", n_configs=N_RELATION_MIN - 1, seed=1)
    with pytest.warns(SmallSampleWarning) as rec:
        compute_stats(load_any(sim), StatsOptions(n_boot=0, gof=False))
    msg = " ".join(str(w.message) for w in rec if w.category is SmallSampleWarning)
    assert msg.startswith("set tiny: ")
    assert f"fewer than the {N_SELECT_MIN} samples model selection needs" in msg
    n_voids = len(load_any(sim).voids)
    assert n_voids < N_SELECT_MIN and f"area_L2 n = {n_voids}" in msg
    assert f"eq14_slope n = {N_RELATION_MIN - 1}" in msg
    # a set large enough for every selection and relation gives none
    big = demo.write_demo_simulation(tmp_path / "big", n_configs=N_SELECT_MIN, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SmallSampleWarning)
        compute_stats(load_any(big), StatsOptions(n_boot=0, gof=False,
                                                  quantities=("E", "e", "length_L")))
    # the command line: one warning line, and the report says it beside the numbers
    capfd.readouterr()
    assert main(["stats", str(sim), "--out", str(tmp_path / "r"), "--n-boot", "0", "--no-gof",
                 "--no-figures"]) == 0
    err = capfd.readouterr().err.splitlines()
    assert len([ln for ln in err if ": set tiny: " in ln]) == 1
    # 'warning: FILE: ...': a warning about a set names the report it is about
    assert all(ln.startswith(f"warning: {tmp_path / 'r'}: set ") for ln in err
               if ": set " in ln)
    page = (tmp_path / "r" / "report.html").read_text()
    n = N_RELATION_MIN - 1
    assert f"n = {n_voids}: below the {N_SELECT_MIN} samples model selection needs" in page
    assert f"n = {n}: below the {N_RELATION_MIN} configurations a fitted relation needs" in page
    # the numbers are still given
    assert len(pd.read_csv(tmp_path / "r" / "relations.csv").dropna(subset=["fitted"])) > 0


def test_absent_figures_and_rows_are_named_and_log_axes_follow_the_data(tmp_path,
                                                                         monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import numpy as np

    from crosssection.stats import compute_stats, load_any
    from crosssection.stats.report import _left_out, pdf_figure
    from crosssection.stats.tables import StatsOptions

    # one simulation of 3 configurations: 3 total energies, too few for any fit of E
    s = demo.write_demo_simulation(tmp_path / "few", n_configs=3, seed=2)
    out = tmp_path / "rep"
    assert _run([str(s), "--out", str(out), "--n-boot", "0", "--no-gof"]) == 0
    assert not (out / "figures" / "pdf_E.png").exists()
    assert ("Not drawn (fewer than 5 positive values above any detection limit, or all "
            "equal, in every set): the distribution of the total energy"
            in (out / "report.html").read_text())
    # a set with 6 periphery branches: absent from that row of the figure and named
    b = demo.write_demo_batch(tmp_path / "b", n_images=2, seed=2,
                              sets={"A": {"n_stacks": 30}, "B": {"n_stacks": 30}})
    ens = load_any(b)
    per = ens.branches.index[(ens.branches["set"] == "B")
                             & (ens.branches["region"] == "periphery")]
    ens.branches.loc[per[4:], "region"] = "bulk"  # B keeps 4 periphery branches
    res = compute_stats(ens, StatsOptions(n_boot=20, gof=False, quantities=("length_L",)))
    assert ("B", "periphery", "length_L") not in res.summaries
    assert ("Not drawn (fewer than 5 positive values above any detection limit, or all "
            "equal): B (periphery") in _left_out(res, ens, "length_L", 5)
    # the log panels' y-range is that of the points and the laws, not of the bands: a band
    # exploding to 1e15 times the law (a small sample's bootstrap) is clipped
    from crosssection.stats import report as R

    band = R._band
    monkeypatch.setattr(R, "_band", lambda *a, **k: (lambda b: None if b is None else
                                                     (b[0], b[1] * 1e15))(band(*a, **k)))
    fig = pdf_figure(res, ens, "length_L")
    for ax in fig.axes[1::2]:
        ys = [np.max(np.asarray(ln.get_ydata(), float)) for ln in ax.lines
              if str(ln.get_gid()).startswith(("law:", "points:"))]
        top = max(ys)
        assert ax.get_ylim()[1] <= 3.5 * top


def test_a_degenerate_law_with_a_lower_bic_is_named_beside_the_selected_one():
    # log-uniform data: the Bose-Einstein fit runs off to a 1/x law (degenerate, never
    # selected) with a BIC far below the selected law's; the table must not hide it
    from types import SimpleNamespace

    from crosssection.stats.fits import fit_all
    from crosssection.stats.report import _selected_table

    x = np.exp(np.random.default_rng(0).uniform(0.0, np.log(1000.0), 300))
    s = fit_all(x, n_boot=0, gof=False, seed=0)
    assert not s.results["bose_einstein"].selectable
    assert s.results["bose_einstein"].bic < s.results[s.best].bic - 50
    row = _selected_table(SimpleNamespace(summaries={("A", "all", "e"): s})).iloc[0]
    text = row["runner-up law, BIC − BIC(selected)"]
    assert "set aside as degenerate" in text and "Bose-Einstein" in text


def test_a_selection_the_data_do_not_decide_is_said_so():
    # Gamma samples of the paper's total energy (shape about 40): a Gaussian fits as well
    from types import SimpleNamespace

    from crosssection.stats.fits import fit_all
    from crosssection.stats.report import BIC_UNDECIDED, _selected_table

    said = []
    for seed in range(6):
        x = np.random.default_rng(seed).gamma(40.0, 100.0, 60)
        s = fit_all(x, families=("gamma", "gaussian", "lognormal"), n_boot=0, gof=False)
        gap = sorted(r.bic for r in s.results.values() if r.selectable)[1] - \
            s.results[s.best].bic
        text = _selected_table(SimpleNamespace(summaries={("A", "all", "E"): s})).iloc[0][
            "runner-up law, BIC − BIC(selected)"]
        assert ("do not tell the two laws apart" in text) == (gap < BIC_UNDECIDED)
        said.append(gap < BIC_UNDECIDED)
    assert any(said)


def test_the_methods_paragraph_names_the_curvature_method_the_scans_used(tmp_path):
    """The methods paragraph says how κ was read: each method the scans recorded."""
    import json as _json

    from crosssection.stats.report import _curvature_methods, _curvature_text

    class _Ens:
        def __init__(self, methods):
            self.configs = pd.DataFrame({"analysis": [
                _json.dumps({"version": "x", "parameters": {"curvature_method": m}})
                for m in methods] + [_json.dumps({"version": "x", "parameters": {}})]})

    # a configuration without image parameters (a simulation) names no method
    assert _curvature_methods(_Ens(["paper"])) == ["paper"]
    text = _curvature_text(_curvature_methods(_Ens(["walls", "paper"])))
    assert "several" in text and "smoothed skeleton" in text and "two walls" in text
    assert _curvature_methods(None) == [] and _curvature_text([]) == ""
    only = _curvature_text(["paper"])
    assert "<code>paper</code>" in only and "walls" not in only


def test_a_selected_law_the_data_reject_is_said_so():
    # counts of 1 and 2 about half each: the laws with a width fit as spikes (set aside), and
    # the exponential left, selected, fails its test: the table said "selected" alone
    import warnings
    from types import SimpleNamespace

    from crosssection.stats.fits import fit_all
    from crosssection.stats.report import _selected_table

    x = np.array([1] * 29 + [2] * 25, float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = fit_all(x, n_boot=0, gof=True, n_mc=200, discrete=True, seed=0)
    assert s.best and s.results[s.best].pvalue < 0.05
    row = _selected_table(SimpleNamespace(summaries={("A", "all", "n_br"): s})).iloc[0]
    assert "the data reject it" in row["goodness of fit"]
    # a law that fits is not marked
    y = np.random.default_rng(1).gamma(2.0, 1.0, 200)
    s = fit_all(y, families=("gamma", "exponential"), n_boot=0, gof=True, n_mc=200, seed=0)
    row = _selected_table(SimpleNamespace(summaries={("A", "all", "e"): s})).iloc[0]
    assert "reject" not in row["goodness of fit"]
