"""HDF5 result file, XDMF sidecar and checkpoints."""

import os
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.io import RunFile, read_checkpoint, write_checkpoint
from iceresist.io.meta import git_revision, mlups, run_meta

SHAPE = (6, 4, 3)  # distinct lengths so a swapped axis cannot go unnoticed


def _fields(rng, t=0.0):
    return {"rho": 1.0 + 0.01 * rng.standard_normal(SHAPE), "u": rng.standard_normal(SHAPE + (3,)) + t,
            "flags": (rng.random(SHAPE) > 0.8).astype(np.uint8)}


def test_fields_round_trip_in_xyz_and_are_zyx_float32_on_disk(tmp_path, rng):
    f = _fields(rng)
    with RunFile(tmp_path / "r.h5", "w", shape_cells=SHAPE, dx_m=0.01) as rf:
        rf.write_fields(10, 0.5, f, units={"rho": "kg/m^3", "u": "m/s"})
    with RunFile(tmp_path / "r.h5") as rf:
        assert rf.snapshot_iterations() == [10]
        assert rf.snapshot_time_s(10) == 0.5
        np.testing.assert_array_equal(rf.read_field(10, "rho"), f["rho"].astype(np.float32))
        np.testing.assert_array_equal(rf.read_field(10, "u"), f["u"].astype(np.float32))
        np.testing.assert_array_equal(rf.read_field(10, "flags"), f["flags"])
    with h5py.File(tmp_path / "r.h5") as h5:
        g = h5["fields/0000000010"]
        assert g["rho"].shape == (3, 4, 6) and g["rho"].dtype == np.float32
        assert g["u"].shape == (3, 4, 6, 3)
        assert g["flags"].dtype == np.uint8
        assert g["u"].attrs["units"] == "m/s"
        # disk index [z, y, x] holds the engine's [x, y, z]
        assert g["rho"][2, 1, 5] == np.float32(f["rho"][5, 1, 2])


def test_wrong_field_shape_is_refused(tmp_path):
    with RunFile(tmp_path / "r.h5", "w", shape_cells=SHAPE) as rf:
        with pytest.raises(ValueError, match="shape"):
            rf.write_fields(0, 0.0, {"rho": np.zeros((2, 2, 2))})


def test_xdmf_is_well_formed_and_points_at_existing_datasets(tmp_path, rng):
    with RunFile(tmp_path / "run.h5", "w", shape_cells=SHAPE, dx_m=0.25, origin_m=(1.0, 2.0, 3.0)) as rf:
        for it in (0, 5, 10):
            rf.write_fields(it, 0.1 * it, _fields(rng, it))
    root = ET.parse(tmp_path / "run.xdmf").getroot()
    assert root.tag == "Xdmf"
    coll = root.find("Domain/Grid")
    assert coll.get("GridType") == "Collection" and coll.get("CollectionType") == "Temporal"
    grids = coll.findall("Grid")
    assert [float(g.find("Time").get("Value")) for g in grids] == pytest.approx([0.0, 0.5, 1.0])
    with h5py.File(tmp_path / "run.h5") as h5:
        for g in grids:
            topo = g.find("Topology")
            assert topo.get("TopologyType") == "3DCoRectMesh"
            assert topo.get("Dimensions") == "4 5 7"  # points z, y, x = cells + 1
            origin, spacing = (d.text.split() for d in g.findall("Geometry/DataItem"))
            assert [float(v) for v in origin] == [3.0, 2.0, 1.0]
            assert [float(v) for v in spacing] == [0.25] * 3
            attrs = g.findall("Attribute")
            assert {a.get("Name") for a in attrs} == {"rho", "u", "flags"}
            for a in attrs:
                item = a.find("DataItem")
                fname, dpath = item.text.split(":")
                assert fname == "run.h5"
                ds = h5[dpath]
                assert tuple(int(n) for n in item.get("Dimensions").split()) == ds.shape
                assert int(item.get("Precision")) == ds.dtype.itemsize
                assert a.get("Center") == "Cell"
                assert a.get("AttributeType") == ("Vector" if a.get("Name") == "u" else "Scalar")


def test_timeseries_columns_append_and_pad(tmp_path):
    with RunFile(tmp_path / "r.h5", "w") as rf:
        rf.append_timeseries({"iteration": 0, "time_s": 0.0, "mass": 1.0})
        rf.append_timeseries({"iteration": 1, "time_s": 0.1, "mass": 1.5, "force_N": [1.0, 2.0, 3.0]})
        rf.append_timeseries({"iteration": 2, "time_s": 0.2, "force_N": [4.0, 5.0, 6.0]})
        ts = rf.timeseries()
    np.testing.assert_array_equal(ts["iteration"], [0, 1, 2])
    assert ts["iteration"].dtype == np.int64
    np.testing.assert_array_equal(ts["mass"], [1.0, 1.5, np.nan])
    assert np.isnan(ts["force_N"][0]).all()
    np.testing.assert_array_equal(ts["force_N"][1:], [[1, 2, 3], [4, 5, 6]])


def test_truncate_after_drops_later_rows_and_snapshots(tmp_path, rng):
    with RunFile(tmp_path / "r.h5", "w", shape_cells=SHAPE) as rf:
        for it in range(0, 50, 10):
            rf.append_timeseries({"iteration": it, "time_s": it * 0.1})
            rf.write_fields(it, it * 0.1, _fields(rng))
    with RunFile(tmp_path / "r.h5", "a") as rf:
        rf.truncate_after(20)
        assert rf.snapshot_iterations() == [0, 10, 20]
        np.testing.assert_array_equal(rf.timeseries()["iteration"], [0, 10, 20])
    assert ET.parse(tmp_path / "r.xdmf").getroot().find("Domain/Grid").findall("Grid").__len__() == 3


def test_meta_attributes(tmp_path):
    meta = run_meta(scene_text="[scene]\nname = 'x'\n", backend="cpu", precision="float32", cells=96)
    with RunFile(tmp_path / "r.h5", "w") as rf:
        rf.write_meta(**meta, units={"dx_m": 0.01}, wall_time_s=1.5, mlups=mlups(96, 1000, 1.5))
    with RunFile(tmp_path / "r.h5") as rf:
        m = rf.meta
    assert m["scene_toml"].startswith("[scene]")
    assert m["cells"] == 96 and m["precision"] == "float32" and m["backend"] == "cpu"
    assert m["mlups"] == pytest.approx(0.064)
    assert '"dx_m": 0.01' in m["units"]
    assert m["iceresist_version"]
    assert m["git_revision"] == git_revision()


def test_meta_object_decodes_what_write_meta_encoded(tmp_path):
    model = {"tier": 2, "steady_window_m": [4.01, 4.79], "hull": "b063", "mixed": [1, "a"]}
    with RunFile(tmp_path / "r.h5", "w") as rf:
        rf.write_meta(model=model, cells=96, window=[0.5, 1.5])
    with RunFile(tmp_path / "r.h5") as rf:
        assert isinstance(rf.meta["model"], str)  # stored as JSON text
        assert rf.meta_object("model") == model
        assert rf.meta_object("cells") == 96
        np.testing.assert_array_equal(rf.meta_object("window"), [0.5, 1.5])  # numeric lists stay arrays
        with pytest.raises(KeyError):
            rf.meta_object("absent")


def test_mode_x_refuses_to_overwrite(tmp_path):
    p = tmp_path / "r.h5"
    with RunFile(p, "w") as rf:
        rf.write_meta(a=1)
    with pytest.raises((FileExistsError, OSError)):
        RunFile(p, "x")
    with RunFile(p) as rf:
        assert rf.meta["a"] == 1


def test_checkpoint_round_trip_keeps_dtypes_bit_for_bit(tmp_path, rng):
    state = {"f": rng.standard_normal((27, 8)).astype(np.float32), "iteration": np.int64(42), "time_s": 0.125,
             "name": "fluid", "nested": {"q": np.arange(5, dtype=np.int16), "none": None}}
    p = write_checkpoint(tmp_path / "chk.h5", state)
    back = read_checkpoint(p)
    assert back["f"].dtype == np.float32 and np.array_equal(back["f"], state["f"])
    assert back["iteration"] == 42 and back["time_s"] == 0.125 and back["name"] == "fluid"
    assert back["nested"]["q"].dtype == np.int16 and back["nested"]["none"] is None
    assert sorted(os.listdir(tmp_path)) == ["chk.h5"]  # no temporary file left


def test_failed_checkpoint_leaves_the_previous_one_whole(tmp_path):
    p = write_checkpoint(tmp_path / "chk.h5", {"x": np.arange(3)})
    with pytest.raises(TypeError):
        write_checkpoint(p, {"y": np.arange(4), "bad": object()})
    assert sorted(os.listdir(tmp_path)) == ["chk.h5"]
    np.testing.assert_array_equal(read_checkpoint(p)["x"], [0, 1, 2])


def test_reading_a_non_checkpoint_is_an_input_error(tmp_path):
    (tmp_path / "junk.h5").write_text("not hdf5")
    with pytest.raises(InputError, match="cannot open"):
        read_checkpoint(tmp_path / "junk.h5")
    with RunFile(tmp_path / "r.h5", "w"):
        pass
    with pytest.raises(InputError, match="not an iceresist checkpoint"):
        read_checkpoint(tmp_path / "r.h5")
