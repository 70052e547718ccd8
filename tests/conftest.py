"""Shared fixtures: where the real scans are, and the bpy marker skip."""

import atexit
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

# Node groups kept between runs (bpy_pipeline/blender/group_cache.py) go to a folder of this test process (and the runs
# it starts), never the user's cache; removed at exit
if "BPY_PIPELINE_CACHE" not in os.environ:
    os.environ["BPY_PIPELINE_CACHE"] = tempfile.mkdtemp(prefix="bpy_pipeline_cache_")
    atexit.register(shutil.rmtree, os.environ["BPY_PIPELINE_CACHE"], True)

REAL_SCANS = Path(os.environ.get("BPY_PIPELINE_REAL_SCANS", Path(__file__).resolve().parents[2] / "shared" / "real_scans"))
HAS_BPY = importlib.util.find_spec("bpy") is not None


@pytest.fixture(scope="session")
def real_scans_folder() -> Path:
    """The folder of the real scans (it may be absent; tests skip with a reason then)."""
    return REAL_SCANS


@pytest.fixture(scope="module")
def real_samples(real_scans_folder):
    """The real nuScenes HDL-32E sweep (``fitting.read_scan``) and its drop samples; skips with a reason where it is absent."""
    from bpy_pipeline.lidar.fit import fitting

    path = real_scans_folder / "nuscenes_hdl32e_sweep.bin"
    if not path.exists():
        pytest.skip(f"real scan {path} is absent (set BPY_PIPELINE_REAL_SCANS to its folder)")
    scan = fitting.read_scan(path, 32)
    return scan, fitting.drop_samples(scan, fitting.scan_geometry(scan))


@pytest.fixture
def real_scan():
    """Path of a file in ../shared/real_scans; skips with a reason where it is absent."""

    def get(name: str) -> Path:
        path = REAL_SCANS / name
        if not path.exists():
            pytest.skip(f"real scan {path} is absent (set BPY_PIPELINE_REAL_SCANS to its folder)")
        return path

    return get


# ----------------------------------------------------------------------------- test lanes
# Two lanes (docs/layout.md, "Tests"):
#   .venv/bin/python -m pytest -q -m "not slow"                 between edits: under 3 minutes on 2 cores
#   .venv/bin/python -m pytest -q -n auto --dist loadgroup      the whole suite in parallel (README, .ci/run)
# SLOW: what the fast lane leaves out, named here so the lanes read in one place (a test may also carry
# @pytest.mark.slow itself). A file name means every test in it; "file::test" every parametrization of
# that test. In it: tests that start Blender sessions (run.py, an extension session, the golden jobs,
# a fresh venv), and tests over about 2 s on a quiet machine (pytest --durations=80).
SLOW = frozenset({
    "test_dataset.py",  # every test runs run.py: frame ranges, kill -9, workers, Ray
    "test_empty_file.py",  # three Blender sessions: the factory file emptied two ways
    "test_extension.py",  # builds the zip, installs it in a Blender session
    "test_extension_checkout.py",
    "test_io_kitti_camera.py",  # Workbench renders
    "test_loaders.py",  # its module fixtures generate datasets with run.py: parking, the hall twice, the street (about 60 s)
    "test_packaging.py",  # builds the wheel, installs it in a fresh venv
    "test_run.py",  # every test runs run.py
    "test_bad_input_matrix.py::test_sigterm_is_one_line_exit_143_lock_released_frames_kept",
    "test_bad_input_matrix.py::test_two_resumes_on_a_stale_lock_never_both_take_it",
    "test_evaluate.py::test_evaluate_command_end_to_end_on_a_generated_street",
    "test_evaluate.py::test_leave_one_group_out_never_trains_on_the_test_group",
    "test_evaluate.py::test_model_learns_the_toy_world_and_is_deterministic",
    "test_golden.py::test_frames_keep_their_bytes",
    "test_mixing_run.py::test_real_scan_frame_range_gives_the_full_runs_bytes",
    "test_mixing_run.py::test_real_scan_run_writes_a_mixed_frame",
    "test_population.py::test_bad_population_keys_exit_2_with_one_line_naming_the_key",
    "test_population.py::test_frame_k_after_k_minus_1_is_frame_k_alone",
    "test_population.py::test_placed_objects_never_cross_each_other_or_the_hall_and_stand_on_allowed_surfaces",
    "test_population.py::test_population_works_on_a_procedural_builder",
    "test_railway_clearance.py::test_overlaps_and_steady_arms_stay_clear",
    "test_railway_ground_truth.py::test_every_frame_gets_the_layout_its_points_show",
    "test_realism_profiles.py::test_realism_benchmark_runs_small_and_its_figures_hold",
    "test_rig.py::test_rig_sensors_draw_from_their_own_generators",
    "test_rig.py::test_skip_empty_records_skipped_frames_and_can_fill_the_requested_kept_frames",
    "test_rig.py::test_three_camera_rig_is_the_union_of_three_single_camera_runs_byte_for_byte",
    "test_splits.py::test_project_labels_keep_the_project_ids",
    "test_splits.py::test_written_splits_are_the_same_for_a_full_run_a_frame_range_and_two_workers",
    "test_street.py::test_exported_street_has_no_intersections_and_users_stand_on_their_ground",
    "test_street.py::test_field_of_view_aware_placement_puts_users_where_the_camera_sees_them",
    "test_street.py::test_same_seed_same_bytes_whatever_frame_a_run_starts_at",
    "test_weather.py::test_weather_frames_alone_and_over_workers_give_the_full_runs_bytes",
})
# GROUPS: files whose tests share something beyond their tmp_path; under --dist loadgroup one xdist worker
# runs each group, one test after another.
GROUPS = {
    "test_dataset.py": "dataset",  # the module's full run, kill -9 timings, `ray stop --force` (stops every local Ray)
    "test_extension.py": "extension",  # scripts/build_extension.py stages into the checkout's build/extension/
    "test_packaging.py": "wheel",  # pip wheel builds in the checkout's build/
    "test_loaders.py": "loaders",  # one generated dataset for the module (made once, not once per worker)
    "test_splits.py": "splits",  # likewise
}


def lane_marks(item) -> list:
    """The ``slow`` and ``xdist_group`` marks :data:`SLOW` and :data:`GROUPS` give ``item``."""
    file = item.path.name
    test = item.nodeid.split("::", 1)[-1].split("[", 1)[0]
    marks = [pytest.mark.slow] if file in SLOW or f"{file}::{test}" in SLOW else []
    if file in GROUPS:
        marks.append(pytest.mark.xdist_group(GROUPS[file]))
    return marks


@pytest.hookimpl(tryfirst=True)  # before -m deselects and before xdist reads the groups
def pytest_collection_modifyitems(config, items):
    for item in items:
        for mark in lane_marks(item):
            item.add_marker(mark)
    if HAS_BPY:
        return
    skip = pytest.mark.skip(reason="needs the bpy module (pip install 'bpy==4.5.*' on Python 3.11)")
    for item in items:
        if "bpy" in item.keywords:
            item.add_marker(skip)



@pytest.fixture
def killed_run_environment(tmp_path) -> dict:
    """This environment with ``TMPDIR`` inside the test's folder, for runs the test kills with SIGKILL: such a process
    cannot remove the folder the bpy module made for it (``blender_XXXXXX``), so it stays with the test's files."""
    temporary = tmp_path / "process_tmp"
    temporary.mkdir(exist_ok=True)
    return {**os.environ, "TMPDIR": str(temporary)}


@pytest.fixture
def bpy_scene():
    """An empty Blender scene (what a builder keeps across frames is owned by each run or call, never by a module)."""
    bpy = pytest.importorskip("bpy")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy


RENDER_PROBE = """
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.engine = "BLENDER_WORKBENCH"
scene.render.resolution_x = scene.render.resolution_y = 8
camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
scene.collection.objects.link(camera)
scene.camera = camera
bpy.ops.render.render()
"""


@pytest.fixture(scope="session")
def blender_renders() -> None:
    """Skip unless the bpy module can render (Workbench needs an OpenGL driver through EGL: without Mesa's
    libegl-mesa0 and libgl1-mesa-dri, which setup.sh installs, Blender aborts the whole process)."""
    pytest.importorskip("bpy")
    probe = subprocess.run([sys.executable, "-c", RENDER_PROBE], capture_output=True, text=True, timeout=120)
    if probe.returncode != 0:
        pytest.skip("the bpy module cannot render here (no OpenGL driver through EGL: install libegl1 libegl-mesa0 libgl1-mesa-dri)")
