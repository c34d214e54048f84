"""Collision operators on one cell, built for a target from one source.

Interface shared by every operator (BGK here, the cumulant operator in
``cumulant.py``)::

    collide(f, omega, Fx, Fy, Fz) -> f_post

* ``f``: 27-tuple of populations in the well-conditioned form f_i - w_i rho0,
  lattice units, rho0 = 1 (fewer digits lost in float32);
* ``omega = 1/tau``: the shear relaxation rate;
* ``Fx, Fy, Fz``: body-force density in lattice units (gravity, driving force);
* returns the post-collision 27-tuple, same form.

Macroscopic values use the half-force velocity shift: rho = 1 + sum f,
u = (sum c f + F/2) / rho, so that the momentum the force adds over one step is F.
"""

from __future__ import annotations

from iceresist.lattice import C, Q, W
from iceresist.lbm.codegen import F_NAMES, compile_source, term, unpack


def moments_source(names=F_NAMES) -> str:
    """Source lines computing drho, rho, jx, jy, jz, ux, uy, uz (half-force shift) from 27 scalars."""
    s = f"    drho = {' + '.join(names)}\n"
    s += "    rho = one + drho\n"
    for a, comp in enumerate("xyz"):
        expr = "".join(term(C[q, a], names[q]) for q in range(Q))
        s += f"    j{comp} = zero{expr}\n"
    s += "    inv_rho = one / rho\n"
    for comp in "xyz":
        s += f"    u{comp} = (j{comp} + half * F{comp}) * inv_rho\n"
    return s


def build_collide_bgk(target, real):
    """BGK (single relaxation time) with Guo's forcing (Guo, Zheng and Shi 2002).

    Reference operator for tests: f_i' = f_i + omega (f_i^eq - f_i) + (1 - omega/2) S_i,
    S_i = w_i [3 (c_i - u) + 9 (c_i . u) c_i] . F, f_eq of paper eq. (12).
    """
    src = "def collide_bgk(f, omega, Fx, Fy, Fz):\n" + unpack()
    src += moments_source()
    src += "    uu = ux * ux + uy * uy + uz * uz\n"
    src += "    g = one - half * omega\n"
    outs = []
    for q in range(Q):
        cx, cy, cz = (int(v) for v in C[q])
        cu = "zero" + term(cx, "ux") + term(cy, "uy") + term(cz, "uz")
        cf = "zero" + term(cx, "Fx") + term(cy, "Fy") + term(cz, "Fz")
        src += f"    cu = {cu}\n"
        src += f"    feq = w{q} * (drho + rho * (three * cu + c45 * cu * cu - c15 * uu))\n"
        src += (f"    s = w{q} * g * (three * ({cf} - (ux * Fx + uy * Fy + uz * Fz))"
                f" + nine * cu * ({cf}))\n")
        src += f"    o{q} = f{q} + omega * (feq - f{q}) + s\n"
        outs.append(f"o{q}")
    src += f"    return ({', '.join(outs)})\n"
    ns = {"zero": real(0.0), "one": real(1.0), "half": real(0.5), "three": real(3.0), "nine": real(9.0),
          "c45": real(4.5), "c15": real(1.5)}
    ns.update({f"w{q}": real(W[q]) for q in range(Q)})
    return compile_source(src, "collide_bgk", ns, target.device)
