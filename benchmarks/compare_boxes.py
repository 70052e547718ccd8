"""Two checkouts' 3D boxes of the same job, box by box: what a change to the boxes stage does to the labels.

Each checkout runs the job (``--config``, ``--set``, ``--frames``; one frame at a time, ``run_frames(..., overlap=False)``)
in a subprocess importing that checkout's ``bpy_pipeline``, keeping every box the annotate stage fits (world frame, none
dropped: :func:`bpy_pipeline.stages.annotate.world_boxes`) and the sha256 of every output file but the records and the
manifest. Boxes are matched by frame and instance; reported: how many change ``visible``, ``unoccluded``, occlusion level
and truncation, the largest ``unoccluded`` change (rays and share), whether ``visible <= unoccluded`` holds, and the
output files whose bytes differ.

    python benchmarks/compare_boxes.py --old ../main [--config examples/street/ego_hdl64e.yaml] [--frames 40]
    python benchmarks/compare_boxes.py --old ../main --config '' --set scene.builder=parking --frames 10   # the garage

Results: ``benchmarks/results/<--name>`` (default ``compare_boxes.json``).
"""

from __future__ import annotations

import argparse
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_street_frame import checkout_environment, output_digests, write_result

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def part(config_path: str, overrides: list[str], frames: int, dump: Path) -> None:
    """In the checkout on ``PYTHONPATH``: run the job, pickle ``{"boxes": {frame: world boxes}, "digests": {file: sha256}}`` to ``dump``."""
    import bpy_pipeline  # first: its numpy settings apply only before numpy loads

    import bpy

    from bpy_pipeline import plan
    from bpy_pipeline.config import load_config
    from bpy_pipeline.stages import annotate

    boxes = {}
    fitted = annotate.world_boxes

    def kept(*args, **kwargs):
        out = fitted(*args, **kwargs)
        frame = args[5] if len(args) > 5 else kwargs.get("frame", 0)
        boxes[int(frame)] = out.copy()
        return out

    annotate.world_boxes = kept
    bpy.ops.wm.read_factory_settings(use_empty=True)
    config = load_config(config_path or None, [f"frames={frames}", *overrides])
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        for _ in plan.run_frames(config, out, overlap=False):
            pass
        digests = output_digests(out)
    dump.write_bytes(pickle.dumps({"boxes": boxes, "digests": digests, "code": str(Path(bpy_pipeline.__file__).parent)}))


def in_checkout(code: Path, args: argparse.Namespace, dump: Path) -> dict:
    """:func:`part` in a subprocess importing ``code``'s package (cwd and PYTHONPATH there)."""
    command = [sys.executable, str(HERE / "compare_boxes.py"), "--part", "--config", args.config, "--frames", str(args.frames), "--dump", str(dump)]
    for value in args.set:
        command += ["--set", value]
    done = subprocess.run(command, cwd=code, env=checkout_environment(code), capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{code}: {done.stderr.strip()[-800:]}")
    row = pickle.loads(dump.read_bytes())
    if not row["code"].startswith(str(code)):
        raise RuntimeError(f"{code}: imported bpy_pipeline from {row['code']}")
    return row


def compare(new: dict, old: dict) -> dict:
    """Box by box (frame, instance), the new checkout's boxes against the old's."""
    import numpy as np

    boxes = changed_visible = changed_unoccluded = changed_level = changed_truncation = unmatched = 0
    largest, largest_share, visible_over, levels = 0, 0.0, {"new": 0, "old": 0}, []
    for frame in sorted(set(new) | set(old)):
        a, b = new.get(frame), old.get(frame)
        if a is None or b is None or a["instance"].tolist() != b["instance"].tolist():
            unmatched += 1
            continue
        boxes += len(a)
        changed_visible += int((a["visible"] != b["visible"]).sum())
        delta = np.abs(a["unoccluded"].astype(np.int64) - b["unoccluded"].astype(np.int64))
        changed_unoccluded += int((delta > 0).sum())
        if delta.any():
            largest = max(largest, int(delta.max()))
            largest_share = max(largest_share, float((delta / np.maximum(b["unoccluded"], 1)).max()))
        level = a["occlusion"] != b["occlusion"]
        changed_level += int(level.sum())
        levels += [{"frame": frame, "instance": int(a["instance"][i]), "new": [int(a["occlusion"][i]), int(a["visible"][i]), int(a["unoccluded"][i])],
                    "old": [int(b["occlusion"][i]), int(b["visible"][i]), int(b["unoccluded"][i])]} for i in np.flatnonzero(level)]
        changed_truncation += int((a["truncation"] != b["truncation"]).sum())
        visible_over["new"] += int((a["visible"] > a["unoccluded"]).sum())
        visible_over["old"] += int((b["visible"] > b["unoccluded"]).sum())
    return {"boxes": boxes, "frames_unmatched": unmatched, "visible_changed": changed_visible, "unoccluded_changed": changed_unoccluded,
            "largest_unoccluded_change_rays": largest, "largest_unoccluded_change_share": round(largest_share, 4), "occlusion_level_changed": changed_level,
            "level_changes": levels, "truncation_changed": changed_truncation, "visible_over_unoccluded": visible_over}  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--old", type=Path, help="the older checkout")
    p.add_argument("--config", default="examples/street/ego_hdl64e.yaml", help="the job's config ('': the defaults, with --set)")
    p.add_argument("--set", action="append", default=[], help="key.path=value, as run.py takes it (repeatable)")
    p.add_argument("--frames", type=int, default=40)
    p.add_argument("--out", type=Path, default=HERE / "results")
    p.add_argument("--name", default="compare_boxes.json")
    p.add_argument("--part", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--dump", type=Path, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.part:
        part(args.config, args.set, args.frames, args.dump)
        return
    with tempfile.TemporaryDirectory() as tmp:
        new = in_checkout(ROOT, args, Path(tmp) / "new.pkl")
        old = in_checkout(args.old.resolve(), args, Path(tmp) / "old.pkl")
    result = {"config": args.config, "set": args.set, "frames": args.frames} | compare(new["boxes"], old["boxes"])
    files = set(new["digests"]) | set(old["digests"])
    result["files"] = len(files)
    result["files_differing"] = sorted(f for f in files if new["digests"].get(f) != old["digests"].get(f))
    print({k: v for k, v in result.items() if k != "level_changes"})
    write_result(args.out, args.name, result)


if __name__ == "__main__":
    main()
