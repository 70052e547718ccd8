"""The street's road users as the export stage takes them: from the builder's arrays (``BuildResult.dynamic_parts``,
``export.parts_buffers``), the same buffers, byte for byte, as reading the users' collection back from Blender; and
its static world exported once, the same for every frame."""

import numpy as np
import pytest

pytestmark = pytest.mark.bpy


def test_users_from_arrays_are_the_users_read_back_from_blender():
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.blender.export import export_scene, parts_buffers
    from bpy_pipeline.frame import Frame, Run, frame_rng
    from bpy_pipeline.stages.scene import build_stage, export_stage, pose_stage

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config("examples/street/ego_hdl64e.yaml", ["frames=4"])
    run = Run(config)
    statics = []
    for index in range(3):
        frame = Frame(index, config, frame_rng(config.seed, index))
        for stage in (build_stage, pose_stage, export_stage):
            stage(frame, run)
        scene = frame.scene
        assert scene.dynamic is not None and scene.dynamic_parts
        within = (frame.pose[:3, 3], config.sensor.spec.max_range)
        read = export_scene(run.table, run.rules, keep_within=within, only=scene.dynamic)
        made = parts_buffers(run.table, scene.dynamic_parts, run.rules, keep_within=within)
        assert 0 < len(made.objects) < len(scene.dynamic_parts) + 1 and len(made.triangles) > 10_000
        for name in ("vertices", "triangles", "triangle_object"):
            a, b = getattr(read, name), getattr(made, name)
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), name
        assert read.objects.rows() == made.objects.rows() and np.array_equal(read.objects.surface, made.objects.surface)
        statics.append(run.static_world[1])
        users = np.arange(len(frame.buffers.objects)) >= len(statics[-1].objects)
        assert not np.isin(frame.buffers.objects.instance[~users], list(scene.headings)).any()  # no road user in the static world
        assert set(frame.buffers.objects.instance[users].tolist()) <= set(scene.headings)
    assert statics[0] is statics[1] is statics[2]  # exported once


def test_a_sensor_out_of_reach_of_the_static_world_is_an_error():
    """The static world exported whole still answers a sensor that no object is within range of, as the export within
    its reach did: one line naming sensor.max_range."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.errors import InputError
    from bpy_pipeline.frame import Frame, Run, frame_rng
    from bpy_pipeline.stages.scene import build_stage, export_stage, pose_stage

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["scene.builder=street", "sensor.preset=hdl64e", "sensor.position=[5000, 0, 0]", "frames=1"])
    run = Run(config)
    frame = Frame(0, config, frame_rng(config.seed, 0))
    build_stage(frame, run)
    pose_stage(frame, run)
    assert frame.scene.dynamic is not None
    with pytest.raises(InputError, match="sensor.max_range"):
        export_stage(frame, run)



def test_a_run_reading_only_the_arrays_fills_blender_once_at_its_end(tmp_path):
    """A run whose stages read the builder's arrays only (no rendered camera, no rig) leaves Blender's copy of each frame's
    road users out while it runs (``BuildContext.in_blender`` false) and fills it with the last frame's at its end: the
    objects then hold that frame's parts (names, tags, vertices) and the spares nothing."""
    import bpy

    from bpy_pipeline.builders.street.scene import USERS_COLLECTION
    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import plan, run_frames

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config("examples/street/ego_hdl64e.yaml", ["frames=3", "output.formats=[semantickitti]"])
    assert not any(stage.reads_blender for stage in plan(config))
    seen, last = [], None
    for frame in run_frames(config, tmp_path / "run", overlap=False):
        seen.append(sum(len(obj.data.vertices) for obj in bpy.data.collections[USERS_COLLECTION].objects))
        last = frame.scene.dynamic_parts
    assert seen == [0, 0, 0] and len(last) > 3  # nothing put in Blender while the run went on
    kept = list(bpy.data.collections[USERS_COLLECTION].objects)
    assert len(kept) >= len(last) and all(len(obj.data.vertices) == 0 for obj in kept[len(last) :])
    for obj, (name, tags, vertices, _) in zip(kept, last):
        co = np.empty(len(obj.data.vertices) * 3, np.float32)
        obj.data.vertices.foreach_get("co", co)
        assert obj.name == name and obj["lidar_instance"] == tags["lidar_instance"] and obj["lidar_class"] == tags["lidar_class"]
        assert np.array_equal(co.reshape(-1, 3), vertices.astype(np.float32))


def test_runs_whose_stages_read_blender_keep_filling_it_every_frame():
    """A rig's members export the scene from Blender, and KITTI's rendered camera image is Blender's: their plans say so,
    so such runs put each frame's road users into Blender as they build (``Run.in_blender``)."""
    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import plan

    rig = load_config(None, ["scene.builder=street", "frames=1"])
    assert rig.sensor.rig and any(stage.reads_blender for stage in plan(rig))
    rendered = load_config("examples/street/ego_hdl64e.yaml", ["output.kitti.camera.render=true"])
    assert [stage.name for stage in plan(rendered) if stage.reads_blender] == ["camera"]
    plain = load_config("examples/street/ego_hdl64e.yaml")
    assert not any(stage.reads_blender for stage in plan(plain))


def test_parts_joined_in_one_pass_are_the_parts_one_at_a_time():
    """``parts_buffers`` joins the parts' vertices once; the bytes and rows are those of a part at a time, with parts
    beyond the range left out (one exactly at it kept), two parts of one name, and one without triangles."""
    from bpy_pipeline.blender.export import _Labeller, _parts_one_by_one, parts_buffers
    from bpy_pipeline.labels import load_class_table

    table, rng = load_class_table(), np.random.default_rng(3)
    tags = {"lidar_class": "car", "lidar_material": "diffuse", "lidar_reflectivity": 0.4, "lidar_instance": 7}

    def part(name, x):
        return name, dict(tags), rng.normal(size=(5, 3)) + [x, 0.0, 0.0], rng.integers(0, 5, (4, 3))

    flat = ("edge", dict(tags), np.array([[10.0, -1, -1], [11, 1, 1], [12, 0, 0]]), np.array([[0, 1, 2]]))  # its nearest point 10 m away
    parts = [part("a", 0.0), part("far", 50.0), part("b", 3.0), flat, ("empty", dict(tags), np.zeros((0, 3)), np.zeros((0, 3), int))]
    within = (np.zeros(3), 10.0)
    for chosen, keep_within in ((parts, within), (parts, None), (parts + [part("a", 1.0)], within)):
        made = parts_buffers(table, chosen, keep_within=keep_within)
        one = _parts_one_by_one(_Labeller(table), [p for p in chosen if len(p[3])], keep_within)
        for name in ("vertices", "triangles", "triangle_object"):
            a, b = getattr(one, name), getattr(made, name)
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), name
        assert made.objects.rows() == one.objects.rows()
    names = [row["name"] for row in parts_buffers(table, parts, keep_within=within).objects.rows()]
    assert names == ["a", "b", "edge"]
