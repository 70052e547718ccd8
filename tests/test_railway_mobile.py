"""The railway mobile multi-beam setup (preset railway_multibeam, examples/railway/mobile.yaml): a tilted
spinning sensor on a train roof whose columns fire at their own times along the trajectory."""

import json
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.builders.railway.parts import H_SECTION
from bpy_pipeline.lidar.sensor.sensors import preset_sources, presets

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "railway" / "mobile.yaml"


def test_the_preset_and_the_example_carry_their_sources():
    preset = presets()["railway_multibeam"]
    assert preset["pattern"] == "spinning" and preset["channels"] == 64
    sources = preset_sources("railway_multibeam")
    assert {"noise.sigma", "drop.threshold", "divergence"} <= set(sources) and "datasheet" in sources["divergence"]
    config = load_config(EXAMPLE)
    assert config.sensor.spec.name == "railway_multibeam" and config.sensor.trajectory is not None
    assert config.sensor.divergence.rays > 1 and config.sensor.divergence.mrad == pytest.approx(2.27)
    assert config.effects.noise.sigma > 0  # the realistic profile is on: noise and drop from the datasheet
    assert config.effects.drop.model == "threshold"


@pytest.mark.bpy
def test_a_short_mobile_run_keeps_every_mast_in_place_across_frames(tmp_path):
    import bpy

    from bpy_pipeline.io import read_ply
    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # the worked config, 5 frames (0.5 s, 10 m), with its noise, drop and divergence; 512 columns keep it quick
    config = load_config(EXAMPLE, ["frames=5", "sensor.columns=512", "output.preview=false"])
    manifest = run(config, tmp_path, log=lambda *_: None)
    truth = json.loads((tmp_path / "railway_layout" / "000000.json").read_text())
    bases = {f"support.{s['index']:02d}.mast.{m['side']}": np.array(m["base"]) for s in truth["supports"] for m in s["masts"]}
    seen = {}
    for frame in manifest["frames"]:
        cloud = read_ply(tmp_path / "ply" / f"{frame['index']:06d}.ply")
        times = cloud["time"]
        assert times.max() - times.min() > 0.09  # a rolling shutter: the columns span the 0.1 s sweep
        for row in frame["objects"]:
            hit = cloud[cloud["instance"] == row["instance"]]
            if row["name"] in bases and len(hit) >= 20:
                xyz = np.column_stack([hit["x"], hit["y"], hit["z"]]).astype(float)
                seen.setdefault(row["name"], []).append(xyz)
    # the rolling shutter: each point lies at its range from where the optical centre was at its own time
    from bpy_pipeline.lidar.sensor.sensors import frame_time
    from bpy_pipeline.stages.view import scene_trajectory

    trajectory = scene_trajectory(config)
    for frame in manifest["frames"]:
        cloud = read_ply(tmp_path / "ply" / f"{frame['index']:06d}.ply")
        centres = trajectory.poses(frame["index"] * frame_time(config.sensor.spec) + cloud["time"].astype(float))[:, :3, 3]
        xyz = np.column_stack([cloud["x"], cloud["y"], cloud["z"]]).astype(float)
        error = np.abs(np.linalg.norm(xyz - centres, axis=1) - cloud["range"])
        assert np.percentile(error, 99) < 0.01, np.percentile(error, [50, 99])  # fired from the frame's start pose: 0.64 m off (median)
    steady = {name: frames for name, frames in seen.items() if len(frames) == 5}
    assert len(steady) >= 2, {name: len(frames) for name, frames in seen.items()}  # the masts beside the 10 m of path
    for name, frames in steady.items():
        # along the line (x): the H-section mast is 0.30 m deep; points of every frame stay on it within 5 cm
        # (the 1.5 cm noise included): one mast in every frame, no ghost
        half = H_SECTION[1] / 2
        along = [np.percentile(f[:, 0], [1, 99]) - bases[name][0] for f in frames]
        assert all(lo > -half - 0.05 and hi < half + 0.05 for lo, hi in along), (name, along)
        assert np.percentile(np.concatenate(frames)[:, 0], 99.5) - np.percentile(np.concatenate(frames)[:, 0], 0.5) < 2 * half + 0.1  # one mast, no ghost
