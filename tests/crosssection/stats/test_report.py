"""The ``stats`` subcommand end to end on small synthetic batch outputs and simulations."""
import argparse
import json

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
    assert meta["sets"]["s1"]["fits"]["all"]["length_L"]["selected"]
    html = (out / "report.html").read_text()
    figs = sorted((out / "figures").glob("*.png"))
    assert len(figs) >= 10
    for f in figs:  # the page links every figure
        assert f"figures/{f.name}" in html
    for name in ("pdf_length_L.png", "pdf_e.png", "pdf_n_br.png", "network_Nbr_vs_Nl.png",
                 "sqrt_s_vs_l.png", "E_vs_Nbr.png", "e_vs_nbr.png"):
        assert (out / "figures" / name).is_file(), name
    # atomic writes leave no temporary files behind
    assert not [p for p in out.rglob(".*")]


def test_stats_same_seed_same_tables(tmp_path):
    s = demo.write_demo_simulation(tmp_path / "sim", n_configs=6, seed=1)
    for k in ("a", "b"):
        _run([str(s), "--out", str(tmp_path / k), "--n-boot", "8", "--n-mc", "9",
              "--no-figures"])
    assert (tmp_path / "a" / "fits.csv").read_text() == (tmp_path / "b" / "fits.csv").read_text()


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
    assert "Not drawn (fewer than 5 positive values, or all equal): few." in html
    # its branches are many and draw it; it has no stacks.csv, so no n_br to draw either
    assert html.count("Not drawn") == 2
    e_part = html.split("Distribution of the branch energy e")[1].split("<h3")[0]
    assert "Not drawn" not in e_part
