"""The Blender extension: manifest, zip built by Blender's own tool, installed from the zip into a fresh
user folder, every operator run on small scenes (tests/extension_session.py), register / unregister cycles,
and configs that run the same from the panel and from run.py."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import platform
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

import bpy_pipeline
from bpy_pipeline import config as cfg
from bpy_pipeline.labels import load_class_table

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
SYSTEMS = {"Linux": "linux", "Darwin": "macos", "Windows": "windows"}
MACHINES = {"x86_64": "x64", "AMD64": "x64", "arm64": "arm64", "aarch64": "arm64"}
THIS_PLATFORM = f"{SYSTEMS.get(platform.system(), '?')}-{MACHINES.get(platform.machine(), '?')}"
MODULE = "bl_ext.user_default.lidar_pipeline"


def build_script():
    spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def frame_files(out: Path) -> dict[str, str]:
    return {
        str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(out.rglob("*"))
        if p.is_file() and p.name != "manifest.json" and p.parent.name != "records"
    }  # records hold timings


@pytest.fixture(scope="module")
def extension_zip(tmp_path_factory) -> Path:
    if THIS_PLATFORM not in MANIFEST["platforms"]:
        pytest.skip(f"the extension ships no wheels for {THIS_PLATFORM}")
    out = tmp_path_factory.mktemp("dist")
    result = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platform", THIS_PLATFORM, "--out", str(out)],
        capture_output=True, text=True, timeout=600,
    )
    if result.returncode != 0 and "cannot fetch" in result.stderr:
        pytest.skip(f"wheels not cached in wheels/ and the package index is unreachable: {result.stderr.strip()}")
    assert result.returncode == 0, result.stderr
    (path,) = [Path(line) for line in result.stdout.split()]
    return path


@pytest.fixture(scope="module")
def session(extension_zip, tmp_path_factory) -> tuple[dict, Path]:
    work = tmp_path_factory.mktemp("session")
    home = work / "home"
    env = dict(os.environ, HOME=str(home), BLENDER_USER_RESOURCES=str(home / "blender"))
    env.pop("BPY_PIPELINE_CACHE", None)  # the extension keeps its node groups in its own user folder
    result = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "extension_session.py"), str(extension_zip), str(work)],
        capture_output=True, text=True, timeout=600, env=env, cwd=work,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return json.loads((work / "report.json").read_text()), work


# ----------------------------------------------------------------------------- the manifest (no bpy needed)
def test_manifest_declares_the_extension():
    assert MANIFEST["schema_version"] == "1.0.0"
    assert MANIFEST["id"].isidentifier() and MANIFEST["name"] and 0 < len(MANIFEST["tagline"]) <= 64
    assert MANIFEST["version"] == bpy_pipeline.__version__
    assert MANIFEST["blender_version_min"] == "4.2.0"
    assert MANIFEST["license"] == ["SPDX:GPL-3.0-or-later"]
    assert MANIFEST["permissions"]["files"]
    assert MANIFEST["build"]["paths_exclude_pattern"]


def test_manifest_wheels_cover_every_platform_and_blender_python():
    build = build_script()
    names = [Path(w).name for w in MANIFEST["wheels"]]
    assert {build.wheel_tags(n)[0] for n in names} == {"embreex", "pyyaml"}  # numpy comes with Blender; nothing at run time needs trimesh
    assert build.missing_wheels(MANIFEST["wheels"], MANIFEST["platforms"]) == []
    # cp311: Blender 4.2 to 5.0; cp313: Blender 5.1 and newer, Debian 13's 4.3; cp314: distribution Blenders on Python 3.14
    assert {build.wheel_tags(n)[2] for n in names if build.wheel_platforms(n) != {"*"}} == {"cp311", "cp313", "cp314"}
    # platforms are exactly those the binary wheels exist for
    covered = set.intersection(*({p for n in names if build.wheel_tags(n)[0] == dist for p in build.wheel_platforms(n)} for dist in ("embreex", "pyyaml")))
    assert covered == set(MANIFEST["platforms"])
    assert build.missing_wheels(MANIFEST["wheels"], ["linux-arm64"]) != []


# ----------------------------------------------------------------------------- built and installed with Blender
@pytest.mark.bpy
def test_zip_is_validated_and_holds_only_what_runs(extension_zip):
    with zipfile.ZipFile(extension_zip) as archive:
        names = archive.namelist()
        manifest = tomllib.loads(archive.read("blender_manifest.toml").decode())
    package = {str(p.relative_to(ROOT)) for p in (ROOT / "bpy_pipeline").rglob("*") if p.suffix in (".py", ".yaml")}
    addon = {p.name for p in (ROOT / "addon").glob("*.py")}
    wheels = {n for n in names if n.startswith("wheels/")}
    assert "__init__.py" in names and "blender_manifest.toml" in names
    assets = {f"assets_manifest/{p.name}" for p in (ROOT / "assets_manifest").glob("*.yaml")}
    assert "assets_manifest/labels.yaml" in assets
    assert addon | package | assets | {"blender_manifest.toml"} | wheels == set(names)
    assert not any("__pycache__" in n or n.endswith(".pyc") or n.startswith(("tests/", "benchmarks/")) for n in names)
    assert manifest["platforms"] == [THIS_PLATFORM]
    assert sorted(wheels) == sorted(w.removeprefix("./") for w in manifest["wheels"])
    assert {Path(w).name.split("-")[2] for w in wheels} == {"cp311", "cp313", "cp314"}


@pytest.mark.bpy
def test_installs_from_the_zip_with_its_own_wheels(session):
    report, _ = session
    assert report["install"] == ["FINISHED"] and report["enabled"]
    assert report["bundled"] == {"embreex": "True", "yaml": "True"}
    assert {"__init__.py", "bpy_pipeline/config.py", "assets_manifest/labels.yaml"} <= set(report["extension_files"])
    operators = {"LIDAR_OT_build_scene", "LIDAR_OT_scan", "LIDAR_OT_show_cloud", "LIDAR_OT_generate", "LIDAR_OT_config_load", "LIDAR_OT_config_save",
                 "LIDAR_OT_config_reset", "LIDAR_OT_tag_selected", "LIDAR_OT_clear_tags"}
    assert operators <= set(report["classes"])
    sections = {"LIDAR_PT_run", "LIDAR_PT_scene", "LIDAR_PT_sensor", "LIDAR_PT_effects", "LIDAR_PT_output", "LIDAR_PT_legend", "LIDAR_PT_labels"}
    advanced = {"LIDAR_PT_scene_advanced", "LIDAR_PT_sensor_advanced", "LIDAR_PT_effects_advanced", "LIDAR_PT_output_advanced"}
    assert {c for c in report["classes"] if c.startswith("LIDAR_PT_")} == sections | advanced
    assert set(report["builders"]) == (set(cfg.BUILDER_PARAMS) - {"blend"}) | {"my_scene"}
    assert report["panels_drawn"] > 20  # every panel drew, naming only properties and operators that exist
    # every builder: the panel's defaults are the config's, and its parameters are drawn
    assert set(report["every_builder"]) == set(cfg.BUILDER_PARAMS) - {"blend"}
    needs_input = {name: built for name, (_, _, built) in report["every_builder"].items() if isinstance(built, str)}
    assert all(message.startswith("Error: scene.path:") for message in needs_input.values()), needs_input  # real_scan: a scan file
    assert all(same and (drawn > 10 or name in needs_input) and built for name,
               (same, drawn, built) in report["every_builder"].items()), report["every_builder"]
    assert {"Parking Level", "Industrial Hall", "Track", "Street Road"} <= set(report["kept_groups"])  # under the extension's user folder


@pytest.mark.bpy
def test_build_scan_and_show_cloud(session):
    report, work = session
    assert report["build_scene"] == ["FINISHED"] and report["scene_objects"] == ["box_1", "plane_0", "plane_2", "sphere_3"]
    assert report["scan"] == ["FINISHED"] and report["scan_points"] > 1000
    assert {"ply/000000.ply", "sequences/00/velodyne/000000.bin", "sequences/00/labels/000000.label", "preview/000000.png"} <= set(report["scan_files"])
    clouds = report["clouds"]
    direct = {n: c for n, c in clouds.items() if not n.startswith("LiDAR cloud ghosts ")}
    ghosts = {n: c for n, c in clouds.items() if n.startswith("LiDAR cloud ghosts ")}
    assert sum(c["points"] for c in clouds.values()) == report["scan_points"]
    assert all(c["bounces"] == [0] for c in direct.values())
    assert ghosts and all(min(c["bounces"]) >= 1 for c in ghosts.values())  # the mirror plane shows ghost points
    table = load_class_table()
    lut = table.color_lut().astype(float) / 255.0
    linear = np.where(lut <= 0.04045, lut / 12.92, ((lut + 0.055) / 1.055) ** 2.4)
    for name, c in direct.items():  # one object per class, named, coloured and with the material of its class
        (class_id,) = c["classes"]
        assert name == f"LiDAR cloud {table.names[class_id]}" and c["colors"] == 1
        assert np.allclose(c["object_color"][:3], linear[class_id], atol=1e-4)
        assert c["material"] == f"LiDAR class colour {class_id:02d} {table.names[class_id]}"
    assert {table.id_of(name) for name in ("ground", "wall", "person")} <= {c["classes"][0] for c in direct.values()}
    assert all(c["matrix_is_pose"] and c["drawn_as_points"] for c in clouds.values())
    assert report["show_cloud_from_disk"] == ["FINISHED"] and report["cloud_points_from_disk"] == report["scan_points"]
    assert report["bad_scan"].endswith("sensor.min_range: must be >= 0 and below sensor.max_range (0.5 >= 0.1)")


@pytest.mark.bpy
def test_panel_yaml_round_trip_and_run_py(session, tmp_path):
    """A config loaded into the panel and saved again is the same config, and panel and run.py write the same files."""
    report, work = session
    assert report["fresh_panel_is_default_config"]
    assert report["preset_brings_its_profile"] and report["preset_back_brings_default_effects"]
    assert report["panel_ideal_is_config_ideal"] and report["panel_ideal_keeps_what_the_user_set"] and report["panel_back_to_realistic"]
    assert report["load"] == ["FINISHED"] and report["loaded_equals_file"]
    assert report["save"] == ["FINISHED"] and report["saved_equals_file"] and report["resave_is_byte_identical"]
    assert report["generate"] == ["FINISHED"] and report["generate_manifest_frames"] == 2
    assert report["generate_invoke"] == ["FINISHED"] and report["generate_invoke_files"] == report["generate_files"]
    for config in ("job.yaml", "saved.yaml"):
        out = tmp_path / config
        result = subprocess.run([sys.executable, str(ROOT / "run.py"), "--config", str(work / config), "--out", str(out)], capture_output=True, text=True,
                                timeout=300)
        assert result.returncode == 0, result.stderr
        assert frame_files(out) == report["generate_files"]


@pytest.mark.bpy
def test_cancelled_generation_keeps_finished_frames(session):
    report, _ = session
    assert report["cancel"] == {"manifest_frames": [0, 1], "ply": ["000000.ply", "000001.ply"], "leftovers": [], "step_after_cancel": False}


@pytest.mark.bpy
def test_the_panel_shows_the_street_road_users_as_frames_go(session):
    """The panel's frames fill Blender's road users at every step, though the run itself would leave them to its end."""
    report, _ = session
    assert len(report["street_users_shown_per_step"]) == 3 and all(n > 0 for n in report["street_users_shown_per_step"])


@pytest.mark.bpy
def test_labels_and_sensor_pose_from_objects(session):
    report, _ = session
    assert report["tag"] == ["FINISHED"] and report["crate_tags"] == {"lidar_class": "car", "lidar_material": "glass", "lidar_reflectivity": 0.25}
    assert report["draw_with_tagged_active"] == ["label Crate: car (tag)"]
    assert report["clear"] == ["FINISHED"] and report["crate_keys_after_clear"] == []
    assert report["draw_with_untagged_active"] == ["label Garden wall: wall (name rules)"]
    for kind in ("EMPTY", "CAMERA"):
        errors = report["object_poses"][kind]
        assert errors["origin_error"] < 1e-5 and errors["forward_error"] < 1e-6 and errors["up_error"] < 1e-6, kind


@pytest.mark.bpy
def test_trajectory_curve_and_default_output_folder(session):
    report, _ = session
    assert report["default_output_in_user_folder"], report["default_output"]
    if not report["trajectory_offered"]:
        pytest.skip("this config has no sensor.trajectory")
    assert report["trajectory"] == {"curve": "track path", "speed": 5.0, "position_given": False}
    assert report["trajectory_drawn"] and report["trajectory_loaded"] == ["TRAJECTORY", "track path"]


@pytest.mark.bpy
def test_my_scene_is_scanned_as_it_is_and_saved_as_its_file(session):
    report, work = session
    assert report["mine_scan"] == ["FINISHED"] and report["mine_scene_untouched"]
    assert report["mine_objects"]["Garden wall"] == "wall"  # untagged: the name rules
    assert report["mine_objects"]["Crate"] == "unlabeled"  # tags cleared, no rule matches
    assert report["mine_yaml_scene"] == {"builder": "blend", "path": str(work / "mine.blend")}


@pytest.mark.bpy
def test_register_unregister_cycles_and_registration_errors(session):
    report, _ = session
    registered = len(report["classes"])
    assert report["cycles"] == [[0, False], [registered, True]] * 3
    assert report["after_cycles_scan"] == ["FINISHED"]
    assert report["registration_error"] == "ValueError"  # propagated, not swallowed
    assert report["after_failed_registration"] == [[], False]  # what was registered is unregistered again
    assert report["after_retry"] == [registered, True]
    assert report["reset"] == ["FINISHED"] and report["reset_is_default"]
    assert report["extension_dir_unchanged"]  # nothing written into the extension's own folder
