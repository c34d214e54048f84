"""Launchers: one generator for every iteration shape of the engine's kernels (docs/ARCHITECTURE.md).

A scalar device function is written once; a launcher runs it over an iteration shape on either target:

* :class:`CellLauncher` ``cell(b, c, *args)`` for every cell of every forest block: CPU ``prange`` over blocks,
  the 512 cells of a block in order (x fastest) inside one thread (or one call of a per-block form of the same
  update, ``per_block=True``); CUDA one thread per cell, grid = nblocks, block = 512 threads (8x8x8 cells);
* :class:`ItemLauncher` ``item(i, *args)`` for i < n (forest blocks, bodies, spheres, array elements): CPU
  ``prange`` over items (on one thread below a size the kernel module chooses), CUDA one thread per item;
  :class:`BlockLauncher` is the same launcher over forest blocks;
* :class:`BodyLauncher` ``visit(k, gx, gy, gz, bint, *args)`` over the cells ``bint[k, 10:12]`` of the cell box
  ``bint[k, 3:9]`` of every launch row k (a body, or a run of its box's cells): CPU ``prange`` over rows, CUDA one
  thread block per row, its threads striding over the run;
* :class:`ActiveLauncher` ``visit(b, c, *args)`` for the cells of the forest blocks flagged ``active[b] != 0``.

Launchers are generated with named arguments (numba's CUDA kernels take no ``*args``) and live outside the
kernels, so the same device function serves both targets. On the CPU a launcher given a ``cache_key`` compiles
from the on-disk kernel cache (:mod:`iceresist.backends.cache`).

Every CUDA kernel of the engine is compiled by :func:`~iceresist.backends.conf.cuda_kernel` (which names it) and
launched by :func:`cuda_launch`: the one place a launch happens, so the GPU build check
(:mod:`iceresist.backends.buildcheck`) can record each kernel's argument types, launches of no items included,
instead of running it.

Every launcher has a ``label`` (``"f_update"``, ``"links"``, ``"dem_contact"``, ...), the same on both targets;
within :func:`profiling` each launch is timed under it (the coupled-step benchmark's parts).
"""

from __future__ import annotations

import contextlib
import time
from functools import lru_cache

import numpy as np

from iceresist.backends import cache
from iceresist.backends.conf import CUDA_BLOCK_CELLS, cpu_jit, cuda_api, cuda_kernel, get_threads, prange, set_threads
from iceresist.errors import InputError


def copy_into(dst, host):
    """Overwrite a target array (NumPy or CUDA device array) with the host array ``host`` of the same shape
    (a checkpoint being loaded); a shape that does not fit is refused with a message naming both."""
    host = np.ascontiguousarray(host)
    if tuple(dst.shape) != host.shape:
        raise InputError(f"checkpoint array of shape {host.shape} does not fit {tuple(dst.shape)}: "
                         f"it belongs to another scene")
    if hasattr(dst, "copy_to_device"):
        dst.copy_to_device(host)
    else:
        dst[...] = host


#: Set by the GPU build check: ``recorder(kernel, threads, args)`` is called instead of each CUDA launch.
_RECORDER = None


#: Set by :func:`iceresist.backends.transfers.counting`: ``watch(args)`` sees the arguments of each CUDA launch.
_ARG_WATCH = None


#: Set by :func:`tallying`: the :class:`LaunchTally` every CUDA launch and device synchronisation is counted in.
_TALLY = None


class LaunchTally:
    """``launches[kernel name]`` and ``syncs`` (device synchronisations) counted within :func:`tallying`."""

    def __init__(self):
        from collections import Counter

        self.launches: Counter = Counter()
        self.syncs = 0

    @property
    def total(self) -> int:
        return sum(self.launches.values())

    def __str__(self) -> str:
        return ", ".join(f"{n} x {name}" for name, n in self.launches.most_common()) + f"; {self.syncs} syncs"


@contextlib.contextmanager
def tallying():
    """Within: every CUDA launch (by the kernel's name, a launch of no blocks not counted) and every device
    synchronisation the engine asks for is counted into the yielded :class:`LaunchTally`: the launch budget of a
    coupled step (docs/PERFORMANCE.md), counted on the CUDA simulator or while the GPU build check traces."""
    global _TALLY
    saved, _TALLY = _TALLY, LaunchTally()
    try:
        yield _TALLY
    finally:
        _TALLY = saved


def note_sync():
    """Count a device synchronisation within :func:`tallying`; within :func:`recording` the launches noted so far
    are made first."""
    if _TALLY is not None:
        _TALLY.syncs += 1
    if _RECORDING is not None:
        _RECORDING.flush()


class Recording:
    """The launches noted within :func:`recording`: ``calls`` ``[(kernel, grid, threads, args)]`` in order;
    ``flushed`` once a copy or synchronisation made them early (:meth:`flush`)."""

    def __init__(self):
        self.calls: list = []
        self.flushed = False

    def flush(self, *_):
        """Make the launches noted so far (before a copy or a synchronisation that must see their results)."""
        make(self.take())
        self.flushed = True

    def take(self) -> list:
        calls, self.calls = self.calls, []
        return calls


#: Set by :func:`recording`: the :class:`Recording` CUDA launches are noted in instead of being made.
_RECORDING = None


@contextlib.contextmanager
def recording():
    """Within: every CUDA launch is noted in the yielded :class:`Recording`, not made (a step to be replayed as a
    CUDA graph, :mod:`iceresist.backends.graphs`); the caller makes them (:func:`make`) or replays them."""
    global _RECORDING
    saved, _RECORDING = _RECORDING, Recording()
    try:
        yield _RECORDING
    finally:
        _RECORDING = saved


def make(calls):
    """Make the noted launches ``calls`` one by one, in order."""
    for kernel, grid, threads, args in calls:
        kernel[grid, threads](*args)


def cuda_launch(kernel, grid: int, threads: int, *args):
    """Launch ``kernel[grid, threads](*args)``; a grid of no blocks launches nothing."""
    if _ARG_WATCH is not None:
        _ARG_WATCH(args)
    if _TALLY is not None and grid:
        _TALLY.launches[getattr(kernel, "kernel_name", device_name(kernel))] += 1
    if _RECORDER is not None:
        _RECORDER(kernel, threads, args)
    elif grid:
        if _RECORDING is not None:
            _RECORDING.calls.append((kernel, grid, threads, args))
        else:
            kernel[grid, threads](*args)


#: Set by :func:`profiling`: ``{label: [seconds, launches]}``, and the device synchronisation after each launch.
_PROFILE = None
_SYNC = None


@contextlib.contextmanager
def profiling(target):
    """Within: every launch made through a launcher (:func:`profiled`) is timed, wall clock, into the yielded
    ``{label: [seconds, launches]}``; on CUDA the device is synchronised after each launch so that the time is the
    kernel's own. Meant for benchmarks: the synchronisation serialises the device."""
    global _PROFILE, _SYNC
    saved = (_PROFILE, _SYNC)
    _PROFILE, _SYNC = {}, (target.synchronize if target.is_cuda else None)
    try:
        yield _PROFILE
    finally:
        _PROFILE, _SYNC = saved


def profiled(label: str, call):
    """``call`` (a launch function) timed under ``label`` within :func:`profiling`; the same call otherwise."""
    def launch(*args):
        if _PROFILE is None:
            return call(*args)
        t0 = time.perf_counter()
        out = call(*args)
        if _SYNC is not None:
            _SYNC()
        entry = _PROFILE.setdefault(label, [0.0, 0])
        entry[0] += time.perf_counter() - t0
        entry[1] += 1
        return out

    launch.label = label
    launch.__name__ = label
    return launch


def device_name(fn) -> str:
    """The Python name of a device function (a numba dispatcher or a plain function)."""
    return getattr(getattr(fn, "py_func", fn), "__name__", "kernel")



def jit_generated(target, src: str, name: str, namespace: dict, label: str | None = None,
                  threads: int = CUDA_BLOCK_CELLS):
    """Compile the generated launcher ``name`` defined by ``src`` (the names it calls in ``namespace``): a CUDA
    kernel named ``label`` (default ``name``) for blocks of at most ``threads`` threads, or a parallel njit with
    the project's fast-math flags on the CPU."""
    if target.is_cuda:
        ns = {"cuda": cuda_api(), **namespace}
        exec(compile(src, f"<iceresist {name} cuda>", "exec"), ns)
        return cuda_kernel(ns[name], label or name, threads)
    return compile_cpu(name, src, namespace, [(name, True)])


def compile_cpu(label: str, src: str, namespace: dict, functions, cache_key: str | None = None):
    """Compile the functions ``functions`` (``(name, parallel)`` in order) of the generated CPU source ``src``
    calling the names in ``namespace``; each is bound as ``{name}_jit`` where a later one may call it. With a
    ``cache_key`` (:func:`iceresist.backends.cache.fingerprint`) from the on-disk kernel cache under ``label``
    where the cache is on, else in memory. Returns the last one."""
    if cache_key is not None:
        kern = cache.cpu_launcher(label, src, namespace, functions, cache_key)
        if kern is not None:
            return kern
    ns = {"prange": prange, **namespace}
    exec(compile(src, f"<iceresist {label} cpu>", "exec"), ns)
    kern = None
    for fn_name, parallel in functions:
        kern = cpu_jit(ns[fn_name], parallel=parallel)
        ns[f"{fn_name}_jit"] = kern
    return kern


def _on_one_thread(kernel, *args):
    """``kernel(*args)`` with numba's parallel loops on one thread for the call (no wait for the workers)."""
    threads = get_threads()
    if threads == 1:
        kernel(*args)
        return
    set_threads(1)
    try:
        kernel(*args)
    finally:
        set_threads(threads)


class _GeneratedLauncher:
    """A launcher generated around one device function ``fn``: subclasses give ``name``, the name of the generated
    launcher, ``fn_name``, the name ``fn`` has in the generated source, the source (:meth:`_source`), the CPU
    functions of that source to compile (:attr:`cpu_functions`) and the CUDA launch shape (:meth:`_cuda_launch`).

    ``cache_key``: compile the CPU launcher from the on-disk kernel cache (:func:`compile_cpu`). ``parallel``:
    ``parallel(n)`` says whether a CPU launch over ``n`` runs on all threads (else on one, no wait for the
    workers); None: always on all. ``kernel`` is the compiled launcher (on the CPU, its cache statistics)."""

    name = ""
    fn_name = ""
    threads = CUDA_BLOCK_CELLS
    cpu_functions: tuple = ()

    def __init__(self, target, fn, argnames, label: str | None = None, cache_key: str | None = None,
                 parallel=None, **options):
        self.target = target
        self.argnames = tuple(argnames)
        self.label = label or device_name(fn)
        self.parallel = parallel
        self.source = self._source(target.is_cuda, self.argnames, **options)
        if target.is_cuda:
            self._kernel = jit_generated(target, self.source, self.name, {self.fn_name: fn}, label=self.label,
                                         threads=self.threads)
        else:
            self._kernel = compile_cpu(self.label, self.source, {self.fn_name: fn},
                                       self.cpu_functions or ((self.name, True),), cache_key)
        self.kernel = self._kernel
        self._call = profiled(self.label, self._launch)

    def __call__(self, n, *args):
        self._call(n, *args)

    def _launch(self, n, *args):
        if self.target.is_cuda:
            grid, threads, lead = self._cuda_launch(n)
            cuda_launch(self._kernel, grid, threads, *lead, *args)
        elif n:
            if self.parallel is None or self.parallel(n):
                self._kernel(n, *args)
            else:
                _on_one_thread(self._kernel, n, *args)


class CellLauncher(_GeneratedLauncher):
    """Callable ``launcher(nblocks, *args)`` running ``cell(b, c, *args)`` for every cell of every block;
    with ``per_block=True`` (CPU only) ``cell(b, *args)`` updates a whole block."""

    name, fn_name = "launch_cells", "cell"

    def __init__(self, target, cell, argnames, per_block: bool = False, label: str | None = None, **options):
        super().__init__(target, cell, argnames, label=label, per_block=per_block, **options)

    @staticmethod
    def _source(cuda: bool, argnames, per_block: bool) -> str:
        sig = ", ".join(argnames)
        if cuda:
            return (f"def launch_cells({sig}):\n    b = cuda.blockIdx.x\n    c = cuda.threadIdx.x\n"
                    f"    cell(b, c, {sig})\n")
        inner = (f"        cell(b, {sig})\n" if per_block else
                 f"        for c in range({CUDA_BLOCK_CELLS}):\n            cell(b, c, {sig})\n")
        return f"def launch_cells(nblocks, {sig}):\n    for b in prange(nblocks):\n" + inner

    @staticmethod
    def _cuda_launch(n):
        return n, CUDA_BLOCK_CELLS, ()


#: Threads per CUDA block for one-thread-per-item launches (:class:`ItemLauncher`).
CUDA_BLOCK_THREADS = 128


class ItemLauncher(_GeneratedLauncher):
    """Callable ``launcher(n, *args)`` running ``item(i, *args)`` once per item i < n: forest blocks (a reduction
    over the block's cells into ``out[b, ...]``, diagnostics read on the host from a small array, not a copy of
    the fields), bodies, spheres, elements of an array.

    * CPU: ``prange`` over items (on one thread where ``parallel(n)`` says so);
    * CUDA: one thread per item, :data:`CUDA_BLOCK_THREADS` threads per CUDA block.
    """

    name, fn_name = "launch_items", "item"
    threads = CUDA_BLOCK_THREADS

    @staticmethod
    def _source(cuda: bool, argnames) -> str:
        sig = ", ".join(argnames)
        if cuda:
            return f"def launch_items(n, {sig}):\n    i = cuda.grid(1)\n    if i < n:\n        item(i, {sig})\n"
        return f"def launch_items(n, {sig}):\n    for i in prange(n):\n        item(i, {sig})\n"

    @staticmethod
    def _cuda_launch(n):
        return (n + CUDA_BLOCK_THREADS - 1) // CUDA_BLOCK_THREADS, CUDA_BLOCK_THREADS, (np.int64(n),)


#: A launcher over the blocks of a forest is a launcher over items.
BlockLauncher = ItemLauncher

#: Threads per CUDA block of a per-body launch (:class:`BodyLauncher`): they stride over the body's cell box.
BODY_THREADS = 128


class BodyLauncher(_GeneratedLauncher):
    """``launcher(nrows, bint, *rest)`` runs ``visit(k, gx, gy, gz, bint, *rest)`` over the cells of each launch
    row k: the cells ``bint[k, 10] <= i < bint[k, 11]`` of its cell box ``bint[k, 3:9]`` (inclusive), counted x
    fastest (i = x + nx (y + ny z) from the box's low corner). On the CPU a prange over rows, each calling the
    per-row loop (compiled once, serial, the visit inlined into it); on CUDA one thread block per row, threads
    striding over its cells."""

    name, fn_name = "launch_bodies", "visit"
    threads = BODY_THREADS
    cpu_functions = (("body_loop", False), ("launch_bodies", True))

    def __init__(self, target, visit, argnames, per_row: bool = False, label: str | None = None, **options):
        """``per_row=True`` (CPU only): ``visit(k, *args)`` walks the run of row k itself."""
        if per_row and target.is_cuda:
            raise ValueError("a per-row visit is a CPU form; CUDA visits one cell per thread")
        super().__init__(target, visit, argnames, label=label, per_row=per_row, **options)

    @staticmethod
    def _source(cuda: bool, argnames, per_row: bool = False) -> str:
        sig = ", ".join(argnames)
        if per_row:
            return (f"def body_loop(k, {sig}):\n    visit(k, {sig})\n\n\ndef launch_bodies(nbodies, {sig}):\n"
                    f"    for k in prange(nbodies):\n        body_loop_jit(k, {sig})\n")
        if cuda:
            return (f"def launch_bodies({sig}):\n"
                    "    k = cuda.blockIdx.x\n"
                    "    lx = bint[k, 3]\n    ly = bint[k, 4]\n    lz = bint[k, 5]\n"
                    "    nx = bint[k, 6] - lx + 1\n    ny = bint[k, 7] - ly + 1\n"
                    "    for i in range(bint[k, 10] + cuda.threadIdx.x, bint[k, 11], cuda.blockDim.x):\n"
                    "        gx = lx + i % nx\n        gy = ly + (i // nx) % ny\n        gz = lz + i // (nx * ny)\n"
                    f"        visit(k, gx, gy, gz, {sig})\n")
        loop = (f"def body_loop(k, {sig}):\n"
                "    lx = bint[k, 3]\n    ly = bint[k, 4]\n    hx = bint[k, 6]\n    hy = bint[k, 7]\n"
                "    nx = hx - lx + 1\n    ny = hy - ly + 1\n    s = bint[k, 10]\n    e = bint[k, 11]\n"
                "    if e <= s:\n        return\n"
                "    gx = lx + s % nx\n    gy = ly + (s // nx) % ny\n    gz = bint[k, 5] + s // (nx * ny)\n"
                "    for _ in range(e - s):\n"
                f"        visit(k, gx, gy, gz, {sig})\n"
                "        gx += 1\n"
                "        if gx > hx:\n"
                "            gx = lx\n            gy += 1\n"
                "            if gy > hy:\n                gy = ly\n                gz += 1\n")
        return (f"{loop}\n\ndef launch_bodies(nbodies, {sig}):\n"
                "    for k in prange(nbodies):\n"
                f"        body_loop_jit(k, {sig})\n")

    @staticmethod
    def _cuda_launch(n):
        return n, BODY_THREADS, ()


class ActiveLauncher(_GeneratedLauncher):
    """``launcher(nblocks, active, *rest)`` runs ``visit(b, c, *rest)`` for the 512 cells of each block b with
    ``active[b] != 0`` (a flag per forest block, set on the target): on the CPU a prange over the list of those
    blocks (a host-side scan of the flags, which live in host memory there), each calling the per-block loop
    (compiled once, serial); on CUDA one thread per cell of every block, the blocks without the flag returning at
    once (the flags never leave the device)."""

    name, fn_name = "launch_active", "visit"
    cpu_functions = (("block_loop", False), ("launch_active", True))

    def __init__(self, target, visit, argnames, per_block: bool = False, label: str | None = None, **options):
        """``per_block=True`` (CPU only): ``visit(b, *rest)`` updates the whole block b."""
        if per_block and target.is_cuda:
            raise ValueError("a per-block visit is a CPU form; CUDA visits one cell per thread")
        super().__init__(target, visit, argnames, label=label, per_block=per_block, **options)

    @staticmethod
    def _source(cuda: bool, argnames, per_block: bool = False) -> str:
        if argnames[0] != "active":
            raise ValueError(f"an active-block launcher takes 'active' first, not {argnames[0]!r}")
        rest = ", ".join(argnames[1:])
        sig = ", ".join(argnames)
        if cuda:
            return (f"def launch_active({sig}):\n"
                    "    b = cuda.blockIdx.x\n"
                    "    if active[b] != 0:\n"
                    f"        visit(b, cuda.threadIdx.x, {rest})\n")
        loop = (f"def block_loop(b, {rest}):\n" + (f"    visit(b, {rest})\n" if per_block else
                f"    for c in range({CUDA_BLOCK_CELLS}):\n"
                f"        visit(b, c, {rest})\n"))
        return (f"{loop}\n\ndef launch_active(nactive, {sig}):\n"
                "    for i in prange(nactive):\n"
                f"        block_loop_jit(active[i], {rest})\n")

    def __call__(self, nblocks, active, *args):
        self._call(nblocks, active, *args)

    def _launch(self, nblocks, active, *args):
        if self.target.is_cuda:
            cuda_launch(self._kernel, nblocks, CUDA_BLOCK_CELLS, active, *args)
            return
        blocks = np.flatnonzero(active).astype(np.int32)
        if len(blocks):
            self._kernel(len(blocks), blocks, *args)


def _fill_item(i, a, value):
    a[i] = value


@lru_cache(maxsize=None)
def _filler(target):
    return ItemLauncher(target, target.device(_fill_item), ("a", "value"), label="fill")


def fill(target, a, value):
    """Set every element of the contiguous target array ``a`` to ``value`` with a kernel over its elements (a
    reset inside a step that uploads nothing: :meth:`iceresist.backends.jit.Target.fill`)."""
    flat = a.reshape(a.size)
    _filler(target)(int(a.size), flat, a.dtype.type(value))


def _fill4_item(i, a, va, b, vb, c, vc, d, vd):
    if i < a.size:
        a[i] = va
    if i < b.size:
        b[i] = vb
    if i < c.size:
        c[i] = vc
    if i < d.size:
        d[i] = vd


@lru_cache(maxsize=None)
def _filler4(target):
    return ItemLauncher(target, target.device(_fill4_item), ("a", "va", "b", "vb", "c", "vc", "d", "vd"),
                        label="fill")


def fill4(target, a, va, b, vb, c, vc, d, vd):
    """:func:`fill` of four contiguous target arrays (any sizes and types) in one launch."""
    arrays = (a, b, c, d)
    flat = [x.reshape(x.size) for x in arrays]
    _filler4(target)(max(int(x.size) for x in arrays), flat[0], a.dtype.type(va), flat[1], b.dtype.type(vb),
                     flat[2], c.dtype.type(vc), flat[3], d.dtype.type(vd))


@lru_cache(maxsize=None)
def build_block_sum6(real, threads: int):
    """CUDA device function ``block_sum6(t, a0, ..., a5)``: the six sums of the values of the ``threads`` threads of
    a thread block (``t`` its thread index; ``threads`` a power of two), returned to every thread: a tree in shared
    memory, always added in the same order (the same sums on every run, unlike atomics). Every thread of the block
    must call it."""
    if threads & (threads - 1):
        raise ValueError(f"block_sum6 needs a power of two threads, not {threads}")
    ns = {"cuda": cuda_api(), "real": real, "T": int(threads)}   # cuda: a global, for the simulator
    exec("def block_sum6(t, a0, a1, a2, a3, a4, a5):\n"
         "    sh = cuda.shared.array((6, T), real)\n"
         "    sh[0, t] = a0\n    sh[1, t] = a1\n    sh[2, t] = a2\n"
         "    sh[3, t] = a3\n    sh[4, t] = a4\n    sh[5, t] = a5\n"
         "    cuda.syncthreads()\n"
         "    d = T // 2\n"
         "    while d > 0:\n"
         "        if t < d:\n"
         "            for a in range(6):\n"
         "                sh[a, t] += sh[a, t + d]\n"
         "        cuda.syncthreads()\n"
         "        d //= 2\n"
         "    out = (sh[0, 0], sh[1, 0], sh[2, 0], sh[3, 0], sh[4, 0], sh[5, 0])\n"
         "    cuda.syncthreads()\n"
         "    return out\n", ns)
    return cuda_api().jit(ns["block_sum6"], device=True)


def build_accumulate(target):
    """``accumulate(a, i, j, v)``: a[i, j] += v; atomic on CUDA (where threads share the row)."""
    if target.is_cuda:
        # ``cuda`` must be a global of the function (not a closure cell) so that the simulator can swap it
        ns = {"cuda": cuda_api()}
        exec("def accumulate(a, i, j, v):\n    cuda.atomic.add(a, (i, j), v)\n", ns)
        return target.device(ns["accumulate"])

    def accumulate(a, i, j, v):
        a[i, j] += v

    return target.device(accumulate)
