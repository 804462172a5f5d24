"""Figures of one analysed scan: the overlay (paper Figs. 1c and 9a), the processing steps
(paper Fig. 2), the curvature along the stacks and the stack widths against the calibration.
matplotlib ``Figure`` objects without pyplot (no GUI backend; they show in a notebook); save
with ``crosssection.core.fileio.save_figure``. ``AnalysisResult.plot`` draws them all.

Stacks are drawn as one ``LineCollection`` (thousands of stacks render in about a second),
with a line width proportional to ``n_br`` (one sheet thickness per branch on the image's
scale, at least 0.6 pt per branch), bulk bluish green and periphery vermillion, labelled with
``n_br`` at their mid point when they are long enough to carry a label.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from crosssection.core.errors import printable
from crosssection.core.fileio import SAVE_DPI

__all__ = ["overlay_figure", "draw_overlay", "overlay_window", "steps_figure", "threshold_title",
           "step_titles", "curvature_figure", "widths_figure", "dim_image"]

# bluish green and vermillion (Okabe and Ito's palette): told apart with every common colour
# vision deficiency, where green and red are not, and neither is the ink's blue
BULK_COLOR = "#009e73"
PERIPHERY_COLOR = "#d55e00"
OTHER_COLOR = "#2b83ba"


def _figure_width_in(shape, ncols=1, nrows=1, inches=10.0) -> float:
    h, w = shape[:2]
    return max(3.0, w * ncols * inches / max(h * nrows, w * ncols))


def _figure(shape, ncols=1, nrows=1, inches=10.0, header_in=0.6):
    from matplotlib.figure import Figure  # no pyplot: no GUI backend, thread-safe

    h, w = shape[:2]
    scale = inches / max(h * nrows, w * ncols)
    fig = Figure(figsize=(_figure_width_in(shape, ncols, nrows, inches),
                          max(3.0, h * nrows * scale + header_in)))
    return fig


# Header of the overlay: the title's lines above the legend's rows, so that neither covers the
# other whatever the scan's aspect (a tall scan makes a narrow figure). Widths in inches at
# the header's font sizes (10 pt title, 8 pt legend), measured on matplotlib's DejaVu Sans.
_TITLE_CHAR_IN = 0.085
_LEGEND_ITEM_IN = 1.25
_LINE_IN = 0.22


def _overlay_header(text: str, n_items: int, width_in: float) -> tuple[str, int, float]:
    """The title wrapped to the figure's width, the legend's columns, and the header's
    height (inches)."""
    import textwrap

    title = textwrap.fill(text, max(20, int((width_in - 0.2) / _TITLE_CHAR_IN)))
    ncol = max(1, min(n_items, int((width_in - 0.2) / _LEGEND_ITEM_IN)))
    rows = -(-n_items // ncol)
    height = (title.count("\n") + 1 + rows) * _LINE_IN + 0.15
    return title, ncol, height


def dim_image(rgb, amount=0.55) -> np.ndarray:
    """The scan as float RGB in [0, 1], blended towards white by ``amount``."""
    a = np.asarray(rgb)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    a = a[..., :3]
    vmax = 65535.0 if a.dtype == np.uint16 else (255.0 if a.dtype.kind in "ui" else 1.0)
    f = np.clip(a.astype(np.float32) / vmax, 0, 1)
    return f * (1 - amount) + amount


# The overlay shows the hole and this much of its radius around it: a page scanned at 1200 dpi
# holds a hole of a few hundred pixels in thousands, drawn whole it is unreadable.
HOLE_VIEW_MARGIN = 0.08


#: File stems that say nothing of the scan (a scene folder's image.png): the overlay's title
#: names the folder too
GENERIC_STEMS = frozenset({"image", "scan", "img"})


def overlay_window(shape, hole=None) -> tuple[int, int, int, int]:
    """The part of the scan an overlay shows, ``(row0, row1, col0, col1)`` (end exclusive):
    the hole's square widened by :data:`HOLE_VIEW_MARGIN` of its radius, within the scan; the
    whole scan when no hole is known."""
    h, w = shape[:2]
    if hole is None or not np.isfinite(getattr(hole, "radius_px", np.nan)):
        return 0, h, 0, w
    r = float(hole.radius_px) * (1.0 + HOLE_VIEW_MARGIN)
    (cr, cc) = (float(x) for x in hole.center_rc)
    r0, r1 = max(0, int(np.floor(cr - r))), min(h, int(np.ceil(cr + r)) + 1)
    c0, c1 = max(0, int(np.floor(cc - r))), min(w, int(np.ceil(cc + r)) + 1)
    if r1 - r0 < 2 or c1 - c0 < 2:
        return 0, h, 0, w
    return r0, r1, c0, c1


#: Longest side, in pixels, of the scan as an image panel draws it: twice the 1200 px of a
#: 10-inch figure saved at 120 dpi. A 4000 x 4000 scan handed to matplotlib whole is resampled
#: in float64 copies: 1.24 GB peak for the analysis of one, 819 MB with the scan shrunk.
PANEL_MAX_PX = 2400


def panel_image(img, max_px: int = PANEL_MAX_PX) -> np.ndarray:
    """``img`` (RGB or a 2-D mask) shrunk by area averaging so that its longer side is at most
    ``max_px``; as it is when it is no larger. A mask comes back as float in [0, 1], so a thin
    line stays visible as grey. Draw it with the full image's ``extent``.

    Parameters
    ----------
    img : (H, W) or (H, W, C) array
    max_px : int

    Returns
    -------
    ndarray
    """
    import cv2

    a = np.asarray(img)
    h, w = a.shape[:2]
    if max(h, w) <= max_px:
        return a
    f = max_px / max(h, w)
    size = (max(1, round(w * f)), max(1, round(h * f)))
    if a.dtype == bool:
        a = a.astype(np.float32)
    elif a.dtype.kind not in "uf" or a.dtype == np.float16:
        a = a.astype(np.float32)
    return cv2.resize(np.ascontiguousarray(a), size, interpolation=cv2.INTER_AREA)


def _count(n: int, noun: str) -> str:
    """``1 stack``, ``2 stacks``, ``1 branch``, ``0 branches``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}{'es' if noun.endswith('ch') else 's'}"


def _get(result, name, default=None):
    return getattr(result, name, default) if result is not None else default


def overlay_figure(rgb, result=None, *, junctions_df=None, stacks_df=None, paths=None,
                   hole=None, thickness_px=5.0, title=None, label_min_px=None,
                   max_labels=600):
    """The scan dimmed, with the network drawn on it (paper Figs. 1c and 9a).

    Parameters
    ----------
    rgb : array (H, W, 3)
        The scan (any dtype).
    result : AnalysisResult, optional
        Takes ``junctions``, ``stacks``, ``graph.paths`` and ``hole`` from it when the keyword
        arguments are not given.
    junctions_df : DataFrame
        ``x_px``, ``y_px`` (junction centres; column, row).
    stacks_df : DataFrame
        ``n_br``, ``region``; optional ``mid_x_px``, ``mid_y_px``.
    paths : list of (P, 2) arrays
        Pixel paths (row, col) in the order of ``stacks_df`` rows.
    hole : Hole, optional
        Drawn as a dashed circle; the figure shows the hole and a margin of
        :data:`HOLE_VIEW_MARGIN` of its radius (:func:`overlay_window`), not the whole page.
    thickness_px : float
        Sheet thickness in px: a stack of n_br branches is drawn ``n_br * thickness_px`` wide.
    title : str, optional
    label_min_px : float, optional
        Only stacks at least this long (px) get an n_br label (default: 4 label heights).
    max_labels : int
        At most this many labels, on the longest stacks.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.lines import Line2D

    img = np.asarray(rgb)
    r0, r1, c0, c1 = overlay_window(img.shape, hole if hole is not None else _get(result, "hole"))
    view = (r1 - r0, c1 - c0)
    # the counts in the title are known after drawing: the header is sized for the longest
    # counts a scan can have
    n_items = 6 if len(_step_points(result)) else 5
    path = _get(result, "path")
    # a scan named generically (image.png of a scene folder) is named with its folder
    shown = (f"{Path(path).parent.name}/{Path(path).name}"
             if path and Path(path).stem.lower() in GENERIC_STEMS and Path(path).parent.name
             else Path(path).name if path else "")
    shown = printable(shown)  # a name that is not UTF-8 cannot be drawn as it is
    head = title or ((f"{shown}: " if shown else "") + "stacks: width and label = n_br")
    wide = f"{head}   (00000 junctions, 00000 stacks, 000000 branches)"
    _, _, header_in = _overlay_header(wide, n_items, _figure_width_in(view))
    fig = _figure(view, header_in=header_in)
    ax = fig.add_axes([0, 0, 1, 1 - header_in / fig.get_figheight()])
    n_j, m, n_br_total = draw_overlay(
        ax, img, result, junctions_df=junctions_df, stacks_df=stacks_df, paths=paths,
        hole=hole, thickness_px=thickness_px, label_min_px=label_min_px,
        max_labels=max_labels)
    st = stacks_df if stacks_df is not None else _get(result, "stacks")
    regions = set(st["region"]) if st is not None and "region" in st else {"bulk", "periphery"}
    # only what the figure shows: a scan without a periphery stack shows no periphery colour
    handles = [Line2D([], [], color=c, lw=3, label=r)
               for r, c in (("bulk", BULK_COLOR), ("periphery", PERIPHERY_COLOR))
               if r in regions]
    if n_j:
        handles.append(Line2D([], [], marker="o", mfc="none", mec="black", ls="none",
                              label="junction"))
    if len(_step_points(result)):
        handles.append(Line2D([], [], marker="D", mfc="white", mec="black", ls="none",
                              label="layer step"))
    if (hole if hole is not None else _get(result, "hole")) is not None:
        handles.append(Line2D([], [], color="0.25", ls="--", lw=1.2, label="hole"))
    px_per_mm = getattr(_get(result, "params"), "px_per_mm", None)
    if px_per_mm:
        _scale_bar(ax, float(px_per_mm), view[1], img[max(r0, 0):r1, max(c0, 0):c1])
    text, ncol, _ = _overlay_header(
        f"{head}   ({_count(n_j, 'junction')}, {_count(m, 'stack')}, "
        f"{_count(n_br_total, 'branch')})", len(handles),
        fig.get_figwidth())
    height = fig.get_figheight()
    fig.suptitle(text, fontsize=10, x=0.1 / fig.get_figwidth(), y=1 - 0.05 / height,
                 ha="left", va="top")
    below = (text.count("\n") + 1) * _LINE_IN + 0.08
    fig.legend(handles=handles, loc="upper left", ncol=ncol, fontsize=8, frameon=False,
               bbox_to_anchor=(0.05 / fig.get_figwidth(), 1 - below / height),
               borderaxespad=0.0, handlelength=1.8, columnspacing=1.2)
    return fig


def _scale_bar(ax, px_per_mm: float, width_px: float, view_rgb=None) -> None:
    """A bar of a round length in mm (about a fifth of the view's width) in the corner of
    ``ax`` with the least ink of ``view_rgb`` (the lower left one without it; a scan cropped
    through its hole has stacks in the corners), labelled with its length."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    target_mm = 0.2 * width_px / px_per_mm
    nice = [m * 10.0 ** k for k in range(-2, 4) for m in (1, 2, 5)]
    mm = max([v for v in nice if v <= target_mm] or [nice[0]])
    label = f"{mm:g} mm"
    loc = "lower left"
    if view_rgb is not None and view_rgb.size:
        img = np.asarray(view_rgb)
        h, w = img.shape[:2]
        bh, bw = max(int(0.08 * h), 1), max(int(1.3 * mm * px_per_mm), 1)
        rows = {"lower": slice(h - bh, h), "upper": slice(0, bh)}
        cols = {"left": slice(0, bw), "right": slice(w - bw, w)}
        top = np.iinfo(img.dtype).max if img.dtype.kind in "ui" else 1.0
        # ink and marks are darker than paper in at least one channel
        dark = {f"{v} {u}": float(np.mean(img[rows[v], cols[u]].min(axis=-1) < 0.63 * top))
                for v in ("lower", "upper") for u in ("left", "right")}
        loc = min(dark, key=lambda k: (dark[k] > 0.005, dark[k], k != "lower left"))
    ax.add_artist(AnchoredSizeBar(ax.transData, mm * px_per_mm, label, loc,
                                  pad=0.4, borderpad=0.5, sep=3, frameon=False,
                                  size_vertical=max(1.0, 0.004 * width_px), color="black",
                                  fontproperties={"size": 8}))


def _step_points(result) -> np.ndarray:
    """(x, y) of the result's layer steps (graph nodes of kind ``"step"``), (0, 2) if none."""
    graph = _get(result, "graph")
    kinds = _get(graph, "node_kind", {}) or {}
    rc = [graph.node_rc[n] for n, k in kinds.items() if k == "step"]
    return np.asarray(rc, float)[:, ::-1] if rc else np.zeros((0, 2))


def draw_overlay(ax, rgb, result=None, *, junctions_df=None, stacks_df=None, paths=None,
                 hole=None, thickness_px=5.0, label_min_px=None, max_labels=600):
    """Draw the overlay of :func:`overlay_figure` into an existing matplotlib axes (no title,
    no legend). Parameters as :func:`overlay_figure`.

    Returns
    -------
    (n_junctions, n_stacks, n_branches) : tuple of int
        What was drawn.
    """
    import math

    from matplotlib import patheffects
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle

    junctions_df = junctions_df if junctions_df is not None else _get(result, "junctions")
    stacks_df = stacks_df if stacks_df is not None else _get(result, "stacks")
    if paths is None:
        paths = _get(_get(result, "graph"), "paths", [])
    hole = hole if hole is not None else _get(result, "hole")
    paths = list(paths or [])
    img = np.asarray(rgb)
    r0, r1, c0, c1 = overlay_window(img.shape, hole)
    # the hole's part of the scan, drawn in the scan's own pixel coordinates
    ax.imshow(dim_image(panel_image(img[r0:r1, c0:c1])), interpolation="antialiased",
              extent=(c0 - 0.5, c1 - 0.5, r1 - 0.5, r0 - 0.5))
    ax.set_xlim(c0 - 0.5, c1 - 0.5)
    ax.set_ylim(r1 - 0.5, r0 - 0.5)
    ax.set_axis_off()
    # line widths are in points: one image pixel is this many points at the axes' size
    pt_per_px = ax.get_position().width * ax.figure.get_figwidth() * 72.0 / (c1 - c0)

    m = len(paths)
    n_br = np.ones(m, dtype=float)
    regions = np.array(["bulk"] * m, dtype=object)
    if stacks_df is not None and len(stacks_df) == m:
        if "n_br" in stacks_df:
            n_br = np.nan_to_num(stacks_df["n_br"].to_numpy(dtype=float), nan=1.0)
        if "region" in stacks_df:
            regions = stacks_df["region"].astype(str).to_numpy()
    colors = np.where(regions == "periphery", PERIPHERY_COLOR,
                      np.where(regions == "bulk", BULK_COLOR, OTHER_COLOR))
    lw_layer = max(0.6, thickness_px * pt_per_px)
    segs = [np.asarray(p, float)[:, ::-1] for p in paths if len(p) >= 2]
    keep = [i for i, p in enumerate(paths) if len(p) >= 2]
    if segs:
        lc = LineCollection(segs, colors=colors[keep], linewidths=lw_layer * n_br[keep],
                            alpha=0.8, capstyle="round", joinstyle="round")
        ax.add_collection(lc)

    # n_br labels at the mid points of long enough stacks (the longest max_labels: text is
    # the slow part of a matplotlib figure, ~2.5 ms per label)
    fontsize = 7.0
    if label_min_px is None:
        label_min_px = 4 * fontsize / pt_per_px
    label_px = fontsize / pt_per_px
    lengths = np.array([len(p) for p in paths])
    order = np.argsort(-lengths, kind="stable")[:max_labels]
    for i in order:
        p = paths[i]
        if len(p) == 0 or len(p) < label_min_px:
            continue
        if stacks_df is not None and len(stacks_df) == m and "mid_x_px" in stacks_df:
            x, y = float(stacks_df["mid_x_px"].iloc[i]), float(stacks_df["mid_y_px"].iloc[i])
        else:
            y, x = np.asarray(p[len(p) // 2], float)
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        t = ax.text(x, y, str(int(n_br[i])), fontsize=fontsize, ha="center", va="center",
                    color="black", fontweight="bold", clip_on=True)
        if hole is not None and abs(math.hypot(x - hole.center_rc[1], y - hole.center_rc[0])
                                    - hole.radius_px) < label_px:
            # a wall stack's label on the hole's dashed circle: a white outline keeps it read
            t.set_path_effects([patheffects.withStroke(linewidth=2.0, foreground="white")])

    if junctions_df is not None and len(junctions_df):
        ax.scatter(junctions_df["x_px"], junctions_df["y_px"],
                   s=max(12.0, (2.5 * thickness_px * pt_per_px) ** 2), facecolors="none",
                   edgecolors="black", linewidths=1.0, zorder=3)
    steps = _step_points(result)
    if len(steps):
        ax.scatter(steps[:, 0], steps[:, 1], marker="D",
                   s=max(10.0, (1.5 * thickness_px * pt_per_px) ** 2), facecolors="white",
                   edgecolors="black", linewidths=0.8, zorder=3)
    if hole is not None:
        ax.add_patch(Circle((hole.center_rc[1], hole.center_rc[0]), hole.radius_px, fill=False,
                            ls="--", lw=1.2, ec="0.25", zorder=2))
    n_j = 0 if junctions_df is None else len(junctions_df)
    return n_j, m, int(n_br.sum())


def threshold_title(thresholds: dict | None) -> str:
    """The steps figure's title of the threshold panel, from ``summary['thresholds']``: the
    rule and the cuts used (:func:`crosssection.stages.threshold.threshold_rgb`)."""
    t = thresholds or {}

    def num(x):
        return f"{x:.0f}" if x is not None and float(x).is_integer() else f"{x:.1f}"

    if t.get("method") == "fixed" and t.get("blue_min") is not None:
        return f"threshold: B \u2265 {num(t['blue_min'])}, R, G \u2264 {num(t['rg_max'])}"
    if t.get("cut") is not None:
        rg = f", R, G \u2264 {num(t['rg_max'])}" if t.get("rg_max") is not None else ""
        return f"threshold ({t.get('method')}): B \u2212 max(R, G) \u2265 {num(t['cut'])}{rg}"
    return "threshold (blue high, red/green low)"


def step_titles(thresholds: dict | None = None) -> list:
    """The four panel titles of :func:`steps_figure`, the threshold's from
    :func:`threshold_title`."""
    return ["raw scan", threshold_title(thresholds), "cleaned (voids \u2265 s_min kept)",
            "skeleton and junctions"]


def steps_figure(rgb, mask_threshold, mask_clean, skeleton, junction_centers_rc, *,
                 titles=None, axes=None, px_per_mm=None, hole=None):
    """The four steps of paper Fig. 2: raw scan, thresholded, cleaned, skeleton + junctions.

    Parameters
    ----------
    rgb : array (H, W, 3)
    mask_threshold, mask_clean, skeleton : bool arrays (H, W)
    junction_centers_rc : array (K, 2)
    titles : list of 4 str, optional
    axes : sequence of 4 matplotlib axes, optional
        Draw into these instead of a new figure.
    px_per_mm : float, optional
        The scan's resolution: a scale bar in mm on the raw scan's panel (the four panels
        share one scale).
    hole : Hole, optional
        The panels show the hole and a margin around it, as the overlay does
        (:func:`overlay_window`); the whole scan without it.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from scipy import ndimage as ndi

    r0, r1, c0, c1 = overlay_window(np.shape(rgb), hole)
    img = np.asarray(rgb)[r0:r1, c0:c1]
    mask_threshold, mask_clean, skeleton = (np.asarray(m)[r0:r1, c0:c1] for m in
                                            (mask_threshold, mask_clean, skeleton))
    H, W = img.shape[:2]
    own = axes is None
    if own:
        fig = _figure(img.shape, ncols=4, inches=16.0)
        axes = fig.subplots(1, 4)
    else:
        from matplotlib.axes import Axes

        from crosssection.core.errors import ParameterError

        axes = list(np.ravel(np.asarray(axes, dtype=object)))
        if len(axes) != 4:
            raise ParameterError(f"steps need 4 axes, got {len(axes)}")
        if not all(isinstance(a, Axes) for a in axes):
            raise ParameterError("steps need 4 matplotlib Axes, got "
                                 f"{', '.join(sorted({type(a).__name__ for a in axes}))}")
        fig = axes[0].figure
    titles = titles or step_titles()
    # every panel in the scan's pixel coordinates, whatever size it is drawn at
    extent = (-0.5, W - 0.5, H - 0.5, -0.5)
    axes[0].imshow(dim_image(panel_image(img), 0.0), extent=extent)
    sk = np.asarray(skeleton, bool)
    # a one-pixel skeleton vanishes when a large scan is shown small: thicken for display
    grow = int(max(0, round(max(H, W) / 1000.0)))
    if grow:
        sk = ndi.binary_dilation(sk, iterations=grow)
    if own:
        fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.92, wspace=0.03)
    for ax, mask in zip(axes[1:], (mask_threshold, mask_clean, sk)):
        shown = panel_image(np.asarray(mask, bool))
        # a panel a few hundred pixels wide (at the dpi figures are saved at) shows a
        # larger mask filtered, not by its nearest pixels, which break lines a few pixels
        # wide into dashes (a 5000 px scan's single sheets)
        panel_px = ax.get_position().width * fig.get_figwidth() * SAVE_DPI
        ax.imshow(shown, cmap="gray_r", vmin=0, vmax=1, extent=extent,
                  interpolation="antialiased" if max(shown.shape) > 1.5 * panel_px
                  else "nearest")
    jc = np.asarray(junction_centers_rc, float).reshape(-1, 2) - (r0, c0)
    if len(jc):
        axes[3].scatter(jc[:, 1], jc[:, 0], s=14, facecolors="none", edgecolors="red",
                        linewidths=0.8)
    for ax, t in zip(axes, titles):
        ax.set_title(t, fontsize=10)
        ax.set_axis_off()
    if px_per_mm:
        _scale_bar(axes[0], float(px_per_mm), W, img)
    return fig


def curvature_figure(profiles, stacks_df=None, *, ax=None, max_stacks=8):
    """Local curvature along the longest stacks (``stages.curvature`` profiles).

    Parameters
    ----------
    profiles : list of CurvatureProfile
        ``s_mm``, ``kappa_per_mm``, ``fit_start``, ``fit_stop`` per stack, in the order of
        ``stacks_df``.
    stacks_df : DataFrame, optional
        ``n_br`` of each stack (shown in the legend).
    ax : matplotlib axes, optional
        Draw into it instead of a new figure.
    max_stacks : int
        The longest this many stacks are drawn.

    Returns
    -------
    matplotlib.figure.Figure
        Solid: the fitted samples; dotted: fork zones and ends (not fitted).
    """
    ax = _axes(ax, (8.4, 4.2), right=0.78)
    profiles = list(profiles or [])
    order = sorted(range(len(profiles)), key=lambda i: -float(profiles[i].length_mm))
    for k, i in enumerate(order[:max_stacks]):
        p = profiles[i]
        s, kap = np.asarray(p.s_mm, float), np.asarray(p.kappa_per_mm, float)
        a, b = int(p.fit_start), int(p.fit_stop)
        n_br = ""
        if stacks_df is not None and len(stacks_df) == len(profiles) and "n_br" in stacks_df:
            n_br = f", n_br = {int(stacks_df['n_br'].iloc[i])}"
        line, = ax.plot(s[a:b], kap[a:b], lw=1.2, label=f"stack {i}{n_br}")
        ax.plot(s, kap, ":", lw=0.8, color=line.get_color())
    ax.axhline(0, color="0.6", lw=0.6)
    ax.set_xlabel("arc length s [mm]")
    ax.set_ylabel(r"curvature $\kappa$ [1/mm]")
    shown = min(max_stacks, len(profiles))
    ax.set_title(("curvature along the stack" if shown == 1 else
                  f"curvature along the {shown} longest stacks") + " (dotted: not fitted)",
                 fontsize=10)
    if profiles:  # beside the axes: the curves run anywhere inside them
        ax.legend(fontsize=7, frameon=False, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                  borderaxespad=0.0)
    return ax.figure


def widths_figure(stacks_df, calibration=None, *, ax=None,
                  calibration_label: str = "calibration w(n)"):
    """Measured stack widths against their layer counts, with the calibration law.

    Parameters
    ----------
    stacks_df : DataFrame
        ``width_mm``, ``n_br`` and ``region`` per stack.
    calibration : Calibration, optional
        Its ``width(n)`` is drawn as the line the widths are read against.
    ax : matplotlib axes, optional
        Draw into it instead of a new figure.
    calibration_label : str
        The line's legend entry (an analysis without a calibration reads widths against the
        law read from the scan, or ``w = n h``: no calibration either way).

    Returns
    -------
    matplotlib.figure.Figure
    """
    ax = _axes(ax, (6.0, 4.2))
    df = stacks_df if stacks_df is not None else None
    n_max = 1
    if df is not None and len(df):
        n = df["n_br"].to_numpy(float)
        w = df["width_mm"].to_numpy(float)
        regions = (df["region"].astype(str).to_numpy() if "region" in df
                   else np.array(["bulk"] * len(df)))
        # a little horizontal jitter: many stacks share a layer count
        jitter = (np.arange(len(df)) % 7 - 3) * 0.03
        for reg, color in (("bulk", BULK_COLOR), ("periphery", PERIPHERY_COLOR)):
            k = regions == reg
            if k.any():
                ax.plot(n[k] + jitter[k], w[k], "o", ms=3, alpha=0.6, color=color, label=reg)
        other = ~np.isin(regions, ["bulk", "periphery"])
        if other.any():
            ax.plot(n[other] + jitter[other], w[other], "o", ms=3, alpha=0.6,
                    color=OTHER_COLOR)
        n_max = int(np.nanmax(n)) if np.isfinite(n).any() else 1
    if calibration is not None:
        ns = np.arange(1, max(n_max, 1) + 2)
        ax.plot(ns, calibration.width(ns), "-", color="black", lw=1, label=calibration_label)
    ax.set_xlabel(r"layers $n_{br}$")
    ax.set_ylabel("stack width [mm]")
    ax.set_title("stack widths and the calibration they are read against", fontsize=10)
    ax.legend(fontsize=8, frameon=False)
    return ax.figure


def _axes(ax, figsize, right: float = 0.97):
    """``ax``, or the single axes of a new (pyplot-free) figure (``right``: where the axes
    end, leaving room for a legend beside them)."""
    if ax is not None:
        return ax
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    ax = fig.add_subplot()
    fig.subplots_adjust(left=0.12 * 7.0 / figsize[0], right=right, bottom=0.13, top=0.9)
    return ax
