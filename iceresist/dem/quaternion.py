"""Unit quaternions (w, x, y, z) and the free rigid rotor, as scalar device functions.

The orientation quaternion maps body (principal) axes to world axes. The free rotor uses the symplectic,
time-reversible splitting of Dullweber, Leimkuhler and McLachlan (1997, J. Chem. Phys. 107, 5840): the kinetic
energy sum_k L_k^2 / (2 I_k) is split into three exact rotations about the principal axes, applied as
x(h/2) y(h/2) z(h) y(h/2) x(h/2). Each one rotates the body about body axis k by theta = h L_k / I_k and the
body-frame angular momentum back by -theta, so the world angular momentum is unchanged to round-off.
"""

from __future__ import annotations

import math


def build_quaternion(target, real):
    """Return ``(rotate, rotate_inv, mul, free_rotor, spin_world)`` device functions for ``real`` precision."""
    zero, half, one, two = real(0), real(0.5), real(1), real(2)
    sqrt, sin, cos = math.sqrt, math.sin, math.cos

    @target.device
    def rotate(qw, qx, qy, qz, vx, vy, vz):
        """v' = q v q* (body -> world)."""
        tx = two * (qy * vz - qz * vy)
        ty = two * (qz * vx - qx * vz)
        tz = two * (qx * vy - qy * vx)
        return (vx + qw * tx + (qy * tz - qz * ty),
                vy + qw * ty + (qz * tx - qx * tz),
                vz + qw * tz + (qx * ty - qy * tx))

    @target.device
    def rotate_inv(qw, qx, qy, qz, vx, vy, vz):
        """v' = q* v q (world -> body)."""
        return rotate(qw, -qx, -qy, -qz, vx, vy, vz)

    @target.device
    def mul(aw, ax, ay, az, bw, bx, by, bz):
        """Hamilton product a b."""
        return (aw * bw - ax * bx - ay * by - az * bz,
                aw * bx + ax * bw + ay * bz - az * by,
                aw * by - ax * bz + ay * bw + az * bx,
                aw * bz + ax * by - ay * bx + az * bw)

    @target.device
    def normalize(qw, qx, qy, qz):
        s = one / sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        return (qw * s, qx * s, qy * s, qz * s)

    @target.device
    def flow_x(qw, qx, qy, qz, l0, l1, l2, i0, h):
        th = h * l0 / i0
        c = cos(th)
        s = sin(th)
        ch = cos(half * th)
        sh = sin(half * th)
        qw, qx, qy, qz = mul(qw, qx, qy, qz, ch, sh, zero, zero)
        return (qw, qx, qy, qz, l0, c * l1 + s * l2, -s * l1 + c * l2)

    @target.device
    def flow_y(qw, qx, qy, qz, l0, l1, l2, i1, h):
        th = h * l1 / i1
        c = cos(th)
        s = sin(th)
        ch = cos(half * th)
        sh = sin(half * th)
        qw, qx, qy, qz = mul(qw, qx, qy, qz, ch, zero, sh, zero)
        return (qw, qx, qy, qz, c * l0 - s * l2, l1, s * l0 + c * l2)

    @target.device
    def flow_z(qw, qx, qy, qz, l0, l1, l2, i2, h):
        th = h * l2 / i2
        c = cos(th)
        s = sin(th)
        ch = cos(half * th)
        sh = sin(half * th)
        qw, qx, qy, qz = mul(qw, qx, qy, qz, ch, zero, zero, sh)
        return (qw, qx, qy, qz, c * l0 + s * l1, -s * l0 + c * l1, l2)

    @target.device
    def free_rotor(qw, qx, qy, qz, Lx, Ly, Lz, i0, i1, i2, h):
        """Advance the orientation of a free body of world angular momentum L over h (DLM splitting)."""
        l0, l1, l2 = rotate_inv(qw, qx, qy, qz, Lx, Ly, Lz)
        hh = half * h
        qw, qx, qy, qz, l0, l1, l2 = flow_x(qw, qx, qy, qz, l0, l1, l2, i0, hh)
        qw, qx, qy, qz, l0, l1, l2 = flow_y(qw, qx, qy, qz, l0, l1, l2, i1, hh)
        qw, qx, qy, qz, l0, l1, l2 = flow_z(qw, qx, qy, qz, l0, l1, l2, i2, h)
        qw, qx, qy, qz, l0, l1, l2 = flow_y(qw, qx, qy, qz, l0, l1, l2, i1, hh)
        qw, qx, qy, qz, l0, l1, l2 = flow_x(qw, qx, qy, qz, l0, l1, l2, i0, hh)
        return normalize(qw, qx, qy, qz)

    @target.device
    def spin_world(qw, qx, qy, qz, wx, wy, wz, h):
        """Rotate an orientation by the world angular velocity w held over h (exact for constant w)."""
        w = sqrt(wx * wx + wy * wy + wz * wz)
        if w == zero:
            return (qw, qx, qy, qz)
        th = half * w * h
        s = sin(th) / w
        rw, rx, ry, rz = mul(cos(th), wx * s, wy * s, wz * s, qw, qx, qy, qz)
        return normalize(rw, rx, ry, rz)

    @target.device
    def omega_world(qw, qx, qy, qz, Lx, Ly, Lz, i0, i1, i2):
        """omega = R I^-1 R^T L (paper eq. 15)."""
        l0, l1, l2 = rotate_inv(qw, qx, qy, qz, Lx, Ly, Lz)
        return rotate(qw, qx, qy, qz, l0 / i0, l1 / i1, l2 / i2)

    return rotate, rotate_inv, mul, free_rotor, spin_world, omega_world
