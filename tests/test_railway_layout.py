"""Railway layout without Blender: supports, spans, droppers, stations, validation and level of detail."""

import math

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.builders.railway import catenary
from bpy_pipeline.geometry.lod import SensorView, section_error
from bpy_pipeline.lidar.sensor.view import view_of
from bpy_pipeline.builders.railway.layout import level_of_detail, plan, station_frames


def params(*overrides):
    return load_config(None, list(overrides)).scene.params


def test_spans_are_jittered_within_bounds_and_fill_the_line():
    p = params("scene.track.start=[0, 0, 0]", "scene.track.mid=[500, 0, 0]", "scene.track.end=[1000, 0, 0]", "scene.supports.span=48",
               "scene.supports.span_jitter=2")
    layout = plan(p, np.random.default_rng(3))
    spans = layout.spans
    assert len(spans) == 20 and spans.min() >= 46 and spans.max() <= 50 and spans.std() > 0.3
    chainages = [s.chainage for s in layout.supports]
    assert chainages[0] >= 0 and chainages[-1] <= 1000 and chainages[0] == pytest.approx(1000 - chainages[-1])


def test_droppers_follow_the_rule_and_hang_between_the_wires():
    p = params("scene.catenary.dropper_spacing=6", "scene.catenary.dropper_jitter=0.5")
    layout = plan(p, np.random.default_rng(0))
    contact = {(w.run, w.span): w for w in layout.wires if w.kind == "contact_wire"}
    messenger = {(w.run, w.span): w for w in layout.wires if w.kind == "messenger_wire"}
    assert len(layout.droppers) == len(contact) == len(layout.spans) > 0
    for d in layout.droppers:
        wire = contact[(d.run, d.span)]
        assert len(d.t) == max(1, math.floor(wire.length / 6.0))
        np.testing.assert_allclose(d.lower[:, 2], wire.z_at(d.t))
        np.testing.assert_allclose(d.upper[:, 2], messenger[(d.run, d.span)].z_at(d.t))
        assert (d.upper[:, 2] - d.lower[:, 2] > 0.15).all()


def test_double_contact_wires_stagger_their_droppers():
    layout = plan(params("scene.catenary.double_contact_probability=1", "scene.catenary.double_contact_spacing=0.05"), np.random.default_rng(0))
    assert layout.double_contact.all()
    a = next(d for d in layout.droppers if d.run == "t0" and d.span == 0)
    b = next(d for d in layout.droppers if d.run == "t0b" and d.span == 0)
    merged = np.sort(np.concatenate([a.t, b.t]))
    assert len(a.t) == len(b.t) and set(merged[0::2]) == set(a.t)  # alternate along the span
    wa = next(w for w in layout.wires if w.run == "t0" and w.span == 0 and w.kind == "contact_wire")
    wb = next(w for w in layout.wires if w.run == "t0b" and w.span == 0 and w.kind == "contact_wire")
    assert np.linalg.norm(wa.start - wb.start) == pytest.approx(0.05)


def test_support_types_follow_the_track_count():
    rng = np.random.default_rng(0)
    assert plan(params(), rng).layout == "single"
    layouts = {plan(params("scene.track.tracks=2"), np.random.default_rng(s)).layout for s in range(12)}
    assert layouts == {"single", "both_sides"}
    layout = plan(params("scene.track.tracks=4"), rng)
    assert layout.layout == "gantry" and all(s.gantry for s in layout.supports)
    carried = sorted(i for m in layout.supports[0].masts for i in m.tracks)
    assert carried == [0, 1, 2, 3]
    both = plan(params("scene.track.tracks=3", "scene.supports.layout=both_sides"), rng)
    assert [m.tracks for m in both.supports[0].masts] == [(0, 1), (2,)]


def test_stations_beside_the_track():
    p = params("scene.stations.count=3", "scene.track.tracks=2", "scene.stations.side=right", "scene.stations.offset=4")
    frames = station_frames(p)
    assert frames.shape == (3, 4, 4)
    np.testing.assert_allclose(frames[:, 0, 3], [-50, 0, 50])
    np.testing.assert_allclose(frames[:, 1, 3], -2.0 - 4.0)  # 4 m beyond the right track's centreline (at -2)
    curved = params("scene.track.mid=[0, 30, 0]", "scene.stations.chainages=[10, 80]")
    frames = station_frames(curved)
    from bpy_pipeline.builders.railway.alignment import arc_through

    arc = arc_through((-75, 0, 0), (0, 30, 0), (75, 0, 0))
    np.testing.assert_allclose(frames[:, :3, 3], arc.offset([10, 80], 4.0, 0.0))  # on the lateral perpendicular
    np.testing.assert_allclose(frames[:, :3, 0], np.cross(arc.lateral([10, 80]), [0, 0, 1]))
    assert station_frames(params("scene.stations.count=0")).shape == (0, 4, 4)


def test_same_seed_same_layout():
    p = params("scene.track.tracks=2", "scene.supports.mast_type=mixed", "scene.catenary.double_contact_probability=0.5")
    a, b, c = plan(p, np.random.default_rng(7)), plan(p, np.random.default_rng(7)), plan(p, np.random.default_rng(8))
    same = lambda x, y: all(np.array_equal(u.start, v.start) and u.sag == v.sag for u, v in zip(x.wires, y.wires)) and len(x.wires) == len(y.wires)  # noqa: E731
    assert same(a, b) and not same(a, c)


BAD = {
    "scene.supports.span=0": r"^scene.supports.span: must be > 0",
    "scene.supports.span_jitter=50": r"^scene.supports.span_jitter: must stay below span \(50.0 m\)",
    "scene.track.end=[-75, 0, 0]": r"^scene.track: start and end coincide",
    "scene.track.tracks=6": r"^scene.track.tracks: must lie in 1..5",
    "scene.supports.layout=gantry": r"^scene.supports.layout: gantry serves 2 to 5 tracks",
    "scene.catenary.system_height=0.3": r"^scene.catenary.system_height: the messenger would sag",
    "scene.supports.mast_height=6": r"^scene.supports.mast_height: a mast must reach above the cantilever",
    "scene.stations.chainages=[200]": r"^scene.stations.chainages\[0\]: must lie along the line",
    "scene.catenary.dropper_jitter=3": r"^scene.catenary.dropper_jitter: must stay below half",
    "scene.wheels=4": r"^scene.wheels: unknown key",
}


@pytest.mark.parametrize("override", BAD)
def test_bad_railway_config_names_its_key(override):
    with pytest.raises(InputError, match=BAD[override]):
        load_config(None, [override])


def test_sensor_driven_detail():
    p = params("scene.track.start=[0, 0, 0]", "scene.track.mid=[400, 30, 0]", "scene.track.end=[800, 0, 0]")
    layout = plan(p, np.random.default_rng(0))
    spec = load_config().sensor.spec
    station = layout.alignment.offset([100.0], 5.0, 2.0)
    view = view_of(spec, station)
    assert view.step == pytest.approx(math.radians(0.2))
    detail = level_of_detail(layout, p, view)
    built = [w for w, s in zip(layout.wires, detail.wires) if s is not None]
    assert 0 < len(built) < len(layout.wires)  # spans beyond 150 m are not built
    for wire, setting in zip(layout.wires, detail.wires):
        distance = float(view.segment_distance(wire.start, wire.end)[0])
        if setting is None:
            assert distance - wire.sag > view.max_range
            continue
        samples, sides = setting
        tolerance = max(0.5 * view.step * max(distance - wire.sag, 0.5), 1e-4)
        modelled = catenary.chord_error(wire.length, wire.sag, samples) + section_error(wire.diameter / 2, sides)
        assert modelled <= tolerance  # chords and section together under half the beam spacing
    assert detail.track_trim[0] == 0.0 and detail.track_trim[1] < layout.alignment.length  # the far end is not built
    assert detail.stone_radius == pytest.approx(0.045 / (2 * view.step))
    (k, (s0, s1)), = detail.stone_trims
    assert k == 0 and s0 < 100 < s1 and s1 - s0 < 2 * (detail.stone_radius + layout.section.ballast_toe_half) + 2
    assert len(detail.supports) < len(layout.supports)
    fixed = level_of_detail(layout, params("scene.detail.mode=fixed"), view)
    assert all(s is not None for s in fixed.wires) and fixed.stone_radius == 0
    assert [s for s, _ in fixed.wires] == [catenary.thesis_sample_count(w.length, 20) for w in layout.wires]


def test_far_view_builds_nothing_of_the_catenary():
    layout = plan(params(), np.random.default_rng(0))
    view = SensorView(np.array([[0.0, 1000.0, 0.0]]), math.radians(0.1), 150.0)
    detail = level_of_detail(layout, params(), view)
    assert detail.supports == [] and all(s is None for s in detail.wires) and detail.track_trim == (0.0, 0.0)


def test_supports_and_wires_sit_on_the_lateral_perpendicular_of_a_curve():
    p = params("scene.track.mid=[0, 12, 0]", "scene.track.start=[-150, 0, 0]", "scene.track.end=[150, 0, 0]")
    layout = plan(p, np.random.default_rng(0))
    arc, section = layout.alignment, layout.section
    contact_z = section.rail_top + p.catenary.contact_wire_height
    for support in layout.supports:
        np.testing.assert_allclose(support.frame[:3, 3], arc.point(support.chainage)[0])
        np.testing.assert_allclose(support.frame[:3, 1], arc.lateral(support.chainage)[0])
        mast = support.masts[0]
        assert mast.side == "right" and mast.lateral == pytest.approx(-p.supports.mast_offset)
    for wire in (w for w in layout.wires if w.kind == "contact_wire"):
        a, b = layout.supports[wire.span], layout.supports[wire.span + 1]
        np.testing.assert_allclose(wire.start, arc.offset([a.chainage], a.stagger, contact_z)[0], atol=1e-9)
        np.testing.assert_allclose(wire.end, arc.offset([b.chainage], b.stagger, contact_z)[0], atol=1e-9)


def test_an_auxiliary_messenger_hangs_between_and_splits_the_droppers():
    p = params("scene.catenary.auxiliary_messenger=true")
    layout = plan(p, np.random.default_rng(0))
    cat = p.catenary
    contact_z = layout.section.rail_top + cat.contact_wire_height
    aux = [w for w in layout.wires if w.kind == "auxiliary_messenger"]
    contact = {w.span: w for w in layout.wires if w.kind == "contact_wire"}
    messenger = {w.span: w for w in layout.wires if w.kind == "messenger_wire"}
    assert aux and len(aux) == len(contact) and all(w.class_name == "auxiliary messenger" for w in aux)
    for wire in aux:
        assert wire.start[2] == pytest.approx(contact_z + 0.3) and wire.end[2] == pytest.approx(contact_z + 0.3)
        t = np.linspace(0, 1, 21)
        assert (wire.z_at(t) > contact[wire.span].z_at(t) + 0.075).all() and (wire.z_at(t) < messenger[wire.span].z_at(t) - 0.075).all()
    lower = [d for d in layout.droppers if d.run == "t0"]
    upper = [d for d in layout.droppers if d.run == "t0p"]
    assert len(lower) == len(upper) == len(contact)
    for d in upper:
        np.testing.assert_allclose(d.upper[:, 2], messenger[d.span].z_at(d.t))
        np.testing.assert_allclose(d.lower[:, 2], [w for w in aux if w.span == d.span][0].z_at(d.t))
    with pytest.raises(InputError, match="auxiliary_messenger_height"):
        load_config(None, ["scene.catenary.auxiliary_messenger=true", "scene.catenary.auxiliary_messenger_height=1.35"])


def test_tension_sections_overlap_over_one_span_with_the_ending_run_rising():
    from bpy_pipeline.io.railway_layout import layout_record

    p = params("scene.track.start=[0, 0, 0]", "scene.track.mid=[200, 0, 0]", "scene.track.end=[400, 0, 0]", "scene.supports.span=40",
               "scene.supports.span_jitter=0", "scene.catenary.tension_length=150", "scene.track.tracks=2", "scene.supports.layout=both_sides")
    layout = plan(p, np.random.default_rng(0))
    cat = p.catenary
    assert [(o.span, o.track, o.ending, o.starting) for o in layout.overlaps] == [(3, 0, "t0", "t0s1"), (3, 1, "t1", "t1s1"), (7, 0, "t0s1", "t0s2"),
                                                                                  (7, 1, "t1s1", "t1s2")]
    wires = {(w.run, w.span, w.kind): w for w in layout.wires}
    for o in layout.overlaps:
        ending, starting = wires[(o.ending, o.span, "contact_wire")], wires[(o.starting, o.span, "contact_wire")]
        # side by side, overlap_spacing apart at both supports; the ending run rises at the far one, the starting one at the near one
        assert np.linalg.norm((ending.start - starting.start)[:2]) == pytest.approx(cat.overlap_spacing)
        assert np.linalg.norm((ending.end - starting.end)[:2]) == pytest.approx(cat.overlap_spacing)
        assert ending.end[2] - ending.start[2] == pytest.approx(cat.overlap_rise) and starting.start[2] - starting.end[2] == pytest.approx(cat.overlap_rise)
        # in service where they meet the spans beside: the ending run continues its previous span, the starting run its next
        assert np.allclose(wires[(o.ending, o.span - 1, "contact_wire")].end, ending.start)
        assert np.allclose(wires[(o.starting, o.span + 1, "contact_wire")].start, starting.end)
        messenger = wires[(o.starting, o.span, "messenger_wire")]
        assert messenger.start[2] - starting.start[2] == pytest.approx(cat.system_height)  # the whole run rises: its droppers keep their lengths
        both = [d for d in layout.droppers if d.span == o.span and d.run in (o.ending, o.starting)]
        assert len(both) == 2 and all(len(d.t) for d in both)
    record = layout_record(layout, p)
    lengths = {(w["run"], w["kind"]): w["tension_length"] for w in record["wires"] if w["kind"] == "contact_wire"}
    spans = layout.spans
    assert lengths[("t0", "contact_wire")] == pytest.approx(spans[:4].sum(), abs=0.05)  # first support to the end of its overlap span (stagger: a few mm more)
    assert lengths[("t0s1", "contact_wire")] == pytest.approx(spans[3:8].sum(), abs=0.05)  # overlap to overlap
    assert record["overlaps"][0] == {"span": 3, "track": 0, "ending": "t0", "starting": "t0s1"}
    assert plan(params(), np.random.default_rng(0)).overlaps == ()  # off by default


def test_a_steady_arm_is_a_part_apart_at_the_end_of_the_registration_arm():
    from bpy_pipeline.builders.railway import parts as railway_parts

    whole = railway_parts.cantilever(-3.05, 0.2, 6.2, 7.6, 0.3, arm_length=1.2)
    split = railway_parts.cantilever(-3.05, 0.2, 6.2, 7.6, 0.3, arm_length=1.2, steady_arm=0.5)
    assert "steady arm" not in whole and "steady arm" in split
    arm, steady = split["registration arm"][0], split["steady arm"][0]
    assert arm[:, 1].max() == pytest.approx(0.2 - 0.5, abs=0.03)  # the registration arm stops at the hinge, 0.5 m short of the wire
    assert steady[:, 1].min() == pytest.approx(0.2 - 0.5, abs=0.03) and steady[:, 1].max() == pytest.approx(0.2, abs=0.05)
    assert steady[:, 2].min() == pytest.approx(6.2 - 0.015, abs=0.005)  # its clamp sits on the contact wire
    assert whole["registration arm"][0][:, 1].max() == pytest.approx(0.2, abs=0.03)


def test_overlap_and_steady_arm_settings_are_checked():
    with pytest.raises(InputError, match="catenary.overlap_spacing"):
        params("scene.catenary.overlap_spacing=2")
    with pytest.raises(InputError, match="catenary.tension_length"):
        params("scene.catenary.tension_length=-1")
    with pytest.raises(InputError, match="catenary.steady_arm_length"):
        params("scene.catenary.steady_arms=true", "scene.catenary.steady_arm_length=1.5")
