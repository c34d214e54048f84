"""The documented self-check command runs and reports sane numbers (small sizes here)."""

import json

import pytest

from iceresist.post.selfcheck import check_ar1, main


def test_check_ar1_small():
    r = check_ar1(0.5, reps=200, length_tau=200, seed=3, n_tau=2**14)
    assert r["n"] == 600 and r["refused"] == 0
    assert r["tau_int_long_record"] == pytest.approx(3.0, rel=0.15)
    assert r["coverage_95"] == pytest.approx(0.95, abs=0.05)  # 200 records: binomial se 0.015


def test_selfcheck_cli_json(capsys):
    assert main(["--a", "0.5", "--reps", "20", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["a"] == 0.5 and out["reps"] == 20
    # the printed numbers are those of check_ar1 with the command's defaults (length 200 tau_int, seed 1)
    direct = check_ar1(0.5, reps=20, length_tau=200.0, seed=1)
    for key in ("coverage_95", "tau_int_mean", "tau_int_long_record", "refused", "n", "stderr_rms_over_true"):
        assert out[key] == direct[key], key
    assert out["coverage_95"] * (20 - out["refused"]) == pytest.approx(round(out["coverage_95"] * (20 - out["refused"])))
