"""Fixed sphere in uniform flow: drag coefficient against Schiller-Naumann (the kind of set-up of
tests/test_sphere_drag.py, in smaller boxes: that test uses a 12 x 8 x 8 d box with the sphere 4 d behind the inlet).

Velocity inlet at x-, pressure outlet at x+, periodic sides; the sphere (a fixed body of the scene, coupled
by interpolated bounce-back and momentum exchange, paper eqs. 16-19) sits 3 diameters behind the inlet. The set-up
is the scene file iceresist/validate/scenes/sphere_drag.toml (the middle quick rung); a rung sets its resolution
over it and runs it through the driver. The quick
box (8 x 4 x 4 d) repeats the sphere every 4 d sideways, which is most of its 18-24 % error (docs/VALIDATION.md).
Re = U d / nu = 10, U = 0.1 (lattice). The run lasts 16 d / U and C_d is the mean of the time series' fluid force
(a row every 1/80 of the run) over its last quarter.
"""

from __future__ import annotations

import math

import numpy as np

from iceresist.models import build_model
from iceresist.validate.result import CaseResult, relative_error
from iceresist.validate.rung import run_rung, scene_of
from iceresist.validate.scenes import scene_data

NAME = "sphere_drag"
REFERENCE = ("Schiller-Naumann C_d = 24/Re (1 + 0.15 Re^0.687) at Re = 10 (Clift, Grace and Weber 1978). "
             "The domain is fixed in diameters (quick 8 x 4 x 4 d, blockage pi/64 = 4.9 %; full 12 x 8 x 8 d, "
             "1.2 %), so the error holds the blockage and the finite domain beside the resolution error and "
             "levels off at the blockage error on the finest rungs")
REYNOLDS = 10.0
U_LATTICE = 0.1
RUN_DIAMETERS = 16.0     # run length in d / U
MEAN_FRACTION = 0.25     # drag averaged over this last part of the run


def schiller_naumann(re: float) -> float:
    return 24.0 / re * (1.0 + 0.15 * re ** 0.687)


def ladder(quick: bool) -> list[dict]:
    """Cells per diameter 6/8/12 in an 8 x 4 x 4 d box (quick), 16/24/32 in a 12 x 8 x 8 d box (full)."""
    ds, box = ((6, 8, 12), (8, 4, 4)) if quick else ((16, 24, 32), (12, 8, 8))
    return [{"label": f"{d} cells/diameter", "resolution": float(d), "d": d, "box_diameters": box}
            for d in ds]


def steps_for(d: float) -> int:
    """Steps of a rung: ``RUN_DIAMETERS`` d / U."""
    return int(RUN_DIAMETERS * d / U_LATTICE)


def scene(params: dict, *, backend: str = "cpu", precision: str = "float32"):
    """The scene of a rung: the scene file (iceresist/validate/scenes/sphere_drag.toml, the middle quick rung)
    with the rung's diameter ``d`` (cells), box (``box_diameters``, rounded up to whole blocks), tau (Re = 10),
    sphere radius and position (3 d behind the inlet, centred sideways) and run length set over it."""
    d = float(params["d"])
    shape = [int(math.ceil(n * d / 8) * 8) for n in params["box_diameters"]]
    nu = U_LATTICE * d / REYNOLDS
    data = scene_data(NAME)
    data["scene"].update(name=f"{NAME}-{d:g}", description=f"fixed sphere, Re {REYNOLDS:g}, {d:g} cells per "
                         f"diameter, {' x '.join(f'{n:g}' for n in params['box_diameters'])} d box")
    data["domain"]["cells"] = shape
    data["numerics"].update(tau=3 * nu + 0.5, precision=precision, backend=backend)
    data["run"] = {"steps": steps_for(d)}
    data["bodies"][0].update(radius_m=d / 2, position_m=[3 * d, shape[1] / 2, shape[2] / 2])
    return scene_of(data, f"{NAME} {params['label']}")


def run(params: dict, *, backend: str = "cpu", precision: str = "float32", out_dir=None) -> CaseResult:
    """One rung through the driver (:func:`iceresist.validate.rung.run_rung`): C_d from the mean of the fluid
    force (``sphere_Fx_N``, eq. 20, lattice units) over the rows of the last ``MEAN_FRACTION`` of the run."""
    d = float(params["d"])
    sc = scene(params, backend=backend, precision=precision)
    steps = steps_for(d)
    rung = run_rung(build_model(sc), sc, out_dir, NAME, params, steps=steps, sample_every=max(1, steps // 80))
    it, fx = rung.timeseries["iteration"], rung.timeseries["sphere_Fx_N"]
    force = float(fx[it >= (1 - MEAN_FRACTION) * steps].mean())
    radius = d / 2
    cd = force / (0.5 * U_LATTICE ** 2 * math.pi * radius ** 2)
    ref = schiller_naumann(REYNOLDS)
    cells = int(np.prod(sc.domain.padded_cells()))
    return CaseResult(case=NAME, label=params["label"], resolution=d, cells=cells, steps=rung.steps,
                      wall_s=rung.run_time_s, quantity="drag coefficient C_d", value=cd, reference=ref,
                      error=relative_error(cd, ref), backend=backend, precision=precision,
                      extra={"tau": 3 * (U_LATTICE * d / REYNOLDS) + 0.5,
                             "blockage": math.pi / 4 / (params["box_diameters"][1] * params["box_diameters"][2]),
                             "result_file": str(rung.path)})
