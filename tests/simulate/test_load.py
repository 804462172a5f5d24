"""Simulation ensembles from Python (``simulate.load``) and the progress bar of ``render``."""
import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from crosssection import console
from crosssection.core.errors import ConfigError
from simulate.contacts import analyze_rod
from simulate.load import load_ensemble, plot_configuration

ARGS = ["--n-configs", "2", "--segments", "60", "--lambda", "2e4", "--noise", "300",
        "--runs", "2", "--maxiter", "3", "--nematic-runs", "0", "--no-progress"]


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "q"
    assert console.main(["quench", *ARGS, "--seed", "5", "--out", str(out)]) == 0
    return out


def test_load_ensemble_tables_params_and_rods(sim):
    ens = load_ensemble(sim)
    for name in ("configs", "branches", "stacks", "voids"):
        pd.testing.assert_frame_equal(getattr(ens, name), pd.read_csv(sim / f"{name}.csv"))
    assert ens.params["lam"] == 2e4 and ens.params["n_segments"] == 60
    assert ens.keys == ["config_00000", "config_00001"]
    xy = ens.rod(1)
    assert xy.shape == (61, 2)
    assert np.allclose(xy, ens.rod("config_00001"))
    # the stored rod is the configuration of the tables
    assert analyze_rod(xy, lam=2e4).n_branches == int(ens.configs["n_branches"].iloc[1])
    with pytest.raises(KeyError, match="no configuration"):
        ens.rod(7)
    assert "2 configurations" in repr(ens)
    with pytest.raises(ConfigError, match="configs.csv"):
        load_ensemble(sim / "parts")


def test_plot_configuration_draws_rod_and_stacks(sim):
    ens = load_ensemble(sim)
    fig = ens.plot(0)
    assert isinstance(fig, Figure)
    ax = fig.axes[0]
    assert np.allclose(ax.lines[0].get_xydata(), ens.rod(0))
    n_stacks = int(ens.configs["n_stacks"].iloc[0])
    assert len(ax.collections[0].get_segments()) == n_stacks
    assert f"{n_stacks} stacks" in ax.get_title()
    # the colours read as counts: a colour bar of whole n_br from 1, one colour each, as
    # tall as the axes beside it
    (bar,) = ax.child_axes
    assert "n_{br}" in bar.get_ylabel() and bar.get_yticks()[0] == 1
    top = int(ens.stacks.loc[ens.stacks["config_id"] == ens.stacks["config_id"].iloc[0],
                             "n_br"].max())
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import QuadMesh

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    (solids,) = [c for c in bar.collections if isinstance(c, QuadMesh)]
    assert len(np.unique(solids.get_facecolors(), axis=0)) == max(top, 2)
    a, b = ax.get_window_extent(renderer), bar.get_window_extent(renderer)
    assert abs(a.height - b.height) < 1 and b.x0 > a.x1
    bare = Figure().add_subplot()
    assert plot_configuration(ens.rod(0), ax=bare, stacks=False, wall_radius=0.2) is bare.figure
    assert not bare.collections and len(bare.patches) == 1


@pytest.mark.parametrize("flag, bar", [([], False), (["--progress"], True)])
def test_render_progress_only_when_asked_off_a_terminal(sim, tmp_path, capfd, flag, bar):
    out = tmp_path / "scenes"
    assert console.main(["render", str(sim), "--out", str(out), "--limit", "1",
                         "--px-per-mm", "25", *flag]) == 0
    # the warning lines (this small rod is below the render's validated segment count) aside
    err = "\n".join(ln for ln in capfd.readouterr().err.splitlines()
                    if not ln.startswith("warning: "))
    assert ("render" in err and "config" in err) == bar
    if not bar:
        assert err == ""
    assert (out / "config_00000" / "truth" / "summary.json").is_file()


def test_plot_keeps_title_labels_and_colour_bar_inside_the_figure(sim):
    """At the default size the title (with its counts), both axis labels and the colour
    bar's label lie inside the figure, as drawn by savefig."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    ens = load_ensemble(sim)
    for config in (0, 1):
        fig = ens.plot(config)
        renderer = FigureCanvasAgg(fig).get_renderer()
        fig.draw(renderer)
        (ax,) = fig.axes
        (bar,) = ax.child_axes
        texts = {"title": ax.title, "x label": ax.xaxis.label, "y label": ax.yaxis.label,
                 "colour bar label": bar.yaxis.label}
        assert "stacks" in ax.get_title() and bar.get_ylabel()
        page = fig.bbox
        for name, text in texts.items():
            box = text.get_window_extent(renderer)
            assert box.width > 0, name
            assert (box.x0 >= page.x0 and box.x1 <= page.x1 and box.y0 >= page.y0
                    and box.y1 <= page.y1), (name, box, page)
