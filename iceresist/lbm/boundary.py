"""Link boundary rules of the pull scheme, in the well-conditioned form f - w (rho0 = 1).

When the source x - c_q of population q at fluid cell x is not fluid, the
population comes back from x itself (the wall sits half-way, half a cell
outside the last fluid cell):

* resting wall, solid cell, unallocated block (half-way bounce-back):
  f_q(x) = f*_opp(q)(x). Because w_q = w_opp(q) the rule holds for f - w as for f.
* moving wall and velocity inlet (bounce-back with a wall velocity u_w, Ladd 1994):
  f_q(x) = f*_opp(q)(x) + 6 w_q rho0 (c_q . u_w). An inlet is a moving wall whose
  velocity is the inflow velocity: it imposes u_w at the half-way face.
* pressure outlet (anti-bounce-back, Ginzburg 2008; Krueger et al. 2017, eq. 5.53):
  F_q(x) = -F*_opp(q)(x) + 2 w_q rho_w [1 + 9/2 (c_q . u)^2 - 3/2 u^2], u the
  velocity of cell x (from its post-collision populations of the previous step,
  half-force shift removed). In the form f = F - w:
  f_q = -f*_opp + 2 w_q [(rho_w - 1) + rho_w (9/2 (c_q . u)^2 - 3/2 u^2)].
  The anti-bounce-back fixes the density at the face to rho_w and lets the
  velocity through; the velocity in the quadratic term is the cell's own, which
  is first-order in the half-cell offset but exact for a uniform outflow.
* free-slip wall (specular reflection; Succi 2001, section 12.4; Krueger et al. 2017, section 5.3.3):
  the population leaves the cell beside x along the face and is mirrored at the face, so that its
  tangential velocity is kept and its normal one reversed: f_q(x) = f*_q'(x - c_t), with c_q' = c_q
  with its normal component negated and c_t the tangential part of c_q. The reflection maps the
  populations that leave through the face one to one onto those that enter, so mass is kept exactly,
  and no tangential momentum goes into the wall (zero shear stress at the half-way face). It reads
  another cell's population, so the fused kernel applies it (``iceresist.lbm.stream``); where the
  cell x - c_t is not fluid (an edge of two faces, a solid) the link falls back to bounce-back.
"""

from __future__ import annotations

from iceresist.grid import flags as FL

#: Flag bit of a non-fluid cell covered by a moving body: the fused kernel pulls from it as from a fluid
#: cell, because a pre-pass of the coupling (:mod:`iceresist.coupling.links`) wrote into its slot q the
#: interpolated bounce-back population f_q that the fluid cell x = y + c_q needs (paper eq. 16).
GHOST = FL.GHOST


def build_link_boundary(target, real, device=None):
    """``link_boundary(fopp, row, bc_kind, bc_u, bc_rho, cx, cy, cz, w, ulx, uly, ulz) -> f_q``.

    ``row`` indexes the boundary table (kind codes of ``iceresist.grid.flags``,
    wall velocity ``bc_u[row]``, density ``bc_rho[row]``, lattice units);
    ``cx, cy, cz, w`` are c_q and w_q as ``real``; ``ul*`` the cell velocity (outlets only).
    ``device``: the decorator to compile with (default ``target.device``).
    """
    zero, one, two, six, c45, c15 = (real(v) for v in (0.0, 1.0, 2.0, 6.0, 4.5, 1.5))
    bc_wall, bc_outlet, bc_slip = FL.BC_WALL, FL.BC_OUTLET, FL.BC_SLIP

    @(device or target.device)
    def link_boundary(fopp, row, bc_kind, bc_u, bc_rho, cx, cy, cz, w, ulx, uly, ulz):
        kind = bc_kind[row]
        if kind == bc_wall or kind == bc_slip:   # slip: a link normal to the face, reflected straight back
            return fopp
        if kind == bc_outlet:
            rho_w = bc_rho[row]
            cu = cx * ulx + cy * uly + cz * ulz
            uu = ulx * ulx + uly * uly + ulz * ulz
            return -fopp + two * w * ((rho_w - one) + rho_w * (c45 * cu * cu - c15 * uu))
        return fopp + six * w * (cx * bc_u[row, 0] + cy * bc_u[row, 1] + cz * bc_u[row, 2]) + zero

    return link_boundary
