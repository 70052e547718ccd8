"""Cost of the sensor effects beside the scan of the default job, measured in the same run.

Builds and exports the default job's scene (python run.py without --config) as run_frames does, times
``stages.scan.scan_buffers`` with ``apply_effects`` taken out (the scan alone: trace, records,
labels), keeps the points and beam facts it would have handed to ``effects.apply_effects`` (one
call per chunk of rays, as the pipeline makes them), and times those calls with each effect,
and with all of them together: the
lidar-equation intensity, the fitted (range, incidence) drop table, the noise table, a per-ring
bias and angular jitter (models fitted on ../shared/real_scans/nuscenes_hdl32e_sweep.bin; the
datasheet threshold and a constant sigma stand in when it is absent). Target: all together add
at most 10 % to the scan. Every timing is the best of five rounds taken in turn; the end-to-end
check times scan_buffers with all effects on as well (a difference of two timings: noisier).
Run: python benchmarks/bench_effects.py [--small]
"""

import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from common import ROOT, arguments, report

import bpy  # noqa: F401

from bpy_pipeline.frame import frame_rng
from bpy_pipeline.stages.scene import build_frame_scene
from bpy_pipeline.stages.view import sensor_pose
from bpy_pipeline.stages import scan as scan_stages  # the effects stage's own apply_effects is the one patched
from bpy_pipeline.config import effects_from_dict, load_config
from bpy_pipeline.blender.export import export_scene
from bpy_pipeline.labels import load_class_table
from bpy_pipeline.lidar.fit import fitting
from bpy_pipeline.lidar.effects.apply import write_model_file

SCAN = ROOT.parent / "shared" / "real_scans" / "nuscenes_hdl32e_sweep.bin"


def model_file(folder: Path) -> str:
    """Models fitted on the real sweep (the recommended 4 x 2 drop table), or '' without it."""
    if not SCAN.exists():
        return ""
    models, _ = fitting.fit_models(fitting.read_scan(SCAN, 32), fitting.FitOptions(folds=0))
    path = folder / "hdl32e.yaml"
    write_model_file(path, models)
    return str(path)


def variants(path: str, rings: int) -> dict:
    """Effects sections to time, by name; ``all`` switches every effect on at once."""
    bias = [round(float(b), 4) for b in np.random.default_rng(0).normal(0.0, 0.005, rings)]
    fitted = bool(path)
    drop = {"model": "table", "model_file": path} if fitted else {"model": "threshold"}
    noise = {"model": "table", "model_file": path} if fitted else {"sigma": 0.002}
    out = {
        "intensity lidar": {"intensity": {"model": "lidar", "alpha": 0.0002}},
        "drop uniform": {"drop": {"model": "uniform", "probability": 0.003}},
        "drop carla": {"drop": {"model": "carla"}},
        "drop threshold": {"drop": {"model": "threshold"}},
        "noise constant": {"noise": {"sigma": 0.002}},
        "noise range": {"noise": {"model": "range", "sigma": 0.002, "sigma_per_metre": 0.0002}},
        "ring bias": {"noise": {"ring_bias": bias}},
        "angular jitter": {"noise": {"angular_jitter_deg": 0.01}},
        "all": {"intensity": {"model": "lidar", "alpha": 0.0002}, "drop": drop,
                "noise": {**noise, "ring_bias": bias, "angular_jitter_deg": 0.01}},
    }
    if fitted:
        out["drop table"] = {"drop": drop}
        out["noise table"] = {"noise": noise}
    return out


def interleaved(fns: dict, rounds: int) -> dict:
    """Best wall time of each callable, measured in turn round after round (a shared machine's load
    then weighs on all of them alike)."""
    best = {k: float("inf") for k in fns}
    for _ in range(rounds):
        for k, fn in fns.items():
            start = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - start)
    return best


def main():
    args = arguments(__doc__)
    overrides = ["sensor.sampling_factor=0.1"] if args.small else []
    config = load_config(None, overrides)
    build_frame_scene(config, 0)
    buffers = export_scene(load_class_table(), (), keep_within=(sensor_pose(config)[:3, 3], config.sensor.spec.max_range))

    captured = []
    original = scan_stages.apply_effects

    def capture(points, beam, effects, generator, **_):  # the scan alone: keep what the effects would get
        captured.append((points, beam))
        return points

    def scan_alone():
        captured.clear()
        scan_stages.apply_effects = capture
        try:
            return scan_stages.scan_buffers(buffers, config, frame_rng(0, 0))
        finally:
            scan_stages.apply_effects = original

    def effects_on_every_chunk(effects):  # as the pipeline applies them: chunk after chunk of the scan
        rng = np.random.default_rng(0)
        return sum(len(original(points, beam, effects, rng)) for points, beam in chunks)

    scan_alone()
    chunks = list(captured)
    n_points = sum(len(p) for p, _ in chunks)
    rounds = 5
    with tempfile.TemporaryDirectory() as tmp:
        path = model_file(Path(tmp))
        sections = variants(path, config.sensor.spec.channels)
        effects = {name: effects_from_dict(section, config.sensor.spec) for name, section in sections.items()}
        kept = {name: effects_on_every_chunk(e) for name, e in effects.items()}  # warms: model files read, rasters built
        on = dataclasses.replace(config, effects=effects["all"])
        timed = {"scan alone": scan_alone, "scan + all effects": lambda: scan_stages.scan_buffers(buffers, on, frame_rng(0, 0))}
        timed |= {name: (lambda e=e: effects_on_every_chunk(e)) for name, e in effects.items()}
        best = interleaved(timed, rounds)
    t_scan = best["scan alone"]
    rows = [{"effects": "none (scan alone)", "points": n_points, "time_s": t_scan, "percent_of_scan": 0.0}]
    rows += [{"effects": name, "points": kept[name], "time_s": best[name], "percent_of_scan": 100 * best[name] / t_scan} for name in effects]
    all_row = next(r for r in rows if r["effects"] == "all")
    notes = {
        "command": "python benchmarks/bench_effects.py" + (" --small" if args.small else ""),
        "job": "the default job (python run.py)" + (" at sensor.sampling_factor=0.1" if args.small else ""),
        "scan_points": n_points, "scan_chunks": len(chunks), "rounds": rounds,
        "scan_buffers_all_effects_s": best["scan + all effects"],
        "end_to_end_added_percent": 100 * (best["scan + all effects"] - t_scan) / t_scan,
        "all_effects_percent_of_scan": all_row["percent_of_scan"], "target_percent": 10.0,
        "models": "fitted on the nuScenes HDL-32E sweep" if path else "datasheet threshold and constant sigma (real sweep absent)",
        "load_average_1min": os.getloadavg()[0],
    }
    name = "effects" + ("_small" if args.small else "")
    report(name, rows, args.out, notes)
    print(f"all effects together: {all_row['percent_of_scan']:.1f} % of the scan ({'within' if all_row['percent_of_scan'] <= 10 else 'OVER'} the 10 % target); "
          f"end to end: {notes['end_to_end_added_percent']:.1f} %")


if __name__ == "__main__":
    main()
