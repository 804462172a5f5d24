"""The result of one analysis, :class:`AnalysisResult`, and how it is written to disk."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core import schema
from crosssection.core.errors import ImageError

__all__ = ["AnalysisResult", "write_step_images"]


@dataclass(repr=False)
class AnalysisResult:
    """Everything ``analyze`` computed for one scan.

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
                f"L = {s['rod_length_mm']:.1f} mm"
                + (f", epsilon = {eps:.2f}" if eps is not None else ""))
        codes = [f.code for f in self.quality]
        return head + (f", warnings: {', '.join(codes)})" if codes else ")")

    @property
    def tables(self) -> dict:
        """``{"junctions", "stacks", "branches", "voids"}`` -> DataFrame."""
        return {"junctions": self.junctions, "stacks": self.stacks,
                "branches": self.branches, "voids": self.voids}

    @property
    def thickness_px(self) -> float:
        return self.params.thickness_px

    def write(self, out_dir, figure: bool = True, *, steps: bool = False) -> dict:
        """Write ``summary.json``, the four CSV tables and (optionally) ``overlay.png``.

        Parameters
        ----------
        out_dir : str or Path
            Created if needed. Files are written atomically; ``summary.json`` last.
        figure : bool
            Also write ``overlay.png`` (paper Figs. 1c and 9a).
        steps : bool
            Also write the step images of paper Fig. 2 (see :meth:`write_steps`).

        Returns
        -------
        dict
            Name -> written path.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {}
        if figure:
            from crosssection.figures import overlay_figure
            from crosssection.core.fileio import save_figure

            t0 = time.perf_counter()
            fig = overlay_figure(self.rgb, self, thickness_px=self.thickness_px)
            paths["overlay"] = save_figure(fig, out / "overlay.png")
            self.summary.setdefault("output_timings_s", {})["overlay_figure"] = \
                time.perf_counter() - t0
        if steps:
            paths.update(self.write_steps(out))
        paths.update(schema.write_tables(out, self.summary, self.tables))
        return paths

    def write_steps(self, out_dir, *, figure: bool = True) -> dict:
        """Save the processing steps of paper Fig. 2 as PNG images.

        Writes ``step1_raw.png`` (the scan), ``step2_threshold.png``, ``step3_clean.png``
        (ink black on white), ``step4_skeleton.png`` (skeleton black, junctions as red
        circles), all at the scan's resolution, and ``steps.png`` (the four side by side,
        ``figures.steps_figure``) when ``figure``.
        """
        return write_step_images(out_dir, self.rgb, self.mask_threshold, self.mask_clean,
                                 self.skeleton, self.graph_junction_centers(), figure=figure)

    def graph_junction_centers(self) -> np.ndarray:
        if self.junction_clusters is not None:
            return np.asarray(self.junction_clusters.centers_rc, float).reshape(-1, 2)
        return np.zeros((0, 2))


def write_step_images(out_dir, rgb, mask_threshold, mask_clean, skeleton, junction_centers_rc,
                      *, figure: bool = True) -> dict:
    """Write the four step images of paper Fig. 2 (see ``AnalysisResult.write_steps``)."""
    import cv2

    from crosssection.core.fileio import atomic_path

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}

    def save(name, img):
        p = out / name
        with atomic_path(p) as tmp:
            if not cv2.imwrite(str(tmp), img):
                raise ImageError("cannot write image", p)
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

        fig = steps_figure(raw, mask_threshold, mask_clean, skeleton, junction_centers_rc)
        paths["steps"] = save_figure(fig, out / "steps.png")
    return paths
