"""``output.formats: [railway_layout]``: the ground-truth layout of a railway frame as JSON. Pure.

For parameter-extraction models (support positions, wire geometry) beside the labeled points:
``OUT/railway_layout/NNNNNN.json`` per frame, world coordinates in metres::

    {"frame": 3, "layout": "single", "rail_top_height": 0.742,
     "centreline": [[x, y, z], ...],              # the track alignment at formation level, every <= 1 m
     "tracks": [{"index": 0, "offset": 0.0, "double_contact": false}],
     "supports": [{"index", "chainage", "type": "mast" | "gantry", "stagger",
                   "masts": [{"side", "kind", "base": [x, y, z], "height"}],
                   "cantilevers": [{"track", "attach": [x, y, z] (contact wire), "arm_length"}]}],
     "wires": [{"class", "kind", "run", "span", "start", "end", "sag", "length", "tension_length",
                "polyline": [[x, y, z], ...]}],  # every <= 1 m along the sag parabola
     "droppers": [{"run", "span", "lower": [[x, y, z]...], "upper": [...]}],
     "overlaps": [{"span", "track", "ending", "starting"}],   # runs handing over (catenary.tension_length)
     "signals": [{"base": [x, y, z], "height"}]}   # with scene.trackside.signal_spacing

``tension_length`` is the length of the wire's run from its first support to its last: the whole line,
or its tension section (run ``t<i>s<m>``) with ``catenary.tension_length``. With ``catenary.steady_arms``
each cantilever also gives its ``steady_arm_length``. The layout is the one the frame's scene was built from,
read from the frame's :class:`~bpy_pipeline.builders.base.BuildResult` (``frame.scene.scene``, signals
included): the writer draws nothing, so a change to the builder's draws cannot part the file from the scene.
The layout object gives its cantilevers itself (``RailwayLayout.support_cantilevers``): this writer imports
nothing of the railway builder (io sits below the builders).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from .atomic import atomic_write
from .writers import Writer, register_writer

POLYLINE_STEP = 1.0  # m between written wire and centreline points


def _xyz(p) -> list[float]:
    return [round(float(v), 5) for v in np.asarray(p, float).reshape(3)]


def layout_record(layout, params) -> dict:
    """The JSON-ready ground truth of a :class:`~bpy_pipeline.builders.railway.layout.RailwayLayout`
    planned from the ``RailwayScene`` ``params`` (see the module docstring)."""
    alignment, section, cat = layout.alignment, layout.section, params.catenary
    s = np.linspace(0.0, alignment.length, max(2, int(np.ceil(alignment.length / POLYLINE_STEP)) + 1))
    contact_z = section.rail_top + cat.contact_wire_height
    supports = []
    for support in layout.supports:
        frame = np.asarray(support.frame, float)
        world = lambda y, z: frame[:3, :3] @ np.array([0.0, y, z]) + frame[:3, 3]  # noqa: E731
        masts = [{"side": m.side, "kind": m.kind, "base": _xyz(world(m.lateral, m.base)), "height": round(m.top - m.base, 5)} for m in support.masts]
        arms = [{"track": c.track, "attach": _xyz(world(c.attach_y, contact_z)), "arm_length": round(c.arm_length, 5)}
                | ({"steady_arm_length": round(min(cat.steady_arm_length, c.arm_length - 0.2), 5)} if cat.steady_arms else {})
                for c in layout.support_cantilevers(support, params)]
        supports.append({"index": support.index, "chainage": round(support.chainage, 5), "type": "gantry" if support.gantry else "mast",
                         "stagger": round(support.stagger, 5), "masts": masts, "cantilevers": arms})
    runs: dict[tuple, float] = {}
    for wire in layout.wires:
        runs[(wire.kind, wire.run)] = runs.get((wire.kind, wire.run), 0.0) + wire.length
    wires = []
    for wire in layout.wires:
        t = np.linspace(0.0, 1.0, max(2, int(np.ceil(wire.length / POLYLINE_STEP)) + 1))
        wires.append({"class": wire.class_name, "kind": wire.kind, "run": wire.run, "span": wire.span, "start": _xyz(wire.start), "end": _xyz(wire.end),
                      "sag": round(wire.sag, 6), "length": round(wire.length, 5), "tension_length": round(runs[(wire.kind, wire.run)], 5),
                      "polyline": [_xyz(p) for p in wire.points_at(t)]})
    droppers = [{"run": d.run, "span": d.span, "lower": [_xyz(p) for p in d.lower], "upper": [_xyz(p) for p in d.upper]} for d in layout.droppers]
    return {
        "layout": layout.layout,
        "rail_top_height": round(float(section.rail_top), 6),
        "centreline": [_xyz(p) for p in alignment.point(s)],
        "tracks": [{"index": i, "offset": round(float(o), 5), "double_contact": bool(layout.double_contact[i])} for i, o in enumerate(section.offsets)],
        "supports": supports,
        "wires": wires,
        "droppers": droppers,
        "overlaps": [{"span": o.span, "track": o.track, "ending": o.ending, "starting": o.starting} for o in layout.overlaps],
    }


def _check(config) -> None:
    if config.scene.builder != "railway":
        raise InputError(f"output.formats: railway_layout writes the layout of a railway scene, scene.builder is {config.scene.builder}")


def _write(frame, out: Path) -> list[Path]:
    layout = frame.scene.scene  # the layout the frame's scene was built from (frame.scene: its BuildResult)
    if layout is None or layout.signals is None:
        raise InputError(f"output.formats: railway_layout writes the layout of a railway the run built; frame {frame.index} scans a scene it did not build")
    record = {"frame": frame.index} | layout_record(layout, frame.config.scene.params)
    record["signals"] = [{"base": _xyz(f[:3, 3]), "height": frame.config.scene.params.trackside.signal_height} for f in layout.signals]
    path = Path(out) / "railway_layout" / f"{frame.stem}.json"
    with atomic_write(path) as tmp:
        tmp.write_text(json.dumps(record, separators=(",", ":")))
    return [path]


register_writer("railway_layout", Writer(_write, _check))
