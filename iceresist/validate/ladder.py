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
import pkgutil
import time
from pathlib import Path

import pandas as pd

import iceresist.validate.cases as pkg
from iceresist.errors import InputError
from iceresist.post.convergence import TABLE_NAME, load_table

log = logging.getLogger(__name__)

#: The reference cases of ``iceresist validate`` in report order (issue: error against run time).
KNOWN_CASES = ("poiseuille", "taylor_green", "sphere_drag", "sphere_array", "standing_wave", "dam_break", "floating_cube",
               "heave_decay", "heave_added_mass",
               "settling_sphere", "ship_tier1", "ship_tier2", "ship_tier2_amr")
KEY = ("case", "label", "ladder", "backend", "precision")


# -- discovery ---------------------------------------------------------------------------------------------
def discover_cases() -> tuple[dict, dict]:
    """``(available, missing)``: case modules by NAME that import and follow the protocol, and
    ``{name: reason}`` for the known cases that do not (absent module, import error, missing attribute)."""
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
    if modules is None:
        available, missing = discover_cases()
    else:
        available, missing = dict(modules), {}
    names = select_cases(cases, available, missing)
    ladder = "quick" if quick else "full"
    bare = [n for n in names if not available[n].ladder(quick)]
    if bare and len(bare) == len(names):
        raise InputError(f"--cases: {', '.join(bare)} {'has' if len(bare) == 1 else 'have'} no rungs on the {ladder} "
                         f"ladder; run {'it' if len(bare) == 1 else 'them'} with --{'full' if quick else 'quick'}")
    for n in bare:
        log.info("validate: %s has no rungs on the %s ladder", n, ladder)
    out.mkdir(parents=True, exist_ok=True)
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
            res = available[name].run(params, backend=backend, precision=precision, out_dir=out)
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
