"""The scene file schema: TOML sections as pydantic v2 models; docs/SCENES.md is generated from them.

Every model forbids unknown keys. Key names carry their SI unit (``_m``, ``_s``,
``_m_s``, ``_kg_m3``, ``_N_m``, ...). A scene with ``[scene] units = "lattice"``
is written in lattice units instead: every such key is then read with
dx = dt = rho0 = 1 (the unit suffix is kept so one schema serves both).

Sections ``[free_surface]``, ``[ship]``, ``[ice]``, ``[contact]`` and
``[[bodies]]`` are optional; a scene that leaves one out gets ``None`` (or an
empty list) and the model builder allocates nothing for it. Cross-key rules
raise ``ValueError("key: message")`` (``section.key`` from the root); the loader turns them into one line
``file: section.key: message``.
"""

from __future__ import annotations

import logging
import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, field_validator, model_validator

from iceresist.ship.cases import CASES, FIDELITIES
from iceresist.units import MACH_LATTICE, MACH_LATTICE_CEILING, MIN_TAU_EXCESS, Units, check_lattice_velocity

log = logging.getLogger(__name__)

Vec3 = tuple[float, float, float]
PositiveFloat = Annotated[float, Field(gt=0)]
FACE_KINDS = ("periodic", "wall", "moving_wall", "velocity_inlet", "pressure_outlet", "slip")
FACE_NAMES = ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")
FIELD_NAMES = ("rho", "u", "pressure", "flags", "phi", "surface")


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_default=True, allow_inf_nan=False)


def _norm(v) -> float:
    return math.sqrt(sum(float(c) * float(c) for c in v))


# ---------------------------------------------------------------------------------------------------------
class CaseBase(_Section):
    """``[case]`` (optional): start from a ship case of the paper's sweep matrix (:mod:`iceresist.scene.case_scenes`,
    docs/SHIP.md) at a fidelity and tier. The file's other sections then change only the keys they name and
    keep the case's others (e.g. ``[domain] cells``/``dx_m`` for a finer grid, ``[ice] channel_length_m`` for a
    longer channel); a section the case does not have is added whole."""

    name: str = Field(..., description="Case name `<bow>-c<percent>-v<knots>`: "
                                       + ", ".join(f"`{c}`" for c in CASES) + ".")
    fidelity: Literal[tuple(FIDELITIES)] = Field("quick", description="Preset fidelity (docs/SHIP.md).")
    tier: Literal[1, 2] = Field(1, description="1 = DEM with water models; 2 = the coupled LBM-DEM.")
    amr: bool = Field(False, description="Tier 2 on the preset's refined levels (its `[tier2.<fidelity>.amr]` "
                      "in iceresist/ship/cases.toml: the hull, the ice and the surface on the finest level, the deep "
                      "water coarser; docs/SHIP.md).")

    @field_validator("name")
    @classmethod
    def _known_case(cls, v):
        if v not in CASES:
            raise ValueError(f"unknown case {v!r}; known cases: {', '.join(CASES)}")
        return v


class SceneInfo(_Section):
    """``[scene]``: what the case is and which unit system its numbers are in."""

    name: str = Field("scene", pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$", max_length=100,
                      description="Case name; names the result file `<name>.h5`. Letters, digits, `_ . -`, "
                                  "starting with a letter, digit or `_`.")
    description: str = Field("", description="Free text stored in the result file.")
    units: Literal["physical", "lattice"] = Field(
        "physical", description="`physical`: SI units. `lattice`: every number in lattice units (dx = dt = rho0 = 1).")


class Face(_Section):
    """One domain face: its boundary condition."""

    kind: Literal[FACE_KINDS] = Field("wall", description="Boundary condition: " + ", ".join(FACE_KINDS) + " "
                                      "(`wall`: no-slip; `slip`: free-slip, specular reflection).")
    velocity_m_s: Vec3 = Field((0.0, 0.0, 0.0),
                               description="Wall or inlet velocity (m/s); only for `moving_wall` and `velocity_inlet`.")
    density_kg_m3: float | None = Field(None, gt=0,
                                        description="Outlet density (kg/m^3); only for `pressure_outlet`. "
                                                    "Default: the fluid density.")

    @model_validator(mode="after")
    def _kind_uses_its_keys(self):
        if any(self.velocity_m_s) and self.kind not in ("moving_wall", "velocity_inlet"):
            raise ValueError(f"velocity_m_s: only a moving_wall or velocity_inlet face has a velocity "
                             f"(this face is {self.kind})")
        if self.density_kg_m3 is not None and self.kind != "pressure_outlet":
            raise ValueError(f"density_kg_m3: only a pressure_outlet face has a density (this face is {self.kind})")
        return self


class Faces(_Section):
    """``[domain.faces]``: one boundary condition per face; write ``x_min = "periodic"`` or a table."""

    x_min: Face = Field(Face(), description="Face at x = 0.")
    x_max: Face = Field(Face(), description="Face at x = L_x.")
    y_min: Face = Field(Face(), description="Face at y = 0.")
    y_max: Face = Field(Face(), description="Face at y = L_y.")
    z_min: Face = Field(Face(), description="Face at z = 0 (bottom; gravity points to -z).")
    z_max: Face = Field(Face(), description="Face at z = L_z (top).")

    @field_validator(*FACE_NAMES, mode="before")
    @classmethod
    def _kind_shorthand(cls, v):
        return {"kind": v} if isinstance(v, str) else v

    @model_validator(mode="after")
    def _consistent(self):
        for axis, a in zip("xyz", range(3)):
            lo, hi = getattr(self, f"{axis}_min"), getattr(self, f"{axis}_max")
            if (lo.kind == "periodic") != (hi.kind == "periodic"):
                raise ValueError(f"{axis}_min: periodic faces come in pairs: set both {axis}_min and {axis}_max "
                                 f"periodic, or neither")
            for side, face in ((f"{axis}_min", lo), (f"{axis}_max", hi)):
                if face.kind == "moving_wall" and face.velocity_m_s[a] != 0.0:
                    raise ValueError(f"{side}: a moving_wall slides in its own plane: velocity_m_s[{a}] must be 0")
        return self

    def items(self):
        return [(n, getattr(self, n)) for n in FACE_NAMES]


class Domain(_Section):
    """``[domain]``: the box, its resolution and its faces. Give ``cells`` or ``size_m``, and ``dx_m``."""

    size_m: tuple[PositiveFloat, PositiveFloat, PositiveFloat] | None = Field(
        None, description="Box size [L_x, L_y, L_z] (m); rounded to whole cells of dx_m.")
    cells: tuple[Annotated[int, Field(ge=1)], Annotated[int, Field(ge=1)], Annotated[int, Field(ge=1)]] | None = Field(
        None, description="Number of cells [n_x, n_y, n_z] (instead of size_m).")
    dx_m: float | None = Field(None, gt=0, description="Cell size (m). Required in physical units; 1 in lattice units.")
    faces: Faces = Field(Faces(), description="Boundary conditions, see `[domain.faces]`.")
    pad_to_blocks: bool = Field(False, description="Round the grid up to whole 8x8x8 blocks with solid cells "
                                "beyond x_max, y_max and z_max, so that the box keeps its size at any dx_m (the "
                                "solid cells are a no-slip wall at the box's edge: a face that is padded must be "
                                "a `wall`). Fluid scenes, with or without `[[bodies]]`; not with `[free_surface]`.")

    @model_validator(mode="after")
    def _one_extent(self):
        if (self.size_m is None) == (self.cells is None):
            raise ValueError("cells: give exactly one of cells and size_m")
        if self.size_m is not None and self.dx_m is None:
            raise ValueError("dx_m: size_m needs the cell size dx_m")
        if self.pad_to_blocks:
            for axis, n in zip("xyz", self.shape_cells()):
                face = getattr(self.faces, f"{axis}_max")
                if n % 8 and face.kind != "wall":
                    raise ValueError(f"faces.{axis}_max: the grid is padded with solid cells beyond {axis}_max "
                                     f"({n} cells along {axis}), which act as a no-slip wall: set "
                                     f"{axis}_max = \"wall\", or give a multiple of 8 cells along {axis}")
        return self

    def padded_cells(self) -> tuple[int, int, int]:
        """The grid's cells along x, y, z: :meth:`shape_cells`, rounded up to whole 8-cell blocks where
        ``pad_to_blocks`` is set."""
        shape = self.shape_cells()
        return tuple(-(-n // 8) * 8 for n in shape) if self.pad_to_blocks else shape

    def shape_cells(self) -> tuple[int, int, int]:
        """(n_x, n_y, n_z): ``cells``, or ``size_m / dx_m`` rounded to whole cells."""
        if self.cells is not None:
            return tuple(int(n) for n in self.cells)
        dx = self.dx_m
        shape = tuple(max(1, int(round(s / dx))) for s in self.size_m)
        if any(abs(n * dx - s) > 1e-9 * max(s, 1.0) for n, s in zip(shape, self.size_m)):
            log.info("domain size %s m rounded to %s cells of %g m", self.size_m, shape, dx)
        return shape


class Fluid(_Section):
    """``[fluid]``: the liquid and the forces on it."""

    nu_m2_s: float | None = Field(None, gt=0, description="Kinematic viscosity (m^2/s); water at 20 C: 1.0e-6. "
                                                          "Lattice scenes may give numerics.tau instead.")
    rho_kg_m3: float | None = Field(None, gt=0, description="Density (kg/m^3). Default 1000 (physical), 1 (lattice).")
    operator: Literal["cumulant", "bgk"] = Field(
        "cumulant", description="Collision operator: `cumulant` (Geier et al. 2015) or `bgk` (reference).")
    initial_velocity_m_s: Vec3 = Field((0.0, 0.0, 0.0), description="Uniform velocity at t = 0 (m/s).")
    gravity_m_s2: Vec3 = Field((0.0, 0.0, 0.0), description="Gravitational acceleration (m/s^2), e.g. [0, 0, -9.81].")
    body_force_N_m3: Vec3 = Field((0.0, 0.0, 0.0),
                                  description="Uniform driving force density (N/m^3), e.g. a pressure gradient.")


class Numerics(_Section):
    """``[numerics]``: precision, backend and the step-size limits."""

    precision: Literal["float32", "float64"] = Field("float32", description="Storage and arithmetic precision.")
    backend: Literal["auto", "cpu", "cuda"] = Field("auto", description="`auto` takes CUDA where a GPU is visible.")
    mach: float = Field(MACH_LATTICE, gt=0, le=MACH_LATTICE_CEILING,
                        description="Lattice velocity limit: the reference speed in lattice units, u dt/dx.")
    u_max_m_s: float | None = Field(None, gt=0, description="Largest flow speed expected (m/s), e.g. of a "
                                                            "force-driven flow; the speeds the scene names (faces, "
                                                            "initial flow, ship, bodies) count too.")
    dt_s: float | None = Field(None, gt=0, description="Time step (s). Default: from the lattice velocity limit.")
    tau: float | None = Field(None, gt=0.5, description="Shear relaxation time (lattice scenes only; "
                                                        "instead of fluid.nu_m2_s).")
    min_tau_excess: float = Field(MIN_TAU_EXCESS, gt=0, description="Smallest tau - 1/2 accepted.")
    check_limits: bool = Field(True, description="Refuse settings beyond the measured limits of the collision "
                                                 "operator (cell Reynolds number, lattice speed; docs/VALIDATION.md). "
                                                 "`false` runs them anyway; the run watchdog still stops a run "
                                                 "that goes unstable.")


class RunSettings(_Section):
    """``[run]``: when to stop. At least one of ``steps`` and ``end_time_s``; the first reached stops the run."""

    steps: int | None = Field(None, ge=0, description="Number of time steps.")
    end_time_s: float | None = Field(None, ge=0, description="Simulated time to stop at (s).")
    wall_time_limit_s: float | None = Field(None, gt=0, description="Stop (with output written) after this wall time.")
    watchdog_every_steps: int | None = Field(None, ge=1, description="Check for NaN, runaway speed, density out of "
                                             "band and kinetic-energy growth every N steps, and stop the run with a "
                                             "diagnostic. Default: 100 (fluid), 1 (ship scenes, tiers 1 and 2: one "
                                             "step = one record; tier 2 reads the density band and the kinetic "
                                             "energy at every tenth check).")

    @model_validator(mode="after")
    def _a_stop(self):
        if self.steps is None and self.end_time_s is None:
            raise ValueError("steps: give steps or end_time_s")
        return self


class Output(_Section):
    """``[output]``: where results go and how often."""

    directory: str = Field("runs", min_length=1, max_length=1000,
                           description="Result folder, relative to the working directory and below it (`runs`, "
                                       "`my runs/case 1`); `iceresist run --output DIR` names a folder elsewhere.",
                           json_schema_extra={"allowed": "a folder below the working one: not absolute, no `..`"})

    @field_validator("directory")
    @classmethod
    def _below_working_folder(cls, v: str):
        """A scene writes only below the folder it runs in (docs/SCENES.md): a relative path without ``..``."""
        if not v.strip():
            raise ValueError('must not be blank; give a folder, e.g. "runs"')
        if any(ord(ch) < 32 for ch in v):
            raise ValueError('holds a control character; give a folder, e.g. "runs"')
        parts = v.replace("\\", "/").split("/")
        if v.startswith(("/", "\\", "~")) or (len(v) > 1 and v[1] == ":"):
            raise ValueError(f"{v[:60]!r} is not below the working folder: a scene writes only there; "
                             f"give a relative folder such as \"runs\", or name a folder elsewhere with iceresist "
                             f"run --output")
        if ".." in parts:
            raise ValueError(f"{v[:60]!r} climbs out of the working folder ('..'): a scene writes only "
                             f"below it; give a relative folder such as \"runs\", or name a folder elsewhere with "
                             f"iceresist run --output")
        return v

    fields: list[Literal[FIELD_NAMES]] = Field(["rho", "u", "flags"], description="Fields in each snapshot: "
                                               + ", ".join(f"`{n}`" for n in FIELD_NAMES) + ".")
    fields_every_steps: int | None = Field(None, ge=1, description="Snapshot every N steps (and at the end). "
                                                                    "Neither this nor fields_every_s: at the end only.")
    fields_every_s: float | None = Field(None, gt=0, description="Snapshot every t seconds of simulated time.")
    timeseries_every_steps: int = Field(10, ge=1, description="Diagnostics row (mass, kinetic energy, max |u|) "
                                                              "every N steps.")
    checkpoint_every_steps: int | None = Field(None, ge=1, description="Checkpoint every N steps (a checkpoint "
                                                                        "is always written at the end).")
    checkpoint_wall_s: float | None = Field(None, gt=0, description="Checkpoint every t seconds of wall time. "
                                                                     "Neither key: every 600 s of wall time.")

    @model_validator(mode="after")
    def _one_field_schedule(self):
        if self.fields_every_steps is not None and self.fields_every_s is not None:
            raise ValueError("fields_every_s: give at most one of fields_every_steps and fields_every_s")
        if self.checkpoint_every_steps is not None and self.checkpoint_wall_s is not None:
            raise ValueError("checkpoint_wall_s: give at most one of checkpoint_every_steps and checkpoint_wall_s")
        return self


# ---------------------------------------------------------------------------------------------------------
# Optional sections (later engine components). A scene without them builds none of their state.
class FreeSurface(_Section):
    """``[free_surface]``: phase-field free surface (paper section 2.2, eqs. 4-11)."""

    water_depth_m: float = Field(..., gt=0, description="Still-water depth measured from z = 0 (m), below the top "
                                                        "of the domain.")
    mobility_lattice: float = Field(0.02, gt=0, description="Interface mobility M in lattice units (eq. 4, 10).")
    interface_width_cells: float = Field(3.0, ge=2, description="Interface thickness W in cells (eq. 4).")
    h_lattice: Literal["D3Q7", "D3Q15", "D3Q19", "D3Q27"] = Field(
        "D3Q15", description="Velocity set of the phase-field populations h (eqs. 5-8); D3Q15 is the measured "
                             "choice (docs/VALIDATION.md).")
    column_length_m: float | None = Field(None, gt=0, description="Dam break: water only over x < "
                                                                  "column_length_m (m), the rest of the floor "
                                                                  "dry. Default: water over the whole floor.")
    f_pool_margin: float | Literal["full"] = Field(
        0.25, description="Spare rows of LBM populations, as a fraction of the blocks holding water at the "
                          "start (blocks wholly in the gas hold none); `\"full\"`: populations in every block. "
                          "When the water spreads over more blocks the pool grows (its buffers are copied once), so "
                          "a larger margin only saves that copy.")

    @field_validator("f_pool_margin")
    @classmethod
    def _margin(cls, v):
        if v != "full" and not v >= 0:
            raise ValueError("f_pool_margin must be >= 0 or \"full\"")
        return v


class Ship(_Section):
    """``[ship]``: the hull and its prescribed constant speed along +x (paper section 3).

    The built-in `b063` hull is the NMRI double-ended model ship of the paper, built from these parameters
    as a convex polyhedron (docs/SHIP.md): wall sides, a parallel middle body, wedge ends of waterline
    half angle `waterline_angle_deg` and plane bow faces raked at `bow_angle_deg` (stern: `stern_angle_deg`).
    """

    hull: Literal["b063", "mesh"] = Field("b063", description="`b063`: the NMRI model ship of the paper, from the "
                                          "parameters below; `mesh`: the closed surface in `mesh_file`.")
    mesh_file: str | None = Field(None, description="Hull mesh (STL or OBJ) for `hull = \"mesh\"`: a path (relative to "
                                  "the scene file) or a built-in mesh (`b063`: the B-063 model with Bow A at +x).")
    mesh_unit: Literal["m", "cm", "mm", "ft", "in"] = Field("m", description="Unit of the mesh's coordinates.")
    mesh_bow: Literal["+x", "-x", "+y", "-y"] = Field("+x", description="The mesh's axis toward the bow.")
    mesh_up: Literal["+x", "-x", "+y", "-y", "+z", "-z"] = Field("+z", description="The mesh's upward axis. The keel "
                                                                 "is put at z = 0 and the centreline at y = 0.")
    mesh_scale: float = Field(1.0, gt=0, description="The mesh's lengths (in `mesh_unit`) are divided by this: 25 "
                              "runs a full-scale mesh as a 1:25 model (`draught_m` is the model's).")
    bow_angle_deg: float = Field(30.0, gt=0, lt=90, description="Stem rake of the bow going ahead (deg): "
                                                               "30 = Bow A, 45 = Bow B.")
    stern_angle_deg: float | None = Field(None, gt=0, lt=90, description="Stem rake of the other end (deg). "
                                          "Default: the other B-063 bow (45 for Bow A, 30 for Bow B).")
    length_m: float = Field(3.5, gt=0, description="Length overall, at the deck (m).")
    beam_m: float = Field(0.7, gt=0, description="Beam (m).")
    draught_m: float = Field(0.44, gt=0, description="Draught (m); B-063: 11.0 m / 25.")
    parallel_length_m: float = Field(1.828, ge=0, description="Length of the parallel middle body (m); "
                                                              "B-063: 45.7 m / 25.")
    waterline_angle_deg: float = Field(30.0, gt=0, lt=90, description="Half angle of the waterline at the "
                                                                      "ends (deg), alpha of FSICR.")
    speed_m_s: float = Field(..., ge=0, description="Ship speed (m/s); 1 knot = 0.514 m/s.")
    start_x_m: float | None = Field(None, description="x of the stem at the waterline at t = 0 (m). "
                                                      "Default: 0.05 m before the ice channel.")
    centre_y_m: float | None = Field(None, description="y of the centreline (m). Default: the middle of the domain.")
    tier: Literal[1, 2] = Field(1, description="Fidelity: 1 = DEM with water models (no flow field), "
                                               "2 = coupled LBM-DEM (paper's method).")
    sphere_spacing_m: float = Field(0.02, gt=0, description="DEM sphere spacing on the hull surface (m).")
    sphere_band_m: float = Field(0.1, gt=0, description="Hull spheres are kept up to this height above the "
                                                        "waterline (m); the dry upper hull never meets the ice.")
    steady_window_m: tuple[float, float] | None = Field(
        None, description="Stem positions x (m) of the steady window for the mean resistance. Default: from "
                          "the channel start plus the waterline length (whole ship in the ice) to the channel "
                          "end; for a channel shorter than the ship, from the channel start plus one bow length.")

    @model_validator(mode="after")
    def _window(self):
        if self.hull == "mesh" and not self.mesh_file:
            raise ValueError("mesh_file: a mesh hull needs its file, e.g. mesh_file = \"hull.stl\" (or \"b063\")")
        if self.hull != "mesh" and self.mesh_file:
            raise ValueError("hull: mesh_file is given; set hull = \"mesh\" to use it")
        w = self.steady_window_m
        if w is not None and not w[1] > w[0]:
            raise ValueError("steady_window_m: give [x0, x1] with x1 > x0")
        return self


class Ice(_Section):
    """``[ice]``: a brash-ice channel of floating cubes (paper section 3). Give ``concentration`` or ``count``.

    Cubes sit on a regular pattern (docs/SHIP.md): 68 % gives 28 x 112 = 3136 cubes and 88 % gives
    32 x 128 = 4096 in the paper's 1.39 m x 5.56 m channel; 50 % gives 24 x 96 = 2304 (the paper's 2034 is
    read as a misprint; `count = 2034` reproduces it literally). With `size_distribution`, an ice field instead:
    square floes of edges drawn from the distribution, `thickness_m` thick, packed without overlap to
    `concentration` with random yaw (docs/SHIP.md, "Ice fields").
    """

    size_m: float = Field(0.041, gt=0, description="Cube edge (m).")
    density_kg_m3: float = Field(950.0, gt=0, description="Ice density (kg/m^3).")
    concentration: float | None = Field(None, gt=0, le=1, description="Area fraction of the channel covered.")
    count: int | None = Field(None, ge=1, description="Number of cubes (instead of concentration).")
    channel_width_m: float | None = Field(None, gt=0, description="Channel width (m). Default: the domain width.")
    channel_length_m: float = Field(5.56, gt=0, description="Channel length (m).")
    channel_start_x_m: float = Field(4.0, description="x where the channel begins (m).")
    arrangement: Literal["regular", "random"] = Field(
        "regular", description="`regular` grid, or `random`: the grid with every cube moved by a random offset "
                               "of up to half the gap.")
    jitter_m: float | None = Field(None, ge=0, description="Random offset of each cube in x and y (m), capped "
                                                           "at half the gap. Default: 0 (regular), half the gap "
                                                           "(random).")
    seed: int = Field(0, ge=0, description="Random seed for `random` placement and jitter.")
    spheres_per_edge: int = Field(3, ge=2, description="DEM spheres along a cube edge (clumped-sphere body).")
    drag_coefficient: float = Field(1.05, ge=0, description="Tier 1: quadratic drag coefficient of a floe.")
    added_mass_coefficient: float = Field(0.5, ge=0, description="Tier 1: added-mass coefficient of a floe.")
    size_distribution: Literal["none", "uniform", "lognormal"] = Field(
        "none", description="`none`: cubes of `size_m`; `uniform`: floe edges uniform in [`size_min_m`, "
                            "`size_max_m`]; `lognormal`: median `size_m`, log-standard deviation `size_sigma`, cut "
                            "to [`size_min_m`, `size_max_m`].")
    size_min_m: float | None = Field(None, gt=0, description="Smallest floe edge (m). Default: `size_m` (uniform), "
                                                             "`size_m` / 2 (lognormal).")
    size_max_m: float | None = Field(None, gt=0, description="Largest floe edge (m). Default: `size_m` (uniform), "
                                                             "2 `size_m` (lognormal).")
    size_sigma: float = Field(0.3, gt=0, description="Lognormal: standard deviation of ln(edge).")
    thickness_m: float | None = Field(None, gt=0, description="Floe thickness (m) of a size distribution. "
                                                              "Default: `size_m`.")
    yaw: Literal["random", "none"] = Field("random", description="Floes of a size distribution: `random` yaw "
                                           "within what the packing leaves room for, or `none`.")

    @model_validator(mode="after")
    def _amount(self):
        if (self.concentration is None) == (self.count is None):
            raise ValueError("concentration: give exactly one of concentration and count")
        if self.size_distribution != "none" and self.count is not None:
            raise ValueError("count: a size distribution is packed to a concentration; give concentration instead")
        return self


class Contact(_Section):
    """``[contact]``: DEM spring-dashpot contact law with Coulomb friction (paper section 2.3)."""

    stiffness_N_m: float = Field(1.0e4, gt=0, description="Normal spring stiffness (N/m).")
    tangential_stiffness_ratio: float = Field(2.0 / 7.0, gt=0, le=1, description="Tangential / normal stiffness.")
    restitution: float = Field(0.3, gt=0, le=1, description="Normal coefficient of restitution (sets the dashpot).")
    friction_ice_ice: float = Field(0.3, ge=0, description="Coulomb friction coefficient, ice on ice.")
    friction_ice_hull: float = Field(0.1, ge=0, description="Coulomb friction coefficient, ice on hull.")
    dem_safety: float = Field(0.2, gt=0, le=0.4, description="DEM sub-step as a fraction of the critical "
                              "2 sqrt(m/k). Measured on the quick tier-1 case A-c68-v1.0: 0.4 runs to the end, 0.5 "
                              "to 1.0 run away within 70-230 records (clumps of spheres, damping and friction make "
                              "the stable sub-step shorter than the undamped 2 sqrt(m/k)).")
    dashpot: Literal["sphere_pair", "face"] = Field(
        "sphere_pair", description="'sphere_pair': every sphere pair gets the dashpot of the bodies' masses, so a "
        "flat face of n spheres in contact has sqrt(n) times the damping ratio of the restitution (restitution 0.5: "
        "a face impact of 2 x 2 spheres rebounds at 0.22, of 3 x 3 at 0.07). 'face': the masses in the dashpot "
        "divided by the spheres on a body's largest face, so a face impact rebounds with the restitution, and "
        "clumps held by many sphere pairs stay stable at the sub-step (iceresist.dem.system). Both ship presets "
        "use 'face'.")
    fluid_film: bool = Field(True, description="Tier 2: a face in contact with another body or a wall keeps the "
                             "water pressure around it (a film of water; without it a submerged floe is pressed "
                             "onto the hull by the missing pressure).")
    sample_interval_s: float = Field(0.005, gt=0, description="Tier 1: interval of the recorded ice force (s); "
                                                              "each record is the mean over its DEM sub-steps.")


class Oscillation(_Section):
    """``bodies[].oscillation`` (a prescribed body only): a harmonic motion on top of ``velocity_m_s``, the forced
    oscillation of a seakeeping test (added mass and radiation damping from the force in phase with the
    acceleration and with the velocity). The body's centre moves by r(t) amplitude_m sin(2 pi t / period_s), the
    ramp r(t) = (1 - cos(pi t / t_r)) / 2 rising from 0 to 1 over t_r = ramp_periods periods (no jump in
    velocity at the start), 1 after."""

    amplitude_m: Vec3 = Field(..., description="Amplitude of the centre's displacement along x, y, z (m).")
    period_s: float = Field(..., gt=0, description="Period of the oscillation (s).")
    ramp_periods: float = Field(1.0, ge=0, description="Periods over which the amplitude rises from zero (0: the "
                                                       "full amplitude from the start, a jump in velocity).")

    def velocity_m_s(self, t_s: float) -> tuple[float, float, float]:
        """The oscillation's velocity (m/s) at time ``t_s``: d/dt [r(t) amplitude sin(omega t)]."""
        omega = 2.0 * math.pi / self.period_s
        t_r = self.ramp_periods * self.period_s
        if t_s < t_r:
            r = 0.5 * (1.0 - math.cos(math.pi * t_s / t_r))
            dr = 0.5 * math.pi / t_r * math.sin(math.pi * t_s / t_r)
        else:
            r, dr = 1.0, 0.0
        s = dr * math.sin(omega * t_s) + r * omega * math.cos(omega * t_s)
        return tuple(a * s for a in self.amplitude_m)

    def displacement_m(self, t_s: float) -> tuple[float, float, float]:
        """The oscillation's displacement (m) at time ``t_s``: r(t) amplitude sin(omega t)."""
        t_r = self.ramp_periods * self.period_s
        r = 0.5 * (1.0 - math.cos(math.pi * t_s / t_r)) if t_s < t_r else 1.0
        s = r * math.sin(2.0 * math.pi * t_s / self.period_s)
        return tuple(a * s for a in self.amplitude_m)


class Body(_Section):
    """``[[bodies]]``: an extra rigid body (box, sphere or convex mesh), free, fixed or moving at a prescribed
    velocity (with ``oscillation``, a harmonic motion on top of it)."""

    name: str = Field(..., pattern=r"^[A-Za-z0-9_.-]+$", description="Body name (time-series column prefix).")
    shape: Literal["box", "sphere", "mesh"] = Field(..., description="`box` (edges size_m), `sphere` (radius_m) or "
                                                    "`mesh` (a closed convex surface in mesh_file).")
    size_m: tuple[PositiveFloat, PositiveFloat, PositiveFloat] | None = Field(
        None, description="Box edges (m); each at least two cells of the finest level (a smaller body may cover no "
                          "cell centre, and the fluid would not see it).")
    radius_m: float | None = Field(None, gt=0, description="Sphere radius (m); at least one cell of the finest "
                                                           "level (two cells across).")
    mesh_file: str | None = Field(None, description="Mesh body: STL or OBJ file (relative to the scene file), "
                                  "placed as it is drawn with the centre of its bounding box at position_m.")
    mesh_unit: Literal["m", "cm", "mm", "ft", "in"] = Field("m", description="Mesh body: unit of the mesh's "
                                                            "coordinates (lattice units in a lattice-unit scene: m).")
    sphere_spacing_m: float | None = Field(None, gt=0, description="Mesh body: DEM sphere spacing on its surface "
                                           "(m). Default: a quarter of its smallest extent.")
    position_m: Vec3 = Field(..., description="Centre at t = 0 (m); a mesh's bounding-box centre.")
    velocity_m_s: Vec3 = Field((0.0, 0.0, 0.0), description="Velocity at t = 0, or the prescribed velocity (m/s).")
    density_kg_m3: float | None = Field(None, gt=0, description="Density (kg/m^3); needed for `free` bodies.")
    motion: Literal["free", "prescribed", "fixed"] = Field("free", description="How the body moves.")
    oscillation: Oscillation | None = Field(None, description="A prescribed body: a harmonic motion on top of "
                                            "velocity_m_s, see `[bodies.oscillation]`.")

    @model_validator(mode="after")
    def _shape_keys(self):
        if self.shape == "box" and self.size_m is None:
            raise ValueError("size_m: a box needs size_m")
        if self.shape == "sphere" and self.radius_m is None:
            raise ValueError("radius_m: a sphere needs radius_m")
        if self.shape == "mesh" and not self.mesh_file:
            raise ValueError("mesh_file: a mesh body needs its file, e.g. mesh_file = \"body.stl\"")
        if self.motion == "free" and self.density_kg_m3 is None:
            raise ValueError("density_kg_m3: a free body needs its density")
        if self.oscillation is not None and self.motion != "prescribed":
            raise ValueError(f"oscillation: only a prescribed body oscillates: set motion = \"prescribed\" (this "
                             f"body is {self.motion})")
        return self


class RefinementBox(_Section):
    """``[[refinement.boxes]]``: a box whose blocks are refined to ``level``."""

    lo_m: Vec3 = Field(..., description="Low corner (m; cells in a lattice scene).")
    hi_m: Vec3 = Field(..., description="High corner (m; cells in a lattice scene).")
    level: int = Field(..., ge=1, description="Level of the blocks the box overlaps (cells dx_m / 2^level).")

    @model_validator(mode="after")
    def _corners(self):
        if not all(h > lo for lo, h in zip(self.lo_m, self.hi_m)):
            raise ValueError("hi_m: each coordinate must exceed lo_m's")
        return self


class Refinement(_Section):
    """``[refinement]`` (optional): static block refinement (paper section 2.5). Level 0 is the grid of
    ``domain.dx_m``; level l has cells dx_m / 2^l and time steps dt / 2^l (acoustic scaling, the same physical
    viscosity). A block takes the highest level of the regions it overlaps (the boxes, the band around the water
    surface, the band along the walls); 2:1 balance adds the levels between. The fluid alone, or with a `[free_surface]` whose surface lies in
    the finest level (the coarser levels all water; iceresist.freesurface.refined), or with `[[bodies]]` on the
    finest level (iceresist.models.bodies), on the CPU or (the conservative interface) CUDA
    (iceresist.lbm.refinement)."""

    levels: int = Field(..., ge=1, le=6, description="The finest level (cells dx_m / 2^levels).")
    boxes: list[RefinementBox] = Field([], description="Regions and their levels, see `[[refinement.boxes]]`.")
    surface_band_m: float | None = Field(
        None, gt=0, description="With `[free_surface]`: the blocks within this distance (m; cells in a lattice "
        "scene) above or below the still-water level take the finest level. The surface must lie in the finest "
        "level, about 2.5 interface widths inside it.")
    wall_band_m: float | None = Field(
        None, gt=0, description="The blocks within this distance (m; cells in a lattice scene) of a solid face of "
        "the domain (wall, moving wall, free slip) take the finest level: the boundary layers.")
    body_band_m: float | None = Field(
        None, gt=0, description="With `[[bodies]]` (or a tier-2 ship in `[ice]`: the hull and every ice piece): the "
        "blocks within this distance (m; cells in a lattice scene) of a body's bounding box at the start take the "
        "finest level, where the bodies and their coupling live. "
        "With `regrid_every_steps` the band follows the bodies: at every regrid it is drawn around each body's "
        "bounding sphere where the body is then, so it must exceed the distance a body travels between regrids.")
    vorticity_1_s: float | None = Field(
        None, gt=0, description="With `regrid_every_steps`: the blocks holding a cell whose vorticity |curl u| "
        "(1/s; per time unit in a lattice scene), on the level-0 grid, exceeds this take the finest level: the "
        "eddies. Regridding follows them.")
    regrid_every_steps: int | None = Field(
        None, ge=1, description="Regrid every this many level-0 steps: the octree is built again from the criteria "
        "(the static regions above, `vorticity_1_s` on the current flow, `body_band_m` around the bodies where "
        "they are) and every cell's populations carried to the new blocks (a refined cell copies its parent, a "
        "coarsened one takes the mean of its children: mass to round-off; iceresist.grid.regrid). With a "
        "`[free_surface]` the surface band stays where it is (its phase field is carried with the water), and a "
        "regrid also keeps on the finest level every block the surface has reached (phi below 1 - 1e-4 outside the "
        "bodies) and the blocks within one finest block of it, so a wave or ice pushed down past the band does not "
        "lose its fine blocks when a body's band moves on.")
    regrid_slack: float = Field(
        0.0, ge=0, description="With `regrid_every_steps`: a regrid is put off while the present blocks hold, at "
        "their level or finer, everything the criteria ask for now and cost at most this fraction more cell updates "
        "per level-0 step than the levels a rebuild would give (the fine blocks a moving body left behind stay fine "
        "a while; each rebuild costs seconds to minutes of setting up); 0 rebuilds whenever the blocks change.")
    regrid_lookahead_steps: int = Field(
        0, ge=0, description="With `regrid_slack` and `body_band_m`: a regrid that rebuilds the levels draws each "
        "body's band over the path its present velocity takes it in this many level-0 steps, so the fine blocks "
        "reach ahead of a moving body and the regrids that follow wait until it nears their edge; the slack is then "
        "measured against the levels such a rebuild would give. 0: the band where the bodies are.")
    scheme: Literal["conservative", "interpolate"] = Field(
        "conservative", description="Level interface: 'conservative' (packets exploded and coalesced, Rohde et "
        "al. 2006: mass to round-off) or 'interpolate' (the paper's trilinear interpolation, its non-equilibrium "
        "part rescaled as Dupuis and Chopard; mass drifts about 7e-6 per 1000 steps; CPU only).")

    @model_validator(mode="after")
    def _levels(self):
        if self.vorticity_1_s is not None and self.regrid_every_steps is None:
            raise ValueError("regrid_every_steps: refinement.vorticity_1_s moves the fine blocks with the eddies, "
                             "which needs regridding: give refinement.regrid_every_steps (e.g. 50)")
        if self.regrid_slack and self.regrid_every_steps is None:
            raise ValueError("regrid_slack: puts regrids off, which needs refinement.regrid_every_steps (e.g. 10)")
        if self.regrid_lookahead_steps and not (self.regrid_slack and self.body_band_m):
            raise ValueError("regrid_lookahead_steps: draws the bodies' band ahead of them for the regrids that wait, "
                             "which needs refinement.body_band_m and refinement.regrid_slack (e.g. 0.25)")
        if self.regrid_every_steps is not None and self.vorticity_1_s is None and self.body_band_m is None:
            raise ValueError("vorticity_1_s: regridding needs a criterion that moves, refinement.vorticity_1_s "
                             "(e.g. 5.0) or, with [[bodies]], refinement.body_band_m (e.g. two cells)")
        if (not self.boxes and self.surface_band_m is None and self.wall_band_m is None and self.body_band_m is None
                and self.vorticity_1_s is None):
            raise ValueError("boxes: give at least one [[refinement.boxes]], refinement.surface_band_m, "
                             "refinement.wall_band_m, refinement.body_band_m or refinement.vorticity_1_s")
        for i, b in enumerate(self.boxes):
            if b.level > self.levels:
                raise ValueError(f"boxes[{i}].level: {b.level} is finer than levels = {self.levels}; use a level "
                                 f"<= {self.levels} or raise levels")
        return self


# ---------------------------------------------------------------------------------------------------------
#: The smallest body the fluid coupling resolves, in cells of the finest level across: a sphere or box at least
#: two cells across covers a cell centre wherever it lies, so that links cross its surface.
MIN_BODY_CELLS = 2.0


class Scene(_Section):
    """A whole scene file. Build one with :func:`iceresist.scene.load.load_scene`."""

    scene: SceneInfo = Field(SceneInfo(), description="Name, description, unit system.")
    domain: Domain = Field(..., description="Box, resolution, faces.")
    fluid: Fluid = Field(..., description="Viscosity, density, forces, initial flow.")
    numerics: Numerics = Field(Numerics(), description="Precision, backend, step limits.")
    run: RunSettings = Field(..., description="Stop criteria.")
    output: Output = Field(Output(), description="Result files.")
    free_surface: FreeSurface | None = Field(None, description="Optional phase-field free surface.")
    ship: Ship | None = Field(None, description="Optional ship.")
    ice: Ice | None = Field(None, description="Optional ice field.")
    contact: Contact | None = Field(None, description="Optional DEM contact law (defaults apply where ice is present).")
    bodies: list[Body] = Field([], description="Optional extra rigid bodies.")
    case: CaseBase | None = Field(None, description="Optional ship case this scene starts from.")
    refinement: Refinement | None = Field(None, description="Optional static block refinement.")

    _source_text: str = PrivateAttr("")
    _source_name: str = PrivateAttr("scene.toml")

    @model_validator(mode="after")
    def _unit_system(self):
        lattice = self.scene.units == "lattice"
        if lattice:
            if self.domain.dx_m not in (None, 1.0):
                raise ValueError("domain.dx_m: a lattice-unit scene has dx_m = 1; leave it out")
            if self.numerics.dt_s not in (None, 1.0):
                raise ValueError("numerics.dt_s: a lattice-unit scene has dt_s = 1; leave it out")
            if (self.numerics.tau is None) == (self.fluid.nu_m2_s is None):
                raise ValueError("numerics.tau: a lattice-unit scene gives exactly one of numerics.tau "
                                 "and fluid.nu_m2_s")
            if self.fluid.rho_kg_m3 not in (None, 1.0):
                raise ValueError("fluid.rho_kg_m3: a lattice-unit scene has density 1; leave it out")
        else:
            if self.domain.dx_m is None:
                raise ValueError("domain.dx_m: a physical scene needs the cell size dx_m (m)")
            if self.fluid.nu_m2_s is None:
                raise ValueError("fluid.nu_m2_s: a physical scene needs the viscosity (water: 1.0e-6 m^2/s)")
            if self.numerics.tau is not None:
                raise ValueError("numerics.tau: only lattice-unit scenes give tau; physical scenes give "
                                 "fluid.nu_m2_s")
        if self.free_surface is not None and not any(self.fluid.gravity_m_s2):
            raise ValueError("fluid.gravity_m_s2: a free surface needs gravity, e.g. [0, 0, -9.81]")
        if self.ice is not None and self.free_surface is None:
            raise ValueError("free_surface: floating ice needs a [free_surface] section (water depth)")
        names = [b.name for b in self.bodies]
        if len(set(names)) != len(names):
            raise ValueError("bodies: body names must be unique")
        self._bodies_resolved()
        if self.refinement is not None:
            size = self.domain.size_m or tuple(n * (self.domain.dx_m or 1.0) for n in self.domain.cells or (0, 0, 0))
            for i, b in enumerate(self.refinement.boxes):
                if any(lo < 0 or h > L * (1 + 1e-9) for lo, h, L in zip(b.lo_m, b.hi_m, size)):
                    raise ValueError(f"refinement.boxes[{i}]: the box must lie inside the domain "
                                     f"[0, 0, 0] - {list(size)}")
            if self.refinement.surface_band_m is not None and self.free_surface is None:
                raise ValueError("refinement.surface_band_m: a band around the water surface needs a "
                                 "[free_surface] section; refine with [[refinement.boxes]] instead")
            if self.refinement.body_band_m is not None and not self.bodies and self.ice is None:
                raise ValueError("refinement.body_band_m: a band around the bodies needs [[bodies]] or a ship in "
                                 "[ice]; refine with [[refinement.boxes]] instead")
        return self

    def _bodies_resolved(self):
        """A sphere or box body at least :data:`MIN_BODY_CELLS` cells of the finest level across (a mesh body's size
        is known once its file is read): a smaller one may cover no cell centre, and then the fluid does not see it
        at all (no link crosses its surface)."""
        dx = (1.0 if self.is_lattice else self.domain.dx_m) / 2 ** (self.refinement.levels if self.refinement else 0)
        floor = MIN_BODY_CELLS * dx
        unit = "cells" if self.is_lattice else "m"
        for i, b in enumerate(self.bodies):
            if b.shape == "sphere":
                key, size, value = f"bodies[{i}].radius_m", 2.0 * b.radius_m, b.radius_m
                need = 0.5 * floor
            elif b.shape == "box":
                key, size, value = f"bodies[{i}].size_m", min(b.size_m), min(b.size_m)
                need = floor
            else:
                continue
            if size < floor * (1.0 - 1e-9):
                raise ValueError(f"{key}: {value:.4g} {unit} gives a body {size:.4g} {unit} across, below the "
                                 f"smallest the fluid coupling resolves, {MIN_BODY_CELLS:g} cells of "
                                 f"{dx:.4g} {unit} (the finest level): use at least {need:.4g} {unit}, or refine "
                                 f"the grid (domain.dx_m, refinement.levels)")

    # -- derived values --------------------------------------------------------------------------------
    @property
    def source_text(self) -> str:
        """The TOML text this scene was read from (stored in the result file)."""
        return self._source_text

    @property
    def source_name(self) -> str:
        return self._source_name

    @property
    def has_lattice(self) -> bool:
        """Whether the scene builds a lattice: every scene but a tier-1 ship (DEM with water models), whose
        ``[domain]`` is the tank and no grid, so its cells, tau and Mach number are never checked nor spoken of."""
        return not (self.ship is not None and self.ice is not None and self.ship.tier == 1 and not self.bodies)

    @property
    def is_lattice(self) -> bool:
        return self.scene.units == "lattice"

    @property
    def rho_kg_m3(self) -> float:
        if self.fluid.rho_kg_m3 is not None:
            return self.fluid.rho_kg_m3
        return 1.0 if self.is_lattice else 1000.0

    def shape_cells(self) -> tuple[int, int, int]:
        return self.domain.shape_cells()

    def fastest(self) -> tuple[str, float]:
        """(key, speed): the scene key that names the largest speed (faces, initial flow, ship, bodies,
        ``numerics.u_max_m_s``), and that speed; messages about the speed name the key the user wrote."""
        speeds = [(f"domain.faces.{n}.velocity_m_s", _norm(f.velocity_m_s)) for n, f in self.domain.faces.items()]
        speeds.append(("fluid.initial_velocity_m_s", _norm(self.fluid.initial_velocity_m_s)))
        if self.ship is not None:
            speeds.append(("ship.speed_m_s", self.ship.speed_m_s))
        speeds += [(f"bodies[{i}].velocity_m_s", _norm(b.velocity_m_s)) for i, b in enumerate(self.bodies)]
        if self.numerics.u_max_m_s is not None:
            speeds.append(("numerics.u_max_m_s", self.numerics.u_max_m_s))
        return max(speeds, key=lambda ks: ks[1])

    def largest_speed_m_s(self) -> float:
        """The largest speed the scene names (:meth:`fastest`)."""
        return self.fastest()[1]

    def units(self) -> Units:
        """Lattice scales of this scene; raises StabilityError when it cannot run stably."""
        n = self.numerics
        if self.is_lattice:
            u = Units.lattice(tau=n.tau, nu=self.fluid.nu_m2_s, min_tau_excess=n.min_tau_excess)
            key, speed = self.fastest()
            check_lattice_velocity(speed, n.mach, what=f"{key} = {speed:g} (the largest speed in the scene)")
            return u
        g = _norm(self.fluid.gravity_m_s2) or 9.81
        depth = self.free_surface.water_depth_m if self.free_surface is not None else None
        return Units.from_physical(self.domain.dx_m, self.fluid.nu_m2_s, self.largest_speed_m_s(),
                                   mach_lattice=n.mach, depth_m=depth, g_m_s2=g, rho0_kg_m3=self.rho_kg_m3,
                                   dt_s=n.dt_s, min_tau_excess=n.min_tau_excess)

    def optional_sections(self) -> list[str]:
        """Names of the optional sections this scene uses."""
        used = [k for k in ("free_surface", "ship", "ice", "contact", "refinement") if getattr(self, k) is not None]
        return used + (["bodies"] if self.bodies else [])
