"""B-063 hull from parameters: geometry against the paper's numbers, FSICR inputs against table 1."""

import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull

import fsicr
from iceresist.errors import InputError
from iceresist.ship.hull import PAPER_TABLE1, b063_hull


@pytest.mark.parametrize("bow", ["A", "B"])
def test_main_dimensions(bow):
    h = b063_hull(bow)
    v = h.vertices()
    assert v[:, 0].max() - v[:, 0].min() == pytest.approx(3.5, abs=1e-12)  # length overall at the deck
    assert v[:, 1].max() - v[:, 1].min() == pytest.approx(0.7, abs=1e-12)
    assert h.waterline_length_m == pytest.approx(1.828 + 2 * 0.35 / math.tan(math.radians(30)), rel=1e-12)
    # the freeboard that makes LOA 3.5 m: 0.4596 m / (cot 30 + cot 45)
    assert h.freeboard_m == pytest.approx((3.5 - 3.040436) / (math.sqrt(3) + 1), abs=1e-6)
    # convex: every vertex is on the hull
    assert len(ConvexHull(v).vertices) == 12


@pytest.mark.parametrize("bow,rake", [("A", 30.0), ("B", 45.0)])
def test_stem_rake_and_buttock(bow, rake):
    """The stem spans T / tan(phi) horizontally (0.762 m at 30 deg, 0.44 m at 45 deg), and so does B/4."""
    h = b063_hull(bow)
    bottom, deck = h._hexagon(0.0), h._hexagon(h.depth_m)
    assert -bottom[0, 0] == pytest.approx(0.44 / math.tan(math.radians(rake)), rel=1e-12)
    # slope of the bow face at y = B/4 between the bottom and the waterline: rake phi2 = phi1
    wl = h._hexagon(h.draught_m)
    x_wl = wl[0, 0] + (wl[1, 0] - wl[0, 0]) * 0.5   # halfway to the shoulder = y = B/4
    x_bt = bottom[0, 0] + (bottom[1, 0] - bottom[0, 0]) * 0.5
    assert math.degrees(math.atan2(h.draught_m, x_wl - x_bt)) == pytest.approx(rake, abs=1e-9)
    assert deck[0, 0] == pytest.approx(h.freeboard_m / math.tan(math.radians(rake)))


def test_volume_prismatoid_matches_convex_hull():
    h = b063_hull("A")
    below = np.vstack([h._hexagon(0.0), h._hexagon(h.draught_m)])
    assert h.volume_m3() == pytest.approx(ConvexHull(below).volume, rel=1e-12)


@pytest.mark.parametrize("bow", ["A", "B"])
def test_fsicr_inputs_against_table1(bow):
    got, paper = b063_hull(bow).fsicr_inputs(), PAPER_TABLE1[bow]
    for key in ("L_m", "LPAR_m", "B_m", "T_m", "alpha_deg", "phi1_deg", "phi2_deg"):
        assert got[key] == pytest.approx(paper[key], abs=0.02), key
    # (L - LPAR)/2 = 15.15 m = (B/2)/tan 30: the wedge bow
    assert got["LBOW_m"] == pytest.approx(15.155, abs=1e-3)
    # the waterplane of the wedge bow is LBOW B / 2 = 132.6 m^2; table 1's 96.25 = B T / 2 (docs/SHIP.md)
    assert got["Awf_m2"] == pytest.approx(132.61, abs=0.01)
    assert paper["Awf_m2"] == pytest.approx(paper["B_m"] * paper["T_m"] / 2)


def test_fsicr_from_geometry_close_to_table2():
    """R_CH from the geometry: 300 / 362 kN against the paper's 293 / 355 kN; the B/A ratio 1.21 holds."""
    ra = fsicr.r_ch(b063_hull("A").fsicr_ship(), "IA").r_ch_N / 1e3
    rb = fsicr.r_ch(b063_hull("B").fsicr_ship(), "IA").r_ch_N / 1e3
    assert ra == pytest.approx(293, rel=0.03) and rb == pytest.approx(355, rel=0.03)
    assert rb / ra == pytest.approx(1.21, abs=0.005)


def test_bad_bow_and_geometry():
    with pytest.raises(InputError, match="bow"):
        b063_hull("C")
    with pytest.raises(InputError, match="freeboard"):
        b063_hull("A", length_overall_m=3.0)
