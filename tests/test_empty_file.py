"""cli.empty_file: a Blender this process just started is emptied as read_factory_settings(use_empty=True) empties it."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("bpy")

ROOT = Path(__file__).resolve().parents[1]

# Prints the state a run starts from: every data block by kind and name, and the scene's own settings (its plain
# properties and those of its render, unit and display settings; not its session_uid, a counter of the data blocks
# the session made), after the given way of emptying the file.
PROGRAM = """
import json, sys
import bpy
from bpy_pipeline.cli import empty_file, exit_process

way = sys.argv[1]
if way == "touched":  # a session the user changed: an object, a setting
    bpy.ops.mesh.primitive_cube_add()
    bpy.context.scene.render.fps = 7
    empty_file(bpy, started=False)
elif way == "started":
    empty_file(bpy, started=True)
else:
    bpy.ops.wm.read_factory_settings(use_empty=True)

def plain(struct):
    out = {}
    for prop in struct.bl_rna.properties:
        if prop.type in {"BOOLEAN", "INT", "FLOAT", "STRING", "ENUM"} and prop.identifier not in ("rna_type", "session_uid"):
            value = getattr(struct, prop.identifier)
            out[prop.identifier] = list(value) if hasattr(value, "__len__") and not isinstance(value, str) else value
    return out

blocks = {name: sorted(b.name for b in getattr(bpy.data, name)) for name in dir(bpy.data)  # all_ids (Blender 5.x): every kind's again
          if name != "all_ids" and isinstance(getattr(bpy.data, name, None), bpy.types.bpy_prop_collection)}
scene = bpy.context.scene
state = {"blocks": blocks, "scene": plain(scene), "render": plain(scene.render), "units": plain(scene.unit_settings),
         "display": plain(scene.display), "world": scene.world and scene.world.name,
         "collection": [c.name for c in scene.collection.children] + [o.name for o in scene.collection.objects]}
print(json.dumps(state, sort_keys=True, default=str))
exit_process(0)  # Blender's teardown skipped, its session folder removed
"""


def state_after(way: str) -> dict:
    done = subprocess.run([sys.executable, "-c", PROGRAM, way], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_just_started_blender_is_emptied_as_reading_the_factory_settings_empties_it():
    factory = state_after("factory")
    assert set(name for name, blocks in factory["blocks"].items() if blocks) == {"scenes", "screens", "window_managers", "workspaces"}
    assert state_after("started") == factory
    assert state_after("touched") == factory  # not just started: the factory settings are read (the cube and the fps go)
