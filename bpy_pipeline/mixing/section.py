"""``scene.builder: real_scan``: the section's parameters (a real scan as the background, objects cast into it).

Everything in the sensor frame of the scan (x forward, y left, z up, metres); a box is its
centre, its size (length along the heading, width, height) and its yaw in degrees.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from ..schema import meta
from ..geometry.placement import Distribution
from ..lidar.effects.materials import CarGlass
from .paint import CarPaint


@dataclass(frozen=True)
class ObjectBox:
    """One object: ``type`` car | person | cyclist | robot_arm | box, or a mesh file (.glb, .gltf, .obj, .ply; glass where
    a material's name says glass or window: :mod:`.objects`), scaled to the box (``size`` 0: the type's nominal size,
    a file's own)."""

    type: str = "car"
    center: tuple[float, float, float] = field(default=(10.0, 0.0, 0.0), metadata=meta("m", help="box centre, sensor frame"))
    size: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), metadata=meta("m", low=0, help="0: the type's nominal size"))
    yaw_deg: float = field(default=0.0, metadata=meta("deg"))
    class_name: str = field(default="", metadata={"key": "class"})  # "" : the type's class (car, person, rider, robot arm; a file's by its name)


@dataclass(frozen=True)
class RemoveBox:
    """A box whose real returns are cut out before insertion (to swap a real object for a synthetic one)."""

    center: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), metadata=meta("m", help="box centre, sensor frame"))
    size: tuple[float, float, float] = field(default=(1.0, 1.0, 1.0), metadata=meta("m", low=0, low_open=True))
    yaw_deg: float = field(default=0.0, metadata=meta("deg"))


@dataclass(frozen=True)
class ParkingRule:
    """The parking paper's insertion rule: ``count`` objects from N(5, 4), each at a distance from
    ``distance`` (N(10, 20) m, up to 20 m) and a random angle about the sensor, turned
    ``rotation_step_deg`` about it up to ``rotations`` times until it fits; ``max_consecutive_failures``
    objects in a row that fit nowhere end it. Refused where more than ``max_real_points`` non-ground
    real returns fall in the box grown by ``box_margin`` (10 %), where fewer than ``min_ground_points``
    ground returns lie under it (an empty space), where it overlaps an object placed before, or where
    more than ``max_hidden_fraction`` of the firings towards it already return nearer. An object drawn nearer
    than ``near_rejection_distance`` (m) is refused outright with ``near_rejection_probability`` (the paper's
    refinement of its distance histogram, section 5.1: 10 % under 5 m; as the procedural garage does).
    ``heading``: the object's yaw minus its bearing from the sensor, degrees (0: pointing away from the
    sensor); the default, uniform over the circle, is the paper's random yaw. ``bpy-pipeline match``
    writes ``count``, ``distance`` and ``heading`` as histograms fitted to labelled real scans."""

    enabled: bool = False
    type: str = "car"
    count: Distribution = field(default_factory=lambda: Distribution("normal", 5.0, 4.0, 0.0, 40.0))
    distance: Distribution = field(default_factory=lambda: Distribution("normal", 10.0, 20.0, 2.5, 20.0))
    height: Distribution = field(default_factory=lambda: Distribution("uniform", 1.625, 0.0, 1.55, 1.70))
    heading: Distribution = field(default_factory=lambda: Distribution("uniform", 0.0, 0.0, -180.0, 180.0))
    rotation_step_deg: float = field(default=10.0, metadata=meta("deg"))
    rotations: int = field(default=36, metadata=meta(""))
    max_consecutive_failures: int = field(default=10, metadata=meta(""))
    max_real_points: int = field(default=5, metadata=meta(""))
    box_margin: float = field(default=0.1, metadata=meta("", help="the box grown by this share when real returns in it are counted (0.1: 10 %)"))
    min_ground_points: int = field(default=3, metadata=meta(""))
    max_hidden_fraction: float = field(default=0.5, metadata=meta(""))
    near_rejection_distance: float = field(default=5.0, metadata=meta("m", low=0))
    near_rejection_probability: float = field(default=0.1, metadata=meta("", 0, 1))


@dataclass(frozen=True)
class KittiRule:
    """The KITTI paper's rule: ``candidates`` random ground returns; one picked at random removes the
    others within ``collision_distance`` (d), candidates within d / 2 of a non-ground return are
    discarded, ``count`` kept; yaw by its equation (1) from the lateral offset (|y| < 10 m: 0 or 180 deg;
    10-30 m: 0, 180 or random; else random), snapped to the nearest labelled real vehicle within
    ``snap_distance`` m (0: never). Candidates lie between ``min_range`` and ``max_range`` m of the sensor
    in the plane (``min_range`` keeps objects clear of the recording vehicle, whose own returns a scan lacks)."""

    enabled: bool = False
    type: str = "car"
    count: int = field(default=5, metadata=meta(""))
    candidates: int = field(default=200, metadata=meta(""))
    collision_distance: float = field(default=5.0, metadata=meta("m"))
    snap_distance: float = field(default=0.0, metadata=meta("m"))
    max_range: float = field(default=50.0, metadata=meta("m"))
    min_range: float = field(default=0.0, metadata=meta("m"))


@dataclass(frozen=True)
class NoiseInjections:
    """The parking paper's noise injections for ablation, on the inserted objects only (all off by default).

    dropout_max : per object a dropout probability from U(0, dropout_max) (the paper: 0.003)
    range_sigma : per object a sigma from U(range_sigma) along the beam, metres (the paper: 0.001..0.03; 0..0 off)
    interior_points : per car up to this many points inside it (radius N(0.3, 0.5) m about its centre,
        uniform angles), each put on the nearest firing and kept only where it is the nearest return there
    cutoff_probability, cutoff_fraction : an object is cut vertically with this probability, losing this
        share (U range) of its points on one side (the paper: 0.6, 0.2..0.8)
    class_flip : share of all points given a wrong class (the paper: 0.02)

    ``scene.noise`` may also name a profile of :data:`NOISE_PROFILES` (``scene.noise: parking_paper_best``).
    """

    dropout_max: float = field(default=0.0, metadata=meta(""))
    range_sigma: tuple[float, float] = field(default=(0.0, 0.0), metadata=meta("m"))
    interior_points: int = field(default=0, metadata=meta(""))
    cutoff_probability: float = field(default=0.0, metadata=meta(""))
    cutoff_fraction: tuple[float, float] = field(default=(0.2, 0.8), metadata=meta(""))
    class_flip: float = field(default=0.0, metadata=meta(""))

    @classmethod
    def named(cls, name: str, path: str = "scene.noise") -> "NoiseInjections":
        """The profile ``name`` of :data:`NOISE_PROFILES`; ``InputError`` naming ``path`` for another name."""
        if name not in NOISE_PROFILES:
            from ..errors import InputError

            raise InputError(f"{path}: {name!r} is not a noise profile; give a mapping or one of {', '.join(NOISE_PROFILES)}")
        return NOISE_PROFILES[name]


# Named noise profiles (``scene.noise: NAME``), the parking paper's section 3.3 values in its Table 2's rows.
NOISE_PROFILES = {
    "none": NoiseInjections(),
    # Table 2's best row (77.1 % accuracy, 73.0 IoU; 64.7 with no injection): dropout, per-object range noise, interior
    # points and the cut-off, without class flips (the row before it shows they cost 0.4 IoU). Its last column,
    # the adjusted distance histogram, is the parking rule's near rejection (ParkingRule.near_rejection_*, on by default).
    "parking_paper_best": NoiseInjections(0.003, (0.001, 0.03), 15, 0.6, (0.2, 0.8), 0.0),
    # every injection of section 3.3, class flips (2 %) included: no row of Table 2 has them all
    "parking_paper_all": NoiseInjections(0.003, (0.001, 0.03), 15, 0.6, (0.2, 0.8), 0.02),
}


@dataclass(frozen=True)
class SupportParams:
    """How support surfaces are found in a real scan's points (:func:`~.supports.find_supports`): sequential RANSAC
    of near-horizontal planes, DBSCAN of each plane's inliers in the plane.

    threshold : m, a plane's inlier distance; iterations : RANSAC draws per plane; max_tilt_deg : a plane's normal
        from +z at most; max_planes : planes taken out in turn; min_inliers : fewer ends the search
    voxel : m, the cells a plane's inliers are thinned to (and a surface's spots); eps, min_samples : DBSCAN over
        those cells (m; cells within eps, itself included); min_area : m^2, min_width : m (minor extent) of a surface
    desk_height : m above the floor plane of a desk (or bench, seat); floor_band : m, surfaces this near the floor's
        plane are floor; headroom, max_covered : a desk (and a floor other than the largest) has at most this share
        of its cells with points up to ``headroom`` m above it (a shelf board under the next is not a desk)
    sample : RANSAC scores each draw on at most this many points; seed : its own generator (the surfaces of a
        scan do not depend on the frame's draws)
    """

    threshold: float = field(default=0.05, metadata=meta("m", low=0, low_open=True, help="a plane's inlier distance"))
    iterations: int = field(default=300, metadata=meta("", low=1))
    max_tilt_deg: float = field(default=10.0, metadata=meta("deg", 0, 90, high_open=True))
    max_planes: int = field(default=10, metadata=meta("", low=1))
    min_inliers: int = field(default=30, metadata=meta("", low=1))
    voxel: float = field(default=0.1, metadata=meta("m", low=0, low_open=True, help="the cells a plane's inliers are thinned to"))
    eps: float = field(default=0.4, metadata=meta("m", low=0, low_open=True, help="DBSCAN: cells within eps"))
    min_samples: int = field(default=4, metadata=meta("", low=1))
    min_area: float = field(default=0.25, metadata=meta("m^2", low=0, low_open=True))
    min_width: float = field(default=0.3, metadata=meta("m", low=0, low_open=True))
    desk_height: tuple[float, float] = field(default=(0.4, 1.2), metadata=meta("m", low=0))
    floor_band: float = field(default=0.2, metadata=meta("m", low=0, low_open=True, help="surfaces this near the floor's plane are floor"))
    headroom: float = field(default=0.8, metadata=meta("m", low=0, low_open=True))
    max_covered: float = field(default=0.25, metadata=meta("", 0, 1))
    sample: int = field(default=20000, metadata=meta("", low=1))
    seed: int = field(default=0, metadata=meta(""))


@dataclass(frozen=True)
class RealPopulation:
    """``scene.population`` of a real scan: ``people`` standing people on the ``people_on`` surfaces and ``arms``
    robot arms on the ``arms_on`` surfaces (floor, desk, other) that :class:`SupportParams` finds in its points.

    person_height : m, drawn per person (the population builder's N(1.72, 0.09) in 1.50-1.98)
    tries : spots tried per object; keep_out : m between objects' boxes (those placed before included)
    clearance : m above its surface from which real returns count as obstacles; max_points : real returns a
        person's box may hold; margin : m an arm's capsules keep from real returns
    reach, arm_reach : m around a foot (a footprint corner) or an arm base point within which surface points must
        lie, at a local height within ``step`` m of the spot's
    min_range, max_range : m from the sensor in the plane (0: no limit)
    """

    people: int = field(default=0, metadata=meta("", low=0))
    arms: int = field(default=0, metadata=meta("", low=0))
    people_on: list[str] = field(default_factory=lambda: ["floor"])
    arms_on: list[str] = field(default_factory=lambda: ["desk"])
    person_height: Distribution = field(default_factory=lambda: Distribution("normal", 1.72, 0.09, 1.50, 1.98))
    tries: int = field(default=60, metadata=meta("", low=1))
    keep_out: float = field(default=0.3, metadata=meta("m", low=0, help="between objects' boxes"))
    clearance: float = field(default=0.1, metadata=meta("m", low=0))
    max_points: int = field(default=0, metadata=meta("", low=0))
    margin: float = field(default=0.03, metadata=meta("m", low=0, help="an arm's capsules keep this far from real returns"))
    reach: float = field(default=0.3, metadata=meta("m", low=0))
    arm_reach: float = field(default=0.2, metadata=meta("m", low=0))
    step: float = field(default=0.05, metadata=meta("m", low=0))
    min_range: float = field(default=1.0, metadata=meta("m", low=0))
    max_range: float = field(default=0.0, metadata=meta("m", low=0))
    supports: SupportParams = field(default_factory=SupportParams)


@dataclass(frozen=True)
class RealScanScene:
    """``scene.builder: real_scan``: a real scan as the background, objects cast in with the real sensor's own firings.

    path, format : the scan (format guessed from the file when empty: nuscenes, kitti, semantickitti, npy, ply, las, pcd);
        a folder or a glob pattern of scans gives frame k the k-th in name order (mod their number)
    preset : a sensor preset (hdl32e, hdl64e, ...) filling what the file lacks (its step, frame time, elevations)
    objects : placed explicitly; remove : boxes cut out of the real returns first
    parking_rule, kitti_rule : rule-based population (off by default)
    parking_rules : more parking rules, applied after ``parking_rule`` (one per class: ``bpy-pipeline match``)
    background_class : the class of real returns (SemanticKITTI labels are kept when ``keep_labels``)
    real_boxes : labelled real objects (class, box), whose occlusion is updated when inserted objects hide them
    ground : auto (Patchwork++ where installed, else RANSAC) | ransac | patchwork
    max_range : firings are cast this far, metres (0: the preset's, else 100 m)
    car_bodies : all (the 24 bodies of geometry/objects.py BODIES: sedans, hatchbacks, estates, SUVs, pickups, vans, one
        drawn per car; a rule's car takes its body's size) | classic (the builders' three styles at the rule's height:
        the frames made before the body set, byte for byte). Explicit ``objects`` keep their box either way.
    population : people and robot arms on the floors and desks found in the scan's points (:class:`RealPopulation`,
        :mod:`.supports`; off with no people and no arms)
    car_glass : what an inserted car's windows and cabin do to the beam (lidar/effects/materials.py :class:`CarGlass`: Fresnel
        and tint by incidence, a dark cabin; opt-in, ``enabled: true``; off: the windows of before)
    car_fittings : licence plates (retroreflector) and lamps (glossy) on every inserted car, their models applied
        to the inserted returns (geometry/objects.py ``car_fittings``)
    car_paint : a reflectance model per part of an inserted car (body, upper body and roof, glass, cabin, tyres, plates,
        lamps), the body's paint drawn per car (:class:`~.paint.CarPaint`; opt-in, ``enabled: true``)
    """

    path: str = ""
    format: str = ""
    preset: str = ""
    objects: list[ObjectBox] = field(default_factory=list)
    remove: list[RemoveBox] = field(default_factory=list)
    parking_rule: ParkingRule = field(default_factory=ParkingRule)
    parking_rules: list[ParkingRule] = field(default_factory=list)
    kitti_rule: KittiRule = field(default_factory=KittiRule)
    noise: NoiseInjections = field(default_factory=NoiseInjections)
    background_class: str = "unlabeled"
    keep_labels: bool = True
    real_boxes: list[ObjectBox] = field(default_factory=list)
    ground: Literal["auto", "ransac", "patchwork"] = "auto"
    max_range: float = field(default=0.0, metadata=meta("m", low=0))
    car_bodies: Literal["all", "classic"] = "all"
    population: RealPopulation = field(default_factory=RealPopulation)
    car_glass: CarGlass = field(default_factory=CarGlass)
    car_fittings: bool = True
    car_paint: CarPaint = field(default_factory=CarPaint)
