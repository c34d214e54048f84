"""Reference case: a 41 mm ice cube (950 kg/m^3) released at the surface of still water floats at 95 % of its
height (Archimedes: submerged fraction = rho_ice / rho_water).

The set-up is the scene file iceresist/validate/scenes/floating_cube.toml (8 cells per edge); a rung sets its
resolution over it and runs it through the driver. The cube (the paper's ice piece, section 3) is released from rest with its bottom ``release_draft`` of its
height under the still-water level, in a closed tank three cube widths square and four high, water 2.5 cube
heights deep. The free-surface LBM (BGK, phase field, eq. 11), the DEM and the coupling of
:class:`~iceresist.models.floating_bodies.FloatingBodiesModel` carry it; buoyancy is the hydrostatic pressure of the
gravity body force, summed by the momentum exchange. The headline quantity is the submerged fraction
(water level - cube bottom) / height, averaged over the last heave period of the run; its reference is 0.95.
The heave period and its decay come from the successive extremes of the heave about its mean
(:func:`heave_analysis`); the natural period is compared with 2 pi sqrt(draft (1 + C_a) / g') of
:func:`period_estimate_s` (C_a the added mass over the cube's mass, g' the restoring of the tank).

Lattice: g = ``g_lattice`` (default 1e-3, dt = sqrt(g_lattice dx / g)); tau = 0.55 (nu about 6e-4 m^2/s at
8 cells per edge: a viscous water that damps the heave within a few periods). The water level is measured
(phi = 1/2) over the columns the cube does not reach; the still-water level is chosen so that the level of
the floating state lies on a cell face (the pressure datum of eq. 11 is the face between the last liquid
and the first gas cell, so the level is resolved to half a cell; see docs/notes/floating-cube.md).
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.models import build_model
from iceresist.validate.result import CaseResult, relative_error
from iceresist.validate.rung import run_rung, scene_of
from iceresist.validate.scenes import scene_data

NAME = "floating_cube"
REFERENCE = "Archimedes: submerged fraction rho_ice / rho_water = 950 / 1000 = 0.95 of the 41 mm cube's height"

EDGE_M = 0.041
RHO_ICE = 950.0
RHO_WATER = 1000.0
FRACTION = RHO_ICE / RHO_WATER
G = 9.81


def ladder(quick: bool) -> list[dict]:
    """Cells per cube edge from coarse to fine; the quick ladder runs 1.5 estimated periods, the full one 6."""
    periods = 1.5 if quick else 6.0
    return [{"label": f"{n} cells/edge", "resolution": n, "periods": periods, "release_draft": 0.8}
            for n in ((6, 8, 10) if quick else (6, 8, 12, 16))]


def period_estimate_s(edge_m: float = EDGE_M, added_mass: float = 0.0, tank_widths: float = 3.0) -> float:
    """Heave period 2 pi sqrt(draft (1 + C_a) / g') of a floating cube, draft = 0.95 edge, C_a the added mass
    over the cube's mass, and the restoring force of the tank, rho g A_cube A_tank / (A_tank - A_cube)
    (the level rises as the cube sinks): g' = g w^2 / (w^2 - 1), w the tank width in cube widths."""
    w2 = tank_widths ** 2
    return 2 * math.pi * math.sqrt(FRACTION * edge_m * (1 + added_mass) * (w2 - 1) / (w2 * G))


def scene(n: int, *, release_draft: float = 0.8, tau: float = 0.55, g_lattice: float = 1e-3,
          precision: str = "float64", backend: str = "cpu", steps: int = 1):
    """The scene of the tank with one cube of ``n`` cells per edge: the scene file
    (iceresist/validate/scenes/floating_cube.toml, 8 cells per edge) with the cell size, the tank (three cube
    widths square, four high, in whole blocks), the time step sqrt(g_lattice dx / g), the viscosity of ``tau``,
    the still-water level and the cube's release point (its bottom ``release_draft`` of its height under the
    still level) set over it, run for ``steps`` steps."""
    dx = EDGE_M / n
    nxy = int(math.ceil(3 * n / 8) * 8)
    nz = int(math.ceil(4 * n / 8) * 8)
    area = nxy * nxy
    # still-water level (cells) chosen so that the level of the floating state lies on a cell face
    final = math.floor(2.5 * n) + 0.0
    level0 = final - (FRACTION - release_draft) * n ** 3 / area
    dt = math.sqrt(g_lattice * dx / G)
    data = scene_data(NAME)
    data["scene"].update(name=f"{NAME}-{n}", description=f"41 mm ice cube released at {release_draft:g} draft, "
                         f"{n} cells per edge")
    data["domain"].update(cells=[nxy, nxy, nz], dx_m=dx)
    data["fluid"].update(nu_m2_s=(tau - 0.5) * dx * dx / (3.0 * dt), rho_kg_m3=RHO_WATER)
    # the lattice speed of the shallow-water wave, sqrt(g_lattice h / dx), under the Mach limit
    data["numerics"].update(dt_s=dt, precision=precision, backend=backend,
                            mach=min(0.3, max(0.2, 1.1 * math.sqrt(g_lattice * level0))))
    data["run"] = {"steps": int(steps)}
    data["free_surface"]["water_depth_m"] = level0 * dx
    data["bodies"][0].update(size_m=[EDGE_M] * 3, density_kg_m3=RHO_ICE,
                             position_m=[0.5 * nxy * dx, 0.5 * nxy * dx, (level0 - release_draft * n + 0.5 * n) * dx])
    return scene_of(data, f"{NAME} {n} cells/edge")


def steps_for(periods: float, dt_s: float) -> int:
    """Steps of ``periods`` estimated heave periods (added mass 0.5)."""
    return int(periods * period_estimate_s(added_mass=0.5) / dt_s)


def build(n: int, *, release_draft: float = 0.8, tau: float = 0.55, g_lattice: float = 1e-3,
          precision: str = "float64", backend: str = "cpu"):
    """The tank with one cube of ``n`` cells per edge, released at ``release_draft`` of its height under the
    still-water level; returns the model (:class:`~iceresist.models.floating_bodies.FloatingBodiesModel`) of the
    scene :func:`scene` writes."""
    return build_model(scene(n, release_draft=release_draft, tau=tau, g_lattice=g_lattice, precision=precision,
                             backend=backend))


def heave_analysis(t_s: np.ndarray, z_m: np.ndarray, t_window_s: float, threshold: float = 0.05,
                   about: float | None = None) -> dict:
    """Heave of a released body from the series ``z_m`` (any measure of the heave, e.g. the submerged fraction).

    ``mean``: the mean over the last ``t_window_s``, or ``about`` where given (a known floating position). Extremes: the largest excursion |z - mean| between
    successive crossings of the mean, the release counting as the first; excursions below ``threshold`` of the
    release excursion (noise about the settled state) are dropped and neighbours of one sign merged.
    ``half_ratio``: mean ratio of successive extremes (the decay per half period); ``damping_ratio``
    zeta = delta / sqrt(pi^2 + delta^2), delta = -ln(half_ratio); ``period_s``: the damped period, twice the
    mean time between extremes; ``natural_period_s`` = period_s sqrt(1 - zeta^2). NaN where fewer than two
    extremes remain."""
    last = t_s >= t_s[-1] - t_window_s
    mean = float(z_m[last].mean()) if about is None else float(about)
    s = z_m - mean
    bounds = np.concatenate([[0], np.flatnonzero(np.sign(s[:-1]) != np.sign(s[1:])) + 1, [len(s)]])
    ext = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        i = a + int(np.argmax(np.abs(s[a:b])))
        if abs(s[i]) < threshold * abs(s[0]):
            continue
        if ext and np.sign(ext[-1][1]) == np.sign(s[i]):
            if abs(s[i]) > abs(ext[-1][1]):
                ext[-1] = (t_s[i], s[i])
            continue
        ext.append((float(t_s[i]), float(s[i])))
    out = {"mean": mean, "extremes": ext, "period_s": float("nan"), "half_ratio": float("nan"),
           "damping_ratio": float("nan"), "natural_period_s": float("nan")}
    if len(ext) >= 2:
        te = np.array([e[0] for e in ext])
        pe = np.abs([e[1] for e in ext])
        ratio = float(np.mean(pe[1:] / pe[:-1]))
        delta = -math.log(ratio)
        zeta = delta / math.sqrt(math.pi ** 2 + delta ** 2)
        period = float(2 * np.diff(te).mean())
        out.update(period_s=period, half_ratio=ratio, damping_ratio=zeta,
                   natural_period_s=period * math.sqrt(1 - zeta ** 2))
    return out


def simulate(n: int, periods: float, *, release_draft: float = 0.8, sample_every: int = 5, **kw):
    """Run the cube for ``periods`` estimated periods (C_a = 0.5) through the driver into a scratch folder
    (:func:`~iceresist.validate.rung.run_rung`, ``kw`` as :func:`scene`); the time series every ``sample_every``
    steps (t_s, submerged fraction, fluid force z N, water volume relative change), the model, the steps and the
    wall time of the stepping (the first, compiling chunk excluded)."""
    sc = scene(n, release_draft=release_draft, **kw)
    model = build_model(sc)
    steps = steps_for(periods, model.dt_s)
    rung = run_rung(model, sc, None, NAME, {"label": f"{n} cells/edge", "resolution": n, "periods": periods,
                                            "release_draft": release_draft}, steps=steps, sample_every=sample_every)
    ts = rung.timeseries
    after = ts["iteration"] > 0
    frac = (ts["water_level_m"] - (ts["cube_z_m"] - 0.5 * EDGE_M)) / EDGE_M
    rows = np.stack([ts["time_s"], frac, ts["cube_Fz_N"], ts["water_volume_drift"]], axis=1)[after]
    return rows, model, steps, rung.wall_s


def run(params: dict, *, backend: str = "cpu", precision: str = "float64", out_dir=None) -> CaseResult:
    """One rung through the driver (:func:`iceresist.validate.rung.run_rung`, a row every 5 steps): the submerged
    fraction, (water_level_m - cube bottom) / edge, over the last estimated period against 0.95 (the row of the
    release, t = 0, left out)."""
    n = int(params["resolution"])
    sc = scene(n, release_draft=params["release_draft"], backend=backend, precision=precision)
    model = build_model(sc)
    steps = steps_for(params["periods"], model.dt_s)
    rung = run_rung(model, sc, out_dir, NAME, params, steps=steps, sample_every=5)
    ts = rung.timeseries
    keep = ts["iteration"] > 0
    t = ts["time_s"][keep]
    frac = (ts["water_level_m"][keep] - (ts["cube_z_m"][keep] - 0.5 * EDGE_M)) / EDGE_M
    heave = heave_analysis(t, frac, period_estimate_s(added_mass=0.5))
    mean = heave["mean"]
    t0 = period_estimate_s()
    weight = RHO_ICE * EDGE_M ** 3 * G
    return CaseResult(case=NAME, label=params["label"], resolution=float(n), cells=model.forest.cells, steps=steps,
                      wall_s=rung.run_time_s, quantity="submerged fraction", value=mean, reference=FRACTION,
                      error=relative_error(mean, FRACTION), backend=backend, precision=precision,
                      extra={"period_s": heave["period_s"], "natural_period_s": heave["natural_period_s"],
                             "period_no_added_mass_s": t0, "half_period_decay": heave["half_ratio"],
                             "damping_ratio": heave["damping_ratio"],
                             "added_mass_implied": (heave["natural_period_s"] / t0) ** 2 - 1,
                             "force_over_weight": float(ts["cube_Fz_N"][-1] / weight),
                             "volume_drift": float(np.abs(ts["water_volume_drift"]).max()),
                             "result_file": str(rung.path)})
