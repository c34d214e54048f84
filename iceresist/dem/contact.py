"""Linear spring-dashpot contact with a tangential spring capped by Coulomb friction (Cundall and Strack 1979).

Normal: F_n = -(k_n delta + c_n v_n) n on the first sphere, with n pointing from it to the second, delta the
overlap and v_n > 0 when they approach. The dashpot comes from the restitution coefficient e:
zeta = -ln e / sqrt(pi^2 + ln^2 e), c_n = 2 zeta sqrt(m_eff k_n), which gives exactly e and a contact time
t_c = pi / sqrt(k_n/m_eff - (c_n / 2 m_eff)^2) for a head-on collision (no cut-off of the tensile dashpot force,
so the relation is exact; the sphere pair separates when the overlap returns to zero).

Tangential: the accumulated tangential displacement xi (kept per contact pair across steps) is rotated into
the current tangent plane keeping its length, advanced by v_t dt, and F_t = -k_t xi - c_t v_t
(c_t = 2 zeta sqrt(m_eff k_t)); where |F_t| > mu max(F_n, 0) the force is capped and xi reset to -F_t / k_t.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iceresist.errors import InputError


@dataclass(frozen=True)
class ContactParameters:
    """One contact parameter set (SI): normal and tangential stiffness (N/m), restitution, friction."""

    normal_stiffness_N_m: float = 2.0e4
    tangential_stiffness_N_m: float | None = None  # default 2/7 of the normal one (Cundall-Strack practice)
    restitution: float = 0.5
    friction: float = 0.3

    def __post_init__(self):
        if not (self.normal_stiffness_N_m > 0 and np.isfinite(self.normal_stiffness_N_m)):
            raise InputError(f"normal_stiffness_N_m must be positive, got {self.normal_stiffness_N_m}")
        if self.tangential_stiffness_N_m is not None and self.tangential_stiffness_N_m < 0:
            raise InputError(f"tangential_stiffness_N_m must be >= 0, got {self.tangential_stiffness_N_m}")
        if not (0 < self.restitution <= 1):
            raise InputError(f"restitution must lie in (0, 1], got {self.restitution}")
        if self.friction < 0:
            raise InputError(f"friction must be >= 0, got {self.friction}")

    @property
    def k_t(self) -> float:
        kt = self.tangential_stiffness_N_m
        return 2.0 / 7.0 * self.normal_stiffness_N_m if kt is None else float(kt)

    @property
    def damping_ratio(self) -> float:
        """zeta = -ln e / sqrt(pi^2 + ln^2 e) (0 for e = 1)."""
        le = math.log(self.restitution)
        return -le / math.sqrt(math.pi**2 + le * le)

    def row(self) -> list[float]:
        """The row [k_n, k_t, zeta, mu] the kernels read."""
        return [float(self.normal_stiffness_N_m), self.k_t, self.damping_ratio, float(self.friction)]

    def contact_time_s(self, m_eff_kg: float) -> float:
        """Duration of a head-on collision of effective mass m_eff (damped linear oscillator half period)."""
        k = self.normal_stiffness_N_m
        c = 2 * self.damping_ratio * math.sqrt(m_eff_kg * k)
        return math.pi / math.sqrt(k / m_eff_kg - (c / (2 * m_eff_kg)) ** 2)


def build_contact_force(target, real):
    """``contact_force(n, delta, v_rel, m_eff, xi_old, k_n, k_t, zeta, mu, dt)`` -> force on the first body,
    new tangential displacement and elastic energy. ``v_rel`` is the first minus the second body's velocity
    at the contact point; ``n`` points from the first to the second."""
    zero, half, two = real(0), real(0.5), real(2)
    sqrt = math.sqrt

    @target.device
    def contact_force(nx, ny, nz, delta, vrx, vry, vrz, m_eff, xix, xiy, xiz, kn, kt, zeta, mu, dt):
        vn = vrx * nx + vry * ny + vrz * nz
        fn = kn * delta + two * zeta * sqrt(m_eff * kn) * vn
        vtx = vrx - vn * nx
        vty = vry - vn * ny
        vtz = vrz - vn * nz
        # carry the old displacement into the current tangent plane, keeping its length
        xin = xix * nx + xiy * ny + xiz * nz
        rx = xix - xin * nx
        ry = xiy - xin * ny
        rz = xiz - xin * nz
        old2 = xix * xix + xiy * xiy + xiz * xiz
        new2 = rx * rx + ry * ry + rz * rz
        if new2 > zero:
            s = sqrt(old2 / new2)
            rx *= s
            ry *= s
            rz *= s
        xix = rx + vtx * dt
        xiy = ry + vty * dt
        xiz = rz + vtz * dt
        ct = two * zeta * sqrt(m_eff * kt)
        ftx = -kt * xix - ct * vtx
        fty = -kt * xiy - ct * vty
        ftz = -kt * xiz - ct * vtz
        ft = sqrt(ftx * ftx + fty * fty + ftz * ftz)
        cap = mu * fn if fn > zero else zero
        if ft > cap:
            if ft > zero:
                s = cap / ft
                ftx *= s
                fty *= s
                ftz *= s
            if kt > zero:
                xix = -ftx / kt
                xiy = -fty / kt
                xiz = -ftz / kt
            else:
                xix = zero
                xiy = zero
                xiz = zero
        energy = half * (kn * delta * delta + kt * (xix * xix + xiy * xiy + xiz * xiz))
        return (-fn * nx + ftx, -fn * ny + fty, -fn * nz + ftz, xix, xiy, xiz, energy)

    return contact_force
