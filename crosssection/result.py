"""The result of one analysis, :class:`AnalysisResult`, and how it is written to disk."""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core import schema
from crosssection.core.errors import ImageError, OutputError, ParameterError, output_error

__all__ = ["AnalysisResult", "write_step_images"]


def rod_length_text(summary: dict) -> str:
    """``L = 287.9 mm`` for a one-line report of an analysis, and ``L = 287.9 mm measured,
    320.0 mm given`` when the rod length given (``rod_length_used_mm``, the L of epsilon and
    the energies) is another."""
    def mm(v):
        return f"{v:.1f}" if v >= 1 else f"{v:.3g}"

    measured = summary["rod_length_mm"]
    used = summary.get("rod_length_used_mm")
    if used is None or mm(used) == mm(measured):
        return f"L = {mm(measured)} mm"
    return f"L = {mm(measured)} mm measured, {mm(used)} mm given"


@dataclass(repr=False, eq=False, frozen=True)
class AnalysisResult:
    """Everything ``analyze`` computed for one scan.

    Compared by identity (``==`` is ``is``): two analyses of one scan differ in their
    timings; compare their ``tables`` and ``summary`` to compare their results.

    Frozen one level deep: no attribute can be rebound, but the dict, the tables and the
    arrays it holds are the analysis' own and can be edited in place, which every later use
    of this result (``repr``, ``network()``, ``write``) then shows. Edit a copy
    (``result.stacks.copy()``, ``copy.deepcopy(result.summary)``).

    Attributes
    ----------
    summary : dict
        ``schema.SUMMARY_KEYS`` plus thresholds, linear-system diagnostics, parameters,
        warnings, version, image info and per-stage ``timings_s``.
    junctions, stacks, branches, voids : DataFrame
        The tables (``schema`` columns first, extra columns after).
    graph : StackGraph
        Junctions and stacks with their pixel paths.
    hole : Hole
        Container wall (given or fitted).
    rgb : ndarray
        The scan.
    mask_threshold, mask_clean, skeleton : bool ndarrays
        Intermediate images (paper Fig. 2).
    junction_clusters : Junctions
        Junction pixels and label image.
    packs : dict
        Junction node -> Pack.
    linear_system : LinearSystemResult or None
    profiles : list of CurvatureProfile
    params : AnalysisParams
        The parameters used.
    path : str or None
        Image file.
    quality : tuple of QualityFlag
        Failed quality checks (:mod:`crosssection.quality`).
    """

    summary: dict
    junctions: pd.DataFrame
    stacks: pd.DataFrame
    branches: pd.DataFrame
    voids: pd.DataFrame
    graph: object
    hole: object
    rgb: np.ndarray
    mask_threshold: np.ndarray
    mask_clean: np.ndarray
    skeleton: np.ndarray
    junction_clusters: object = None
    packs: dict = field(default_factory=dict)
    linear_system: object = None
    profiles: list = field(default_factory=list)
    params: object = None
    path: str | None = None
    quality: tuple = ()

    def __repr__(self) -> str:
        s = self.summary
        eps = s.get("epsilon")
        head = (f"AnalysisResult({self.path or 'array'}: {s['n_junctions']} junctions, "
                f"{s['n_stacks']} stacks, {s['n_branches']} branches, {s['n_voids']} voids, "
                f"{rod_length_text(s)}"
                + (f", epsilon = {eps:.2f}" if eps is not None else ""))
        codes = [f.code for f in self.quality]
        return head + (f", warnings: {', '.join(codes)})" if codes else ")")

    def _repr_html_(self) -> str:
        """A notebook summary: counts, rod length, epsilon and quality warnings, beside a
        small overlay thumbnail (PNG embedded in base64, a few tens of kB).

        Returns
        -------
        str
            An HTML table (Jupyter shows it as the value of a cell).
        """
        import html

        s = self.summary

        def num(key, fmt):
            v = s.get(key)
            return "" if v is None else format(v, fmt)

        rows = [("image", html.escape(str(self.path or "array"))),
                ("junctions", num("n_junctions", "d")), ("stacks", num("n_stacks", "d")),
                ("branches", num("n_branches", "d")), ("voids", num("n_voids", "d")),
                ("branches per stack", num("mean_branches_per_stack", ".2f")),
                ("rod length L", html.escape(rod_length_text(s).removeprefix("L = "))),
                ("epsilon = L / 2 pi R", num("epsilon", ".2f")),
                ("total energy e", num("total_energy", ".4g"))]
        warn = "".join(f"<li><b>{html.escape(f.code)}</b>: {html.escape(f.message)}</li>"
                       for f in self.quality)
        rows.append(("quality", f"<ul style='margin:0;padding-left:1.2em'>{warn}</ul>" if warn
                     else "no warning"))
        table = "".join(f"<tr><th style='text-align:left'>{k}</th><td style='text-align:left'>"
                        f"{v}</td></tr>" for k, v in rows)
        thumb = ""
        if self.rgb is not None:
            thumb = (f"<td style='vertical-align:top'><img alt='overlay' "
                     f"src='data:image/png;base64,{self.thumbnail_png(base64=True)}'></td>")
        return (f"<table><tr><td style='vertical-align:top'><b>AnalysisResult</b><table>"
                f"{table}</table></td>{thumb}</tr></table>")

    def thumbnail_png(self, size_px: int = 320, *, base64: bool = False):
        """The overlay, small, as PNG bytes (a 64-colour palette keeps it to tens of kB).

        Parameters
        ----------
        size_px : int
            Longest side in pixels.
        base64 : bool
            Return the base64 text (for an HTML ``data:`` URI) instead of bytes.

        Returns
        -------
        bytes or str
        """
        import base64 as b64
        import io

        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from PIL import Image

        from crosssection.figures import draw_overlay

        h, w = np.asarray(self.rgb).shape[:2]
        dpi = 100
        fig = Figure(figsize=(size_px * w / max(h, w) / dpi, size_px * h / max(h, w) / dpi),
                     dpi=dpi)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes([0, 0, 1, 1])
        draw_overlay(ax, self.rgb, self, thickness_px=self._drawn_thickness_px(), max_labels=0)
        canvas.draw()
        img = Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3])
        buf = io.BytesIO()
        img.quantize(colors=64).save(buf, format="PNG", optimize=True)
        data = buf.getvalue()
        return b64.b64encode(data).decode("ascii") if base64 else data

    def plot(self, kind: str = "overlay", ax=None):
        """A figure of this analysis (the drawing code of :mod:`crosssection.figures`).

        Parameters
        ----------
        kind : {"overlay", "steps", "curvature", "widths"}
            ``overlay``: the network on the dimmed scan (paper Figs. 1c, 9a); ``steps``: raw,
            threshold, cleaned, skeleton with junctions (Fig. 2); ``curvature``: local
            curvature along the longest stacks; ``widths``: measured stack widths against
            n_br with the calibration law.
        ax : matplotlib axes, optional
            Draw into it (for ``steps``: a sequence of 4 axes); default a new figure.

        Returns
        -------
        matplotlib.figure.Figure
            Shown as a cell's value in a notebook; save with ``fig.savefig``.
        """
        from crosssection import figures as F

        if ax is not None and kind in ("overlay", "curvature", "widths"):
            from matplotlib.axes import Axes

            if not isinstance(ax, Axes):
                raise ParameterError(f"ax must be one matplotlib Axes for {kind!r}, got "
                                     f"{type(ax).__name__}")
        if kind == "overlay":
            if ax is None:
                return F.overlay_figure(self.rgb, self, thickness_px=self._drawn_thickness_px())
            F.draw_overlay(ax, self.rgb, self, thickness_px=self._drawn_thickness_px())
            return ax.figure
        if kind == "steps":
            return F.steps_figure(self.rgb, self.mask_threshold, self.mask_clean, self.skeleton,
                                  self.graph_junction_centers(), axes=ax,
                                  titles=self._step_titles(),
                                  px_per_mm=getattr(self.params, "px_per_mm", None),
                                  hole=self.hole)
        if kind == "curvature":
            return F.curvature_figure(self.profiles, self.stacks, ax=ax)
        if kind == "widths":
            from crosssection.pipeline import _calibration

            cal = _calibration(self.params) if self.params is not None else None
            given = self.params is not None and self.params.calibration is not None
            label = "calibration w(n)" if given else "no calibration: w = n h"
            law = self.summary.get("width_law") or {}
            if not given and law.get("ok"):
                from crosssection.stages.widthlaw import WidthLawFit

                fit = WidthLawFit.from_record(law)
                cal, label = fit.calibration(), f"read from the scan: {fit.formula()}"
            return F.widths_figure(self.stacks, cal, ax=ax, calibration_label=label)
        raise ParameterError(f"kind must be one of 'overlay', 'steps', 'curvature', 'widths', "
                             f"got {kind!r}")

    def _drawn_thickness_px(self) -> float:
        # a result assembled by hand may lack its parameters: draw with the figures' default
        return self.thickness_px if self.params is not None else 5.0

    @property
    def tables(self) -> dict:
        """``{"junctions", "stacks", "branches", "voids"}`` -> DataFrame."""
        return {"junctions": self.junctions, "stacks": self.stacks,
                "branches": self.branches, "voids": self.voids}

    @property
    def thickness_px(self) -> float:
        return self.params.thickness_px

    def network(self):
        """The folded network as a ``networkx.MultiGraph``: junctions as nodes, stacks as
        edges carrying their table columns and ``energy``
        (:func:`crosssection.tables.network_graph`)."""
        from crosssection.tables import network_graph

        return network_graph(self.junctions, self.stacks, self.branches)

    def write(self, out_dir, *, figure: bool = True, steps: bool = False) -> dict:
        """Write ``summary.json``, the four CSV tables and (optionally) ``overlay.png``.

        Parameters
        ----------
        out_dir : str or Path
            Created if needed. Files are written atomically, all renamed into place at the
            end (``summary.json`` last): a write stopped midway leaves the folder's earlier
            files as they were. The hidden temporary files that a write killed midway left
            there are removed first (:func:`crosssection.commands.clear_temporary`).
            Nothing else in the folder is touched: an ``overlay.png`` or step images of an
            earlier write stay when this one does not write them (``foldstat analyze`` removes them,
            :func:`crosssection.commands.remove_stale`).
        figure : bool
            Also write ``overlay.png`` (paper Figs. 1c and 9a), and ``steps.png`` with
            ``steps``.
        steps : bool
            Also write the step images of paper Fig. 2 (see :meth:`write_steps`).

        Returns
        -------
        dict
            Name -> written path.

        Raises
        ------
        ParameterError
            ``out_dir`` is not a path, holds the output of another command (a batch, a stats
            report, a render, a validate report, a simulation) or step images of another
            scan, or is the scan's own folder (as ``foldstat analyze`` refuses them:
            :func:`crosssection.commands.check_not_other_output`,
            :func:`crosssection.commands.check_not_beside`).
        OutputError
            The folder cannot be created or written (a file in the way, no permission).
        """
        if not isinstance(out_dir, (str, os.PathLike)) or not str(out_dir).strip():
            raise ParameterError(f"out_dir must be a folder path, got {out_dir!r}")
        from crosssection.commands import check_not_beside, check_not_other_output, run_files

        if self.path is not None:
            check_not_beside(self.path, out_dir, given_as="out_dir")
        check_not_other_output(out_dir, self.path, given_as="out_dir",
                               writes=run_files("analyze", figure=figure, steps=steps))
        out = Path(out_dir).expanduser()
        # the result stays as analysed: the figure's timing goes to the file only
        summary = dict(self.summary)
        paths = {}
        from crosssection.commands import clear_temporary
        from crosssection.core.fileio import renamed_together, save_figure

        created = not out.exists()
        try:
            out.mkdir(parents=True, exist_ok=True)
            clear_temporary(out, "analyze")
            with renamed_together():  # never one run's figure beside another's tables
                if figure:
                    from crosssection.figures import overlay_figure

                    t0 = time.perf_counter()
                    fig = overlay_figure(self.rgb, self, thickness_px=self.thickness_px)
                    made_from = {"image": summary.get("image"),
                                 "parameters": summary.get("parameters")}
                    paths["overlay"] = save_figure(
                        fig, out / "overlay.png",
                        description=json.dumps(made_from, default=str, sort_keys=True))
                    summary["output_timings_s"] = {**summary.get("output_timings_s", {}),
                                                   "overlay_figure": time.perf_counter() - t0}
                if steps:  # steps.png is a figure too, as under ``foldstat steps --no-figure``
                    paths.update(self.write_steps(out, figure=figure))
                paths.update(schema.write_tables(out, summary, self.tables))
        except OutputError:
            _remove_if_empty(out, created)
            raise
        except OSError as exc:
            _remove_if_empty(out, created)
            raise output_error(exc, out) from None
        return paths

    def write_steps(self, out_dir, *, figure: bool = True) -> dict:
        """Save the processing steps of paper Fig. 2 as PNG images.

        Writes ``step1_raw.png`` (the scan), ``step2_threshold.png``, ``step3_clean.png``
        (ink black on white), ``step4_skeleton.png`` (skeleton black, junctions as red
        circles), all at the scan's resolution, and ``steps.png`` (the four side by side,
        ``figures.steps_figure``) when ``figure``.
        """
        made_from = {"image": self.summary.get("image"),
                     "parameters": self.summary.get("parameters")}
        return write_step_images(out_dir, self.rgb, self.mask_threshold, self.mask_clean,
                                 self.skeleton, self.graph_junction_centers(), figure=figure,
                                 titles=self._step_titles(),
                                 px_per_mm=getattr(self.params, "px_per_mm", None),
                                 hole=self.hole,
                                 description=json.dumps(made_from, default=str,
                                                        sort_keys=True))

    def _step_titles(self) -> list:
        """The steps figure's panel titles, the threshold's with the rule and cuts used."""
        from crosssection.figures import step_titles

        return step_titles(self.summary.get("thresholds"))

    def graph_junction_centers(self) -> np.ndarray:
        if self.junction_clusters is not None:
            return np.asarray(self.junction_clusters.centers_rc, float).reshape(-1, 2)
        return np.zeros((0, 2))


def _remove_if_empty(folder: Path, created: bool) -> None:
    """Remove a folder this write created when it failed before leaving anything in it (a
    full disk): no empty result folder is left to look like a run."""
    if created:
        try:
            folder.rmdir()
        except OSError:
            pass  # not empty, or gone: left as it is


def write_step_images(out_dir, rgb, mask_threshold, mask_clean, skeleton, junction_centers_rc,
                      *, figure: bool = True, titles=None, description: str | None = None,
                      px_per_mm: float | None = None, hole=None) -> dict:
    """Write the four step images of paper Fig. 2 (see ``AnalysisResult.write_steps``);
    ``titles``: the four panel titles of ``steps.png`` (``figures.steps_figure``), whose raw
    panel has a scale bar when ``px_per_mm`` is given and whose panels show ``hole`` (a
    margin around it) when it is given; the four step images are the whole scan. Each PNG's
    text records the package version (``Software``) and ``description`` (what the images
    were made from) when given, as the figures do."""
    import cv2

    from crosssection._version import __version__
    from crosssection.core.fileio import atomic_path, png_with_chunks

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    text = {"Software": f"foldstat {__version__}"}
    if description is not None:
        text["Description"] = description
    # tEXt: Latin-1 keys and values (others escaped)
    chunks = [(b"tEXt", k.encode("latin-1") + b"\0"
               + str(v).encode("latin-1", "backslashreplace")) for k, v in text.items()]

    def save(name, img):
        p = out / name
        ok, buf = cv2.imencode(".png", img)
        if not ok:
            raise ImageError("cannot write image", p)
        data = buf.tobytes()
        with atomic_path(p) as tmp:
            tmp.write_bytes(png_with_chunks(data, chunks))
        paths[name[:-4]] = p

    raw = np.asarray(rgb)
    save("step1_raw.png", np.ascontiguousarray(raw[..., ::-1]))
    save("step2_threshold.png", np.where(mask_threshold, 0, 255).astype(np.uint8))
    save("step3_clean.png", np.where(mask_clean, 0, 255).astype(np.uint8))
    sk = np.full(skeleton.shape + (3,), 255, np.uint8)
    sk[np.asarray(skeleton, bool)] = 0
    rad = max(3, int(round(max(skeleton.shape) / 300)))
    for r, c in np.asarray(junction_centers_rc, float).reshape(-1, 2):
        cv2.circle(sk, (int(round(c)), int(round(r))), rad, (0, 0, 255), 1, cv2.LINE_AA)
    save("step4_skeleton.png", sk)
    if figure:
        from crosssection.figures import steps_figure
        from crosssection.core.fileio import save_figure

        fig = steps_figure(raw, mask_threshold, mask_clean, skeleton, junction_centers_rc,
                           titles=titles, px_per_mm=px_per_mm, hole=hole)
        paths["steps"] = save_figure(fig, out / "steps.png", description=description)
    return paths
