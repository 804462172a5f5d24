"""Stage 8: stack widths from the distance transform, and the width -> layers calibration.

Paper, section "Image analysis procedure": the thickness of a stack gives its number of
branches through a calibration, because the hot-wire cut thickens stacks *nonlinearly*; the
calibration is the user's measurement (CSV ``n_layers,width_mm``) and is used as given.

Width along the skeleton
------------------------
For a band of ``w`` foreground pixels, the Euclidean distance transform (distance to the
nearest *background pixel centre*) along the cross-section is a tent peaking at
``D = w/2 + 1/2`` at the band's true centre line, which may lie between pixels.  Reading the
EDT only at the skeleton pixel gives ``2 d`` = ``w + 1`` (odd w) or ``w`` (even w), a +-0.5 px
ambiguity.  We instead sample the EDT (bilinear) one pixel on each side of the skeleton along
the local normal: for a tent, ``(d(-1) + d(+1)) / 2 + 1 = D`` exactly wherever the peak lies
within half a pixel, so ``width = d(-1) + d(+1) + 1``.  The residual bias, measured on bands
of known width 5..60 px at several angles (tests/test_widths.py), is below 0.3 px.
The per-stack value is the median along the path, skipping the parts within
``max(junction_margin_px, width)`` of a junction or a free end, where the mask widens (or
narrows); short stacks fall back to their central half.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

from .errors import ConfigError

__all__ = ["stack_widths", "stack_widths_px", "path_width_profile_px", "Calibration"]


def _unit_normals(path: np.ndarray, half_window: int = 3) -> np.ndarray:
    """Unit normals (row, col) of a pixel path from central differences over a window."""
    p = path.astype(float)
    n = len(p)
    if n < 2:
        return np.tile([1.0, 0.0], (n, 1))
    idx = np.arange(n)
    lo = np.clip(idx - half_window, 0, n - 1)
    hi = np.clip(idx + half_window, 0, n - 1)
    t = p[hi] - p[lo]
    norm = np.hypot(t[:, 0], t[:, 1])
    norm[norm == 0] = 1.0
    t /= norm[:, None]
    return np.column_stack([-t[:, 1], t[:, 0]])


def path_width_profile_px(path_rc: np.ndarray, distance_px: np.ndarray, *,
                          step_px: float = 0.25, normal_half_window: int | None = None
                          ) -> np.ndarray:
    """Local width (px) at every pixel of a skeleton path.

    Parameters
    ----------
    path_rc : (P, 2) int array
        Skeleton pixel path (row, col).
    distance_px : 2-D float array
        Euclidean distance transform of the foreground mask
        (``scipy.ndimage.distance_transform_edt(mask)``); the mask is ``distance_px > 0``
        and the EDT bounds how far to look.
    step_px : float
        Sampling step along the normal.
    normal_half_window : int, optional
        Half window (path pixels) of the central difference giving the local direction;
        default ``clip(median EDT, 3, 15)`` (a wider band needs a better direction, the
        width error being ``w (1/cos(angle error) - 1)``).

    Returns
    -------
    (P,) float array
        Distance between the two 0.5-crossings of the bilinearly interpolated mask along the
        local normal, on the run of foreground containing the skeleton pixel (the
        sub-pixel iso-contour of the binary image, as ``skimage.measure.find_contours`` at
        level 0.5 would place it).
    """
    path = np.asarray(path_rc).reshape(-1, 2).astype(int)
    if len(path) == 0:
        return np.zeros(0)
    dist = np.asarray(distance_px, dtype=float)
    d_centre = dist[path[:, 0], path[:, 1]]
    if normal_half_window is None:
        normal_half_window = int(np.clip(np.median(d_centre), 3, 15))
    nrm = _unit_normals(path, normal_half_window)
    reach = float(np.max(d_centre)) + 2.0
    t = np.arange(-np.ceil(reach / step_px), np.ceil(reach / step_px) + 1) * step_px
    c0 = len(t) // 2
    pts = path[:, None, :].astype(float) + t[None, :, None] * nrm[:, None, :]
    mask = (dist > 0).astype(float)
    vals = ndimage.map_coordinates(mask, pts.reshape(-1, 2).T, order=1, mode="constant",
                                   cval=0.0).reshape(len(path), len(t))
    vals[np.abs(t)[None, :] > (d_centre[:, None] + 2.0)] = 0.0  # stay near this band
    inside = vals >= 0.5
    inside[:, c0] = True
    rows = np.arange(len(path))
    # right crossing: first outside sample after the centre
    right_out = ~inside[:, c0:]
    jr = np.where(right_out.any(axis=1), np.argmax(right_out, axis=1), right_out.shape[1] - 1)
    jr = c0 + np.maximum(jr, 1)
    left_out = ~inside[:, : c0 + 1][:, ::-1]
    jl = np.where(left_out.any(axis=1), np.argmax(left_out, axis=1), left_out.shape[1] - 1)
    jl = c0 - np.maximum(jl, 1)

    def crossing(j_in, j_out):
        a, b = vals[rows, j_in], vals[rows, j_out]
        frac = np.where(a - b > 1e-12, (a - 0.5) / np.maximum(a - b, 1e-12), 0.0)
        return t[j_in] + frac * (t[j_out] - t[j_in])

    return crossing(jr - 1, jr) - crossing(jl + 1, jl)


def _arc_length(path: np.ndarray) -> np.ndarray:
    step = np.hypot(*np.diff(path.astype(float), axis=0).T) if len(path) > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(step)])


def stack_widths_px(graph, distance_px: np.ndarray, *, junction_margin_px: float,
                    margin_width_factor: float = 1.0) -> np.ndarray:
    """Width in pixels of every stack (median of the local width away from its ends).

    Parameters
    ----------
    graph : StackGraph
        Stage-6 graph (``paths``, ``ends``, ``node_kind``).
    distance_px : 2-D float array
        Euclidean distance transform of the cleaned mask.
    junction_margin_px : float
        Path pixels closer (in arc length) than ``max(junction_margin_px,
        margin_width_factor * w0)`` to an end at a junction or a free end are skipped, ``w0``
        being a first width estimate from the central half of the stack.  Loop nodes
        (closed loops without a junction) get no margin.
    margin_width_factor : float
        See above: a thick stack's junction blob extends about one width.

    Returns
    -------
    (M,) float array
        Width in px; NaN for an empty path.
    """
    dist = np.asarray(distance_px, dtype=float)
    out = np.full(len(graph.paths), np.nan)
    for sid, path in enumerate(graph.paths):
        path = np.asarray(path).reshape(-1, 2)
        if len(path) == 0:
            continue
        prof = path_width_profile_px(path, dist)
        s = _arc_length(path)
        total = s[-1]
        central = (s >= 0.25 * total) & (s <= 0.75 * total)
        if not central.any():
            central = np.ones(len(path), bool)
        w0 = float(np.median(prof[central]))
        u, v = graph.ends[sid]
        margin = max(float(junction_margin_px), margin_width_factor * w0)
        keep = np.ones(len(path), bool)
        if graph.node_kind.get(u, "junction") != "loop":
            keep &= s >= margin
        if graph.node_kind.get(v, "junction") != "loop":
            keep &= s <= total - margin
        out[sid] = float(np.median(prof[keep])) if keep.sum() >= 3 else w0
    return out


def stack_widths(graph, distance_px: np.ndarray, *, px_per_mm: float,
                 junction_margin_px: float, margin_width_factor: float = 1.0) -> np.ndarray:
    """Width in mm of every stack; see :func:`stack_widths_px`.

    Parameters
    ----------
    graph : StackGraph
    distance_px : 2-D float array
        Euclidean distance transform of the cleaned mask.
    px_per_mm : float
        Scan resolution (50 in the paper).
    junction_margin_px : float
        Minimal arc length skipped at junction / free ends.
    margin_width_factor : float
        The skipped length is at least this many first-estimate widths.

    Returns
    -------
    (M,) float array
        ``width_mm`` per stack (NaN for an empty path).
    """
    if not px_per_mm > 0:
        raise ValueError("px_per_mm must be positive")
    return stack_widths_px(graph, distance_px, junction_margin_px=junction_margin_px,
                           margin_width_factor=margin_width_factor) / float(px_per_mm)


@dataclass(frozen=True)
class Calibration:
    """Width of a stack as a function of its number of layers, and its inverse.

    The table is the user's measurement of cut stacks of ``n`` sheets (paper: the hot-wire cut
    thickens stacks nonlinearly).  Between table rows the width is interpolated by a monotone
    cubic (PCHIP, no overshoot); beyond the table it is extended linearly with the slope of
    the end segment (below the first row, through the first segment).  ``layers`` is the exact
    numerical inverse of ``width`` (bisection on the monotone interpolant), so
    ``layers(width(n)) == n`` for every ``n``, tabulated or not.

    Attributes
    ----------
    n_layers, width_mm : tuple of float
        The table, strictly increasing in both columns.
    source : str or None
        File the table was read from.
    """

    n_layers: tuple
    width_mm: tuple
    source: str | None = None
    _interp: object = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        n = np.asarray(self.n_layers, dtype=float)
        w = np.asarray(self.width_mm, dtype=float)
        where = self.source
        if n.ndim != 1 or n.shape != w.shape or len(n) == 0:
            raise ConfigError("calibration needs at least one row of n_layers,width_mm", where)
        if not (np.all(np.isfinite(n)) and np.all(np.isfinite(w))):
            raise ConfigError("calibration contains non-numeric or missing values", where)
        if np.any(n <= 0) or np.any(w <= 0):
            raise ConfigError("calibration n_layers and width_mm must be positive", where)
        if np.any(np.diff(n) <= 0) or np.any(np.diff(w) <= 0):
            raise ConfigError("calibration must be strictly increasing in n_layers and width_mm",
                              where)
        if len(n) == 1:  # a single row: proportional through the origin
            n = np.array([0.0, n[0]])
            w = np.array([0.0, w[0]])
        interp = None
        if len(n) >= 3:
            from scipy.interpolate import PchipInterpolator
            interp = PchipInterpolator(n, w, extrapolate=False)
        object.__setattr__(self, "_interp", (n, w, interp))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_csv(cls, path) -> "Calibration":
        """Read a ``n_layers,width_mm`` CSV (header required, extra columns ignored).

        Raises
        ------
        ConfigError
            Missing file, missing columns, non-numeric, non-positive or non-increasing values;
            the message names the file.
        """
        import pandas as pd

        path = Path(path)
        try:
            df = pd.read_csv(path, comment="#", skipinitialspace=True)
        except FileNotFoundError:
            raise ConfigError("calibration file not found", path) from None
        except Exception as exc:  # parser errors, empty file, binary junk
            raise ConfigError(f"cannot read calibration CSV ({type(exc).__name__})", path) from None
        df.columns = [str(c).strip().lower() for c in df.columns]
        missing = [c for c in ("n_layers", "width_mm") if c not in df.columns]
        if missing:
            raise ConfigError(f"calibration lacks column(s) {', '.join(missing)} "
                              "(expected n_layers,width_mm)", path)
        n = pd.to_numeric(df["n_layers"], errors="coerce").to_numpy(float)
        w = pd.to_numeric(df["width_mm"], errors="coerce").to_numpy(float)
        return cls(tuple(n), tuple(w), source=str(path))

    @classmethod
    def linear(cls, thickness_mm: float, n_max: int = 50) -> "Calibration":
        """The default calibration ``width = n h`` for ``n = 1..n_max``."""
        if not thickness_mm > 0:
            raise ConfigError(f"thickness_mm must be positive, got {thickness_mm}")
        n = np.arange(1, int(n_max) + 1, dtype=float)
        return cls(tuple(n), tuple(n * float(thickness_mm)))

    # ------------------------------------------------------------------ evaluation
    def width(self, n) -> np.ndarray:
        """Width (mm) of a stack of ``n`` layers (float or array; continuous ``n`` allowed)."""
        tn, tw, interp = self._interp
        x = np.asarray(n, dtype=float)
        lo_slope = (tw[1] - tw[0]) / (tn[1] - tn[0])
        hi_slope = (tw[-1] - tw[-2]) / (tn[-1] - tn[-2])
        if interp is not None:
            inside = np.asarray(interp(np.clip(x, tn[0], tn[-1])), dtype=float)
        else:
            inside = np.interp(x, tn, tw)
        out = np.where(x < tn[0], tw[0] + (x - tn[0]) * lo_slope,
                       np.where(x > tn[-1], tw[-1] + (x - tn[-1]) * hi_slope, inside))
        return out if out.ndim else float(out)

    def layers(self, width_mm) -> np.ndarray:
        """Continuous number of layers of a stack of width ``width_mm`` (inverse of width).

        NaN widths give NaN.
        """
        tn, tw, interp = self._interp
        y = np.asarray(width_mm, dtype=float)
        lo_slope = (tw[1] - tw[0]) / (tn[1] - tn[0])
        hi_slope = (tw[-1] - tw[-2]) / (tn[-1] - tn[-2])
        if interp is None:
            inside = np.interp(y, tw, tn)
        else:
            # bisection on the monotone interpolant, bracketed by the table rows
            yc = np.clip(y, tw[0], tw[-1])
            k = np.clip(np.searchsorted(tw, yc, side="right") - 1, 0, len(tw) - 2)
            a, b = tn[k].copy(), tn[k + 1].copy()
            a = np.where(np.isfinite(a), a, tn[0])
            for _ in range(60):
                m = 0.5 * (a + b)
                below = interp(m) < yc
                a = np.where(below, m, a)
                b = np.where(below, b, m)
            inside = 0.5 * (a + b)
        out = np.where(y < tw[0], tn[0] + (y - tw[0]) / lo_slope,
                       np.where(y > tw[-1], tn[-1] + (y - tw[-1]) / hi_slope, inside))
        out = np.where(np.isfinite(y), out, np.nan)
        return out if out.ndim else float(out)
