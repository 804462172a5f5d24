"""The report's figures read without a legend hunt: tick labels of a log axis never run into
each other whatever its span and width, the histogram points and their error bars lie inside
the axes, a detection limit shared by every scan is printed once, and the network figure's
legend names each set once and each line style once."""
import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from crosssection.stats.data import BRANCH_COLS, CONFIG_COLS, STACK_COLS, VOID_COLS, Ensemble
from crosssection.stats.report import _log_ticks, network_figure, pdf_figure
from crosssection.stats.tables import StatsOptions, StatsResult, fit_quantity


def _tick_boxes(fig, ax):
    """Window extents of the visible, non-empty x tick labels inside ``ax``'s span."""
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    lo, hi = sorted(ax.get_xlim())
    boxes = [t.get_window_extent(renderer) for t in ax.get_xticklabels()
             if t.get_visible() and t.get_text()
             and lo * (1 - 1e-9) <= t.get_position()[0] <= hi * (1 + 1e-9)]
    return sorted(boxes, key=lambda b: b.x0)


@pytest.mark.parametrize("decades", [1.5, 2.0, 3.0, 5.0])
@pytest.mark.parametrize("width", [1.2, 2.0, 2.8, 5.0])
def test_log_tick_labels_never_run_into_each_other(decades, width):
    """Labels at 1, 2 and 5 times the powers of ten on a panel four inches wide ran
    together as "5×10⁻³10⁻²2×10⁻²5×10⁻²10⁻¹"."""
    fig = Figure(figsize=(width + 1.0, 3.0), layout="constrained")
    ax = fig.subplots()
    lo = 0.0027
    ax.plot([lo, lo * 10 ** decades], [1, 2])
    ax.set_xscale("log")
    ax.set_xlim(lo, lo * 10 ** decades)
    _log_ticks(ax.xaxis)
    boxes = _tick_boxes(fig, ax)
    assert len(boxes) >= 2
    assert all(a.x1 < b.x0 for a, b in zip(boxes, boxes[1:])), [b.extents for b in boxes]


def test_log_tick_labels_keep_apart_on_the_reports_panels():
    """The same in the report's own figure: three rows of six-inch-wide panel pairs with a
    legend beside, spans of about two decades."""
    rng = np.random.default_rng(4)
    ens = _ensemble({"a": 10 ** rng.uniform(-2.4, -0.6, 400),
                     "b": 10 ** rng.uniform(-2.2, -1.2, 300)})
    fig = pdf_figure(_fits(ens, "length_L"), ens, "length_L")
    log_ax = fig.axes[1]
    assert log_ax.get_xscale() == "log"
    boxes = _tick_boxes(fig, log_ax)
    assert len(boxes) >= 2
    assert all(a.x1 < b.x0 for a, b in zip(boxes, boxes[1:])), [b.extents for b in boxes]


def _ensemble(lengths: dict, cut=None) -> Ensemble:
    """One configuration per set with the branch lengths ``lengths[set]`` (and the detection
    limit ``cut`` of every scan, in units of L, when given)."""
    configs, branches = [], []
    for s, x in lengths.items():
        configs.append(pd.DataFrame({"set": [s], "config_id": ["0"]}))
        branches.append(pd.DataFrame({"set": s, "config_id": "0", "length_L": x,
                                      "e": x * 1e4, "region": "none",
                                      **({} if cut is None else {"l_min_L": cut})}))
    return Ensemble(pd.concat(configs, ignore_index=True).reindex(columns=CONFIG_COLS),
                    pd.concat(branches, ignore_index=True).reindex(columns=BRANCH_COLS),
                    pd.DataFrame(columns=STACK_COLS), pd.DataFrame(columns=VOID_COLS))


def _fits(ens, q):
    opts = StatsOptions(seed=1, n_boot=0, gof=False, quantities=(q,))
    summ = {(s, "all", q): fit_quantity(ens.subset(s), q, "all", opts, 1)[0]
            for s in ens.sets}
    empty = pd.DataFrame()
    return StatsResult(empty, empty, empty, empty, empty, empty, empty, empty, summ)


def test_points_and_error_bars_lie_inside_the_linear_and_log_axes():
    """A law diverging at 0 (Gamma, alpha < 1) must not set the linear panel's limit, nor a
    narrow law of one set cut the points of another; every point and the top of every error
    bar is inside its axes."""
    rng = np.random.default_rng(2)
    ens = _ensemble({"steep": rng.gamma(0.5, 0.02, 300),
                     "wide": rng.gamma(3.0, 0.01, 60)})
    fig = pdf_figure(_fits(ens, "e"), ens, "e")
    for ax in fig.axes:
        y0, y1 = ax.get_ylim()
        for c in ax.containers:  # errorbar containers: points, caps, bars
            y = np.asarray(c.lines[0].get_ydata(), float)
            tops = [seg[:, 1].max() for seg in c.lines[2][0].get_segments()]
            assert (y >= y0).all() and (y <= y1).all(), (ax.get_title(), y.max(), y1)
            assert max(tops) <= y1, (ax.get_title(), max(tops), y1)


def test_a_detection_limit_shared_by_every_scan_is_printed_once():
    """The legend read "detection limits 0.0056-0.0056" where every scan had the same."""
    from crosssection.stats.report import _limits_label

    assert _limits_label("scenes", (0.00561, 0.00564)) == \
        "scenes: detection limit 0.0056 (dotted)"
    assert _limits_label("s", (3.1e-5, 3.1e-5)) == "s: detection limit 3.1e-05 (dotted)"
    assert _limits_label("s", (0.0031, 0.0036)).startswith("s: detection limits 0.0031-0.0036")
    rng = np.random.default_rng(5)
    x = rng.gamma(3.0, 0.01, 200) + 0.006
    cut = np.where(np.arange(x.size) % 2 == 0, 0.00561, 0.00564)
    ens = _ensemble({"scenes": x}, cut=cut)
    fig = pdf_figure(_fits(ens, "length_L"), ens, "length_L")
    texts = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert "scenes: detection limit 0.0056 (dotted)" in texts, texts
    assert not any("0.0056-0.0056" in t for t in texts)


def _network_result(n_br: dict) -> StatsResult:
    """Per-configuration counts of sets whose mean numbers of branches per stack are
    ``n_br[set]``, with the relations table the network figure reads."""
    rows, rel, macro = [], [], []
    for i, (s, nbr) in enumerate(n_br.items()):
        for k, nl in enumerate((8, 12, 17, 23)):
            rows.append({"set": s, "config_id": str(k), "N_l": nl, "N_br": nbr * nl,
                         "n_br_bar": nbr, "sqrt_s_bar": 0.02, "l_bar": 0.03,
                         "epsilon": 0.3 + 0.05 * i})
        rel.append({"set": s, "relation": "eq12_const", "fitted": 2.4 + i, "n": 4})
        macro.append({"set": s, "region": "all", "n_br": nbr})
    empty = pd.DataFrame()
    return StatsResult(macro=pd.DataFrame(macro), micro=empty, dof=empty, fits=empty,
                       truncation=empty, relations=pd.DataFrame(rel), correlations=empty,
                       per_config=pd.DataFrame(rows))


def test_the_network_legend_names_each_set_once_and_each_line_style_once():
    """The legend had five entries per set (20 for four sets), each line named per panel."""
    res = _network_result({"a": 3.0, "b": 2.2, "c": 1.53, "d": 1.52})
    fig = network_figure(res)
    legend = fig.axes[1].get_legend()
    texts = [t.get_text().replace("\n", " ") for t in legend.get_texts()]
    assert len(texts) == 4 + 3, texts
    for s in "abcd":
        assert sum(t.startswith(f"{s}: ") for t in texts) == 1, texts
    assert sum("(15)" in t for t in texts) == 1


def test_coinciding_n_br_lines_of_two_sets_alternate_their_dashes():
    """Two sets with <n_br> = 1.53 and 1.52 drew their Eq. (15) lines on top of each other:
    only the colour drawn last showed."""
    res = _network_result({"c": 1.53, "d": 1.52})
    right = network_figure(res).axes[1]
    (c,) = [ln for ln in right.lines if ln.get_label().startswith("c: Eq. (15)")]
    (d,) = [ln for ln in right.lines if ln.get_label().startswith("d: Eq. (15)")]
    (c_off, c_seq), (d_off, d_seq) = c._unscaled_dash_pattern, d._unscaled_dash_pattern
    assert list(c_seq) == list(d_seq) and c_off != d_off
    # each colour's dashes fall in the other's gaps
    assert abs(c_off - d_off) == c_seq[0] and c_seq[1] == c_seq[0]


def test_bin_errors_count_whole_stacks():
    from crosssection.stats.report import _bin_errors

    bins = np.array([0, 0, 0, 1, 1, -1])
    # three branches of one stack in bin 0; two lone values in bin 1; one value outside
    groups = np.full(6, None, dtype=object)
    for i in range(3):
        groups[i] = ("s", "c", 1.0)
    err = _bin_errors(bins, groups, 2)
    assert err == pytest.approx([3.0, np.sqrt(2.0)])
    # without groups: sqrt(count)
    assert _bin_errors(bins, np.full(6, None, dtype=object), 2) == pytest.approx(
        [np.sqrt(3.0), np.sqrt(2.0)])
