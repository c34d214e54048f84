"""Reduction of the resolution ladders of ``iceresist validate`` (``DIR/ladder.csv``) to error against run time:
observed order of convergence, Richardson extrapolation where a case has no external reference, the cheapest
run meeting each error level, and the Markdown table of docs/VALIDATION.md.

A case without an external reference (``reference`` NaN, e.g. the ship) is measured against its own ladder:
the Richardson extrapolation of its three finest rungs where they converge monotonically, else its finest
rung (Roache 1998, *Verification and validation in computational science and engineering*, ch. 5).
Reads the table the ladders wrote; runs nothing and writes nothing.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

#: Error levels of the cheapest-run table.
THRESHOLDS = (0.10, 0.05, 0.01)
#: The ladders' table in a validation folder.
TABLE_NAME = "ladder.csv"


def load_table(out_dir) -> pd.DataFrame:
    """The rows written so far (empty frame when none)."""
    path = Path(out_dir) / TABLE_NAME
    if not path.is_file() or path.stat().st_size == 0:
        return pd.DataFrame()
    return pd.read_csv(path)



# -- convergence -------------------------------------------------------------------------------------------
def observed_order(resolution, error) -> float:
    """Least-squares slope p of log(error) = c - p log(resolution): the observed order of convergence.

    NaN with fewer than two positive finite errors."""
    n = np.asarray(resolution, dtype=float)
    e = np.asarray(error, dtype=float)
    ok = np.isfinite(n) & np.isfinite(e) & (n > 0) & (e > 0)
    if ok.sum() < 2:
        return float("nan")
    return float(-np.polyfit(np.log(n[ok]), np.log(e[ok]), 1)[0])


def richardson(resolution, value) -> tuple[float, float]:
    """Observed order p and extrapolated value of the three finest rungs (Roache 1998, eqs. 5.4.1-5.4.3).

    With h = 1/resolution and f1, f2, f3 from coarse to fine, p solves
    (f1 - f2)/(f2 - f3) = (h1^p - h2^p)/(h2^p - h3^p) (closed form ln(ratio)/ln(r) for a constant
    refinement ratio r), and f_exact = f3 + (f3 - f2) h3^p/(h2^p - h3^p). Returns (NaN, NaN) when the
    differences change sign (oscillatory or no convergence) or fewer than three rungs are given."""
    n = np.asarray(resolution, dtype=float)
    f = np.asarray(value, dtype=float)
    order = np.argsort(n)
    n, f = n[order][-3:], f[order][-3:]
    if len(n) < 3 or not np.all(np.isfinite(f)) or len(set(n)) < 3:
        return float("nan"), float("nan")
    h1, h2, h3 = 1.0 / n
    d12, d23 = f[0] - f[1], f[1] - f[2]
    if d23 == 0.0 or d12 == 0.0 or np.sign(d12) != np.sign(d23):
        return float("nan"), float("nan")
    ratio = d12 / d23
    r21, r32 = h1 / h2, h2 / h3
    if math.isclose(r21, r32, rel_tol=1e-9):
        if ratio <= 1.0:
            return float("nan"), float("nan")
        p = math.log(ratio) / math.log(r32)
    else:
        from scipy.optimize import brentq

        def g(p):
            return (h1 ** p - h2 ** p) / (h2 ** p - h3 ** p) - ratio

        try:
            p = brentq(g, 1e-3, 20.0)
        except ValueError:
            return float("nan"), float("nan")
    f_ext = f[2] + (f[2] - f[1]) * h3 ** p / (h2 ** p - h3 ** p)
    return float(p), float(f_ext)


def with_errors(table: pd.DataFrame) -> pd.DataFrame:
    """The table with ``error`` filled in for cases measured against their own ladder, and the column
    ``reference_kind`` ("external", "Richardson" or "finest rung"), and for those cases ``error_vs_finest`` (the
    error against the finest rung) and ``richardson_order``. Rows of a case without an external
    reference get the Richardson value of their ladder where it exists, else the finest rung's value."""
    if table.empty:
        return table.assign(reference_kind=pd.Series(dtype=str))
    t = table.copy()
    t["reference_kind"] = "external"
    for (case, ladder, backend, precision), g in t.groupby(["case", "ladder", "backend", "precision"]):
        if np.isfinite(g.reference.astype(float)).all():
            continue
        p, f_ext = richardson(g.resolution, g.value)
        finest = float(g.loc[g.resolution.idxmax(), "value"])
        t.loc[g.index, "error_vs_finest"] = (g.value - finest).abs() / abs(finest) if finest != 0 else np.nan
        if np.isfinite(f_ext) and f_ext != 0.0:
            ref, kind = f_ext, "Richardson"
        else:
            ref, kind = finest, "finest rung"
        t.loc[g.index, "reference"] = ref
        t.loc[g.index, "error"] = (g.value - ref).abs() / abs(ref) if ref != 0 else np.nan
        t.loc[g.index, "reference_kind"] = kind
        t.loc[g.index, "richardson_order"] = p
    return t


def cheapest_runs(table: pd.DataFrame, thresholds=THRESHOLDS) -> pd.DataFrame:
    """Per case and ladder, the run of least wall time whose error is at most each threshold.

    Columns: case, ladder, then for each threshold ``label_<pct>``, ``wall_s_<pct>``, ``error_<pct>``
    (NaN / "" where the ladder does not reach it)."""
    rows = []
    if table.empty:
        return pd.DataFrame(columns=["case", "ladder"])
    for (case, ladder), g in table.groupby(["case", "ladder"], sort=False):
        row = {"case": case, "ladder": ladder}
        for thr in thresholds:
            pct = f"{100 * thr:g}"
            ok = g[g.error <= thr]
            if ok.empty:
                row.update({f"label_{pct}": "", f"wall_s_{pct}": np.nan, f"error_{pct}": np.nan})
            else:
                best = ok.loc[ok.wall_s.idxmin()]
                row.update({f"label_{pct}": best.label, f"wall_s_{pct}": float(best.wall_s),
                            f"error_{pct}": float(best.error)})
        rows.append(row)
    return pd.DataFrame(rows)


def case_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per case and ladder: rungs, observed order (error against resolution), smallest error, total wall time,
    whether the error falls at every refinement, and the reference kind."""
    rows = []
    for (case, ladder), g in table.groupby(["case", "ladder"], sort=False):
        g = g.sort_values("resolution")
        e = g.error.to_numpy(dtype=float)
        pos = g[g.error > 0]
        rows.append({"case": case, "ladder": ladder, "rungs": len(g),
                     "observed_order": observed_order(pos.resolution, pos.error),
                     "min_error": float(np.nanmin(e)) if np.isfinite(e).any() else np.nan,
                     "wall_s": float(g.wall_s.sum()),
                     "monotone": bool(np.all(np.diff(e[e > 0]) < 0)) if (e > 0).sum() > 1 else False,
                     "reference_kind": g.reference_kind.iloc[0] if "reference_kind" in g else "external"})
    return pd.DataFrame(rows)


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
