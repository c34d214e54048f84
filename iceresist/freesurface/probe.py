"""The watchdog's probe of a free-surface fluid, reduced per block on the target (:mod:`iceresist.watchdog`).

One pass over the cells of each block writes a row of :data:`COLUMNS` into ``out[block]``; the host reduces
the (nblocks, 13) rows. So a probe copies 104 bytes per block off the target instead of the populations, the
velocity and the phase field (about 160 bytes per cell in float64 on the host): at the paper's resolution that
is tens of GB per probe, and on the 2-core CPU it was a fifth of a quick tier-2 case's wall time.

It reads, as :func:`iceresist.models.probe.fluid_probe` does on dense arrays:

* phi finite on every cell;
* on the liquid cells (flag FLUID; a cell a body covers is GHOST): the velocity finite and the fastest cell.
  The ``full`` probe takes rho = 1 + sum_q (f_q - w_q) and u = j / rho + g / 2 (as
  :meth:`FreeSurfaceFluid.macroscopic`) from the populations, in float64, and adds the density band, the
  kinetic energy sum 1/2 rho u^2 and the mass sum rho (the records of a free-surface model read these too,
  :meth:`~iceresist.models.surface.FreeSurfaceModel.diagnostics`); the cheap one reads the velocity the step
  stored for the phase field.

Cells are visited in the dense array's order within a block (x slowest, z fastest), and the host breaks ties
between blocks by the dense index, so the cell named for a maximum, minimum or first bad value is the one
NumPy's ``argmax`` / ``argmin`` / ``argwhere(...)[0]`` names on the dense arrays.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from iceresist import lattice as L
from iceresist.backends.launch import BlockLauncher
from iceresist.freesurface import kernel_key
from iceresist.grid import flags as FL
from iceresist.grid.forest import BLOCK

#: Columns of a block's row: counts, values and the in-block cell index (-1: none) of each.
COLUMNS = ("n_liquid", "n_bad", "bad_cell", "n_bad_phi", "bad_phi_cell", "speed2_max", "speed2_cell",
           "rho_min", "rho_min_cell", "rho_max", "rho_max_cell", "kinetic_energy", "mass")
_COL = {name: i for i, name in enumerate(COLUMNS)}


@lru_cache(maxsize=None)
def probe_launcher(target) -> BlockLauncher:
    """``launch(nblocks, f, fslot, flags, u, phi, full, half_g, out)`` writing the :data:`COLUMNS` of each block
    (``full`` 1 or 0; ``half_g`` = g / 2 added to u_z, lattice units)."""
    f64 = np.float64
    cx, cy, cz = (np.ascontiguousarray(L.C[:, a].astype(np.float64)) for a in range(3))
    fluid = np.uint8(FL.FLUID)
    big = 1e300

    def probe_block(b, f, fslot, flags, u, phi, full, half_g, out):
        s = np.int64(fslot[b])
        n_liq = 0
        n_bad = 0
        bad_c = -1
        n_bad_phi = 0
        bad_phi_c = -1
        s2max = -1.0
        s2c = -1
        rmin = big
        rminc = -1
        rmax = -big
        rmaxc = -1
        ke = 0.0
        mass = 0.0
        for x in range(BLOCK):
            for y in range(BLOCK):
                for z in range(BLOCK):
                    c = x + BLOCK * (y + BLOCK * z)
                    if not math.isfinite(f64(phi[b, c])):
                        n_bad_phi += 1
                        if bad_phi_c < 0:
                            bad_phi_c = c
                    if flags[b, c] & fluid == 0:
                        continue
                    n_liq += 1
                    rho = 1.0
                    if full:
                        acc = 0.0
                        jx = 0.0
                        jy = 0.0
                        jz = 0.0
                        if s >= 0:
                            for q in range(27):
                                fq = f64(f[s, q, c])
                                acc += fq
                                jx += cx[q] * fq
                                jy += cy[q] * fq
                                jz += cz[q] * fq
                        rho = 1.0 + acc
                        ux = jx / rho
                        uy = jy / rho
                        uz = jz / rho + half_g
                    else:
                        ux = f64(u[b, 0, c])
                        uy = f64(u[b, 1, c])
                        uz = f64(u[b, 2, c])
                    if not (math.isfinite(rho) and math.isfinite(ux) and math.isfinite(uy) and math.isfinite(uz)):
                        n_bad += 1
                        if bad_c < 0:
                            bad_c = c
                        continue
                    sp = ux * ux + uy * uy + uz * uz
                    if sp > s2max:
                        s2max = sp
                        s2c = c
                    if rho < rmin:
                        rmin = rho
                        rminc = c
                    if rho > rmax:
                        rmax = rho
                        rmaxc = c
                    ke += 0.5 * rho * sp
                    mass += rho
        out[b, 0] = n_liq
        out[b, 1] = n_bad
        out[b, 2] = bad_c
        out[b, 3] = n_bad_phi
        out[b, 4] = bad_phi_c
        out[b, 5] = s2max
        out[b, 6] = s2c
        out[b, 7] = rmin
        out[b, 8] = rminc
        out[b, 9] = rmax
        out[b, 10] = rmaxc
        out[b, 11] = ke
        out[b, 12] = mass

    return BlockLauncher(target, target.device(probe_block),
                         ("f", "fslot", "flags", "u", "phi", "full", "half_g", "out"), label="probe",
                         cache_key=kernel_key(target, "probe"))


class FluidProbe:
    """The probe of one free-surface fluid: ``probe(f, fslot, flags, u, phi, full, half_g, kinetic_energy_ref)``
    returns the dict of :func:`iceresist.models.probe.fluid_probe` (``full``) or
    :func:`iceresist.models.probe.fluid_speed_probe`, cells as [i, j, k] of the dense grid. ``decomp``: the
    :class:`~iceresist.parallel.decomposition.Decomposition` of a fluid split over MPI ranks: the rows of every
    rank's own blocks are reduced on rank 0 and the result is the same dict on every rank."""

    def __init__(self, forest, target, decomp=None):
        self.forest = forest
        self.target = target
        self.decomp = decomp
        self._launch = probe_launcher(target)
        rows = np.zeros((forest.nblocks, len(COLUMNS)), np.float64)
        self._out = target.to_device(rows)
        self._origin = (forest if decomp is None else decomp.forest).origin * BLOCK

    def rows(self, f, fslot, flags, u, phi, full: bool, half_g: float) -> np.ndarray:
        """The (nblocks, 13) rows of :data:`COLUMNS`, on the host."""
        self._launch(self.forest.nblocks, f, fslot, flags, u, phi, np.int64(bool(full)), np.float64(half_g),
                     self._out)
        return self.target.to_host(self._out)

    def _dense_index(self, blocks, cells):
        """[i, j, k] of (block, in-block cell) pairs and their flat index in the dense (nx, ny, nz) array."""
        blocks, cells = np.asarray(blocks, np.int64), np.asarray(cells, np.int64)
        ijk = self._origin[blocks] + np.stack([cells % BLOCK, (cells // BLOCK) % BLOCK, cells // (BLOCK * BLOCK)],
                                              axis=-1)
        _, ny, nz = self.forest.shape_cells
        return ijk, (ijk[..., 0] * ny + ijk[..., 1]) * nz + ijk[..., 2]

    def _pick(self, rows, value_col, cell_col, sign):
        """(value, [i, j, k]) of the block rows' extreme (``sign`` +1 max, -1 min), ties to the first dense cell."""
        has = rows[:, cell_col] >= 0
        if not has.any():
            return None
        blocks = np.flatnonzero(has)
        v = rows[blocks, value_col]
        best = v.max() if sign > 0 else v.min()
        tied = blocks[v == best]
        ijk, flat = self._dense_index(tied, rows[tied, cell_col])
        i = int(np.argmin(flat))
        return float(best), [int(a) for a in ijk[i]]

    def _first(self, rows, count_col, cell_col):
        blocks = np.flatnonzero(rows[:, count_col] > 0)
        ijk, flat = self._dense_index(blocks, rows[blocks, cell_col])
        return [int(a) for a in ijk[int(np.argmin(flat))]]

    def probe(self, f, fslot, flags, u, phi, full: bool, half_g: float, kinetic_energy_ref: float) -> dict:
        rows = self.rows(f, fslot, flags, u, phi, full, half_g)
        if self.decomp is None:
            return self.reduce(rows, full, kinetic_energy_ref)
        whole = self.decomp.gather_rows(rows)       # the ranks' own blocks in global order, on rank 0
        return self.decomp.bcast(None if whole is None else self.reduce(whole, full, kinetic_energy_ref))

    def reduce(self, rows, full: bool, kinetic_energy_ref: float) -> dict:
        """The probe's dict from the block rows (of the whole forest on several ranks)."""
        if rows[:, _COL["n_bad_phi"]].sum() > 0:
            return {"finite": (False, self._first(rows, _COL["n_bad_phi"], _COL["bad_phi_cell"]))}
        if rows[:, _COL["n_bad"]].sum() > 0:
            return {"finite": (False, self._first(rows, _COL["n_bad"], _COL["bad_cell"]))}
        out = {"finite": (True, None)}
        fastest = self._pick(rows, _COL["speed2_max"], _COL["speed2_cell"], +1)
        if fastest is None:  # no liquid cell: as the dense probe, the first cell of the grid at speed 0
            out["max_lattice_speed"] = (0.0, [0, 0, 0])
        else:
            out["max_lattice_speed"] = (math.sqrt(max(fastest[0], 0.0)), fastest[1])
        if full:
            out["density_min"] = self._pick(rows, _COL["rho_min"], _COL["rho_min_cell"], -1) or (math.inf, [0, 0, 0])
            out["density_max"] = self._pick(rows, _COL["rho_max"], _COL["rho_max_cell"], +1) or (-math.inf, [0, 0, 0])
            out["kinetic_energy"] = float(rows[:, _COL["kinetic_energy"]].sum())
            out["mass"] = float(rows[:, _COL["mass"]].sum())
            out["kinetic_energy_ref"] = float(kinetic_energy_ref)
        return out
