"""FSICR 2017 calculator: the paper's table 2, an independent hand calculation, clamps, classes, power, validity."""

import dataclasses
import json

import numpy as np
import pytest

from fsicr import formulas
from fsicr.errors import FsicrInputError
from fsicr.power import required_power
from fsicr.resistance import r_ch, r_ch_at_waterlines
from fsicr.rules import parse_ice_class
from fsicr.ship import LowerWaterline, Ship
from fsicr.shipfile import load_ship
from fsicr.validity import validity_values, validity_warnings

# Watanabe, Hu and Aoki (2023), table 2, FSICR column [kN].
PAPER_FSICR_KN = {"b063_bow_a": 293.0, "b063_bow_b": 355.0}


def b063(phi_deg: float, **changes) -> Ship:
    """The paper's table-1 full-scale ship with phi1 = phi2 = phi_deg (30: Bow A, 45: Bow B)."""
    base = dict(L_m=76.0, B_m=17.5, T_m=11.0, LPAR_m=45.7, LBOW_m=15.15, Awf_m2=96.25,
                alpha_deg=30.0, phi1_deg=phi_deg, phi2_deg=phi_deg, Dp_m=6.6)
    base.update(changes)
    return Ship(**base)


@pytest.mark.parametrize("name", sorted(PAPER_FSICR_KN))
def test_table2_within_half_a_percent(name):
    ship, cls, _ = load_ship(name)
    assert cls == "IA"
    res = r_ch(ship, cls)
    paper = PAPER_FSICR_KN[name]
    assert res.r_ch_kN == pytest.approx(paper, rel=5e-3)
    assert res.r_ch_unclamped_N / 1000 == pytest.approx(paper, rel=5e-3)


def test_table2_exact_values_with_and_without_shape_clamp():
    """Rules (clamp to 20) and unclamped (20.34, what the paper's rounding matches), to 0.01 kN."""
    a, b = r_ch(b063(30.0), "IA"), r_ch(b063(45.0), "IA")
    assert a.r_ch_kN == pytest.approx(292.22, abs=0.01)
    assert a.r_ch_unclamped_N / 1e3 == pytest.approx(292.57, abs=0.01)
    assert b.r_ch_kN == pytest.approx(354.54, abs=0.01)
    assert b.r_ch_unclamped_N / 1e3 == pytest.approx(354.90, abs=0.01)
    # Paper: ratio Bow B / Bow A of the FSICR formula 1.21.
    assert b.r_ch_N / a.r_ch_N == pytest.approx(1.21, rel=5e-3)


def test_hand_calculation_bow_a_matches_every_term():
    """Eqs. (22)-(26) written out again with numpy for Bow A, class IA (H_M = 1 m)."""
    L, B, T, LPAR, Awf = 76.0, 17.5, 11.0, 45.7, 96.25
    alpha, phi2, HM = np.radians(30.0), np.radians(30.0), 1.0
    psi = np.arctan(np.tan(phi2) / np.sin(alpha))
    cmu_raw = 0.15 * np.cos(phi2) + np.sin(psi) * np.sin(alpha)
    cmu = max(cmu_raw, 0.45)
    psi_deg = np.degrees(psi)
    cpsi = 0.047 * psi_deg - 2.115 if psi_deg > 45.0 else 0.0
    HF = 0.26 + np.sqrt(HM * B)
    sf_raw = (L * T / B**2) ** 3
    sf = np.clip(sf_raw, 5.0, 20.0)
    t3 = 845.0 * cmu * (HF + HM) ** 2 * (B + cpsi * HF)
    t4 = 42.0 * LPAR * HF**2
    t5 = 825.0 * sf * Awf / L
    expected = {
        "H_M_m": HM, "H_F_m": HF, "psi_deg": psi_deg, "C_mu_unclamped": cmu_raw, "C_mu": cmu,
        "C_psi": cpsi, "LT_over_B2": L * T / B**2, "shape_factor_unclamped": sf_raw, "shape_factor": sf,
        "C1_N": 0.0, "C2_N": 0.0, "C3_term_N": t3, "C4_term_N": t4, "C5_term_N": t5,
        "R_CH_N": t3 + t4 + t5, "R_CH_unclamped_N": t3 + t4 + 825.0 * sf_raw * Awf / L,
    }
    terms = r_ch(b063(30.0), "IA").terms
    for key, value in expected.items():
        assert terms[key] == pytest.approx(value, rel=1e-12, abs=1e-9), key
    # The numbers a reader checks by hand (4 significant figures).
    assert psi_deg == pytest.approx(49.11, abs=0.01)
    assert cmu == pytest.approx(0.5079, abs=1e-4)
    assert cpsi == pytest.approx(0.1930, abs=1e-4)
    assert HF == pytest.approx(4.443, abs=1e-3)
    assert sf_raw == pytest.approx(20.34, abs=0.01)


def test_c_mu_clamp_active_for_a_fine_waterline_angle():
    # alpha = 15 deg, phi2 = 30 deg: psi = 65.85 deg, 0.15 cos 30 + sin psi sin 15 = 0.366 < 0.45.
    assert formulas.psi_deg(15.0, 30.0) == pytest.approx(65.85, abs=0.01)
    assert formulas.c_mu_unclamped(15.0, 30.0) == pytest.approx(0.3661, abs=1e-4)
    assert formulas.c_mu(15.0, 30.0) == 0.45
    terms = r_ch(b063(30.0, alpha_deg=15.0), "IA").terms
    assert terms["C_mu"] == 0.45 and terms["C_mu_unclamped"] < 0.45
    # Not active for Bow A.
    assert formulas.c_mu(30.0, 30.0) == formulas.c_mu_unclamped(30.0, 30.0) > 0.45


def test_c_psi_zero_at_and_below_45_deg():
    # alpha = 30 deg, phi2 = 20 deg: psi = 36.05 deg, where 0.047 psi - 2.115 would be -0.42.
    psi = formulas.psi_deg(30.0, 20.0)
    assert psi == pytest.approx(36.05, abs=0.01)
    assert formulas.c_psi(psi) == 0.0
    assert formulas.c_psi(45.0) == 0.0
    assert formulas.c_psi(45.0 + 1e-9) == pytest.approx(0.0, abs=1e-9)  # continuous at 45 deg
    assert formulas.c_psi(60.0) == pytest.approx(0.047 * 60.0 - 2.115)
    assert r_ch(b063(20.0), "IA").terms["C_psi"] == 0.0


def test_psi_is_90_deg_for_a_vertical_bow():
    assert formulas.psi_deg(30.0, 90.0) == pytest.approx(90.0, abs=1e-12)
    assert formulas.psi_deg(90.0, 45.0) == pytest.approx(45.0, abs=1e-12)


def test_shape_factor_clamped_at_both_ends():
    # Low: L T / B^2 = 65 * 4 / 30^2 = 0.289, cubed 0.024 -> 5.
    assert formulas.shape_factor_unclamped(65.0, 4.0, 30.0) == pytest.approx((65 * 4 / 900) ** 3)
    assert formulas.shape_factor(65.0, 4.0, 30.0) == 5.0
    # High: L T / B^2 = 250 * 15 / 11^2 = 31.0, cubed 29,780 -> 20.
    assert formulas.shape_factor(250.0, 15.0, 11.0) == 20.0
    # Inside: unchanged.
    assert formulas.shape_factor(76.0, 9.0, 17.5) == pytest.approx((76 * 9 / 17.5**2) ** 3)
    wide = r_ch(b063(45.0, B_m=30.0, T_m=4.0), "IA").terms
    assert wide["shape_factor"] == 5.0 and wide["shape_factor_unclamped"] < 5.0
    assert wide["C5_term_N"] == pytest.approx(825.0 * 5.0 * 96.25 / 76.0)


def test_ia_super_adds_c1_c2_other_classes_do_not():
    ship = b063(30.0)
    B, T, L, LPAR, LBOW, phi1 = 17.5, 11.0, 76.0, 45.7, 15.15, 30.0
    c1 = 23 * B * LPAR / (2 * T / B + 1) + (1 + 0.021 * phi1) * (45.8 * B + 14.7 * LBOW + 29 * B * LBOW)
    c2 = (1 + 0.063 * phi1) * (1530 + 170 * B) + 400 * (1 + 1.2 * T / B) * B**2 / np.sqrt(L)
    sup = r_ch(ship, "IA Super")
    assert sup.terms["C1_N"] == pytest.approx(c1, rel=1e-12)
    assert sup.terms["C2_N"] == pytest.approx(c2, rel=1e-12)
    assert c1 == pytest.approx(22_350, rel=1e-3) and c2 == pytest.approx(37_670, rel=1e-3)
    ia = r_ch(ship, "IA")
    assert sup.r_ch_N == pytest.approx(ia.r_ch_N + c1 + c2, rel=1e-12)  # same H_M = 1.0 m
    for cls in ("IA", "IB", "IC"):
        t = r_ch(ship, cls).terms
        assert t["C1_N"] == 0.0 and t["C2_N"] == 0.0


def test_brash_thickness_per_class():
    for cls, hm in (("IA Super", 1.0), ("IA", 1.0), ("IB", 0.8), ("IC", 0.6)):
        t = r_ch(b063(45.0), cls).terms
        assert t["H_M_m"] == hm
        assert t["H_F_m"] == pytest.approx(0.26 + np.sqrt(hm * 17.5))
    assert r_ch(b063(45.0), "IC").r_ch_N < r_ch(b063(45.0), "IB").r_ch_N < r_ch(b063(45.0), "IA").r_ch_N


def test_bulbous_bow_takes_phi1_90():
    plain = r_ch(b063(30.0, phi1_deg=90.0), "IA Super")
    bulb = r_ch(b063(30.0, bulbous_bow=True), "IA Super")
    assert bulb.terms["phi1_used_deg"] == 90.0
    assert bulb.terms["C1_N"] == pytest.approx(plain.terms["C1_N"])
    assert bulb.terms["C2_N"] == pytest.approx(plain.terms["C2_N"])


def test_engine_power_formula_and_ke_table():
    assert formulas.engine_power(292_216.46, 2.03, 6.6) == pytest.approx(2.03 * 292.21646**1.5 / 6.6)
    table = {(1, "cp"): 2.03, (1, "electric"): 2.03, (1, "hydraulic"): 2.03, (1, "fp"): 2.26,
             (2, "cp"): 1.44, (2, "fp"): 1.60, (3, "cp"): 1.18, (3, "fp"): 1.31}
    for (n, kind), value in table.items():
        assert formulas.ke(n, kind) == value
    p = required_power(b063(30.0), "IA")
    assert p.Ke == 2.03
    assert p.required_kW == pytest.approx(2.03 * 292.2164602632128**1.5 / 6.6, rel=1e-9)
    assert p.required_kW == pytest.approx(1536.42, abs=0.01)
    assert p.governing == "upper ice waterline"


def test_class_minimum_governs_a_small_resistance():
    small = Ship(L_m=70.0, B_m=12.0, T_m=5.0, LPAR_m=30.0, LBOW_m=15.0, Awf_m2=100.0,
                 alpha_deg=25.0, phi1_deg=30.0, phi2_deg=50.0, Dp_m=3.5, n_propellers=2, propulsion="cp")
    ic = required_power(small, "IC")
    assert ic.power_by_waterline_kW["upper"] < 1000.0
    assert ic.required_kW == 1000.0 and ic.governing.startswith("class minimum")
    sup = required_power(small, "IA Super")
    assert sup.minimum_kW == 2800.0 and sup.required_kW >= 2800.0
    assert formulas.minimum_power("IB") == 1000.0


def test_both_waterlines_required_is_the_larger():
    ship = b063(45.0, lower=LowerWaterline(T_m=8.0, phi2_deg=60.0, Awf_m2=110.0))
    up, low = r_ch_at_waterlines(ship, "IA")
    assert (up.waterline, low.waterline) == ("upper", "lower")
    assert low.ship.T_m == 8.0 and low.ship.phi2_deg == 60.0 and low.ship.B_m == 17.5
    assert low.terms["shape_factor"] == pytest.approx((76 * 8 / 17.5**2) ** 3)
    p = required_power(ship, "IA")
    kw = {wl: 2.03 * (r.r_ch_N / 1e3) ** 1.5 / 6.6 for wl, r in (("upper", up), ("lower", low))}
    assert dict(p.power_by_waterline_kW) == pytest.approx(kw)
    assert p.required_kW == pytest.approx(max(kw.values()))
    assert p.governing == f"{max(kw, key=kw.get)} ice waterline"
    assert p.governing == "lower ice waterline"  # phi2 = 60 deg at the lower waterline raises C_mu, C_psi
    # Without a lower waterline only the upper one is computed.
    assert len(r_ch_at_waterlines(b063(45.0), "IA")) == 1


def test_validity_warnings_of_the_b063_ship():
    """Each range checked: Bow A violates phi2 and Awf/(L B); Bow B only Awf/(L B)."""
    values = validity_values(b063(30.0))
    assert values["L"] == 76.0 and values["B"] == 17.5 and values["T"] == 11.0 and values["alpha"] == 30.0
    assert values["phi1"] == 30.0
    assert values["LBOW/L"] == pytest.approx(0.1993, abs=1e-4)
    assert values["LPAR/L"] == pytest.approx(0.6013, abs=1e-4)
    assert values["Dp/T"] == pytest.approx(0.6)
    assert values["Awf/(L*B)"] == pytest.approx(0.07237, abs=1e-5)
    a = validity_warnings(b063(30.0))
    assert [w.split(": ")[1].split(" =")[0] for w in a] == ["phi2", "Awf/(L*B)"]
    assert "phi2 = 30 deg" in a[0] and "45-90 deg" in a[0] and "model tests" in a[0]
    assert "0.07237" in a[1] and "0.09-0.27" in a[1]
    b = validity_warnings(b063(45.0))
    assert len(b) == 1 and "Awf/(L*B)" in b[0]
    assert r_ch(b063(45.0), "IA").warnings == b


def test_every_range_reported():
    odd = Ship(L_m=300.0, B_m=45.0, T_m=3.0, LPAR_m=50.0, LBOW_m=20.0, Awf_m2=5000.0,
               alpha_deg=60.0, phi1_deg=20.0, phi2_deg=40.0, Dp_m=3.0)
    names = [w.split(": ")[1].split(" =")[0] for w in validity_warnings(odd, "lower")]
    assert names == ["alpha", "phi1", "phi2", "L", "B", "T", "LBOW/L", "LPAR/L", "Dp/T", "Awf/(L*B)"]
    assert all(w.startswith("lower ice waterline: ") for w in validity_warnings(odd, "lower"))
    assert validity_values(dataclasses.replace(odd, Dp_m=None))["Dp/T"] is None


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"L_m": 0.0}, "L_m (--L): must be in [0.01, 1000] m"),
        ({"B_m": -1.0}, "B_m (--B): must be in [0.01, 1000] m"),
        ({"alpha_deg": 0.0}, "alpha_deg (--alpha): angle must be in (0, 90]"),
        ({"phi2_deg": 95.0}, "phi2_deg (--phi2): angle must be in (0, 90]"),
        ({"T_m": "abc"}, "T_m (--T): must be a number"),
        ({"Awf_m2": float("nan")}, "Awf_m2 (--Awf): must be a finite number"),
        ({"n_propellers": 4}, "must be 1, 2 or 3"),
        ({"propulsion": "sail"}, "propulsion (--propulsion): must be one of cp, fp, electric, hydraulic"),
        ({"Dp_m": 0.0}, "Dp_m (--Dp): propeller diameter must be in [0.01, 1000] m"),
    ],
)
def test_ship_rejects_bad_values(changes, message):
    with pytest.raises(FsicrInputError, match=None) as info:
        b063(30.0, **changes)
    assert message in str(info.value)


def test_lower_waterline_rejects_bad_values():
    with pytest.raises(FsicrInputError, match=r"lower_T_m \(--lower-T\): must be in \[0.01, 1000\] m"):
        LowerWaterline(T_m=-2.0)


def test_power_needs_a_propeller_diameter():
    with pytest.raises(FsicrInputError, match=r"Dp_m \(--Dp\)"):
        required_power(b063(30.0, Dp_m=None), "IA")


@pytest.mark.parametrize("text, expected", [("IA", "IA"), ("1A", "IA"), ("ia super", "IA Super"),
                                            ("IAS", "IA Super"), ("1a-super", "IA Super"), ("ic", "IC")])
def test_ice_class_spellings(text, expected):
    assert parse_ice_class(text) == expected


def test_unknown_ice_class():
    with pytest.raises(FsicrInputError, match="unknown class 'II'; allowed: IA Super, IA, IB, IC"):
        r_ch(b063(30.0), "II")


def test_results_are_frozen_and_serialise():
    res = r_ch(b063(30.0), "IA")
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.r_ch_N = 0.0
    with pytest.raises(TypeError):
        res.terms["R_CH_N"] = 0.0
    d = json.loads(json.dumps(res.to_dict()))
    assert d["terms"]["R_CH_N"] == pytest.approx(res.r_ch_N)
    assert d["ship"]["L_m"] == 76.0 and len(d["warnings"]) == 2
    p = json.loads(json.dumps(required_power(b063(30.0), "IA").to_dict()))
    assert p["required_kW"] == pytest.approx(1536.42, abs=0.01)
