"""The table of a sweep folder, read from its case files.

Layout of a sweep folder (written by ``iceresist sweep``, :mod:`iceresist.sweep`)::

    DIR/sweep.json            preset, tier, cases asked for
    DIR/cases/<case>.h5       one finished run
    DIR/sweep.csv             the table, written by the sweep once at its end

:func:`sweep_table` analyses every finished case file (:func:`iceresist.post.case.analyse_case`) and returns
the table; it writes nothing, so reading a sweep (``iceresist report``) leaves ``sweep.csv`` as the sweep wrote it.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from iceresist.errors import InputError
from iceresist.io.hdf5 import RunFile
from iceresist.post.case import analyse_case
from iceresist.ship.cases import CASES, FIDELITY_NOTES

#: The table's file in a sweep folder.
TABLE_NAME = "sweep.csv"


def case_path(out_dir, case: str) -> Path:
    return Path(out_dir) / "cases" / f"{case}.h5"


def stored_meta(path: Path) -> dict | None:
    """The meta attributes of a case file, or None when there is no readable one."""
    if not path.is_file():
        return None
    try:
        with RunFile(path, "r") as rf:
            return rf.meta
    except (OSError, KeyError):
        return None


def is_finished(path: Path) -> bool:
    """A case file under its final name that records a completed run."""
    meta = stored_meta(path)
    return bool(meta is not None and meta.get("finished", False))


def sweep_table(out_dir) -> pd.DataFrame:
    """The table of every finished case in ``out_dir``, one row per case (:func:`~iceresist.post.case.analyse_case`),
    in the order of the folder's ``sweep.json`` (the sweep's matrix), else of the paper's matrix
    (:data:`iceresist.ship.cases.CASES`)."""
    out = Path(out_dir)
    return pd.DataFrame([_analyse(case_path(out, c)) for c in case_order(out) if is_finished(case_path(out, c))])


def case_order(out: Path) -> list[str]:
    """The cases of a sweep folder in its matrix's order: its ``sweep.json`` list, else the paper's matrix."""
    import json

    try:
        cases = json.loads((out / "sweep.json").read_text()).get("cases")
    except (OSError, ValueError, AttributeError):
        cases = None
    if isinstance(cases, list) and all(isinstance(c, str) for c in cases):
        return cases
    return list(CASES)


def _analyse(path: Path) -> dict:
    """:func:`analyse_case`, a file that is not a whole case result named in one line."""
    try:
        return analyse_case(path)
    except (KeyError, OSError, ValueError, IndexError) as exc:
        raise InputError(f"{path}: marked finished but not a readable case result ({type(exc).__name__}: {exc}); "
                         f"move it away and run the sweep again to redo the case") from None


def preset_note(preset: str | None, tier: int) -> str:
    """What the quick preset trades away (:data:`iceresist.ship.cases.FIDELITY_NOTES`; its tier-2 note too for
    a tier-2 sweep, with the grid caveat); empty for the paper preset."""
    if preset != "quick":
        return ""
    note = "Quick preset: " + FIDELITY_NOTES[("quick", 1)]
    if tier == 2:
        note += " Tier 2: " + FIDELITY_NOTES[("quick", 2)]
    return note
