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

On the CPU, ``build_stream_collide_block`` updates a whole block per call in three
sweeps (pull into a block scratch, collision vectorised across cells, write-back),
reusing the pull code of the per-cell update for blocks with boundary cells
(docs/PERFORMANCE.md, "LBM CPU kernel optimisation").
"""

from __future__ import annotations

import math
import re

import numpy as np

from iceresist.grid import flags as FL
from iceresist.grid.forest import CELLS
from iceresist.lattice import C, OPP, Q, W, index_of
from iceresist.lbm.boundary import GHOST, build_link_boundary
from iceresist.lbm.codegen import F_NAMES, compile_source, term

ARGS = ("src", "dst", "nbr_key", "link_bc", "flags", "bc_kind", "bc_u", "bc_rho", "omega", "Fx", "Fy", "Fz")
#: Arguments of the free-surface variant: ``ARGS`` plus the phase field ``phi[block, cell]`` and half the
#: interface width W / 2 (lattice units), which place the surface inside the cell (eq. 11 with a sub-cell
#: hydrostatic link density, :func:`stream_collide_source`).
FS_ARGS = ARGS + ("phi", "half_width")
#: |2 phi - 1| is clamped below this before artanh (a signed distance of at most ~3.8 W / 2).
TANH_CLIP = 0.999
#: Arguments of the slot-indexed free-surface update: ``fslot[block]`` is the row of the population pool
#: that holds the block (-1 for a block wholly in the gas, which holds none; :mod:`iceresist.freesurface.pool`).
POOL_ARGS = FS_ARGS + ("fslot",)
#: The same with the velocity written as the populations are: ``u[block, 3, cell]`` gets the cell's
#: j / rho - F / 2 from its post-collision populations (0 outside the liquid), the field the phase field and the
#: velocity extension read (:func:`_block_velocity_lines`).
POOL_U_ARGS = POOL_ARGS + ("u",)


def _source_lines(q: int):
    """Source expressions (block key, cell index) of the cell x - c_q."""
    return _offset_lines(C[q])


def _offset_lines(cvec):
    """Source expressions (block key, cell index) of the cell x - c for an integer vector c."""
    parts_key, parts_cell = ["13"], []
    for axis, (l, scale_key, scale_cell) in enumerate((("lx", 1, 1), ("ly", 3, 8), ("lz", 9, 64))):
        c = int(cvec[axis])
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
    is given by eq. (11), and (Fx, Fy, Fz) is an acceleration g (gravity, along -z:
    g = -Fz): the body force of the cell is rho g. The arguments are ``FS_ARGS``.

    Eq. (11) is an anti-bounce-back: it imposes the density it is given at the link
    midpoint x - c_q / 2. The paper's rho0 there puts the gas pressure on the cell
    staircase, so a sub-cell displacement of the surface feels no restoring pressure.
    We impose instead the density that the hydrostatic liquid has at the link midpoint
    when the gas pressure c_s^2 rho0 acts exactly on the phi = 1/2 surface:

        s(x)    = (W / 2) artanh(2 phi(x) - 1)            (signed distance to the surface,
                                                           > 0 in the liquid; the profile of eq. 4)
        s_mid   = [s(x) + s(x - c_q)] / 2                 (linear along the link, exact for a plane)
        rho_mid = rho0 + 3 g s_mid                        (c_s^2 d(rho)/d(depth) = rho0 g)

    with |2 phi - 1| clamped to ``TANH_CLIP``; s_mid stands for the depth below the surface,
    exact for a level surface (a relative error of slope^2 / 2 on a tilted one). In the form
    f - w with rho0 = 1, eq. (11) with f^eq(rho_mid, u) of eq. (12) reads

        f_q = -f*_opp + 2 w_q [(rho_mid - 1) + rho_mid (9/2 (c_q . u)^2 - 3/2 u^2)]

    (the odd terms of f^eq cancel); u is the cell's own velocity from its post-collision
    populations of the previous step, as at an outlet. A level surface at a cell face
    (s_mid = 0) gives back the paper's rule at rho0 = 1.
    """
    args = FS_ARGS if free_surface else ARGS
    s = "def stream_collide_cell(b, c, " + ", ".join(args) + "):\n"
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
        # the sub-cell depth of the cell itself only where a gas source is possible: a GAS neighbour makes the
        # cell NEAR_SURFACE (reflag), and NEED_U holds that bit; a cell near a wall alone skips the artanh
        s += "        uu_l = ulx * ulx + uly * uly + ulz * ulz\n"
        s += "        g3 = -three * Fz\n"
        s += "        s_c = zero\n"
        s += "        if flag & NEED_U:\n"
        s += "            t = two * phi[b, c] - one\n"
        s += "            t = min(max(t, -tclip), tclip)\n"
        s += "            s_c = half_width * atanh(t)\n"
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
            s += _gas_source_lines(q, "            ")
        s += "            else:\n"
        s += f"                f{q} = fopp\n"
        s += "        else:\n"
        s += "            row = link_bc[b, k]\n"
        call = (f"link_boundary(fopp, row, bc_kind, bc_u, bc_rho, "
                f"r{cx + 1}, r{cy + 1}, r{cz + 1}, w{q}, ulx, uly, ulz)\n")
        if sum(1 for v in (cx, cy, cz) if v) > 1:
            s += "            if bc_kind[row] == BC_SLIP:\n"
            s += _slip_lines(q, free_surface)
            s += "            else:\n"
            s += f"                f{q} = " + call
        else:   # a link normal to the face: the specular reflection is the bounce-back of link_boundary
            s += f"            f{q} = " + call
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
        s = (f"def stream_collide_block(b, {', '.join(args)}):\n"
             f"    for c in range({CELLS}):\n" + body)
    return s


def _block_velocity_lines() -> str:
    """Source of the block form's velocity sweep (:func:`stream_collide_block_source`), a loop of its own over the
    post-collision populations in the scratch (from the cache rather than from memory; in the collision sweep itself
    the 30 extra stores stop LLVM vectorising it): ``u[b, :, c]`` = j / rho - F / 2, the sums in the order of the
    separate velocity pass (:func:`iceresist.freesurface.fluid.build_velocity_block`): rho = 1 plus f_0 .. f_26, j_a =
    0 plus or minus the f_q with c_qa = +-1, q rising. The post-collision j is the pre-collision one plus the full
    force, hence - F / 2."""
    s = f"    for c in range({CELLS}):\n"
    s += "".join(f"        v{q} = tmp[{_slot(q)} + c]\n" for q in range(Q))
    s += f"        rho_u = one + {' + '.join(f'v{q}' for q in range(Q))}\n"
    for a, comp in enumerate("xyz"):
        expr = "".join(term(C[q, a], f"v{q}") for q in range(Q))
        s += f"        u[b, {a}, c] = (zero{expr}) / rho_u - half * F{comp}\n"
    return s


def _zero_velocity_lines(indent: str) -> str:
    return "".join(f"{indent}u[b, {a}, c] = zero\n" for a in range(3))


def _slip_lines(q: int, free_surface: bool) -> str:
    """Source of the free-slip rule for population ``q`` (``iceresist.lbm.boundary``, specular reflection).

    The face the link leaves through is that of the boundary row (rows 1-6 are x-, x+, y-, y+, z-, z+,
    so its axis is (row - 1) >> 1). The population comes from the cell x - c_t beside x (c_t: c_q without
    its normal component) in the mirrored direction q' (c_q with the normal component negated). Where
    x - c_t is not a fluid cell the link falls back to bounce-back; where it is a gas cell (free surface)
    eq. (11) applies as for a pull from that gas cell.
    """
    c = [int(v) for v in C[q]]
    axes = [a for a in range(3) if c[a]]          # two or three: the face's axis is one of them
    s = f"                f{q} = fopp\n"
    for i, a in enumerate(axes):
        tangential = [0 if j == a else c[j] for j in range(3)]
        mirrored = [-c[j] if j == a else c[j] for j in range(3)]
        key, cell = _offset_lines(tangential)
        test = "else:" if i == len(axes) - 1 else f"{'if' if i == 0 else 'elif'} (row - 1) >> 1 == {a}:"
        s += f"                {test}\n"
        s += f"                    nb = nbr_key[b, {key}]\n"
        s += f"                    sc = {cell}\n"
        s += f"                    qm = {index_of(*mirrored)}\n"
    s += "                if nb >= 0:\n"
    s += "                    if flags[nb, sc] & PULLED:\n"
    s += f"                        f{q} = src[nb, qm, sc]\n"
    if free_surface:
        s += _gas_source_lines(q, "                    ")
    return s


def _gas_source_lines(q: int, indent: str) -> str:
    """``elif`` branch of a pull of population ``q`` from the gas cell (nb, sc): eq. (11) with the sub-cell
    hydrostatic link density (:func:`stream_collide_source`)."""
    cu = "".join(term(C[q, a], f"ul{'xyz'[a]}") for a in range(3))
    lines = ["elif flags[nb, sc] & GAS:",
             f"    cu = zero{cu}",
             "    t = two * phi[nb, sc] - one",
             "    t = min(max(t, -tclip), tclip)",
             "    d3g = g3 * half * (s_c + half_width * atanh(t))",
             f"    f{q} = -fopp + two_w{q} * (d3g + (one + d3g) * (c45 * cu * cu - c15 * uu_l))"]
    return "".join(indent + ln + "\n" for ln in lines)


def stream_namespace(target, real, collide):
    """The names the generated stream-collide sources call: flags, constants, the collision ``collide``, the
    lattice's tables in the real type ``real`` and the target's helpers."""
    ns = {"FLUID": FL.FLUID, "PULLED": FL.FLUID | GHOST, "BC_SLIP": FL.BC_SLIP, "NEAR_OUTLET": FL.NEAR_OUTLET,
          "GAS": FL.GAS,
          "NEED_U": FL.NEAR_OUTLET | FL.NEAR_SURFACE, "c45": real(4.5), "c15": real(1.5),
          "izero": np.int64(0), "zero": real(0.0),
          "one": real(1.0), "half": real(0.5), "two": real(2.0), "three": real(3.0), "tclip": real(TANH_CLIP),
          "atanh": math.atanh, "r0": real(-1.0), "r1": real(0.0), "r2": real(1.0),
          "collide": collide, "link_boundary": build_link_boundary(target, real, cell_device(target))}
    ns.update({f"w{q}": real(W[q]) for q in range(Q)})
    ns.update({f"two_w{q}": real(2.0 * W[q]) for q in range(Q)})
    return ns


def pooled_source(src: str) -> str:
    """The update ``src`` with the populations indexed through the block -> pool-row map ``fslot``.

    ``src[b, ...]``/``dst[b, ...]`` become ``src[sb, ...]``/``dst[sb, ...]`` with ``sb = fslot[b]`` and a pull from
    block ``nb`` reads ``src[fslot[nb], ...]``. Only liquid cells read or write populations and they pull
    from their 26 neighbours, all in wet blocks or blocks next to one, which the pool always holds; a
    block without a row (``fslot = -1``) is never touched. The arithmetic is that of ``src`` unchanged.
    """
    s = re.sub(r"\b(src|dst)\[b, ", r"\1[sb, ", src)
    s = re.sub(r"\bsrc\[(nb|nbr_key\[b, [^\]]+\]), ", r"src[fslot[\1], ", s)
    s = re.sub(r"\n( +)ci = c \+ izero\n", r"\n\1ci = c + izero\n\1sb = fslot[b]\n", s)
    s = s.replace(", ".join(FS_ARGS) + ", u):", ", ".join(POOL_U_ARGS) + "):", 1)
    return s.replace(", ".join(FS_ARGS) + "):", ", ".join(POOL_ARGS) + "):", 1)


def build_stream_collide(target, real, collide, free_surface: bool = False):
    """The fused pull stream-collide update of one cell, ``stream_collide_cell(b, c, *ARGS)``;
    ``free_surface``: eq. (11) at GAS sources with the sub-cell link density and the force rho g,
    arguments ``FS_ARGS`` (see :func:`stream_collide_source`)."""
    return compile_source(stream_collide_source(free_surface=free_surface), "stream_collide_cell",
                          stream_namespace(target, real, collide), cell_device(target))


def build_stream_collide_block(target, real, collide, vector: bool = True, free_surface: bool = False):
    """The same update over the 512 cells of a block, ``stream_collide_block(b, *ARGS)`` (CPU form).

    With ``vector`` (default) the block is updated in three sweeps so that the collision vectorises
    across cells (:func:`stream_collide_block_source`); without it, the per-cell update looped over
    the cells (``stream_collide_source(loop_cells=True)``), kept as the reference form. Both take
    ``free_surface`` (gravity times the cell's density, eq. 11 at gas sources)."""
    if not vector:
        return compile_source(stream_collide_source(loop_cells=True, free_surface=free_surface),
                              "stream_collide_block", stream_namespace(target, real, collide), cell_device(target))
    return compile_source(stream_collide_block_source(free_surface), "stream_collide_block",
                          block_namespace(target, real, collide), cell_device(target))


def block_namespace(target, real, collide) -> dict:
    """The names :func:`stream_collide_block_source` uses: those of the per-cell form and its scratch."""
    ns = stream_namespace(target, real, collide)
    ns.update({"np": np, "rdtype": real, "PLANE": PLANE})
    return ns


def _pull_body(free_surface: bool = False) -> str:
    """The pull part of the per-cell update (everything before the collision), taken from
    :func:`stream_collide_source` so both forms share one set of boundary rules."""
    body = stream_collide_source(free_surface=free_surface).split("\n", 1)[1]
    return body.split("    rho_c = " if free_surface else "    out = collide(", 1)[0]


#: Stride of one population in the block scratch: 512 cells plus 8 cells of padding either side,
#: which the line copies of the all-fluid gather may overrun.
PLANE = CELLS + 16


def _slot(q: int) -> int:
    """Offset of population ``q`` of cell 0 in the block scratch."""
    return q * PLANE + 8


def _line_gather(q: int) -> str:
    """Source pulling population ``q`` of a block whose cells are all FLUID into ``tmp``.

    Per line of 8 cells along x, one contiguous 8-value copy from the source block; for
    cx = +1 (-1) it lands one slot to the right (left) and the value that crosses the block face
    is then taken from the x-neighbour block. The copy overruns into the next (previous) line's
    edge slot, which that line writes afterwards: lines run upwards for cx = +1, downwards for
    cx = -1, and the overrun at the plane ends falls in the scratch padding.
    """
    cx, cy, cz = (int(v) for v in C[q])
    rng = "range(7, -1, -1)" if cx < 0 else "range(8)"
    s = f"    for lz in {rng}:\n"
    s += f"        sz = lz {'-' if cz > 0 else '+'} 1\n" if cz else "        sz = lz\n"
    s += f"        for ly in {rng}:\n"
    s += f"            sy = ly {'-' if cy > 0 else '+'} 1\n" if cy else "            sy = ly\n"
    s += "            k = 13 + 3 * (sy >> 3) + 9 * (sz >> 3)\n"
    s += "            sl = 8 * (sy & 7) + 64 * (sz & 7)\n"
    s += "            nb = nbr_key[b, k]\n"
    s += f"            dl = {_slot(q) + cx} + 8 * ly + 64 * lz\n"
    # all eight loads before the eight stores, so that LLVM's SLP vectoriser may merge each group
    # into one vector load and one vector store without proving that tmp and src do not overlap
    s += "".join(f"            v{i} = src[nb, {q}, sl + {i}]\n" for i in range(8))
    s += "".join(f"            tmp[dl + {i}] = v{i}\n" for i in range(8))
    if cx > 0:
        s += f"            tmp[dl - 1] = src[nbr_key[b, k - 1], {q}, sl + 7]\n"
    elif cx < 0:
        s += f"            tmp[dl + 8] = src[nbr_key[b, k + 1], {q}, sl]\n"
    return s


def stream_collide_block_source(free_surface: bool = False, velocity: bool = False) -> str:
    """Python source of the CPU block update ``stream_collide_block(b, *ARGS)`` in three sweeps (``*FS_ARGS`` with
    ``free_surface``: the pull of a mixed block takes eq. (11) at GAS sources and the collision the force
    rho g, as in :func:`stream_collide_source`).

    1. pull: the 27 populations of the 512 cells into a block scratch, population q of cell c at
       ``tmp[q * PLANE + 8 + c]``, gathered line by line (:func:`_line_gather`) without per-cell neighbour
       look-ups; then, in a block with other cells than plain FLUID ones, those cells are pulled again one by one
       with the boundary rules of the per-cell update (a line from a missing block reads some row of ``src``, in
       bounds, and every cell it lands in is such a cell). A block with no FLUID cell returns at once: it
       writes nothing in any form;
    2. collide: one branch-free loop over the 512 cells reading and writing ``tmp`` at constant
       offsets, which LLVM vectorises across cells (8 float32 or 4 float64 cells per AVX2 register);
    3. write: ``tmp`` to ``dst[b]``, population by population (fluid cells only in a mixed block).

    Same arithmetic as the per-cell form, cell by cell; only the order of the work differs. With ``velocity``
    (free surface) the collision sweep also writes each cell's velocity ``u`` from its post-collision populations
    (:func:`_block_velocity_lines`), and the cells outside the liquid get u = 0: the arguments are ``FS_ARGS`` and ``u``.
    """
    if velocity and not free_surface:
        raise ValueError("velocity is written by the free-surface update only")
    args = FS_ARGS + (("u",) if velocity else ()) if free_surface else ARGS
    s = f"def stream_collide_block(b, {', '.join(args)}):\n"
    s += "    full = True\n    wet = False\n"
    s += (f"    for c in range({CELLS}):\n        fc = flags[b, c]\n        if fc != FLUID:\n            full = False\n"
          "        if fc & FLUID:\n            wet = True\n")
    # no cell to update: nothing is written (but the velocity, 0)
    zero_u = f"        for c in range({CELLS}):\n" + _zero_velocity_lines("            ") if velocity else ""
    s += "    if not wet:\n" + zero_u + "        return\n"
    s += f"    tmp = np.empty({Q * PLANE}, rdtype)\n"
    # every block is gathered line by line; the cells with a boundary link (or none to update) are then pulled
    # again one by one, so only those pay for the neighbour look-ups
    s += "".join(ln + "\n" for q in range(Q) for ln in _line_gather(q).splitlines())
    s += "    if not full:\n"
    zero_fill = "".join(f"                tmp[{_slot(q)} + c] = zero\n" for q in range(Q))
    body = _pull_body(free_surface).replace("        return\n", zero_fill + "                continue\n", 1)
    s += f"        for c in range({CELLS}):\n"
    s += "            if flags[b, c] == FLUID:\n                continue\n"
    s += "".join("        " + ln + "\n" for ln in body.splitlines())
    s += "".join(f"            tmp[{_slot(q)} + c] = f{q}\n" for q in range(Q))
    # 2. collide, vectorised across cells
    s += f"    for c in range({CELLS}):\n"
    s += "".join(f"        f{q} = tmp[{_slot(q)} + c]\n" for q in range(Q))
    if free_surface:
        s += f"        rho_c = one + {' + '.join(F_NAMES)}\n"
        s += f"        out = collide(({', '.join(F_NAMES)}), omega, rho_c * Fx, rho_c * Fy, rho_c * Fz)\n"
    else:
        s += f"        out = collide(({', '.join(F_NAMES)}), omega, Fx, Fy, Fz)\n"
    s += "".join(f"        tmp[{_slot(q)} + c] = out[{q}]\n" for q in range(Q))
    if velocity:
        s += _block_velocity_lines()
    # 3. write back
    s += "    if full:\n"
    s += f"        for q in range({Q}):\n"
    s += "            to = q * PLANE + 8\n"
    s += f"            for c in range({CELLS}):\n                dst[b, q, c] = tmp[to + c]\n"
    # a mixed block: population by population, so that the stores run along dst's contiguous cell index (cell by
    # cell with the populations inner, each store 512 values from the last, this write cost a third of the update)
    s += "    else:\n"
    s += f"        for q in range({Q}):\n            to = q * PLANE + 8\n"
    s += f"            for c in range({CELLS}):\n                if flags[b, c] & FLUID:\n"
    s += "                    dst[b, q, c] = tmp[to + c]\n"
    if velocity:
        s += f"        for c in range({CELLS}):\n            if (flags[b, c] & FLUID) == 0:\n"
        s += _zero_velocity_lines("                ")
    return s


def cell_device(target):
    """Decorator for large per-cell functions: ``target.device`` on CUDA; on the CPU a plain
    (not IR-inlined) njit function, which LLVM still inlines where it pays. Numba's IR-level
    ``inline="always"`` of the whole fused update inside a ``prange`` body costs minutes of
    compile time for no speed."""
    if target.is_cuda:
        return target.device
    return lambda fn: target.kernel(fn, parallel=False, error_model="numpy")
