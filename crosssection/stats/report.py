"""Write the statistics report: tables (CSV + Markdown), figures (PNG), stats.json, report.html.

Figures follow the paper's style: probability densities in linear and logarithmic scales with
the selected fit drawn over the histogram; bulk (green) and periphery (red) superposed as in
the paper's figure of the two sub-systems; every curve labelled directly in the panel with its
parameters, so that no legend has to be looked up.
"""
from __future__ import annotations

import html
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd

from crosssection._version import __version__
from crosssection.core.fileio import save_figure, write_csv, write_json, write_text
from crosssection.stats import fits as F
from crosssection.stats.families import FAMILIES
from crosssection.stats.data import Ensemble
from crosssection.stats.tables import (EQ1_CONST, QUANTITIES, StatsOptions, StatsResult,
                     compute_stats, regions_of, to_markdown)

REGION_COLOR = {"all": "black", "bulk": "tab:green", "periphery": "tab:red"}
SET_COLORS = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]


def _subplots(ncols=1, figsize=(6, 4.5)):
    """A figure and its axes without pyplot: no GUI backend is touched and a notebook's
    backend is left alone."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    axes = fig.subplots(1, ncols)
    return fig, axes


def _margins(fig, two=False):
    """Fixed margins (``tight_layout`` cost 0.36 s per figure, half of a small report)."""
    if two:
        fig.subplots_adjust(left=0.07, right=0.98, bottom=0.13, top=0.91, wspace=0.22)
    else:
        fig.subplots_adjust(left=0.14, right=0.96, bottom=0.12, top=0.91)


def _nanmean(v) -> float:
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return float(np.mean(v)) if v.size else float("nan")


def _fit_text(summ: F.FitSummary) -> str:
    if summ is None or summ.best is None:
        return "no fit"
    r = summ.results[summ.best]
    p = r.p_text()
    return r.label() + (f", {p}" if p else "")


def _density_curve(r: F.FitResult, xs, cut):
    y = r.pdf(xs)
    if r.truncated and cut is not None:
        y = np.where(xs >= cut, y / FAMILIES[r.family].sf(r.params, cut), np.nan)
    return y


def pdf_figure(res: StatsResult, ens: Ensemble, set_name: str, quantity: str):
    """Histogram densities of one quantity in linear and log scales with the selected fits.

    Returns
    -------
    matplotlib.figure.Figure or None
        None when nothing was fitted.
    """
    table, col, _, tcol, label = QUANTITIES[quantity]
    sub = ens.subset(set_name)
    regs = [r for r in regions_of(sub) if (set_name, r, quantity) in res.summaries]
    if not regs:
        return None
    fig, axes = _subplots(2, figsize=(11, 4.2))
    lines = []
    hmax = 0.0
    for reg in regs:
        summ = res.summaries[(set_name, reg, quantity)]
        df = getattr(sub, table)
        if reg != "all" and "region" in df.columns:
            df = df[df["region"].astype(str) == reg]
        x = np.asarray(df[col], float)
        x = x[np.isfinite(x) & (x > 0)]
        cut = None
        if tcol is not None and summ.results and next(iter(summ.results.values())).truncated:
            cut = float(np.nanmean(df[tcol]))
            x = x[x >= np.nanmin(df[tcol])]
        color = REGION_COLOR.get(reg, "black")
        best = summ.results.get(summ.best) if summ.best else None
        for ax, logscale in zip(axes, (False, True)):
            positive = x.min() > 0
            if logscale and positive and x.max() / x.min() > 10:
                bins = np.geomspace(x.min(), x.max(), 30)
                ax.set_xscale("log")
            else:
                bins = np.linspace(x.min(), x.max(), 30)
            h, edges = np.histogram(x, bins=bins, density=True)
            mids = np.sqrt(edges[1:] * edges[:-1]) if ax.get_xscale() == "log" \
                else (edges[1:] + edges[:-1]) / 2
            ax.plot(mids[h > 0], h[h > 0], "o", ms=4, color=color, alpha=0.8)
            if not logscale:
                hmax = max(hmax, float(h.max()))
            if best is not None:
                xs = (np.geomspace(bins[0], bins[-1], 300) if ax.get_xscale() == "log"
                      else np.linspace(bins[0], bins[-1], 300))
                ax.plot(xs, _density_curve(best, xs, cut), "-", color=color, lw=1.6)
                gam = summ.results.get("gamma")
                if summ.best != "gamma" and gam is not None and gam.selectable and reg == "all":
                    ax.plot(xs, _density_curve(gam, xs, cut), "--", color="grey", lw=1)
            if cut is not None:
                ax.axvline(cut, color="grey", ls=":", lw=1)
            if logscale:
                ax.set_yscale("log")
        lines.append((reg, color, f"{reg} (n={summ.results[next(iter(summ.results))].n}): "
                                  f"{_fit_text(summ)}"))
    if hmax > 0:  # a Gamma law with alpha < 1 diverges at 0: keep the histogram readable
        axes[0].set_ylim(0, 1.35 * hmax)
    for i, (reg, color, text) in enumerate(lines):
        axes[0].text(0.98, 0.95 - 0.08 * i, text, transform=axes[0].transAxes, ha="right",
                     va="top", color=color, fontsize=8)
    extra = []
    if any("gamma" in res.summaries[(set_name, r, quantity)].results for r in regs):
        extra.append("dashed grey: Gamma")
    if tcol is not None:
        extra.append("dotted: detection limit (truncation-aware fit)")
    if extra:
        axes[1].text(0.02, 0.03, "; ".join(extra), transform=axes[1].transAxes, fontsize=7,
                     color="grey")
    for ax in axes:
        ax.set_xlabel(label)
        ax.set_ylabel(rf"$\rho$({label})")
    axes[0].set_title(f"{set_name}: pdf of {label} (linear)")
    axes[1].set_title(f"{set_name}: pdf of {label} (log)")
    _margins(fig, two=True)
    return fig


def plot_pdf(source, quantity: str = "e", *, set_name: str | None = None, seed: int = 0):
    """The probability density of one quantity of an ensemble with its fitted laws (the
    report's figure, from Python).

    The laws are fitted here by maximum likelihood, truncation-aware where a detection limit
    applies, without bootstrap intervals nor goodness of fit (run ``foldstat stats`` for
    those).

    Parameters
    ----------
    source : Ensemble, str or Path
        An ensemble, or a batch output, ``analyze`` output or simulation folder
        (:func:`crosssection.stats.data.load_any`).
    quantity : str
        A key of :data:`crosssection.stats.tables.QUANTITIES`: ``length_L``, ``kappa_m_L``,
        ``kappa_plus_L``, ``e``, ``E``, ``n_br``, ``area_L2``, ``shape_ratio``.
    set_name : str, optional
        The set to draw (default: the first).
    seed : int
        Seed of the fits' random starts.

    Returns
    -------
    matplotlib.figure.Figure
        Linear and logarithmic panels, bulk and periphery apart when the data carry them.

    Raises
    ------
    ValueError
        Unknown quantity or set, or too few values to fit.
    """
    from crosssection.stats.data import load_any
    from crosssection.stats.tables import fit_quantity

    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be one of {sorted(QUANTITIES)}, got {quantity!r}")
    ens = source if isinstance(source, Ensemble) else load_any(source)
    set_name = ens.sets[0] if set_name is None and ens.sets else set_name
    if set_name not in ens.sets:
        raise ValueError(f"set must be one of {ens.sets}, got {set_name!r}")
    sub = ens.subset(set_name)
    opts = StatsOptions(seed=seed, n_boot=0, gof=False, quantities=(quantity,))
    regions = ["all"] if QUANTITIES[quantity][0] in ("configs", "voids") else regions_of(sub)
    seeds = np.random.SeedSequence(seed).spawn(len(regions))
    summaries = {}
    for reg, sd in zip(regions, seeds):
        summ, _, _ = fit_quantity(sub, quantity, reg, opts, sd)
        if summ is not None:
            summaries[(set_name, reg, quantity)] = summ
    if not summaries:
        raise ValueError(f"{set_name}: too few positive values of {quantity} to fit "
                         f"(at least {opts.min_n})")
    empty = pd.DataFrame()
    fits_only = StatsResult(empty, empty, empty, empty, empty, empty, empty, empty, summaries)
    return pdf_figure(fits_only, ens, set_name, quantity)


def network_figure(res: StatsResult):
    """N_br vs N_l with Eqs. 1 and 3, and n_br_bar vs N_l with Eqs. 2 and 4, per set."""
    pc = res.per_config
    fig, axes = _subplots(2, figsize=(11, 4.2))
    for i, (s, g) in enumerate(pc.groupby("set", sort=False)):
        c = SET_COLORS[i % len(SET_COLORS)]
        rel = res.relations[res.relations["set"] == s].set_index("relation")["fitted"]
        nbr = res.macro.query("set == @s and region == 'all'")["n_br"].iloc[0]
        if not np.isfinite(nbr):  # no per-stack counts (simulations): the Eq. 3 fitted slope
            nbr = rel.get("eq3_slope", np.nan)
        axes[0].plot(g["N_l"], g["N_br"], "o", color=c, ms=4, alpha=0.7)
        axes[1].plot(g["N_l"], g["n_br_bar"], "o", color=c, ms=4, alpha=0.7)
        nl = np.linspace(max(1, g["N_l"].min() * 0.8), g["N_l"].max() * 1.2, 100)
        ratio = _nanmean(g["sqrt_s_bar"] / g["l_bar"])  # NaN for scans without voids
        eps = _nanmean(g["epsilon"])
        if np.isfinite(ratio) and np.isfinite(eps):
            eq1 = EQ1_CONST * eps * ratio * np.sqrt(nl)  # Eq. 1 with set means
            axes[0].plot(nl, eq1, "-", color=c)
            axes[1].plot(nl, eq1 / nl, "-", color=c)  # Eq. 2
        if np.isfinite(nbr):
            axes[0].plot(nl, nbr * nl, "--", color=c)  # Eq. 3
            axes[1].axhline(nbr, ls="--", color=c)  # Eq. 4
        axes[0].text(nl[-1], nbr * nl[-1] if np.isfinite(nbr) else g["N_br"].max(),
                     f" {s}: <n_br>={nbr:.2g}, C={rel.get('eq1_const', np.nan):.2g}",
                     color=c, fontsize=8, va="center")
    axes[0].set(xlabel=r"$N_l$", ylabel=r"$N_{br}$",
                title=r"$N_{br}$ vs $N_l$: solid Eq.1 ($C=2\sqrt{\pi/3}$), dashed Eq.3")
    axes[1].set(xlabel=r"$N_l$", ylabel=r"$\bar n_{br}=N_{br}/N_l$",
                title=r"$\bar n_{br}$ vs $N_l$: solid Eq.2, dashed Eq.4")
    _margins(fig, two=True)
    return fig


def _scatter_fig(res, x, y, xlabel, ylabel, title, *, through_origin=False, paper_slope=None):
    pc = res.per_config
    fig, ax = _subplots()
    for i, (s, g) in enumerate(pc.groupby("set", sort=False)):
        c = SET_COLORS[i % len(SET_COLORS)]
        xv, yv = np.asarray(g[x], float), np.asarray(g[y], float)
        k = np.isfinite(xv) & np.isfinite(yv)
        ax.plot(xv[k], yv[k], "o", color=c, ms=4, alpha=0.7)
        if k.sum() >= 2:
            txt = f"{s}"
            if through_origin:
                a = np.sum(xv[k] * yv[k]) / np.sum(xv[k] ** 2)
                xs = np.linspace(0, xv[k].max() * 1.1, 10)
                ax.plot(xs, a * xs, "-", color=c)
                txt += f": slope {a:.3g}"
            elif np.ptp(xv[k]) > 0 and np.ptp(yv[k]) > 0:
                txt += f": r={np.corrcoef(xv[k], yv[k])[0, 1]:.2f}"
            ax.annotate(txt, (xv[k].max(), yv[k][np.argmax(xv[k])]), color=c, fontsize=8,
                        xytext=(4, 0), textcoords="offset points")
    if paper_slope is not None:
        xs = np.array([0, np.nanmax(pc[x]) * 1.1])
        ax.plot(xs, paper_slope * xs, ":", color="grey")
        ax.text(xs[1], paper_slope * xs[1], f"paper {paper_slope}", color="grey", fontsize=8)
    ax.set(xlabel=xlabel, ylabel=ylabel, title=title)
    _margins(fig)
    return fig


def e_vs_nbr_figure(ens: Ensemble):
    """Mean branch energy against the number of branches of its stack (paper fig energo_micro3)."""
    br = ens.branches.dropna(subset=["n_br", "e"])
    if br.empty:
        return None
    fig, ax = _subplots()
    for i, s in enumerate(ens.sets):
        g = br[br["set"] == s]
        if g.empty:
            continue
        c = SET_COLORS[i % len(SET_COLORS)]
        for reg, ls in (("bulk", ":"), ("periphery", "--"), (None, "-")):
            gg = g if reg is None else g[g["region"] == reg]
            if gg.empty:
                continue
            st = gg.groupby("n_br")["e"].agg(["mean", "sem", "size"])
            ax.errorbar(st.index, st["mean"], yerr=st["sem"].fillna(0), fmt="o" + ls, color=c,
                        ms=4 if reg is None else 2, lw=1, capsize=2,
                        alpha=1 if reg is None else 0.6)
            if reg is None:
                ax.annotate(s, (st.index[-1], st["mean"].iloc[-1]), color=c, fontsize=8,
                            xytext=(4, 0), textcoords="offset points")
    ax.set(xlabel=r"$n_{br}$ (branches in the stack)", ylabel=r"$\langle e\rangle$",
           title=r"mean branch energy vs $n_{br}$ (mean $\pm$ s.e.m.)")
    ax.text(0.98, 0.97, "solid: all; dotted: bulk; dashed: periphery", transform=ax.transAxes,
            ha="right", va="top", fontsize=8, color="grey")
    _margins(fig)
    return fig


def _html_table(df: pd.DataFrame) -> str:
    return df.to_html(index=False, float_format=lambda v: f"{v:.4g}", na_rep="",
                      border=0, classes="t")


def write_report(ens: Ensemble, out_dir, *, opts: StatsOptions | None = None,
                 inputs=(), figures: bool = True, progress: bool | None = False) -> dict:
    """Compute every statistic of ``ens`` and write the report folder.

    Parameters
    ----------
    ens : Ensemble
    out_dir : path
        Receives macro/micro/fits/relations/dof/truncation (.csv, .md), correlations.csv,
        per_config.csv, stats.json, figures/*.png and report.html. All writes are atomic.
    opts : StatsOptions, optional
    inputs : sequence of str
        Input folders, recorded in stats.json.
    figures : bool
        Draw the PNG figures.
    progress : bool or None
        tqdm bars on stderr over the fits and the figures; None shows them only when stderr
        is a terminal.

    Returns
    -------
    dict
        Name -> written path.
    """
    from tqdm import tqdm

    opts = opts or StatsOptions()
    out = Path(out_dir)
    res = compute_stats(ens, opts, progress=progress)
    paths = {}
    tables = {"macro": res.macro, "micro": res.micro, "fits": res.fits,
              "relations": res.relations, "dof": res.dof, "truncation": res.truncation}
    for name, df in tables.items():
        paths[f"{name}.csv"] = write_csv(out / f"{name}.csv", df)
        paths[f"{name}.md"] = write_text(out / f"{name}.md", to_markdown(df))
    paths["correlations.csv"] = write_csv(out / "correlations.csv", res.correlations)
    paths["per_config.csv"] = write_csv(out / "per_config.csv", res.per_config)

    figs = []
    if figures:
        fdir = out / "figures"
        pdfs = [(s, q) for s in ens.sets for q in opts.quantities]
        for s, q in tqdm(pdfs, desc="stats figures", unit="fig", leave=False,
                         disable=None if progress is None else not progress):
            fig = pdf_figure(res, ens, s, q)
            if fig is not None:
                name = f"pdf_{q}_{_safe(s)}.png"
                paths[name] = save_figure(fig, fdir / name)
                figs.append((f"{s}: pdf of {q}", f"figures/{name}"))
        scatter = [
            ("network_Nbr_vs_Nl.png", "N_br vs N_l (Eqs. 1-4)", lambda: network_figure(res)),
            ("sqrt_s_vs_l.png", "sqrt(s_bar) vs l_bar", lambda: _scatter_fig(
                res, "l_bar", "sqrt_s_bar", r"$\bar\ell/L$", r"$\sqrt{\bar s}/L$",
                r"$\sqrt{\bar s}$ vs $\bar\ell$ per configuration (fit through 0)",
                through_origin=True, paper_slope=1.1)),
            ("E_vs_Nbr.png", "E vs N_br", lambda: _scatter_fig(
                res, "N_br", "E", r"$N_{br}$", r"$E$", r"total energy vs number of branches")),
            ("e_vs_nbr.png", "e vs n_br", lambda: e_vs_nbr_figure(ens)),
        ]
        for name, title, make in scatter:
            fig = make()
            if fig is not None:
                paths[name] = save_figure(fig, fdir / name)
                figs.append((title, f"figures/{name}"))

    stats_json = {
        "package": "foldstat", "version": __version__, "inputs": [str(i) for i in inputs],
        "options": {k: (list(v) if isinstance(v, tuple) else v)
                    for k, v in vars(opts).items()},
        "model_selection": f"min BIC; a family with fewer parameters within "
                           f"dBIC < {F.DELTA_BIC_SIMPLER} is preferred",
        "sets": {},
    }
    for s in ens.sets:
        sel = {}
        for (ss, reg, q), summ in res.summaries.items():
            if ss != s:
                continue
            sel.setdefault(reg, {})[q] = {
                "selected": summ.best,
                "fits": {f: {"params": r.params, "ci": r.ci, "bic": r.bic, "aic": r.aic,
                             "pvalue": r.pvalue, "n_mc": r.n_mc, "p_text": r.p_text(),
                             "n": r.n, "truncated": r.truncated, "rejected": r.rejected}
                         for f, r in summ.results.items() if r.ok}}
        stats_json["sets"][s] = {
            "macro": res.macro[res.macro["set"] == s].to_dict("records"),
            "micro": res.micro[res.micro["set"] == s].to_dict("records"),
            "relations": res.relations[res.relations["set"] == s].to_dict("records"),
            "correlations": res.correlations[res.correlations["set"] == s].to_dict("records"),
            "dof": res.dof[res.dof["set"] == s].to_dict("records"),
            "fits": sel}
    paths["stats.json"] = write_json(out / "stats.json", stats_json)
    paths["report.html"] = write_text(out / "report.html", _html(res, figs, stats_json))
    return paths


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(name))


def _html(res: StatsResult, figs, meta) -> str:
    sel = res.fits[res.fits["selected"]] if not res.fits.empty else res.fits
    pcols = tuple(f"p{i}{s}" for i in range(1, F.MAX_PARAMS + 1)
                  for s in ("_name", "", "_lo", "_hi"))
    sel_cols = [c for c in ("set", "region", "quantity", "family", "n", *pcols, "delta_bic",
                            "p_text") if c in sel.columns]
    rej = (res.fits[res.fits["rejected"].fillna("").astype(str) != ""]
           if "rejected" in res.fits.columns else res.fits.iloc[:0])
    rej_cols = ["set", "region", "quantity", "family", "rejected"]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>foldstat statistics</title>",
        "<style>body{font-family:sans-serif;max-width:1200px;margin:auto}"
        "table.t{border-collapse:collapse;font-size:12px}table.t td,table.t th"
        "{border:1px solid #ccc;padding:2px 6px}img{max-width:100%}</style></head><body>",
        f"<h1>Folding statistics</h1><p>foldstat {html.escape(meta['version'])}; inputs: "
        f"{html.escape(', '.join(meta['inputs']))}; seed {meta['options']['seed']}, "
        f"{meta['options']['n_boot']} bootstrap resamples. Model selection: "
        f"{html.escape(meta['model_selection'])}. Lengths in units of L.</p>",
        "<p>Tables: " + " ".join(f"<a href='{n}.csv'>{n}.csv</a> <a href='{n}.md'>(md)</a>"
                                 for n in ("macro", "micro", "fits", "relations", "dof",
                                           "truncation"))
        + " <a href='correlations.csv'>correlations.csv</a> <a href='stats.json'>stats.json</a>"
          "</p>",
        "<h2>Macro (paper table tab_macro)</h2>", _html_table(res.macro),
        "<h2>Micro (paper table tab_micro)</h2>", _html_table(res.micro),
        "<h2>Degrees of freedom: alpha_E/alpha_e vs N_l (paper table tab_res)</h2>",
        _html_table(res.dof),
        "<h2>Relations (paper Eqs. 1-5)</h2>", _html_table(res.relations),
        "<h2>Correlations</h2>", _html_table(res.correlations),
        "<h2>Selected laws</h2>",
        _html_table(sel[sel_cols].dropna(axis=1, how="all")) if len(sel) else "<p>none</p>",
    ]
    if len(rej):
        parts += ["<h2>Degenerate fits (never selected)</h2>", _html_table(rej[rej_cols])]
    if not res.truncation.empty:
        parts += ["<h2>Detection limits: naive vs truncation-aware fits</h2>",
                  _html_table(res.truncation)]
    parts.append("<h2>Figures</h2>")
    for title, rel in figs:
        parts.append(f"<h3>{html.escape(title)}</h3><a href='{rel}'><img src='{rel}' "
                     f"alt='{html.escape(title)}'></a>")
    parts.append("</body></html>\n")
    return "\n".join(parts)
