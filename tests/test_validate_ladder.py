"""``iceresist validate``: convergence arithmetic on synthetic data, the resumable ladder table, the report, the
command line, and the quick ladders of the cheap cases (error falls as the resolution rises)."""

from __future__ import annotations

import types

import numpy as np
import pandas as pd
import pytest

from iceresist.post import convergence as C
from iceresist.validate import cli as validate_cli
from iceresist.validate import ladder as L
from iceresist.validate.result import CaseResult, relative_error


# -- arithmetic ---------------------------------------------------------------------------------------------
def test_observed_order_of_second_order_data_is_two():
    n = np.array([8.0, 16.0, 32.0, 64.0])
    assert C.observed_order(n, 3.0 * n ** -2) == pytest.approx(2.0, abs=1e-12)
    assert C.observed_order([10.0, 15.0, 23.0], 0.4 * np.array([10.0, 15.0, 23.0]) ** -1.3) == pytest.approx(1.3)
    assert np.isnan(C.observed_order([8.0], [0.1]))
    assert np.isnan(C.observed_order([8.0, 16.0], [0.1, 0.0]))       # a zero error carries no order


@pytest.mark.parametrize("n", [(8.0, 16.0, 32.0), (10.0, 14.0, 20.0), (6.0, 8.0, 12.0)])
def test_richardson_recovers_order_and_limit_exactly(n):
    """f = f0 + C h^p: the three rungs give p and f0 to round-off (constant and varying refinement ratio)."""
    n = np.asarray(n)
    f = 1.7 - 0.3 * (1.0 / n) ** 1.6
    p, f0 = C.richardson(n[::-1], f[::-1])          # any order of the rows
    assert p == pytest.approx(1.6, rel=1e-8)
    assert f0 == pytest.approx(1.7, rel=1e-12)


def test_richardson_refuses_oscillating_or_short_ladders():
    assert np.isnan(C.richardson([8, 16, 32], [1.0, 1.2, 1.1])[1])          # differences change sign
    assert np.isnan(C.richardson([8, 16, 32], [1.0, 1.1, 1.3])[1])          # differences grow: diverging
    assert np.isnan(C.richardson([8, 16], [1.0, 1.1])[1])


def _rows(case, res, err, wall, ladder="quick", value=None, reference=1.0):
    value = np.asarray(value if value is not None else 1.0 + np.asarray(err))
    return pd.DataFrame({"case": case, "label": [f"{r:g} cells" for r in res], "resolution": res,
                         "cells": [int(r) ** 3 for r in res], "steps": 100, "wall_s": wall, "quantity": "q",
                         "value": value, "reference": reference, "error": err, "backend": "cpu",
                         "precision": "float32", "mlups": 1.0, "ladder": ladder})


def test_cheapest_runs_pick_the_least_wall_time_meeting_each_level():
    t = pd.concat([_rows("a", [8, 16, 32], [0.2, 0.04, 0.008], [1.0, 4.0, 16.0]),
                   _rows("b", [8, 16, 32], [0.09, 0.07, 0.06], [1.0, 2.0, 3.0]),
                   _rows("c", [8, 16, 32], [0.03, 0.02, 0.04], [5.0, 1.0, 9.0])])
    c = C.cheapest_runs(t).set_index("case")
    assert c.loc["a", "label_10"] == "16 cells" and c.loc["a", "wall_s_10"] == 4.0
    assert c.loc["a", "label_5"] == "16 cells"
    assert c.loc["a", "label_1"] == "32 cells" and c.loc["a", "error_1"] == 0.008
    assert c.loc["b", "label_10"] == "8 cells" and c.loc["b", "label_5"] == "" and np.isnan(c.loc["b", "wall_s_1"])
    assert c.loc["c", "label_5"] == "16 cells"                              # cheaper than the coarser rung
    s = C.case_summary(C.with_errors(t)).set_index("case")
    assert s.loc["a", "monotone"] and not s.loc["c", "monotone"]
    assert s.loc["a", "observed_order"] == pytest.approx(np.log2(0.2 / 0.008) / 2, rel=0.05)


def test_self_referenced_case_measured_against_its_richardson_limit():
    n = np.array([10.0, 14.0, 20.0])
    f = 2.0 + 5.0 * (1 / n) ** 2
    t = _rows("ship", n, np.nan, [1.0, 2.0, 3.0], value=f, reference=np.nan)
    e = C.with_errors(t)
    assert (e.reference_kind == "Richardson").all()
    assert np.allclose(e.reference, 2.0)
    assert np.allclose(e.error, np.abs(f - 2.0) / 2.0)
    assert np.allclose(e.error_vs_finest, np.abs(f - f[-1]) / f[-1]) and np.allclose(e.richardson_order, 2.0)
    # an oscillating ladder falls back on its finest rung
    e2 = C.with_errors(_rows("ship", n, np.nan, [1.0, 2.0, 3.0], value=[2.1, 1.9, 2.0], reference=np.nan))
    assert (e2.reference_kind == "finest rung").all() and np.allclose(e2.error, [0.05, 0.05, 0.0])


# -- the resumable runner -----------------------------------------------------------------------------------
def fake_case(calls: list, fail_at=None):
    """A case following the protocol whose error is 0.5 / resolution^2."""
    def ladder(quick):
        return [{"label": f"n{n}", "resolution": float(n)} for n in ((4, 8, 16) if quick else (8, 16, 32))]

    def run(params, *, backend="cpu", precision="float32", out_dir=None):
        if params["label"] == fail_at:
            raise KeyboardInterrupt
        calls.append(params["label"])
        e = 0.5 / params["resolution"] ** 2
        return CaseResult(case="fake", label=params["label"], resolution=params["resolution"], cells=10,
                          steps=5, wall_s=params["resolution"] / 10, quantity="q", value=1 + e, reference=1.0,
                          error=relative_error(1 + e, 1.0), backend=backend, precision=precision,
                          extra={"note": 1.0})

    return types.SimpleNamespace(NAME="fake", REFERENCE="exact", ladder=ladder, run=run)


def test_a_killed_ladder_keeps_its_rows_and_a_rerun_runs_only_the_rest(tmp_path):
    calls = []
    with pytest.raises(KeyboardInterrupt):
        L.run_ladders(tmp_path, modules={"fake": fake_case(calls, fail_at="n16")}, progress=False)
    assert calls == ["n4", "n8"]
    assert list(C.load_table(tmp_path).label) == ["n4", "n8"]
    calls.clear()
    t = L.run_ladders(tmp_path, modules={"fake": fake_case(calls)}, progress=False)
    assert calls == ["n16"]
    assert list(t.label) == ["n4", "n8", "n16"] and (t.x_note == 1.0).all()
    calls.clear()
    L.run_ladders(tmp_path, modules={"fake": fake_case(calls)}, progress=False)
    assert calls == []
    L.run_ladders(tmp_path, quick=False, modules={"fake": fake_case(calls)}, progress=False)
    assert calls == ["n8", "n16", "n32"]                  # the full ladder is a ladder of its own
    t = C.with_errors(C.load_table(tmp_path))
    s = C.case_summary(t)
    assert np.allclose(s.observed_order, 2.0)


def test_cases_with_different_extra_columns_share_one_table(tmp_path):
    calls = []
    a = fake_case(calls)
    b = fake_case(calls)
    run_b = b.run
    b.run = lambda params, **kw: type(r := run_b(params, **kw))(**{**r.__dict__, "case": "other", "extra": {}})
    L.run_ladders(tmp_path, modules={"fake": a}, progress=False)
    t = L.run_ladders(tmp_path, modules={"other": b}, progress=False)
    assert list(t.case) == ["fake"] * 3 + ["other"] * 3
    assert t.x_note.isna().sum() == 3


def test_discovery_lists_missing_cases_without_failing():
    available, missing = L.discover_cases()
    assert {"poiseuille", "taylor_green", "sphere_drag", "ship_tier1"} <= set(available)
    assert set(available) | set(missing) >= set(L.KNOWN_CASES)
    assert all(why.startswith("not available") for why in missing.values())


# -- the report and the command line ------------------------------------------------------------------------
def test_report_writes_html_and_pdf_from_a_table(tmp_path):
    from iceresist.post.convergence import markdown_table
    from reports.validation import write_validation_report

    t = pd.concat([_rows("poiseuille", [8, 16, 32], [4e-3, 1e-3, 2.5e-4], [0.1, 0.8, 6.0]),
                   _rows("ship_tier1", [10, 14, 20], np.nan, [5.0, 8.0, 10.0], value=[1.72, 1.51, 1.40],
                         reference=np.nan)])
    t.to_csv(tmp_path / "ladder.csv", index=False)
    html, pdf = write_validation_report(tmp_path, references={"poiseuille": "Hagen-Poiseuille profile, closed form"},
                                        missing={"dam_break": "not available (no module)"})
    text = html.read_text()
    assert "Hagen-Poiseuille profile, closed form" in text and "dam_break" in text
    assert text.startswith("<!DOCTYPE html>") and "data:image/png;base64," in text
    assert "poiseuille" in text and "ship_tier1" in text and "Richardson" in text and "error vs finest" in text
    assert pdf.read_bytes()[:4] == b"%PDF"
    md = markdown_table(C.load_table(tmp_path))
    assert "| poiseuille | quick | 32 cells |" in md and "2.00 |" in md


def test_cli_rejects_bad_flags_with_one_line_and_status_2(capsys, tmp_path):
    from iceresist.validate.cli import main

    assert main(["--bogus"]) == 2
    assert main(["--quick", "--full"]) == 2
    assert main(["--cases", "nosuch", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and "unknown case 'nosuch'" in err[-1]


def test_a_case_without_rungs_on_the_ladder_asked_for_is_refused_before_anything_is_written(capsys, tmp_path):
    """The tier-2 ship on levels is a GPU ladder (no quick rungs): asked for alone on the quick one, one line
    naming --full, exit 2, and no output folder."""
    from iceresist.validate.cli import main

    out = tmp_path / "v"
    assert main(["--quick", "--cases", "ship_tier2_amr", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ship_tier2_amr has no rungs on the quick ladder" in err[0] and "--full" in err[0]
    assert not out.exists()


def test_iceresist_validate_runs_the_ladders_then_draws_the_report_from_their_files(tmp_path, monkeypatch, capsys):
    """``iceresist validate`` composes engine -> files -> report: the ladders write ladder.csv (stood in for by a
    table here), the command line prints their Markdown table and writes the report with each case's reference."""
    from iceresist.cli import main

    def fake_run_ladders(out, **kw):
        _rows("poiseuille", [8, 16, 32], [4e-3, 1e-3, 2.5e-4], [0.1, 0.8, 6.0]).to_csv(out + "/ladder.csv",
                                                                                      index=False)
        return C.load_table(out)

    monkeypatch.setattr(validate_cli, "run_ladders", fake_run_ladders)      # where the command binds it
    assert main(["validate", "--out", str(tmp_path), "--cases", "poiseuille"]) == 0
    out = capsys.readouterr().out
    assert "| poiseuille | quick | 32 cells |" in out and "report.html" in out
    from iceresist.validate.cases import poiseuille

    assert poiseuille.REFERENCE in (tmp_path / "report.html").read_text()


def test_report_notes_a_stability_table(tmp_path):
    from reports.validation import write_validation_report

    _rows("poiseuille", [8, 16, 32], [4e-3, 1e-3, 2.5e-4], [0.1, 0.8, 6.0]).to_csv(tmp_path / "ladder.csv",
                                                                                  index=False)
    pd.DataFrame({"tau": [0.51, 0.6], "u": [0.1, 0.05], "stable": [False, True]}).to_csv(
        tmp_path / "stability.csv", index=False)
    html, _ = write_validation_report(tmp_path)
    assert "Stability map" in html.read_text()


@pytest.mark.parametrize("name", ["poiseuille", "taylor_green", "sphere_drag", "ship_tier1"])
def test_case_ladders_follow_the_protocol(name):
    import importlib

    mod = importlib.import_module(f"iceresist.validate.cases.{name}")
    assert mod.NAME == name and len(mod.REFERENCE) > 40
    for quick in (True, False):
        rungs = mod.ladder(quick)
        res = [r["resolution"] for r in rungs]
        assert len(rungs) >= 3 and np.all(np.diff(res) > 0)
        assert len({r["label"] for r in rungs}) == len(rungs)


# -- the quick ladders of the cheap cases -------------------------------------------------------------------
def quick_ladder(case, tmp_path):
    """(table with errors, errors from coarse to fine) of a quick ladder run on one thread: grids of 1-64 blocks
    gain nothing from more, and on a loaded machine the thread barrier of every step costs more than the step."""
    import numba

    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        table = C.with_errors(L.run_ladders(tmp_path, cases=case, progress=False))
    finally:
        numba.set_num_threads(threads)
    return table, table.sort_values("resolution").error.to_numpy()


@pytest.mark.parametrize("case", ["poiseuille", "taylor_green"])
def test_quick_ladder_error_falls_as_resolution_rises(case, tmp_path):
    """Poiseuille (measured 4.27e-3, 1.06e-3, 2.24e-4: order 2.1) and Taylor-Green (order about 2): the error
    falls at every rung, with an observed order near 2."""
    table, e = quick_ladder(case, tmp_path)
    assert len(e) >= 3 and np.all(np.diff(e) < 0), e
    p = C.observed_order(table.resolution, table.error)
    assert 1.5 < p < 3.0, (p, e)


def test_standing_wave_quick_ladder_error_falls(tmp_path):
    """Period against linear theory at 16 / 24 / 32 cells per wavelength, a = lambda / 32: measured 1.55, 0.72,
    0.06 % (float32, 1.5 periods). With a = lambda / 64 the surface moved by less than a cell and the error rose
    (1.0, 2.1, 2.3 %)."""
    _, e = quick_ladder("standing_wave", tmp_path)
    assert len(e) >= 3 and np.all(np.diff(e) < 0), e
    assert e[-1] < 0.005 and e[0] < 0.03, e


# 90-120 s on a 2-core x86 VM: CI time; test_bodies.py steps its scene (10 steps, a regrid) in CI
@pytest.mark.slow
def test_settling_sphere_quick_ladder_error_falls(tmp_path):
    """ten Cate E1 at 5 / 6 / 8 cells per diameter in the experiment's box to the nearest cell: measured -6.91,
    -5.62, -3.11 % (BGK, float32, 2.0 s, the velocity sampled every 5 steps). With the box rounded up to whole blocks (120 / 100 / 105 mm wide) the
    wall effect changed between rungs and the error did not fall (-5.0, -7.2, -4.2 % at 0.8 s)."""
    _, e = quick_ladder("settling_sphere", tmp_path)
    assert len(e) >= 3 and np.all(np.diff(e) < 0), e
    assert e[-1] < 0.045 and e[0] < 0.09, e


@pytest.mark.slow
def test_sphere_drag_quick_ladder_error_falls(tmp_path):
    _, e = quick_ladder("sphere_drag", tmp_path)
    assert np.all(np.diff(e) < 0), e
