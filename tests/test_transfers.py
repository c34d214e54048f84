"""The coupled step keeps its state on the device: copies between host and device per step, counted by watching
numba-cuda (iceresist.backends.transfers).

On the CUDA simulator: a kinematic box moving through the surface of an 8 x 8 x 16 tank and a floating ice cube
beside it, so that cells are covered and uncovered, the DEM has contacts and the fluid loads change every step.
A tier-2 record (the model's step: several coupled steps and the mean ice and fluid force on the hull) is counted
in the GPU build check's trace (tests/test_gpu_build.py), where the CI-sized tier-2 case can be stepped in seconds.
"""

import numpy as np
import pytest

from iceresist.backends import jit, transfers
from iceresist.coupling import Box
from iceresist.coupling.floating import FloatingBodies
from iceresist.dem import box

#: Host-device copies per coupled step: none is needed (the limit set for the step was one small read per LBM
#: step; a step that needs one again raises this deliberately).
PER_STEP = 0


def _box_and_cube(target):
    dx = 0.01
    model = FloatingBodies((8, 8, 16), depth_m=8 * dx, dx_m=dx, tau=0.6, g_lattice=1e-3, target=target)
    v = dx / model.dt_s
    model.add_body(Box((3 * dx,) * 3), box((3 * dx,) * 3, 900.0), position_m=(2.45 * dx, 4.1 * dx, 7.62 * dx),
                   velocity_m_s=(0.25 * v, 0.0, -0.5 * v), kinematic=True)
    model.add_body(Box((2 * dx,) * 3), box((2 * dx,) * 3, 900.0), position_m=(5.9 * dx, 4.0 * dx, 8.3 * dx))
    model.start()
    model.step(1)
    return model


@pytest.fixture(scope="module")
def simulated():
    """The tank on the CUDA target, built and stepped once (on the simulator a coupled step takes about 90 s on a
    2-core x86 VM: both tests share it)."""
    return _box_and_cube(jit.cuda())


@pytest.mark.xdist_group("simulated_tank")
def test_a_coupled_step_on_the_device_copies_nothing_between_host_and_device(simulated):
    model = simulated
    steps = 2      # the box moves a cell down in them: cells covered and uncovered (about 130 s a step here)
    owners = model.coupling.owners()
    with transfers.counting() as tally:
        model.step(steps)
    assert tally.total() <= PER_STEP * steps, str(tally)
    # read after the count: the box covered and uncovered cells, and the fluid pushes both bodies
    assert (model.coupling.owners() != owners).sum() > 4
    assert (np.abs(model.fluid_force_N).max(axis=1) > 0).all()


@pytest.mark.xdist_group("simulated_tank")
def test_the_count_sees_reads_uploads_and_host_arrays_handed_to_kernels(simulated):
    """The counter is not blind: a read of the loads, an upload and a host array launched all count, with where."""
    model = simulated
    cp = model.coupling
    with transfers.counting() as tally:
        cp.force_lattice
        jit.cuda().to_device(np.zeros(3))
        cp._s["near_events"](cp.forest.nblocks, np.zeros(cp.forest.nblocks, np.int32), cp._d["nbr"], cp._d["near"])
    # the host array launched is copied over and back: counted as implicit, and its copy back as a download
    assert tally.counts["implicit"] == 1 and tally.counts["upload"] == 1, str(tally)
    assert "download at coupler.py" in str(tally), str(tally)
    assert "upload at test_transfers.py" in str(tally) and "implicit at test_transfers.py" in str(tally)
