"""Parts of a frame's stages measured in process: the figures of docs/performance.md, rounds sixteen and seventeen.

- ``railway``: the default railway's rays (1,441,800) against its first frame's triangles: raw embreex
  (``EmbreeScene.run(output=1)``, chunks of 32,768 over 2 threads), the compiled pass's own Embree calls
  (``numba_kernels.trace_rays``, the same chunks and threads) and the whole scan (``scanner.scan_chunks``: trace,
  records, join), each the best of 3; and the ``scan`` timings of a run's frames 2 on.
- ``cone``: the boxes' cone test (``visibility.cone_pairs``) on three presets' patterns against 63 random boxes,
  compiled (blocks of rays pruned) and numpy (every pair), the same pairs; the share of (block, box) pairs kept.
- ``export``: ``export_scene`` of each builder's first frame, fastest of 10.
- ``ego_street``: the ego street's stages one frame at a time (``overlap=False``), median of frames 2 on, with the
  vehicles' plates and lamps and without (``scene.car_fittings``).
- ``boxes_from_scan``: the boxes stage of the garage and of the ego street, one frame at a time, median of frames 2 on,
  with the ``visible`` counts taken from the scan's own returns (``stages.scan.counts_direct_returns``, the default)
  and with the rays that pass the boxes traced again (that function made to answer False), in alternating rounds; the
  boxes of both, byte for byte.

    python benchmarks/bench_stage_parts.py [--small] [--name NAME]

Results: ``benchmarks/results/stage_parts.json`` (``--small``: fewer frames and repeats).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import RESULTS, ROOT, best_of  # puts the checkout on the path

import bpy_pipeline  # noqa: F401  (before numpy: its numpy settings apply only before numpy loads)
import numpy as np


def best(fn, repeats: int) -> float:
    """:func:`common.best_of` after one call that warms ``fn`` (compiled kernels, caches)."""
    fn()
    return best_of(fn, repeats)


def railway(frames: int, repeats: int) -> dict:
    from concurrent.futures import ThreadPoolExecutor

    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    from bpy_pipeline.config import load_config
    from bpy_pipeline.lidar.cast import scanner
    from bpy_pipeline.lidar.sensor.sensor_rays import CHUNK_RAYS
    from bpy_pipeline.lidar.sensor.sensors import sensor_pattern
    from bpy_pipeline.plan import run_frames

    config = load_config(None, [f"frames={frames}"])
    with tempfile.TemporaryDirectory() as tmp:
        made = list(run_frames(config, Path(tmp) / "run", overlap=False))
    first, spec = made[0], config.sensor.spec
    pattern = sensor_pattern(spec)
    d64 = np.ascontiguousarray(pattern.directions, np.float64)
    d32 = d64.astype(np.float32)
    o32 = np.lib.stride_tricks.as_strided(np.zeros(3, np.float32), d32.shape, (0, 4))
    far = np.full(len(d32), np.float32(spec.max_range), np.float32)
    local = (np.asarray(first.buffers.vertices, np.float64) - first.pose[:3, 3]) @ first.pose[:3, :3]
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(local, np.float32), np.ascontiguousarray(first.buffers.triangles, np.int32))
    caster = first.caster
    caster._pool = None  # the run's pool ended with it: the caster makes its own
    spans = [slice(i, i + 32768) for i in range(0, len(d32), 32768)]
    tfar, prim, origin = np.empty(len(d32), np.float32), np.empty(len(d32), np.int32), np.zeros((1, 3))
    with ThreadPoolExecutor(2) as pool:
        raw = best(lambda: list(pool.map(lambda s: scene.run(o32[s], d32[s], dists=float(far[0]), output=1), spans)), repeats)
        out = {"rays": len(d32), "raw_embreex_s": raw}
        if caster.kernels is not None and caster.kernels.traces:
            def trace(s):
                return caster.kernels.trace_rays(caster.embree_handles, caster.part_triangle, caster.part_shift, far[s], origin, d64[s], tfar[s], prim[s])

            out["compiled_embree_calls_s"] = best(lambda: list(pool.map(trace, spans)), repeats)

    def whole():
        for _ in scanner.scan_chunks(caster, first.buffers, pattern, first.pose, spec.min_range, spec.max_range, chunk_rays=CHUNK_RAYS):
            pass

    out["scan_alone_s"] = best(whole, repeats)
    out["scan_alone_ratio"] = raw / out["scan_alone_s"]
    out["scan_in_run_s"] = [round(f.timings["scan"], 4) for f in made[1:]]
    return out


def cone(repeats: int) -> list:
    from bpy_pipeline.lidar.cast.kernels import compiled
    from bpy_pipeline.lidar.sensor.sensors import resolve_sensor, sensor_pattern
    from bpy_pipeline.lidar.cast.visibility import CONE_MARGIN, cone_pairs

    kernels, rows = compiled(), []
    for preset in ("hdl64e", "os1_128", "vlp16"):
        directions = np.ascontiguousarray(sensor_pattern(resolve_sensor({"preset": preset})).directions, np.float64)
        rng = np.random.default_rng(0)
        centres = rng.normal(size=(63, 3)) * [20.0, 20.0, 1.0]
        distance = np.linalg.norm(centres, axis=1)
        axes = np.ascontiguousarray(centres / distance[:, None])
        cos_limit = np.sqrt(np.clip(1 - (rng.uniform(1, 4, 63) / distance) ** 2, 0, 1))
        row = {"preset": preset, "rays": len(directions), "boxes": len(axes), "numpy_s": best(lambda: cone_pairs(directions, axes, cos_limit), repeats)}
        if kernels is not None:
            row["compiled_s"] = best(lambda: cone_pairs(directions, axes, cos_limit, kernels), repeats)
            row["kept_share"] = float(kernels.cone_blocks(directions, axes, cos_limit - CONE_MARGIN).mean())
            row["same_pairs"] = all(np.array_equal(a, b) for a,
                                    b in zip(cone_pairs(directions, axes, cos_limit, kernels), cone_pairs(directions, axes, cos_limit)))
        rows.append(row)
    return rows


def export(repeats: int) -> list:
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.frame import frame_rng
    from bpy_pipeline.stages.scene import build_frame_scene

    rows, table = [], load_class_table()
    for builder in ("parking", "street", "railway", "industrial_hall"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        config = load_config(None, [f"scene.builder={builder}"])
        build_frame_scene(config, 0, frame_rng(config.seed, 0), {})
        buffers = export_scene(table)
        rows.append({"builder": builder, "objects": len(buffers.objects), "triangles": len(buffers.triangles),
                     "export_s": best(lambda: export_scene(table), repeats), "blender": bpy.app.version_string})
    return rows


def ego_street(frames: int) -> dict:
    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import run_frames

    out = {}
    for fittings in ("true", "false"):
        config = load_config(str(ROOT / "examples/street/ego_hdl64e.yaml"), [f"frames={frames}", f"scene.car_fittings={fittings}"])
        with tempfile.TemporaryDirectory() as tmp:
            timings = [f.timings for f in run_frames(config, Path(tmp) / "run", overlap=False)][1:]
        out[f"car_fittings_{fittings}"] = {k: round(statistics.median(t[k] for t in timings), 4) for k in timings[0]}
    return out


def boxes_from_scan(jobs: dict, rounds: int) -> dict:
    """Per job ``{name: (config file or None, overrides)}``: its boxes stage, median of frames 2 on, one frame at a time,
    with the scan's counts and traced again, in alternating rounds; whether both give the same boxes."""
    import bpy

    from bpy_pipeline.config import load_config
    from bpy_pipeline.plan import run_frames
    from bpy_pipeline.stages import scan

    counted = scan.counts_direct_returns
    out = {}
    try:
        for name, (path, overrides) in jobs.items():
            config = load_config(path, overrides)
            stage, boxes = {"scan_counts": [], "traced": []}, {}
            for _ in range(rounds):
                for way in stage:
                    scan.counts_direct_returns = counted if way == "scan_counts" else (lambda config, frame: False)
                    bpy.ops.wm.read_factory_settings(use_empty=True)
                    with tempfile.TemporaryDirectory() as tmp:
                        made = list(run_frames(config, Path(tmp) / "run", overlap=False))
                    stage[way].append(statistics.median(f.timings["boxes"] for f in made[1:]))
                    boxes[way] = b"".join(f.boxes.tobytes() for f in made)
            out[name] = {"frames": config.frames, "boxes_stage_s": {way: [round(v, 5) for v in values] for way, values in stage.items()},
                         "best_ratio_traced_over_scan_counts": round(min(stage["traced"]) / min(stage["scan_counts"]), 3),
                         "same_boxes": boxes["scan_counts"] == boxes["traced"]}
    finally:
        scan.counts_direct_returns = counted
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--small", action="store_true", help="fewer frames and repeats (under a minute)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--name", default=None, help="results file name (default stage_parts.json; --small stage_parts_small.json)")
    args = parser.parse_args()
    repeats, frames = (1, 3) if args.small else (3, 7)
    result = {"cone": cone(repeats), "export": export(1 if args.small else 10), "ego_street": ego_street(frames),
              "railway": railway(2 if args.small else 6, repeats),
              "boxes_from_scan": boxes_from_scan({"garage": (None, ["scene.builder=parking", f"frames={6 if args.small else 30}"]),
                                                  "ego_street": (str(ROOT / "examples/street/ego_hdl64e.yaml"), [f"frames={frames}"])}, 1 if args.small else 3)}
    for row in result["cone"]:
        print(
            f"cone {row['preset']}: numpy {row['numpy_s'] * 1e3:.1f} ms, compiled {row.get('compiled_s', float('nan')) * 1e3:.1f} ms, kept "
            f"{row.get('kept_share', 1.0):.3f}, same pairs {row.get('same_pairs')}",
            flush=True,
        )
    for row in result["export"]:
        print(f"export {row['builder']}: {row['export_s'] * 1e3:.1f} ms ({row['objects']} objects, {row['triangles']} triangles)")
    for key, stages in result["ego_street"].items():
        print(f"ego street {key}: " + ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in stages.items()))
    r = result["railway"]
    print(f"railway: raw embreex {r['raw_embreex_s'] * 1e3:.1f} ms, compiled Embree calls {r.get('compiled_embree_calls_s', float('nan')) * 1e3:.1f} ms, "
          f"scan alone {r['scan_alone_s'] * 1e3:.1f} ms ({r['scan_alone_ratio']:.2f} of raw), in the run {[round(s * 1e3, 1) for s in r['scan_in_run_s']]} ms")
    for name, g in result["boxes_from_scan"].items():
        print(
            f"{name} boxes stage: with the scan's counts {[round(v * 1e3, 2) for v in g['boxes_stage_s']['scan_counts']]} ms, traced again "
            f"{[round(v * 1e3, 2) for v in g['boxes_stage_s']['traced']]} ms "
            f"({g['best_ratio_traced_over_scan_counts']:.2f}x best against best), the same boxes: {g['same_boxes']}"
        )
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / (args.name or ("stage_parts_small.json" if args.small else "stage_parts.json"))
    path.write_text(json.dumps(result, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
