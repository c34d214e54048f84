"""The watchdog's probe and the water volume of a free-surface fluid, reduced per block on the target, against
the dense NumPy reading of the same fields (iceresist.models.probe.fluid_probe, PhaseField.h), CPU and CUDA."""

import numpy as np
import pytest

from iceresist.models import probe as watchdog_probes
from iceresist.backends import jit
from iceresist.freesurface.fluid import FreeSurfaceFluid
from iceresist.freesurface.probe import FluidProbe
from iceresist.grid.forest import BlockForest, Face

KE_REF = 12.5


@pytest.fixture(scope="module")
def flow():
    """A 16 x 8 x 16 closed tank (4 blocks), 10 cells of water set moving at 0.03 along x and 0.01 along y, 6 steps:
    the water piles up at the far walls, so density, speed and phi differ from cell to cell."""
    forest = BlockForest.uniform((16, 8, 16), {k: Face("wall") for k in ("x-", "x+", "y-", "y+", "z-", "z+")})
    fs = FreeSurfaceFluid(forest, tau=0.6, gravity_lattice=1e-4, depth_cells=10.0, operator="bgk",
                          precision="float64")
    fs.initialize(u=(0.03, 0.01, 0.0))
    fs.step(6)
    return fs


def _reference(fs, full):
    if full:
        rho, u = fs.macroscopic()
        return watchdog_probes.fluid_probe(rho, u, fs.liquid(), KE_REF)
    return watchdog_probes.fluid_speed_probe(fs.velocity(), fs.liquid())


def _field(fs, full):
    """The dense field each extreme is taken of: speed, density."""
    rho, u = fs.macroscopic() if full else (None, fs.velocity())
    return {"max_lattice_speed": np.sqrt(np.nansum(u ** 2, axis=0)), "density_min": rho, "density_max": rho}


@pytest.mark.parametrize("full", [True, False])
def test_probe_equals_the_dense_reading(flow, full):
    """Same extremes (to 1e-12) at cells holding them, same kinetic energy and mass, on a flow whose fields vary."""
    got, ref = flow.probe(full, KE_REF), _reference(flow, full)
    assert got["finite"] == ref["finite"] == (True, None)
    assert set(got) == set(ref)
    fields = _field(flow, full)
    for key in ("max_lattice_speed",) + (("density_min", "density_max") if full else ()):
        assert got[key][0] == pytest.approx(ref[key][0], rel=1e-12, abs=1e-15), key
        assert fields[key][tuple(got[key][1])] == pytest.approx(ref[key][0], rel=1e-12, abs=1e-15), key
    assert ref["max_lattice_speed"][0] > 0.005  # the flow moves
    if full:
        assert ref["density_max"][0] - ref["density_min"][0] > 1e-4  # hydrostatic and piled-up water
        assert got["kinetic_energy"] == pytest.approx(ref["kinetic_energy"], rel=1e-12)
        assert got["mass"] == pytest.approx(ref["mass"], rel=1e-12)      # the records' mass (FreeSurfaceModel)
        assert got["kinetic_energy_ref"] == KE_REF


def test_probe_names_the_first_bad_cell_of_the_dense_grid(flow):
    """NaNs in two cells: the probe names the one NumPy's argwhere names first on the dense grid (x slowest), also
    where that cell lies in the later block of the forest or later in its block's storage (x fastest)."""
    fs = flow
    shape = fs.forest.shape_cells
    ids = fs.forest.from_dense(np.arange(np.prod(shape)).reshape(shape))

    def where(cell):
        blk, c = np.argwhere(ids == np.ravel_multi_index(cell, shape))[0]
        return int(blk), int(c)

    f0, phi0 = fs.fluid.state.copy(), fs.phase.phi.copy()
    try:
        # [3, 4, 9] comes first densely but lies in a later block than [12, 2, 3]
        first, later = [3, 4, 9], [12, 2, 3]
        assert fs.liquid()[tuple(first)] and fs.liquid()[tuple(later)] and where(first)[0] > where(later)[0]
        for cell in (later, first):
            blk, c = where(cell)
            fs.fluid.state[fs.fluid.fslot[blk], 7, c] = np.nan
        assert fs.probe(True)["finite"] == (False, first) == _reference(fs, True)["finite"]
        fs.fluid.state[...] = f0
        # in one block: [0, 0, 6] comes first densely, [1, 0, 5] first in the block's storage
        first, later = [0, 0, 6], [1, 0, 5]
        assert where(first)[0] == where(later)[0] and where(first)[1] > where(later)[1]
        for cell in (later, first):
            fs.phase.phi[where(cell)] = np.nan
        assert fs.probe(False)["finite"] == (False, first)
        assert np.argwhere(~np.isfinite(fs.phi()))[0].tolist() == first
    finally:
        fs.fluid.state[...] = f0
        fs.phase.phi[...] = phi0
    assert fs.probe(True)["finite"] == (True, None)


def test_volume_is_the_float64_sum_of_h_outside_solids(flow):
    """Per-block sums on the target equal the host sum of h over the cells no solid covers (to 1e-13)."""
    ph = flow.phase

    def dense_sum():
        return float(np.asarray(ph.h).astype(np.float64).sum(axis=1)[np.asarray(ph.solid) < 0].sum())

    whole = ph.volume()
    assert whole == pytest.approx(dense_sum(), rel=1e-13)
    solid0 = ph.solid.copy()
    try:
        ph.solid[0, :100] = 3  # a body covering the bottom 100 cells of block 0 (all water) takes them out
        assert ph.volume() == pytest.approx(dense_sum(), rel=1e-13)
        taken = float(np.asarray(ph.h)[0, :, :100].astype(np.float64).sum())
        assert whole - ph.volume() == pytest.approx(taken, rel=1e-12) and taken > 90  # about one per water cell
    finally:
        ph.solid[...] = solid0


def test_cuda_probe_equals_cpu(flow):
    """The same reduction compiled for CUDA (the simulator in CI) gives the CPU's rows on the same fields."""
    from numba import cuda

    fs = flow
    args = [np.ascontiguousarray(np.asarray(a)) for a in (fs.fluid.state, fs.fluid.fslot, fs.fluid.flags, fs._u,
                                                          fs.phase.phi)]
    cpu = FluidProbe(fs.forest, jit.cpu).rows(*args, True, 0.5 * fs.g)
    gpu = FluidProbe(fs.forest, jit.cuda()).rows(*[cuda.to_device(a) for a in args], True, 0.5 * fs.g)
    assert cpu.shape == (fs.forest.nblocks, 13) and cpu[:, 0].sum() == fs.liquid().sum()
    np.testing.assert_allclose(gpu, cpu, rtol=1e-13, atol=0)
