"""The car bodies (geometry/objects.py BODIES): at least 20, distinct, drawn from the seed; the classic three unchanged."""

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.geometry import objects
from bpy_pipeline.geometry.checks import check_mesh
from bpy_pipeline.geometry.objects import BODIES, CAR_BODY_SETS, STYLES, body_size, car_object, car_parts, draw_body, style_size

# sha256 of the classic styles' meshes (vertices then triangles of body, windows, interior, tyres): the parking
# builder's cars and its golden frames depend on them (recorded with OpenBLAS's Haswell kernels: see the test below).
# The vertices are those made before the body set existed (commit 39f308d); the triangles are wound outwards
# (hood, trunk and the +y side glass were inside out: test_every_part_is_wound_outwards).
CLASSIC = {
    "sedan": "2f4bf26fbd82ed494aa44c3c9c4519c62a48dbbcf2d082e8efd845280de12e1a",
    "hatchback": "3d466ac7e502eb510013df835c318275bde19e15fea86c83990c99f2cd493071",
    "estate": "1ede39b7aa87fb46637441b15e35482c93617b595fc4aaac5964a95f66610778",
}


def digest(parts: dict) -> str:
    return hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for v, t in parts.values() for a in (v, t))).hexdigest()


def test_at_least_twenty_bodies_of_six_kinds_each_distinct():
    assert len(BODIES) >= 20 and BODIES[:3] == STYLES
    kinds = {b.kind or b.name for b in BODIES}
    assert {"sedan", "hatchback", "estate", "suv", "pickup", "van"} <= kinds
    sizes = np.array([style_size(b, b.height) for b in BODIES])
    assert len({tuple(np.round(s, 3)) for s in sizes}) == len(BODIES)  # no two bodies share length, width and height
    shapes = {digest(car_parts(b, b.height)) for b in BODIES}
    assert len(shapes) == len(BODIES)
    # dimensions of passenger cars, SUVs, pickups and vans (docs/mixing.md compares them with published sizes)
    assert 3.5 <= sizes[:, 0].min() and sizes[:, 0].max() <= 6.3
    assert 1.6 <= sizes[:, 1].min() and sizes[:, 1].max() <= 2.1
    assert 1.4 <= sizes[:, 2].min() and sizes[:, 2].max() <= 2.05


@pytest.mark.parametrize("body", BODIES, ids=[b.name for b in BODIES])
def test_every_body_is_a_valid_car_in_its_box_with_glass(body):
    parts = car_parts(body, body.height)
    assert list(parts) == list(objects.PARTS)
    size = style_size(body, body.height)
    for name, (v, t) in parts.items():
        check_mesh(v, t, name)
        assert len(t) > 0
        assert (v.min(axis=0) >= [-size[0] / 2, -size[1] / 2 - 0.01,
                                  -1e-9]).all() and (v.max(axis=0) <= [size[0] / 2, size[1] / 2 + 0.01, size[2] + 1e-9]).all()
    made = car_object(np.random.default_rng(0), None, "all", BODIES.index(body))
    assert [p.material for p in made] == ["diffuse", "glass", "diffuse", "diffuse"]
    v = np.concatenate([p.vertices for p in made])
    np.testing.assert_allclose(v.max(axis=0) - v.min(axis=0), size, atol=1e-9)


def _pieces(triangles: np.ndarray) -> list[np.ndarray]:
    """The triangles of each connected piece (pieces share no vertex), as ``(m, 3)`` index arrays."""
    label = np.arange(int(triangles.max()) + 1)
    for _ in range(len(label)):  # join each triangle's corners until nothing changes
        before = label.copy()
        low = label[triangles].min(axis=1)
        for k in range(3):
            np.minimum.at(label, triangles[:, k], low)
        label = label[label]
        if np.array_equal(label, before):
            break
    piece = label[triangles[:, 0]]
    return [triangles[piece == p] for p in np.unique(piece)]


@pytest.mark.parametrize("body", BODIES, ids=[b.name for b in BODIES])
def test_every_part_is_wound_outwards(body):
    """Every closed piece of a car (the body's prisms, boxes and beams, the seats, the tyres) is wound consistently with
    its normals outwards, and each pane of glass faces out of the car. An inside-out piece is seen by every ray from its
    back faces: the scanner then takes each such ray for one that slipped between triangles and traces it again."""
    for name, (v, t) in car_parts(body, body.height).items():
        for piece in _pieces(np.asarray(t)):
            directed = piece[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
            assert len(np.unique(directed, axis=0)) == len(directed), f"{body.name} {name}: a piece wound both ways"
            p = v[piece]
            normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
            if name == "windows":  # a pane: its normal away from the middle of the car
                assert np.dot(normal.sum(axis=0), p.mean(axis=(0, 1)) - [0.0, 0.0, body.height / 2]) > 0, f"{body.name}: a pane faces into the car"
            else:
                volume = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6
                assert volume > 0, f"{body.name} {name}: a piece is inside out"


def test_a_prism_is_wound_outwards():
    from bpy_pipeline.geometry import primitives
    from bpy_pipeline.lidar.cast.raycast import closed_surface

    v, t = primitives.prism(np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.5, 1.5]]), -1.0, 3.0)
    p = v[t]
    assert closed_surface(t)
    assert np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6 > 0


def test_pickups_have_an_open_bed_and_the_others_a_closed_rear():
    # a ray straight down into the middle of the rear section meets the bed floor of a pickup well below its walls
    for body in BODIES:
        v, t = car_parts(body, body.height)["body"]
        L, H = body.length_ratio * body.height, body.height
        x = (-L / 2 + body.rear_base * L) / 2  # middle of the rear section
        tri = v[t]
        # the highest body surface above (x, 0)
        top = -1.0
        for a, b, c in tri:
            m = np.array([[b[0] - a[0], c[0] - a[0]], [b[1] - a[1], c[1] - a[1]]])
            if abs(np.linalg.det(m)) < 1e-12:
                continue
            u, w = np.linalg.solve(m, [x - a[0], -a[1]])
            if u >= 0 and w >= 0 and u + w <= 1:
                top = max(top, a[2] + u * (b[2] - a[2]) + w * (c[2] - a[2]))
        if body.bed:
            assert top < body.deck * H - 0.1  # the floor, below the bed walls
        else:
            assert top >= body.deck * H - 0.2 * H  # the trunk lid or the rear roof


def test_bodies_are_drawn_from_the_seed():
    draws = [draw_body(np.random.default_rng(seed)) for seed in range(200)]
    assert draws == [draw_body(np.random.default_rng(seed)) for seed in range(200)]
    assert len(set(draws)) == len(BODIES)  # 200 draws reach every body
    a = car_object(np.random.default_rng(5), None, "all")
    b = car_object(np.random.default_rng(5), None, "all")
    assert all(np.array_equal(p.vertices, q.vertices) and p.reflectivity == q.reflectivity for p, q in zip(a, b))
    np.testing.assert_allclose(body_size(3), style_size(BODIES[3], BODIES[3].height))
    assert set(CAR_BODY_SETS) == {"all", "classic"} and CAR_BODY_SETS["classic"] == STYLES


def test_the_classic_styles_keep_their_bytes():
    """The digests hold for the matrix products of OpenBLAS's Haswell kernels (AVX2 and FMA; Zen's give the same bits).
    A product's last bit depends on the kernel OpenBLAS picks for the CPU, and its SkylakeX kernels, on a CPU with
    AVX-512, round a sedan's beams apart. So the meshes are made in a process that asks for the Haswell kernels."""
    cpu = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    if not {"avx2", "fma"} <= set(cpu.split()):
        pytest.skip("the digests are of OpenBLAS's Haswell kernels, which need a CPU with AVX2 and FMA")
    code = ("import json, sys\n"
            f"sys.path.insert(0, {str(Path(__file__).parent)!r})\n"
            "from test_car_bodies import STYLES, car_parts, digest\n"
            "print(json.dumps({s.name: digest(car_parts(s)) for s in STYLES}))")
    made = subprocess.run([sys.executable, "-c", code], env={**os.environ, "OPENBLAS_CORETYPE": "Haswell"}, capture_output=True, text=True, check=True)
    assert json.loads(made.stdout) == CLASSIC


def test_the_classic_draw_is_unchanged():
    # car_object's default is the classic set, drawn as before the body set (one draw of the style, one of the paint)
    rng = np.random.default_rng(11)
    style = STYLES[int(rng.integers(len(STYLES)))]
    made = car_object(np.random.default_rng(11), (4.5, 1.8, 1.6))
    v = np.concatenate([p.vertices for p in made])
    np.testing.assert_allclose(v.max(axis=0) - v.min(axis=0), (4.5, 1.8, 1.6), atol=1e-9)
    ref = car_parts(style)
    assert len(made[0].triangles) == len(ref["body"][1])
