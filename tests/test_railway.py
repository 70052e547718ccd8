"""The railway builder in Blender: measured from labeled scans, and the Track node group a user can edit."""

import math

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.builders.railway import catenary

pytestmark = pytest.mark.bpy
TLS = ["sensor.preset=railway_tls"]


def scan_world(tmp_path, *overrides):
    """Run the pipeline in-process (world-frame output); ``(points, manifest)``."""
    import bpy

    from bpy_pipeline.io import read_ply
    from bpy_pipeline.plan import run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, ["output.formats=[ply]", "output.preview=false", "output.frame=world", *overrides])
    manifest = run(config, tmp_path, log=lambda *_: None)
    return read_ply(tmp_path / "ply" / "000000.ply"), manifest


def instance_of(manifest, name):
    return next(o["instance"] for o in manifest["frames"][0]["objects"] if o["name"] == name)


def test_gauge_measured_from_the_rail_points(tmp_path):
    # a station on the centreline, looking down at both rails' inner faces
    points, manifest = scan_world(tmp_path, *TLS, "sensor.vertical_fov_deg=[-70, -50]", "sensor.sampling_factor=0.5",
                                  "scene.stations.offset=0", "scene.track.gauge=1.5", "scene.detail.stones=false", "effects.ideal=true")
    rails = points[points["instance"] == instance_of(manifest, "rails.t0")]
    y, z = rails["y"].astype(float), rails["z"].astype(float)
    head = z > z.max() - 0.030  # the rail heads (43 mm high): their inner faces carry the gauge
    gauge = y[head & (y > 0)].min() - y[head & (y < 0)].max()
    assert len(rails) > 1000 and gauge == pytest.approx(1.5, abs=1e-3)


def test_sag_measured_from_the_contact_wire_points(tmp_path):
    sag = 0.25  # pre-sag at the reference length; the law scales it with each span
    points, manifest = scan_world(tmp_path, *TLS, "sensor.vertical_fov_deg=[0, 90]", "sensor.sampling_factor=0.5",
                                  f"scene.catenary.contact_wire_sag={sag}", "scene.catenary.sag_exponent=2", "scene.catenary.sag_reference_length=50")
    objects = {o["name"]: o for o in manifest["frames"][0]["objects"]}
    checked = 0
    for name, row in objects.items():
        if not name.endswith("contact_wire"):
            continue
        wire = points[points["instance"] == row["instance"]]
        if len(wire) < 200:
            continue
        xyz = np.column_stack([wire["x"], wire["y"], wire["z"]]).astype(float)
        span = next(s for s in manifest_spans(manifest) if s[0] == int(name.split(".")[2]))
        start, end = span[1], span[2]
        t = (xyz[:, :2] - start[:2]) @ (end[:2] - start[:2]) / np.sum((end[:2] - start[:2]) ** 2)
        c2, _, _ = np.polyfit(t, xyz[:, 2], 2)  # z = z0 + (dz - 4 s) t + 4 s t^2
        expected = catenary.sag_for_span(np.linalg.norm((end - start)[:2]), sag, 50.0, 2.0)
        assert c2 / 4 == pytest.approx(expected, abs=0.01), name
        checked += 1
    assert checked >= 1  # the span over the station (farther ones return too few points at 0.1 deg)


def manifest_spans(manifest):
    """``(span index, start (3,), end (3,))`` of each contact wire, rebuilt from the resolved config."""
    from bpy_pipeline.config import config_from_dict
    from bpy_pipeline.builders.railway.layout import plan
    from bpy_pipeline.frame import frame_rng

    config = config_from_dict(manifest["config"])
    layout = plan(config.scene.params, frame_rng(manifest["seed"], 0))
    return [(w.span, w.start, w.end) for w in layout.wires if w.kind == "contact_wire"]


def build(*overrides, seed=0, view=None):
    import bpy

    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.blender import build_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(None, list(overrides))
    return config, build_scene(config.scene, frame_rng(seed, 0), view).scene  # the railway layout


def test_dropper_count_per_span_follows_the_rule():
    import bpy

    _, layout = build("scene.catenary.dropper_spacing=4.5", "scene.track.start=[-150, 0, 0]", "scene.track.end=[150, 0, 0]")
    contact = {w.span: w for w in layout.wires if w.kind == "contact_wire"}
    assert len(contact) >= 4
    for span, wire in contact.items():
        droppers = bpy.data.objects[f"span.t0.{span:02d}.droppers"]
        assert len(droppers.data.splines) == max(1, math.floor(wire.length / 4.5))
    from bpy_pipeline.builders.railway.support_nodes import support_frames

    masts = {}  # the instanced masts' stations: the points of the "Railway Supports" objects
    for obj in (o for o in bpy.data.objects if o.name.startswith("supports.mast.")):
        masts |= dict(zip(obj["lidar_parts"], support_frames(obj)))
    for support in layout.supports:  # the support assemblies stand in their frames on the alignment
        np.testing.assert_allclose(masts[f"support.{support.index:02d}.mast.right"], support.frame, atol=1e-4)  # float32 station points
        for part in ("cantilever.t0", "registration_arm.t0", "insulators.t0"):
            np.testing.assert_allclose(np.array(bpy.data.objects[f"support.{support.index:02d}.{part}"].matrix_world), support.frame, atol=1e-6)


def evaluated_vertices(obj):
    import bpy

    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    v = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", v)
    evaluated.to_mesh_clear()
    return v.reshape(-1, 3).astype(float) @ np.array(obj.matrix_world)[:3, :3].T + np.array(obj.matrix_world)[:3, 3]


def test_collinear_alignment_gives_a_straight_track():
    import bpy

    build("scene.track.start=[0, 0, 0]", "scene.track.mid=[30, 40, 0]", "scene.track.end=[60, 80, 0]", "scene.stations.count=0")
    rails = evaluated_vertices(bpy.data.objects["rails.t0"])
    direction = np.array([0.6, 0.8, 0.0])
    lateral = rails[:, :2] @ np.array([-0.8, 0.6])
    along = rails @ direction
    assert along.min() == pytest.approx(0, abs=1e-4) and along.max() == pytest.approx(100, abs=1e-4)
    rail_centre = 1.435 / 2 + 0.072 / 2  # the head's inner face is half the gauge out
    assert np.abs(lateral).min() == pytest.approx(rail_centre - 0.075, abs=1e-5) and np.abs(lateral).max() == pytest.approx(rail_centre + 0.075, abs=1e-5)


def test_the_track_follows_a_curve_and_its_node_group_is_editable():
    import bpy

    from bpy_pipeline.blender.compat import set_modifier_input
    from bpy_pipeline.builders.railway.alignment import arc_through

    build("scene.track.mid=[0, 25, 0]", "scene.stations.count=0", "scene.track.design_speed=0")  # no cant: rails level across
    arc = arc_through((-75, 0, 0), (0, 25, 0), (75, 0, 0))
    rails = evaluated_vertices(bpy.data.objects["rails.t0"])
    s = arc.nearest_chainage(rails)
    offset = np.einsum("ij,ij->i", rails - arc.point(s), arc.lateral(s))
    head = rails[:, 2] > rails[:, 2].max() - 0.03
    assert np.abs(offset[head]).min() == pytest.approx(1.435 / 2, abs=0.002)  # rails keep the gauge along the arc
    assert np.abs(offset).max() == pytest.approx(1.435 / 2 + 0.036 + 0.075, abs=0.002)
    group = bpy.data.node_groups["Track"]
    names = {item.name for item in group.interface.items_tree if getattr(item, "in_out", None) == "INPUT"}
    assert {"Gauge", "Sleeper Spacing", "Ballast Height", "Ballast Shoulder", "Tracks", "Track Spacing", "Embankment Height", "Embankment Slope",
            "Rail Head Width"} <= names
    rails_obj = bpy.data.objects["rails.t0"]
    set_modifier_input(rails_obj.modifiers[0], "Gauge", 1.0)  # what a user does in the modifier panel
    rails_obj.update_tag()
    moved = evaluated_vertices(rails_obj)
    s = arc.nearest_chainage(moved)
    head = moved[:, 2] > moved[:, 2].max() - 0.03
    assert np.abs(np.einsum("ij,ij->i", moved - arc.point(s), arc.lateral(s))[head]).min() == pytest.approx(0.5, abs=0.002)
    curve = bpy.data.objects["track_centreline"]
    curve.location.z = 1.0  # editing the centreline moves the track
    bpy.context.view_layer.update()
    assert evaluated_vertices(rails_obj)[:, 2].min() == pytest.approx(1.0 + 0.35 + 0.22, abs=1e-4)


def test_every_class_of_the_scene_appears_in_the_output(tmp_path):
    from bpy_pipeline.labels import load_class_table

    table = load_class_table()
    for layout in ("single", "gantry"):
        out = tmp_path / layout
        points, manifest = scan_world(out, "scene.track.tracks=2", f"scene.supports.layout={layout}", "scene.track.embankment_height=0.6",
                                      "scene.catenary.double_contact_probability=1", "scene.supports.mast_type=lattice")
        built = {o["class"] for o in manifest["frames"][0]["objects"]}
        seen = {table.names[i] for i in np.unique(points["semantic"])}
        expected = {"ground", "ballast", "rail", "sleeper", "cantilever", "registration arm", "insulator", "contact wire", "messenger wire",
                    "dropper", "feeder wire", "earth wire", "mast" if layout == "single" else "gantry"}
        assert built == expected and seen == expected, (layout, built ^ expected, expected - seen)


def test_same_seed_same_scene():
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.lidar.sensor.view import view_of
    from bpy_pipeline.labels import load_class_table

    overrides = ("scene.track.tracks=2", "scene.supports.mast_type=mixed", "scene.catenary.double_contact_probability=0.5")
    spec = load_config().sensor.spec
    view = view_of(spec, [[0.0, 8.0, 2.0]])
    scenes = []
    for seed in (5, 5, 6):
        build(*overrides, seed=seed, view=view)
        buffers = export_scene(load_class_table())
        scenes.append((buffers.vertices.tobytes(), buffers.triangles.tobytes(), tuple(buffers.objects.names)))
    assert scenes[0] == scenes[1] and scenes[0] != scenes[2]


def test_stations_are_frames_of_one_built_line(tmp_path):
    points, manifest = scan_world(tmp_path, "scene.stations.count=3", "frames=4", "sensor.sampling_factor=0.05")
    frames = manifest["frames"]
    assert [f["station"] for f in frames] == [0, 1, 2, 0]  # the fourth frame scans from the first station again
    xs = [f["sensor_pose"][0][3] for f in frames]
    np.testing.assert_allclose(xs, [-50, 0, 50, -50])
    np.testing.assert_allclose([f["sensor_pose"][1][3] for f in frames], 4.0)
    np.testing.assert_allclose([f["sensor_pose"][2][3] for f in frames], 2.0)  # 2 m above the ground beside the track
    assert frames[1]["timings_s"]["build"] < frames[0]["timings_s"]["build"]  # built once, scanned three times


def test_ballast_fills_between_the_sleepers():
    import bpy

    config, layout = build("scene.detail.mode=fixed", "scene.track.crib_height=0.15")
    track = config.scene.params.track
    top = evaluated_vertices(bpy.data.objects["ballast"])[:, 2].max()
    sleepers = evaluated_vertices(bpy.data.objects["sleepers.t0"])[:, 2]
    assert top == pytest.approx(track.ballast_height + 0.15, abs=1e-4)  # the crib ballast's top
    assert sleepers.min() == pytest.approx(track.ballast_height, abs=1e-4) and sleepers.max() > top + 0.05  # sleepers stand 7 cm proud
    assert float(layout.section.surface(0.0)) == pytest.approx(top, abs=1e-6)


@pytest.mark.parametrize("turn", [1, -1])
def test_cant_on_a_600_m_curve_measured_from_the_rail_points(tmp_path, turn):
    # a 300 m chord with a 19.05 m rise: R = 600 m; at 80 km/h the equilibrium cant is 11.8 * 80^2 / 600 = 125.9 mm
    mid = 600.0 - math.sqrt(600.0**2 - 150.0**2)
    points, manifest = scan_world(tmp_path, *TLS, "sensor.vertical_fov_deg=[-70, -50]", "sensor.sampling_factor=0.5", "scene.stations.offset=0",
                                  "scene.track.start=[-150, 0, 0]", f"scene.track.mid=[0, {turn * mid}, 0]", "scene.track.end=[150, 0, 0]",
                                  "scene.track.design_speed=80", "scene.detail.stones=false", "effects.ideal=true")
    rails = points[points["instance"] == instance_of(manifest, "rails.t0")]
    centre = np.array([0.0, turn * (mid - 600.0)])
    radius = np.hypot(rails["x"] - centre[0], rails["y"] - centre[1])
    z = rails["z"].astype(float)
    inner, outer = z[radius < 600.0].max(), z[radius > 600.0].max()  # the heads' top corners: gauge + head width apart
    assert len(rails) > 1000
    assert outer - inner == pytest.approx(11.8 * 80**2 / 600.0 / 1000.0, abs=0.003)
    ground = manifest["frames"][0]["sensor_pose"][2][3] - 2.0  # the station (offset 0) stands on the ballast, 0.35 + 0.17 m up
    assert inner - (ground - 0.52) == pytest.approx(0.742, abs=0.003)  # the inner rail keeps its height above formation


def test_cant_given_or_capped():
    from bpy_pipeline.builders.railway.alignment import arc_through
    from bpy_pipeline.builders.railway.layout import cant

    track = load_config(None, ["scene.track.design_speed=200"]).scene.params.track
    curve = arc_through((-150, 0, 0), (0, 600.0 - math.sqrt(600.0**2 - 150.0**2), 0), (150, 0, 0))
    assert cant(track, curve) == track.max_cant == 0.16  # 786 mm wanted, capped
    given = load_config(None, ["scene.track.cant_from=value", "scene.track.cant=0.05"]).scene.params.track
    assert cant(given, curve) == 0.05 and cant(given, arc_through((-1, 0, 0), (0, 0, 0), (1, 0, 0))) == 0.0


def test_trackside_fences_signals_and_a_platform(tmp_path):
    import bpy

    from bpy_pipeline.labels import load_class_table

    sides = ["scene.trackside.fences=true", "scene.trackside.signal_spacing=60", "scene.trackside.platform_length=60", "scene.trackside.platform_chainage=110",
             "scene.trackside.vegetation_per_100m=20"]
    points, manifest = scan_world(tmp_path, "sensor.preset=vlp16", "sensor.mount_height=2.5", "effects.ideal=true", *sides)
    table = load_class_table()
    found = {table.names[int(c)] for c in np.unique(points["semantic"])}
    assert {"fence", "signal", "platform", "vegetation"} <= found
    config, layout = build(*sides, "scene.detail.mode=fixed")
    top = evaluated_vertices(bpy.data.objects["platform"])[:, 2].max()
    assert top == pytest.approx(layout.section.rail_top + 0.76, abs=1e-4)
    supports = np.array([s.chainage for s in layout.supports])
    signals = [o for o in bpy.data.objects if o.name.startswith("signal.")]
    assert len(signals) == 2  # every 60 m +- 15 m along 150 m
    for obj in signals:
        x = evaluated_vertices(obj)[:, 0].mean() + 75.0  # chainage on the straight line from x = -75
        assert np.abs(supports - x).min() >= 2.9
    plants = evaluated_vertices(bpy.data.objects["vegetation"])
    assert np.abs(plants[:, 1]).min() > 6.0 + 1.0 - 3.0 - 1e-6  # beyond the fences (a crown reaches 3 m towards them)
    fence = evaluated_vertices(bpy.data.objects["fence.left"])
    assert np.allclose(fence[:, 1].mean(), 6.0, atol=0.05) and fence[:, 2].max() == pytest.approx(1.8, abs=1e-6)


def test_the_cant_ramps_along_transition_curves():
    import bpy

    from bpy_pipeline.builders.railway.layout import cant

    mid = 600.0 - math.sqrt(600.0**2 - 150.0**2)
    config, layout = build("scene.detail.mode=fixed", "scene.track.start=[-150, 0, 0]", f"scene.track.mid=[0, {mid}, 0]", "scene.track.end=[150, 0, 0]",
                           "scene.track.transition_length=40", "scene.track.design_speed=80")
    alignment = layout.alignment
    full = cant(config.scene.params.track, alignment)
    assert full == pytest.approx(11.8 * 80**2 / alignment.radius / 1000.0) and alignment.radius < 600.0
    rails = evaluated_vertices(bpy.data.objects["rails.t0"])
    s = alignment.nearest_chainage(rails)
    lateral = np.einsum("ij,ij->i", rails - alignment.point(s), alignment.lateral(s))
    outward = -np.sign(np.einsum("ij,ij->i", alignment.lateral(s), alignment.centre - alignment.point(s)))
    checked = 0
    for ring in np.unique(np.round(s, 2)):  # the profile rings Curve to Mesh makes at each centreline point
        near = np.abs(s - ring) < 0.02
        outer, inner = near & (lateral * outward > 0), near & (lateral * outward < 0)
        if outer.sum() < 10 or inner.sum() < 10:
            continue
        expected = full * float(alignment.curvature([ring])[0]) * alignment.radius
        assert rails[outer, 2].max() - rails[inner, 2].max() == pytest.approx(expected, abs=0.004), ring
        checked += 1
    assert checked >= 20


def test_anchors_weights_and_section_insulators():
    import bpy

    config, layout = build("scene.detail.mode=fixed", "scene.catenary.anchors=true", "scene.catenary.section_insulator_every=2")
    classes = {o.name: o.get("lidar_class") for o in bpy.data.objects}
    last = len(layout.supports) - 1
    for k in (0, last):
        assert classes[f"support.{k:02d}.anchor.right"] == "anchor" and classes[f"support.{k:02d}.tensioning_weight.right"] == "tensioning weight"
        weight = evaluated_vertices(bpy.data.objects[f"support.{k:02d}.tensioning_weight.right"])
        mast_x = layout.supports[k].frame[0, 3]
        assert (weight[:, 0].mean() - mast_x) * (1 if k else -1) == pytest.approx(0.6, abs=1e-6)  # behind the end mast, away from the line
    insulators = [n for n, c in classes.items() if c == "section insulator"]
    assert insulators == [f"span.t0.{k:02d}.section_insulator" for k in range(1, last, 2)]
    for name in insulators:
        span = int(name.split(".")[2])
        droppers = next(d for d in layout.droppers if d.span == span and d.run == "t0")
        wire = next(w for w in layout.wires if w.span == span and w.kind == "contact_wire")
        assert (np.abs(droppers.t - 0.5) * wire.length >= 1.2).all()


def test_a_cutting_with_undulating_ground():
    import bpy

    config, layout = build("scene.detail.mode=fixed", "scene.track.cut_depth=4", "scene.track.ground_roughness=0.5", "scene.track.ground_wavelength=30")
    section = layout.section
    ground = evaluated_vertices(bpy.data.objects["ground"])
    d = np.abs(ground[:, 1])
    bottom, slope, top = (
        d <= section.embankment_top_half,
        (d > section.embankment_top_half + 0.1) & (d < section.embankment_toe_half - 0.1),
        d > section.embankment_toe_half + 5,
    )
    assert np.allclose(ground[bottom, 2], 0.0) and np.allclose(ground[slope, 2], section.surface(ground[slope, 1]))  # formation, then the slopes
    # undulating about the top by at most the amplitude (three waves of weights 1, 1/2, 1/4 over 1.75: std 0.46 x 0.5 m)
    assert ground[top, 2].mean() == pytest.approx(4.0, abs=0.2) and 0.15 < ground[top, 2].std() < 0.35 and np.abs(ground[top, 2] - 4.0).max() <= 0.5 + 1e-6
    mast = layout.supports[0].masts[0]
    assert mast.base == pytest.approx(float(section.surface(mast.lateral)))  # the masts stand on the cutting's floor
    with pytest.raises(InputError, match="cut_depth"):
        load_config(None, ["scene.track.cut_depth=2", "scene.track.embankment_height=1"])
