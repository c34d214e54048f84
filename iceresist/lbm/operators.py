"""Registry of collision operators by name (``"bgk"``, ``"cumulant"``).

Every builder has the signature ``build(target, real, **options)`` and returns a
device function ``collide(f, omega, Fx, Fy, Fz) -> 27-tuple`` (see :mod:`iceresist.lbm.collide`).
"""

from __future__ import annotations

from iceresist.backends import jit
from iceresist.lattice import Q, W
from iceresist.lbm.codegen import compile_source
from iceresist.lbm.collide import build_collide_bgk
from iceresist.lbm.cumulant import build_collide_cumulant

_BUILDERS = {"bgk": build_collide_bgk, "cumulant": build_collide_cumulant}

#: Names accepted by :func:`get_collide_builder`.
OPERATORS = tuple(_BUILDERS)


def get_collide_builder(name: str):
    """Return the builder of collision operator ``name`` (``'bgk'`` or ``'cumulant'``)."""
    try:
        return _BUILDERS[name]
    except KeyError:
        raise ValueError(f"collision operator must be one of {', '.join(OPERATORS)}, not {name!r}") from None


def cpu_cell_rate(name: str, precision: str = "float32", cells: int = 1_000_000, repeats: int = 3) -> float:
    """Single-core throughput of one collision operator in million cells per second.

    A serial ``njit`` loop over ``cells`` cells reads 27 populations of a (cells, 27) array,
    calls the operator and writes the result to a second array (unrolled writes); compile
    time is excluded and the best of ``repeats`` sweeps is taken.
    """
    import time

    import numpy as np

    real = jit.real_type(precision)
    src = "def sweep(f, fo, omega, Fx, Fy, Fz):\n    for i in range(f.shape[0]):\n"
    src += "        r = collide((" + ", ".join(f"f[i, {q}]" for q in range(Q)) + "), omega, Fx, Fy, Fz)\n"
    src += "".join(f"        fo[i, {q}] = r[{q}]\n" for q in range(Q))
    ns = {"collide": get_collide_builder(name)(jit.cpu, real)}
    sweep = compile_source(src, "sweep", ns, jit.cpu_jit)

    rng = np.random.default_rng(0)
    f = (W * 1e-3 * rng.standard_normal((cells, Q))).astype(real)
    fo = np.zeros_like(f)
    args = (real(1.8), real(1e-6), real(0.0), real(0.0))
    sweep(f[:16], fo[:16], *args)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        sweep(f, fo, *args)
        best = min(best, time.perf_counter() - t0)
    return cells / best / 1e6
