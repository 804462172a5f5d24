"""The scans and truth of ``benchmarks/estimator_transfer.py``: the written truth reads back as
the scene's (scale, hole, L = sum n_br * length, total energy, calibration, scan bytes), and the
scorer returns the relative errors of a known result, uses the shared calibration of an
independent-generator folder, passes no method nobody asked for, and records a failing scene
without the folder's path."""
from __future__ import annotations

import json
from types import SimpleNamespace

import cv2
import numpy as np
import pandas as pd
import pytest


@pytest.fixture(scope="module")
def et(load_script):
    return load_script("estimator_transfer")


@pytest.fixture(scope="module")
def scene():
    from crosssection.truth.network import make_scene

    return make_scene(seed=0, n_stacks=20, max_layers=4)  # a 432 px scan, about 1 s


def test_parse_seeds(et):
    assert et.parse_seeds("100-103") == [100, 101, 102, 103]
    assert et.parse_seeds("7,100-101") == [7, 100, 101]


def test_the_truth_round_trips(et, scene, tmp_path):
    et.write_scene(scene, tmp_path, "typical_3")
    truth = json.loads((tmp_path / "typical_3.json").read_text())
    stacks = scene.tables["stacks"]
    assert truth["px_per_mm"] == scene.params["px_per_mm"]
    assert truth["thickness_mm"] == scene.params["thickness_mm"]
    assert truth["hole_radius_mm"] == pytest.approx(scene.params["hole_radius_mm"])
    assert truth["hole_center_px"] == pytest.approx(list(scene.params["hole_center_px"]))
    assert truth["L_mm"] == pytest.approx((stacks["n_br"] * stacks["length_mm"]).sum())
    assert truth["energy_total"] == pytest.approx(scene.summary["total_energy"])
    cal = pd.read_csv(tmp_path / "typical_3_calibration.csv")
    assert list(cal.columns) == ["n_layers", "width_mm"]
    assert cal["n_layers"].tolist() == list(range(1, 61))
    assert np.allclose(cal["width_mm"], scene.calibration.width(cal["n_layers"]))
    png = cv2.imread(str(tmp_path / "typical_3.png"), cv2.IMREAD_COLOR)
    assert np.array_equal(png[:, :, ::-1], scene.rgb)
    assert et.scene_written(tmp_path, "typical_3")
    assert not et.scene_written(tmp_path, "typical_4")
    # a withheld hole is written as null; without a summary total, the branch energies count
    et.write_scene(scene, tmp_path, "typical_nohole_3", hole_given=False)
    nohole = json.loads((tmp_path / "typical_nohole_3.json").read_text())
    assert nohole["hole_radius_mm"] is None and nohole["hole_center_px"] is None
    bare = SimpleNamespace(**{k: getattr(scene, k) for k in ("rgb", "params", "tables",
                                                              "calibration")}, summary={})
    assert et.scene_truth(bare)["energy_total"] == pytest.approx(
        scene.tables["branches"]["energy"].sum())


def _write_truth(folder, name, **extra):
    truth = {"px_per_mm": 50.0, "thickness_mm": 0.1, "hole_radius_mm": 10.0,
             "hole_center_px": [100.0, 120.0], "L_mm": 200.0, "energy_total": 400.0, **extra}
    (folder / f"{name}.json").write_text(json.dumps(truth))
    (folder / f"{name}.png").write_bytes(b"")


def test_the_scorer_returns_the_errors_of_a_known_result(et, tmp_path):
    _write_truth(tmp_path, "thick_01")
    _write_truth(tmp_path, "thick_dense_01", hole_radius_mm=None, hole_center_px=None)
    (tmp_path / "calibration.csv").write_text("n_layers,width_mm\n1,0.14\n2,0.26\n")
    (tmp_path / "thick_dense_01_calibration.csv").write_text("n_layers,width_mm\n1,0.1\n2,0.2\n")
    (tmp_path / "thick_01_lines.json").write_text("{}")  # not a scene: no <cond>_<N> name
    calls = {}

    def fake_analyze(path, **kw):
        calls[path.rsplit("/", 1)[-1]] = kw
        return SimpleNamespace(branches=pd.DataFrame({"energy": [300.0, 200.0]}),  # 500 / 400
                               stacks=pd.DataFrame({"n_br": [1, 3], "length_mm": [30.0, 50.0]}))

    df = et.score_folder(tmp_path, ["thick"], analyze=fake_analyze, version="9.9")
    assert df["scene"].tolist() == ["thick_01"]  # thick_dense is another condition
    row = df.iloc[0]
    assert row["energy_rel_error"] == pytest.approx(0.25)
    assert row["rod_length_rel_error"] == pytest.approx(180.0 / 200.0 - 1)
    assert row["version"] == "9.9" and pd.isna(row["error"])
    kw = calls["thick_01.png"]
    assert kw["calibration"].endswith("/calibration.csv")  # the folder's shared calibration
    assert kw["hole_radius_mm"] == 10.0 and kw["hole_center_px"] == (100.0, 120.0)
    assert kw["rod_length_mm"] == 200.0
    assert "threshold_method" not in kw and "curvature_method" not in kw

    df = et.score_folder(tmp_path, None, analyze=fake_analyze, version="9.9",
                         curvature_method="paper")
    assert df["scene"].tolist() == ["thick_01", "thick_dense_01"]
    kw = calls["thick_dense_01.png"]
    assert kw["calibration"].endswith("/thick_dense_01_calibration.csv")
    assert "hole_radius_mm" not in kw and "hole_center_px" not in kw
    assert kw["curvature_method"] == "paper"


def test_a_failing_scene_is_recorded(et, tmp_path):
    _write_truth(tmp_path, "typical_1")
    _write_truth(tmp_path, "typical_2")

    def analyze(path, **kw):
        if path.endswith("typical_1.png"):
            raise ValueError(f"{path}: cannot read")
        return SimpleNamespace(branches=pd.DataFrame({"energy": [400.0]}),
                               stacks=pd.DataFrame({"n_br": [2], "length_mm": [100.0]}))

    df = et.score_folder(tmp_path, None, analyze=analyze, version="9.9")
    assert df["error"].tolist()[0] == "ValueError: typical_1.png: cannot read"
    summary = et.summarize(df).iloc[0]
    assert summary["scenes"] == 2 and summary["failures"] == 1
    assert summary["energy_abs_med"] == pytest.approx(0.0)
    assert summary["rod_med"] == pytest.approx(0.0)
