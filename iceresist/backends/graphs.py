"""A coupled step replayed as one CUDA graph (docs/PERFORMANCE.md, "Launches per coupled step").

A coupled tier-2 step is some forty small launches; through numba's dispatcher each costs the host tens of
microseconds (its arguments checked and packed), often more than the kernel itself. A CUDA graph holds the
launches of a step, their grids and arguments, and starts them all with one call.

:class:`StepReplay` runs a step's Python as it is, but within :func:`iceresist.backends.launch.recording`: each
launch is noted (kernel, grid, threads, arguments), not made. The step's *signature* is the list of its launches
with each device array named by its memory and shape and each scalar by its value. Then

* a signature met before with its graph: the graph is launched (one call);
* a signature met once before: its launches are captured into a graph (a cuda.core graph builder as the launch
  stream), which is then launched;
* a new signature: the noted launches are made one by one.

So a graph only ever replays launches equal, argument for argument, to those the step's own Python asked for: the
results are the same bit for bit, and a changed launch shape, a reallocated array (a regrid, ``load_state`` into
new arrays) or a new scalar (another sub-step length) is a new signature, never a stale graph. The buffers that
swap every step make two signatures, one graph per parity. A copy between host and device or a synchronisation
inside the step first makes the launches noted so far (the step is then not replayed as a graph).

On the CUDA simulator and the CPU there are no graphs: :class:`StepReplay` makes the noted launches one by one (the
same code path otherwise, so the simulator tests hold the signatures and the order). ``ICERESIST_CUDA_GRAPHS=0``
turns replay off (every launch made at once, as without it).
"""

from __future__ import annotations

import logging
import os
from collections import OrderedDict

from iceresist.backends import launch, transfers

log = logging.getLogger(__name__)

#: Graphs kept per replayed step (least recently used dropped): the two buffer parities and a few shapes.
CACHE = 8
#: Signatures met once that are remembered (then forgotten all at once).
SEEN = 64


def graphs_wanted() -> bool:
    """False where ``ICERESIST_CUDA_GRAPHS`` is set to 0, off or no."""
    return os.environ.get("ICERESIST_CUDA_GRAPHS", "1").strip().lower() not in ("0", "off", "no", "false")


def _arg_key(a):
    """What names a launch argument in a signature: a device array its memory, shape and strides; a scalar its
    type and value."""
    gpu = getattr(a, "gpu_data", None)
    if gpu is not None:     # the address itself: a view made anew each step is the same memory
        return (gpu.device_pointer_value, a.shape, a.strides)
    host = getattr(a, "_ary", None)          # the simulator's device array
    if host is not None:
        return (host.__array_interface__["data"][0], host.shape, host.strides)
    return (type(a), a)


class StepReplay:
    """Replays a step (a callable making CUDA launches) as a CUDA graph where it can (module docstring).
    ``enabled``: False makes every launch at once (no recording). Counters: ``hits`` (steps replayed by a graph),
    ``captures``, ``direct`` (steps launched one by one), ``repeats`` (steps whose signature was met before:
    replayed, or on the simulator launched one by one)."""

    def __init__(self, target, enabled: bool = True):
        self.target = target
        self.enabled = bool(enabled) and target.is_cuda and graphs_wanted()
        self.graphs_possible = self.enabled and not target.simulator
        self._seen: set = set()
        self._graphs: OrderedDict = OrderedDict()
        self.hits = self.captures = self.direct = self.repeats = 0
        self._stream = None

    def run(self, step):
        """Run ``step()`` once, its launches replayed as a graph where its signature has one."""
        if not self.enabled or launch._PROFILE is not None or launch._RECORDER is not None:
            step()      # off, or a benchmark timing each launch, or the GPU build check tracing
            return
        with launch.recording() as rec, transfers.counting(before=rec.flush):
            step()
        calls = rec.take()
        if rec.flushed or not calls:
            launch.make(calls)
            self.direct += 1
            return
        sig = tuple((id(k), g, t, tuple(_arg_key(a) for a in args)) for k, g, t, args in calls)
        entry = self._graphs.get(sig)
        if entry is None and sig in self._seen:
            self.repeats += 1
            entry = self._capture(calls) if self.graphs_possible else None
            if entry is not None:
                self._graphs[sig] = entry
                while len(self._graphs) > CACHE:
                    self._graphs.popitem(last=False)
        if entry is None:
            if len(self._seen) >= SEEN:     # signatures that never came back: forget them
                self._seen.clear()
            self._seen.add(sig)
            launch.make(calls)
            self.direct += 1
            return
        self._graphs.move_to_end(sig)
        try:
            entry[0].launch(self._default_stream())
        except Exception as exc:  # the driver refused the graph: launch kernel by kernel from now on
            log.warning("CUDA graphs off: launching a captured step failed (%s: %s)", type(exc).__name__, exc)
            self.graphs_possible = False
            self._graphs.clear()
            launch.make(calls)
            self.direct += 1
            return
        self.hits += 1

    def _default_stream(self):
        if self._stream is None:
            from cuda.core import Stream

            self._stream = Stream.from_handle(0)     # the legacy default stream, where reads and fills go
        return self._stream

    def _capture(self, calls):
        """(graph, calls) of the launches ``calls`` captured by a cuda.core graph builder; None (and replay off)
        where capture fails."""
        try:
            from cuda.core import Device

            dev = Device()
            dev.set_current()
            builder = dev.create_graph_builder()
            builder.begin_building()
            try:
                for kernel, grid, threads, args in calls:
                    kernel[grid, threads, builder](*args)
            finally:
                builder.end_building()
            graph = builder.complete()
        except Exception as exc:  # an older numba-cuda or driver: go on launching one by one
            log.warning("CUDA graphs off: capturing a coupled step failed (%s: %s); launching kernel by kernel",
                        type(exc).__name__, exc)
            self.graphs_possible = False
            return None
        self.captures += 1
        return graph, calls      # the calls keep the arrays (so their memory) of the graph alive
