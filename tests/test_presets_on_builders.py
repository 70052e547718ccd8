"""Every sensor preset on every procedural builder makes a labelled frame.

A user tries another sensor on a scene by one key (``--set sensor.preset=...``). Each builder asks the sensor for its
field of view before its first frame (placement in view, levels of detail), and a pattern that fires no rows crashed
there on every builder (a sensor on a path, as in the railway's mobile example, excepted). One frame a preset, boxes asked
for, the sensor 1.5 m above where the builder puts it (a robot's or a handheld unit's preset has no mount height: on the
ground it sees nothing, and the run says so).
"""

from __future__ import annotations

import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.lidar.sensor.sensors import presets

BUILDERS = ("parking", "industrial_hall", "railway", "street", "primitives")
SMALLER = {"railway_tls": ["sensor.sampling_factor=0.05"]}  # the terrestrial scanner's 23 M rays thinned to a test's size


@pytest.mark.bpy
@pytest.mark.slow
@pytest.mark.parametrize("builder", BUILDERS)
def test_every_preset_makes_a_frame_on_the_builder(bpy_scene, tmp_path, builder):
    from bpy_pipeline.plan import run

    made = {}
    for name in presets():
        config = load_config(None, [f"scene.builder={builder}", f"sensor.preset={name}", *SMALLER.get(name, []), "sensor.mount_height=1.5", "frames=1",
                                    "output.formats=[ply]", "output.preview=false", "output.boxes.formats=[kitti]"])
        manifest = run(config, tmp_path / name, log=lambda *_: None)
        made[name] = manifest["frames"][0]["points"]
    assert all(points > 0 for points in made.values()), made
