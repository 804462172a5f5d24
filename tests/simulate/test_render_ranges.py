"""What a render can and cannot promise: a rod length consistent with a compaction's
thickness, the segment counts its truth is validated from, stacks of zero length, and pieces
the truth holds apart that its drawing joins."""
import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from crosssection.core.errors import ParameterError
from simulate.cli import main
from simulate.render import (VALIDATED_COMPACT_SEGMENTS, VALIDATED_QUENCH_SEGMENTS,
                             ScanRangeWarning, TruthWarning, _rod_beyond_validated,
                             _touching_pieces, _zero_length_check, render_configuration)

DATA = Path(__file__).parent / "data"


def _sim(tmp_path, params, n_configs=1, name="quench_rod_5.npy"):
    sim = tmp_path / "sim"
    sim.mkdir()
    xy = np.load(DATA / name)
    np.savez(sim / "rods.npz", **{f"config_{i:05d}": xy for i in range(n_configs)})
    (sim / "params.json").write_text(json.dumps(params))
    return sim


def _caught(fn, *args, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    return out, caught


# --- a rod length against a compaction's thickness ------------------------------------------

def test_a_rod_length_contradicting_the_rods_thickness_is_refused():
    xy = np.load(DATA / "quench_rod_5.npy")
    # 0.1 mm / 100 mm = 1e-3 L: passes drawn half as thick as the 2e-3 L rod
    with pytest.raises(ParameterError, match=r"rod_thickness is 0\.002 L") as err:
        render_configuration(xy, rod_thickness=2e-3, wall_radius=0.1, rod_length_mm=100.0,
                             clean=True)
    assert err.value.path == "rod_length_mm"
    assert "thickness_mm 0.1" in err.value.cause and "50 mm" in err.value.cause


def test_cli_refuses_a_rod_length_the_compaction_contradicts(tmp_path, capsys):
    sim = _sim(tmp_path, {"command": "compact", "thickness": 2e-3, "wall_radius": 0.1})
    out = tmp_path / "s"
    assert main(["render", str(sim), "--out", str(out), "--rod-length-mm", "100"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: --rod-length-mm: 100 with ")
    assert "--thickness-mm 0.1" in err and f"the thickness of {sim / 'params.json'}" in err
    assert "is 0.002 L" in err
    assert not out.exists()


def test_cli_takes_a_rod_length_the_compaction_agrees_with(tmp_path, capsys):
    sim = _sim(tmp_path, {"command": "compact", "thickness": 2e-3, "wall_radius": 0.1})
    out = tmp_path / "s"
    # 0.2 mm / 100 mm = 2e-3 L: the compaction's thickness
    assert main(["render", str(sim), "--out", str(out), "--rod-length-mm", "100",
                 "--thickness-mm", "0.2", "--clean"]) == 0
    params = json.loads((out / "config_00000" / "params.json").read_text())
    assert params["rod_length_mm"] == 100.0


# --- the segment counts the truth is validated from -----------------------------------------

def test_the_validated_segment_counts():
    assert _rod_beyond_validated(VALIDATED_QUENCH_SEGMENTS, compaction=False) is None
    assert _rod_beyond_validated(VALIDATED_COMPACT_SEGMENTS, compaction=True) is None
    assert "validated from 300 segments on a quench's rod, this one has 299" in \
        _rod_beyond_validated(299, compaction=False)
    # a compaction is validated from more segments than a quench
    assert "validated from 2000 segments on a compaction's rod, this one has 1999" in \
        _rod_beyond_validated(1999, compaction=True)


def test_a_short_rod_is_a_scan_range_warning():
    xy = np.load(DATA / "quench_rod_n100_seed1.npy")
    _, caught = _caught(render_configuration, xy, clean=True)
    ranges = [str(w.message) for w in caught if w.category is ScanRangeWarning]
    assert ranges == [_rod_beyond_validated(len(xy) - 1, compaction=False)]
    _, caught = _caught(render_configuration, np.load(DATA / "quench_rod_n300_seed1.npy"),
                        clean=True)
    assert not [w for w in caught if w.category is ScanRangeWarning]


def test_cli_warns_a_short_rod_once_per_run(tmp_path, capsys):
    sim = _sim(tmp_path, {"command": "quench", "lam": 3e4}, n_configs=2,
               name="quench_rod_n100_seed1.npy")
    out = tmp_path / "s"
    assert main(["render", str(sim), "--out", str(out), "--clean"]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "validated from" in ln]
    assert lines == [f"warning: {out}: the render's truth is validated from 300 segments on "
                     "a quench's rod, this one has 100: its truth's stacks may hold another "
                     "rod length than the rod's, with stacks of zero length, and its energy "
                     "errors are not the analysis'"]


# --- a truth stack of zero length -----------------------------------------------------------

def test_a_stack_of_zero_length_is_named():
    stacks = pd.DataFrame({"stack_id": [0, 1, 2], "n_br": [1, 2, 3],
                           "length_mm": [4.0, 0.0, 2.0]})
    assert _zero_length_check(stacks) == ("truth stack 1 (n_br 2) has length 0: branches "
                                          "without rod, which no image shows")
    assert _zero_length_check(stacks.assign(length_mm=1.0)) is None


def test_a_render_with_a_stack_of_zero_length_warns(monkeypatch):
    from simulate import render

    tables = render._truth_tables

    def zero_first(*args, **kwargs):
        out = tables(*args, **kwargs)
        out["stacks"].loc[0, "length_mm"] = 0.0
        return out

    monkeypatch.setattr(render, "_truth_tables", zero_first)
    sc, caught = _caught(render_configuration, np.load(DATA / "quench_rod_n300_seed1.npy"),
                         clean=True)
    truth = [str(w.message) for w in caught if w.category is TruthWarning]
    assert any(m.startswith("truth stack 0 (n_br ") and "has length 0" in m for m in truth)
    assert any("has length 0" in m for m in sc.summary["truth_warnings"])


# --- pieces the truth holds apart -----------------------------------------------------------

def _stacks(ends, n_br=1):
    return pd.DataFrame({"stack_id": range(len(ends)), "junction_a": [a for a, _ in ends],
                         "junction_b": [b for _, b in ends], "n_br": n_br})


def _line(x0, y0, x1, y1, n=50):
    return np.column_stack([np.linspace(x0, x1, n), np.linspace(y0, y1, n)])


def test_unrelated_bands_closer_than_the_gap_touch():
    lines = [_line(0, 0, 100, 0), _line(0, 8, 100, 8)]
    widths = np.array([7.0, 7.0])
    # 8 px apart, 1 px of paper between 7 px bands: less than a 2 px gap
    hits = _touching_pieces(_stacks([(-1, -1), (-1, -1)]), lines, widths, gap_px=2.0)
    assert [(a, b) for a, b, _, _ in hits] == [(0, 1)]
    # 12 px apart: 5 px of paper
    lines[1] = _line(0, 12, 100, 12)
    assert _touching_pieces(_stacks([(-1, -1), (-1, -1)]), lines, widths, gap_px=2.0) == []


def test_bands_of_one_junction_may_touch_near_it():
    # within the end zones (3 x (widest band + 2 gaps) = 33 px) of the junction ends
    lines = [_line(0, 0, 30, 0), _line(0, 8, 30, 8)]
    widths = np.array([7.0, 7.0])
    assert _touching_pieces(_stacks([(0, 1), (1, 2)]), lines, widths, gap_px=2.0) == []
    # linked through one stack (junctions 0-1): one junction cluster
    lines.append(_line(200, 0, 300, 0))
    assert _touching_pieces(_stacks([(0, 5), (1, 6), (0, 1)]), lines, np.full(3, 7.0),
                            gap_px=2.0) == []


def test_a_rod_end_curled_back_onto_its_neighbour_touches_it():
    """A free end of a stack of junction 0 lying on the middle of another stack of junction
    0: related stacks, but they touch far from any junction end of either, where the image
    shows a fork the truth does not have."""
    t = np.linspace(0, np.pi, 200)
    trunk = _line(0, 0, 300, 0, n=300)
    # from junction 0 (0, 0) up and round, its free end down onto the trunk at x = 150
    curl = np.concatenate([_line(0, 0, 0, 60, n=60),
                           np.column_stack([75 - 75 * np.cos(t), 60 + 75 * np.sin(t)]),
                           _line(150, 60, 150, 8, n=50)])
    hits = _touching_pieces(_stacks([(0, 1), (0, -1)]), [trunk, curl], np.array([7.0, 7.0]),
                            gap_px=2.0)
    assert [(a, b) for a, b, _, _ in hits] == [(0, 1)]
    assert abs(hits[0][2] - 150) < 10
    # the same end stopping short of the trunk by more than the gap: apart
    short = curl[curl[:, 1] > 20]
    assert _touching_pieces(_stacks([(0, 1), (0, -1)]), [trunk, short], np.array([7.0, 7.0]),
                            gap_px=2.0) == []


def test_a_band_bending_back_onto_itself_touches_itself():
    t = np.linspace(0, 1, 300)
    # a hairpin whose arms lie 8 px apart, far along the line from each other
    u_turn = np.concatenate([_line(100, 0, 0, 0), _line(0, 8, 100, 8)])
    hits = _touching_pieces(_stacks([(-1, -1)]), [u_turn], np.array([7.0]), gap_px=2.0)
    assert [(a, b) for a, b, _, _ in hits] == [(0, 0)]
    arc = np.column_stack([200 * np.cos(np.pi * t), 200 * np.sin(np.pi * t)])
    assert _touching_pieces(_stacks([(-1, -1)]), [arc], np.array([7.0]), gap_px=2.0) == []
    # a short hairpin at a junction end: a hook curled into its junction point
    hook = np.concatenate([_line(20, 0, 0, 0), _line(0, 8, 20, 8)])
    assert _touching_pieces(_stacks([(-1, -1)]), [hook], np.array([7.0]), gap_px=2.0) != []
    assert _touching_pieces(_stacks([(0, -1)]), [hook], np.array([7.0]), gap_px=2.0) == []
    # a band of two passes out to a fold and back
    assert _touching_pieces(_stacks([(-1, -1)], n_br=2), [u_turn], np.array([7.0]),
                            gap_px=2.0) == []


def test_a_rod_end_brushing_the_rod_is_no_guaranteed_gap():
    """A rod end 0.2 delta from the rod, over a contact shorter than the analysis' shortest
    run: the truth is one free stack, the drawing joins the end to the rod in a Y."""
    xy = np.load(DATA / "quench_rod_end_brushing.npy")
    sc, caught = _caught(render_configuration, xy, lam=3e3, seed=7, plate="dark",
                          hole_radius_mm="auto")
    assert len(sc.tables["stacks"]) == 1 and sc.tables["junctions"].empty
    truth = [str(w.message) for w in caught if w.category is TruthWarning]
    assert len(truth) == 1 and truth[0].startswith(
        "pieces the truth holds apart touch in the drawing (stack 0 touches itself at")
    assert sc.summary["truth_warnings"] == truth
    # a quenched rod of fewer segments than the truth is validated from: its range recorded
    coarse = [str(w.message) for w in caught if "render's truth is validated from" in
              str(w.message)]
    assert sc.summary["truth_range"] == (coarse[0] if coarse else None)
    assert sc.params["gap_guaranteed"] is False


def test_a_render_without_touching_pieces_keeps_its_gap():
    sc, caught = _caught(render_configuration, np.load(DATA / "quench_rod_n300_seed1.npy"),
                         clean=True)
    assert not any("touch in the drawing" in str(w.message) for w in caught)
    assert sc.params["gap_guaranteed"] is True
