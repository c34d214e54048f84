"""The validation report of a ``iceresist validate`` folder: ``report.html`` (self-contained) and ``report.pdf``.

Reads only ``DIR/ladder.csv`` (and ``DIR/stability.csv`` where the stability matrix was run); never runs a
simulation. Uses the machinery of the ship report (:mod:`reports.common`).
"""

from __future__ import annotations

import datetime as _dt
import logging
import math
from pathlib import Path

import pandas as pd

from iceresist.errors import InputError
from iceresist.validate.ladder import THRESHOLDS, case_summary, cheapest_runs, load_table, with_errors

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
    try:
        from iceresist.validate.stability import plot_stability_map
    except ImportError as exc:
        return {"note": f"stability.csv holds {len(df)} runs; the map needs iceresist.validate.stability ({exc})",
                "fig": None}
    fig, ax = plt.subplots(figsize=(6.0, 4.5), layout="constrained")
    try:
        plot_stability_map(df, ax)
    except Exception as exc:  # a table the map cannot read must not cost the rest of the report
        plt.close(fig)
        log.error("stability map: %s: %s", type(exc).__name__, exc)
        return {"note": f"stability.csv holds {len(df)} runs; the map could not be drawn ({type(exc).__name__}: "
                        f"{exc})", "fig": None}
    return {"note": f"{len(df)} runs from {path.name}.", "fig": fig}


def write_validation_report(out_dir) -> tuple[Path, Path]:
    """Write ``report.html`` and ``report.pdf`` of a validation folder; returns their paths."""
    from matplotlib.backends.backend_pdf import PdfPages

    from iceresist.validate.ladder import discover_cases
    from reports.common import html_table, pdf_table_page, png64, pyplot, template_env

    out = Path(out_dir)
    raw = load_table(out)
    if raw.empty:
        raise InputError(f"{out}: no finished validation run (no {out / 'ladder.csv'}); run `iceresist validate "
                         f"--out {out}` first")
    table = with_errors(raw)
    summary = case_summary(table)
    cheapest = cheapest_runs(table)
    available, missing = discover_cases()
    plt = pyplot()
    figs = {"error_time": fig_error_time(plt, table, summary)}
    stab = stability_section(plt, out)
    cases = []
    for case in dict.fromkeys(table.case):
        mod = available.get(case)
        rows = table[table.case == case].sort_values(["ladder", "resolution"])
        cols = dict(RUN_COLUMNS)
        if "error_vs_finest" in rows and rows.error_vs_finest.notna().any():
            cols["error_vs_finest"] = "error vs finest rung"
        cases.append({"name": case, "reference": getattr(mod, "REFERENCE", "") if mod else "",
                      "table": html_table(rows, cols, na_rep=""), "rows": rows, "columns": cols})
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
        if missing_list:
            pdf.savefig(pdf_table_page(plt, pd.DataFrame(missing_list, columns=["case", "status"]),
                                       {"case": "case", "status": "status"}, "Cases not available"))
        if stab is not None and stab["fig"] is not None:
            pdf.savefig(stab["fig"])
    plt.close("all")
    log.info("validation report: %s, %s", html_path, pdf_path)
    return html_path, pdf_path


def markdown_table(table: pd.DataFrame) -> str:
    """The error-against-run-time table as Markdown (docs/VALIDATION.md): one row per run with the case's
    observed order, then the cheapest run meeting each threshold."""
    t = with_errors(table) if "reference_kind" not in table else table
    summary = case_summary(t)
    lines = ["| case | ladder | rung | cells | steps | wall [s] | MLUPS | value | reference | error | order p |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    order = {c: i for i, c in enumerate(dict.fromkeys(t.case))}
    for _, r in t.sort_values(["case", "ladder", "resolution"], key=lambda c: c.map(order) if c.name == "case" else c,
                              kind="stable").iterrows():
        s = summary[(summary.case == r.case) & (summary.ladder == r.ladder)].iloc[0]
        lines.append(f"| {r.case} | {r.ladder} | {r.label} | {int(r.cells)} | {int(r.steps)} | {r.wall_s:.3g} | "
                     f"{r.mlups:.3g} | {r.value:.5g} | {r.reference:.5g} | {r.error:.3g} | "
                     f"{s.observed_order:.2f} |")
    lines += ["", "| case | ladder | " + " | ".join(f"≤ {100 * t_:g} %" for t_ in THRESHOLDS) + " |",
              "|---|---|" + "---|" * len(THRESHOLDS)]
    for _, r in cheapest_runs(t).iterrows():
        cells = []
        for thr in THRESHOLDS:
            pct = f"{100 * thr:g}"
            lab = r[f"label_{pct}"]
            cells.append(f"{lab} ({r[f'wall_s_{pct}']:.3g} s)" if isinstance(lab, str) and lab else "not reached")
        lines.append(f"| {r.case} | {r.ladder} | " + " | ".join(cells) + " |")
    return "\n".join(lines)

