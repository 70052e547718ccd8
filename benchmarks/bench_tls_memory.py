"""The railway thesis's static scan in bounded memory: peak memory and time split of the pipeline.

The default job's one-track railway scene (``scene.builder: railway``) scanned by the
``railway_tls`` preset (0..360 x -70..+90 deg at 0.05 deg: 23 million rays at
``sampling_factor`` 1; the thesis itself ran 1.5, 52 million) and written in all four formats
with the preview. Each run is a fresh Python process running :func:`bpy_pipeline.plan.run`;
its peak resident memory is its own ``ru_maxrss``. A second process builds and exports the same
scene and sets up the caster without scanning: the memory every run needs before its first ray.

Rays go through in chunks of ``lidar.sensor.sensor_rays.CHUNK_RAYS``: traced, given their effects and moved into
one array of point records (37 bytes a point) chunk by chunk; the writers convert a million
points at a time. So memory is the set-up plus the records, and the target is under 2 GB.
Run: python benchmarks/bench_tls_memory.py [--small]
"""

import json
import shutil
import subprocess
import sys
import tempfile

from common import ROOT, arguments, report

from bpy_pipeline.config import load_config
from bpy_pipeline.lidar.sensor.sensors import ray_count

FORMATS = "[ply,semantickitti,las,npy]"
CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, sys.argv[1])
start = time.perf_counter()
from bpy_pipeline.config import load_config
from bpy_pipeline.plan import run
from bpy_pipeline.stages.scene import build_frame_scene
from bpy_pipeline.stages.view import sensor_pose
config = load_config(None, json.loads(sys.argv[3]))
imported = time.perf_counter() - start
if sys.argv[2] == "setup":  # build, export and the caster, no scan
    from bpy_pipeline.blender.export import export_scene
    from bpy_pipeline.labels import load_class_table
    from bpy_pipeline.lidar.cast.raycast import RayCaster
    build_frame_scene(config, 0)
    buffers = export_scene(load_class_table(), keep_within=(sensor_pose(config)[:3, 3], config.sensor.spec.max_range))
    RayCaster(buffers, frame=sensor_pose(config))
    result = {"triangles": int(len(buffers.triangles))}
else:
    frame = run(config, sys.argv[2], log=lambda *a: None)["frames"][0]
    result = {"points": frame["points"], "triangles": frame["triangles"], "timings_s": frame["timings_s"]}
result.update(import_s=imported, wall_s=time.perf_counter() - start, peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
print(json.dumps(result))
"""


def child(mode: str, overrides: list[str]) -> dict:
    """Run :data:`CHILD` in a fresh interpreter; its JSON result."""
    done = subprocess.run([sys.executable, "-c", CHILD, str(ROOT), mode, json.dumps(overrides)], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def chart(rows: list[dict], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    rays = [r["rays"] / 1e6 for r in rows]
    left.plot(rays, [r["peak_mb"] for r in rows], "o-", label="peak (whole run)")
    left.plot(rays, [r["setup_mb"] for r in rows], "s--", color="grey", label="set-up only (scene, export, caster)")
    left.axhline(2048, color="red", ls=":", lw=0.8, label="2 GB")
    left.set(xlabel="rays per scan (millions)", ylabel="peak resident memory (MB)", title="Memory", ylim=(0, 2300))
    left.legend(fontsize=8)
    bottom = [0.0] * len(rows)
    for key in ("import", "build", "export", "scan", "effects", "write"):
        values = [r[f"{key}_s"] for r in rows]
        right.bar([f"{r:.1f} M" for r in rays], values, bottom=bottom, label=key)
        bottom = [b + v for b, v in zip(bottom, values)]
    right.set(xlabel="rays per scan", ylabel="seconds", title="Time split (one process each)")
    right.legend(fontsize=8)
    for ax in (left, right):
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    args = arguments(__doc__)
    factors = [0.1, 0.25] if args.small else [0.25, 1.0, 1.5]
    base = ["sensor.preset=railway_tls", "frames=1", f"output.formats={FORMATS}", "output.preview=true"]
    rows = []
    for factor in factors:  # the railway builder models as finely as the sensor resolves: set-up depends on it
        setup = child("setup", base + [f"sensor.sampling_factor={factor}"])
        out = tempfile.mkdtemp(prefix="bench_tls_memory_")
        try:
            run = child(out, base + [f"sensor.sampling_factor={factor}"])
        finally:
            shutil.rmtree(out, ignore_errors=True)
        rays = ray_count(load_config(None, base + [f"sensor.sampling_factor={factor}"]).sensor.spec)
        timings = run["timings_s"]
        rows.append({
            "sampling_factor": factor, "rays": rays, "points": run["points"], "triangles": run["triangles"], "peak_mb": run["peak_mb"],
            "setup_mb": setup["peak_mb"], "bytes_per_point_above_setup": (run["peak_mb"] - setup["peak_mb"]) * 2**20 / max(run["points"], 1),
            "import_s": run["import_s"], **{f"{k}_s": timings.get(k, 0.0) for k in ("build", "export", "scan", "effects", "write")}, "wall_s": run["wall_s"],
        })  # fmt: skip
    name = "tls_memory" + ("_small" if args.small else "")
    report(name, rows, args.out, {"formats": FORMATS, "preview": True, "chunk_rays": "lidar.sensor.sensor_rays.CHUNK_RAYS"})
    chart(rows, args.out / f"{name}.png")


if __name__ == "__main__":
    main()
