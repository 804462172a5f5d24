"""``crosssection.testing`` for users' test suites: the fixtures, the grid, the hypothesis
strategies, and the example test of its docstring and of the README."""
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings

from crosssection.testing import DEFAULT_SCAN, analysis_params, scan_grid, scenes
from crosssection.truth.scoring import score

# the fixtures come from the package's pytest11 entry point once foldstat is installed; this
# line loads them as well where the installed metadata predates the entry point
pytest_plugins = ["crosssection.testing"]


# --- the example of the module docstring and the README, verbatim ---------------------------
@pytest.mark.parametrize("foldstat_scan", scan_grid(layers=[4], degradations=["clean",
                                                                            "noisy"]),
                         indirect=True)
def test_my_settings_recover_the_network(foldstat_scan):
    result = foldstat_scan.analyze(curvature_method="missing")
    s = score(result, foldstat_scan.truth, px_per_mm=foldstat_scan.px_per_mm,
              thickness_mm=foldstat_scan.thickness_mm)
    assert abs(s["rod_length_rel_error"]) < 0.03
    assert s["junction_f1"] >= 0.95
    assert s["n_br_exact_length_fraction"] >= 0.9
# ---------------------------------------------------------------------------------------------


def test_the_documented_example_is_this_test():
    import inspect
    import textwrap
    from pathlib import Path

    import crosssection.testing

    source = inspect.getsource(test_my_settings_recover_the_network).strip()
    doc = textwrap.dedent(crosssection.testing.__doc__.split("write (analyse")[1]
                          .split("::", 1)[1].split("\nBatch workflow")[0])
    assert source in doc
    readme = Path(__file__).resolve().parents[2] / "README.md"
    if readme.is_file():  # a source tree
        assert source in readme.read_text()


def test_default_scan_is_the_documented_one_with_its_truth(foldstat_scan):
    assert foldstat_scan.options == DEFAULT_SCAN
    assert foldstat_scan.image.is_file()
    assert (foldstat_scan.folder / "truth" / "stacks.csv").is_file()
    summary, tables = foldstat_scan.truth
    assert summary["n_branches"] == int(tables["stacks"]["n_br"].sum())
    assert tables["stacks"]["n_br"].max() <= DEFAULT_SCAN["max_layers"]
    assert foldstat_scan.px_per_mm == 50.0


def test_factory_caches_and_applies_the_conditions(foldstat_scan_factory):
    a = foldstat_scan_factory(px_per_mm=40.0, degradation="jpeg", seed=2)
    assert foldstat_scan_factory(px_per_mm=40.0, degradation="jpeg", seed=2) is a
    assert a.scene.params["px_per_mm"] == 40.0
    assert a.scene.params["options"]["jpeg_quality"] == 80
    b = foldstat_scan_factory(seed=3, n_stacks=30)
    assert b.folder != a.folder and b.scene.summary["n_stacks"] > 10


def test_grid_ids_and_unknown_degradation(foldstat_scan_factory):
    grid = scan_grid(resolutions=[25, 50], layers=[2, 6], densities=[20],
                     degradations=["clean", "defects"])
    assert len(grid) == 8 and len({p.id for p in grid}) == 8
    assert grid[0].id == "25pxmm-2layers-20stacks-clean"
    with pytest.raises(Exception, match="degradation"):
        foldstat_scan_factory(degradation="sepia")


@settings(max_examples=25, deadline=None)
@given(analysis_params(l_min_mm=1.0))
def test_analysis_params_strategy_gives_valid_resolvable_parameters(params):
    assert params.thickness_px >= 1.0
    assert params.l_min_mm == 1.0
    assert params.replace(merge_px=params.merge_px) == params


@settings(max_examples=2, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(scenes(n_stacks=(10, 16), max_layers=(2, 3), resolutions=(50.0,)))
def test_scene_strategy_draws_scans_with_consistent_truth(scene):
    assert scene.rgb.ndim == 3 and scene.rgb.dtype.name == "uint8"
    st = scene.tables["stacks"]
    assert scene.summary["n_branches"] == int(st["n_br"].sum())
    assert 1 <= st["n_br"].max() <= 3


def test_import_needs_neither_hypothesis_nor_heavy_libraries():
    code = ("import sys\nsys.modules['hypothesis'] = None\n"
            "import crosssection.testing as T\n"
            "print([m for m in ('numpy', 'pandas', 'hypothesis') if m in sys.modules "
            "and sys.modules[m] is not None])\n"
            "try:\n    T.scan_options()\nexcept ImportError:\n    print('lazy')\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["[]", "lazy"]
