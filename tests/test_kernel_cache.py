"""The on-disk kernel cache of the CPU launchers: keyed file names, and a second process loads instead of compiling."""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from iceresist.backends import jit
from iceresist.backends import cache


@jit.cpu.device
def _double(i, a):
    a[i] = 2.0 * i


SRC = "def t_double(n, a):\n    for i in prange(n):\n        item(i, a)\n"


def _launcher(key):
    return cache.cpu_launcher("t_double", SRC, {"item": _double}, [("t_double", True)], key)


def test_launchers_are_written_under_their_key_and_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("ICERESIST_CACHE", str(tmp_path))
    kern = _launcher("k1")
    a = np.zeros(5)
    kern(5, a)
    assert a.tolist() == [0, 2, 4, 6, 8]
    files = sorted(p.name for p in (tmp_path / "kernels").glob("t_double_*.py"))
    assert len(files) == 1
    assert list((tmp_path / "kernels" / "__pycache__").glob("*t_double_*.nbi"))  # numba saved the compile
    _launcher("k2")  # another fingerprint: another file
    assert len(list((tmp_path / "kernels").glob("t_double_*.py"))) == 2
    monkeypatch.setenv("ICERESIST_CACHE", "off")
    assert _launcher("k1") is None


def test_fingerprint_follows_variant_and_sources():
    mods = ("iceresist.dem.kernels",)
    assert cache.fingerprint("float64", mods) != cache.fingerprint("float32", mods)
    assert cache.fingerprint("float64", mods) != cache.fingerprint("float64", ("iceresist.coupling.kernels",))


SCRIPT = textwrap.dedent("""
    import json
    from iceresist.dem import DEMSystem, sphere
    s = DEMSystem(gravity_m_s2=(0, 0, 0))
    s.add_body(sphere(0.01, 1000.0), (0, 0, 0), (0.5, 0, 0))
    s.add_body(sphere(0.01, 1000.0), (0.0205, 0, 0), (-0.5, 0, 0))
    s.add_wall((-0.05, 0, 0), (1, 0, 0))
    s.step(0.001)
    s.contact_count()
    stats = {n: [len(f.kernel.stats.cache_hits), len(f.kernel.stats.cache_misses)]
             for n, f in s._k.items() if n != "sort"}
    print(json.dumps({"stats": stats, "x": s.positions[:, 0].tolist()}))
""")


def test_second_process_loads_the_dem_kernels_from_the_cache(capsys):
    import json

    if cache.cache_dir() is None:
        pytest.skip("the kernel cache is switched off (ICERESIST_CACHE=off)")
    exec(SCRIPT, {})  # this process: compiles (or loads) the launchers and saves them to the cache
    here = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0"}
    env["PYTHONPATH"] = os.pathsep.join([os.getcwd(), env.get("PYTHONPATH", "")])
    run = subprocess.run([sys.executable, "-c", SCRIPT], env=env, check=True, capture_output=True, text=True)
    there = json.loads(run.stdout.strip().splitlines()[-1])
    assert set(there["stats"]) == {"drift", "place", "contact", "gather", "count"}
    for name, (hits, misses) in there["stats"].items():
        assert hits == 1 and misses == 0, name  # loaded, not compiled
    assert there["x"] == here["x"]


SCRIPT_TANK = textwrap.dedent("""
    import gc, json
    from iceresist.backends.launch import _GeneratedLauncher
    from iceresist.models import build_model
    from iceresist.scene import parse_scene, preset_text
    text = preset_text("still_tank")
    model = build_model(parse_scene(text, "still_tank.toml"))
    model.step(2)
    stats = {}
    for o in gc.get_objects():
        try:
            mine = isinstance(o, _GeneratedLauncher) and not o.target.is_cuda
        except ReferenceError:      # a weak proxy whose object is gone
            continue
        if mine:
            st = getattr(o.kernel, "stats", None)
            if st is not None and (st.cache_hits or st.cache_misses):
                stats[o.label] = [len(st.cache_hits), len(st.cache_misses)]
    print(json.dumps({"stats": stats, "mass": float(model.diagnostics()["mass_kg"])}))
""")


def test_second_process_loads_every_free_surface_kernel_from_the_cache(capsys):
    """Every CPU launcher a free-surface scene calls (the pooled stream-collide, the phase field, velocity,
    extension, reflag, pool, probe) is loaded from the kernel cache by a second process, none compiled; the same
    mass bit for bit. Planted: the phase-field launchers built without their cache key fail (h_stream compiled)."""
    import json

    if cache.cache_dir() is None:
        pytest.skip("the kernel cache is switched off (ICERESIST_CACHE=off)")
    exec(SCRIPT_TANK, {})
    here = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0"}
    env["PYTHONPATH"] = os.pathsep.join([os.getcwd(), env.get("PYTHONPATH", "")])
    run = subprocess.run([sys.executable, "-c", SCRIPT_TANK], env=env, check=True, capture_output=True, text=True)
    there = json.loads(run.stdout.strip().splitlines()[-1])
    assert {"f_update", "h_stream", "h_collide", "velocity", "reflag", "extension"} <= set(there["stats"])
    for name, (hits, misses) in there["stats"].items():
        assert misses == 0 and hits >= 1, name  # loaded, not compiled
    assert there["mass"] == here["mass"]


SCRIPT_SCALE = textwrap.dedent("""
    import math
    import sys
    import numpy as np
    from iceresist.backends import cache, jit
    from iceresist.lbm.codegen import compile_source

    def launcher(k):
        # a function of the constant k compiled apart and too long for LLVM to inline, like the fused LBM step of
        # each operator
        body = "".join(f"    x = math.sqrt(x + {k}.0 + {j})\\n" for j in range(300))
        item = compile_source(f"def scale_item(i, a):\\n    x = 1.0 * i\\n{body}    a[i] = x\\n", "scale_item",
                              {"math": math}, lambda fn: jit.cpu.kernel(fn, parallel=False))
        src = "def t_scale(n, a):\\n    for i in prange(n):\\n        item(i, a)\\n"
        return cache.cpu_launcher("t_scale", src, {"item": item}, [("t_scale", True)], f"scale={k}")

    out = []
    for k in map(int, sys.argv[1:]):
        a = np.zeros(3)
        launcher(k)(3, a)
        out.append(float(a[1]))
    print(out)
""")


def test_two_variants_compiled_in_two_processes_keep_their_own_code(tmp_path):
    """Two processes compile one closure with another constant in the same order (so numba numbers both
    functions alike, under one hash seed); a third loads both from the cache and each must run its own constant.
    Planted: numba's counter from 1 again (``conf._distinct_function_ids`` not called): the third process runs the
    first one loaded twice."""
    # one hash seed: numba's names carry the fast-math flags in set order, which string hashing shuffles
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0", "ICERESIST_CACHE": str(tmp_path), "PYTHONHASHSEED": "0"}
    env["PYTHONPATH"] = os.pathsep.join([os.getcwd(), env.get("PYTHONPATH", "")])

    def child(*ks):
        run = subprocess.run([sys.executable, "-c", SCRIPT_SCALE, *map(str, ks)], env=env, check=True,
                             capture_output=True, text=True)
        return run.stdout.strip().splitlines()[-1]

    two, three = child(2), child(3)
    assert two != three
    assert child(2, 3) == f"[{two[1:-1]}, {three[1:-1]}]" and child(3, 2) == f"[{three[1:-1]}, {two[1:-1]}]"
