"""Road vehicles' and two-wheelers' meshes in their own frame (x forward, y left, z up, origin on the ground). Pure numpy.

Shared by the street builder (:mod:`bpy_pipeline.builders.street.layout`, its road users) and the
object catalogue (:mod:`.objects`, a cyclist is a rider on :func:`two_wheeler_parts`).
"""

from __future__ import annotations

import numpy as np

from . import primitives
from .primitives import beam_mesh, box_mesh, quads_mesh, wheels_mesh

Mesh = tuple[np.ndarray, np.ndarray]  # vertices (n, 3) float64, triangles (m, 3) int32


def vehicle_parts(kind: str, size) -> dict[str, Mesh]:
    """``{"body", "glass", "tyres"}`` meshes of a vehicle of ``kind`` and ``size`` (length, width, height), own frame.

    Every part lies within the box ``[-L/2, L/2] x [-W/2, W/2] x [0, H]``. Car: a lower body to the
    belt line and a narrower cabin; van: a cabin over nearly its length; truck: a cab and a cargo
    box; bus: one box with a window band. Glass sits 1 cm outside the body it covers.
    """
    body, glass, tyres = _outline(kind, size)
    bounds = np.array(body, float)
    return {"body": primitives.boxes_mesh(bounds[:, 0::2], bounds[:, 1::2]), "glass": quads_mesh(glass), "tyres": tyres}


def _outline(kind: str, size) -> tuple[list, list, Mesh]:
    """What :func:`vehicle_parts` makes its meshes of: the body's boxes ``[(x0, x1, y0, y1, z0, z1)]`` and the glass quads
    ``[(4 corners (3,))]`` (m, Python floats) and the tyres' mesh."""
    L, W, H = (float(s) for s in size)
    x0, x1, y = -L / 2, L / 2, W / 2
    radius = {"car": 0.31, "van": 0.34, "truck": 0.5, "bus": 0.5}[kind]
    clearance = 0.55 * radius
    tyre_w = 0.2 if kind in ("car", "van") else 0.3
    axles = {"car": (0.33, -0.33), "van": (0.34, -0.34), "truck": (0.38, -0.3), "bus": (0.36, -0.28)}[kind]
    tyres = wheels_mesh([(a * L, side * (y - 0.02 - tyre_w / 2)) for a in axles for side in (-1, 1)], radius, tyre_w)
    body, glass = [], []  # boxes (x0, x1, y0, y1, z0, z1), quads (4 corners)
    if kind == "car":
        belt = 0.58 * H
        body.append((x0, x1, -y, y, clearance, belt))
        cx0, cx1, cy = x0 + 0.26 * L, x1 - 0.3 * L, y - 0.08
        body.append((cx0, cx1, -cy, cy, belt, H))
        glass.append(((cx1 + 0.01, -cy, belt + 0.05), (cx1 + 0.01, cy, belt + 0.05), (cx1 + 0.01, cy, H - 0.05), (cx1 + 0.01, -cy, H - 0.05)))
        for side in (-1, 1):
            gy = side * (cy + 0.01)
            glass.append(((cx0 + 0.1, gy, belt + 0.05), (cx1 - 0.1, gy, belt + 0.05), (cx1 - 0.1, gy, H - 0.06), (cx0 + 0.1, gy, H - 0.06)))
    elif kind == "van":
        hood = x1 - 0.14 * L
        body.append((hood, x1, -y, y, clearance, 0.5 * H))
        body.append((x0, hood, -y, y, clearance, H))
        glass.append(((hood + 0.01, -y + 0.1, 0.55 * H), (hood + 0.01, y - 0.1, 0.55 * H), (hood + 0.01, y - 0.1, 0.92 * H),
                      (hood + 0.01, -y + 0.1, 0.92 * H)))
    elif kind == "truck":
        cab = x1 - 2.2
        body.append((cab, x1, -y + 0.05, y - 0.05, clearance, 0.92 * H))
        body.append((x0, cab - 0.3, -y, y, clearance + 0.4, H))
        body.append((x0 + 0.2, cab, -0.4, 0.4, clearance, clearance + 0.4))  # chassis under the cargo box
        glass.append(((x1 + 0.01, -y + 0.2, 0.55 * H), (x1 + 0.01, y - 0.2, 0.55 * H), (x1 + 0.01, y - 0.2, 0.85 * H),
                      (x1 + 0.01, -y + 0.2, 0.85 * H)))
    else:  # bus
        body.append((x0, x1, -y, y, clearance, H))
        for side in (-1, 1):
            gy = side * (y + 0.01)
            glass.append(((x0 + 0.5, gy, 0.4 * H), (x1 - 0.5, gy, 0.4 * H), (x1 - 0.5, gy, 0.85 * H), (x0 + 0.5, gy, 0.85 * H)))
        glass.append(((x1 + 0.01, -y + 0.1, 0.3 * H), (x1 + 0.01, y - 0.1, 0.3 * H), (x1 + 0.01, y - 0.1, 0.9 * H), (x1 + 0.01, -y + 0.1, 0.9 * H)))
    return body, glass, tyres


PLATE_SIZE = (0.52, 0.11)  # m: an EU licence plate (520 x 110 mm); geometry/objects.py's cars use it too
LAMP = (0.2, 0.07)  # m: a lamp's width and height


def vehicle_fittings(body: np.ndarray, length: float) -> dict[str, Mesh]:
    """``{"plates", "lights"}`` meshes of a vehicle whose :func:`vehicle_parts` body has vertices ``body`` (n, 3) and whose
    length is ``length`` (m), own frame: a licence plate centred on each end (5 mm proud) and a lamp in each corner of each
    end (1 cm proud), on the body face that ends the vehicle there (a car's lower body, a van's hood and box, a truck's
    cab and cargo box, a bus), read from the body's vertices on that end.

    Each end's face spans heights ``z0 .. z1``: the plate's lower edge is ``min(0.2 (z1 - z0), 0.25)`` m above
    ``z0``, the lamps' centres ``min(0.6 (z1 - z0), 0.55)`` m, 0.15 m in from the face's sides. These parts stand the
    millimetres proud of the box ``[-L/2, L/2] x ...`` that holds the other parts.
    """
    plates, lights = [], []  # (x0, x1, y0, y1, z0, z1) of each box
    for out in (1.0, -1.0):  # front, then rear
        x = out * length / 2
        face = body[np.abs(body[:, 0] - x) <= 1e-9]
        _end_fittings(out, x, face[:, 2].min(), face[:, 2].max(), np.abs(face[:, 1]).max(), plates, lights)
    bounds = np.array(plates + lights)  # every box at once: each box's vertices are its own products
    vertices, triangles = primitives.boxes_mesh(bounds[:, 0::2], bounds[:, 1::2])
    cut = 8 * len(plates)  # vertices of the plates; 12 triangles per 8
    return {"plates": (vertices[:cut], triangles[: 12 * len(plates)]), "lights": (vertices[cut:], triangles[12 * len(plates) :] - cut)}


def _fitting_boxes(body: list, length: float) -> list[tuple[float, ...]]:
    """The boxes ``(x0, x1, y0, y1, z0, z1)`` of :func:`vehicle_fittings` (the plates, then the lamps) from the body's boxes
    (:func:`_outline`), in Python floats: a box's vertex coordinates are :func:`~.primitives.boxes_mesh`'s numbers
    (``-+0.5 (high - low) + (low + high) / 2``), so each end's face is the same as read from the body's vertices."""
    corners = [[(-0.5 * (hi - lo) + (lo + hi) / 2, 0.5 * (hi - lo) + (lo + hi) / 2) for lo, hi in ((x0, x1), (y0, y1), (z0, z1))]
               for x0, x1, y0, y1, z0, z1 in body]  # per box: its (low, high) vertex coordinate along x, y and z
    plates, lights = [], []
    for out in (1.0, -1.0):  # front, then rear
        x = out * length / 2
        face = [(ys, zs) for xs, ys, zs in corners if abs(xs[0] - x) <= 1e-9 or abs(xs[1] - x) <= 1e-9]
        z0, z1 = min(zs[0] for _, zs in face), max(zs[1] for _, zs in face)
        _end_fittings(out, x, z0, z1, max(abs(y) for ys, _ in face for y in ys), plates, lights)
    return plates + lights


def _end_fittings(out: float, x: float, z0: float, z1: float, half: float, plates: list, lights: list) -> None:
    """The boxes ``(x0, x1, y0, y1, z0, z1)`` of one end's plate and two lamps, appended to ``plates`` and ``lights``: the end
    faces ``out`` (1 front, -1 rear) at ``x`` (m), its face spans heights ``z0 .. z1`` and ``-half .. half`` across."""
    (pw, ph), (lw, lh) = PLATE_SIZE, LAMP
    low = z0 + min(0.2 * (z1 - z0), 0.25)
    plates.append((*sorted((x, x + out * 0.005)), -pw / 2, pw / 2, low, low + ph))
    mid = z0 + min(0.6 * (z1 - z0), 0.55)
    for side in (-1.0, 1.0):
        c = side * (half - 0.15)
        lights.append((*sorted((x - out * 0.06, x + out * 0.01)), c - lw / 2, c + lw / 2, mid - lh / 2, mid + lh / 2))


def vehicles_parts(kinds, sizes, fittings: bool = True) -> list[dict[str, Mesh]]:
    """Each vehicle's :func:`vehicle_parts` (with ``fittings``, merged with its :func:`vehicle_fittings`), the same
    numbers: every vehicle's boxes in one :func:`~.primitives.boxes_mesh`, every glass quad in one array."""
    outlines = [_outline(kind, size) for kind, size in zip(kinds, sizes)]
    boxes, quads, counts = [], [], []  # counts: (body boxes, fitting boxes, glass quads) per vehicle
    for (body, glass, _), size in zip(outlines, sizes):
        extra = _fitting_boxes(body, float(size[0])) if fittings else []
        boxes += body + extra
        quads += glass
        counts.append((len(body), len(extra), len(glass)))
    if not outlines:
        return []
    bounds = np.array(boxes, float)
    corners = primitives.boxes_mesh(bounds[:, 0::2], bounds[:, 1::2])[0].reshape(-1, 8, 3)
    glass = np.asarray(quads, float).reshape(-1, 4, 3)
    out, at, quad_at = [], 0, 0
    for (_, _, tyres), (n_body, n_extra, n_glass) in zip(outlines, counts):
        parts = {"body": (corners[at : at + n_body].reshape(-1, 3), _box_triangles(n_body)),
                 "glass": (glass[quad_at : quad_at + n_glass].reshape(-1, 3), _quad_triangles(n_glass)), "tyres": tyres}
        if n_extra:
            plates = corners[at + n_body : at + n_body + 2].reshape(-1, 3)
            lights = corners[at + n_body + 2 : at + n_body + n_extra].reshape(-1, 3)
            parts |= {"plates": (plates, _box_triangles(2)), "lights": (lights, _box_triangles(n_extra - 2))}
        out.append(parts)
        at += n_body + n_extra
        quad_at += n_glass
    return out


def _box_triangles(count: int) -> np.ndarray:
    """``(12 count, 3)`` int32: :func:`~.primitives.boxes_mesh`'s triangles of ``count`` boxes."""
    return (primitives.BOX_TRIANGLES + 8 * np.arange(count, dtype=np.int32)[:, None, None]).reshape(-1, 3).astype(np.int32)


def _quad_triangles(count: int) -> np.ndarray:
    """``(2 count, 3)`` int32: :func:`~.primitives.quads_mesh`'s triangles of ``count`` quads."""
    return (np.array([[0, 1, 2], [0, 2, 3]], np.int32)[None] + 4 * np.arange(count, dtype=np.int32)[:, None, None]).reshape(-1, 3).astype(np.int32)


def two_wheeler_parts(kind: str, size) -> dict[str, Mesh]:
    """``{"frame", "wheels"}`` of a bicycle or motorcycle of ``size`` (length, width, height of the whole with its rider).

    The saddle's top is at :func:`saddle_height`, its centre at x = -0.1 L; the rider sits there.
    """
    L = float(size[0])
    radius = 0.34 if kind == "bicycle" else 0.3
    width = 0.04 if kind == "bicycle" else 0.12
    front, rear = L / 2 - radius, -L / 2 + radius
    wheels = wheels_mesh([(front, -width / 2), (rear, -width / 2)], radius, width)
    seat = saddle_height(kind, size)
    hub = radius
    if kind == "bicycle":
        t = 0.035
        saddle = (-0.1 * L, 0.0, seat - 0.04)
        bar = (front - 0.08, 0.0, seat + 0.1)
        crank = (0.02 * L, 0.0, radius)
        frame = [beam_mesh((rear, 0, hub), saddle, t), beam_mesh((rear, 0, hub), crank, t), beam_mesh(crank, saddle, t),
                 beam_mesh(crank, (front - 0.15, 0, seat - 0.05), t), beam_mesh(saddle, (front - 0.15, 0, seat - 0.05), t),
                 beam_mesh((front, 0, hub), bar, t), box_mesh(bar[0] - 0.03, bar[0] + 0.03, -0.28, 0.28, bar[2] - 0.015, bar[2] + 0.015),
                 box_mesh(saddle[0] - 0.13, saddle[0] + 0.1, -0.07, 0.07, seat - 0.04, seat)]
    else:
        frame = [box_mesh(rear + 0.15, front - 0.2, -0.18, 0.18, radius * 0.6, seat - 0.12),  # engine and tank
                 box_mesh(-0.1 * L - 0.3, -0.1 * L + 0.2, -0.15, 0.15, seat - 0.12, seat),  # seat
                 beam_mesh((front, 0, hub), (front - 0.2, 0, seat + 0.2), 0.06),
                 box_mesh(front - 0.24, front - 0.16, -0.38, 0.38, seat + 0.18, seat + 0.24)]
    return {"frame": primitives.merge(frame), "wheels": wheels}


def saddle_height(kind: str, size) -> float:
    """Height (m) of the saddle's top of a two-wheeler of ``size``: the rider's seat."""
    return (0.5 if kind == "bicycle" else 0.45) * float(size[2])
