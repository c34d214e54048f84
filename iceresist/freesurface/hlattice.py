"""Velocity sets for the phase-field distribution h (paper eqs. 5-9): D3Q7, D3Q15, D3Q19, D3Q27.

Each is a subset of the D3Q27 directions of :mod:`iceresist.lattice`, so h streams
through the same neighbour table as f. The paper uses D3Q27 for h; the smaller
sets save memory traffic (h is 7/15/19/27 numbers per cell). D3Q7 uses the
weights 1/4 (rest) and 1/8 (faces), so c_s^2 = 1/4 for it; the others have
c_s^2 = 1/3. docs/VALIDATION.md (section "Free surface") compares their accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from iceresist import lattice as L
from iceresist.errors import InputError


@dataclass(frozen=True)
class HLattice:
    """A velocity set for h: ``q27[k]`` is the D3Q27 index of direction k; ``w[k]`` its weight."""

    name: str
    q27: tuple
    w: tuple
    cs2: float

    @property
    def q(self) -> int:
        return len(self.q27)

    @property
    def c(self) -> np.ndarray:
        """Velocities, shape (q, 3), int64."""
        return L.C[list(self.q27)]

    @property
    def opp(self) -> tuple:
        """Index k' (within this set) of the direction opposite to k."""
        pos = {q: k for k, q in enumerate(self.q27)}
        return tuple(pos[int(L.OPP[q])] for q in self.q27)


def _by_len2(len2_weight: dict, cs2: float, name: str) -> HLattice:
    len2 = np.sum(L.C * L.C, axis=1)
    q27 = tuple(int(q) for q in range(L.Q) if int(len2[q]) in len2_weight)
    w = tuple(len2_weight[int(len2[q])] for q in q27)
    return HLattice(name, q27, w, cs2)


H_LATTICES = {
    "D3Q7": _by_len2({0: 1 / 4, 1: 1 / 8}, 1 / 4, "D3Q7"),
    "D3Q15": _by_len2({0: 2 / 9, 1: 1 / 9, 3: 1 / 72}, 1 / 3, "D3Q15"),
    "D3Q19": _by_len2({0: 1 / 3, 1: 1 / 18, 2: 1 / 36}, 1 / 3, "D3Q19"),
    "D3Q27": _by_len2({0: 8 / 27, 1: 2 / 27, 2: 1 / 54, 3: 1 / 216}, 1 / 3, "D3Q27"),
}


def h_lattice(name: str) -> HLattice:
    """The velocity set called ``name`` (``free_surface.h_lattice`` in a scene)."""
    try:
        return H_LATTICES[name]
    except KeyError:
        raise InputError(f"free_surface.h_lattice must be one of {sorted(H_LATTICES)}, not {name!r}") from None
