"""The level-interface transfer of block refinement as a kernel, one source for CPU and CUDA.

Each item of a transfer table (:func:`iceresist.lbm.refinement.explosion_tables`,
:func:`~iceresist.lbm.refinement.coalescence_table`) writes one population slot:

    dst[db, dq, dc] = weight * sum_k packet_k

where packet k is slot sq_k of cell (sb_k, sc_k) of the source array its tag names (0: the coarse level at t, 1: the
fine level at t, 2: the fine level at t + 1/2), and, for coarse packets with the linear reconstruction, plus the
central difference over the coarse neighbours (nb, nc)[k, 2a], (nb, nc)[k, 2a + 1] along axis a times the packet's
offset (span: how many of the two neighbours exist). The host form is the NumPy reference
(:func:`iceresist.lbm.refinement._apply_slots`).
"""

from __future__ import annotations

import numpy as np

from functools import lru_cache

from iceresist.backends import cache
from iceresist.backends.launch import ItemLauncher

TRANSFER_ARGS = ("db", "dq", "dc", "tag", "sb", "sc", "sq", "off", "nb", "nc", "nok", "weight", "linear", "src0",
                 "src1", "src2", "dst")


def build_transfer(target, real):
    """The item function ``transfer(i, *TRANSFER_ARGS)`` (module docstring)."""
    zero = real(0.0)

    @target.device
    def packet(src, b, q, c, k, i, nb, nc, nok, off, linear, is_coarse):
        v = src[b, q, c]
        if linear != 0 and is_coarse:
            for a in range(3):
                m = 2 * a
                p = 2 * a + 1
                span = real(nok[i, k, m] + nok[i, k, p])
                if span > zero:
                    v += off[i, k, a] * (src[nb[i, k, p], q, nc[i, k, p]] - src[nb[i, k, m], q, nc[i, k, m]]) / span
        return v

    @target.device
    def transfer(i, db, dq, dc, tag, sb, sc, sq, off, nb, nc, nok, weight, linear, src0, src1, src2, dst):
        acc = zero
        for k in range(tag.shape[1]):
            t = tag[i, k]
            q = sq[i, k]
            if t == 0:
                acc += packet(src0, sb[i, k], q, sc[i, k], k, i, nb, nc, nok, off, linear, True)
            elif t == 1:
                acc += packet(src1, sb[i, k], q, sc[i, k], k, i, nb, nc, nok, off, linear, False)
            else:
                acc += packet(src2, sb[i, k], q, sc[i, k], k, i, nb, nc, nok, off, linear, False)
        dst[db[i], dq[i], dc[i]] = weight * acc

    return transfer


_CACHE: dict = {}


def transfer_launcher(target, real) -> ItemLauncher:
    """The compiled transfer launcher ``launcher(n, *TRANSFER_ARGS)`` (cached per target and precision)."""
    key = (target.name, target.simulator, np.dtype(real).name)
    if key not in _CACHE:
        k = None if target.is_cuda else cache.fingerprint(f"level_transfer|{np.dtype(real).name}",
                                                          ("iceresist.lbm.exchange",))
        _CACHE[key] = ItemLauncher(target, build_transfer(target, real), TRANSFER_ARGS, label="level_transfer",
                                   cache_key=k)
    return _CACHE[key]


def pack_table(table, real) -> dict:
    """A transfer table (tuple of NumPy columns) as the flat arrays of :data:`TRANSFER_ARGS` (host), indices as
    int32. A table without coarse packets (a coalescence) never reads the offsets and neighbours of the linear
    reconstruction: they are packed as one row each (the kernel reads them for coarse packets only), which keeps a
    large interface's tables a tenth of the size."""
    db, q, dc, tag, sb, sc, sq, (off, nbrs) = table
    if tag.ndim == 1:
        tag, sb, sc, sq = tag[:, None], sb[:, None], sc[:, None], sq[:, None]
        off = off[:, None, :]
        nbrs = [(b[:, None], c[:, None], ok[:, None]) for b, c, ok in nbrs]
    rows = slice(None) if (np.asarray(tag) == 0).any() else slice(0, 1)
    nb = np.stack([b[rows] for b, _, _ in nbrs], axis=-1)
    nc = np.stack([c[rows] for _, c, _ in nbrs], axis=-1)
    nok = np.stack([ok[rows] for _, _, ok in nbrs], axis=-1)
    as_int = {k: np.ascontiguousarray(v, dtype=np.int32) for k, v in
              dict(db=db, dq=q, dc=dc, tag=tag, sb=sb, sc=sc, nb=nb, nc=nc).items()}
    return {**as_int, "sq": np.ascontiguousarray(sq, dtype=np.int8),
            "nok": np.ascontiguousarray(nok, dtype=np.int8),
            "off": np.ascontiguousarray(np.asarray(off)[rows], dtype=real)}


def _copy_block_item(i, blocks, dst, src):
    b = blocks[i]
    for r in range(dst.shape[1]):
        dst[b, r] = src[b, r]


@lru_cache(maxsize=None)
def _block_copier(target):
    return ItemLauncher(target, target.device(_copy_block_item), ("blocks", "dst", "src"), label="copy_blocks")


def copy_blocks(target, dst, src, blocks, nblocks: int):
    """dst[b] = src[b] for the ``nblocks`` blocks listed in ``blocks`` (a target int64 array) of two contiguous
    target arrays of the same shape (blocks first): the snapshot of a level that the transfer tables read, a block
    per item on the CPU (13 824 floats each, faster than NumPy's whole-array copy even for every block); on CUDA the
    whole array, one device-to-device copy at the memory's full bandwidth (a gather would cost more than it
    saves)."""
    if target.is_cuda:
        target.copy(dst, src)
        return
    if nblocks == 0:
        return
    d = dst.reshape(dst.shape[0], dst.size // dst.shape[0])
    s = src.reshape(src.shape[0], src.size // src.shape[0])
    _block_copier(target)(int(nblocks), blocks, d, s)
