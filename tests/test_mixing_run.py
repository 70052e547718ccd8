"""``python run.py --set scene.builder=real_scan --set scene.path=...`` end to end: files on disk, labels, boxes, bad input."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OBJECTS = "[{type: car, center: [8, 4, -0.9], size: [4.5, 1.9, 1.6], yaw_deg: 0}, {type: person, center: [6, -2, -1.0]}]"


def run(*args):
    return subprocess.run([sys.executable, str(ROOT / "run.py"), *args], capture_output=True, text=True, timeout=300)


def test_real_scan_run_writes_a_mixed_frame(real_scan, tmp_path):
    sweep = real_scan("nuscenes_hdl32e_sweep.bin")
    out = tmp_path / "run"
    done = run("--out", str(out), "--set", "scene.builder=real_scan", "--set", f"scene.path={sweep}", "--set", f"scene.objects={OBJECTS}", "--set",
               "effects.ideal=true", "--set", "output.preview=false")
    assert done.returncode == 0, done.stderr
    xyzi = np.fromfile(out / "sequences/00/velodyne/000000.bin", np.float32).reshape(-1, 4)  # frame 0: the first train unit
    label = np.fromfile(out / "sequences/00/labels/000000.label", np.uint32)
    assert len(xyzi) == len(label) and 28000 < len(label) <= 34688  # at most one return per firing
    semantic, instance = label & 0xFFFF, label >> 16
    car, person = 10, 30  # SemanticKITTI's raw ids (assets_manifest/labels.yaml semantickitti:)
    assert (semantic == car).sum() > 100 and (semantic == person).sum() > 20
    assert set(np.unique(instance[semantic == car])) == {1} and set(np.unique(instance[semantic == person])) == {2}
    # the car's points sit in its box, in the scan's sensor frame (x forward, y left)
    xyz = xyzi[semantic == car, :3]
    assert (np.abs(xyz[:, 0] - 8) <= 2.26).all() and (np.abs(xyz[:, 1] - 4) <= 0.96).all()
    record = json.loads((out / "records" / "000000.json").read_text())
    assert record["scene"]["firings"]["firings"] == 34688 and record["scene"]["inserted_points"] > 120
    assert [b["class"] for b in record["boxes"]] == ["car", "person"]
    labels = sorted(out.glob("kitti/**/label_2/000000.txt"))
    assert labels and labels[0].read_text().startswith("Car ")


def test_real_scan_bad_input_exits_2_naming_the_key(tmp_path, real_scan):
    done = run("--out", str(tmp_path / "a"), "--set", "scene.builder=real_scan")
    assert done.returncode == 2 and "scene.path" in done.stderr
    sweep = real_scan("nuscenes_hdl32e_sweep.bin")
    done = run("--out", str(tmp_path / "b"), "--set", "scene.builder=real_scan", "--set", f"scene.path={sweep}", "--set", "scene.objects=[{type: spaceship}]")
    assert done.returncode == 2 and "scene.objects[0].type" in done.stderr
    assert not (tmp_path / "b" / "sequences").exists()


def test_real_scan_frame_range_gives_the_full_runs_bytes(real_scan, tmp_path):
    sweep = real_scan("nuscenes_hdl32e_sweep.bin")
    common = ["--frames", "3", "--set", "scene.builder=real_scan", "--set", f"scene.path={sweep}", "--set", "scene.parking_rule.enabled=true", "--set",
              "output.preview=false", "--set", "output.formats=[semantickitti]"]
    full, part = run("--out", str(tmp_path / "full"), *common), run("--out", str(tmp_path / "part"), *common, "--frames-range", "2:3")
    assert full.returncode == 0 and part.returncode == 0, full.stderr + part.stderr
    for kind in ("velodyne/000002.bin", "labels/000002.label"):  # frame 2 is val: sequence 08 (output.split)
        assert (tmp_path / "full/sequences/08" / kind).read_bytes() == (tmp_path / "part/sequences/08" / kind).read_bytes()
    labels = [np.fromfile(next((tmp_path / "full").glob(f"sequences/*/labels/{k:06d}.label")), np.uint32) for k in range(3)]
    assert len({x.tobytes() for x in labels}) == 3  # each frame places its own cars
