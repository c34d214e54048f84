"""The D3Q27 velocity set: the single source of truth for every kernel.

Ordering: q = 0 rest; 1-6 faces; 7-18 edges; 19-26 corners. Directions come in
opposite pairs (2k-1, 2k), so ``OPP[q] = q + 1`` for odd q and ``q - 1`` for even q > 0.
Weights: 8/27 (rest), 2/27 (faces), 1/54 (edges), 1/216 (corners); c_s^2 = 1/3.
"""

from __future__ import annotations

import numpy as np

Q = 27
CS2 = 1.0 / 3.0

_FACES = [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
_EDGES = [(1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1), (0, 1, -1)]
_CORNERS = [(1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)]


def _pairs(vs):
    out = []
    for v in vs:
        out.append(v)
        out.append(tuple(-c for c in v))
    return out


#: Lattice velocities c[q] = (cx, cy, cz), shape (27, 3), int64.
C = np.array([(0, 0, 0)] + _pairs(_FACES) + _pairs(_EDGES) + _pairs(_CORNERS), dtype=np.int64)
CX, CY, CZ = (C[:, a].copy() for a in range(3))

_w_of_len2 = {0: 8.0 / 27.0, 1: 2.0 / 27.0, 2: 1.0 / 54.0, 3: 1.0 / 216.0}
#: Weights w[q], float64, summing to 1.
W = np.array([_w_of_len2[int(np.sum(c * c))] for c in C])

#: Opposite direction index: C[OPP[q]] == -C[q].
OPP = np.array([int(np.flatnonzero((C == -c).all(axis=1))[0]) for c in C], dtype=np.int64)


def index_of(cx: int, cy: int, cz: int) -> int:
    """Index q of the velocity (cx, cy, cz)."""
    return int(np.flatnonzero((C == (cx, cy, cz)).all(axis=1))[0])


def equilibrium(rho, ux, uy, uz):
    """Second-order equilibrium f_eq (paper eq. 12), NumPy, shape (27,) + shape of the inputs."""
    rho, ux, uy, uz = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (rho, ux, uy, uz)))
    cu = CX.reshape((-1,) + (1,) * rho.ndim) * ux + CY.reshape((-1,) + (1,) * rho.ndim) * uy \
        + CZ.reshape((-1,) + (1,) * rho.ndim) * uz
    uu = ux * ux + uy * uy + uz * uz
    w = W.reshape((-1,) + (1,) * rho.ndim)
    return w * rho * (1.0 + 3.0 * cu + 4.5 * cu * cu - 1.5 * uu)
