"""The import contract of the packages (docs/ARCHITECTURE.md, "The layers"), read from the source with ``ast``.

Every ``import`` counts, also those inside functions (a cycle hidden in a function-level import is still a
cycle). The rules:

* layers (:data:`LAYER_PARTS`, from the bottom): base (backends, lattice, errors, units, io, console) < grid
  (grid, parallel: the grid owns its split over the ranks) < kernels (lbm, freesurface, dem, coupling) < domain
  (ship, scene, limits) < post < models < driver (simulation, watchdog, driver, run, sweep, validate) < the
  command line (iceresist.cli); every part of the package is ranked and nothing imports a layer above its own (so
  post imports neither the models nor the driver, and ship, below nothing of scene, cannot import it);
* no module imports a private name (``_x``) of a module in another part of the package;
* data flows one way: engine -> files -> ``iceresist.post`` -> ``reports``: nothing under iceresist/ imports
  ``reports`` except the composition root ``iceresist.cli``; ``reports`` imports from iceresist only
  ``post``, ``io`` and ``errors``; ``fsicr`` imports nothing from iceresist;
* no import cycles between modules of iceresist/, fsicr/ and reports/.

``__main__`` modules are entry points (they may call the command line) and are not checked against the layers.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("iceresist", "fsicr", "reports")

#: The layers from the bottom up, each with the top-level parts of iceresist it holds: a part may import its own
#: layer and those below, never one above (docs/ARCHITECTURE.md, "The layers"). Every part is ranked
#: (:func:`test_every_part_of_the_package_is_ranked`).
LAYER_PARTS = (
    ("base", {"backends", "lattice", "errors", "units", "io", "console"}),
    ("grid", {"grid", "parallel"}),
    ("kernels", {"lbm", "freesurface", "dem", "coupling"}),
    ("domain", {"ship", "scene", "limits"}),
    ("post", {"post"}),
    ("models", {"models"}),
    ("driver", {"simulation", "watchdog", "driver", "run", "sweep", "validate"}),
    ("cli", {"cli"}),
)
LAYERS = {part: level for level, (_, parts) in enumerate(LAYER_PARTS) for part in parts}
LAYER_NAMES = tuple(name for name, _ in LAYER_PARTS)
#: What reports may import from iceresist.
REPORTS_MAY_IMPORT = ("iceresist.post", "iceresist.io", "iceresist.errors")


@cache
def modules() -> dict[str, Path]:
    """Dotted module name -> file, for every module of the packages."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _known(name: str) -> str | None:
    """The longest prefix of ``name`` that is one of our modules (None for a third-party name)."""
    mods = modules()
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        cand = ".".join(parts[:k])
        if cand in mods:
            return cand
    return None


@cache
def imports() -> dict[str, set[str]]:
    """Module -> the set of our modules it imports (anywhere in the file, functions included)."""
    mods = modules()
    graph = {}
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        package = name if is_pkg else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base_parts = package.split(".")
                    base_parts = base_parts[:len(base_parts) - (node.level - 1)]
                    base = ".".join(base_parts + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
            else:
                continue
            for t in targets:
                k = _known(t)
                if k is not None and k != name:
                    found.add(k)
        graph[name] = found
    return graph


def _edges():
    for src, targets in imports().items():
        for dst in sorted(targets):
            yield src, dst


def _part(module: str) -> str | None:
    """The top-level part of iceresist a module belongs to (``iceresist.dem.system`` -> ``dem``)."""
    parts = module.split(".")
    return parts[1] if parts[0] == "iceresist" and len(parts) > 1 else None


def layer_violations() -> list[str]:
    bad = []
    for src, dst in _edges():
        if src.rpartition(".")[2] == "__main__":
            continue
        ls, ld = LAYERS.get(_part(src)), LAYERS.get(_part(dst))
        if ls is not None and ld is not None and ld > ls:
            bad.append(f"{src} ({LAYER_NAMES[ls]}) imports {dst} ({LAYER_NAMES[ld]})")
    return bad


def flow_violations() -> list[str]:
    bad = []
    for src, dst in _edges():
        top_s, top_d = src.split(".")[0], dst.split(".")[0]
        if top_s == "iceresist" and top_d == "reports" and src != "iceresist.cli":
            bad.append(f"{src} imports {dst}: only iceresist.cli composes the engine with the reports")
        if top_s == "fsicr" and top_d == "iceresist":
            bad.append(f"{src} imports {dst}: fsicr stands alone")
        if top_s == "reports" and top_d == "iceresist" and not any(
                dst == ok or dst.startswith(ok + ".") for ok in REPORTS_MAY_IMPORT):
            bad.append(f"{src} imports {dst}: reports read files through {', '.join(REPORTS_MAY_IMPORT)} only")
    return bad


def import_cycles() -> list[frozenset]:
    """The strongly connected components of more than one module (Tarjan), each one cycle or knot of cycles."""
    graph = imports()
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
        # iterative Tarjan: (node, iterator over its successors)
        work = [(v, iter(sorted(graph[v])))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        while work:
            node, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[node] = min(low[node], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = set()
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.add(w)
                        if w == node:
                            break
                    if len(comp) > 1:
                        out.append(frozenset(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out, key=sorted)


def _describe(cycles) -> str:
    return "\n".join("  " + " <-> ".join(sorted(c)) for c in cycles)


def test_the_import_graph_is_read():
    """The graph sees imports inside functions and relative imports (else the contract proves nothing)."""
    g = imports()
    assert {"iceresist.cli", "iceresist.post.case", "reports.report", "fsicr"} <= set(g)
    assert "reports.report" in g["iceresist.cli"]
    assert "iceresist.lbm.operators" in g["iceresist.lbm.solver"]  # a function-level import
    assert "iceresist.post.case" in g["reports.report"]


def parts() -> set[str]:
    """The top-level parts of iceresist (packages and modules, ``__main__`` left out)."""
    return {_part(m) for m in modules() if _part(m) not in (None, "__main__")}


def private_imports() -> list[str]:
    """``from a.b import _name`` where a.b lies in another part of iceresist than the importing module."""
    bad = []
    for name, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if not isinstance(node, ast.ImportFrom) or node.level or not (node.module or "").startswith("iceresist."):
                continue
            if _part(node.module) == _part(name):
                continue
            for a in node.names:
                if a.name.startswith("_"):
                    bad.append(f"{name} imports {node.module}.{a.name}")
    return bad


def function_imports() -> list[str]:
    """Imports of the project's modules (iceresist, fsicr, reports) inside a function of iceresist without a
    ``# deferred:`` comment on the line or the line above saying what the deferral spares (an optional or costly
    dependency): module-level imports show what a module needs, and a cycle cannot hide in a function."""
    bad = []
    for name, path in modules().items():
        if not name.startswith("iceresist.") or name.endswith("__main__"):
            continue
        lines = path.read_text(encoding="utf-8").splitlines()
        tree = ast.parse("\n".join(lines), str(path))
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Import):
                    mods = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom):
                    mods = ["." if node.level else (node.module or "")]
                else:
                    continue
                if not any(m == "." or m.split(".")[0] in PACKAGES for m in mods):
                    continue
                said = lines[node.lineno - 1] + (lines[node.lineno - 2] if node.lineno > 1 else "")
                if "# deferred:" not in said:
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno} ({fn.name})")
    return sorted(set(bad))


def test_the_project_is_imported_at_module_level():
    bad = function_imports()
    assert not bad, "imports of the project inside functions (move them up, or say why with # deferred:):\n  " + \
        "\n  ".join(bad)


def test_every_part_of_the_package_is_ranked():
    assert parts() <= set(LAYERS), f"parts with no layer: {sorted(parts() - set(LAYERS))}"


def test_no_private_name_crosses_a_part():
    bad = private_imports()
    assert not bad, "private names imported across parts:\n  " + "\n  ".join(bad)


def test_layers_kernels_below_models_below_cli():
    bad = layer_violations()
    assert not bad, "imports against the layers:\n  " + "\n  ".join(bad)


def test_data_flows_one_way_engine_files_post_reports():
    bad = flow_violations()
    assert not bad, "imports against the one-way flow:\n  " + "\n  ".join(bad)


def test_no_import_cycles():
    cycles = import_cycles()
    assert not cycles, f"import cycles:\n{_describe(cycles)}"
