"""Tier 2 (coupled LBM-DEM ship in ice) on the CI-sized case: through sweep.run_case to the HDF5 the report reads,
no NaN, water volume kept, cubes pushed, the recorded ice force equal to a hand sum of the DEM sphere forces;
and the allocation rule of issue 7 (a scene allocates only what it uses)."""

import h5py
import numpy as np
import pytest

from iceresist.models import build_model
from iceresist.scene.case_scenes import TIER2, case_scene
from iceresist.post.case import analyse_case
from iceresist.sweep import TINY_OVERRIDES, TINY_TIER2_OVERRIDES, run_case

CASE = "A-c68-v1.0"
#: one test process for the tests that build tier 2's kernels (the heave cases' CI rungs share them)
pytestmark = pytest.mark.xdist_group("tier2_kernels")


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """One CI-sized tier-2 case (64 x 16 x 16 cells, 4 cubes, 13 records of 4 LBM steps) with a probe that sums
    the DEM contact forces on the hull's spheres by hand at every DEM sub-step."""
    out = tmp_path_factory.mktemp("tier2")
    probe = {"rows": [], "volume": [], "vx": [], "subs": []}

    def install(sim):
        m = sim.model
        if probe.get("model") is not None:
            return
        probe["model"] = m
        dem, n_hull = m.dem, m.hull.n_spheres
        inner = dem._substep
        acc = {"sum": np.zeros(3), "n": 0}
        probe["acc"] = acc

        def substep(h):
            inner(h)
            acc["sum"] += dem._get("sforce")[:n_hull].astype(float).sum(axis=0)
            acc["n"] += 1
        dem._substep = substep

    def record(sim):
        m, acc = sim.model, probe["acc"]
        if m.iteration > 0:
            d = m.diagnostics()
            last = m.dem._get("sforce")[:m.hull.n_spheres].astype(float).sum(axis=0)
            probe["rows"].append((d["Fx_N"], acc["sum"][0] / acc["n"], d["Fx_last_N"], last[0], d["Fz_N"],
                                  acc["sum"][2] / acc["n"]))
            probe["subs"].append(acc["n"])
        acc["sum"][:] = 0.0
        acc["n"] = 0
        probe["volume"].append(m.water_volume_cells() * m.units.dx_m ** 3)
        probe["vx"].append(m.ice_state()["velocities_m_s"][:, 0].copy())

    path = run_case(CASE, "quick", 2, out, backend="cpu", overrides=TINY_TIER2_OVERRIDES,
                    callbacks={"a_install": (install, 1), "b_record": (record, 1)})
    return path, probe


def test_tier2_case_file_is_what_the_report_reads(tiny_run):
    path, probe = tiny_run
    m = probe["model"]
    with h5py.File(path, "r") as h5:
        assert h5["meta"].attrs["finished"] and int(h5["meta"].attrs["tier"]) == 2
        fx = h5["timeseries/Fx_N"][...]
        ffl = h5["timeseries/Fx_fluid_N"][...]
        assert len(fx) == 1 + m.iteration == 1 + 13
        assert np.isfinite(fx).all() and np.isfinite(ffl).all()
        assert h5["bodies/final_positions_m"].shape == (4, 3)
    row = analyse_case(path)
    assert row["tier"] == 2 and row["cubes"] == 4 and row["cells"] == 64 * 16 * 16
    assert np.isfinite(row["mean_force_N"]) and row["mean_force_N"] > 0  # the hull meets the middle cube
    assert row["R_sim_kN"] == pytest.approx(row["mean_force_N"] * 25 ** 3 / 1e3, rel=1e-12)
    # the tank check of the report by hand: midship 0.08 x 0.06 m in 16 cells of 41/3 mm x 0.14 m of water
    m_block = 0.08 * 0.06 / (16 * 0.041 / 3 * 0.14)
    f_limit = (2 * np.sin(np.arcsin(1 - m_block) / 3)) ** 1.5
    assert row["tank_froude_fraction"] == pytest.approx(0.514 / np.sqrt(9.81 * 0.14) / f_limit, rel=1e-9)
    # the tank's water motion, every record: the start wave of this tank, U A_s / (2 W c) = 4.8 mm, is a third of
    # a cell, so both bands stay within one cell of the still level (a band reading the hull or a column with no
    # surface would be off by many); the cubes start at rest
    with h5py.File(path, "r") as h5:
        levels = np.stack([h5["timeseries/level_fore_wall_m"][...], h5["timeseries/level_ahead_m"][...]])
        drift = h5["timeseries/ice_drift_ahead_m_s"][...]
    assert levels.shape == (2, 1 + 13) and np.isfinite(levels).all()
    assert np.abs(levels).max() < m.units.dx_m
    assert drift[0] == 0.0 and np.isfinite(drift).all()
    # the start wave read back from the file (tank width from the blockage) is the model's own
    sw = m.describe()["start_wave"]
    assert row["start_wave_fraction"] == pytest.approx(sw["window_fraction"], abs=1e-12)
    assert sw["duration_s"] == pytest.approx(m.geometry.prismatic_length_m / (np.sqrt(9.81 * 0.14) - 0.514),
                                             rel=1e-9)
    # units: dt from the Mach rule against sqrt(g h), gravity from dt (module docstring of iceresist.models.tier2)
    u = m.units  # the lattice's scales: dt is the LBM step, a record (the model's step) holds several
    assert u.dt_s == m.lbm_dt_s == pytest.approx(0.1 * u.dx_m / np.sqrt(9.81 * 0.14), rel=1e-9)
    assert m.dt_s == m.lbm_steps_per_record * u.dt_s
    assert m.g_lattice == pytest.approx(9.81 * u.dt_s ** 2 / u.dx_m, rel=1e-12)
    assert u.tau == pytest.approx(0.5 + 3 * 1e-5 * u.dt_s / u.dx_m ** 2, rel=1e-12)


def test_tier2_keeps_the_water_and_pushes_the_cubes(tiny_run):
    _, probe = tiny_run
    v = np.array(probe["volume"])
    assert np.isfinite(v).all()
    assert np.abs(v / v[0] - 1).max() < 5e-3
    vx = np.array(probe["vx"])  # (records + 1, 4)
    m = probe["model"]
    ahead = np.argmin(np.abs(m.layout.centres_m[:, 1] - m.centre_y_m) + m.layout.centres_m[:, 0])
    assert vx[0].max() == 0.0
    assert vx[-1, ahead] > 0.05 * m.speed_m_s  # the cube in the hull's path is pushed forward
    assert (vx[-1] > 0).all()                 # and the water ahead of the bow pushes the others


def test_recorded_force_equals_a_hand_sum_of_the_dem_sphere_forces(tiny_run):
    _, probe = tiny_run
    rows = np.array(probe["rows"])
    assert (np.array(probe["subs"]) >= 4).all()       # 4 LBM steps per record, >= 1 DEM sub-step each
    fx, fx_hand, fx_last, fx_last_hand, fz, fz_hand = rows.T
    assert np.abs(fx).max() > 0.1                        # contact happened
    assert np.allclose(fx, fx_hand, rtol=1e-9, atol=1e-12)
    assert np.allclose(fz, fz_hand, rtol=1e-9, atol=1e-12)
    assert np.allclose(fx_last, fx_last_hand, rtol=1e-9, atol=1e-12)


def test_tier2_case_killed_and_continued_is_the_straight_run(tiny_run, tmp_path):
    """A sweep case killed at record 9 continues from its checkpoint of record 8 (populations, phase field, cell
    owners and DEM contact history) to the straight run's records and final ice bit for bit."""
    from iceresist.simulation import IterationInterval
    from iceresist.sweep import checkpoint_path

    straight, _ = tiny_run

    def kill(sim):
        if sim.model.iteration >= 9:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_case(CASE, "quick", 2, tmp_path, backend="cpu", overrides=TINY_TIER2_OVERRIDES,
                 callbacks={"kill": (kill, 1)}, checkpoint_schedule=IterationInterval(4))
    assert checkpoint_path(tmp_path, CASE).is_file()
    path = run_case(CASE, "quick", 2, tmp_path, backend="cpu", overrides=TINY_TIER2_OVERRIDES)
    with h5py.File(path, "r") as a, h5py.File(straight, "r") as b:
        assert a["meta"].attrs["legs"] == 2 and a["meta"].attrs["iteration"] == b["meta"].attrs["iteration"]
        assert a["meta"].attrs["lbm_steps"] == b["meta"].attrs["lbm_steps"]
        assert sorted(a["timeseries"]) == sorted(b["timeseries"])
        for key in b["timeseries"]:
            np.testing.assert_array_equal(a["timeseries"][key][:], b["timeseries"][key][:], err_msg=key)
        np.testing.assert_array_equal(a["bodies/final_positions_m"][:], b["bodies/final_positions_m"][:])
    assert not checkpoint_path(tmp_path, CASE).exists()


def test_tier2_allocates_lbm_phase_field_and_dem(tiny_run):
    m = tiny_run[1]["model"]
    a = m.allocation()
    cells = 64 * 16 * 16
    assert a["lbm"] >= 2 * 27 * 4 * cells             # two float32 population buffers
    assert a["phase_field"] >= 2 * 15 * 4 * cells + 4 * cells  # h (D3Q15, two buffers) and phi
    assert a["dem"] > 0 and a["coupling"] > 0
    assert m.allocated_bytes() == sum(a.values())
    assert m.describe()["allocation_bytes"] == a


def test_tier2_watchdog_probe_reads_the_flow_and_names_the_cell_of_a_nan(tiny_run):
    """The probe of a healthy run reads the water, not the cells a body covers: the fastest wet cell moves at
    0.9-1.1 x the hull's lattice speed (measured 0.93-1.0 x on this case: the water at the hull is dragged with
    it), below the watchdog's limit, with the density within the band; the cells inside the hull and the
    floes hold no water: the free surface keeps them GHOST through its reflag (it used to call about 470 of
    them liquid after a step here) and the probe and the fields leave them out. A NaN put
    into one liquid cell's populations is reported as non-finite at that cell, [i, j, k] of the dense grid."""
    from iceresist import watchdog
    from iceresist.grid.forest import CELLS

    m = tiny_run[1]["model"]
    p = m.watchdog_probe(full=True)
    u_ship = m.speed_m_s * m.lbm_dt_s / m.units.dx_m
    assert p["finite"] == (True, None)
    assert 0.9 * u_ship < p["max_lattice_speed"][0] < min(1.1 * u_ship, watchdog.LATTICE_SPEED_LIMIT)
    assert 0.9 < p["density_min"][0] <= 1.0 <= p["density_max"][0] < 1.1
    liquid = m.fluid.liquid()
    covered = m.fluid.forest.to_dense(m.coupling.owners()) >= 0
    assert covered.sum() > 1000 and not (liquid & covered).any()
    for q in ("max_lattice_speed", "density_min", "density_max"):
        assert liquid[tuple(p[q][1])] and not covered[tuple(p[q][1])], q
    assert np.isnan(m.fluid.macroscopic()[0][covered]).all()
    assert watchdog.Watchdog().inspect(m) is None
    assert watchdog.default_interval(m) == 1
    fresh = build_model(case_scene(CASE, "quick", 2, **TINY_TIER2_OVERRIDES), backend="cpu")
    fresh.step(1)
    fl = fresh.fluid
    liquid = fl.liquid()
    cell = [int(v) for v in np.argwhere(liquid)[len(np.argwhere(liquid)) // 2]]
    blocks, f = fl.fluid.rows()
    ids = np.full((fl.forest.nblocks, CELLS), -1, dtype=np.int64)
    ids[blocks] = np.arange(len(blocks))[:, None] * CELLS + np.arange(CELLS)
    dense = np.nan_to_num(fl.forest.to_dense(ids.astype(np.float64)), nan=-1).astype(np.int64)
    row, k = divmod(int(dense[tuple(cell)]), CELLS)
    f = f.copy()
    f[row, 5, k] = np.nan
    fl.fluid.set_rows(blocks, f)
    report = watchdog.Watchdog().inspect(fresh)
    assert report is not None and report.quantity == "finite" and report.where == cell
    fl._velocity()  # the step's velocity pass: the cheap probe sees the NaN through it
    light = fresh.watchdog_probe(full=False)
    assert light["finite"] == (False, cell)


def test_tier2_cheap_watchdog_probe_reads_the_speed_the_populations_give(tiny_run):
    """Between full probes the watchdog reads the velocity the step stored for the phase field instead of the
    populations: the same fastest cell and speed as the full probe (float32 storage), one full probe in ten."""
    m = tiny_run[1]["model"]
    full, light = m.watchdog_probe(full=True), m.watchdog_probe(full=False)
    assert "density_min" in full and "density_min" not in light and "kinetic_energy" not in light
    assert light["finite"] == (True, None)
    assert light["max_lattice_speed"][0] == pytest.approx(full["max_lattice_speed"][0], rel=1e-6)
    # the same cell, or its mirror across the tank's centre plane (the flow is symmetric in y, so the two speeds tie
    # to the last bits and either probe may name either)
    (i, j, k), ny = light["max_lattice_speed"][1], m.shape_cells[1]
    assert full["max_lattice_speed"][1] in ([i, j, k], [i, ny - 1 - j, k])
    assert light["max_body_speed_m_s"] == full["max_body_speed_m_s"]
    m._probes = 0
    kinds = ["density_min" in m.watchdog_probe() for _ in range(2 * m.full_probe_every)]
    assert kinds == ([True] + [False] * (m.full_probe_every - 1)) * 2


def test_scenes_allocate_only_what_they_use():
    """Tier 1: no LBM arrays (the DEM's alone); a single-phase fluid scene: no phase field and no DEM."""
    t1 = build_model(case_scene(CASE, "quick", 1, **TINY_OVERRIDES), backend="cpu")
    assert list(t1.allocation()) == ["dem"] and t1.cells == 0
    # the DEM's arrays: at least positions, velocities, quaternions and forces of every body and sphere (float64)
    assert t1.allocated_bytes() >= 8 * (3 + 3 + 4 + 3) * t1.dem.n_bodies + 8 * 3 * t1.dem.n_spheres
    assert not any(hasattr(t1, k) for k in ("fb", "fluid", "solver", "forest", "phase"))
    from iceresist.scene.schema import Scene

    fluid = build_model(Scene.model_validate({
        "domain": {"cells": [8, 8, 8], "dx_m": 0.01}, "fluid": {"nu_m2_s": 1e-4},
        "numerics": {"u_max_m_s": 0.1}, "run": {"steps": 1}}), backend="cpu", precision="float32")
    assert not any(hasattr(fluid, k) for k in ("phase", "fb", "dem", "coupling"))
    assert not hasattr(fluid.lbm.solvers[0], "phase")
    assert fluid.allocated_bytes() == 2 * 27 * 4 * 512


def test_paper_tier2_preset_is_the_papers_resolution():
    s = case_scene(CASE, "paper", 2)
    assert s.ship.tier == 2 and s.domain.dx_m == pytest.approx(0.00272, abs=1e-5)
    assert s.shape_cells() == TIER2["paper"]["cells"]
    assert s.free_surface.water_depth_m == 1.11 and s.fluid.nu_m2_s == 1e-6
    q = case_scene(CASE, "quick", 2)
    assert q.ice.size_m / q.domain.dx_m == pytest.approx(3.07, abs=0.01)
    assert all(n % 8 == 0 for n in q.shape_cells())


def test_tier2_scene_runs_through_iceresist_run_with_hydrostatic_fields(tmp_path):
    """`iceresist run` of the CI-sized tier-2 scene: exit 0, finite fields; at t = 0 the pressure at the tank
    bottom is the hydrostatic rho g h in pascals (away from the hull and the cubes)."""
    from iceresist.cli import main
    from iceresist.scene.case_scenes import scene_data, to_toml

    d = scene_data(CASE, "quick", 2)
    for k, v in TINY_TIER2_OVERRIDES.items():
        d.setdefault(k, {}).update(v)
    d["ice"] = {k: v for k, v in d["ice"].items() if v is not None}
    d["output"]["fields"] = ["rho", "u", "pressure", "flags"]
    scene = tmp_path / "tiny_t2.toml"
    scene.write_text(to_toml(d))
    name = d["scene"]["name"]
    for steps, out in ((0, "t0"), (2, "t2")):
        rc = main(["run", str(scene), "--output", str(tmp_path / out), "--backend", "cpu", "--steps", str(steps),
                   "--no-progress"])
        assert rc == 0
    from iceresist.io.hdf5 import RunFile

    with RunFile(tmp_path / "t0" / f"{name}.h5", "r") as rf:
        p = rf.read_field(rf.snapshot_iterations()[-1], "pressure")
    assert p.shape == (64, 16, 16)
    dx = TINY_TIER2_OVERRIDES["domain"]["dx_m"]
    depth = TINY_TIER2_OVERRIDES["free_surface"]["water_depth_m"]
    assert p[60, 1, 0] == pytest.approx(1000 * 9.81 * (depth - 0.5 * dx), rel=0.03)
    with h5py.File(tmp_path / "t2" / f"{name}.h5", "r") as h5:
        snap = h5["fields"][sorted(h5["fields"].keys())[-1]]
        assert int(snap.attrs["iteration"]) == 2
        assert all(np.isfinite(snap[k][...]).all() for k in ("rho", "u", "pressure"))


def test_report_draws_the_tanks_water_from_the_case_file(tiny_run):
    """The report's tier-2 tank figure plots the recorded levels (cm) and drift against time, and marks t_s of the
    case's start wave; a tier-1 case (no levels recorded) gets no figure."""
    from reports.common import pyplot
    from iceresist.post.case import load_case
    from reports.report import fig_tank

    path, probe = tiny_run
    case = load_case(path)
    plt = pyplot()
    fig = fig_tank(plt, {"A-c68-v1.0": case})
    ax, drift = fig.axes[0], fig.axes[1]
    fore, ahead = ax.get_lines()[:2]
    assert np.array_equal(fore.get_xdata(), case["ts"]["time_s"])
    assert np.allclose(fore.get_ydata(), 100 * case["ts"]["level_fore_wall_m"])
    assert np.allclose(ahead.get_ydata(), 100 * case["ts"]["level_ahead_m"])
    assert np.allclose(drift.get_lines()[0].get_ydata(), case["ts"]["ice_drift_ahead_m_s"], equal_nan=True)
    t_s = probe["model"].start_wave.duration_s
    assert any(np.allclose(line.get_xdata(), t_s) for line in ax.get_lines()[2:])
    tier1 = {**case, "ts": {k: v for k, v in case["ts"].items() if not k.startswith(("level_", "ice_drift"))}}
    assert fig_tank(plt, {"A-c68-v1.0": tier1}) is None
    plt.close("all")
