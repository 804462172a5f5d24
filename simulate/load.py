"""Simulation ensembles from Python: read a ``quench`` / ``anneal`` output folder and draw its
configurations.

>>> from simulate.load import load_ensemble
>>> ens = load_ensemble("sim/")                      # doctest: +SKIP
>>> ens.configs[["rg", "epsilon", "energy_total"]].describe()  # doctest: +SKIP
>>> ens.plot(0)                                       # doctest: +SKIP

Lengths are in units of the rod length L. The ensemble statistics of the same folder (the
fits and the paper's tables) are those of ``crosssection.stats.load_any(folder)`` and
``crosssection.stats.plot_pdf``.
"""
from __future__ import annotations

import json
import math
import numbers
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core.errors import ConfigError, ParameterError, why_unreadable
from simulate.energy import LAMBDA
from simulate.geometry import checked_rod, is_point

__all__ = ["SimulationEnsemble", "load_ensemble", "plot_configuration", "ConfigurationNotFound"]

TABLES = ("configs", "branches", "stacks", "voids")


class ConfigurationNotFound(ParameterError, KeyError):
    """No configuration of that id or key in the folder's ``rods.npz``.

    A :class:`~crosssection.core.errors.ParameterError` that is also a :class:`KeyError`:
    the lookup of a missing key raised ``KeyError`` before, and callers catching it keep
    working.
    """

    # KeyError's own __str__ shows the message quoted (the repr of a missing key); the
    # package's errors are one plain line
    __str__ = ParameterError.__str__


@dataclass
class SimulationEnsemble:
    """The tables, parameters and rods of one simulation folder (:func:`load_ensemble`).

    Attributes
    ----------
    folder : Path
    configs, branches, stacks, voids : DataFrame
        The folder's CSV tables (columns in :mod:`simulate.ensemble`); ``stacks`` is empty
        for folders written without it.
    params : dict
        ``params.json``: the command, lambda (``lam``), noise, segments, seed, ...
    keys : list of str
        Keys of ``rods.npz`` (``config_00000``, ...), one per configuration.
    """

    folder: Path
    configs: pd.DataFrame
    branches: pd.DataFrame
    stacks: pd.DataFrame
    voids: pd.DataFrame
    params: dict = field(default_factory=dict)
    keys: list = field(default_factory=list)

    def __repr__(self) -> str:
        failed = 0
        if "error" in self.configs.columns:
            err = self.configs["error"]
            failed = int((err.notna() & (err.astype(str).str.strip() != "")).sum())
        n = len(self.configs) - failed
        return (f"SimulationEnsemble({self.folder}: {n} configurations"
                + (f" ({failed} failed: their rows of configs hold the error)" if failed else "")
                + ", "
                f"{len(self.branches)} branches, {len(self.voids)} voids, "
                f"lambda = {self.params.get('lam', 'n/a')})")

    def _key(self, config) -> str:
        """The ``rods.npz`` key of ``config`` (checked: a stored configuration)."""
        if isinstance(config, str):
            key = config
        elif (isinstance(config, numbers.Real) and not isinstance(config, bool)
              and math.isfinite(config) and config == int(config)):
            # a whole float (a config_id read from a table with gaps) names its configuration;
            # 1.7 names none, and int() would silently pick configuration 1
            key = f"config_{int(config):05d}"
        else:
            raise ParameterError(f"config must be a whole number (config_id) or a rods.npz "
                                 f"key, got {config!r}")
        rods = self.folder / "rods.npz"
        if not self.keys and not rods.is_file():
            raise ConfigError("missing: the folder holds no rods (tables only)", rods)
        if key not in self.keys:
            raise ConfigurationNotFound(f"no configuration {config!r} in {rods} "
                                        f"({len(self.keys)} configurations)")
        return key

    def rod(self, config) -> np.ndarray:
        """Node positions of one configuration.

        Parameters
        ----------
        config : int or str
            ``config_id`` or a ``rods.npz`` key.

        Returns
        -------
        (N+1, 2) float array
            Units of L.

        Raises
        ------
        ConfigurationNotFound
            No such configuration (a :class:`ParameterError` and a :class:`KeyError`).
        ParameterError
            ``config`` is neither a whole number nor a string.
        ConfigError
            The folder has no ``rods.npz``, or it can no longer be read.
        """
        key = self._key(config)
        path = self.folder / "rods.npz"
        try:
            with np.load(path, allow_pickle=False) as rods:
                return np.asarray(rods[key], float)
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            # the file was read when the ensemble was loaded: it changed since
            raise ConfigError(f"unreadable rods file ({why_unreadable(exc)})", path) from None

    def plot(self, config=0, *, ax=None, stacks: bool = True):
        """Draw one configuration (:func:`plot_configuration`).

        The wall of a compaction (or of a quench with a wall) is drawn where the simulator
        put it, centred on the origin, with the radius of the configuration's row of
        ``configs`` (else that of ``params.json``).

        Parameters
        ----------
        config : int or str
            ``config_id`` or a ``rods.npz`` key.
        ax : matplotlib axes, optional
        stacks : bool
            Colour the stacks by their number of branches (contact analysis with this
            ensemble's lambda and contact distance).

        Returns
        -------
        matplotlib.figure.Figure

        Raises
        ------
        ConfigurationNotFound, ParameterError, ConfigError
            As :meth:`rod`.
        """
        key = self._key(config)
        return plot_configuration(
            self.rod(config), ax=ax, stacks=stacks,
            lam=float(self.params.get("lam", LAMBDA)),
            contact_distance=self.params.get("contact_distance"),
            wall_radius=self._wall_radius(key), title=key)

    def _wall_radius(self, key: str) -> float | None:
        """The wall radius of configuration ``key``: its row of ``configs`` (a compaction
        records each configuration's wall), else ``params.json``'s; None without a wall."""
        wall = self.params.get("wall_radius")
        number = key.rsplit("_", 1)[-1]
        if ({"wall_radius", "config_id"} <= set(self.configs.columns) and number.isdigit()):
            row = self.configs.loc[self.configs["config_id"] == int(number), "wall_radius"]
            if len(row) and pd.notna(row.iloc[0]):
                wall = row.iloc[0]
        return float(wall) if wall else None


def load_ensemble(folder) -> SimulationEnsemble:
    """Read a simulation folder written by ``foldstat quench`` or ``foldstat anneal``.

    Parameters
    ----------
    folder : str or Path
        Holds ``configs.csv``, ``branches.csv``, ``voids.csv``, optionally ``stacks.csv``,
        ``params.json`` and ``rods.npz``.

    Returns
    -------
    SimulationEnsemble

    Raises
    ------
    ConfigError
        Not a simulation folder, or an unreadable file (named).
    ParameterError
        ``folder`` is not a path.
    """
    if not isinstance(folder, (str, os.PathLike)) or not str(folder).strip():
        raise ParameterError(f"folder must be a simulation folder's path, got {folder!r}")
    folder = Path(folder).expanduser()
    if not (folder / "configs.csv").is_file():
        raise ConfigError("not a simulation folder (no configs.csv)", folder)
    tables = {}
    for name in TABLES:
        path = folder / f"{name}.csv"
        if not path.is_file() and name == "stacks":
            tables[name] = pd.DataFrame()
            continue
        try:
            tables[name] = pd.read_csv(path)
        except FileNotFoundError:
            raise ConfigError("missing table", path) from None
        except pd.errors.EmptyDataError:
            tables[name] = pd.DataFrame()
        except (pd.errors.ParserError, UnicodeDecodeError) as exc:
            raise ConfigError(f"unreadable CSV ({why_unreadable(exc)})", path) from None
    params = {}
    if (folder / "params.json").is_file():
        try:
            params = json.loads((folder / "params.json").read_text())
        except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ConfigError(f"unreadable params.json ({why_unreadable(exc)})",
                              folder / "params.json") from None
    keys = []
    if (folder / "rods.npz").is_file():
        try:
            with np.load(folder / "rods.npz", allow_pickle=False) as rods:
                keys = sorted(rods.files)
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            raise ConfigError(f"unreadable rods file ({why_unreadable(exc)})",
                              folder / "rods.npz") from None
    return SimulationEnsemble(folder, **tables, params=params, keys=keys)


def plot_configuration(xy, *, ax=None, stacks: bool = True, lam: float = LAMBDA,
                       contact_distance: float | None = None, wall_radius: float | None = None,
                       wall_center=(0.0, 0.0), title: str | None = None):
    """Draw a rod configuration; optionally its stacks coloured by number of branches.

    The first node is drawn as a circle, the last as a square; a legend below the axes names
    them and the wall.

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions (units of L).
    ax : matplotlib axes, optional
        Draw into it; default a new 5.5 x 5.5 in figure (no pyplot) with constrained layout,
        which keeps the title and the labels inside it.
    stacks : bool
        Run :func:`simulate.contacts.analyze_rod` and draw every stack's mean line with a
        width and colour growing with its n_br.
    lam : float
        Lambda of the contact analysis (its energies; the stacks do not depend on it).
    contact_distance : float, optional
        Contact cut-off delta in units of L (default: the analysis's, 0.5/N).
    wall_radius : float, optional
        A hard wall drawn as a dashed circle of this radius about ``wall_center``.
    wall_center : (float, float)
        The wall's centre (units of L); the quench and the compaction centre their wall on
        the origin, and a rod's centre of mass need not lie there.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers with N >= 1 (N >= 2 with
        ``stacks``: the contact analysis needs two segments), or ``wall_center`` is not two
        finite numbers.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle
    from matplotlib.ticker import MaxNLocator
    from matplotlib.transforms import offset_copy

    xy = _checked_xy(xy, stacks=stacks)
    if not is_point(wall_center):
        raise ParameterError(f"wall_center must be two finite numbers (x, y), got "
                             f"{wall_center!r}")
    if ax is None:
        from matplotlib.figure import Figure

        # constrained layout keeps the title, the axis labels and the colour bar's label
        # inside the figure whatever their length
        fig = Figure(figsize=(5.5, 5.5), layout="constrained")
        ax = fig.add_subplot()
    ax.plot(xy[:, 0], xy[:, 1], "-", color="0.35", lw=0.7, zorder=1)
    ax.plot(*xy[0], "o", ms=4, color="black", zorder=3, label="first node")
    ax.plot(*xy[-1], "s", ms=4, color="black", zorder=3, label="last node")
    text = title or "configuration"
    if stacks:
        from matplotlib import colormaps

        from simulate.contacts import analyze_rod

        an = analyze_rod(xy, lam=lam, contact_distance=contact_distance)
        n_br = an.stacks["n_br"].to_numpy(int) if len(an.stacks) else np.zeros(0, int)
        if len(n_br):
            from matplotlib.cm import ScalarMappable
            from matplotlib.colors import BoundaryNorm

            top = max(int(n_br.max()), 2)
            # one colour per count, as the lines are drawn: a count is not a continuum
            cmap = colormaps["viridis"].resampled(top)
            norm = BoundaryNorm(np.arange(0.5, top + 1.0), top)
            lc = LineCollection([np.asarray(line, float) for line in an.stack_lines],
                                colors=cmap(norm(n_br)), linewidths=1.0 + 1.2 * n_br,
                                alpha=0.75, zorder=2)
            ax.add_collection(lc)
            # beside the axes and as tall as they are (the equal aspect leaves them shorter
            # than the figure, where a bar of the figure's height would stand apart)
            cax = ax.inset_axes([1.04, 0.0, 0.045, 1.0])
            bar = ax.figure.colorbar(ScalarMappable(norm, cmap), cax=cax,
                                     ticks=range(1, top + 1))
            bar.set_label("branches per stack $n_{br}$")
        # two lines: one would be wider than the axes of the default figure
        text += (f": {an.n_stacks} stacks, {an.n_branches} branches, "
                 f"{an.n_junctions} junctions\n(line width and colour: n_br)")
    if wall_radius:
        # above the stacks: a rod pressed against the wall would hide it
        ax.add_patch(Circle(tuple(np.asarray(wall_center, float)), wall_radius, fill=False,
                            ls="--", lw=0.9, color="0.25", zorder=2.5))
        ax.plot([], [], ls="--", lw=0.9, color="0.25",
                label=f"wall (radius {wall_radius:.4g} L)")
    ax.set_aspect("equal")
    # at most five labels per axis: labels such as -0.075 run into each other otherwise
    ax.xaxis.set_major_locator(MaxNLocator(5))
    ax.yaxis.set_major_locator(MaxNLocator(5))
    # below the axis label (about 36 points below the axes): inside the axes, it would hide
    # part of a rod that fills its wall
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=3, fontsize=8,
              frameon=False, handlelength=2.0,
              bbox_transform=offset_copy(ax.transAxes, fig=ax.figure, y=-36, units="points"))
    ax.set_xlabel("x / L")
    ax.set_ylabel("y / L")
    ax.set_title(text, fontsize=9)
    return ax.figure


def _checked_xy(xy, *, stacks: bool) -> np.ndarray:
    """``xy`` as an (N+1, 2) float array of finite numbers with N >= 1 (N >= 2 for the
    ``stacks`` analysis).

    Raises
    ------
    ParameterError
        Naming ``xy``, its shape and the cause.
    """
    arr = checked_rod(xy, min_segments=1)
    if stacks and len(arr) < 3:
        raise ParameterError("xy has N = 1 segment: the contact analysis of stacks=True needs "
                             "N >= 2 (stacks=False draws it)")
    return arr
