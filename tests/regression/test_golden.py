"""Golden-master regression: the tables of a fixed set of inputs, against committed copies.

Inputs: two bundled sample scans (their ``set.toml`` parameters), a generated network scene
with a grey plate, and a small quenched rod (``inputs/quench_rod.csv``): its contact analysis
and its render. Any change of the numbers beyond the libraries' rounding fails this test; a
deliberate change regenerates the copies with

    python tests/regression/test_golden.py --update

and says in its commit message what changed and why.

The rod is an input, not quenched here: the quench is chaotic, so a last-bit difference in
a library's floating point (numba, numpy) changes its minimum and every table after it; the
quench's own reproducibility is tested in ``tests/simulate``. Floats are compared to
:data:`RTOL`: between library releases the curvature fits move by up to 2e-3 (relative) on a
few stacks, while every count, layer number and identifier must be identical.
"""
from __future__ import annotations

import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

HERE = Path(__file__).resolve().parent
GOLDEN = HERE / "golden"
REPO = HERE.parents[1]
SAMPLES = ("scan_01_sparse.png", "scan_04_jpeg.jpg")
#: floats are compared to this relative tolerance (libraries round differently); integer
#: columns exactly
RTOL = 1e-2
ROD = HERE / "inputs" / "quench_rod.csv"


def _sample_tables():
    import crosssection

    root = REPO / "sample_images"
    cfg = tomllib.loads((root / "set.toml").read_text())
    for name in SAMPLES:
        ov = cfg["images"][name]
        res = crosssection.analyze(str(root / name), px_per_mm=cfg["px_per_mm"],
                                   thickness_mm=cfg["thickness_mm"],
                                   calibration=str(root / cfg["calibration"]),
                                   hole_radius_mm=ov["hole_radius_mm"],
                                   hole_center_px=tuple(ov["hole_center_px"]))
        for t, df in res.tables.items():
            yield f"sample_{Path(name).stem}_{t}", df


def _scene_tables():
    import crosssection
    from crosssection.truth.backdrop import apply_backdrop
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=5, n_stacks=40, max_layers=8, noise_sigma=4.0, blur_px=1.0, specks=5)
    p = sc.params
    cx, cy = p["hole_center_px"]
    rgb = apply_backdrop(sc.rgb, ink_mask=np.zeros(sc.rgb.shape[:2], bool),
                         hole_center_rc=(cy, cx),
                         hole_radius_px=p["hole_radius_mm"] * p["px_per_mm"],
                         rng=np.random.default_rng(5), plate="grey", illumination=0.1, cast=0.04)
    for t, df in sc.tables.items():
        yield f"scene_truth_{t}", df
    res = crosssection.analyze(rgb, px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
                               calibration=sc.calibration)
    for t, df in res.tables.items():
        yield f"scene_{t}", df


def quench_rod(tmp: Path) -> np.ndarray:
    """The small quench whose first configuration is the rod input (``--update`` only)."""
    from simulate.ensemble import run_ensemble

    params = dict(command="quench", n_configs=2, n_segments=60, lam=7e5 * 60 / 300,
                  noise=750.0, seed=1, method="powell", n_runs=3, maxiter=6, nematic_runs=[1],
                  u=100.0, ftol=1e-4, xtol=1e-4, wall_radius=None, contact_distance=None,
                  parametrization=None)
    tabs = run_ensemble(params, tmp / "quench", workers=1, progress=False)
    assert len(tabs.pop("failed")) == 0
    with np.load(tmp / "quench" / "rods.npz") as rods:
        return np.asarray(rods[sorted(rods.files)[0]], float)


def _simulation_tables(tmp):
    import crosssection
    from simulate.contacts import analyze_rod
    from simulate.render import render_configuration

    xy = pd.read_csv(ROD)[["x", "y"]].to_numpy(float)
    an = analyze_rod(xy, lam=7e5 * 60 / 300)
    for t in ("junctions", "stacks", "branches", "voids"):
        df = getattr(an, t)
        yield f"rod_{t}", df.drop(columns=[c for c in ("passes",) if c in df.columns])
    sc = render_configuration(xy, seed=2, clean=True, smooth="long")
    for t, df in sc.tables.items():
        yield f"render_truth_{t}", df
    p = sc.params
    res = crosssection.analyze(sc.rgb, px_per_mm=p["px_per_mm"], thickness_mm=p["thickness_mm"],
                               calibration=sc.calibration)
    for t, df in res.tables.items():
        yield f"render_{t}", df


def all_tables(tmp: Path) -> dict[str, pd.DataFrame]:
    """Every table of the golden inputs, by name."""
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for gen in (_sample_tables(), _scene_tables(), _simulation_tables(tmp)):
            for name, df in gen:
                out[name] = df.reset_index(drop=True)
    return out


def _assert_same(name: str, got: pd.DataFrame, want: pd.DataFrame) -> None:
    assert list(got.columns) == list(want.columns), name
    assert len(got) == len(want), f"{name}: {len(got)} rows, golden {len(want)}"
    for c in want.columns:
        a, b = got[c], want[c]
        if pd.api.types.is_integer_dtype(b) and pd.api.types.is_integer_dtype(a):
            assert a.tolist() == b.tolist(), f"{name}.{c}"
        elif pd.api.types.is_numeric_dtype(b) and pd.api.types.is_numeric_dtype(a) \
                and not pd.api.types.is_bool_dtype(b):
            np.testing.assert_allclose(a.to_numpy(float), b.to_numpy(float), rtol=RTOL,
                                       atol=1e-9, equal_nan=True, err_msg=f"{name}.{c}")
        else:
            assert a.astype(str).tolist() == b.astype(str).tolist(), f"{name}.{c}"


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    return all_tables(tmp_path_factory.mktemp("golden"))


def test_golden_tables(tables):
    names = sorted(p.stem for p in GOLDEN.glob("*.csv"))
    assert names == sorted(tables), "the set of golden tables changed"
    for name in names:
        # read back through CSV, as the goldens were written
        tmp = pd.read_csv(pd.io.common.StringIO(tables[name].to_csv(index=False)))
        _assert_same(name, tmp, pd.read_csv(GOLDEN / f"{name}.csv"))


if __name__ == "__main__" and "--update" in sys.argv:
    import tempfile

    GOLDEN.mkdir(exist_ok=True)
    for old in GOLDEN.glob("*.csv"):
        old.unlink()
    with tempfile.TemporaryDirectory() as d:
        if "--rod" in sys.argv or not ROD.exists():
            ROD.parent.mkdir(exist_ok=True)
            rod = quench_rod(Path(d))
            pd.DataFrame({"x": rod[:, 0], "y": rod[:, 1]}).to_csv(ROD, index=False,
                                                                  float_format="%.17g")
        for n, df in all_tables(Path(d)).items():
            df.to_csv(GOLDEN / f"{n}.csv", index=False)
    print(f"golden tables written to {GOLDEN}")
