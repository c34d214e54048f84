"""The CUDA launcher of the fused kernel matches its CPU twin to round-off (CUDA simulator without a GPU).

2x2x2 blocks (16^3 cells), periodic x, walls in y (one moving), inlet/outlet in z and a solid bar:
every path of the kernel (interior, block faces, links to walls, solids, inlet and outlet) is used.
"""

import numpy as np
import pytest

from iceresist.backends import jit
from tests.conftest import SIMULATED
from tests.test_stream import mixed_case

STEPS = 2 if SIMULATED else 20
TOL = {"float32": 1e-6, "float64": 1e-13}


@pytest.mark.parametrize("operator", ["bgk"])
def test_cuda_matches_cpu(precision, operator):
    if not jit.cuda_available():
        pytest.skip("no CUDA GPU and the simulator is off")
    _, cpu = mixed_case(precision, jit.cpu, np.random.default_rng(7), operator)
    _, gpu = mixed_case(precision, jit.cuda(), np.random.default_rng(7), operator)
    cpu.step(STEPS)
    gpu.step(STEPS)
    a, b = cpu.populations(), gpu.populations()
    assert np.abs(a - b).max() < TOL[precision]
    assert abs(cpu.mass() - gpu.mass()) < TOL[precision] * cpu.cells
    assert np.abs(a).max() > 1e-3        # the state moved away from rest
