"""Meshes of the objects inserted into scenes and real scans: cars, people, robot arms. Pure numpy.

Every mesh is ``(vertices (n, 3) float64 metres, triangles (m, 3) int32)`` with outward winding.
The parking builder (builders/parking/scene.py) shows these cars in Blender; the real-scan mixing
(bpy_pipeline.mixing) casts the real sensor's firings at them without any Blender scene.

A car is four parts sharing one instance: the body (its paint's reflectivity), the windows
(``glass``), the interior (dashboard and seats) and the tyres. Three classic body styles (sedan,
hatchback, estate: :data:`STYLES`), each a nominal mesh at :data:`NOMINAL_HEIGHT` scaled to a car's
height, are what the builders draw; :data:`BODIES` holds 24 bodies (those three and 21 more: sedans,
hatchbacks, estates, SUVs, pickups with an open bed, vans), each at its own length, width and height,
drawn per object by real-scan insertion (``scene.car_bodies``, :data:`CAR_BODY_SETS`).
A person is the capsule body of :mod:`.human`; a robot arm the capsule links of :mod:`.kinematics`;
a cyclist a rider of :mod:`.human` seated on the bicycle of :mod:`.vehicles`, one instance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import primitives
from .vehicles import PLATE_SIZE

GLASS_REFLECTIVITY = 0.08  # two faces of about 4 % each at normal incidence
INTERIOR_REFLECTIVITY = 0.15
TYRE_REFLECTIVITY = 0.05
NOMINAL_HEIGHT = 1.625  # m: the styles' meshes are built at this height and scaled to each car's
# Paint colours: share of cars (roughly the global popularity of recent years: white, black, grey,
# silver, blue, red, others) and reflectivity at 905 nm (assumed: white paint about 0.7, black 0.05).
COLOURS = (
    ("white", (0.9, 0.9, 0.9), 0.35, 0.70),
    ("black", (0.02, 0.02, 0.02), 0.19, 0.05),
    ("grey", (0.3, 0.3, 0.32), 0.18, 0.30),
    ("silver", (0.6, 0.6, 0.62), 0.09, 0.50),
    ("blue", (0.05, 0.15, 0.5), 0.07, 0.20),
    ("red", (0.6, 0.03, 0.03), 0.06, 0.45),
    ("beige", (0.6, 0.5, 0.35), 0.06, 0.40),
)


@dataclass(frozen=True)
class CarStyle:
    """A body shape: length and width per metre of height; x positions as fractions of the length
    from the centre (front +); heights as fractions of the height."""

    name: str
    length_ratio: float
    width_ratio: float
    windshield: float  # base of the windshield
    roof_front: float
    roof_back: float
    rear_base: float  # base of the rear window
    deck: float  # rear deck (trunk lid) height; a pickup's bed walls
    belt: float  # beltline (bottom of the side windows)
    # the defaults below are the classic styles' (their meshes keep their bytes)
    height: float = NOMINAL_HEIGHT  # m: the body's own nominal height
    kind: str = ""  # sedan | hatchback | estate | suv | pickup | van ("": the style's name)
    clearance: float = 0.17  # underside of the body, fraction of the height
    nose: float = 0.45  # top of the front face
    tail: float = 0.45  # top of the rear face
    deck_back: float = 0.04  # the rear deck ends this share of the length before the rear face
    tyre: float = 0.197  # tyre radius
    bed: bool = False  # an open load bed behind the cab (pickups) instead of a closed trunk


STYLES = (
    CarStyle("sedan", 2.85, 1.12, 0.20, -0.02, -0.26, -0.38, 0.62, 0.58),
    CarStyle("hatchback", 2.55, 1.10, 0.22, 0.03, -0.37, -0.47, 0.60, 0.57),
    CarStyle("estate", 2.80, 1.12, 0.21, 0.02, -0.45, -0.49, 0.62, 0.58),
)
PARTS = ("body", "windows", "interior", "tyres")


def _body(name: str, kind: str, length: float, width: float, height: float, profile: tuple, **shape) -> CarStyle:
    """A body of ``length`` x ``width`` x ``height`` m (width without mirrors); ``profile`` the six
    fractions windshield, roof_front, roof_back, rear_base, deck, belt of :class:`CarStyle`."""
    return CarStyle(name, length / height, width / height, *profile, height=height, kind=kind, **shape)


# Profiles (fractions of length and height, see CarStyle) and shape per family; sizes below.
_SEDAN = ((0.20, -0.02, -0.26, -0.38, 0.62, 0.58), {"clearance": 0.11, "nose": 0.48, "tail": 0.50, "tyre": 0.215})
_HATCH = ((0.24, 0.05, -0.38, -0.47, 0.60, 0.57), {"clearance": 0.11, "nose": 0.48, "tail": 0.48, "tyre": 0.21, "deck_back": 0.02})
_ESTATE = ((0.21, 0.02, -0.45, -0.48, 0.62, 0.58), {"clearance": 0.11, "nose": 0.48, "tail": 0.50, "tyre": 0.215, "deck_back": 0.01})
_SUV = ((0.23, 0.06, -0.44, -0.48, 0.60, 0.60), {"clearance": 0.14, "nose": 0.55, "tail": 0.55, "tyre": 0.21, "deck_back": 0.01})
_PICKUP = ((0.22, 0.10, -0.10, -0.12, 0.56, 0.57), {"clearance": 0.16, "nose": 0.55, "tail": 0.52, "tyre": 0.205, "bed": True})
_VAN = ((0.36, 0.28, -0.46, -0.48, 0.50, 0.52), {"clearance": 0.10, "nose": 0.45, "tail": 0.48, "tyre": 0.17, "deck_back": 0.01})
_FAMILIES = {"sedan": _SEDAN, "hatchback": _HATCH, "estate": _ESTATE, "suv": _SUV, "pickup": _PICKUP, "van": _VAN}
# (name, family, length, width, height) m: typical of recent European and North American models of each size class
_SIZES = (
    ("sedan_compact", "sedan", 4.45, 1.75, 1.44), ("sedan_midsize", "sedan", 4.70, 1.82, 1.45),
    ("sedan_large", "sedan", 4.95, 1.86, 1.47), ("sedan_executive", "sedan", 5.15, 1.90, 1.48),
    ("hatchback_mini", "hatchback", 3.60, 1.63, 1.50), ("hatchback_small", "hatchback", 4.05, 1.74, 1.45),
    ("hatchback_compact", "hatchback", 4.30, 1.79, 1.46),
    ("estate_compact", "estate", 4.55, 1.80, 1.48), ("estate_midsize", "estate", 4.78, 1.83, 1.50),
    ("estate_large", "estate", 4.95, 1.88, 1.50),
    ("suv_small", "suv", 4.20, 1.78, 1.60), ("suv_compact", "suv", 4.50, 1.84, 1.67),
    ("suv_midsize", "suv", 4.80, 1.92, 1.76), ("suv_large", "suv", 5.05, 2.00, 1.85),
    ("pickup_compact", "pickup", 5.10, 1.85, 1.78), ("pickup_midsize", "pickup", 5.35, 1.90, 1.83),
    ("pickup_fullsize", "pickup", 5.90, 2.03, 1.96), ("pickup_heavy", "pickup", 6.20, 2.05, 2.00),
    ("van_compact", "van", 4.50, 1.80, 1.82), ("van_midsize", "van", 4.97, 1.95, 1.95),
    ("van_long", "van", 5.30, 2.00, 1.99),
)
BODIES = STYLES + tuple(_body(name, kind, L, W, H, _FAMILIES[kind][0], **_FAMILIES[kind][1]) for name, kind, L, W, H in _SIZES)
# scene.car_bodies -> the bodies a car is drawn from (uniformly)
CAR_BODY_SETS = {"all": BODIES, "classic": STYLES}


# ----------------------------------------------------------------------------- car meshes (pure numpy)
def _prism_xz(profile, y0: float, y1: float):
    v, t = primitives.prism(np.asarray(profile, float), y0, y1)
    return v[:, [1, 0, 2]], t[:, ::-1].copy()


def _box(x0, x1, y0, y1, z0, z1):
    return primitives.translated(primitives.box(x1 - x0, y1 - y0, z1 - z0), ((x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2))


def _beam(p0, p1, thickness: float):
    """A square beam from ``p0`` to ``p1`` (3,)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    axis = p1 - p0
    length = np.linalg.norm(axis)
    w = axis / length
    u = np.cross(w, [0.0, 1.0, 0.0] if abs(w[1]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    vertices, triangles = primitives.box(thickness, thickness, length)
    rotation = np.column_stack([u, v, w])
    return vertices @ rotation.T + (p0 + p1) / 2, triangles


def _quad(a, b, c, d):
    """A planar polygon a-b-c-d (one-sided: glass either way)."""
    return np.array([a, b, c, d], float), np.array([[0, 1, 2], [0, 2, 3]], np.int32)


def _tyre(x, y, radius, width):
    v, t = primitives.cylinder(radius, width, 16)
    return v[:, [0, 2, 1]] + [x, y, radius], t[:, ::-1].copy()


def car_parts(style: CarStyle, height: float = NOMINAL_HEIGHT) -> dict:
    """Part name -> ``(vertices, triangles)`` of a car of ``style`` at ``height`` (m), origin on the ground at its centre, nose +x.

    Everything lies within the box of length x width x height around the origin (z from 0).
    """
    H = height
    L, W = style.length_ratio * H, style.width_ratio * H
    xf, xr = L / 2, -L / 2
    xw, xr1, xr2, xb = style.windshield * L, style.roof_front * L, style.roof_back * L, style.rear_base * L
    zc, belt, deck, roof = style.clearance * H, style.belt * H, style.deck * H, 0.97 * H
    ys, yt = W / 2 - 0.04, W / 2 - 0.10  # side glass at the beltline and at the roof (tumblehome)
    if style.bed:  # an open load bed: its floor, side walls and tailgate, and the cab's back wall
        floor = style.tail * H - 0.08 * H
        rear = [_box(xr, xb, -W / 2, W / 2, zc, floor), _box(xr, xb, W / 2 - 0.05, W / 2, floor, deck), _box(xr, xb, -W / 2, -W / 2 + 0.05, floor, deck),
                _box(xr, xr + 0.05, -W / 2 + 0.05, W / 2 - 0.05, floor, deck), _box(xb - 0.04, xb, -W / 2, W / 2, zc, deck)]
    else:
        rear = [_prism_xz([(xr, zc), (xb, zc), (xb, deck), (xr + style.deck_back * L, deck), (xr, style.tail * H)], -W / 2, W / 2)]  # trunk and rear
    body = [
        _prism_xz([(xw, zc), (xf, zc), (xf, style.nose * H), (xf - 0.06 * L, belt), (xw, belt)], -W / 2, W / 2),  # hood and front
        *rear,
        _box(xb, xw, -W / 2, W / 2, zc, zc + 0.08 * H),  # cabin floor
        _box(xb, xw, W / 2 - 0.05, W / 2, zc, belt),  # doors
        _box(xb, xw, -W / 2, -W / 2 + 0.05, zc, belt),
        _box(xr2, xr1, -yt, yt, roof, H),  # roof
    ]
    for side in (-1, 1):
        body.append(_beam((xw, side * ys, belt), (xr1, side * yt, roof), 0.07))  # A pillar
        xm = (xr1 + xr2) / 2
        body.append(_beam((xm, side * ys, belt), (xm, side * yt, roof), 0.08))  # B pillar
        body.append(_beam((xb, side * ys, deck), (xr2, side * yt, roof), 0.09))  # C pillar
    windows = [
        _quad((xw, -ys, belt), (xw, ys, belt), (xr1, yt, roof), (xr1, -yt, roof)),  # windshield
        _quad((xb, ys, deck), (xb, -ys, deck), (xr2, -yt, roof), (xr2, yt, roof)),  # rear window
    ]
    for side in (-1, 1):
        outline = [(xw, side * ys, belt), (xr1, side * yt, roof), (xr2, side * yt, roof), (xb, side * ys, deck), (xb, side * ys, belt)]
        fan = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]], np.int32)
        windows.append((np.array(outline, float), fan if side < 0 else fan[:, ::-1].copy()))  # each side's glass wound outwards
    cabin = lambda c: xb + c * (xw - xb)  # noqa: E731 - fraction of the cabin from its rear
    interior = [
        _box(xw - 0.08 * L, xw, -W / 2 + 0.06, W / 2 - 0.06, zc, belt + 0.02 * H),  # dashboard
        _box(cabin(0.04), cabin(0.10), -0.42 * W, 0.42 * W, zc, 0.80 * H),  # rear bench back
        _box(cabin(0.08), cabin(0.32), -0.42 * W, 0.42 * W, zc, 0.44 * H),  # rear bench cushion
    ]
    for y0, y1 in ((0.03 * W, 0.44 * W), (-0.44 * W, -0.03 * W)):
        interior.append(_box(cabin(0.42), cabin(0.48), y0, y1, zc, 0.84 * H))  # front seat back
        interior.append(_box(cabin(0.46), cabin(0.70), y0, y1, zc, 0.45 * H))  # front seat cushion
    radius, width = style.tyre * H, 0.13 * W
    tyres = [_tyre(x, side * (W / 2 - 0.02 - width / 2), radius, width) for x in (xf - 0.17 * L, xr + 0.18 * L) for side in (-1, 1)]
    return {"body": primitives.merge(body), "windows": primitives.merge(windows), "interior": primitives.merge(interior), "tyres": primitives.merge(tyres)}


# Fittings (not in PARTS: the parts every car has): licence plates and lamps, each with the reflectance model
# (lidar/effects/materials.py) its ``lidar_material`` names. The builders' cars carry them unless ``scene.car_fittings:
# false`` (the population's ``car.fittings``); inserted cars with ``scene.car_fittings``. Their reflectivities
# differ from every paint's, so an instance's parts keep their models apart (lidar/effects/materials.py).
FITTINGS = {"plates": ("retroreflector", 0.8), "lights": ("glossy_paint", 0.6)}  # part -> (lidar_material, reflectivity)


def car_fittings(style: CarStyle, height: float = NOMINAL_HEIGHT) -> dict:
    """Part name -> ``(vertices, triangles)``: ``plates`` (front and rear, 5 mm proud of the body's end faces,
    centred, lower edge at 0.25 height) and ``lights`` (head and tail lamps, 0.20 m wide at the corners,
    0.36-0.43 height, 1 cm proud), in the frame of :func:`car_parts`; within the car's box but for those millimetres.
    """
    H = height
    L, W = style.length_ratio * H, style.width_ratio * H
    pw, ph = PLATE_SIZE
    z0 = 0.25 * H
    plates = [_box(L / 2, L / 2 + 0.005, -pw / 2, pw / 2, z0, z0 + ph), _box(-L / 2 - 0.005, -L / 2, -pw / 2, pw / 2, z0, z0 + ph)]
    lights = []
    for x0, x1 in ((L / 2 - 0.06, L / 2 + 0.01), (-L / 2 - 0.01, -L / 2 + 0.06)):
        for side in (-1, 1):
            y = side * (W / 2 - 0.15)
            lights.append(_box(x0, x1, y - 0.10, y + 0.10, 0.36 * H, 0.43 * H))
    return {"plates": primitives.merge(plates), "lights": primitives.merge(lights)}


def car_meshes(style: CarStyle, fittings: bool, height: float = NOMINAL_HEIGHT) -> dict:
    """Part name -> ``(vertices, triangles)``: :func:`car_parts`, then :func:`car_fittings` when ``fittings``."""
    return {**car_parts(style, height), **(car_fittings(style, height) if fittings else {})}


def car_surfaces(paint: float) -> dict:
    """Part name -> ``(lidar_material, reflectivity)`` of every part of a car (:data:`PARTS`, :data:`FITTINGS`)
    whose paint has reflectivity ``paint``: what a builder tags each part's object with."""
    return {"body": ("diffuse", paint), "windows": ("glass", GLASS_REFLECTIVITY), "interior": ("diffuse", INTERIOR_REFLECTIVITY),
            "tyres": ("diffuse", TYRE_REFLECTIVITY), **FITTINGS}


def style_size(style: CarStyle, height: float = NOMINAL_HEIGHT) -> np.ndarray:
    """``(3,)`` length, width, height (m) of the nominal car of ``style``."""
    return np.array([style.length_ratio * height, style.width_ratio * height, height])


# ----------------------------------------------------------------------------- robot arms and people
def link_meshes(model) -> list:
    """``[(vertices, triangles), ...]`` per link of an arm (:class:`~.kinematics.ArmModel`, base first), in the link's own frame."""
    from .collision import capsule_mesh

    out = []
    for link in range(model.joints + 1):
        rows = np.flatnonzero(model.capsule_link == link)
        parts = [capsule_mesh(model.capsule_a[k], model.capsule_b[k], float(model.capsule_radius[k]), 16, 4, bool(model.capsule_flat_start[k])) for k in rows]
        out.append(primitives.merge(parts))
    return out


def arm_mesh(model, q: np.ndarray, base: np.ndarray | None = None):
    """The whole arm posed at joint angles ``q`` (radians): ``(vertices, triangles)`` in the frame of ``base`` (4, 4)."""
    from .kinematics import forward

    frames = forward(model, np.asarray(q, float), base)
    parts = [(v @ frames[k][:3, :3].T + frames[k][:3, 3], t) for k, (v, t) in enumerate(link_meshes(model))]
    return primitives.merge(parts)


def person_mesh(angles: np.ndarray, height: float, build: float = 1.0, pose: str = "standing"):
    """A posed body (:mod:`.human`) standing on z = 0 at the origin, facing +x: ``(vertices, triangles)``."""
    from .human import body_mesh, pose_person

    person = pose_person(angles, height, build, pose, (0.0, 0.0), 0.0)
    vertices, triangles, _ = body_mesh(person.a, person.b, person.radius)
    return vertices, triangles


# ----------------------------------------------------------------------------- an object fitted to a box
@dataclass(frozen=True)
class ObjectPart:
    """One part of an object: mesh, ``lidar_material`` (``diffuse``, ``glass``, ...) and reflectivity 0..1."""

    vertices: np.ndarray  # (n, 3) float64, metres
    triangles: np.ndarray  # (m, 3) int32
    material: str = "diffuse"
    reflectivity: float = 0.5
    paint: object = None  # an inserted car part's own reflectance model (mixing/paint.py PartModel, scene.car_paint); None: the material's


def fit_to_box(parts: list[ObjectPart], size) -> list[ObjectPart]:
    """``parts`` scaled per axis so their joint bounds fill a box of ``size`` (length, width, height) m centred at the origin."""
    vertices = np.concatenate([p.vertices for p in parts])
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    scale = np.asarray(size, float) / np.maximum(high - low, 1e-9)
    centre = (low + high) / 2
    return [ObjectPart((p.vertices - centre) * scale, p.triangles, p.material, p.reflectivity) for p in parts]


def draw_body(rng: np.random.Generator, bodies: str = "all") -> int:
    """Index of a body of ``CAR_BODY_SETS[bodies]``, uniform (one draw of ``rng``)."""
    return int(rng.integers(len(CAR_BODY_SETS[bodies])))


def body_size(index: int, bodies: str = "all") -> np.ndarray:
    """``(3,)`` length, width, height (m) of body ``index`` of ``CAR_BODY_SETS[bodies]`` at its own nominal height."""
    style = CAR_BODY_SETS[bodies][index]
    return style_size(style, style.height)


def car_object(rng: np.random.Generator, size=None, bodies: str = "classic", body: int = -1, fittings: bool = False) -> list[ObjectPart]:
    """A car of a random body of ``CAR_BODY_SETS[bodies]`` (or body ``body`` of it, drawn before: no draw) and a random
    paint, its parts centred on the origin (nose +x); scaled to ``size`` when given, else at the body's own size.

    ``fittings``: the :func:`car_fittings` parts follow :data:`PARTS` (plates, then lights, with the materials of
    :data:`FITTINGS`), moved and scaled as the car's own parts are (the fit ignores their millimetres out of the box);
    no extra draw, so the car's parts are the same either way."""
    styles = CAR_BODY_SETS[bodies]
    style = styles[int(rng.integers(len(styles)))] if body < 0 else styles[body]
    shares = np.array([c[2] for c in COLOURS])
    paint = COLOURS[int(rng.choice(len(COLOURS), p=shares / shares.sum()))][3]
    mesh = car_parts(style, style.height)
    reflect = car_surfaces(paint)
    parts = [ObjectPart(mesh[name][0], mesh[name][1], *reflect[name]) for name in PARTS]
    fitted = fit_to_box(parts, style_size(style, style.height) if size is None else size)
    if not fittings:
        return fitted
    vertices = np.concatenate([p.vertices for p in parts])
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    scale = np.asarray(style_size(style, style.height) if size is None else size, float) / np.maximum(high - low, 1e-9)
    extra = car_fittings(style, style.height)
    return fitted + [ObjectPart((extra[name][0] - (low + high) / 2) * scale, extra[name][1], *FITTINGS[name]) for name in FITTINGS]


PERSON_REFLECTIVITY = 0.4  # clothing (an assumption)


def person_object(rng: np.random.Generator, size=None) -> list[ObjectPart]:
    """A standing or walking person of a random pose; scaled to ``size`` when given."""
    from .human import BUILDS, sample_pose

    pose = ("standing", "walking")[int(rng.integers(2))]
    build = BUILDS[("slim", "medium", "broad")[int(rng.integers(3))]]
    height = 1.75 if size is None else float(size[2])
    v, t = person_mesh(sample_pose(pose, rng, build), height, build, pose)
    part = ObjectPart(v, t, "diffuse", PERSON_REFLECTIVITY)
    return fit_to_box([part], (v.max(axis=0) - v.min(axis=0)) if size is None else size)


ARM_REFLECTIVITY = 0.55  # painted metal (as blender/robot_arm.py)


def robot_arm_object(rng: np.random.Generator, size=None) -> list[ObjectPart]:
    """The project's six-axis arm (assets_manifest/robot_arm.yaml) at a random valid pose on z = 0; scaled to ``size`` when given."""
    from .kinematics import load_arm, random_configuration

    model = load_arm()
    v, t = arm_mesh(model, random_configuration(model, rng, floor_z=0.0))
    part = ObjectPart(v, t, "diffuse", ARM_REFLECTIVITY)
    return fit_to_box([part], (v.max(axis=0) - v.min(axis=0)) if size is None else size)


CYCLIST_SIZE = (1.76, 0.6, 1.73)  # m: length, width, height of a rider on a bicycle (the KITTI Cyclist class's mean box)
BICYCLE_REFLECTIVITY, WHEEL_REFLECTIVITY = 0.3, 0.05  # a painted frame, black tyres (as the street builder's, builders/street/layout.py)


def cyclist_object(rng: np.random.Generator, size=None) -> list[ObjectPart]:
    """A rider (:mod:`.human`, a drawn seated pose and build) on a bicycle (:func:`.vehicles.two_wheeler_parts`: two
    wheels and a frame), facing +x: three parts (frame, wheels, rider) of one object; scaled to ``size`` when given."""
    from .human import BUILDS, pose_person, sample_pose, body_mesh
    from .vehicles import saddle_height, two_wheeler_parts

    nominal = np.asarray(CYCLIST_SIZE, float)
    bike = two_wheeler_parts("bicycle", nominal)
    build = BUILDS[("slim", "medium", "broad")[int(rng.integers(3))]]
    angles = sample_pose("sitting", rng, build)
    seat = saddle_height("bicycle", nominal)
    rider = pose_person(angles, 0.95 * nominal[2], build, "sitting", (-0.1 * nominal[0] - 0.05, 0.0), 0.0, seat + 0.005)
    v, t, _ = body_mesh(rider.a, rider.b, rider.radius, 8, 2)
    parts = [ObjectPart(*bike["frame"], "diffuse", BICYCLE_REFLECTIVITY), ObjectPart(*bike["wheels"], "diffuse", WHEEL_REFLECTIVITY),
             ObjectPart(v, np.asarray(t, np.int32), "diffuse", PERSON_REFLECTIVITY)]
    vertices = np.concatenate([p.vertices for p in parts])
    return fit_to_box(parts, (vertices.max(axis=0) - vertices.min(axis=0)) if size is None else size)


def box_object(rng: np.random.Generator, size=None) -> list[ObjectPart]:
    """A plain box (a wall, a crate) of ``size`` (1 m cube by default)."""
    v, t = primitives.box(*((1.0, 1.0, 1.0) if size is None else size))
    return [ObjectPart(v, t, "diffuse", 0.5)]


# type -> (class name, maker(rng, size) -> parts, nominal size (length, width, height) m)
OBJECT_TYPES = {
    "box": ("wall", box_object, (1.0, 1.0, 1.0)),
    "car": ("car", car_object, (4.6, 1.8, 1.625)),
    "person": ("person", person_object, (0.6, 0.5, 1.75)),
    "robot_arm": ("robot arm", robot_arm_object, (1.2, 0.6, 1.6)),
    # one instance, class rider: SemanticKITTI's bicyclist (31) and KITTI's Cyclist (labels.yaml)
    "cyclist": ("rider", cyclist_object, CYCLIST_SIZE),
}
