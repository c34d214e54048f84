"""The report of a user's test matrix (``iceresist sweep --matrix`` or the matrix flags): the hull's name in the title,
the matrix in words, full-scale resistance beside FSICR R_CH and the required engine output, and resistance against
speed per concentration. Called by :func:`reports.report.write_report` for a sweep folder whose ``sweep.json``
holds a matrix; reads only what the sweep wrote."""

from __future__ import annotations

from reports.common import html_table

#: The matrix table: full scale first (what the naval architect signs), model scale after.
MATRIX_COLUMNS = {"case": "case", "concentration_nominal": "concentration", "concentration": "covered", "full_scale_knots": "speed [kn]",
                  "scale": "scale 1:", "R_sim_kN": "R simulated [kN]", "R_sim_ci95_kN": "± 95 % [kN]",
                  "R_CH_FSICR_kN": "FSICR R_CH [kN]", "ratio_sim_FSICR": "sim/FSICR", "P_sim_kW": "P from sim [kW]",
                  "P_FSICR_kW": "P from R_CH [kW]", "mean_force_N": "model mean [N]", "ci95_N": "± 95 % [N]",
                  "window_steady": "steady window"}


def group_label(case: str) -> str:
    """What a case's name says beyond its concentration and speed (``-s40-stern``), the same for one curve's
    cases: ``c68-v5kn-s40-stern`` -> ``1:40, stern ahead``; '' for the defaults."""
    words = []
    for part in case.split("-")[2:]:
        if part == "stern":
            words.append("stern ahead")
        elif part.startswith("s"):
            words.append(f"1:{part[1:]}")
        elif part.startswith("e"):
            words.append(f"ice {part[1:]}")
        elif part.startswith("h"):
            words.append(f"{part[1:]} thick")
        elif part.startswith("w"):
            words.append(f"channel {part[1:]}")
    return ", ".join(words)


def fig_speed(plt, table):
    """Full-scale resistance (+- 95 %) against full-scale speed, a line per concentration, one panel per other
    matrix value (scale, ice, channel, end), FSICR R_CH of the panel's hull and class dashed beside it."""
    groups = list(dict.fromkeys(group_label(c) for c in table.case))
    fig, axes = plt.subplots(1, len(groups), figsize=(min(4.2 * len(groups), 12.0) + 1.0, 3.4), squeeze=False,
                             sharey=True, layout="constrained")
    for ax, g in zip(axes[0], groups):
        part = table[[group_label(c) == g for c in table.case]]
        for conc, rows in part.groupby("concentration_nominal"):
            rows = rows.sort_values("full_scale_knots")
            ax.errorbar(rows.full_scale_knots, rows.R_sim_kN, yerr=rows.R_sim_ci95_kN, marker="o", capsize=3,
                        label=f"{100 * conc:g} % simulated")
        r_ch = float(part.R_CH_FSICR_kN.iloc[0])
        ax.axhline(r_ch, color="k", ls="--", lw=1.0, label=f"FSICR R_CH ({part.ice_class.iloc[0]}) {r_ch:.0f} kN")
        ax.set_xlabel("ship speed, full scale [kn]")
        ax.set_title(g or "resistance against speed", fontsize=8, loc="left")
        ax.legend(fontsize=6)
    axes[0, 0].set_ylabel("ice resistance, full scale [kN]")
    return fig


def axes_in_words(axes: dict) -> str:
    """The matrix's axes as a sentence (full scale)."""
    def join(values, fmt):
        return ", ".join(fmt(v) for v in values)

    words = [f"concentration {join(axes['concentration'], lambda v: f'{100 * v:g} %')}",
             f"speed {join(axes['speed_knots'], lambda v: f'{v:g}')} kn",
             f"model scale {join(axes['scale'], lambda v: f'1:{v:g}')}",
             f"ice pieces {join(axes['ice_size_m'], lambda v: f'{v:g} m')}"]
    if any(t is not None for t in axes["ice_thickness_m"]):
        words.append(f"thickness {join(axes['ice_thickness_m'], lambda v: 'the edge' if v is None else f'{v:g} m')}")
    if any(w is not None for w in axes["channel_width_m"]):
        words.append(f"channel {join(axes['channel_width_m'], lambda v: 'the tank' if v is None else f'{v:g} m')}")
    words.append(f"{' and '.join(axes['ahead'])} ahead")
    return "; ".join(words)


def matrix_context(info: dict, table) -> dict:
    """The template values of a matrix report beside the shared ones."""
    hull = info.get("hull", {})
    name = str(table.hull.iloc[0]) if "hull" in table else "hull"
    n_axes = info["axes"]
    return {"hull_name": name, "matrix_words": axes_in_words(n_axes), "n_cases": len(info.get("cases", [])),
            "finished": len(table), "ice_class": hull.get("ice_class", "IA"),
            "propeller": (f"{hull['propeller_diameter_m']:g} m propeller, {hull.get('propellers', 1)} x "
                          f"{hull.get('propulsion', 'cp')}") if hull.get("propeller_diameter_m") else "",
            "matrix_table": html_table(table, MATRIX_COLUMNS, na_rep="–")}
