"""Geometry Nodes groups kept on disk between runs (bpy_pipeline/blender/group_cache.py): a group the same code made
is appended instead of made again, with the same geometry; nothing is kept when switched off; a damaged file is
made again; a group whose names are taken in the session is made, not appended under other names."""

import hashlib

import numpy as np
import pytest

pytestmark = pytest.mark.bpy


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("BPY_PIPELINE_CACHE", str(tmp_path))
    return tmp_path / "node_groups"


def fresh():
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)


def exported_digest(overrides) -> str:
    """sha256 of the first frame's exported triangles and their objects, built from a fresh session."""
    from bpy_pipeline.api import load_config
    from bpy_pipeline.frame import Frame, Run, frame_rng
    from bpy_pipeline.plan import plan

    fresh()
    config = load_config(None, [*overrides, "frames=1"])
    run, frame = Run(config, True, log=None), Frame(0, config, frame_rng(config.seed, 0))
    for stage in plan(config):
        stage(frame, run)
        if stage.name == "export":
            break
    digest = hashlib.sha256()
    for array in (frame.buffers.vertices, frame.buffers.triangles, frame.buffers.triangle_object):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def never_made(monkeypatch):
    """Fail if any group is made node by node from here on."""
    from bpy_pipeline.blender import nodes

    def refuse(*args, **kwargs):
        raise AssertionError("a group was made, not appended")

    monkeypatch.setattr(nodes.GroupBuilder, "__init__", refuse)


@pytest.mark.parametrize("builder", ["parking", "railway"])
def test_a_kept_group_is_appended_and_builds_the_same_scene(cache, monkeypatch, builder):
    import bpy

    made = exported_digest([f"scene.builder={builder}"])
    kept = sorted(p.name for p in cache.rglob("*.blend"))
    assert kept and all(".v" in name for name in kept)
    never_made(monkeypatch)
    assert exported_digest([f"scene.builder={builder}"]) == made
    assert len(bpy.data.libraries) == 0  # appended, local: no reference to the cache file
    assert not any(g.name.endswith(".001") for g in bpy.data.node_groups)  # the railway's nested groups came once


def test_switched_off_nothing_is_kept(monkeypatch, tmp_path):
    from bpy_pipeline.builders.parking.level_nodes import level_group
    from bpy_pipeline.blender import group_cache

    monkeypatch.setenv("BPY_PIPELINE_CACHE", "")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))  # where it would go without the variable
    fresh()
    level_group()
    assert group_cache.folder() is None and not list(tmp_path.rglob("*.blend"))


def test_a_damaged_file_is_made_again_and_kept_anew(cache):
    from bpy_pipeline.builders.parking import level_nodes
    from bpy_pipeline.blender import group_cache

    fresh()
    level_nodes.level_group()
    path = group_cache.path_of(level_nodes.GROUP, level_nodes.VERSION)
    path.write_bytes(b"not a blend file")
    fresh()
    assert group_cache.load(level_nodes.GROUP, level_nodes.VERSION) is None and not path.exists()
    group = level_nodes.level_group()
    assert len(group.nodes) > 100 and path.stat().st_size > 10_000


def test_names_taken_in_the_session_are_not_appended_under_others(cache):
    import bpy

    from bpy_pipeline.builders.railway import track_nodes
    from bpy_pipeline.blender import group_cache

    fresh()
    track_nodes.track_group()
    fresh()
    bpy.data.node_groups.new("Rail Profile", "GeometryNodeTree")  # a user's group of a name the track's file holds
    assert group_cache.load("Track", track_nodes.VERSION) is None
    assert "Track" not in bpy.data.node_groups and len(bpy.data.libraries) == 0


def test_changed_code_reads_another_file(cache, monkeypatch):
    from bpy_pipeline.blender import group_cache

    before = group_cache.path_of("Parking Level", 3)
    monkeypatch.setattr(group_cache, "code_digest", lambda: "0" * 16)
    assert group_cache.path_of("Parking Level", 3) != before and group_cache.path_of("Parking Level", 4) != group_cache.path_of("Parking Level", 3)
