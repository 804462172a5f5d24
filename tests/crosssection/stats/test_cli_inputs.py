"""The ``stats`` command line on malformed and doubtful inputs, absurd options and report
folders: one ``error:`` line and status 2 for what cannot be used, one ``warning:`` line for
what is used anyway, and a report folder that is always one whole report."""
import json
import os

import pandas as pd
import pytest

from crosssection.cli import build_parser, main
from crosssection.core import fileio
from crosssection.core.errors import ParameterError
from crosssection.quality import QualityWarning
from crosssection.stats import cli, demo, report
from crosssection.stats.data import RECORDED, load_any, load_inputs
from crosssection.stats.tables import StatsOptions

FAST = ["--n-boot", "0", "--no-gof", "--no-figures"]


def _stats(capfd, *argv, small=False):
    """Run ``stats``; return (status, stdout lines, stderr lines): without the small-sample
    warning line of these small sets (see conftest.py) unless ``small``."""
    capfd.readouterr()
    status = main(["stats", *map(str, argv)])
    out, err = capfd.readouterr()
    err = [ln for ln in err.splitlines()
           if small or not (": set " in ln and ln.endswith("indicative only"))]
    return status, out.splitlines(), err


def _batch(root, n_images=3, complete=True):
    """A small batch output with the ``batch.json`` of a finished (or interrupted) batch."""
    demo.write_demo_batch(root, n_images=n_images, seed=4, sets={"s1": {"n_stacks": 15}})
    meta = {"n_images": n_images, "complete": complete}
    (root / "batch.json").write_text(json.dumps(meta))
    return root


@pytest.fixture
def batch(tmp_path):
    return _batch(tmp_path / "batch")


def _replace_cell(path, column, value, row=0):
    df = pd.read_csv(path)
    df[column] = df[column].astype(object)
    df.loc[row, column] = value
    df.to_csv(path, index=False)


# --------------------------------------------------------------- malformed inputs: status 2


@pytest.mark.parametrize("table, column", [("branches.csv", "length_mm"),
                                           ("branches.csv", "energy"),
                                           ("stacks.csv", "n_br"),
                                           ("voids.csv", "area_mm2")])
def test_text_in_a_numeric_column_of_a_scan_is_one_error_line(batch, tmp_path, capfd, table,
                                                              column):
    path = batch / "s1" / "img001" / table
    _replace_cell(path, column, "abc", row=2)
    status, out, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 2 and out == []
    assert err == [f"error: {path}: column {column} holds 'abc' in data row 3 where a number "
                   "is expected"]
    assert not (tmp_path / "rep").exists()


def test_text_in_a_simulation_table_is_one_error_line(tmp_path, capfd):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=4, seed=1)
    _replace_cell(sim / "branches.csv", "kappa_pm", "abc")
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    assert status == 2
    assert err == [f"error: {sim / 'branches.csv'}: column kappa_pm holds 'abc' in data row 1 "
                   "where a number is expected"]


@pytest.mark.parametrize("content, cause", [
    ("[1, 2]", "holds a JSON list, not an object"),
    ('"text"', "holds a JSON string, not an object"),
    (None, 'n_branches is "many", not a number'),
    (None, "rod_length_mm is true, not a number"),
    (None, "quality is not an object with a list of codes"),
    (b"\xff\xfe\x00binary", "unreadable summary.json (not a text file)"),
])
def test_malformed_summary_is_one_error_line(batch, tmp_path, capfd, content, cause):
    path = batch / "s1" / "img000" / "summary.json"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    else:
        summary = json.loads(path.read_text())
        key = cause.split()[0]
        summary[key] = {"n_branches": "many", "rod_length_mm": True, "quality": "bad"}[key]
        path.write_text(json.dumps(summary))
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 2 and err == [f"error: {path}: {cause}"]


# ------------------------------------------------------------------ absurd options: status 2


@pytest.mark.parametrize("option, value, cause", [
    ("--seed", "-1", "must be an integer >= 0, got -1"),
    ("--n-boot", "-1", "must be an integer >= 0, got -1"),
    ("--n-mc", "-5", "must be an integer >= 1, got -5"),
    ("--n-boot", "100001", "must be at most 100000, got 100001"),
    ("--n-mc", "1000000000", "must be at most 100000, got 1000000000"),
    ("--l-min-mm", "-1", "must be a finite number >= 0 (0 = no limit), got -1"),
    ("--l-min-mm", "inf", "must be a finite number >= 0 (0 = no limit), got inf"),
    ("--s-min-mm2", "nan", "must be a finite number >= 0 (0 = no limit), got nan"),
    ("--s-min-mm2", "-0.5", "must be a finite number >= 0 (0 = no limit), got -0.5"),
])
def test_absurd_option_is_one_error_line_naming_it(batch, tmp_path, capfd, option, value,
                                                   cause):
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST, option, value)
    assert status == 2 and err == [f"error: {option}: {cause}"]
    assert not (tmp_path / "rep").exists()


def test_the_resample_bound_is_said_in_the_help_and_accepted(capfd):
    with pytest.raises(SystemExit):
        main(["stats", "--help"])
    help_text = " ".join(capfd.readouterr().out.split())
    opts = StatsOptions()
    assert f"0 (none) to {cli.MAX_RESAMPLES} (default {opts.n_boot})" in help_text
    assert f"at most {cli.MAX_RESAMPLES} (default {opts.n_mc})" in help_text
    args = build_parser(["stats"]).parse_args(
        ["stats", "d", "--out", "r", "--n-boot", str(cli.MAX_RESAMPLES),
         "--n-mc", str(cli.MAX_RESAMPLES)])
    cli.check_options(args)  # the bound itself is no absurd value


def test_the_help_says_how_a_sets_seed_is_derived_and_reproduced(batch, tmp_path, capfd):
    """Each set's stream derives from --seed and its name: the help says so, and how to get
    the same numbers again; stats.json records each set's seed."""
    from crosssection.stats.tables import set_seed

    with pytest.raises(SystemExit):
        main(["stats", "--help"])
    help_text = " ".join(capfd.readouterr().out.split())
    assert "derived from this seed and the set's name" in help_text
    assert "same --seed and the same set names (--name)" in help_text
    assert "set_seed" in StatsOptions.__doc__ and "set name" in StatsOptions.__doc__
    status, _, _ = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST, "--seed", "7",
                          "--name", "exp")
    assert status == 0
    sets = json.loads((tmp_path / "rep" / "stats.json").read_text())["sets"]
    assert {name: v["seed"] for name, v in sets.items()} == {
        name: set_seed(7, name) for name in sets}


def test_the_defaults_are_those_of_the_statistics_and_the_loader(capfd):
    """One source: the options' defaults, and the help saying them, are StatsOptions' and
    load_inputs'."""
    import inspect

    opts = StatsOptions()
    limits = inspect.signature(load_inputs).parameters
    args = build_parser(["stats"]).parse_args(["stats", "d", "--out", "r"])
    # --n-boot and --n-mc are None when not given (so that --fast can tell them apart)
    assert (args.seed, *cli.resamples(args)) == (opts.seed, opts.n_boot, opts.n_mc)
    # not given: each scan keeps the limits its analysis used, the loader's default
    assert args.l_min_mm is None and limits["l_min_mm"].default == RECORDED
    assert args.s_min_mm2 is None and limits["s_min_mm2"].default == RECORDED
    with pytest.raises(SystemExit):
        main(["stats", "--help"])
    help_text = " ".join(capfd.readouterr().out.split())
    assert "(default: the l_min each scan was analysed with" in help_text
    assert "(default: the s_min each scan was analysed with" in help_text
    assert (f"quick look: {cli.FAST_N_BOOT} bootstrap resamples and {cli.FAST_N_MC} GOF "
            "samples") in help_text


@pytest.mark.parametrize("flags, want", [
    (["--n-boot", "70", "--fast"], (70, cli.FAST_N_MC)),  # an explicit value wins
    (["--fast", "--n-mc", "19"], (cli.FAST_N_BOOT, 19)),
    (["--n-boot", "70", "--n-mc", "19"], (70, 19))])
def test_explicit_resamples_win_over_fast(batch, tmp_path, capfd, monkeypatch, flags, want):
    seen = {}
    monkeypatch.setattr(report, "write_report",
                        lambda ens, out, *, opts, **kw: seen.setdefault("opts", opts) and [])
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", "--no-figures", *flags)
    assert status == 0 and err == []
    assert (seen["opts"].n_boot, seen["opts"].n_mc) == want


def test_too_few_bootstrap_resamples_give_a_warning(batch, tmp_path, capfd):
    from crosssection.stats.fits import N_BOOT_MIN

    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", "--no-figures",
                            "--no-gof", "--n-boot", "1")
    assert status == 0
    # a warning about an option names the report it is about
    assert err == [f"warning: {tmp_path / 'rep'}: n_boot 1: fewer than the {N_BOOT_MIN} "
                   "bootstrap resamples a "
                   "95 % percentile interval needs (its ends are then the extreme draws): the "
                   "intervals are indicative only"]
    assert json.loads((tmp_path / "rep" / "stats.json").read_text())["options"]["n_boot"] == 1
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", "--no-figures",
                            "--no-gof", "--n-boot", str(N_BOOT_MIN))
    assert status == 0 and err == []


@pytest.mark.parametrize("flags, fast", [([], False), (["--fast"], True)])
def test_fast_runs_the_resamples_its_help_says(batch, tmp_path, capfd, monkeypatch, flags,
                                               fast):
    seen = {}

    def fake_report(ens, out, *, opts, **kwargs):
        seen["opts"] = opts
        return []

    monkeypatch.setattr(report, "write_report", fake_report)
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", "--no-figures", *flags)
    assert status == 0 and err == []
    want = (cli.FAST_N_BOOT, cli.FAST_N_MC) if fast else (StatsOptions().n_boot,
                                                          StatsOptions().n_mc)
    assert (seen["opts"].n_boot, seen["opts"].n_mc) == want
    # a quick look: fewer resamples than the default run
    assert cli.FAST_N_BOOT < StatsOptions().n_boot and cli.FAST_N_MC < StatsOptions().n_mc


def test_one_name_for_two_dirs_is_refused(batch, tmp_path, capfd):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=4, seed=1)
    status, out, err = _stats(capfd, batch, sim, "--out", tmp_path / "rep", *FAST,
                              "--name", "X", "--name", "X")
    assert status == 2 and out == []
    assert err == [f"error: --name: 'X' given for both {batch} and {sim}: give each DIR its "
                   "own set name"]
    assert not (tmp_path / "rep").exists()
    # one folder under two spellings is one set: read once, as without --name
    status, _, err = _stats(capfd, sim, f"{sim}/", "--out", tmp_path / "rep", *FAST,
                            "--name", "X", "--name", "X")
    assert status == 0 and err == [f"warning: {sim}/: given twice (also as {sim}); "
                                   "counted once"]


def test_two_dirs_of_one_folder_name_are_kept_apart_as_documented(tmp_path, capfd):
    a = demo.write_demo_simulation(tmp_path / "a" / "run", n_configs=6, seed=1)
    b = demo.write_demo_simulation(tmp_path / "b" / "run", n_configs=6, seed=2)
    status, _, err = _stats(capfd, a, b, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and err == []
    assert set(pd.read_csv(tmp_path / "rep" / "macro.csv")["set"]) == {"run", "run#2"}
    with pytest.raises(SystemExit):
        main(["stats", "--help"])
    assert "kept apart as run, run#2" in " ".join(capfd.readouterr().out.split())


def test_zero_detection_limits_mean_none(batch, tmp_path, capfd):
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", "--l-min-mm", "0",
                            "--s-min-mm2", "0", *FAST)
    assert status == 0 and err == []
    meta = json.loads((tmp_path / "rep" / "stats.json").read_text())
    assert meta["detection_limits"] == {"l_min_mm": None, "s_min_mm2": None}
    assert "l_min = none, s_min = none" in (tmp_path / "rep" / "report.html").read_text()


def test_report_records_the_limits_and_the_sets_of_each_dir(batch, tmp_path, capfd):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=4, seed=1)
    status, _, err = _stats(capfd, batch, sim, "--out", tmp_path / "rep", "--l-min-mm", "2",
                            "--s-min-mm2", "1.5", *FAST, "--name", "exp", "--name", "simu")
    # the limits cut the scans; the simulation, in units of its rod length, is told apart
    assert status == 0 and len(err) == 1 and str(sim) in err[0] and "not applied" in err[0]
    meta = json.loads((tmp_path / "rep" / "stats.json").read_text())
    assert meta["detection_limits"] == {"l_min_mm": 2.0, "s_min_mm2": 1.5}
    assert meta["sets_of_inputs"] == {str(batch): ["exp"], str(sim): ["simu"]}
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "here l_min = 2 mm, s_min = 1.5 mm²" in page
    assert "each scan's analysis records" not in page
    assert f"{batch} (set exp), {sim} (set simu)" in page
    # the page says it of the simulation's set, not of the scans'
    assert page.count("the limits given are not applied") == 1
    assert "simu: l_min = none, s_min = none (the limits given are not applied" in page


# ------------------------------------------------------- doubtful inputs: one warning, used


def test_clean_batch_gives_no_warning(batch, tmp_path, capfd):
    status, out, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and err == [] and "3 configurations" in out[0]


def test_interrupted_batch_is_used_with_a_warning(tmp_path, capfd):
    b = _batch(tmp_path / "batch", complete=False)
    meta = json.loads((b / "batch.json").read_text())
    meta.update(n_images=10)
    (b / "batch.json").write_text(json.dumps(meta))
    status, out, err = _stats(capfd, b, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and "3 configurations" in out[0]
    assert err == [f"warning: {b / 'batch.json'}: the batch did not finish (interrupted, or "
                   "still running): only 3 of its 10 images are done and used"]


def test_batch_json_without_complete_is_an_unfinished_batch(tmp_path, capfd):
    b = _batch(tmp_path / "batch")
    (b / "batch.json").write_text(json.dumps({"n_images": 3}))  # written when a batch starts
    status, _, err = _stats(capfd, b, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and len(err) == 1 and "did not finish" in err[0]


def test_truncated_branch_table_is_used_with_a_warning(batch, tmp_path, capfd):
    path = batch / "s1" / "img002" / "branches.csv"
    n = len(pd.read_csv(path))
    pd.read_csv(path).head(3).to_csv(path, index=False)
    status, out, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 0
    assert err == [f"warning: {path}: holds 3 branches where summary.json counts {n} "
                   "(truncated or edited?); the 3 rows are used"]
    with pytest.warns(QualityWarning, match="summary.json counts"):
        assert len(load_any(batch).branches.query("config_id == 'img002'")) == 3


def test_a_table_cut_inside_its_last_line_counts_no_row_of_it(batch, tmp_path, capfd):
    # a stacks.csv cut to 200 bytes: its cut-off line was read as a row (one n_br NaN)
    path = batch / "s1" / "img002" / "stacks.csv"
    text = path.read_bytes()
    first, second = text.split(b"\n")[:2]
    path.write_bytes(first + b"\n" + second + b"\n" + second[:len(second) // 3])
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and len(err) == 1 and "the 1 rows are used" in err[0], err
    # a table that only lacks its final newline (edited by hand) keeps every row
    path.write_bytes(first + b"\n" + second)
    from crosssection.stats.data import _read_csv

    assert len(_read_csv(path, ["n_br"])) == 1


def test_a_truncated_table_gives_every_count_of_its_scan_and_is_reported(batch, tmp_path,
                                                                         capfd):
    # the rows are used: for the counts of the whole system as for bulk and periphery
    path = batch / "s1" / "img002" / "branches.csv"
    pd.read_csv(path).head(3).to_csv(path, index=False)
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and len(err) == 1
    rep = tmp_path / "rep"
    m = pd.read_csv(rep / "macro.csv").set_index("region")
    assert m.loc["all", "N_br"] == pytest.approx(m.loc["bulk", "N_br"]
                                                 + m.loc["periphery", "N_br"])
    assert m.loc["all", "N_br"] * m.loc["all", "n_configs"] == m.loc["all", "n_branches"]
    pc = pd.read_csv(rep / "per_config.csv", dtype={"config_id": str}).set_index("config_id")
    assert pc.loc["img002", "N_br"] == 3
    assert pc["N_br"].sum() == m.loc["all", "n_branches"]
    said = err[0].removeprefix("warning: ")
    assert json.loads((rep / "stats.json").read_text())["tables_unlike_summary"] == [said]
    assert pc.loc["img002", "table_note"] == said and pc["table_note"].isna().sum() == 2
    page = (rep / "report.html").read_text()
    assert "Table unlike its summary.json" in page and str(path) in page


def test_failed_simulation_configurations_are_recorded_in_the_report(tmp_path, capfd):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    cfg = pd.read_csv(sim / "configs.csv")
    results = [c for c in cfg.columns if c not in ("config_id", "seed")]
    cfg[results] = cfg[results].astype(object)
    cfg.loc[2, results] = None  # as simulate's assemble writes a failed configuration
    cfg["error"] = ["", "", "RuntimeError: boom", "", "", ""]
    cfg.to_csv(sim / "configs.csv", index=False)
    br = pd.read_csv(sim / "branches.csv")
    br[br["config_id"] != 2].to_csv(sim / "branches.csv", index=False)
    status, out, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    said = (f"{sim / 'configs.csv'}: 1 of 6 configurations failed in the simulation "
            "(config_id 2; see failures.csv) and is not in the statistics")
    assert status == 0 and "5 configurations" in out[0] and err == [f"warning: {said}"]
    meta = json.loads((tmp_path / "rep" / "stats.json").read_text())
    assert meta["incomplete_batches"] == [said]
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "Incomplete input" in page and "(config_id 2; see failures.csv)" in page


def test_a_simulation_whose_every_configuration_failed_is_one_line(tmp_path, capfd):
    """It crashed in the figures (the maximum of no value), exit 1."""
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=2, seed=1)
    cfg = pd.read_csv(sim / "configs.csv")
    results = [c for c in cfg.columns if c not in ("config_id", "seed")]
    cfg[results] = cfg[results].astype(object)
    cfg.loc[:, results] = None
    cfg["error"] = "RuntimeError: boom"
    cfg.to_csv(sim / "configs.csv", index=False)
    for name in ("branches.csv", "stacks.csv", "voids.csv"):
        if (sim / name).is_file():
            pd.read_csv(sim / name).iloc[:0].to_csv(sim / name, index=False)
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    assert status == 2 and err == [f"error: {sim}: ensemble holds no finished configuration "
                                   "(all 2 failed in the simulation; see failures.csv)"]
    assert not (tmp_path / "rep").exists()


def test_the_same_folder_twice_is_counted_once(batch, tmp_path, capfd):
    status, out, err = _stats(capfd, batch, f"{batch}{os.sep}", "--out", tmp_path / "rep",
                              *FAST)
    assert status == 0 and "1 set(s), 3 configurations" in out[0]
    assert err == [f"warning: {batch}{os.sep}: given twice (also as {batch}); counted once"]
    assert set(pd.read_csv(tmp_path / "rep" / "macro.csv")["set"]) == {"s1"}


def test_an_image_folder_of_a_batch_given_too_is_counted_once(batch, tmp_path, capfd):
    img = batch / "s1" / "img001"
    status, out, err = _stats(capfd, batch, img, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and "1 set(s), 3 configurations" in out[0]
    assert err == [f"warning: {img}: its image outputs were already read from {batch}; "
                   "counted once"]
    status, out, err = _stats(capfd, img, batch, "--out", tmp_path / "rep2", *FAST)
    assert status == 0 and "3 configurations" in out[0]
    assert err == [f"warning: {batch}: 1 of its 3 image outputs were already read from {img}; "
                   "counted once"]


def test_unparsable_index_line_is_left_out_with_a_warning(batch, tmp_path, capfd):
    index = batch / "index.csv"
    lines = index.read_text().splitlines()
    lines[2] = "img001.png,s1,ok"  # too few fields: the image it lists is unknown
    index.write_text("\n".join(lines) + "\n")
    status, out, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and "2 configurations" in out[0]
    assert err == [f"warning: {index}: cannot parse line(s) 3 (not one field per column); "
                   "the images listed there are left out"]


def test_unreadable_index_falls_back_to_the_folders_with_a_warning(batch, tmp_path, capfd):
    index = batch / "index.csv"
    index.write_bytes(b"\xff\xfe\x00\x01garbage")
    status, out, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and "3 configurations" in out[0]
    assert err == [f"warning: {index}: unreadable (not a text file); every */summary.json "
                   f"below {batch} is read instead"]


def test_image_listed_as_done_without_its_folder_gives_a_warning(batch, tmp_path, capfd):
    (batch / "s1" / "img000" / "summary.json").unlink()
    status, out, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and "2 configurations" in out[0]
    assert err == [f"warning: {batch / 'index.csv'}: 1 image(s) listed as done have no "
                   "summary.json (s1/img000) and are left out"]


# ------------------------------------------------------ the report folder: old or new, whole


def _interrupted(*args, **kwargs):
    raise KeyboardInterrupt


def _snapshot(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def _hidden_beside(folder):
    return sorted(p.name for p in folder.parent.iterdir() if p.name.startswith("."))


def test_a_report_without_figures_replaces_one_with_figures(tmp_path, capfd):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    rep = tmp_path / "rep"
    assert _stats(capfd, sim, "--out", rep, "--n-boot", "0", "--no-gof")[0] == 0
    assert list((rep / "figures").glob("*.png"))
    status, out, _ = _stats(capfd, sim, "--out", rep, *FAST)
    assert status == 0 and "(16 files)" in out[0]
    assert not (rep / "figures").exists()  # no stale figures beside the new tables
    assert "figures/" not in (rep / "report.html").read_text()
    assert _hidden_beside(rep) == []


def test_an_interrupted_report_leaves_the_old_one_whole(tmp_path, capfd, monkeypatch):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    rep = tmp_path / "rep"
    assert _stats(capfd, sim, "--out", rep, *FAST)[0] == 0
    before = _snapshot(rep)

    # the new report's tables are written by then, its figures not yet
    monkeypatch.setattr(report, "save_figure", _interrupted)
    status, out, err = _stats(capfd, sim, "--out", rep, "--n-boot", "0", "--no-gof",
                              "--seed", "5")
    assert status == 130 and out == []
    assert err == [f"error: {rep}: interrupted; the report folder was left as it was (re-run "
                   "the command to write it)"]
    assert _snapshot(rep) == before
    assert _hidden_beside(rep) == []


def test_an_interrupted_first_report_leaves_nothing(tmp_path, capfd, monkeypatch):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    monkeypatch.setattr(report, "write_text", _interrupted)
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    assert status == 130
    assert err == [f"error: {tmp_path / 'rep'}: interrupted; no report was written (re-run the "
                   "command to write it)"]
    assert not (tmp_path / "rep").exists() and _hidden_beside(tmp_path / "rep") == []


def test_a_full_disk_names_the_report_folder_not_its_working_folder(tmp_path, capfd,
                                                                     monkeypatch):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)

    def full(path, text):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(report, "write_text", full)
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    assert status == 2
    assert err[-1] == f"error: {tmp_path / 'rep'}: cannot write (No space left on device)"
    assert not (tmp_path / "rep").exists() and _hidden_beside(tmp_path / "rep") == []


def test_a_failed_swap_puts_the_old_report_back(tmp_path, monkeypatch):
    old, new = tmp_path / "rep", tmp_path / ".rep.partial-x"
    for folder, text in ((old, "old"), (new, "new")):
        folder.mkdir()
        (folder / "report.html").write_text(text)
    real_replace = os.replace

    def failing(src, dst):
        if src == new:
            raise OSError(28, "No space left on device", str(dst))
        real_replace(src, dst)

    monkeypatch.setattr(fileio.os, "replace", failing)
    with pytest.raises(OSError):
        fileio.swap_in_folder(new, old)
    assert (old / "report.html").read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == [".rep.partial-x", "rep"]


def test_leftovers_of_a_killed_run_are_removed(tmp_path, capfd):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    for name in (".rep.partial-abc", ".rep.old-def"):
        (tmp_path / name / "figures").mkdir(parents=True)
    assert _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)[0] == 0
    assert _hidden_beside(tmp_path / "rep") == []


def test_report_folder_is_created_with_its_parents(tmp_path, capfd):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    out = tmp_path / "a" / "b" / "rep"
    assert _stats(capfd, sim, "--out", out, *FAST)[0] == 0
    assert (out / "report.html").is_file() and (out / "stats.json").is_file()
    assert out.stat().st_mode & 0o777 == 0o777 & ~_umask()  # not mkdtemp's 0700


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


@pytest.mark.parametrize("where", ["file", "under_file"])
def test_a_file_in_the_way_is_refused_before_the_work(tmp_path, capfd, monkeypatch, where):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    (tmp_path / "afile").write_text("keep")
    out = tmp_path / "afile" if where == "file" else tmp_path / "afile" / "rep"
    monkeypatch.setattr(report, "compute_stats", None)  # never reached
    status, _, err = _stats(capfd, sim, "--out", out, *FAST)
    assert status == 2 and len(err) == 1
    assert err[0].startswith(f"error: {out}: ") and "a file is in the way" in err[0]
    assert (tmp_path / "afile").read_text() == "keep"


@pytest.mark.parametrize("out_of", ["the input", "a parent of the input"])
def test_the_report_never_replaces_an_input(batch, capfd, out_of):
    out = batch if out_of == "the input" else batch.parent
    before = _snapshot(batch)
    status, _, err = _stats(capfd, batch, "--out", out, *FAST)
    verb = "is" if out_of == "the input" else "holds"
    assert status == 2
    assert err == [f"error: {out}: {verb} the input folder {batch}, which the report would "
                   "replace: give another --out"]
    assert _snapshot(batch) == before


def test_a_folder_holding_other_files_is_not_replaced(tmp_path, capfd):
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    out = tmp_path / "rep"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    status, _, err = _stats(capfd, sim, "--out", out, *FAST)
    assert status == 2 and len(err) == 1
    assert err[0].startswith(f"error: {out}: holds notes.txt, which is no part of a stats "
                             "report")
    assert (out / "notes.txt").read_text() == "mine"


def test_an_empty_folder_or_a_report_with_browser_files_is_replaced(tmp_path):
    out = tmp_path / "rep"
    out.mkdir()
    report.check_report_dir(out)
    for name in ("macro.csv", "report.html", ".DS_Store", ".macro.csv.x1y2.csv"):
        (out / name).write_text("")
    (out / "figures").mkdir()
    (out / "figures" / "pdf_e.png").write_bytes(b"")
    report.check_report_dir(out)
    (out / "figures" / "draft.svg").write_text("")
    with pytest.raises(ParameterError, match="figures/draft.svg"):
        report.check_report_dir(out)


def test_write_report_returns_the_final_paths(tmp_path):
    ens = load_any(demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1))
    from crosssection.stats.tables import StatsOptions

    paths = report.write_report(ens, tmp_path / "rep", figures=False,
                                opts=StatsOptions(n_boot=0, gof=False))
    assert all(p.parent == tmp_path / "rep" and p.is_file() for p in paths.values())
    assert all(p.name in report.REPORT_FILES for p in paths.values())


def test_name_of_a_batch_of_several_sets_keeps_them_apart(tmp_path, capfd):
    b = demo.write_demo_batch(tmp_path / "b2", n_images=2, seed=4,
                              sets={"A": {"n_stacks": 10}, "B": {"n_stacks": 12}})
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=4, seed=1)
    status, _, err = _stats(capfd, b, sim, "--out", tmp_path / "rep", *FAST,
                            "--name", "exp", "--name", "simu")
    assert status == 0 and err == []
    sets = pd.read_csv(tmp_path / "rep" / "per_config.csv")["set"]
    assert list(dict.fromkeys(sets)) == ["exp/A", "exp/B", "simu"]
    # a batch of one set takes the name itself
    one = demo.write_demo_batch(tmp_path / "b1", n_images=2, seed=4, sets={"A": {}})
    assert load_any(one, set_name="exp").sets == ["exp"]
    assert load_any(b, set_name="exp").sets == ["exp/A", "exp/B"]
    with pytest.raises(SystemExit):
        main(["stats", "--help"])
    assert "NAME/A, NAME/B" in " ".join(capfd.readouterr().out.split())


def test_image_limits_given_for_a_simulation_are_said_not_applied(tmp_path):
    import warnings

    from crosssection.stats.data import DetectionLimitWarning

    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=3, seed=1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ens = load_any(sim, l_min_mm=1.0)
    said = [str(w.message) for w in caught if w.category is DetectionLimitWarning]
    assert len(said) == 1 and "l_min_mm = 1" in said[0] and "not applied" in said[0]
    assert ens.branches["l_min_L"].isna().all()
    with warnings.catch_warnings():
        warnings.simplefilter("error", DetectionLimitWarning)
        load_any(sim)  # the recorded limits (none): nothing to say
        load_any(sim, l_min_mm=0)


@pytest.mark.parametrize("table, column, value", [("branches.csv", "length", "-0.5"),
                                                  ("configs.csv", "energy_total", "-100"),
                                                  ("configs.csv", "n_stacks", "8.5"),
                                                  ("voids.csv", "area", "-1e-4")])
def test_a_value_outside_its_columns_domain_is_one_line(tmp_path, capfd, table, column, value):
    """A hand-edited value the fits leave out entered the means of macro.csv and micro.csv
    (a length of -0.5 moved the mean branch length by 9 %)."""
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=3, seed=1)
    df = pd.read_csv(sim / table)
    df[column] = df[column].astype(object)
    df.loc[1, column] = value
    df.to_csv(sim / table, index=False)
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    kind = "a finite whole number" if column == "n_stacks" else "a finite number"
    assert status == 2 and err == [f"error: {sim / table}: column {column} holds "
                                   f"{float(value):g} in data row 2 where {kind} >= 0 is "
                                   "expected"]


def test_figures_with_no_value_are_not_drawn_but_named(tmp_path, capfd):
    """A detection limit above every length drew six empty axes; an ensemble without voids
    drew the void-size scatter with no point."""
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    vo = pd.read_csv(sim / "voids.csv")
    vo.iloc[:0].to_csv(sim / "voids.csv", index=False)
    status, _, _ = _stats(capfd, sim, "--out", tmp_path / "rep", "--n-boot", "0",
                          "--no-gof")
    assert status == 0
    figures = {p.name for p in (tmp_path / "rep" / "figures").iterdir()}
    assert "sqrt_s_vs_l.png" not in figures and "pdf_area_L2.png" not in figures
    assert "pdf_length_L.png" in figures
    page = (tmp_path / "rep" / "report.html").read_text()
    assert "Not drawn (no configuration with the values): void size against branch length" \
        in page


def test_a_detection_limit_above_every_length_draws_no_empty_axes(batch, tmp_path, capfd):
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "rep", "--n-boot", "0",
                            "--no-gof", "--l-min-mm", "1e6", small=True)
    assert status == 0 and any("below the detection limit" in e for e in err)
    assert not (tmp_path / "rep" / "figures" / "pdf_length_L.png").exists()
    assert "the distribution of the branch length" in (tmp_path / "rep" /
                                                        "report.html").read_text()


def test_configurations_without_a_network_are_left_out_and_named(tmp_path, capfd):
    """A rod whose contact analysis failed has no counts: it entered the statistics as a
    configuration of no branch, and an ensemble of only such rods drew empty figures."""
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=3, seed=1)
    cfg = pd.read_csv(sim / "configs.csv")
    cfg["analysis_error"] = ["", "ValueError: no contact", ""]
    for c in ("n_stacks", "n_branches", "n_voids"):
        cfg[c] = cfg[c].astype(object)
        cfg.loc[1, c] = None
    cfg.to_csv(sim / "configs.csv", index=False)
    for name in ("branches.csv", "voids.csv"):
        t = pd.read_csv(sim / name)
        t[t["config_id"] != 1].to_csv(sim / name, index=False)
    status, out, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and "2 configurations" in out[0]
    assert err == [f"warning: {sim / 'configs.csv'}: 1 of 3 configurations have no network "
                   "(the contact analysis failed) (config_id 1; see analysis_error in "
                   "configs.csv) and is not in the statistics"]
    cfg["analysis_error"] = "ValueError: no contact"
    cfg.to_csv(sim / "configs.csv", index=False)
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep2", *FAST)
    assert status == 2 and err == [f"error: {sim}: ensemble holds no finished configuration "
                                   "(all 3 have no network (the contact analysis failed); "
                                   "see analysis_error in configs.csv)"]


def test_the_same_scan_twice_in_a_batch_is_named(batch, tmp_path, capfd):
    """A copy of a scan under another name was analysed and counted twice without a word."""
    summaries = sorted(batch.glob("s1/*/summary.json"))
    for path, sha in zip(summaries, ("ab" * 32, "ab" * 32, "cd" * 32)):
        s = json.loads(path.read_text())
        s["inputs"] = {"image": {"path": "x.png", "resolved": "/x.png", "sha256": sha}}
        path.write_text(json.dumps(s))
    status, out, err = _stats(capfd, batch, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and "3 configurations" in out[0]
    assert err == [f"warning: {summaries[0].parent}: the same scan (SHA-256 abababababab...) "
                   f"as {summaries[1].parent}: one cut analysed 2 times weighs 2 times in its "
                   "set's statistics"]


def test_scans_left_out_or_weighed_twice_are_named_in_the_report(batch, tmp_path, capfd):
    # these notes went to stderr only, and a deleted table refused the whole batch
    import shutil

    b = tmp_path / "b"
    shutil.copytree(batch, b)
    summaries = sorted(b.glob("s1/*/summary.json"))
    for path in summaries[:2]:
        s = json.loads(path.read_text())
        s["inputs"] = {"image": {"path": "x.png", "resolved": "/x.png", "sha256": "ab" * 32}}
        path.write_text(json.dumps(s))
    (summaries[2].parent / "voids.csv").unlink()
    status, out, err = _stats(capfd, b, "--out", tmp_path / "rep", *FAST)
    assert status == 0 and "2 configurations" in out[0]
    assert any("voids.csv: missing table: this image is left out" in ln for ln in err)
    rep = json.loads((tmp_path / "rep" / "stats.json").read_text())
    said = json.dumps(rep["incomplete_batches"])
    assert "missing table" in said and "weighs 2 times" in said
    assert "weighs 2 times" in (tmp_path / "rep" / "report.html").read_text()


def test_a_folder_holding_two_batches_of_one_set_name(tmp_path, capfd):
    """Their scans share names within the set: the report's tables crashed on the repeated
    (set, configuration) pair (exit 1)."""
    root = tmp_path / "runs"
    for run in ("monday", "tuesday"):
        _batch(root / run)
        (root / run / "batch.json").unlink()
        (root / run / "index.csv").unlink(missing_ok=True)
        for path in (root / run).glob("s1/*/summary.json"):  # as batch records the set
            summary = json.loads(path.read_text())
            summary["batch"] = {"set": "s1"}
            path.write_text(json.dumps(summary))
    status, out, _ = _stats(capfd, root, "--out", tmp_path / "rep", "--n-boot", "0",
                            "--no-gof")
    assert status == 0 and "6 configurations" in out[0]
    pc = pd.read_csv(tmp_path / "rep" / "per_config.csv", dtype={"config_id": str})
    assert pc[["set", "config_id"]].duplicated().sum() == 0


@pytest.mark.parametrize("name", ["", "a/../b", "../up", "x y"])
def test_a_set_name_no_folder_can_hold_is_refused(batch, tmp_path, capfd, name):
    """A set name is a folder of the report: --name takes what a set.toml's name takes."""
    status, _, err = _stats(capfd, batch, "--out", tmp_path / "r", "--name", name, *FAST)
    assert status == 2 and len(err) == 1 and err[0].startswith("error: --name: name must be")


def test_a_folder_whose_name_is_not_utf8_is_reported(batch, tmp_path, capfd):
    """A scan folder named in bytes that are not UTF-8 (analyze writes into it) gave stats
    an unexpected error, exit 1: its path is written into per_config.csv escaped."""
    odd = tmp_path / os.fsdecode(b"x\xe9")
    try:
        odd.mkdir()
    except (UnicodeEncodeError, OSError):
        pytest.skip("the file system refuses names that are not UTF-8")
    scan = sorted(p.parent for p in batch.rglob("summary.json"))[0]
    import shutil

    shutil.copytree(scan, odd / "scan")
    status, out, err = _stats(capfd, odd / "scan", "--out", tmp_path / "rep", *FAST)
    assert status == 0 and not [e for e in err if not e.startswith("warning: ")]
    text = (tmp_path / "rep" / "per_config.csv").read_bytes().decode("utf-8")
    assert "\\udce9" in text


def test_a_second_stats_run_writing_the_same_report_is_refused(batch, tmp_path, capfd):
    """Two runs into one --out both exited 0, the second having removed the first's working
    folder: the folder held part of one report. While one writes, a second is refused."""
    out = tmp_path / "rep"
    with fileio.exclusive_lock(tmp_path / ".rep.lock", where=out, busy="held"):
        status, _, err = _stats(capfd, batch, "--out", out, *FAST)
    assert status == 2 and len(err) == 1
    assert err[0].startswith(f"error: {out}: another stats run is writing this report")
    assert not out.exists()
    status, _, err = _stats(capfd, batch, "--out", out, *FAST)
    assert status == 0 and (out / "macro.csv").is_file()
    assert not (tmp_path / ".rep.lock").exists()


def test_an_unfinished_simulation_is_named_as_such(tmp_path, capfd):
    """A quench stopped before its tables: its folder holds params.json and parts/ only."""
    sim = tmp_path / "sim"
    (sim / "parts").mkdir(parents=True)
    (sim / "params.json").write_text('{"command": "quench"}')
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    assert status == 2 and len(err) == 1
    assert err[0] == (f"error: {sim}: an unfinished simulation (its params.json and parts/, "
                      "no configs.csv yet): re-run the command that made it to finish it")


def test_configurations_folding_back_at_one_node_are_named_by_the_statistics(tmp_path, capfd):
    """The quench warns of folds within one node, whose branches carry the discrete rod's
    4 / ds cap; stats fitted those branches without a word."""
    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=4, seed=1)
    cfg = pd.read_csv(sim / "configs.csv")
    cfg["n_hairpin_nodes"] = [0, 1, 0, 2]
    cfg.to_csv(sim / "configs.csv", index=False)
    with pytest.warns(QualityWarning, match="2 of 4 configurations fold back at a single node"):
        load_any(sim)
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep", *FAST)
    assert status == 0
    assert [line for line in err if "fold back at a single node" in line] == [
        f"warning: {sim / 'configs.csv'}: 2 of 4 configurations fold back at a single node "
        "(n_hairpin_nodes): the discrete rod caps such a fold's bending at 4 / ds, and the "
        "branches holding it, whose energies are that cap, are in the statistics"]
    cfg["n_hairpin_nodes"] = 0
    cfg.to_csv(sim / "configs.csv", index=False)
    status, _, err = _stats(capfd, sim, "--out", tmp_path / "rep2", *FAST)
    assert status == 0 and err == []
