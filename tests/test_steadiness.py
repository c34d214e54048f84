"""``iceresist steadiness``: mean ice force over steps of stem travel, against the step means of a known force."""

import hashlib
import json
import logging
import math

import numpy as np
import pytest

from iceresist.cli import main
from iceresist.errors import InputError
from iceresist.io.hdf5 import RunFile
from iceresist.post import window_parts
from iceresist.post.steadiness import format_steadiness, read_case_record, steadiness_table, window_spans

R_INF_N, DECAY_M = 14.0, 0.4  # R(s) = R_inf (1 - exp(-s / l)), s the stem travel into the channel
CHANNEL_X0_M, SPEED_M_S, DT_S = 3.4, 0.514, 0.002


def settling_force_N(s_m):
    return R_INF_N * (1.0 - np.exp(-np.asarray(s_m) / DECAY_M))


def step_mean_N(a_m, b_m):
    """Exact mean of R(s) over a <= s <= b."""
    return R_INF_N * (1.0 - DECAY_M / (b_m - a_m) * (math.exp(-a_m / DECAY_M) - math.exp(-b_m / DECAY_M)))


def write_case(path, travel_end_m, finished=True, window_m=(4.006, 4.786)):
    """A ship case file as iceresist writes it (meta.model, timeseries), the ship at 1 knot from x = 3.35 m, the
    contact force -R(s) once the stem is in the channel; row 0 is the state before the first step."""
    n = int(round((CHANNEL_X0_M + travel_end_m - 3.35) / (SPEED_M_S * DT_S))) + 1
    with RunFile(path, "w") as rf:
        rf.write_meta(case="T-c68-v1.0", model={"tier": 2, "steady_window_m": list(window_m),
                                                "channel_start_x_m": CHANNEL_X0_M})
        for i in range(n):
            x = 3.35 + SPEED_M_S * DT_S * i
            rf.append_timeseries({"iteration": i, "time_s": DT_S * i, "x_bow_m": x,
                                  "Fx_N": -float(settling_force_N(max(x - CHANNEL_X0_M, 0.0)))})
        if finished:
            rf.write_meta(finished=True, final_x_bow_m=x)
    return path


def test_window_parts_of_a_ramp():
    """R = a + b x: the mean over each part is R at the part's middle."""
    t = np.arange(2001) * 0.001
    x = 4.0 + 0.5 * t
    parts = window_parts(t, -(10.0 + 2.0 * (x - 4.0)), x, edges_m=(4.0, 4.25, 4.5, 5.0))
    assert [p.mean_N for p in parts] == pytest.approx([10.25, 10.75, 11.5], abs=3e-3)
    assert [p.n_samples for p in parts] == pytest.approx([500, 500, 1000], abs=2)
    for bad in ((4.0,), (4.5, 4.0), ((4.0, 4.5), (4.5, 5.0))):
        with pytest.raises(InputError):
            window_parts(t, -x, x, edges_m=bad)
    with pytest.raises(InputError, match="exactly one"):
        window_parts(t, -x, x)


def test_step_means_of_a_settling_force(tmp_path, caplog):
    """Whole steps of 0.39 m from the window start (0.606 m into the channel) up to 2.2 m of travel: four steps,
    each the exact mean of R(s) over it; the steps after the steady window are marked."""
    path = write_case(tmp_path / "case.h5", travel_end_m=2.2)
    table = steadiness_table([path], step_m=0.39)
    assert list(table.step) == [0, 1, 2, 3]
    starts = 0.606 + 0.39 * np.arange(4)
    assert np.allclose(table.travel_from_m, starts, atol=1e-9)
    assert np.allclose(table.travel_to_m, starts + 0.39, atol=1e-9)
    expected = [step_mean_N(a, a + 0.39) for a in starts]
    assert np.allclose(table.mean_N, expected, rtol=2e-3)
    # rising from step to step, the last within 1 % of where the force settles, the first 14 % below it
    assert np.all(np.diff(table.mean_N) > 0) and table.mean_N.iloc[-1] == pytest.approx(R_INF_N, rel=0.01)
    assert table.mean_N.iloc[0] < 0.9 * R_INF_N
    assert list(table.in_window) == [True, True, False, False]
    assert table.finished.all() and (table.tier == 2).all()
    # a smooth force is correlated over the whole step: each interval is flagged once, in the table, not logged
    assert table.interval_too_narrow.all() and (table.batch_tau_int < 5).all()
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    text = format_steadiness(table)
    assert "T-c68-v1.0 (tier 2)" in text and "0.61-1.00 m" in text and "~*" in text.splitlines()[-1]


def test_a_running_case_is_read_as_far_as_it_goes(tmp_path):
    """No final position in the meta: "not finished"; the last, partial step is left out; a file whose stem
    has not travelled one step past the window start gives no row."""
    path = write_case(tmp_path / "running.h5", travel_end_m=1.2, finished=False)
    rec = read_case_record(path)
    assert not rec.finished and rec.window_m[0] - rec.channel_start_x_m == pytest.approx(0.606)
    table = steadiness_table([path], step_m=0.39)
    assert list(table.step) == [0] and not table.finished.any()
    assert "not finished" in format_steadiness(table)
    short = write_case(tmp_path / "short.h5", travel_end_m=0.9, finished=False)
    assert steadiness_table([short], step_m=0.39).empty


def test_a_run_result_is_finished_when_its_file_says_so(tmp_path):
    """``iceresist run`` writes ``finished`` as the sweep does (tests/test_run.py: not after an interrupt, a
    divergence or a continued leg cut short); steadiness reads it, and a file without it is unfinished."""
    path = write_case(tmp_path / "run.h5", travel_end_m=1.2, finished=False)
    assert not read_case_record(path).finished
    with RunFile(path, "a") as rf:
        rf.write_meta(finished=True, stop_reason="stop time 5.5 s reached")
    assert read_case_record(path).finished


def test_cases_sharing_a_window_shade_it_once(tmp_path):
    """Three cases, two on the same window: two spans, in stem travel into the channel, each with its first case."""
    paths = [write_case(tmp_path / f"{k}.h5", 1.4, window_m=w) for k, w in
             (("a", (4.006, 4.786)), ("b", (4.006, 4.786)), ("c", (4.3, 6.18)))]
    spans = window_spans([read_case_record(p) for p in paths])
    assert len(spans) == 2
    assert spans[0] == pytest.approx((4.006 - CHANNEL_X0_M, 4.786 - CHANNEL_X0_M, 0))
    assert spans[1] == pytest.approx((4.3 - CHANNEL_X0_M, 6.18 - CHANNEL_X0_M, 2))


def test_cli_prints_plots_and_leaves_the_case_file_alone(tmp_path, capsys):
    path = write_case(tmp_path / "case.h5", travel_end_m=2.2)
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    png, csv = tmp_path / "steady.png", tmp_path / "steady.csv"
    assert main(["steadiness", str(path), "--plot", str(png), "--csv", str(csv)]) == 0
    out = capsys.readouterr().out
    assert "1.78-2.17 m" in out and png.stat().st_size > 10_000 and csv.is_file()
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before
    assert main(["steadiness", str(path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["step"] for r in rows] == [0, 1, 2, 3] and rows[0]["case"] == "T-c68-v1.0"


@pytest.mark.parametrize("argv, field", [
    (["steadiness", "{tmp}/none.h5"], "no such case file"),
    (["steadiness", "{tmp}/plain.h5"], "not a ship case file"),
    (["steadiness", "{tmp}/case.h5", "--step-m", "-0.1"], "positive length"),
    (["steadiness", "{tmp}/case.h5", "--step-m", "x"], "--step-m"),
])
def test_cli_errors_exit_2(tmp_path, capsys, argv, field):
    write_case(tmp_path / "case.h5", travel_end_m=1.1)
    with RunFile(tmp_path / "plain.h5", "w") as rf:
        rf.append_timeseries({"iteration": 0, "time_s": 0.0})
    try:  # input errors return 2; argparse's own usage errors exit with 2
        rc = main([a.format(tmp=tmp_path) for a in argv])
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2 and field in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
