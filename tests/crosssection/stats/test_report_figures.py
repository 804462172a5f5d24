"""What the report's figures and page show: the number of branches per stack as a probability
mass function comparable with its fitted law, counting error bars and bootstrap bands, one
colour per set across figures, and a page that explains its method in words."""
import numpy as np
import pandas as pd
import pytest
from matplotlib.collections import LineCollection, PolyCollection

from crosssection.stats import Ensemble, demo, load_any
from crosssection.stats.data import BRANCH_COLS, CONFIG_COLS, STACK_COLS, VOID_COLS
from crosssection.stats.report import (_html, e_vs_nbr_figure, pdf_figure, set_colors)
from crosssection.stats.tables import StatsOptions, StatsResult, compute_stats, fit_quantity

# column and heading codes of the CSV tables that must not reach the page as headings
RAW_NAMES = ("n_br_mean", "p1_name", "p1_lo", "p2_hi", "delta_bic", "p_text", "s_L2",
             "sqrt_s_over_p", "l_L", "kappa_m_L", "E_tilde", "alpha_E_over_alpha_e",
             "pearson_r", "spearman_r", "naive_bias_rel", "mean_minus_cut", "eq12_const",
             "eq14_slope", "n_br_exp_mu", "n_branches", "tab_macro", "tab_micro", "tab_res")


def _ensemble(sets, rng, n_stacks=250):
    """Sets whose stacks hold geometric numbers of branches (mean 2) and whose branches have
    Gamma lengths and energies."""
    configs, branches, stacks = [], [], []
    for s in sets:
        nbr = rng.geometric(0.5, n_stacks)
        configs.append(pd.DataFrame({"set": [s], "config_id": ["0"]}))
        stacks.append(pd.DataFrame({"set": s, "config_id": "0", "n_br": nbr,
                                    "region": "none"}))
        n = int(nbr.sum())
        branches.append(pd.DataFrame({
            "set": s, "config_id": "0", "length_L": rng.gamma(2.0, 0.01, n),
            "e": rng.gamma(0.5, 300.0, n), "n_br": np.repeat(nbr, nbr), "region": "none"}))
    return Ensemble(pd.concat(configs, ignore_index=True).reindex(columns=CONFIG_COLS),
                    pd.concat(branches, ignore_index=True).reindex(columns=BRANCH_COLS),
                    pd.concat(stacks, ignore_index=True).reindex(columns=STACK_COLS),
                    pd.DataFrame(columns=VOID_COLS))


def _fits(ens, quantities, n_boot=20):
    opts = StatsOptions(seed=1, n_boot=n_boot, gof=False, quantities=quantities)
    summ = {}
    for s in ens.sets:
        for q in quantities:
            summ[(s, "all", q)] = fit_quantity(ens.subset(s), q, "all", opts, 1)[0]
    empty = pd.DataFrame()
    return StatsResult(empty, empty, empty, empty, empty, empty, empty, empty, summ)


@pytest.fixture(scope="module")
def geometric():
    ens = _ensemble(["a", "b"], np.random.default_rng(0))
    return ens, _fits(ens, ("n_br", "length_L"))


def _line(ax, gid):
    return next(ln for ln in ax.lines if ln.get_gid() == gid)


def test_n_br_pmf_points_sum_to_one_and_match_the_law(geometric):
    ens, res = geometric
    fig = pdf_figure(res, ens, "n_br")
    ax = fig.axes[0]  # whole system, linear scale
    pts = _line(ax, "points:a:all")
    k, p = pts.get_xdata(), pts.get_ydata()
    assert np.allclose(k, np.round(k))  # points at the integers
    assert p.sum() == pytest.approx(1.0)  # fractions of stacks, not a density over bins
    law = _line(ax, "law:a:all")
    lk, lp = law.get_xdata(), law.get_ydata()
    for kk in (1, 2):  # the geometric law: its fitted masses sit on the points
        assert lp[lk == kk][0] == pytest.approx(p[k == kk][0], rel=0.2)
    best = res.summaries[("a", "all", "n_br")]
    r = best.results[best.best]
    assert r.discrete and r.pmf(np.arange(1, 400)).sum() == pytest.approx(1.0, abs=1e-6)


def _errorbar_halfwidths(ax, pts):
    """Upper half-lengths of the error bars drawn at the points ``pts``."""
    x, y = pts.get_xdata(), pts.get_ydata()
    for coll in ax.collections:
        if isinstance(coll, LineCollection) and len(coll.get_segments()) == len(x):
            segs = coll.get_segments()
            if np.allclose([sg[0][0] for sg in segs], x):
                return np.array([max(sg[0][1], sg[1][1]) for sg in segs]) - y
    return None


def test_counting_error_bars_and_bootstrap_bands(geometric):
    ens, res = geometric
    fig = pdf_figure(res, ens, "n_br")
    ax = fig.axes[0]
    pts = _line(ax, "points:a:all")
    n = len(ens.subset("a").stacks)
    half = _errorbar_halfwidths(ax, pts)
    assert half is not None  # sqrt(count)/n for unit-wide integer bins
    assert np.allclose(half, np.sqrt(pts.get_ydata() * n) / n)
    # the law's band: vertical bars at the integers (counts) ...
    assert any(isinstance(c, LineCollection) and "bootstrap" in str(c.get_label())
               for c in ax.collections)
    # ... and a shaded band around a continuous density, in both scales
    fig = pdf_figure(res, ens, "length_L")
    for ax in fig.axes:
        assert any(isinstance(c, PolyCollection) and "bootstrap" in str(c.get_label())
                   for c in ax.collections)
        assert _errorbar_halfwidths(ax, _line(ax, "points:a:all")) is not None


def test_a_set_keeps_its_colour_in_every_figure(geometric):
    ens, res = geometric
    colors = set_colors(ens.sets)
    assert colors["a"] != colors["b"]
    for fig in (pdf_figure(res, ens, "n_br"), pdf_figure(res, ens, "length_L")):
        for s in ens.sets:  # both sets overlaid on one axis
            assert _line(fig.axes[0], f"law:{s}:all").get_color() == colors[s]
            assert _line(fig.axes[0], f"points:{s}:all").get_color() == colors[s]
    ax = e_vs_nbr_figure(ens).axes[0]
    for s in ens.sets:
        assert any(c.lines[0].get_color() == colors[s] and c.get_label().startswith(s)
                   for c in ax.containers)  # the error-bar series of the set
    # only "b": it keeps the colour it has beside "a"
    only_b = pdf_figure(res, ens, "n_br", sets=["b"])
    assert _line(only_b.axes[0], "law:b:all").get_color() == colors["b"]


def test_legends_sit_outside_the_data():
    ens = _ensemble(["a"], np.random.default_rng(1), n_stacks=60)
    fig = pdf_figure(_fits(ens, ("length_L",), n_boot=0), ens, "length_L")
    fig.canvas.draw()
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    assert legends
    for leg in legends:
        box = leg.get_window_extent()
        for ax in fig.axes:
            assert not box.overlaps(ax.get_window_extent())
    text = " ".join(t.get_text() for ax in fig.axes for t in ax.texts)
    assert "Gamma" not in text  # no note about a curve that is not drawn


def test_page_explains_the_method_in_words(tmp_path):
    b = demo.write_demo_batch(tmp_path / "b", n_images=2, seed=1,
                              sets={"s1": {"n_stacks": 20}})
    ens = load_any(b)
    ens.configs.loc[0, "quality"] = "low_contrast;hole_uncertain"
    opts = StatsOptions(seed=0, n_boot=0, gof=False, quantities=("n_br", "length_L"))
    res = compute_stats(ens, opts)
    meta = {"version": "0", "inputs": ["b"], "options": {"seed": 0}}
    page = _html(res, [("Distribution", "figures/pdf_n_br.png", "What is seen.")], meta,
                 ens, StatsOptions(n_mc=199))
    assert "<b>Methods.</b>" in page and "BIC" in page and "AIC" in page
    assert "p &lt; 1/200" in page  # the Monte-Carlo floor of the p-values, in words
    assert "low_contrast, hole_uncertain" in page  # the inputs' quality warnings
    assert "paper, set 1" in page  # the paper's values beside ours
    assert "figures/pdf_n_br.png" in page and "What is seen." in page
    for raw in RAW_NAMES:
        assert raw not in page, raw


def test_page_says_what_the_scans_energies_rest_on(tmp_path):
    b = demo.write_demo_batch(tmp_path / "b", n_images=3, seed=1,
                              sets={"s1": {"n_stacks": 20}})
    ens = load_any(b)
    ens.configs["E_model_share"] = [0.5, 0.7, float("nan")]
    opts = StatsOptions(seed=0, n_boot=0, gof=False, quantities=("n_br",))
    meta = {"version": "0", "inputs": ["b"], "options": {"seed": 0}}
    page = _html(compute_stats(ens, opts), [], meta, ens, opts)
    assert "a median 0.60 of each scan's total (range 0.50-0.70, 2 scans)" in page
    # simulations have no such share: no note
    ens.configs["E_model_share"] = float("nan")
    assert "of each scan's total" not in _html(compute_stats(ens, opts), [], meta, ens, opts)



def _overlapping_ticks(fig):
    """Pairs of tick labels of one axis whose boxes overlap, once the figure is drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    bad = []
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            labels = [t for t in axis.get_ticklabels() if t.get_visible() and t.get_text()]
            boxes = [t.get_window_extent(renderer) for t in labels]
            bad += [(labels[i].get_text(), labels[j].get_text())
                    for i in range(len(boxes)) for j in range(i + 1, len(boxes))
                    if boxes[i].overlaps(boxes[j])]
    return bad


def test_tick_labels_never_run_together(tmp_path):
    """Small void areas (s/L^2 ~ 1e-4) once gave ten labels like 0.00015 that ran into each
    other; no panel of any quantity may have overlapping tick labels or negative ticks under
    positive data."""
    from crosssection.stats.report import plot_pdf

    b = demo.write_demo_batch(tmp_path / "b", n_images=3, seed=1, sets={"s1": {"n_stacks": 60}})
    for q in ("area_L2", "length_L", "shape_ratio", "kappa_m_L", "kappa_plus_L", "e"):
        fig = plot_pdf(b, q)
        assert _overlapping_ticks(fig) == [], q
        # the x labels of the linear and log panels of a row stay apart
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        renderer = FigureCanvasAgg(fig).get_renderer()
        fig.draw(renderer)
        boxes = [ax.xaxis.label.get_window_extent(renderer) for ax in fig.axes]
        for i in range(0, len(boxes) - 1, 2):
            assert not boxes[i].overlaps(boxes[i + 1]), q
        for ax in fig.axes:
            if ax.get_xscale() == "linear":
                assert ax.get_xlim()[0] >= 0, q


def test_axis_labels_never_split_a_formula():
    from crosssection.stats.report import LABELS, _wrap_label

    assert any("$" in label for label in LABELS.values())
    for label in LABELS.values():
        wrapped = _wrap_label(label, 36)
        assert wrapped.replace("\n", " ") == label
        # every line holds whole formulas: an even number of $ (else matplotlib prints it raw)
        assert all(line.count("$") % 2 == 0 for line in wrapped.splitlines()), wrapped


def test_axis_labels_never_split_a_parenthesis():
    """A unit in parentheses moves to the next line whole: "(rod length L)" is not cut into
    "(rod length" and a lone "L)"."""
    from crosssection.stats.report import LABELS, _wrap_label

    wrapped = _wrap_label("branch length $\\ell/L$ (rod length L)", 36)
    assert wrapped.splitlines()[-1] == "(rod length L)"
    for label in LABELS.values():
        for line in _wrap_label(label, 36).splitlines():
            assert line.count("(") == line.count(")"), line
    assert _wrap_label("a (b c) d", 3) == "a\n(b c)\nd"


def test_figures_of_small_samples_show_empty_bins_the_law_and_are_marked():
    from crosssection.stats import SmallSampleWarning, plot_pdf
    from crosssection.stats.fits import N_SELECT_MIN
    from crosssection.stats.report import BINS_MIN

    rng = np.random.default_rng(4)
    ens = _ensemble(["a"], rng, n_stacks=4)
    # six well-spread values: the fewest bins, BINS_MIN, and some of them empty
    ens.branches = ens.branches.iloc[:6].assign(e=[3540.0, 3620.0, 3790.0, 4390.0, 4550.0,
                                                   5490.0])
    with pytest.warns(SmallSampleWarning, match=r"e: laws selected on fewer than the "
                      rf"{N_SELECT_MIN} samples model selection needs \(a n = 6\)"):
        fig = plot_pdf(ens, "e")
    lin, log = fig.axes[0], fig.axes[1]
    pts = _line(lin, "points:a:all")
    assert len(pts.get_xdata()) == BINS_MIN and (pts.get_ydata() == 0).sum() == 2
    assert len(_line(log, "points:a:all").get_xdata()) <= 6  # a log axis shows no zero
    legend = [t.get_text() for t in log.get_legend().get_texts()]
    assert any(t.startswith("a: data, indicative only (n = 6") for t in legend), legend
    # the fitted law (well below the points' densities here) stays inside the log panel
    law = _line(log, "law:a:all").get_ydata()
    lo, hi = log.get_ylim()
    assert lo <= np.nanmin(law) and np.nanmax(law) <= hi
    # a large sample is not marked
    ens = _ensemble(["a"], rng)
    fig = pdf_figure(_fits(ens, ("e",), n_boot=0), ens, "e")
    legend = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert "a: data (n = " in legend[0] and not any("indicative" in t for t in legend)


def test_the_number_of_bins_follows_the_number_of_values():
    """A dozen values in 24 bins were a flat row of single counts: the count grows with n,
    within BINS_MIN..BINS_MAX, on the linear and the log panel alike."""
    from crosssection.stats.report import BINS_MAX, BINS_MIN, bin_edges

    rng = np.random.default_rng(5)
    small, large = rng.gamma(2.0, 0.01, 12), rng.gamma(2.0, 0.01, 5000)
    for log in (False, True):
        assert len(bin_edges(small, log)) - 1 == BINS_MIN
        k = len(bin_edges(large, log)) - 1
        assert 20 <= k <= BINS_MAX
        edges = bin_edges(large, log)
        assert edges[0] == pytest.approx(large.min()) and edges[-1] == pytest.approx(large.max())
    ens = _ensemble(["a"], rng, n_stacks=6)
    ens.branches = ens.branches.iloc[:12]
    fig = pdf_figure(_fits(ens, ("length_L",), n_boot=0), ens, "length_L")
    pts = _line(fig.axes[0], "points:a:all")
    assert len(pts.get_xdata()) == BINS_MIN
    # most bins hold more than one value: not a flat row of single counts
    counts = np.round(pts.get_ydata() * 12 * np.diff(bin_edges(ens.branches["length_L"])))
    assert counts.sum() == 12 and counts.max() >= 3


@pytest.mark.parametrize("log", [False, True])
def test_every_value_falls_in_a_bin(log):
    """Log edges are exp(log(x)), which rounds inside [min, max]: the end values were left
    out of the log panels (3 of 5 totals counted; a value lost in 2 of 3 samples of 50)."""
    from crosssection.stats.report import bin_edges

    rng = np.random.default_rng(11)
    for n in (2, 5, 50, 400):
        for _ in range(50):
            x = rng.lognormal(rng.normal(0, 3), rng.uniform(0.1, 2), n)
            counts, _ = np.histogram(x, bin_edges(x, log))
            assert counts.sum() == n
    assert np.histogram([3794.0, 8000, 9000, 12000, 44934], bin_edges(
        [3794.0, 8000, 9000, 12000, 44934], log))[0].sum() == 5


def test_a_set_left_out_of_a_distribution_figure_is_named_in_its_legend(geometric):
    ens, res = geometric
    # "b" has no fit of the branch length (too few values): the figure draws "a" and says so
    without_b = StatsResult(*(pd.DataFrame() for _ in range(8)), {
        k: v for k, v in res.summaries.items() if k != ("b", "all", "length_L")})
    fig = pdf_figure(without_b, ens, "length_L")
    legend = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert "b: not drawn (too few values to fit, or all equal)" in legend
    assert not any(ln.get_gid() == "points:b:all" for ln in fig.axes[0].lines)
    # nothing said when every set is drawn
    legend = [t.get_text() for t in pdf_figure(res, ens, "length_L").axes[1]
              .get_legend().get_texts()]
    assert not any("not drawn" in t for t in legend)


def test_the_branch_energy_caption_is_true_of_scans_and_simulations(tmp_path):
    from crosssection.stats.report import _e_vs_nbr_bars

    batch = load_any(demo.write_demo_batch(tmp_path / "b", n_images=2, seed=1,
                                           sets={"s1": {"n_stacks": 20}}))
    sim = load_any(demo.write_demo_simulation(tmp_path / "s", n_configs=2, seed=1))
    # a simulated branch has its own energy: a point on one stack of several has a bar
    assert "no error bar" not in _e_vs_nbr_bars(sim)
    assert "own energy" in _e_vs_nbr_bars(sim)
    assert "share its energy" in _e_vs_nbr_bars(batch)
    assert "own energy" not in _e_vs_nbr_bars(batch)
    both = Ensemble(*(pd.concat([getattr(batch, t), getattr(sim, t)], ignore_index=True)
                      for t in ("configs", "branches", "stacks", "voids")))
    text = _e_vs_nbr_bars(both)
    assert "In a scan the branches of one stack share its energy" in text
    assert "in a simulated rod each branch carries its own energy" in text


def test_the_network_figure_names_the_eq12_constant_and_draws_the_fitted_one(tmp_path):
    from crosssection.stats.report import network_figure
    from crosssection.stats.tables import EQ12_CONST

    ens = load_any(demo.write_demo_simulation(tmp_path / "s", n_configs=6, seed=1))
    res = compute_stats(ens, StatsOptions(n_boot=0, gof=False, quantities=("n_br",)))
    fitted = res.relations.set_index("relation").loc["eq12_const", "fitted"]
    assert np.isfinite(fitted) and abs(fitted / EQ12_CONST - 1) > 1e-3
    left = network_figure(res).axes[0]
    labels = {ln.get_label(): ln for ln in left.lines}
    (paper,) = [k for k in labels if "Eq. (12), paper's C = 2√(π/3)" in k]
    (ours,) = [k for k in labels if f"Eq. (12), fitted C = {fitted:.3g}" in k]
    # the fitted constant is drawn per configuration, with its own epsilon and means: on the
    # points where the relation holds (a line through the set's means missed them)
    pc = res.per_config
    own = fitted * pc["epsilon"] * pc["sqrt_s_bar"] / pc["l_bar"] * np.sqrt(pc["N_l"])
    assert np.allclose(labels[ours].get_xdata(), pc["N_l"])
    assert np.allclose(labels[ours].get_ydata(), own)
    assert labels[ours].get_linestyle() == "None" and labels[ours].get_marker() == "x"
    assert len(labels[paper].get_xdata()) == 100  # the paper's constant: a line


def test_a_missing_count_is_an_empty_cell_not_pandas_na():
    """A nullable count column (voids of the bulk, the paper's rows) showed "<NA>"."""
    from crosssection.stats.report import _html_table

    df = pd.DataFrame({"set": ["a", "b"], "n_voids": pd.array([141, None], dtype="Int64"),
                       "l_L": [0.0102, np.nan]})
    page = _html_table(df)
    assert "NA" not in page and "<td>141</td>" in page and page.count("<td></td>") == 2


def test_a_long_set_name_is_shortened_in_the_legend_only():
    """Names of 60 characters shrank the panels, clipped their titles and ran their tick
    labels together."""
    from crosssection.stats.report import LEGEND_NAME_MAX, _short, legend_names

    long = "experiment_polyester_sheet_december_2026_series_A_hole_8mm"
    assert _short("set_a") == "set_a" and len(_short(long)) == LEGEND_NAME_MAX
    assert _short(long).startswith("experiment_p") and _short(long).endswith("_A_hole_8mm")
    # names that differ only where the ellipsis falls keep the part that tells them apart
    a, b = (f"polyester_sheet_8mm_hole_series_{x}_compaction_19" for x in "AB")
    assert _short(a) == _short(b)
    names = legend_names([a, b, "quench"])
    assert len(set(names.values())) == 3 and names["quench"] == "quench"
    assert all(len(v) <= LEGEND_NAME_MAX for v in names.values())
    ens = _ensemble([long], np.random.default_rng(3), n_stacks=60)
    fig = pdf_figure(_fits(ens, ("length_L",), n_boot=0), ens, "length_L")
    texts = [t.get_text() for ax in fig.axes if ax.get_legend()
             for t in ax.get_legend().get_texts()]
    assert texts and all(t.startswith(_short(long) + ": ") for t in texts)


def test_the_bootstrap_band_is_drawn_only_where_the_replicates_share_the_support():
    """A Bose-Einstein law is bounded by its sample's extremes, which move from resample to
    resample: its band stops where replicates disagree on the support, instead of running
    from 0 to the law's height there."""
    import numpy as np

    from crosssection.stats import fits as F
    from crosssection.stats.report import _band

    x = np.random.default_rng(3).gamma(1.5, 0.01, 300) + 0.002
    r = F.fit_family(x, "bose_einstein", n_boot=60, seed=1)
    grid = np.linspace(x.min() * 0.9, x.max() * 1.1, 400)
    lo, hi = _band(r, grid, None, False)
    drawn = np.isfinite(lo) & np.isfinite(hi)
    assert drawn.any()
    # beyond the sample, no replicate's support: nothing drawn; where drawn, above 0
    assert not drawn[(grid < x.min()) | (grid > x.max())].any()
    assert (lo[drawn] > 0).all()


@pytest.mark.parametrize("lo, hi, least", [(0.0027, 0.0365, 3), (0.0045, 0.06, 3),
                                           (8.0, 700.0, 5)])
def test_a_log_axis_of_one_or_two_decades_has_labels_enough(lo, hi, least):
    """matplotlib's log formatter labelled only 10^-2 and 2x10^-2 of a 0.003-0.04 axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from crosssection.stats.report import _log_ticks

    fig, ax = plt.subplots()
    ax.set_xscale("log")
    ax.set_xlim(lo, hi)
    _log_ticks(ax.xaxis)
    fig.canvas.draw()
    shown = [t.get_text() for t in ax.get_xticklabels()
             if t.get_text() and lo <= t.get_position()[0] <= hi]
    plt.close(fig)
    assert len(shown) >= least, shown
    assert len(set(shown)) == len(shown)


def test_distribution_captions_say_only_what_applies(tmp_path):
    """Captions written for scans' branches (counts summed over stacks, one row per
    sub-system, a detection limit) were given to a configuration's E, to the voids and to
    simulations, which have none of them."""
    from crosssection.stats.report import _pdf_caption

    scans = load_any(demo.write_demo_batch(tmp_path / "b", n_images=2, seed=1))
    sims = load_any(demo.write_demo_simulation(tmp_path / "s", n_configs=2, seed=1))
    e_scan, e_sim = _pdf_caption("e", scans), _pdf_caption("e", sims)
    assert "summed over the stacks" in e_scan and "one row per sub-system" in e_scan
    assert "summed over the stacks" not in e_sim and "one row per sub-system" in e_sim
    for q in ("E", "area_L2", "shape_ratio"):
        text = _pdf_caption(q, scans)
        assert "summed over the stacks" not in text and "sub-system" not in text
    assert "detection limit" in _pdf_caption("area_L2", scans)
    assert "detection limit" not in _pdf_caption("area_L2", sims)


def test_the_branch_energy_error_bars_count_a_stack_once():
    # two stacks of 3 branches (energies 1 and 3, repeated per branch) and one of 2: the
    # error of the n_br = 3 point is over the two stacks, not the six branch rows
    from crosssection.stats.report import _means_by_count

    br = pd.DataFrame({"set": "s", "config_id": "c", "stack_id": [0, 0, 0, 1, 1, 1, 2, 2],
                       "n_br": [3, 3, 3, 3, 3, 3, 2, 2], "e": [1, 1, 1, 3, 3, 3, 5, 5.0]})
    st = _means_by_count(br)
    assert st.loc[3, "mean"] == 2.0 and st.loc[3, "size"] == 2
    assert st.loc[3, "sem"] == pytest.approx(np.std([1, 3], ddof=1) / np.sqrt(2))
    assert np.isnan(st.loc[2, "sem"])  # one stack: no error bar
    # without stack ids (a simulation) every branch is its own value
    sim = _means_by_count(br.drop(columns="stack_id"))
    assert sim.loc[3, "size"] == 6 and sim.loc[2, "sem"] == 0.0


def test_a_single_value_is_drawn_hollow_and_the_title_says_so():
    # n_br = 3 holds two stacks (a mean with an error), n_br = 2 one stack (no error bar):
    # that point is hollow, so that a reader does not take it for a mean of several
    import matplotlib.pyplot as plt

    br = pd.DataFrame({"set": "s", "config_id": "c", "stack_id": [0, 0, 0, 1, 1, 1, 2, 2],
                       "n_br": [3, 3, 3, 3, 3, 3, 2, 2], "e": [1, 1, 1, 3, 3, 3, 5, 5.0],
                       "region": "none"})
    ens = Ensemble(pd.DataFrame({"set": ["s"], "config_id": ["c"]}).reindex(columns=CONFIG_COLS),
                   br.reindex(columns=BRANCH_COLS),
                   pd.DataFrame(columns=STACK_COLS), pd.DataFrame(columns=VOID_COLS))
    fig = e_vs_nbr_figure(ens)
    ax = fig.axes[0]
    hollow = [ln for ln in ax.lines if ln.get_markerfacecolor() in ("white", (1, 1, 1, 1))
              and len(ln.get_xdata())]
    assert len(hollow) == 1
    assert list(hollow[0].get_xdata()) == [2] and list(hollow[0].get_ydata()) == [5.0]
    assert "hollow: a single value" in [t.get_text() for t in ax.get_legend().get_texts()][-1]
    plt.close(fig)


def test_the_legends_name_the_goodness_of_fit_p_value():
    from crosssection.stats.report import _fit_text

    class R:
        def label(self):
            return "Gamma alpha=0.3 chi=700"

        def p_text(self):
            return "p = 0.01"

    assert _fit_text(R()) == "Gamma alpha=0.3 chi=700, GOF p = 0.01"
