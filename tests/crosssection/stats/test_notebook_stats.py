"""Statistics from Python (report folders read back, a density plotted) and the progress bars
of the ``stats`` command (only on a terminal or when asked)."""
import argparse

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from crosssection.core.errors import ConfigError
from crosssection.stats import Ensemble, cli, demo, load_any, load_report, plot_pdf
from crosssection.stats.data import BRANCH_COLS, CONFIG_COLS, STACK_COLS, VOID_COLS
from crosssection.stats.fits import PAPER_FAMILIES, fit_all


def _run(argv):
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="command", required=True)
    cli.add_subparser(sub)
    args = p.parse_args(["stats", *argv])
    return args.func(args)


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    # a simulation: no detection limits, so the fits are quick
    return demo.write_demo_simulation(tmp_path_factory.mktemp("s") / "sim", n_configs=8,
                                      seed=2)


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    return demo.write_demo_batch(tmp_path_factory.mktemp("b") / "batch", n_images=3, seed=2,
                                 sets={"s1": {"n_stacks": 25}})


def test_report_folder_reads_back(sim, tmp_path, capfd):
    out = tmp_path / "rep"
    assert _run([str(sim), "--out", str(out), "--n-boot", "0", "--no-gof", "--no-figures"]) == 0
    capfd.readouterr()
    rep = load_report(out)
    for name in ("macro", "micro", "fits", "relations", "dof", "correlations", "per_config"):
        written = pd.read_csv(out / f"{name}.csv")
        pd.testing.assert_frame_equal(getattr(rep, name), written)
    assert rep.meta["options"]["n_boot"] == 0 and "sim" in rep.meta["sets"]
    sel = rep.selected()
    assert len(sel) and sel["selected"].all()
    assert len(sel) == len(sel.drop_duplicates(["set", "region", "quantity"]))
    # a notebook cell's value: one line naming the sets, not every table
    text = repr(rep)
    assert "\n" not in text and len(text) < 300 and "sim" in text
    assert f"{len(sel)} selected laws" in text
    with pytest.raises(ConfigError, match="stats.json"):
        load_report(sim)


def test_batch_folder_loads_into_dataframes_and_plots(batch):
    ens = load_any(batch)
    assert isinstance(ens, Ensemble) and ens.sets == ["s1"] and len(ens.configs) == 3
    fig = plot_pdf(ens, "e")
    # one row per sub-system (whole, bulk, periphery), linear and log panels
    assert isinstance(fig, Figure) and len(fig.axes) == 2 * 3
    for ax in fig.axes:  # the histogram points and the fitted law in every panel
        gids = {ln.get_gid() for ln in ax.lines}
        assert any(str(g).startswith("points:") for g in gids)
        assert any(str(g).startswith("law:") for g in gids)
    assert isinstance(plot_pdf(batch, "kappa_m_L"), Figure)  # from the folder itself
    with pytest.raises(ValueError, match="too few"):
        plot_pdf(batch, "E")  # one total energy per scan: 3 values
    with pytest.raises(ValueError, match="quantity"):
        plot_pdf(ens, "weight")
    with pytest.raises(ValueError, match="set"):
        plot_pdf(ens, "e", set_name="nope")


def _one_configuration(quantity: str, x) -> Ensemble:
    """A set ``g`` of one configuration whose branches hold the values ``x`` of ``quantity``."""
    return Ensemble(
        pd.DataFrame({"set": ["g"], "config_id": ["0"]}).reindex(columns=CONFIG_COLS),
        pd.DataFrame({"set": "g", "config_id": "0", quantity: x,
                      "region": "none"}).reindex(columns=BRANCH_COLS),
        pd.DataFrame(columns=STACK_COLS), pd.DataFrame(columns=VOID_COLS))


def test_plot_pdf_draws_the_fitted_density():
    rng = np.random.default_rng(0)
    x = rng.gamma(2.0, 0.5, 400)
    ens = _one_configuration("length_L", x)
    fig = plot_pdf(ens, "length_L")
    curve = next(ln for ln in fig.axes[0].lines if ln.get_gid() == "law:g:all")
    xs, ys = curve.get_xdata(), curve.get_ydata()
    summ = fit_all(x, PAPER_FAMILIES, n_boot=0, gof=False)
    assert np.allclose(ys, summ.results[summ.best].pdf(xs), rtol=1e-6)
    from scipy import stats

    k = (xs > 0.2) & (xs < 2)  # and that law is close to the generating one
    assert np.allclose(ys[k], stats.gamma(2.0, scale=0.5).pdf(xs[k]), rtol=0.2)


def test_a_large_scale_is_named_in_the_axis_label_not_beside_the_axis():
    # matplotlib's "x10^4" beside the axis lies under the end of a two-line label
    rng = np.random.default_rng(1)
    x = rng.gamma(0.6, 2e4, 400)
    ens = _one_configuration("e", x)
    fig = plot_pdf(ens, "e")
    lin = fig.axes[0]
    fig.canvas.draw()
    assert lin.xaxis.get_offset_text().get_text() == ""
    import re

    # the symbol times 10^-k on one line of its own at most: e in units of 10^k
    label = lin.get_xlabel()
    power = -int(re.search(r"\$10\^\{(-\d+)\}\\,e\$", label).group(1))
    assert label.count("\n") <= 1
    top = lin.get_xlim()[1]
    assert 10 ** power <= top < 10 ** (power + 1)
    ticks = [float(t.get_text()) for t in lin.get_xticklabels() if t.get_text()]
    assert ticks and max(ticks) < 10  # 0.5, 1, ... in units of 10^power: not 50000
    # the density is per unit e, not per unit of the ticks: the label says so (its area
    # read off the ticks is 10^-power), and the log panel, in e itself, needs no such words
    assert "per unit $e$" in lin.get_ylabel()
    assert fig.axes[1].get_ylabel() == "probability density"


@pytest.mark.parametrize("flag, bar", [([], False), (["--progress"], True)])
def test_progress_only_when_asked_off_a_terminal(sim, tmp_path, capfd, flag, bar):
    assert _run([str(sim), "--out", str(tmp_path / "r"), "--n-boot", "0", "--no-gof",
                 "--no-figures", *flag]) == 0
    err = capfd.readouterr().err
    assert ("stats fits" in err) == bar
    if not bar:  # nothing but the small-sample warning of this small set
        assert [ln for ln in err.splitlines() if not ln.endswith("indicative only")] == []
