"""Per-stack bending energy against the truth (``benchmarks/stack_energy_errors.py``)."""
from __future__ import annotations

import numpy as np
import pandas as pd


def test_one_scene_stack_by_stack(load_script, tmp_path):
    # one typical network scene (seed 100): measured 114 stacks matched, 73 % of them within
    # a factor 1.5, median ratio 0.94
    mod = load_script("stack_energy_errors")
    df = pd.DataFrame(mod.run_one("typical", 100, str(tmp_path)))
    assert len(df) >= 100
    assert (df["energy_rel_uncertainty"] >= 0).all()
    ratio = df["energy_out"] / df["energy_true"]
    assert 0.8 < ratio.median() < 1.25
    assert (np.abs(np.log(ratio)) <= np.log(1.5)).mean() > 0.6


def test_summary_shares_and_bins(load_script):
    mod = load_script("stack_energy_errors")
    df = pd.DataFrame({"generator": ["typical"] * 4,
                       "energy_true": [10.0, 30.0, 60.0, 0.0],
                       "energy_out": [10.0, 90.0, 60.0, 5.0],
                       "energy_rel_uncertainty": [0.1, 0.1, 0.6, 0.6]})
    t = mod.summarize(df, "energy_rel_uncertainty", mod.SHARE_BINS).loc["typical"]
    low = t.iloc[0]
    # the stack without true energy is left out; 10 of the bin's 40 read within 1.5
    assert low["stacks"] == 2 and low["within_1_5x"] == 0.25
    assert low["energy_share"] == 0.4 and t.iloc[1]["within_1_5x"] == 1.0
    assert low["median_ratio"] == 2.0
