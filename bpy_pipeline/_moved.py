"""Modules that moved, importable by their old dotted path for this round (the next round removes this table).

A builder is one package now (``builders/<name>/``): its pure geometry came from ``geometry/`` and its
Blender side from ``scenes/``. :data:`MOVED` maps each old path to the module that holds it now, both
below this package; :func:`install` puts a finder on ``sys.meta_path`` that answers an old path with the
new module object itself (``import bpy_pipeline.geometry.catenary`` gives
``bpy_pipeline.builders.railway.catenary``, the same module, not a copy). An old ``builders/<name>.py``
is the package ``builders/<name>/`` now, which re-exports its ``params``. Names that moved up a layer out of
a module that stays (:data:`MOVED_NAMES`) are answered by that module on first use, so it imports nothing above it.

The table is relative to this package, so it also serves the copy bundled in the Blender extension
(``bl_ext.<repo>.<id>.bpy_pipeline``).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys

MOVED = {
    # railway
    "geometry.railway_layout": "builders.railway.layout",
    "geometry.alignment": "builders.railway.alignment",
    "geometry.catenary": "builders.railway.catenary",
    "geometry.railway_parts": "builders.railway.parts",
    "geometry.trackside": "builders.railway.trackside",
    "geometry.terrain": "builders.railway.terrain",
    "geometry.railway_assets": "builders.railway.assets",
    "scenes.railway": "builders.railway.scene",
    "scenes.railway_assets": "builders.railway.scene_assets",
    "scenes.railway_nodes": "builders.railway.track_nodes",
    "scenes.catenary_nodes": "builders.railway.catenary_nodes",
    # street
    "geometry.street": "builders.street.layout",
    "geometry.street_dressing": "builders.street.dressing",
    "geometry.vegetation": "builders.street.vegetation",
    "scenes.street": "builders.street.scene",
    "scenes.street_nodes": "builders.street.scatter_nodes",
    # parking, industrial_hall, primitives, blend
    "scenes.parking": "builders.parking.scene",
    "scenes.parking_nodes": "builders.parking.level_nodes",
    "scenes.industrial_hall": "builders.industrial_hall.scene",
    "scenes.hall_nodes": "builders.industrial_hall.hall_nodes",
    "scenes.primitives": "builders.primitives.scene",
    "scenes.blend": "builders.blend.scene",
}


MOVED_NAMES = {
    # names that moved up a layer out of a module that stays: {module: {name: module that holds it now}}
    "geometry.lod": {"view_of": "lidar.view", "planned_path": "stages.view"},
}


class MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old path of :data:`MOVED` (under ``package``) and loads it as the new module: ``exec_module``
    puts the new module in ``sys.modules`` under the old name, which the import system then returns.
    A module of :data:`MOVED_NAMES` is loaded as itself, then answers its moved names (:class:`KeepsMovedNames`),
    so the module itself names nothing of the layer above it."""

    def __init__(self, package: str):
        self.package = package
        self.moved = {f"{package}.{old}": f"{package}.{new}" for old, new in MOVED.items()}
        self.names = {f"{package}.{module}": {name: f"{package}.{home}" for name, home in names.items()} for module, names in MOVED_NAMES.items()}

    def find_spec(self, name, path=None, target=None):
        if name in self.names:
            spec = importlib.machinery.PathFinder.find_spec(name, path)
            if spec is not None:
                spec.loader = KeepsMovedNames(spec.loader, self.names[name])
            return spec
        if name not in self.moved:
            return None
        return importlib.util.spec_from_loader(name, self)

    def create_module(self, spec):
        return None  # a placeholder module; exec_module replaces it

    def exec_module(self, module):
        sys.modules[module.__name__] = importlib.import_module(self.moved[module.__name__])


class KeepsMovedNames(importlib.abc.Loader):
    """Loads a module with its own loader, then gives it a module ``__getattr__`` that imports each moved name
    (``{name: dotted module}``) from where it lives now, on first use."""

    def __init__(self, loader, names: dict[str, str]):
        self.loader, self.names = loader, names

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module):
        self.loader.exec_module(module)
        names = self.names

        def __getattr__(name: str):
            if name in names:
                return getattr(importlib.import_module(names[name]), name)
            raise AttributeError(f"module {module.__name__!r} has no attribute {name!r}")

        module.__getattr__ = __getattr__


def install(package: str) -> None:
    """Make the old paths below ``package`` (this package's ``__name__``) importable, once."""
    if not any(isinstance(f, MovedModules) and f.package == package for f in sys.meta_path):
        sys.meta_path.insert(0, MovedModules(package))  # first: a module of MOVED_NAMES exists on disk, and the path finder would load it plainly
