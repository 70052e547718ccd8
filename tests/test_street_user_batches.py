"""The street's road users made together (a frame's people posed and meshed at once, every vehicle's boxes in one
call, each vehicle's parts turned in one product) give the bytes of one user at a time; every part of them but the glass
is a closed surface (the scanner's slip check looks at closed objects only)."""

import dataclasses

import numpy as np
import pytest

from bpy_pipeline.builders.street import layout as street
from bpy_pipeline.builders.street.params import StreetScene
from bpy_pipeline.geometry import human, primitives, vehicles
from bpy_pipeline.geometry.placement import Distribution


def _same(x, y) -> bool:
    x, y = np.asarray(x), np.asarray(y)
    return x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()


def _people(rng, n):
    poses = [str(rng.choice(["walking", "standing", "sitting", "crouching"])) for _ in range(n)]
    builds = [float(rng.choice(list(human.BUILDS.values()))) for _ in range(n)]
    angles = [human.sample_pose(pose, rng, build) for pose, build in zip(poses, builds)]
    heights = list(rng.uniform(1.5, 1.95, n))
    xy = list(rng.uniform(-30, 30, (n, 2)))
    yaws = list(rng.uniform(-4, 4, n))
    support = list(rng.uniform(0, 0.2, n))
    return angles, heights, builds, poses, xy, yaws, support


def test_pose_people_and_body_meshes_are_pose_person_and_body_mesh_bit_for_bit():
    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 13):
        args = _people(rng, n)
        together = human.pose_people(*args)
        meshes = human.body_meshes(together, 8, 2)
        for i, person in enumerate(together):
            alone = human.pose_person(*(column[i] for column in args))
            for field in ("angles", "placement", "frames", "a", "b", "radius", "support"):
                assert _same(getattr(person, field), getattr(alone, field)), (n, i, field)
            assert (person.height, person.build, person.pose) == (alone.height, alone.build, alone.pose)
            v, t, _ = human.body_mesh(alone.a, alone.b, alone.radius, 8, 2)
            assert _same(meshes[i][0], v) and _same(meshes[i][1], t), (n, i)
    assert human.pose_people([], [], [], [], [], [], []) == [] and human.body_meshes([]) == []


@pytest.mark.parametrize("fittings", [True, False])
def test_vehicles_parts_are_vehicle_parts_and_fittings_bit_for_bit(fittings):
    rng = np.random.default_rng(4)
    kinds = [str(k) for k in rng.choice(street.VEHICLES, 40)]
    sizes = [np.array(street.NOMINAL_SIZE[k]) * (1.0 + rng.uniform(-0.1, 0.1, 3)) for k in kinds]
    together = vehicles.vehicles_parts(kinds, sizes, fittings)
    for kind, size, parts in zip(kinds, sizes, together):
        alone = vehicles.vehicle_parts(kind, size)
        if fittings:
            alone |= vehicles.vehicle_fittings(alone["body"][0], size[0])
        assert list(parts) == list(alone)
        for name in alone:
            assert _same(parts[name][0], alone[name][0]) and _same(parts[name][1], alone[name][1]), (kind, name)
    assert vehicles.vehicles_parts([], [], fittings) == []


def test_transformed_parts_are_transformed_bit_for_bit():
    rng = np.random.default_rng(5)
    for _ in range(50):
        meshes = [(rng.uniform(-5, 5, (int(rng.integers(1, 120)), 3)), np.zeros((1, 3), np.int32)) for _ in range(int(rng.integers(1, 6)))]
        centre, yaw, z = rng.uniform(-40, 40, 2), float(rng.uniform(-4, 4)), float(rng.uniform(0, 0.2))
        for (v, t), mesh in zip(primitives.transformed_parts(meshes, centre, yaw, z), meshes):
            one = primitives.transformed(mesh, centre, yaw, z)
            assert _same(v, one[0]) and t is mesh[1]


def test_a_frames_users_meshed_together_are_each_user_meshed_alone():
    params = dataclasses.replace(StreetScene(), bicycles=Distribution("normal", 3.0, 0.0, 0.0, 20.0),
                                 motorcycles=Distribution("normal", 2.0, 0.0, 0.0, 20.0))
    layout = street.street_layout(params, np.random.default_rng(params.layout_seed))
    for seed in (1, 2):
        users = street.place_users(params, layout, np.random.default_rng(seed)).users
        assert {u.kind for u in users} >= {"person", "car", "bicycle", "motorcycle"}
        first, second = np.random.default_rng([seed, 9]), np.random.default_rng([seed, 9])
        together = street.users_meshes(users, first, params.car_fittings)
        alone = [street.user_meshes(user, second, params.car_fittings) for user in users]
        assert first.bit_generator.state == second.bit_generator.state
        for a, b in zip(together, alone):
            assert [p[:4] for p in a] == [p[:4] for p in b]
            assert all(_same(x[4][0], y[4][0]) and _same(x[4][1], y[4][1]) for x, y in zip(a, b))


def test_every_road_user_part_but_the_glass_is_closed():
    """The scanner takes a back face of a closed object also seen from the front for a ray that slipped between its
    triangles, and traces it again; an open object is not looked at (``RayCaster.suspects``). So every part of the
    street's vehicles but their glass, every two-wheeler's part and every person's body must be a closed surface, or a
    slip into it goes unseen."""
    from bpy_pipeline.lidar.cast.raycast import closed_surface

    rng = np.random.default_rng(4)
    kinds = [kind for kind in street.VEHICLES for _ in range(6)]
    for fittings in (True, False):
        for kind, parts in zip(kinds, vehicles.vehicles_parts(kinds, [street._draw_size(kind, rng) for kind in kinds], fittings)):
            for name, (v, t) in parts.items():
                if len(t) and name != "glass":
                    assert closed_surface(np.asarray(t)), f"{kind} {name}"
    for kind in street.TWO_WHEELERS:
        for name, (v, t) in vehicles.two_wheeler_parts(kind, street._draw_size(kind, rng)).items():
            assert closed_surface(np.asarray(t)), f"{kind} {name}"
    poses = ["walking", "standing", "sitting"] * 2
    angles = [human.sample_pose(pose, rng) for pose in poses]
    people = human.pose_people(angles, np.full(len(poses), 1.75), np.ones(len(poses)), poses, np.zeros((len(poses), 2)), np.zeros(len(poses)),
                               np.zeros(len(poses)))
    for v, t in human.body_meshes(people, 8, 2):
        assert closed_surface(np.asarray(t))
