"""The compiled diffuse path (lidar/cast/kernels.py) and the numpy path give the same bytes.

Every scene is scanned twice, once with ``kernel="numpy"`` and once with ``kernel="numba"``
(skipped, with the reason, where numba is not installed): shared and per-ray origins, a caster
whose frame is not the sensor's, a moving sensor, the range limits, an absorber, grazing rays,
rays aimed at the vertices of closed meshes (some slip and are traced again) and a sensor
inside a closed mesh. A scene with glass keeps the numpy path. The static-plus-moving caster of
:class:`CasterCache` gives the bytes of one caster of the whole scene.
"""

from types import SimpleNamespace
from unittest import mock

import numpy as np
import pytest

from bpy_pipeline.buffers import MATERIAL_ID, SceneBuffers
from bpy_pipeline.errors import InputError
from bpy_pipeline.geometry import primitives
from bpy_pipeline.geometry.transforms import pose_matrix
from bpy_pipeline.lidar.cast import raycast, scanner
from bpy_pipeline.compiled import numba_available
from bpy_pipeline.lidar.cast.raycast import CasterCache, RayCaster
from bpy_pipeline.lidar.cast.scanner import scan, scan_chunk
from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern
from bpy_pipeline.lidar.sensor.rays import Pattern

needs_numba = pytest.mark.skipif(not numba_available(), reason="numba is not installed (the 'fast' extra): only the numpy path exists here")


def room() -> SceneBuffers:
    """A closed box room seen from inside, a closed UV sphere and a box in it, an open wall seen from both sides, an absorber."""
    sphere = primitives.uv_sphere(0.8, 24)
    parts = {
        "room": primitives.box(30.0, 24.0, 8.0),
        "sphere": (sphere[0] + [4.0, 1.0, 0.5], sphere[1]),
        "crate": (primitives.box(1.0, 2.0, 1.5)[0] + [-3.0, -2.0, -1.0], primitives.box(1.0, 2.0, 1.5)[1]),
        "wall": (primitives.plane(3.0, 2.0)[0] @ pose_matrix([0, 0, 0], [90, 0, 30])[:3, :3].T + [1.0, -4.0, 0.0], primitives.plane(3.0, 2.0)[1]),
        "absorber": (primitives.box(0.5, 0.5, 0.5)[0] + [-2.0, 3.0, 0.0], primitives.box(0.5, 0.5, 0.5)[1]),
    }
    buffers = SceneBuffers.from_meshes(parts)
    buffers.objects.material[4] = MATERIAL_ID["absorber"]
    buffers.objects.semantic[:] = np.arange(1, 6, dtype=np.uint16) * 10
    buffers.objects.reflectivity[:] = np.float32([0.3, 0.9, 0.55, 0.71, 0.5])
    return buffers


def vertex_pattern(buffers: SceneBuffers, origin: np.ndarray) -> Pattern:
    """Rays from ``origin`` aimed exactly at every vertex (some slip between the triangles there), plus a spinning sensor's."""
    d = buffers.vertices - origin
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    spin = sensor_pattern(resolve_sensor({"preset": "custom", "channels": 32, "vertical_fov_deg": [-60, 60], "horizontal_resolution_deg": 1.0, "min_range": 0.0,
                                          "max_range": 100.0}))
    directions = np.concatenate([d, spin.directions])
    return Pattern(directions, np.arange(len(directions)).astype(np.uint16), np.linspace(0.0, 0.1, len(directions)))


def both(run):
    """``run(kernel)`` with the numpy path and with the compiled kernel, which calls Embree inside its
    pass and, where it cannot (scene handles unknown), runs after embreex: all three byte-identical."""
    reference = run("numpy")
    fused = run("numba")
    with mock.patch.object(raycast, "scene_handle", lambda scene: 0):
        after = run("numba")
    for a, b, c in zip(reference, fused, after):
        assert a.dtype == b.dtype == c.dtype and len(a) == len(b) == len(c)
        assert a.tobytes() == b.tobytes() == c.tobytes()
    return reference


@needs_numba
def test_the_compiled_pass_calls_embree_itself_where_it_can():
    from bpy_pipeline.lidar.cast import embree, kernels

    if not embree.shared_buffers_supported():
        pytest.skip("this embreex's objects do not have the checked layout: Embree's answer comes from embreex")
    assert kernels.compiled().traces
    caster = RayCaster(room(), frame=np.eye(4), kernel="numba")
    assert caster.embree_handles is not None and len(caster.embree_handles) == 1
    with mock.patch.object(raycast, "scene_handle", lambda scene: 0):
        assert RayCaster(room(), frame=np.eye(4), kernel="numba").embree_handles is None


@needs_numba
@pytest.mark.parametrize("case", ["sensor frame", "other frame", "per-ray origins", "moving sensor", "range limits"])
def test_the_kernel_gives_the_numpy_paths_bytes(case, monkeypatch):
    buffers = room()
    pose = pose_matrix([0.3, 0.2, 0.4], [3.0, -2.0, 20.0])
    pattern = vertex_pattern(buffers, pose[:3, 3])
    pattern = Pattern(pattern.directions @ pose[:3, :3], pattern.ring, pattern.time)  # sensor frame
    min_range, max_range = (2.0, 9.0) if case == "range limits" else (0.0, 100.0)
    frame = np.eye(4) if case == "other frame" else pose
    if case == "per-ray origins":
        rng = np.random.default_rng(2)
        pattern = Pattern(pattern.directions, pattern.ring, pattern.time, rng.uniform(-0.05, 0.05, (len(pattern), 3)))
    sensor = pose
    if case == "moving sensor":
        sensor = lambda t: np.stack([pose_matrix([0.3 + 2.0 * s, 0.2, 0.4], [3.0, -2.0, 20.0 + 30 * s]) for s in t])  # noqa: E731

    def run(kernel):
        caster = RayCaster(buffers, frame=frame, threads=2, chunk=700, kernel=kernel)
        if kernel == "numba":  # the compiled path must be the one taken
            monkeypatch.setattr(scanner, "trace_beams", lambda *a, **k: pytest.fail("numpy path taken"))
        out = scan(caster, buffers, pattern, sensor, min_range, max_range)
        monkeypatch.undo()
        return out

    points, beam = both(run)
    assert len(points) > 0.3 * len(pattern.directions)
    assert not np.isin(points["semantic"], [50]).any()  # the absorber returns nothing
    if case == "range limits":
        assert points["range"].min() >= 2.0 and points["range"].max() <= 9.0


@needs_numba
def test_slipped_and_enclosed_rays_are_traced_again_in_both_paths():
    """Rays at the vertices of the room from inside and of the sphere from outside: the re-trace runs, bytes agree."""
    buffers = room()
    caster = RayCaster(buffers, frame=np.eye(4), kernel="numpy")
    origin = np.array([0.3, 0.2, 0.4])
    pattern = vertex_pattern(buffers, origin)
    retraced = []
    original = RayCaster.retrace

    def counting(self, rays, *args):
        retraced.append(len(rays))
        return original(self, rays, *args)

    RayCaster.retrace = counting
    try:
        both(lambda kernel: scan_chunk(RayCaster(buffers, frame=pose_matrix(origin, [0, 0, 0]), kernel=kernel), buffers, pattern, np.eye(4), 0.0, 100.0))
    finally:
        RayCaster.retrace = original
    assert retraced and retraced[0] == retraced[-1] > 0  # the wall seen from both sides: the same suspects in both paths
    assert caster.kernels is None


@needs_numba
def test_grazing_rays_and_a_sensor_in_the_surface():
    buffers = SceneBuffers.from_meshes({"ground": primitives.plane(4000.0, 4000.0)})
    elevation = np.radians([-0.1, -0.05, -0.01, -1e-6, 0.0, 1e-6, 0.1])
    azimuth = np.radians(np.arange(0, 360, 15.0))
    e, a = (x.ravel() for x in np.meshgrid(elevation, azimuth, indexing="ij"))
    pattern = Pattern(np.column_stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)]), np.zeros(len(e), np.uint16), np.zeros(len(e)))
    for height in (1.5, 0.0):
        pose = pose_matrix([0, 0, height], [0, 0, 0])
        both(lambda kernel: scan(RayCaster(buffers, frame=pose, kernel=kernel), buffers, pattern, pose, 0.0, 1900.0))


@needs_numba
@pytest.mark.parametrize("ideal", [False, True])
def test_glass_and_mirrors_continue_in_the_numpy_path_with_the_same_bytes(ideal):
    """The crate is glass (some beams reflect, drawn from the generator), the wall a mirror: those rays go on in trace_beams."""
    from bpy_pipeline.lidar.cast.scanner import MirrorGlassRules

    buffers = room()
    buffers.objects.material[2] = MATERIAL_ID["glass"]
    buffers.objects.material[3] = MATERIAL_ID["mirror"]
    pose = pose_matrix([0.3, 0.2, 0.4], [3.0, -2.0, 20.0])
    pattern = vertex_pattern(buffers, pose[:3, 3])
    pattern = Pattern(pattern.directions @ pose[:3, :3], pattern.ring, pattern.time)
    surfaces = MirrorGlassRules(mirror_return_deg=2.0, glass_return_deg=5.0, glass_reflect=0.3, glass_passes=4)

    def run(kernel):
        caster = RayCaster(buffers, frame=pose, threads=2, chunk=700, kernel=kernel)
        return scan(caster, buffers, pattern, pose, 0.5, 100.0, max_bounces=2, ghost_semantic=99, ideal=ideal, surfaces=surfaces, rng=np.random.default_rng(4))

    points, _ = both(run)
    assert (points["bounces"] > 0).sum() > 50 and (points["semantic"] == 99).any()  # mirrored returns are in it


def test_a_bad_kernel_name_is_refused():
    buffers = room()
    with pytest.raises(InputError, match="scan kernel 'fast'"):
        RayCaster(buffers, frame=np.eye(4), kernel="fast")


def test_the_numpy_path_is_forced_by_the_environment(monkeypatch):
    monkeypatch.setenv("BPY_PIPELINE_SCAN_KERNEL", "numpy")
    assert RayCaster(room(), frame=np.eye(4)).kernels is None


def moved(buffers: SceneBuffers, rows, shift) -> SceneBuffers:
    """``buffers`` with the objects ``rows`` moved by ``shift`` (3,) metres."""
    vertices = buffers.vertices.copy()
    vertices[np.unique(buffers.triangles[np.isin(buffers.triangle_object, rows)])] += shift
    return SceneBuffers(vertices, buffers.triangles, buffers.triangle_object, buffers.objects)


@pytest.mark.parametrize("kernel", ["numpy", pytest.param("numba", marks=needs_numba)])
def test_a_kept_static_caster_with_a_moving_part_gives_one_casters_bytes(kernel):
    """Frame after frame, the sphere and the crate move; the room, the wall and the absorber are kept."""
    base = room()
    order = [0, 3, 4, 1, 2]  # the moving objects last: the static vertices stay in one span
    names = [base.objects.names[r] for r in order]
    meshes = {}
    for name, row in zip(names, order):
        t = base.triangles[base.triangle_object == row]
        used = np.unique(t)
        meshes[name] = (base.vertices[used], np.searchsorted(used, t))
    last = SceneBuffers.from_meshes(meshes)
    for field in ("material", "semantic", "reflectivity"):
        getattr(last.objects, field)[:] = getattr(base.objects, field)[order]
    pose = pose_matrix([0.3, 0.2, 0.4], [0, 0, 10])
    spec = resolve_sensor({"preset": "custom", "channels": 32, "vertical_fov_deg": [-60, 60], "horizontal_resolution_deg": 1.0, "min_range": 0.0,
                           "max_range": 100.0})
    pattern = sensor_pattern(spec)
    for buffers, moving, reused in ((last, np.array([False, False, False, True, True]), 2), (base, np.array([False, True, True, False, False]), 0)):
        cache = CasterCache(threads=2, kernel=kernel)
        for frame in range(3):
            scene = moved(buffers, np.flatnonzero(moving), [0.7 * frame, -0.3 * frame, 0.0])
            kept = scan(cache.caster(scene, pose, moving), scene, pattern, pose, 0.0, 100.0)
            whole = scan(RayCaster(scene, frame=pose, kernel=kernel), scene, pattern, pose, 0.0, 100.0)
            for a, b in zip(kept, whole):
                assert a.tobytes() == b.tobytes()
            assert len(kept[0]) > 0.9 * len(pattern)
        # moving objects between static ones change the static vertex span: built again each frame, same bytes
        assert (cache.builds, cache.reuses) == (3 - reused, reused)
    cache = CasterCache(threads=2, kernel=kernel)
    cache.caster(last, pose, moving=None)
    cache.caster(moved(last, [1], [0.0, 0.0, 0.01]), pose)  # a static object changed: built again
    cache.caster(moved(last, [1], [0.0, 0.0, 0.01]), pose, key="same")
    cache.caster(last, pose, key="same")  # the caller's key is trusted
    assert (cache.builds, cache.reuses) == (3, 1)
    with pytest.raises(InputError, match="moving must give each of the 5 object rows"):
        cache.caster(last, pose, np.zeros(2, bool))


def test_parts_finished_out_of_order_are_joined_in_firing_order():
    """InOrder: parts filled at their own rows, finishing in any order on any threads, end up one after another."""
    import time as clock
    from concurrent.futures import ThreadPoolExecutor

    from bpy_pipeline.lidar.points import POINT_DTYPE
    from bpy_pipeline.lidar.cast.scanner import InOrder

    rng = np.random.default_rng(8)
    chunk, parts = 1000, 9
    starts = list(range(0, chunk * parts, chunk))
    filled = rng.integers(0, chunk + 1, parts)
    filled[3] = 0
    filled[4] = chunk  # a part with no hits, a part all hits
    source = np.zeros(chunk * parts, POINT_DTYPE)
    source["range"] = rng.random(len(source), dtype=np.float32)
    source["ring"] = np.arange(len(source)) % 7
    expected = np.concatenate([source[s : s + f] for s, f in zip(starts, filled)])
    for order, threads in ((range(parts), 1), (reversed(range(parts)), 3), (rng.permutation(parts), 2)):
        points, ray = np.zeros(len(source), POINT_DTYPE), np.full(len(source), -1, np.int64)
        joined = InOrder((points, ray), starts)
        delay = {int(j): 0.002 * k for k, j in enumerate(order)}  # part j finishes after its delay

        def fill(j):
            s = slice(starts[j], starts[j] + filled[j])
            points[s], ray[s] = source[s], np.arange(s.start, s.stop)
            clock.sleep(delay[j])
            joined.finished(j, int(filled[j]))

        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(fill, range(parts)))
        total = joined.ends[-1]
        assert total == filled.sum() and points[:total].tobytes() == expected.tobytes()
        assert np.array_equal(ray[:total], np.concatenate([np.arange(s, s + f) for s, f in zip(starts, filled)]))


def test_records_spliced_in_firing_order_without_the_dropped_rays():
    """spliced: the rows of the re-traced rays leave, the re-traced and glass rays' rows come in, all in firing order (the
    sort of every row it replaces gives the same bytes); the first and last rays among them, none dropped, none added."""
    from bpy_pipeline.lidar.cast.raycast import RecordPool
    from bpy_pipeline.lidar.cast.scanner import spliced
    from bpy_pipeline.lidar.points import BEAM_DTYPE, POINT_DTYPE

    rng = np.random.default_rng(3)
    n = 5000
    ray = np.flatnonzero(rng.random(n) < 0.8)
    def noise(k, dtype):  # records of random bytes
        return np.frombuffer(rng.bytes(k * dtype.itemsize), dtype)

    records = (noise(len(ray), POINT_DTYPE), noise(len(ray), BEAM_DTYPE), ray)
    for case in ("both", "no drop", "nothing added", "ends"):
        drop = np.zeros(n, bool)
        if case != "no drop":
            drop[rng.choice(ray, 300, replace=False)] = True
        free = np.flatnonzero(~np.isin(np.arange(n), ray[~drop[ray]]))
        more = np.sort(rng.choice(free, 0 if case == "nothing added" else 400, replace=False))
        if case == "ends":
            drop[ray[0]] = True
            more = np.union1d(more, [ray[0], n - 1] if n - 1 in free else [ray[0]])
        extra = (noise(len(more), POINT_DTYPE), noise(len(more), BEAM_DTYPE), more)
        keep = ~drop[ray]
        order = np.argsort(np.concatenate([ray[keep], more]), kind="stable")
        expected = [np.concatenate([a[keep], e])[order] for a, e in zip(records, extra)]
        out = spliced(records, None if case == "no drop" else drop, extra, RecordPool())
        assert all(a.dtype == b.dtype and a.tobytes() == b.tobytes() for a, b in zip(out, expected)), case


def test_the_static_part_is_kept_only_for_the_same_bytes_and_a_far_vertex_is_refused_kept_or_built():
    """The kept static part is reused only for the same triangles and vertex bytes (a copy of them is kept, so a
    change made in place to the caller's buffers is seen); a caster that reuses the whole kept part skips its
    extent check only because the kept part passed it."""
    from bpy_pipeline.lidar.cast import raycast

    rng = np.random.default_rng(3)
    vertices = rng.normal(size=(200_000, 3))
    triangles = rng.integers(0, len(vertices), (60_000, 3)).astype(np.int32)
    big = SceneBuffers.from_meshes({"cloud": (vertices, triangles)})
    every = np.arange(len(triangles))
    same = SceneBuffers(big.vertices.copy(), big.triangles.copy(), big.triangle_object, big.objects)
    kept = raycast.static_geometry(big, every)
    assert raycast.same_geometry(kept, raycast.static_geometry(same, every))
    assert not raycast.same_geometry(kept, raycast.static_geometry(big, every[1:]))
    assert not raycast.same_geometry(kept, raycast.static_geometry(moved(big, [0], [0.0, 0.0, 1e-9]), every))
    signed = same.vertices.copy()
    signed[triangles.min(), 0] = 0.0  # a zero of the other sign: the same value, other bytes
    same.vertices[triangles.min(), 0] = -0.0
    assert not raycast.same_geometry(raycast.static_geometry(same, every),
                                     raycast.static_geometry(SceneBuffers(signed, big.triangles, big.triangle_object, big.objects), every))
    assert raycast.same_geometry(("key", 1), ("key", 1)) and not raycast.same_geometry(("key", 1), ("key", 2)) and not raycast.same_geometry(("key", 1), kept)

    changed = room()
    pose = pose_matrix([0.3, 0.2, 0.4], [0, 0, 10])
    cache = CasterCache(threads=2)
    cache.caster(changed, pose)
    changed.vertices[changed.triangles[changed.triangle_object == 1]] += 0.5  # in place, after the part was kept
    cache.caster(changed, pose)
    assert (cache.builds, cache.reuses) == (2, 0)
    base = room()
    pose = pose_matrix([0.3, 0.2, 0.4], [0, 0, 10])
    cache = CasterCache(threads=2)
    cache.caster(base, pose)
    assert cache.caster(base, pose).parts[0] is cache.kept.part  # the whole static part reused
    far = moved(base, [1], [0.0, 0.0, 2 * raycast.MAX_COORDINATE])
    with pytest.raises(InputError, match=f"object {base.objects.names[1]!r}: has vertices more than"):
        cache.caster(far, pose)  # its digest differs: built again, and checked
    moving = np.zeros(len(base.objects), bool)
    moving[1] = True
    with pytest.raises(InputError, match=f"object {base.objects.names[1]!r}: has vertices more than"):
        cache.caster(far, pose, moving)  # a far moving object beside the kept part


@needs_numba
def test_compiled_planes_have_numpys_bits():
    from bpy_pipeline.lidar.cast.kernels import compiled
    from bpy_pipeline.lidar.cast.raycast import triangle_planes

    rng = np.random.default_rng(5)
    vertices = rng.normal(size=(20000, 3)) * rng.choice([1e-3, 1.0, 1e4], (20000, 1))
    triangles = rng.integers(0, len(vertices), (50000, 3)).astype(np.int32)
    triangles[:50, 2] = triangles[:50, 0]  # zero-area triangles
    for a, b in zip(triangle_planes(vertices, triangles), triangle_planes(vertices, triangles, compiled())):
        assert a.tobytes() == b.tobytes()


def compiled_casters(threads: int) -> tuple[RayCaster, RayCaster]:
    """The room in one compiled caster whose pass calls Embree itself, and in a caster of a kept static part with the
    sphere and the crate moving (two Embree parts)."""
    base = room()
    pose = pose_matrix([0.3, 0.2, 0.4], [0, 0, 10])
    cache = CasterCache(threads=threads, kernel="numba")
    moving = np.array([False, True, True, False, False])
    cache.caster(base, pose, moving)
    two_parts = cache.caster(moved(base, [1, 2], [0.5, 0.0, 0.0]), pose, moving)
    assert len(two_parts.parts) == 2
    casters = RayCaster(base, frame=pose, kernel="numba"), two_parts
    for caster in casters:
        assert caster.kernels.traces and caster.embree_handles is not None  # the compiled pass, not embreex, answers
    return casters


def assert_embreexs_answer(caster: RayCaster, origins32, directions32, far) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`RayCaster._embree` through the compiled pass gives embreex's own ``(tfar, prim)``, byte for byte; returns embreex's."""
    got = [a.copy() for a in caster._embree(origins32, directions32, far)]
    with mock.patch.object(caster, "kernels", SimpleNamespace(**{**vars(caster.kernels), "traces": False})):
        expected = caster._embree(origins32, directions32, far)
    for a, b in zip(got, expected):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
    return expected


@needs_numba
def test_embrees_answer_from_the_compiled_pass_is_embreexs():
    """:meth:`RayCaster._embree` through :func:`~bpy_pipeline.lidar.cast.numba_kernels.trace_rays` gives embreex's ``(tfar, prim)``,
    byte for byte: one caster of the room and a kept static part with a moving one, rays from the origin (one row
    repeated by strides) and from their own origins, float32 and float64 directions, limits that cut some hits."""
    rng = np.random.default_rng(7)
    for caster in compiled_casters(threads=2):
        n = 5000
        directions = rng.normal(size=(n, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        for origins in (np.zeros(3), rng.uniform(-3.0, 3.0, (n, 3))):
            for d in (directions, directions.astype(np.float32)):
                _, origins32, directions32, far = caster.launch(origins, directions, 100.0, d if d.dtype == np.float32 else None, convert=False)
                far[::3] = rng.uniform(0.5, 12.0, len(far[::3])).astype(np.float32)
                expected = assert_embreexs_answer(caster, origins32, directions32, far)
                assert (expected[1] >= 0).mean() > 0.5 and (expected[1] < 0).any()


@needs_numba
def test_packets_of_rays_at_vertices_and_edges_get_embreexs_answer():
    """Eight rays a query (``rtcIntersect8``) give each ray the answer embreex's one-ray query gives, byte for byte, where
    ties are most likely: rays aimed exactly at every vertex and at the middle of every edge (two or more triangles at
    the same distance), in a sensor's order and shuffled (incoherent packets), a count that leaves the last packet part
    full, one caster and a kept static part with a moving one."""
    from bpy_pipeline.lidar.cast.numba_kernels import PACKET

    rng = np.random.default_rng(11)
    for caster in compiled_casters(threads=1):
        buffers = caster.buffers
        corners = buffers.vertices[buffers.triangles]  # (m, 3, 3) world
        targets = np.concatenate([buffers.vertices, (corners + np.roll(corners, 1, axis=1)).reshape(-1, 3) / 2])
        targets = targets[: len(targets) - (len(targets) % PACKET == 0)]
        local = caster.to_local(targets)
        directions = local / np.linalg.norm(local, axis=1, keepdims=True)
        assert len(directions) % PACKET
        for order in (np.arange(len(directions)), rng.permutation(len(directions))):
            _, origins32, directions32, far = caster.launch(np.zeros(3), directions[order], 100.0)
            expected = assert_embreexs_answer(caster, origins32, directions32, far)
            assert (expected[1] >= 0).mean() > 0.9
