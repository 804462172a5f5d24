"""Rod ends inside bands: junctions where conservation holds up to one layer
(crosssection.analyze on a drawn scan; :func:`crosssection.linsys.equations.rod_end_junctions`).
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

import crosssection
from crosssection.core.calibration import Calibration
from crosssection.linsys import solve_branch_counts

PX_PER_MM = 50.0
SHIFT = 4  # cv2 drawing at 1/16 px
H_MM = 0.22  # one layer, drawn 11 px wide
#: every band is one layer drawn h wide: the law n h is the scans' calibration
CALIBRATION = Calibration.linear(H_MM)
#: the side rings (drawn so that the width noise is measured on five stacks) and the lone
#: segment are separate networks, closed loops and isolated pieces, which NetworkWarning
#: rightly reports; these tests check the junctions and the rod ends
DRAWN_EXTRAS = pytest.mark.filterwarnings("ignore::crosssection.quality.NetworkWarning")


def _pt(p) -> tuple:
    return tuple(int(v) for v in np.round(np.asarray(p, float) * 2 ** SHIFT))


def _ring_and_chord(span_deg: float, *, size=760, ring_px=170, band_px=9, side_ring_px=75):
    """A single sheet (ring) with a chord of the same sheet whose two ends abut the ring,
    ``span_deg`` apart on it, and two single-sheet rings beside it (so that the width noise
    is measured on five stacks). Returns the RGB image, the hole centre (x, y) px and radius
    px.

    One rod draws the ring and the chord: from its first end, abutting the ring at P, along
    the chord to Q, round the whole ring and back to Q, where its second end abuts the chord.
    The skeleton sees two junctions of three single sheets: one layer ends at each.
    """
    mask = np.zeros((size, size), np.uint8)
    c = np.array([size / 2, size / 2])
    cv2.circle(mask, _pt(c), int(ring_px * 2 ** SHIFT), 1, band_px, cv2.LINE_8, SHIFT)
    for dx in (-290, 290):
        cv2.circle(mask, _pt(c + [dx, 0]), int(side_ring_px * 2 ** SHIFT), 1, band_px,
                   cv2.LINE_8, SHIFT)
    a = np.radians([200.0, 200.0 + span_deg])
    ends = c + ring_px * np.stack([np.cos(a), np.sin(a)], axis=1)
    cv2.line(mask, _pt(ends[0]), _pt(ends[1]), 1, band_px, cv2.LINE_8, SHIFT)
    rgb = np.full((size, size, 3), 245, np.uint8)
    rgb[mask > 0] = (40, 70, 190)
    return rgb, (size / 2, size / 2), 0.49 * size


@DRAWN_EXTRAS
@pytest.mark.parametrize("span_deg", [120.0, 140.0])
def test_free_ends_abutting_a_sheet_leave_every_stack_one_layer(span_deg):
    # three single sheets at each T (1 + 1 + 1 layers: odd, no pack partition conserves);
    # exact conservation there made one of the three stacks two layers. The widths (one
    # layer, drawn 11 px wide: h = 0.22 mm) say where the rod's two ends lie.
    rgb, centre, radius_px = _ring_and_chord(span_deg)
    res = crosssection.analyze(rgb, px_per_mm=PX_PER_MM, thickness_mm=H_MM,
                               calibration=CALIBRATION,
                               hole_center_px=centre, hole_radius_mm=radius_px / PX_PER_MM)
    st = res.stacks
    assert res.summary["n_junctions"] == 2
    assert len(st) == 5  # ring halves, chord, two side rings
    np.testing.assert_allclose(st["layers_est"], 1.0, atol=0.1)
    np.testing.assert_array_equal(st["n_br"], 1)
    ends = [j for c in res.linear_system.components for j in c.rod_end_junctions]
    assert sorted(ends) == [0, 1]
    assert any(f.startswith("rod-end-junctions") for f in res.linear_system.flags)
    # one layer ends at each junction: a residual of one, which conservation allows there
    assert set(np.abs(res.junctions["conservation_residual"])) == {1}
    assert res.junctions["conservation_ok"].all()
    assert not [f for f in res.quality if f.code == "linear_system"]
    # without rod ends to place (rod_ends=0), conservation makes one stack two layers
    old = solve_branch_counts(res.graph, res.packs, st["layers_est"].to_numpy(float),
                              rod_ends=0)
    assert sorted(old.n_br.tolist()) == [1, 1, 1, 1, 2]


@DRAWN_EXTRAS
def test_rod_ends_seen_as_free_ends_are_not_placed_at_junctions():
    # the same scan with two free ends of the skeleton elsewhere (a single sheet cut by
    # nothing: a segment): both rod ends are accounted for, the junctions keep their equation
    rgb, centre, radius_px = _ring_and_chord(120.0)
    mask = np.zeros(rgb.shape[:2], np.uint8)
    cv2.line(mask, (340, 700), (420, 700), 1, 9)
    rgb[mask > 0] = (40, 70, 190)
    # conservation then makes one single sheet two layers, against its width: said, rightly
    with pytest.warns(crosssection.quality.LinearSystemWarning, match="own width reads"):
        res = crosssection.analyze(rgb, px_per_mm=PX_PER_MM, thickness_mm=H_MM,
                                   calibration=CALIBRATION,
                                   hole_center_px=centre, hole_radius_mm=radius_px / PX_PER_MM)
    assert sum(1 for k in res.graph.node_kind.values() if k == "end") == 2
    assert all(not c.rod_end_junctions for c in res.linear_system.components)
    assert "count_width" in res.summary["quality"]["codes"]
