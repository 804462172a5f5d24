"""Ensembles of quenched (or annealed) rods: the ``quench`` and ``anneal`` subcommands.

``python -m simulate quench --n-configs K --lambda 7e5 --noise 750 --segments 300 --seed S
[--method powell|lbfgs] [--workers W] [--scheduler ADDR] --out DIR`` writes

* ``DIR/configs.csv`` -- one row per configuration: config_id, seed, rg, epsilon (= 1/(2 pi Rg),
  paper section "Simulations vs experiments"), epsilon_sqrt2 (= 1/(2 pi sqrt(2) Rg), the disk
  radius read as sqrt(2) Rg), energy_total, energy_bending, energy_confinement, n_stacks,
  n_branches, n_junctions, n_voids, method, wall_s, plus minimiser counters and
  n_hairpin_nodes (nodes turning by more than :data:`HAIRPIN_NODE_DEG`: folds within one
  node, warned of with :class:`HairpinNodeWarning`);
* ``DIR/branches.csv`` -- config_id, branch_id, length, kappa_plus, kappa_pm, energy_bending,
  energy_confinement, energy (from :func:`simulate.contacts.analyze_rod`; the curvatures are
  empty (NaN) on a branch shorter than one segment, which the discrete rod does not resolve);
* ``DIR/voids.csv`` -- config_id, area, perimeter, shape_ratio, n_edges;
* ``DIR/stacks.csv`` -- config_id, stack_id, n_br, length (for rho(n_br) and paper Eqs. (14)-(15));
* ``DIR/rods.npz`` -- node positions of every configuration, key ``config_XXXXX``;
* ``DIR/params.json`` -- all parameters, every default the run used written out
  (:func:`resolve_defaults`), and the package and library versions (``version``,
  ``libraries``) of the run that computed the configurations: a re-run that computes
  nothing leaves the file as it is; one that adds configurations under other versions keeps
  the first and lists, in ``versions``, those that computed the part files on disk (each
  part records its own), with a :class:`MixedVersionsWarning` (:func:`params_record`);
* ``DIR/failures.csv`` -- config_id, seed, error: one line per configuration whose computation
  raised (its row of configs.csv has the ``error`` and no results; the others go on). A
  re-run tries the failed configurations again. A Dask cluster that goes away stops the
  ensemble instead (one ``error:`` line): its configurations are not recorded and no table is
  written; the re-run computes them.

Configuration ``i`` always uses the seed ``spawn_seeds(seed, K)[i]``, so results do not depend
on the number of workers. Every finished configuration is written atomically to
``DIR/parts/config_XXXXX.npz`` and skipped when the command is run again (resume); the tables
are assembled from the parts at the end.

Measured, the paper's ensemble (``quench --n-configs 250 --lambda 7e5 --noise 750 --segments
300 --seed 1 --workers 2``, powell, tangent coordinates): its time on 2 cores is in README.md
("Speed") and docs/validation/README.md; <Rg> = 0.057, <eps> = 2.85
(1/(2 pi Rg)) or 2.02 (sqrt(2) Rg reading; paper 2.3), <N_br>/<N_l> = 21.2/14.0 = 1.5 (paper ~20/~10), <sqrt(s)/p> =
0.20 (paper 0.19), <E> = 4139 = 1837 bending + 2302 confinement (paper 4300); Gamma shapes:
total energy 31 (paper 61), branch energy 0.62 (0.31), branch length 1.26 (0.4).
"""
from __future__ import annotations

import argparse
import errno
import json
import math
import os
import re
import sys
import time
import warnings
from concurrent.futures import BrokenExecutor, as_completed
from contextlib import nullcontext
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection._version import __version__
from crosssection.core.errors import ConfigError, ParameterError, output_error
from crosssection.core.fileio import (BROWSER_FILES, check_out, folder_lock, foreign_entry,
                                      renamed_together, write_csv, write_json, write_npz)
from crosssection.core.parallel import (ClusterLostError, capped_workers, get_executor,
                                        spawn_seeds)
from crosssection.quality import QualityWarning

from simulate.contacts import MIN_CONTACT_DISTANCE, default_contact_distance
from simulate.energy import LAMBDA, LAMBDA_MAX
from simulate.geometry import sharp_nodes
from simulate.noise import (N_SEGMENTS, NOISE, NOISE_PER_SEGMENT_MAX,
                            VALIDATED_QUENCH_SEGMENTS)
from simulate.optimize import (FTOL, FTOL_MAX, LAM_START, MAXITER, MAXITER_MAX, N_RUNS,
                               N_RUNS_MAX,
                               NEMATIC_RUNS, NEMATIC_U, NEMATIC_U_MAX, RAMPS, STAGES,
                               STAGES_MAX, XTOL, XTOL_MAX, default_contact_cutoff)

CONFIG_COLUMNS = ["config_id", "seed", "rg", "epsilon", "epsilon_sqrt2", "energy_total",
                  "energy_bending", "energy_confinement", "n_stacks", "n_branches",
                  "n_junctions", "n_voids", "method", "wall_s"]
BRANCH_COLUMNS = ["config_id", "branch_id", "length", "kappa_plus", "kappa_pm",
                  "energy_bending", "energy_confinement", "energy", "stack_id"]
STACK_COLUMNS = ["config_id", "stack_id", "n_br", "length"]
VOID_COLUMNS = ["config_id", "area", "perimeter", "shape_ratio", "n_edges"]

#: Minimisers of each command, the default first: annealing ramps Lambda through Powell runs
#: or L-BFGS quenches (:func:`simulate.optimize.anneal`), never scipy's Powell
METHODS = {"quench": ("powell", "lbfgs", "scipy-powell"), "anneal": ("powell", "lbfgs")}

#: The minimisers' own options and, per command, the methods that use them: given with another
#: method an option would be recorded and change nothing, so it is refused
#: (:func:`params_from_args`). L-BFGS-B has its own schedule; scipy's Powell protocol takes no
#: nematic cut-off (:func:`simulate.optimize.scipy_protocol`).
_POWELL = {"quench": ("powell", "scipy-powell"), "anneal": ("powell",)}
METHOD_OPTIONS = {"--runs": _POWELL, "--maxiter": _POWELL, "--nematic-runs": _POWELL,
                  "--u": _POWELL, "--ftol": _POWELL, "--xtol": _POWELL,
                  "--parametrization": _POWELL, "--nematic-cutoff": {"quench": ("powell",)}}
# the run parameters these options set (None in params.json where the method does not use them)
_POWELL_KEYS = ("n_runs", "maxiter", "nematic_runs", "u", "ftol", "xtol")

#: Powell search coordinates of each command without --parametrization: tangent angles for
#: quench (they reproduce the prototype's statistics), bend angles for anneal (the ramp winds
#: the rod into the spiral)
PARAMETRIZATION = {"quench": "tangent", "anneal": "bend"}

#: Nodes of start shapes drawn to check a --wall-radius before a run (:func:`wall_check`): the
#: whole of the paper's ensemble (250 x 301, about 20 ms); a larger ensemble or a finer rod is
#: checked on its first configurations only (at least :data:`_WALL_CHECK_MIN`), which keeps
#: the check well under a second (0.07 s per start at N = 100000)
_WALL_CHECK_NODES = 100_000
_WALL_CHECK_MIN = 4


class WallStartWarning(QualityWarning):
    """Some start shapes leave the static hard wall (``--wall-radius``): their configurations
    fail, the others run (:func:`wall_check`)."""


class MixedVersionsWarning(QualityWarning):
    """A re-run adds configurations to an ensemble under another package or library version
    than the one that computed its others (:func:`params_record`): a seed gives the same rod
    only with the same floating-point operations, so the ensemble is no longer one run's."""


class CoarseSegmentsWarning(QualityWarning):
    """A quench or anneal of fewer segments than its statistics are validated from
    (:data:`simulate.noise.VALIDATED_QUENCH_SEGMENTS`)."""


def coarse_segments_doubt(params: dict) -> str | None:
    """Why a quench's or anneal's segment count is doubtful, or None.

    docs/validation/simulator/README.md compares quenches of N = 100 to 1000 segments with a
    reference: N = 100 differs in four of five ensemble statistics (a segment is a quarter of
    Rg), N = 200 in alpha_e; the default N = 300 is the smallest kept
    (:data:`~simulate.noise.VALIDATED_QUENCH_SEGMENTS`, also the smallest the renders' truth
    is validated from).

    Parameters
    ----------
    params : dict
        Run parameters (see :func:`run_ensemble`); a compaction's are not judged here.

    Returns
    -------
    str or None
    """
    n = params.get("n_segments")
    if params.get("command") not in _POWELL or n is None or n >= VALIDATED_QUENCH_SEGMENTS:
        return None
    return (f"N = {n} segments is below the {VALIDATED_QUENCH_SEGMENTS} the simulator's "
            "ensemble statistics are validated from (docs/validation/simulator/README.md: "
            "N = 100 and 200 disagree with the reference): its energies, Rg and branch "
            "statistics are the discretisation's")


class CoarseRodWarning(QualityWarning):
    """Most branches of an ensemble are shorter than one segment of the rod: its segments are
    too long for the contact structure they make (:func:`coarse_rod_doubt`)."""


#: Share of branches shorter than one segment above which an ensemble's contact analysis is
#: doubtful. Measured: a compaction to epsilon 19 at N = 500 (a segment 48 h) has 97 % such
#: branches, junctions of degree 197 and 3.5 times the stacks of N = 2000 (8.8 %); default
#: quenches (N = 150, 300) have none, N = 80 5.5 %.
COARSE_BRANCH_SHARE = 0.25


def coarse_rod_doubt(tables: dict, n_segments: int) -> str | None:
    """Why an ensemble's stacks and branches are doubtful, or None.

    Parameters
    ----------
    tables : dict
        As returned by :func:`run_ensemble` (its ``branches``).
    n_segments : int
        Segments N of the rods.

    Returns
    -------
    str or None
        The warning's text when more than :data:`COARSE_BRANCH_SHARE` of the branches are
        shorter than one segment ``1/N``: the discrete rod does not resolve them (their
        curvature is NaN), and the stacks they bound are artefacts of the discretisation.
    """
    br = tables.get("branches")
    if br is None or not len(br) or "length" not in br:
        return None
    share = float(np.mean(pd.to_numeric(br["length"], errors="coerce") < 1.0 / n_segments))
    if share <= COARSE_BRANCH_SHARE:
        return None
    return (f"{100 * share:.0f} % of the branches are shorter than one segment 1/N: N = "
            f"{n_segments} segments are too long for the stacks they make, whose counts and "
            "branches are then artefacts (use more --segments)")


class HairpinNodeWarning(QualityWarning):
    """Configurations of an ensemble fold back at a single node: a node turning by more than
    :data:`HAIRPIN_NODE_DEG`, a fold tighter than one segment, whose bending the discrete
    energy caps at ``4 / ds`` (configs.csv ``n_hairpin_nodes``, :func:`hairpin_doubt`)."""


#: A node turning by more than this folds the rod back within one node (configs.csv
#: ``n_hairpin_nodes``). The paper's finite-difference energy (Eq. (8)) prices a node's turn
#: dtheta at ``(2 - 2 cos dtheta) / ds``, at most ``4 / ds``, as much as a cap of radius 0.8
#: segment: a fold tighter than the rod resolves, which the minimiser can prefer to a cap of
#: several segments under a strong confinement. Measured on the default quench (48
#: configurations, seed 3): every other node turns by less than 40 degrees; 6 configurations
#: have one node turning by 172-180 degrees, which alone carries 4 / ds = 1200 of the
#: configuration's bending energy (about 2000).
HAIRPIN_NODE_DEG = 90.0


def hairpin_doubt(configs: pd.DataFrame) -> str | None:
    """Why some configurations' energies are the discretisation's, or None.

    Parameters
    ----------
    configs : DataFrame
        configs.csv of a quench or anneal (its ``n_hairpin_nodes``; folders written before that
        column existed have none and are not judged).

    Returns
    -------
    str or None
        The warning's text when any configuration has a node turning by more than
        :data:`HAIRPIN_NODE_DEG`.
    """
    if "n_hairpin_nodes" not in configs:
        return None
    n = pd.to_numeric(configs["n_hairpin_nodes"], errors="coerce").fillna(0)
    if not (n > 0).any():
        return None
    return (f"{int((n > 0).sum())} of {len(configs)} configurations fold back at a single node "
            f"({int(n.sum())} node(s) turning by more than {HAIRPIN_NODE_DEG:.0f} degrees, "
            "n_hairpin_nodes in configs.csv): a fold tighter than one segment, whose bending "
            "energy the discrete rod caps at 4 / ds; the branches holding them carry it")


# parameters that define the physics: a re-run into the same folder must agree on them
_PHYSICS_KEYS = ("command", "n_segments", "lam", "noise", "seed", "method", "n_runs",
                 "maxiter", "nematic_runs", "u", "nematic_cutoff", "ftol", "xtol", "wall_radius",
                 "contact_distance", "lam_start", "stages", "ramp", "parametrization")


def _physics_keys(params: dict) -> tuple:
    """The parameters a re-run of a quench or anneal must agree on: the Powell protocol's only
    for a method that uses them (whatever a folder of another method recorded of them, they
    changed nothing)."""
    command = params.get("command")
    if command in _POWELL and params.get("method") not in _POWELL[command]:
        drop = set(_POWELL_KEYS) | {"parametrization", "nematic_cutoff"}
        return tuple(k for k in _PHYSICS_KEYS if k not in drop)
    return _PHYSICS_KEYS


def resolve_defaults(params: dict) -> dict:
    """``params`` of a quench or anneal with every default the run uses written out.

    ``contact_distance`` None becomes the analysis's default (half a segment,
    :func:`simulate.contacts.default_contact_distance`); for the methods that use them,
    ``parametrization`` None becomes the command's (:data:`PARAMETRIZATION`) and the Powell
    quench's ``nematic_cutoff`` None one segment
    (:func:`simulate.optimize.default_contact_cutoff`). A record holding the values stays the
    same ensemble if a default changes, and a record that holds None (an older folder)
    compares equal to one holding the values it stood for. Parameters of other commands
    (compact) are returned unchanged.

    Parameters
    ----------
    params : dict
        Run parameters (see :func:`run_ensemble`), or a params.json read back.

    Returns
    -------
    dict
        A new dict.
    """
    from simulate.contacts import default_contact_distance

    out = dict(params)
    command, method = out.get("command"), out.get("method")
    if command not in _POWELL or out.get("n_segments") is None:
        return out
    n = int(out["n_segments"])
    if out.get("contact_distance") is None:
        out["contact_distance"] = default_contact_distance(n)
    if method in _POWELL[command] and out.get("parametrization") is None:
        out["parametrization"] = PARAMETRIZATION[command]
    if (method in METHOD_OPTIONS["--nematic-cutoff"].get(command, ())
            and out.get("nematic_cutoff") is None):
        out["nematic_cutoff"] = default_contact_cutoff(n)
    return out


#: The key of the parameters handed to a task that holds the run's digest of its physics
#: parameters (:func:`params_digest`), which the task's part file records.
RUN_DIGEST = "run_digest"


def params_digest(params: dict, keys) -> str:
    """A digest of the physics parameters ``keys`` of ``params``: a part file computed under
    others (a stopped run's configuration still finishing on a Dask worker, after its folder
    was emptied for a run of other parameters) is not this run's."""
    import hashlib

    text = json.dumps({k: params.get(k) for k in keys}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def part_path(out, config_id: int) -> Path:
    """Path of the part file of one configuration."""
    return Path(out) / "parts" / f"config_{config_id:05d}.npz"


def minimize_config(xy0, params: dict, seed: int):
    """Run the minimisation named by ``params`` on one start shape.

    Parameters
    ----------
    xy0 : (N+1, 2) array
    params : dict
        Run parameters (see :func:`run_ensemble`); ``method`` "lbfgs" reads none of the
        Powell protocol's (``n_runs``, ``maxiter``, ``nematic_runs``, ``u``, ``ftol``,
        ``xtol``, ``parametrization``).
    seed : int
        Seed of the minimiser's random choices (direction resets).

    Returns
    -------
    simulate.optimize.QuenchResult
    """
    from simulate import optimize

    lam, wall = params["lam"], params["wall_radius"]
    if params["method"] == "lbfgs":
        # L-BFGS-B has its own schedule: the Powell protocol's parameters do not reach it
        if params["command"] == "anneal":
            return optimize.anneal(xy0, lam, lam_start=params["lam_start"],
                                   stages=params["stages"], ramp=params["ramp"], method="lbfgs",
                                   seed=seed, wall_radius=wall)
        return optimize.lbfgs_quench(xy0, lam, seed=seed, wall_radius=wall)
    common = dict(seed=seed, n_runs=params["n_runs"], maxiter=params["maxiter"],
                  nematic_runs=tuple(params["nematic_runs"]), u=params["u"],
                  ftol=params["ftol"], xtol=params["xtol"], wall_radius=wall,
                  parametrization=params.get("parametrization") or
                  PARAMETRIZATION[params["command"]])
    if params["command"] == "anneal":
        return optimize.anneal(xy0, lam, lam_start=params["lam_start"],
                               stages=params["stages"], ramp=params["ramp"],
                               method=params["method"], **common)
    if params["method"] == "powell":
        return optimize.powell_protocol(xy0, lam, contact_cutoff=params.get("nematic_cutoff"),
                                        **common)
    if params["method"] == "scipy-powell":
        return optimize.scipy_protocol(xy0, lam, **common)
    raise ParameterError(f"unknown method {params['method']!r}")


def _streams(seed: int):
    """The two independent streams of one configuration's seed: its start shape's and its
    minimiser's."""
    return np.random.SeedSequence(seed).spawn(2)


def start_shape(seed: int, n_segments: int, noise: float) -> np.ndarray:
    """The start shape of the configuration whose seed is ``seed``.

    Parameters
    ----------
    seed : int
        The configuration's seed (``spawn_seeds(ensemble seed, K)[i]`` for configuration i).
    n_segments : int
    noise : float
        Noise amplitude D.

    Returns
    -------
    (N+1, 2) array
        As :func:`simulate.noise.initial_shape`, centre of mass at the origin.
    """
    from simulate.noise import initial_shape

    return initial_shape(n_segments, noise, seed=np.random.default_rng(_streams(seed)[0]))


def run_config(config_id: int, seed: int, params: dict, out: str) -> int:
    """Generate, minimise and analyse configuration ``config_id``; write its part file.

    Returns
    -------
    int
        ``config_id`` (the part file holds the results).
    """
    from simulate.contacts import analyze_rod

    xy0 = start_shape(seed, params["n_segments"], params["noise"])
    opt_seed = int(_streams(seed)[1].generate_state(1, dtype=np.uint32)[0])
    t0 = time.perf_counter()
    res = minimize_config(xy0, params, opt_seed)
    wall_s = time.perf_counter() - t0
    row = {"config_id": config_id, "seed": seed, "method": params["method"], "wall_s": wall_s,
           "energy_total": res.energy_total, "energy_bending": res.energy_bending,
           "energy_confinement": res.energy_confinement}
    branches = []
    voids = []
    stacks = []
    try:
        an = analyze_rod(res.xy, lam=params["lam"], contact_distance=params["contact_distance"])
        rg = float(an.rg)
        row.update(rg=rg, epsilon=float(an.epsilon),
                   epsilon_sqrt2=1.0 / (2.0 * np.pi * np.sqrt(2.0) * rg) if rg > 0 else np.inf,
                   n_stacks=int(an.n_stacks), n_branches=int(an.n_branches),
                   n_junctions=int(an.n_junctions), n_voids=int(an.n_voids))
        branches, voids, stacks = analysis_records(an)
    except Exception as exc:  # noqa: BLE001 - recorded per configuration, the ensemble goes on
        from simulate.geometry import radius_of_gyration

        rg = radius_of_gyration(res.xy)
        row.update(rg=rg, epsilon=1.0 / (2.0 * np.pi * rg),
                   epsilon_sqrt2=1.0 / (2.0 * np.pi * np.sqrt(2.0) * rg),
                   analysis_error=f"{type(exc).__name__}: {exc}")
    row.update({f"n_{k}": v for k, v in res.stats.items()})
    row["n_hairpin_nodes"] = sharp_nodes(res.xy, HAIRPIN_NODE_DEG)
    write_part(out, config_id, row, res.xy, xy0, branches, voids, stacks,
               digest=params.get(RUN_DIGEST))
    return config_id


def analysis_records(an):
    """Branch, void and stack records of one :class:`simulate.contacts.RodAnalysis`, with the
    columns of branches.csv, voids.csv and stacks.csv (config_id added at assembly).

    Returns
    -------
    branches, voids, stacks : lists of dict
    """
    bcols = [c for c in BRANCH_COLUMNS if c != "config_id"]
    vcols = [c for c in VOID_COLUMNS if c != "config_id"]
    scols = [c for c in STACK_COLUMNS if c != "config_id"]
    return (an.branches.reindex(columns=bcols).to_dict("records"),
            an.voids.reindex(columns=vcols).to_dict("records"),
            an.stacks.reindex(columns=scols).to_dict("records"))


def write_part(out, config_id: int, row: dict, xy, xy0, branches=(), voids=(), stacks=(),
               digest: str | None = None):
    """Write the part file of one configuration atomically (read back by :func:`assemble`).

    Parameters
    ----------
    out : path
        Output folder.
    config_id : int
    row : dict
        Its row of configs.csv (``config_id`` and ``seed`` included: a resume checks them).
    xy, xy0 : (N+1, 2) arrays
        Final and initial node positions.
    branches, voids, stacks : lists of dict
        See :func:`analysis_records`.
    digest : str, optional
        The run's :data:`RUN_DIGEST` (the digest of its physics parameters): a resume keeps
        only the parts of its own parameters.
    """
    # the process that computed the rod records its versions (a Dask worker's may differ
    # from the client's): params.json lists those of the rods kept (:func:`params_record`)
    meta = json.dumps({"row": row, "branches": list(branches), "voids": list(voids),
                       "stacks": list(stacks), "computed_by": computing_versions(),
                       "digest": digest},
                      default=lambda o: o.item() if hasattr(o, "item") else str(o))
    write_npz(part_path(out, config_id), xy=xy, xy0=xy0, meta=np.array(meta))


def _read_part(path):
    with np.load(path, allow_pickle=False) as z:
        return json.loads(str(z["meta"])), z["xy"].copy()


def _parts_versions(metas, recorded: dict) -> list[dict]:
    """The ``{"version", "libraries"}`` that computed some part files, each listed once in
    the order of the parts.

    Parameters
    ----------
    metas : iterable of dict
        The parts' records (:func:`_kept_part`).
    recorded : dict
        The folder's params.json: its ``version`` and ``libraries``, and its ``versions``
        when it lists several. A part without ``computed_by`` may come from any of those:
        they are all kept.

    Returns
    -------
    list of dict
    """
    runs, unsaid = [], False
    for meta in metas:
        got = meta.get("computed_by")
        if not isinstance(got, dict):
            unsaid = True
        elif got not in runs:
            runs.append(got)
    if unsaid:
        listed = recorded.get("versions")
        first = {"version": recorded.get("version"), "libraries": recorded.get("libraries")}
        for run in ([r for r in listed if isinstance(r, dict)]
                    if isinstance(listed, list) and listed else [first]):
            if run not in runs:
                runs.append(run)
    return runs


def _kept_part(path, config_id: int, seed: int, digest: str | None = None) -> dict | None:
    """The record of a part file that is a complete result of this configuration (same id,
    seed and, when given, parameters' ``digest``), else None: a truncated, garbled or foreign
    one is redone, so a resume never fails on it."""
    if not path.exists():
        return None
    try:
        meta, xy = _read_part(path)
        row = meta["row"]
        ok = (int(row["config_id"]) == config_id and int(row["seed"]) == int(seed)
              # (a part written before parts recorded a digest is taken on its id and seed)
              and (digest is None or meta.get("digest") in (None, digest))
              and xy.ndim == 2 and xy.shape[1] == 2 and bool(np.isfinite(xy).all()))
    except Exception:  # noqa: BLE001 - any unreadable part is simply redone
        return None
    return meta if ok else None


def assemble(out, n_configs: int, columns=None, failed=None) -> dict:
    """Assemble configs.csv, branches.csv, voids.csv and rods.npz from the part files.

    ``columns`` are the leading columns of configs.csv (default :data:`CONFIG_COLUMNS`); the
    other keys of the rows follow in their order. ``failed`` maps the id of every
    configuration that has no part file to ``(seed, error)``: its row holds only
    ``config_id``, ``seed`` and ``error``, and rods.npz has no entry for it.

    Returns
    -------
    dict
        ``{"configs": DataFrame, "branches": DataFrame, "voids": DataFrame}``.
    """
    out = Path(out)
    rows, brows, vrows, srows, rods = [], [], [], [], {}
    failed = failed or {}
    for i in range(n_configs):
        if i in failed:
            rows.append({"config_id": i, "seed": failed[i][0], "error": failed[i][1]})
            continue
        meta, xy = _read_part(part_path(out, i))
        rows.append(meta["row"])
        brows += [{"config_id": i, **b} for b in meta["branches"]]
        vrows += [{"config_id": i, **v} for v in meta["voids"]]
        srows += [{"config_id": i, **v} for v in meta.get("stacks", [])]
        rods[f"config_{i:05d}"] = xy
    configs = pd.DataFrame(rows)
    if failed and len(configs):
        # a failed row's empty cells would turn the counts into floats (10.0 branches)
        done = [r for r in rows if "error" not in r]
        for c in configs.columns:
            if done and all(isinstance(r.get(c), (int, np.integer)) and not isinstance(
                    r.get(c), bool) for r in done):
                configs[c] = configs[c].astype("Int64")
    columns = list(CONFIG_COLUMNS if columns is None else columns)
    extra = [c for c in configs.columns if c not in columns]
    configs = configs.reindex(columns=columns + extra)
    # a task's extra columns (compact's wall region) follow the standard ones
    branches = _with_extras(pd.DataFrame(brows), BRANCH_COLUMNS)
    voids = _with_extras(pd.DataFrame(vrows), VOID_COLUMNS)
    stacks = _with_extras(pd.DataFrame(srows), STACK_COLUMNS)  # per-stack n_br for the stats
    with renamed_together():  # one run's tables, or the earlier run's: never some of each
        write_csv(out / "stacks.csv", stacks)
        write_csv(out / "configs.csv", configs)
        write_csv(out / "branches.csv", branches)
        write_csv(out / "voids.csv", voids)
        write_npz(out / "rods.npz", **rods)
    return {"configs": configs, "branches": branches, "voids": voids, "stacks": stacks}


#: The files of an ensemble's output folder (:func:`run_ensemble`, :func:`assemble`), beside
#: its ``parts/`` folder of ``config_XXXXX.npz`` files
OUTPUT_FILES = frozenset({"params.json", "configs.csv", "branches.csv", "voids.csv",
                          "stacks.csv", "rods.npz", "failures.csv"})
#: a part file, or the leftover temporary file of its atomic write
_PART_NAME = re.compile(r"config_\d{5,}\.npz|\.config_\d{5,}\.npz\..+")


def _parts_rule(folder: Path) -> str | None:
    """:func:`~crosssection.core.fileio.foreign_entry`'s rule for an ensemble's subfolders:
    ``parts`` holds part files only."""
    if folder.name != "parts":
        return folder.name
    for f in sorted(folder.iterdir()):
        if f.name not in BROWSER_FILES and not (f.is_file() and _PART_NAME.fullmatch(f.name)):
            return f"parts/{f.name}"
    return None


def check_out_folder(out, command: str) -> None:
    """Refuse an output folder that holds anything but an ensemble's files.

    ``out`` may be missing (it is created), empty, or hold an earlier run's output, which a
    re-run with the same parameters resumes (:func:`run_ensemble` compares them). Files of
    another kind (a batch's index, scans) would end up beside the ensemble's tables, and
    ``stats`` reading the folder would take it for an ensemble and ignore the rest.

    Parameters
    ----------
    out : path
    command : str
        The command writing the folder (named in the message).

    Raises
    ------
    FileExistsError
        ``out`` is a file.
    ParameterError
        ``out`` holds an entry no ensemble writes (naming it).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), str(out))
    if not out.is_dir():
        return
    foreign = foreign_entry(out, OUTPUT_FILES, _parts_rule)
    if foreign is not None:
        raise ParameterError(f"holds {foreign}, which is no part of a {command} output: give "
                             f"a new folder, an empty one or one an earlier {command} wrote",
                             out)


def library_versions() -> dict:
    """Versions of the numerical libraries a configuration depends on.

    A quench or a compaction is chaotic: the same seed gives the same rod only with the same
    floating-point operations, and a new release of numpy, scipy, numba or llvmlite can move
    their last bits, after which the run ends on another rod. Recorded in ``params.json``
    beside the package version.
    """
    from crosssection.core.provenance import library_versions as versions

    return versions(("numpy", "scipy", "numba", "llvmlite"))


def computing_versions() -> dict:
    """The versions of this process that decide a rod's last bits.

    Returns
    -------
    dict
        ``{"version": the package's, "libraries": ...}`` (:func:`library_versions`).
    """
    return {"version": __version__, "libraries": library_versions()}


def params_record(params: dict, old: dict | None, kept: list[dict],
                  computing: bool) -> tuple[dict, str | None]:
    """The content of ``params.json`` and, when the ensemble mixes versions, why.

    ``version`` and ``libraries`` (:func:`library_versions`) say which code computed the
    rods: a resume keeps those of the folder's record. When the part files kept were
    computed under several package or library versions, ``versions`` lists the
    ``{"version", "libraries"}`` of each, the recorded one first (absent while all are the
    same). A run lists only the parts on disk: one stopped before any configuration of its
    own finished leaves the record as it was.

    Parameters
    ----------
    params : dict
        The run's parameters, defaults resolved.
    old : dict or None
        The folder's params.json, when some of the configurations asked for were computed
        under it (None: this run computes them all).
    kept : list of dict
        The versions that computed the part files kept (:func:`_parts_versions`).
    computing : bool
        Whether this run computes configurations.

    Returns
    -------
    (record, mixed) : (dict, str or None)
        ``mixed`` names the versions when this run adds configurations to an ensemble
        computed under others.
    """
    now = computing_versions()
    if old is None:
        return {**params, **now}, None
    first = {"version": old.get("version"), "libraries": old.get("libraries")}
    if kept and first not in kept:  # the parts say who computed them, the record did not
        first = kept[0]
    runs = [first] + [r for r in kept if r != first]
    mixed = None
    about = runs + [now] if computing and now not in runs else runs
    if computing and len(about) > 1:

        def shown(r):
            libs = r.get("libraries") or {}
            return (f"foldstat {r.get('version') or 'of unknown version'}"
                    + (f" ({', '.join(f'{k} {v}' for k, v in sorted(libs.items()))})"
                       if isinstance(libs, dict) and libs else ""))

        mixed = (f"the ensemble mixes versions: its configurations were computed by "
                 f"{'; '.join(shown(r) for r in about)} (params.json lists them under "
                 "versions); a seed gives the same rod only with the same versions")
    record = {**params, **first}
    if len(runs) > 1:
        record["versions"] = runs
    return record, mixed


def run_ensemble(params: dict, out, *, workers: int = 1, scheduler: str | None = None,
                 progress: bool | None = None, task=None, columns=None, physics_keys=None,
                 on_wait=None) -> dict:
    """Run (or resume) an ensemble and write its tables.

    Parameters
    ----------
    params : dict
        ``command`` ("quench" or "anneal"), ``n_configs``, ``n_segments``, ``lam``, ``noise``,
        ``seed``, ``method``, ``n_runs``, ``maxiter``, ``nematic_runs``, ``u``, ``ftol``,
        ``xtol`` (the Powell protocol's: None for lbfgs, which does not use them, nor does a
        re-run of lbfgs compare them), ``wall_radius``, ``contact_distance``, optionally
        ``parametrization`` and ``nematic_cutoff`` (quench with Powell: the distance within
        which segments touch for the nematic term, units of L), and for anneal
        ``lam_start``, ``stages``, ``ramp``. None stands for a default, written out in
        params.json (:func:`resolve_defaults`).
    out : path
        Output folder.
    workers : int
        Local worker processes (1 = inline).
    scheduler : str, optional
        Dask scheduler address.
    progress : bool or None
        Show a tqdm progress bar (configurations done, ETA) on stderr; None: only when stderr
        is a terminal.
    task : callable, optional
        ``task(config_id, seed, params, out)`` computes one configuration and writes its part
        file (:func:`write_part`); default :func:`run_config` (quench, anneal).
    columns : list of str, optional
        Leading columns of configs.csv (see :func:`assemble`).
    physics_keys : tuple of str, optional
        Parameters a re-run into the same folder must agree on (default: quench's).
    on_wait : callable, optional
        Told, in one line, that a cluster has no worker yet (see
        :func:`~crosssection.core.parallel.get_executor`).

    Returns
    -------
    dict of DataFrames (see :func:`assemble`), and ``"failed"``: DataFrame config_id, seed,
    error of the configurations whose task raised (also in ``failures.csv``); the others are
    all computed and written.

    Raises
    ------
    ParameterError
        ``out`` holds files no ensemble writes (:func:`check_out_folder`), or the executor
        cannot be had (``workers``, an unreachable ``scheduler``): nothing is written then.
    ConfigError
        ``out`` holds a different ensemble (its params.json differs on ``physics_keys``).
    ClusterLostError
        The Dask cluster went away: the configurations it had are not recorded, nor are
        the tables written (the part files of the finished ones stay, for the re-run).

    Warns
    -----
    CoarseSegmentsWarning
        A quench or anneal of fewer segments than its statistics are validated from
        (:func:`coarse_segments_doubt`).
    MixedVersionsWarning
        The run adds configurations to an ensemble computed under other package or library
        versions than its own (:func:`params_record`).
    """
    given = out  # named in messages as the caller gave it
    out = Path(out)
    # the workers write the parts: a Dask worker runs in its own working folder, where a
    # relative path names another place than the client's
    where = str(out.expanduser().absolute())
    if task is None:  # a dict typed in Python is checked as the command line's options are
        params = checked_params(params)
    params = resolve_defaults(params)
    params = {k: params.get(k) for k in sorted(params)}
    # two runs into one folder would each take it for theirs: one whose params.json the
    # other had not yet written computed beside it, and the tables mixed the two ensembles
    def unlocked():
        warnings.warn(f"{given}: its file system takes no lock: a second run into it would "
                      "not be refused (run one at a time there)", QualityWarning, stacklevel=4)

    with folder_lock(out, "simulation", where=given, unlocked=unlocked,
                     busy=f"another {params['command']} is writing into it"):
        return _run_ensemble_locked(params, out, given, where, workers=workers,
                                    scheduler=scheduler, progress=progress, task=task,
                                    columns=columns, physics_keys=physics_keys,
                                    on_wait=on_wait)


def _run_ensemble_locked(params, out, given, where, *, workers, scheduler, progress, task,
                         columns, physics_keys, on_wait) -> dict:
    """:func:`run_ensemble` holding the output folder's lock, its parameters resolved."""
    check_out_folder(out, params["command"])
    pfile = out / "params.json"
    raw = None
    if pfile.exists():
        try:
            old = json.loads(pfile.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ConfigError(f"unreadable params.json ({exc})", path=pfile) from None
        raw = old if isinstance(old, dict) else None
        # a folder that recorded None for a default is compared with the value it stood for
        old = resolve_defaults(old) if isinstance(old, dict) else {}
        diff = [k for k in (_physics_keys(params) if physics_keys is None else physics_keys)
                if json.dumps(old.get(k)) != json.dumps(params.get(k))]
        if diff:
            raise ConfigError("output folder holds a different ensemble (parameters differ: "
                              + ", ".join(diff) + "); use another --out", path=out)
    coarse = coarse_segments_doubt(params)
    if coarse:
        warnings.warn(f"{given}: {coarse}", CoarseSegmentsWarning, stacklevel=2)
    n = int(params["n_configs"])
    seeds = spawn_seeds(params["seed"], n)
    digest = params_digest(params, _physics_keys(params) if physics_keys is None
                           else physics_keys)
    kept = {i: meta for i in range(n)
            if (meta := _kept_part(part_path(out, i), i, seeds[i], digest)) is not None}
    todo = [i for i in range(n) if i not in kept]
    # the record's versions are those of the runs that computed the configurations kept
    record, mixed = params_record(params, raw if kept else None,
                                  _parts_versions(kept.values(), raw or {}), bool(todo))
    if mixed:
        warnings.warn(f"{given}: {mixed}", MixedVersionsWarning, stacklevel=2)
    task = run_config if task is None else task
    given = dict(params, **{RUN_DIGEST: digest})  # the task's part records the digest
    failed = {}
    # nothing is written before the executor exists: a refused --scheduler or --workers
    # leaves no folder behind
    with get_executor(workers, scheduler, on_wait=on_wait) if todo else nullcontext() as ex:
        out.mkdir(parents=True, exist_ok=True)
        # the tables hold the first n configurations: so does the record (parts of a larger
        # earlier run stay on disk, and a re-run that asks for them again reuses them); a
        # record that would not change is not rewritten
        if raw != json.loads(json.dumps(record, default=str)):
            write_json(pfile, record)
        bar = None
        if progress is not False:
            from tqdm import tqdm

            bar = tqdm(total=n, initial=n - len(todo), unit="config", desc=params["command"],
                       disable=None if progress is None else not progress)
        try:
            if todo:
                if workers == 1 and not scheduler:
                    # inline executor runs at submit: submit one by one so the bar moves
                    done = ((i, ex.submit(task, i, seeds[i], given, where)) for i in todo)
                else:
                    ids = {ex.submit(task, i, seeds[i], given, where): i for i in todo}
                    done = ((ids[f], f) for f in as_completed(ids))
                for i, fut in done:
                    try:
                        fut.result()
                    except (BrokenExecutor, ClusterLostError):
                        raise  # a dead pool or cluster, not this configuration: a re-run resumes
                    except OSError as exc:
                        if exc.errno not in (errno.ENOSPC, errno.EDQUOT):
                            failed[i] = (int(seeds[i]), f"{type(exc).__name__}: {exc}")
                        else:  # a full disk fails every configuration after: stop here
                            raise output_error(exc, part_path(out, i)) from None
                    except Exception as exc:  # noqa: BLE001 - recorded, the ensemble goes on
                        failed[i] = (int(seeds[i]), f"{type(exc).__name__}: {exc}")
                    if bar is not None:
                        bar.update(1)
        finally:
            if bar is not None:
                bar.close()
    fail = pd.DataFrame([{"config_id": i, "seed": s, "error": e}
                         for i, (s, e) in sorted(failed.items())],
                        columns=["config_id", "seed", "error"])
    write_csv(out / "failures.csv", fail)
    if todo:
        metas = []
        for i in (i for i in range(n) if i not in failed):
            meta = _kept_part(part_path(out, i), i, seeds[i], digest)
            if meta is None:
                # a stopped run's configuration still finishing on a Dask worker wrote its
                # part over this run's: computed again here
                task(i, seeds[i], given, where)
                meta = _read_part(part_path(out, i))[0]
            metas.append(meta)
        # the configurations this run computed join the record's versions
        final, _ = params_record(params, record, _parts_versions(metas, record), False)
        if final != record:
            write_json(pfile, final)
    tables = assemble(out, n, columns, failed)
    tables["failed"] = fail
    return tables


def _with_extras(df: pd.DataFrame, columns) -> pd.DataFrame:
    return df.reindex(columns=list(columns) + [c for c in df.columns if c not in columns])


def summary_head(tables: dict, out) -> tuple[str, pd.DataFrame]:
    """The head of a command's summary line and the configurations that succeeded.

    Parameters
    ----------
    tables : dict
        As returned by :func:`run_ensemble`.
    out : path
        The output folder, as given.

    Returns
    -------
    head : str
        ``"K configurations -> OUT"``, followed by how many failed when some did, or by
        the statement that none succeeded: then there is nothing to average and the caller
        prints ``head`` alone; and by how many configurations beyond K an earlier run left
        in ``parts/``.
    done : DataFrame
        The rows of configs.csv of the configurations that succeeded (possibly none).
    """
    c, failed = tables["configs"], tables["failed"]
    done = c[~c["config_id"].isin(failed["config_id"])]
    head = f"{len(c)} configuration{'' if len(c) == 1 else 's'} -> {out}"
    if done.empty and len(c):
        head += f": none succeeded, no results (errors in {Path(out) / 'failures.csv'})"
    elif len(failed):
        head += f" ({len(failed)} failed)"
    beyond = _parts_beyond(out, len(c))
    if beyond:
        # a lower --n-configs than an earlier run's keeps its parts for a later resume
        head += (f" ({beyond} more configuration{'s' if beyond > 1 else ''} of an earlier run "
                 "kept in parts/, not in the tables)")
    return head, done


def _parts_beyond(out, n_configs: int) -> int:
    """How many part files of ``out`` hold configurations numbered ``n_configs`` or more."""
    n = 0
    for f in (Path(out) / "parts").glob("config_*.npz"):
        try:
            n += int(f.stem[len("config_"):]) >= n_configs
        except ValueError:
            continue
    return n


def report_failures(tables: dict, out) -> int:
    """Print one ``warning: OUT: ...`` line on stderr per failed configuration; return the
    exit status of the command: 3 when some configurations failed, else 0."""
    import sys

    for r in tables["failed"].itertuples():
        print(f"warning: {out}: configuration {r.config_id} (seed {r.seed}) failed: {r.error}",
              file=sys.stderr)
    return 3 if len(tables["failed"]) else 0


def _add_common(p, command):
    p.add_argument("--n-configs", type=int, default=250,
                   help="number of configurations K (default 250)")
    p.add_argument("--lambda", dest="lam", type=float, default=LAMBDA,
                   help="confinement Lambda, dimensionless (target Lambda for anneal; "
                        f"default {LAMBDA:g}, the paper's; at most {LAMBDA_MAX:g}, above "
                        "which the rod is jammed)")
    p.add_argument("--noise", type=float, default=NOISE,
                   help=f"initial noise D, dimensionless (default {NOISE:g}, the paper's; at "
                        f"most {NOISE_PER_SEGMENT_MAX:g} N, above which nearly every start "
                        "shape crosses itself)")
    p.add_argument("--segments", type=int, default=N_SEGMENTS,
                   help=f"number of segments N of the rod of length L (default {N_SEGMENTS})")
    p.add_argument("--seed", type=int, default=0, help="ensemble seed (default 0)")
    p.add_argument("--method", choices=METHODS[command], default=METHODS[command][0],
                   help=f"minimiser (default {METHODS[command][0]} = the paper's protocol)")
    # the Powell protocol's options default to None, resolved to the protocol's defaults in
    # params_from_args: so a method that does not use them can tell the ones the user gave
    powell = "with --method " + " or ".join(_POWELL[command])
    p.add_argument("--runs", type=int, default=None,
                   help=f"Powell runs per configuration (default {N_RUNS}; at most "
                        f"{N_RUNS_MAX}; {powell})")
    p.add_argument("--maxiter", type=int, default=None,
                   help=f"iterations per Powell run (default {MAXITER}; at most "
                        f"{MAXITER_MAX}; {powell})")
    p.add_argument("--parametrization", choices=["tangent", "bend"], default=None,
                   help="Powell search coordinates (default: tangent for quench = the "
                        "prototype's statistics; bend for anneal = winds into the spiral; "
                        f"{powell})")
    nematic = ",".join(map(str, NEMATIC_RUNS))
    p.add_argument("--nematic-runs", type=str, default=None,
                   help="comma-separated Powell runs (0-based) with the nematic term "
                        f"(default {nematic}, the paper's, which needs --runs "
                        f"{max(NEMATIC_RUNS) + 2} or more: it is never cut down to fit fewer "
                        f"runs; {powell})")
    p.add_argument("--u", type=float, default=None,
                   help=f"nematic strength u, dimensionless (default {NEMATIC_U:g}; "
                        f"{powell}): at most {NEMATIC_U_MAX:g}, the paper's range 50-150; "
                        "0 only with --nematic-runs '' (no nematic term)")
    p.add_argument("--nematic-cutoff", type=float, default=None,
                   help="distance within which two segments touch for the nematic term, in "
                        "units of L, below 1 (quench with --method powell; default one "
                        "segment, 1/N)")
    p.add_argument("--ftol", type=float, default=None,
                   help=f"Powell ftol (default {FTOL:g}, scipy's; at most {FTOL_MAX:g}; "
                        f"{powell})")
    p.add_argument("--xtol", type=float, default=None,
                   help=f"Powell xtol (default {XTOL:g}, scipy's; at most {XTOL_MAX:g}; "
                        f"{powell})")
    p.add_argument("--wall-radius", type=float, default=None,
                   help="hard-wall disk radius in units of L, above half a segment 1/(2N); "
                        "the wall stops the rod but does not compress it, so a start shape "
                        "must fit inside (default: none)")
    p.add_argument("--contact-distance", type=float, default=None,
                   help="contact cut-off of the analysis, in units of L, from "
                        f"{MIN_CONTACT_DISTANCE:g} to {CONTACT_DISTANCE_MAX:g} or half a "
                        "segment if larger (default half a segment, 1/(2N))")
    p.add_argument("--workers", type=int, default=1, help="local worker processes (default 1)")
    p.add_argument("--scheduler", default=None,
                   help="Dask scheduler address, e.g. tcp://host:8786 (default: local workers)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: only when stderr is a terminal)")
    p.add_argument("--out", required=True,
                   help="output folder (created; a re-run with the same parameters resumes; "
                        "a folder holding other files is refused)")
    if command == "anneal":
        p.add_argument("--lambda-start", dest="lam_start", type=float, default=LAM_START,
                       help=f"initial Lambda of the ramp (default {LAM_START:g})")
        p.add_argument("--stages", type=int, default=STAGES,
                       help=f"number of Lambda stages (default {STAGES}, at most "
                            f"{STAGES_MAX})")
        p.add_argument("--ramp", choices=RAMPS, default=RAMPS[0],
                       help=f"Lambda schedule (default {RAMPS[0]})")
    p.set_defaults(func=run, command=command)


#: the largest contact distance a quench or anneal takes, in units of L, unless half a
#: segment (the default) is larger: twice the mean gap between neighbouring passes of a rod
#: folded at the paper's radius of gyration, 0.05 (disk area over rod length, about 0.015);
#: beyond, passes count in contact across the gaps between them (at 0.1 a rod of 300
#: segments reads as a single stack of one branch, at 0.05 as a stack of 3; at 0.99 any rod)
CONTACT_DISTANCE_MAX = 0.03


def _finite(name, value, *, low=None, low_open=False, allow_none=False):
    """``value`` as a float, finite and above ``low`` (ParameterError naming the option)."""
    if value is None and allow_none:
        return None
    v = float(value)
    if not math.isfinite(v) or (low is not None and (v < low or (low_open and v == low))):
        bound = "" if low is None else f" {'>' if low_open else '>='} {low:g}"
        raise ParameterError(f"{name} must be a finite number{bound}, got {value!r}")
    return v


def _unused_options(args) -> list:
    """The minimiser options (:data:`METHOD_OPTIONS`) given on the command line that the
    chosen method does not use, in the table's order."""
    return [opt for opt, users in METHOD_OPTIONS.items()
            if getattr(args, opt[2:].replace("-", "_")) is not None
            and args.method not in users.get(args.command, ())]


def _unused_error(args, unused) -> ParameterError:
    """The error naming the options ``unused`` and the methods that take them."""
    def users(command):
        return [m for m in METHODS[command]
                if any(m in METHOD_OPTIONS[o].get(command, ()) for o in unused)]

    where = (f"--method {' or '.join(users(args.command))}" if users(args.command) else
             " and ".join(f"{c} --method {' or '.join(users(c))}" for c in METHODS if users(c)))
    one = len(unused) == 1
    return ParameterError(f"{', '.join(unused)} {'has' if one else 'have'} no effect on "
                          f"{args.command} --method {args.method}: "
                          f"{'it is an option' if one else 'they are options'} of {where}")


def params_from_args(args) -> dict:
    """The parameter dict of :func:`run_ensemble` from parsed CLI arguments, every value
    checked (finite, in range, whole where it must be) before anything is written.

    The Powell protocol's options (:data:`METHOD_OPTIONS`, None when not given) are resolved
    to their defaults for the methods that use them and recorded as None for the others; a
    method refuses those it does not use when they are given. ``--contact-distance`` is
    resolved too (:func:`resolve_defaults`).

    Parameters
    ----------
    args : argparse.Namespace
        Parsed ``quench`` or ``anneal`` arguments.

    Returns
    -------
    dict

    Raises
    ------
    ParameterError
        An absurd value, or an option the chosen method does not use (one line naming it).
    """
    unused = _unused_options(args)
    if unused:
        raise _unused_error(args, unused)
    for name, v, low in (("--n-configs", args.n_configs, 1), ("--segments", args.segments, 3),
                         ("--seed", args.seed, 0), ("--workers", args.workers, 1)):
        if v < low:
            raise ParameterError(f"{name} must be >= {low}, got {v}")
    if args.segments > 100_000 or args.n_configs > 10_000_000:
        raise ParameterError("--segments must be <= 100000 and --n-configs <= 10000000")
    # no confinement, nothing folds: the rod relaxes straight (epsilon below 1)
    lam = _finite("--lambda", args.lam, low=0.0, low_open=True)
    if lam > LAMBDA_MAX:
        raise ParameterError(f"--lambda must be <= {LAMBDA_MAX:g} (the paper's is {LAMBDA:g}): "
                             "above, the rod is jammed and the bending energy drowns in the "
                             f"confinement, got {args.lam:g}")
    noise = _finite("--noise", args.noise, low=0.0)
    noise_max = NOISE_PER_SEGMENT_MAX * args.segments
    if noise > noise_max:
        raise ParameterError(f"--noise must be <= {NOISE_PER_SEGMENT_MAX:g} N = {noise_max:g} "
                             f"at --segments {args.segments} (its default, {NOISE:g}, is the "
                             f"paper's at {N_SEGMENTS} segments): above, nearly every start "
                             "shape crosses itself and none is drawn; lower --noise or raise "
                             f"--segments, got {args.noise:g}")
    if noise == 0.0 and args.method == "lbfgs":
        # the straight start is a stationary point of the energy (a saddle): a gradient
        # method stays on it and returns the straight rod, where Powell's line searches fold it
        raise ParameterError("--noise 0 with --method lbfgs: the straight start rod is a "
                             "stationary point of the energy, which a gradient method does "
                             "not leave (every configuration would be the straight rod); give "
                             "--noise > 0 or --method powell")
    params = dict(command=args.command, n_configs=args.n_configs, n_segments=args.segments,
                  lam=lam, noise=noise, seed=args.seed,
                  method=args.method,
                  nematic_cutoff=_finite("--nematic-cutoff", args.nematic_cutoff, low=0.0,
                                         low_open=True, allow_none=True),
                  wall_radius=_finite("--wall-radius", args.wall_radius, low=0.0, low_open=True,
                                      allow_none=True),
                  contact_distance=_finite("--contact-distance", args.contact_distance, low=0.0,
                                           low_open=True, allow_none=True),
                  parametrization=args.parametrization, **dict.fromkeys(_POWELL_KEYS))
    if args.method in _POWELL[args.command]:
        params.update(_powell_params(args))
    nc = params["nematic_cutoff"]
    if nc is not None and nc >= 1.0:
        # as the contact distance: two segments of a rod of length 1 are always closer
        raise ParameterError(f"--nematic-cutoff must be below the rod length 1, got {nc:g}")
    cd = params["contact_distance"]
    if cd is not None and not MIN_CONTACT_DISTANCE <= cd < 1.0 \
            and cd == default_contact_distance(args.segments):
        # the default, half a segment, of a rod of very many segments
        raise ParameterError(f"--segments {args.segments}: the default contact distance, half "
                             f"a segment ({cd:.6g}), is below the analysis' "
                             f"{MIN_CONTACT_DISTANCE:g}: use at most "
                             f"{math.floor(0.5 / MIN_CONTACT_DISTANCE + 1e-9)} segments or give "
                             "--contact-distance")
    most = max(CONTACT_DISTANCE_MAX, default_contact_distance(args.segments))
    if cd is not None and not MIN_CONTACT_DISTANCE <= cd <= most:
        # below, the analysis' own range (simulate.contacts.analyze_rod), on which every
        # analysis would fail; above, passes of a folded rod touch across their gaps
        raise ParameterError(f"--contact-distance must be from {MIN_CONTACT_DISTANCE:g} up to "
                             f"{most:g} (twice the mean gap between the passes of a rod "
                             "folded to a radius of gyration of 0.05, or half a segment if "
                             f"larger: beyond, passes touch across their gaps), got {cd:g}")
    wall, half = params["wall_radius"], 0.5 / args.segments
    if wall is not None and wall <= half:
        # a segment is a straight chord 1/N long: a disk no wider holds it only as its
        # diameter, and the next segment would have to run back over it
        raise ParameterError(f"--wall-radius must be above half a segment 1/(2N) = {half:.3g} "
                             f"(a disk no wider than one segment cannot hold the rod), got "
                             f"{args.wall_radius!r}")
    if args.command == "anneal":
        if not 1 <= args.stages <= STAGES_MAX:
            raise ParameterError(f"--stages must be from 1 to {STAGES_MAX} (the default is "
                                 f"{STAGES}; each stage is a whole Powell protocol), got "
                                 f"{args.stages}")
        params.update(lam_start=_finite("--lambda-start", args.lam_start, low=0.0,
                                        low_open=True),
                      stages=args.stages, ramp=args.ramp)
        if params["lam_start"] > params["lam"]:
            raise ParameterError(f"--lambda-start {args.lam_start:g} is above --lambda "
                                 f"{args.lam:g}: the ramp compacts the rod toward --lambda")
    return resolve_defaults(params)


#: :func:`run_ensemble`'s parameter names -> the command line's (argparse ``dest``)
_ARG_NAMES = {"n_configs": "n_configs", "n_segments": "segments", "lam": "lam",
              "noise": "noise", "seed": "seed", "method": "method",
              "nematic_cutoff": "nematic_cutoff", "wall_radius": "wall_radius",
              "contact_distance": "contact_distance", "parametrization": "parametrization",
              "n_runs": "runs", "maxiter": "maxiter", "nematic_runs": "nematic_runs", "u": "u",
              "ftol": "ftol", "xtol": "xtol", "lam_start": "lam_start", "stages": "stages",
              "ramp": "ramp"}
_WHOLE = ("n_configs", "n_segments", "seed", "n_runs", "maxiter", "stages")


def checked_params(params: dict) -> dict:
    """A quench's or anneal's parameters given to :func:`run_ensemble` in Python, checked as
    the command line checks its options and completed with its defaults.

    Parameters
    ----------
    params : dict
        ``command`` ("quench" or "anneal") and any of the keys :func:`run_ensemble` lists;
        a key left out takes the command line's default.

    Returns
    -------
    dict
        As :func:`params_from_args` returns it.

    Raises
    ------
    ParameterError
        An unknown key, a value of the wrong type, or one the command line refuses (the
        message names the option).
    """
    from simulate.cli import build_parser

    command = params.get("command")
    if command not in _POWELL:
        raise ParameterError(f"params['command'] must be one of {', '.join(_POWELL)}, got "
                             f"{command!r}")
    unknown = sorted(set(params) - set(_ARG_NAMES) - {"command"})
    if unknown:
        raise ParameterError(f"unknown {command} parameter(s) {', '.join(map(repr, unknown))} "
                             f"(known: {', '.join(_ARG_NAMES)})")
    args = build_parser().parse_args([command, "--out", "."])
    for key, value in params.items():
        if key == "command" or value is None:
            continue
        if key in _WHOLE and (isinstance(value, bool) or not isinstance(value, (int, np.integer))):
            raise ParameterError(f"params[{key!r}] must be a whole number, got {value!r}")
        if key == "nematic_runs" and not isinstance(value, str):
            try:
                value = ",".join(str(int(k)) for k in value)
            except (TypeError, ValueError):
                raise ParameterError(f"params['nematic_runs'] must be run numbers, got "
                                     f"{value!r}") from None
        elif key in ("method", "parametrization", "ramp"):
            allowed = {"method": METHODS[command], "parametrization": ("tangent", "bend"),
                       "ramp": RAMPS}[key]
            if value not in allowed:
                raise ParameterError(f"params[{key!r}] must be one of {', '.join(allowed)}, "
                                     f"got {value!r}")
        elif key not in _WHOLE and key != "nematic_runs":
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise ParameterError(f"params[{key!r}] must be a number, got {value!r}")
        setattr(args, _ARG_NAMES[key], int(value) if key in _WHOLE else value)
    return params_from_args(args)


def _powell_params(args) -> dict:
    """The Powell protocol's run parameters (``n_runs``, ``maxiter``, ``nematic_runs``,
    ``u``, ``ftol``, ``xtol``) from ``args``, each option not given at its default."""
    def given(value, default):
        return default if value is None else value

    runs, maxiter = given(args.runs, N_RUNS), given(args.maxiter, MAXITER)
    nematic = given(args.nematic_runs, ",".join(map(str, NEMATIC_RUNS)))
    try:
        nem = [int(x) for x in str(nematic).split(",") if x.strip()]
    except ValueError:
        raise ParameterError(f"--nematic-runs must be integers, got {nematic!r}") from None
    for name, v in (("--runs", runs), ("--maxiter", maxiter)):
        if v < 1:
            raise ParameterError(f"{name} must be >= 1, got {v}")
    if runs > N_RUNS_MAX:
        raise ParameterError(f"--runs must be <= {N_RUNS_MAX} (the paper's protocol has "
                             f"{N_RUNS}; each run is a whole Powell minimisation), got {runs}")
    if maxiter > MAXITER_MAX:
        raise ParameterError(f"--maxiter must be <= {MAXITER_MAX} (default {MAXITER}; ftol ends "
                             f"a run long before), got {maxiter}")
    if any(k < 0 or k >= runs - 1 for k in nem):
        which = (f"runs 0..{runs - 2} of the --runs {runs}" if runs > 1 else
                 f"no run: --runs {runs} has only the last")
        if args.nematic_runs is None:
            # the default is the paper's protocol for its runs; it is not cut down to fit
            # fewer runs, which would silently drop the nematic term from the protocol
            fits = "--nematic-runs 0 or " if runs > 1 else ""
            raise ParameterError(f"--runs {runs}: the default --nematic-runs {nematic!r} (the "
                                 f"paper's, for {N_RUNS} runs) does not fit it: the nematic "
                                 f"term must never be in the last run (paper); give {fits}"
                                 "--nematic-runs '' for none")
        raise ParameterError(f"--nematic-runs must name {which}: the nematic term must not be "
                             f"used in the last run (paper), got {nematic!r} "
                             "(--nematic-runs '' for none)")
    u = _finite("--u", given(args.u, NEMATIC_U), low=0.0)
    if u > NEMATIC_U_MAX:
        raise ParameterError(f"--u must be <= {NEMATIC_U_MAX:g} (the paper's range is 50-150): "
                             "above, the nematic term outweighs the bending and confinement "
                             f"it is meant to help minimise, got {args.u:g}")
    if u == 0 and nem:
        # a protocol naming runs with a term of no strength: which one the user meant is
        # unknown, and params.json would record both
        named = ("the default " if args.nematic_runs is None else "") + "--nematic-runs"
        raise ParameterError(f"--u must be > 0 with {named} {nematic!r}: give --nematic-runs "
                             "'' for no nematic term, got 0")
    tols = {}
    for name, v, default, high in (("--ftol", args.ftol, FTOL, FTOL_MAX),
                                   ("--xtol", args.xtol, XTOL, XTOL_MAX)):
        tols[name[2:]] = _finite(name, given(v, default), low=0.0, low_open=True)
        if tols[name[2:]] > high:
            raise ParameterError(f"{name} must be <= {high:g} (default {default:g}): looser, "
                                 "Powell stops before the rod is minimised, got "
                                 f"{tols[name[2:]]:g}")
    return dict(n_runs=runs, maxiter=maxiter, nematic_runs=nem, u=u, **tols)


def _round_up(x: float, digits: int = 3) -> str:
    """``x`` rounded up to ``digits`` significant digits: a radius that holds what ``x`` does."""
    step = 10.0 ** (math.floor(math.log10(x)) - digits + 1)
    return f"{math.ceil(x / step) * step:.{digits}g}"


def wall_check(params: dict) -> str | None:
    """Check the start shapes against the static hard wall ``params["wall_radius"]``.

    A start that leaves the wall makes its configuration fail (the wall stops the rod, it
    does not compress it: :func:`simulate.optimize.powell_protocol`). The start shapes of the
    first configurations are drawn as :func:`run_config` draws them: all of them when they
    hold at most :data:`_WALL_CHECK_NODES` nodes together (the paper's ensemble), else the
    first ones within that budget (at least :data:`_WALL_CHECK_MIN`), so the check stays well
    under a second.

    Parameters
    ----------
    params : dict
        Run parameters (see :func:`run_ensemble`).

    Returns
    -------
    str or None
        The warning when some of the drawn starts do not fit (their configurations will fail,
        the others run); None when all fit or there is no wall.

    Raises
    ------
    ParameterError
        None of the drawn starts fits: the message gives the smallest radius that holds one.
    """
    if params.get("wall_radius") is None:
        return None
    wall = float(params["wall_radius"])
    n, nodes = int(params["n_configs"]), int(params["n_segments"]) + 1
    k = min(n, max(_WALL_CHECK_MIN, _WALL_CHECK_NODES // nodes))
    radii = np.array([np.max(np.hypot(*start_shape(s, params["n_segments"], params["noise"]).T))
                      for s in spawn_seeds(params["seed"], k)])
    starts = f"{k} start shapes" if k == n else f"first {k} start shapes (of {n})"
    outside = int(np.count_nonzero(radii > wall))
    if outside == k:
        raise ParameterError(f"--wall-radius {wall!r} holds none of the {starts}: the hard wall "
                             f"stops the rod but does not compress it, a start must fit "
                             f"inside; the smallest radius that holds one is "
                             f"{_round_up(radii.min())}, half of them fit within "
                             f"{_round_up(float(np.median(radii)))}")
    if outside:
        return (f"--wall-radius {wall!r}: {outside} of the {starts} leave the hard-wall disk, "
                f"their configurations will fail (all fit within {_round_up(radii.max())})")
    return None


def run(args) -> int:
    """Entry point of ``quench`` / ``anneal``."""
    check_out(args.out)
    try:
        params = params_from_args(args)
        doubt = wall_check(params)
    except ParameterError as exc:
        raise ParameterError(exc.cause, args.out) from None
    if doubt:
        warnings.warn(f"{args.out}: {doubt}", WallStartWarning, stacklevel=2)
    workers, lowered = capped_workers(args.workers, args.scheduler)
    if lowered:
        print(f"warning: {lowered}", file=sys.stderr)
    tables = run_ensemble(params, args.out, workers=workers, scheduler=args.scheduler,
                          progress=args.progress,
                          on_wait=lambda message: print(f"warning: {message}", file=sys.stderr))
    head, c = summary_head(tables, args.out)
    if c.empty:
        print(head)
    else:
        print(f"{head}: <E> = {c.energy_total.mean():.1f} "
              f"(bending {c.energy_bending.mean():.1f}, confinement "
              f"{c.energy_confinement.mean():.1f}), <Rg> = {c.rg.mean():.4f}")
        coarse = coarse_rod_doubt(tables, params["n_segments"])
        if coarse:
            warnings.warn(f"{args.out}: {coarse}", CoarseRodWarning, stacklevel=2)
        hairpins = hairpin_doubt(c)
        if hairpins:
            warnings.warn(f"{args.out}: {hairpins}", HairpinNodeWarning, stacklevel=2)
    return report_failures(tables, args.out)


def add_subparser(sub):
    """Register the ``quench`` and ``anneal`` subcommands."""
    q = sub.add_parser("quench", help="quench an ensemble of random rods (paper protocol)",
                       description=__doc__.split("\n\n")[0].replace("``", ""))
    _add_common(q, "quench")
    a = sub.add_parser("anneal", help="anneal rods: Lambda ramped slowly to the target",
                       description="Like quench, but Lambda is ramped from --lambda-start to "
                                   "--lambda over --stages stages.")
    _add_common(a, "anneal")


__all__ = ["run_ensemble", "report_failures", "run_config", "assemble", "minimize_config",
           "add_subparser", "check_out_folder", "start_shape", "wall_check",
           "WallStartWarning", "CoarseRodWarning", "coarse_rod_doubt", "OUTPUT_FILES",
           "HairpinNodeWarning", "HAIRPIN_NODE_DEG", "hairpin_doubt",
           "MixedVersionsWarning", "CoarseSegmentsWarning", "coarse_segments_doubt",
           "params_record",
           "METHOD_OPTIONS",
           "analysis_records", "write_part", "resolve_defaults", "PARAMETRIZATION",
           "params_digest", "RUN_DIGEST",
           "summary_head",
           "CONFIG_COLUMNS", "BRANCH_COLUMNS", "VOID_COLUMNS"]
