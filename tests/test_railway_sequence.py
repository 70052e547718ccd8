"""One railway per run: every frame of a mobile or multi-station run scans the same built line."""

import numpy as np
import pytest

from bpy_pipeline.config import load_config

pytestmark = pytest.mark.bpy

MOBILE = ["sensor.preset=vlp16", "sensor.trajectory={curve: track_centreline, speed: 20, height: 3.5}", "scene.supports.span_jitter=8",
          "scene.supports.layout=auto", "scene.track.tracks=2", "scene.supports.mast_type=mixed", "effects.ideal=true"]


def run_world(tmp_path, *overrides, frames=5, frames_range=None):
    import bpy

    from bpy_pipeline.io import read_ply
    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["output.formats=[ply]", "output.preview=false", "output.frame=world", f"frames={frames}", *overrides])
    manifest = run(config, tmp_path, log=lambda *_: None, frames=frames_range)
    clouds = {f["index"]: read_ply(tmp_path / "ply" / f"{f['index']:06d}.ply") for f in manifest["frames"]}
    return clouds, manifest


def mast_points(clouds, manifest) -> dict[str, list[np.ndarray]]:
    """{mast object name: [(n, 3) world points of each frame that hit it]}."""
    out: dict[str, list[np.ndarray]] = {}
    for frame in manifest["frames"]:
        cloud = clouds[frame["index"]]
        for row in frame["objects"]:
            if ".mast." not in row["name"] and not row["name"].endswith(".gantry"):
                continue
            hit = cloud[cloud["instance"] == row["instance"]]
            if len(hit) >= 5:
                out.setdefault(row["name"], []).append(np.column_stack([hit["x"], hit["y"], hit["z"]]).astype(float))
    return out


def test_a_mobile_run_scans_one_railway(tmp_path):
    clouds, manifest = run_world(tmp_path, *MOBILE)
    masts = {name: frames for name, frames in mast_points(clouds, manifest).items() if len(frames) == 5 and ".mast." in name}
    assert len(masts) >= 2
    for name, frames in masts.items():
        # a mast is at most 0.4 m wide (lattice), so points of one mast seen from five places span no more
        # than that plus 5 cm across the frames; a mast rebuilt elsewhere moves by metres
        every = np.concatenate(frames)
        extent = every[:, :2].max(0) - every[:, :2].min(0)
        assert (extent <= 0.4 * np.sqrt(2) + 0.05).all(), (name, extent)
        centres = np.array([f[:, :2].mean(0) for f in frames])
        assert np.abs(centres - centres[0]).max() < 0.3, name
    built = [f["timings_s"].get("build", 0.0) for f in manifest["frames"]]
    assert "scene" in manifest["frames"][0] or built[0] >= max(built[1:])


def test_a_frame_range_scans_the_line_of_the_full_run(tmp_path):
    # frames 3..4 alone build the railway from frame 0's generator: same masts, same places
    full, full_manifest = run_world(tmp_path / "full", *MOBILE)
    part, part_manifest = run_world(tmp_path / "part", *MOBILE, frames_range=[3, 4])
    for index in (3, 4):
        assert np.array_equal(full[index].tobytes(), part[index].tobytes())


def test_reroll_every_frame_draws_a_new_line(tmp_path):
    clouds, manifest = run_world(tmp_path, *MOBILE, "scene.reroll_every=1", frames=2)
    masts = mast_points(clouds, manifest)
    moved = [name for name, frames in masts.items() if len(frames) == 2 and np.abs(frames[0][:, 0].mean() - frames[1][:, 0].mean()) > 1.0]
    assert moved  # a new draw of the spans puts the masts elsewhere


def test_stations_revisited_scan_the_same_line(tmp_path):
    clouds, manifest = run_world(tmp_path, "sensor.preset=vlp16", "scene.stations.count=2", "scene.supports.span_jitter=8", frames=4)
    assert [f["sensor_pose"][0][3] for f in manifest["frames"]][:2] == [f["sensor_pose"][0][3] for f in manifest["frames"]][2:]
    assert clouds[0].tobytes() == clouds[2].tobytes() and clouds[1].tobytes() == clouds[3].tobytes()


def test_a_profile_scanner_on_a_train_roof_cuts_the_line_across(tmp_path):
    clouds, manifest = run_world(tmp_path, "sensor.preset=railway_profiler", "sensor.rotation_deg=[0, 0, 30]", "effects.ideal=true",
                                 "sensor.trajectory={curve: track_centreline, speed: 10, height: 4.2, start_distance: 20}", frames=3)
    classes = {}
    for frame in manifest["frames"]:
        cloud = clouds[frame["index"]]
        assert cloud["ring"].max() == 19 and 0 <= cloud["time"].min() and cloud["time"].max() < 0.1  # 20 profiles in 0.1 s
        names = {o["instance"]: o["name"] for o in frame["objects"]}
        for name in {names.get(int(i), "") for i in np.unique(cloud["instance"])}:
            kind = name.split(".")[-1] if name.startswith("span.") else name.split(".")[2] if name.startswith("support.") else name.split(".")[0]
            classes[kind] = classes.get(kind, 0) + 1
        # profile p is fired 5 cm further along the track than profile p - 1 (10 m/s, 200 Hz): a rail's points show it
        rails = cloud[np.char.startswith(np.array([names.get(int(i), "") for i in cloud["instance"]]), "rails")]
        first, last = rails[rails["ring"] == 0], rails[rails["ring"] == 19]
        assert np.median(last["x"]) - np.median(first["x"]) == pytest.approx(19 * 0.05, abs=0.15)
    assert {"contact_wire", "messenger_wire", "rails", "sleepers"} <= set(classes)
