"""Ground truth from geometry: stacks, junctions, branches and voids of a simulated rod.

Never from images: everything here follows from the node positions of the rod (units of L).

Definitions (paper sections "Simulations vs experiments", "Tiling", "Curvature of branches",
"Energetical properties"):

- The rod is resampled at arclength spacing ``h <= min(ds, delta) / 3`` (nodes included).
- Two samples ``k`` and ``j`` are *in contact* when ``|R_k - R_j| < delta`` and they lie on
  different *passes*: the rod between them leaves the disk of radius ``delta`` around ``R_k``.
  (A tight fold of radius < delta/2 is therefore one pass at its apex, as it is one band in a
  scan.)
- Contacts chain: a pass touching a pass that touches a third forms one band of three (as in
  a scan, where bands closer than the resolution merge). The *multiplicity* of a sample is the
  number of distinct passes in its chained cluster, itself included.
- Runs of constant multiplicity (runs shorter than ``min_run`` = 3 delta are merged into a
  neighbour; a run also ends where a partner pass jumps, and at the apex where it folds back
  onto itself, a cap so merged) are unioned through their contacts
  into *stacks*; a short single run between two runs of the same stack is a fold cap and is
  split between them (the stack ends there, like a free end: junction -1).
- A stack whose runs wrap around (a spiral) is cut where its passes cross the normal at its
  first sample, so that every stack has ``n_br`` runs = branches, and
  ``N_br = sum(n_br) = number of branches``.
- *Junctions* are where the runs of two or more different stacks meet (they change the set of
  passes in contact); free rod ends, fold caps and loop cuts are not junctions.
- *Branches* are the rod pieces between consecutive stack boundaries along the rod (junctions,
  free ends, fold apices): each belongs to exactly one stack. Their energies add up to the
  rod's; their mean curvatures are NaN on a branch shorter than one segment, which the
  discrete rod does not resolve.
- *Voids* are the bounded components of the plane minus the rod thickened to width delta
  (contacts merged), rasterised at ``delta/6`` per pixel; their area and perimeter are measured
  on sub-pixel contours and corrected by the Steiner formula back to the rod centre line.

Turning, mirroring or shifting the rod leaves every decision unchanged: the void raster lies
in the rod's principal frame, on a pixel lattice about its centre of mass. Ties of the run
analysis are broken by quantities that do not depend on which rod end is node 0 (length,
multiplicity, distance from the rod's middle). What still depends on the numbering: a spiral
stack is cut at the normal of its first sample (its branch count may differ by one or two
between the two numberings), a run split in the middle lands on the middle sample on one
side (one sample ``h``), and the passes of a contact cluster are listed in sample order
(taking the nearest first moves the stack lines of compacted rods, whose renders' junction
joins then cross the paper). A rod whose two principal moments are equal has no frame of its
own, and a void whose free part is about a pixel wide is found or missed with the rod's
sub-pixel position: a perturbed rod (not a rigidly moved one) may gain or lose it.
Measured with the nodes reversed: 15 quenched rods of 300 segments read the same stacks,
branches and junctions; a quenched rod of 60 segments read 7 stacks and 22 branches
instead of 8 and 25 in its last fifth, and random walks and zig-zags (which may cross
themselves) 30 -> 33 stacks at N = 300. A branch's energy takes the nodes from its start
to the node before its end, so a fold at one node gives its bending to the branch that
comes after it in node order (reversed: to the other arm; the total is the same), and
every branch boundary moves by one sample ``h`` between the two numberings.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import pandas as pd
from numba import njit
from scipy.spatial import cKDTree

from crosssection.core.errors import ParameterError
from crosssection.core.unionfind import group_labels
from simulate.checks import check_real
from simulate.energy import bending_energy, confinement_energy, node_curvature
from simulate.geometry import checked_rod

__all__ = ["RodAnalysis", "analyze_rod", "default_contact_distance", "resample_rod",
           "MIN_CONTACT_DISTANCE", "MAX_SAMPLES"]

#: Smallest contact cut-off delta :func:`analyze_rod` takes, in units of the rod length L. The
#: rod is resampled at ``min(1/N, delta) / 3``: about ``3 / delta`` samples whatever N, which
#: the contact search and the run analysis loop over, so the bound is on delta itself (3e5
#: samples here). A compaction's cut-off is 3 h, and the experiments' h is 2.6e-5 L or more;
#: below this bound the sample count grows without bound (1e-9: a 45 GiB allocation).
MIN_CONTACT_DISTANCE = 1e-5
#: Most samples :func:`resample_rod` makes (1.6e8 bytes of positions).
MAX_SAMPLES = 10_000_000


def default_contact_distance(n_segments: int) -> float:
    """Default contact cut-off ``delta`` = half a segment length, ``0.5 / N`` (units of L).

    Half a segment is below the resolution of the rod itself (two passes closer than that are
    in contact for every practical purpose) and, rendered at the default scale of
    :mod:`simulate.render`, maps to the band width of a thin stack plus a visible gap.
    """
    return 0.5 / max(int(n_segments), 1)


@dataclass
class RodAnalysis:
    """Ground-truth analysis of one rod configuration (units of L).

    Attributes
    ----------
    rg : float
        Radius of gyration ``sqrt(int R^2 ds)`` (paper Eq. (11), trapezoid rule).
    epsilon, epsilon_sqrt2 : float
        ``1/(2 pi Rg)`` (paper's definition) and ``1/(2 pi sqrt(2) Rg)`` (disk of radius
        sqrt(2) Rg; the reading under which the paper's <eps> = 2.3 matches Rg = 0.05-0.07).
    energy_total, energy_bending, energy_confinement : float
        Whole-rod energies (paper Eq. (8), hard core 0).
    n_stacks, n_branches, n_junctions, n_voids : int
        ``n_branches = sum(stacks.n_br)``.
    multiplicity : (N+1,) int array
        Number of passes in the chained contact cluster of each node, itself included.
    junctions, stacks, branches, voids : DataFrame
        See the module docstring; columns ``junction_id, x, y, n_stacks``;
        ``stack_id, junction_a, junction_b, length, n_br, passes``;
        ``branch_id, stack_id, length, kappa_plus, kappa_pm, energy_bending,
        energy_confinement, energy, s_start, s_end``; ``area, perimeter, shape_ratio, n_edges``.
        A branch shorter than one segment has NaN curvatures (below the rod's resolution) and
        the bending energy of the nodes it holds, possibly none (see :func:`_branch_table`).
    contact_distance : float
        The cut-off delta used.
    stack_lines : list of (P, 2) arrays
        Mean line of every stack (centroid of its passes), extended to its junctions; used by
        the renderer.
    samples_s, samples_xy, samples_multiplicity : arrays
        The resampled rod and the multiplicity of every sample.
    """

    rg: float
    epsilon: float
    epsilon_sqrt2: float
    energy_total: float
    energy_bending: float
    energy_confinement: float
    n_stacks: int
    n_branches: int
    n_junctions: int
    n_voids: int
    multiplicity: np.ndarray
    junctions: pd.DataFrame
    stacks: pd.DataFrame
    branches: pd.DataFrame
    voids: pd.DataFrame
    contact_distance: float
    stack_lines: list = field(default_factory=list, repr=False)
    samples_s: np.ndarray = field(default=None, repr=False)
    samples_xy: np.ndarray = field(default=None, repr=False)
    samples_multiplicity: np.ndarray = field(default=None, repr=False)


# ----------------------------------------------------------------------------------------
# resampling and contacts


def resample_rod(xy, spacing: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Resample the rod at equal arclength steps, nodes included.

    Parameters
    ----------
    xy : (N+1, 2) array
        Node positions; segments of equal length 1/N.
    spacing : float
        Largest allowed sample spacing (units of L), > 0; at most :data:`MAX_SAMPLES` samples.

    Returns
    -------
    s : (K,) arclengths, pts : (K, 2) positions, sub : int samples per segment.

    Raises
    ------
    ParameterError
        ``xy`` is not an (N+1, 2) array of finite numbers with N >= 1, or ``spacing`` is not
        a finite number > 0 or asks for more than :data:`MAX_SAMPLES` samples.
    """
    xy = checked_rod(xy, min_segments=1)
    spacing = check_real("spacing", spacing, low=0.0, low_open=True)
    n = xy.shape[0] - 1
    if n * np.ceil((1.0 / n) / spacing) + 1 > MAX_SAMPLES:
        raise ParameterError(f"spacing must give at most {MAX_SAMPLES} samples, got {spacing!r} "
                             f"for N = {n} segments")
    return _resample(xy, spacing)


def _resample(xy, spacing):
    """:func:`resample_rod` without the checks (``xy`` a float (N+1, 2) array)."""
    n = xy.shape[0] - 1
    sub = max(1, int(np.ceil((1.0 / n) / spacing)))
    t = np.arange(sub) / sub
    a = xy[:-1, None, :] * (1 - t)[None, :, None] + xy[1:, None, :] * t[None, :, None]
    pts = np.concatenate([a.reshape(-1, 2), xy[-1:]], axis=0)
    s = np.arange(pts.shape[0]) / (n * sub)
    return s, pts, sub


@njit(cache=True)
def _other_pass(pts, pairs, delta):
    """For each pair (k, j), k < j: is j on another pass than k seen from k (col 0) and k
    seen from j (col 1)? Another pass = the rod between them leaves the disk of radius delta."""
    m = pairs.shape[0]
    out = np.zeros((m, 2), dtype=np.bool_)
    d2 = delta * delta
    for p in range(m):
        k = pairs[p, 0]
        j = pairs[p, 1]
        for side in range(2):
            c = k if side == 0 else j
            cx = pts[c, 0]
            cy = pts[c, 1]
            for i in range(k + 1, j):
                dx = pts[i, 0] - cx
                dy = pts[i, 1] - cy
                if dx * dx + dy * dy >= d2:
                    out[p, side] = True
                    break
    return out


def _partner_lists(pts, delta, local_window):
    """For every sample, the representative (closest) sample of every other pass within delta."""
    k_total = pts.shape[0]
    tree = cKDTree(pts)
    pairs = tree.query_pairs(delta, output_type="ndarray")
    partners = [[] for _ in range(k_total)]
    if len(pairs) == 0:
        return partners
    pairs = np.sort(pairs, axis=1)
    # chord <= arc: samples closer than delta in arclength are always on the same pass
    pairs = pairs[(pairs[:, 1] - pairs[:, 0]) > local_window]
    if len(pairs) == 0:
        return partners
    other = _other_pass(pts, pairs.astype(np.int64), float(delta))
    nb = [[] for _ in range(k_total)]
    for (k, j), (ok_k, ok_j) in zip(pairs.tolist(), other.tolist()):
        if ok_k:
            nb[k].append(j)
        if ok_j:
            nb[j].append(k)
    for k in range(k_total):
        if not nb[k]:
            continue
        js = np.sort(np.asarray(nb[k]))
        d = np.hypot(*(pts[js] - pts[k]).T)
        breaks = np.flatnonzero(np.diff(js) > 1) + 1
        for seg_js, seg_d in zip(np.split(js, breaks), np.split(d, breaks)):
            partners[k].append(int(seg_js[np.argmin(seg_d)]))
    return partners


def _clusters(partners, same_pass_window, max_size=64):
    """Chained contact cluster of every sample: sorted member samples, one per pass."""
    out = []
    for k in range(len(partners)):
        members = [k]
        frontier = [k]
        while frontier and len(members) < max_size:
            nxt = []
            for r in frontier:
                for q in partners[r]:
                    if all(abs(q - m) > same_pass_window for m in members):
                        members.append(q)
                        nxt.append(q)
            frontier = nxt
        out.append(sorted(members))
    return out


def _runs(labels):
    """(start, stop) index pairs (stop exclusive) of runs of equal labels."""
    labels = np.asarray(labels)
    if labels.size == 0:
        return []
    cut = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    starts = np.r_[0, cut]
    stops = np.r_[cut, labels.size]
    return list(zip(starts.tolist(), stops.tolist()))


def _smooth_short_runs(mult, min_len):
    """Give runs shorter than ``min_len`` samples the multiplicity of their longer neighbour,
    the shortest first, until none is left (every merge removes at least one run)."""
    mult = mult.copy()
    k_total = mult.size
    for _ in range(len(_runs(mult))):
        runs = _runs(mult)
        if len(runs) < 2:
            break
        # ties broken by what does not depend on which rod end is sample 0: the lower
        # multiplicity first, then the run nearer the middle of the rod
        order = sorted(range(len(runs)), key=lambda i: (
            runs[i][1] - runs[i][0], mult[runs[i][0]], abs(runs[i][0] + runs[i][1] - k_total)))
        changed = False
        for i in order:
            a, b = runs[i]
            if b - a >= min_len:
                break
            left = runs[i - 1] if i > 0 else None
            right = runs[i + 1] if i + 1 < len(runs) else None
            cand = [r for r in (left, right) if r is not None]
            # equal lengths: the higher multiplicity (equal ones give the same result)
            best = max(cand, key=lambda r: (r[1] - r[0], mult[r[0]]))
            mult[a:b] = mult[best[0]]
            changed = True
            break  # recompute runs after each merge (keeps it simple and order independent)
        if not changed:
            break
    return mult


# ----------------------------------------------------------------------------------------
# main entry


#: largest relative departure of a rod's length from 1 (units of L) that
#: :func:`analyze_rod` accepts: the simulators keep it within 1e-6, a rod resampled from a
#: finer curve is shorter by its chords, and a rod in other units is off by far more
UNIT_LENGTH_TOLERANCE = 0.05


def _check_unit_length(xy) -> None:
    """Refuse a rod in other units than its length: its Rg and areas would be in those
    units while its branches' lengths, fractions of the rod, stay in units of L."""
    seg = np.hypot(*np.diff(xy, axis=0).T)
    total = float(seg.sum())
    if not abs(total - 1.0) <= UNIT_LENGTH_TOLERANCE:
        from crosssection.core.errors import ParameterError

        raise ParameterError(f"xy must be in units of the rod length L (total length 1), "
                             f"got a rod of length {total:.6g}: pass xy / {total:.6g}")


def analyze_rod(xy, *, lam: float, contact_distance: float | None = None,
                min_run: float | None = None, void_px: float | None = None) -> RodAnalysis:
    """Stacks, junctions, branches, voids, Rg and energies of one rod configuration.

    The stages follow the module docstring: contacts on the resampled rod, runs of constant
    multiplicity, stacks (runs unioned through their contacts, fold caps split, loops cut,
    two-ended junctions merged away), junctions, branches, voids.

    Parameters
    ----------
    xy : (N+1, 2) float array
        Node positions of the rod (units of L, N >= 2 equal segments of length 1/N), finite.
    lam : float
        Dimensionless confinement Lambda (for the confinement energies), finite and >= 0.
    contact_distance : float, optional
        Contact cut-off delta (units of L); default :func:`default_contact_distance` = 0.5/N.
        At least :data:`MIN_CONTACT_DISTANCE` (the rod is resampled at
        ``min(1/N, delta) / 3``, about ``3 / delta`` samples, so smaller cut-offs multiply the
        samples without bound) and below 1, the rod length (a contact needs the rod to leave
        the disk of radius delta and come back, an arclength above delta).
    min_run : float, optional
        Contact runs shorter than this arclength are merged into their neighbour
        (default 3 delta: the disk of radius delta blurs multiplicity changes over ~2 delta).
        At least 0 (no merging) and below 1, the rod length (every run would be merged).
    void_px : float, optional
        Pixel size (units of L) of the void rasterisation (default delta/6); above 0 and at
        most delta, the width of the thickened rod (coarser pixels let the voids leak into each
        other through it).

    Returns
    -------
    RodAnalysis

    Raises
    ------
    ParameterError
        An argument out of the ranges above, naming it (with a hint when ``xy`` looks
        transposed), or a rod whose length is not 1 within :data:`UNIT_LENGTH_TOLERANCE`.
    """
    xy = checked_rod(xy, min_segments=2)
    n = xy.shape[0] - 1
    _check_unit_length(xy)
    lam = check_real("lam", lam, low=0.0)
    if contact_distance is None:
        delta = default_contact_distance(n)
    else:
        delta = check_real("contact_distance", contact_distance,
                           low=MIN_CONTACT_DISTANCE, high=1.0, high_open=True,
                           why="units of the rod length L; about 3 / contact_distance samples")
    if min_run is None:
        min_run = 3.0 * delta
    else:
        min_run = check_real("min_run", min_run, low=0.0, high=1.0, high_open=True,
                             why="an arclength shorter than the rod")
    if void_px is not None:
        void_px = check_real("void_px", void_px, low=0.0, low_open=True, high=delta,
                             why=f"a pixel no wider than the contact distance {delta:.3g}")

    whole = _whole_rod(xy, lam)
    smp = _sample_contacts(xy, delta, min_run)
    runs, apices = _split_hairpins(_contact_runs(smp, delta), smp, delta)
    cls = _union_runs(runs, smp)
    runs, cls, caps = _split_fold_caps(runs, cls, smp, delta)
    runs, cls = _cut_loops(runs, cls, smp)
    topo = _merge_two_ended_junctions(runs, cls, smp, apices | caps)
    junctions, junction_of_end = _junction_table(topo)
    j_xy = junctions[["x", "y"]].to_numpy(float) if len(junctions) else np.zeros((0, 2))
    branches = _branch_table(xy, lam, topo, smp, whole.r2)
    stacks, lines = _stack_table(topo, smp, branches, junction_of_end, j_xy)
    voids = _voids(xy, delta, j_xy, void_px)

    return RodAnalysis(
        rg=whole.rg, epsilon=whole.epsilon, epsilon_sqrt2=whole.epsilon_sqrt2,
        energy_total=whole.e_bend + whole.e_conf, energy_bending=whole.e_bend,
        energy_confinement=whole.e_conf, n_stacks=len(topo.stack_runs),
        n_branches=len(topo.runs), n_junctions=len(junctions), n_voids=len(voids),
        multiplicity=smp.mult[np.arange(n + 1) * smp.sub], junctions=junctions,
        stacks=stacks, branches=branches, voids=voids, contact_distance=delta,
        stack_lines=lines, samples_s=smp.s, samples_xy=smp.pts, samples_multiplicity=smp.mult)


# ----------------------------------------------------------------------------------------
# stages


class _WholeRod(NamedTuple):
    """Energies and size of the whole rod (paper Eqs. (8) and (11))."""

    e_bend: float
    e_conf: float
    r2: np.ndarray  # |R|^2 at every node
    rg: float
    epsilon: float
    epsilon_sqrt2: float


def _whole_rod(xy, lam) -> _WholeRod:
    ds = 1.0 / (xy.shape[0] - 1)
    r2 = np.einsum("ij,ij->i", xy, xy)
    rg = float(np.sqrt(np.sum((r2[1:] + r2[:-1]) * 0.5) * ds))
    eps = 1.0 / (2 * np.pi * rg) if rg > 0 else np.inf
    return _WholeRod(e_bend=float(bending_energy(xy)), e_conf=float(confinement_energy(xy, lam)),
                     r2=r2, rg=rg, epsilon=float(eps), epsilon_sqrt2=float(eps / np.sqrt(2.0)))


class _Samples(NamedTuple):
    """The resampled rod and its contacts."""

    s: np.ndarray         # (K,) arclengths
    pts: np.ndarray       # (K, 2) positions
    sub: int              # samples per segment
    h: float              # sample spacing
    same_pass: int        # samples closer than this along the rod are on one pass
    clusters: list        # chained contact cluster of every sample (one sample per pass)
    mult_raw: np.ndarray  # (K,) passes in every cluster
    mult: np.ndarray      # mult_raw with runs shorter than min_run merged into a neighbour
    min_len: int = 1      # min_run in samples


def _sample_contacts(xy, delta, min_run) -> _Samples:
    ds = 1.0 / (xy.shape[0] - 1)
    s, pts, sub = _resample(xy, min(ds, delta) / 3.0)
    h = s[1] - s[0]
    partners = _partner_lists(pts, delta, int(np.floor(delta / h)))
    same_pass = int(np.ceil(2.0 * delta / h)) + 1
    clusters = _clusters(partners, same_pass)
    mult_raw = np.array([len(c) for c in clusters], dtype=np.int64)
    min_len = max(1, int(round(min_run / h)))
    mult = _smooth_short_runs(mult_raw, min_len)
    return _Samples(s=s, pts=pts, sub=sub, h=h, same_pass=same_pass, clusters=clusters,
                    mult_raw=mult_raw, mult=mult, min_len=min_len)


def _run_ids(runs, k_total):
    """Run index of every sample (runs tile the samples)."""
    run_id = np.empty(k_total, dtype=np.int64)
    for i, (a, b) in enumerate(runs):
        run_id[a:b] = i
    return run_id


def _contact_runs(smp, delta):
    """Runs ``[start, stop)`` of constant multiplicity whose partner passes do not jump."""
    mult, mult_raw, clusters, same_pass = smp.mult, smp.mult_raw, smp.clusters, smp.same_pass
    k_total = len(smp.s)
    jump = max(3 * same_pass, int(np.ceil(4 * delta / smp.h)))
    runs = []
    start = 0
    for k in range(1, k_total + 1):
        cut = k == k_total
        if not cut:
            if mult[k] != mult[k - 1]:
                cut = True
            elif mult[k] > 1 and mult_raw[k] == mult[k] and mult_raw[k - 1] == mult[k - 1]:
                a = [q for q in clusters[k - 1] if abs(q - (k - 1)) > same_pass]
                b = [q for q in clusters[k] if abs(q - k) > same_pass]
                if any(min(abs(q - r) for r in b) > jump for q in a) or \
                        any(min(abs(q - r) for r in a) > jump for q in b):
                    cut = True
        if cut:
            runs.append([start, k])
            start = k
    return runs


def _split_hairpins(runs, smp, delta):
    """Cut a run at every fold it holds (returns the runs and the samples cut at): a sample in
    contact with a sample of its own run less than a fold cap (``4 delta + pi delta``, as in
    :func:`_split_fold_caps`) further along the rod.

    A fold whose cap is shorter than ``min_run`` has its cap merged into the passes beside it
    by :func:`_smooth_short_runs`, so that one run goes round the fold, and the partner
    check of :func:`_contact_runs` is skipped where the multiplicity was smoothed. A branch
    ends at a fold apex (module docstring): without the cut, an accordion of 4 layers 0.99
    delta apart read 5 branches, two of them slivers of 0.005 L. The cut is the middle of
    the two samples in contact, the apex; one within ``same_pass`` of the run's end is the
    run's end already. Only where the rod turns back: a pass that stands off its band over a
    bump shorter than ``min_run`` touches itself across the bump and goes on the way it
    came. A spiral's passes touch a whole turn further along: a loop, cut by
    :func:`_cut_loops`.
    """
    span = int(np.floor((4.0 + np.pi) * delta / smp.h))
    same_pass, mult, clusters = smp.same_pass, smp.mult, smp.clusters
    pts, last = smp.pts, len(smp.pts) - 1
    m = max(span // 2, 1)

    def turns_back(c):
        # the rod's direction over half a cap before and after the apex: opposed at a fold;
        # a pass bulging off its band for a moment goes on the way it came
        u = pts[max(c - m, 0)] - pts[max(c - 2 * m, 0)]
        v = pts[min(c + 2 * m, last)] - pts[min(c + m, last)]
        return u @ v < 0

    out, cut_at = [], set()
    for a, b in runs:
        if mult[a] < 2:
            out.append([a, b])
            continue
        apices = sorted((k + q) // 2 for k in range(a, b) for q in clusters[k]
                        if k + same_pass < q < min(b, k + span + 1))
        cuts = []
        for group in np.split(np.asarray(apices, np.int64),
                              np.flatnonzero(np.diff(apices) > same_pass) + 1):
            if len(group):
                c = int(np.median(group))
                if a + same_pass < c < b - same_pass and turns_back(c):
                    cuts.append(c)
        edges = [a] + cuts + [b]
        out.extend([u, v] for u, v in zip(edges[:-1], edges[1:]))
        cut_at.update(cuts)
    return out, cut_at


def _union_runs(runs, smp):
    """Stack label of every run: runs joined by a contact of unsmoothed multiplicity."""
    mult, mult_raw = smp.mult, smp.mult_raw
    run_id = _run_ids(runs, len(smp.s))
    pairs = [(run_id[k], run_id[q]) for k in range(len(smp.s))
             if mult[k] >= 2 and mult_raw[k] == mult[k]
             for q in smp.clusters[k] if q != k and mult[q] == mult[k]]
    return group_labels(len(runs), pairs).tolist()


def _split_fold_caps(runs, cls, smp, delta):
    """A short run between two runs of one stack is a fold cap: split it between them.

    Returns the runs, their stack labels and the samples where a cap was split (apices)."""
    mult = smp.mult
    apices = set()
    cap_max = 4.0 * delta + np.pi * delta

    def middle(r):  # a run's multiplicity: its ends may hold half a cap split before
        return mult[(r[0] + r[1]) // 2]

    changed = True
    while changed:
        changed = False
        for i in range(1, len(runs) - 1):
            a, b = runs[i]
            if (b - a) * smp.h < cap_max and cls[i - 1] == cls[i + 1] and cls[i] != cls[i - 1] \
                    and min(middle(runs[i - 1]), middle(runs[i + 1])) > middle(runs[i]):
                mid = (a + b) // 2
                runs[i - 1][1] = mid
                runs[i + 1][0] = mid
                apices.add(mid)
                del runs[i]
                del cls[i]
                changed = True
                break
    return runs, cls, apices


def _cut_loops(runs, cls, smp):
    """A stack with fewer runs than passes wraps around (a spiral): cut it at one normal."""
    same_pass = smp.same_pass
    run_id = _run_ids(runs, len(smp.s))
    for _ in range(4):
        groups = {}
        for i, c in enumerate(cls):
            groups.setdefault(c, []).append(i)
        cut_points = []
        for c, members in groups.items():
            m_mode = int(np.bincount(
                smp.mult[np.r_[tuple(slice(*runs[i]) for i in members)]]).argmax())
            if len(members) >= m_mode:
                continue
            a0 = runs[members[0]][0]
            k0 = a0 + min(same_pass, (runs[members[0]][1] - a0) // 2)
            cut_points.extend(q for q in smp.clusters[k0] if run_id[q] in members)
        cut_points = sorted(set(cut_points))
        if not cut_points:
            break
        new_runs, new_cls = [], []
        for i, (a, b) in enumerate(runs):
            cuts = [q for q in cut_points if a + same_pass < q < b - same_pass]
            edges = [a] + cuts + [b]
            for u, v in zip(edges[:-1], edges[1:]):
                new_runs.append([u, v])
                new_cls.append(cls[i])
        if len(new_runs) == len(runs):
            break
        runs, cls = new_runs, new_cls
        run_id = _run_ids(runs, len(smp.s))
    return runs, cls


class _Topology(NamedTuple):
    """Final runs (= branches) and how they form stacks and junctions (see :func:`_topology`)."""

    runs: list
    run_stack: np.ndarray
    stack_runs: list
    side: dict
    groups: dict
    node_pts: dict


def _merge_two_ended_junctions(runs, cls, smp, apices=frozenset()) -> _Topology:
    """Number the stacks and merge every pair of stacks meeting alone at a junction.

    A junction with exactly two stack ends (a free rod end or a fold inside a band, or a third
    pass brushing a band) changes the set of passes but not the band: a scan shows one band
    whose width changes, the skeleton no junction. Convention (truth and pipeline agree): the
    two stacks are one; the passes running through are one branch each, so n_br = number of
    distinct rod pieces in the band (the larger count). A pass that folds back there (two
    runs meeting at a sample of ``apices``, the fold apices) is two pieces, as a fold is
    everywhere else: a hairpin lying in a band that a third pass leaves beyond the fold
    counts both its legs.
    """
    rside = None  # [side of start, side of end] per run; 2 = inside its stack (merged away)
    for _ in range(len(runs) + 1):
        run_stack, stack_runs, side, groups, node_pts = _topology(runs, cls, smp.pts, rside)
        rside = [[side[(i, 0)], side[(i, 1)]] for i in range(len(runs))]
        deg2 = [ends for ends in groups.values()
                if len(ends) == 2 and ends[0][0] != ends[1][0]]
        if not deg2:
            break
        (st_a, sd_a), (st_b, sd_b) = deg2[0]  # one merge at a time: sides stay consistent
        c_a, c_b = cls[stack_runs[st_a][0]], cls[stack_runs[st_b][0]]
        for i in range(len(runs)):
            for e in (0, 1):
                if run_stack[i] == st_a and rside[i][e] == sd_a:
                    rside[i][e] = 2
                elif run_stack[i] == st_b:
                    if rside[i][e] == sd_b:
                        rside[i][e] = 2
                    elif rside[i][e] == 1 - sd_b:
                        rside[i][e] = sd_a  # B's far end takes the side freed in A
        cls = [c_a if c == c_b else c for c in cls]
        new_runs, new_cls, new_side = [list(runs[0])], [cls[0]], [list(rside[0])]
        for i in range(1, len(runs)):
            if new_side[-1][1] == 2 and rside[i][0] == 2 and new_cls[-1] == cls[i] \
                    and runs[i][0] not in apices:
                new_runs[-1][1] = runs[i][1]  # one pass through the merged band: one branch
                new_side[-1][1] = rside[i][1]
            else:
                new_runs.append(list(runs[i]))
                new_cls.append(cls[i])
                new_side.append(list(rside[i]))
        runs, cls, rside = new_runs, new_cls, new_side
    return _Topology(runs=runs, run_stack=run_stack, stack_runs=stack_runs, side=side,
                     groups=groups, node_pts=node_pts)


def _junction_table(topo):
    """Junctions: stack-end groups holding two or more stacks. Returns the table and the
    junction of every (stack, side) end."""
    runs, run_stack = topo.runs, topo.run_stack

    # rod ends and fold apices are not where stacks meet: keep them out of junction positions
    def is_meeting(i, e):
        if (e == 0 and i == 0) or (e == 1 and i == len(runs) - 1):
            return False
        j = i - 1 if e == 0 else i + 1
        return run_stack[j] != run_stack[i]

    junction_of_end = {}
    jrows = []
    for _, ends in sorted(topo.groups.items(), key=lambda g: min(g[1])):
        if len({st for st, _ in ends}) < 2:
            continue  # free end, fold apex or loop cut: not a junction
        jid = len(jrows)
        pp = [p for e in ends for (p, i, ee) in topo.node_pts[e] if is_meeting(i, ee)]
        if not pp:
            pp = [p for e in ends for (p, _, _) in topo.node_pts[e]]
        c = np.mean(pp, axis=0)
        jrows.append({"junction_id": jid, "x": float(c[0]), "y": float(c[1]),
                      "n_stacks": len(ends)})
        for e in ends:
            junction_of_end[e] = jid
    return pd.DataFrame(jrows, columns=["junction_id", "x", "y", "n_stacks"]), junction_of_end


def _branch_table(xy, lam, topo, smp, r2):
    """One row per run: length, curvatures and energies.

    The discrete rod's curvature lives on its nodes, each standing for one segment ``ds`` of
    rod (:func:`simulate.energy.node_curvature`). A branch takes the nodes in
    ``[s_start, s_end)`` (the last branch its end node too):

    * ``energy_bending`` is the sum of their ``kappa^2 ds``, so the branches' bending energies
      add up to the rod's exactly (:func:`simulate.energy.bending_energy`); a branch that holds
      no node (one lying within a segment) stores none of the discrete rod's bending energy:
      0 is its value, not a missing one. ``energy_confinement`` integrates the trapezoid
      rule's linear interpolant of ``Lambda R^2`` over the branch exactly (the branches add up
      to the rod's as well); ``energy`` is their sum.
    * ``kappa_plus = sum |kappa| ds / length`` and ``kappa_pm = sum kappa ds / length`` are
      mean curvatures over the branch, measured only on a branch at least one segment long:
      a shorter one is below the rod's resolution, and holds no node (no curvature of its
      own: the turning of the rod there is at the nodes of the branches beside it) or one,
      which the mean would weigh by ``ds / length > 1``. Both are NaN there.
    """
    n = xy.shape[0] - 1
    ds = 1.0 / n
    s, k_total, runs = smp.s, len(smp.s), topo.runs
    kappa = node_curvature(xy)
    node_s = np.arange(n + 1) * ds
    brows = []
    for i, (a, b) in enumerate(runs):
        s0, s1 = s[a], (s[b] if b < k_total else 1.0)
        if i == len(runs) - 1:
            s1 = 1.0
        in_br = (node_s >= s0 - 1e-12) & ((node_s < s1 - 1e-12) | (i == len(runs) - 1))
        eb = float(np.sum(kappa[in_br] ** 2) * ds)
        ec = float(lam * _trapezoid_piece(r2, n, s0, s1))
        length = s1 - s0
        kap = kappa[in_br]
        # the sample arclengths are k / (N sub): a branch one segment long may come out a
        # rounding error short of ds
        resolved = length >= ds * (1.0 - 1e-9)
        kp = float(np.sum(np.abs(kap)) * ds / length) if resolved else np.nan
        kpm = float(np.sum(kap) * ds / length) if resolved else np.nan
        brows.append({"branch_id": i, "stack_id": int(topo.run_stack[i]), "length": length,
                      "kappa_plus": kp, "kappa_pm": kpm, "energy_bending": eb,
                      "energy_confinement": ec, "energy": eb + ec, "s_start": s0, "s_end": s1})
    return pd.DataFrame(brows)


def _stack_table(topo, smp, branches, junction_of_end, j_xy):
    """One row per stack (its junctions, mean branch length, n_br) and its mean line."""
    run_id = _run_ids(topo.runs, len(smp.s))
    srows, lines = [], []
    for st, members in enumerate(topo.stack_runs):
        ja = junction_of_end.get((st, 0), -1)
        jb = junction_of_end.get((st, 1), -1)
        lengths = [branches.loc[r, "length"] for r in members]
        srows.append({"stack_id": st, "junction_a": ja, "junction_b": jb,
                      "length": float(np.mean(lengths)), "n_br": len(members),
                      "passes": ";".join(str(r) for r in members)})
        lines.append(_mean_line(st, members, topo, smp, run_id, j_xy, ja, jb))
    stacks = pd.DataFrame(srows, columns=["stack_id", "junction_a", "junction_b", "length",
                                          "n_br", "passes"])
    return stacks, lines


def _end_point(runs, pts, i, e):
    """Position of end ``e`` (0: start, 1: stop) of run ``i``."""
    a, b = runs[i]
    return pts[a] if e == 0 else pts[b - 1 if b == len(pts) else b]


def _topology(runs, cls, pts, rside=None):
    """Stack numbering, sides of every run end and the junction groups of stack ends.

    Returns ``run_stack`` (stack of every run, numbered by first appearance along the rod),
    ``stack_runs``, ``side[(run, end)]`` (0/1: which end of its stack the run end lies at,
    matched to the stack's longest run, or taken from ``rside``; 2: inside the stack),
    ``groups`` (lists of (stack, side) ends joined by consecutive runs: junctions when they
    hold two or more stacks) and ``node_pts`` ((stack, side) -> list of (point, run, end)).
    """
    stack_of_cls = {}
    for c in cls:
        stack_of_cls.setdefault(c, len(stack_of_cls))
    run_stack = np.array([stack_of_cls[c] for c in cls], dtype=np.int64)
    n_stacks = len(stack_of_cls)
    stack_runs = [[] for _ in range(n_stacks)]
    for i, st in enumerate(run_stack):
        stack_runs[st].append(i)
    side = {}
    for st, members in enumerate(stack_runs):
        if rside is not None:
            for r in members:
                side[(r, 0)], side[(r, 1)] = rside[r]
            continue
        ref = max(members, key=lambda r: runs[r][1] - runs[r][0])
        p0, p1 = _end_point(runs, pts, ref, 0), _end_point(runs, pts, ref, 1)
        for r in members:
            q0, q1 = _end_point(runs, pts, r, 0), _end_point(runs, pts, r, 1)
            direct = np.hypot(*(q0 - p0)) + np.hypot(*(q1 - p1))
            flipped = np.hypot(*(q0 - p1)) + np.hypot(*(q1 - p0))
            side[(r, 0)], side[(r, 1)] = (0, 1) if direct <= flipped else (1, 0)
    # stack end (st, sd) is node 2 st + sd of the graph whose edges join consecutive runs
    node_pts = {(st, sd): [] for st in range(n_stacks) for sd in (0, 1)}
    pairs = []
    for i in range(len(runs)):
        for e in (0, 1):
            if side[(i, e)] < 2:  # 2: a free end or fold inside a merged band
                node_pts[(int(run_stack[i]), side[(i, e)])].append(
                    (_end_point(runs, pts, i, e), i, e))
    for i in range(len(runs) - 1):
        if side[(i, 1)] < 2 and side[(i + 1, 0)] < 2:
            pairs.append((2 * run_stack[i] + side[(i, 1)],
                          2 * run_stack[i + 1] + side[(i + 1, 0)]))
    labels = group_labels(2 * n_stacks, pairs)
    groups = {}
    for st, sd in node_pts:
        groups.setdefault(int(labels[2 * st + sd]), []).append((st, sd))
    return run_stack, stack_runs, side, groups, node_pts


def _trapezoid_piece(r2, n, s0, s1):
    """Integral over [s0, s1] of the piecewise-linear interpolant of the nodal values r2.

    Summed over a partition of [0, 1] it equals the trapezoid rule exactly."""
    ds = 1.0 / n
    x = np.arange(n + 1) * ds

    def cumulative(t):
        i = min(int(np.floor(t / ds)), n - 1)
        tau = t - x[i]
        f0, f1 = r2[i], r2[i + 1]
        full = np.sum((r2[1:i + 1] + r2[:i]) * 0.5) * ds
        return full + f0 * tau + (f1 - f0) * tau * tau / (2 * ds)

    return cumulative(min(s1, 1.0)) - cumulative(max(s0, 0.0))


def _mean_line(st, members, topo, smp, run_id, j_xy, ja, jb):
    """Centroid line of a stack's passes along its longest run, extended to its junctions
    (side 0 first).

    Where a pass stands off the others for less than ``min_run`` (a run merged by
    :func:`_smooth_short_runs`), the sample's contact cluster lacks it: the centroid of the
    passes found there would jump by up to the band's width. Such stretches (fewer passes of
    the stack than the run's multiplicity, shorter than ``min_run``, between samples that
    hold them all) take the centroid interpolated between their ends.
    """
    runs, pts = topo.runs, smp.pts
    r0 = max(members, key=lambda r: runs[r][1] - runs[r][0])
    a, b = runs[r0]
    b_incl = min(b, len(pts) - 1)
    idx = np.arange(a, b_incl + 1)
    line = np.empty((len(idx), 2))
    full = np.zeros(len(idx), bool)
    for t, k in enumerate(idx):
        mem = [q for q in smp.clusters[k] if topo.run_stack[run_id[q]] == st]
        line[t] = pts[mem].mean(axis=0) if mem else pts[k]
        full[t] = len(mem) >= smp.mult[min(k, b - 1)]
    for lo, hi in _runs(full.astype(np.int64)):
        if not full[lo] and lo > 0 and hi < len(idx) and hi - lo < smp.min_len:
            w = (np.arange(lo, hi) - (lo - 1)) / (hi - (lo - 1))
            line[lo:hi] = (1 - w)[:, None] * line[lo - 1] + w[:, None] * line[hi]
    if topo.side[(r0, 0)] == 1 or topo.side[(r0, 1)] == 0:
        line = line[::-1]
    head = [j_xy[ja]] if ja >= 0 else []
    tail = [j_xy[jb]] if jb >= 0 else []
    out = np.concatenate([np.asarray(head).reshape(-1, 2), line, np.asarray(tail).reshape(-1, 2)])
    if ja < 0 and jb < 0 and len(members) > 1 and len(line) > 2:
        # a loop stack (cut at one normal): close it
        if np.hypot(*(line[0] - line[-1])) < 0.25 * np.hypot(*np.ptp(line, axis=0)):
            out = np.concatenate([out, out[:1]])
    return out


# ----------------------------------------------------------------------------------------
# voids


def _voids(xy, delta, j_xy, void_px=None, max_px=4000):
    """Bounded faces of the rod thickened to width delta, measured back to the centre line."""
    import cv2
    from scipy import ndimage
    from skimage import measure

    cols = ["area", "perimeter", "shape_ratio", "n_edges", "centroid_x", "centroid_y"]
    # raster in the rod's own frame, so that a turned, mirrored, shifted or reversed rod
    # meets the same pixels: a void whose free part is a few pixels wide is then found or
    # missed alike in every copy
    origin, axes = _principal_frame(xy)
    xy = (xy - origin) @ axes
    j_xy = (np.asarray(j_xy, float).reshape(-1, 2) - origin) @ axes
    px = delta / 6.0 if void_px is None else float(void_px)
    px = max(px, float(np.max(np.ptp(xy, axis=0) + 4 * delta)) / max_px)
    # pixel centres on the lattice px Z^2 about the centre of mass: mirroring an axis maps
    # it onto itself
    lo = np.floor((xy.min(axis=0) - 2 * delta) / px) * px
    hi = xy.max(axis=0) + 2 * delta
    shape = (int(np.ceil((hi[1] - lo[1]) / px)) + 3, int(np.ceil((hi[0] - lo[0]) / px)) + 3)
    canvas = np.full(shape, 255, np.uint8)
    shift = 4
    poly = np.round((xy - lo) / px * (1 << shift)).astype(np.int32)  # (x, y) = (col, row)
    cv2.polylines(canvas, [poly.reshape(-1, 1, 2)], False, 0, 1, cv2.LINE_8, shift)
    dist = cv2.distanceTransform(canvas, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    half = 0.5 * delta / px
    # exact distances to the centre line near the void boundaries (the raster line is off by
    # up to half a pixel, which biases contour perimeters by ~1%)
    near = np.argwhere(dist < half + 3)
    if len(near):
        _, dense, _ = _resample(xy, px / 4)
        dnear, _ = cKDTree((dense - lo) / px).query(near[:, ::-1].astype(float))
        dist[near[:, 0], near[:, 1]] = dnear
    free = dist > half
    lab, nlab = ndimage.label(free)
    border = np.unique(np.r_[lab[0], lab[-1], lab[:, 0], lab[:, -1]])
    rows = []
    jp = (j_xy - lo) / px if len(j_xy) else np.zeros((0, 2))
    reach = half + 1.5 * delta / px + 1.0  # junctions on the contour: within ~delta of the void
    pad = int(np.ceil(reach)) + 2
    for lab_id, sl in enumerate(ndimage.find_objects(lab), start=1):
        if sl is None or lab_id in border:
            continue
        sub = np.pad(lab[sl] == lab_id, pad)
        if sub.sum() < 4:
            continue
        # sub-pixel boundary: the level ``half`` of the distance to the centre line, restricted
        # to this component (a binary-mask contour overestimates perimeters by ~5%)
        r0, c0 = sl[0].start - pad, sl[1].start - pad
        win = np.zeros(sub.shape, np.float32)
        rr0, cc0 = max(r0, 0), max(c0, 0)
        rr1, cc1 = min(r0 + sub.shape[0], dist.shape[0]), min(c0 + sub.shape[1], dist.shape[1])
        win[rr0 - r0:rr1 - r0, cc0 - c0:cc1 - c0] = dist[rr0:rr1, cc0:cc1]
        win = np.where(sub | (win <= half), win, 0.0)
        contours = [c for c in measure.find_contours(win, half) if len(c) > 3
                    and np.allclose(c[0], c[-1])]
        if not contours:
            continue
        c = max(contours, key=len)
        area_px = 0.5 * abs(np.dot(c[:-1, 0], c[1:, 1]) - np.dot(c[1:, 0], c[:-1, 1]))
        per_px = float(np.sum(np.hypot(*np.diff(c, axis=0).T)))
        # Steiner: the face of the centre line is the void grown by delta/2
        r = half
        area = (area_px + per_px * r + np.pi * r * r) * px * px
        per = (per_px + 2 * np.pi * r) * px
        cy, cx = np.argwhere(sub).mean(axis=0) + [r0, c0]
        n_edges = 0
        if len(jp):
            dd = ndimage.distance_transform_edt(~sub)
            for (jx, jy) in jp:
                rr, cc = int(round(jy)) - r0, int(round(jx)) - c0
                if 0 <= rr < dd.shape[0] and 0 <= cc < dd.shape[1] and dd[rr, cc] <= reach:
                    n_edges += 1
        centroid = origin + axes @ (lo + np.array([cx, cy]) * px)
        rows.append({"area": area, "perimeter": per, "shape_ratio": np.sqrt(area) / per,
                     "n_edges": n_edges, "centroid_x": float(centroid[0]),
                     "centroid_y": float(centroid[1])})
    return pd.DataFrame(rows, columns=cols)


def _principal_frame(xy):
    """Centre of mass and principal axes (columns) of the rod's nodes.

    Each axis points to where the rod's third moment along it is positive, so a rotated,
    mirrored or shifted copy of the rod (or the same nodes in reverse order) has the same
    coordinates in its frame up to rounding. Only a rod whose two axes have equal moments
    (or whose third moment along an axis vanishes) leaves the frame undetermined.
    """
    n = xy.shape[0] - 1
    w = np.full(n + 1, 1.0 / n)
    w[[0, -1]] *= 0.5
    origin = w @ xy
    d = xy - origin
    _, axes = np.linalg.eigh((d * w[:, None]).T @ d)
    skew = w @ (d @ axes) ** 3
    axes = axes * np.where(skew < 0, -1.0, 1.0)
    return origin, axes
