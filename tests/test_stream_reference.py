"""NumPy reference of one LBM step on a dense grid: pull streaming with link boundaries, then BGK.

Written independently of the kernels (dense arrays, np.roll, explicit face rules) so tests of
the fused kernel compare against something that shares none of its index arithmetic.
"""

import numpy as np

from iceresist.grid.flags import FACE_PRIORITY
from iceresist.lattice import C, OPP, Q, W

FACES = ("x-", "x+", "y-", "y+", "z-", "z+")


def _link_value(face, fopp, q, u_cell):
    if face.kind in ("wall",) or face is None:
        return fopp
    if face.kind == "pressure_outlet":
        cu = np.einsum("a,a...->...", C[q].astype(float), u_cell)
        uu = (u_cell ** 2).sum(axis=0)
        return -fopp + 2 * W[q] * ((face.density - 1) + face.density * (4.5 * cu * cu - 1.5 * uu))
    return fopp + 6 * W[q] * float(np.dot(C[q], face.velocity))


def stream(f, faces, solid, force):
    """Pull streaming of post-collision f - w (27, nx, ny, nz) with half-way bounce-back rules."""
    shape = f.shape[1:]
    rho = 1 + f.sum(axis=0)
    u_cell = (np.einsum("qa,q...->a...", C.astype(float), f) - 0.5 * np.asarray(force)[:, None, None, None]) / rho
    idx = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
    out = np.empty_like(f)
    out[0] = f[0]
    for q in range(1, Q):
        src = [idx[a] - C[q, a] for a in range(3)]
        crossed = np.full(shape, -1)
        best = np.full(shape, 99)
        for a in range(3):
            lo, hi = faces[FACES[2 * a]], faces[FACES[2 * a + 1]]
            if lo.kind == "periodic":
                src[a] %= shape[a]
                continue
            for k, mask in ((2 * a, src[a] < 0), (2 * a + 1, src[a] >= shape[a])):
                pr = FACE_PRIORITY[faces[FACES[k]].kind] * 10 + k
                take = mask & (pr < best)
                crossed[take] = k
                best[take] = pr
            src[a] = np.clip(src[a], 0, shape[a] - 1)
        pulled = f[q][tuple(src)]
        src_solid = solid[tuple(src)]
        fopp = f[OPP[q]]
        res = np.where(src_solid, fopp, pulled)
        for k in range(6):
            m = crossed == k
            if m.any():
                res[m] = _link_value(faces[FACES[k]], fopp, q, u_cell)[m]
        out[q] = res
    return out


def bgk(f, omega, force):
    """BGK with Guo forcing on f - w (27, ...), as documented in iceresist.lbm.collide."""
    F = np.asarray(force, dtype=float)
    drho = f.sum(axis=0)
    rho = 1 + drho
    u = (np.einsum("qa,q...->a...", C.astype(float), f) + 0.5 * F[:, None, None, None]) / rho
    uu = (u ** 2).sum(axis=0)
    out = np.empty_like(f)
    for q in range(Q):
        cu = np.einsum("a,a...->...", C[q].astype(float), u)
        cf = float(np.dot(C[q], F))
        feq = W[q] * (drho + rho * (3 * cu + 4.5 * cu * cu - 1.5 * uu))
        s = W[q] * (1 - omega / 2) * (3 * (cf - np.einsum("a,a...->...", F, u)) + 9 * cu * cf)
        out[q] = f[q] + omega * (feq - f[q]) + s
    return out


def step(f, faces, solid, omega, force):
    g = bgk(stream(f, faces, solid, force), omega, force)
    g[:, solid] = f[:, solid]
    return g
