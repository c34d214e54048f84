"""``iceresist report SWEEP_DIR``: the naval architect's report of a sweep, as ``report.html`` and ``report.pdf``.

Reads only the files a sweep wrote (``sweep.json``, ``cases/*.h5``) through :mod:`iceresist.post`, which
builds the table from the case files; never runs a simulation and never writes ``sweep.csv`` (the sweep's
own record). The HTML is self-contained (figures embedded as base64 PNG, one jinja2 template); the PDF holds the
same figures and tables as matplotlib ``PdfPages``. One template for both formats would need an HTML-to-PDF
renderer, and the one that renders such pages well (WeasyPrint) needs Pango from the operating system, which
``pip install`` cannot bring; matplotlib, already drawing every figure, writes the PDF with nothing more.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import logging
from pathlib import Path

import numpy as np

from iceresist.errors import InputError
from iceresist.post.case import (SCALE, case_start_wave, floe_outlines, hull_of_model, load_case,
                                  mesh_hull_inputs)
from iceresist.post.sweeptable import case_path, preset_note, sweep_table
from iceresist.post.trends import trends_table
from reports.common import html_table as _html_table
from reports.common import pdf_table_page as _pdf_table_page
from reports.common import png64 as _png64
from reports.common import pyplot as _plt
from reports.common import template_env

log = logging.getLogger(__name__)

PAPER_TABLE2_KN = {"A": (188.0, 293.0), "B": (330.0, 355.0)}


def bow_ratios(table) -> tuple[float, float]:
    """(simulated, FSICR) ratio Bow B / Bow A at 68 %, 1 knot; NaN where a case is missing."""
    a = table[table.case == "A-c68-v1.0"]
    b = table[table.case == "B-c68-v1.0"]
    if a.empty or b.empty:
        return float("nan"), float("nan")
    return (float(b.R_sim_kN.iloc[0] / a.R_sim_kN.iloc[0]),
            float(b.R_CH_FSICR_kN.iloc[0] / a.R_CH_FSICR_kN.iloc[0]))


# -- figures ---------------------------------------------------------------------------------------------
def fig_forces(plt, cases: dict, table):
    n = len(cases)
    fig, axes = plt.subplots(n, 1, figsize=(7.0, 1.6 * n + 0.4), sharex=True, squeeze=False)
    for ax, (name, c) in zip(axes[:, 0], cases.items()):
        x, R = c["ts"]["x_bow_m"][1:], -c["ts"]["Fx_N"][1:]
        row = table[table.case == name].iloc[0]
        ax.semilogy(x, np.where(R > 0, R, np.nan), color="0.3", lw=0.6)
        ax.axvspan(row.window_x0_m, row.window_x1_m, color="tab:blue", alpha=0.08)
        ax.hlines(row.mean_force_N, row.window_x0_m, row.window_x1_m, color="red", lw=1.5)
        ax.set_ylabel("R [N]")
        ax.set_title(f"{name}: mean {row.mean_force_N:.3g} N", fontsize=8, loc="left")
    axes[-1, 0].set_xlabel("stem position x [m]")
    return fig


def fig_trends(plt, table):
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(7.0, 3.0))
    conc = table[(table.bow == "A") & (table.knots == 1.0)].sort_values("concentration")
    a1.errorbar(100 * conc.concentration, conc.mean_force_N, yerr=conc.ci95_N, marker="o", capsize=3)
    a1.set_xlabel("ice concentration [%]")
    a1.set_ylabel("mean ice resistance [N] (model)")
    a1.set_title("Bow A, 1 knot", fontsize=8)
    spd = table[(table.bow == "A") & (np.isclose(table.concentration, 0.68, atol=0.02))].sort_values("knots")
    a2.errorbar(spd.speed_m_s, spd.mean_force_N, yerr=spd.ci95_N, marker="s", capsize=3, color="tab:green")
    a2.set_xlabel("ship speed [m/s] (model)")
    a2.set_title("Bow A, 68 %", fontsize=8)
    return fig


def fig_bows(plt, table):
    fig, ax = plt.subplots(figsize=(5.0, 3.0))
    rows = [table[table.case == c] for c in ("A-c68-v1.0", "B-c68-v1.0")]
    labels, sim, ci, fs = [], [], [], []
    for bow, r in zip("AB", rows):
        if r.empty:
            continue
        labels.append(f"Bow {bow}")
        sim.append(r.R_sim_kN.iloc[0])
        ci.append(r.R_sim_ci95_kN.iloc[0])
        fs.append(r.R_CH_FSICR_kN.iloc[0])
    xs = np.arange(len(labels))
    ax.bar(xs - 0.27, sim, 0.26, yerr=ci, capsize=3, label="simulated (this sweep)")
    ax.bar(xs, fs, 0.26, label="FSICR R_CH")
    ax.bar(xs + 0.27, [PAPER_TABLE2_KN[lab[-1]][0] for lab in labels], 0.26, label="paper, LBM-DEM", color="0.6")
    ax.set_xticks(xs, labels)
    ax.set_ylabel("full-scale ice resistance [kN]")
    ax.legend(fontsize=7)
    return fig


def fig_tank(plt, cases: dict):
    """Tier 2: the water level at the fore wall and ahead of the bow and the drift of the ice ahead of the bow
    against time (:meth:`iceresist.models.tier2.Tier2Model.tank_motion`), with the steady window and the time the
    stern's start wave reaches the bow (docs/SHIP.md, "The start wave"); None when no case recorded them."""
    shown = {k: c for k, c in cases.items() if "level_ahead_m" in c["ts"]}
    if not shown:
        return None
    fig, axes = plt.subplots(len(shown), 1, figsize=(7.0, 1.7 * len(shown) + 0.5), sharex=True, squeeze=False)
    for ax, (name, c) in zip(axes[:, 0], shown.items()):
        ts = c["ts"]
        t = ts["time_s"]
        ax.plot(t, 100 * ts["level_fore_wall_m"], color="tab:blue", lw=0.9, label="level at the fore wall")
        ax.plot(t, 100 * ts["level_ahead_m"], color="tab:cyan", lw=0.9, label="level ahead of the bow")
        ax.axhline(0.0, color="0.6", lw=0.5)
        ax.set_ylabel("level [cm]")
        drift = ax.twinx()
        drift.plot(t, ts["ice_drift_ahead_m_s"], color="tab:orange", lw=0.9, label="ice drift ahead [m/s]")
        drift.set_ylabel("drift [m/s]")
        sw = case_start_wave(c["model"], hull_of_model(c["model"]))
        title = name
        if sw is not None:
            wave, (w0, w1) = sw
            ax.axvspan(w0, w1, color="tab:blue", alpha=0.08)
            ax.axvline(wave.duration_s, color="k", ls="--", lw=0.8)
            drift.axhline(wave.drift_m_s, color="tab:orange", ls=":", lw=0.8)
            title += f": start wave over {100 * wave.window_fraction(w0, w1):.0f} % of the window"
        ax.set_title(title, fontsize=8, loc="left")
    h1, l1 = axes[0, 0].get_legend_handles_labels()
    axes[0, 0].legend(h1 + [drift.get_lines()[0]], l1 + ["ice drift ahead"], fontsize=6, loc="upper left")
    axes[-1, 0].set_xlabel("time since the start [s]")
    return fig


def fig_ice_field(plt, cases: dict):
    """The initial ice field of the first case that packs floes of a size distribution (top view and the edges'
    histogram), or None where every case has the regular cubes."""
    from matplotlib.collections import PolyCollection

    name, c = next(((k, v) for k, v in cases.items() if "ice_field" in v["model"]), (None, None))
    if c is None:
        return None
    m, b = c["model"], c["bodies"]
    info = m["ice_field"]
    polys, _ = floe_outlines(m, b, b["initial_positions_m"])
    size = np.asarray(b["floe_sizes_m"]) * 1e3
    fig, (ax, hx) = plt.subplots(1, 2, figsize=(10.0, 4.5), layout="constrained",
                                 gridspec_kw={"width_ratios": [2.2, 1.0]})
    pc = PolyCollection(polys, array=size, cmap="viridis", edgecolor="none")
    ax.add_collection(pc)
    ax.set_xlim(m["channel_start_x_m"], m["channel_start_x_m"] + m["channel_length_m"])
    ax.set_ylim(m["centre_y_m"] - m["channel_width_m"] / 2, m["centre_y_m"] + m["channel_width_m"] / 2)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{name}: {info['floes']} floes, {100 * info['concentration']:.1f} % covered, "
                 f"{1e3 * info['thickness_m']:.0f} mm thick, seed {info['seed']}", fontsize=9, loc="left")
    fig.colorbar(pc, ax=ax, label="edge [mm]", orientation="horizontal", shrink=0.6)
    hx.hist(size, bins=30, color="0.5")
    hx.set_xlabel("floe edge [mm]")
    hx.set_ylabel("floes")
    hx.set_title(f"{info['distribution']} edges", fontsize=9, loc="left")
    return fig


def fig_topviews(plt, cases: dict):
    from matplotlib.collections import PolyCollection

    n = len(cases)
    m0 = next(iter(cases.values()))["model"]
    span = m0["channel_length_m"] + 0.8
    fig, axes = plt.subplots(n, 1, figsize=(8.0, n * 8.0 * m0["channel_width_m"] / span + 1.0), squeeze=False,
                             layout="constrained")
    for ax, (name, c) in zip(axes[:, 0], cases.items()):
        m, b = c["model"], c["bodies"]
        p = b["final_positions_m"]
        polys, thick = floe_outlines(m, b, p, b.get("final_quaternions"))
        depth = np.clip(m["water_level_m"] - (p[:, 2] + thick / 2), 0, None)
        pc = PolyCollection(polys, array=depth, cmap="viridis_r", clim=(0, 0.1), edgecolor="none")
        ax.add_collection(pc)
        wl = hull_of_model(m).waterline_polygon() + np.array([float(c["meta"]["final_x_bow_m"]), m["centre_y_m"]])
        ax.fill(wl[:, 0], wl[:, 1], facecolor="none", edgecolor="k", lw=1.0)
        x0 = m["channel_start_x_m"] - 0.5
        ax.set_xlim(x0, m["channel_start_x_m"] + m["channel_length_m"] + 0.3)
        ax.set_ylim(m["centre_y_m"] - m["channel_width_m"] / 2, m["centre_y_m"] + m["channel_width_m"] / 2)
        ax.set_aspect("equal")
        ax.set_title(name, fontsize=8, loc="left")
        ax.set_ylabel("y [m]")
    axes[-1, 0].set_xlabel("x [m]")
    fig.colorbar(pc, ax=axes[:, 0].tolist(), label="depth of cube top below surface [m]", shrink=0.6,
                 orientation="horizontal")
    return fig


# -- tables ----------------------------------------------------------------------------------------------
TABLE2_COLUMNS = {"case": "case", "mean_force_N": "model mean [N]", "ci95_N": "± 95 % CI [N]",
                  "R_sim_kN": "full scale [kN]", "R_sim_ci95_kN": "± 95 % CI [kN]",
                  "R_CH_FSICR_kN": "FSICR R_CH [kN]", "ratio_sim_FSICR": "sim/FSICR",
                  "ice_free_width_m": "ice-free width [m]", "floes_under_hull": "floes under hull"}
TREND_COLUMNS = {"trend": "trend of the paper", "values": "mean ice force +- 95 % (model scale)",
                 "verdict": "on this sweep"}
RUN_COLUMNS = {"case": "case", "tier": "tier", "fidelity": "preset", "cubes": "cubes", "spheres": "DEM spheres",
               "resolution_m": "resolution [m]", "cells_per_cube": "cells per cube (finest)", "levels": "levels",
               "converged": "grid-converged", "cells": "cells", "steps": "records",
               "dem_substeps": "DEM sub-steps", "simulated_s": "simulated [s]", "wall_time_s": "wall time [s]",
               "backend": "backend", "half_ratio": "2nd / 1st half", "window_steady": "steady window",
               "tank_froude_fraction": "F_h / F_L",
               "start_wave_fraction": "window in start wave", "ci_method": "CI method", "note": "note"}


def hull_summary(hull: dict, scale: float = SCALE) -> tuple[str, "pd.DataFrame | None"]:
    """The hull's name for the title, and for a mesh hull the FSICR inputs measured on it at full scale (1:``scale``)."""
    import pandas as pd

    rows = mesh_hull_inputs(hull, scale)
    if rows is None:
        return "B-063", None
    return f"{Path(hull.get('mesh_file', 'mesh')).stem} (mesh hull)", pd.DataFrame(rows)


def write_report(sweep_dir) -> tuple[Path, Path]:
    """Write ``report.html`` and ``report.pdf`` into ``sweep_dir``; returns their paths."""
    d = Path(sweep_dir)
    if not d.is_dir():
        raise InputError(f"{d}: no such sweep folder; run `iceresist sweep --output {d}` first")
    if not (d / "sweep.json").is_file():
        raise InputError(f"{d}: not a sweep folder (no sweep.json); run `iceresist sweep --output {d}` first")
    info = json.loads((d / "sweep.json").read_text())
    table = sweep_table(d)
    if table.empty:
        raise InputError(f"{d}: no finished case yet; run `iceresist sweep --output {d}` to finish them")
    cases = {name: load_case(case_path(d, name)) for name in table.case}
    plt = _plt()
    if "axes" in info:
        return _write_matrix_report(d, info, table, cases, plt)
    figs = {"forces": fig_forces(plt, cases, table), "trends": fig_trends(plt, table),
            "bows": fig_bows(plt, table), "topviews": fig_topviews(plt, cases)}
    tank = fig_tank(plt, cases)
    if tank is not None:
        figs["tank"] = tank
    field = fig_ice_field(plt, cases)
    if field is not None:
        figs["ice_field"] = field
    images = {k: _png64(f) for k, f in figs.items()}
    r_sim, r_fs = bow_ratios(table)
    trends = trends_table(table)
    note = preset_note(info.get("preset"), int(info.get("tier", 1)))
    hull_name, hull_inputs = hull_summary(next(iter(cases.values()))["model"]["hull"])
    env = template_env()
    html = env.get_template("report.html.j2").render(
        title=f"{info.get('preset')} preset, tier {info.get('tier')}", sweep_dir=str(d), preset=info.get("preset"),
        tier=info.get("tier"), generated=_now(), scale=f"{SCALE:g}", table2=_html_table(table, TABLE2_COLUMNS),
        runs=_html_table(table, RUN_COLUMNS, na_rep="–"),
        bow_ratio_sim=f"{r_sim:.3g}", bow_ratio_fsicr=f"{r_fs:.3g}", images=images, preset_note=note,
        trends=_html_table(trends, TREND_COLUMNS), hull_name=hull_name,
        hull_inputs=None if hull_inputs is None else _html_table(hull_inputs, {c: c for c in hull_inputs.columns}))
    pages = [_pdf_table_page(plt, table, TABLE2_COLUMNS, f"Full-scale ice resistance beside FSICR (lambda = {SCALE:g}); "
                             f"Bow B/A: sim {r_sim:.3g}, FSICR {r_fs:.3g}"),
             _pdf_table_page(plt, trends, TREND_COLUMNS, "The paper's trends on this sweep "
                             "(mean +- 95 % interval, model scale)")]
    return _write(d, html, pages, figs, table, plt)


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def _write(d: Path, html: str, pages: list, figs: dict, table, plt) -> tuple[Path, Path]:
    """``report.html``, ``report.pdf`` (``pages``, the figures, the runs) and ``topviews.png`` into ``d``."""
    from matplotlib.backends.backend_pdf import PdfPages

    html_path, pdf_path = d / "report.html", d / "report.pdf"
    html_path.write_text(html, encoding="utf-8")
    with PdfPages(pdf_path) as pdf:
        for page in pages:
            pdf.savefig(page)
        for f in figs.values():
            pdf.savefig(f)
        pdf.savefig(_pdf_table_page(plt, table, RUN_COLUMNS, "Runs", na_rep="–"))
    figs["topviews"].savefig(d / "topviews.png")
    plt.close("all")
    log.info("report: %s, %s", html_path, pdf_path)
    return html_path, pdf_path


def _write_matrix_report(d: Path, info: dict, table, cases: dict, plt) -> tuple[Path, Path]:
    """The report of a user's test matrix (:mod:`reports.matrix`)."""
    from reports.matrix import MATRIX_COLUMNS, fig_speed, matrix_context

    figs = {"speed": fig_speed(plt, table), "forces": fig_forces(plt, cases, table),
            "topviews": fig_topviews(plt, cases)}
    field = fig_ice_field(plt, cases)
    if field is not None:
        figs["ice_field"] = field
    first = next(iter(cases.values()))
    _, hull_inputs = hull_summary(first["model"]["hull"], float(table.scale.iloc[0]))
    ctx = matrix_context(info, table)
    html = template_env().get_template("matrix.html.j2").render(
        **ctx, sweep_dir=str(d), preset=info.get("preset"), tier=info.get("tier"), generated=_now(),
        images={k: _png64(f) for k, f in figs.items()}, runs=_html_table(table, RUN_COLUMNS, na_rep="–"),
        preset_note=preset_note(info.get("preset"), int(info.get("tier", 1))),
        first_scale=f"{float(table.scale.iloc[0]):g}",
        hull_inputs=None if hull_inputs is None else _html_table(hull_inputs, {c: c for c in hull_inputs.columns}))
    pages = [_pdf_table_page(plt, table, MATRIX_COLUMNS, f"{ctx['hull_name']}: {ctx['matrix_words']}", na_rep="–")]
    return _write(d, html, pages, figs, table, plt)


def add_report_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``iceresist report``; sets ``func=cmd_report``."""
    p.add_argument("sweep_dir", metavar="SWEEP_DIR", help="folder written by `iceresist sweep`")
    p.set_defaults(func=cmd_report)
    return p


def cmd_report(args) -> int:
    html, pdf = write_report(args.sweep_dir)
    print(f"{html}\n{pdf}")
    return 0
