"""The paper's trends, checked on a sweep table (Watanabe, Hu and Aoki 2023, section 4).

The paper finds that the mean ice resistance rises with ice concentration (figs 9d and 10d, table 2) and with
ship speed, and that the steeper Bow B meets more resistance than Bow A (1.76 x simulated, 1.21 x by FSICR).
Its full-scale values are of the order of the FSICR channel resistance R_CH (0.64 and 0.93 x). Each check here
reads only the sweep table (``iceresist.post.sweeptable.sweep_table``): the mean force and its 95 % interval per case.

A trend *holds* when the means are in the stated order. It is *resolved* when, in addition, the 95 % intervals
of neighbouring cases do not overlap, so that the order is not an accident of the averaging window.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# (name, cases in the order the mean resistance must rise)
PAPER_TRENDS = (
    ("rises with ice concentration (Bow A, 1 knot: 50, 68, 88 %)", ("A-c50-v1.0", "A-c68-v1.0", "A-c88-v1.0")),
    ("rises with ship speed (Bow A, 68 %: 1, 1.5, 2 knots)", ("A-c68-v1.0", "A-c68-v1.5", "A-c68-v2.0")),
    ("Bow B above Bow A (68 %, 1 knot)", ("A-c68-v1.0", "B-c68-v1.0")),
)
FSICR_FACTOR = 3.0
"""The project's bound for full scale "of the order of" FSICR R_CH: within this factor either way. The paper's own
ratios are 0.64 (Bow A) and 0.93 (Bow B)."""
ORDER_OF_MAGNITUDE = 10.0
"""The literal "same order" of the issue: within a factor of ten either way."""


@dataclass(frozen=True)
class TrendCheck:
    """One trend on one sweep: the cases that were found, their means (N, model scale) and the verdict."""

    name: str
    cases: tuple[str, ...]
    mean_N: tuple[float, ...]
    ci95_N: tuple[float, ...]
    missing: tuple[str, ...]

    @property
    def holds(self) -> bool | None:
        """Means rise in the stated order; None when a case of the trend is missing."""
        if self.missing:
            return None
        return bool(np.all(np.diff(self.mean_N) > 0))

    @property
    def resolved(self) -> bool | None:
        """Means rise and neighbouring 95 % intervals do not overlap; None when a case is missing."""
        if self.missing:
            return None
        lo = np.array(self.mean_N) - np.array(self.ci95_N)
        hi = np.array(self.mean_N) + np.array(self.ci95_N)
        return bool(self.holds and np.all(lo[1:] > hi[:-1]))

    @property
    def verdict(self) -> str:
        if self.missing:
            return "not run (" + ", ".join(self.missing) + " missing)"
        if not self.holds:
            return "does not hold"
        return "holds, intervals apart" if self.resolved else "holds in the means, intervals overlap"

    def values(self) -> str:
        """'5.69 +- 3.30 < 10.3 +- 2.81 N' for the cases found."""
        parts = [f"{m:.3g} +- {c:.2g}" for m, c in zip(self.mean_N, self.ci95_N)]
        return " < ".join(parts) + " N" if parts else ""


def paper_trends(table) -> list[TrendCheck]:
    """The three trends of :data:`PAPER_TRENDS` on ``table`` (columns case, mean_force_N, ci95_N)."""
    by_case = table.set_index("case")
    out = []
    for name, cases in PAPER_TRENDS:
        found = [c for c in cases if c in by_case.index]
        out.append(TrendCheck(name=name, cases=tuple(found),
                              mean_N=tuple(float(by_case.at[c, "mean_force_N"]) for c in found),
                              ci95_N=tuple(float(by_case.at[c, "ci95_N"]) for c in found),
                              missing=tuple(c for c in cases if c not in by_case.index)))
    return out


def fsicr_order(table, factor: float = FSICR_FACTOR) -> tuple[bool, float, float]:
    """(every case within ``factor`` of FSICR R_CH either way, smallest ratio, largest ratio)."""
    r = np.asarray(table["ratio_sim_FSICR"], dtype=float)
    return bool(np.all((r > 1 / factor) & (r < factor))), float(r.min()), float(r.max())


def trends_table(table):
    """The checks as a DataFrame for the report: trend, values, verdict; and the FSICR order row."""
    import pandas as pd

    rows = [{"trend": t.name, "values": t.values(), "verdict": t.verdict} for t in paper_trends(table)]
    ok3, lo, hi = fsicr_order(table)
    ok10 = fsicr_order(table, ORDER_OF_MAGNITUDE)[0]
    if ok3:
        verdict = f"holds (within {FSICR_FACTOR:g} x)"
    elif ok10:
        verdict = f"same order of magnitude, not within {FSICR_FACTOR:g} x"
    else:
        verdict = "does not hold"
    rows.append({"trend": "full scale of the order of FSICR R_CH (paper: 0.64 and 0.93 x)",
                 "values": f"sim / FSICR {lo:.2f} to {hi:.2f}", "verdict": verdict})
    return pd.DataFrame(rows)
