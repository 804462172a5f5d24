"""The width law of a stack: width as a function of its number of layers, and its inverse.

Paper, section "Image analysis procedure": the thickness of a stack gives its number of
branches through a calibration, because the heating by the hot-wire cut thickens a stack
*nonlinearly*. The calibration is the user's measurement (CSV ``n_layers,width_mm``), used as
given; the scan generators draw their bands with a law of the same kind
(:meth:`Calibration.nonlinear`) and write it next to the scan.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from numba import njit

from crosssection.core.errors import ConfigError, why_unreadable
from crosssection.core.fileio import write_csv

__all__ = ["Calibration"]

#: The largest calibration file read: a table of layer counts and widths is a few hundred
#: bytes; a file of megabytes is another file (a scan, a log) given by mistake.
CALIBRATION_MAX_BYTES = 1 << 20

#: Decimals of ``width_mm`` written to a calibration table (1 nm, far below any scan's pixel).
WIDTH_DECIMALS = 6


@njit(cache=True)
def _bisect_pchip(bp, c, yc, a, b):  # pragma: no cover - numba
    """Where a monotone cubic interpolant (breakpoints ``bp``, coefficients ``c`` of a 1-D
    ``scipy.interpolate.PchipInterpolator``) reaches ``yc``, by 60 halvings of the brackets
    [``a``, ``b``]: the midpoint of the last bracket.

    The interpolant is evaluated as scipy evaluates it, bit for bit: the interval
    ``bp[i] <= x < bp[i + 1]`` (the last one closed on the right), and the sum
    ``c3 + c2 s + c1 s^2 + c0 s^3`` term by term with the powers by repeated products.
    Through the interpolant's own calls (60 of them, whose checks and reshapes cost more
    than the sums) the bisection took 0.7-1.1 ms for the 245-512 widths of a dense
    2000 x 2000 scan, nine times an analysis: 7.5 ms, against 2.2 ms here.
    """
    out = np.empty(yc.size)
    for j in range(yc.size):
        lo = a[j]
        hi = b[j]
        y = yc[j]
        for _ in range(60):
            m = 0.5 * (lo + hi)
            # the interval by bisection on the breakpoints (m lies between the first and
            # the last: it ends on the last interval at the last breakpoint)
            i = 0
            k = bp.size - 1
            while k - i > 1:
                mid = (i + k) // 2
                if m >= bp[mid]:
                    i = mid
                else:
                    k = mid
            s = m - bp[i]
            z = s * s
            if ((c[3, i] + c[2, i] * s) + c[1, i] * z) + c[0, i] * (z * s) < y:
                lo = m
            else:
                hi = m
        out[j] = 0.5 * (lo + hi)
    return out


@dataclass(frozen=True)
class Calibration:
    """Width of a stack as a function of its number of layers, and its inverse.

    Between table rows the width is interpolated by a monotone cubic (PCHIP, no overshoot) and
    equals the table at a tabulated ``n``; beyond the table it is extended linearly with the
    slope of the end segment (below the first row, through the first segment). ``layers`` is
    the exact numerical inverse of ``width`` (bisection on the monotone interpolant), so
    ``layers(width(n)) == n`` for every ``n``, tabulated or not.

    Attributes
    ----------
    n_layers, width_mm : tuple of float
        The table, strictly increasing in both columns; ``n_layers`` whole numbers.
    source : str or None
        File the table was read from (named in errors).
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
        # a stack holds whole layers, so a calibration measures whole counts: a fraction is a
        # typing error or a shifted column (widths under n_layers)
        frac = np.flatnonzero(n != np.round(n))
        if len(frac):
            i = int(frac[0])
            raise ConfigError(f"calibration n_layers = {n[i]:g} (row {i + 1} of the table, below "
                              "its header) is not a whole number of layers", where)
        if np.any(np.diff(n) <= 0) or np.any(np.diff(w) <= 0):
            raise ConfigError("calibration must be strictly increasing in n_layers and width_mm",
                              where)
        if len(n) == 1:  # a single row: proportional through the origin
            n = np.array([0.0, n[0]])
            w = np.array([0.0, w[0]])
        interp = None
        if len(n) >= 3:
            # imported here: scipy.interpolate costs 0.17 s of start-up to every analysis
            # run without a calibration
            from scipy.interpolate import PchipInterpolator

            interp = PchipInterpolator(n, w, extrapolate=False)
        object.__setattr__(self, "_interp", (n, w, interp))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_frame(cls, table: pd.DataFrame, *, source=None) -> "Calibration":
        """A calibration from a table with columns ``n_layers`` and ``width_mm``.

        Parameters
        ----------
        table : DataFrame
            Column names are matched without case or surrounding blanks; extra columns are
            ignored.
        source : str or Path, optional
            Where the table comes from (named in errors).

        Raises
        ------
        ConfigError
            Missing columns, non-numeric, non-positive or non-increasing values, or a
            fractional ``n_layers``.
        """
        cols = {str(c).strip().lower(): c for c in table.columns}
        missing = [c for c in ("n_layers", "width_mm") if c not in cols]
        if missing:
            raise ConfigError(f"calibration lacks column(s) {', '.join(missing)} "
                              "(expected n_layers,width_mm)", source)
        n = pd.to_numeric(table[cols["n_layers"]], errors="coerce").to_numpy(float)
        w = pd.to_numeric(table[cols["width_mm"]], errors="coerce").to_numpy(float)
        return cls(tuple(n), tuple(w), source=None if source is None else str(source))

    @classmethod
    def from_csv(cls, path) -> "Calibration":
        """Read a ``n_layers,width_mm`` CSV (header required, extra columns ignored).

        Raises
        ------
        ConfigError
            Missing file, missing columns, non-numeric, non-positive or non-increasing values,
            or a fractional ``n_layers`` (its row named); the message names the file.
        """
        from crosssection.core.fileio import special_file_reason

        path = Path(path)
        special = special_file_reason(path)
        if special:
            raise ConfigError(special, path)
        try:
            size = path.stat().st_size
        except OSError:
            size = 0  # read_csv names what is wrong with the path
        if size > CALIBRATION_MAX_BYTES:
            raise ConfigError(f"{size} bytes, more than a calibration table of layer counts "
                              "and widths holds: is it the right file?", path)
        try:
            table = pd.read_csv(path, comment="#", skipinitialspace=True)
        except FileNotFoundError:
            raise ConfigError("calibration file not found", path) from None
        except Exception as exc:  # noqa: BLE001 - parser errors, empty or binary files, folders
            raise ConfigError(f"{why_unreadable(exc)}: a calibration CSV holds a header "
                              "n_layers,width_mm and one row per layer count", path) from None
        return cls.from_frame(table, source=path)

    @classmethod
    def of(cls, value) -> "Calibration":
        """The calibration a parameter value stands for.

        Parameters
        ----------
        value : str, Path, Calibration, DataFrame, sequence of pairs or mapping
            A CSV path; a Calibration; a table with columns ``n_layers`` and ``width_mm`` (a
            DataFrame, or an object with ``to_frame()``); ``[[n_layers, width_mm], ...]``
            pairs (a list or an (N, 2) array: the form ``summary.json`` records a table
            given in memory in); or ``{"n_layers": [...], "width_mm": [...]}``.

        Raises
        ------
        ConfigError
            A value of none of these forms, or a table :meth:`from_frame` refuses.
        """
        if isinstance(value, cls):
            return value
        if isinstance(value, (str, Path)):
            return cls.from_csv(value)
        if not isinstance(value, pd.DataFrame) and hasattr(value, "to_frame"):
            value = value.to_frame()
        if isinstance(value, pd.DataFrame):
            return cls.from_frame(value)
        if isinstance(value, dict):
            try:
                return cls.from_frame(pd.DataFrame(value))
            except ValueError:  # columns of different lengths, scalars
                raise ConfigError("calibration n_layers and width_mm must be lists of the "
                                  "same length") from None
        if isinstance(value, (list, tuple, np.ndarray)):
            try:
                pairs = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                pairs = None
            if pairs is None or pairs.ndim != 2 or pairs.shape[1] != 2:
                raise ConfigError("calibration pairs must be [[n_layers, width_mm], ...] "
                                  "numbers")
            return cls(tuple(pairs[:, 0]), tuple(pairs[:, 1]))
        raise ConfigError(f"calibration must be a CSV path, a Calibration, a table with columns "
                          f"n_layers and width_mm or [[n_layers, width_mm], ...] pairs, got "
                          f"{type(value).__name__}")

    @classmethod
    def linear(cls, thickness_mm: float, n_max: int = 50) -> "Calibration":
        """The law ``width = n h`` for ``n = 1..n_max`` (no thickening by the cut)."""
        n = cls._layer_grid(thickness_mm, n_max)
        return cls(tuple(n), tuple(n * float(thickness_mm)))

    @classmethod
    def nonlinear(cls, thickness_mm: float, n_max: int = 40) -> "Calibration":
        """The generators' law ``w(n) = h (n + 0.4 sqrt(n))`` for ``n = 1..n_max``.

        The hot-wire cut thickens each stack by a melted rim that grows sub-linearly with the
        stack (paper: "the heating by the cutting tool thickens a stack nonlinearly"); the term
        is large enough that assuming ``w = n h`` miscounts thick stacks (12 layers read as
        13.4).
        """
        n = cls._layer_grid(thickness_mm, n_max)
        return cls(tuple(n), tuple(float(thickness_mm) * (n + 0.4 * np.sqrt(n))))

    @staticmethod
    def _layer_grid(thickness_mm: float, n_max: int) -> np.ndarray:
        if not thickness_mm > 0:
            raise ConfigError(f"thickness_mm must be positive, got {thickness_mm}")
        if int(n_max) < 1:
            raise ConfigError(f"n_max must be at least 1, got {n_max}")
        return np.arange(1, int(n_max) + 1, dtype=float)

    # ------------------------------------------------------------------ evaluation
    def width(self, n) -> np.ndarray:
        """Width (mm) of a stack of ``n`` layers (float or array; continuous ``n`` allowed)."""
        tn, tw, interp = self._interp
        x = np.asarray(n, dtype=float)
        lo_slope = (tw[1] - tw[0]) / (tn[1] - tn[0])
        hi_slope = (tw[-1] - tw[-2]) / (tn[-1] - tn[-2])
        xc = np.clip(x, tn[0], tn[-1])
        if interp is not None:
            inside = np.asarray(interp(xc), dtype=float)
            # the measured row itself, not the interpolant's rounding of it
            row = np.clip(np.searchsorted(tn, xc), 0, len(tn) - 1)
            inside = np.where(tn[row] == xc, tw[row], inside)
        else:
            inside = np.interp(xc, tn, tw)
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
            inside = _bisect_pchip(interp.x, np.ascontiguousarray(interp.c), yc.ravel(),
                                   a.ravel(), b.ravel()).reshape(yc.shape)
        out = np.where(y < tw[0], tn[0] + (y - tw[0]) / lo_slope,
                       np.where(y > tw[-1], tn[-1] + (y - tw[-1]) / hi_slope, inside))
        out = np.where(np.isfinite(y), out, np.nan)
        return out if out.ndim else float(out)

    # ------------------------------------------------------------------ output
    def to_frame(self, n_max: int | None = None) -> pd.DataFrame:
        """The table ``n_layers, width_mm`` (what ``calibration.csv`` holds).

        Parameters
        ----------
        n_max : int, optional
            Tabulate the law at ``n = 1..n_max``; by default the table's own rows.

        Returns
        -------
        DataFrame
            ``width_mm`` rounded to :data:`WIDTH_DECIMALS`.
        """
        if n_max is None:
            n = np.asarray(self.n_layers, dtype=float).astype(int)
            w = np.asarray(self.width_mm, dtype=float)
        else:
            n = np.arange(1, int(n_max) + 1)
            w = self.width(n)
        return pd.DataFrame({"n_layers": n, "width_mm": np.round(w, WIDTH_DECIMALS)})

    def to_csv(self, path, n_max: int | None = None) -> Path:
        """Write :meth:`to_frame` as ``path`` (atomically); returns the path."""
        return write_csv(path, self.to_frame(n_max))
