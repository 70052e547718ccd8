"""Shared benchmark plumbing: timing, a printed table, and JSON results under benchmarks/results/."""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"


def arguments(description: str) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--small", action="store_true", help="a small size, for CI (checks the benchmark runs)")
    p.add_argument("--out", type=Path, default=RESULTS, help="folder for the JSON results")
    return p.parse_args()


def run_ego_job(frames: int, out: Path) -> int:
    """``examples/street/ego_hdl64e.yaml`` for ``frames`` frames into ``out`` through the command line, in this process
    (the ``bpy_pipeline`` first on ``sys.path``, from the current folder); returns its exit code."""
    from bpy_pipeline import cli

    sys.argv = ["run.py", "--config", "examples/street/ego_hdl64e.yaml", "--frames", str(frames), "--out", str(out)]
    try:
        cli.main()
    except SystemExit as stop:
        return int(stop.code or 0)
    return 0


def best_of(fn, repeat: int = 3) -> float:
    """Smallest wall time of ``repeat`` calls of ``fn()``, seconds (shared machines are noisy)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def report(name: str, rows: list[dict], out: Path, notes: dict | None = None) -> None:
    """Print ``rows`` as a table and write them to ``out/name.json`` with the machine's facts."""
    keys = list(dict.fromkeys(k for row in rows for k in row))
    widths = {k: max(len(k), *(len(_fmt(r.get(k))) for r in rows)) for k in keys}
    print(f"\n{name}")
    print("  ".join(k.ljust(widths[k]) for k in keys))
    for row in rows:
        print("  ".join(_fmt(row.get(k)).ljust(widths[k]) for k in keys))
    try:
        import bpy

        blender = bpy.app.version_string
    except ImportError:
        blender = None
    import os

    payload = {"benchmark": name, "rows": rows, "notes": notes or {},
               "machine": {"cores": os.cpu_count(), "python": platform.python_version(), "blender": blender}}
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps(payload, indent=2) + "\n")


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return "" if value is None else str(value)
