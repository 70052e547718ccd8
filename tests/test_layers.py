"""The package's layers hold, counting imports inside functions too, and no modules import each other around a circle.

Layers, top to bottom (docs/layout.md): cli/api -> plan/stages -> builders, dataset -> mixing, io -> lidar -> geometry.
A builder is one package, ``builders/<name>/``: its pure geometry (every file but ``params.py``, ``__init__.py`` and
the Blender side ``scene*.py`` / ``*_nodes.py``) keeps geometry's rule, its own package's geometry aside; the shared
Blender side (``blender``) serves every builder and the population, and imports neither.
An import is an edge from the importing module to the module it names (``from pkg import name`` names
``pkg.name`` when that is a module), wherever the statement sits: module level, inside a function, or
under ``if TYPE_CHECKING`` (an annotation-only import still ties the layers together for a reader), with no
exception. No compatibility layer either: no module-level ``__getattr__`` and no import finder on ``sys.meta_path``;
when a module moves, its callers move with it.

``python tests/test_layers.py`` prints the figures: the largest circle, the wrong-way imports and the
imports inside functions.
"""

from __future__ import annotations

import ast
import sys
from collections import Counter
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "bpy_pipeline"

# layer -> what it must not import (prefixes of dotted names below bpy_pipeline)
FORBIDDEN = {
    "geometry": ("lidar", "io", "config", "pipeline", "builders", "population", "blender", "mixing", "plan", "stages", "dataset", "api", "cli", "rig", "frame"),
    "lidar": ("io", "config", "pipeline", "builders", "population", "blender", "mixing", "plan", "stages", "dataset", "api", "cli", "rig", "frame"),
    "io": ("pipeline", "builders", "population", "blender", "plan", "stages", "dataset", "api", "cli", "mixing", "lidar", "rig", "config"),
    "mixing": ("pipeline", "builders", "population.params", "population.scene", "blender", "plan", "stages", "dataset", "api", "cli", "rig", "config",
               "frame", "evaluate"),
    # the population every builder gets: its section and placement, and its Blender side on the shared one
    "population": ("lidar", "io", "config", "pipeline", "builders", "mixing", "plan", "stages", "dataset", "api", "cli", "rig", "frame"),
}
BUILDER_PACKAGES = tuple(sorted(p.parent.name for p in (PACKAGE / "builders").glob("*/__init__.py")))
FORBIDDEN["blender"] = ("population",) + tuple(f"builders.{b}" for b in BUILDER_PACKAGES)
# what io may use of lidar: the point record and the sensor's layout (its spec, rings, columns, frame time)
ALLOWED = {"io": ("lidar.points", "lidar.sensor.grid", "lidar.sensor.sensors")}


def builder_geometry(rel: str) -> bool:
    """``builders.<builder>.<file>`` that is the builder's pure geometry (not params, not its Blender side)."""
    parts = rel.split(".")
    if len(parts) != 3 or parts[0] != "builders" or parts[1] not in BUILDER_PACKAGES:
        return False
    leaf = parts[2]
    return leaf != "params" and leaf != "scene" and not leaf.startswith("scene_") and not leaf.endswith("_nodes")


def rules(rel: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(forbidden, allowed)`` prefixes for the module ``rel`` (dotted, below bpy_pipeline)."""
    if builder_geometry(rel):  # geometry's rule; its own package's geometry is fine
        package = rel.rpartition(".")[0]
        own = tuple(f"{package}.{p.stem}" for p in sorted((PACKAGE / package.replace(".", "/")).glob("*.py")) if builder_geometry(f"{package}.{p.stem}"))
        return FORBIDDEN["geometry"], own
    layer = rel.split(".")[0]
    return FORBIDDEN.get(layer, ()), ALLOWED.get(layer, ())


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports(path: Path, name: str, known: set[str]) -> list[tuple[str, int, bool]]:
    """``[(imported module, line, inside a function)]`` of the package's own modules that ``path`` imports."""
    tree = ast.parse(path.read_text(), str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []

    def visit(node, in_function: bool):
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    if alias.name.split(".")[0] == "bpy_pipeline":
                        out.append((alias.name, child.lineno, in_function))
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")
                    base = base[: len(base) - (child.level - 1)]
                    target = ".".join(base + ([child.module] if child.module else []))
                else:
                    target = child.module or ""
                if target.split(".")[0] != "bpy_pipeline":
                    continue
                for alias in child.names:
                    sub = f"{target}.{alias.name}"
                    out.append((sub if sub in known else target, child.lineno, in_function))
            visit(child, inner)

    visit(tree, False)
    return [row for row in out if row[0] in known and row[0] != name]


def graph() -> tuple[dict[str, set[str]], list[tuple[str, str, int, bool]]]:
    """``({module: modules it imports}, [(module, imported, line, inside a function)])``, every import counted."""
    found = modules()
    known = set(found)
    edges: dict[str, set[str]] = {m: set() for m in found}
    rows = []
    for name, path in found.items():
        for target, line, in_function in imports(path, name, known):
            edges[name].add(target)
            rows.append((name, target, line, in_function))
    return edges, rows


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), largest first."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(10000)

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                out.append(sorted(part))

    for v in sorted(edges):
        if v not in index:
            strong(v)
    return sorted(out, key=len, reverse=True)


def short(name: str) -> str:
    return name.removeprefix("bpy_pipeline.")


def wrong_way(rows) -> list[tuple[str, str, int]]:
    """``[(module, imported, line)]``: imports against the layers."""
    out = []
    for name, target, line, _ in rows:
        rel = short(target)
        forbidden, allowed = rules(short(name))
        if any(rel == f or rel.startswith(f + ".") for f in forbidden) and not any(rel == a or rel.startswith(a + ".") for a in allowed):
            out.append((short(name), rel, line))
    return out


def compat_hooks(path: Path) -> list[str]:
    """What keeps old import paths alive in ``path``: a module-level ``__getattr__`` or a use of ``sys.meta_path``."""
    tree = ast.parse(path.read_text(), str(path))
    found = [f"__getattr__ at line {node.lineno}" for node in tree.body if isinstance(node, ast.FunctionDef) and node.name == "__getattr__"]
    found += [f"sys.meta_path at line {node.lineno}" for node in ast.walk(tree)
              if isinstance(node, ast.Attribute) and node.attr == "meta_path" and isinstance(node.value, ast.Name) and node.value.id == "sys"]
    return found


def test_no_compatibility_layer():
    found = {short(name): hooks for name, path in modules().items() if (hooks := compat_hooks(path))}
    assert not found, f"old import paths kept alive (move the callers instead): {found}"


def test_layers_import_one_way():
    _, rows = graph()
    bad = wrong_way(rows)
    assert not bad, "imports against the layers:\n" + "\n".join(f"  {m}:{line} imports {t}" for m, t, line in bad)


def test_no_circles_between_modules():
    edges, _ = graph()
    found = circles(edges)
    assert not found, f"{len(found)} circles; the largest ties {len(found[0])} modules: " + ", ".join(short(m) for m in found[0])


def test_the_graph_sees_imports_inside_functions(tmp_path):
    """The parser counts a function-level import and resolves relative ones (else the checks above could not fail)."""
    source = "from ..lidar import points\n\ndef f():\n    from ..config import Config\n    import bpy_pipeline.pipeline\n"
    path = PACKAGE / "geometry" / "lod.py"
    known = {"bpy_pipeline.lidar.points", "bpy_pipeline.config", "bpy_pipeline.pipeline", "bpy_pipeline.geometry.lod"}
    probe = tmp_path / "lod.py"
    probe.write_text(source)
    found = imports(probe, "bpy_pipeline.geometry.lod", known)
    assert found == [("bpy_pipeline.lidar.points", 1, False), ("bpy_pipeline.config", 4, True), ("bpy_pipeline.pipeline", 5, True)]
    rows = [("bpy_pipeline.geometry.lod", *row) for row in found]
    assert [t for _, t, _ in wrong_way(rows)] == ["lidar.points", "config", "pipeline"]
    probe.write_text("def __getattr__(name):\n    from ..config import Config\n    return Config\n")
    assert imports(probe, "bpy_pipeline.geometry.lod", known) == [("bpy_pipeline.config", 2, True)]  # a module __getattr__'s import counts
    assert compat_hooks(probe) == ["__getattr__ at line 1"]
    probe.write_text("import sys\n\nsys.meta_path.insert(0, object())\n\ndef g():\n    def __getattr__(name):\n        return name\n")
    assert compat_hooks(probe) == ["sys.meta_path at line 3"]  # a function's own __getattr__ is no module hook
    assert path.exists()
    # a builder's geometry keeps geometry's rule, its own package's geometry aside; the shared Blender side imports no builder's package
    rows = [("bpy_pipeline.builders.railway.layout", "bpy_pipeline.builders.railway.catenary", 1, False),
            ("bpy_pipeline.builders.railway.layout", "bpy_pipeline.geometry.lod", 2, False),
            ("bpy_pipeline.builders.railway.layout", "bpy_pipeline.lidar.points", 3, True),
            ("bpy_pipeline.builders.railway.layout", "bpy_pipeline.builders.railway.scene", 4, True),
            ("bpy_pipeline.builders.railway.layout", "bpy_pipeline.builders.street.layout", 5, False),
            ("bpy_pipeline.builders.railway.params", "bpy_pipeline.builders.railway.scene", 6, True),
            ("bpy_pipeline.builders.railway.scene", "bpy_pipeline.blender.mesh_objects", 7, False),
            ("bpy_pipeline.blender.box_nodes", "bpy_pipeline.builders.street.scatter_nodes", 8, False),
            ("bpy_pipeline.population.scene", "bpy_pipeline.population.params", 9, False),
            ("bpy_pipeline.blender.people", "bpy_pipeline.population.placer", 10, True)]
    assert [line for _, _, line in wrong_way(rows)] == [3, 4, 5, 8, 10]
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def report() -> None:
    edges, rows = graph()
    found = circles(edges)
    inside = sorted({(r[0], r[2]) for r in rows if r[3]})  # statements: (module, line)
    bad = sorted(set(wrong_way(rows)))
    print(f"modules: {len(edges)}; import statements of the package's own modules: {len({(r[0], r[2]) for r in rows})}; inside functions: {len(inside)}")
    print(f"circles: {len(found)} holding {sum(map(len, found))} modules; largest: {len(found[0]) if found else 0}")
    for part in found:
        print(f"  {len(part)}: " + ", ".join(short(m) for m in part))
    print(f"wrong-way imports: {len(bad)} statements, {len({(m, t) for m, t, _ in bad})} module pairs")
    for m, t, line in bad:
        print(f"  {m}:{line} -> {t}")
    print("inside functions, by module: " + ", ".join(f"{short(m)} {n}" for m, n in Counter(r[0] for r in inside).most_common(12)))


if __name__ == "__main__":
    report()
