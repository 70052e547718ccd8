"""Cost of the sensor effects beside the scan of the default job, measured in the same run.

Builds and exports the default job's scene (python run.py without --config), times
``pipeline.scan_buffers`` with every effect off (the scan alone: trace, records, labels), keeps
the points and beam facts it hands to ``effects.apply_effects``, and times ``apply_effects`` on
them with each effect, and with all of them together: the lidar-equation intensity, the
fitted (range, incidence) drop table, the noise table, a per-ring bias and angular jitter
(models fitted on ../shared/real_scans/nuscenes_hdl32e_sweep.bin; the datasheet threshold and a
constant sigma stand in when it is absent). Target: all together add at most 10 % to the scan.
Best of five; the end-to-end check times scan_buffers with all effects on as well.
Run: python benchmarks/bench_effects.py [--small]
"""

import dataclasses
import tempfile
from pathlib import Path

import numpy as np
from common import ROOT, arguments, best_of, report

import bpy  # noqa: E402,F401

from bpy_pipeline import pipeline  # noqa: E402
from bpy_pipeline.config import effects_from_dict, load_config  # noqa: E402
from bpy_pipeline.export import export_scene  # noqa: E402
from bpy_pipeline.labels import load_class_table  # noqa: E402
from bpy_pipeline.lidar import fitting  # noqa: E402
from bpy_pipeline.lidar.effects import write_model_file  # noqa: E402
from bpy_pipeline.scenes import build_scene  # noqa: E402

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


def main():
    args = arguments(__doc__)
    overrides = ["sensor.sampling_factor=0.1"] if args.small else []
    config = load_config(None, overrides)
    rng = pipeline.frame_rng(config.seed, 0)
    build_scene(config.scene, rng)
    buffers = export_scene(load_class_table(), (), keep_within=(pipeline.sensor_pose(config)[:3, 3], config.sensor.spec.max_range))

    captured = {}
    original = pipeline.apply_effects

    def capture(points, beam, effects, generator):
        captured["points"], captured["beam"] = points, beam
        return original(points, beam, effects, generator)

    pipeline.apply_effects = capture
    try:
        t_buffers_off = best_of(lambda: pipeline.scan_buffers(buffers, config, pipeline.frame_rng(0, 0)), 5)
    finally:
        pipeline.apply_effects = original
    points, beam = captured["points"], captured["beam"]
    t_off = best_of(lambda: original(points, beam, config.effects, np.random.default_rng(0)), 5)  # copies the records only
    t_scan = t_buffers_off - t_off
    rows = [{"effects": "none (scan alone)", "points": len(points), "time_s": t_scan, "percent_of_scan": 0.0}]
    with tempfile.TemporaryDirectory() as tmp:
        path = model_file(Path(tmp))
        for name, section in variants(path, config.sensor.spec.channels).items():
            effects = effects_from_dict(section, config.sensor.spec)
            original(points, beam, effects, np.random.default_rng(0))  # warm: model file read, table raster built
            t = best_of(lambda: original(points, beam, effects, np.random.default_rng(0)), 5)
            kept = len(original(points, beam, effects, np.random.default_rng(0)))
            rows.append({"effects": name, "points": kept, "time_s": t, "percent_of_scan": 100 * t / t_scan})
        everything = effects_from_dict(variants(path, config.sensor.spec.channels)["all"], config.sensor.spec)
        on = dataclasses.replace(config, effects=everything)
        t_buffers_on = best_of(lambda: pipeline.scan_buffers(buffers, on, pipeline.frame_rng(0, 0)), 5)
    all_row = next(r for r in rows if r["effects"] == "all")
    notes = {
        "command": "python benchmarks/bench_effects.py" + (" --small" if args.small else ""),
        "job": "the default job (python run.py)" + (" at sensor.sampling_factor=0.1" if args.small else ""),
        "rays_scanned_points": len(points),
        "scan_buffers_effects_off_s": t_buffers_off, "scan_buffers_all_effects_s": t_buffers_on,
        "end_to_end_added_percent": 100 * (t_buffers_on - t_buffers_off) / t_scan,
        "all_effects_percent_of_scan": all_row["percent_of_scan"], "target_percent": 10.0,
        "models": "fitted on the nuScenes HDL-32E sweep" if path else "datasheet threshold and constant sigma (real sweep absent)",
    }
    name = "effects" + ("_small" if args.small else "")
    report(name, rows, args.out, notes)
    print(f"all effects together: {all_row['percent_of_scan']:.1f} % of the scan ({'within' if all_row['percent_of_scan'] <= 10 else 'OVER'} the 10 % target); "
          f"end to end: {notes['end_to_end_added_percent']:.1f} %")


if __name__ == "__main__":
    main()
