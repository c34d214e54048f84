"""The kernel cache changes nothing but the time: a tier-1 case run with an empty kernel cache (every launcher
compiled in the process) and again with the cache it left (every launcher loaded) gives the same state bit for
bit. With numba's ``nsz`` fast-math flag beside ``reassoc`` it did not (9.954 against 9.799 N on the quick case
A-c68-v1.0): :data:`iceresist.backends.conf.CPU_FASTMATH` leaves ``nsz`` out."""

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
from iceresist.ship.presets import scene_data
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


def _state(cache: Path) -> str:
    env = {**os.environ, "ICERESIST_CACHE": str(cache)}
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=900,
                          cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stderr[-2000:]
    return next(line for line in done.stdout.splitlines() if line.startswith("STATE"))


def test_cold_and_warm_kernel_cache_give_the_same_state(tmp_path):
    cold = _state(tmp_path / "cache")          # compiles every launcher and fills the cache
    assert any((tmp_path / "cache" / "kernels").iterdir())
    warm = _state(tmp_path / "cache")          # loads them
    assert cold == warm
