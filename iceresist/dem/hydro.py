"""Tier-1 hydrodynamics for scenes without a flow field: buoyancy, quadratic drag and added mass.

Still water below a flat plane z = level (gravity along -z):

* Buoyancy: F_B = -rho_w V_sub g at the centre of buoyancy. V_sub sums the body's volume samples (sub-boxes),
  each submerged by the fraction clamp((level - z_k) / (2 h_z) + 1/2, 0, 1), h_z its vertical half extent.
  For a box whose sub-boxes are level this is the exact clipped volume; tilted, it is a close approximation.
* Drag: F_D = -1/2 rho_w C_d A phi |v| v with A = V^(2/3) and phi = V_sub / V; default C_d = 1.05, a cube
  face-on (Hoerner 1965, Fluid-Dynamic Drag, ch. 3). Rotation: T_D = -(C_d / 16) rho_w a^5 phi |w| w, the
  face-on drag integrated over the four faces of a cube of side a = V^(1/3) spinning about a face normal.
* Added mass: m_a = C_a rho_w V_sub added to the inertia of the translation (not to the weight). Default
  C_a = 0.5: the order of the cube's deep-submergence value 0.67 (DNV-RP-H103 (2011), table A-2) reduced
  for a body at the free surface; the floating equilibrium does not depend on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from iceresist.errors import InputError


@dataclass(frozen=True)
class Water:
    """Still water for tier-1 runs (SI units)."""

    level_m: float = 0.0
    density_kg_m3: float = 1000.0
    drag_coefficient: float = 1.05
    added_mass_coefficient: float = 0.5

    def __post_init__(self):
        if self.density_kg_m3 <= 0:
            raise InputError(f"water density_kg_m3 must be positive, got {self.density_kg_m3}")
        if self.drag_coefficient < 0 or self.added_mass_coefficient < 0:
            raise InputError("water drag_coefficient and added_mass_coefficient must be >= 0")

    def row(self, enabled: bool = True) -> np.ndarray:
        return np.array([self.level_m, self.density_kg_m3, self.drag_coefficient, self.added_mass_coefficient,
                         1.0 if enabled else 0.0])


def build_hydro_force(target, real, rotate):
    """``hydro_force(b, ...) -> (Fx, Fy, Fz, Tx, Ty, Tz, m_added)`` on body ``b`` (torque about its centre).

    ``env`` = (level, rho_w, C_d, C_a, on, g_x, g_y, g_z)."""
    zero, half, one, two = real(0), real(0.5), real(1), real(2)
    c16 = real(1.0 / 16.0)
    sqrt = math.sqrt

    @target.device
    def hydro_force(b, bpos, bquat, bvel, bomega, bvolume, blen, bhalf, sfirst, scount, soff, svol, env):
        level = env[0]
        rho = env[1]
        cd = env[2]
        ca = env[3]
        gx = env[5]
        gy = env[6]
        gz = env[7]
        qw = bquat[b, 0]
        qx = bquat[b, 1]
        qy = bquat[b, 2]
        qz = bquat[b, 3]
        r20 = two * (qx * qz - qw * qy)
        r21 = two * (qy * qz + qw * qx)
        r22 = one - two * (qx * qx + qy * qy)
        hz = abs(r20) * bhalf[b, 0] + abs(r21) * bhalf[b, 1] + abs(r22) * bhalf[b, 2]
        zc = bpos[b, 2]
        vsub = zero
        mx = zero
        my = zero
        mz = zero
        for k in range(sfirst[b], sfirst[b] + scount[b]):
            rx, ry, rz = rotate(qw, qx, qy, qz, soff[k, 0], soff[k, 1], soff[k, 2])
            f = (level - (zc + rz)) / (two * hz) + half
            if f > one:
                f = one
            if f > zero:
                w = svol[k] * f
                vsub += w
                mx += w * rx
                my += w * ry
                mz += w * rz
        # buoyancy -rho V g and its torque (sum w r) x (-rho g)
        fbx = -rho * vsub * gx
        fby = -rho * vsub * gy
        fbz = -rho * vsub * gz
        tbx = -rho * (my * gz - mz * gy)
        tby = -rho * (mz * gx - mx * gz)
        tbz = -rho * (mx * gy - my * gx)
        phi = vsub / bvolume[b]
        a = blen[b]
        vx = bvel[b, 0]
        vy = bvel[b, 1]
        vz = bvel[b, 2]
        sp = sqrt(vx * vx + vy * vy + vz * vz)
        kd = -half * rho * cd * a * a * phi * sp
        wx = bomega[b, 0]
        wy = bomega[b, 1]
        wz = bomega[b, 2]
        ws = sqrt(wx * wx + wy * wy + wz * wz)
        kr = -c16 * cd * rho * a * a * a * a * a * phi * ws
        return (fbx + kd * vx, fby + kd * vy, fbz + kd * vz,
                tbx + kr * wx, tby + kr * wy, tbz + kr * wz, ca * rho * vsub)

    return hydro_force
