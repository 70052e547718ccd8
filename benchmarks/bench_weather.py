"""Cost and effect of the weather (lidar/effects/weather/) beside the clear scan, measured in the same run.

An HDL-64E (full 0.17 deg columns, its realistic profile) in a street of walls at 8-110 m over a road;
``bpy_pipeline.api.scan`` (trace, effects, records) timed clear and with each weather, rounds taken
in turn, best of five each; the cost is the weather scan's time over the clear scan's. Beside it,
what the weather did: the share of the clear scan's returns still seen, the clutter points of the
weather's class and their median range. Pure: no Blender.
Run: python benchmarks/bench_weather.py [--small]
"""

import math
import time

import numpy as np
from common import arguments, report

from bpy_pipeline.api import scan
from bpy_pipeline.labels import load_class_table

TABLE = load_class_table()


def street() -> dict:
    def quad(centre, normal_az, width, height, refl, cls):
        a = math.radians(normal_az)
        t = np.array([-math.sin(a), math.cos(a), 0.0])
        c = np.asarray(centre, float)
        v = np.array([c - t * width / 2, c + t * width / 2, c + t * width / 2 + [0, 0, height], c - t * width / 2 + [0, 0, height]])
        return (v, np.array([[0, 1, 2], [0, 2, 3]]), cls, "diffuse", refl)

    meshes = {"road": (np.array([[-150, -150, -1.73], [150, -150, -1.73], [150, 150, -1.73], [-150, 150, -1.73]], float), np.array([[0, 1, 2], [0, 2, 3]]),
                       "road", "diffuse", 0.1)}
    for k, (dist, refl) in enumerate([(8, 0.3), (15, 0.6), (25, 0.2), (40, 0.5), (60, 0.8), (85, 0.4), (110, 0.7)]):
        az = k * 51.0
        meshes[f"wall{k}"] = quad([dist * math.cos(math.radians(az)), dist * math.sin(math.radians(az)), -1.73], az, dist * 0.6, 12.0, refl, "wall")
    return meshes


def main() -> None:
    args = arguments(__doc__)
    sensor = {"preset": "hdl64e", "horizontal_resolution_deg": 0.68 if args.small else 0.17}
    weathers = {
        "clear": {},
        "fog 200 m": {"fog": {"visibility": 200}},
        "fog 50 m": {"fog": {"visibility": 50}},
        "fog 20 m": {"fog": {"visibility": 20}},
        "rain 5 mm/h": {"rain": {"rate": 5}},
        "rain 25 mm/h": {"rain": {"rate": 25}},
        "snow 0.5 mm/h": {"snow": {"rate": 0.5}},
        "snow 2.5 mm/h": {"snow": {"rate": 2.5}},
        "snow 2.5 mm/h, wet ground": {"snow": {"rate": 2.5, "wet_ground": True}},
    }
    meshes = street()
    rounds = 2 if args.small else 5
    times = {name: [] for name in weathers}
    clouds = {}
    scan(meshes, sensor, effects={"weather": {"fog": {"visibility": 50}}})  # warm up (compiled kernels, the fog table)
    for _ in range(rounds):
        for name, weather in weathers.items():
            start = time.perf_counter()
            clouds[name] = scan(meshes, sensor, effects={"weather": weather} if weather else {})
            times[name].append(time.perf_counter() - start)
    clear = clouds["clear"]
    rows = []
    for name, weather in weathers.items():
        points = clouds[name]
        kind = next(iter(weather), None)
        cls = {"fog": "fog", "rain": "rain", "snow": "snow"}.get(kind)
        clutter = points["semantic"] == TABLE.id_of(cls) if cls else np.zeros(len(points), bool)
        rows.append({
            "weather": name,
            "scan s": round(min(times[name]), 4),
            "cost over clear": round(min(times[name]) / min(times["clear"]), 3),
            "added us per return": round((min(times[name]) - min(times["clear"])) / len(clear) * 1e6, 2),
            "returns": len(points),
            "kept share": round(len(points) / len(clear), 4),
            "clutter points": int(clutter.sum()),
            "clutter median m": round(float(np.median(points["range"][clutter])), 2) if clutter.any() else None,
            "hard max m": round(float(points["range"][~clutter].max()), 1),
        })
    report("weather", rows, args.out, {"sensor": sensor, "rounds": rounds, "clear returns": len(clear),
                                       "method": "api.scan timed clear and with each weather in turn, best of the rounds; cost = weather scan / clear scan"})


if __name__ == "__main__":
    main()
