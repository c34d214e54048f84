"""Pre-run stability limits: each refusal names the key, the limit and a value that works; `iceresist run` exits 2
and writes nothing (an existing result stays untouched); the value the message proposes is accepted."""

import re
import tomllib

import pytest

from iceresist import cli, limits
from iceresist.errors import InputError, StabilityError
from iceresist.scene import parse_scene, preset_text
from iceresist.scene.case_scenes import scene_data, to_toml


def _cli_run(tmp_path, capsys, text, *extra):
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    out = tmp_path / "out"
    rc = cli.main(["run", str(scene), "--output", str(out), "--no-progress", *extra])
    err = capsys.readouterr().err.strip()
    return rc, err, out


def _refused(tmp_path, capsys, text, *needles):
    rc, err, out = _cli_run(tmp_path, capsys, text)
    assert rc == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], lines[0]
    assert not out.exists() or not any(out.iterdir()), "a refused run wrote files"
    return lines[0]


def _number_after(text, key_op):
    m = re.search(re.escape(key_op) + r"\s*([0-9.eE+-]+)", text)
    assert m, (key_op, text)
    return float(m.group(1).rstrip("."))


def _cavity(tau, operator="cumulant", lid=0.05):
    d = tomllib.loads(preset_text("cavity"))
    d["fluid"].pop("nu_m2_s")
    d["fluid"]["operator"] = operator
    d["numerics"].update(tau=tau, backend="cpu")
    d["domain"]["faces"]["z_max"] = {"kind": "moving_wall", "velocity_m_s": [lid, 0.0, 0.0]}
    d["run"]["steps"] = 10
    return d


def _tier1(**over):
    d = scene_data("A-c68-v1.0", "quick", 1)
    d["ice"]["channel_length_m"] = 0.1
    d["ship"].update(start_x_m=3.98, sphere_band_m=0.03, sphere_spacing_m=0.05, steady_window_m=[4.0, 4.1])
    d["run"] = {"end_time_s": 0.01}
    d["numerics"]["backend"] = "cpu"
    for s, v in over.items():
        d[s].update(v)
    return d


# -- fluid ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("operator, tau", [("bgk", 0.5 + 1e-3), ("cumulant", 0.5 + 1e-4)])
def test_cell_reynolds_refused_with_a_working_tau(tmp_path, capsys, operator, tau):
    line = _refused(tmp_path, capsys, to_toml(_cavity(tau, operator)), "numerics.tau", "cell Reynolds number",
                    f"limit {limits.CELL_REYNOLDS_MAX[operator]:g} of the {operator} operator")
    tau_ok = _number_after(line, "numerics.tau >=")
    u_lat = 0.05
    assert 3 * u_lat / (tau_ok - 0.5) == pytest.approx(limits.CELL_REYNOLDS_MAX[operator], rel=1e-3)
    ok = parse_scene(to_toml(_cavity(tau_ok * (1 + 1e-6), operator)))
    limits.check_fluid(ok, ok.units())          # the proposed tau is accepted


def test_bgk_refusal_proposes_the_cumulant_operator_when_it_would_run(tmp_path, capsys):
    e = 3 * 0.05 / (0.5 * (limits.CELL_REYNOLDS_MAX["bgk"] + limits.CELL_REYNOLDS_MAX["cumulant"]))
    _refused(tmp_path, capsys, to_toml(_cavity(0.5 + e, "bgk")), 'fluid.operator = "cumulant"')


def test_check_limits_false_lets_the_setting_through():
    d = _cavity(0.5 + 1e-4, "cumulant")
    scene = parse_scene(to_toml(d))
    with pytest.raises(StabilityError):
        limits.check_fluid(scene, scene.units())
    d["numerics"]["check_limits"] = False
    scene = parse_scene(to_toml(d))
    limits.check_fluid(scene, scene.units())


def test_physical_scene_names_the_cell_size():
    d = tomllib.loads(preset_text("poiseuille"))
    d["numerics"]["u_max_m_s"] = 1.0  # u dx / nu = 1000
    scene = parse_scene(to_toml(d))
    with pytest.raises(StabilityError, match=r"domain.dx_m: .* use domain.dx_m <= ([0-9.e-]+) m") as exc:
        limits.check_fluid(scene, scene.units())
    dx_ok = _number_after(str(exc.value), "domain.dx_m <=")
    assert 1.0 * dx_ok / 1e-6 == pytest.approx(limits.CELL_REYNOLDS_MAX["cumulant"], rel=1e-3)


def test_time_step_too_small_for_the_run_length(tmp_path, capsys):
    d = tomllib.loads(preset_text("poiseuille"))
    d["numerics"]["dt_s"] = 1e-6              # 20 s / 1e-6 s = 2e7 steps
    line = _refused(tmp_path, capsys, to_toml(d), "run.end_time_s", "2e+07 steps", "maximum 1e+07",
                    "numerics.dt_s >= 2e-06 s")
    assert _number_after(line, "run.end_time_s <=") == pytest.approx(10.0)


def test_time_step_too_large_breaks_the_lattice_speed(tmp_path, capsys):
    d = tomllib.loads(preset_text("poiseuille"))
    d["numerics"]["dt_s"] = 0.1
    line = _refused(tmp_path, capsys, to_toml(d), "numerics.dt_s", "above the limit 0.1 (numerics.mach)")
    assert _number_after(line, "numerics.dt_s <=") == pytest.approx(0.01)


def test_time_step_below_the_tau_floor(tmp_path, capsys):
    d = tomllib.loads(preset_text("poiseuille"))
    d["numerics"]["dt_s"] = 1e-9
    line = _refused(tmp_path, capsys, to_toml(d), "numerics.dt_s", "below the floor")
    assert _number_after(line, "numerics.dt_s >=") == pytest.approx(1e-8 * 1e-6 / 3 / 1e-6, rel=1e-3)


def test_mach_above_the_ceiling_is_refused(tmp_path, capsys):
    d = _cavity(0.6, lid=0.35)
    d["numerics"]["mach"] = 0.35
    _refused(tmp_path, capsys, to_toml(d), "numerics.mach", "0.3")


def test_refusal_leaves_an_existing_result_untouched(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    old = out / "cavity.h5"
    old.write_bytes(b"an earlier result")
    d = _cavity(0.5 + 1e-6, "bgk")
    rc, err, _ = _cli_run(tmp_path, capsys, to_toml(d), "--force")
    assert rc == 2 and "numerics.tau" in err
    assert old.read_bytes() == b"an earlier result"
    assert sorted(p.name for p in out.iterdir()) == ["cavity.h5"]


# -- ice and DEM ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("rho", [1000.0, 1020.0])
def test_ice_that_cannot_float_is_refused(tmp_path, capsys, rho):
    line = _refused(tmp_path, capsys, to_toml(_tier1(ice={"density_kg_m3": rho})), "ice.density_kg_m3",
                    "cannot float", "below 1000")
    assert _number_after(line, "e.g.") < 1000.0


def test_concentration_beyond_touching_is_refused_with_the_touching_limit(tmp_path, capsys):
    line = _refused(tmp_path, capsys, to_toml(_tier1(ice={"concentration": 1.0})), "ice.concentration",
                    "touching limit")
    c_ok = _number_after(line, "ice.concentration <=")
    assert 0.9 < c_ok < 1.0
    from iceresist.models.tier1 import Tier1Model

    model = Tier1Model(parse_scene(to_toml(_tier1(ice={"concentration": c_ok}))), backend="cpu")
    assert model.layout.gap_across_m >= -1e-12 and model.layout.gap_along_m >= -1e-12


def test_count_beyond_touching_is_refused():
    w, L, a = 1.39, 0.1, 0.041
    n = limits.touching_count(w, L, a)
    assert 33 <= n <= 33 * 2       # at least one full row across, at most two
    from iceresist.scene.schema import Ice

    with pytest.raises(StabilityError, match=f"ice.count <= {n}"):
        limits.check_ice_amount(Ice(count=n + 1, channel_length_m=L), w)
    limits.check_ice_amount(Ice(count=n, channel_length_m=L), w)


def test_too_many_dem_substeps_names_a_stiffness_that_works(monkeypatch):
    from iceresist.models.tier1 import Tier1Model

    monkeypatch.setattr(limits, "MAX_DEM_SUBSTEPS", 300)
    scene = parse_scene(to_toml(_tier1(contact={"stiffness_N_m": 5e5}, run={"end_time_s": 0.1})))
    with pytest.raises(StabilityError, match=r"contact.stiffness_N_m: .*use contact.stiffness_N_m <= ") as exc:
        Tier1Model(scene, backend="cpu")
    k_ok = _number_after(str(exc.value), "contact.stiffness_N_m <=")
    Tier1Model(parse_scene(to_toml(_tier1(contact={"stiffness_N_m": 0.99 * k_ok}, run={"end_time_s": 0.1}))),
               backend="cpu")


def test_ship_too_fast_for_the_dem_substep(tmp_path, capsys):
    """With the cube clumps the floe-overlap limit comes first; a body whose spheres are heavy for their size
    (here a stand-in model: 1 kg, 1 cm spheres, 0.01 s sub-step) meets the hull-travel limit."""
    from types import SimpleNamespace as NS

    scene = parse_scene(to_toml(_tier1()))
    model = NS(scene=scene, dt_s=0.005, substeps_per_step=1, substep_s=0.01, speed_m_s=1.0,
               contact=NS(stiffness_N_m=1e6, dem_safety=0.2), cube=NS(sphere_radius_m=0.01, mass_kg=1.0e-3))
    with pytest.raises(StabilityError, match=r"ship.speed_m_s: the hull moves 0.01 m per DEM sub-step .* use "
                                             r"ship.speed_m_s <= 0.5, or contact.dem_safety <= 0.1"):
        limits.check_tier1(model)


def test_ship_too_fast_for_the_floes_it_strikes(tmp_path, capsys):
    """At 5000 N/m a 41 mm floe struck at 4.8 m/s overlaps 1.7 sphere radii (measured: runs away); 4 knots
    (2.06 m/s, 0.72 radii) runs, so the speed offered lies between."""
    line = _refused(tmp_path, capsys, to_toml(_tier1(ship={"speed_m_s": 4.8})), "ship.speed_m_s",
                    "would overlap the hull by", "contact.stiffness_N_m >=")
    assert 2.06 < _number_after(line, "ship.speed_m_s <=") < 3.0


def test_a_soft_spring_is_named_as_the_cause(tmp_path, capsys):
    _refused(tmp_path, capsys, to_toml(_tier1(contact={"stiffness_N_m": 1.0})), "contact.stiffness_N_m",
             "would overlap the hull by", "use contact.stiffness_N_m >=")


def test_dem_safety_beyond_the_measured_limit_is_refused(tmp_path, capsys):
    _refused(tmp_path, capsys, to_toml(_tier1(contact={"dem_safety": 1.0})), "contact.dem_safety",
             "must be <= 0.4")


def test_stiffness_raises_the_substep_count_as_sqrt_k():
    from iceresist.models.tier1 import Tier1Model

    n = [Tier1Model(parse_scene(to_toml(_tier1(contact={"stiffness_N_m": k, "sample_interval_s": 0.01}))),
                    backend="cpu").substeps_per_step for k in (5e3, 5e5)]
    assert n[1] / n[0] == pytest.approx(10.0, rel=0.2)


def test_input_errors_are_stability_errors_or_input_errors():
    assert issubclass(StabilityError, InputError)


def test_cell_reynolds_limit_falls_above_the_reference_lattice_speed():
    """Measured: the cumulant cavity at lid speed 0.2 blew up at Re_cell = 60 (stable at 0.1) and ran at 20."""
    assert limits.cell_reynolds_max("cumulant", 0.05) == limits.CELL_REYNOLDS_MAX["cumulant"]
    assert limits.cell_reynolds_max("cumulant", 0.2) == pytest.approx(15.0)
    for eps, refused in ((3 * 0.2 / 60, True), (3 * 0.2 / 20, True), (3 * 0.2 / 14.9, False)):
        d = _cavity(0.5 + eps, lid=0.2)
        d["numerics"]["mach"] = 0.2
        scene = parse_scene(to_toml(d))
        if refused:
            with pytest.raises(StabilityError, match="numerics.tau >="):
                limits.check_fluid(scene, scene.units())
        else:
            limits.check_fluid(scene, scene.units())
