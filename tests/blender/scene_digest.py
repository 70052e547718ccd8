"""Per-object digest of the exported scene of frame 0 (what the scan sees), for telling apart Blenders.

``python scene_digest.py -- OUT.json [--set key=value ...]`` with the bpy module, or
``blender --background --python-exit-code 1 --python scene_digest.py -- OUT.json [...]``.
Writes {object name: {triangles, vertices, bbox, sha256 of float32 vertices}} of
``export_scene`` after ``build_frame_scene(config, 0)``.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import bpy
import numpy as np

from bpy_pipeline import config as cfg
from bpy_pipeline.blender.export import export_scene
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.stages.scene import build_frame_scene

args = sys.argv[sys.argv.index("--") + 1 :]
out, sets = Path(args[0]), [a for a in args[1:] if a != "--set"]
data: dict = {}
for item in sets:
    key, value = item.split("=", 1)
    node = data
    *parents, last = key.split(".")
    for p in parents:
        node = node.setdefault(p, {})
    node[last] = float(value) if value.replace(".", "", 1).isdigit() else value
bpy.ops.wm.read_factory_settings(use_empty=True)
config = cfg.config_from_dict(data)
build_frame_scene(config, 0)
buffers = export_scene(load_class_table())
digest = {"blender": bpy.app.version_string}
vertices = np.asarray(buffers.vertices, np.float32)
triangles = np.asarray(buffers.triangles)
for index, name in enumerate(buffers.objects.names):
    tris = triangles[np.asarray(buffers.triangle_object) == index]
    used = np.unique(tris)
    v = vertices[used] if len(used) else np.zeros((0, 3), np.float32)
    digest[name] = {
        "triangles": int(len(tris)),
        "vertices": int(len(used)),
        "bbox": [v.min(0).round(4).tolist(), v.max(0).round(4).tolist()] if len(v) else None,
        "sha256": hashlib.sha256(np.ascontiguousarray(vertices[tris]).tobytes()).hexdigest()[:16],
    }
out.write_text(json.dumps(digest, indent=1, sort_keys=True))
