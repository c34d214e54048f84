"""Counting the copies between host and device (what a step on a GPU should avoid).

Within :func:`counting`, every copy between host memory and a CUDA device array is counted, wherever in the engine
it is made, by watching numba-cuda itself (the real driver, the CUDA simulator, or the host stand-ins of the GPU
build check, :class:`~iceresist.backends.jit.HostStandIn`):

* ``upload``: a host array copied to the device (``cuda.to_device``, ``DeviceNDArray.copy_to_device`` of a host
  array; a device-to-device copy is not counted);
* ``download``: a device array copied to the host (``copy_to_host``), with its bytes (``nbytes``, ``largest``);
* ``implicit``: a host array handed to a kernel launch, which numba-cuda copies to the device and back.

Each entry also keeps where it was made (file:line of the first engine frame), so a test that fails names the
copy to remove.
"""

from __future__ import annotations

import contextlib
import os
import traceback
from collections import Counter

from iceresist.backends import jit, launch


def _site() -> str:
    """file:line of the innermost frame outside this package's backends and outside installed packages."""
    backends = os.path.dirname(os.path.abspath(__file__))
    for frame in reversed(traceback.extract_stack()[:-2]):
        path = os.path.abspath(frame.filename)
        if not path.startswith(backends) and "site-packages" not in path and not path.startswith("<"):
            return f"{os.path.basename(path)}:{frame.lineno}"
    return "?"


class TransferCount:
    """``counts[kind]`` and ``sites[(kind, file:line)]`` of the copies made within :func:`counting`."""

    def __init__(self):
        self.counts: Counter = Counter()
        self.sites: Counter = Counter()
        self.nbytes: Counter = Counter()
        self.largest: Counter = Counter()

    def add(self, kind: str, nbytes: int = 0):
        self.counts[kind] += 1
        self.sites[(kind, _site())] += 1
        self.nbytes[kind] += int(nbytes)
        self.largest[kind] = max(self.largest[kind], int(nbytes))

    def total(self) -> int:
        return sum(self.counts.values())

    def __str__(self) -> str:
        lines = [f"{n} x {kind} at {where}" for (kind, where), n in self.sites.most_common()]
        return "; ".join(lines) or "no transfers"


_INHERITED = object()


def _device_array_classes() -> list:
    from numba import config

    if jit._HOST_STAND_IN:
        return [jit.HostStandIn]
    if config.ENABLE_CUDASIM:
        from numba.cuda.simulator.cudadrv.devicearray import FakeCUDAArray

        return [FakeCUDAArray]
    from numba.cuda.cudadrv.devicearray import DeviceNDArray

    return [DeviceNDArray]


@contextlib.contextmanager
def counting(before=None):
    """Within: every copy between host and device is counted into the yielded :class:`TransferCount`; ``before``
    (where given) is called with the kind before each copy, a device-to-device one (``"copy"``) included."""
    from numba import cuda

    tally = TransferCount()
    saved = []
    nested = [0]  # > 0 inside ``cuda.to_device``, whose own ``copy_to_device`` must not count a second time

    def patch(owner, name, wrapper):
        saved.append((owner, name, vars(owner).get(name, _INHERITED)))
        setattr(owner, name, wrapper)

    for cls in _device_array_classes():
        to_host, to_device = cls.copy_to_host, cls.copy_to_device

        def copy_to_host(self, *a, _f=to_host, **k):
            tally.add("download", getattr(self, "nbytes", 0))
            if before is not None:
                before("download")
            return _f(self, *a, **k)

        def copy_to_device(self, ary, *a, _f=to_device, **k):
            host = jit.is_host_array(ary)
            if host and not nested[0]:
                tally.add("upload")
            if before is not None:
                before("upload" if host else "copy")
            return _f(self, ary, *a, **k)

        patch(cls, "copy_to_host", copy_to_host)
        patch(cls, "copy_to_device", copy_to_device)

    if jit._HOST_STAND_IN:
        stand_in = jit.Target.to_device

        def to_device_stand_in(self, a, _f=stand_in):
            if self.is_cuda:
                tally.add("upload")
            return _f(self, a)

        patch(jit.Target, "to_device", to_device_stand_in)
    else:
        upload = cuda.to_device

        def to_device(a, *args, _f=upload, **k):
            if jit.is_host_array(a):
                tally.add("upload")
                if before is not None:
                    before("upload")
            nested[0] += 1
            try:
                return _f(a, *args, **k)
            finally:
                nested[0] -= 1

        patch(cuda, "to_device", to_device)

    def watch(args):
        for a in args:
            if jit.is_host_array(a):
                tally.add("implicit")
                if before is not None:
                    before("implicit")

    saved_watch = launch._ARG_WATCH
    launch._ARG_WATCH = watch
    try:
        yield tally
    finally:
        launch._ARG_WATCH = saved_watch
        for owner, name, value in reversed(saved):
            if value is _INHERITED:
                delattr(owner, name)
            else:
                setattr(owner, name, value)
