"""What ``stats`` takes from its inputs and records of them: the detection limits the scans
were analysed with, an unfinished batch, scans the analysis flagged, the parameters and
versions that made the data; per-set random streams; checked hand-built ensembles; and the
figures' detection limits and stack-size gaps."""
import json
import warnings

import matplotlib
import numpy as np
import pandas as pd
import pytest

from crosssection.cli import main
from crosssection.core.errors import ParameterError
from crosssection.stats import demo, report
from crosssection.stats.data import (BRANCH_COLS, STACK_COLS, VOID_COLS, DetectionLimitWarning,
                                     Ensemble, MixedParametersWarning, FlaggedScanWarning, load_any)
from crosssection.stats.tables import StatsOptions, compute_stats, set_seed

matplotlib.use("Agg")
FAST = ["--n-boot", "0", "--no-gof", "--no-figures"]


def _summaries(root):
    return sorted(root.glob("*/*/summary.json"))


def _edit(path, **entries):
    s = json.loads(path.read_text())
    s.update(entries)
    path.write_text(json.dumps(s))


@pytest.fixture
def analysed(tmp_path):
    """A batch whose summaries record the analysis' parameters: l_min 2 mm, and one scan
    with h = 0.08 mm (s_min (10 h)^2 = 0.64 mm^2) beside h = 0.1 mm ones."""
    root = demo.write_demo_batch(tmp_path / "b", n_images=3, seed=4,
                                 sets={"s1": {"n_stacks": 15, "l_min_mm": 2.0}})
    for i, summ in enumerate(_summaries(root)):
        h = 0.08 if i == 0 else 0.1
        _edit(summ, version="9.9.9", parameters={"l_min_mm": 2.0, "s_min_mm2": None,
                                                 "thickness_mm": h, "px_per_mm": 50.0})
    return root


def _stats(capfd, *argv, mixed: bool = False):
    """(status, warning lines); the line on the fixture's two sheet thicknesses only with
    ``mixed``."""
    capfd.readouterr()
    status = main(["stats", *map(str, argv)])
    out, err = capfd.readouterr()
    err = [ln for ln in err.splitlines()
           if not (": set " in ln and ln.endswith("indicative only"))
           and (mixed or "made with different parameters" not in ln)]
    return status, err


def test_loaders_use_the_limits_each_scan_was_analysed_with(analysed):
    ens = load_any(analysed)
    L = ens.configs.set_index("config_id")["rod_length_mm"]
    br_mm = ens.branches["l_min_L"] * ens.branches["config_id"].map(L)
    assert np.allclose(br_mm, 2.0)
    s_mm2 = (ens.voids["s_min_L2"] * ens.voids["config_id"].map(L) ** 2).round(9)
    assert sorted(set(s_mm2)) == [0.64, 1.0]


def test_a_given_limit_wins_but_below_the_analysis_one_warns(analysed):
    with pytest.warns(DetectionLimitWarning, match=r"l_min = 1 mm given for set s1 is below "
                                                   r"the 2 mm its analysis used"):
        ens = load_any(analysed, l_min_mm=1.0)
    L = ens.configs.set_index("config_id")["rod_length_mm"]
    assert np.allclose(ens.branches["l_min_L"] * ens.branches["config_id"].map(L), 1.0)


def test_cli_records_the_limits_used_and_warns_below_them(analysed, tmp_path, capfd):
    status, err = _stats(capfd, analysed, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and err == []
    meta = json.loads((tmp_path / "rep" / "stats.json").read_text())
    assert meta["detection_limits"] == {"l_min_mm": 2.0, "s_min_mm2": [0.64, 1.0]}
    assert meta["sets"]["s1"]["detection_limits"]["l_min_mm"] == 2.0
    assert meta["detection_limits_given"] == {}
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "s1: l_min = 2 mm" in page
    status, err = _stats(capfd, analysed, "--out", tmp_path / "rep2", "--s-min-mm2", "0.5",
                         *FAST)
    assert status == 0
    assert len(err) == 1 and err[0].startswith(f"warning: {analysed}: s_min = 0.5 mm^2 given")
    meta = json.loads((tmp_path / "rep2" / "stats.json").read_text())
    assert meta["detection_limits_given"] == {"s_min_mm2": 0.5}


def test_report_records_an_unfinished_batch(analysed, tmp_path, capfd):
    (analysed / "batch.json").write_text(json.dumps({"n_images": 12, "complete": False}))
    status, err = _stats(capfd, analysed, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and len(err) == 1 and "did not finish" in err[0]
    meta = json.loads((tmp_path / "rep" / "stats.json").read_text())
    assert meta["incomplete_batches"] == [f"{analysed / 'batch.json'}: the batch did not "
                                          "finish (interrupted, or still running): only 3 "
                                          "of its 12 images are done and used"]
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "Incomplete input" in page and "only 3 of its 12 images" in page


def test_flagged_scans_give_one_warning_line_each(analysed, tmp_path, capfd):
    first = _summaries(analysed)[0]
    _edit(first, quality={"ok": False, "codes": ["no_calibration", "layer_lattice"],
                          "flags": []})
    status, err = _stats(capfd, analysed, "--out", tmp_path / "rep", *FAST)
    assert status == 0
    assert err == [f"warning: {first}: flagged by the analysis: no_calibration, layer_lattice"]
    with pytest.warns(FlaggedScanWarning):
        load_any(analysed)


def test_many_flagged_scans_of_a_set_give_one_line(tmp_path):
    root = demo.write_demo_batch(tmp_path / "b", n_images=7, seed=1,
                                 sets={"s1": {"n_stacks": 10}})
    for summ in _summaries(root):
        _edit(summ, quality={"ok": False, "codes": ["count_width"], "flags": []})
    with pytest.warns(FlaggedScanWarning) as rec:
        load_any(root)
    flagged = [w for w in rec if w.category is FlaggedScanWarning]
    assert len(flagged) == 1 and "set s1: 7 of 7 scans flagged" in str(flagged[0].message)


def test_stats_json_records_resolved_inputs_and_what_made_the_data(analysed, tmp_path, capfd,
                                                                   monkeypatch):
    monkeypatch.chdir(analysed.parent)
    status, err = _stats(capfd, "b", "--out", tmp_path / "rep", *FAST, mixed=True)
    assert status == 0
    assert err == [f"warning: {tmp_path / 'rep'}: set 's1' pools configurations made with "
                   "different parameters (thickness_mm: 0.08, 0.1): its statistics mix "
                   "measurements not made alike (analyse them again with one set of "
                   "parameters, or give them different set names)"]
    meta = json.loads((tmp_path / "rep" / "stats.json").read_text())
    assert meta["inputs"] == [str(analysed.resolve())]
    assert list(meta["sets_of_inputs"]) == [str(analysed.resolve())]
    made = meta["sets"]["s1"]["made_by"]
    assert made["versions"] == ["9.9.9"]
    assert made["parameters"]["l_min_mm"] == 2.0
    assert made["parameters_differing"] == {"thickness_mm": [0.08, 0.1]}
    assert "thickness_mm (0.08, 0.1)" in (tmp_path / "rep" / "report.html").read_text()
    assert "analysis" not in pd.read_csv(tmp_path / "rep" / "per_config.csv").columns


def test_a_set_differing_only_in_each_scans_hole_is_not_mixed(analysed, tmp_path):
    for i, summ in enumerate(_summaries(analysed)):
        _edit(summ, parameters={"l_min_mm": 2.0, "thickness_mm": 0.1, "px_per_mm": 50.0,
                                "hole_radius_mm": 7.0 + i, "calibration": f"c{i}.csv"})
    ens = load_any(analysed)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MixedParametersWarning)
        report.write_report(ens, tmp_path / "rep", opts=StatsOptions(n_boot=0, gof=False),
                            figures=False)


def test_a_sets_intervals_do_not_depend_on_the_other_sets(tmp_path):
    two = load_any(demo.write_demo_batch(tmp_path / "b", n_images=3, seed=2))
    one = Ensemble(*(df[df["set"] == "set3"].reset_index(drop=True)
                     for df in (two.configs, two.branches, two.stacks, two.voids)))
    opts = StatsOptions(seed=3, n_boot=20, gof=False, quantities=("length_L",))
    res2 = compute_stats(two, opts)
    res1 = compute_stats(one, opts)
    assert set_seed(3, "set3") != set_seed(3, "set1")
    ci = lambda res: res.summaries[("set3", "all", "length_L")].results["exponential"].ci  # noqa: E731
    assert ci(res1) == ci(res2)


def _hand_built():
    cfg = pd.DataFrame({"set": "A", "config_id": [0, 1], "N_l": 5.0, "N_br": 9.0,
                        "n_voids": 1.0, "epsilon": 3.0, "E": [10.0, 12.0]})
    br = pd.DataFrame({"set": "A", "config_id": [0, 1] * 5, "length_L": np.linspace(.01, .1, 10),
                       "kappa_m_L": 1.0, "kappa_plus_L": 1.0, "e": 1.0, "region": "none",
                       "n_br": 2.0, "l_min_L": np.nan})
    return cfg, br, pd.DataFrame(columns=STACK_COLS), pd.DataFrame(columns=VOID_COLS)


def test_hand_built_ensembles_are_checked_and_integer_ids_become_text():
    cfg, br, st, vo = _hand_built()
    ens = Ensemble(cfg, br, st, vo)
    assert ens.configs["config_id"].tolist() == ["0", "1"]
    assert ens.branches["config_id"].tolist()[:2] == ["0", "1"]
    with pytest.raises(ParameterError, match=r"Ensemble.branches lacks column\(s\) \['l_min_L'\]"):
        Ensemble(cfg, br.drop(columns="l_min_L"), st, vo)
    with pytest.raises(ParameterError, match=r"Ensemble.voids lacks column\(s\) \['s_min_L2'\]"):
        Ensemble(cfg, br, st, pd.DataFrame({"set": ["A"], "config_id": ["0"],
                                            **{c: [1.0] for c in VOID_COLS[2:-1]}}))
    with pytest.raises(ParameterError, match=r"Ensemble.configs lacks column\(s\) \['set'\]"):
        Ensemble(cfg.drop(columns="set"), br, st, vo)
    with pytest.raises(ParameterError, match="Ensemble.stacks must be a pandas DataFrame"):
        Ensemble(cfg, br, None, vo)
    with pytest.raises(ParameterError, match="'config_id' must hold text or integer"):
        Ensemble(cfg.assign(config_id=[0.5, 1.5]), br, st, vo)
    empty = Ensemble(*(pd.DataFrame() for _ in range(4)))
    assert empty.sets == [] and list(empty.branches.columns) == BRANCH_COLS


def test_dof_and_micro_tables_mark_gamma_fits_on_few_values(analysed):
    ens = load_any(analysed)
    res = compute_stats(ens, StatsOptions(n_boot=0, gof=False, min_n=3))
    dof = report._small_fits_marked(res.dof, res)
    assert "indicative only" in str(dof.loc[0, "alpha_E"])
    assert "indicative only" in str(dof.loc[0, "alpha_E_over_alpha_e"])
    micro = report._small_fits_marked(res.micro, res)
    assert "indicative only" in str(micro.loc[0, "alpha_E"])
    # the CSV says it in its own column, as fits, micro and relations do
    assert res.dof["indicative"].tolist() == [True]
    big = compute_stats(ens, StatsOptions(n_boot=0, gof=False, min_n=3, quantities=("length_L",)))
    assert big.dof["indicative"].tolist() == [False]  # no Gamma of e or E behind it


def test_truncation_keeps_its_columns_when_nothing_was_fitted(analysed):
    from crosssection.stats.fits import TRUNCATION_COLUMNS

    res = compute_stats(load_any(analysed),
                        StatsOptions(n_boot=0, gof=False, min_n=10**6))
    assert res.truncation.empty
    assert list(res.truncation.columns) == ["set", "region", "quantity", *TRUNCATION_COLUMNS]


def test_e_vs_nbr_breaks_the_line_at_missing_stack_sizes():
    cfg, br, st, vo = _hand_built()
    br = br.assign(n_br=[5.0, 5.0, 7.0, 7.0, 9.0, 9.0, 5.0, 7.0, 9.0, 9.0], e=np.arange(10.0))
    fig = report.e_vs_nbr_figure(Ensemble(cfg, br, st, vo))
    line = next(ln for ln in fig.axes[0].lines if len(ln.get_xdata()) > 1)
    x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
    assert x.tolist() == [5, 6, 7, 8, 9]
    assert np.isnan(y[[1, 3]]).all() and np.isfinite(y[[0, 2, 4]]).all()


def test_pdf_figure_draws_the_range_of_per_scan_limits(analysed):
    ens = load_any(analysed)
    res = compute_stats(ens, StatsOptions(n_boot=0, gof=False, quantities=("length_L",)))
    fig = report.pdf_figure(res, ens, "length_L")
    cuts = ens.branches["l_min_L"]
    ax = fig.axes[1]
    line = next(ln for ln in ax.lines if ln.get_gid() == "limit:s1:all")
    assert np.isclose(line.get_xdata()[0], cuts.max())
    assert any(p.get_gid() == "limits:s1:all" for p in ax.patches)
    assert any("detection limits" in t.get_text() and "largest" in t.get_text()
               for t in ax.get_legend().get_texts())


@pytest.mark.filterwarnings("ignore::crosssection.quality.QualityWarning")
def test_nested_sets_are_read_by_their_recorded_names_with_or_without_the_index(tmp_path):
    """Two experiments' day1/ folders are the sets eps8/day1 and eps12/day1; a scan's
    config_id is its folder's name. Without index.csv the sets come from the summaries'
    batch.set, and a folder the batch lists as stale is left out."""
    import shutil
    from pathlib import Path

    from crosssection.stats.data import load_batch

    samples = Path(__file__).resolve().parents[3] / "sample_images"
    for exp, scan in (("eps8", "scan_01_sparse.png"), ("eps12", "scan_05_16bit.tif")):
        d = tmp_path / "in" / exp / "day1"
        d.mkdir(parents=True)
        shutil.copy(samples / scan, d / scan)
        (d / "set.toml").write_text("thickness_mm = 0.1\n")
    out = tmp_path / "out"
    assert main(["batch", str(tmp_path / "in"), "--out", str(out), "--no-figure",
                 "--workers", "1"]) == 0
    want = [("eps12/day1", "scan_05_16bit"), ("eps8/day1", "scan_01_sparse")]
    ens = load_batch(out)
    assert sorted(zip(ens.configs["set"], ens.configs["config_id"])) == want
    (out / "index.csv").unlink()
    shutil.copytree(out / "eps8" / "day1" / "scan_01_sparse", out / "eps8" / "old")
    meta = json.loads((out / "batch.json").read_text())
    (out / "batch.json").write_text(json.dumps({**meta, "stale_outputs": ["eps8/old"]}))
    ens = load_batch(out)
    assert sorted(zip(ens.configs["set"], ens.configs["config_id"])) == want


def test_a_set_folder_inside_a_batch_is_read_through_the_batch_record(analysed, tmp_path,
                                                                      capfd):
    """``stats OUT/<set>`` keeps to what the batch's index.csv records as done: a folder of
    an earlier run that the index no longer lists, and a scan the index records as failed,
    stay out, and an unfinished batch is said, as for ``stats OUT``."""
    import shutil

    from crosssection.stats.data import load_any

    set_dir = analysed / "s1"
    shutil.copytree(set_dir / "img000", set_dir / "img_old")  # an earlier run's leftover
    index = pd.read_csv(analysed / "index.csv")
    index.loc[index["output"] == "s1/img002", "status"] = "failed"
    index.to_csv(analysed / "index.csv", index=False)
    (analysed / "batch.json").write_text(json.dumps({"n_images": 3, "complete": False}))
    with pytest.warns(Warning) as caught:
        ens = load_any(set_dir)
    assert sorted(ens.configs["config_id"]) == ["img000", "img001"]
    assert set(ens.configs["set"]) == {"s1"}
    assert any("did not finish" in str(w.message) for w in caught)
    # the same through the command line
    status, err = _stats(capfd, set_dir, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and any("did not finish" in ln for ln in err)
    per_config = pd.read_csv(tmp_path / "rep" / "per_config.csv")
    assert len(per_config) == 2
    # a set folder whose batch records none of its scans as done is refused in one line
    index["status"] = "failed"
    index.to_csv(analysed / "index.csv", index=False)
    status, err = _stats(capfd, set_dir, "--out", tmp_path / "rep2", *FAST)
    assert status == 2 and len(err) == 1 and "lists none below it as done" in err[0]


def test_a_branch_longer_than_its_rod_is_said(analysed, tmp_path):
    """A branch of five rod lengths (an edited table) moves the mean l/L by half: said."""
    from crosssection.stats.data import load_any

    scan = analysed / "s1" / "img001"
    L = json.loads((scan / "summary.json").read_text())["rod_length_mm"]
    br = pd.read_csv(scan / "branches.csv")
    br.loc[0, "length_mm"] = 5 * L
    br.to_csv(scan / "branches.csv", index=False)
    with pytest.warns(Warning) as caught:
        ens = load_any(analysed)
    said = [str(w.message) for w in caught if "longer than the rod" in str(w.message)]
    assert len(said) == 1 and said[0].startswith(f"{scan / 'branches.csv'}: 1 branch longer")
    assert "l / L up to 5" in said[0]
    note = ens.configs.set_index("config_id").loc["img001", "table_note"]
    assert "longer than the rod" in note
    # a simulation's lengths are in units of its rod: one beyond 1 is said the same way
    from crosssection.stats.data import _check_lengths

    with pytest.warns(Warning, match="2 branches longer than the rod"):
        assert _check_lengths(tmp_path / "branches.csv", [0.2, 1.5, np.nan, 3.0])
    assert _check_lengths(tmp_path / "branches.csv", [0.2, 1.0, np.nan]) == ""
