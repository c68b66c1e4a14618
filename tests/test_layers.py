"""The package's layers (docs/explanation/architecture.md), checked on the source with ``ast``.

Imports go one way, from a layer to its own layer or the layers below it:

    base → light → ground → models → daily loop → render/tune/sweeps → cli

and there are no import cycles among the package's modules, counting imports made inside
functions as well as those at the top of a module. Imports inside functions are kept to a short
list, each with its reason. ``python tests/test_layers.py`` prints every finding.
"""
from __future__ import annotations

import ast
import importlib
import sys
import tomllib
import types
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "mitsuba_veg"
# where each package's modules are on disk (``integrators/`` ships as mitsuba_veg.integrators)
SOURCES = {PACKAGE: ROOT / "mitsuba_veg", f"{PACKAGE}.integrators": ROOT / "integrators"}

# The layers, lowest first; a module belongs to the layer of its longest matching prefix (the
# names are relative to ``mitsuba_veg``). Keep this table and docs/explanation/architecture.md the same.
LAYERS: list[tuple[str, list[str]]] = [
    ("base", ["backend", "errors", "defaults", "atomic", "arrays", "meshes", "outputs", "parallel",
              "plots", "units"]),
    ("light", ["light", "integrators"]),   # integrators/: every Mitsuba plugin of the package
    ("ground", ["soil", "climate", "terrain", "forest_floor", "scenario", "inputs"]),
    ("models", ["moss", "trees", "foliage", "world", "export_gltf"]),
    ("daily loop", ["daily"]),
    ("render/tune/sweeps", ["render", "tune", "sweeps", "canopy_photo"]),
    ("cli", ["cli", "tune.__main__"]),
]
# the package's own __init__ (the public facade, ``import mitsuba_veg as mv``) sits above all
FACADE = PACKAGE

# Edges from a module to a package above the module it imports, left out of the cycle search,
# with the reason (importer, package). Importing ``a.b.c`` runs ``a.b``'s ``__init__`` first; an
# importer listed here reads only the named submodule, which imports nothing of that package,
# never a name the package's ``__init__`` binds, so a partly run ``__init__`` serves it. Its
# edge to the submodule itself stays in the search
# (test_left_out_package_edges_read_leaf_submodules).
PACKAGE_EDGES_ALLOWED: dict[tuple[str, str], str] = {
    ("mitsuba_veg.integrators.veg_sky", "mitsuba_veg.light"):
        "the veg_sky plugin reads its radiance model, light.sky (base imports only); light's "
        "__init__ imports the photon pass, which imports the plugins' package "
        "(mitsuba_veg.integrators): whichever of the two packages is imported first, the "
        "other finds the submodule it reads",
}

# Imports inside functions that stay, with the reason (importer, imported module).
LAZY_ALLOWED: dict[tuple[str, str], str] = {
    ("mitsuba_veg.cli.grow", "mitsuba_veg.trees.weber_penn"):
        "`model = \"weber_penn\"` without the module is a one-line error "
        "(tests/test_tree_cli.py::test_weber_penn_model)",
    ("mitsuba_veg.render.gltf_day", "mitsuba_veg.export_gltf"):
        "the glTF writer imports trimesh (a few tenths of a second): only an export pays for it, "
        "not every render command",
}


def _module_files() -> dict[str, Path]:
    """Every module of the package by dotted name (packages by their ``__init__``)."""
    mods = {}
    for pkg, base in SOURCES.items():
        for path in base.rglob("*.py"):
            rel = path.relative_to(base).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            name = ".".join([pkg, *parts])
            if pkg == PACKAGE and name.startswith(f"{PACKAGE}.integrators"):
                continue
            mods[name] = path
    return mods


MODULES = _module_files()


def _is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


def _resolve(importer: str, node: ast.AST) -> list[str]:
    """The package modules that an import statement loads (most specific existing name)."""
    out = []
    if isinstance(node, ast.Import):
        for alias in node.names:
            name = alias.name
            while name and name not in MODULES:
                name = name.rpartition(".")[0]
            if name:
                out.append(name)
        return out
    assert isinstance(node, ast.ImportFrom)
    if node.level:
        base = importer if _is_package(importer) else importer.rpartition(".")[0]
        for _ in range(node.level - 1):
            base = base.rpartition(".")[0]
        base = f"{base}.{node.module}" if node.module else base
    else:
        base = node.module or ""
    if not (base == PACKAGE or base.startswith(PACKAGE + ".")):
        return out
    for alias in node.names:
        sub = f"{base}.{alias.name}"
        if sub in MODULES:
            out.append(sub)
        else:
            name = base
            while name and name not in MODULES:
                name = name.rpartition(".")[0]
            if name:
                out.append(name)
    return out


def imports() -> list[tuple[str, str, bool, int]]:
    """(importer, imported, inside a function, line) for every package-internal import."""
    found = set()
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text(), filename=str(path))

        def visit(node, in_func):
            for child in ast.iter_child_nodes(node):
                inner = in_func or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                      ast.Lambda))
                if isinstance(child, (ast.Import, ast.ImportFrom)):
                    for target in _resolve(name, child):
                        if target != name:
                            found.add((name, target, in_func, child.lineno))
                visit(child, inner)

        visit(tree, False)
    return sorted(found)


def layer_of(module: str) -> int:
    """The index in :data:`LAYERS` of a module (``len(LAYERS)`` for the facade)."""
    if module == FACADE:
        return len(LAYERS)
    rel = module[len(PACKAGE) + 1:]
    best, best_len = None, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (rel == p or rel.startswith(p + ".")) and len(p) > best_len:
                best, best_len = i, len(p)
    if best is None:
        raise AssertionError(f"{module} is in no layer of tests/test_layers.py")
    return best


def cycles(edges) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    graph = defaultdict(set)
    for a, b in edges:
        graph[a].add(b)
    index, low, stack, on, comps = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(10000)

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in list(MODULES):
        if v not in index:
            strong(v)
    return comps


def _ancestors(module: str) -> list[str]:
    """The packages above a module, facade excluded (``a.b.c`` -> ``a.b``)."""
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(2, len(parts))]


def _graph_edges():
    """Import edges for the cycle search. Importing ``a.b.c`` runs ``a.b``'s ``__init__``
    first, so an edge to a module is also an edge to the packages above it (those that are
    not above the importer itself: they are being imported already). Edges into the facade
    are left out: it is always imported first (and imports of it are reported apart); so are
    the allowed lazy imports (they run on first use, not when the module loads)."""
    edges = set()
    for a, b, _, _ in imports():
        if b == FACADE or (a, b) in LAZY_ALLOWED:
            continue
        mine = set(_ancestors(a)) | {a}
        for t in [b, *_ancestors(b)]:
            if t != b and (a, t) in PACKAGE_EDGES_ALLOWED:
                continue
            if t not in mine and t in MODULES:
                edges.add((a, t))
    return edges


def _a_cycle(comp, edges) -> list[str]:
    """One shortest cycle through the first module of a strongly connected component."""
    comp = set(comp)
    start = min(comp)
    prev, frontier = {start: None}, [start]
    while frontier:
        nxt = []
        for v in frontier:
            for a, b in edges:
                if a == v and b in comp:
                    if b == start:
                        path = [v]
                        while prev[path[-1]] is not None:
                            path.append(prev[path[-1]])
                        return [start, *reversed(path[:-1]), start] if len(path) > 1 else \
                            [start, v, start]
                    if b not in prev:
                        prev[b] = v
                        nxt.append(b)
        frontier = nxt
    return []


def findings() -> dict[str, list[str]]:
    """Every violation, by kind."""
    edges = imports()
    out = {"cycles": [], "upward": [], "cli imported from below": [], "facade imported": [],
           "in-function": []}
    graph = _graph_edges()
    for comp in cycles(graph):
        out["cycles"].append(" <-> ".join(comp) + "; e.g. " + " -> ".join(_a_cycle(comp, graph)))
    for a, b, in_func, line in edges:
        where = f"{a}:{line} -> {b}"
        if a == FACADE:
            continue
        if b == FACADE:
            out["facade imported"].append(where)
            continue
        if layer_of(b) == len(LAYERS) - 1 and layer_of(a) != layer_of(b):
            out["cli imported from below"].append(where)
        if layer_of(b) > layer_of(a):
            out["upward"].append(f"{where} ({LAYERS[layer_of(a)][0]} -> {LAYERS[layer_of(b)][0]})")
        if in_func and (a, b) not in LAZY_ALLOWED:
            out["in-function"].append(where)
    return out


def test_every_module_has_a_layer():
    for m in MODULES:
        layer_of(m)


# Modules whose findings are listed, not failed, while they are being rewritten (module: reason).
# Empty: every module follows the layers.
PENDING: dict[str, str] = {}


def _open(kind) -> list[str]:
    """Findings of a kind outside the pending modules."""
    return [f for f in findings()[kind] if f.split(":")[0] not in PENDING]


def test_no_import_cycles():
    assert findings()["cycles"] == []


def test_nothing_below_cli_imports_it():
    assert _open("cli imported from below") == []


def test_imports_go_downwards():
    assert _open("upward") == []
    assert findings()["facade imported"] == []


def test_in_function_imports_are_listed():
    assert _open("in-function") == []
    used = {(a, b) for a, b, in_func, _ in imports() if in_func}
    assert not set(LAZY_ALLOWED) - used, "allow-list entries no longer needed"


def test_left_out_package_edges_read_leaf_submodules():
    """Each importer of PACKAGE_EDGES_ALLOWED imports submodules of the package, never the
    package itself, and those submodules import nothing of the package."""
    found = imports()
    for a, pkg in PACKAGE_EDGES_ALLOWED:
        targets = {b for x, b, _, _ in found if x == a and b.startswith(pkg + ".")}
        assert targets, f"{a} no longer imports from {pkg}: drop its entry"
        assert not [b for x, b, _, _ in found if x == a and b == pkg], (a, pkg)
        for sub in targets:
            inner = [b for x, b, _, _ in found
                     if x == sub and (b == pkg or b.startswith(pkg + "."))]
            assert inner == [], (sub, inner)


def test_pending_modules_still_exist():
    assert not set(PENDING) - set(MODULES)


# `mv.<package>.<name>` should name the module <name>.py, not a function that the package's
# __init__ imports over it (the modules of `variant`, `light.daylight`, `light.sun_position` and
# `moss.fitness` and `tune.fit` are backend, light.clear_sky, light.solar_position,
# moss.fitness_model and tune.fitting). None may come back.
SHADOWED: set[str] = set()


def test_package_attributes_name_modules():
    shadowed = set()
    for name, path in MODULES.items():
        if path.name != "__init__.py" or name.endswith(".integrators"):
            continue
        pkg = importlib.import_module(name)
        for sub in MODULES:
            if sub.rpartition(".")[0] == name:
                attr = getattr(pkg, sub.rpartition(".")[2], None)
                if attr is not None and not isinstance(attr, types.ModuleType):
                    shadowed.add(sub)
    assert shadowed <= SHADOWED, sorted(shadowed - SHADOWED)


def test_every_package_ships():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(cfg["tool"]["setuptools"]["packages"])
    packages = {m for m, p in MODULES.items() if p.name == "__init__.py"}
    assert not packages - listed, "add them to [tool.setuptools] packages in pyproject.toml"


def test_layer_names_match_the_architecture_doc():
    doc = (ROOT / "docs" / "explanation" / "architecture.md").read_text()
    for name, _ in LAYERS:
        assert name in doc, name


if __name__ == "__main__":
    f = findings()
    for kind, items in f.items():
        print(f"== {kind}: {len(items)}")
        for it in items:
            print("  ", it)


def test_integrators_are_imported_as_part_of_the_package():
    """``integrators/`` ships as ``mitsuba_veg.integrators``: imported as a top-level
    ``integrators`` package it would be a second copy of the module, registering the plugin
    again with its own caches (a scene's index dropped in one copy stays in the other)."""
    found = []
    for folder in ("tests", "benchmarks", "scripts", "mitsuba_veg", "integrators"):
        for path in (ROOT / folder).rglob("*.py"):
            for i, line in enumerate(path.read_text().splitlines(), 1):
                s = line.strip()
                if s.startswith(("from integrators", "import integrators")):
                    found.append(f"{path.relative_to(ROOT)}:{i}: {s}")
    assert found == []
