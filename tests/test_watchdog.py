"""The run watchdog: each trigger (NaN, runaway speed, density band, kinetic-energy growth, runaway DEM body) stops
the run, writes the diagnostic (JSON and the result file's `watchdog` group) and leaves the result readable with
the last good output and no output from the bad state."""

import json

import h5py
import numpy as np
import pytest

from iceresist import watchdog
from iceresist.io import RunFile
from iceresist.models.base import Model
from iceresist.models.probe import fluid_probe
from iceresist.simulation import FieldWriter, IterationInterval, Simulation, TimeSeriesWriter


class _Fake(Model):
    """The parts of the model contract these fakes do not exercise."""

    iteration = 0

    def state(self):
        return {}

    def load_state(self, state):
        pass

    def describe(self):
        return {}

    def allocation(self):
        return {}


class FakeFluid(_Fake):
    """A 8^3 lattice 'fluid' at rest whose state goes bad at ``bad_at`` in the way ``mode`` says."""

    cells = 512
    dt_s = 1.0
    shape_cells = (8, 8, 8)

    def __init__(self, mode: str, bad_at: int = 30, cell=(3, 4, 5)):
        self.mode, self.bad_at, self.cell = mode, bad_at, cell
        self.iteration = 0
        self.rho = np.ones((8, 8, 8))
        self.u = np.zeros((3, 8, 8, 8))
        self.u[0] = 0.01  # KE reference 0.5 * 512 * 0.05^2 below

    def step(self, n=1):
        for _ in range(n):
            self.iteration += 1
            k = self.iteration - self.bad_at
            if k < 0:
                continue
            i, j, l = self.cell
            if self.mode == "nan":
                self.rho[i, j, l] = np.nan
            elif self.mode == "speed":
                self.u[1, i, j, l] = 0.45
            elif self.mode == "density_low":
                self.rho[i, j, l] = 0.3
            elif self.mode == "density_high":
                self.rho[i, j, l] = 1.7
            elif self.mode == "energy":
                self.u[0] = min(0.3, 0.05 * 1.5 ** (k + 1))   # uniform, below the speed limit, growing fast

    def fields(self):
        return {"rho": self.rho.copy(), "u": np.moveaxis(self.u, 0, -1).copy()}

    def diagnostics(self):
        return {"max_u": float(np.abs(self.u).max())}

    def watchdog_probe(self):
        fluid = np.ones((8, 8, 8), dtype=bool)
        return fluid_probe(self.rho, self.u, fluid, 0.5 * self.cells * 0.05 ** 2)


def _run(tmp_path, model, stop=200, every=10, fields_every=20):
    path = tmp_path / "run.h5"
    with RunFile(path, "w", shape_cells=model.shape_cells) as rf:
        sim = Simulation(model, stop_iteration=stop, progress=False)
        sim.output_writers["fields"] = FieldWriter(rf, IterationInterval(fields_every))
        sim.output_writers["timeseries"] = TimeSeriesWriter(rf, IterationInterval(5))
        dog = watchdog.install(sim, interval=every, runfile=rf, json_path=path.with_suffix(".watchdog.json"))
        sim.run()
    return sim, dog, path


def _readable(path):
    with h5py.File(path, "r") as h5:
        snaps = sorted(int(k) for k in h5["fields"])
        it = h5["timeseries/iteration"][...]
        diag = dict(h5["watchdog"].attrs)
        rho_last = h5["fields"][f"{snaps[-1]:010d}"]["rho"][...]
    return snaps, it, diag, rho_last


@pytest.mark.parametrize("mode, quantity, value, limit", [
    ("nan", "finite", None, None),
    ("speed", "max_lattice_speed", 0.45, watchdog.LATTICE_SPEED_LIMIT),
    ("density_low", "density_min", 0.3, watchdog.DENSITY_BAND[0]),
    ("density_high", "density_max", 1.7, watchdog.DENSITY_BAND[1]),
])
def test_each_field_trigger_stops_the_run_and_keeps_the_result_readable(tmp_path, mode, quantity, value, limit):
    sim, dog, path = _run(tmp_path, FakeFluid(mode, bad_at=33))
    assert sim.diverged and sim.stop_reason.startswith("watchdog: " + quantity)
    assert dog.report.quantity == quantity
    assert dog.report.iteration == 35                       # the first output due after the state went bad
    assert dog.report.last_good_iteration == 30
    assert dog.report.where == [3, 4, 5]                     # the cell
    if value is not None:
        assert dog.report.value == pytest.approx(value, rel=1e-3) and dog.report.limit == limit
    snaps, it, diag, rho_last = _readable(path)
    assert snaps == [0, 20]                                  # nothing written from the bad state
    assert it.max() == 30                                    # the row due at 35 was not written
    assert np.isfinite(rho_last).all()
    assert diag["quantity"] == quantity and int(diag["iteration"]) == 35
    js = json.loads(path.with_suffix(".watchdog.json").read_text())
    assert js["quantity"] == quantity and js["where"] == [3, 4, 5] and js["last_good_iteration"] == 30


def test_kinetic_energy_growth_stops_the_run_before_the_speed_limit(tmp_path):
    sim, dog, path = _run(tmp_path, FakeFluid("energy", bad_at=33))
    r = dog.report
    assert r.quantity == "kinetic_energy_growth"
    assert r.value > watchdog.ENERGY_GROWTH and r.limit == watchdog.ENERGY_GROWTH
    with h5py.File(path, "r") as h5:
        u = h5["fields"]["0000000020"]["u"][...]
    assert np.allclose(u[..., 0], 0.01)                       # the last good snapshot


def test_a_steady_flow_never_triggers(tmp_path):
    sim, dog, path = _run(tmp_path, FakeFluid("none"), stop=100)
    assert not sim.diverged and dog.report is None and dog.checks >= 10
    assert not path.with_suffix(".watchdog.json").exists()


def test_writers_between_checks_wait_for_the_watchdog(tmp_path):
    """A snapshot due between two scheduled checks runs the watchdog first: no bad state reaches the file."""
    sim, dog, path = _run(tmp_path, FakeFluid("speed", bad_at=33), every=50, fields_every=20)
    assert dog.report.iteration == 35                        # its own schedule would have looked at 50 only
    snaps, _, _, _ = _readable(path)
    assert snaps == [0, 20]


class FakeDEM(_Fake):
    """Bodies drifting at 0.1 m/s; one body runs away at ``bad_at``."""

    cells = 0
    dt_s = 0.01
    shape_cells = None

    def __init__(self, bad_at=7):
        self.iteration, self.bad_at = 0, bad_at
        self.v = np.full((5, 3), 0.1)

    def step(self, n=1):
        self.iteration += n
        if self.iteration >= self.bad_at:
            self.v[2] = 1e3

    def fields(self):
        return {}

    def diagnostics(self):
        return {"ke": 0.5 * float((self.v ** 2).sum())}

    def watchdog_probe(self):
        s = np.sqrt((self.v ** 2).sum(axis=1))
        return {"finite": (True, None), "max_body_speed_m_s": (float(s.max()), {"body": int(s.argmax())}),
                "max_body_speed_limit_m_s": 10.0, "kinetic_energy": 0.5 * float((self.v ** 2).sum()),
                "kinetic_energy_ref": 1.0}


def test_runaway_body_is_named(tmp_path):
    path = tmp_path / "dem.h5"
    with RunFile(path, "w") as rf:
        sim = Simulation(FakeDEM(), stop_iteration=50, progress=False)
        sim.output_writers["timeseries"] = TimeSeriesWriter(rf, IterationInterval(1))
        dog = watchdog.install(sim, runfile=rf, json_path=path.with_suffix(".watchdog.json"))
        sim.run()
    assert dog.report.quantity == "max_body_speed_m_s" and dog.report.where == {"body": 2}
    assert dog.report.iteration == 7 and dog.report.limit == 10.0
    with h5py.File(path, "r") as h5:
        assert h5["timeseries/iteration"][-1] == 6
        assert json.loads(h5["watchdog"].attrs["where"]) == {"body": 2}


def test_a_probe_of_finiteness_alone_stops_the_run_at_the_first_bad_state(tmp_path):
    class Plain(_Fake):
        dt_s = 1.0

        def step(self, n=1):
            self.iteration += n

        def fields(self):
            return {}

        def diagnostics(self):
            return {}

        def watchdog_probe(self):
            return {"finite": (self.iteration < 4, None)}

    sim = Simulation(Plain(), stop_iteration=20, progress=False)
    sim.callbacks.pop("nan_checker")
    dog = watchdog.install(sim)
    sim.run()
    assert dog.report.quantity == "finite" and dog.report.iteration == 4 and sim.diverged


def test_the_simulation_refuses_what_is_not_a_model():
    class Plain:
        cells, dt_s, iteration, time_s = 0, 1.0, 0, 0.0

    with pytest.raises(TypeError, match="needs an iceresist.models.base.Model"):
        Simulation(Plain(), stop_iteration=20, progress=False)


def test_real_fluid_beyond_the_limits_is_stopped_and_readable(tmp_path, capsys):
    """A BGK cavity at tau - 1/2 = 1e-3 (cell Reynolds number 300, ten times the BGK limit), let through with
    numerics.check_limits = false, is stopped by the watchdog through `iceresist run` (exit 1)."""
    import tomllib

    from iceresist import cli
    from iceresist.scene import preset_text
    from iceresist.scene.case_scenes import to_toml

    d = tomllib.loads(preset_text("cavity"))
    d["fluid"].pop("nu_m2_s")
    d["fluid"]["operator"] = "bgk"
    d["numerics"].update(tau=0.501, backend="cpu", check_limits=False)
    d["domain"]["faces"]["z_max"] = {"kind": "moving_wall", "velocity_m_s": [0.1, 0.0, 0.0]}
    d["run"] = {"steps": 600, "watchdog_every_steps": 20}
    d["output"] = {"fields": ["rho", "u"], "fields_every_steps": 20, "timeseries_every_steps": 10}
    scene = tmp_path / "cav.toml"
    scene.write_text(to_toml(d))
    rc = cli.main(["run", str(scene), "--output", str(tmp_path), "--no-progress"])
    assert rc == 1
    js = json.loads((tmp_path / "cavity.watchdog.json").read_text())
    assert js["quantity"] in ("finite", "max_lattice_speed", "density_min", "density_max", "kinetic_energy_growth")
    with RunFile(tmp_path / "cavity.h5") as rf:
        its = rf.snapshot_iterations()
        assert its and its[-1] <= js["iteration"] - 20 + 1e-9
        assert np.isfinite(rf.read_field(its[-1], "rho")).all()
        assert rf.meta["diverged"] and rf.meta["stop_reason"].startswith("watchdog")
        assert not rf.meta["finished"]
        assert rf.h5["watchdog"].attrs["quantity"] == js["quantity"]
