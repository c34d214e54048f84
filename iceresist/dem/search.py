"""Contact search on a uniform cell grid stored as a hash table (Teschner et al. 2003; Green 2010).

Cells are cubes of side h >= the largest sphere diameter, so touching spheres lie in the same or in one of the
26 neighbouring cells. Cell (i, j, k) goes to bucket ((i p1) xor (j p2) xor (k p3)) & mask of a power-of-two
table of about two buckets per sphere, so the domain is unbounded and memory is O(spheres). A counting sort by
bucket (counts, exclusive prefix sum, scatter) gives ``start`` and ``count`` per bucket and the sorted sphere
indices. Since two cells can share a bucket, the contact kernel checks each candidate's own cell.

CPU: one serial pass (O(spheres + buckets), small beside the contact kernel). CUDA: the spheres are counted into
``tally`` by the pass that finds their buckets (``place``, :func:`build_tally`), then two launches
(docs/PERFORMANCE.md, the launch budget): the exclusive scan in one thread block (each thread sums a run of buckets,
the block scans the run sums in shared memory, each thread writes its run's starts and counts and zeroes its tallies
and cursors, so ``tally`` is zero again for the next sort without a launch of its own), and an atomic scatter (the
order inside a bucket is then not fixed).
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.backends import cache
from iceresist.backends.jit import Target, cuda_api
from iceresist.backends.launch import cuda_launch

cuda = cuda_api()  # cuda.grid / cuda.atomic inside the kernels below (a module global, for the simulator)

P1, P2, P3 = 73856093, 19349663, 83492791
THREADS = 128
#: Threads of the one thread block that scans the bucket counts (a power of two).
SCAN_THREADS = 512


def table_size(n_spheres: int) -> int:
    """Power of two >= 2 n_spheres (at least 64)."""
    return max(64, 1 << int(math.ceil(math.log2(max(2 * n_spheres, 2)))))


def build_cell_hash(target: Target):
    """``cell_hash(cx, cy, cz, mask)``: the bucket of integer cell (cx, cy, cz) (int64 arguments)."""
    @target.device
    def cell_hash(cx, cy, cz, mask):
        return ((cx * P1) ^ (cy * P2) ^ (cz * P3)) & mask

    return cell_hash


def build_cell_index(target: Target):
    """``cell_index(x, inv_cell)``: the int64 index of the grid cell holding coordinate ``x`` (floor of
    ``x * inv_cell``). ``math.floor`` of a float is an integer on the CPU but a float under numba-cuda, and a
    float cell index cannot be hashed with ``xor`` (the DEM then did not compile for a real GPU)."""
    int64 = np.int64

    @target.device
    def cell_index(x, inv_cell):
        return int64(math.floor(x * inv_cell))

    return cell_index


def build_tally(target: Target):
    """``tally_sphere(tally, k)``: on CUDA one more sphere in bucket ``k`` (an atomic count, the sort's first pass
    made by the pass that finds the bucket); on the CPU nothing (the serial sort counts)."""
    if target.is_cuda:
        ns = {"cuda": cuda_api()}   # a global of the function, so that the simulator can swap it
        exec("def tally_sphere(tally, k):\n    cuda.atomic.add(tally, k, 1)\n", ns)
        return target.device(ns["tally_sphere"])

    def tally_sphere(tally, k):
        pass

    return target.device(tally_sphere)


def sort_cpu(n, key, start, count, cursor, order, tally):
    """Serial counting sort of sphere indices by bucket (the CPU body of :func:`build_grid_sort`; ``tally`` is
    not used)."""
    count[:] = 0
    for i in range(n):
        count[key[i]] += 1
    run = 0
    for b in range(count.shape[0]):
        start[b] = run
        cursor[b] = run
        run += count[b]
    for i in range(n):
        k = key[i]
        order[cursor[k]] = i
        cursor[k] += 1


def build_grid_sort(target: Target):
    """``sort(n, key, start, count, cursor, order, tally)``: bucket counts, starts and sphere indices sorted by
    bucket; on CUDA ``tally`` holds the spheres per bucket (counted by ``place``) and is left zero."""
    if not target.is_cuda:
        return cache.cpu_function(sort_cpu)

    @target.kernel(threads=SCAN_THREADS)
    def scan_buckets(nb, tally, start, count, cursor):
        """start = exclusive prefix sum of tally, count = tally, then tally = cursor = 0; one block of SCAN_THREADS
        threads (Hillis and Steele 1986 on the threads' run sums)."""
        t = cuda.threadIdx.x
        per = (nb + SCAN_THREADS - 1) // SCAN_THREADS
        lo = min(t * per, nb)
        hi = min(lo + per, nb)
        own = 0
        for b in range(lo, hi):
            own += tally[b]
        part = cuda.shared.array(SCAN_THREADS, np.int32)
        part[t] = own
        cuda.syncthreads()
        d = 1
        while d < SCAN_THREADS:
            v = part[t - d] if t >= d else 0
            cuda.syncthreads()
            part[t] += v
            cuda.syncthreads()
            d *= 2
        run = part[t] - own
        for b in range(lo, hi):
            m = tally[b]
            start[b] = run
            count[b] = m
            tally[b] = 0
            cursor[b] = 0
            run += m

    @target.kernel(threads=THREADS)
    def scatter(n, key, start, cursor, order):
        i = cuda.grid(1)
        if i < n:
            k = key[i]
            p = cuda.atomic.add(cursor, k, 1)
            order[start[k] + p] = i

    def grid(n):
        return ((n + THREADS - 1) // THREADS, THREADS)

    def sort_cuda(n, key, start, count, cursor, order, tally):
        nb = count.shape[0]
        cuda_launch(scan_buckets, 1, SCAN_THREADS, nb, tally, start, count, cursor)
        cuda_launch(scatter, *grid(n), n, key, start, cursor, order)

    return sort_cuda
