"""The speed round's shortcuts give the bytes of the long way: rays made once per run, the compiled
preview splat, digests taken while writing, the preview written on a thread, a single effects part
kept without a copy; and what keeps a run off cores it does not need: one BLAS thread, a worker's share of the
cores. No timings here (benchmarks/bench_speed.py measures)."""

import hashlib
import json
import os
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.buffers import SceneBuffers
from bpy_pipeline.config import load_config
from bpy_pipeline.frame import Frame, Run, frame_rng
from bpy_pipeline.geometry import primitives
from bpy_pipeline.io import preview
from bpy_pipeline.io.atomic import atomic_write, digests_while_writing, hashed_open
from bpy_pipeline.io.ply import write_ply
from bpy_pipeline.io.semantickitti import write_semantickitti
from bpy_pipeline.lidar.points import POINT_DTYPE
from bpy_pipeline.lidar.sensor.sensor_rays import CHUNK_RAYS, SensorRays
from bpy_pipeline.lidar.sensor.sensors import iter_pattern
from bpy_pipeline.stages.scan import collect_points, effects_stage, scan_stage
from bpy_pipeline.stages.scene import pose_stage


def cloud(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    points = np.zeros(n, POINT_DTYPE)
    for k in "xyz":
        points[k] = rng.normal(0, 10, n)
    points["semantic"], points["instance"], points["intensity"] = rng.integers(0, 5, n), rng.integers(0, 50, n), rng.random(n)
    return points


@pytest.mark.parametrize("preset", ["vlp16", "os1_128"])
def test_kept_rays_are_the_patterns_rays_every_frame_and_read_only(preset):
    config = load_config(None, [f"sensor.preset={preset}"])
    rays = SensorRays(config)
    for frame in (0, 3):
        kept = list(rays.patterns(frame))
        fresh = list(iter_pattern(config.sensor.spec, CHUNK_RAYS, frame))
        assert len(kept) == len(fresh)
        for a, b in zip(kept, fresh):
            for name in ("directions", "ring", "time"):
                assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
            assert not a.directions.flags.writeable
    assert rays.patterns(1)[0] is rays.patterns(2)[0]  # made once


def test_a_rosette_is_not_kept():
    config = load_config(None, ["sensor.preset=livox_mid40"])
    assert config.sensor.spec.pattern == "rosette"
    rays = SensorRays(config)
    first, later = list(rays.patterns(0)), list(rays.patterns(1))
    assert rays.kept is None
    assert first[0].directions.tobytes() != later[0].directions.tobytes()


def box_frames(config, rays: SensorRays | None, frames: int = 3) -> list[bytes]:
    """Frames of a sensor in a closed box through the scan stages; ``rays`` None: a fresh SensorRays every frame (no kept rays)."""
    buffers = SceneBuffers.from_meshes({"box": primitives.box(40.0, 40.0, 10.0)})
    run = Run(config, build=False, rays=rays)
    out = []
    for index in range(frames):
        if rays is None:
            run.rays = SensorRays(config)
        frame = Frame(index, config, frame_rng(config.seed, index), buffers=buffers)
        for stage in (pose_stage, scan_stage, effects_stage):
            stage(frame, run)
        out.append(frame.points.tobytes())
    return out


@pytest.mark.parametrize("kernel", ["numba", "numpy"])
def test_kept_rays_give_the_bytes_of_rays_made_every_frame(kernel, monkeypatch):
    if kernel == "numba":
        pytest.importorskip("numba")
    monkeypatch.setenv("BPY_PIPELINE_SCAN_KERNEL", kernel)
    config = load_config(None, ["sensor.preset=vlp16", "sensor.position=[0.2, -0.3, 0.1]"])
    kept = box_frames(config, SensorRays(config))
    fresh = box_frames(config, None)
    assert kept == fresh
    assert len(set(kept)) == 3  # the frames differ (their noise draws), so the comparison means something


def test_compiled_and_numpy_paths_give_the_same_box_bytes(monkeypatch):
    pytest.importorskip("numba")
    config = load_config(None, ["sensor.preset=os1_128", "sensor.position=[0.2, -0.3, 0.1]"])
    monkeypatch.setenv("BPY_PIPELINE_SCAN_KERNEL", "numba")
    compiled = box_frames(config, SensorRays(config), 2)
    monkeypatch.setenv("BPY_PIPELINE_SCAN_KERNEL", "numpy")
    assert box_frames(config, SensorRays(config), 2) == compiled


def test_compiled_splat_paints_the_pixels_of_the_numpy_splat(monkeypatch):
    if preview._splat_kernel() is None:
        pytest.skip("numba is not installed: only the numpy splat runs")
    rng = np.random.default_rng(1)
    n, h, w = 20000, 40, 60
    col, row = rng.integers(0, w, n), rng.integers(0, h, n)
    depth = rng.integers(0, 6, n).astype(np.float64)  # many equal depths on a pixel: the later point must win
    colors = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    images = []
    for kernel in (preview._splat_kernel(), None):
        monkeypatch.setattr(preview, "_splat_kernel", lambda kernel=kernel: kernel)
        image = np.zeros((h, w, 3), np.uint8)
        depth_image = np.full((h, w), -np.inf)
        depth_image[:5] = 3.0  # painted before: only points at least this deep go over it
        preview.splat(image, col[: n // 2], row[: n // 2], depth[: n // 2], colors[: n // 2], depth_image)
        preview.splat(image, col[n // 2 :], row[n // 2 :], depth[n // 2 :], colors[n // 2 :], depth_image)
        fresh = np.zeros((h, w, 3), np.uint8)
        preview.splat(fresh, col, row, depth, colors)
        images.append((image.tobytes(), depth_image.tobytes(), fresh.tobytes()))
    assert images[0] == images[1]
    points = cloud(5000)
    from bpy_pipeline.labels import load_class_table

    table = load_class_table()
    monkeypatch.setattr(preview, "_splat_kernel", lambda: None)
    slow = preview.render_preview(points, table.color_lut(), names=table.names)
    monkeypatch.undo()
    assert preview.render_preview(points, table.color_lut(), names=table.names).tobytes() == slow.tobytes()


def test_digests_taken_while_writing_are_the_files_sha256(tmp_path):
    from bpy_pipeline.labels import load_class_table

    points = cloud(3000)
    with digests_while_writing() as digests:
        files = [write_ply(tmp_path / "a.ply", points), *write_semantickitti(tmp_path, 0, 0, points),
                 preview.write_preview(tmp_path / "p.png", points, load_class_table().color_lut())]
    assert len(digests) == 4
    for path in files:
        assert digests[os.path.abspath(path)] == hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_a_file_written_past_the_hashing_handle_gets_no_digest(tmp_path):
    with digests_while_writing() as digests:
        with atomic_write(tmp_path / "x.bin") as tmp:
            with hashed_open(tmp) as f:
                f.write(b"abc")
            with open(tmp, "ab") as g:
                g.write(b"more")
        with atomic_write(tmp_path / "y.bin") as tmp:
            with hashed_open(tmp) as f:
                f.write(np.arange(5, dtype=np.int32))
    assert os.path.abspath(tmp_path / "x.bin") not in digests
    assert digests[os.path.abspath(tmp_path / "y.bin")] == hashlib.sha256(np.arange(5, dtype=np.int32).tobytes()).hexdigest()


@pytest.mark.parametrize("pooled", [True, False])
def test_frame_files_keep_the_writers_order_and_a_failure_beside_is_raised(tmp_path, monkeypatch, pooled):
    from concurrent.futures import ThreadPoolExecutor

    from bpy_pipeline.dataset import write_frame_files
    from bpy_pipeline.io import formats

    config = load_config(None, ["output.formats=[ply, semantickitti]"])
    pool = ThreadPoolExecutor(2, "beside") if pooled else None
    ran, preview, image = [], formats.write_frame_preview, formats.kitti.write_image  # where each beside part runs
    monkeypatch.setattr(formats, "write_frame_preview", lambda *a, **k: ran.append(threading.current_thread().name) or preview(*a, **k))
    monkeypatch.setattr(formats.kitti, "write_image", lambda *a, **k: ran.append(threading.current_thread().name) or image(*a, **k))
    frame = Frame(0, config, frame_rng(0, 0))
    frame.points = cloud(2000)
    written = write_frame_files(frame, tmp_path / "a", ["ply", "preview", "semantickitti", "kitti"], pool)
    names = [str(Path(p).relative_to(tmp_path / "a")) for p in written]
    assert names == ["ply/000000.ply", "preview/000000.png", "sequences/00/velodyne/000000.bin", "sequences/00/labels/000000.label",
                     "kitti/training/velodyne/000000.bin", "kitti/training/label_2/000000.txt", "kitti/training/calib/000000.txt",
                     "kitti/training/planes/000000.txt",
                     "kitti/training/image_2/000000.png"]
    assert all(name.startswith("beside") for name in ran) if pooled else ran == [threading.current_thread().name] * 2
    assert len(ran) == 2
    alone = write_frame_files(frame, tmp_path / "c", ["kitti"], pool)  # one writer: its image after its text, here
    assert [str(Path(p).relative_to(tmp_path / "c")) for p in alone] == names[4:] and ran[2] == threading.current_thread().name

    def broken(*args, **kwargs):
        raise ValueError("preview broke")

    monkeypatch.setattr(formats, "write_frame_preview", broken)
    with pytest.raises(ValueError, match="preview broke"):
        write_frame_files(frame, tmp_path / "b", ["ply", "preview"], pool)
    monkeypatch.setattr(formats.kitti, "render_image", lambda *a, **k: (_ for _ in ()).throw(ValueError("image broke")))
    with pytest.raises(ValueError, match="image broke"):
        write_frame_files(frame, tmp_path / "d", ["ply", "kitti"], pool)
    if pool is not None:
        pool.shutdown()


@pytest.mark.parametrize("threads", [2, 1])
def test_a_run_starts_its_beside_writers_once_and_stops_them(tmp_path, monkeypatch, threads):
    """With a thread to spare, the frames' previews and KITTI images are made on the dataset's own threads, the same
    ones every frame (none started per frame), which are gone when the run ends; with one thread, on the run's own."""
    from bpy_pipeline import plan
    from bpy_pipeline.io import formats

    config = load_config(None, ["sensor.preset=vlp16", "output.formats=[ply]", "output.boxes.formats=[kitti]", "frames=3", f"threads={threads}"])
    ran, preview, image = [], formats.write_frame_preview, formats.kitti.write_image
    monkeypatch.setattr(formats, "write_frame_preview", lambda *a, **k: ran.append(threading.current_thread()) or preview(*a, **k))
    monkeypatch.setattr(formats.kitti, "write_image", lambda *a, **k: ran.append(threading.current_thread()) or image(*a, **k))
    assert len(list(plan.run_frames(config, tmp_path / "out"))) == 3
    assert len(ran) == 6
    if threads > 1:
        assert len(set(ran)) <= 2 and all(t.name.startswith("beside writer") and not t.is_alive() for t in ran)
    else:
        assert set(ran) == {threading.current_thread()}


def test_a_single_effects_part_is_kept_and_several_are_joined():
    part = cloud(100)
    assert collect_points(iter([part]), 100) is part
    parts = [cloud(50, 1), cloud(70, 2)]
    assert collect_points(iter(parts), 10).tobytes() == np.concatenate(parts).tobytes()
    assert len(collect_points(iter([]), 10)) == 0


BLAS_THREADS = (
    "import {first}, threadpoolctl; "
    "print([i['num_threads'] for i in threadpoolctl.threadpool_info() if i['internal_api'] == 'openblas'])"
)


def blas_threads(first: str, **env) -> list[int]:
    """The OpenBLAS thread counts a fresh Python reports after importing ``first`` (then numpy), with ``env``."""
    import subprocess
    import sys

    base = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    done = subprocess.run([sys.executable, "-c", BLAS_THREADS.format(first=first + ", numpy")], env={**base, **env}, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(os.cpu_count() < 2, reason="OpenBLAS runs one thread on one core anyway")
def test_the_package_runs_one_blas_thread_unless_the_user_sets_a_count():
    """numpy's idle OpenBLAS threads spin on the core the scan needs (bpy_pipeline/__init__.py); a user's own
    OPENBLAS_NUM_THREADS stays as it is."""
    pytest.importorskip("threadpoolctl")
    alone = blas_threads("os")
    if not alone:
        pytest.skip("this numpy is not built on OpenBLAS")
    assert alone != [1]  # numpy alone: a thread a core
    assert blas_threads("bpy_pipeline") == [1]
    assert blas_threads("bpy_pipeline", OPENBLAS_NUM_THREADS="2") == blas_threads("os", OPENBLAS_NUM_THREADS="2") == [2]


HUGEPAGE = (
    "import {first}, numpy; "
    "core = numpy._core if int(numpy.__version__.split('.')[0]) >= 2 else numpy.core; "
    "get = getattr(core.multiarray, '_get_madvise_hugepage', None); "
    "print(-1 if get is None else int(get()))"
)


def madvise_hugepage(first: str, **env) -> int:
    """Whether numpy marks large arrays MADV_HUGEPAGE (1 or 0) in a fresh Python that imports ``first`` first, with
    ``env``; -1 for a numpy that cannot say (before 1.23)."""
    import subprocess

    base = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    done = subprocess.run([sys.executable, "-c", HUGEPAGE.format(first=first)], env={**base, **env}, capture_output=True, text=True, check=True)
    return int(done.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="numpy asks for huge pages on Linux only")
def test_the_package_turns_numpys_huge_page_advice_off_unless_the_user_sets_it():
    """A fault in memory numpy marked MADV_HUGEPAGE may wait for the kernel's compaction (bpy_pipeline/__init__.py);
    a user's own NUMPY_MADVISE_HUGEPAGE stays as it is."""
    alone = madvise_hugepage("os")
    if alone < 0:
        pytest.skip("this numpy cannot say whether it asks for huge pages (numpy._core.multiarray._get_madvise_hugepage: numpy 1.23 and later)")
    if not alone:
        pytest.skip("this numpy or kernel never asks for huge pages")
    assert madvise_hugepage("bpy_pipeline") == 0
    assert madvise_hugepage("bpy_pipeline", NUMPY_MADVISE_HUGEPAGE="1") == 1


def test_a_worker_joins_the_run_on_its_share_of_the_cores(tmp_path):
    """``--workers N`` hands each worker ``--threads`` (its share of the cores); a joining worker reads the run's
    config from the manifest and must keep that share, or every worker casts rays and writes previews on every core."""
    import argparse

    from bpy_pipeline.cli import load_run_config
    from bpy_pipeline.dataset import Dataset

    config = load_config(None, ["frames=4"])
    with Dataset.open(tmp_path / "run", config, "new"):
        pass
    joining = argparse.Namespace(join=True, out=str(tmp_path / "run"), threads=1)
    assert load_run_config(joining).threads == 1
    assert load_run_config(argparse.Namespace(join=True, out=str(tmp_path / "run"), threads=None)).threads == config.threads == 0


def test_the_parent_of_workers_starts_no_blender_of_its_own(tmp_path):
    """``--workers N``'s own process opens the run (its manifest names the Blender) and starts the workers' commands
    without importing bpy: that would start a Blender in it (0.3-0.5 s of a core) before the first worker starts."""
    import subprocess
    from importlib import metadata

    program = (
        "import sys, json\n"
        "from bpy_pipeline.config import load_config\n"
        "from bpy_pipeline.dataset import Dataset\n"
        "from bpy_pipeline.parallel import worker_command\n"
        f"out = {str(tmp_path / 'run')!r}\n"
        "with Dataset.open(out, load_config(None, ['frames=4']), 'new'):\n"
        "    command = worker_command(out, [0, 1], 1)\n"
        "print(json.dumps({'bpy': 'bpy' in sys.modules, 'command': command}))\n"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[1])
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout)
    assert not seen["bpy"]
    assert seen["command"][:4] == [sys.executable, "-m", "bpy_pipeline", "run"]
    manifest = json.loads((tmp_path / "run" / "manifest.json").read_text())
    assert manifest["versions"]["blender"] == metadata.version("bpy")


def test_inside_blender_workers_are_blenders_and_the_manifest_names_its_version(monkeypatch):
    import types

    from bpy_pipeline.frame import versions
    from bpy_pipeline.parallel import worker_command

    blender = types.SimpleNamespace(app=types.SimpleNamespace(binary_path="/opt/blender-4.5/blender", version=(4, 5, 15)))
    monkeypatch.setitem(sys.modules, "bpy", blender)
    command = worker_command("out", [3, 4, 5], 2)
    assert command[:6] == ["/opt/blender-4.5/blender", "--background", "--factory-startup", "--python-exit-code", "1", "--python"]
    assert command[command.index("--") + 1 :] == ["--out", "out", "--join", "--frames-range", "3:6", "--threads", "2", "--parent-pipe"]
    assert versions()["blender"] == "4.5.15"
