"""Bands bending far from any junction (``benchmarks/u_turns.py``): the scans draw the bend
asked for, and a bend longer than the window reads close to its truth."""
from __future__ import annotations

import re

import numpy as np
import pytest


@pytest.mark.parametrize("turn_deg", [90.0, 180.0])
def test_a_bend_longer_than_the_window_reads_close_to_its_truth(load_script, capsys, turn_deg):
    # one sheet at r = 1.5 mm (an arc of 2.4-4.7 mm, the window 0.5 mm): measured -2.6 %
    # (U-turn) and -4 % (90 degrees)
    script = load_script("u_turns")
    assert script.main(["--radii", "1.5", "--layers", "1", "--turn-deg", str(turn_deg)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith(f"1 sheet(s), {turn_deg:g} deg, r = 1.50 mm")
    err = float(re.search(r"\(([-+][\d.]+) %\)", line).group(1))
    assert -10.0 < err < 5.0


def test_the_bend_scan_draws_its_arms_and_its_turn(load_script):
    script = load_script("u_turns")
    img, centre = script.bend_scan(1.0, 2, np.pi / 2)
    ink = (img[..., 2].astype(int) - img[..., 0]) > 60  # half the ink's contrast
    # two arms of 4 mm and a quarter circle of 1 mm radius, 0.2 mm wide, at 50 px/mm
    length_px = (8.0 + np.pi / 2) * script.PX_PER_MM
    assert abs(ink.sum() / (length_px * 2 * script.H_MM * script.PX_PER_MM) - 1.0) < 0.1
    rows, cols = np.nonzero(ink)
    # the arms run along x and, after the turn, along y: the ink spans about 5 mm each way
    assert 4.5 < np.ptp(cols) / script.PX_PER_MM < 5.6
    assert 4.5 < np.ptp(rows) / script.PX_PER_MM < 5.6


@pytest.mark.parametrize("r_mm, layers", [(0.15, 1), (0.2, 1), (0.3, 2), (0.4, 3)])
def test_a_turn_tighter_than_the_window_reads_close_to_its_truth(load_script, capsys, r_mm,
                                                                 layers):
    # the window turning by 1.25-2 rad over its half: a parabola over the whole U-turn read
    # +71 / +22 / +74 / +92 %; refitted where it turns by 2 rad in all, -3 / -2 / -5 / -5 %
    script = load_script("u_turns")
    assert script.main(["--radii", str(r_mm), "--layers", str(layers), "--raw"]) == 0
    err = float(re.search(r"\(([-+][\d.]+) %\)", capsys.readouterr().out).group(1))
    assert -15.0 < err < 10.0, err
