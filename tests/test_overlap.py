"""A frame finishing beside the next one (``plan.run_frames``): its finishing stages and commit on a thread
while the next frame's first stages run. The same bytes and records, the same frames committed when a run
stops or fails, log lines in frame order, and whole frames under kill -9."""

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bpy_pipeline.config import load_config
from bpy_pipeline.errors import InputError
from bpy_pipeline.plan import OVERLAP_MIN_RAYS, Stage, finishing_start, overlaps, plan

ROOT = Path(__file__).resolve().parents[1]
# a garage frame large enough to finish beside the next one (the os1_64: 65,536 rays), with boxes
GARAGE = ["scene.builder=parking", "sensor.preset=os1_64", "output.formats=[ply,semantickitti]", "output.boxes.formats=[kitti]", "seed=4", "threads=2"]


def test_the_finishing_stages_are_the_last_ones_and_blender_comes_before_them():
    stages = plan(load_config(None, ["scene.builder=parking", "output.kitti.camera.render=true"]))
    assert [s.name for s in stages[finishing_start(stages):]] == ["annotate"]
    assert [s.name for s in stages][-2:] == ["camera", "annotate"]  # the camera renders in Blender: before the finishing stages
    flash = plan(load_config(None, ["sensor.preset=flash96x16_carla", "output.formats=[ply,flash_image]", "output.boxes.formats=[kitti]"]))
    assert [s.name for s in flash[finishing_start(flash):]] == ["annotate", "flash"]
    rig = plan(load_config(None, ["sensor.rig=flash_post_240", "output.boxes.formats=[openpcdet]"]))
    assert [s.name for s in rig[finishing_start(rig):]] == ["merged boxes"]
    plain = plan(load_config(None, []))
    assert finishing_start(plain) == len(plain)  # nothing finishes beside the next frame but the commit
    assert finishing_start((Stage("a", print, None, finishing=True), Stage("b", print, None))) == 2


def test_a_run_overlaps_with_a_core_to_spare_and_frames_of_many_rays():
    config = load_config(None, GARAGE)
    assert overlaps(config, until_kept=False)
    assert not overlaps(config, until_kept=True)  # output.frames_kept counts kept frames before the next one
    assert not overlaps(replace(config, threads=1), until_kept=False)  # a worker on one core
    assert not overlaps(load_config(None, ["scene.builder=parking"]), until_kept=False)  # the vlp16: 14,480 rays
    assert overlaps(load_config(None, ["threads=2"]), until_kept=False)  # the railway's scanner
    small = load_config(None, ["sensor.preset=os1_64", "threads=2", "sensor.columns=512"])
    assert not overlaps(small, until_kept=False) and 64 * 512 < OVERLAP_MIN_RAYS


def frame_bytes(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file() and p.suffix != ".json" and ".lock" not in p.name}


def records(out: Path) -> list[dict]:
    kept = []
    for path in sorted((out / "records").glob("*.json")):
        record = json.loads(path.read_text())
        record.pop("timings_s")
        kept.append(record)
    return kept


@pytest.mark.bpy
def test_the_same_bytes_and_records_beside_the_next_frame_or_alone(bpy_scene, tmp_path):
    from bpy_pipeline.plan import run_frames

    config = replace(load_config(None, GARAGE), frames=4)
    said = {True: [], False: []}
    for overlap in (True, False):
        bpy_scene.ops.wm.read_factory_settings(use_empty=True)
        made = [f.index for f in run_frames(config, tmp_path / str(overlap), log=said[overlap].append, overlap=overlap)]
        assert made == [0, 1, 2, 3]
    assert frame_bytes(tmp_path / "True") == frame_bytes(tmp_path / "False")
    assert records(tmp_path / "True") == records(tmp_path / "False")
    assert said[True] == said[False]
    boxes = [r["boxes"] for r in records(tmp_path / "True")]
    assert sum(len(b) for b in boxes) > 0  # the finishing stage ran: the frames have their boxes


@pytest.mark.bpy
def test_skipped_frames_say_so_in_frame_order(bpy_scene, tmp_path):
    from bpy_pipeline.plan import run_frames

    config = replace(load_config(None, [*GARAGE, "output.skip_empty=true", "output.min_objects=99", "output.frames_kept=false"]), frames=4)
    said = []
    assert list(run_frames(config, tmp_path / "run", log=said.append)) == []
    skipped = [line for line in said if line.endswith("fewer than output.min_objects (99))")]
    assert [line.split(":")[0] for line in skipped] == ["frame 0", "frame 1", "frame 2", "frame 3"]


def failing_at(index: int, finishing: bool):
    """The garage's plan with a stage that raises on frame ``index``: among the first stages or the finishing ones."""

    def fail(frame, run):
        if frame.index == index:
            raise InputError(f"test: frame {index} fails")

    def patched(config):
        stages = plan(config)
        extra = Stage("fail", fail, None, finishing=finishing)
        return (*stages, extra) if finishing else (extra, *stages)

    return patched


@pytest.mark.bpy
@pytest.mark.parametrize("finishing", [False, True], ids=["first stages", "finishing stages"])
def test_a_failing_frame_leaves_the_frames_before_it_committed_and_no_other(bpy_scene, tmp_path, monkeypatch, finishing):
    import bpy_pipeline.plan as plan_module
    from bpy_pipeline.io import read_dataset

    monkeypatch.setattr(plan_module, "plan", failing_at(2, finishing))
    config = replace(load_config(None, GARAGE), frames=4)
    yielded = []
    with pytest.raises(InputError, match="frame 2 fails"):
        for frame in plan_module.run_frames(config, tmp_path / "run"):
            yielded.append(frame.index)
    assert yielded == [0, 1]
    assert [r["index"] for r in read_dataset(tmp_path / "run")["frames"]] == [0, 1]
    assert sorted(p.name for p in (tmp_path / "run" / "ply").iterdir()) == ["000000.ply", "000001.ply"]


@pytest.mark.bpy
def test_stopping_after_a_frame_commits_no_other(bpy_scene, tmp_path):
    from bpy_pipeline.io import read_dataset
    from bpy_pipeline.plan import run_frames

    config = replace(load_config(None, GARAGE), frames=4)
    frames = run_frames(config, tmp_path / "run")
    assert next(frames).index == 0
    assert next(frames).index == 1  # frame 2's first stages have run by now, its commit has not
    frames.close()
    assert [r["index"] for r in read_dataset(tmp_path / "run")["frames"]] == [0, 1]


@pytest.mark.bpy
@pytest.mark.slow
def test_kill_9_while_a_frame_finishes_beside_the_next_then_resume_gives_the_uninterrupted_bytes(tmp_path, killed_run_environment):
    args = [a for o in GARAGE for a in ("--set", o)]

    def cli(out: Path, *extra):
        return subprocess.run([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--frames", "16", *args, *extra], cwd=ROOT, capture_output=True,
                              text=True, timeout=600)

    reference = tmp_path / "full"
    assert cli(reference).returncode == 0
    rng = np.random.default_rng(1)
    interrupted = 0
    for k in range(int(os.environ.get("BPY_PIPELINE_KILL_RUNS", "6"))):
        out = tmp_path / f"killed{k}"
        proc = subprocess.Popen([sys.executable, str(ROOT / "run.py"), "--out", str(out), "--frames", "16", *args], cwd=ROOT, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, env=killed_run_environment)
        deadline = time.time() + 300
        while not (out / "records" / "000000.json").exists() and proc.poll() is None and time.time() < deadline:
            time.sleep(0.02)
        time.sleep(float(rng.uniform(0.0, 1.0)))  # among the frames: one finishing beside the next
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        interrupted += len(list((out / "records").glob("*.json"))) < 16
        done = cli(out, "--resume")
        assert done.returncode == 0, done.stderr
        assert frame_bytes(out) == frame_bytes(reference)
        assert records(out) == records(reference)
    assert interrupted  # some kill landed among the frames


def test_a_mirror_sensor_keeps_the_rays_of_the_frame_finishing_and_of_the_next(monkeypatch):
    """A rosette's rays change every frame: the frame finishing beside the next asks for its own frame's after the next
    frame asked for its, and gets them without tracing them through the mirrors again."""
    import bpy_pipeline.lidar.sensor.sensor_rays as sensor_rays

    traced = []
    real = sensor_rays.MirrorFrame.of

    def counted(reflector, spec, frame):
        traced.append(frame)
        return real(reflector, spec, frame)

    monkeypatch.setattr(sensor_rays.MirrorFrame, "of", staticmethod(counted))
    rays = sensor_rays.SensorRays(load_config(None, ["sensor.preset=livox_mid40", "sensor.reflector={enabled: true, edge_drop: {mask: none}}"]))
    first = rays.patterns(0)[0]
    assert rays.patterns(1)[0] is not first and rays.patterns(0)[0] is first
    assert traced == [0, 1]
    rays.patterns(2)
    rays.patterns(0)
    assert traced == [0, 1, 2, 0]  # two frames kept: the oldest goes
