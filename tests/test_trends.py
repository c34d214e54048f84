"""The paper's trend checks on hand-made sweep tables: order, overlap of intervals, missing cases, FSICR order."""

import pandas as pd

from iceresist.post.trends import fsicr_order, paper_trends, trends_table

CASES = ["A-c50-v1.0", "A-c68-v1.0", "A-c88-v1.0", "A-c68-v1.5", "A-c68-v2.0", "B-c68-v1.0"]


def table(means, ci, ratios=None):
    ratios = ratios or [0.5] * len(means)
    return pd.DataFrame({"case": CASES[:len(means)], "mean_force_N": means, "ci95_N": ci,
                         "ratio_sim_FSICR": ratios})


def by_name(checks):
    return {c.name.split(" (")[0]: c for c in checks}


def test_trends_hold_and_resolve_when_intervals_are_apart():
    t = by_name(paper_trends(table([3.0, 6.0, 10.0, 8.5, 12.0, 7.5], [1.0] * 6)))
    conc, speed, bow = t["rises with ice concentration"], t["rises with ship speed"], t["Bow B above Bow A"]
    assert conc.holds and conc.resolved and conc.mean_N == (3.0, 6.0, 10.0)
    assert speed.holds and speed.resolved and speed.cases == ("A-c68-v1.0", "A-c68-v1.5", "A-c68-v2.0")
    assert bow.holds and not bow.resolved          # 6 +- 1 against 7.5 +- 1 overlap
    assert bow.verdict == "holds in the means, intervals overlap"


def test_a_reversed_or_flat_trend_does_not_hold():
    t = by_name(paper_trends(table([3.0, 6.0, 5.0, 6.0, 9.0, 5.9], [0.1] * 6)))
    assert t["rises with ice concentration"].holds is False
    assert t["rises with ship speed"].holds is False   # 6.0 -> 6.0 is not a rise
    assert t["Bow B above Bow A"].verdict == "does not hold"


def test_missing_cases_are_reported_not_judged():
    t = by_name(paper_trends(table([3.0, 6.0, 10.0], [1.0] * 3)))
    assert t["rises with ice concentration"].holds
    speed = t["rises with ship speed"]
    assert speed.holds is None and speed.missing == ("A-c68-v1.5", "A-c68-v2.0")
    assert speed.verdict.startswith("not run")


def test_fsicr_order_within_a_factor_three():
    assert fsicr_order(table([1.0] * 6, [0.1] * 6, [0.34, 0.5, 1.0, 2.0, 2.9, 0.64])) == (True, 0.34, 2.9)
    ok, lo, _ = fsicr_order(table([1.0] * 6, [0.1] * 6, [0.3, 0.5, 1.0, 2.0, 2.9, 0.64]))
    assert not ok and lo == 0.3
    rows = trends_table(table([3.0, 6.0, 10.0, 8.0, 12.0, 7.5], [1.0] * 6))
    assert len(rows) == 4 and rows.verdict.iloc[-1] == "holds (within 3 x)"
    assert rows["values"].iloc[0] == "3 +- 1 < 6 +- 1 < 10 +- 1 N"
    rows = trends_table(table([1.0] * 6, [0.1] * 6, [0.29, 0.5, 1.0, 2.0, 2.9, 0.64]))
    assert rows.verdict.iloc[-1] == "same order of magnitude, not within 3 x"
    rows = trends_table(table([1.0] * 6, [0.1] * 6, [0.09, 0.5, 1.0, 2.0, 2.9, 0.64]))
    assert rows.verdict.iloc[-1] == "does not hold"
