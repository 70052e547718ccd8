"""Run every benchmark in turn: python benchmarks/run_all.py [--small] [--out DIR]."""

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = [
    "bench_export.py",
    "bench_scan.py",
    "bench_caster_reuse.py",
    "bench_workers.py",
    "bench_sensor_rate.py",
    "bench_call_cpu.py",
    "bench_thread_time.py",
    "bench_default_job.py",
    "bench_effects.py",
    "bench_fitting.py",
    "bench_realism.py",
    "bench_intensity.py",
    "bench_weather.py",
    "bench_materials.py",
    "bench_divergence.py",
    "bench_mirrors.py",
    "bench_railway_catenary.py",
    "bench_railway_lod.py",
    "bench_railway.py",
    "bench_railway_assets.py",
    "bench_railway_mobile.py",
    "bench_scenes.py",
    "bench_raycasters.py",
    "bench_scaling.py",
    "bench_far_origin.py",
    "bench_tls_memory.py",
    "bench_dataset.py",
    "bench_reference_jobs.py",
    "bench_street.py",
    "bench_mixing.py",
    "bench_convert.py",
    "bench_match.py",
    "bench_real_twins.py",
    "bench_writers.py",
    "bench_population.py",
    "bench_sim2real.py",
    "bench_sim2real_match.py",
    "bench_speed.py",
    "bench_stage_parts.py",
    "bench_weather_particles.py",
    "bench_layout_seeds.py",
    "bench_rangenet.py",
    "bench_rangenet_ablation.py",
]

if __name__ == "__main__":
    for name in BENCHMARKS:
        print(f"== {name}", flush=True)
        subprocess.run([sys.executable, str(HERE / name), *sys.argv[1:]], check=True)
