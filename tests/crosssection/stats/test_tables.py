"""Loading batch outputs and simulation ensembles; the paper's tables, relations, correlations."""
import json

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ConfigError
from crosssection.core.schema import write_tables
from crosssection.quality import QualityWarning
from crosssection.stats import data as D
from crosssection.stats import demo
from crosssection.stats import tables as T

FAST = T.StatsOptions(seed=0, n_boot=0, gof=False)


def _image(folder, *, L, lengths_mm, kappa_m, energy, regions, stack_of, n_br, areas_mm2,
           ratios, epsilon=10.0, L_used=None):
    nst = len(n_br)
    stacks = pd.DataFrame({"stack_id": range(nst), "junction_a": -1, "junction_b": -1,
                           "length_mm": 5.0, "width_mm": 0.1, "n_br": n_br,
                           "region": [regions[list(stack_of).index(i)] for i in range(nst)],
                           "mid_x_px": 0.0, "mid_y_px": 0.0})
    nb = len(lengths_mm)
    branches = pd.DataFrame({"branch_id": range(nb), "stack_id": stack_of,
                             "length_mm": lengths_mm, "kappa_pm": -np.asarray(kappa_m),
                             "kappa_plus": kappa_m, "kappa_m": kappa_m, "energy": energy,
                             "region": regions})
    voids = pd.DataFrame({"void_id": range(len(areas_mm2)), "area_mm2": areas_mm2,
                          "perimeter_mm": np.sqrt(areas_mm2) / np.asarray(ratios),
                          "shape_ratio": ratios, "n_edges": 4, "centroid_x_px": 0.0,
                          "centroid_y_px": 0.0})
    summary = {"n_junctions": 0, "n_stacks": nst, "n_branches": nb, "n_voids": len(areas_mm2),
               "mean_branches_per_stack": nb / nst, "rod_length_mm": L, "epsilon": epsilon,
               "total_energy": float(np.sum(energy)), "hole": None, "timings_s": {}}
    if L_used is not None:  # analyze --rod-length-mm: e, E and epsilon use the given L
        summary.update(rod_length_used_mm=L_used, rod_length_given=True)
    write_tables(folder, summary, {"stacks": stacks, "branches": branches, "voids": voids})


def test_image_units_are_normalised_by_rod_length(tmp_path):
    _image(tmp_path / "b" / "setA" / "img0", L=1000.0, lengths_mm=[10.0, 20.0, 30.0],
           kappa_m=[0.5, 0.25, 0.1], energy=[5.0, 6.0, 7.0],
           regions=["bulk", "bulk", "periphery"], stack_of=[0, 0, 1], n_br=[2, 1],
           areas_mm2=[4.0, 9.0], ratios=[0.2, 0.18])
    assert D.detect_kind(tmp_path / "b") == "batch"
    assert D.detect_kind(tmp_path / "b" / "setA" / "img0") == "image"
    ens = D.load_any(tmp_path / "b", l_min_mm=1.0, s_min_mm2=1.0)
    assert ens.sets == ["setA"]
    br = ens.branches
    np.testing.assert_allclose(br["length_L"], [0.01, 0.02, 0.03])
    np.testing.assert_allclose(br["kappa_m_L"], [500.0, 250.0, 100.0])
    np.testing.assert_allclose(br["l_min_L"], 1e-3)
    assert list(br["n_br"]) == [2, 2, 1]
    np.testing.assert_allclose(ens.voids["area_L2"], [4e-6, 9e-6])
    np.testing.assert_allclose(ens.voids["s_min_L2"], 1e-6)
    m = T.macro_table(ens).set_index("region")
    assert m.loc["all", "N_l"] == 2 and m.loc["all", "N_br"] == 3
    assert m.loc["all", "n_br"] == 1.5
    assert m.loc["all", "s_L2"] == pytest.approx(6.5e-6)
    assert m.loc["all", "sqrt_s_over_p"] == pytest.approx(0.19)
    assert m.loc["all", "l_L"] == pytest.approx(0.02)
    assert m.loc["bulk", "N_br"] == 2 and m.loc["periphery", "l_L"] == pytest.approx(0.03)


def test_a_sub_system_without_stacks_has_its_row_of_zero_counts(tmp_path):
    # every stack at the wall: the bulk row was missing, as if not computed
    _image(tmp_path / "b" / "setA" / "img0", L=1000.0, lengths_mm=[10.0, 20.0, 30.0],
           kappa_m=[0.5, 0.25, 0.1], energy=[5.0, 6.0, 7.0],
           regions=["periphery"] * 3, stack_of=[0, 0, 1], n_br=[2, 1],
           areas_mm2=[4.0, 9.0], ratios=[0.2, 0.18])
    ens = D.load_any(tmp_path / "b", l_min_mm=1.0, s_min_mm2=1.0)
    m = T.macro_table(ens).set_index("region")
    assert list(m.index) == ["all", "bulk", "periphery"]
    assert m.loc["bulk", "N_l"] == 0 and m.loc["bulk", "N_br"] == 0
    assert m.loc["bulk", "n_branches"] == 0 and np.isnan(m.loc["bulk", "l_L"])
    assert m.loc["periphery", "N_br"] == m.loc["all", "N_br"] == 3
    res = T.compute_stats(ens, T.StatsOptions(n_boot=0, gof=False))
    assert list(res.micro["region"]) == ["all", "bulk", "periphery"]
    assert np.isnan(res.micro.set_index("region").loc["bulk", "e"])


def test_given_rod_length_normalises_every_quantity(tmp_path):
    # measured L = 500 mm, analysed with --rod-length-mm 1000: the energies and epsilon of the
    # summary use 1000, so lengths, curvatures and areas must as well
    _image(tmp_path / "img", L=500.0, L_used=1000.0, lengths_mm=[10.0, 20.0],
           kappa_m=[0.5, 0.25], energy=[5.0, 6.0], regions=["bulk", "bulk"], stack_of=[0, 0],
           n_br=[2], areas_mm2=[4.0], ratios=[0.2], epsilon=1000.0 / (2 * np.pi * 20.0))
    ens = D.load_any(tmp_path / "img", l_min_mm=1.0, s_min_mm2=1.0)
    np.testing.assert_allclose(ens.branches["length_L"], [0.01, 0.02])
    np.testing.assert_allclose(ens.branches["kappa_m_L"], [500.0, 250.0])
    np.testing.assert_allclose(ens.branches["kappa_plus_L"], [500.0, 250.0])
    np.testing.assert_allclose(ens.branches["l_min_L"], 1e-3)
    np.testing.assert_allclose(ens.stacks["length_L"], [5e-3])
    np.testing.assert_allclose(ens.voids["area_L2"], [4e-6])
    np.testing.assert_allclose(ens.voids["perimeter_L"], [1e-2])
    np.testing.assert_allclose(ens.voids["s_min_L2"], 1e-6)
    np.testing.assert_allclose(ens.voids["shape_ratio"], [0.2])  # dimensionless
    cfg = ens.configs.iloc[0]
    assert cfg["rod_length_mm"] == 1000.0
    # the energies and epsilon are taken as the analysis wrote them (in units of the same L)
    np.testing.assert_allclose(ens.branches["e"], [5.0, 6.0])
    assert cfg["E"] == pytest.approx(11.0)
    assert cfg["epsilon"] == pytest.approx(1000.0 / (2 * np.pi * 20.0))


@pytest.mark.parametrize("bad", [0.0, -5.0])
def test_rod_length_used_must_be_positive(tmp_path, bad):
    _image(tmp_path / "img", L=500.0, L_used=bad, lengths_mm=[10.0], kappa_m=[0.5],
           energy=[5.0], regions=["bulk"], stack_of=[0], n_br=[1], areas_mm2=[4.0],
           ratios=[0.2])
    with pytest.raises(ConfigError, match="rod_length_used_mm"):
        D.load_any(tmp_path / "img")


def test_simulation_ensemble_is_read_in_units_of_L(tmp_path):
    sim = tmp_path / "sim"
    sim.mkdir()
    pd.DataFrame({"config_id": [0, 1], "seed": 1, "rg": 0.06, "epsilon": [2.2, 2.4],
                  "energy_total": [4000.0, 4600.0], "energy_bending": 0.0,
                  "energy_confinement": 0.0, "n_stacks": [10, 12], "n_branches": [20, 25],
                  "n_voids": [1, 1], "method": "powell", "wall_s": 1.0}).to_csv(
        sim / "configs.csv", index=False)
    pd.DataFrame({"config_id": [0, 0, 1], "branch_id": [0, 1, 0], "length": [0.1, 0.2, 0.05],
                  "kappa_plus": [30.0, 40.0, 20.0], "kappa_pm": [-30.0, 10.0, 20.0],
                  "energy_bending": 1.0, "energy_confinement": 1.0,
                  "energy": [200.0, 300.0, 100.0]}).to_csv(sim / "branches.csv", index=False)
    pd.DataFrame({"config_id": [0, 1], "area": [1e-3, 2e-3], "perimeter": [0.2, 0.3],
                  "shape_ratio": [0.16, 0.15], "n_edges": [4, 5]}).to_csv(
        sim / "voids.csv", index=False)
    assert D.detect_kind(sim) == "simulation"
    # three rows stand for the configurations' 45 branches: named, and used
    with pytest.warns(QualityWarning, match="branches.csv: holds 3 branches .* counts 45"):
        ens = D.load_any(sim)
    assert ens.sets == ["sim"]
    np.testing.assert_allclose(ens.branches["kappa_m_L"], [30.0, 10.0, 20.0])  # |kappa_pm|
    np.testing.assert_allclose(ens.branches["length_L"], [0.1, 0.2, 0.05])
    assert ens.branches["l_min_L"].isna().all()
    assert T.regions_of(ens) == ["all"]
    m = T.macro_table(ens)
    assert list(m["region"]) == ["all"]
    assert m["N_l"].item() == 11 and m["N_br"].item() == 22.5
    # a missing column is reported with its file
    pd.DataFrame({"config_id": [0]}).to_csv(sim / "voids.csv", index=False)
    with pytest.raises(ConfigError) as ei:
        D.load_any(sim)
    assert "voids.csv" in ei.value.one_line() and "area" in ei.value.one_line()


def test_batch_skips_staging_folders_and_failed_rows(tmp_path):
    b = demo.write_demo_batch(tmp_path / "b", n_images=2, seed=4, sets={"s": {"n_stacks": 10}})
    n_ok = len(D.load_any(b).configs)
    # an interrupted batch leaves a hidden staging copy holding a summary.json
    import shutil

    shutil.copytree(b / "s" / "img000", b / "s" / ".img000.partial-abc")
    idx = pd.read_csv(b / "index.csv")
    idx.loc[1, "status"] = "failed"
    idx.to_csv(b / "index.csv", index=False)
    assert len(D.load_any(b).configs) == n_ok - 1  # the index decides
    (b / "index.csv").unlink()
    ens = D.load_any(b)  # without index: glob, hidden folders ignored
    assert sorted(ens.configs["config_id"]) == ["img000", "img001"]


def test_the_warning_on_failed_scans_gives_each_ones_reason(tmp_path):
    b = demo.write_demo_batch(tmp_path / "b", n_images=2, seed=4, sets={"s": {"n_stacks": 10}})
    pd.DataFrame({"image": ["s/blank.png", "s/x.png"], "set": ["s", "s"],
                  "reason": [f"{tmp_path}/in/s/blank.png: empty mask: no pixel passes",
                             "not an image file"]}).to_csv(b / "failures.csv", index=False)
    with pytest.warns(D.IncompleteBatchWarning) as rec:
        D.load_any(b)
    said = " ".join(str(w.message) for w in rec)
    assert "(s/blank.png: empty mask: no pixel passes; s/x.png: not an image file)" in said
    assert str(tmp_path / "in") not in said


def test_unrecognised_folder(tmp_path):
    with pytest.raises(ConfigError):
        D.detect_kind(tmp_path)
    with pytest.raises(ConfigError):
        D.detect_kind(tmp_path / "missing")
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "summary.json").write_text(json.dumps({"rod_length_mm": None}))
    with pytest.raises(ConfigError, match="rod_length_mm"):
        D.load_any(tmp_path / "x")


def _relations_ensemble(rng, n=25, slope=1.1, nbr=3.0):
    """Configurations built to satisfy sqrt(s_bar) = slope l_bar and N_br = nbr N_l exactly."""
    cfg, br, vo, st = [], [], [], []
    for k in range(n):
        n_l = int(rng.integers(10, 60))
        n_br = int(nbr * n_l)
        l_bar = rng.uniform(2e-3, 1e-2)
        s_bar = (slope * l_bar) ** 2
        eps = rng.uniform(5, 20)
        cfg.append({"set": "X", "config_id": str(k), "N_l": n_l, "N_br": n_br, "n_voids": 2,
                    "epsilon": eps, "E": rng.gamma(10, 100), "rod_length_mm": np.nan,
                    "source": ""})
        ln = np.full(n_br, l_bar)
        km = rng.uniform(10, 100, n_br)
        br.append(pd.DataFrame({"set": "X", "config_id": str(k), "length_L": ln,
                                "kappa_m_L": km, "kappa_plus_L": km, "e": ln * km ** 2,
                                "region": "none", "n_br": nbr, "l_min_L": np.nan}))
        vo.append(pd.DataFrame({"set": "X", "config_id": str(k),
                                "area_L2": [0.5 * s_bar, 1.5 * s_bar], "perimeter_L": 1.0,
                                "shape_ratio": 0.18, "n_edges": 4, "s_min_L2": np.nan}))
        st.append(pd.DataFrame({"set": "X", "config_id": str(k), "n_br": np.full(n_l, nbr),
                                "length_L": 0.01, "region": "none"}))
    return D.Ensemble(pd.DataFrame(cfg), pd.concat(br, ignore_index=True),
                      pd.concat(st, ignore_index=True), pd.concat(vo, ignore_index=True))


@pytest.mark.parametrize("seed,slope,nbr", [(0, 1.1, 3.0), (1, 0.8, 2.0)])
def test_relations_recover_constants(seed, slope, nbr):
    ens = _relations_ensemble(np.random.default_rng(seed), slope=slope, nbr=nbr)
    pc = T.per_config_table(ens)
    rel = T.relations_table(ens, pc, {}).set_index("relation")
    assert rel.loc["slope_sqrt_s_vs_l", "fitted"] == pytest.approx(slope, rel=1e-9)
    assert rel.loc["eq14_slope", "fitted"] == pytest.approx(nbr, rel=1e-9)
    assert rel.loc["eq14_slope", "expected"] == pytest.approx(nbr)
    assert rel.loc["eq15_fluct", "fitted"] == pytest.approx(0.0, abs=1e-12)
    want5 = nbr * np.sqrt(pc["N_l"].mean()) / pc["epsilon"].mean()
    assert rel.loc["eq16", "fitted"] == pytest.approx(want5)
    # Eq. (12) with data built from it: N_br = C eps sqrt(s)/l sqrt(N_l)
    pc2 = pc.copy()
    pc2["N_br"] = T.EQ12_CONST * pc2["eq12_x"]
    c, r2, _ = T.slope_through_origin(pc2["eq12_x"], pc2["N_br"])
    assert c == pytest.approx(T.EQ12_CONST) and r2 == pytest.approx(1.0)


def test_a_configuration_without_a_branch_is_no_point_of_the_relations():
    # at (0, 0) it took R^2 of eq14_slope from 0.00 to 0.97 (a hand-made empty scan; a rod
    # that touches itself nowhere holds no stack either)
    ens = _relations_ensemble(np.random.default_rng(5), n=12)
    pc = T.per_config_table(ens)
    pc["N_br"] = pc["N_br"] + np.random.default_rng(6).normal(0, 20, len(pc))  # scatter
    ref = T.relations_table(ens, pc, {}).set_index("relation")
    zero = pc.iloc[:1].copy()
    zero[["config_id", "N_l", "N_br"]] = ["empty", 0, 0]
    with pytest.warns(QualityWarning, match="1 of 13 configurations hold no branch"):
        rel = T.relations_table(ens, pd.concat([pc, zero], ignore_index=True),
                                {}).set_index("relation")
    assert rel.loc["eq14_slope", "r2"] == pytest.approx(ref.loc["eq14_slope", "r2"])
    assert rel.loc["eq14_slope", "n"] == ref.loc["eq14_slope", "n"]


def test_relations_hold_no_row_equal_by_construction():
    # a configuration's E is the sum of its branches' energies (the simulator's contact
    # analysis here; a scan's summary sums its branches.csv), so <E> = <N_br><e> exactly and
    # a row comparing them could never fail
    from simulate.contacts import analyze_rod
    from simulate.shapes import hairpin, resample

    an = analyze_rod(resample(hairpin(0.01, arm=0.3), 60), lam=2e4)
    assert an.energy_total == pytest.approx(an.branches["energy"].sum(), rel=1e-12)
    ens = _relations_ensemble(np.random.default_rng(3), n=8)
    rel = T.relations_table(ens, T.per_config_table(ens), {})
    assert "E_vs_Nbr_e" not in set(rel["relation"])
    assert set(rel["relation"]) == {*T.SLOPE_RELATIONS, "eq15_fluct", "eq16", "n_br_exp_mu"}


def test_correlations_of_few_pairs_are_marked_indicative():
    # the relations' rule: fewer than N_RELATION_MIN pairs (three points give r = 1 or near)
    ens = _relations_ensemble(np.random.default_rng(4), n=T.N_RELATION_MIN - 1)
    cor = T.correlations_table(ens).set_index("pair")
    assert cor["indicative"].dtype == bool
    assert cor.loc["E_vs_N_br", "n"] == T.N_RELATION_MIN - 1 and cor.loc["E_vs_N_br",
                                                                         "indicative"]
    assert not cor.loc["e_vs_l_kappa_m2", "indicative"]  # hundreds of branches
    big = T.correlations_table(_relations_ensemble(np.random.default_rng(4),
                                                   n=T.N_RELATION_MIN))
    assert not big["indicative"].any()
    # the page says it beside the number
    from crosssection.stats.report import _correlations_shown

    shown = _correlations_shown(T.correlations_table(ens)).set_index("pair")
    assert "indicative" not in shown.columns
    assert shown.loc["E_vs_N_br", "n"] == (f"n = {T.N_RELATION_MIN - 1}: below the "
                                           f"{T.N_RELATION_MIN} pairs of values a correlation "
                                           "needs: indicative only")


def test_every_relation_follows_its_small_sample_rule():
    ens = _relations_ensemble(np.random.default_rng(4), n=T.N_RELATION_MIN - 1)
    rel = T.relations_table(ens, T.per_config_table(ens), {})
    assert set(T.CONFIG_RELATIONS) | {T.LAW_RELATION} == set(rel["relation"])
    for r in T.CONFIG_RELATIONS:
        assert T.relation_note(r, T.N_RELATION_MIN - 1, 1.0).startswith(
            f"n = {T.N_RELATION_MIN - 1}: below the {T.N_RELATION_MIN} configurations")
        assert T.relation_note(r, T.N_RELATION_MIN, 1.0) == ""
        assert T.relation_note(r, 1, np.nan) == ""  # not computed: nothing to qualify
    # the mean of the law of n_br: the laws' rule, on the stacks it is fitted to
    from crosssection.stats.fits import N_SELECT_MIN

    assert T.relation_note(T.LAW_RELATION, N_SELECT_MIN - 1, 2.0) != ""
    assert T.relation_note(T.LAW_RELATION, N_SELECT_MIN, 2.0) == ""
    # the means over configurations (eq15_fluct, eq16) are marked and named as the slopes
    from crosssection.stats import SmallSampleWarning

    with pytest.warns(SmallSampleWarning) as rec:
        res = T.compute_stats(ens, T.StatsOptions(n_boot=0, gof=False,
                                                  quantities=("length_L",)))
    rel = res.relations.set_index("relation")
    assert np.isfinite(rel.loc[["eq15_fluct", "eq16"], "fitted"]).all()
    assert rel.loc[list(T.CONFIG_RELATIONS), "indicative"].all()
    msg = " ".join(str(w.message) for w in rec if w.category is SmallSampleWarning)
    for name in T.CONFIG_RELATIONS:
        assert f"{name} n = {T.N_RELATION_MIN - 1}" in msg, msg
    # the page says it beside the number
    from crosssection.stats.report import _relations_shown

    shown = _relations_shown(res.relations).set_index("relation")
    assert str(shown.loc["eq16", "n"]).endswith("indicative only")


def test_correlations_and_micro_gamma_fits():
    rng = np.random.default_rng(2)
    ens = _relations_ensemble(rng, n=40)
    cor = T.correlations_table(ens).set_index("pair")
    # e = l kappa_m^2 exactly, so r = 1
    assert cor.loc["e_vs_l_kappa_m2", "pearson_r"] == pytest.approx(1.0)
    assert cor.loc["E_vs_N_br", "paper"] == 0.75
    # branch energies from a known Gamma law: alpha_e recovered; dof ratio consistent
    ens.branches["e"] = rng.gamma(0.31, 728.0, len(ens.branches))
    res = T.compute_stats(ens, T.StatsOptions(n_boot=0, gof=False,
                                              quantities=("e", "E", "length_L")))
    mic = res.micro.set_index("region").loc["all"]
    assert mic["alpha_e"] == pytest.approx(0.31, rel=0.08)
    assert mic["chi_e"] == pytest.approx(728.0, rel=0.12)
    dof = res.dof.iloc[0]
    assert dof["alpha_E_over_alpha_e"] == pytest.approx(dof["alpha_E"] / dof["alpha_e"])
    assert res.fits.groupby(["quantity"])["selected"].sum().eq(1).all()


def test_the_tables_carry_the_uncertainty_of_their_means_shapes_and_coefficients():
    from scipy import stats

    rng = np.random.default_rng(5)
    ens = _relations_ensemble(rng, n=30)
    ens.branches["e"] = rng.gamma(0.5, 300.0, len(ens.branches))
    res = T.compute_stats(ens, T.StatsOptions(seed=1, n_boot=100, gof=False,
                                              quantities=("e", "E")))
    mac = res.macro.set_index("region").loc["all"]
    n_l = ens.configs["N_l"].to_numpy(float)
    assert mac["N_l_se"] == pytest.approx(n_l.std(ddof=1) / np.sqrt(len(n_l)))
    # a pooled mean's error counts configurations, not branches: every branch of a
    # configuration shares its length, so the error over branches alone would be far smaller
    ln = ens.branches["length_L"].to_numpy(float)
    assert mac["l_L_se"] > 3 * ln.std(ddof=1) / np.sqrt(len(ln))
    per = ens.branches.groupby("config_id")["length_L"].agg(["sum", "size"])
    m = per["sum"].sum() / per["size"].sum()
    G = len(per)
    want = np.sqrt(G / (G - 1) * ((per["sum"] - m * per["size"]) ** 2).sum()) / per["size"].sum()
    assert mac["l_L_se"] == pytest.approx(want)
    mic = res.micro.set_index("region").loc["all"]
    assert mic["alpha_e_lo"] < mic["alpha_e"] < mic["alpha_e_hi"]
    assert mic["alpha_E_lo"] < mic["alpha_E"] < mic["alpha_E_hi"]
    gamma = res.fits[(res.fits["quantity"] == "e") & (res.fits["family"] == "gamma")].iloc[0]
    assert (mic["alpha_e_lo"], mic["alpha_e_hi"]) == (gamma["p1_lo"], gamma["p1_hi"])
    dof = res.dof.iloc[0]
    assert dof["alpha_E_over_alpha_e_lo"] < dof["alpha_E_over_alpha_e"] \
        < dof["alpha_E_over_alpha_e_hi"]
    cor = res.correlations.set_index("pair").loc["E_vs_N_br"]
    want = stats.pearsonr(ens.configs["E"], ens.configs["N_br"])
    assert cor["pearson_p"] == pytest.approx(want.pvalue)
    ci = want.confidence_interval(0.95)
    assert (cor["pearson_lo"], cor["pearson_hi"]) == pytest.approx((ci.low, ci.high))
    # one configuration: no error over configurations
    one = T.macro_table(D.Ensemble(ens.configs.iloc[:1], ens.branches[
        ens.branches["config_id"] == "0"], ens.stacks[ens.stacks["config_id"] == "0"],
        ens.voids[ens.voids["config_id"] == "0"])).iloc[0]
    assert np.isnan(one["N_l_se"]) and np.isnan(one["l_L_se"])


def test_the_gamma_shape_of_the_resamples_is_scipys():
    from scipy import stats

    rng = np.random.default_rng(0)
    for a in (0.3, 0.64, 5.0, 50.0):
        x = rng.gamma(a, 2.0, 400)
        assert T.gamma_shape_mle(x.mean(), np.log(x).mean()) == pytest.approx(
            stats.gamma.fit(x, floc=0)[0], rel=1e-6)


def test_the_shape_of_a_gamma_law_another_law_beats_is_marked_on_the_page():
    from crosssection.stats.report import _small_fits_marked

    rng = np.random.default_rng(4)
    ens = _relations_ensemble(rng, n=30)
    ens.branches["e"] = rng.lognormal(3.0, 1.5, len(ens.branches))
    res = T.compute_stats(ens, T.StatsOptions(seed=1, n_boot=20, gof=False,
                                              quantities=("e",)))
    cell = _small_fits_marked(res.micro, res).set_index("region").loc["all", "alpha_e"]
    assert "log-normal is the law selected for e" in cell
    ens.branches["e"] = rng.gamma(0.5, 300.0, len(ens.branches))
    res = T.compute_stats(ens, T.StatsOptions(seed=1, n_boot=20, gof=False,
                                              quantities=("e",)))
    cell = _small_fits_marked(res.micro, res).set_index("region").loc["all", "alpha_e"]
    assert not isinstance(cell, str)


def test_the_page_puts_each_uncertainty_beside_its_value():
    from crosssection.stats.report import _with_errors

    df = pd.DataFrame({"set": ["a", "b"], "N_l": [14.52, 3.0], "N_l_se": [0.477, np.nan],
                       "alpha_e": ["0.644 (n = 20: indicative only)", 0.5],
                       "alpha_e_lo": [0.61, 0.4], "alpha_e_hi": [0.68, 0.6]})
    out = _with_errors(df)
    assert list(out.columns) == ["set", "N_l", "alpha_e"]
    assert out["N_l"].tolist() == ["14.52 ± 0.48", 3.0]
    # a standard error over fewer configurations than a relation needs is marked
    few = _with_errors(pd.DataFrame({"set": ["a", "b"], "N_l": [12.0, 12.0],
                                     "N_l_se": [2.0, 2.0]}), {"a": 2, "b": 30})
    assert few["N_l"].tolist() == ["12.0 ± 2.0 (n = 2 configurations: indicative only)",
                                   "12.0 ± 2.0"]
    errors = pd.DataFrame({"E": [4092.94, 0.0, 0.04428, 16447.3],
                           "E_se": [83.4, 0.0, 0.00132, 7402.0]})
    assert _with_errors(errors)["E"].tolist() == ["4093 ± 83", "0", "0.0443 ± 0.0013",
                                                  "16400 ± 7400"]
    assert out["alpha_e"].tolist() == ["0.644 [0.61, 0.68] (n = 20: indicative only)",
                                       "0.5 [0.4, 0.6]"]


def test_demo_batch_tables_bulk_periphery_and_truncation(tmp_path):
    demo.write_demo_batch(tmp_path / "b", n_images=4, seed=3,
                          sets={"s1": {"n_stacks": 50, "nbr_mean": 3.0, "length_mu_L": 4e-3}})
    ens = D.load_any(tmp_path / "b")
    res = T.compute_stats(ens, T.StatsOptions(n_boot=20, gof=False,
                                              quantities=("length_L", "n_br", "e")))
    assert set(res.macro["region"]) == {"all", "bulk", "periphery"}
    m = res.macro.set_index("region")
    # bulk + periphery partition the branches
    assert m.loc["bulk", "N_br"] + m.loc["periphery", "N_br"] == pytest.approx(m.loc["all", "N_br"])
    f = res.fits[(res.fits["quantity"] == "length_L") & (res.fits["region"] == "all")]
    assert f["truncated"].all()
    exp = f[f["family"] == "exponential"].iloc[0]
    assert exp["p1_lo"] <= 4e-3 <= exp["p1_hi"]  # generated mu (units of L) recovered
    tr = res.truncation[(res.truncation["family"] == "exponential")
                        & (res.truncation["region"] == "all")].iloc[0]
    assert tr["naive"] > tr["truncated"]  # naive fit biased upward by l_min
    assert tr["mean_minus_cut"] == pytest.approx(tr["truncated"])
    # the truncation-aware fit's interval is reported beside it, and holds it
    assert tr["truncated_lo"] <= tr["truncated"] <= tr["truncated_hi"]
    assert tr["truncated_lo"] == pytest.approx(exp["p1_lo"])
    # N_br = sum of n_br over stacks, so Eq. (14) holds exactly per configuration
    rel = res.relations.set_index("relation")
    assert rel.loc["eq14_slope", "r2"] == pytest.approx(1.0, abs=0.2)


def test_to_markdown():
    md = T.to_markdown(pd.DataFrame({"a": [1.23456789, np.nan], "b": ["x|y", "z"]}))
    lines = md.strip().splitlines()
    assert lines[0] == "| a | b |" and lines[1] == "|---|---|"
    assert lines[2] == "| 1.235 | x\\|y |" and lines[3] == "|  | z |"


def test_small_samples_not_fitted_are_named_and_rows_marked_indicative(tmp_path):
    from crosssection.stats import SmallSampleWarning
    from crosssection.stats.fits import N_SELECT_MIN
    from crosssection.stats.report import write_report

    sim = demo.write_demo_simulation(tmp_path / "tiny", n_configs=T.N_RELATION_MIN - 1, seed=1)
    ens = D.load_any(sim)
    opts = T.StatsOptions(n_boot=0, gof=False, quantities=("E", "e", "area_L2"))
    with pytest.warns(SmallSampleWarning) as rec:
        res = T.compute_stats(ens, opts)
    msgs = [str(w.message) for w in rec if w.category is SmallSampleWarning]
    assert len(msgs) == 1, msgs  # one per set, whatever it names
    assert (f"not fitted, fewer than the {opts.min_n} values a fit needs (min_n): "
            f"E n = {T.N_RELATION_MIN - 1}") in msgs[0]
    assert "E" not in set(res.fits["quantity"])
    # fits: the voids (a few per configuration) are below N_SELECT_MIN, the branches not
    n_by_q = res.fits.groupby("quantity")["n"].first()
    assert n_by_q["area_L2"] < N_SELECT_MIN <= n_by_q["e"]
    ind = res.fits.groupby("quantity")["indicative"].agg(["min", "max"])
    assert ind.loc["area_L2"].tolist() == [True, True]
    assert ind.loc["e"].tolist() == [False, False]
    rel = res.relations.set_index("relation")
    # every relation computed across configurations is marked (test below for the means)
    computed = np.isfinite(rel["fitted"].astype(float))
    assert (rel["indicative"] == (computed & rel.index.isin(T.CONFIG_RELATIONS))).all()
    assert rel.loc["eq14_slope", "indicative"]
    assert res.micro["indicative"].dtype == bool
    # the columns are written and read back
    with pytest.warns(SmallSampleWarning):
        write_report(ens, tmp_path / "r", opts=opts, figures=False)
    rep = D.load_report(tmp_path / "r")
    for name in ("fits", "micro", "relations", "correlations"):
        back, ours = getattr(rep, name), getattr(res, name)
        assert back["indicative"].dtype == bool
        assert back["indicative"].tolist() == ours["indicative"].tolist()


def test_micro_marks_gamma_parameters_of_few_values_indicative(tmp_path):
    sim = demo.write_demo_simulation(tmp_path / "tiny", n_configs=8, seed=1)
    res = T.compute_stats(D.load_any(sim), T.StatsOptions(
        n_boot=0, gof=False, quantities=("E", "e")))
    mic = res.micro.set_index("region").loc["all"]
    # alpha_E rests on the 8 configurations' energies
    assert np.isfinite(mic["alpha_E"]) and mic["indicative"]
    # ... alpha_e on the ~150 branch energies: a flag for each fit, as the report marks cells
    assert mic["indicative_E"] and not mic["indicative_e"]
    assert res.dof[["indicative_E", "indicative_e"]].values.tolist() == [[True, False]]
    big = demo.write_demo_simulation(tmp_path / "big", n_configs=60, seed=1)
    res = T.compute_stats(D.load_any(big), T.StatsOptions(
        n_boot=0, gof=False, quantities=("E", "e")))
    assert not res.micro["indicative"].any()


def test_nothing_fitted_keeps_the_fits_columns(tmp_path):
    sim = demo.write_demo_simulation(tmp_path / "tiny", n_configs=3, seed=1)
    res = T.compute_stats(D.load_any(sim), T.StatsOptions(n_boot=0, gof=False,
                                                          min_n=10**6))
    assert res.fits.empty and list(res.fits.columns) == T.fits_columns()
    assert {"selected", "family", "indicative"} <= set(res.fits.columns)
    assert res.fits[res.fits["selected"].astype(bool)].empty


@pytest.mark.filterwarnings("ignore::crosssection.quality.QualityWarning")  # a built ensemble
def test_two_configurations_give_no_correlation_in_the_table_or_the_figure():
    # two points always lie on a line: r = +-1 says nothing, in the table as in the legend
    import matplotlib

    matplotlib.use("Agg")
    from crosssection.stats.report import _scatter_fig

    ens = _relations_ensemble(np.random.default_rng(5), n=T.CORRELATION_MIN_PAIRS - 1)
    cor = T.correlations_table(ens).set_index("pair")
    assert np.isnan(cor.loc["E_vs_N_br", "pearson_r"])
    res = T.compute_stats(ens, T.StatsOptions(n_boot=0, gof=False))
    fig = _scatter_fig(res, "N_br", "E", "N_br", "E", "E against N_br")
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert labels and not any("Pearson" in label for label in labels)
    three = _relations_ensemble(np.random.default_rng(5), n=T.CORRELATION_MIN_PAIRS)
    fig3 = _scatter_fig(T.compute_stats(three, T.StatsOptions(n_boot=0, gof=False)),
                        "N_br", "E", "N_br", "E", "E against N_br")
    labels3 = fig3.axes[0].get_legend_handles_labels()[1]
    # the number of pairs is in the legend, as the coefficient rests on it
    assert any("Pearson r = " in label and f"(n = {T.CORRELATION_MIN_PAIRS}, indicative only)"
               in label for label in labels3)
    many = _relations_ensemble(np.random.default_rng(5), n=T.N_RELATION_MIN)
    fig5 = _scatter_fig(T.compute_stats(many, T.StatsOptions(n_boot=0, gof=False)),
                        "N_br", "E", "N_br", "E", "E against N_br")
    assert any(f"(n = {T.N_RELATION_MIN})" in label
               for label in fig5.axes[0].get_legend_handles_labels()[1])


def test_a_simulation_resumed_under_other_versions_reports_every_version(tmp_path):
    import json

    from crosssection.stats.report import provenance

    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=3, seed=1)
    p = {"command": "quench", "n_segments": 300}
    runs = [{"version": "0.0.1", "libraries": {"numpy": "1.0.0"}},
            {"version": "0.0.2", "libraries": {"numpy": "2.0.0"}}]
    (sim / "params.json").write_text(json.dumps({**p, "version": "0.0.1",
                                                 "libraries": runs[0]["libraries"],
                                                 "versions": runs}))
    prov = provenance(D.load_any(sim))
    assert prov["versions"] == ["0.0.1", "0.0.2"]
    assert prov["libraries"]["numpy"] == ["1.0.0", "2.0.0"]
    assert "versions" not in prov["parameters"]  # a record of the code, not a parameter


def test_a_detection_limit_above_every_value_is_named(tmp_path):
    from crosssection.stats import SmallSampleWarning

    batch = demo.write_demo_batch(tmp_path / "b", n_images=3, seed=2)
    ens = D.load_any(batch, l_min_mm=1e6)  # a kilometre: above every branch
    opts = T.StatsOptions(n_boot=0, gof=False, quantities=("length_L",))
    with pytest.warns(SmallSampleWarning) as rec:
        T.compute_stats(ens, opts)
    msgs = [str(w.message) for w in rec if w.category is SmallSampleWarning]
    for s, n in ens.branches.groupby("set").size().items():  # each set names its own
        assert any(m.startswith(f"set {s}: ") and f"length_L n = 0 ({n} below the detection "
                   "limit or not finite)" in m for m in msgs), msgs


def test_the_ratio_interval_combines_the_two_shapes_intervals():
    # alpha_e known exactly: the ratio's interval is alpha_E's over it
    assert T.dof_ratio_interval(20.0, (10.0, 40.0), 0.5, (0.5, 0.5)) == pytest.approx((20.0, 80.0))
    # both uncertain: each side wider than either shape's alone, on a log scale in quadrature
    lo, hi = T.dof_ratio_interval(20.0, (10.0, 40.0), 0.5, (0.25, 1.0))
    assert lo == pytest.approx(40.0 * np.exp(-np.hypot(np.log(2), np.log(2))))
    assert hi == pytest.approx(40.0 * np.exp(np.hypot(np.log(2), np.log(2))))
    assert np.isnan(T.dof_ratio_interval(20.0, (np.nan, np.nan), 0.5, (0.4, 0.6))).all()
    # alpha_E unbounded above: the ratio too, its lower bound kept
    lo, hi = T.dof_ratio_interval(20.0, (10.0, np.inf), 0.5, (0.25, 1.0))
    assert lo == pytest.approx(40.0 * np.exp(-np.hypot(np.log(2), np.log(2)))) and hi == np.inf


@pytest.mark.filterwarnings("ignore::crosssection.quality.QualityWarning")  # a built ensemble
def test_a_fit_through_zero_on_few_configurations_is_marked_in_the_legend():
    # the figure's slope rested on two configurations and said nothing of it
    import matplotlib

    matplotlib.use("Agg")
    from crosssection.stats.report import _scatter_fig

    def legend(n):
        res = T.compute_stats(_relations_ensemble(np.random.default_rng(5), n=n),
                              T.StatsOptions(n_boot=0, gof=False))
        fig = _scatter_fig(res, "l_bar", "sqrt_s_bar", "l", "sqrt(s)", "s against l",
                           through_origin=True)
        return [t for t in fig.axes[0].get_legend_handles_labels()[1] if "fit through 0" in t]

    assert [t.endswith("(n = 2, indicative only)") for t in legend(2)] == [True]
    assert [t.endswith("indicative only)") for t in legend(T.N_RELATION_MIN)] == [False]
