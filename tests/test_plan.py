"""The frame plan: one tuple of stages chosen per run, typed frames, writers that only write."""

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.frame import Frame, Run, StaticPose, frame_rng
from bpy_pipeline.plan import plan


def names(*overrides):
    return [s.name for s in plan(load_config(None, list(overrides)))]


def test_one_plan_per_run_single_sensor_rig_or_real_scan(tmp_path):
    assert names() == ["build", "pose", "export", "scan", "effects"]
    assert names("scene.builder=parking", "output.boxes.formats=[kitti]") == ["build", "pose", "export", "scan", "effects", "annotate"]
    assert names("sensor.rig=flash_post_240") == ["build", "pose", "members", "merge"]
    assert names("sensor.rig=flash_post_240", "output.boxes.formats=[openpcdet]") == ["build", "pose", "members", "merge", "merged boxes"]
    scan = tmp_path / "scan.bin"
    np.zeros((10, 4), np.float32).tofile(scan)
    assert names("scene.builder=real_scan", f"scene.path={scan}") == ["background", "place", "cast", "effects", "annotate"]


def test_a_writer_that_needs_flash_images_brings_the_flash_stage():
    single = plan(load_config(None, ["sensor.preset=flash96x16_carla", "output.formats=[ply,flash_image]"]))
    rig = plan(load_config(None, ["sensor.rig=flash_post_240", "output.formats=[ply,flash_image]"]))
    assert single[-1].name == rig[-1].name == "flash" and single[-1].function.__name__ == "flash_stage" and rig[-1].function.__name__ == "rig_flash_stage"
    assert [s.timing for s in single] == ["build", "build", "export", "scan", None, "flash"]  # the effects stage times its tracing and its effects


def test_a_frame_is_typed_pose_4x4_and_pose_at_a_function_of_time():
    config = load_config(None, [])
    frame = Frame(3, config, frame_rng(0, 3))
    assert frame.pose.shape == (4, 4) and not frame.moving and frame.scene.headings == {}
    pose = np.eye(4)
    pose[:3, 3] = (1.0, 2.0, 3.0)
    frame.place(pose)
    poses = frame.pose_at(np.array([0.0, 0.05, 0.1]))
    assert isinstance(frame.pose_at, StaticPose) and poses.shape == (3, 4, 4) and np.array_equal(poses[2], pose)
    with pytest.raises(ValueError, match="4, 4"):
        Frame(0, config, frame_rng(0, 0), pose=np.eye(3))
    run = Run(config, build=False)
    assert run.result.scene is None and run.members == []


def test_the_railway_layout_writer_reads_the_built_layout_and_draws_nothing(tmp_path):
    from bpy_pipeline.io import WRITERS

    config = load_config(None, ["output.formats=[ply,railway_layout]"])
    frame = Frame(0, config, frame_rng(0, 0))  # a frame of a scene it did not build: no layout to write
    with pytest.raises(InputError, match="railway_layout"):
        WRITERS.get("railway_layout").write(frame, tmp_path)
