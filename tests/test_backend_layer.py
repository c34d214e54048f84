"""The backend layer owns numba: no kernel module imports it, and the backend and coupling modules import one way."""

import ast
from pathlib import Path

import iceresist

ROOT = Path(iceresist.__file__).parent

#: Modules outside iceresist/backends that may import numba: the run metadata reads its version and the device name.
ALLOWED = {"io/meta.py"}


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module
            for a in node.names:
                yield f"{node.module}.{a.name}"


def test_numba_is_imported_only_by_the_backend_layer():
    offenders = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith("backends/") or rel in ALLOWED:
            continue
        if any(name == "numba" or name.startswith("numba.") for name in _imports(path)):
            offenders.append(rel)
    assert not offenders, f"import numba through iceresist.backends instead: {offenders}"


def test_no_import_cycle_in_the_backend_and_coupling_modules():
    names = {}
    for sub in ("backends", "coupling"):
        for path in (ROOT / sub).glob("*.py"):
            if path.name != "__init__.py":
                names[f"iceresist.{sub}.{path.stem}"] = path
    edges = {m: {n for n in _imports(p) if n in names} for m, p in names.items()}

    def reaches(a, b):
        seen, todo = set(), [a]
        while todo:
            for n in edges[todo.pop()]:
                if n == b:
                    return True
                if n not in seen:
                    seen.add(n)
                    todo.append(n)
        return False

    cycles = sorted(m for m in names if reaches(m, m))
    assert not cycles, f"modules on an import cycle: {cycles}"
