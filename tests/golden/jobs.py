"""The golden jobs: small runs of every builder whose frames must keep their bytes across refactors.

``python tests/golden/jobs.py record`` runs each job with this Python's bpy and writes its digests
into ``golden.json`` beside this file, under the Blender's major.minor (``"4.5"``, ``"5.3"``; the
entries of other Blenders are kept): per frame, the sha256 of the point records (canonical
:data:`POINT_DTYPE` bytes, independent of the file formats) and of the SemanticKITTI files, with the
versions that produced them. ``tests/test_golden.py`` runs the same jobs and compares against the
entry of the Blender it runs on.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
GOLDEN = HERE / "golden.json"

# name -> run.py arguments (the default job at a coarser step so the check stays quick)
JOBS = {
    "default": ["--set", "sensor.horizontal_resolution_deg=0.5", "--set", "sensor.vertical_resolution_deg=0.5"],
    "parking": ["--set", "scene.builder=parking", "--frames", "3", "--seed", "7"],
    "industrial_hall": ["--set", "scene.builder=industrial_hall", "--frames", "2", "--seed", "5", "--set", "sensor.columns=512"],
    "primitives": ["--set", "scene.builder=primitives", "--set", "sensor.preset=vlp16", "--set", "sensor.position=[0,0,1]", "--set", "effects.noise.sigma=0.01",
                   "--set", "effects.drop.model=uniform", "--set", "effects.drop.probability=0.1"],
}


def blender_key() -> str:
    """The Blender release series of this Python's bpy: ``"4.5"`` for 4.5.15 LTS (the key of the digests table)."""
    import bpy

    return "{}.{}".format(*bpy.app.version[:2])


def read_golden() -> dict:
    """``{"by_blender": {major.minor: {"versions": {...}, "jobs": {job: {frame: {kind: sha256}}}}}}``."""
    return json.loads(GOLDEN.read_text()) if GOLDEN.is_file() else {"by_blender": {}}


def versions() -> dict:
    import bpy
    import embreex
    import numpy

    return {"blender": bpy.app.version_string, "numpy": numpy.__version__, "embreex": getattr(embreex, "__version__", "unknown")}


def digests(out: Path) -> dict:
    """{frame file stem: {"points": sha256 of the canonical records, "bin": ..., "label": ...}}."""
    sys.path.insert(0, str(ROOT))
    from bpy_pipeline.io import read_ply
    from bpy_pipeline.lidar.points import POINT_DTYPE

    result = {}
    for ply in sorted((out / "ply").glob("*.ply")):
        records = read_ply(ply)
        canonical = __import__("numpy").empty(len(records), POINT_DTYPE)
        for name in POINT_DTYPE.names:
            canonical[name] = records[name]
        entry = {"points": hashlib.sha256(canonical.tobytes()).hexdigest()}
        for kind, pattern in (("bin", f"sequences/*/velodyne/{ply.stem}.bin"), ("label", f"sequences/*/labels/{ply.stem}.label")):
            for path in sorted(out.glob(pattern)):  # the frame's sequence follows its split (output.split)
                entry[kind] = hashlib.sha256(path.read_bytes()).hexdigest()
        result[ply.stem] = entry
    return result


def run_job(name: str, out: Path, extra: list[str] = ()) -> dict:
    """Run job ``name`` into ``out`` (PLY and SemanticKITTI, ideal effects beyond what the job sets)."""
    # effects.ideal: the recorded bytes are those of the ideal scan (before presets carried their realistic effects)
    args = [sys.executable, str(ROOT / "run.py"), "--out", str(out), *JOBS[name], "--set", "output.formats=[ply,semantickitti]", "--set", "effects.ideal=true",
            *extra]
    done = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        raise RuntimeError(f"{name}: {done.stderr.strip()}")
    return digests(out)


if __name__ == "__main__" and sys.argv[1:] == ["record"]:
    import tempfile

    record = {"versions": versions(), "jobs": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for name in JOBS:
            record["jobs"][name] = run_job(name, Path(tmp) / name)
            print(name, record["jobs"][name])
    golden = read_golden()
    golden["by_blender"][blender_key()] = record
    golden["by_blender"] = dict(sorted(golden["by_blender"].items(), key=lambda kv: tuple(map(int, kv[0].split(".")))))
    GOLDEN.write_text(json.dumps(golden, indent=1) + "\n")
