"""The railway_layout writer: the ground-truth layout of every frame, checked against the labeled points."""

import json

import numpy as np
import pytest

from bpy_pipeline.config import load_config

pytestmark = pytest.mark.bpy


def segment_distance(points, polyline):
    """``(n,)`` distance (m) from each point to the polyline ((k, 3))."""
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    t = np.clip(((points[:, None] - a[None]) * ab[None]).sum(-1) / (ab**2).sum(-1)[None], 0, 1)
    return np.linalg.norm(points[:, None] - (a[None] + t[..., None] * ab[None]), axis=-1).min(1)


def test_every_frame_gets_the_layout_its_points_show(tmp_path):
    import bpy

    from bpy_pipeline.io import read_ply
    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["output.formats=[ply,railway_layout]", "output.preview=false", "output.frame=world", "frames=2",
                                "scene.stations.count=2", "sensor.preset=railway_tls", "sensor.sampling_factor=0.25", "effects.ideal=true",
                                "scene.supports.span_jitter=6", "scene.trackside.signal_spacing=50"])
    manifest = run(config, tmp_path, log=lambda *_: None)
    truths = [json.loads((tmp_path / "railway_layout" / f"{k:06d}.json").read_text()) for k in range(2)]
    assert truths[0] | {"frame": 1} == truths[1]  # one railway per run: one layout
    assert manifest["frames"][0]["scene"]["supports"] == len(truths[0]["supports"])
    points = read_ply(tmp_path / "ply" / "000000.ply")
    objects = {o["name"]: o["instance"] for o in manifest["frames"][0]["objects"]}
    xyz = lambda p: np.column_stack([p["x"], p["y"], p["z"]]).astype(float)  # noqa: E731
    checked = 0
    for wire in truths[0]["wires"]:
        name = f"span.{wire['run']}.{wire['span']:02d}.{wire['kind']}"
        hit = points[points["instance"] == objects.get(name, -1)]
        if len(hit) >= 20:
            # on the wire's surface: its radius plus the sensor-driven sampling's chord error (<= half the beam spacing)
            assert np.percentile(segment_distance(xyz(hit), np.array(wire["polyline"])), 99) < 0.015 + (0.024 if wire["kind"] == "feeder" else 0.012) / 2, name
            checked += 1
    assert checked >= 3
    assert len(truths[0]["signals"]) == len([o for o in manifest["frames"][0]["objects"] if o["name"].startswith("signal.")]) >= 2
    seen = 0
    for k, signal in enumerate(truths[0]["signals"]):  # the signal the builder placed, from the same draws
        hit = points[points["instance"] == objects.get(f"signal.{k:02d}", -1)]
        if len(hit):
            assert np.abs(xyz(hit)[:, :2] - np.array(signal["base"])[:2]).max() < 0.5
            seen += 1
    assert seen >= 1
    for support in truths[0]["supports"]:
        for mast in support["masts"]:
            hit = points[points["instance"] == objects.get(f"support.{support['index']:02d}.mast.{mast['side']}", -1)]
            if len(hit):
                off = np.abs(xyz(hit)[:, :2] - np.array(mast["base"])[:2]).max(0)  # a straight line along x: (along, across)
                assert off[0] < 0.25 and off[1] < 0.8  # the mast's width; across, its feeder bracket's 0.75 m reach
                assert xyz(hit)[:, 2].max() <= mast["base"][2] + mast["height"] + 0.06


def test_the_writer_refuses_another_builder():
    from bpy_pipeline.errors import InputError

    with pytest.raises(InputError, match="railway_layout"):
        load_config(None, ["output.formats=[railway_layout]", "scene.builder=primitives"])


def test_overlap_runs_and_steady_arms_are_where_the_layout_says(tmp_path):
    import bpy

    from bpy_pipeline.io import read_ply
    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # 200 m, 40 m spans, tension sections of 80 m: one overlap over span 2, scanned from beside it
    config = load_config(None, ["output.formats=[ply,railway_layout]", "output.preview=false", "output.frame=world", "frames=1",
                                "scene.track.start=[-100, 0, 0]", "scene.track.mid=[0, 0, 0]", "scene.track.end=[100, 0, 0]",
                                "scene.supports.span=40", "scene.supports.span_jitter=0", "scene.catenary.tension_length=80",
                                "scene.catenary.steady_arms=true", "scene.stations.chainages=[100]", "sensor.preset=railway_tls",
                                "sensor.sampling_factor=0.25", "effects.ideal=true"])
    manifest = run(config, tmp_path, log=lambda *_: None)
    truth = json.loads((tmp_path / "railway_layout" / "000000.json").read_text())
    assert truth["overlaps"] == [{"span": 2, "track": 0, "ending": "t0", "starting": "t0s1"}]
    points = read_ply(tmp_path / "ply" / "000000.ply")
    objects = {o["name"]: o["instance"] for o in manifest["frames"][0]["objects"]}
    xyz = lambda p: np.column_stack([p["x"], p["y"], p["z"]]).astype(float)  # noqa: E731
    for wire in truth["wires"]:
        if wire["span"] != 2 or wire["kind"] not in ("contact_wire", "messenger_wire"):
            continue
        hit = points[points["instance"] == objects[f"span.{wire['run']}.02.{wire['kind']}"]]
        assert len(hit) >= 20, wire["run"]  # both runs of the overlap are scanned, each where its polyline runs
        assert np.percentile(segment_distance(xyz(hit), np.array(wire["polyline"])), 99) < 0.015 + 0.006, (wire["run"], wire["kind"])
    steady = [o for o in manifest["frames"][0]["objects"] if ".steady_arm." in o["name"]]
    assert steady and all(o["class"] == "steady arm" for o in steady)
    assert np.isin([o["instance"] for o in steady], points["instance"]).any()
