"""R_CH of one ship at one ice waterline, with every intermediate value (eqs. 22-26)."""

from __future__ import annotations

import types
from dataclasses import dataclass
from typing import Mapping

from . import formulas
from .rules import parse_ice_class
from .ship import Ship
from .validity import validity_warnings

#: Printed label of each entry of :attr:`ResistanceResult.terms`, in print order.
TERM_LABELS = {
    "H_M_m": "H_M    brash-ice thickness in mid channel [m]",
    "H_F_m": "H_F    = 0.26 + (H_M B)^0.5 [m]                         (eq. 25)",
    "psi_deg": "psi    = arctan(tan phi2 / sin alpha) [deg]             (eq. 26)",
    "C_mu_unclamped": "C_mu   before clamp = 0.15 cos phi2 + sin psi sin alpha (eq. 23)",
    "C_mu": "C_mu   used, >= 0.45                                    (eq. 23)",
    "C_psi": "C_psi  = 0.047 psi - 2.115, 0 if psi <= 45 deg          (eq. 24)",
    "phi1_used_deg": "phi1   used in C1, C2 (90 for a bulbous bow) [deg]",
    "LT_over_B2": "L T / B^2",
    "shape_factor_unclamped": "(L T / B^2)^3 before clamp",
    "shape_factor": "(L T / B^2)^3 used, 5 <= . <= 20",
    "C1_N": "C1     consolidated layer (IA Super only) [N]",
    "C2_N": "C2     consolidated layer (IA Super only) [N]",
    "C3_term_N": "C3 C_mu (H_F + H_M)^2 (B + C_psi H_F) [N]",
    "C4_term_N": "C4 LPAR H_F^2 [N]",
    "C5_term_N": "C5 (L T / B^2)^3 Awf / L [N]",
    "R_CH_N": "R_CH   = C1 + C2 + C3 term + C4 term + C5 term [N]  (eq. 22)",
    "C5_term_unclamped_N": "C5 term with (L T / B^2)^3 unclamped [N]",
    "R_CH_unclamped_N": "R_CH with (L T / B^2)^3 unclamped [N] (not the rules)",
}


@dataclass(frozen=True)
class ResistanceResult:
    """R_CH at one waterline: ``terms`` holds every intermediate value (see :data:`TERM_LABELS`)."""

    ice_class: str
    waterline: str
    ship: Ship
    r_ch_N: float
    terms: Mapping[str, float]
    warnings: tuple[str, ...]

    @property
    def r_ch_kN(self) -> float:
        return self.r_ch_N / 1000.0

    @property
    def r_ch_unclamped_N(self) -> float:
        """R_CH without the rules' bounds on (L T / B^2)^3 (reported for comparison only)."""
        return self.terms["R_CH_unclamped_N"]

    def to_dict(self) -> dict:
        return {
            "ice_class": self.ice_class,
            "waterline": self.waterline,
            "ship": self.ship.to_dict(),
            "r_ch_N": self.r_ch_N,
            "r_ch_kN": self.r_ch_kN,
            "terms": dict(self.terms),
            "warnings": list(self.warnings),
        }


def r_ch(ship: Ship, ice_class: str, waterline: str = "upper") -> ResistanceResult:
    """Brash-ice channel resistance R_CH [N] of ``ship`` (its main fields) in ``ice_class`` (eq. 22)."""
    cls = parse_ice_class(ice_class)
    s = ship
    HM = formulas.hm_for_class(cls)
    HF = formulas.brash_thickness_HF(HM, s.B_m)
    psi = formulas.psi_deg(s.alpha_deg, s.phi2_deg)
    cmu_raw = formulas.c_mu_unclamped(s.alpha_deg, s.phi2_deg)
    cmu = formulas.c_mu(s.alpha_deg, s.phi2_deg)
    cpsi = formulas.c_psi(psi)
    phi1 = s.phi1_effective_deg
    ratio = formulas.shape_ratio(s.L_m, s.T_m, s.B_m)
    sf_raw = formulas.shape_factor_unclamped(s.L_m, s.T_m, s.B_m)
    sf = formulas.shape_factor(s.L_m, s.T_m, s.B_m)
    C1 = formulas.c1(cls, s.B_m, s.T_m, s.LPAR_m, s.LBOW_m, phi1)
    C2 = formulas.c2(cls, s.B_m, s.T_m, s.L_m, phi1)
    t3 = formulas.channel_term_C3(cmu, HF, HM, s.B_m, cpsi)
    t4 = formulas.parallel_term_C4(s.LPAR_m, HF)
    t5 = formulas.bow_shape_term_C5(sf, s.Awf_m2, s.L_m)
    t5_raw = formulas.bow_shape_term_C5(sf_raw, s.Awf_m2, s.L_m)
    total = C1 + C2 + t3 + t4 + t5
    terms = {
        "H_M_m": HM,
        "H_F_m": HF,
        "psi_deg": psi,
        "C_mu_unclamped": cmu_raw,
        "C_mu": cmu,
        "C_psi": cpsi,
        "phi1_used_deg": phi1,
        "LT_over_B2": ratio,
        "shape_factor_unclamped": sf_raw,
        "shape_factor": sf,
        "C1_N": C1,
        "C2_N": C2,
        "C3_term_N": t3,
        "C4_term_N": t4,
        "C5_term_N": t5,
        "R_CH_N": total,
        "C5_term_unclamped_N": t5_raw,
        "R_CH_unclamped_N": C1 + C2 + t3 + t4 + t5_raw,
    }
    return ResistanceResult(
        ice_class=cls,
        waterline=waterline,
        ship=s,
        r_ch_N=total,
        terms=types.MappingProxyType(terms),
        warnings=validity_warnings(s, waterline),
    )


def r_ch_at_waterlines(ship: Ship, ice_class: str) -> tuple[ResistanceResult, ...]:
    """R_CH at the upper and, where the ship gives one, the lower ice waterline."""
    return tuple(r_ch(s, ice_class, label) for label, s in ship.waterlines())
