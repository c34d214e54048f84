"""Your own hull: a mesh hull (``ship.hull = "mesh"``) in the engine. The shipped B-063 mesh as a
:class:`MeshHull` against the parametric hull; spheres on a mesh solid of any shape (an L-shaped prism against
its closed-form mass properties); tier 2 on a mesh of the CI-sized hull sees the flow force of the parametric one;
tier 1 through the sweep with the mesh's own FSICR; and one-line refusals with exit status 2."""

import copy

import h5py
import numpy as np
import pytest
import trimesh

from fsicr.hullmesh import write_stl
from iceresist.dem.bodies import convex_polyhedron, distance_to_mesh, inside_mesh, mesh_solid
from iceresist.errors import InputError
from iceresist.models import build_model
from iceresist.ship.hull import HullGeometry, b063_hull
from iceresist.ship.meshhull import MeshHull
from iceresist.scene.load import load_scene
from iceresist.scene.case_scenes import case_scene
from iceresist.sweep import TINY_OVERRIDES, TINY_TIER2_OVERRIDES, run_case

CASE = "A-c68-v1.0"


def _polygon_area(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def l_prism():
    """Three unit cubes in an L (a solid that is not convex): (vertices, faces), outward."""
    xy = np.array([[1, 1], [1, 2], [0, 2], [0, 0], [2, 0], [2, 1]], float)
    tri = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]])
    m = trimesh.creation.extrude_triangulation(xy, tri, 1.0)
    assert m.is_watertight and m.volume > 0
    return np.asarray(m.vertices, float), np.asarray(m.faces)


def test_the_b063_mesh_hull_answers_as_the_parametric_hull():
    for bow, axis in (("A", "+x"), ("B", "-x")):
        ref, got = b063_hull(bow), MeshHull.from_file("b063", 0.44, bow=axis)
        assert got.is_convex
        for key in ("beam_m", "waterline_length_m", "end_length_m", "parallel_length_m", "length_overall_m",
                    "freeboard_m", "midship_area_m2", "prismatic_length_m"):
            assert getattr(got, key) == pytest.approx(getattr(ref, key), rel=1e-6), key
        assert got.volume_m3() == pytest.approx(ref.volume_m3(), rel=1e-6)
        assert _polygon_area(got.waterline_polygon()) == pytest.approx(_polygon_area(ref.waterline_polygon()), rel=1e-6)
        assert got.fsicr_inputs(25)["phi1_deg"] == pytest.approx(ref.bow_rake_deg, abs=1e-5)


def test_spheres_on_a_solid_that_is_not_convex():
    v, f = l_prism()
    rho, spacing = 500.0, 0.1
    s = mesh_solid(v, f, rho, spacing, name="L")
    assert s.volume_m3 == pytest.approx(3.0, rel=1e-12)
    assert s.model_com_m == pytest.approx([2.5 / 3, 2.5 / 3, 0.5], rel=1e-12)
    # inertia about the centre of mass: three unit cubes (1/6 each about their centres) moved by the parallel axis
    centres = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [0.5, 1.5, 0.5]]) - s.model_com_m
    ref = sum(np.eye(3) / 6.0 + (c @ c) * np.eye(3) - np.outer(c, c) for c in centres) * rho
    assert s.inertia_tensor_model() == pytest.approx(ref, abs=1e-9 * rho)
    # every sphere inside, one radius from the nearest face; the reflex edge gets no sphere outside the L
    c = s.model_com_m + s.sphere_offsets_m @ s.model_to_body.T
    r = s.sphere_radius_m
    assert inside_mesh(c, v, f).all()
    d = distance_to_mesh(c, v, f, 2 * r)
    assert d.min() >= 0.98 * r and d.max() == pytest.approx(r, rel=1e-9)
    assert not ((c[:, 0] > 1 + 1e-9) & (c[:, 1] > 1 + 1e-9)).any()
    # the surface is covered: every point of it within 1.05 spacings of a sphere's centre (a square lattice of
    # spacing s one radius under a face leaves 0.87 s; the faces' own lattices meet their edges less evenly)
    surface = trimesh.sample.sample_surface(trimesh.Trimesh(v, f), 2000, seed=1)[0]
    from scipy.spatial import cKDTree

    assert cKDTree(c).query(surface)[0].max() < 1.05 * spacing
    # the same body as a convex polyhedron would fill the notch: the mesh solid does not
    assert convex_polyhedron(v, rho, spacing).volume_m3 == pytest.approx(3.5, rel=1e-12)


def test_inside_mesh_against_the_l_prism():
    v, f = l_prism()
    p = np.random.default_rng(3).uniform(-0.2, 2.2, (5000, 3))
    truth = (p >= 0).all(axis=1) & (p[:, 2] <= 1) & (p[:, :2] <= 2).all(axis=1) & ~((p[:, 0] > 1) & (p[:, 1] > 1))
    assert (inside_mesh(p, v, f) == truth).all()


@pytest.fixture(scope="module")
def tiny_hull_mesh(tmp_path_factory):
    """The CI-sized tier-2 hull (TINY_TIER2_OVERRIDES) written as an STL, moved off the ship frame."""
    sh = TINY_TIER2_OVERRIDES["ship"]
    g = HullGeometry(length_overall_m=sh["length_m"], beam_m=sh["beam_m"], draught_m=sh["draught_m"],
                     parallel_length_m=sh["parallel_length_m"], bow_rake_deg=30.0, stern_rake_deg=45.0)
    path = tmp_path_factory.mktemp("mesh") / "tiny.stl"
    v, f = g.mesh()
    write_stl(path, v + np.array([0.7, -0.2, 0.5]), f)  # anywhere: the reader puts keel, centreline and stem
    return path


def test_tier2_on_a_mesh_hull_sees_the_flow_force_of_the_parametric_hull(tiny_hull_mesh, tmp_path):
    """Until the first ice contact (record 10) the hull's flow force of the mesh equals the parametric hull's
    (the same convex polyhedron to float32 rounding); then their sphere layouts, not the flow, differ."""
    mesh = copy.deepcopy(TINY_TIER2_OVERRIDES)
    mesh["ship"].update(hull="mesh", mesh_file=str(tiny_hull_mesh))
    fluid = {}
    for name, overrides in (("parametric", TINY_TIER2_OVERRIDES), ("mesh", mesh)):
        path = run_case(CASE, "quick", 2, tmp_path / name, backend="cpu", overrides=overrides)
        with h5py.File(path) as h:
            fluid[name] = np.stack([h["timeseries"][k][:10] for k in ("Fx_fluid_N", "Fz_fluid_N")])
            if name == "mesh":
                assert h["bodies/hull_vertices_m"].shape == (12, 3)
    assert np.abs(fluid["parametric"]).max() > 1.0
    assert fluid["mesh"] == pytest.approx(fluid["parametric"], rel=1e-4, abs=1e-4)


def test_tier1_sweep_case_on_the_b063_mesh_uses_the_meshs_fsicr_and_the_report_says_so(tmp_path):
    from iceresist.sweep import run_sweep
    from reports.report import write_report

    overrides = copy.deepcopy(TINY_OVERRIDES)
    overrides["ship"].update(hull="mesh", mesh_file="b063")
    table = run_sweep("quick", 1, tmp_path, CASE, backend="cpu", overrides=overrides)
    row = table.iloc[0]
    assert row["R_CH_FSICR_kN"] == pytest.approx(300.1, abs=0.05)  # measured L 76.01 m, Awf 132.6 m^2
    assert np.isfinite(row["mean_force_N"]) and row["mean_force_N"] > 0
    html = write_report(tmp_path)[0].read_text()
    assert "<h1>b063 (mesh hull) in a brash-ice channel" in html
    assert "area of the waterline of the bow Awf [m^2]</td>" in html and "<td>132.6</td>" in html


def test_tier2_on_convex_slabs_of_the_hull_sees_the_same_flow_force(tiny_hull_mesh, tmp_path, monkeypatch):
    """The union-of-pieces path of the kernels' SDF (a hull that is not convex): the CI-sized hull taken as 8
    convex slabs along x (exact for a convex hull: no excess) feels the flow force of the one polyhedron to 1e-4
    until the first ice contact; the seams between slabs read inside."""
    mesh = copy.deepcopy(TINY_TIER2_OVERRIDES)
    mesh["ship"].update(hull="mesh", mesh_file=str(tiny_hull_mesh))
    fluid = {}
    for name in ("polyhedron", "slabs"):
        if name == "slabs":
            monkeypatch.setattr(MeshHull, "is_convex", property(lambda self: False))
        model = build_model(case_scene(CASE, "quick", 2, **mesh), backend="cpu")
        rows = []
        for _ in range(8):
            model.step(1)
            d = model.diagnostics()
            rows.append((d["Fx_fluid_N"], d["Fz_fluid_N"]))
        fluid[name] = np.array(rows)
        if name == "slabs":
            assert len(model.geoms[0].pieces_m) == 8
    assert np.abs(fluid["polyhedron"]).max() > 1.0
    assert fluid["slabs"] == pytest.approx(fluid["polyhedron"], rel=1e-4, abs=1e-4)


def test_tier2_takes_a_hull_convex_in_section_and_refuses_one_that_is_not(tmp_path):
    """An L-shaped plan (convex sections) is cut into slabs within 1 % of its volume; an L-shaped section along
    the whole length (a hull whose cross-sections are not convex) is refused naming ship.tier."""
    v, f = l_prism()
    plan, section = tmp_path / "plan.stl", tmp_path / "section.stl"
    write_stl(plan, v * np.array([0.2, 0.04, 0.1]), f)  # 0.4 m long, the notch in the plan
    write_stl(section, np.column_stack([v[:, 2] * 0.4, v[:, 0] * 0.04, v[:, 1] * 0.05]), f)  # the L across
    for path, ok in ((plan, True), (section, False)):
        mesh = copy.deepcopy(TINY_TIER2_OVERRIDES)
        mesh["ship"].update(hull="mesh", mesh_file=str(path), draught_m=0.06)
        scene = case_scene(CASE, "quick", 2, **mesh)
        if ok:
            model = build_model(scene, backend="cpu")
            g = model.geoms[0]
            assert len(g.pieces_m) >= 8 and model.geometry.union_excess(list(g.pieces_m)) <= 0.01
        else:
            with pytest.raises(InputError, match=r"ship.tier: .* cross-sections are not convex\); run it at tier = 1"):
                build_model(scene, backend="cpu")


def test_a_scene_names_the_mesh_key_of_a_bad_hull(tmp_path):
    """Scene files with a mesh hull (the mesh path relative to the scene file): one line naming the key."""
    v, f = b063_hull("A").mesh()
    write_stl(tmp_path / "open.stl", v, f[1:])
    head = '[case]\nname = "A-c68-v1.0"\nfidelity = "quick"\ntier = 1\n[ship]\n'
    for ship, needle in (('hull = "mesh"', 'ship.mesh_file: a mesh hull needs its file'),
                         ('mesh_file = "b063"', 'set hull = "mesh"'),
                         ('hull = "mesh"\nmesh_file = "open.stl"', "ship.mesh_file: 'open.stl' is not watertight"),
                         ('hull = "mesh"\nmesh_file = "b063"\nmesh_unit = "mm"', "ship.mesh_unit: the hull is "
                                                                               "0.0035 m long in 'mm'")):
        path = tmp_path / "scene.toml"
        path.write_text(head + ship + "\n")
        with pytest.raises(InputError) as err:
            build_model(load_scene(path), backend="cpu")
        assert needle in str(err.value) and "\n" not in str(err.value), str(err.value)


@pytest.mark.parametrize("argv, needle", [
    (["--mesh", "nope.stl"], "--mesh: no file 'nope.stl'"),
    (["--mesh", "b063", "--mesh-unit", "mm"], "--mesh-unit: the hull is 0.0035 m long in 'mm'"),
    (["--mesh", "b063", "--cases", "B-c68-v1.0"], "--cases: B-c68-v1.0 name Bow B"),
    (["--mesh", "b063", "--mesh-bow", "+z"], "--mesh-bow: '+z' is not one of"),
])
def test_sweep_mesh_refusals_are_one_line_and_write_nothing(tmp_path, capsys, monkeypatch, argv, needle):
    from iceresist import cli

    monkeypatch.chdir(tmp_path)
    rc = cli.main(["sweep", *argv, "--output", "out", "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and needle in err[0], err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_the_quick_tier1_sweep_on_the_b063_mesh_equals_the_parametric_hulls(tmp_path):
    """Every Bow A case of the quick tier-1 sweep, B-063 from its shipped mesh and from its parameters: the mean
    ice forces agree within their combined 95 % intervals (about 3 min on a 2-core x86 VM)."""
    from iceresist.scene.case_scenes import CASES
    from iceresist.sweep import run_sweep

    names = ",".join(c for c in CASES if c.startswith("A-"))
    mesh = run_sweep("quick", 1, tmp_path / "mesh", names, backend="cpu",
                     overrides={"ship": {"hull": "mesh", "mesh_file": "b063"}})
    param = run_sweep("quick", 1, tmp_path / "param", names, backend="cpu")
    both = mesh.merge(param, on="case", suffixes=("_mesh", "_param"))
    print(both[["case", "mean_force_N_mesh", "ci95_N_mesh", "mean_force_N_param", "ci95_N_param"]].to_string())
    assert len(both) == 5
    scatter = np.hypot(both["ci95_N_mesh"], both["ci95_N_param"])
    gap = (both["mean_force_N_mesh"] - both["mean_force_N_param"]).abs()
    assert (gap <= scatter).all(), both[["mean_force_N_mesh", "mean_force_N_param", "ci95_N_mesh", "ci95_N_param"]]
    assert (both["R_CH_FSICR_kN_mesh"] - 300.1).abs().max() < 0.05


def test_the_documented_mesh_scene_builds_and_steps():
    from iceresist.scene.docs import MESH_EXAMPLE
    from iceresist.scene.load import parse_scene

    model = build_model(parse_scene(MESH_EXAMPLE, "mesh_example.toml"), backend="cpu")
    assert model.describe_ship()["hull"]["kind"] == "mesh"
    # the same surface sampled from float32 vertices: the faces' triangles differ, so the count does a little
    assert model.hull.n_spheres == pytest.approx(build_model(case_scene(CASE, "quick", 1), backend="cpu").hull.n_spheres,
                                                 rel=0.03)
    model.step(2)
    assert np.isfinite(model.diagnostics()["Fx_N"])


# -- mesh bodies in [[bodies]] -------------------------------------------------------------------------------
def _channel_with(body_toml: str) -> str:
    from test_bodies import CHANNEL

    head = CHANNEL[:CHANNEL.index("[[bodies]]")]
    return head + body_toml


def test_a_fixed_mesh_box_feels_the_flow_force_of_the_box_body(tmp_path):
    """A box drawn as a mesh (and moved off its centre in the file) and the same `box` body, fixed in a channel:
    the fluid sees the same solid (a convex polyhedron of six planes, a box), so the drag agrees to 1e-4 (measured
    5e-5: the two compute the links' wall distances their own way, in float32)."""
    write_stl(tmp_path / "brick.stl", *(lambda m: (m.vertices + np.array([5.0, -3.0, 2.0]), m.faces))(
        trimesh.creation.box((6.0, 4.0, 4.0))))
    box = 'name = "post"\nshape = "box"\nsize_m = [6.0, 4.0, 4.0]\nposition_m = [10.0, 8.0, 8.0]\nmotion = "fixed"\n'
    mesh = ('name = "post"\nshape = "mesh"\nmesh_file = "brick.stl"\nposition_m = [10.0, 8.0, 8.0]\n'
            'motion = "fixed"\n')
    fx = {}
    for name, body in (("box", box), ("mesh", mesh)):
        path = tmp_path / f"{name}.toml"
        path.write_text(_channel_with("[[bodies]]\n" + body))
        model = build_model(load_scene(path), backend="cpu")
        model.step(20)
        fx[name] = model.diagnostics()["post_Fx_N"]
    assert fx["box"] > 0
    assert fx["mesh"] == pytest.approx(fx["box"], rel=1e-4)


def test_mesh_bodies_are_refused_in_one_line_naming_the_key(tmp_path, capsys):
    from iceresist import cli

    v, f = l_prism()
    write_stl(tmp_path / "L.stl", v, f)
    write_stl(tmp_path / "big.stl", v * 20.0, f)
    for body, needle in (('mesh_file = "nope.stl"', "bodies[0].mesh_file: no file 'nope.stl'"),
                         ('mesh_file = "L.stl"', "bodies[0].mesh_file: body 'post' fills 85.7 % of its convex hull"),
                         ('mesh_file = "big.stl"', "bodies[0].mesh_unit: body 'post' is 40 m across along x")):
        path = tmp_path / "s.toml"
        path.write_text(_channel_with(f'[[bodies]]\nname = "post"\nshape = "mesh"\n{body}\n'
                                      f'position_m = [10.0, 8.0, 8.0]\nmotion = "fixed"\n'))
        rc = cli.main(["run", str(path), "--output", str(tmp_path / "out"), "--no-progress"])
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and needle in err[0], err
        assert not (tmp_path / "out").exists()


def test_the_mesh_hulls_signed_distance_is_the_analytic_b063s():
    """Issue check: the fluid's signed distance of the B-063 mesh hull against the parametric hull's at random
    points around it: within 1e-6 of the hull's length (measured 8e-8, the STL's float32); cut into 16 convex
    slabs, the same near the surface and the same sign everywhere."""
    from iceresist.coupling.geometry import ConvexPolyhedron, ConvexUnion
    from iceresist.dem import convex_polyhedron

    ref_hull = b063_hull("A")
    mesh = MeshHull.from_file("b063", ref_hull.draught_m)
    shape = convex_polyhedron(ref_hull.vertices(), 500.0, 0.03)
    ref = ConvexPolyhedron.of_shape(ref_hull.vertices(), shape)
    lo, hi = ref_hull.vertices().min(axis=0) - 0.2, ref_hull.vertices().max(axis=0) + 0.2
    p = (np.random.default_rng(5).uniform(lo, hi, (20000, 3)) - shape.model_com_m) @ shape.model_to_body
    d = ref.sdf(p)
    one = ConvexPolyhedron.of_shape(mesh.vertices(), shape).sdf(p)
    assert np.abs(one - d).max() < 1e-6 * ref_hull.length_overall_m
    # the slabs: the same within 50 mm of the surface (where links and mirrors read it); farther out, beyond the
    # hull's edges, each is its own lower bound of the distance (0.10 against 0.20 m at a deck corner)
    slabs = ConvexUnion.of_shape(mesh.convex_pieces(16), mesh.mesh.volume_m3, shape).sdf(p)
    near = np.abs(d) < 0.05
    assert near.sum() > 1000 and np.abs(slabs - d)[near].max() < 1e-6 * ref_hull.length_overall_m
    assert ((slabs < 0) == (d < 0)).all()
