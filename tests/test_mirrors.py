"""Mirrors, glass and absorbers in the scene, against analytic references.

The scenes are triangle buffers built from the pure primitives (fast, no Blender), plus one
end-to-end run through Blender's depsgraph and the pipeline; every expected position, range
and bounce count below is solved by hand (plane intersections and reflections).
"""

import numpy as np
import pytest

from bpy_pipeline.buffers import MATERIAL_ID, ObjectTable, SceneBuffers
from bpy_pipeline.geometry import primitives
from bpy_pipeline.lidar.cast.raycast import RayCaster
from bpy_pipeline.lidar.cast.scanner import MirrorGlassRules, scan, trace_beams
from bpy_pipeline.lidar.sensor.rays import Pattern

WALL, MIRROR_CLASS, REFLECTION = 17, 20, 25


def scene(*objects, offset=(0.0, 0.0, 0.0)):
    """SceneBuffers of ``(name, (vertices, triangles), material, reflectivity, semantic)`` objects, moved by ``offset``."""
    vertices, triangles, rows, start = [], [], [], 0
    for row, (_, (v, t), *_rest) in enumerate(objects):
        vertices.append(v + offset)
        triangles.append(t + start)
        rows.append(np.full(len(t), row, np.int32))
        start += len(v)
    k = len(objects)
    table = ObjectTable(
        [o[0] for o in objects], [""] * k, ["x"] * k, np.array([o[4] for o in objects], np.uint16), np.arange(1, k + 1, dtype=np.uint32),
        np.array([MATERIAL_ID[o[2]] for o in objects], np.uint8), np.array([o[3] for o in objects], np.float32),
    )
    return SceneBuffers(np.concatenate(vertices), np.concatenate(triangles).astype(np.int32), np.concatenate(rows), table)


def plane_at(size, centre, normal, up=(0.0, 0.0, 1.0)):
    """A square or rectangle (size: edge or [along, up]) centred at ``centre`` facing ``normal`` (winding gives that normal)."""
    sx, sy = (size, size) if np.isscalar(size) else size
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    up = np.asarray(up, float) - normal * np.dot(up, normal)
    up /= np.linalg.norm(up)
    along = np.cross(up, normal)
    v, t = primitives.plane(sx, sy)  # normal +z: x -> along, y -> up, z -> normal
    return np.asarray(centre, float) + v[:, :1] * along + v[:, 1:2] * up + v[:, 2:] * normal, t


def fan(azimuths_deg, elevations_deg):
    az, el = np.meshgrid(np.radians(azimuths_deg), np.radians(elevations_deg))
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1).reshape(-1, 3)
    return d


def run(buffers, directions, origin=(0.0, 0.0, 0.0), max_range=100.0, **kwargs):
    pose = np.eye(4)
    pose[:3, 3] = origin
    pattern = Pattern(np.asarray(directions, float), np.zeros(len(directions), np.uint16), np.arange(len(directions), dtype=np.float64))
    return scan(RayCaster(buffers, frame=pose), buffers, pattern, pose, 0.1, max_range, **kwargs)


def reflect(points, plane_point, normal):
    """Mirror images of ``points`` (n, 3) across a plane."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    return points - 2.0 * ((points - plane_point) @ normal)[:, None] * normal


# A mirror at 45 degrees 5 m ahead turns beams along +x towards +y; a wall 6 m to the side faces it.
M_CENTRE, M_NORMAL = np.array([5.0, 0.0, 0.0]), np.array([-1.0, 1.0, 0.0]) / np.sqrt(2)
MIRROR_45 = ("mirror", plane_at(2.0, M_CENTRE, M_NORMAL), "mirror", 0.9, MIRROR_CLASS)
SIDE_WALL = ("wall", plane_at(30.0, [5.0, 6.0, 0.0], [0.0, -1.0, 0.0]), "diffuse", 0.5, WALL)
BEAMS_45 = fan(np.linspace(-8, 8, 41), np.linspace(-8, 8, 41))


def on_mirror(directions, margin):
    """(n,) bool: beams from the origin that meet the 2 m mirror at least ``margin`` metres inside its edges."""
    hit = ((M_CENTRE @ M_NORMAL) / (directions @ M_NORMAL))[:, None] * directions - M_CENTRE
    along = np.cross([0.0, 0.0, 1.0], M_NORMAL)
    return (np.abs(hit[:, 2]) < 1.0 - margin) & (np.abs(hit @ along) < 1.0 - margin)


def expected_ghost(directions, origin=np.zeros(3)):
    """Analytic path (n,) and true hit (n, 3) of beams off the 45 degree mirror onto the side wall."""
    t1 = ((M_CENTRE - origin) @ M_NORMAL) / (directions @ M_NORMAL)
    hit = origin + t1[:, None] * directions
    r = directions - 2.0 * (directions @ M_NORMAL)[:, None] * M_NORMAL
    t2 = (6.0 - hit[:, 1]) / r[:, 1]
    return t1 + t2, hit + t2[:, None] * r


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (3000.0, -2000.0, 100.0)])
def test_ghosts_of_a_45_degree_mirror_are_mirror_images_at_the_total_path(offset):
    buffers = scene(MIRROR_45, SIDE_WALL, offset=np.array(offset))
    points, beam = run(buffers, BEAMS_45, origin=offset)
    path, true_hit = expected_ghost(BEAMS_45)
    ghosts = points[points["bounces"] == 1]
    rays = ghosts["time"].astype(int)  # the test pattern's time is the ray index
    assert np.isin(np.flatnonzero(on_mirror(BEAMS_45, 1e-6)), rays).all() and on_mirror(BEAMS_45, 1e-6).sum() > 800
    assert on_mirror(BEAMS_45, -1e-6)[rays].all() and (points["bounces"] <= 1).all()
    xyz = np.column_stack([ghosts["x"], ghosts["y"], ghosts["z"]]).astype(np.float64)
    assert np.abs(xyz - reflect(true_hit[rays], M_CENTRE, M_NORMAL)).max() < 1e-3  # the mirror image of the true hit
    assert np.abs(xyz - reflect(true_hit[rays], M_CENTRE, M_NORMAL)).max() < 1e-5  # (in fact far better)
    assert np.abs(ghosts["range"] - path[rays]).max() < 1e-5  # float32 range = total path length
    assert np.allclose(beam["gain"][points["bounces"] == 1], 0.9)


def test_ideal_sensor_reports_the_true_hit_and_labels_follow_the_policy():
    buffers = scene(MIRROR_45, SIDE_WALL)
    _, true_hit = expected_ghost(BEAMS_45)
    points, _ = run(buffers, BEAMS_45, ideal=True)
    ghosts = points[points["bounces"] == 1]
    xyz = np.column_stack([ghosts["x"], ghosts["y"], ghosts["z"]]).astype(np.float64)
    assert np.abs(xyz - true_hit[ghosts["time"].astype(int)]).max() < 1e-5 and np.allclose(ghosts["y"], 6.0)
    # target policy: class of the wall, instance of the mirror (so ghosts can be found)
    assert (ghosts["semantic"] == WALL).all() and (ghosts["instance"] == 1).all()
    reflection, _ = run(buffers, BEAMS_45, ghost_semantic=REFLECTION)
    assert (reflection["semantic"][reflection["bounces"] == 1] == REFLECTION).all()
    assert (reflection["instance"][reflection["bounces"] == 1] == 1).all()


def test_range_noise_moves_points_along_their_own_beam():
    """Behind the mirror (reported) a ghost moves along the emitted ray; at its true position
    (ideal) along the reflected segment, so it stays on the wall instead of drifting off it."""
    from bpy_pipeline.config import effects_from_dict
    from bpy_pipeline.lidar.effects.apply import apply_effects

    buffers = scene(MIRROR_45, SIDE_WALL)
    noise = effects_from_dict({"noise": {"sigma": 0.05}})
    for ideal in (False, True):
        points, beam = run(buffers, BEAMS_45, ideal=ideal)
        noisy = apply_effects(points, beam, noise, np.random.default_rng(0))
        ghost = points["bounces"] == 1
        before = np.column_stack([points[k] for k in "xyz"]).astype(np.float64)[ghost]
        after = np.column_stack([noisy[k] for k in "xyz"]).astype(np.float64)[ghost]
        step = (noisy["range"] - points["range"]).astype(np.float64)[ghost]
        assert np.std(step) > 0.03  # the noise really moved them
        np.testing.assert_allclose(after - before, step[:, None] * beam["direction"][ghost], atol=2e-5)
        if ideal:  # the reflected segment runs from the mirror to the wall (+y), not back to the sensor
            assert (beam["direction"][ghost][:, 1] > 0.9).all()
        else:
            np.testing.assert_allclose(np.linalg.norm(after, axis=1), noisy["range"][ghost], rtol=1e-5)


def test_two_facing_mirrors_stop_at_max_bounces():
    # Mirrors at x = -2 and x = +2 facing each other, 400 m long, a floor 3 m below the sensor.
    left = ("left", plane_at([400.0, 20.0], [-2.0, 0.0, 0.0], [1.0, 0.0, 0.0]), "mirror", 1.0, MIRROR_CLASS)
    right = ("right", plane_at([400.0, 20.0], [2.0, 0.0, 0.0], [-1.0, 0.0, 0.0]), "mirror", 1.0, MIRROR_CLASS)
    floor = ("floor", plane_at(400.0, [0.0, 0.0, -3.0], [0.0, 0.0, 1.0], up=(0.0, 1.0, 0.0)), "diffuse", 0.5, WALL)
    buffers = scene(left, right, floor)
    elevations = -np.degrees(np.arctan(3.0 / (2.0 + 4.0 * np.arange(30) + 1.0)))  # lands mid-way between bounce k and k + 1
    directions = fan([0.0], elevations)
    horizontal = 3.0 / np.tan(np.radians(-elevations))  # distance along x travelled before the floor
    expected = np.floor((horizontal - 2.0) / 4.0).astype(int) + 1  # walls met at 2, 6, 10, ... m
    for max_bounces in (0, 3, 12):
        points, _ = run(buffers, directions, max_bounces=max_bounces)
        rays = points["time"].astype(int)
        assert np.array_equal(rays, np.flatnonzero(expected <= max_bounces))  # beyond max_bounces the beam is lost
        assert np.array_equal(points["bounces"], expected[rays])
        assert np.allclose(points["range"], 3.0 / np.sin(np.radians(-elevations[rays])), atol=1e-4)  # unfolded path
    # A beam at normal incidence between them: with no normal-incidence return it bounces to the limit and is lost ...
    normal = np.array([[1.0, 0.0, 0.0]])
    points, _ = run(buffers, normal, max_bounces=255, max_range=1e6)
    assert len(points) == 0
    # ... with one, the first mirror returns it from its own surface.
    points, _ = run(buffers, normal, max_bounces=255, surfaces=MirrorGlassRules(mirror_return_deg=0.5))
    assert len(points) == 1 and points["bounces"][0] == 0 and points["range"][0] == pytest.approx(2.0, abs=1e-6)


def test_a_beam_across_a_mirror_edge_is_either_a_ghost_or_a_direct_hit():
    buffers = scene(MIRROR_45, SIDE_WALL, ("back", plane_at(60.0, [30.0, 0.0, 0.0], [-1.0, 0.0, 0.0]), "diffuse", 0.5, WALL))
    edge = np.arctan(1.0 / 5.0)  # the mirror's top edge, 1 m above its centre, 5 m ahead
    elevation = edge + np.linspace(-1e-6, 1e-6, 401)  # straddling the edge by a micro-radian
    directions = np.column_stack([np.cos(elevation), np.zeros_like(elevation), np.sin(elevation)])
    along = np.cross([0.0, 0.0, 1.0], M_NORMAL)
    diagonal = M_CENTRE + np.linspace(-0.99, 0.99, 101)[:, None] * (along + [0.0, 0.0, 1.0])  # the edge shared by its two triangles
    directions = np.concatenate([directions, diagonal / np.linalg.norm(diagonal, axis=1, keepdims=True)])
    points, _ = run(buffers, directions)
    assert len(points) == len(directions) and np.array_equal(points["time"].astype(int), np.arange(len(directions)))  # one return each
    xyz = np.column_stack([points["x"], points["y"], points["z"]]).astype(np.float64)
    ghost = points["bounces"] == 1
    path, true_hit = expected_ghost(directions)
    rays = np.arange(len(directions))
    assert np.abs(xyz[ghost] - reflect(true_hit[ghost], M_CENTRE, M_NORMAL)).max() < 1e-3
    direct = directions[~ghost] * (30.0 / directions[~ghost, :1])  # straight on to the back wall at x = 30
    assert np.abs(xyz[~ghost] - direct).max() < 1e-3
    clearly_in = rays[:401][elevation < edge - 1e-7]
    clearly_out = rays[:401][elevation > edge + 1e-7]
    assert ghost[clearly_in].all() and not ghost[clearly_out].any()
    assert ghost[401:].all()  # beams across the mirror's middle, through its diagonal, all reflect


def test_back_face_of_a_mirror_is_a_diffuse_surface():
    mirror = ("mirror", plane_at(2.0, [5.0, 0.0, 0.0], [1.0, 0.0, 0.0]), "mirror", 0.9, MIRROR_CLASS)  # faces away from the sensor
    buffers = scene(mirror, ("back", plane_at(60.0, [30.0, 0.0, 0.0], [-1.0, 0.0, 0.0]), "diffuse", 0.5, WALL))
    directions = fan(np.linspace(-5, 5, 11), np.linspace(-5, 5, 11))
    points, beam = run(buffers, directions)
    assert len(points) == len(directions) and (points["bounces"] == 0).all()
    assert np.allclose(points["x"], 5.0, atol=1e-5) and (points["semantic"] == MIRROR_CLASS).all()
    assert np.allclose(beam["reflectivity"], 0.9)


def test_a_mirror_of_zero_reflectivity_and_an_absorber_lose_the_beam():
    beams = fan(np.linspace(-5, 5, 11), np.linspace(-5, 5, 11))
    back = ("back", plane_at(60.0, [30.0, 0.0, 0.0], [-1.0, 0.0, 0.0]), "diffuse", 0.5, WALL)
    for material, reflectivity in (("mirror", 0.0), ("absorber", 0.5)):
        blocker = ("blocker", plane_at(4.0, [5.0, 0.0, 0.0], [-1.0, 0.2, 0.0]), material, reflectivity, MIRROR_CLASS)
        points, _ = run(scene(blocker, SIDE_WALL, back), beams, surfaces=MirrorGlassRules(mirror_return_deg=20.0))
        assert len(points) == 0, material
    alone, _ = run(scene(SIDE_WALL, back), beams)
    assert len(alone) == len(beams)  # without the blocker every beam returns


def test_path_counts_against_the_maximum_range():
    buffers = scene(MIRROR_45, SIDE_WALL)
    path, _ = expected_ghost(BEAMS_45)
    limit = float(np.median(path))
    points, _ = run(buffers, BEAMS_45, max_range=limit)
    rays = points["time"].astype(int)
    ghosts = rays[points["bounces"] == 1]
    assert len(ghosts) and (path[ghosts] <= limit + 1e-9).all()
    surely = np.flatnonzero(on_mirror(BEAMS_45, 1e-6) & (path < limit - 1e-6))
    possibly = np.flatnonzero(on_mirror(BEAMS_45, -1e-6) & (path <= limit + 1e-6))  # beams on the mirror's edge may go either way
    assert np.isin(surely, ghosts).all() and np.isin(ghosts, possibly).all() and 0 < len(surely) < on_mirror(BEAMS_45, 1e-6).sum()


# ----------------------------------------------------------------------------- glass
WINDOW = ("window", plane_at(4.0, [5.0, 0.0, 0.0], [-1.0, 0.0, 0.0]), "glass", 0.2, 20)
INTERIOR = ("seat", plane_at(8.0, [7.0, 0.0, 0.0], [-1.0, 0.0, 0.0]), "diffuse", 0.5, 20)


def test_glass_passes_beams_returns_near_normal_incidence_and_scales_intensity():
    directions = fan(np.linspace(-14.75, 14.75, 60), [0.0])
    angle = np.abs(np.linspace(-14.75, 14.75, 60))  # incidence on the window at x = 5 (normal -x); none exactly at 5
    buffers = scene(WINDOW, INTERIOR)
    points, beam = run(buffers, directions, surfaces=MirrorGlassRules(glass_return_deg=5.0))
    assert len(points) == len(directions) and (points["bounces"] == 0).all()
    on_glass = np.isclose(points["x"], 5.0, atol=1e-5)
    assert np.array_equal(on_glass, angle < 5.0) and 0 < on_glass.sum() < len(angle)  # the glass itself returns near normal incidence
    behind = ~on_glass
    assert np.allclose(points["x"][behind], 7.0, atol=1e-5)  # the interior, at its true position (direction unchanged)
    assert np.allclose(points["range"][behind], 7.0 / directions[behind, 0], atol=1e-5)
    assert np.allclose(beam["gain"][behind], 0.8)  # 1 - the glass's reflectivity
    assert np.allclose(points["intensity"][behind], 0.5 * np.cos(np.radians(angle[behind])) * 0.8, atol=1e-6)
    none, _ = run(buffers, directions)  # default MirrorGlassRules: glass never returns
    assert np.allclose(none["x"], 7.0, atol=1e-5)


def test_glass_pane_of_two_faces_counts_passes():
    pane = ("pane", primitives.translated(primitives.box(0.01, 4.0, 4.0), [5.0, 0.0, 0.0]), "glass", 0.1, 20)
    buffers = scene(pane, INTERIOR)
    directions = fan(np.linspace(-10, 10, 21), np.linspace(-10, 10, 21))
    points, beam = run(buffers, directions)
    assert len(points) == len(directions) and np.allclose(points["x"], 7.0, atol=1e-5)
    assert np.allclose(beam["gain"], 0.81)  # through two faces
    assert len(run(buffers, directions, surfaces=MirrorGlassRules(glass_passes=1))[0]) == 0  # the second face is one pass too many


def test_a_glass_reflection_fraction_is_a_mirror_share_drawn_from_the_generator():
    side = ("side", plane_at(60.0, [5.0, -10.0, 0.0], [0.0, 1.0, 0.0]), "diffuse", 0.5, WALL)
    window = ("window", plane_at(40.0, [5.0, 0.0, 0.0], [-1.0, -1.0, 0.0]), "glass", 0.5, 20)
    back = ("back", plane_at(80.0, [30.0, 0.0, 0.0], [-1.0, 0.0, 0.0]), "diffuse", 0.5, WALL)
    buffers = scene(window, side, back)
    directions = fan(np.linspace(-3, 3, 101), np.linspace(-3, 3, 101))
    all_reflect, _ = run(buffers, directions, surfaces=MirrorGlassRules(glass_reflect=1.0))
    true_hit, _ = run(buffers, directions, surfaces=MirrorGlassRules(glass_reflect=1.0), ideal=True)
    assert len(all_reflect) == len(directions) and (all_reflect["bounces"] == 1).all() and np.allclose(true_hit["y"], -10.0)
    ghost = np.column_stack([all_reflect["x"], all_reflect["y"], all_reflect["z"]]).astype(np.float64)
    real = np.column_stack([true_hit["x"], true_hit["y"], true_hit["z"]]).astype(np.float64)
    assert np.abs(ghost - reflect(real, [5.0, 0.0, 0.0], [-1.0, -1.0, 0.0])).max() < 1e-4  # the side wall, seen in the glass
    with pytest.raises(ValueError, match="Generator"):
        run(buffers, directions, surfaces=MirrorGlassRules(glass_reflect=0.3))
    a, _ = run(buffers, directions, surfaces=MirrorGlassRules(glass_reflect=0.3), rng=np.random.default_rng(7))
    b, _ = run(buffers, directions, surfaces=MirrorGlassRules(glass_reflect=0.3), rng=np.random.default_rng(7))
    c, _ = run(buffers, directions, surfaces=MirrorGlassRules(glass_reflect=0.3), rng=np.random.default_rng(8))
    assert a.tobytes() == b.tobytes() and a.tobytes() != c.tobytes()
    share = (a["bounces"] == 1).mean()
    n = len(a)
    assert abs(share - 0.3) < 4 * np.sqrt(0.3 * 0.7 / n)  # binomial, 4 sigma


def test_trace_beams_handles_no_hits_and_a_huge_mirror_near_the_sensor():
    huge = ("huge", plane_at(4000.0, M_CENTRE, M_NORMAL), "mirror", 1.0, MIRROR_CLASS)  # corners 2.8 km away, hits 5 m away
    buffers = scene(huge, SIDE_WALL)
    caster = RayCaster(buffers, frame=np.eye(4))
    beams = trace_beams(caster, buffers, np.zeros(3), BEAMS_45, 0.1, 100.0)
    path, true_hit = expected_ghost(BEAMS_45)
    assert len(beams.ray) == len(BEAMS_45) and (beams.bounces == 1).all()  # no re-hit of the mirror it left
    assert np.abs(beams.point - true_hit).max() < 1e-5 and np.abs(beams.path - path).max() < 1e-5
    empty = trace_beams(caster, buffers, np.zeros(3), -BEAMS_45, 0.1, 100.0)
    assert len(empty.ray) == 0 and empty.point.shape == (0, 3)


@pytest.mark.bpy
def test_pipeline_scene_mirror_through_blender(tmp_path):
    """Config -> primitives builder (a mirror plane and a wall) -> depsgraph -> scan: ghosts labelled ``reflection``."""
    import bpy

    from bpy_pipeline.config import config_from_dict
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.scan import scan_buffers
    from bpy_pipeline.blender import build_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    shapes = [  # the 45 degree mirror (a plane's normal is +z before rotation) and the side wall
        {"name": "mirror", "type": "plane", "size": 2, "position": [5, 0, 1.5], "rotation_deg": [0, -90, -45], "class": "wall", "material": "mirror",
         "reflectivity": 0.9},
        {"name": "wall", "type": "plane", "size": 30, "position": [5, 6, 1.5], "rotation_deg": [90, 0, 0], "class": "wall"},
    ]
    config = config_from_dict({
        "scene": {"builder": "primitives", "shapes": shapes},
        "sensor": {"preset": "custom", "channels": 32, "vertical_fov_deg": [-8, 8], "horizontal_fov_deg": [-8, 8], "horizontal_resolution_deg": 0.5,
                   "position": [0, 0, 1.5], "max_range": 50},
        "effects": {"mirrors": {"label": "reflection"}},
    })
    build_scene(config.scene, frame_rng(0, 0))
    buffers = export_scene(load_class_table())
    points, pose = scan_buffers(buffers, config, frame_rng(0, 0))
    ghosts = points[points["bounces"] == 1]
    assert len(ghosts) > 500 and (ghosts["semantic"] == REFLECTION).all()
    mirror_row = buffers.objects.names.index("mirror")
    assert (ghosts["instance"] == buffers.objects.instance[mirror_row]).all()
    xyz = np.column_stack([ghosts["x"], ghosts["y"], ghosts["z"]]).astype(np.float64)  # sensor frame = world - (0, 0, 1.5)
    d = xyz / np.linalg.norm(xyz, axis=1, keepdims=True)
    path, true_hit = expected_ghost(d)
    assert np.abs(ghosts["range"] - path).max() < 1e-4
    assert np.abs(xyz - reflect(true_hit, M_CENTRE, M_NORMAL)).max() < 1e-3
