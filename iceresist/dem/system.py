"""``DEMSystem``: rigid bodies of spheres, walls, contact laws, tier-1 water, and the sub-stepped time step.

State lives in structure-of-arrays on the chosen backend (NumPy arrays on the CPU, device arrays on CUDA) and is
copied to the host only when a property asks for it. All quantities are SI.

Sub-step rule: the critical step of a linear contact is dt_crit = 2 sqrt(m / k) with the
largest stiffness k = max(k_n, k_t) and the smallest pair mass m = m_s,min / 2, where m_s = 1 / (1/m + r^2 / I_min)
is the effective mass a body shows at its sphere at lever arm r (translation plus the softest rotation). A step
``dt`` is cut into ceil(dt / (safety dt_crit)) sub-steps; a forced sub-step above dt_crit is refused with
:class:`~iceresist.errors.StabilityError`. The gather kernel also sums each body's contact force and torque over
the sub-steps of a step (:meth:`DEMSystem.mean_contact_force_on`), so a caller that records a mean over a step
needs no loop of its own.

Dashpot (``dashpot``): ``'sphere_pair'`` gives every sphere pair the dashpot of the bodies' effective mass,
c = 2 zeta sqrt(m_eff k) (:mod:`iceresist.dem.contact`). A flat face of n spheres pressing on another body acts
through n pairs in parallel: stiffness n k but damping n c, a damping ratio sqrt(n) zeta, so a head-on face impact
rebounds far below the restitution asked for (3 x 3 spheres per face, e = 0.5: measured below), and where many pairs
hold two clumps (two cubes of the paper preset interlocked through 12 to 28 pairs) the explicit dashpot outruns the
sub-step: their rotation flips sign every sub-step and grows (the paper preset's A-c88-v1.0 at t = 5.0 s;
docs/notes/paper-preset-substep.md). ``'face'`` divides each body's mass in the dashpot by its
:attr:`~iceresist.dem.bodies.RigidShape.face_pairs`, c = 2 zeta sqrt(m_eff k / n): a face impact of n pairs has the
damping ratio zeta and rebounds with the restitution asked for, and the damping rate of n pairs grows as sqrt(n)
like their stiffness. :meth:`DEMSystem.state` and :meth:`DEMSystem.load_state` carry the contact history,
so a restart continues bit for bit.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from iceresist.backends import jit
from iceresist.dem.bodies import RigidShape, matrix_from_quaternion, quaternion_from_matrix
from iceresist.dem.contact import ContactParameters
from iceresist.dem.hydro import Water
from iceresist.dem.kernels import build_launchers
from iceresist.dem.search import table_size
from iceresist.errors import InputError, StabilityError

log = logging.getLogger(__name__)

MATERIALS = {"ice": 0, "ship": 1, "structure": 1}
#: Dashpot laws (module docstring).
DASHPOTS = ("sphere_pair", "face")

_LAUNCHERS: dict = {}


def _launchers(target, real):
    key = (target.name, target.simulator, np.dtype(real).name)
    if key not in _LAUNCHERS:
        _LAUNCHERS[key] = build_launchers(target, real)
    return _LAUNCHERS[key]


@dataclass
class _Body:
    shape: RigidShape
    position: np.ndarray
    quat: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    kinematic: bool
    material: int
    name: str = ""
    ext_force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ext_torque: np.ndarray = field(default_factory=lambda: np.zeros(3))


def _turn(orientation) -> np.ndarray:
    """The rotation matrix of ``orientation`` (w, x, y, z; None: none)."""
    return np.eye(3) if orientation is None else matrix_from_quaternion(np.asarray(orientation, dtype=float))


def centre_of_mass_m(shape: RigidShape, position_m, orientation=None) -> np.ndarray:
    """Where :meth:`DEMSystem.add_body` puts the centre of mass of ``shape`` (m): the model frame's origin at
    ``position_m``, turned by ``orientation``."""
    return np.asarray(position_m, dtype=float) + _turn(orientation) @ np.asarray(shape.model_com_m, dtype=float)


class DEMSystem:
    """Rigid ice floes and a ship of clumped spheres with Cundall-Strack contacts (paper section 2.3).

    Parameters: ``backend`` ``'cpu'|'cuda'|'auto'``; ``precision`` ``'float64'`` (default: metre positions over
    11 m domains need it) or ``'float32'``; ``gravity_m_s2``; ``ice_ice`` and ``ice_ship`` contact parameter sets
    (``ice_ship`` also serves walls); ``safety`` the sub-step fraction of the critical step; ``history_slots`` the
    number of contacts per sphere whose tangential history is kept; ``dashpot`` ``'sphere_pair'`` or ``'face'`` (see
    the module docstring).
    """

    def __init__(self, backend: str = "cpu", precision: str = "float64", gravity_m_s2=(0.0, 0.0, -9.81),
                 ice_ice: ContactParameters | None = None, ice_ship: ContactParameters | None = None,
                 safety: float = 0.05, history_slots: int = 12, dashpot: str = "sphere_pair"):
        self.target = jit.resolve_backend(backend)
        self.real = jit.real_type(precision)
        self.precision = precision
        self.gravity = np.asarray(gravity_m_s2, dtype=float).reshape(3)
        self.ice_ice = ice_ice or ContactParameters()
        self.ice_ship = ice_ship or ContactParameters()
        if not (0 < safety <= 1):
            raise InputError(f"safety must lie in (0, 1], got {safety}")
        self.safety = float(safety)
        if dashpot not in DASHPOTS:
            raise InputError(f"dashpot must be one of {', '.join(DASHPOTS)}, got {dashpot!r}")
        self.dashpot = dashpot
        self.history_slots = int(history_slots)
        self.water: Water | None = None
        self._bodies: list[_Body] = []
        self._walls: list[np.ndarray] = []
        self._built = False
        self._dirty = True          # no sphere contact forces yet: place, sort and contact before the first kick
        self._loads_stale = False   # the body forces lack new external loads: sum them again before the kick
        self.time_s = 0.0
        self.substeps_taken = 0
        self.last_substeps = 0

    # ------------------------------------------------------------------ scene
    def add_body(self, shape: RigidShape, position_m=(0.0, 0.0, 0.0), velocity_m_s=(0.0, 0.0, 0.0),
                 angular_velocity_rad_s=(0.0, 0.0, 0.0), orientation=None, kinematic: bool = False,
                 material: str = "ice", name: str = "") -> int:
        """Add a body; ``position_m`` places the origin of the shape's model frame, ``orientation`` (w, x, y, z)
        rotates the model frame into the world. Returns the body index."""
        if self._built:
            raise InputError("bodies must be added before the first step of a DEMSystem")
        if material not in MATERIALS:
            raise InputError(f"material must be one of {sorted(MATERIALS)}, got {material!r}")
        R_user = _turn(orientation)
        R_body = R_user @ shape.model_to_body
        com = centre_of_mass_m(shape, position_m, orientation)
        self._bodies.append(_Body(shape=shape, position=com, quat=quaternion_from_matrix(R_body),
                                  velocity=np.asarray(velocity_m_s, dtype=float).copy(),
                                  omega=np.asarray(angular_velocity_rad_s, dtype=float).copy(),
                                  kinematic=bool(kinematic), material=MATERIALS[material], name=name))
        return len(self._bodies) - 1

    def add_wall(self, point_m, normal) -> int:
        """A static plane through ``point_m``; ``normal`` points to the side where bodies live."""
        if self._built:
            raise InputError("walls must be added before the first step of a DEMSystem")
        n = np.asarray(normal, dtype=float)
        n = n / np.linalg.norm(n)
        self._walls.append(np.concatenate([np.asarray(point_m, dtype=float), n]))
        return len(self._walls) - 1

    def set_water(self, water: Water | None = Water()):
        """Switch on (or off with ``None``) tier-1 hydrodynamics for dynamic bodies."""
        self.water = water
        if self._built:
            self._put("env", self._env_row())
            self._loads_stale = True

    def set_external(self, body: int, force_N=None, torque_N_m=None):
        """Hold F_fluid and M_fluid (paper eqs. 13-14) on a body over the sub-steps of the following steps."""
        if self._built:
            ext = self._get("ext").copy()
            if force_N is not None:
                ext[body, :3] = force_N
            if torque_N_m is not None:
                ext[body, 3:] = torque_N_m
            self._put("ext", ext)
            self._loads_stale = True
        else:
            if force_N is not None:
                self._bodies[body].ext_force = np.asarray(force_N, dtype=float)
            if torque_N_m is not None:
                self._bodies[body].ext_torque = np.asarray(torque_N_m, dtype=float)

    def set_external_all(self, force_N, torque_N_m):
        """Hold F_fluid and M_fluid (paper eqs. 13-14, arrays (n_bodies, 3), N and N m) on every body at once over
        the sub-steps of the following steps: one upload, where a call of :meth:`set_external` per body uploads
        the whole table each time."""
        force_N, torque_N_m = np.asarray(force_N, dtype=float), np.asarray(torque_N_m, dtype=float)
        n = self.n_bodies
        if force_N.shape != (n, 3) or torque_N_m.shape != (n, 3):
            raise InputError(f"set_external_all: force and torque of shape ({n}, 3) expected, got "
                             f"{force_N.shape} and {torque_N_m.shape}")
        if not self._built:
            for b, body in enumerate(self._bodies):
                body.ext_force, body.ext_torque = force_N[b].copy(), torque_N_m[b].copy()
            return
        self._put("ext", np.concatenate([force_N, torque_N_m], axis=1))
        self._loads_stale = True

    def set_prescribed_velocity(self, body: int, velocity_m_s):
        """Move the kinematic ``body`` at ``velocity_m_s`` (m/s) from the next sub-step on (a forced oscillation
        changes it every step; a free body is refused)."""
        if not self._bodies[body].kinematic:
            raise InputError(f"set_prescribed_velocity: body {body} is free; only a kinematic body is moved")
        v = np.asarray(velocity_m_s, dtype=float)
        if not self._built:
            self._bodies[body].velocity = v.copy()
            return
        self._h["pvel"][body] = v
        if self.target.is_cuda:
            self._d["pvel"].copy_to_device(self._h["pvel"])

    def device(self, name: str):
        """The target array ``name`` of the system (``pos``, ``quat``, ``vel``, ``omega``, ``ext``, ...; shapes as
        in :meth:`state`), for a coupling that reads the body state and writes the external loads on the target.
        After writing ``ext`` call :meth:`external_loads_changed`."""
        if not self._built:
            self._build()
        return self._d[name]

    def external_loads_changed(self):
        """The external loads (``device("ext")``) were written on the target: the next step sums the body forces
        again (the stored sphere contact forces with the new loads) before its first kick."""
        self._loads_stale = True

    # ------------------------------------------------------------------ build
    @property
    def n_bodies(self) -> int:
        return len(self._bodies)

    @property
    def n_spheres(self) -> int:
        return sum(b.shape.n_spheres for b in self._bodies)

    def _build(self):
        if not self._bodies:
            raise InputError("a DEMSystem needs at least one body")
        real = self.real
        nb = len(self._bodies)
        sh = [b.shape for b in self._bodies]
        counts = np.array([s.n_spheres for s in sh], dtype=np.int64)
        vcounts = np.array([len(s.sample_volumes_m3) for s in sh], dtype=np.int64)
        h = {}
        h["pos"] = np.array([b.position for b in self._bodies], dtype=real)
        h["vel"] = np.array([b.velocity for b in self._bodies], dtype=real)
        h["vpred"] = h["vel"].copy()
        h["quat"] = np.array([b.quat for b in self._bodies], dtype=real)
        h["kin"] = np.array([int(b.kinematic) for b in self._bodies], dtype=np.int32)
        h["mat"] = np.array([b.material for b in self._bodies], dtype=np.int32)
        h["mass"] = np.array([s.mass_kg for s in sh], dtype=real)
        h["inv_mass"] = np.where(h["kin"] != 0, 0.0, 1.0 / h["mass"]).astype(real)
        h["inv_meff"] = h["inv_mass"].copy()
        # the dashpot's inverse masses: per face pair (n / m) with the 'face' dashpot
        npairs = np.array([s.face_pairs if self.dashpot == "face" else 1 for s in sh], dtype=real)
        h["inv_mdamp"] = (h["inv_mass"] * npairs).astype(real)
        h["inertia"] = np.array([s.inertia_kg_m2 for s in sh], dtype=real)
        h["volume"] = np.array([s.volume_m3 for s in sh], dtype=real)
        h["blen"] = h["volume"] ** (1.0 / 3.0)
        h["bhalf"] = np.array([s.sample_half_extent_m for s in sh], dtype=real)
        h["angmom"] = np.zeros((nb, 3), dtype=real)
        h["omega"] = np.zeros((nb, 3), dtype=real)
        h["pvel"] = np.zeros((nb, 3), dtype=real)
        h["pomega"] = np.zeros((nb, 3), dtype=real)
        for k, b in enumerate(self._bodies):
            R = matrix_from_quaternion(b.quat)
            if b.kinematic:
                h["pvel"][k] = b.velocity
                h["pomega"][k] = b.omega
            else:
                h["angmom"][k] = R @ (b.shape.inertia_kg_m2 * (R.T @ b.omega))
            h["omega"][k] = b.omega
        h["ext"] = np.array([np.concatenate([b.ext_force, b.ext_torque]) for b in self._bodies], dtype=real)
        h["force"] = np.zeros((nb, 3), dtype=real)
        h["torque"] = np.zeros((nb, 3), dtype=real)
        h["bcontact"] = np.zeros((nb, 6), dtype=real)
        h["bcsum"] = np.zeros((nb, 6), dtype=real)
        h["bfirst"] = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        h["bcount"] = counts
        h["vfirst"] = np.concatenate([[0], np.cumsum(vcounts)[:-1]]).astype(np.int64)
        h["vcount"] = vcounts
        h["voff"] = np.concatenate([s.sample_offsets_m for s in sh]).astype(real)
        h["vvol"] = np.concatenate([s.sample_volumes_m3 for s in sh]).astype(real)
        ns = int(counts.sum())
        h["soff"] = np.concatenate([s.sphere_offsets_m for s in sh]).astype(real)
        h["srad"] = np.repeat([s.sphere_radius_m for s in sh], counts).astype(real)
        h["sbody"] = np.repeat(np.arange(nb), counts).astype(np.int32)
        h["xs"] = np.zeros((ns, 3), dtype=real)
        nbk = table_size(ns)
        self._mask = nbk - 1
        h["key"] = np.zeros(ns, dtype=np.int32)
        h["start"] = np.zeros(nbk, dtype=np.int32)
        h["count"] = np.zeros(nbk, dtype=np.int32)
        h["cursor"] = np.zeros(nbk, dtype=np.int32)
        h["tally"] = np.zeros(nbk, dtype=np.int32)     # CUDA: spheres per bucket between place and sort, else 0
        h["order"] = np.zeros(ns, dtype=np.int32)
        K = self.history_slots
        for tag in ("a", "b"):
            h["hp_" + tag] = np.full((ns, K), -(2**40), dtype=np.int64)
            h["hxi_" + tag] = np.zeros((ns, K, 3), dtype=real)
            h["hn_" + tag] = np.zeros(ns, dtype=np.int32)
        h["sforce"] = np.zeros((ns, 3), dtype=real)
        h["storque"] = np.zeros((ns, 3), dtype=real)
        h["senergy"] = np.zeros(ns, dtype=real)
        h["snew"] = np.zeros(ns, dtype=np.int64)
        h["sover"] = np.zeros(ns, dtype=np.int64)
        h["scount"] = np.zeros(ns, dtype=np.int64)
        walls = np.array(self._walls, dtype=real) if self._walls else np.zeros((1, 6), dtype=real)
        h["walls"] = walls
        h["params"] = np.array([self.ice_ice.row(), self.ice_ship.row()], dtype=real)
        h["env"] = self._env_row().astype(real)
        self._h = h
        self._inv_cell = 1.0 / (2.0 * float(h["srad"].max()))
        self._cur = "a"
        self._d = {k: self.target.to_device(v) for k, v in h.items()} if self.target.is_cuda else h
        self._k = _launchers(self.target, self.real)
        self._dt_crit = self._critical_step()
        self._built = True
        log.info("DEM system: %d bodies, %d spheres, %d hash buckets, critical step %.3g s", nb, ns, nbk,
                 self._dt_crit)

    def _env_row(self) -> np.ndarray:
        water = self.water or Water()
        return np.concatenate([water.row(enabled=self.water is not None), self.gravity])

    def _put(self, name, value):
        self._h[name][...] = value
        if self.target.is_cuda:
            self._d[name].copy_to_device(self._h[name])

    def _get(self, name) -> np.ndarray:
        if not self._built:
            self._build()
        if self.target.is_cuda:
            return self._d[name].copy_to_host()
        return self._h[name]

    # ------------------------------------------------------------------ stability
    def _critical_step(self) -> float:
        m_min = math.inf
        n_dyn = 0
        for b in self._bodies:
            if b.kinematic:
                continue
            n_dyn += 1
            s = b.shape
            r2 = (s.sphere_offsets_m ** 2).sum(axis=1)
            m_s = 1.0 / (1.0 / s.mass_kg + r2 / s.inertia_kg_m2.min())
            m_min = min(m_min, float(m_s.min()))
        if n_dyn == 0:
            return math.inf
        m_pair = m_min / 2 if n_dyn > 1 else m_min
        k_max = max(max(p.normal_stiffness_N_m, p.k_t) for p in (self.ice_ice, self.ice_ship))
        return 2.0 * math.sqrt(m_pair / k_max)

    def critical_step_s(self) -> float:
        """dt_crit = 2 sqrt(m_pair,min / k_max) (see the module docstring)."""
        if not self._built:
            self._build()
        return self._dt_crit

    def substep_s(self) -> float:
        """The automatic sub-step safety * dt_crit."""
        return self.safety * self.critical_step_s()

    def substeps_for(self, dt_s: float) -> int:
        return max(1, int(math.ceil(dt_s / self.substep_s() - 1e-9)))

    # ------------------------------------------------------------------ time stepping
    def _hist(self, tag):
        d = self._d
        return d["hp_" + tag], d["hxi_" + tag], d["hn_" + tag]

    def _forces(self, h: float, kick: int):
        d, k, r = self._d, self._k, self.real
        ns = len(self._h["srad"])
        k["place"](ns, d["soff"], d["sbody"], d["pos"], d["quat"], d["xs"], d["key"], r(self._inv_cell),
                   np.int64(self._mask), d["tally"])
        k["sort"](ns, d["key"], d["start"], d["count"], d["cursor"], d["order"], d["tally"])
        old = self._hist(self._cur)
        nxt = "b" if self._cur == "a" else "a"
        new = self._hist(nxt)
        k["contact"](ns, d["xs"], d["srad"], d["sbody"], d["pos"], d["vpred"], d["omega"], d["inv_mdamp"], d["kin"],
                     d["mat"], d["start"], d["count"], d["order"], np.int64(self._mask), r(self._inv_cell),
                     d["walls"], np.int64(len(self._walls)), d["params"], r(h), *old, *new, d["sforce"],
                     d["storque"], d["senergy"], d["snew"], d["sover"])
        self._cur = nxt
        self._gather(h, kick)

    def _gather(self, h: float, kick: int):
        """Body forces from the sphere contact forces, the external loads and the water; a kick (``kick`` 1)
        also half-kicks the velocities and adds the contact loads to the sub-step sums."""
        d, r = self._d, self.real
        self._k["gather"](self.n_bodies, r(h), np.int64(kick), d["bfirst"], d["bcount"], d["sforce"], d["storque"],
                          d["mass"], d["kin"], d["ext"], d["env"], d["pos"], d["quat"], d["vel"], d["omega"],
                          d["angmom"], d["volume"], d["blen"], d["bhalf"], d["vfirst"], d["vcount"], d["voff"],
                          d["vvol"], d["bcontact"], d["bcsum"], d["force"], d["torque"], d["inv_meff"])

    def _substep(self, h: float):
        d, r = self._d, self.real
        self._k["drift"](self.n_bodies, r(h), d["pos"], d["vel"], d["vpred"], d["quat"], d["angmom"], d["omega"],
                         d["inertia"], d["inv_meff"], d["kin"], d["pvel"], d["pomega"], d["force"], d["torque"])
        self._forces(h, 1)

    def prime(self):
        """Evaluate contacts and forces at the current state without moving (done before the first step)."""
        if not self._built:
            self._build()
        self._forces(0.0, 0)
        self._dirty = self._loads_stale = False

    def _regather(self):
        """The body forces again from the sphere contact forces of the last sub-step and the loads now (new
        external loads, water): the spheres have not moved since, so their contacts need no second evaluation."""
        self._gather(0.0, 0)
        self._loads_stale = False

    def step(self, dt_s: float, substeps: int | None = None, accumulate: bool = False) -> int:
        """Advance by ``dt_s`` seconds in sub-steps (automatic from the stiffness, or ``substeps`` forced).

        Returns the number of sub-steps. A forced sub-step above the critical step raises StabilityError.
        ``accumulate``: add this step's sub-step contact loads to the sums of the steps before
        (:meth:`contact_sum_on`) instead of starting them anew (a caller averaging over several steps reads them
        once)."""
        if not (dt_s > 0 and math.isfinite(dt_s)):
            raise InputError(f"DEM step dt_s must be a positive number of seconds, got {dt_s}")
        if not self._built:
            self._build()
        if substeps is None:
            n = self.substeps_for(dt_s)
        else:
            n = int(substeps)
            if n < 1:
                raise InputError(f"substeps must be >= 1, got {substeps}")
            h = dt_s / n
            if h > self._dt_crit:
                need = int(math.ceil(dt_s / (self.safety * self._dt_crit)))
                raise StabilityError(
                    f"DEM sub-step {h:.3e} s exceeds the critical step {self._dt_crit:.3e} s = 2 sqrt(m/k) for "
                    f"k = {max(self.ice_ice.normal_stiffness_N_m, self.ice_ship.normal_stiffness_N_m):.3g} N/m: "
                    f"use substeps >= {need} (or leave substeps unset), a smaller dt_s, or softer contacts")
        if self._dirty:
            self.prime()
        elif self._loads_stale:
            self._regather()
        h = dt_s / n
        if not accumulate:
            self.target.fill(self._d["bcsum"], 0)
        for _ in range(n):
            self._substep(h)
        self.time_s += dt_s
        self.substeps_taken += n
        self.last_substeps = n
        return n

    # ------------------------------------------------------------------ checkpoint
    #: Arrays that change while stepping (or through set_external / set_water); everything else follows from
    #: the bodies, walls and parameters the system was built with.
    STATE_ARRAYS = ("pos", "vel", "vpred", "quat", "angmom", "omega", "inv_meff", "pvel", "pomega", "ext", "env",
                    "force", "torque", "bcontact", "bcsum", "xs", "sforce", "storque", "senergy", "snew", "sover")

    def state(self) -> dict[str, np.ndarray]:
        """Everything :meth:`load_state` needs to continue bit for bit: body states, the last forces, the
        tangential springs of the contacts (partner, spring vector, count per sphere), counters and the time.

        A checkpoint fits a system built with the same bodies, walls and parameters in the same order."""
        if not self._built:
            self._build()
        out = {k: np.array(self._get(k), copy=True) for k in self.STATE_ARRAYS}
        hp, hxi, hn = (np.array(self._get(f"{k}_{self._cur}"), copy=True) for k in ("hp", "hxi", "hn"))
        out.update(history_partner=hp, history_spring_m=hxi, history_count=hn)
        out["time_s"] = np.float64(self.time_s)
        out["substeps_taken"] = np.int64(self.substeps_taken)
        out["last_substeps"] = np.int64(self.last_substeps)
        out["primed"] = np.int8(0 if self._dirty else 2 if self._loads_stale else 1)
        return out

    def load_state(self, state: dict):
        """Restore a :meth:`state` taken from a system built the same way (same bodies, walls, precision)."""
        if not self._built:
            self._build()
        names = self.STATE_ARRAYS + ("history_partner", "history_spring_m", "history_count")
        missing = [k for k in names if k not in state]
        if missing:
            raise InputError(f"DEM state lacks {', '.join(missing)}: it was not written by DEMSystem.state()")
        for k in self.STATE_ARRAYS:
            self._load(k, k, state[k])
        for k, name in (("hp", "history_partner"), ("hxi", "history_spring_m"), ("hn", "history_count")):
            self._load(f"{k}_a", name, state[name])
        self._cur = "a"
        self.time_s = float(state["time_s"])
        self.substeps_taken = int(state["substeps_taken"])
        self.last_substeps = int(state["last_substeps"])
        primed = int(state["primed"])  # 0: contacts to evaluate; 1: forces current; 2: loads to sum again
        self._dirty, self._loads_stale = primed == 0, primed == 2

    def _load(self, key, name, value):
        value = np.asarray(value)
        want = self._h[key]
        if value.shape != want.shape:
            raise InputError(f"DEM state {name}: shape {value.shape} does not fit this system's {want.shape} "
                             f"({self.n_bodies} bodies, {self.n_spheres} spheres, {self.history_slots} history "
                             f"slots): build the system as the checkpointed one was built")
        if value.dtype != want.dtype:
            raise InputError(f"DEM state {name}: dtype {value.dtype} is not this system's {want.dtype} "
                             f"(precision {self.precision})")
        self._put(key, value)

    # ------------------------------------------------------------------ state and diagnostics
    @property
    def positions(self) -> np.ndarray:
        """Centres of mass (n_bodies, 3), m."""
        return self._get("pos").astype(float)

    @property
    def velocities(self) -> np.ndarray:
        return self._get("vel").astype(float)

    @property
    def quaternions(self) -> np.ndarray:
        """Orientations (w, x, y, z) of the principal frames."""
        return self._get("quat").astype(float)

    @property
    def angular_momenta(self) -> np.ndarray:
        """World-frame angular momenta (n_bodies, 3), kg m^2/s."""
        return self._get("angmom").astype(float)

    def body_angular_velocities(self) -> np.ndarray:
        """Angular velocities in each body's principal frame (n_bodies, 3), rad/s."""
        q, L = self.quaternions, self.angular_momenta
        inertia = self._h["inertia"].astype(float)
        out = np.empty_like(L)
        for b in range(len(q)):
            out[b] = (matrix_from_quaternion(q[b]).T @ L[b]) / inertia[b]
        return out

    def kinetic_energy(self) -> float:
        """Translational plus rotational kinetic energy of the dynamic bodies, J."""
        dyn = self._h["kin"] == 0
        m = self._h["mass"].astype(float)
        v = self.velocities
        e = 0.5 * (m[dyn] * (v[dyn] ** 2).sum(axis=1)).sum()
        q, L = self.quaternions[dyn], self.angular_momenta[dyn]
        lb = np.einsum("bji,bj->bi", matrix_from_quaternion(q), L)     # angular momentum in the body frame
        return float(e + 0.5 * (lb ** 2 / self._h["inertia"][dyn].astype(float)).sum())

    def potential_energy(self) -> float:
        """Elastic energy stored in the contact springs plus gravity (-m g.x) of the dynamic bodies, J."""
        dyn = self._h["kin"] == 0
        m = self._h["mass"].astype(float)
        grav = -(m[dyn] * (self.positions[dyn] @ self.gravity)).sum()
        return float(self._get("senergy").astype(float).sum() + grav)

    def contact_force_on(self, body: int) -> np.ndarray:
        """Sum of the contact forces on a body's spheres (N) at the last sub-step."""
        return self._get("bcontact")[body, :3].astype(float)

    def contact_torque_on(self, body: int) -> np.ndarray:
        return self._get("bcontact")[body, 3:].astype(float)

    def mean_contact_force_on(self, body: int) -> np.ndarray:
        """Contact force on a body (N) averaged over the sub-steps of the last :meth:`step` call, each sub-step's
        force taken at its end (the value :meth:`contact_force_on` shows after that sub-step); after a step with
        ``accumulate`` use :meth:`contact_sum_on` instead."""
        if self.last_substeps == 0:
            return self.contact_force_on(body)
        return self._get("bcsum")[body, :3].astype(float) / self.last_substeps

    def reset_contact_sums(self):
        """Start the contact sums (:meth:`contact_sum_on`) anew, on the target."""
        if not self._built:
            self._build()
        self.target.fill(self._d["bcsum"], 0)

    def contact_sum_on(self, body: int) -> np.ndarray:
        """Contact force and torque on a body (6,), N and N m, summed over the sub-steps since the last :meth:`step`
        without ``accumulate`` (or :meth:`reset_contact_sums`)."""
        return self._get("bcsum")[body].astype(float)

    def ice_force_on(self, body: int) -> np.ndarray:
        """Ice force on a (ship) body: the contact forces on its spheres, x y z in N (paper section 4.2)."""
        return self.contact_force_on(body)

    def contact_count(self) -> int:
        """Contacts now: sphere pairs once, sphere-wall contacts once (counted per sphere on the target: one
        integer per sphere is read, not the contact history)."""
        if not self._built:
            self._build()
        d = self._d
        self._k["count"](len(self._h["srad"]), d["hp_" + self._cur], d["hn_" + self._cur], d["scount"])
        return int(self._get("scount").sum() // 2)

    def collision_count(self) -> int:
        """Contacts begun since the start (sphere pairs and sphere-wall), a count of collisions."""
        return int(self._get("snew").sum())

    def history_overflows(self) -> int:
        """Contacts whose tangential history found no free slot (raise ``history_slots`` if non-zero)."""
        return int(self._get("sover").sum())

    def describe(self) -> dict:
        """A summary of the system for logs and result files."""
        if not self._built:
            self._build()
        return {
            "backend": self.target.name + ("-simulator" if self.target.simulator else ""),
            "precision": self.precision,
            "bodies": self.n_bodies,
            "kinematic_bodies": int(self._h["kin"].sum()),
            "spheres": self.n_spheres,
            "walls": len(self._walls),
            "hash_buckets": self._mask + 1,
            "cell_size_m": 1.0 / self._inv_cell,
            "critical_step_s": self._dt_crit,
            "substep_s": self.substep_s(),
            "safety": self.safety,
            "dashpot": self.dashpot,
            "gravity_m_s2": self.gravity.tolist(),
            "ice_ice": self.ice_ice.row(),
            "ice_ship": self.ice_ship.row(),
            "water": None if self.water is None else self.water.row().tolist(),
            "time_s": self.time_s,
            "substeps_taken": self.substeps_taken,
        }
