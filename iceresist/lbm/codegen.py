"""Straight-line code over 27 named scalars, generated once from the lattice tables.

Numba compiles a tuple of 27 scalars into registers on both targets; loops over
q through arrays cost about twice as much. Builders here
write Python source text, exec it in a namespace of typed constants, and hand
the function to ``target.device``.
"""

from __future__ import annotations

from iceresist.lattice import Q

F_NAMES = [f"f{q}" for q in range(Q)]


def unpack(tuple_name: str = "f", names=F_NAMES) -> str:
    """Source line that unpacks a 27-tuple into scalars."""
    return f"    {', '.join(names)} = {tuple_name}\n"


def compile_source(src: str, name: str, namespace: dict, device):
    """Exec ``src`` with ``namespace`` as globals and compile function ``name`` with ``device``."""
    ns = dict(namespace)
    exec(compile(src, f"<iceresist generated {name}>", "exec"), ns)
    fn = ns[name]
    fn.__iceresist_source__ = src
    return device(fn)


def term(coeff: int, name: str) -> str:
    """'+ name', '- name' or '' for an integer coefficient in {-1, 0, 1}."""
    return {1: f" + {name}", -1: f" - {name}", 0: ""}[int(coeff)]
