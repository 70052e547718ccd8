"""Packaging: the wheel is complete (class table, arm model, sensor presets inside), installs into a
fresh venv and runs a frame through the ``bpy-pipeline`` console command; ``python run.py`` outside
a set-up environment says in one line how to set up."""

import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    done = subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(out)], capture_output=True, text=True, timeout=300)
    if done.returncode:
        pytest.fail(f"pip wheel failed: {done.stderr[-2000:]}")
    (path,) = out.glob("bpy_pipeline-*.whl")
    return path


def test_wheel_holds_every_data_file_the_package_reads(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for data in ("assets_manifest/labels.yaml", "assets_manifest/robot_arm.yaml", "assets_manifest/assets.yaml", "bpy_pipeline/lidar/sensor/sensors.yaml"):
        assert data in names, f"{data} missing from {wheel.name}"
    source = {p.relative_to(ROOT).as_posix() for p in (ROOT / "bpy_pipeline").rglob("*.py")}
    assert source <= names, f"modules missing from the wheel: {sorted(source - names)[:5]}"
    entry = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("entry_points.txt"))).decode()
    assert "bpy-pipeline = bpy_pipeline.cli.commands:console" in entry
    metadata = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith("METADATA"))).decode()
    requires = [line for line in metadata.splitlines() if line.startswith("Requires-Dist:") and "extra ==" not in line]
    assert not any("trimesh" in line for line in requires), "trimesh is a test dependency, not a runtime one"


@pytest.mark.bpy
@pytest.mark.slow
def test_wheel_in_a_fresh_venv_runs_a_frame_with_the_console_command(wheel, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], capture_output=True, text=True,
                               check=True).stdout.strip())
    # The dependencies (bpy is 300 MB) come from this environment, appended after the venv's own
    # site-packages; only directories are added, so this environment's editable install of the
    # project is not (its finder is a .pth file, which a plain path line does not run).
    (site / "zz_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    done = subprocess.run([str(python), "-m", "pip", "install", "--no-deps", "--no-index", "-q", str(wheel)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    work = tmp_path / "elsewhere"  # not the repository: nothing may be found through the working directory
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    where = subprocess.run([str(python), "-c",
                            "import bpy_pipeline, bpy_pipeline.labels as l; print(bpy_pipeline.__file__); print(l.load_class_table().names[1])"], cwd=work,
                           env=env, capture_output=True, text=True)
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.split()[0]).is_relative_to(venv), where.stdout
    out = tmp_path / "out"
    command = [str(venv / "bin" / "bpy-pipeline"), "run", "--out", str(out), "--frames", "1",
               "--set", "scene.builder=primitives", "--set",
               "scene.shapes=[{type: box, size: 4, position: [6, 0, 0], class: wall}, {type: plane, size: 30, class: ground}]",
               "--set", "sensor.preset=vlp16", "--set", "sensor.position=[0, 0, 1.5]", "--set", "output.formats=[ply,semantickitti]"]
    result = subprocess.run(command, cwd=work, env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert (out / "ply" / "000000.ply").stat().st_size > 1000
    assert (out / "sequences" / "00" / "labels" / "000000.label").is_file()
    assert (out / "manifest.json").is_file()


def test_run_py_outside_the_venv_says_how_to_set_up(tmp_path):
    # A Python that cannot import the dependencies: isolated mode, no site-packages at all.
    result = subprocess.run([sys.executable, "-S", "-I", str(ROOT / "run.py"), "--frames", "1"], cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert "venv" in lines[0] and "pip install" in lines[0]
