"""Run the resolution ladders of the reference cases and reduce them to error against run time.

Every finished run is appended at once as one row to ``DIR/ladder.csv`` (columns of
:meth:`CaseResult.row` plus ``ladder`` = "quick"/"full"), so a killed validation keeps what it did and a
rerun skips the rungs already in the table.

A case without an external reference (``reference`` NaN, e.g. the ship) is measured against its own ladder:
the Richardson extrapolation of its three finest rungs where they converge monotonically, else its finest
rung (Roache 1998, *Verification and validation in computational science and engineering*, ch. 5).
"""

from __future__ import annotations

import importlib
import logging
import math
import pkgutil
import time
from pathlib import Path

import numpy as np
import pandas as pd

from iceresist.errors import InputError

log = logging.getLogger(__name__)

#: The reference cases of ``iceresist validate`` in report order (issue: error against run time).
KNOWN_CASES = ("poiseuille", "taylor_green", "sphere_drag", "standing_wave", "dam_break", "floating_cube",
               "settling_sphere", "ship_tier1", "ship_tier2")
#: Error levels of the cheapest-run table.
THRESHOLDS = (0.10, 0.05, 0.01)
TABLE_NAME = "ladder.csv"
KEY = ("case", "label", "ladder", "backend", "precision")


# -- discovery ---------------------------------------------------------------------------------------------
def discover_cases() -> tuple[dict, dict]:
    """``(available, missing)``: case modules by NAME that import and follow the protocol, and
    ``{name: reason}`` for the known cases that do not (absent module, import error, missing attribute)."""
    import iceresist.validate.cases as pkg

    names = list(KNOWN_CASES) + sorted(m.name for m in pkgutil.iter_modules(pkg.__path__)
                                       if m.name not in KNOWN_CASES and not m.name.startswith("_"))
    present = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    available, missing = {}, {}
    for name in names:
        if name not in present:
            missing[name] = "not available (no case module in this version)"
            continue
        try:
            mod = importlib.import_module(f"iceresist.validate.cases.{name}")
        except Exception as exc:  # a broken case must not stop the others
            missing[name] = f"not available (import failed: {type(exc).__name__}: {exc})"
            continue
        lacking = [a for a in ("NAME", "REFERENCE", "ladder", "run") if not hasattr(mod, a)]
        if lacking:
            missing[name] = f"not available (module lacks {', '.join(lacking)})"
            continue
        available[mod.NAME] = mod
    return available, missing


def select_cases(cases, available: dict, missing: dict) -> list[str]:
    """Case names to run from ``--cases a,b`` (None or "all" = every available case)."""
    if cases is None or cases == "all":
        return list(available)
    if isinstance(cases, str):
        cases = [c.strip() for c in cases.split(",") if c.strip()]
    out = []
    for c in cases:
        if c in available:
            out.append(c)
        elif c in missing:
            raise InputError(f"--cases: case {c!r} is {missing[c]}")
        else:
            raise InputError(f"--cases: unknown case {c!r}; known cases: {', '.join(list(available) + list(missing))}")
    return out


# -- the table ---------------------------------------------------------------------------------------------
def load_table(out_dir) -> pd.DataFrame:
    """The rows written so far (empty frame when none)."""
    path = Path(out_dir) / TABLE_NAME
    if not path.is_file() or path.stat().st_size == 0:
        return pd.DataFrame()
    return pd.read_csv(path)


def append_row(out_dir, row: dict):
    """Append one run to ``ladder.csv``; new ``x_`` columns of a later case widen the table."""
    path = Path(out_dir) / TABLE_NAME
    new = pd.DataFrame([row])
    if path.is_file() and path.stat().st_size > 0:
        old = pd.read_csv(path)
        if set(new.columns) <= set(old.columns):
            new.reindex(columns=old.columns).to_csv(path, mode="a", header=False, index=False, float_format="%.10g")
            return
        new = pd.concat([old, new], ignore_index=True)
    new.to_csv(path, index=False, float_format="%.10g")


def finished(table: pd.DataFrame, case: str, label: str, ladder: str, backend: str, precision: str) -> bool:
    if table.empty:
        return False
    sel = ((table.case == case) & (table.label == label) & (table.ladder == ladder) & (table.backend == backend)
           & (table.precision == precision))
    return bool(sel.any())


def run_ladders(out_dir, *, quick: bool = True, cases=None, backend: str = "cpu", precision: str = "float32",
                progress: bool = True, modules: dict | None = None) -> pd.DataFrame:
    """Run every rung of every selected case not yet in ``DIR/ladder.csv``; returns the whole table.

    ``modules`` replaces the discovered case modules (tests)."""
    from tqdm import tqdm

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if modules is None:
        available, missing = discover_cases()
    else:
        available, missing = dict(modules), {}
    names = select_cases(cases, available, missing)
    ladder = "quick" if quick else "full"
    table = load_table(out)
    todo = [(n, p) for n in names for p in available[n].ladder(quick)
            if not finished(table, n, p["label"], ladder, backend, precision)]
    skipped = sum(len(available[n].ladder(quick)) for n in names) - len(todo)
    if skipped:
        log.info("validate: %d rungs finished earlier, skipped", skipped)
    bar = tqdm(todo, disable=not progress, unit="run")
    for name, params in bar:
        bar.set_description(f"{name} {params['label']}")
        t0 = time.perf_counter()
        try:
            res = available[name].run(params, backend=backend, precision=precision)
        except InputError:
            raise
        except Exception as exc:  # one failing rung is reported and the ladder goes on
            log.error("validate: %s %s failed: %s: %s", name, params["label"], type(exc).__name__, exc)
            continue
        row = res.row()
        row["ladder"] = ladder
        row["total_s"] = time.perf_counter() - t0
        append_row(out, row)
        log.info("validate: %s %s: %s = %.6g (reference %.6g), error %.3g, %.3g s, %.3g MLUPS", name,
                 params["label"], res.quantity, res.value, res.reference, res.error, res.wall_s, res.mlups)
    return load_table(out)


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
