"""The run keeps its static objects' caster from frame to frame (``Run.casters``, a CasterCache):
a frame scanned with the kept caster gives the same bytes as the same frame made alone with a fresh
one, points and boxes alike."""

import numpy as np
import pytest

pytestmark = pytest.mark.bpy


def frames(config, indices):
    """``{index: frame}`` made in turn by one run, and the run."""
    from bpy_pipeline.frame import Run
    from bpy_pipeline.plan import make_frame

    run = Run(config)
    return {k: make_frame(run, k) for k in indices}, run


def same_frame(a, b):
    assert a.points.tobytes() == b.points.tobytes()
    assert (a.boxes is None) == (b.boxes is None)
    if a.boxes is not None:
        assert a.boxes.tobytes() == b.boxes.tobytes()


def test_hall_frames_keep_the_static_caster_and_their_bytes(bpy_scene):
    """People and robots move; the hall is kept (the sensor hangs still): frame 2 after 0 and 1 is frame 2 alone."""
    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages.scan import moving_objects

    config = load_config(overrides=["scene.builder=industrial_hall", "frames=3", "seed=5", "sensor.columns=512", "output.boxes.formats=[kitti]"])
    together, run = frames(config, [0, 1, 2])
    assert run.casters.builds == 1 and run.casters.reuses == 2
    moving = moving_objects(together[2])
    assert moving.any() and not moving.all()
    assert len(together[2].caster.parts) == 2  # the kept hall and this frame's people and robots
    assert len(together[2].boxes)
    bpy_scene.ops.wm.read_factory_settings(use_empty=True)
    alone, fresh = frames(config, [2])
    assert fresh.casters.builds == 1 and fresh.casters.reuses == 0
    same_frame(together[2], alone[2])


def test_static_scene_reuses_the_whole_caster(bpy_scene):
    """Nothing moves (the railway from one pose): frame 1 traces frame 0's caster and gives frame 1's bytes alone."""
    from bpy_pipeline.config import load_config

    config = load_config(overrides=["frames=2", "sensor.horizontal_resolution_deg=1.0", "sensor.vertical_resolution_deg=1.0"])
    together, run = frames(config, [0, 1])
    assert run.casters.builds == 1 and run.casters.reuses == 1
    assert together[1].caster.parts[0] is together[0].caster.parts[0]
    assert not np.array_equal(together[0].points, together[1].points)  # each frame its own draws
    bpy_scene.ops.wm.read_factory_settings(use_empty=True)
    alone, _ = frames(config, [1])
    same_frame(together[1], alone[1])
