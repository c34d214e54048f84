"""The FSICR 2017 brash-ice channel resistance, one function per quantity.

Equation numbers are those of Watanabe, Hu and Aoki (2023), who quote FSICR 2017 section
3.2.2. Lengths in m, areas in m^2, angles in degrees, forces in N, power in kW.
"""

from __future__ import annotations

import math

from . import rules
from .errors import FsicrInputError


def psi_deg(alpha_deg: float, phi2_deg: float) -> float:
    """psi = arctan(tan phi2 / sin alpha) [deg] (eq. 26); exact 90 deg at phi2 = 90 deg."""
    a, p2 = math.radians(alpha_deg), math.radians(phi2_deg)
    return math.degrees(math.atan2(math.sin(p2), math.cos(p2) * math.sin(a)))


def c_mu_unclamped(alpha_deg: float, phi2_deg: float) -> float:
    """0.15 cos phi2 + sin psi sin alpha, before the lower bound (eq. 23)."""
    psi = math.radians(psi_deg(alpha_deg, phi2_deg))
    return 0.15 * math.cos(math.radians(phi2_deg)) + math.sin(psi) * math.sin(math.radians(alpha_deg))


def c_mu(alpha_deg: float, phi2_deg: float) -> float:
    """C_mu of eq. (23) with the rules' bound C_mu >= 0.45."""
    return max(rules.C_MU_MIN, c_mu_unclamped(alpha_deg, phi2_deg))


def c_psi(psi: float) -> float:
    """C_psi = 0.047 psi - 2.115 (psi in degrees), and 0 where psi <= 45 deg (eq. 24) [m/m]."""
    if psi <= rules.PSI_CPSI_ZERO_DEG:
        return 0.0
    return 0.047 * psi - 2.115


def hm_for_class(ice_class: str) -> float:
    """Brash-ice thickness in mid channel H_M [m] of an ice class."""
    return rules.HM_BY_CLASS_M[rules.parse_ice_class(ice_class)]


def brash_thickness_HF(HM_m: float, B_m: float) -> float:
    """Thickness of the brash-ice layer displaced by the bow H_F = 0.26 + (H_M B)^0.5 [m] (eq. 25)."""
    return 0.26 + math.sqrt(HM_m * B_m)


def shape_ratio(L_m: float, T_m: float, B_m: float) -> float:
    """L T / B^2 [-]."""
    return L_m * T_m / B_m**2


def shape_factor_unclamped(L_m: float, T_m: float, B_m: float) -> float:
    """(L T / B^2)^3 before the rules' bounds [-]."""
    return shape_ratio(L_m, T_m, B_m) ** 3


def shape_factor(L_m: float, T_m: float, B_m: float) -> float:
    """(L T / B^2)^3 taken not less than 5 and not more than 20 (FSICR 2017, 3.2.2)."""
    return min(rules.SHAPE_FACTOR_MAX, max(rules.SHAPE_FACTOR_MIN, shape_factor_unclamped(L_m, T_m, B_m)))


def _is_ia_super(ice_class: str) -> bool:
    return rules.parse_ice_class(ice_class) == "IA Super"


def c1(ice_class: str, B_m: float, T_m: float, LPAR_m: float, LBOW_m: float, phi1_deg: float) -> float:
    """Consolidated-layer term C1 [N]; zero except for IA Super (FSICR 2017, 3.2.2).

    C1 = f1 B LPAR / (2T/B + 1) + (1 + 0.021 phi1)(f2 B + f3 LBOW + f4 B LBOW), phi1 in degrees.
    """
    if not _is_ia_super(ice_class):
        return 0.0
    return rules.F1 * B_m * LPAR_m / (2.0 * T_m / B_m + 1.0) + (1.0 + 0.021 * phi1_deg) * (
        rules.F2 * B_m + rules.F3 * LBOW_m + rules.F4 * B_m * LBOW_m
    )


def c2(ice_class: str, B_m: float, T_m: float, L_m: float, phi1_deg: float) -> float:
    """Consolidated-layer term C2 [N]; zero except for IA Super (FSICR 2017, 3.2.2).

    C2 = (1 + 0.063 phi1)(g1 + g2 B) + g3 (1 + 1.2 T/B) B^2 / sqrt(L), phi1 in degrees.
    """
    if not _is_ia_super(ice_class):
        return 0.0
    return (1.0 + 0.063 * phi1_deg) * (rules.G1 + rules.G2 * B_m) + rules.G3 * (1.0 + 1.2 * T_m / B_m) * B_m**2 / math.sqrt(L_m)


def channel_term_C3(c_mu_value: float, HF_m: float, HM_m: float, B_m: float, c_psi_value: float) -> float:
    """Brash-ice term C3 C_mu (H_F + H_M)^2 (B + C_psi H_F) [N] of eq. (22)."""
    return rules.C3 * c_mu_value * (HF_m + HM_m) ** 2 * (B_m + c_psi_value * HF_m)


def parallel_term_C4(LPAR_m: float, HF_m: float) -> float:
    """Parallel-midbody friction term C4 LPAR H_F^2 [N] of eq. (22)."""
    return rules.C4 * LPAR_m * HF_m**2


def bow_shape_term_C5(shape_factor_value: float, Awf_m2: float, L_m: float) -> float:
    """Bow-shape term C5 (L T / B^2)^3 Awf / L [N] of eq. (22); pass the clamped shape factor for the rules."""
    return rules.C5 * shape_factor_value * Awf_m2 / L_m


def ke(n_propellers: int, propulsion: str) -> float:
    """Ke of the engine-output formula (FSICR 2017, 3.2.2): 1, 2 or 3 propellers; "cp", "fp", "electric", "hydraulic"."""
    return rules.ke_coefficient(n_propellers, propulsion)


def engine_power(r_ch_N: float, ke_value: float, Dp_m: float) -> float:
    """P = Ke (R_CH / 1000)^1.5 / Dp [kW], R_CH in N, Dp in m; before the class minimum."""
    if Dp_m <= 0.0:
        raise FsicrInputError(f"Dp_m (--Dp): propeller diameter must be > 0 m, got {Dp_m:g}")
    return ke_value * (r_ch_N / 1000.0) ** 1.5 / Dp_m


def minimum_power(ice_class: str) -> float:
    """Minimum engine output of an ice class [kW]: 2800 for IA Super, 1000 for IA, IB, IC."""
    return rules.MIN_POWER_KW[rules.parse_ice_class(ice_class)]
