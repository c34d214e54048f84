"""The frozen bulk: the phase field advanced only in the blocks that reach the interface.

Away from the surface phi is constant in each phase (1 in the water, 0 in the air) up to the tail of the
interface profile (phi = 1/2 + 1/2 tanh(2 z / W): 1 - phi = 2e-5 eight cells from the surface at W = 3) and the
drift the velocity's discrete divergence gives it. No pass of the liquid reads more of phi there than
``phi >= 1/2`` (paper section 2.2: eq. 11 and reflag act at the surface), so eqs. 4-10 need not be solved
there. The paper keeps the surface on the finest level and the coarse levels liquid
(:mod:`iceresist.freesurface.refined` does the same); this is that rule on one level, per block.

Each step, from the phase bits of each block and its 26 neighbours (``near``,
:func:`iceresist.freesurface.fluid.build_block_phases`):

* **active** blocks (gas and liquid within reach) run passes 1 and 2 of :class:`PhaseField` as before;
* **ghost** blocks (not active, next to an active block) hold h = h^eq(phi, u, n) (eqs. 7-8, the same
  function as the initial state) for the active cells to pull: an open boundary of the active region, phi
  held at its frozen value outside it (what the active cells send across is not pulled by anyone);
* **frozen** blocks (the rest) keep phi; their h is not read.

``valid[b]`` (kept by :class:`PhaseField`, 1 where h holds the block's state, i.e. the block was active in the
last step) decides where phi is the state: a block leaving the active set first takes phi = sum h
(``settle``); a block joining it first takes h^eq of its phi (``refill``, as a ghost does every step).
The quick tier-2 case holds 1 872 active and 624 ghost blocks of 6 240.

Volume: sum h over the active cells + sum phi over the others is what :meth:`PhaseField.volume` reports. Water
crossing the open boundary carries phi in and out; their difference is the change of the frozen water's
density, which the whole-grid step would book as a drift of its phi (phi follows rho where div u != 0): it is
bounded by the weak compressibility of the LBM. A ghost that also balanced the crossing fluxes conserves sum
phi exactly, but it cannot pass water on into the frozen blocks, so its phi grows wherever water flows out of
the active region (a standing wave of 64 cells: +0.1 in 400 steps): not kept.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from iceresist.backends import jit
from iceresist.backends.launch import ActiveLauncher, BlockLauncher
from iceresist.freesurface import kernel_key
from iceresist.freesurface.hlattice import h_lattice as lookup_h_lattice
from iceresist.freesurface.layout import HAS_GAS, HAS_LIQUID

#: ``near`` of an active block: gas and liquid within its reach.
BOTH = HAS_GAS | HAS_LIQUID


def build_bulk_blocks(target):
    """Compile the per-block passes ``(active_block, roles_block, near_roles_block)``:

    * ``active_block(b, near, act)``: ``act[b]`` = 1 where ``near[b]`` holds gas and liquid;
    * ``roles_block(b, act, nbr, valid, ghost, settle, refill)``: ghost = not active and next to an active
      block; settle = not active and valid (h -> phi); refill = ghost, or active and not valid (phi -> h);
    * ``near_roles_block(b, near, nbr, valid, act, ghost, settle, refill)``: the first two in one pass (one
      process, where the ``near`` of every neighbour is known: one launch fewer a step).
    """
    int8, int64 = np.int8, np.int64
    both, one, zero = int8(BOTH), int8(1), int8(0)

    def active_block(b, near, act):
        b = int64(b)
        act[b] = one if near[b] == both else zero

    def roles_block(b, act, nbr, valid, ghost, settle, refill):
        b = int64(b)
        a = act[b] != 0
        g = False
        if not a:
            for q in range(1, 27):
                bn = nbr[b, q]
                if bn >= 0:
                    if act[bn] != 0:
                        g = True
        v = valid[b] != 0
        ghost[b] = one if g else zero
        settle[b] = one if (v and not a) else zero
        refill[b] = one if (g or (a and not v)) else zero

    def near_roles_block(b, near, nbr, valid, act, ghost, settle, refill):
        """``active_block`` and ``roles_block`` in one pass, a neighbour's activity read from its ``near`` (one
        process: every block's ``near`` is whole)."""
        b = int64(b)
        a = near[b] == both
        g = False
        if not a:
            for q in range(1, 27):
                bn = nbr[b, q]
                if bn >= 0:
                    if near[bn] == both:
                        g = True
        v = valid[b] != 0
        act[b] = one if a else zero
        ghost[b] = one if g else zero
        settle[b] = one if (v and not a) else zero
        refill[b] = one if (g or (a and not v)) else zero

    dev = target.device
    return dev(active_block), dev(roles_block), dev(near_roles_block)


def build_bulk_cells(target, real, nq: int):
    """Compile ``settle_cell(b, c, h, phi, solid)``: phi = sum_k h_k (eq. 5) in a cell no body covers, for an h
    lattice of ``nq`` directions."""
    zero = real(0.0)
    int64 = np.int64

    def settle_cell(b, c, h, phi, solid):
        b = int64(b)
        if solid[b, c] >= 0:
            return
        s = zero
        for k in range(nq):
            s += h[b, k, c]
        phi[b, c] = s

    return target.device(settle_cell)


@lru_cache(maxsize=None)
def bulk_launchers(target, precision: str, lattice_name: str):
    """``{"active", "roles", "near_roles", "settle"}``: the launchers of the frozen bulk (module docstring),
    compiled once per target, precision and h lattice."""
    lat = lookup_h_lattice(lattice_name)
    real = jit.real_type(precision)
    k = kernel_key(target, f"bulk|{precision}|{lattice_name}")
    active_block, roles_block, near_roles_block = build_bulk_blocks(target)
    settle_cell = build_bulk_cells(target, real, lat.q)
    return {
        "active": BlockLauncher(target, active_block, ("near", "act"), label="bulk_roles", cache_key=k),
        "roles": BlockLauncher(target, roles_block, ("act", "nbr", "valid", "ghost", "settle", "refill"),
                               label="bulk_roles", cache_key=k),
        "near_roles": BlockLauncher(target, near_roles_block,
                                    ("near", "nbr", "valid", "act", "ghost", "settle", "refill"),
                                    label="bulk_roles", cache_key=k),
        "settle": ActiveLauncher(target, settle_cell, ("active", "h", "phi", "solid"), label="bulk_settle",
                                 cache_key=k),
    }


class FrozenBulk:
    """The masks of the frozen bulk of a :class:`~iceresist.freesurface.phasefield.PhaseField` and its step.

    ``exchange``: on several MPI ranks, ``exchange(act)`` gives the halo blocks their owners' active flags
    (a halo block's own ``near`` misses the blocks beyond the halo); None on one process. ``split()``: whether
    the phase field is split over ranks now (default: an ``exchange`` is given)."""

    def __init__(self, phase, exchange=None, split=None):
        self.phase = phase
        self.exchange = exchange
        #: ``split()``: the phase field is split over several ranks now (its halo blocks' ``near`` is partial)
        self.split = split if split is not None else (lambda: exchange is not None)
        self._k = bulk_launchers(phase.target, np.dtype(phase.real).name, phase.lat.name)
        n = phase.nblocks
        zeros = lambda: phase.target.to_device(np.zeros(n, np.int8))  # noqa: E731
        self.act, self.ghost, self.settle, self.refill = zeros(), zeros(), zeros(), zeros()

    def step(self, u, near) -> None:
        """One step of the phase field with the velocity ``u`` (``[block, 3, cell]``) in the blocks whose ``near``
        (per block, on the target) holds both phases, the ghosts around them refilled, the rest frozen."""
        p, k, n = self.phase, self._k, self.phase.nblocks
        if not self.split():
            k["near_roles"](n, near, p.nbr, p.valid, self.act, self.ghost, self.settle, self.refill)
        else:   # the halo blocks take their owners' activity before the roles are read from it
            k["active"](n, near, self.act)
            self.exchange(self.act)
            k["roles"](n, self.act, p.nbr, p.valid, self.ghost, self.settle, self.refill)
        k["settle"](n, self.settle, p.h, p.phi, p.solid)
        u = p._u(u)
        p._init_active(n, self.refill, p.h, p.phi, u, p.nbr, p.kappa)
        p.stream_collide(u, self.act)
        # h is the state where the step ran: the active flags become ``valid`` (a swap, no launch; the old
        # ``valid`` is the next step's scratch for the active flags, which it overwrites whole)
        p.valid, self.act = self.act, p.valid
