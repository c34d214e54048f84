"""Reference case: a standing gravity wave in a periodic channel (free surface, paper section 2.2).

Set-up (lattice units): one wavelength lambda = ``cells_per_wavelength`` cells along periodic x, a quasi-2D
slab of 8 cells along periodic y, still depth h = ``depth_wavelengths`` lambda over a no-slip bottom, a closed
lid above the gas. The surface starts at rest, z_s = h + a cos(k x), with the hydrostatic density under it
(:meth:`~iceresist.freesurface.fluid.FreeSurfaceFluid.initialize`), and oscillates as the standing wave

    eta(x, t) = a e^(-gamma t) cos(omega t) cos(k x),   omega^2 = g k tanh(k h)      (linear theory)

with the viscous amplitude decay gamma = 2 nu k^2 (Lamb 1932, Hydrodynamics, section 348, deep water; a
no-slip bottom and the diffuse interface add to it). The case measures the mode amplitude
A(t) = (2 / n_x) sum_x (z_s(x) - mean) cos(k x) each step, and fits omega and gamma to
A = A0 e^(-gamma t) cos(omega t + psi) + A_inf (linear least squares in the offset, nonlinear in omega,
gamma). Headline: the period 2 pi / omega against linear theory.

g is chosen from the target period in steps (``period_steps``), so the Mach number a omega / c_s
stays ~ 1e-2 and the run length scales with the wavelength (acoustic scaling at fixed lambda / period
ratio of c_s / c_wave).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from iceresist.errors import InputError
from iceresist.freesurface.refined import RefinedFreeSurface
from iceresist.grid.forest import Face
from iceresist.grid.octree import BlockOctree
from iceresist.models import FreeSurfaceModel
from iceresist.validate.result import CaseResult, relative_error
from iceresist.validate.rung import run_rung, scene_of

log = logging.getLogger(__name__)

NAME = "standing_wave"
REFERENCE = ("linear standing gravity wave, omega^2 = g k tanh(k h); viscous decay 2 nu k^2 "
             "(Lamb 1932, Hydrodynamics, 6th ed., section 348)")

#: Defaults of one rung (lattice units unless named otherwise).
#: The amplitude lambda / 32 (ka = 0.196) is half a cell at 16 cells per wavelength and one cell at 32: at
#: lambda / 64 the surface moved by a quarter to half a cell, the period was set by when cells flip between gas
#: and liquid, and its error did not fall with the resolution (1.0 / 2.1 / 2.3 % at 16 / 24 / 32 cells; now
#: 1.5 / 0.72 / 0.06 %, docs/VALIDATION.md "Error against run time").
DEFAULTS = dict(cells_per_wavelength=32, depth_wavelengths=0.5, amplitude_wavelengths=1 / 32, periods=2.0,
                period_over_wavelength=14.0, tau=0.51, operator="bgk", ny=8, mobility=0.01)


def theory(params: dict) -> dict:
    """Linear-theory figures of a rung: k, h, a, g, omega, period_steps, decay (2 nu k^2), nu."""
    p = {**DEFAULTS, **params}
    lam = float(p["cells_per_wavelength"])
    k = 2.0 * math.pi / lam
    h = p["depth_wavelengths"] * lam
    period = p["period_over_wavelength"] * lam
    omega = 2.0 * math.pi / period
    g = omega ** 2 / (k * math.tanh(k * h))
    nu = (p["tau"] - 0.5) / 3.0
    return dict(k=k, h=h, a=p["amplitude_wavelengths"] * lam, g=g, omega=omega, period_steps=period,
                decay=2.0 * nu * k * k, nu=nu)


def ladder(quick: bool) -> list[dict]:
    """Three (quick) or four rungs of cells per wavelength; the quick ladder totals well under 2 min on a
    2-core x86 VM after compilation."""
    if quick:
        return [dict(label=f"{n} cells/wavelength", resolution=n, cells_per_wavelength=n, periods=1.5)
                for n in (16, 24, 32)]
    return [dict(label=f"{n} cells/wavelength", resolution=n, cells_per_wavelength=n, periods=3.0)
            for n in (16, 32, 48, 64)]


def fit_damped_cosine(t: np.ndarray, a: np.ndarray, omega0: float) -> tuple[float, float, float]:
    """(omega, gamma, amplitude) of A = A0 e^(-gamma t) cos(omega t + psi) + A_inf fitted to ``a(t)``;
    a grid search in omega around ``omega0`` then scipy least squares."""
    from scipy.optimize import least_squares

    def model(x):
        om, ga, c, s, off = x
        return np.exp(-ga * t) * (c * np.cos(om * t) + s * np.sin(om * t)) + off

    x0 = np.array([omega0, 0.0, a[0], 0.0, 0.0])
    sol = least_squares(lambda x: model(x) - a, x0, x_scale=np.array([omega0, omega0, abs(a[0]), abs(a[0]),
                                                                        abs(a[0])]))
    om, ga, c, s, _ = sol.x
    return abs(float(om)), float(ga), float(math.hypot(c, s))


def mode_amplitude(surface: np.ndarray, k: float) -> float:
    """A = (2 / n_x) sum_x (z_s - mean) cos(k x) of the y-mean surface height (cells), x at cell centres."""
    zs = surface.mean(axis=1)
    x = np.arange(zs.size) + 0.5
    return float(2.0 / zs.size * np.sum((zs - zs.mean()) * np.cos(k * x)))


def scene(params: dict, *, backend: str = "cpu", precision: str = "float32"):
    """The scene of a rung (lattice units): one wavelength along periodic x, ``ny`` cells along periodic y, walls
    at the bottom and the lid, still depth h, gravity from the target period."""
    p = {**DEFAULTS, **params}
    th = theory(p)
    nx = int(p["cells_per_wavelength"])
    nz = 8 * math.ceil((th["h"] + th["a"] + 6.0) / 8)
    return scene_of({
        "scene": {"name": f"{NAME}-{nx}", "description": f"standing gravity wave, {nx} cells per wavelength",
                  "units": "lattice"},
        "domain": {"cells": [nx, int(p["ny"]), nz],
                   "faces": {"x_min": "periodic", "x_max": "periodic", "y_min": "periodic", "y_max": "periodic",
                             "z_min": "wall", "z_max": "wall"}},
        "fluid": {"gravity_m_s2": [0.0, 0.0, -th["g"]], "operator": p["operator"]},
        "numerics": {"tau": p["tau"], "precision": precision, "backend": backend},
        "run": {"steps": steps_for(p)},
        "output": {"fields": ["u"]},
        "free_surface": {"water_depth_m": th["h"], "mobility_lattice": p["mobility"], "interface_width_cells": 3.0,
                         "h_lattice": "D3Q15", "f_pool_margin": 0.25},
    }, f"{NAME} {p.get('label', nx)}")


def steps_for(params: dict) -> int:
    p = {**DEFAULTS, **params}
    return int(round(p["periods"] * theory(p)["period_steps"]))


def build(params: dict, *, backend: str = "cpu", precision: str = "float32"):
    """The scene of a rung, its model with the surface z_s = h + a cos(k x) at rest over hydrostatic water, and
    its :func:`theory`."""
    p = {**DEFAULTS, **params}
    th = theory(p)
    sc = scene(p, backend=backend, precision=precision)
    model = FreeSurfaceModel(sc)
    nx, ny, _ = model.shape_cells
    x = np.arange(nx) + 0.5
    model.fluid.initialize(surface=np.broadcast_to((th["h"] + th["a"] * np.cos(th["k"] * x))[:, None], (nx, ny)))
    model.volume0_cells = model.fluid.volume()
    return sc, model, th


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """Run one rung through the driver, the mode amplitude sampled 40 times a period; the period error against
    linear theory, with the decay rate in ``extra``."""
    p = {**DEFAULTS, **params}
    sc, model, th = build(p, backend=backend, precision=precision)
    steps = steps_for(p)
    sample = max(1, int(th["period_steps"] // 40))
    rung = run_rung(model, sc, out_dir, NAME, {**p, "label": p.get("label", f"{p['cells_per_wavelength']} cells")},
                    steps=steps, sample_every=sample, fields=("u",),
                    probes={"mode_amplitude_cells": lambda m: mode_amplitude(m.fluid.surface_height(), th["k"])},
                    initial=f"surface z_s = h + a cos(k x), a = {th['a']:.6g} cells, at rest over hydrostatic water")
    t = rung.timeseries["iteration"].astype(float)
    amp = rung.timeseries["mode_amplitude_cells"]
    omega, gamma, a0 = fit_damped_cosine(t, amp, th["omega"])
    period = 2.0 * math.pi / omega
    extra = dict(omega=omega, omega_theory=th["omega"], decay_per_step=gamma, decay_lamb=th["decay"],
                 log_decrement=gamma * period, log_decrement_lamb=th["decay"] * th["period_steps"],
                 amplitude0=a0, g=th["g"], tau=p["tau"], operator=p["operator"],
                 volume=float(rung.timeseries["water_volume_m3"][-1]),
                 max_u_final=float(np.nanmax(np.abs(rung.fields["u"]))), mach=th["a"] * th["omega"] * math.sqrt(3.0),
                 t=t.tolist(), amplitude=amp.tolist(), result_file=str(rung.path))
    log.info("standing wave %s: period %.1f steps vs %.1f (%.2f %%), decay %.3g vs Lamb %.3g per step",
             p.get("label", ""), period, th["period_steps"], 100 * relative_error(period, th["period_steps"]),
             gamma, th["decay"])
    return CaseResult(case=NAME, label=p.get("label", f"{p['cells_per_wavelength']} cells/wavelength"),
                      resolution=float(p.get("resolution", p["cells_per_wavelength"])), cells=model.cells,
                      steps=rung.steps, wall_s=rung.run_time_s, quantity="period (steps)", value=period,
                      reference=th["period_steps"], error=relative_error(period, th["period_steps"]),
                      backend=backend, precision=precision, extra=extra)


def run_on_levels(params: dict, *, precision: str = "float32") -> CaseResult:
    """The standing wave with its surface in the finer of two levels (:mod:`iceresist.freesurface.refined`): the
    rung's wavelength, depth, amplitude and time step on level 1 (``cells_per_wavelength`` a multiple of 16), a slab
    of 16 level-1 cells along y, level 0 below the deepest multiple of 16 level-1 cells that leaves 8 of them of
    liquid under the trough, level 1 above it to the lid. The period against linear theory, as :func:`run`."""
    import time

    p = {**DEFAULTS, **params}
    th = theory(p)
    lam = int(p["cells_per_wavelength"])
    if lam % 16:
        raise InputError(f"cells_per_wavelength must be a multiple of 16 on levels (two level-0 blocks per 16 "
                         f"level-1 cells), not {lam}")
    h, a = th["h"], th["a"]
    z_int = 16 * math.floor((h - a - 8.0) / 16.0)
    top = 16 * math.ceil((h + a + 8.0) / 16.0)
    if z_int < 16:
        raise InputError(f"depth_wavelengths: the water ({h:g} level-1 cells) leaves no level-0 block under the "
                         f"surface with 8 cells to spare; deepen it to {(24 + a) / lam:.3g} wavelengths or more")
    tree = BlockOctree((lam // 16, 1, top // 16), 1, periodic=(True, True, False)).refine(
        lambda lo, hi: np.where(lo[:, 2] >= z_int // 2, 1, 0))
    faces = {"x-": Face("periodic"), "x+": Face("periodic"), "y-": Face("periodic"), "y+": Face("periodic"),
             "z-": Face("wall"), "z+": Face("wall")}
    m = RefinedFreeSurface(tree, tau0=0.5 + (p["tau"] - 0.5) / 2, gravity0=2.0 * th["g"], depth0=h / 2,
                           mobility=p["mobility"], width=3.0, operator=p["operator"], precision=precision,
                           faces=faces)
    x = np.arange(lam) + 0.5
    m.initialize(surface=np.broadcast_to(((h + a * np.cos(th["k"] * x)) / 2)[:, None], (lam, 16)))
    v0 = m.volume()
    steps = steps_for(p)
    sample = max(2, 2 * int(th["period_steps"] // 80))   # fine steps per sample, even
    t, amp = [0.0], [mode_amplitude(m.surface_height(), th["k"])]
    t0 = time.perf_counter()
    while t[-1] < steps:
        m.step(sample // 2)
        t.append(t[-1] + sample)
        amp.append(mode_amplitude(m.surface_height(), th["k"]))
    wall = time.perf_counter() - t0
    t, amp = np.array(t), np.array(amp)
    omega, gamma, a0 = fit_damped_cosine(t, amp, th["omega"])
    period = 2.0 * math.pi / omega
    cells = int(sum(m.views[lv].nleaves for lv in m.levels) * 512)
    fine_cells = lam * 16 * top
    extra = dict(omega=omega, omega_theory=th["omega"], decay_per_step=gamma, decay_lamb=th["decay"],
                 amplitude0=a0, g=th["g"], tau=p["tau"], operator=p["operator"], level_interface_cells=z_int,
                 volume_change=(m.volume() - v0) / v0, max_speed=m.max_speed(), cells_per_level=[
                     int(m.views[lv].nleaves * 512) for lv in m.levels], fine_grid_cells=fine_cells,
                 t=t.tolist(), amplitude=amp.tolist())
    log.info("standing wave on levels %s: period %.1f steps vs %.1f (%.2f %%), volume %+.2e", p.get("label", ""),
             period, th["period_steps"], 100 * relative_error(period, th["period_steps"]), extra["volume_change"])
    return CaseResult(case=NAME, label=f"{lam} cells/wavelength on two levels", resolution=float(lam), cells=cells,
                      steps=int(t[-1]), wall_s=wall, quantity="period (steps)", value=period,
                      reference=th["period_steps"], error=relative_error(period, th["period_steps"]),
                      backend="cpu", precision=precision, extra=extra)
