"""``iceresist steadiness CASE.h5 [CASE.h5 ...]``: the mean ice force over steps of stem travel into the channel
(:mod:`iceresist.post.steadiness`), printed as a table, optionally written as CSV and drawn as a PNG.

Reads case files only (finished, stopped or still being written); never changes them.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from iceresist.post.steadiness import (
    DEFAULT_STEP_M,
    case_labels,
    format_steadiness,
    read_case_record,
    steadiness_table,
    window_spans,
)
from reports.common import pyplot


def plot_steadiness(table: pd.DataFrame, records, png) -> Path:
    """Force against stem travel into the channel for each case (thin line) with the step means and their
    intervals (bars): where the bars stop rising, the force has settled."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for i, (rec, label) in enumerate(zip(records, case_labels(records))):
        colour = f"C{i}"
        g = table[table.file == str(rec.path)] if len(table) else table
        ax.plot(rec.travel_m, -rec.Fx_N, color=colour, lw=0.4, alpha=0.35, label=None if len(g) else label)
        if len(g):
            mid = 0.5 * (g.travel_from_m + g.travel_to_m)
            ax.errorbar(mid, g.mean_N, yerr=g.ci95_N, xerr=0.5 * (g.travel_to_m - g.travel_from_m), fmt="o",
                        color=colour, capsize=3, label=label)
    for lo, hi, i in window_spans(records):
        ax.axvspan(lo, hi, color=f"C{i}", alpha=0.08)
    ax.set_xlabel("stem travel into the ice channel [m]")
    ax.set_ylabel("ice resistance, model scale [N]")
    ax.set_title("Does the ice force settle? Step means (bars: 95 % interval); shaded: steady window")
    if len(table):
        top = float((table.mean_N + table.ci95_N).max())
        ax.set_ylim(min(0.0, float((table.mean_N - table.ci95_N).min())) * 1.2, 2.5 * top)
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3)
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return png


def add_steadiness_arguments(p) -> None:
    """Arguments of ``iceresist steadiness``; sets ``func=cmd_steadiness``."""
    p.add_argument("cases", nargs="+", help="case files (.h5) of ship runs; a running case is read as far as it goes")
    p.add_argument("--step-m", type=float, default=DEFAULT_STEP_M,
                   help=f"step of stem travel in metres (default {DEFAULT_STEP_M}, half the quick window)")
    p.add_argument("--plot", default=None, help="also draw the force against stem travel into this PNG file")
    p.add_argument("--csv", default=None, help="also write the table (one row per case and step) to this CSV file")
    p.add_argument("--json", action="store_true", help="print the table as JSON (one object per case and step)")
    p.set_defaults(func=cmd_steadiness)


def cmd_steadiness(args) -> int:
    records = [read_case_record(path) for path in args.cases]
    table = steadiness_table(records, args.step_m)
    print(table.to_json(orient="records") if args.json else format_steadiness(table))
    if args.csv:
        table.to_csv(args.csv, index=False)
        if not args.json:
            print(f"table: {args.csv}")
    if args.plot:
        png = plot_steadiness(table, records, args.plot)
        if not args.json:
            print(f"figure: {png}")
    return 0
