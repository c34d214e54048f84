"""What a first run is doing while its kernels compile: one line per kernel, named, counted, timed.

numba compiles a kernel the first time it is called and tells listeners of its ``numba:compile`` event (numba-cuda
has its own event of that name); a kernel loaded from the on-disk cache (:mod:`iceresist.backends.cache`) is not
compiled and says nothing. :func:`install` listens to both: each kernel compiled at the top level (not a device
function compiled inside another) is logged by name with its count against the kernels made so far
(:data:`iceresist.backends.conf.KERNELS`: compiled, or made and without code yet), so a user sees a compile, not a
hang. :func:`compiled_since` gives the kernels and seconds of compiling since a time, which a run's closing line
names.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from pathlib import Path

from iceresist.backends.cache import cache_dir
from iceresist.backends.conf import KERNELS

log = logging.getLogger(__name__)
log.setLevel(logging.INFO)     # shown even where a command quiets the engine's own lines (``iceresist demo``)

_STATE = threading.local()
#: (start on the perf_counter clock, seconds) of every top-level compile in this process.
_COMPILES: list[tuple[float, float]] = []
_INSTALLED = False


def _has_code(d) -> bool:
    return bool(getattr(d, "overloads", None))


def kernel_label(dispatcher) -> str:
    """A kernel's name for people: the launcher's label where the kernel cache named its module
    (``iceresist_kernel_<label>_<digest>``), else the kernel's own name."""
    fn = getattr(dispatcher, "py_func", dispatcher)
    module = getattr(fn, "__module__", "") or ""
    if module.startswith("iceresist_kernel_"):
        return module[len("iceresist_kernel_"):].rsplit("_", 1)[0]
    return getattr(dispatcher, "kernel_name", None) or getattr(fn, "__name__", "kernel")


def cache_folder_text() -> str:
    """Where compiled kernels are kept, for messages (~ for the home folder)."""
    folder = cache_dir()
    if folder is None:
        return "nowhere (ICERESIST_CACHE=off: every run compiles)"
    home = str(Path.home())
    text = str(folder)
    return "~" + text[len(home):] if text.startswith(home + os.sep) else text


class _Listener:
    """Logs each top-level compile as it starts and adds its wall time when it ends."""

    def on_start(self, event):
        depth = getattr(_STATE, "depth", 0)
        _STATE.depth = depth + 1
        if depth:
            return
        _STATE.t0 = time.perf_counter()
        done = len(_COMPILES)
        if done == 0:
            log.info("compiling the kernels this run needs, on a first run only: they are kept in %s and later "
                     "runs load them in seconds (on 2 CPU cores: seconds for tier 1, about 2 min for a "
                     "free-surface scene)", cache_folder_text())
        d = event.data.get("dispatcher")
        todo = sum(1 for k in list(KERNELS) if not _has_code(k) and k is not d)
        log.info("compiling kernel %d of the %d made so far: %s (%.0f s of compiling so far)", done + 1,
                 done + 1 + todo, kernel_label(d), sum(sec for _, sec in _COMPILES))

    def on_end(self, event):
        _STATE.depth = max(getattr(_STATE, "depth", 1) - 1, 0)
        if _STATE.depth == 0:
            t0 = getattr(_STATE, "t0", time.perf_counter())
            _COMPILES.append((t0, time.perf_counter() - t0))


def _listener_class(base):
    """:class:`_Listener` as a subclass of numba's (or numba-cuda's) ``Listener``: its methods come first."""
    return type("CompileProgress", (_Listener, base), {})


def install() -> None:
    """Listen to numba's (and numba-cuda's) compile events for the rest of the process; once."""
    global _INSTALLED
    if _INSTALLED:
        return
    _INSTALLED = True
    from numba.core import event

    event.register("numba:compile", _listener_class(event.Listener)())
    try:
        from numba.cuda.core import event as cuda_event
    except ImportError:  # pragma: no cover - a numba-cuda without its own events
        return
    if cuda_event is not event:
        for kind in ("numba-cuda:compile", "numba:compile"):     # the name differs between numba-cuda releases
            try:
                cuda_event.register(kind, _listener_class(cuda_event.Listener)())
                break
            except ValueError:
                continue


def compiled_since(t0: float) -> tuple[int, float]:
    """(kernels, seconds) compiled at the top level since ``t0`` (``time.perf_counter()``): a run's own, not those
    of an earlier run in the same process (the cases of a sweep)."""
    own = [s for start, s in _COMPILES if start >= t0]
    return len(own), float(sum(own))
