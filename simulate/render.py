"""Render simulated rods into synthetic scans with exact ground truth (``render`` subcommand).

Each stack of :func:`simulate.contacts.analyze_rod` is drawn as one blue band of width
``w(n_br)`` along the mean line of its passes, extended to its junctions (paper, section
"Image analysis procedure": branches in contact closer than the resolution form one band whose
width counts them). Voids show light receding surfaces; the outside is white paper.

Scale. The rod of length 1 maps to ``rod_length_mm``. Passes closer than the contact cut-off
delta merge into one band; passes further apart must show a gap, which holds when
``delta * rod_length_mm >= (w(1) + w(n_max)) / 2 + gap_px / px_per_mm`` (worst case: a single
pass at distance delta from a stack of n_max coincident passes). The default
``rod_length_mm`` is the smallest that satisfies this (about 150-200 mm for N = 300 and the
default delta = 0.5/N), which keeps quench configurations (extent ~0.25 L) under ~2500 px.

Calibration. ``w(n) = h n + 0.5 h (1 - exp(-(n - 1)/3))``: linear in the number of layers plus a
saturating excess (the heating of the hot-wire cut swells thick stacks), written to
``calibration.csv`` so the pipeline can invert it.

Coordinates: column = x, row = y (no flip), so the image is the mirror image of a plot with y
up; signed curvatures therefore compare in absolute value.
"""
from __future__ import annotations

import argparse
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from crosssection.core import schema
from crosssection.core.errors import ConfigError, ParameterError
from crosssection.core.fileio import write_csv, write_json

from simulate.contacts import RodAnalysis, analyze_rod

__all__ = ["RenderedScene", "default_calibration", "render_configuration", "write_scene",
           "render_directory", "add_subparser"]

INK_RGB = np.array([40.0, 70.0, 190.0])
VOID_RGB = np.array([212.0, 215.0, 226.0])
PAPER_RGB = np.array([250.0, 250.0, 248.0])
SMEAR_RGB = np.array([160.0, 185.0, 242.0])


def default_calibration(thickness_mm: float = 0.1, n_max: int = 30) -> pd.DataFrame:
    """Nonlinear width law ``w(n) = h n + 0.5 h (1 - exp(-(n-1)/3))`` as (n_layers, width_mm)."""
    n = np.arange(1, n_max + 1)
    w = thickness_mm * n + 0.5 * thickness_mm * (1 - np.exp(-(n - 1) / 3.0))
    return pd.DataFrame({"n_layers": n, "width_mm": w})


def _width_fn(calibration, thickness_mm):
    if calibration is None:
        calibration = default_calibration(thickness_mm)
    if isinstance(calibration, (str, Path)):
        calibration = pd.read_csv(calibration)
    if isinstance(calibration, pd.DataFrame):
        df = calibration.sort_values("n_layers")
        n, w = df["n_layers"].to_numpy(float), df["width_mm"].to_numpy(float)
        step = w[-1] - w[-2] if len(w) > 1 else w[-1]

        def width(k):
            k = np.asarray(k, float)
            return np.where(k <= n[-1], np.interp(k, n, w), w[-1] + step * (k - n[-1]))
        return width, df
    if callable(calibration):
        nn = np.arange(1, 31)
        return calibration, pd.DataFrame({"n_layers": nn, "width_mm": calibration(nn)})
    raise ParameterError(f"unsupported calibration {type(calibration).__name__}")


@dataclass
class RenderedScene:
    """A rendered configuration: the scan and its truth in :mod:`crosssection.core.schema`."""

    rgb: np.ndarray
    summary: dict
    tables: dict
    params: dict
    calibration: pd.DataFrame
    ink_mask: np.ndarray = field(repr=False, default=None)

    @property
    def truth_summary(self) -> dict:
        return self.summary

    @property
    def truth_tables(self) -> dict:
        return self.tables


def _poly_len(p):
    return float(np.sum(np.hypot(*np.diff(p, axis=0).T))) if len(p) > 1 else 0.0


def _point_at_half(p):
    seg = np.hypot(*np.diff(p, axis=0).T)
    if len(seg) == 0 or seg.sum() == 0:
        return p[0]
    c = np.r_[0, np.cumsum(seg)]
    t = 0.5 * c[-1]
    i = min(int(np.searchsorted(c, t)) - 1, len(seg) - 1)
    i = max(i, 0)
    f = (t - c[i]) / seg[i] if seg[i] > 0 else 0.0
    return p[i] + f * (p[i + 1] - p[i])


def _loop_mid(p):
    """Mid point of a closed line started at its raster-first point (min row, then min col).

    A junction-free closed loop has no natural start; the pipeline (``crosssection.stages.graph``)
    starts its path at the first skeleton pixel in raster order and takes the point at half
    the length (``pipeline._mid_points``). The half-way point does not depend on the
    direction, so starting the truth line at the same place makes the two mid points agree
    (``crosssection.truth.scoring`` matches stacks by mid point).
    """
    q = np.asarray(p, float)[:-1]
    row = np.round(q[:, 1])
    cand = np.flatnonzero(row == row.min())
    i0 = int(cand[np.argmin(q[cand, 0])])
    q = np.concatenate([q[i0:], q[:i0], q[i0:i0 + 1]])
    return _point_at_half(q)


def render_configuration(xy, analysis: RodAnalysis | None = None, *, lam: float = 7e5,
                         px_per_mm: float = 50.0, thickness_mm: float = 0.1,
                         rod_length_mm: float | None = None, calibration=None,
                         contact_distance: float | None = None,
                         noise_sigma: float = 0.0, blur_px: float = 0.0,
                         jpeg_quality: int | None = None, smears: int = 0, specks: int = 0,
                         pinholes: int = 0, seed: int = 0, margin_mm: float = 2.0,
                         gap_px: float = 2.0, max_size_px: int = 2500,
                         hole_radius_mm: float | None = None) -> RenderedScene:
    """Render one rod configuration into an RGB scan with exact truth tables.

    Parameters
    ----------
    xy : (N+1, 2) array
        Rod node positions (units of L).
    analysis : RodAnalysis, optional
        Result of :func:`simulate.contacts.analyze_rod` (computed when omitted).
    lam : float
        Lambda for the analysis when computed here.
    px_per_mm, thickness_mm : float
        Scan resolution and sheet thickness h.
    rod_length_mm : float, optional
        Length of the rod in mm; default: the smallest that keeps a visible gap of
        ``gap_px`` between passes farther apart than delta (module docstring), capped so the
        image stays under ``max_size_px``.
    calibration : DataFrame (n_layers, width_mm), path or callable, optional
        Width law; default :func:`default_calibration`.
    contact_distance : float, optional
        delta for the analysis when computed here.
    noise_sigma, blur_px : float
        Gaussian noise (grey levels) and Gaussian blur sigma (px).
    jpeg_quality : int, optional
        JPEG round trip at this quality.
    smears, specks, pinholes : int
        Numbers of light-blue smears (kept by the threshold), small dark specks in the paper
        and small white pinholes in the ink (both smaller than s_min, removed by cleaning).
    seed : int
        Seed of every random choice (colour jitter, noise, defects).
    margin_mm : float
        Paper around the configuration.
    hole_radius_mm : float, "auto" or None
        Draw a hard-wall disk of this radius centred on the rod's centre of mass
        (stacks touching it are "periphery"); ``"auto"``: the smallest disk enclosing the
        rod plus the half width of the thickest band and 2 h, centred on it (the CLI
        default: a scan always has its container); None: no hole (all "bulk").

    Returns
    -------
    RenderedScene
    """
    import cv2
    from scipy import ndimage

    from crosssection.stages.voids import contour_perimeter_px

    xy = np.asarray(xy, float)
    if analysis is None:
        analysis = analyze_rod(xy, lam=lam, contact_distance=contact_distance)
    if px_per_mm <= 0 or thickness_mm <= 0:
        raise ParameterError("px_per_mm and thickness_mm must be positive")
    width, cal_df = _width_fn(calibration, thickness_mm)
    rng = np.random.default_rng(seed)
    st = analysis.stacks
    n_max = int(st["n_br"].max()) if len(st) else 1
    lo = xy.min(axis=0)
    extent = float(np.max(xy.max(axis=0) - lo))
    delta = analysis.contact_distance
    need_mm = 0.5 * (float(width(1)) + float(width(n_max))) + gap_px / px_per_mm
    gap_ok = True
    if rod_length_mm is None:
        rod_length_mm = need_mm / delta
        cap = ((max_size_px - 2) / px_per_mm - 2 * margin_mm) / max(extent, 1e-9)
        if rod_length_mm > cap:
            warnings.warn(f"rod length capped at {cap:.1f} mm to keep the image under "
                          f"{max_size_px} px: passes just beyond delta may touch", stacklevel=2)
            rod_length_mm, gap_ok = cap, False
    else:
        gap_ok = delta * rod_length_mm >= need_mm
    scale = rod_length_mm * px_per_mm  # px per unit L
    margin_px = margin_mm * px_per_mm
    hole_center_l = np.average(xy, axis=0)
    if isinstance(hole_radius_mm, str):
        if hole_radius_mm != "auto":
            raise ParameterError(f"hole_radius_mm must be a number, None or 'auto', got "
                                 f"{hole_radius_mm!r}")
        # the experiment's container: the smallest disk holding the rod, plus the half width
        # of the thickest band and 2 h of clearance (the pipeline then uses the known hole
        # instead of fitting one to the ink envelope)
        (cx, cy), r_l = cv2.minEnclosingCircle(xy.astype(np.float32))
        hole_center_l = np.array([cx, cy], float)
        hole_radius_mm = float(r_l * rod_length_mm + 0.5 * float(width(n_max))
                               + 2 * thickness_mm)
    hole_px = None if hole_radius_mm is None else hole_radius_mm * px_per_mm
    if hole_px is not None:
        c_off = (hole_center_l - lo) * scale
        far = (xy.max(axis=0) - hole_center_l) * scale
        need = hole_px + 2 * thickness_mm * px_per_mm - np.minimum(c_off, far)
        margin_px = max(margin_px, float(need.max()))

    def to_px(p):  # (x, y) in L -> (col, row) float px
        return (np.asarray(p, float) - lo) * scale + margin_px

    size = np.ceil((xy.max(axis=0) - lo) * scale + 2 * margin_px).astype(int) + 1
    w_px, h_px = int(size[0]), int(size[1])
    hole_c = None
    if hole_px is not None:
        hole_c = to_px(hole_center_l)

    # --- ink: one band of width w(n) per stack along its mean line (exact distance bands)
    coverage = np.zeros((h_px, w_px), np.float32)
    shift = 4
    lines_px = [to_px(line) for line in analysis.stack_lines]
    for n in sorted(set(st["n_br"].tolist())):
        canvas = np.full((h_px, w_px), 255, np.uint8)
        for sid in st.index[st["n_br"] == n]:
            p = np.round(lines_px[sid] * (1 << shift)).astype(np.int32).reshape(-1, 1, 2)
            cv2.polylines(canvas, [p], False, 0, 1, cv2.LINE_8, shift)
        d = cv2.distanceTransform(canvas, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        half = 0.5 * float(width(n)) * px_per_mm
        coverage = np.maximum(coverage, np.clip(half - d + 0.5, 0, 1))
    ink = coverage >= 0.5

    # --- voids: enclosed paper (4-connected), receding surfaces
    lab, nlab = ndimage.label(~ink)
    border = set(np.unique(np.r_[lab[0], lab[-1], lab[:, 0], lab[:, -1]]).tolist()) - {0}
    enclosed = (lab > 0) & ~np.isin(lab, list(border))

    # --- colours
    img = np.empty((h_px, w_px, 3), np.float32)
    img[:] = PAPER_RGB
    img[enclosed] = VOID_RGB + rng.uniform(-6, 6, size=3)
    if hole_c is not None:
        rr, cc = np.mgrid[0:h_px, 0:w_px]
        outside = (rr - hole_c[1]) ** 2 + (cc - hole_c[0]) ** 2 > hole_px ** 2
        img[outside & ~ink] = PAPER_RGB * 0.97
    ink_col = INK_RGB + rng.uniform(-10, 10, size=3)
    ink_jit = rng.normal(0, 6, size=(h_px, w_px, 1)).astype(np.float32)
    a = coverage[..., None]
    img = img * (1 - a) + (ink_col + ink_jit) * a
    s_min_px = (10 * thickness_mm * px_per_mm) ** 2
    for _ in range(int(smears)):
        cy, cx = rng.uniform(0, h_px), rng.uniform(0, w_px)
        ax = rng.uniform(10, 60), rng.uniform(4, 20)
        m = np.zeros((h_px, w_px), np.uint8)
        cv2.ellipse(m, (int(cx), int(cy)), (int(ax[0]), int(ax[1])), rng.uniform(0, 180), 0, 360,
                    1, -1)
        sm = (m > 0) & ~ink
        img[sm] = img[sm] * 0.4 + SMEAR_RGB * 0.6
    bg = np.argwhere(~ink)
    for _ in range(int(specks)):
        r, c = bg[rng.integers(len(bg))]
        rad = int(rng.integers(1, max(2, int(np.sqrt(s_min_px) / 8))))
        cv2.circle(img, (int(c), int(r)), rad, tuple(float(v) for v in INK_RGB), -1)
    ink_core = np.argwhere(ndimage.binary_erosion(ink, iterations=2))
    for _ in range(int(pinholes)):
        if len(ink_core) == 0:
            break
        r, c = ink_core[rng.integers(len(ink_core))]
        cv2.circle(img, (int(c), int(r)), 1, tuple(float(v) for v in PAPER_RGB), -1)
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), float(blur_px))
    if noise_sigma > 0:
        img = img + rng.normal(0, noise_sigma, img.shape).astype(np.float32)
    rgb = np.clip(np.round(img), 0, 255).astype(np.uint8)
    if jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        rgb = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()

    # --- truth tables (schema.py)
    mm_per_l = rod_length_mm
    jt = analysis.junctions
    jpx = to_px(jt[["x", "y"]].to_numpy(float)) if len(jt) else np.zeros((0, 2))
    junctions = pd.DataFrame({"junction_id": jt["junction_id"].astype(int) if len(jt) else [],
                              "x_px": jpx[:, 0], "y_px": jpx[:, 1],
                              "n_stacks": jt["n_stacks"].astype(int) if len(jt) else []})
    regions = []
    srows = []
    for sid, row in st.iterrows():
        line = lines_px[sid]
        region = "bulk"
        if hole_c is not None:
            r = np.hypot(line[:, 0] - hole_c[0], line[:, 1] - hole_c[1])
            if np.any(r >= hole_px - float(width(row.n_br)) * px_per_mm - 2 * thickness_mm * px_per_mm):
                region = "periphery"
        regions.append(region)
        closed = (row.junction_a < 0 and row.junction_b < 0 and len(line) > 3
                  and np.allclose(line[0], line[-1]))
        mid = _loop_mid(line) if closed else _point_at_half(line)
        srows.append({"stack_id": int(sid), "junction_a": int(row.junction_a),
                      "junction_b": int(row.junction_b), "length_mm": _poly_len(line) / px_per_mm,
                      "width_mm": float(width(row.n_br)), "n_br": int(row.n_br),
                      "region": region, "mid_x_px": float(mid[0]), "mid_y_px": float(mid[1])})
    stacks = pd.DataFrame(srows, columns=schema.STACK_COLUMNS)
    br = analysis.branches
    branches = pd.DataFrame({
        "branch_id": br["branch_id"].astype(int), "stack_id": br["stack_id"].astype(int),
        "length_mm": br["length"] * mm_per_l, "kappa_pm": br["kappa_pm"] / mm_per_l,
        "kappa_plus": br["kappa_plus"] / mm_per_l, "kappa_m": br["kappa_pm"].abs() / mm_per_l,
        # e = L int kappa^2 ds is scale free: the simulation's bending energy of the branch
        "energy": br["energy_bending"],
        "region": [regions[s] for s in br["stack_id"]],
        "energy_confinement": br["energy_confinement"], "s_start": br["s_start"],
        "s_end": br["s_end"]})
    vrows = []
    lab_e, ne = ndimage.label(enclosed)
    touch_px = 0.5 * float(width(n_max)) * px_per_mm + 2 * thickness_mm * px_per_mm
    for i, sl in enumerate(ndimage.find_objects(lab_e), start=1):
        region = lab_e[sl] == i
        area = int(region.sum())
        if area < s_min_px:
            continue
        per = contour_perimeter_px(region)
        cy, cx = np.argwhere(region).mean(axis=0) + [sl[0].start, sl[1].start]
        dd = ndimage.distance_transform_edt(lab_e != i) if len(jpx) else None
        n_edges = int(sum(1 for (x, y) in jpx if 0 <= int(round(y)) < h_px and
                          0 <= int(round(x)) < w_px and dd[int(round(y)), int(round(x))] <= touch_px))
        vrows.append({"void_id": len(vrows), "area_mm2": area / px_per_mm ** 2,
                      "perimeter_mm": per / px_per_mm,
                      "shape_ratio": np.sqrt(area) / per if per > 0 else np.nan,
                      "n_edges": n_edges, "centroid_x_px": float(cx), "centroid_y_px": float(cy)})
    voids = pd.DataFrame(vrows, columns=schema.VOID_COLUMNS)

    ys, xs = np.nonzero(ink)
    if len(xs):
        (ccx, ccy), rad = cv2.minEnclosingCircle(np.c_[xs, ys].astype(np.float32))
    else:
        ccx = ccy = rad = 0.0
    hole = ({"center_x_px": float(hole_c[0]), "center_y_px": float(hole_c[1]),
             "radius_px": float(hole_px)} if hole_c is not None else
            {"center_x_px": float(ccx), "center_y_px": float(ccy), "radius_px": float(rad)})
    n_branches = int(stacks["n_br"].sum()) if len(stacks) else 0
    summary = {
        "n_junctions": int(len(junctions)), "n_stacks": int(len(stacks)),
        "n_branches": n_branches, "n_voids": int(len(voids)),
        "mean_branches_per_stack": n_branches / len(stacks) if len(stacks) else 0.0,
        "rod_length_mm": float(rod_length_mm),
        # the scan's compaction rate L / (2 pi R), R the hole (or the enclosing disk of the ink)
        "epsilon": float(rod_length_mm / (2 * np.pi * hole["radius_px"] / px_per_mm))
        if hole["radius_px"] > 0 else None,
        # bending only: the confinement term has no counterpart in a scan
        "total_energy": float(analysis.energy_bending),
        "hole": hole, "timings_s": {},
        "epsilon_rg": analysis.epsilon, "epsilon_rg_sqrt2": analysis.epsilon_sqrt2,
        "rg": analysis.rg, "energy_confinement": analysis.energy_confinement,
        "contact_distance": delta,
    }
    params = {"px_per_mm": float(px_per_mm), "thickness_mm": float(thickness_mm),
              "hole_radius_mm": hole_radius_mm,
              "hole_center_px": None if hole_c is None else [float(hole_c[0]), float(hole_c[1])],
              "seed": int(seed), "rod_length_mm": float(rod_length_mm),
              "contact_distance": delta, "gap_guaranteed": bool(gap_ok),
              "noise_sigma": noise_sigma, "blur_px": blur_px, "jpeg_quality": jpeg_quality,
              "smears": smears, "specks": specks, "pinholes": pinholes,
              "origin_xy": lo.tolist(), "margin_px": float(margin_px)}
    tables = {"junctions": junctions, "stacks": stacks, "branches": branches, "voids": voids}
    return RenderedScene(rgb=rgb, summary=summary, tables=tables, params=params,
                         calibration=cal_df, ink_mask=ink)


def write_scene(scene: RenderedScene, folder) -> Path:
    """Write the scene folder of docs/design.md: image.png, params.json, calibration.csv, truth/."""
    import cv2

    from crosssection.core.fileio import atomic_path

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_path(folder / "image.png") as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(scene.rgb[..., ::-1])):
            raise ConfigError("cannot write image", folder / "image.png")
    write_csv(folder / "calibration.csv", scene.calibration)
    write_json(folder / "params.json", scene.params)
    schema.write_tables(folder / "truth", scene.summary, scene.tables)
    return folder


def render_directory(sim_dir, out_dir, *, configs=None, **kwargs) -> list[Path]:
    """Render every configuration of ``sim_dir/rods.npz`` into ``out_dir/<key>/``.

    ``sim_dir/params.json`` gives ``lambda`` (default 7e5) and optionally ``contact_distance``.
    Scenes already complete (truth/summary.json present) are skipped.
    """
    sim_dir, out_dir = Path(sim_dir), Path(out_dir)
    rods_path = sim_dir / "rods.npz"
    if not rods_path.exists():
        raise ConfigError("no rods.npz (run `python -m simulate quench` first)", rods_path)
    lam = 7e5
    delta = None
    pj = sim_dir / "params.json"
    if pj.exists():
        try:
            p = json.loads(pj.read_text())
        except json.JSONDecodeError as exc:
            raise ConfigError(f"malformed JSON ({exc.msg})", pj) from None
        lam = float(p.get("lambda", p.get("lam", lam)))
        delta = p.get("contact_distance")
    written = []
    with np.load(rods_path) as rods:
        keys = sorted(rods.files) if configs is None else [k for k in sorted(rods.files)
                                                           if k in set(configs)]
        base_seed = int(kwargs.pop("seed", 0))
        for i, key in enumerate(keys):
            folder = out_dir / key
            if (folder / "truth" / "summary.json").exists():
                written.append(folder)
                continue
            xy = np.asarray(rods[key], float)
            if xy.ndim != 2 or xy.shape[1] != 2:
                raise ConfigError(f"array {key!r} has shape {xy.shape}, expected (N+1, 2)",
                                  rods_path)
            an = analyze_rod(xy, lam=lam, contact_distance=delta)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                scene = render_configuration(xy, an, seed=base_seed + i, **kwargs)
            written.append(write_scene(scene, folder))
    return written


def add_subparser(sub) -> None:
    """Register ``render``: ``python -m simulate render DIR --out SCENES [...]``."""
    p = sub.add_parser("render", help="render simulated configurations into synthetic scans",
                       description="Render DIR/rods.npz (one scene per configuration) into "
                                   "scene folders with exact truth.")
    p.add_argument("sim_dir", metavar="DIR")
    p.add_argument("--out", required=True, metavar="SCENES")
    p.add_argument("--px-per-mm", type=float, default=50.0)
    p.add_argument("--thickness-mm", type=float, default=0.1)
    p.add_argument("--rod-length-mm", type=float, default=None,
                   help="default: smallest keeping a visible gap between passes beyond delta")
    p.add_argument("--noise", type=float, default=0.0, help="Gaussian noise sigma (grey levels)")
    p.add_argument("--blur", type=float, default=0.0, help="Gaussian blur sigma (px)")
    p.add_argument("--jpeg", type=int, default=None, help="JPEG quality of a round trip")
    p.add_argument("--smears", type=int, default=0)
    p.add_argument("--specks", type=int, default=0)
    p.add_argument("--pinholes", type=int, default=0)
    p.add_argument("--hole", default="auto",
                   help="hole radius in mm, 'auto' (smallest disk around the rod, default) "
                        "or 'none' (the pipeline then fits one)")
    p.add_argument("--limit", type=int, default=None, help="render only the first K configs")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_run)


def _hole_arg(text):
    if text is None or str(text).lower() in ("none", "null", ""):
        return None
    if str(text).lower() == "auto":
        return "auto"
    try:
        return float(text)
    except ValueError:
        raise ParameterError(f"--hole must be a number, 'auto' or 'none', got {text!r}") from None


def _run(args) -> int:
    configs = None
    if args.limit is not None:
        with np.load(Path(args.sim_dir) / "rods.npz") as rods:
            configs = sorted(rods.files)[: args.limit]
    out = render_directory(args.sim_dir, args.out, configs=configs, px_per_mm=args.px_per_mm,
                           thickness_mm=args.thickness_mm, rod_length_mm=args.rod_length_mm,
                           noise_sigma=args.noise, blur_px=args.blur, jpeg_quality=args.jpeg,
                           smears=args.smears, specks=args.specks, pinholes=args.pinholes,
                           seed=args.seed, hole_radius_mm=_hole_arg(args.hole))
    print(f"{len(out)} scenes in {args.out}")
    return 0
