"""The validation report of a ``iceresist validate`` folder: ``report.html`` (self-contained) and ``report.pdf``,
the stability map (``stability.png``), the heave of the floating sphere against the measurement (from the rungs'
result files) and the settling-sphere figure of docs/notes/settling-sphere.md.

Reads only the files the validation wrote (``DIR/ladder.csv``, ``DIR/stability.csv``, a settling-velocity
CSV) and reduces them with :mod:`iceresist.post.convergence`; never runs a simulation. Uses the machinery of
the ship report (:mod:`reports.common`).

``python -m reports.validation settling CURVES.csv OUT.png`` draws the settling-sphere figure from the curves
that ``python -m iceresist.validate.cases.settling_sphere CURVES.csv 5 6 8`` writes.
"""

from __future__ import annotations

import datetime as _dt
import logging
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from iceresist.errors import InputError
from iceresist.io.hdf5 import RunFile
from iceresist.post.convergence import THRESHOLDS, case_summary, cheapest_runs, load_table, with_errors
from reports.common import html_table, pdf_table_page, png64, pyplot, template_env

log = logging.getLogger(__name__)

SUMMARY_COLUMNS = {"case": "case", "ladder": "ladder", "rungs": "rungs", "observed_order": "observed order p",
                   "min_error": "smallest error", "monotone": "error falls at every rung",
                   "wall_s": "wall time, all rungs [s]", "reference_kind": "reference"}
RUN_COLUMNS = {"label": "rung", "resolution": "resolution", "cells": "cells", "steps": "steps",
               "wall_s": "wall [s]", "mlups": "MLUPS", "value": "value", "reference": "reference",
               "error": "error", "backend": "backend", "precision": "precision"}


def cheapest_columns(thresholds=THRESHOLDS) -> dict:
    cols = {"case": "case", "ladder": "ladder"}
    for thr in thresholds:
        pct = f"{100 * thr:g}"
        cols[f"label_{pct}"] = f"≤ {pct} %: run"
        cols[f"wall_s_{pct}"] = f"≤ {pct} %: wall [s]"
    return cols


def fig_error_time(plt, table: pd.DataFrame, summary: pd.DataFrame):
    """One log-log panel per case: error against wall time per ladder, observed order in the legend."""
    from matplotlib.ticker import NullFormatter

    cases = list(dict.fromkeys(table.case))
    ncol = min(3, max(1, len(cases)))
    nrow = math.ceil(len(cases) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.4 * ncol, 2.8 * nrow + 0.3), squeeze=False,
                             layout="constrained")
    for ax, case in zip(axes.flat, cases):
        for ladder, g in table[table.case == case].groupby("ladder", sort=False):
            g = g[(g.error > 0) & (g.wall_s > 0)].sort_values("resolution")
            s = summary[(summary.case == case) & (summary.ladder == ladder)]
            p = float(s.observed_order.iloc[0]) if not s.empty else float("nan")
            ax.loglog(g.wall_s, g.error, marker="o", label=f"{ladder}: p = {p:.2f}")
            for _, r in g.iterrows():
                ax.annotate(f"{r.resolution:g}", (r.wall_s, r.error), fontsize=6, xytext=(3, 3),
                            textcoords="offset points")
        for thr in THRESHOLDS:
            ax.axhline(thr, color="0.7", lw=0.6, ls=":")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(case, fontsize=8, loc="left")
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel("relative error")
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(cases):]:
        ax.axis("off")
    return fig


def stability_section(plt, out: Path):
    """``(note, figure or None)`` of the stability map, or None without ``stability.csv``."""
    path = out / "stability.csv"
    if not path.is_file():
        return None
    df = pd.read_csv(path)
    fig, ax = plt.subplots(figsize=(6.0, 4.5), layout="constrained")
    try:
        plot_stability_map(df, ax)
    except Exception as exc:  # a table the map cannot read must not cost the rest of the report
        plt.close(fig)
        log.error("stability map: %s: %s", type(exc).__name__, exc)
        return {"note": f"stability.csv holds {len(df)} runs; the map could not be drawn ({type(exc).__name__}: "
                        f"{exc})", "fig": None}
    return {"note": f"{len(df)} runs from {path.name}.", "fig": fig}


def write_validation_report(out_dir, references: dict | None = None,
                            missing: dict | None = None) -> tuple[Path, Path]:
    """Write ``report.html`` and ``report.pdf`` of a validation folder; returns their paths. ``references``:
    ``{case: the reference it is measured against}``; ``missing``: ``{case: why it is not available}`` (both
    from :func:`iceresist.validate.ladder.discover_cases`, passed by the command line)."""
    from matplotlib.backends.backend_pdf import PdfPages

    references, missing = dict(references or {}), dict(missing or {})
    out = Path(out_dir)
    raw = load_table(out)
    if raw.empty:
        raise InputError(f"{out}: no finished validation run (no {out / 'ladder.csv'}); run `iceresist validate "
                         f"--out {out}` first")
    table = with_errors(raw)
    summary = case_summary(table)
    cheapest = cheapest_runs(table)
    plt = pyplot()
    figs = {"error_time": fig_error_time(plt, table, summary)}
    stab = stability_section(plt, out)
    cases = []
    for case in dict.fromkeys(table.case):
        rows = table[table.case == case].sort_values(["ladder", "resolution"])
        cols = dict(RUN_COLUMNS)
        if "error_vs_finest" in rows and rows.error_vs_finest.notna().any():
            cols["error_vs_finest"] = "error vs finest rung"
        fig = CASE_FIGURES[case](plt, rows) if case in CASE_FIGURES else None
        cases.append({"name": case, "reference": references.get(case, ""),
                      "table": html_table(rows, cols, na_rep=""), "rows": rows, "columns": cols, "fig": fig,
                      "image": png64(fig) if fig is not None else ""})
    missing_list = [(n, why) for n, why in missing.items() if n not in set(table.case)]
    html = template_env().get_template("validation.html.j2").render(
        out_dir=str(out), generated=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        summary=html_table(summary, SUMMARY_COLUMNS, na_rep=""),
        cheapest=html_table(cheapest, cheapest_columns(), na_rep=""),
        images={k: png64(f) for k, f in figs.items()}, cases=cases, missing=missing_list,
        stability=None if stab is None else {"note": stab["note"],
                                             "image": png64(stab["fig"]) if stab["fig"] is not None else ""})
    html_path, pdf_path = out / "report.html", out / "report.pdf"
    html_path.write_text(html, encoding="utf-8")
    with PdfPages(pdf_path) as pdf:
        pdf.savefig(pdf_table_page(plt, summary, SUMMARY_COLUMNS, "Validation: observed order per case",
                                   na_rep=""))
        pdf.savefig(pdf_table_page(plt, cheapest, cheapest_columns(), "Cheapest run meeting 10 %, 5 %, 1 % error",
                                   na_rep=""))
        pdf.savefig(figs["error_time"])
        for c in cases:
            pdf.savefig(pdf_table_page(plt, c["rows"], c["columns"], f"{c['name']}", na_rep=""))
            if c["fig"] is not None:
                pdf.savefig(c["fig"])
        if missing_list:
            pdf.savefig(pdf_table_page(plt, pd.DataFrame(missing_list, columns=["case", "status"]),
                                       {"case": "case", "status": "status"}, "Cases not available"))
        if stab is not None and stab["fig"] is not None:
            pdf.savefig(stab["fig"])
    plt.close("all")
    log.info("validation report: %s, %s", html_path, pdf_path)
    return html_path, pdf_path


# -- figures of single cases ------------------------------------------------------------------------------------
def heave_decay_figure(plt, rows: pd.DataFrame):
    """The floating sphere's heave against time, one line per rung whose result file is at hand (the centre's height
    over the water's mean level in the last measured period: the floating level), with the measurement
    (Kramer et al. 2021): the envelope of the release height decaying at the measured rate and the measured first
    trough at half the measured period. None without a result file."""
    fig, ax = plt.subplots(figsize=(7.5, 4.0))
    drawn, h0 = 0, None
    for _, r in rows.iterrows():
        path = Path(str(r.get("x_result_file", "")))
        if not path.is_file():
            continue
        with RunFile(path, "r") as rf:
            ts = rf.timeseries()
        t, z, level = (np.asarray(ts[k], dtype=float) for k in ("time_s", "sphere_z_m", "water_level_m"))
        z = z - level[t >= t[-1] - float(r.reference)].mean()
        h0 = z[0] if h0 is None else h0
        ax.plot(t, 1e3 * z, lw=1.0, label=str(r.label))
        drawn += 1
    if not drawn:
        plt.close(fig)
        return None
    r = rows.iloc[0]
    t = np.linspace(0.0, ax.get_xlim()[1], 200)
    env = 1e3 * h0 * np.exp(-float(r.x_sigma_1_s_reference) * t)
    ax.plot(t, env, "k--", lw=0.8, label="measured decay rate (envelope)")
    ax.plot(t, -env, "k--", lw=0.8)
    ax.plot([0.5 * float(r.reference)], [-1e3 * h0 * float(r.x_first_trough_ratio_reference)], "kv", ms=7,
            label="measured first trough")
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.set_xlabel("time after release [s]")
    ax.set_ylabel("heave [mm]")
    ax.set_title("Floating sphere, free heave decay against Kramer et al. (2021)", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def heave_added_mass_figure(plt, rows: pd.DataFrame):
    """The half-submerged sphere's heave added mass A and damping B from forced oscillation against cells per
    diameter, one line per frequency (KR) and tank, with Hulme's (1982) values dashed. None without the columns."""
    if not {"x_kr", "x_tank_diameters", "x_B", "x_B_reference"} <= set(rows.columns):
        return None
    fig, axes = plt.subplots(1, 2, figsize=(8.5, 3.6))
    for (kr, tank), g in rows.groupby(["x_kr", "x_tank_diameters"]):
        g = g.sort_values("resolution")
        for ax, col, ref in ((axes[0], "value", "reference"), (axes[1], "x_B", "x_B_reference")):
            line, = ax.plot(g.resolution, g[col], "o-", ms=4, label=f"KR {kr:g}, tank {tank:g} D")
            ax.axhline(float(g[ref].iloc[0]), color=line.get_color(), ls="--", lw=0.8)
    for ax, name in zip(axes, ("added mass A = a33 / (rho V)", "damping B = b33 / (rho V omega)")):
        ax.set_xlabel("cells per diameter")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle("Sphere in forced heave against Hulme (1982), dashed", fontsize=9)
    fig.tight_layout()
    return fig


#: Case name -> figure of its rungs (``plt``, the case's rows of the ladder table) drawn under its table.
CASE_FIGURES = {"heave_decay": heave_decay_figure, "heave_added_mass": heave_added_mass_figure}


# -- the stability map (iceresist validate --stability) ----------------------------------------------------
#: Outcomes of a row of the stability matrix (:mod:`iceresist.validate.stability`), in legend order.
OUTCOMES = ("stable", "refused", "stopped by watchdog")
NOT_CAUGHT = "unstable (not caught)"
COLOURS = {"stable": "tab:green", "refused": "tab:orange", "stopped by watchdog": "tab:red", NOT_CAUGHT: "black"}
MARKERS = {"stable": "o", "refused": "X", "stopped by watchdog": "s", NOT_CAUGHT: "*"}


def plot_stability_map(df, ax):
    """The stability map on ``ax``: one row per axis, a coloured marker per setting (label under it), the DEM
    sub-steps per record written above the tier-1 markers."""
    axes = list(dict.fromkeys(df["axis"]))
    for y, axis in enumerate(axes):
        sub = df[df["axis"] == axis].reset_index(drop=True)
        for x, r in sub.iterrows():
            ax.scatter(x, y, s=90, c=COLOURS.get(r["outcome"], "grey"), marker=MARKERS.get(r["outcome"], "o"),
                       edgecolors="k", linewidths=0.5, zorder=3)
            ax.annotate(str(r["setting"]), (x, y), xytext=(0, -11), textcoords="offset points", ha="center",
                        va="top", fontsize=6)
            if not (isinstance(r["dem_substeps"], float) and math.isnan(r["dem_substeps"])):
                ax.annotate(f"{int(r['dem_substeps'])} sub", (x, y), xytext=(0, 7), textcoords="offset points",
                            ha="center", va="bottom", fontsize=6, color="tab:blue")
    ax.set_yticks(range(len(axes)))
    ax.set_yticklabels(axes, fontsize=7)
    ax.set_ylim(len(axes) - 0.5, -0.7)
    ax.set_xlim(-0.6, max(int((df["axis"] == a).sum()) for a in axes) - 0.4)
    ax.set_xticks([])
    ax.set_xlabel("setting (mildest to most extreme, left to right)")
    for outcome in OUTCOMES + (NOT_CAUGHT,):
        if outcome in set(df["outcome"]) or outcome in OUTCOMES:
            ax.scatter([], [], c=COLOURS[outcome], marker=MARKERS[outcome], edgecolors="k", linewidths=0.5,
                       label=outcome)
    ax.legend(loc="lower right", fontsize=7, framealpha=0.9)
    ax.grid(axis="y", alpha=0.3)
    return ax


def write_stability_map(out_dir) -> Path:
    """``DIR/stability.png``: the map of ``DIR/stability.csv``; returns its path."""
    out = Path(out_dir)
    path = out / "stability.csv"
    if not path.is_file():
        raise InputError(f"{out}: no stability.csv; run `iceresist validate --stability --out {out}` first")
    df = pd.read_csv(path)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 0.5 * df["axis"].nunique() + 1.5))
    plot_stability_map(df, ax)
    ax.set_title("Stability map: stable, refused before the start, or stopped by the watchdog")
    fig.tight_layout()
    png = out / "stability.png"
    fig.savefig(png, dpi=150)
    plt.close(fig)
    return png


# -- the settling sphere (docs/notes/settling-sphere.md) --------------------------------------------------------------
def settling_velocity_figure(curves: pd.DataFrame, path) -> Path:
    """Settling velocity against time, one line per ``label`` of ``curves`` (columns label, time_s, w_m_s,
    experiment, terminal_m_s: what :func:`iceresist.validate.cases.settling_sphere.write_curves` writes), with
    the measured terminal velocity of the experiment; written to ``path`` (PNG)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.0, 3.4))
    for label, g in curves.groupby("label", sort=False):
        ax.plot(g.time_s, g.w_m_s, lw=1.0, label=label)
    case, u_ref = str(curves.experiment.iloc[0]), float(curves.terminal_m_s.iloc[0])
    ax.axhline(u_ref, color="k", ls="--", lw=0.8, label=f"ten Cate et al. (2002) {case}: {u_ref} m/s")
    ax.axhspan(0.95 * u_ref, 1.05 * u_ref, color="0.85", zorder=0, label="+- 5 %")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("settling velocity [m/s]")
    ax.set_title(f"Sphere settling in the experiment's box, case {case}", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


if __name__ == "__main__":  # python -m reports.validation settling CURVES.csv OUT.png
    if len(sys.argv) != 4 or sys.argv[1] != "settling":
        print("usage: python -m reports.validation settling CURVES.csv OUT.png", file=sys.stderr)
        raise SystemExit(2)
    settling_velocity_figure(pd.read_csv(sys.argv[2]), sys.argv[3])
