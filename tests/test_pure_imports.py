"""The pure part (config, geometry, lidar, io, mixing, evaluate, population, buffers, labels, the builders' pure files) never imports bpy.

Two checks: every module outside the Blender side imports with ``bpy`` blocked (a module-level
import fails there), and no module of the pure packages holds an import of ``bpy``, ``bmesh``,
``mathutils`` or of the Blender side anywhere, inside functions included (an import there would
only fail when the function runs).

A builder's package (``builders/<name>/``) marks its Blender side by the file name: ``scene.py``,
``scene_*.py`` and ``*_nodes.py`` import bpy; its other files are pure. Its geometry (every pure file but
``params.py``) is held like the pure packages; ``params.py`` imports no Blender module anywhere and its
``scene`` only inside ``build`` (the builder's entry is pure, its ``build`` runs in Blender).
"""

import ast
import importlib.util
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import bpy_pipeline

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "bpy_pipeline"
BPY_SIDE = {"bpy_pipeline.blender", "bpy_pipeline.population.scene"}  # and the builders' Blender files (blender_file)
PURE_PACKAGES = ("geometry", "lidar", "io", "mixing", "evaluate", "population")  # never import Blender, not even inside a function (their BPY_SIDE aside)
BLENDER_MODULES = ("bpy", "bmesh", "mathutils")


# modules that need an optional package (the 'fast' extra)
OPTIONAL = {"bpy_pipeline.lidar.cast.numba_kernels": "numba", "bpy_pipeline.lidar.cast.visibility_kernels": "numba"}


def blender_file(name: str) -> bool:
    """A builder package's Blender side, marked by its name: ``builders.<builder>.scene``, ``.scene_*``, ``.*_nodes``."""
    parts = name.split(".")
    if len(parts) != 4 or parts[:2] != ["bpy_pipeline", "builders"]:
        return False
    return parts[3] == "scene" or parts[3].startswith("scene_") or parts[3].endswith("_nodes")


def blender_side(name: str) -> bool:
    return blender_file(name) or any(name == b or name.startswith(b + ".") for b in BPY_SIDE)


def builder_geometry() -> list[Path]:
    """The pure files of the builders' packages but their ``params.py`` and ``__init__.py``: held like the pure packages."""
    out = []
    for path in sorted((PACKAGE / "builders").glob("*/*.py")):
        name = ".".join(("bpy_pipeline", *path.relative_to(PACKAGE).with_suffix("").parts))
        if not blender_file(name) and path.name not in ("params.py", "__init__.py"):
            out.append(path)
    return out


def pure_modules() -> list[str]:
    names = []
    for info in pkgutil.walk_packages(bpy_pipeline.__path__, "bpy_pipeline."):
        if blender_side(info.name):
            continue
        if info.name in OPTIONAL and importlib.util.find_spec(OPTIONAL[info.name]) is None:
            continue
        names.append(info.name)
    return names


def test_the_blender_side_names_modules_that_exist():
    for name in BPY_SIDE:
        assert importlib.util.find_spec(name) is not None, f"{name} is listed as the Blender side but does not exist"


def blender_imports(source: str, package: str) -> list[tuple[int, str]]:
    """``[(line, module)]``: the imports of Blender's modules or of the package's Blender side in ``source``
    (a module of the package ``package``, dotted), anywhere in it."""
    tree = ast.parse(source)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                names = [".".join(base + ([node.module] if node.module else []))]
                names += [f"{names[0]}.{a.name}" for a in node.names]
            else:
                names = [node.module or ""]
        else:
            continue
        for name in names:
            if name.split(".")[0] in BLENDER_MODULES or blender_side(name):
                out.append((node.lineno, name))
    return out


def test_the_builders_blender_side_is_named_so():
    """A builder's files that import Blender (bpy or the Blender side) at module level are the ones named ``scene*`` / ``*_nodes``."""
    files = sorted((PACKAGE / "builders").glob("*/*.py"))
    assert {p.parent.name for p in files} >= {"railway", "street", "parking", "industrial_hall", "primitives", "blend", "real_scan"}
    for path in files:
        name = ".".join(("bpy_pipeline", *path.relative_to(PACKAGE).with_suffix("").parts))
        source = path.read_text()
        module_level = {n.lineno for n in ast.parse(source).body if isinstance(n, (ast.Import, ast.ImportFrom))}
        imports_blender = any(line in module_level for line, _ in blender_imports(source, name.rpartition(".")[0]))
        assert imports_blender == blender_file(name), f"{path.relative_to(ROOT)}: " + (
            "imports Blender but is not named scene*.py or *_nodes.py" if imports_blender else "is named as the Blender side but imports no Blender module"
        )
    assert builder_geometry() and all(p.name not in ("scene.py", "params.py") for p in builder_geometry())


def test_the_builders_params_import_no_blender_module():
    """A builder's ``params.py`` names no Blender module anywhere and its Blender side only inside functions (``build``)."""
    found = {}
    for path in sorted((PACKAGE / "builders").glob("*/params.py")):
        package = ".".join(("bpy_pipeline", *path.relative_to(PACKAGE).parent.parts))
        tree = ast.parse(path.read_text())
        module_level = {n.lineno for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))}
        for line, name in blender_imports(path.read_text(), package):
            if name.split(".")[0] in BLENDER_MODULES or line in module_level:
                found.setdefault(f"{path.relative_to(ROOT)}:{line}", name)
    assert not found, "Blender imports in a builder's params: " + ", ".join(f"{k} imports {v}" for k, v in found.items())


def test_the_pure_packages_import_no_blender_module_anywhere():
    found = {}
    paths = [path for sub in PURE_PACKAGES for path in sorted((PACKAGE / sub).rglob("*.py"))
             if not blender_side(".".join(("bpy_pipeline", *path.relative_to(PACKAGE).with_suffix("").parts)))] + builder_geometry()
    for path in paths:
        package = ".".join(("bpy_pipeline", *path.relative_to(PACKAGE).parent.parts))
        for line, name in blender_imports(path.read_text(), package):
            found.setdefault(f"{path.relative_to(ROOT)}:{line}", name)
    assert not found, "Blender imports in the pure part: " + ", ".join(f"{k} imports {v}" for k, v in found.items())


@pytest.mark.parametrize("source", ["def f():\n    import bpy\n", "def f():\n    from mathutils import Matrix\n", "from ..blender import mesh_objects\n",
                                    "import bmesh\n",
                                    "from ..builders.railway import scene\n", "def f():\n    from ..builders.street.scatter_nodes import scatter_group\n"])
def test_the_check_finds_a_blender_import(source):
    """The check above fails on a real import of Blender in a pure module, inside a function too (a builder's Blender files too)."""
    assert blender_imports(source, "bpy_pipeline.lidar")
    assert not blender_imports("def f():\n    from ..geometry import lod\n    import numpy\n", "bpy_pipeline.lidar")
    assert not blender_imports("from ..builders.railway import layout, catenary\nfrom ..builders.street.params import StreetScene\n", "bpy_pipeline.lidar")
    assert blender_imports("from .scene_assets import asset_parts\n",
                           "bpy_pipeline.builders.railway") and not blender_imports("from .layout import plan\n", "bpy_pipeline.builders.railway")


def test_pure_modules_import_and_run_with_bpy_blocked():
    modules = pure_modules()
    assert {"bpy_pipeline.lidar.cast.scanner", "bpy_pipeline.io.ply", "bpy_pipeline.config", "bpy_pipeline.geometry.primitives"} <= set(modules)
    code = f"""
import sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('bpy', 'bmesh', 'mathutils'):
            raise ImportError('blocked: ' + name)
sys.meta_path.insert(0, Block())
import importlib
for name in {modules!r}:
    importlib.import_module(name)
# and run the pure chain: config -> pattern -> scan of numpy buffers -> writer
import numpy as np
from bpy_pipeline.config import load_config
from bpy_pipeline.buffers import SceneBuffers, ObjectTable
from bpy_pipeline.geometry import primitives
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.scanner import scan
from bpy_pipeline.lidar.sensor.sensors import sensor_pattern
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.io import write_ply, read_ply
cfg = load_config()
v, t = primitives.box(10, 10, 10)
objs = ObjectTable(['room'], [''], ['wall'], np.array([17], np.uint16), np.array([1], np.uint32), np.array([0], np.uint8), np.array([0.5], np.float32))
buf = SceneBuffers(v, t, np.zeros(len(t), np.int32), objs)
pts, beam = scan(RayCaster(buf, frame=np.eye(4)), buf, sensor_pattern(cfg.sensor.spec), pose_matrix([0, 0, 0], [0, 0, 0]), 0.1, 100)
assert len(pts) == len(sensor_pattern(cfg.sensor.spec)), len(pts)
assert 'bpy' not in sys.modules
print('ok')
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("ok")
