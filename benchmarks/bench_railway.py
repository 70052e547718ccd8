"""Railway scenes end to end, config to files: the thesis's scene size and a 1 km two-track line.

``thesis``: one track, 300 m on a 1.1 km radius curve, supports every 50 +- 5 m with the full
catenary (contact, messenger, feeder and earth wires, droppers), one station scanned by the
thesis's terrestrial scanner at its nominal 0.05 x 0.05 deg (23.0 M rays), written as PLY and
SemanticKITTI with a preview. The thesis needed about 4 minutes per scene (140 in 8-10 h);
the reference is that figure (it cannot be rerun here), the target under 20 s on two cores.
``thesis_divergence``: the same scene and scanner with beam divergence on (0.3 mrad, 7 sub-rays a beam,
first return) besides the preset's 2 mm noise and range-dependent drop (on in every scenario: presets
are realistic by default); ``slowdown_vs_thesis_scene`` is its wall time over the plain scenario's (``scan_slowdown_...``: scan times).
``line_1km``: two tracks, 1 km, 20 spans (48 +- 2 m), five stations (frames = stations), the
scanner at 0.1 deg (5.8 M rays a station); build, export, scan and write time per station.
Each runs ``python run.py --config FILE`` in a subprocess: wall time includes Python start-up
and the bpy import; cpu_s is the CPU time the run used (both cores), load_before the machine's
load average when it started (other work on a shared machine stretches the wall time).
Results: benchmarks/results/railway.json.
Run: python benchmarks/bench_railway.py [--small]
"""

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from common import ROOT, arguments, report

THESIS_SECONDS = 240.0  # about 4 minutes a scene (section 4.1: 140 simulations in 8 to 10 hours)


def scenario(small: bool) -> dict:
    thesis = {
        "scene": {
            "builder": "railway",
            "track": {"start": [-150, 0, 0], "mid": [0, 10, 0], "end": [150, 0, 0]},
            "supports": {"span": 50.0, "span_jitter": 5.0},
        },
        "sensor": {"preset": "railway_tls", "sampling_factor": 0.1 if small else 1.0},
        "output": {"formats": ["ply", "semantickitti"], "preview": True},
    }
    length = 200 if small else 1000
    line = {
        "frames": 2 if small else 5,
        "scene": {
            "builder": "railway",
            "track": {"start": [0, 0, 0], "mid": [length / 2, 0, 0], "end": [length, 0, 0], "tracks": 2},
            "supports": {"span": 48.0, "span_jitter": 2.0, "layout": "both_sides"},
            "stations": {"count": 2 if small else 5},
        },
        "sensor": {"preset": "railway_tls", "sampling_factor": 0.1 if small else 0.5},
        "output": {"formats": ["ply", "semantickitti"], "preview": True},
    }
    divergence = json.loads(json.dumps(thesis))  # the thesis's scene with the preset's noise and drop and a 0.3 mrad footprint
    divergence["sensor"]["divergence"] = {"mrad": 0.3, "rays": 7, "return": "first"}
    return {"thesis": thesis, "thesis_divergence": divergence, "line_1km": line}


def run(config: dict) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "config.yaml"
        path.write_text(yaml.safe_dump(config))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        load = os.getloadavg()[0]
        start = time.perf_counter()
        subprocess.run([sys.executable, str(ROOT / "run.py"), "--config", str(path), "--out", str(Path(tmp) / "out")], check=True, capture_output=True)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        from bpy_pipeline.io import read_dataset

        manifest = read_dataset(Path(tmp) / "out")  # the manifest with its frames' records
        size = sum(p.stat().st_size for p in (Path(tmp) / "out").rglob("*") if p.is_file())
    frames = manifest["frames"]
    totals = {k: sum(f["timings_s"].get(k, 0.0) for f in frames) for k in ("build", "export", "scan", "effects", "write")}
    rays = manifest["sensor"].get("rays") or manifest["sensor"].get("rays_per_frame")
    return {
        "wall_s": wall, "cpu_s": cpu, "load_before": load, **{f"{k}_s": v for k, v in totals.items()}, "startup_s": wall - sum(totals.values()),
        "frames": len(frames), "rays_per_frame": rays, "points": sum(f["points"] for f in frames),
        "triangles_max": max(f["triangles"] for f in frames), "output_mb": size / 1e6,
        "per_frame": [{"station": f.get("station"), **f["timings_s"], "points": f["points"], "triangles": f["triangles"]} for f in frames],
    }


def main():
    args = arguments(__doc__)
    rows, notes = [], {"thesis_seconds_per_scene": THESIS_SECONDS, "configs": scenario(args.small)}
    for name, config in scenario(args.small).items():
        result = run(config)
        per_frame = result.pop("per_frame")
        notes[f"{name}_frames"] = per_frame
        row = {"scenario": name, **result}
        if name.startswith("thesis"):
            row["speedup_vs_thesis"] = THESIS_SECONDS / result["wall_s"]
        if name == "thesis_divergence":
            row["slowdown_vs_thesis_scene"] = result["wall_s"] / rows[0]["wall_s"]
            row["scan_slowdown_vs_thesis_scene"] = result["scan_s"] / rows[0]["scan_s"]
        rows.append(row)
    report("railway" + ("_small" if args.small else ""), rows, args.out, notes)


if __name__ == "__main__":
    main()
