"""Static layouts of the indoor scenes (an underground car park level, a factory hall) and where their sensor sits. Pure numpy.

Both layouts are boxes (``centre (3,)``, ``half (3,)``, metres, axis-aligned) grouped by class,
plus what placement needs: the floor area inside the walls, obstacles on the floor plan, the
parking bays, the hall's furniture. ``builders/parking/scene.py`` and ``builders/industrial_hall/scene.py`` turn
them into Blender objects; the car placement traces rays against the same meshes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import primitives
from .transforms import pose_matrix

Box = tuple  # (centre (3,), half (3,))


def boxes_mesh(boxes: list) -> tuple[np.ndarray, np.ndarray]:
    """One mesh of axis-aligned boxes ``[(centre, half), ...]``."""
    return primitives.merge([primitives.translated(primitives.box(*(2 * np.asarray(h, float))), c) for c, h in boxes])


# ----------------------------------------------------------------------------- car park
@dataclass
class ParkingLayout:
    """One car-park level (``config.ParkingScene``), the driveway along x through the middle (y = 0).

    low, high : (2,) corners of the floor inside the walls
    boxes : class name -> list of boxes (floor, ceiling, wall, pillar)
    ramp : (vertices, triangles) of the ramp wedge, class ``ramp``
    ramp_footprint : ``(centre (2,), half (2,), yaw)`` of the ramp on the floor plan
    pillars : the pillars' rectangles ``(centre (2,), half (2,), yaw)``
    bays : (b, 3) bay centres x, y and the yaw a car parked nose-in faces (radians)
    bay_size : (width, depth) of a bay
    driveway : (x_start, x_end) the sensor robot drives between, along y = 0
    """

    low: np.ndarray
    high: np.ndarray
    boxes: dict = field(default_factory=dict)
    ramp: tuple | None = None
    ramp_footprint: tuple | None = None
    pillars: list = field(default_factory=list)
    bays: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    bay_size: tuple = (2.5, 5.0)
    driveway: tuple = (0.0, 0.0)

    def meshes(self) -> dict:
        """Class name -> ``(vertices, triangles)`` of the whole static level."""
        out = {name: boxes_mesh(boxes) for name, boxes in self.boxes.items() if boxes}
        if self.ramp is not None:
            out["ramp"] = self.ramp
        return out

    @property
    def obstacles(self) -> list:
        """Floor-plan rectangles no car may overlap: the pillars and the ramp."""
        return self.pillars + ([self.ramp_footprint] if self.ramp_footprint is not None else [])


def parking_layout(p) -> ParkingLayout:
    """The level of ``config.ParkingScene`` ``p``: bays in groups of ``pillar_every`` between pillars, both sides of the driveway."""
    t, slab, h = p.wall_thickness, p.slab_thickness, p.ceiling_height
    half_width = p.driveway_width / 2 + p.bay_depth + 0.5  # 0.5 m behind the bays to the wall
    half = np.array([p.length / 2, half_width])
    layout = ParkingLayout(-half, half.copy(), bay_size=(p.bay_width, p.bay_depth))
    outer = half + t
    layout.boxes["floor"] = [(np.array([0.0, 0.0, -slab / 2]), np.array([outer[0], outer[1], slab / 2]))]
    layout.boxes["wall"] = [
        (np.array([0.0, s * (half[1] + t / 2), h / 2]), np.array([outer[0], t / 2, h / 2])) for s in (-1, 1)
    ] + [(np.array([s * (half[0] + t / 2), 0.0, h / 2]), np.array([t / 2, half[1], h / 2])) for s in (-1, 1)]
    # bays and pillars along x: [pillar gap][group of bays][pillar gap]...
    gap = p.pillar_size + 0.2
    group = p.pillar_every * p.bay_width
    groups = int((p.length - gap) // (group + gap))
    start = -(groups * (group + gap) + gap) / 2
    front = p.driveway_width / 2
    ramp_x0 = half[0] - p.ramp_length if p.ramp_length > 0 else np.inf
    bays, pillars = [], []
    for g in range(groups + 1):
        x_pillar = start + g * (group + gap) + gap / 2
        for side in (-1, 1):
            if side == 1 and x_pillar + p.pillar_size / 2 > ramp_x0:
                continue
            pillars.append((np.array([x_pillar, side * (front + p.pillar_size / 2)]), np.array([p.pillar_size / 2] * 2), 0.0))
        if g == groups:
            break
        for k in range(p.pillar_every):
            x = x_pillar + gap / 2 + (k + 0.5) * p.bay_width
            for side in (-1, 1):
                if side == 1 and x + p.bay_width / 2 > ramp_x0:
                    continue
                bays.append((x, side * (front + p.bay_depth / 2), side * np.pi / 2))
    layout.pillars = pillars
    layout.bays = np.array(bays, float).reshape(-1, 3)
    layout.boxes["pillar"] = [(np.array([c[0], c[1], h / 2]), np.array([p.pillar_size / 2, p.pillar_size / 2, h / 2])) for c, _, _ in pillars]
    ceiling = []
    if p.ramp_length > 0:
        # the ramp rises along +x from the floor to the next level, in the bay row on the +y side;
        # the ceiling is open above it
        y0, y1 = front, half[1]
        rise = h + slab
        profile = np.array([[ramp_x0, 0.0], [half[0], 0.0], [half[0], rise]])  # (x, z), counter-clockwise seen from +y
        layout.ramp = _prism_along_y(profile, y0, y1)
        layout.ramp_footprint = (np.array([(ramp_x0 + half[0]) / 2, (y0 + y1) / 2]), np.array([(half[0] - ramp_x0) / 2, (y1 - y0) / 2]), 0.0)
        ceiling.append(((-outer[0] + ramp_x0) / 2, 0.0, (ramp_x0 + outer[0]) / 2, outer[1]))  # west of the ramp, full width
        ceiling.append(((ramp_x0 + outer[0]) / 2, (-outer[1] + y0) / 2, (outer[0] - ramp_x0) / 2, (y0 + outer[1]) / 2))  # beside it
    else:
        ceiling.append((0.0, 0.0, outer[0], outer[1]))
    layout.boxes["ceiling"] = [(np.array([cx, cy, h + slab / 2]), np.array([hx, hy, slab / 2])) for cx, cy, hx, hy in ceiling]
    layout.driveway = driveway(p)
    return layout


def driveway(p) -> tuple[float, float]:
    """``(x_start, x_end)`` metres of the driveway the sensor robot drives along (y = 0): from 1 m inside the level's
    west wall to 1 m before the ramp (or the east wall). :func:`parking_layout`'s ``driveway``, without the layout."""
    half = p.length / 2
    end = half - p.ramp_length if p.ramp_length > 0 else half
    return (-half + 1.0, end - 1.0)


def _prism_along_y(profile_xz: np.ndarray, y0: float, y1: float):
    """A convex ``(k, 2)`` x-z profile (counter-clockwise seen from +y... as drawn in x right, z up) extruded from y0 to y1."""
    vertices, triangles = primitives.prism(profile_xz, y0, y1)  # profile in (y, z) extruded along x
    vertices = vertices[:, [1, 0, 2]]  # swap x and y: a reflection, so flip the winding
    return vertices, triangles[:, ::-1].copy()


def parking_station(p, frame: int) -> np.ndarray:
    """``(4, 4)`` the sensor robot's station for ``frame``: on the driveway centre, ``sensor_height`` up, facing +x.

    It starts ``sensor_start`` metres along the driveway and advances ``sensor_step`` a frame,
    starting over at the driveway's beginning when it passes the end.
    """
    x0, x1 = driveway(p)
    along = (p.sensor_start + frame * p.sensor_step) % max(x1 - x0, 1e-9)
    return pose_matrix([x0 + along, 0.0, p.sensor_height], [0.0, 0.0, 0.0])


# ----------------------------------------------------------------------------- factory hall
@dataclass
class Furniture:
    """A desk or shelf: parts as boxes ``(centre (3,), half (3,))``; ``top`` the height people may sit on (desks)."""

    name: str
    class_name: str
    parts: list
    top: float = 0.0

    @property
    def footprint(self) -> tuple[np.ndarray, np.ndarray]:
        """``(low (2,), high (2,))`` of the parts on the floor plan."""
        low = np.min([c[:2] - h[:2] for c, h in self.parts], axis=0)
        high = np.max([c[:2] + h[:2] for c, h in self.parts], axis=0)
        return low, high

    def mesh(self):
        return boxes_mesh(self.parts)


@dataclass
class HallLayout:
    """The hall of ``config.IndustrialHallScene``: floor ``low``/``high`` (2,) inside the walls, furniture, wall and slab boxes."""

    low: np.ndarray
    high: np.ndarray
    furniture: list = field(default_factory=list)
    walls: list = field(default_factory=list)
    floor: list = field(default_factory=list)
    ceiling: list = field(default_factory=list)


def desk(name: str, centre_xy, size, height: float) -> Furniture:
    """A table: a 4 cm top and four 5 cm legs inset 5 cm."""
    length, depth = size
    top = (np.array([centre_xy[0], centre_xy[1], height - 0.02]), np.array([length / 2, depth / 2, 0.02]))
    legs = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            c = np.array([centre_xy[0] + sx * (length / 2 - 0.075), centre_xy[1] + sy * (depth / 2 - 0.075), (height - 0.04) / 2])
            legs.append((c, np.array([0.025, 0.025, (height - 0.04) / 2])))
    return Furniture(name, "desk", [top, *legs], top=height)


def shelf(name: str, centre_xy, size, levels: int) -> Furniture:
    """A rack: four 6 cm uprights and ``levels`` 3 cm boards from 0.1 m to the top."""
    length, depth, height = size
    parts = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            parts.append((np.array([centre_xy[0] + sx * (length / 2 - 0.03), centre_xy[1] + sy * (depth / 2 - 0.03), height / 2]),
                          np.array([0.03, 0.03, height / 2])))
    for z in np.linspace(0.1, height - 0.015, max(levels, 1)):
        parts.append((np.array([centre_xy[0], centre_xy[1], z]), np.array([length / 2, depth / 2, 0.015])))
    return Furniture(name, "shelf", parts)


WALL_GAP = 0.1  # m: a shelf row stands at least this far from the hall's east wall


def hall_layout(p) -> HallLayout:
    """Desks in ``desk_rows`` rows west of the centre, 1.8 m aisles between rows; shelves in a row 2.5 m from the +y wall,
    centred a quarter of the length east of the centre, or further west where that leaves less than ``WALL_GAP`` to the east wall."""
    half = np.array([p.length / 2, p.width / 2])
    t, h, slab = p.wall_thickness, p.height, 0.3
    layout = HallLayout(-half + t, half - t)
    length, depth = p.desk_size
    for r in range(p.desk_rows):
        y = (r - (p.desk_rows - 1) / 2) * (depth + 1.8)
        for k in range(p.desks_per_row):
            x = -p.length / 4 + (k - (p.desks_per_row - 1) / 2) * (length + 0.8)
            layout.furniture.append(desk(f"desk_{r}_{k}", (x, y), p.desk_size, p.desk_height))
    s_len = p.shelf_size[0]
    row_half = (p.shelves * s_len + max(p.shelves - 1, 0) * 0.8) / 2
    middle = min(p.length / 4, half[0] - t - WALL_GAP - row_half)  # east of the centre, WALL_GAP clear of the east wall
    for k in range(p.shelves):
        x = middle + (k - (p.shelves - 1) / 2) * (s_len + 0.8)
        layout.furniture.append(shelf(f"shelf_{k}", (x, p.width / 2 - 2.5), p.shelf_size, p.shelf_levels))
    layout.walls = [
        (np.array([0.0, s * (half[1] - t / 2), h / 2]), np.array([half[0], t / 2, h / 2])) for s in (-1, 1)
    ] + [(np.array([s * (half[0] - t / 2), 0.0, h / 2]), np.array([t / 2, half[1] - t, h / 2])) for s in (-1, 1)]
    layout.floor = [(np.array([0.0, 0.0, -slab / 2]), np.array([half[0], half[1], slab / 2]))]
    layout.ceiling = [(np.array([0.0, 0.0, h + slab / 2]), np.array([half[0], half[1], slab / 2]))]
    return layout


def hall_station(p) -> np.ndarray:
    """``(4, 4)`` the overhead sensor's station: ``sensor_height`` above the hall's centre, level, x along the hall."""
    return pose_matrix([0.0, 0.0, p.sensor_height], [0.0, 0.0, 0.0])

