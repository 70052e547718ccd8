"""One Blender session with the extension run from the checkout (run by tests/test_extension_checkout.py).

``python tests/extension_checkout_session.py WORK`` with ``HOME`` and ``BLENDER_USER_RESOURCES`` in
``WORK``: links the checkout into the user extension repository as docs/panel.md tells a developer
to (a folder of symbolic links: ``addon/*.py``, ``bpy_pipeline``, ``blender_manifest.toml``), enables
it, and checks that Scan and Generate are one undo step each while the last frame (on the window
manager) survives the undo. Writes what it saw to ``WORK/report.json``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import bpy
import addon_utils  # importable once bpy put Blender's scripts/modules on sys.path

ROOT = Path(__file__).resolve().parents[1]
MODULE = "bl_ext.user_default.lidar_pipeline"
WORK = Path(sys.argv[-1])
JOB = """seed: 3
frames: 2
scene:
  builder: primitives
  shapes:
    - {type: plane, size: [20, 20], class: ground}
    - {type: box, size: [2, 2, 2], position: [5, 0, 1], class: wall}
sensor: {preset: vlp16, sampling_factor: 0.25, position: [0, 0, 1.2], max_range: 30.0}
output: {formats: [ply]}
"""


def raise_error(ex):
    raise ex


def link_checkout() -> Path:
    repo = next(r for r in bpy.context.preferences.extensions.repos if r.module == "user_default")
    package = Path(repo.directory) / "lidar_pipeline"
    package.mkdir(parents=True)
    for path in (*sorted((ROOT / "addon").glob("*.py")), ROOT / "bpy_pipeline", ROOT / "blender_manifest.toml"):
        (package / path.name).symlink_to(path)
    bpy.ops.extensions.repo_refresh_all()
    return package


def scene_objects() -> int:
    collection = bpy.data.collections.get("LiDAR Scene")
    return len(collection.all_objects) if collection is not None else 0


report: dict = {"blender": bpy.app.version_string}
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
package = link_checkout()
addon_utils.enable(MODULE, default_set=True, handle_error=raise_error)
report["enabled"] = MODULE in bpy.context.preferences.addons
report["runs_from_the_checkout"] = Path(sys.modules[MODULE].__file__).resolve() == ROOT / "addon" / "__init__.py"
report["module_level_last"] = hasattr(sys.modules[f"{MODULE}.operators"], "LAST")

job = WORK / "job.yaml"
job.write_text(JOB)
bpy.context.scene.lidar.out_dir = str(WORK / "out")
bpy.ops.lidar.config_load(filepath=str(job))
bpy.ops.ed.undo_push(message="before scan")
# "EXEC_DEFAULT", True: the call pushes its undo step as a click does (a script's calls push none by default)
report["scan"] = sorted(bpy.ops.lidar.scan("EXEC_DEFAULT", True))
report["objects_after_scan"] = scene_objects()
last = bpy.context.window_manager.lidar_last
report["last_file_after_scan"] = bool(last.points_file) and Path(last.points_file).is_file()
bpy.ops.ed.undo()
report["objects_after_undo"] = scene_objects()
report["show_cloud_after_undo"] = sorted(bpy.ops.lidar.show_cloud())  # the window manager's frame survives the undo
bpy.ops.ed.undo_push(message="before generate")
before = scene_objects()
report["generate"] = sorted(bpy.ops.lidar.generate("EXEC_DEFAULT", True))
report["objects_after_generate"] = scene_objects()
bpy.ops.ed.undo()
report["objects_after_generate_undo"] = [before, scene_objects()]
points_file = Path(bpy.context.window_manager.lidar_last.points_file)
addon_utils.disable(MODULE, default_set=True, handle_error=raise_error)
report["last_file_after_disable"] = points_file.exists()
report["window_manager_property_after_disable"] = hasattr(bpy.types.WindowManager, "lidar_last")
(WORK / "report.json").write_text(json.dumps(report, indent=1))
print("session done")
