"""Simulated ice resistance at full scale beside the FSICR R_CH (the paper's table 2).

Each case gives a model-scale mean ice force with its confidence half width,
the geometric scale and the FSICR channel resistance R_CH (paper eq. 22). The
table converts the mean to full scale by the cubic law
(:func:`iceresist.post.scaling.force_to_full_scale`) and sets it beside R_CH:
ratio sim/FSICR, difference sim - FSICR in kN and in percent of R_CH.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np
import pandas as pd

from iceresist.errors import InputError
from iceresist.post.scaling import force_to_full_scale
from iceresist.post.statistics import SteadyMean

#: Input columns (``density_ratio`` and ``ci95_N`` are optional).
INPUT_COLUMNS = ("case", "mean_force_N", "ci95_N", "scale", "fsicr_R_CH_kN", "density_ratio")
_REQUIRED = ("case", "mean_force_N", "scale", "fsicr_R_CH_kN")

#: Output columns of :func:`comparison_table` and their printed headers with units.
COLUMN_LABELS = {
    "case": "case",
    "F_model_N": "model mean force [N]",
    "F_model_ci95_N": "± 95 % CI [N]",
    "R_sim_kN": "full-scale resistance [kN]",
    "R_sim_ci95_kN": "± 95 % CI [kN]",
    "R_CH_FSICR_kN": "FSICR R_CH [kN]",
    "ratio_sim_FSICR": "sim/FSICR",
    "diff_kN": "difference [kN]",
    "diff_pct": "difference [%]",
}


def comparison_row(case: str, steady: SteadyMean, scale: float, fsicr_R_CH_kN: float,
                   density_ratio: float = 1.0) -> dict:
    """One input row for :func:`comparison_table` from a :class:`SteadyMean` of the model-scale ice force."""
    if steady.confidence != 0.95:
        raise InputError(
            f"steady has a {100 * steady.confidence:g} % interval: the table reports 95 % intervals; "
            "recompute with confidence=0.95"
        )
    return {"case": case, "mean_force_N": steady.mean_N, "ci95_N": steady.ci_half_width_N, "scale": scale,
            "fsicr_R_CH_kN": fsicr_R_CH_kN, "density_ratio": density_ratio}


def _as_frame(cases) -> pd.DataFrame:
    if isinstance(cases, pd.DataFrame):
        df = cases.copy()
    elif isinstance(cases, Iterable) and not isinstance(cases, (str, bytes, Mapping)):
        rows = list(cases)
        if not all(isinstance(r, Mapping) for r in rows):
            raise InputError("cases must be a DataFrame or a list of dicts with keys " + ", ".join(_REQUIRED))
        df = pd.DataFrame(rows)
    else:
        raise InputError("cases must be a DataFrame or a list of dicts with keys " + ", ".join(_REQUIRED))
    if df.empty:
        raise InputError("cases is empty: give at least one case")
    for col in _REQUIRED:
        if col not in df.columns:
            raise InputError(f"cases lacks the column {col!r} (needed: {', '.join(_REQUIRED)})")
    if "ci95_N" not in df.columns:
        df["ci95_N"] = np.nan
    if "density_ratio" not in df.columns:
        df["density_ratio"] = 1.0
    df["density_ratio"] = df["density_ratio"].fillna(1.0)
    for col in ("mean_force_N", "ci95_N", "scale", "fsicr_R_CH_kN", "density_ratio"):
        try:
            df[col] = pd.to_numeric(df[col])
        except (TypeError, ValueError):
            raise InputError(f"cases column {col!r} must hold numbers") from None
    for _, row in df.iterrows():
        name = row["case"]
        if not math.isfinite(row["mean_force_N"]):
            raise InputError(f"case {name!r}: mean_force_N={row['mean_force_N']} must be finite")
        if not (math.isfinite(row["fsicr_R_CH_kN"]) and row["fsicr_R_CH_kN"] > 0.0):
            raise InputError(f"case {name!r}: fsicr_R_CH_kN={row['fsicr_R_CH_kN']} must be a positive number")
        if not (math.isnan(row["ci95_N"]) or row["ci95_N"] >= 0.0):
            raise InputError(f"case {name!r}: ci95_N={row['ci95_N']} must be >= 0 (a half width)")
    return df


def comparison_table(cases) -> pd.DataFrame:
    """Table of simulated full-scale ice resistance against FSICR R_CH, one row per case.

    Args:
        cases: a DataFrame or a list of dicts with keys ``case``, ``mean_force_N``
            (model-scale mean ice force [N]), ``ci95_N`` (its 95 % half width [N],
            optional), ``scale`` (geometric scale lambda), ``fsicr_R_CH_kN`` (FSICR
            R_CH at full scale [kN]) and optionally ``density_ratio`` (rho_full/rho_model, default 1).

    Returns:
        DataFrame with the columns of :data:`COLUMN_LABELS`: model mean and CI [N],
        full-scale resistance and CI [kN], R_CH [kN], ratio sim/FSICR, difference
        sim - FSICR [kN] and in percent of R_CH.
    """
    df = _as_frame(cases)
    out = pd.DataFrame({"case": df["case"].astype(str).to_numpy()})
    out["F_model_N"] = df["mean_force_N"].to_numpy(dtype=float)
    out["F_model_ci95_N"] = df["ci95_N"].to_numpy(dtype=float)
    r_kn = np.empty(len(df))
    ci_kn = np.empty(len(df))
    for i, (_, row) in enumerate(df.iterrows()):
        r_kn[i] = force_to_full_scale(row["mean_force_N"], row["scale"], row["density_ratio"]) / 1e3
        ci_kn[i] = force_to_full_scale(row["ci95_N"], row["scale"], row["density_ratio"]) / 1e3
    out["R_sim_kN"] = r_kn
    out["R_sim_ci95_kN"] = ci_kn
    out["R_CH_FSICR_kN"] = df["fsicr_R_CH_kN"].to_numpy(dtype=float)
    out["ratio_sim_FSICR"] = out["R_sim_kN"] / out["R_CH_FSICR_kN"]
    out["diff_kN"] = out["R_sim_kN"] - out["R_CH_FSICR_kN"]
    out["diff_pct"] = 100.0 * out["diff_kN"] / out["R_CH_FSICR_kN"]
    return out


def case_ratio(table: pd.DataFrame, numerator: str, denominator: str) -> tuple[float, float]:
    """Ratio of two cases (e.g. Bow B / Bow A): (simulated, FSICR). The paper reports 1.76 and 1.21."""
    rows = table.set_index("case")
    for name, case in (("numerator", numerator), ("denominator", denominator)):
        if case not in rows.index:
            raise InputError(f"{name}={case!r} is not a case of the table (cases: {', '.join(rows.index)})")
    sim = rows.at[numerator, "R_sim_kN"] / rows.at[denominator, "R_sim_kN"]
    rules = rows.at[numerator, "R_CH_FSICR_kN"] / rows.at[denominator, "R_CH_FSICR_kN"]
    return float(sim), float(rules)


def format_comparison_table(table: pd.DataFrame, style: str = "text", digits: int = 4) -> str:
    """Readable text of a :func:`comparison_table`: ``style="text"`` (aligned columns) or ``"markdown"``.

    Forces are printed with ``digits`` significant digits, the ratio with 3
    decimals, percentages with 1 decimal.
    """
    if style not in ("text", "markdown"):
        raise InputError(f"style={style!r} must be 'text' or 'markdown'")
    missing = [c for c in COLUMN_LABELS if c not in table.columns]
    if missing:
        raise InputError(f"table lacks the column {missing[0]!r}: build it with comparison_table()")

    def fmt(col: str, v) -> str:
        if col == "case":
            return str(v)
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return "-"
        if col == "ratio_sim_FSICR":
            return f"{v:.3f}"
        if col == "diff_pct":
            return f"{v:+.1f}"
        if col == "diff_kN":
            return f"{v:+.{digits}g}"
        return f"{v:.{digits}g}"

    cols = list(COLUMN_LABELS)
    header = [COLUMN_LABELS[c] for c in cols]
    body = [[fmt(c, row[c]) for c in cols] for _, row in table.iterrows()]
    if style == "markdown":
        lines = ["| " + " | ".join(header) + " |",
                 "|" + "|".join("---" if c == "case" else "---:" for c in cols) + "|"]
        lines += ["| " + " | ".join(r) + " |" for r in body]
        return "\n".join(lines)
    widths = [max(len(h), *(len(r[j]) for r in body)) for j, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) if j == 0 else h.rjust(w) for j, (h, w) in enumerate(zip(header, widths)))]
    lines += ["  ".join(v.ljust(w) if j == 0 else v.rjust(w) for j, (v, w) in enumerate(zip(r, widths)))
              for r in body]
    return "\n".join(lines)
