#!/usr/bin/env python
"""Tight bends far from any junction: a band of 1 or 2 sheets making a U-turn.

Each scan draws one band (``n`` sheets of h = 0.1 mm, 50 px/mm, 4x supersampled, blur 1 px,
noise 3) as two straight arms 4 mm long joined by a half circle of centreline radius r (with
``--turn-deg``: an arc turning by that angle), and analyses it with default settings (hole
and calibration w = n h given). The truth of ``int kappa^2 ds`` is the arcs' (turn / r per
sheet, each sheet at its own radius); the straight arms hold none. Prints the measured total
(summary.json ``total_energy`` over the rod length used), the truth and the relative error per
radius; with ``--raw``, the measured total is the profile's ``int kappa^2 ds`` before the
scan's noise floor is removed (one stack per scan: a floor measured on it reads its bend).

Usage: python benchmarks/u_turns.py [--radii 0.3,0.4,0.5,0.75,1,1.5] [--layers 1,2]
       [--turn-deg 180] [--raw] [--curvature-method walls]
"""
from __future__ import annotations

import argparse
import sys
import warnings

import numpy as np

PX_PER_MM = 50.0
H_MM = 0.1


def _band_scan(pts_mm: np.ndarray, n_layers: int, seed: int):
    """The RGB scan of a band of ``n_layers`` sheets along the polyline ``pts_mm`` (x, y) mm
    about the scan's centre, and that centre (x, y) px (module docstring)."""
    import cv2

    size, ss = 700, 4
    centre = np.array([size / 2 + 0.3, size / 2 - 0.2])
    big = np.zeros((size * ss, size * ss), np.uint8)
    q = ((pts_mm * PX_PER_MM + centre) * ss * 16).round().astype(np.int32)
    cv2.polylines(big, [q.reshape(-1, 1, 2)], False, 255,
                  thickness=int(round(n_layers * H_MM * PX_PER_MM * ss)), lineType=cv2.LINE_AA,
                  shift=4)
    cover = cv2.resize(big.astype(np.float32) / 255, (size, size), interpolation=cv2.INTER_AREA)
    ink, paper = np.array([55.0, 80.0, 175.0]), np.full(3, 242.0)
    img = paper * (1 - cover[..., None]) + ink * cover[..., None]
    img = cv2.GaussianBlur(img, (0, 0), 1.0) + np.random.default_rng(seed).normal(0, 3, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8), centre


def u_turn_scan(r_mm: float, n_layers: int, *, arm_mm: float = 4.0, seed: int = 1):
    """The RGB scan of one U-turn band and its centre (x, y) px (module docstring)."""
    arm = np.linspace(-arm_mm, 0.0, 400)
    turn = np.linspace(np.pi, 0.0, 2000)
    pts = np.concatenate([np.column_stack([np.full_like(arm, -r_mm), arm]),
                          np.column_stack([r_mm * np.cos(turn), r_mm * np.sin(turn)]),
                          np.column_stack([np.full_like(arm, r_mm), arm[::-1]])])
    return _band_scan(pts, n_layers, seed)


def bend_scan(r_mm: float, n_layers: int, turn_rad: float, *, arm_mm: float = 4.0,
              seed: int = 1):
    """The RGB scan of one band bending by ``turn_rad`` on an arc of centreline radius
    ``r_mm`` between straight arms, and its centre (x, y) px (as :func:`u_turn_scan`)."""
    arm = np.column_stack([np.linspace(-arm_mm, 0.0, 400), np.zeros(400)])
    t = np.linspace(0.0, turn_rad, 2000)
    arc = np.column_stack([r_mm * np.sin(t), r_mm * (1.0 - np.cos(t))])
    out = arc[-1] + np.linspace(0.0, arm_mm, 400)[:, None] * np.array(
        [np.cos(turn_rad), np.sin(turn_rad)])
    pts = np.concatenate([arm, arc, out])
    return _band_scan(pts - pts.mean(axis=0), n_layers, seed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--radii", default="0.3,0.4,0.5,0.75,1,1.5")
    ap.add_argument("--layers", default="1,2")
    ap.add_argument("--turn-deg", type=float, default=180.0)
    ap.add_argument("--raw", action="store_true",
                    help="int kappa^2 ds of the profile, before the noise floor is removed")
    ap.add_argument("--curvature-method", default=None)
    args = ap.parse_args(argv)
    import pandas as pd

    from crosssection import analyze

    cal = pd.DataFrame({"n_layers": np.arange(1, 9), "width_mm": np.arange(1, 9) * H_MM})
    extra = {} if args.curvature_method is None else {"curvature_method": args.curvature_method}
    for n in (int(v) for v in args.layers.split(",")):
        for r in (float(v) for v in args.radii.split(",")):
            turn = np.radians(args.turn_deg)
            img, c = (u_turn_scan(r, n) if args.turn_deg == 180.0 else
                      bend_scan(r, n, turn))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = analyze(img, px_per_mm=PX_PER_MM, thickness_mm=H_MM, calibration=cal,
                              hole_radius_mm=6.5, hole_center_px=(float(c[0]), float(c[1])),
                              **extra)
            s = res.summary
            measured = s["total_energy"] / s["rod_length_used_mm"]
            if args.raw:
                k, sm = res.profiles[0].kappa_per_mm, res.profiles[0].s_mm
                measured = n * float(np.sum(0.5 * (k[1:] ** 2 + k[:-1] ** 2) * np.diff(sm)))
            # each sheet's arc at its own radius, h apart across the band
            radii = r + H_MM * (np.arange(n) - (n - 1) / 2)
            truth = float(np.sum(turn / radii))
            print(f"{n} sheet(s), {args.turn_deg:g} deg, r = {r:.2f} mm ({r / H_MM:.1f} h): int kappa^2 ds "
                  f"{measured:.2f} for {truth:.2f} ({100 * (measured / truth - 1):+.1f} %), "
                  f"N_br {s['n_branches']}, flags {','.join(s['quality']['codes']) or '-'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
