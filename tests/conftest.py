"""Test configuration: CUDA simulator unless a real GPU run is asked for, and the ``target`` fixture.

NUMBA_ENABLE_CUDASIM must be set before numba is first imported. ``make test``
sets it to 1; on a machine with a GPU run ``NUMBA_ENABLE_CUDASIM=0 pytest`` and
the same tests run on the device.
"""

import os

os.environ.setdefault("NUMBA_ENABLE_CUDASIM", "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from iceresist.backends import jit  # noqa: E402

SIMULATED = os.environ["NUMBA_ENABLE_CUDASIM"] == "1"


@pytest.fixture
def cuda_target():
    """The CUDA target: a GPU, or the simulator (``make test``); a test that needs it is skipped where neither is
    there (``NUMBA_ENABLE_CUDASIM=0`` on a machine without a GPU)."""
    if not jit.cuda_available():
        pytest.skip("no CUDA GPU and the simulator is off")
    return jit.cuda()


@pytest.fixture(params=["cpu", "cuda"])
def target(request):
    """Every kernel test runs on the CPU and on CUDA (the simulator where no GPU is lent)."""
    if request.param == "cpu":
        return jit.cpu
    return request.getfixturevalue("cuda_target")


@pytest.fixture(params=["float32", "float64"])
def precision(request):
    return request.param


@pytest.fixture
def rng():
    return np.random.default_rng(20230809)
