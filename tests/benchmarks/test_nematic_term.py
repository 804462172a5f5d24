"""The statistics of ``benchmarks/nematic_term.py`` on quench tables built with known values:
Gamma shapes recovered, intervals around the estimate, configurations resampled with their
branches, and the paired change from the reference variant."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest


@pytest.fixture(scope="module")
def nem(load_script):
    return load_script("nematic_term")


def _tables(nem, rng, *, n_configs=60, energy_scale=1.0, alpha_e=0.3, alpha_l=0.5):
    """Quench-like tables: per configuration 20-40 branches (Gamma energies and lengths),
    stacks of one or two branches, and voids."""
    cfg, br, st, vo = [], [], [], []
    for c in range(n_configs):
        k = int(rng.integers(20, 41))
        e = rng.gamma(alpha_e, 700.0, k) * energy_scale
        br.append(pd.DataFrame({"config_id": c, "branch_id": np.arange(k),
                                "length": rng.gamma(alpha_l, 0.1, k), "energy": e,
                                "kappa_pm": rng.normal(0, 40, k), "kappa_plus": 10.0}))
        n_br = rng.integers(1, 3, k // 2)
        st.append(pd.DataFrame({"config_id": c, "stack_id": np.arange(len(n_br)), "n_br": n_br,
                                "length": 0.05}))
        vo.append(pd.DataFrame({"config_id": c, "area": rng.uniform(1e-4, 5e-4, 5),
                                "perimeter": 0.1, "shape_ratio": rng.uniform(0.15, 0.23, 5),
                                "n_edges": 4}))
        cfg.append({"config_id": c, "energy_total": e.sum(), "rg": 0.05 + 0.01 * rng.random(),
                    "n_stacks": len(n_br), "n_branches": k, "hull_area": 0.01,
                    "void_area": vo[-1]["area"].sum(), "void_perimeter": 0.5})
    t = {"configs": pd.DataFrame(cfg).set_index("config_id"),
         "branches": pd.concat(br, ignore_index=True), "stacks": pd.concat(st, ignore_index=True),
         "voids": pd.concat(vo, ignore_index=True)}
    t["by_config"] = {k: dict(tuple(t[k].groupby("config_id")))
                      for k in ("branches", "stacks", "voids")}
    return t


def test_statistics_recover_the_drawn_laws(nem):
    t = _tables(nem, np.random.default_rng(3))
    s = nem.statistics(t, t["configs"].index.to_numpy())
    assert s["alpha_e"] == pytest.approx(0.3, rel=0.1)
    assert s["alpha_l"] == pytest.approx(0.5, rel=0.1)
    assert s["nbr_nl"] == pytest.approx(np.mean(t["configs"]["n_branches"]
                                                / t["configs"]["n_stacks"]))
    assert s["e"] == pytest.approx(t["branches"]["energy"].mean())
    assert s["sqrt_s_over_p"] == pytest.approx(0.19, abs=0.01)
    assert 0.4 < s["stacks_one_branch"] < 0.6
    assert s["void_share_of_hull"] == pytest.approx(
        np.median(t["configs"]["void_area"] / 0.01))
    assert s["void_perimeter_per_config"] == pytest.approx(0.5)
    assert s["S_L2"] == pytest.approx(t["voids"]["area"].sum() / 60)


def test_load_measures_the_voids_against_the_hull(nem, tmp_path):
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0.5]], float) * 0.1
    np.savez(tmp_path / "rods.npz", config_00000=square, config_00001=2 * square)
    pd.DataFrame({"config_id": [0, 1], "energy_total": [1.0, 2.0], "rg": 0.05,
                  "n_stacks": 2, "n_branches": 3}).to_csv(tmp_path / "configs.csv", index=False)
    pd.DataFrame({"config_id": [0, 0], "branch_id": [0, 1], "length": 0.1, "energy": 1.0,
                  "kappa_pm": 1.0}).to_csv(tmp_path / "branches.csv", index=False)
    pd.DataFrame({"config_id": [0], "stack_id": [0], "n_br": [1]}).to_csv(
        tmp_path / "stacks.csv", index=False)
    pd.DataFrame({"config_id": [0, 0], "area": [0.002, 0.003], "perimeter": [0.2, 0.3],
                  "shape_ratio": 0.2}).to_csv(tmp_path / "voids.csv", index=False)
    cfg = nem.load(tmp_path)["configs"]
    assert cfg["hull_area"].tolist() == pytest.approx([0.01, 0.04])
    assert cfg["void_area"].tolist() == pytest.approx([0.005, 0.0])
    assert cfg["void_perimeter"].tolist() == pytest.approx([0.5, 0.0])


def test_resampled_configurations_carry_their_branches(nem):
    t = _tables(nem, np.random.default_rng(4), n_configs=10)
    one = nem.statistics(t, np.array([2, 2, 2]))
    assert one["E"] == pytest.approx(t["configs"].loc[2, "energy_total"])
    assert one["e"] == pytest.approx(t["by_config"]["branches"][2]["energy"].mean())


def test_intervals_hold_the_estimate(nem):
    t = _tables(nem, np.random.default_rng(5))
    row = nem.summarize(t, n_boot=40, seed=1)
    for k in nem.STATS:
        assert row[f"{k}_lo"] <= row[k] * 1.0001 and row[k] <= row[f"{k}_hi"] * 1.0001, k
    assert row["alpha_e_hi"] > row["alpha_e_lo"]


def test_paired_change_from_the_reference(nem):
    rng = np.random.default_rng(6)
    ref = _tables(nem, rng)
    more = {**ref, "configs": ref["configs"].assign(
        energy_total=ref["configs"]["energy_total"] * 1.2)}
    assert nem.paired(ref, ref)["paired_energy_change_median"] == 0.0
    p = nem.paired(more, ref)
    assert p["paired_energy_change_median"] == pytest.approx(0.2)
    assert p["same_stacks_share"] == 1.0
