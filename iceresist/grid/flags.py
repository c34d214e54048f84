"""Cell flags (uint8 bit set) and boundary-condition codes of the block forest.

A cell is FLUID or SOLID. A fluid cell also carries one bit per kind of
boundary link it has, so the fused kernel takes a short path (no checks) for
cells whose 26 neighbours are all fluid:

* NEAR_WALL: a link to a solid cell, an unallocated block or a wall-like domain
  face (wall, moving wall, velocity inlet): half-way bounce-back;
* NEAR_OUTLET: a link to a pressure-outlet face: anti-bounce-back.

A link to a free-slip face (``slip``) also sets NEAR_WALL: the kernel reflects it specularly.
"""

from __future__ import annotations

FLUID = 1
SOLID = 2
NEAR_WALL = 4
NEAR_OUTLET = 8
GHOST = 16  # non-fluid cell covered by a moving body; its incoming slots are filled by the coupling
GAS = 32  # free surface: a gas cell (phi < 1/2), not computed; liquid cells pulling from it apply eq. (11)
NEAR_SURFACE = 64  # free surface: a liquid cell with at least one gas neighbour (general path)

#: Boundary-condition codes of the link table (``BlockForest.bc_kind``).
BC_WALL = 0       # resting half-way bounce-back (also solid cells and unallocated blocks)
BC_MOVING = 1     # bounce-back with a wall velocity (moving wall, velocity inlet)
BC_OUTLET = 2     # anti-bounce-back at a prescribed density (pressure outlet)
BC_SLIP = 3       # free-slip wall: specular reflection across the face (iceresist.lbm.boundary)

#: Face kind -> boundary-condition code.
BC_OF_KIND = {"wall": BC_WALL, "moving_wall": BC_MOVING, "velocity_inlet": BC_MOVING, "pressure_outlet": BC_OUTLET,
              "slip": BC_SLIP}

#: Which face wins where a link leaves the domain through an edge or corner shared by two faces:
#: the velocity inlet first, so that the inflow is U * (face area) exactly (each inlet cell takes
#: 6 U sum_{c_x = 1} w_q = U through its links, edge cells included); then resting walls, moving
#: walls, outlets, and free-slip walls last (a slip face reflects only across its own plane, so an edge
#: link shared with any other kind takes the other face's rule).
FACE_PRIORITY = {"velocity_inlet": 0, "wall": 1, "moving_wall": 2, "pressure_outlet": 3, "slip": 4}
