"""The ego street's frame, stage by stage, against an older checkout: where a frame's time goes, and the same bytes.

Each checkout runs ``examples/street/ego_hdl64e.yaml`` for ``--frames`` frames, in an empty Blender scene as ``run.py``
does, one frame at a time (``run_frames(..., overlap=False)``: no frame finishing beside the next, so each stage's time
is its own) in a subprocess importing that checkout's ``bpy_pipeline``; the two alternate for ``--rounds`` rounds. Each
stage is timed in wall seconds and in the process's CPU seconds (every thread; on a machine other jobs share, the
steadier reading: ``scan`` is the caster's set-up, ``effects`` the lazy trace with the effects, ``write`` the commit).
Per checkout: each stage's median over frames 2 on (the first builds the street) of its best round (by wall, and by
CPU), the frame's sum, the process's CPU seconds and peak resident memory;
and the sha256 of every file of every frame but the records and the manifest (they hold timings), compared between
the checkouts (``same_files``), and their point records compared field by field (``points``: how many differ, the
points whose labels differ, the largest position difference of the others).

    python benchmarks/bench_street_frame.py --old ../base [--frames 12] [--rounds 2] [--name NAME]

Results: ``benchmarks/results/<--name>`` (default ``street_frame.json``; the committed run: ``street_frame_round21.json``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SKIPPED = ("records", "manifest.json")  # files holding timings


def output_digests(out: Path) -> dict[str, str]:
    """``{path relative to out: sha256}`` of every file of a run's folder ``out`` but those holding timings (:data:`SKIPPED`)."""
    return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(out.rglob("*"))
            if p.is_file() and not str(p.relative_to(out)).startswith(SKIPPED)}  # fmt: skip


def checkout_environment(code: Path) -> dict[str, str]:
    """This process's environment for a subprocess importing checkout ``code``'s package: ``PYTHONPATH`` there, one BLAS
    thread, and without ``PYTHONDONTWRITEBYTECODE`` (each checkout imported from its bytecode caches, as an installed package is)."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"} | {"PYTHONPATH": str(code), "OPENBLAS_NUM_THREADS": "1"}


def write_result(out: Path, name: str, result: dict) -> None:
    """``result`` as ``out/name`` (indented JSON), and where it went."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / name
    path.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {path}")


def part(frames: int, keep: Path | None = None) -> dict:
    """In the checkout on ``PYTHONPATH`` (the working directory): the job's frames one at a time; stage timings, digests;
    each frame's PLY records copied to ``keep`` (when given) as ``.npy``."""
    import bpy_pipeline  # first: its numpy settings apply only before numpy loads

    import bpy

    from bpy_pipeline import plan
    from bpy_pipeline.config import load_config
    from bpy_pipeline.dataset import Dataset

    bpy.ops.wm.read_factory_settings(use_empty=True)  # as run.py and bpy_pipeline.run start: no startup cube in the street
    config = load_config("examples/street/ego_hdl64e.yaml", [f"frames={frames}"])
    cpu: dict[int, dict[str, float]] = {}  # frame -> stage name (and "write": the commit) -> CPU s of the process
    run_stages, commit = plan.run_stages, Dataset.commit

    def timed_stages(frame, run, stages, said):
        for stage in stages:
            start = time.process_time()
            run_stages(frame, run, (stage,), said)
            cpu.setdefault(frame.index, {})[stage.name] = time.process_time() - start

    def timed_commit(self, frame, *args, **kwargs):
        start = time.process_time()
        try:
            return commit(self, frame, *args, **kwargs)
        finally:
            cpu.setdefault(frame.index, {})["write"] = time.process_time() - start

    plan.run_stages, Dataset.commit = timed_stages, timed_commit
    with tempfile.TemporaryDirectory(dir=os.environ.get("BENCH_SPEED_TMP")) as tmp:
        out = Path(tmp) / "run"
        start = time.perf_counter()
        timings = [dict(f.timings) | {f"cpu_{k}": v for k, v in cpu[f.index].items()} for f in plan.run_frames(config, out, overlap=False)]
        wall = time.perf_counter() - start
        digests = output_digests(out)
        if keep is not None:
            import numpy as np

            from bpy_pipeline.io import read_ply

            keep.mkdir(parents=True, exist_ok=True)
            for ply in sorted((out / "ply").glob("*.ply")):
                np.save(keep / f"{ply.stem}.npy", read_ply(ply))
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return {"code": str(Path(bpy_pipeline.__file__).parent), "timings": timings, "wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime,
            "peak_rss_mb": usage.ru_maxrss / 1024, "digests": digests}


def in_checkout(code: Path, frames: int, keep: Path) -> dict:
    """:func:`part` in a subprocess importing ``code``'s package (cwd and PYTHONPATH there)."""
    done = subprocess.run([sys.executable, str(HERE / "bench_street_frame.py"), "--part", "--frames", str(frames), "--keep", str(keep)], cwd=code,
                          env=checkout_environment(code),
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{code}: {done.stderr.strip()[-800:]}")
    row = json.loads(done.stdout.strip().splitlines()[-1])
    if not row["code"].startswith(str(code)):
        raise RuntimeError(f"{code}: imported bpy_pipeline from {row['code']}")
    return row


def compare_points(new: Path, old: Path) -> dict:
    """Frame by frame, the two checkouts' point records: how many points, how many differ in any field, the labels
    (semantic, instance) of those, and the largest position difference of the points whose labels agree."""
    import numpy as np

    frames, points, differing, relabelled, moved = 0, 0, 0, [], 0.0
    for path in sorted(new.glob("*.npy")):
        a, b = np.load(path), np.load(old / path.name)
        frames += 1
        points += len(a)
        if len(a) != len(b):
            relabelled.append({"frame": path.stem, "points": [len(a), len(b)]})
            continue
        differ = np.zeros(len(a), bool)
        for name in a.dtype.names:
            differ |= a[name].view(f"u{a[name].itemsize}") != b[name].view(f"u{b[name].itemsize}")
        differing += int(differ.sum())
        labels = (a["semantic"] != b["semantic"]) | (a["instance"] != b["instance"])
        relabelled += [{"frame": path.stem, "point": int(i), "new": [int(a["semantic"][i]), int(a["instance"][i]), float(a["range"][i])],
                        "old": [int(b["semantic"][i]), int(b["instance"][i]), float(b["range"][i])]}
                       for i in np.flatnonzero(labels)]
        same = ~labels
        if same.any():
            xyz = lambda r: np.column_stack([r["x"], r["y"], r["z"]])[same].astype(np.float64)  # noqa: E731
            moved = max(moved, float(np.abs(xyz(a) - xyz(b)).max()))
    return {"frames": frames, "points": points, "points_differing": differing, "relabelled": relabelled, "max_position_difference_same_labels_m": moved}


def summary(row: dict) -> dict:
    """Median of each stage over frames 2 on, their sum, and the run's figures."""
    later = row["timings"][1:]
    stages = {k: round(statistics.median(t.get(k, 0.0) for t in later), 4) for k in later[0] if not k.startswith("cpu_")}
    cpu = {k.removeprefix("cpu_"): round(statistics.median(t.get(k, 0.0) for t in later), 4) for k in later[0] if k.startswith("cpu_") and k != "cpu_pose"}
    return {"stages_s": stages, "frame_s": round(sum(stages.values()), 4), "stages_cpu_s": cpu, "frame_cpu_s": round(sum(cpu.values()), 4),
            "wall_s": round(row["wall_s"], 3), "cpu_s": round(row["cpu_s"], 3), "peak_rss_mb": round(row["peak_rss_mb"], 1)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--old", type=Path, required=False, help="the older checkout (e.g. git worktree add ../base 582eb53)")
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--out", type=Path, default=HERE / "results")
    p.add_argument("--name", default="street_frame.json")
    p.add_argument("--part", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--keep", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.part:
        print(json.dumps(part(args.frames, args.keep)))
        return
    sides = {"new": ROOT} | ({"old": args.old.resolve()} if args.old else {})
    runs: dict[str, list[dict]] = {name: [] for name in sides}
    digests = {}
    kept = Path(tempfile.mkdtemp(dir=os.environ.get("BENCH_SPEED_TMP")))
    for _ in range(args.rounds):
        for name, code in sides.items():
            row = in_checkout(code, args.frames, kept / name)
            digests[name] = row.pop("digests")
            runs[name].append(summary(row))
            print(name, runs[name][-1], flush=True)
    result = {"frames": args.frames, "rounds": args.rounds, "checkouts": {k: str(v) for k, v in sides.items()}, "runs": runs,
              "best": {name: min(rows, key=lambda r: r["frame_s"]) for name, rows in runs.items()},
              "best_cpu": {name: min(rows, key=lambda r: r["frame_cpu_s"]) for name, rows in runs.items()}}  # fmt: skip
    if "old" in runs:
        new, old = result["best"]["new"], result["best"]["old"]
        result["frame_old_over_new"] = round(old["frame_s"] / new["frame_s"], 3)
        result["files"] = len(digests["new"])
        result["same_files"] = digests["new"] == digests["old"]
        result["files_differing"] = sorted(k for k in set(digests["new"]) | set(digests["old"]) if digests["new"].get(k) != digests["old"].get(k))
        result["points"] = compare_points(kept / "new", kept / "old")
        result["frame_cpu_old_over_new"] = round(result["best_cpu"]["old"]["frame_cpu_s"] / result["best_cpu"]["new"]["frame_cpu_s"], 3)
        print(
            f"a frame's stages: {new['frame_s'] * 1e3:.0f} ms against {old['frame_s'] * 1e3:.0f} ms ({result['frame_old_over_new']:.2f}x), CPU "
            f"{result['frame_cpu_old_over_new']:.2f}x; {result['files']} files, the same bytes: {result['same_files']}; "
            f"points: {result['points']['points_differing']} of {result['points']['points']} differ, relabelled {result['points']['relabelled']}"
        )
    shutil.rmtree(kept, ignore_errors=True)
    write_result(args.out, args.name, result)


if __name__ == "__main__":
    main()
