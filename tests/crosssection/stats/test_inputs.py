"""Edge inputs of the ``stats`` subcommand: scans without voids, empty ensembles."""
import argparse

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ConfigError
from crosssection.core.schema import write_tables
from crosssection.stats import cli, demo


def _run(argv):
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="command", required=True)
    cli.add_subparser(sub)
    args = p.parse_args(["stats", *argv])
    return args.func(args)


def _voidless_batch(root, rng, n_images=3):
    """A batch output whose scans have branches and stacks but no void at all."""
    for i in range(n_images):
        summary, tables = demo.demo_image_tables(rng, n_stacks=20)
        tables["voids"] = tables["voids"].iloc[:0]
        summary["n_voids"] = 0
        write_tables(root / "setA" / f"img{i}", summary, tables)
    return root


def test_stats_on_scans_without_voids(tmp_path):
    b = _voidless_batch(tmp_path / "b", np.random.default_rng(4))
    out = tmp_path / "rep"
    assert _run([str(b), "--out", str(out), "--n-boot", "5", "--no-gof"]) == 0
    macro = pd.read_csv(out / "macro.csv").set_index("region")
    assert macro.loc["all", "n_voids"] == 0
    assert np.isnan(macro.loc["all", "s_L2"])
    pc = pd.read_csv(out / "per_config.csv")
    assert len(pc) == 3 and pc["sqrt_s_bar"].isna().all()
    fits = pd.read_csv(out / "fits.csv")
    assert "length_L" in set(fits["quantity"]) and "area_L2" not in set(fits["quantity"])
    assert (out / "report.html").is_file()


def test_stats_on_a_single_scan_without_voids(tmp_path):
    rng = np.random.default_rng(5)
    summary, tables = demo.demo_image_tables(rng, n_stacks=15)
    tables["voids"] = None  # written as a header-only table
    summary["n_voids"] = 0
    write_tables(tmp_path / "scan", summary, tables)
    assert _run([str(tmp_path / "scan"), "--out", str(tmp_path / "rep"), "--n-boot", "0",
                 "--no-gof", "--no-figures"]) == 0
    macro = pd.read_csv(tmp_path / "rep" / "macro.csv").set_index("region")
    assert macro.loc["all", "n_voids"] == 0
    assert macro.drop(index="all")["n_voids"].isna().all()  # voids have no sub-system


def test_header_only_configs_is_a_one_line_error(tmp_path):
    s = demo.write_demo_simulation(tmp_path / "sim", n_configs=3, seed=0)
    (s / "configs.csv").write_text((s / "configs.csv").read_text().splitlines()[0] + "\n")
    with pytest.raises(ConfigError) as err:
        _run([str(s), "--out", str(tmp_path / "rep")])
    msg = err.value.one_line()
    assert "configs.csv" in msg and "\n" not in msg
    assert not (tmp_path / "rep").exists()


def test_empty_configs_file_is_a_one_line_error(tmp_path):
    s = demo.write_demo_simulation(tmp_path / "sim", n_configs=3, seed=0)
    (s / "configs.csv").write_text("")
    with pytest.raises(ConfigError, match="configs.csv"):
        _run([str(s), "--out", str(tmp_path / "rep")])


def test_a_scans_model_share_is_read_with_it(tmp_path):
    from crosssection.stats.data import load_any

    summary, tables = demo.demo_image_tables(np.random.default_rng(6), n_stacks=15)
    summary["total_energy_rel_uncertainty"] = 0.42
    write_tables(tmp_path / "scan", summary, tables)
    assert load_any(tmp_path / "scan").configs["E_model_share"].tolist() == [0.42]


def test_a_simulations_branches_take_their_stacks_counts(tmp_path):
    """``simulate quench`` writes n_br per stack (stacks.csv) and stack_id per branch: every
    branch gets its stack's count, so the figures of e against n_br hold simulations too."""
    from crosssection.stats.data import load_simulation

    sim = demo.write_demo_simulation(tmp_path / "sim", n_configs=2, seed=1)
    br = pd.read_csv(sim / "branches.csv")
    # stacks of 1, 2 and 3 branches, numbered within each configuration
    counts = {}
    for cid, group in br.groupby("config_id"):
        sizes = np.resize([1, 2, 3], len(group))
        stack_of = np.repeat(np.arange(len(group)), sizes)[:len(group)]
        br.loc[group.index, "stack_id"] = stack_of
        for sid in np.unique(stack_of):
            counts[(cid, sid)] = int(np.count_nonzero(stack_of == sid))
    br["stack_id"] = br["stack_id"].astype(int)
    br.to_csv(sim / "branches.csv", index=False)
    pd.DataFrame([{"config_id": c, "stack_id": s, "n_br": n, "length": 0.01}
                  for (c, s), n in counts.items()]).to_csv(sim / "stacks.csv", index=False)
    cfg = pd.read_csv(sim / "configs.csv")  # configs.csv counts the stacks made here
    cfg["n_stacks"] = [sum(1 for c, _ in counts if c == cid) for cid in cfg["config_id"]]
    cfg.to_csv(sim / "configs.csv", index=False)
    ens = load_simulation(sim)
    want = [counts[(c, s)] for c, s in zip(br["config_id"], br["stack_id"])]
    assert ens.branches["n_br"].to_numpy().tolist() == want
    # without stacks.csv nothing says the counts
    (sim / "stacks.csv").unlink()
    assert load_simulation(sim).branches["n_br"].isna().all()
