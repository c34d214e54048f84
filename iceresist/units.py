"""Physical (SI) <-> lattice units and the stability limits a run must respect (docs/SCENES.md, "Rules").

Lattice units take the cell size ``dx``, the time step ``dt`` and the reference
density ``rho0`` as 1. A physical quantity with dimension
``kg^a m^b s^c`` becomes a lattice number by dividing by ``rho0^a' dx^b' dt^c'``
(mass expressed as ``rho0 dx^3``).

Time step: the *lattice velocity limit* ``mach_lattice`` is the largest
velocity allowed in lattice units, ``u_lat = u dt / dx <= mach_lattice``
(default 0.1, i.e. a Mach number ``u_lat / c_s = 0.1 * sqrt(3) ~ 0.17`` against
the lattice sound speed ``c_s = 1/sqrt(3)``). The reference speed is the larger
of the fastest flow speed and, where a water depth ``h`` is given, the
shallow-water wave speed ``sqrt(g h)``, so that surface waves stay well below
the lattice sound speed. Hence ``dt = mach_lattice * dx / u_ref``.

Viscosity: ``tau = 1/2 + 3 nu dt / dx^2`` (``c_s^2 = 1/3``), ``omega = 1/tau``.
Model-scale water gives ``tau - 1/2`` of order 1e-5, which the cumulant
operator (Geier et al. 2015, paper ref. [9]) is meant to take; only values
below ``min_tau_excess`` (default 1e-8) are refused, and values below
``WARN_TAU_EXCESS`` are logged as a warning.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

from iceresist.errors import StabilityError

log = logging.getLogger(__name__)

#: Standard gravity (m/s^2), the one value every module uses.
GRAVITY_M_S2 = 9.81
#: Lattice sound speed squared.
CS2 = 1.0 / 3.0
#: Default lattice velocity limit |u| dt/dx.
MACH_LATTICE = 0.1
#: Largest lattice velocity limit accepted at all (beyond it the weakly compressible model breaks down).
MACH_LATTICE_CEILING = 0.3
#: tau - 1/2 below which a run is refused unless the caller lowers the floor.
MIN_TAU_EXCESS = 1e-8
#: tau - 1/2 below which a warning is logged (BGK would not run; the cumulant operator is meant to).
WARN_TAU_EXCESS = 1e-4


def check_tau(tau: float, *, min_tau_excess: float = MIN_TAU_EXCESS, what: str = "tau") -> float:
    """Refuse ``tau <= 1/2`` or ``tau - 1/2 < min_tau_excess``; warn below :data:`WARN_TAU_EXCESS`. Returns tau."""
    excess = tau - 0.5
    if not math.isfinite(tau) or excess <= 0.0:
        raise StabilityError(
            f"{what} = {tau:.6g} must be > 1/2 (viscosity must be positive): raise the viscosity or refine the time step"
        )
    if excess < min_tau_excess:
        raise StabilityError(
            f"{what} - 1/2 = {excess:.3g} is below the floor {min_tau_excess:.3g}: use {what} >= "
            f"{0.5 + min_tau_excess:.12g}, a coarser cell (larger dx), "
            f"a larger viscosity or a smaller lattice velocity limit (mach), or lower numerics.min_tau_excess"
        )
    if excess < WARN_TAU_EXCESS:
        log.warning("%s - 1/2 = %.3g is below %.0e: only the cumulant operator is expected to stay stable",
                    what, excess, WARN_TAU_EXCESS)
    return tau


def check_lattice_velocity(u_lat: float, mach_lattice: float = MACH_LATTICE, *, what: str = "velocity") -> float:
    """Refuse a lattice velocity ``|u| dt/dx`` above the limit ``mach_lattice``. Returns ``u_lat``."""
    if not 0.0 < mach_lattice <= MACH_LATTICE_CEILING:
        raise StabilityError(
            f"lattice velocity limit mach = {mach_lattice:.3g} must be in (0, {MACH_LATTICE_CEILING}]: "
            f"use the default {MACH_LATTICE}"
        )
    if not math.isfinite(u_lat) or abs(u_lat) > mach_lattice * (1.0 + 1e-12):
        raise StabilityError(
            f"{what} is {abs(u_lat):.4g} in lattice units, above the limit {mach_lattice:.3g}: "
            f"reduce the time step (or let it follow from the Mach limit), or reduce the speed"
        )
    return u_lat


def dem_critical_step_s(mass_kg: float, stiffness_N_m: float) -> float:
    """Critical step of an undamped mass-spring pair, ``2 sqrt(m/k)`` (s)."""
    if mass_kg <= 0.0 or stiffness_N_m <= 0.0:
        raise StabilityError(f"DEM mass ({mass_kg:g} kg) and stiffness ({stiffness_N_m:g} N/m) must be > 0")
    return 2.0 * math.sqrt(mass_kg / stiffness_N_m)


def dem_substeps(dt_s: float, mass_kg: float, stiffness_N_m: float, *, safety: float = 0.2) -> int:
    """Number of DEM sub-steps per fluid step so that each is at most ``safety * 2 sqrt(m/k)``."""
    if not 0.0 < safety <= 1.0:
        raise StabilityError(f"DEM safety factor {safety:g} must be in (0, 1]")
    critical = dem_critical_step_s(mass_kg, stiffness_N_m)
    return max(1, math.ceil(dt_s / (safety * critical) - 1e-12))


@dataclass(frozen=True)
class Units:
    """Scales between SI and lattice units: cell size ``dx_m``, time step ``dt_s``, density ``rho0_kg_m3``.

    ``tau`` is the shear relaxation time of the fluid, ``nu_m2_s`` its kinematic viscosity.
    """

    dx_m: float
    dt_s: float
    rho0_kg_m3: float
    nu_m2_s: float
    tau: float

    # -- construction ---------------------------------------------------------------------------------
    @classmethod
    def from_physical(cls, dx_m: float, nu_m2_s: float, u_max_m_s: float, *, mach_lattice: float = MACH_LATTICE,
                      depth_m: float | None = None, g_m_s2: float = GRAVITY_M_S2, rho0_kg_m3: float = 1000.0,
                      dt_s: float | None = None, min_tau_excess: float = MIN_TAU_EXCESS) -> "Units":
        """Units from SI inputs: ``dt = mach_lattice dx / max(u_max, sqrt(g depth))`` unless ``dt_s`` is given.

        Raises :class:`StabilityError` for tau <= 1/2, tau - 1/2 below ``min_tau_excess``, or a lattice velocity
        above ``mach_lattice`` (only possible with an explicit ``dt_s``).
        """
        if not dx_m > 0.0:
            raise StabilityError(f"cell size dx = {dx_m:g} m must be > 0")
        if not rho0_kg_m3 > 0.0:
            raise StabilityError(f"reference density {rho0_kg_m3:g} kg/m^3 must be > 0")
        u_ref = reference_speed_m_s(u_max_m_s, depth_m=depth_m, g_m_s2=g_m_s2)
        if dt_s is None:
            check_lattice_velocity(0.0, mach_lattice)
            if u_ref <= 0.0:
                raise StabilityError("no speed to set the time step from: give the largest flow speed "
                                     "(numerics.u_max_m_s), a moving face, or a water depth")
            dt_s = mach_lattice * dx_m / u_ref
        else:
            if not dt_s > 0.0:
                raise StabilityError(f"time step dt = {dt_s:g} s must be > 0")
            u_lat = u_ref * dt_s / dx_m
            if u_lat > mach_lattice * (1.0 + 1e-12):
                raise StabilityError(
                    f"numerics.dt_s: {dt_s:.4g} s puts the reference speed max(u_max, sqrt(g h)) = {u_ref:.4g} m/s at "
                    f"{u_lat:.4g} in lattice units, above the limit {mach_lattice:.3g} (numerics.mach): use "
                    f"numerics.dt_s <= {mach_lattice * dx_m / u_ref:.4g} s, or leave it out")
            tau_dt = 0.5 + nu_m2_s * (dt_s / dx_m) / (CS2 * dx_m)    # dx^2 alone underflows at dx ~ 1e-160
            if tau_dt - 0.5 < min_tau_excess:
                raise StabilityError(
                    f"numerics.dt_s: {dt_s:.4g} s gives tau - 1/2 = {tau_dt - 0.5:.3g}, below the floor "
                    f"numerics.min_tau_excess = {min_tau_excess:.3g}: use numerics.dt_s >= "
                    f"{min_tau_excess * CS2 * dx_m * dx_m / nu_m2_s:.4g} s, or leave it out")
        check_lattice_velocity(u_ref * dt_s / dx_m, mach_lattice,
                               what="the reference speed max(u_max, sqrt(g h))")
        tau = 0.5 + nu_m2_s * (dt_s / dx_m) / (CS2 * dx_m)
        check_tau(tau, min_tau_excess=min_tau_excess)
        return cls(dx_m=float(dx_m), dt_s=float(dt_s), rho0_kg_m3=float(rho0_kg_m3), nu_m2_s=float(nu_m2_s),
                   tau=float(tau))

    @classmethod
    def from_lattice(cls, dx_m: float, dt_s: float, rho0_kg_m3: float, tau: float) -> "Units":
        """Scales of a lattice whose cell ``dx_m``, step ``dt_s`` and relaxation time ``tau`` are already chosen
        (the viscosity follows: nu = (tau - 1/2) dx^2 / (3 dt))."""
        for name, v in (("dx_m", dx_m), ("dt_s", dt_s), ("rho0_kg_m3", rho0_kg_m3)):
            if not v > 0.0:
                raise StabilityError(f"{name} must be > 0 (got {v!r})")
        return cls(dx_m=float(dx_m), dt_s=float(dt_s), rho0_kg_m3=float(rho0_kg_m3),
                   nu_m2_s=CS2 * (float(tau) - 0.5) * dx_m * dx_m / dt_s, tau=float(tau))

    @classmethod
    def lattice(cls, *, tau: float | None = None, nu: float | None = None,
                min_tau_excess: float = MIN_TAU_EXCESS) -> "Units":
        """Identity scales (dx = dt = rho0 = 1) for scenes written in lattice units; give ``tau`` or ``nu``."""
        if (tau is None) == (nu is None):
            raise StabilityError("lattice-unit scene: give exactly one of tau and the lattice viscosity nu")
        if tau is None:
            tau = 0.5 + nu / CS2
        check_tau(tau, min_tau_excess=min_tau_excess)
        return cls(dx_m=1.0, dt_s=1.0, rho0_kg_m3=1.0, nu_m2_s=CS2 * (tau - 0.5), tau=float(tau))

    # -- derived --------------------------------------------------------------------------------------
    @property
    def omega(self) -> float:
        """Shear relaxation rate 1/tau."""
        return 1.0 / self.tau

    @property
    def nu_lattice(self) -> float:
        """Kinematic viscosity in lattice units, (tau - 1/2)/3."""
        return CS2 * (self.tau - 0.5)

    @property
    def velocity_scale_m_s(self) -> float:
        return self.dx_m / self.dt_s

    def describe(self) -> dict:
        """Plain numbers for run metadata."""
        return {"dx_m": self.dx_m, "dt_s": self.dt_s, "rho0_kg_m3": self.rho0_kg_m3, "nu_m2_s": self.nu_m2_s,
                "tau": self.tau, "tau_minus_half": self.tau - 0.5, "omega": self.omega}

    # -- SI -> lattice --------------------------------------------------------------------------------
    def length_to_lattice(self, x_m):
        return x_m / self.dx_m

    def time_to_lattice(self, t_s):
        return t_s / self.dt_s

    def velocity_to_lattice(self, u_m_s):
        return u_m_s * (self.dt_s / self.dx_m)

    def acceleration_to_lattice(self, a_m_s2):
        return a_m_s2 * (self.dt_s * self.dt_s / self.dx_m)

    def density_to_lattice(self, rho_kg_m3):
        return rho_kg_m3 / self.rho0_kg_m3

    def pressure_to_lattice(self, p_pa):
        return p_pa * (self.dt_s * self.dt_s / (self.rho0_kg_m3 * self.dx_m ** 2))

    def force_to_lattice(self, f_n):
        return f_n * (self.dt_s * self.dt_s / (self.rho0_kg_m3 * self.dx_m ** 4))

    def force_density_to_lattice(self, f_n_m3):
        """Body-force density (N/m^3) to lattice units."""
        return f_n_m3 * (self.dt_s * self.dt_s / (self.rho0_kg_m3 * self.dx_m))

    def viscosity_to_lattice(self, nu_m2_s):
        return nu_m2_s * (self.dt_s / self.dx_m ** 2)

    def mass_to_lattice(self, m_kg):
        return m_kg / (self.rho0_kg_m3 * self.dx_m ** 3)

    # -- lattice -> SI --------------------------------------------------------------------------------
    def length_to_physical(self, x_lat):
        return x_lat * self.dx_m

    def time_to_physical(self, t_lat):
        return t_lat * self.dt_s

    def velocity_to_physical(self, u_lat):
        return u_lat * (self.dx_m / self.dt_s)

    def acceleration_to_physical(self, a_lat):
        return a_lat * (self.dx_m / (self.dt_s * self.dt_s))

    def density_to_physical(self, rho_lat):
        return rho_lat * self.rho0_kg_m3

    def pressure_to_physical(self, p_lat):
        return p_lat * (self.rho0_kg_m3 * self.dx_m ** 2 / (self.dt_s * self.dt_s))

    def force_to_physical(self, f_lat):
        return f_lat * (self.rho0_kg_m3 * self.dx_m ** 4 / (self.dt_s * self.dt_s))

    def force_density_to_physical(self, f_lat):
        return f_lat * (self.rho0_kg_m3 * self.dx_m / (self.dt_s * self.dt_s))

    def viscosity_to_physical(self, nu_lat):
        return nu_lat * (self.dx_m ** 2 / self.dt_s)

    def mass_to_physical(self, m_lat):
        return m_lat * (self.rho0_kg_m3 * self.dx_m ** 3)


def reference_speed_m_s(u_max_m_s: float, *, depth_m: float | None = None, g_m_s2: float = GRAVITY_M_S2) -> float:
    """The speed that sets the time step: ``max(|u_max|, sqrt(g h))`` (the second only where a depth is given)."""
    u = abs(float(u_max_m_s))
    if depth_m is not None:
        if depth_m < 0.0:
            raise StabilityError(f"water depth {depth_m:g} m must be >= 0")
        u = max(u, math.sqrt(abs(g_m_s2) * depth_m))
    return u
