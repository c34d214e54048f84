"""Fused pull stream-and-collide on the block forest: one cell, one source for CPU and CUDA.

``build_stream_collide(target, real, collide)`` returns the device function ::

    stream_collide_cell(b, c, src, dst, nbr_key, link_bc, flags, bc_kind, bc_u, bc_rho,
                        omega, Fx, Fy, Fz)

which, for cell ``c`` of block ``b``, pulls the 27 post-collision populations
f_q(x - c_q) from ``src`` (through ``nbr_key`` where x - c_q lies in another
block), applies the boundary rules of ``iceresist.lbm.boundary`` where x - c_q
is not fluid (a GHOST cell counts as a source: a moving body whose incoming
slots a link pre-pass filled, :mod:`iceresist.coupling`), collides (paper eq. 1, operator ``collide`` of
``iceresist.lbm.collide``) and writes the result to ``dst[b, :, c]``.

Populations are stored in the well-conditioned form f - w (rho0 = 1). Cells whose
26 neighbours are fluid (flag == FLUID) take a short path with no checks; cells
with boundary links (NEAR_WALL, NEAR_OUTLET) take the general path. The code
is straight-line over 27 named scalars, generated from the lattice tables.
"""

from __future__ import annotations

import numpy as np

from iceresist.grid import flags as FL
from iceresist.grid.forest import CELLS
from iceresist.lattice import C, OPP, Q, W
from iceresist.lbm.boundary import GHOST, build_link_boundary
from iceresist.lbm.codegen import F_NAMES, compile_source, term

ARGS = ("src", "dst", "nbr_key", "link_bc", "flags", "bc_kind", "bc_u", "bc_rho", "omega", "Fx", "Fy", "Fz")


def _source_lines(q: int):
    """Source expressions (block key, cell index) of the cell x - c_q."""
    parts_key, parts_cell = ["13"], []
    for axis, (l, scale_key, scale_cell) in enumerate((("lx", 1, 1), ("ly", 3, 8), ("lz", 9, 64))):
        c = int(C[q, axis])
        if c == 0:
            parts_cell.append(f"{l}" if scale_cell == 1 else f"{scale_cell} * {l}")
            continue
        s = f"({l} {'-' if c > 0 else '+'} 1)"
        parts_key.append(f"{scale_key} * ({s} >> 3)" if scale_key != 1 else f"({s} >> 3)")
        parts_cell.append(f"({s} & 7)" if scale_cell == 1 else f"{scale_cell} * ({s} & 7)")
    return " + ".join(parts_key), " + ".join(parts_cell)


def stream_collide_source(loop_cells: bool = False, free_surface: bool = False) -> str:
    """Python source of the fused per-cell update ``stream_collide_cell(b, c, ...)``.

    With ``loop_cells`` the same body is wrapped in a loop over the 512 cells of block
    ``b`` (``stream_collide_block(b, ...)``): the CPU form, one call per block.

    With ``free_surface`` (paper section 2.2): a population whose source is a GAS cell
    is given by eq. (11), and (Fx, Fy, Fz) is an acceleration g: the body force of the
    cell is rho g (gravity). Eq. (11) with rho0 = 1 in the form f - w reads
    f_q = -f*_opp + 2 w_q [9/2 (c_q . u)^2 - 3/2 u^2] (the odd terms of f^eq cancel),
    the anti-bounce-back at rho0 = 1; u is the cell's own velocity from its
    post-collision populations of the previous step, as at an outlet.
    """
    s = "def stream_collide_cell(b, c, " + ", ".join(ARGS) + "):\n"
    s += "    flag = flags[b, c]\n"
    s += "    if (flag & FLUID) == 0:\n        return\n"
    s += "    ci = c + izero\n    lx = ci & 7\n    ly = (ci >> 3) & 7\n    lz = ci >> 6\n"
    s += "    f0 = src[b, 0, c]\n"
    # short path: all 26 sources are fluid cells of allocated blocks
    s += "    if flag == FLUID:\n"
    for q in range(1, Q):
        key, cell = _source_lines(q)
        s += f"        f{q} = src[nbr_key[b, {key}], {q}, {cell}]\n"
    # general path: solids, walls, inlets, outlets
    s += "    else:\n"
    s += "        ulx = zero\n        uly = zero\n        ulz = zero\n"
    s += "        if flag & NEED_U:\n"
    g = [f"g{q}" for q in range(Q)]
    for q in range(Q):
        s += f"            g{q} = src[b, {q}, c]\n"
    s += f"            rho_l = one + {' + '.join(g)}\n"
    for a, comp in enumerate("xyz"):
        expr = "".join(term(C[q, a], g[q]) for q in range(Q))
        if free_surface:
            s += f"            ul{comp} = (zero{expr}) / rho_l - half * F{comp}\n"
        else:
            s += f"            ul{comp} = (zero{expr} - half * F{comp}) / rho_l\n"
    if free_surface:
        s += "        uu_l = ulx * ulx + uly * uly + ulz * ulz\n"
    for q in range(1, Q):
        key, cell = _source_lines(q)
        cx, cy, cz = (int(v) for v in C[q])
        s += f"        k = {key}\n"
        s += "        nb = nbr_key[b, k]\n"
        s += f"        fopp = src[b, {int(OPP[q])}, c]\n"
        s += "        if nb >= 0:\n"
        s += f"            sc = {cell}\n"
        s += "            if flags[nb, sc] & PULLED:\n"
        s += f"                f{q} = src[nb, {q}, sc]\n"
        if free_surface:
            cu = "".join(term(C[q, a], f"ul{'xyz'[a]}") for a in range(3))
            s += "            elif flags[nb, sc] & GAS:\n"
            s += f"                cu = zero{cu}\n"
            s += f"                f{q} = -fopp + two_w{q} * (c45 * cu * cu - c15 * uu_l)\n"
        s += "            else:\n"
        s += f"                f{q} = fopp\n"
        s += "        else:\n"
        s += (f"            f{q} = link_boundary(fopp, link_bc[b, k], bc_kind, bc_u, bc_rho, "
              f"r{cx + 1}, r{cy + 1}, r{cz + 1}, w{q}, ulx, uly, ulz)\n")
    if free_surface:
        s += f"    rho_c = one + {' + '.join(F_NAMES)}\n"
        s += f"    out = collide(({', '.join(F_NAMES)}), omega, rho_c * Fx, rho_c * Fy, rho_c * Fz)\n"
    else:
        s += f"    out = collide(({', '.join(F_NAMES)}), omega, Fx, Fy, Fz)\n"
    for q in range(Q):
        s += f"    dst[b, {q}, c] = out[{q}]\n"
    if loop_cells:
        body = s.split("\n", 1)[1].replace("        return\n", "        continue\n")
        body = "".join("    " + line + "\n" for line in body.splitlines())
        s = (f"def stream_collide_block(b, {', '.join(ARGS)}):\n"
             f"    for c in range({CELLS}):\n" + body)
    return s


def _namespace(target, real, collide):
    ns = {"FLUID": FL.FLUID, "PULLED": FL.FLUID | GHOST, "NEAR_OUTLET": FL.NEAR_OUTLET, "GAS": FL.GAS,
          "NEED_U": FL.NEAR_OUTLET | FL.NEAR_SURFACE, "c45": real(4.5), "c15": real(1.5),
          "izero": np.int64(0), "zero": real(0.0),
          "one": real(1.0), "half": real(0.5), "r0": real(-1.0), "r1": real(0.0), "r2": real(1.0),
          "collide": collide, "link_boundary": build_link_boundary(target, real, cell_device(target))}
    ns.update({f"w{q}": real(W[q]) for q in range(Q)})
    ns.update({f"two_w{q}": real(2.0 * W[q]) for q in range(Q)})
    return ns


def build_stream_collide(target, real, collide, free_surface: bool = False):
    """The fused pull stream-collide update of one cell, ``stream_collide_cell(b, c, *ARGS)``;
    ``free_surface``: eq. (11) at GAS sources and the force rho g (see :func:`stream_collide_source`)."""
    return compile_source(stream_collide_source(free_surface=free_surface), "stream_collide_cell", _namespace(target, real, collide),
                          cell_device(target))


def build_stream_collide_block(target, real, collide, free_surface: bool = False):
    """The same update looped over the 512 cells of a block, ``stream_collide_block(b, *ARGS)`` (CPU form:
    one call per block instead of one per cell, about 1.5x faster streaming)."""
    return compile_source(stream_collide_source(loop_cells=True, free_surface=free_surface), "stream_collide_block",
                          _namespace(target, real, collide), cell_device(target))


def cell_device(target):
    """Decorator for large per-cell functions: ``target.device`` on CUDA; on the CPU a plain
    (not IR-inlined) njit function, which LLVM still inlines where it pays. Numba's IR-level
    ``inline="always"`` of the whole fused update inside a ``prange`` body costs minutes of
    compile time for no speed."""
    if target.is_cuda:
        return target.device
    return lambda fn: target.kernel(fn, parallel=False)
