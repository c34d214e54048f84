"""Reference case: the heave added mass and radiation damping of a half-submerged sphere in forced oscillation,
against Hulme (1982).

Hulme, A. (1982), "The wave forces acting on a floating hemisphere undergoing forced periodic oscillations", J.
Fluid Mech. 121, 443-463: linear potential flow in deep water. A sphere of radius R floating with its centre on
the still level (the body of :mod:`~iceresist.validate.cases.heave_decay`, R = 0.15 m) heaving as
z = a sin(omega t) feels, besides the hydrostatic restoring force -rho g pi R^2 z, the radiation force
-a33 z'' - b33 z'. Hulme tabulates A = a33 / (rho V) and B = b33 / (rho V omega), V = 2/3 pi R^3 the displaced
volume, against KR = omega^2 R / g (:data:`HULME`; A = 0.4284, B = 0.2484 at KR = 1, the frequency near the
sphere's own heave period). The table is the transcription in the public repository LHEEA/Hulme_Heaving_Sphere
(``comparison/HulmeResult.dat``), normalised as above (A -> 0.5 as KR -> infinity, the half of a submerged
sphere's 1/2); docs/VALIDATION.md cites it.

The set-up: the tank of the heave-decay case (walls ``tank_diameters`` D apart, water 0.9 m deep, kh = 6 at
KR = 1: deep water) with the sphere prescribed (``bodies[].oscillation``) to heave about its floating position at
``amplitude`` R, the amplitude ramped up over the first period. After the ramp the vertical fluid force is fitted
over whole periods (:func:`analyse`) by F0 + c_s sin(omega t) + c_c cos(omega t), from which
a33 = (c_s + k a) / (a omega^2) and b33 = -c_c / (a omega), k = rho g pi R^2 the waterplane's stiffness (the
exact sphere's: the discrete sphere's own enters A's error). The window ends before the wave radiated at the
start returns from the walls at its group speed g / (2 omega) (A fitted period by period stays within 3 %: the
walls do not reach it).
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.models import build_model
from iceresist.validate.cases import heave_decay as hd
from iceresist.validate.result import CaseResult, relative_error
from iceresist.validate.rung import run_rung, scene_of

NAME = "heave_added_mass"
REFERENCE = ("Hulme 1982 (J. Fluid Mech. 121, 443), floating hemisphere in forced heave: added mass "
             "A = a33 / (rho 2/3 pi R^3) = 0.4284 at KR = omega^2 R / g = 1")

#: Hulme (1982): KR, A = a33 / (rho V), B = b33 / (rho V omega), V = 2/3 pi R^3 (the rows of KR 0.4 to 3)
HULME = np.array([
    [0.4, 0.6452, 0.3410], [0.5, 0.5861, 0.3391], [0.6, 0.5381, 0.3271], [0.7, 0.4999, 0.3098],
    [0.8, 0.4698, 0.2899], [0.9, 0.4464, 0.2691], [1.0, 0.4284, 0.2484], [1.2, 0.4047, 0.2096],
    [1.4, 0.3924, 0.1756], [1.6, 0.3871, 0.1469], [1.8, 0.3864, 0.1229], [2.0, 0.3884, 0.1031],
    [2.5, 0.3988, 0.0674], [3.0, 0.4111, 0.0452]])

RADIUS_M = hd.RADIUS_M
VOLUME_M3 = 2.0 / 3.0 * math.pi * RADIUS_M ** 3           # displaced at the floating position
STIFFNESS_N_M = hd.RHO_WATER * hd.G * math.pi * RADIUS_M ** 2   # waterplane: rho g pi R^2
AMPLITUDE = 0.1                                           # heave amplitude / R
RAMP_PERIODS = 1.0
PERIODS = 4.0                                             # run: the ramp, then three periods


def hulme(kr: float) -> tuple[float, float]:
    """Hulme's A and B at ``kr`` (linear between the table's rows)."""
    if not HULME[0, 0] <= kr <= HULME[-1, 0]:
        raise ValueError(f"KR = {kr} lies outside the table's {HULME[0, 0]} .. {HULME[-1, 0]}")
    return float(np.interp(kr, HULME[:, 0], HULME[:, 1])), float(np.interp(kr, HULME[:, 0], HULME[:, 2]))


def period_s(kr: float) -> float:
    """The period (s) of the oscillation at KR = omega^2 R / g."""
    return 2.0 * math.pi / math.sqrt(kr * hd.G / RADIUS_M)


def window_s(kr: float, tank_diameters: float) -> tuple[float, float]:
    """The fitted window (s): from the end of the ramp over whole periods, up to the return of the wave the start
    radiated from the nearest wall at the group speed g / (2 omega) (at most the run's end)."""
    T = period_s(kr)
    omega = 2.0 * math.pi / T
    back = 2.0 * (0.5 * tank_diameters * hd.DIAMETER_M - RADIUS_M) / (hd.G / (2.0 * omega))
    t0 = RAMP_PERIODS * T
    whole = math.floor((min(back, PERIODS * T) - t0) / T + 1e-9)
    return t0, t0 + max(whole, 1) * T


def rung(n: int, tank: int, kr: float) -> dict:
    """One rung: ``n`` cells per diameter, a tank ``tank`` diameters wide, the oscillation at KR = ``kr``."""
    return {"label": f"{n} cells/D, tank {tank} D, KR {kr:g}", "resolution": n, "tank_diameters": tank, "kr": kr}


def ladder(quick: bool) -> list[dict]:
    """KR = 1 at 8, 12 and 16 cells per diameter in a tank of eight diameters (the quick ladder); the full ladder
    adds 24 cells/D. The walls' share is kept out by the window (:func:`window_s`: A per fitted period is steady)."""
    return [rung(n, 8, 1.0) for n in ((8, 12, 16) if quick else (8, 12, 16, 24))]


def _held_data(n: int, tank_diameters: float, duration_s: float, motion: str, precision: str, backend: str) -> dict:
    """The heave-decay tank's data with the sphere on the still level, its motion ``motion`` (no density)."""
    data = hd.tank_data(n, tank_diameters, duration_s=duration_s, drop_m=0.0, precision=precision, backend=backend)
    body = data["bodies"][0]
    body.pop("density_kg_m3", None)
    body["motion"] = motion
    return data


def scene(n: int, tank_diameters: float, kr: float, *, amplitude: float = AMPLITUDE, precision: str = "float32",
          backend: str = "cpu"):
    """The heave-decay tank (:func:`~iceresist.validate.cases.heave_decay.tank_data`) with the sphere at its
    floating position, prescribed to heave ``amplitude`` R at KR = ``kr`` for :data:`PERIODS` periods."""
    T = period_s(kr)
    data = _held_data(n, tank_diameters, PERIODS * T, "prescribed", precision, backend)
    data["scene"].update(name=f"{NAME}-{n}-{tank_diameters:g}D-KR{kr:g}",
                         description=f"sphere D 0.3 m heaving {amplitude:g} R at KR {kr:g}, {n} cells/D, "
                                     f"tank {tank_diameters:g} D")
    data["bodies"][0]["oscillation"] = {"amplitude_m": [0.0, 0.0, amplitude * RADIUS_M], "period_s": T,
                                        "ramp_periods": RAMP_PERIODS}
    return scene_of(data, f"{NAME} {n} cells/D, tank {tank_diameters:g} D, KR {kr:g}")


def held_scene(n: int, offset_m: float, *, tank_diameters: float = 4.0, steps: int = 200,
               precision: str = "float32", backend: str = "cpu"):
    """The sphere held fixed with its centre ``offset_m`` above the still level (which its cells leave as it is):
    the hydrostatic force of the discrete sphere at that offset, ``steps`` steps."""
    data = _held_data(n, tank_diameters, 1.0, "fixed", precision, backend)
    data["run"] = {"steps": int(steps)}
    data["scene"].update(name=f"{NAME}-held-{n}", description=f"sphere D 0.3 m held {offset_m * 1e3:g} mm above "
                                                              f"the still level, {n} cells/D")
    data["bodies"][0]["position_m"][2] = hd.DEPTH_M + offset_m
    return scene_of(data, f"{NAME} held {n} cells/D")


def discrete_stiffness_N_m(n: int, amplitude: float = AMPLITUDE, *, steps: int = 200, precision: str = "float32",
                           backend: str = "cpu") -> dict:
    """The hydrostatic stiffness of the sphere as the grid sees it: the mean vertical force over the last half of
    ``steps`` steps on the sphere held ``amplitude`` R above and below the still level (still water from the start:
    the level stays where the scene puts it), k = -(F(+a) - F(-a)) / 2a, beside the exact sphere's
    rho g (V(-a) - V(+a)) / 2a (the waterplane's rho g pi R^2 less the cubic term)."""
    a = amplitude * RADIUS_M
    force = {}
    for sign in (1.0, -1.0):
        model = build_model(held_scene(n, sign * a, steps=steps, precision=precision, backend=backend))
        f = []
        for i in range(steps):
            model.step(1)
            if i >= steps // 2:
                f.append(model.fluid_force_N[0, 2])
        force[sign] = float(np.mean(f))
    exact = hd.RHO_WATER * hd.G * (hd.submerged_volume_m3(-a) - hd.submerged_volume_m3(a)) / (2 * a)
    return {"k_N_m": -(force[1.0] - force[-1.0]) / (2 * a), "k_exact_N_m": exact, "force_up_N": force[1.0],
            "force_down_N": force[-1.0]}


def analyse(t_s: np.ndarray, fz_N: np.ndarray, z_m: np.ndarray, kr: float, window: tuple[float, float],
            stiffness_N_m: float = STIFFNESS_N_M) -> dict:
    """A and B from the vertical fluid force ``fz_N`` on a sphere heaving ``z_m`` (its centre above the floating
    position) at KR = ``kr``: over ``window`` (s) least squares of F0 + c_s sin(omega t) + c_c cos(omega t) on the
    force and of z_s sin + z_c cos on the heave (its amplitude a and phase; the force's components are turned
    into the heave's phase), then a33 = (c_s + k a) / (a omega^2), b33 = -c_c / (a omega) (module docstring),
    k = ``stiffness_N_m`` (the exact waterplane's by default).
    ``residual``: the rms of the force fit's residual over the force's amplitude."""
    omega = math.sqrt(kr * hd.G / RADIUS_M)
    sel = (t_s >= window[0] - 1e-9) & (t_s <= window[1] + 1e-9)
    t = t_s[sel]
    basis = np.column_stack([np.ones_like(t), np.sin(omega * t), np.cos(omega * t)])
    (f0, fs, fc), *_ = np.linalg.lstsq(basis, fz_N[sel], rcond=None)
    (_, zs, zc), *_ = np.linalg.lstsq(basis, z_m[sel], rcond=None)
    a = math.hypot(zs, zc)
    phase = math.atan2(zc, zs)                 # z = a sin(omega t + phase)
    in_phase = fs * math.cos(phase) + fc * math.sin(phase)        # force along sin(omega t + phase)
    quadrature = -fs * math.sin(phase) + fc * math.cos(phase)     # along cos(omega t + phase)
    a33 = (in_phase + stiffness_N_m * a) / (a * omega ** 2)
    b33 = -quadrature / (a * omega)
    fit = basis @ np.array([f0, fs, fc])
    rho_v = hd.RHO_WATER * VOLUME_M3
    return {"A": float(a33 / rho_v), "B": float(b33 / (rho_v * omega)), "amplitude_m": float(a),
            "mean_force_N": float(f0), "residual": float(np.sqrt(np.mean((fz_N[sel] - fit) ** 2)) / math.hypot(fs, fc))}


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One rung through the driver (a row every 5 steps, about 100 per period): A against Hulme's at the rung's KR,
    beside it B."""
    n, w, kr = int(params["resolution"]), float(params["tank_diameters"]), float(params["kr"])
    sc = scene(n, w, kr, backend=backend, precision=precision)
    model = build_model(sc)
    steps = sc.run.steps
    ran = run_rung(model, sc, out_dir, NAME, params, steps=steps, sample_every=5)
    ts = ran.timeseries
    window = window_s(kr, w)
    res = analyse(ts["time_s"], ts["sphere_Fz_N"], ts["sphere_z_m"] - hd.DEPTH_M, kr, window)
    a_ref, b_ref = hulme(kr)
    return CaseResult(case=NAME, label=params["label"], resolution=float(n), cells=model.cells, steps=steps,
                      wall_s=ran.run_time_s, quantity="heave added mass A = a33 / (rho 2/3 pi R^3)", value=res["A"],
                      reference=a_ref, error=relative_error(res["A"], a_ref), backend=backend, precision=precision,
                      extra={"tank_diameters": w, "kr": kr, "B": res["B"], "B_reference": b_ref,
                             "amplitude_m": res["amplitude_m"], "window_from_s": window[0],
                             "window_to_s": window[1],
                             "mean_force_N": res["mean_force_N"],
                             "weight_displaced_N": hd.RHO_WATER * VOLUME_M3 * hd.G, "residual": res["residual"],
                             "volume_drift": float(np.abs(ts["water_volume_drift"]).max()),
                             "result_file": str(ran.path)})
