"""A tier-2 ship run continued from its checkpoint (``iceresist run --pickup``) gives the uninterrupted result bit
for bit: the populations, phase field, cell owners, previous forces and DEM contact history all cross the restart."""

import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.io import RunFile
from iceresist.scene.case_scenes import case_scene
from iceresist.sweep import TINY_TIER2_OVERRIDES
from tests.test_tier1_pickup import run_cli, scene_file

CASE = "A-c68-v1.0"


@pytest.mark.parametrize("tile_cells", [None, 256])
def test_tier2_pickup_continues_bit_for_bit(tmp_path, monkeypatch, tile_cells):
    """``tile_cells`` 256: the hull (a cell box of about 2 000 cells here) is launched in slabs, so the slab counts
    and the slab rows that own the covered cells cross the restart too."""
    if tile_cells is not None:
        from iceresist.coupling import coupler

        monkeypatch.setattr(coupler, "TILE_CELLS", tile_cells)
    path, name = scene_file(tmp_path, 2, TINY_TIER2_OVERRIDES, checkpoint_every=4)
    assert run_cli(path, "--output", tmp_path / "split", "--steps", "8") == 0
    assert run_cli(path, "--output", tmp_path / "split", "--steps", "13", "--pickup") == 0
    assert run_cli(path, "--output", tmp_path / "straight", "--steps", "13") == 0
    with RunFile(tmp_path / "split" / f"{name}.h5") as a, RunFile(tmp_path / "straight" / f"{name}.h5") as b:
        ta, tb = a.timeseries(), b.timeseries()
        assert a.meta["iteration"] == 13
    np.testing.assert_array_equal(ta["iteration"], np.arange(14))
    assert np.abs(tb["Fx_fluid_N"][9:]).max() > 0            # the hull moves the water after the restart
    if tile_cells is not None:
        from iceresist.models import build_model
        from iceresist.scene.load import load_scene

        model = build_model(load_scene(path), backend="cpu")
        model.step(1)
        assert model.coupling._tile_body is not None and len(model.coupling._tile_body) > model.dem.n_bodies
    for key in ("Fx_N", "Fz_N", "Fx_fluid_N", "Fz_fluid_N", "x_bow_m", "contacts", "ice_kinetic_energy_J",
                "water_volume_m3"):
        np.testing.assert_array_equal(ta[key], tb[key], err_msg=key)


def test_tier2_checkpoint_without_flow_state_is_refused():
    from iceresist.models import build_model

    model = build_model(case_scene(CASE, "quick", 2, **TINY_TIER2_OVERRIDES), backend="cpu")
    with pytest.raises(InputError, match="no tier-2 flow state"):
        model.load_state({"iteration": np.int64(3)})
