"""The notebook view of an analysis: ``AnalysisResult._repr_html_`` and ``plot``."""
import base64
import io
import re

import numpy as np
import pytest
from matplotlib.figure import Figure
from PIL import Image

from crosssection.core.errors import ParameterError

pytest_plugins = ["crosssection.testing"]


@pytest.fixture(scope="module")
def result(foldstat_scan_factory):
    return foldstat_scan_factory(seed=4, n_stacks=20, max_layers=4).analyze()


def test_html_summary_and_small_thumbnail(result):
    page = result._repr_html_()
    s = result.summary
    for label, value in (("junctions", s["n_junctions"]), ("stacks", s["n_stacks"]),
                         ("branches", s["n_branches"]), ("voids", s["n_voids"])):
        assert re.search(rf"<th[^>]*>{label}</th><td[^>]*>{value}</td>", page), label
    assert f"{s['rod_length_mm']:.1f} mm" in page and f"{s['epsilon']:.2f}" in page
    assert "no warning" in page  # a clean generated scan with its calibration and hole
    data = base64.b64decode(re.search(r"data:image/png;base64,([A-Za-z0-9+/=]+)", page)[1])
    assert len(data) < 200_000
    img = Image.open(io.BytesIO(data))
    assert img.format == "PNG" and max(img.size) == 320
    rgb = np.asarray(img.convert("RGB")).astype(int)
    r, g = rgb[..., 0], rgb[..., 1]
    # the network is drawn: bluish-green bulk and vermillion periphery pixels, not only the
    # dimmed scan
    assert (g > r + 60).sum() > 100 and (r > g + 60).sum() > 20


def test_html_lists_quality_warnings(result):
    from crosssection.quality import QualityFlag

    flagged = type(result)(**{**vars(result), "quality": (
        QualityFlag("hole_fitted", "hole found with confidence 0.3 < 0.5"),)})
    page = flagged._repr_html_()
    assert "<b>hole_fitted</b>" in page and "no warning" not in page


@pytest.mark.parametrize("kind, n_axes", [("overlay", 1), ("steps", 4), ("curvature", 1),
                                          ("widths", 1)])
def test_plot_kinds(result, kind, n_axes):
    fig = result.plot(kind)
    assert isinstance(fig, Figure) and len(fig.axes) == n_axes
    drawn = sum(len(ax.lines) + len(ax.collections) + len(ax.images) for ax in fig.axes)
    assert drawn > 0


def test_plot_into_given_axes(result):
    fig = Figure()
    axes = fig.subplots(2, 2)
    assert result.plot("widths", ax=axes[0, 0]) is fig
    assert result.plot("overlay", ax=axes[0, 1]) is fig
    assert len(axes[0, 1].images) == 1 and len(axes[0, 1].collections) >= 1
    assert result.plot("curvature", ax=axes[1, 0]) is fig
    # the widths panel shows every stack and the calibration law
    n_points = sum(len(line.get_xdata()) for line in axes[0, 0].lines[:-1])
    assert n_points == len(result.stacks)
    steps = Figure().subplots(1, 4)
    assert result.plot("steps", ax=steps) is steps[0].figure
    with pytest.raises(ParameterError, match="4 axes"):
        result.plot("steps", ax=axes[0, 0])
    with pytest.raises(ParameterError, match="kind"):
        result.plot("histogram")
    # a wrong ax is named, not an AttributeError from inside matplotlib's callers
    for kind, ax in (("overlay", axes), ("curvature", "x"), ("widths", 5)):
        with pytest.raises(ParameterError, match="ax must be one matplotlib Axes"):
            result.plot(kind, ax=ax)
    with pytest.raises(ParameterError, match="4 matplotlib Axes"):
        result.plot("steps", ax=["a", "b", "c", "d"])


def test_html_shows_the_rod_length_the_energies_and_epsilon_use(foldstat_scan_factory):
    # a given L within the rod_length check's factor of the measured one (73 mm)
    given = foldstat_scan_factory(seed=4, n_stacks=20, max_layers=4).analyze(rod_length_mm=80.0)
    page = given._repr_html_()
    measured = given.summary["rod_length_mm"]
    assert f"{measured:.1f} mm measured, 80.0 mm given" in page
    assert f"{given.summary['epsilon']:.2f}" in page


def test_warn_takes_a_bool(result):
    from crosssection import analyze

    with pytest.raises(ParameterError, match="warn must be True or False"):
        analyze(result.rgb, warn="no")


def test_the_widths_plot_names_its_line_by_whether_a_calibration_was_given(result):
    """Without a calibration the widths are read against w = n h, which the legend does not
    call a calibration."""
    import dataclasses

    def legend(res):
        return [t.get_text() for t in res.plot("widths").axes[0].get_legend().get_texts()]

    assert "calibration w(n)" in legend(result)
    bare = type(result)(**{**vars(result),
                           "params": dataclasses.replace(result.params, calibration=None)})
    assert "no calibration: w = n h" in legend(bare) and "calibration w(n)" not in legend(bare)


def test_the_submodules_the_readme_names_load_on_first_use():
    import subprocess
    import sys

    # a fresh interpreter: earlier tests have imported the submodules already
    code = ("import warnings, crosssection, simulate; "
            # the README's filter, before anything else is imported
            "warnings.simplefilter('ignore', crosssection.quality.NoCalibrationWarning); "
            "print(crosssection.samples.copy_samples.__name__, "
            "crosssection.tables.network_graph.__name__, "
            "crosssection.params.AnalysisParams.__name__, "
            "crosssection.setconfig.__name__, simulate.load_ensemble.__name__, "
            "simulate.CompactParams.__name__, simulate.render.__name__)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["copy_samples", "network_graph", "AnalysisParams",
                                "crosssection.setconfig", "load_ensemble", "CompactParams",
                                "simulate.render"]
    # every public submodule, not a hand-picked list
    code = ("import pkgutil, crosssection, simulate\n"
            "for pkg in (crosssection, simulate):\n"
            "    for m in pkgutil.iter_modules(pkg.__path__):\n"
            "        if not m.name.startswith('_'):\n"
            "            getattr(pkg, m.name)\n"
            "print('ok')")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr
