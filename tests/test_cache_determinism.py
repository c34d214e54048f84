"""The kernel cache changes nothing but the time: a tier-1 case run with an empty kernel cache (every launcher
compiled in the process) and again with the cache it left (every launcher loaded) gives the same state bit for
bit. With numba's ``nsz`` fast-math flag beside ``reassoc`` it did not (9.954 against 9.799 N on the quick case
A-c68-v1.0), nor with ``arcp`` in the free surface's velocity extension (1 ulp in 3 175 velocity components of the
probe below, and a tier-2 case apart after a few steps): :data:`iceresist.backends.conf.CPU_FASTMATH` leaves both
out."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

PROBE = r'''
import hashlib, sys
import numpy as np
from iceresist.models.tier1 import Tier1Model
from iceresist.scene.load import parse_scene
from iceresist.scene.write import to_toml
from iceresist.scene.case_scenes import scene_data
d = scene_data("A-c68-v1.0", "quick", 1)
d["numerics"]["backend"] = "cpu"
m = Tier1Model(parse_scene(to_toml(d)), backend="cpu")
m.step(20)
h = hashlib.sha256()
def add(v):
    if isinstance(v, dict):
        for k in sorted(v):
            add(v[k])
    else:
        h.update(np.ascontiguousarray(np.asarray(v)).tobytes())
add(m.state())
print("STATE", m.iteration, h.hexdigest())
'''


#: The velocity extension of the free surface (one launcher, four passes) on a wavy surface with random velocities.
EXTENSION_PROBE = r'''
import hashlib
import numpy as np
from iceresist.backends.jit import cpu
from iceresist.freesurface.extension import extension_launcher, extend_velocity
from iceresist.grid.forest import BlockForest, Face
fo = BlockForest.uniform((32, 24, 40), {f: Face("wall") for f in ("x-", "x+", "z-", "z+")})
X, Y, Z = (a + 0.5 for a in fo.cell_coordinates())
phi = (0.5 + 0.5 * np.tanh(2 * (20.3 + 3 * np.sin(X / 5) - Z) / 3)).astype(np.float32)
u = (0.05 * np.random.default_rng(1).standard_normal((fo.nblocks, 3, 512))).astype(np.float32)
dist = np.zeros((fo.nblocks, 512), np.int8)
extend_velocity(extension_launcher(cpu, "float32"), fo.nblocks, phi, u, dist,
                np.ascontiguousarray(fo.nbr, dtype=np.int64))
print("STATE", hashlib.sha256(u.tobytes() + dist.tobytes()).hexdigest())
'''


def _state(cache: Path, probe: str = PROBE) -> str:
    env = {**os.environ, "ICERESIST_CACHE": str(cache)}
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=900,
                          cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stderr[-2000:]
    return next(line for line in done.stdout.splitlines() if line.startswith("STATE"))


def test_cold_and_warm_kernel_cache_give_the_same_state(tmp_path):
    cold = _state(tmp_path / "cache")          # compiles every launcher and fills the cache
    assert any((tmp_path / "cache" / "kernels").iterdir())
    warm = _state(tmp_path / "cache")          # loads them
    assert cold == warm


def test_the_free_surface_extension_compiled_and_loaded_gives_the_same_velocity(tmp_path):
    cold = _state(tmp_path / "cache", EXTENSION_PROBE)
    warm = _state(tmp_path / "cache", EXTENSION_PROBE)
    assert cold == warm
