"""A step replayed from its noted launches (:mod:`iceresist.backends.graphs`): on the CUDA simulator the same code
path as on a GPU but the last one (the graph itself), so these tests hold the signatures, the order, the flush
before a read and the results bit for bit; on a GPU the graphs themselves (``-m gpu``)."""

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.backends.graphs import StepReplay
from iceresist.backends.launch import ItemLauncher, tallying


def _axpy(target):
    def axpy(i, a, x, y):
        y[i] = a * x[i] + y[i] * 0.5

    return ItemLauncher(target, target.device(axpy), ("a", "x", "y"), label="axpy")


class Toy:
    """Two buffers that swap every step and a scalar that changes once: two signatures, then a third."""

    def __init__(self, target, n=40):
        self.target, self.n = target, n
        self.a = target.to_device(np.linspace(0.0, 1.0, n))
        self.b = target.to_device(np.zeros(n))
        self.launch = _axpy(target)
        self.coeff = 0.25
        self.reads = []

    def step(self, read: bool = False):
        self.launch(self.n, np.float64(self.coeff), self.a, self.b)
        if read:            # a read inside a step: what was launched before it must have run
            self.reads.append(self.target.to_host(self.b).copy())
        self.launch(self.n, np.float64(1.0), self.b, self.a)
        self.a, self.b = self.b, self.a


def _run(enabled: bool):
    target = jit.cuda()
    toy, replay = Toy(target), StepReplay(target, enabled=enabled)
    for k in range(9):
        if k == 6:
            toy.coeff = 0.5
        replay.run(lambda: toy.step(read=(k == 4)))
    return target.to_host(toy.a), target.to_host(toy.b), toy.reads, replay


def test_a_replayed_step_gives_the_launched_one_bit_for_bit_and_its_signatures_repeat():
    a0, b0, reads0, off = _run(False)
    a1, b1, reads1, on = _run(True)
    assert np.array_equal(a0, a1) and np.array_equal(b0, b1)
    assert len(reads1) == 1 and np.array_equal(reads0[0], reads1[0])   # the read saw the launch before it
    assert off.repeats == off.direct == 0                               # off: launched at once
    # steps 0, 1 new (parities); 2, 3 repeat; 4 reads (launched one by one); 5 repeats; 6, 7 new (coeff); 8 repeats
    assert on.repeats == 4
    assert on.direct + on.hits == 9 and on.hits == (on.repeats if on.graphs_possible else 0)


def test_a_step_is_counted_in_the_launch_tally_once():
    target = jit.cuda()
    toy, replay = Toy(target), StepReplay(target)
    for _ in range(3):
        with tallying() as tally:
            replay.run(toy.step)
        assert tally.total == 2


def test_graphs_can_be_turned_off_by_the_environment(monkeypatch):
    monkeypatch.setenv("ICERESIST_CUDA_GRAPHS", "0")
    assert not StepReplay(jit.cuda()).enabled
    monkeypatch.setenv("ICERESIST_CUDA_GRAPHS", "1")
    assert StepReplay(jit.cuda()).enabled
    assert not StepReplay(jit.cpu).enabled


def _real_gpu() -> bool:
    from numba import config, cuda

    return not config.ENABLE_CUDASIM and cuda.is_available()


@pytest.mark.gpu
@pytest.mark.skipif(not _real_gpu(), reason="needs a CUDA GPU (graphs do not exist on the simulator)")
def test_a_coupled_tier2_step_replays_as_a_graph_and_gives_the_same_records(tmp_path):
    """On a GPU: the CI-sized tier-2 case, three records with graphs and three without, the same records bit for
    bit, and the steps after the first few replayed by their graphs."""
    from iceresist.models import build_model
    from iceresist.validate.gpu_build import check_scenes

    out = {}
    for enabled in (False, True):
        model = build_model(check_scenes()["tier2-float32"], backend="cuda")
        model.replay.enabled = enabled and model.replay.enabled
        rows = []
        for _ in range(3):
            model.step(1)
            rows.append(model.diagnostics())
        out[enabled] = (rows, model.replay)
    assert out[False][0] == out[True][0]
    replay, steps = out[True][1], 3 * model.lbm_steps_per_record
    assert replay.captures >= 1 and replay.hits >= steps - 4, vars(replay)
