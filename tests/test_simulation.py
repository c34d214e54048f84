"""The time loop: schedules, stop criteria, NaN checker, crash safety, bitwise restart. A small fake model."""

import shutil
import time

import h5py
import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.io import RunFile
from iceresist.models.base import Model
from iceresist.simulation import (Callback, Checkpointer, FieldWriter, IterationInterval, Simulation,
                                  TimeInterval, TimeSeriesWriter, WallTimeInterval)

SHAPE = (4, 3, 2)


class LogisticModel(Model):
    """x <- r x (1 - x) per cell: chaotic, so any lost or repeated step changes every bit."""

    iteration = 0

    def __init__(self, dt_s=0.1, nan_at=None, seed=1):
        self.x = np.random.default_rng(seed).uniform(0.1, 0.9, SHAPE)
        self.iteration, self.dt_s, self.nan_at = 0, dt_s, nan_at
        self.cells = int(np.prod(SHAPE))
        self.step_calls = []

    def step(self, n=1):
        self.step_calls.append(n)
        for _ in range(n):
            self.x = 3.9 * self.x * (1.0 - self.x)
            self.iteration += 1
            if self.nan_at is not None and self.iteration >= self.nan_at:
                self.x[0, 0, 0] = np.nan

    def fields(self):
        return {"rho": self.x.copy(), "u": np.stack([self.x, -self.x, 2 * self.x], axis=-1)}

    def diagnostics(self):
        return {"mean": float(self.x.mean())}

    def state(self):
        return {"x": self.x.copy(), "iteration": np.int64(self.iteration)}

    def load_state(self, d):
        self.x = np.array(d["x"])
        self.iteration = int(d["iteration"])

    def describe(self):
        return {"kind": "logistic"}

    def watchdog_probe(self):
        return {"finite": (self.is_finite(), None)}

    def allocation(self):
        return {"x": self.x.nbytes}


def _iterations_called(sim, schedule, stop):
    seen = []
    sim.callbacks["probe"] = Callback(lambda s: seen.append(s.model.iteration), schedule)
    sim.run()
    return seen


def test_iteration_interval_lands_exactly_and_steps_in_chunks():
    model = LogisticModel()
    sim = Simulation(model, stop_iteration=25, progress=False)
    assert _iterations_called(sim, IterationInterval(10), 25) == [0, 10, 20]
    assert model.iteration == 25
    assert "stop iteration 25" in sim.stop_reason
    assert sum(model.step_calls) == 25
    assert max(model.step_calls) > 1  # chunks, not one step at a time


def test_time_interval_fires_at_first_step_at_or_after_each_multiple():
    model = LogisticModel(dt_s=0.3)
    sim = Simulation(model, stop_time_s=3.0, progress=False)
    # t = 0.3 i: first steps reaching 1.0, 2.0, 3.0 are i = 4, 7, 10
    assert _iterations_called(sim, TimeInterval(1.0), None) == [0, 4, 7, 10]
    assert model.iteration == 10 and "stop time 3" in sim.stop_reason


def test_wall_time_limit_and_wall_time_interval(monkeypatch):
    import iceresist.simulation as simmod

    clock = [0.0]

    def fake_clock():
        clock[0] += 1.0  # every reading is one second later
        return clock[0]

    monkeypatch.setattr(simmod.time, "perf_counter", fake_clock)
    model = LogisticModel()
    sim = Simulation(model, wall_time_limit_s=30.0, progress=False)
    seen = _iterations_called(sim, WallTimeInterval(10.0), None)
    assert "wall time limit" in sim.stop_reason
    assert 0 < model.iteration < 30
    assert 1 <= len(seen) <= 4


def test_no_stop_criterion_is_refused():
    with pytest.raises(InputError, match="stop criterion"):
        Simulation(LogisticModel(), progress=False).run()


def test_nan_checker_stops_and_keeps_the_last_good_output(tmp_path):
    model = LogisticModel(nan_at=37)
    sim = Simulation(model, stop_iteration=100, progress=False, nan_check_interval=5)
    with RunFile(tmp_path / "r.h5", "w", shape_cells=SHAPE) as rf:
        sim.output_writers["fields"] = FieldWriter(rf, IterationInterval(10))
        sim.output_writers["ts"] = TimeSeriesWriter(rf, IterationInterval(5))
        sim.run()
    assert sim.diverged and "NaN or Inf" in sim.stop_reason and "numerics.mach" in sim.stop_reason
    assert model.iteration == 40  # caught at the first check after step 37
    with RunFile(tmp_path / "r.h5") as rf:
        assert rf.snapshot_iterations() == [0, 10, 20, 30]
        assert np.isfinite(rf.read_field(30, "rho")).all()
        np.testing.assert_array_equal(rf.timeseries()["iteration"], [0, 5, 10, 15, 20, 25, 30, 35])


def test_field_writer_refuses_to_write_nan_even_between_checks(tmp_path):
    model = LogisticModel(nan_at=12)
    sim = Simulation(model, stop_iteration=100, progress=False, nan_check_interval=1000)
    with RunFile(tmp_path / "r.h5", "w", shape_cells=SHAPE) as rf:
        sim.output_writers["fields"] = FieldWriter(rf, IterationInterval(10))
        sim.run()
    assert sim.diverged and model.iteration == 20
    with RunFile(tmp_path / "r.h5") as rf:
        assert rf.snapshot_iterations() == [0, 10]


def test_a_crash_in_a_callback_leaves_a_readable_file(tmp_path):
    model = LogisticModel()
    sim = Simulation(model, stop_iteration=100, progress=False)

    def boom(s):
        if s.model.iteration == 30:
            raise RuntimeError("boom")

    sim.callbacks["boom"] = Callback(boom, IterationInterval(10))
    rf = RunFile(tmp_path / "r.h5", "w", shape_cells=SHAPE)
    sim.output_writers["fields"] = FieldWriter(rf, IterationInterval(10))
    sim.output_writers["ts"] = TimeSeriesWriter(rf, IterationInterval(10))
    with pytest.raises(RuntimeError, match="boom"):
        sim.run()
    # the file is still open: a byte copy of it now is what a killed process would leave on disk
    shutil.copyfile(tmp_path / "r.h5", tmp_path / "copy.h5")
    with h5py.File(tmp_path / "copy.h5", "r") as h5:
        assert sorted(h5["fields"].keys()) == ["0000000000", "0000000010", "0000000020"]
        np.testing.assert_array_equal(h5["timeseries/iteration"][...], [0, 10, 20])
    rf.close()


def _run(tmp_path, name, stop, pickup=False, model=None, crash_at=None):
    model = model or LogisticModel()
    sim = Simulation(model, stop_iteration=stop, progress=False)
    if crash_at is not None:
        def crash(s):
            if s.model.iteration == crash_at:
                raise RuntimeError("node lost")
        sim.callbacks["crash"] = Callback(crash, IterationInterval(1))
    mode = "a" if pickup else "w"
    with RunFile(tmp_path / f"{name}.h5", mode, shape_cells=SHAPE) as rf:
        sim.output_writers["fields"] = FieldWriter(rf, IterationInterval(7))
        sim.output_writers["ts"] = TimeSeriesWriter(rf, IterationInterval(3))
        sim.output_writers["checkpointer"] = Checkpointer(tmp_path / f"{name}.chk.h5", IterationInterval(10))
        sim.run(pickup=pickup)
    return model


def test_restart_after_a_crash_continues_to_the_bitwise_same_result(tmp_path):
    straight = _run(tmp_path, "straight", 53)
    # the first leg dies at 24: last checkpoint at 20, outputs already written up to 21 (fields) and 24 (rows)
    with pytest.raises(RuntimeError, match="node lost"):
        _run(tmp_path, "restart", 53, crash_at=24)
    fresh = LogisticModel(seed=99)  # a different initial state, replaced by the checkpoint
    restarted = _run(tmp_path, "restart", 53, pickup=True, model=fresh)
    assert restarted.iteration == 53
    assert np.array_equal(restarted.x, straight.x)
    with RunFile(tmp_path / "straight.h5") as a, RunFile(tmp_path / "restart.h5") as b:
        assert a.snapshot_iterations() == b.snapshot_iterations() == [0, 7, 14, 21, 28, 35, 42, 49, 53]
        for it in a.snapshot_iterations():
            assert np.array_equal(a.read_field(it, "u"), b.read_field(it, "u"))
        ta, tb = a.timeseries(), b.timeseries()
        np.testing.assert_array_equal(ta["iteration"], tb["iteration"])
        np.testing.assert_array_equal(ta["mean"], tb["mean"])


def test_restart_after_a_planned_stop_picks_up_from_the_final_checkpoint(tmp_path):
    straight = _run(tmp_path, "straight", 53)
    first = _run(tmp_path, "legs", 24)
    assert first.iteration == 24
    restarted = _run(tmp_path, "legs", 53, pickup=True, model=LogisticModel(seed=5))
    assert np.array_equal(restarted.x, straight.x)
    with RunFile(tmp_path / "legs.h5") as b:
        assert b.snapshot_iterations() == [0, 7, 14, 21, 24, 28, 35, 42, 49, 53]


def test_pickup_without_a_checkpoint_is_an_input_error(tmp_path):
    sim = Simulation(LogisticModel(), stop_iteration=5, progress=False)
    sim.output_writers["checkpointer"] = Checkpointer(tmp_path / "none.h5", IterationInterval(10))
    with pytest.raises(InputError, match="no checkpoint"):
        sim.run(pickup=True)


def test_progress_bar_stays_quiet_when_not_a_tty(capsys):
    sim = Simulation(LogisticModel(), stop_iteration=20, progress=True)
    sim.run()
    out = capsys.readouterr()
    assert out.err == "" and out.out == ""
    assert sim.steps_done == 20 and sim.mlups > 0


def test_a_run_without_a_bar_logs_its_progress(monkeypatch, caplog):
    """No tty (a batch run): a line every PROGRESS_LOG_S of wall time with the step, the share done and the time
    still to go. With one fake second per clock reading and 10 s between lines, the lines count up to 100 %."""
    import logging

    import iceresist.simulation as simmod

    clock = [0.0]

    def fake_clock():
        clock[0] += 1.0
        return clock[0]

    monkeypatch.setattr(simmod.time, "perf_counter", fake_clock)
    monkeypatch.setattr(simmod, "PROGRESS_LOG_S", 10.0)
    with caplog.at_level(logging.INFO, logger="iceresist.simulation"):
        Simulation(LogisticModel(), stop_iteration=200, progress=True).run()
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("step ")]
    assert len(lines) >= 3
    shares = [float(line.split(", ")[2].split(" %")[0]) for line in lines]
    assert shares == sorted(shares) and 0 < shares[0] and shares[-1] <= 100
    assert all(" of 200 steps" in line and "min to go" in line for line in lines)


def test_mlups_leaves_out_the_first_compiling_step():
    """A first step that takes 0.3 s (a kernel compiling) is timed apart: MLUPS is the pace of the rest."""
    class Compiling(LogisticModel):
        def step(self, n=1):
            if self.iteration == 0:
                time.sleep(0.3)
            super().step(n)

    sim = Simulation(Compiling(), stop_iteration=40, progress=False)
    sim.run()
    assert sim.first_steps == 1 and sim.first_step_s >= 0.3
    rest_s = sim.step_time_s - sim.first_step_s
    assert rest_s < 0.1
    assert sim.mlups == pytest.approx(sim.model.cells * 39 / rest_s / 1e6, rel=1e-9)
