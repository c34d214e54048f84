"""Plain-text reports of the calculator: every input, intermediate value, term and warning."""

from __future__ import annotations

from .power import PowerResult
from .resistance import TERM_LABELS, ResistanceResult
from .rules import C_MU_MIN, SHAPE_FACTOR_MAX, SHAPE_FACTOR_MIN
from .ship import DESCRIPTIONS, WATERLINE_FIELDS, Ship

_N_TERMS = ("C1_N", "C2_N", "C3_term_N", "C4_term_N", "C5_term_N")


def _clamp_note(key: str, terms) -> str:
    if key == "C_mu":
        active = terms["C_mu_unclamped"] < C_MU_MIN
        return f"  bound C_mu >= {C_MU_MIN:g} {'ACTIVE' if active else 'not active'}"
    if key == "C_psi":
        return "  psi <= 45 deg: set to 0" if terms["psi_deg"] <= 45.0 else ""
    if key == "shape_factor":
        raw = terms["shape_factor_unclamped"]
        if raw > SHAPE_FACTOR_MAX:
            return f"  bound <= {SHAPE_FACTOR_MAX:g} ACTIVE"
        if raw < SHAPE_FACTOR_MIN:
            return f"  bound >= {SHAPE_FACTOR_MIN:g} ACTIVE"
        return "  bounds 5..20 not active"
    return ""


def format_ship_inputs(ship: Ship, indent: str = "  ") -> list[str]:
    lines = [f"{indent}{DESCRIPTIONS[f]:<48s} {getattr(ship, f):10.3f}" for f in WATERLINE_FIELDS]
    lines.append(f"{indent}{'bulbous bow (phi1 = 90 deg in C1, C2)':<48s} {'yes' if ship.bulbous_bow else 'no':>10s}")
    if ship.Dp_m is not None:
        lines.append(f"{indent}{'propeller diameter Dp [m]':<48s} {ship.Dp_m:10.3f}")
    return lines


def format_resistance(res: ResistanceResult) -> str:
    """One waterline: inputs, intermediate values (with clamp states), the terms in kN and R_CH."""
    t = res.terms
    out = [f"{res.waterline.capitalize()} ice waterline, ice class {res.ice_class}", "  Inputs"]
    out += format_ship_inputs(res.ship, "    ")
    out.append("  Intermediate values")
    for key in ("H_M_m", "H_F_m", "psi_deg", "C_mu_unclamped", "C_mu", "C_psi", "phi1_used_deg",
                "LT_over_B2", "shape_factor_unclamped", "shape_factor"):
        out.append(f"    {TERM_LABELS[key]:<66s} {t[key]:10.4f}{_clamp_note(key, t)}")
    out.append("  Terms of R_CH (eq. 22)                                                   [kN]")
    for key in _N_TERMS:
        out.append(f"    {TERM_LABELS[key][:-4]:<66s} {t[key] / 1000:10.2f}")
    out.append(f"    {'R_CH (FSICR 2017)':<66s} {res.r_ch_kN:10.2f}")
    out.append(
        f"    {'R_CH with (L T / B^2)^3 unclamped (not the rules; for comparison)':<66s} {res.r_ch_unclamped_N / 1000:10.2f}"
    )
    return "\n".join(out)


def format_warnings(warnings) -> str:
    if not warnings:
        return "Range of validity: every parameter is inside the FSICR 2017 range."
    head = f"Warnings ({len(warnings)}): outside the FSICR 2017 range of validity (the calculation still ran)"
    return "\n".join([head] + [f"  - {w}" for w in warnings])


def _title(kind: str, meta: dict) -> list[str]:
    lines = [f"FSICR 2017 {kind}"]
    if meta.get("name"):
        lines.append(f"Ship: {meta['name']}")
    if meta.get("file"):
        lines.append(f"File: {meta['file']}")
    return lines


def format_mesh(mesh: dict) -> str:
    """The inputs measured on a hull mesh beside those the user stated (which the calculation uses)."""
    from .hullmesh import HOW

    out = [f"Measured on the hull mesh {mesh['file']} (draught {mesh['draught_m']:g} m, unit {mesh['unit']}, "
           f"scale {mesh['scale']:g})",
           f"  {'input':<48s} {'measured':>10s} {'stated':>10s}  how"]
    for f, v in mesh["measured"].items():
        stated = mesh["stated"].get(f)
        out.append(f"  {DESCRIPTIONS[f]:<48s} {v:10.3f} {'' if stated is None else f'{stated:10.3f}':>10s}  "
                   f"{HOW.get(f, 'the draught given x scale')}")
    if mesh["stated"]:
        out.append("  The calculation uses the stated values where given.")
    return "\n".join(out)


def _with_mesh(parts: list, meta: dict) -> list:
    return parts[:1] + ([format_mesh(meta["mesh"])] if "mesh" in meta else []) + parts[1:]


def format_resistance_report(results: tuple[ResistanceResult, ...], meta: dict) -> str:
    parts = ["\n".join(_title("brash-ice channel resistance R_CH", meta))]
    parts += [format_resistance(r) for r in results]
    if len(results) > 1:
        parts.append("\n".join(f"R_CH at the {r.waterline} ice waterline: {r.r_ch_kN:.2f} kN" for r in results))
    parts.append(format_warnings(tuple(w for r in results for w in r.warnings)))
    return "\n\n".join(_with_mesh(parts, meta))


def format_power_report(p: PowerResult, meta: dict) -> str:
    parts = ["\n".join(_title("required engine output", meta))]
    parts += [format_resistance(r) for r in p.resistances]
    lines = [
        "Engine output  P = Ke (R_CH / 1000)^1.5 / Dp  [kW]",
        f"  Ke = {p.Ke:.2f} ({p.n_propellers} propeller(s), {p.propulsion}), Dp = {p.Dp_m:.3f} m",
    ]
    for wl, kw in p.power_by_waterline_kW.items():
        lines.append(f"  {wl} ice waterline: {kw:10.0f} kW")
    lines.append(f"  minimum for class {p.ice_class}: {p.minimum_kW:10.0f} kW")
    lines.append(f"  REQUIRED ENGINE OUTPUT: {p.required_kW:10.0f} kW  (governed by the {p.governing})")
    parts.append("\n".join(lines))
    parts.append(format_warnings(p.warnings))
    return "\n\n".join(_with_mesh(parts, meta))


def format_compare(c: dict) -> str:
    """The table-2 comparison as a table a naval architect can hand on."""
    r = c["ratios_bow_b_over_bow_a"]
    head = (
        f"FSICR brash-ice channel resistance of the full-scale B-063 ship, ice class {c['ice_class']} "
        f"(H_M = {c['H_M_m']:.1f} m)\n"
        f"beside {c['paper']}, tables 1 and 2"
    )
    hdr = (f"{'case':<8s}{'phi1=phi2':>10s} | {'FSICR paper':>11s} | {'FSICR here':>10s} {'diff':>8s} | "
           f"{'no clamp':>9s} {'diff':>8s} | {'simulated':>9s} {'sim/here':>8s}")
    unit = f"{'':<8s}{'[deg]':>10s} | {'[kN]':>11s} | {'[kN]':>10s} {'[%]':>8s} | {'[kN]':>9s} {'[%]':>8s} | {'[kN]':>9s} {'[-]':>8s}"
    rows = [hdr, unit, "-" * len(hdr)]
    for k in c["cases"]:
        rows.append(
            f"{k['case']:<8s}{k['phi2_deg']:10.0f} | {k['paper_fsicr_kN']:11.0f} | {k['ours_kN']:10.1f} {k['diff_pct']:+8.2f} | "
            f"{k['ours_unclamped_kN']:9.1f} {k['diff_unclamped_pct']:+8.2f} | {k['paper_simulated_kN']:9.0f} "
            f"{k['simulated_over_ours']:8.2f}"
        )
    rows.append(
        f"{'B / A':<8s}{'':>10s} | {r['paper_fsicr']:11.2f} | {r['ours']:10.3f} {'':>8s} | {r['ours_unclamped']:9.3f} "
        f"{'':>8s} | {r['paper_simulated']:9.2f} {'':>8s}"
    )
    terms_hdr = f"{'terms':<8s}{'psi':>8s}{'C_mu':>8s}{'C_psi':>8s}{'H_F':>7s}{'C3 term':>10s}{'C4 term':>10s}{'C5 term':>10s}{'R_CH':>10s}"
    trows = [terms_hdr, f"{'':<8s}{'[deg]':>8s}{'[-]':>8s}{'[-]':>8s}{'[m]':>7s}{'[kN]':>10s}{'[kN]':>10s}{'[kN]':>10s}{'[kN]':>10s}"]
    for k in c["cases"]:
        t = k["terms"]
        trows.append(
            f"{k['case']:<8s}{t['psi_deg']:8.2f}{t['C_mu']:8.4f}{t['C_psi']:8.4f}{t['H_F_m']:7.3f}"
            f"{t['C3_term_N'] / 1e3:10.2f}{t['C4_term_N'] / 1e3:10.2f}{t['C5_term_N'] / 1e3:10.2f}{t['R_CH_N'] / 1e3:10.2f}"
        )
    notes = [
        "Columns: 'FSICR here' applies FSICR 2017 as written; 'no clamp' leaves (L T/B^2)^3 = 20.34 above the",
        "rules' bound of 20 (the paper's figures match it); 'simulated' is the paper's LBM-DEM result at full",
        "scale; diff = (here - paper) / paper.",
    ]
    notes += [
        "Assumption: LBOW = (L - LPAR)/2 = 15.15 m, not in table 1 (symmetric double-ended hull); for class IA",
        "C1 = C2 = 0, so LBOW and phi1 do not change R_CH. Propulsion is not needed here.",
    ]
    warn = ["Range of validity (the rules ask for model tests outside it):"]
    for k in c["cases"]:
        for w in k["warnings"]:
            text = w.split(": ", 1)[1].replace(" is outside the FSICR 2017 range of validity ", " outside ")
            warn.append(f"  {k['case']}: {text.split(';')[0]}")
    return "\n".join([head, "", *rows, "", *trows, "", *notes, "", *warn])
