"""D3Q27 cumulant collision (Geier, Schönherr, Pasquali and Krafczyk 2015; paper section 2.1).

Same interface as :mod:`iceresist.lbm.collide`::

    collide_cumulant(f, omega, Fx, Fy, Fz) -> f_post

with populations in the well-conditioned form f_i - w_i (rho0 = 1) and the
half-force velocity shift u = (j + F/2) / rho. The body force enters through the
first-order central moments, reflected from -F/2 to +F/2 (Geier et al. 2015,
section 4.3), so one step adds exactly F of momentum.

Relaxation rates: ``omega`` (argument, = 1/tau) for the shear cumulants
(off-diagonal and deviatoric second order), ``omega_bulk`` for the trace of the
second order, ``omega_higher`` for orders 3 to 6, whose equilibrium is zero;
the default 1 sets them to equilibrium as Geier et al. recommend for the
unparametrized method. The code is straight-line, generated once by
:mod:`iceresist.lbm.cumulant_gen`.
"""

from __future__ import annotations

from iceresist.lbm.codegen import compile_source
from iceresist.lbm.cumulant_gen import count_flops, cumulant_source


def generated_source(omega_higher: float = 1.0) -> str:
    """The generated source text of the collision for this ``omega_higher``."""
    return cumulant_source(float(omega_higher) == 1.0)[0]


def flop_count(omega_higher: float = 1.0) -> dict:
    """Arithmetic operations of the generated collision per cell (before compiler optimisation)."""
    return count_flops(generated_source(omega_higher))


def build_collide_cumulant(target, real, *, omega_bulk: float = 1.0, omega_higher: float = 1.0):
    """Compile ``collide_cumulant(f, omega, Fx, Fy, Fz) -> 27-tuple`` for ``target`` in precision ``real``.

    ``omega_bulk`` and ``omega_higher`` are build-time constants in (0, 2).
    """
    for name, value in (("omega_bulk", omega_bulk), ("omega_higher", omega_higher)):
        if not 0.0 < float(value) < 2.0:
            raise ValueError(f"{name} must lie in (0, 2) for a stable relaxation, not {value}")
    src, consts = cumulant_source(float(omega_higher) == 1.0)
    ns = {name: real(value) for name, value in consts.items()}
    ns["omega_b"] = real(omega_bulk)
    ns["omega_h"] = real(omega_higher)
    return compile_source(src, "collide_cumulant", ns, target.device)
