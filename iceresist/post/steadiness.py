"""Does the ice force settle along the channel? The analysis of ``iceresist steadiness CASE.h5 [CASE.h5 ...]``.

The steady mean of a case (paper section 4.2) is taken over a fixed window of the stem's travel. Whether that
window is long enough shows in the mean over consecutive steps of the travel: if the force is still rising from
step to step, the window's mean depends on where it ends (docs/SHIP.md, "Where tier 1 settles"). This module
reads case files (finished, stopped or still being written), cuts each into steps of ``step_m`` of stem travel
from the start of its steady window, and gives the mean ice resistance of each step with its batch-means
interval (:func:`iceresist.post.window_parts`). Positions are stem travel into the ice channel, so cases whose
channels start at different x (tier 1 and tier 2) line up. The command and its figure are
:mod:`reports.steadiness`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from iceresist.errors import InputError
from iceresist.io.hdf5 import RunFile
from iceresist.post.resistance import window_parts

log = logging.getLogger(__name__)

#: Default step of stem travel [m]: half the quick presets' steady window (0.78 m), the split of
#: :func:`iceresist.post.window_halves`.
DEFAULT_STEP_M = 0.39


@dataclass(frozen=True)
class CaseRecord:
    """The ice-force record of one ship case file (model scale)."""

    path: Path
    case: str
    tier: int
    t_s: np.ndarray
    Fx_N: np.ndarray
    x_bow_m: np.ndarray
    channel_start_x_m: float
    window_m: tuple[float, float]
    finished: bool

    @property
    def travel_m(self) -> np.ndarray:
        """Stem travel into the ice channel at each record [m]."""
        return self.x_bow_m - self.channel_start_x_m

    @property
    def window_travel_m(self) -> tuple[float, float]:
        """The steady window in stem travel into the ice channel [m]."""
        return self.window_m[0] - self.channel_start_x_m, self.window_m[1] - self.channel_start_x_m


def read_case_record(path) -> CaseRecord:
    """Read a ship case file written by ``iceresist run`` or ``iceresist sweep``. A file still being written
    is read as far as it goes (no file lock is taken, so a running case can be looked at)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such case file; give the .h5 file of a ship case (iceresist run/sweep)")
    try:
        with RunFile(path, "r", locking=False) as rf:
            meta = rf.meta
            model = rf.meta_object("model")
            ts = {k: rf.h5["timeseries"][k][...] for k in ("time_s", "Fx_N", "x_bow_m")}
            window = tuple(float(v) for v in model["steady_window_m"])
            channel_x0 = float(model["channel_start_x_m"])
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: not a ship case file ({exc.__class__.__name__}: {exc}); give the .h5 file "
                         f"of a ship scene written by iceresist run or sweep") from None
    name = str(meta.get("case", meta.get("scene_name", path.stem)))
    # row 0 is the state before the first step (as in iceresist.post.case.analyse_case)
    return CaseRecord(path=path, case=name, tier=int(model.get("tier", 0)), t_s=ts["time_s"][1:],
                      Fx_N=ts["Fx_N"][1:], x_bow_m=ts["x_bow_m"][1:], channel_start_x_m=channel_x0,
                      window_m=window, finished=bool(meta.get("finished", False)))


def step_edges_m(record: CaseRecord, step_m: float = DEFAULT_STEP_M) -> np.ndarray:
    """Stem positions [m] bounding whole steps of ``step_m`` from the start of the window to the last record
    (an unfinished last step is left out; empty when not even one step has been recorded)."""
    if not (math.isfinite(step_m) and step_m > 0):
        raise InputError(f"step {step_m!r} m must be a positive length in metres (e.g. --step-m 0.39)")
    x0 = record.window_m[0]
    x_end = float(record.x_bow_m[-1]) if record.x_bow_m.size else x0
    n = int(math.floor((x_end - x0) / step_m + 1e-9))
    return x0 + step_m * np.arange(n + 1) if n >= 1 else np.empty(0)


def case_labels(records) -> list[str]:
    """"case (tier N[, not finished])" for each record, with its folder where two records are of one case."""
    names = [rec.case for rec in records]
    return [f"{rec.case} (tier {rec.tier}{'' if rec.finished else ', not finished'})"
            + (f" [{_folder_tag(rec.path)}]" if names.count(rec.case) > 1 else "") for rec in records]


def steadiness_table(cases, step_m: float = DEFAULT_STEP_M) -> pd.DataFrame:
    """One row per case and step: ``case``, ``label`` (:func:`case_labels`), ``tier``, ``finished``, ``step``
    (0 is the first step of the window), ``travel_from_m`` / ``travel_to_m`` (stem travel into the channel),
    ``mean_N``, ``ci95_N``, ``samples``, ``batch_tau_int`` (batch length over the integrated autocorrelation
    time), ``interval_too_narrow`` (:attr:`~iceresist.post.SteadyMean.interval_too_narrow`), ``in_window`` (the
    step lies inside the case's steady window). ``cases``: paths or :class:`CaseRecord`."""
    records = [c if isinstance(c, CaseRecord) else read_case_record(c) for c in cases]
    rows = []
    for rec, label in zip(records, case_labels(records)):
        edges = step_edges_m(rec, step_m)
        if edges.size == 0:
            log.warning("%s: the stem has not yet travelled one step (%.2f m) past the window start", rec.case,
                        step_m)
            continue
        parts = window_parts(rec.t_s, rec.Fx_N, rec.x_bow_m, edges_m=edges, motion_direction=+1)
        for k, (lo, hi, sm) in enumerate(zip(edges[:-1], edges[1:], parts)):
            rows.append({"case": rec.case, "label": label, "tier": rec.tier, "finished": rec.finished, "step": k,
                         "travel_from_m": lo - rec.channel_start_x_m, "travel_to_m": hi - rec.channel_start_x_m,
                         "mean_N": sm.mean_N, "ci95_N": sm.ci_half_width_N, "samples": sm.n_samples,
                         "batch_tau_int": sm.batch_length / sm.tau_int_samples,
                         "interval_too_narrow": sm.interval_too_narrow,
                         "in_window": bool(hi <= rec.window_m[1] + 1e-9), "file": str(rec.path)})
    return pd.DataFrame(rows)


def format_steadiness(table: pd.DataFrame) -> str:
    """The table as text: one line per case, one column per step ("mean +- ci95 N")."""
    if table.empty:
        return "no case has a whole step recorded yet"
    cols = sorted({(round(a, 2), round(b, 2)) for a, b in zip(table.travel_from_m, table.travel_to_m)})
    head = ["case (tier)"] + [f"{a:.2f}-{b:.2f} m" for a, b in cols]
    lines = []
    for label, g in table.groupby("label", sort=False):
        cells = {(round(r.travel_from_m, 2), round(r.travel_to_m, 2)):
                 f"{r.mean_N:.1f} +- {r.ci95_N:.1f}{'~' if r.interval_too_narrow else ''}{'' if r.in_window else '*'}"
                 for r in g.itertuples()}
        lines.append([label] + [cells.get(c, "") for c in cols])
    widths = [max(len(row[i]) for row in [head] + lines) for i in range(len(head))]
    fmt = lambda row: "  ".join(c.ljust(w) for c, w in zip(row, widths))  # noqa: E731
    out = ["mean ice resistance [N] (+- 95 % interval) over steps of stem travel into the channel; "
           "~ interval likely too narrow (batches shorter than 5 tau_int); * after the case's steady window",
           fmt(head)] + [fmt(r) for r in lines]
    return "\n".join(out)


def window_spans(records) -> list[tuple[float, float, int]]:
    """The distinct steady windows of the cases as (from, to) in metres of stem travel into the channel, each once
    (to the millimetre) with the index of its first case, so that cases sharing a window shade it once instead
    of darkening it once per case."""
    spans: dict[tuple[float, float], int] = {}
    for i, rec in enumerate(records):
        spans.setdefault(tuple(round(v, 3) for v in rec.window_travel_m), i)
    return [(lo, hi, i) for (lo, hi), i in spans.items()]


def _folder_tag(path: Path) -> str:
    """The folder that tells a case file apart: the sweep folder for ``SWEEP/cases/CASE.h5``, else the parent."""
    parent = path.resolve().parent
    return parent.parent.name if parent.name == "cases" else parent.name
