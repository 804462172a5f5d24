"""The per-image tables: junctions, stacks and branches in the schema of
:mod:`crosssection.core.schema`, assembled from the stages' results.

Conventions (tested in tests/crosssection/test_pipeline.py):

- Stack length is the node-to-node length of the smoothed skeleton path (junction centre to
  junction centre, so the junction blob is not lost). Branch lengths in ``branches.csv`` are
  the same values, so that ``rod_length_mm = sum n_br * length_mm`` holds in both tables.
- ``mid_x_px``/``mid_y_px`` is the point at half the arc length of the stack's path
  (:func:`crosssection.core.polyline.mid_point`): scoring matches stacks by it.
- ``junctions.csv`` reports the layer conservation residual of the final counts under the
  packs it lists, which are the partition the linear solve used there (``equation``: the
  geometric packs, or the candidate the widths picked at an uncertain or a contradicted
  junction). A residual of one layer at a junction where the solve placed a rod end
  (:func:`crosssection.linsys.equations.rod_end_junctions`) is ``conservation_ok``.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from numba import njit

from crosssection.core import schema
from crosssection.core.errors import ParameterError
from crosssection.core.provenance import resolved_path
from crosssection.linsys.equations import candidate_partitions, pack_row
from crosssection.stages import branches as br

__all__ = ["stack_table", "junction_table", "branch_table", "network_graph"]


def _mid_points(paths) -> np.ndarray:
    """:func:`crosssection.core.polyline.mid_point` of every path (NaN for an empty one), all
    at once: its segment lengths by one ``np.hypot``, then per path the same running sum and
    ``np.interp`` arithmetic compiled (:func:`_mid_points_kernel`): 0.5 ms for the 245
    stacks of the dense 2000x2000 benchmark scan, against 3.2 ms path by path."""
    from crosssection.core.polyline import concat_paths

    flat, offs = concat_paths(paths, np.float64)
    d = flat[1:] - flat[:-1]  # np.diff of each path, and a step between paths (unused)
    return _mid_points_kernel(flat, np.hypot(d[:, 0], d[:, 1]), offs)


@njit(cache=True)
def _mid_points_kernel(flat, seg, offs):  # pragma: no cover - numba
    """Point at half the arc length of every path ``flat[offs[i]:offs[i + 1]]``, ``seg[j]``
    the length from point ``j`` to ``j + 1``: the arc length by a running sum (``np.cumsum``)
    and the point by ``np.interp``'s linear interpolation, bit for bit."""
    m = offs.shape[0] - 1
    out = np.full((m, 2), np.nan)
    s = np.empty(flat.shape[0])
    for i in range(m):
        a, b = offs[i], offs[i + 1]
        if b == a:
            continue
        s[a] = 0.0
        for j in range(a, b - 1):
            s[j + 1] = s[j] + seg[j]
        total = s[b - 1]
        if total == 0.0:
            out[i, 0] = flat[a, 0]
            out[i, 1] = flat[a, 1]
            continue
        x = 0.5 * total
        # np.interp: the segment with s[j] <= x < s[j + 1] (0 <= x < total)
        lo, hi = a, b - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if s[mid] <= x:
                lo = mid
            else:
                hi = mid
        j = lo
        for k in range(2):
            if s[j] == x:
                out[i, k] = flat[j, k]
                continue
            slope = (flat[j + 1, k] - flat[j, k]) / (s[j + 1] - s[j])
            v = slope * (x - s[j]) + flat[j, k]
            if np.isnan(v):
                v = slope * (x - s[j + 1]) + flat[j + 1, k]
                if np.isnan(v) and flat[j, k] == flat[j + 1, k]:
                    v = flat[j, k]
            out[i, k] = v
    return out


def _end_junctions(graph):
    ja = np.array([u if graph.node_kind[u] == "junction" else schema.NO_JUNCTION
                   for u, _ in graph.ends], dtype=np.int64)
    jb = np.array([v if graph.node_kind[v] == "junction" else schema.NO_JUNCTION
                   for _, v in graph.ends], dtype=np.int64)
    return ja, jb


def stack_kinds(graph) -> list[str]:
    """Per stack: ``"loop"`` (a closed loop without junction), ``"step"`` (an end where the
    band's layer count steps, :func:`crosssection.stages.widths.layer_steps`), ``"free_end"``
    (an end of the skeleton) or ``"junction"`` (both ends at junctions)."""
    kind = graph.node_kind
    out = []
    for u, v in graph.ends:
        ku, kv = kind[u], kind[v]
        out.append("loop" if ku == "loop" else "step" if "step" in (ku, kv) else
                   "free_end" if "end" in (ku, kv) else "junction")
    return out


def stack_table(graph, *, length_mm, width_mm, layers_est, n_br, fixed_by_width, regions,
                profiles, stack_energy) -> pd.DataFrame:
    """One row per stack (schema columns first, then diagnostics).

    Parameters
    ----------
    graph : StackGraph
    length_mm, width_mm, layers_est : (M,) float arrays
    n_br : (M,) int array
    fixed_by_width : (M,) bool array
        Stacks whose count the widths fixed (linear system).
    regions : list of str
        ``"bulk"`` / ``"periphery"``.
    profiles : list of CurvatureProfile
    stack_energy : (M,) float array
        Dimensionless bending energy of one branch of the stack.

    Returns
    -------
    DataFrame
    """
    m = graph.n_stacks
    mids = _mid_points(graph.paths)
    ja, jb = _end_junctions(graph)
    cols = {
        "stack_id": np.arange(m, dtype=np.int64),
        "junction_a": ja, "junction_b": jb,
        "length_mm": length_mm,
        "width_mm": width_mm,
        "n_br": n_br,
        "region": list(regions),
        "mid_x_px": mids[:, 1], "mid_y_px": mids[:, 0],
        "layers_est": layers_est,
        "fixed_by_width": np.asarray(fixed_by_width, bool),
        "kappa_pm": [p.kappa_pm for p in profiles],
        "kappa_plus": [p.kappa_plus for p in profiles],
        "kappa_m": [p.kappa_m for p in profiles],
        "energy_per_branch": stack_energy,
    }
    if profiles and hasattr(profiles[0], "energy_rel_uncertainty"):
        cols["energy_rel_uncertainty"] = [p.energy_rel_uncertainty for p in profiles]
    cols["kind"] = stack_kinds(graph)
    cols["n_pixels"] = [len(p) for p in graph.paths]
    return pd.DataFrame(cols)


def _junction_equations(linear_system) -> dict:
    """node -> (equation kind, row used) from the linear system's components.

    Kinds: ``packs`` (the geometric packs' conservation), ``widths`` (an uncertain junction
    whose partition the widths picked), ``repartitioned`` (a clear junction switched by the
    widths), ``dropped`` (uncertain, no partition clearly best: no equation), ``rod_end`` (a rod
    end lies there: no equation), ``none`` (no equation: the packs cancel or no packs).
    """
    out = {}
    for c in getattr(linear_system, "components", None) or []:
        rows = getattr(c, "equation_rows", {})
        soft = set(getattr(c, "soft_junctions", []))
        repart = set(getattr(c, "repartitioned_junctions", []))
        for j, r in rows.items():
            kind = "repartitioned" if j in repart else "widths" if j in soft else "packs"
            out[int(j)] = (kind, r)
        for kind, nodes in (("dropped", getattr(c, "dropped_junctions", [])),
                            ("rod_end", getattr(c, "rod_end_junctions", []))):
            for j in nodes:
                out.setdefault(int(j), (kind, None))
    return out


def junction_table(junctions, graph, packs, n_br, linear_system) -> pd.DataFrame:
    """One row per junction: position, degree, packs and the conservation residual.

    ``pack_a`` / ``pack_b`` are the partition whose conservation the linear system used (the
    geometric packs, or the candidate partition the widths picked: ``equation``), and the
    residual ``sum n_br[pack_a] - sum n_br[pack_b]`` is the final counts' under it.  Where the
    system used no equation (``dropped``: no partition clearly best; ``rod_end``; ``none``)
    the packs are the geometric ones and ``conservation_ok`` says whether some candidate
    partition conserves.

    Parameters
    ----------
    junctions : Junctions
    graph : StackGraph
    packs : dict
        Junction node -> Pack.
    n_br : (M,) int array
    linear_system : LinearSystemResult

    Returns
    -------
    DataFrame
    """
    k = len(junctions)
    deg = np.array([graph.degree(j) for j in range(k)], dtype=np.int64)
    eqs = _junction_equations(linear_system)
    comps = getattr(linear_system, "components", None) or []
    rod_end = {int(j) for c in comps for j in getattr(c, "rod_end_junctions", [])}

    def net(a, b) -> int:
        return int(sum(n_br[s] for s, _ in a) - sum(n_br[s] for s, _ in b))

    kinds, sides, cons, ok = [], [], [], []
    for j in range(k):
        p = packs.get(j)
        kind, row = eqs.get(j, ("none", None))
        parts = candidate_partitions(p) if p is not None else [([], [])]
        used = next((ab for ab in parts if row is not None and pack_row(*ab) == row), parts[0])
        r = net(*used)
        good = r == 0 or (j in rod_end and abs(r) == 1)
        if row is None and not good:
            # no equation was used here: any partition that conserves will do
            good = any(net(*ab) == 0 for ab in parts)
        kinds.append(kind)
        sides.append(used)
        cons.append(r)
        ok.append(bool(good))
    return pd.DataFrame({
        "junction_id": np.arange(k, dtype=np.int64),
        "x_px": junctions.centers_rc[:, 1] if k else np.zeros(0),
        "y_px": junctions.centers_rc[:, 0] if k else np.zeros(0),
        "n_stacks": deg,
        # typed: a scan without junctions has the dtypes of one with them
        # "stack:end", not "stack.end", which a CSV reader takes for a decimal number where a
        # pack holds one stack end (the column's type would change from scan to scan)
        "pack_a": pd.Series([" ".join(f"{s}:{e}" for s, e in a) for a, _ in sides],
                            dtype=str),
        "pack_b": pd.Series([" ".join(f"{s}:{e}" for s, e in b) for _, b in sides],
                            dtype=str),
        "ambiguous": np.array([bool(getattr(packs.get(j), "ambiguous", False))
                               for j in range(k)], dtype=bool),
        "reference_dependent": np.array([bool(getattr(packs.get(j), "reference_dependent",
                                                      False)) for j in range(k)], dtype=bool),
        "equation": pd.Series(kinds, dtype=str),
        "conservation_residual": np.array(cons, dtype=np.int64),
        "conservation_ok": np.array(ok, dtype=bool),
        "repartitioned": np.array([kd == "repartitioned" for kd in kinds], dtype=bool),
        "n_pixels": np.array([len(p) for p in junctions.pixels], dtype=np.int64),
    })


def branch_table(profiles, n_br, regions, length_mm, *, rod_length_mm,
                 kappa_c_per_mm=None) -> tuple[pd.DataFrame, np.ndarray]:
    """Branches (``n_br`` per stack) and the energy of one branch of every stack.

    Returns
    -------
    branches : DataFrame
        Schema columns; ``length_mm`` is the stack's node-to-node length.
    stack_energy : (M,) float array
    """
    m = len(profiles)
    # one energy per stack, shared by its branches and stacks.csv
    stack_energy = br.stack_energies(profiles, rod_length_mm=rod_length_mm,
                                     kappa_c_per_mm=kappa_c_per_mm)
    branches = br.branch_table(np.arange(m), profiles, n_br, regions,
                               rod_length_mm=rod_length_mm, kappa_c_per_mm=kappa_c_per_mm,
                               energies=stack_energy)
    if len(branches):
        branches["length_mm"] = length_mm[branches["stack_id"].to_numpy()]
    return schema.check_table("branches", branches), stack_energy


def energy_rel_uncertainty(stacks: pd.DataFrame) -> float | None:
    """Share of the total bending energy that rests on the fork-zone model or the noise floor:
    ``sum_i E_i min(u_i, 1) / sum_i E_i`` over stacks, ``E_i = n_br e_i`` their energy and
    ``u_i`` their ``energy_rel_uncertainty`` (a stack without one counted in full); None when
    the total is 0, the column is absent, or no stack has one (the paper's method, which
    estimates none)."""
    if "energy_rel_uncertainty" not in stacks or not len(stacks):
        return None
    e = (stacks["energy_per_branch"] * stacks["n_br"]).to_numpy(float)
    total = float(np.nansum(e))
    u = stacks["energy_rel_uncertainty"].to_numpy(float)
    if not total > 0 or not np.isfinite(u).any():
        return None
    u = np.nan_to_num(u, nan=1.0)
    return float(np.nansum(e * np.minimum(u, 1.0)) / total)


def hole_record(pre, params) -> dict:
    """The ``hole`` block of ``summary.json`` and ``steps.json``: centre, radius (px and mm),
    whether it was fitted, its confidence and how it was set."""
    return {**pre.hole.as_summary(), "fitted": bool(pre.hole.fitted),
            "radius_mm": _hole_radius_mm(pre, params), "confidence": pre.hole_confidence,
            # a plate's edge, or the ink's envelope (a rod that does not reach the wall reads
            # a smaller hole and a larger epsilon there)
            "found_by": _hole_found_by(pre.hole, params)}


def _hole_radius_mm(pre, params) -> float:
    """The hole's radius in mm: a given one as given, not its round trip through px."""
    radius_mm = float(params.scale.to_mm(pre.hole.radius_px))
    if params.hole_radius_mm is not None and math.isclose(radius_mm, params.hole_radius_mm,
                                                          rel_tol=1e-12):
        return float(params.hole_radius_mm)
    return radius_mm


def _hole_found_by(hole, params) -> str:
    """How the hole of ``summary.json`` was set: given, its radius given and its centre
    fitted to the ink, or found in the scan (a plate's edge or the ink's envelope, the
    hole stage's reason)."""
    if not hole.fitted:
        return "given"
    if (params.hole_radius_mm is not None and params.hole_center_px is None
            and not hole.replaced):
        return "radius given, centre fitted to the ink"
    return hole.reason or "found in the scan"


def recorded_parameters(params) -> dict:
    """The parameters as an output records them (``summary.json``, ``steps.json``):
    :meth:`AnalysisParams.to_dict` with the values derived by default resolved to those used
    (``s_min_mm2``, ``tangent_mm``, ``smooth_px``), so that the record reads without the
    rules that derive them and gives ``AnalysisParams`` the same analysis back.

    Parameters
    ----------
    params : AnalysisParams

    Returns
    -------
    dict
    """
    from crosssection.stages.curvature import default_smooth_px

    smooth = (params.smooth_px if params.smooth_px is not None
              else default_smooth_px(params.thickness_px))
    return {**params.to_dict(), "s_min_mm2": params.s_min_used_mm2,
            # 3 h computed to 12 digits (0.3, not 0.30000000000000004 mm); a given one as given
            "tangent_mm": (params.tangent_mm if params.tangent_mm is not None
                           else float(f"{params.tangent_used_mm:.12g}")),
            "smooth_px": int(smooth)}


def summary(*, pre, params, linear_system, junctions, stacks, branches, voids, rod_measured_mm,
            rod_used_mm, calibration_source, timings, total_time_s, version, inputs=None,
            libraries=None) -> dict:
    """The ``summary.json`` of one analysis (``schema.SUMMARY_KEYS`` first, then the
    thresholds, cleaning, skeleton and linear-system diagnostics, parameters and image).

    Parameters
    ----------
    pre : Preprocessed
        Stages 1-6 (threshold, hole, masks, skeleton, graph).
    params : AnalysisParams
    linear_system : LinearSystemResult
    junctions, stacks, branches, voids : DataFrame
    rod_measured_mm, rod_used_mm : float
        ``sum n_br l`` and the L used (given or measured).
    calibration_source : str or list
        ``"linear n*h"``, ``"fitted to the scan: ..."`` (the law read without a
        calibration), the calibration file (absolute, links followed) or the table given
        in memory as ``[[n_layers, width_mm], ...]`` (:meth:`AnalysisParams.calibration_record`).
    timings : dict
        Stage name -> seconds.
    total_time_s : float
    version : str
    inputs : dict, optional
        What the analysis read (:func:`crosssection.core.provenance.input_record`).
    libraries : dict, optional
        Versions of the numerical libraries
        (:func:`crosssection.core.provenance.library_versions`).

    Returns
    -------
    dict
    """
    n_br = stacks["n_br"].to_numpy()
    deg = junctions["n_stacks"].to_numpy()
    kinds = stacks["kind"].tolist()
    radius_mm = _hole_radius_mm(pre, params)
    total_energy = float(branches["energy"].sum()) if len(branches) else 0.0
    h, w = pre.rgb.shape[:2]
    out = {
        "n_junctions": int(len(junctions)),
        "n_stacks": int(len(stacks)),
        "n_branches": int(n_br.sum()),
        "n_voids": int(len(voids)),
        "mean_branches_per_stack": float(n_br.mean()) if len(n_br) else 0.0,
        "rod_length_mm": float(rod_measured_mm),
        "rod_length_used_mm": float(rod_used_mm),
        "rod_length_given": params.rod_length_mm is not None,
        "epsilon": rod_used_mm / (2.0 * np.pi * radius_mm) if radius_mm > 0 else None,
        "total_energy": total_energy,
        "total_energy_rel_uncertainty": energy_rel_uncertainty(stacks),
        "hole": hole_record(pre, params),
        "timings_s": {k: round(v, 6) for k, v in timings.items()},
        "total_time_s": round(total_time_s, 6),
        "n_junctions_by_degree": {str(int(d)): int(c) for d, c in
                                  zip(*np.unique(deg, return_counts=True))} if len(deg) else {},
        "n_loops": int(sum(1 for k in kinds if k == "loop")),
        "n_free_end_stacks": int(sum(1 for k in kinds if k == "free_end")),
        "n_layer_steps": int(sum(1 for k in pre.graph.node_kind.values() if k == "step")),
        "file_px_per_mm": pre.file_px_per_mm,
        "file_pages": pre.file_pages,
        # 1: stored as displayed; else the EXIF orientation applied, so that every coordinate
        # is in the frame a viewer shows
        "exif_orientation": pre.exif_orientation,
        "thresholds": pre.threshold.as_summary(),
        # (counts of the boolean images: the mean and the sum of 4 Mpx convert every pixel
        # to a number, 3 ms of a dense 2000x2000 scan's analysis; the same values)
        "cleaning": {"s_min_px": pre.s_min_px, "speck_px": pre.speck_px,
                     "foreground_fraction": int(np.count_nonzero(pre.mask_clean))
                     / pre.mask_clean.size,
                     "ink_outside_hole_fraction": pre.ink_outside_fraction,
                     "ink_missed_fraction": getattr(pre, "ink_missed_fraction", 0.0)},
        "skeleton": {"l_min_px": pre.l_min_px, "n_pixels": int(np.count_nonzero(pre.skeleton)),
                     "merged_crossing_links": int(pre.merged_links)},
        "linear_system": linear_system.summary() if hasattr(linear_system, "summary") else {},
        "calibration": calibration_source,
        "parameters": recorded_parameters(params),
        "version": version,
        "libraries": libraries,
        # absolute, links followed, as every path recorded (crosssection.core.provenance)
        "image": {"path": None if pre.path is None else resolved_path(pre.path),
                  "height_px": int(h), "width_px": int(w), "dtype": str(pre.rgb.dtype)},
        "inputs": inputs,
    }
    if params.bending_rigidity_J is not None and rod_used_mm > 0:
        out["total_energy_J"] = total_energy * params.bending_rigidity_J / (2.0 * rod_used_mm
                                                                            * 1e-3)
    return out


def network_graph(junctions: pd.DataFrame, stacks: pd.DataFrame,
                  branches: pd.DataFrame | None = None):
    """The folded network as a graph: junctions are its nodes, stacks its links, ``n_br``
    the links' values (paper, "Topological properties").

    Works on an analysis' tables or on ``junctions.csv``, ``stacks.csv`` and
    ``branches.csv`` read back from disk.

    Parameters
    ----------
    junctions, stacks : DataFrame
        The junction and stack tables.
    branches : DataFrame, optional
        The branch table: each link then carries ``energy``, the sum of its branches'.

    Returns
    -------
    networkx.MultiGraph
        Junction nodes are keyed by ``junction_id`` with the junction table's columns as
        attributes and ``kind="junction"``. A stack end that meets no junction (a free end, or
        a layer step where the table does not say which stack goes on) is a node
        ``"end<stack_id>a"`` or ``"end<stack_id>b"`` (``kind="free_end"``, at no position); a
        closed loop without junction is a self-loop on a node ``"loop<stack_id>"``
        (``kind="loop"``). Each stack is one edge, keyed by its ``stack_id``, with the stack
        table's columns as attributes (two stacks between the same junctions are two edges).

    Raises
    ------
    ParameterError
        Naming the table, the column and the row: a column missing, an id that is blank or
        not a whole number, a ``junction_id`` or ``stack_id`` given twice, a stack end at a
        junction the junction table lacks, a branch of a stack the stack table lacks.
    """
    import networkx as nx

    _whole_ids(junctions, "junctions", ["junction_id"], unique="junction_id")
    _whole_ids(stacks, "stacks", ["stack_id", "junction_a", "junction_b"], unique="stack_id")
    known = set(junctions["junction_id"].astype(np.int64).tolist())
    for col in ("junction_a", "junction_b"):
        ids = stacks[col].astype(np.int64).to_numpy()
        bad = np.flatnonzero((ids >= 0) & ~np.isin(ids, list(known)))
        if len(bad):
            raise ParameterError(f"column {col!r}, row {_row_label(bad[0])}: junction "
                                 f"{ids[bad[0]]} is not in the junctions table", "stacks table")
    if branches is not None:
        _whole_ids(branches, "branches", ["stack_id"])
        if "energy" not in branches.columns:
            raise ParameterError("lacks the column 'energy'", "branches table")
        sids = branches["stack_id"].astype(np.int64).to_numpy()
        bad = np.flatnonzero(~np.isin(sids, stacks["stack_id"].astype(np.int64).to_numpy()))
        if len(bad):
            raise ParameterError(f"column 'stack_id', row {_row_label(bad[0])}: stack "
                                 f"{sids[bad[0]]} is not in the stacks table", "branches table")

    graph = nx.MultiGraph()
    for row in junctions.to_dict("records"):
        graph.add_node(int(row["junction_id"]), kind="junction", **row)
    energy = (branches.groupby("stack_id")["energy"].sum()
              if branches is not None and len(branches) else pd.Series(dtype=float))
    for row in stacks.to_dict("records"):
        sid = int(row["stack_id"])
        a, b = int(row["junction_a"]), int(row["junction_b"])
        if a < 0 and b < 0 and row.get("kind") == "loop":
            u = v = f"loop{sid}"
            graph.add_node(u, kind="loop")
        else:
            u = a if a >= 0 else f"end{sid}a"
            v = b if b >= 0 else f"end{sid}b"
            for node in (u, v):
                if isinstance(node, str):
                    graph.add_node(node, kind="free_end")
        attrs = dict(row)
        if branches is not None:
            attrs["energy"] = float(energy.get(sid, 0.0))
        graph.add_edge(u, v, key=sid, **attrs)
    return graph


def _row_label(i: int) -> str:
    """Row ``i`` (0-based position) of a table as a user finds it: its number among the
    data rows of the CSV, counted from 1."""
    return str(int(i) + 1)


def _whole_ids(table: pd.DataFrame, name: str, columns, unique: str | None = None) -> None:
    """Check that ``table`` (called ``name`` in messages) holds ``columns``, each a whole
    number in every row, and that ``unique`` repeats no value.

    Raises
    ------
    ParameterError
        Naming the table, the column and the (1-based) data row.
    """
    where = f"{name} table"
    for col in columns:
        if col not in table.columns:
            raise ParameterError(f"lacks the column {col!r} (it has: "
                                 f"{', '.join(map(str, table.columns)) or 'none'})", where)
        values = pd.to_numeric(table[col], errors="coerce").to_numpy(float)
        bad = np.flatnonzero(~np.isfinite(values) | (values != np.round(values)))
        if len(bad):
            raise ParameterError(f"column {col!r}, row {_row_label(bad[0])}: "
                                 f"{table[col].iloc[bad[0]]!r} is not a whole number", where)
    if unique is not None:
        ids = table[unique].astype(np.int64)
        dup = np.flatnonzero(ids.duplicated().to_numpy())
        if len(dup):
            raise ParameterError(f"column {unique!r}, row {_row_label(dup[0])}: "
                                 f"{int(ids.iloc[dup[0]])} is given twice", where)
