"""The conditions of ``benchmarks/robust_sweep.py``: the hole-not-given scenes are the typical
scenes themselves, so that the two conditions compare the hole found with the hole given."""
from __future__ import annotations

import pytest


@pytest.mark.parametrize("seed", [100, 103, 107])
def test_hole_not_given_draws_the_typical_scenes(load_script, seed):
    rs = load_script("robust_sweep")
    typical, nohole = rs.scene_options("typical", seed), rs.scene_options("typical_nohole", seed)
    assert nohole["scene"] == typical["scene"]
    assert nohole["backdrop"] == typical["backdrop"]
    assert typical["hole_given"] and not nohole["hole_given"]
    # the other conditions keep their own draws
    assert rs.scene_options("tangential", seed)["scene"] != typical["scene"]
