"""The modules that moved into the builders' packages stay importable by their old paths this round (bpy_pipeline/_moved.py)."""

import importlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

import bpy_pipeline
from bpy_pipeline import _moved

ROOT = Path(__file__).resolve().parents[1]
BUILDERS = ("railway", "street", "parking", "industrial_hall", "primitives", "blend", "real_scan")


@pytest.mark.parametrize("old", sorted(_moved.MOVED))
def test_every_old_path_imports_as_the_moved_module_itself(old):
    new = importlib.import_module(f"bpy_pipeline.{_moved.MOVED[old]}")
    assert importlib.import_module(f"bpy_pipeline.{old}") is new
    package, _, leaf = f"bpy_pipeline.{old}".rpartition(".")
    assert getattr(importlib.import_module(package), leaf) is new  # from bpy_pipeline.geometry import catenary
    assert not (ROOT / "bpy_pipeline" / f"{old.replace('.', '/')}.py").exists(), f"{old}: a file still stands at the old path"


def test_the_table_names_no_module_twice_and_only_existing_ones():
    assert len(set(_moved.MOVED.values())) == len(_moved.MOVED)
    for new in _moved.MOVED.values():
        assert (ROOT / "bpy_pipeline" / f"{new.replace('.', '/')}.py").exists(), new
    assert importlib.util.find_spec("bpy_pipeline.geometry.no_such_module") is None  # the finder answers only its table


@pytest.mark.parametrize("module", sorted(_moved.MOVED_NAMES))
def test_a_name_that_moved_up_is_answered_by_its_old_module_which_never_names_its_new_one(module):
    old = importlib.import_module(f"bpy_pipeline.{module}")
    for name, home in _moved.MOVED_NAMES[module].items():
        assert getattr(old, name) is getattr(importlib.import_module(f"bpy_pipeline.{home}"), name)
        assert f"{name}(" in (ROOT / "bpy_pipeline" / f"{home.replace('.', '/')}.py").read_text()
        assert f"import {name}" not in (ROOT / "bpy_pipeline" / f"{module.replace('.', '/')}.py").read_text()
    with pytest.raises(AttributeError):
        old.no_such_name


@pytest.mark.parametrize("name", BUILDERS)
def test_an_old_builder_module_is_its_package_with_the_params_names(name):
    package = importlib.import_module(f"bpy_pipeline.builders.{name}")
    params = importlib.import_module(f"bpy_pipeline.builders.{name}.params")
    public = [k for k in vars(params) if not k.startswith("_")]
    assert public and all(getattr(package, k) is getattr(params, k) for k in public)


def test_names_split_off_a_moved_module_stay_importable_from_its_old_path():
    from bpy_pipeline.builders.real_scan import kept_scan, real_scan_stage
    from bpy_pipeline.geometry import field_of_view, street, vehicles
    from bpy_pipeline.stages import mixing

    assert kept_scan is mixing.kept_scan and real_scan_stage is mixing.real_scan_stage
    for name in ("FieldOfView", "box_samples", "in_view_fraction"):
        assert getattr(street, name) is getattr(field_of_view, name)
    for name in ("vehicle_parts", "two_wheeler_parts", "saddle_height"):
        assert getattr(street, name) is getattr(vehicles, name)


def test_old_paths_import_first_in_a_fresh_interpreter():
    """Importing an old path before anything else of the package (the finder is installed by the package itself)."""
    code = "import bpy_pipeline.geometry.railway_layout as a, bpy_pipeline.builders.railway.layout as b; from bpy_pipeline.geometry.street import FieldOfView; assert a is b; print('ok')"
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "ok"
    assert sum(isinstance(f, _moved.MovedModules) and f.package == bpy_pipeline.__name__ for f in sys.meta_path) == 1
