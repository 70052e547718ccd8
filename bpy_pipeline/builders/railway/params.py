"""``scene.builder: railway``: tracks, supports and catenary along an arc, scanned from stations beside the track."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ...schema import meta
from ...errors import InputError
from ...geometry.clearance import CLEARANCE
from ..base import Builder, BuildContext, BuildResult, register_builder
from .parts import H_SECTION, LATTICE

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class RailProfile:
    """A simplified flat-bottom rail: three stacked rectangles (m). The default weighs about 60 kg/m
    (7.63e-3 m^2 of steel; UIC 60: 172 mm high, 150 mm foot, 72 mm head, 16.5 mm web)."""

    foot_width: float = field(default=0.150, metadata=meta("m", low=0, low_open=True))
    foot_height: float = field(default=0.018, metadata=meta("m", low=0, low_open=True))
    web_width: float = field(default=0.0165, metadata=meta("m", low=0, low_open=True))
    web_height: float = field(default=0.111, metadata=meta("m", low=0, low_open=True))
    head_width: float = field(default=0.072, metadata=meta("m", low=0, low_open=True))
    head_height: float = field(default=0.043, metadata=meta("m", low=0, low_open=True))


@dataclass(frozen=True)
class RailwayTrack:
    """``scene.track``: the railway thesis's table 4.1, in metres (the thesis gives no values; these are
    European standard-gauge ones). The alignment is the arc through start, mid and end (straight when
    they are collinear), at formation level (the underside of the ballast); tracks are spread evenly
    across it, track 0 the rightmost in the direction of travel."""

    start: Vec3 = field(default=(-75.0, 0.0, 0.0), metadata=meta("m"))
    mid: Vec3 = field(default=(0.0, 0.0, 0.0), metadata=meta("m"))
    end: Vec3 = field(default=(75.0, 0.0, 0.0), metadata=meta("m"))
    gauge: float = field(default=1.435, metadata=meta("m", low=0, low_open=True, help="between the inner faces of the rail heads"))
    rail: RailProfile = field(default_factory=RailProfile)
    sleeper_spacing: float = field(default=0.6, metadata=meta("m", low=0, low_open=True))
    sleeper_length: float = field(default=2.6, metadata=meta("m", low=0, low_open=True, help="concrete monoblock sleeper (B70-like): across the track"))
    sleeper_width: float = field(default=0.26, metadata=meta("m", low=0, low_open=True, help="along the track"))
    sleeper_height: float = field(default=0.22, metadata=meta("m", low=0, low_open=True))
    ballast_height: float = field(default=0.35, metadata=meta("m", low=0, low_open=True, help="under the sleepers"))
    crib_height: float = field(
        default=0.17, metadata=meta("m", help="ballast between the sleepers, above their underside (0 to sleeper_height; 0: bare sleepers on the bed)")
    )
    ballast_shoulder: float = field(default=0.5, metadata=meta("m", low=0, help="beyond the sleeper ends"))
    ballast_slope: float = field(default=1.5, metadata=meta("", low=0, help="horizontal per vertical"))
    tracks: int = field(default=1, metadata=meta("", 1, 5, help="parallel tracks"))
    track_spacing: float = field(default=4.0, metadata=meta("m", low=0, low_open=True, help="between neighbouring track centrelines"))
    embankment_height: float = field(default=0.0, metadata=meta("m", low=0, help="formation above the surrounding ground"))
    embankment_slope: float = field(default=1.5, metadata=meta("", low=0, help="horizontal per vertical"))
    embankment_berm: float = field(default=1.0, metadata=meta("m", low=0, help="flat formation beyond the ballast toe"))
    ground_width: float = field(default=80.0, metadata=meta("m", low=0, low_open=True, help="flat ground strip along the alignment"))
    cut_depth: float = field(default=0.0, metadata=meta("m", low=0, help="the track in a cutting this deep (the ground beyond its slopes; 0: none)"))
    cut_slope: float = field(default=1.5, metadata=meta("", low=0, help="horizontal per vertical"))
    ground_roughness: float = field(default=0.0, metadata=meta("m", low=0, help="amplitude of the ground's undulation beyond the slopes (0: flat)"))
    ground_wavelength: float = field(default=20.0, metadata=meta("m", low=0, low_open=True, help="the undulation's longest wavelength"))
    transition_length: float = field(default=0.0, metadata=meta("m", low=0, help="of clothoid at each end of a curve (0: none); the cant ramps along it"))
    cant_from: Literal["speed", "value"] = "speed"  # the cant on curves: of design_speed, or the cant value
    design_speed: float = field(default=100.0,
                                metadata=meta("", low=0, help="km/h: on a curve the outer rail is raised by the equilibrium cant 11.8 v^2 / R mm"))
    cant: float = field(default=0.0, metadata=meta("m", help="with cant_from: value"))
    max_cant: float = field(default=0.16, metadata=meta("m", low=0, help="the cant never exceeds this (EN 13803: 160 mm on ballasted track)"))


@dataclass(frozen=True)
class RailwaySupports:
    """``scene.supports``: masts (H-section or lattice) with cantilevers and registration arms, or portal
    gantries, every ``span`` +- ``span_jitter`` metres along the alignment (the thesis: 40 to 65 m).
    ``layout``: ``single`` one mast per support on ``side`` carrying up to two tracks; ``both_sides`` a mast
    on each side, each carrying the nearer half of the tracks (up to four); ``gantry`` a portal over
    2 to 5 tracks; ``auto`` single for one track, single or both_sides (even odds) for two, gantry beyond.
    On a curve of radius R (in plan) spans shorten to sqrt(8 R (stagger + 0.4 m)), so the contact wire,
    pulled outwards at every support, strays at most 0.4 m inside the track at mid-span."""

    layout: Literal["auto", "single", "both_sides", "gantry"] = "auto"
    side: Literal["right", "left"] = "right"
    span: float = field(default=50.0, metadata=meta("m", low=0, low_open=True))
    span_jitter: float = field(default=5.0, metadata=meta("m", low=0))
    mast_type: Literal["h_section", "lattice", "mixed"] = "h_section"
    mast_offset: float = field(default=3.2, metadata=meta("m", help="from the centreline of the nearest track"))
    mast_height: float = field(default=8.5, metadata=meta("m", help="above the ground it stands on"))


@dataclass(frozen=True)
class RailwayCatenary:
    """``scene.catenary``: the catenary manager of the thesis (table 4.2), in metres. Sag of a wire over a
    span L: f(L) = <wire>_sag (L / sag_reference_length) ^ sag_exponent; droppers n = max(1, floor(L /
    dropper_spacing)) per contact wire. ``points_per_10m`` samples the wires when ``scene.detail.mode`` is
    ``fixed``; the sensor-driven default samples them as finely as the sensor can tell apart."""

    enabled: bool = True  # ENABLE_CATENARY: contact and messenger wires, droppers
    feeders: bool = True  # ENABLE_FEEDERS
    earth_wire: bool = True  # ENABLE_CdPA
    contact_wire_height: float = field(default=5.5, metadata=meta("m", low=0, low_open=True, help="above the rail heads"))
    system_height: float = field(default=1.4, metadata=meta("m", low=0, low_open=True, help="messenger above the contact wire at the supports (1.1-1.8)"))
    stagger: float = field(default=0.2, metadata=meta("m", low=0, help="contact wire zig-zag at the supports, +- (0.2-0.3)"))
    registration_arm_length: float = field(default=1.2, metadata=meta("m", help="horizontal reach of the registration arm (1-1.5 m on real lines)"))
    double_contact_probability: float = field(default=0.0, metadata=meta("", 0, 1, help="FC_DOUBLE_PROBABILITY, per track"))
    double_contact_spacing: float = field(default=0.04, metadata=meta("m", help="FC_DOUBLE_SPACING: between the two contact wires"))
    sag_reference_length: float = field(default=50.0, metadata=meta("m", low=0, help="SAG_REFERENCE_LENGTH"))
    sag_exponent: float = field(default=2.0, metadata=meta("", help="SAG_EXPONENT_ALPHA (2: sag grows with L^2 at a fixed tension)"))
    contact_wire_sag: float = field(default=0.05, metadata=meta("m", low=0, help="SAG_* at the reference length (contact wire: pre-sag, 1/1000 of the span)"))
    messenger_wire_sag: float = field(default=0.5, metadata=meta("m", low=0))
    feeder_sag: float = field(default=1.0, metadata=meta("m", low=0))
    earth_wire_sag: float = field(default=0.8, metadata=meta("m", low=0))
    contact_wire_diameter: float = field(default=0.012, metadata=meta("m", low=0, low_open=True, help="DIAM_*: 107 mm^2 grooved copper"))
    messenger_wire_diameter: float = field(default=0.011, metadata=meta("m", low=0, low_open=True))
    feeder_diameter: float = field(default=0.024, metadata=meta("m", low=0, low_open=True))
    earth_wire_diameter: float = field(default=0.012, metadata=meta("m", low=0, low_open=True))
    dropper_diameter: float = field(default=0.005, metadata=meta("m", low=0, low_open=True))
    dropper_spacing: float = field(default=5.0, metadata=meta("m", low=0, low_open=True, help="PENDULUM_SPACING"))
    dropper_jitter: float = field(default=0.2, metadata=meta("m", low=0, help="PENDULUM_JITTER, +- along the span"))
    points_per_10m: int = field(default=20, metadata=meta("", low=1, help="CURVE_RESOLUTION_POINTS_PER_10M, for scene.detail.mode fixed"))
    anchors: bool = False  # the end masts anchor the wires: a pulley bracket and a tensioning weight stack behind each
    section_insulator_every: int = field(default=0,
                                         metadata=meta("", low=0, help="a section insulator on the contact wires at the middle of every k-th span (0: none)"))
    auxiliary_messenger: bool = False  # PA: a wire between messenger and contact wire, the droppers in two tiers
    auxiliary_messenger_height: float = field(default=0.3, metadata=meta("m", help="above the contact wire at the supports (assumed)"))
    auxiliary_messenger_sag: float = field(default=0.1,
                                           metadata=meta("m", help="at the reference length (assumed: between the contact wire's and the messenger's)"))
    auxiliary_messenger_diameter: float = field(default=0.0105, metadata=meta("m", help="(assumed: a 65 mm^2 bronze wire)"))
    steady_arms: bool = False  # the registration arm ends in a steady arm, a part apart (class steady arm), hinged steady_arm_length from the wire
    steady_arm_length: float = field(default=0.5, metadata=meta("m", help="horizontal reach of the steady arm (part of registration_arm_length)"))
    tension_length: float = field(
        default=0.0, metadata=meta("m", low=0, help="tension sections about this long, overlapping over one span at each end (0: one section for the line)")
    )
    overlap_spacing: float = field(default=0.2, metadata=meta("m", help="between the two wire runs side by side over an overlap span"))
    overlap_rise: float = field(default=0.5,
                                metadata=meta("m", 0, 1, low_open=True, help="the run out of service rises over the overlap span towards its anchor"))


@dataclass(frozen=True)
class RailwayStations:
    """``scene.stations``: static scanner stations beside the track, ``offset`` metres beyond the outermost
    track on ``side``, on the ground there, facing along the track (the preset's mount_height lifts the
    sensor above it: 2 m for railway_tls). Frame k scans from station k mod n, and one built line serves
    n frames in a row (frames = stations scans one line from every station). ``chainages`` (m from the
    start point) place them; else ``count`` stations sit at the middles of equal parts of the line.
    ``count: 0`` uses sensor.position instead."""

    count: int = field(default=1, metadata=meta("", low=0))
    chainages: list[float] = field(default_factory=list, metadata=meta("m"))
    side: Literal["right", "left"] = "left"  # the masts stand on the right: the scanner sees them across the track
    offset: float = field(default=4.0, metadata=meta("m", low=0))


@dataclass(frozen=True)
class RailwayDetail:
    """``scene.detail``: ``sensor`` (the default) models no finer than the scanner resolves: wire sampling
    and cross-sections within half the beam spacing at their distance, ballast stones of ``stone_size``
    only where two beams fall on one, nothing beyond the sensor's range. ``fixed`` samples wires at
    catenary.points_per_10m, builds the whole line and no stones."""

    mode: Literal["sensor", "fixed"] = "sensor"
    stones: bool = True
    stone_size: float = field(default=0.045, metadata=meta("m", low=0, low_open=True, help="ballast grading 31.5/63 mm"))


@dataclass(frozen=True)
class RailwayTrackside:
    """``scene.trackside``: fences, signals and a platform (each off by default), see builders/railway/trackside.py."""

    fences: bool = False
    fence_offset: float = field(default=6.0, metadata=meta("m", low=0, low_open=True, help="from the outermost track centres, both sides"))
    fence_height: float = field(default=1.8, metadata=meta("m", low=0, low_open=True))
    fence_post_spacing: float = field(default=2.5, metadata=meta("m", low=0, low_open=True))
    signal_spacing: float = field(default=0.0, metadata=meta("m", low=0, help="between signals (+- a quarter); 0: none"))
    signal_side: Literal["right", "left"] = "right"
    signal_height: float = field(default=4.5, metadata=meta("m", low=0, low_open=True))
    platform_length: float = field(default=0.0, metadata=meta("m", low=0, help="0: none"))
    platform_chainage: float = field(default=-1.0, metadata=meta("m", help="the platform's middle; < 0: the line's middle"))
    platform_side: Literal["right", "left"] = "left"
    platform_edge: float = field(default=1.65, metadata=meta("m", low=0, low_open=True, help="from the centre of the nearest track"))
    platform_width: float = field(default=4.0, metadata=meta("m", low=0, low_open=True))
    platform_height: float = field(default=0.76, metadata=meta("m", low=0, help="above the rail heads"))
    vegetation_per_100m: float = field(default=0.0,
                                       metadata=meta("", low=0,
                                                     help="trees and bushes per side and 100 m, beyond the fences (or 2 m beyond the masts); 0: none"))


@dataclass(frozen=True)
class RailwayAssets:
    """``scene.assets``: support assets from files (glTF/GLB, OBJ, PLY; IFC with ifcopenshell) in place of the
    procedural ones, at every support the level of detail builds (builders/railway/assets.py, docs/railway.md).
    The asset's origin is its support's foot, its +Y facing the track, Z up, metres. ``classes``: ``{object or
    material name glob: class}`` for its parts; else a name beginning with a support class names it (``insulator*``)."""

    mast: str = ""  # replaces each mast of a single or both_sides layout (with its brackets)
    cantilever: str = ""  # replaces each mast-face cantilever assembly (cantilever, registration arm, insulators, steady arm)
    gantry: str = ""  # replaces each portal of a gantry layout
    unit_scale: float = field(default=1.0, metadata=meta("", low=0, low_open=True, help="metres per file unit (OBJ and PLY drawn in mm: 0.001)"))
    classes: dict = field(default_factory=dict)


@dataclass(frozen=True)
class RailwayScene:
    """``scene.builder: railway``: tracks on an arc or a straight line, supports, catenary, scanner stations."""

    track: RailwayTrack = field(default_factory=RailwayTrack)
    supports: RailwaySupports = field(default_factory=RailwaySupports)
    catenary: RailwayCatenary = field(default_factory=RailwayCatenary)
    stations: RailwayStations = field(default_factory=RailwayStations)
    detail: RailwayDetail = field(default_factory=RailwayDetail)
    trackside: RailwayTrackside = field(default_factory=RailwayTrackside)
    assets: RailwayAssets = field(default_factory=RailwayAssets)
    reroll_every: int = field(default=0, metadata=meta("", low=0, help="0: one railway per run, drawn from frame 0's generator; k: a new one every k frames"))

    @property
    def place_sensor(self) -> bool:
        """True when the stations place the sensor (then sensor.position is not used, nor saved)."""
        return self.stations.count > 0 or bool(self.stations.chainages)



def check(params: RailwayScene, where: str) -> None:
    """``InputError`` naming the key of a rule between the fields (each field's range is its metadata's, the schema's)."""
    from .layout import check_railway

    side = params.trackside
    if side.fences and side.fence_offset <= params.supports.mast_offset + 0.5:
        raise InputError(
            f"{where}.trackside.fence_offset: a fence must stand beyond the masts ({params.supports.mast_offset + 0.5} m), got {side.fence_offset}"
        )
    cat = params.catenary
    if not 0 < cat.overlap_spacing < params.track.track_spacing / 4:
        raise InputError(
            f"{where}.catenary.overlap_spacing: must lie in (0, {params.track.track_spacing / 4:g}) m (a quarter of the track spacing), got "
            f"{cat.overlap_spacing}"
        )
    if cat.steady_arms and not 0.2 <= cat.steady_arm_length <= cat.registration_arm_length - 0.2:
        raise InputError(
            f"{where}.catenary.steady_arm_length: must lie in [0.2, registration_arm_length - 0.2 = {cat.registration_arm_length - 0.2:g}] m, got "
            f"{cat.steady_arm_length}"
        )
    check_station_clearance(params, where)
    check_railway(params, where)
    from .assets import check_assets
    from ...labels import load_class_table

    check_assets(params.assets, f"{where}.assets", load_class_table().names.values())


STATION_CLEARANCE = CLEARANCE  # m: a station's sensor keeps this from every mast and fence
MAST_REACH = max(H_SECTION[0], LATTICE[0]) / math.sqrt(2.0)  # m: how far a mast reaches from its axis (a 0.40 m lattice's half diagonal)


def check_station_clearance(params: RailwayScene, where: str) -> None:
    """``InputError`` when the stations stand in the line of the masts or the fence on their side: their sensor would
    stand in (or within 0.5 m of) a mast wherever a support falls at a station's chainage."""
    st, sup = params.stations, params.supports
    if not params.place_sensor:
        return
    mast_sides = {"single": {sup.side}, "both_sides": {"right", "left"}, "gantry": {"right", "left"}}.get(
        sup.layout, {sup.side} if params.track.tracks == 1 else {"right", "left"}
    )
    if st.side in mast_sides and abs(st.offset - sup.mast_offset) < MAST_REACH + STATION_CLEARANCE - 1e-9:
        raise InputError(
            f"{where}.stations.offset: stations {st.offset} m beyond the outer track stand in the masts' line ({where}.supports.mast_offset: "
            f"{sup.mast_offset} m) on the {st.side}; keep them at least {MAST_REACH + STATION_CLEARANCE:.2f} m apart"
        )
    side = params.trackside
    if side.fences and abs(st.offset - side.fence_offset) < STATION_CLEARANCE + 0.05:
        raise InputError(
            f"{where}.stations.offset: stations {st.offset} m beyond the outer track stand in the fence's line ({where}.trackside.fence_offset: "
            f"{side.fence_offset} m); keep them at least {STATION_CLEARANCE + 0.05:g} m apart"
        )


def station(params: RailwayScene, frame: int) -> np.ndarray | None:
    """Station ``frame`` mod n of ``scene.stations`` (x along the track, z up), ``None`` without stations."""
    from .layout import station_frames

    stations = station_frames(params)
    return stations[frame % len(stations)] if len(stations) else None


def stations(params: RailwayScene) -> int:
    """How many stations ``station`` cycles through (0 without ``scene.stations``)."""
    from .layout import station_frames

    return len(station_frames(params))


ONE_SCENE_PER_RUN = 2**31 - 1  # frames: more than any run has, so frame k always scans the scene built for frame 0


def frames_per_scene(params: RailwayScene) -> int:
    """One built line serves every frame of the run (stations in turn, or a trajectory), drawn once from
    frame 0's generator; ``reroll_every: k`` builds a new line from frame k's generator every k frames
    (k = the number of stations: each station cycle scans its own line)."""
    return params.reroll_every if params.reroll_every > 0 else ONE_SCENE_PER_RUN


def release_sensor(params: RailwayScene, raw_scene: dict, sensor_data: dict) -> RailwayScene:
    """A sensor.position or trajectory given explicitly replaces the default stations; stations
    configured explicitly as well are an error (one of them places the sensor)."""
    if not any(sensor_data.get(k) is not None for k in ("position", "trajectory")):
        return params
    given = sensor_data.get("trajectory") is not None and "trajectory" or "position"
    stations = raw_scene.get("stations")
    if isinstance(stations, dict) and (stations.get("count", 0) or stations.get("chainages")):
        raise InputError(f"sensor.{given}: scene.stations place the scanner of this railway; give one of them (scene.stations.count: 0 to use sensor.{given})")
    return dataclasses.replace(params, stations=dataclasses.replace(params.stations, count=0, chainages=[]))


def build(params: RailwayScene, context: BuildContext) -> BuildResult:
    from . import scene as railway

    layout = railway.build(params, context.rng, context.view)
    info = {"layout": layout.layout, "length_m": round(float(layout.alignment.length), 4), "supports": len(layout.supports),
            "spans_m": [round(float(s), 4) for s in layout.spans]}
    return BuildResult(info=info, scene=layout)


register_builder("railway", Builder(RailwayScene, build, check, station, frames_per_scene, stations, release_sensor=release_sensor, follows_path=True))
