"""Where everything of a railway scene goes: cross-section, supports, wires, droppers, stations. Pure numpy.

:func:`plan` turns a ``RailwayScene`` config (``bpy_pipeline.config``) and a generator into a
:class:`RailwayLayout`: the alignment (:mod:`.alignment`), the supports every span along it
with their masts or gantry, and every wire of every span with its end points, sag and
diameter (:mod:`.catenary`). The bpy builder (``builders/railway/scene.py``) only turns this into
Blender objects, so everything here is testable without Blender.

Frames: a support or a station has a level frame (x ahead along the track, y to the left,
z up) at the alignment point of its chainage; lateral offsets and heights are in that frame,
heights from formation level (the alignment's z). Track i lies ``offsets[i]`` to the left of
the alignment, track 0 the rightmost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...geometry.lod import PathView, SensorView, polygon_sides, section_error
from . import catenary
from .alignment import Alignment, arc_through, with_transitions

STAY_RISE = 0.3  # m: cantilever stay tube above the messenger attachment
FEEDER_BRACKET = (0.6, -0.5)  # m: feeder beside (field side) and below the mast top
EARTH_BRACKET = (0.35, -1.5)  # m: earth wire beside and below the mast top
GANTRY_CLEARANCE = 0.8  # m: gantry beam above the messenger attachment
MIN_DROPPER = 0.15  # m: shortest dropper the system height must leave at mid-span
MAX_MID_SPAN_OFFSET = 0.4  # m: on a curve, spans shorten so the wire strays no further inside at mid-span
BEAM_RISE = 0.6  # m: a mast's beam to the cantilevers of its farther tracks, above the nearest cantilever's stay
ARM_RISE = 0.2  # m: the registration arm's root above the contact wire (the arm slopes about 10 deg)
SECTION_INSULATOR_CLEARANCE = 1.2  # m: no dropper this close to a section insulator's middle (it is 1.8 m long)
ARM_SHARE = 0.6  # the arm spans at most this share of its cantilever (so the main tube stays above the arm)


# ----------------------------------------------------------------------------- cross-section
@dataclass(frozen=True)
class CrossSection:
    """Widths and heights across the track group (m, heights from formation level).

    offsets : (tracks,) float64 lateral offsets of the track centrelines (+ left)
    """

    offsets: np.ndarray
    gauge: float
    rail_head_width: float
    rail_height: float
    sleeper_top: float
    ballast_height: float  # the bed's top: under the sleepers plus the crib ballast between them
    ballast_top_half: float
    ballast_toe_half: float
    embankment_top_half: float
    embankment_toe_half: float  # where the embankment's (or the cutting's) slope meets the ground
    embankment_height: float
    cut_depth: float = 0.0  # the ground this far above formation beyond a cutting's slopes (m)

    @classmethod
    def of(cls, track) -> "CrossSection":
        """The cross-section of a ``scene.track`` config section."""
        n = track.tracks
        offsets = (np.arange(n) - (n - 1) / 2.0) * track.track_spacing
        rail = track.rail
        top = (n - 1) * track.track_spacing / 2 + track.sleeper_length / 2 + track.ballast_shoulder
        toe = top + (track.ballast_height + track.crib_height) * track.ballast_slope
        berm = toe + track.embankment_berm
        return cls(
            offsets=offsets,
            gauge=track.gauge,
            rail_head_width=rail.head_width,
            rail_height=rail.foot_height + rail.web_height + rail.head_height,
            sleeper_top=track.ballast_height + track.sleeper_height,
            ballast_height=track.ballast_height + track.crib_height,
            ballast_top_half=top,
            ballast_toe_half=toe,
            embankment_top_half=berm,
            embankment_toe_half=berm + track.embankment_height * track.embankment_slope + track.cut_depth * track.cut_slope,
            embankment_height=track.embankment_height,
            cut_depth=track.cut_depth,
        )

    @property
    def ground_height(self) -> float:
        """Height (m, from formation) of the ground beyond the embankment (negative) or the cutting (positive)."""
        return self.cut_depth if self.cut_depth > 0 else -self.embankment_height

    @property
    def rail_top(self) -> float:
        """Height of the rail heads above formation (m)."""
        return self.sleeper_top + self.rail_height

    def rail_offsets(self, track: int) -> np.ndarray:
        """``(2,)`` lateral offsets of the right and left rail-head centres of ``track`` (m)."""
        half = self.gauge / 2 + self.rail_head_width / 2
        return self.offsets[track] + np.array([-half, half])

    def surface(self, lateral) -> np.ndarray:
        """Height (m, from formation) of the top surface at ``lateral`` offsets: ballast, berm, embankment or cutting, ground."""
        d = np.abs(np.asarray(lateral, float))
        h = self.ballast_height
        ballast = np.interp(d, [self.ballast_top_half, self.ballast_toe_half], [h, 0.0])
        ground = np.interp(d, [self.embankment_top_half, self.embankment_toe_half + 1e-12], [0.0, self.ground_height])
        return np.where(d <= self.ballast_toe_half, ballast, ground)


def track_alignment(track, where: str = "scene.track") -> Alignment:
    """The alignment of a ``scene.track`` section: the arc through start, mid and end, with clothoid transitions
    of ``transition_length`` m at both ends when that is > 0."""
    return with_transitions(arc_through(track.start, track.mid, track.end, where), track.transition_length, where)


def plan_radius(alignment: Alignment) -> float:
    """Radius (m) of the alignment's curve in plan; infinite on a straight line or a curve in a vertical plane."""
    if alignment.straight or math.hypot(alignment.normal[0], alignment.normal[1]) >= 0.999:
        return math.inf
    return alignment.radius / max(abs(alignment.normal[2]), 1e-12)


def cant(track, alignment: Alignment) -> float:
    """The cant (m): the outer rail's rise over the inner on the curve, ``track.cant`` (``cant_from: value``) or
    the equilibrium cant of ``track.design_speed`` (km/h), 11.8 v^2 / R mm (R in m), capped at ``track.max_cant``;
    0 on a straight line."""
    radius = plan_radius(alignment)
    if not math.isfinite(radius):
        return 0.0
    wanted = track.cant if track.cant_from == "value" else 11.8 * track.design_speed**2 / radius / 1000.0
    return float(min(max(wanted, 0.0), track.max_cant))


def cant_angle(track, alignment: Alignment) -> float:
    """Signed roll (radians) of the track about the direction of travel: positive raises its left rail (a curve
    turning right), over the distance between the rail-head centres (gauge + head width)."""
    e = cant(track, alignment)
    if e == 0.0:
        return 0.0
    left_turn = float(np.dot(alignment.lateral(np.array([alignment.length / 2]))[0],
                             alignment.centre - alignment.point(np.array([alignment.length / 2]))[0])) > 0
    angle = math.asin(min(e / (track.gauge + track.rail.head_width), 1.0))
    return -angle if left_turn else angle


# ----------------------------------------------------------------------------- supports and wires
@dataclass(frozen=True)
class Mast:
    """A mast or gantry leg: ``lateral`` (m) in its support's frame, ``outward`` +1 left / -1 right,
    ``base`` the ground height there and ``top`` its top (m from formation), ``tracks`` it carries
    cantilevers for."""

    side: str
    lateral: float
    outward: float
    base: float
    top: float
    kind: str
    tracks: tuple[int, ...]


@dataclass(frozen=True)
class Support:
    """One support position: ``frame`` (4, 4) level frame at the alignment point of ``chainage`` (m)."""

    index: int
    chainage: float
    frame: np.ndarray
    gantry: bool
    masts: tuple[Mast, ...]
    stagger: float  # signed lateral offset of the contact wire from its track centre here (m)


@dataclass(frozen=True)
class Wire:
    """One wire over one span. ``start``, ``end``: (3,) world attachment points (m); ``sag`` (m) at mid-span."""

    kind: str  # contact_wire, messenger_wire, feeder, earth_wire
    class_name: str
    run: str  # t<i> (track i), t<i>b (its second contact wire), right / left (a mast row)
    span: int  # between supports span and span + 1
    start: np.ndarray
    end: np.ndarray
    sag: float
    diameter: float

    @property
    def length(self) -> float:
        return float(np.linalg.norm((self.end - self.start)[:2]))

    def z_at(self, t) -> np.ndarray:
        """Wire height (m) at span parameters ``t`` (the thesis's parabola)."""
        t = np.asarray(t, float)
        return self.start[2] + t * (self.end[2] - self.start[2]) - 4.0 * self.sag * t * (1.0 - t)

    def points_at(self, t) -> np.ndarray:
        """``(k, 3)`` wire points at span parameters ``t`` (k,)."""
        t = np.asarray(t, float).reshape(-1)
        out = self.start + t[:, None] * (self.end - self.start)
        out[:, 2] = self.z_at(t)
        return out


@dataclass(frozen=True)
class Droppers:
    """The droppers of one contact wire over one span: ``lower`` and ``upper`` (n, 3) world end points (m)."""

    run: str
    span: int
    t: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    diameter: float


@dataclass(frozen=True)
class Overlap:
    """Where two tension sections of a track's catenary overlap: over span ``span`` (supports ``span`` and
    ``span + 1``) the ``ending`` run rises out of service towards its anchor at the far support while the
    ``starting`` run, beside it, comes down from its anchor at the near support into service."""

    span: int
    track: int
    ending: str
    starting: str


@dataclass(frozen=True)
class RailwayLayout:
    """Everything :func:`plan` places. ``double_contact`` (tracks,) bool: which tracks carry two contact wires.
    ``overlaps``: the tension-section overlaps (``catenary.tension_length``), none by default.
    ``signals``: ``(k, 4, 4)`` frames of the signals the built scene placed (drawn when it is built, after
    the plan; ``None`` for a plan not built)."""

    alignment: Alignment
    section: CrossSection
    layout: str
    supports: list[Support]
    wires: list[Wire]
    droppers: list[Droppers]
    double_contact: np.ndarray
    overlaps: tuple = ()
    signals: np.ndarray | None = None

    @property
    def spans(self) -> np.ndarray:
        """``(k,)`` span lengths (m) between consecutive supports, along the alignment."""
        return np.diff([s.chainage for s in self.supports])

    def support_cantilevers(self, support: Support, params) -> list["CantileverPlan"]:
        """:func:`cantilevers` of ``support`` under this layout's cross-section, with the catenary and track
        spacing of the ``RailwayScene`` ``params`` it was planned from (the railway_layout writer's arms)."""
        return cantilevers(support, self.section, params.catenary, params.track.track_spacing, None)


# ----------------------------------------------------------------------------- planning
def resolve_layout(layout: str, tracks: int, rng: np.random.Generator) -> str:
    """``auto`` -> single (1 track), single or both_sides at even odds (2), gantry (3-5)."""
    if layout != "auto":
        return layout
    if tracks == 1:
        return "single"
    if tracks == 2:
        return "single" if rng.random() < 0.5 else "both_sides"
    return "gantry"


def support_chainages(length: float, span: float, jitter: float, rng: np.random.Generator) -> np.ndarray:
    """``(k + 1,)`` chainages (m) of supports k spans apart, each span ``span`` +- ``jitter`` (uniform),
    as many as fit in ``length``, centred on the line; one support at the middle when none fits."""
    spans = []
    total = 0.0
    while True:
        step = span + (rng.uniform(-jitter, jitter) if jitter > 0 else 0.0)
        if total + step > length + 1e-9:
            break
        spans.append(step)
        total += step
    return (length - total) / 2.0 + np.concatenate([[0.0], np.cumsum(spans)])


def _masts(params, section: CrossSection, layout: str, gantry_top: float, beam_top: float, rng: np.random.Generator) -> list[Mast]:
    supports = params.supports
    n = len(section.offsets)
    right = section.offsets[0] - supports.mast_offset
    left = section.offsets[-1] + supports.mast_offset
    kinds = lambda: supports.mast_type if supports.mast_type != "mixed" else ("h_section" if rng.random() < 0.5 else "lattice")  # noqa: E731
    every = tuple(range(n))

    def mast(side, lateral, outward, carries, kind):
        base = float(section.surface(lateral))
        top = base + supports.mast_height
        if len(carries) > 1:  # its beam to the farther tracks passes above the nearest cantilever
            top = max(top, beam_top)
        return Mast(side, lateral, outward, base, gantry_top if layout == "gantry" else top, kind, carries)

    if layout == "single":
        lateral, outward = (right, -1.0) if supports.side == "right" else (left, 1.0)
        return [mast(supports.side, lateral, outward, every, kinds())]
    half = (n + 1) // 2
    if layout == "gantry":
        kind = kinds()
        return [mast("right", right, -1.0, every, kind), mast("left", left, 1.0, (), kind)]
    return [mast("right", right, -1.0, every[:half], kinds()), mast("left", left, 1.0, every[half:], kinds())]


def curve_span_limit(alignment: Alignment, stagger: float) -> float:
    """Longest span (m) on ``alignment`` whose chord, pulled ``stagger`` to the outside at both supports,
    strays at most :data:`MAX_MID_SPAN_OFFSET` inside the track centre at mid-span: sqrt(8 R (stagger + 0.4)),
    R the radius in plan; infinite on a straight line or a curve in a vertical plane."""
    if alignment.straight or math.hypot(alignment.normal[0], alignment.normal[1]) >= 0.999:
        return math.inf
    plan_radius = alignment.radius / max(abs(alignment.normal[2]), 1e-12)
    return math.sqrt(8.0 * plan_radius * (stagger + MAX_MID_SPAN_OFFSET))


def staggers(alignment: Alignment, chainages: np.ndarray, stagger: float) -> np.ndarray:
    """``(k,)`` signed contact-wire offsets (m, + left) at supports at ``chainages``.

    On a straight line, or a curve whose spans stray less than ``stagger`` from it (chord depth
    L^2 / (8 R) in plan), the wire zig-zags: +stagger, -stagger, ... On a sharper curve it is
    pulled to the outside of the curve at every support and its mid-spans lie inside.
    """
    signs = np.where(np.arange(len(chainages)) % 2 == 0, 1.0, -1.0)
    if alignment.straight or len(chainages) < 2:
        return stagger * signs
    horizontal = math.hypot(alignment.normal[0], alignment.normal[1]) < 0.999  # the arc turns in plan
    plan_radius = alignment.radius / max(abs(alignment.normal[2]), 1e-12)
    depth = float(np.diff(chainages).max()) ** 2 / (8.0 * plan_radius)
    if not horizontal or depth < stagger:
        return stagger * signs
    outward = -np.sign(np.einsum("ij,ij->i", alignment.lateral(chainages), alignment.centre - alignment.point(chainages)))
    return stagger * outward


def overlap_spans(chainages: np.ndarray, tension_length: float) -> list[int]:
    """Spans (index k: supports k and k + 1) where one tension section hands over to the next: the span
    holding each multiple of ``tension_length`` (m) from the first support, never the first or last span,
    at least two spans apart; none for ``tension_length`` 0."""
    if tension_length <= 0 or len(chainages) < 4:
        return []
    out = []
    for m in range(1, int((chainages[-1] - chainages[0]) / tension_length) + 1):
        k = int(np.searchsorted(chainages, chainages[0] + m * tension_length, side="right")) - 1
        if 1 <= k <= len(chainages) - 3 and (not out or k >= out[-1] + 2):
            out.append(k)
    return out


def run_name(track: int, section: int, second: bool = False) -> str:
    """A contact-line run: ``t<i>`` (track i's first tension section), ``t<i>s<m>`` (its section m), + ``b`` for its second contact wire."""
    return f"t{track}" + (f"s{section}" if section else "") + ("b" if second else "")


def plan(params, rng: np.random.Generator) -> RailwayLayout:
    """Place supports, wires and droppers for a ``RailwayScene`` config, drawing only from ``rng``.

    Draw order (fixed, so one seed gives one scene): layout, span lengths, mast types, doubled
    contact wires per track, dropper jitter per span and contact wire.
    """
    track, supports_cfg, cat = params.track, params.supports, params.catenary
    alignment = track_alignment(track)
    section = CrossSection.of(track)
    layout = resolve_layout(supports_cfg.layout, track.tracks, rng)
    span, jitter = supports_cfg.span, supports_cfg.span_jitter
    limit = curve_span_limit(alignment, cat.stagger)
    if span > limit:  # a sharp curve: shorter spans, the jitter in proportion
        span, jitter = limit, jitter * limit / span
    chainages = support_chainages(alignment.length, span, jitter, rng)
    frames = alignment.frames(chainages)
    contact_z = section.rail_top + cat.contact_wire_height
    messenger_z = contact_z + cat.system_height
    gantry_top = messenger_z + STAY_RISE + GANTRY_CLEARANCE
    beam_top = messenger_z + STAY_RISE + BEAM_RISE + 0.2
    offsets = staggers(alignment, chainages, cat.stagger)
    supports = []
    for k, (s, frame) in enumerate(zip(chainages, frames)):
        masts = tuple(_masts(params, section, layout, gantry_top, beam_top, rng))
        supports.append(Support(k, float(s), frame, layout == "gantry", masts, float(offsets[k])))
    double = rng.random(track.tracks) < cat.double_contact_probability

    def world(frame, lateral, z):
        return frame[:3, :3] @ np.array([0.0, lateral, z]) + frame[:3, 3]

    wires, droppers = [], []
    handovers = overlap_spans(chainages, cat.tension_length) if cat.enabled else []
    overlaps = []

    def run_span(i, sec, k, a, b, lateral_a, lateral_b, rise_a, rise_b):
        """One tension section's wires and droppers of track ``i`` over span ``k``; ``rise_*`` lift an end out of service."""
        base = run_name(i, sec)
        messenger = _wire("messenger_wire", base, k, world(a.frame, lateral_a, messenger_z + rise_a), world(b.frame, lateral_b, messenger_z + rise_b), cat)
        wires.append(messenger)
        auxiliary = None
        if cat.auxiliary_messenger:  # PA: the droppers hang the contact wire from it, and it from the messenger
            aux_z = contact_z + cat.auxiliary_messenger_height
            auxiliary = _wire("auxiliary_messenger", base, k, world(a.frame, lateral_a, aux_z + rise_a), world(b.frame, lateral_b, aux_z + rise_b), cat)
            wires.append(auxiliary)
        halves = (-cat.double_contact_spacing / 2, cat.double_contact_spacing / 2) if double[i] else (0.0,)
        shifts = (-0.25, 0.25) if double[i] else (0.0,)
        for j, (half, shift) in enumerate(zip(halves, shifts)):
            run = run_name(i, sec, bool(j))
            contact = _wire("contact_wire", run, k, world(a.frame, lateral_a + half, contact_z + rise_a), world(b.frame, lateral_b + half, contact_z + rise_b),
                            cat)
            wires.append(contact)
            t = catenary.dropper_positions(contact.length, cat.dropper_spacing, cat.dropper_jitter, rng, shift)
            if cat.section_insulator_every > 0 and (k + 1) % cat.section_insulator_every == 0:  # a section insulator at mid-span
                t = t[np.abs(t - 0.5) * contact.length >= SECTION_INSULATOR_CLEARANCE]
            above = messenger if auxiliary is None else auxiliary
            droppers.append(Droppers(run, k, t, contact.points_at(t), above.points_at(t), cat.dropper_diameter))
            # the upper tier, from the auxiliary messenger to the messenger, a quarter spacing on (clear of a second contact wire's droppers)
            if auxiliary is not None and j == 0:
                up = np.clip(t + 0.25 * cat.dropper_spacing / max(contact.length, 1e-9), 0.02, 0.98)
                droppers.append(Droppers(base + "p", k, up, auxiliary.points_at(up), messenger.points_at(up), cat.dropper_diameter))

    for k in range(len(supports) - 1):
        a, b = supports[k], supports[k + 1]
        if cat.enabled:
            sec = sum(1 for h in handovers if h < k)  # the tension section in service over span k
            for i, c in enumerate(section.offsets):
                lateral_a, lateral_b = c + a.stagger, c + b.stagger
                if k not in handovers:
                    run_span(i, sec, k, a, b, lateral_a, lateral_b, 0.0, 0.0)
                else:  # the ending run rises beside the starting one, which comes down into service
                    root = next(p.root_y for p in cantilevers(a, section, cat, track.track_spacing) if p.track == i)
                    toward = float(np.sign(root - lateral_a)) or -1.0  # the starting run hangs on the root's side of the wire at the near support
                    run_span(i, sec, k, a, b, lateral_a, lateral_b - toward * cat.overlap_spacing, 0.0, cat.overlap_rise)
                    run_span(i, sec + 1, k, a, b, lateral_a + toward * cat.overlap_spacing, lateral_b, cat.overlap_rise, 0.0)
                    overlaps.append(Overlap(k, i, run_name(i, sec), run_name(i, sec + 1)))
        for side in ("right", "left"):
            mast_a = next((m for m in a.masts if m.side == side), None)
            mast_b = next((m for m in b.masts if m.side == side), None)
            if mast_a is None or mast_b is None:
                continue
            for kind, enabled, (out, down) in (("feeder", cat.feeders, FEEDER_BRACKET), ("earth_wire", cat.earth_wire, EARTH_BRACKET)):
                if enabled:
                    ends = [world(s.frame, m.lateral + m.outward * out, m.top + down) for s, m in ((a, mast_a), (b, mast_b))]
                    wires.append(_wire(kind, side, k, *ends, cat))
    return RailwayLayout(alignment, section, layout, supports, wires, droppers, double, tuple(overlaps))


WIRE_CLASSES = {"contact_wire": "contact wire", "messenger_wire": "messenger wire", "feeder": "feeder wire", "earth_wire": "earth wire",
                "auxiliary_messenger": "auxiliary messenger"}


def _wire(kind: str, run: str, span: int, start, end, cat) -> Wire:
    length = float(np.linalg.norm((np.asarray(end) - np.asarray(start))[:2]))
    reference = {"contact_wire": cat.contact_wire_sag, "messenger_wire": cat.messenger_wire_sag, "feeder": cat.feeder_sag, "earth_wire": cat.earth_wire_sag,
                 "auxiliary_messenger": cat.auxiliary_messenger_sag}[kind]
    diameter = {"contact_wire": cat.contact_wire_diameter, "messenger_wire": cat.messenger_wire_diameter, "feeder": cat.feeder_diameter,
                "earth_wire": cat.earth_wire_diameter,
                "auxiliary_messenger": cat.auxiliary_messenger_diameter}[kind]
    sag = catenary.sag_for_span(length, reference, cat.sag_reference_length, cat.sag_exponent)
    return Wire(kind, WIRE_CLASSES[kind], run, span, np.asarray(start, float), np.asarray(end, float), sag, diameter)


# ----------------------------------------------------------------------------- cantilevers
@dataclass(frozen=True)
class CantileverPlan:
    """Where one track's cantilever goes at one support (laterals and heights in the support frame, m).

    track : the track it carries
    attach_y : lateral where the messenger and the contact wire hang (track centre + stagger)
    root_y : lateral of its root: the mast's face, or a drop tube hanging from ``drop_from``
    drop_from : height of the drop tube's top (a gantry beam's underside, or the mast's own beam), ``None`` at a mast face
    beam : ``(y0, y1, z)`` a level beam from the mast face to the drop tube (the farther tracks of a mast), or ``None``
    arm_length : horizontal reach (m) of the registration arm, from its root towards the mast to the contact wire
    """

    track: int
    attach_y: float
    root_y: float
    drop_from: float | None
    beam: tuple[float, float, float] | None
    arm_length: float


MAST_FACE = 0.15  # m: half the mast's width, where a cantilever's root sits
BEAM_RADIUS = 0.04  # m


def cantilevers(support: Support, section: CrossSection, cat, track_spacing: float, beam_underside: float | None = None) -> list[CantileverPlan]:
    """The cantilever of every track a support carries, sized from the stagger and the system height.

    The registration arm reaches ``cat.registration_arm_length`` (about 1.2 m; 1-1.5 m on real lines) from
    the contact wire back towards its root. A cantilever at a mast face carries the mast's nearest track;
    the farther ones hang from drop tubes under a level beam ``BEAM_RISE`` above the nearest cantilever's
    stay, as on a gantry, each drop tube ``reach`` m from its wires on the mast's side: far enough for
    the arm (arm / ARM_SHARE) and short of the neighbouring track's wires (track spacing - 0.7 m). No two
    tracks' fittings share any lateral band at the same height.
    """
    contact_z = section.rail_top + cat.contact_wire_height
    stay_z = contact_z + cat.system_height + STAY_RISE
    reach = min(cat.registration_arm_length / ARM_SHARE, track_spacing - 0.7 if len(section.offsets) > 1 else math.inf)
    out = []
    for mast in support.masts:
        face = mast.lateral - mast.outward * MAST_FACE
        order = sorted(mast.tracks, key=lambda i: abs(section.offsets[i] - mast.lateral))
        for rank, i in enumerate(order):
            attach = float(section.offsets[i] + support.stagger)
            if support.gantry:  # every drop tube on the right of its wires: the tracks' fittings never overlap
                root, drop, beam = attach - reach, beam_underside, None
            elif rank == 0:
                root, drop, beam = face, None, None
            else:
                root = attach + mast.outward * reach  # towards the mast
                beam_z = stay_z + BEAM_RISE
                root, drop, beam = root, beam_z - BEAM_RADIUS, (face, root, beam_z)
            length = abs(attach - root)
            arm = min(cat.registration_arm_length, ARM_SHARE * length)
            out.append(CantileverPlan(i, attach, float(root), drop, beam, float(arm)))
    return out


# ----------------------------------------------------------------------------- stations
def station_chainages(stations, length: float) -> np.ndarray:
    """``(n,)`` chainages (m) of the configured stations: the given ones, or the middles of ``count`` equal parts."""
    if stations.chainages:
        return np.asarray(stations.chainages, float)
    return (np.arange(stations.count) + 0.5) * length / max(stations.count, 1)


def station_frames(params) -> np.ndarray:
    """``(n, 4, 4)`` level frames of the scanner stations of a ``RailwayScene`` config (n = 0 for none).

    The origin is the station point on the ground, ``offset`` metres beyond the outermost track on
    ``side`` along the lateral perpendicular; x points along the track. Pure: no generator involved.
    """
    stations = params.stations
    alignment = track_alignment(params.track)
    chainages = station_chainages(stations, alignment.length)
    if len(chainages) == 0:
        return np.zeros((0, 4, 4))
    section = CrossSection.of(params.track)
    lateral = section.offsets[0] - stations.offset if stations.side == "right" else section.offsets[-1] + stations.offset
    return alignment.frames(chainages, lateral, float(section.surface(lateral)))


# ----------------------------------------------------------------------------- validation
def _positive(value, key: str, allow_zero: bool = False) -> None:
    if not (value > 0 or (allow_zero and value == 0)):
        raise InputError(f"{key}: must be {'>= 0' if allow_zero else '> 0'}, got {value}")


def check_railway(params, where: str = "scene") -> None:
    """``InputError`` naming the key when a ``RailwayScene`` config cannot describe a railway: the rules between its
    fields (each field's own range is its metadata's, the schema's)."""
    track, sup, cat, st = params.track, params.supports, params.catenary, params.stations
    t, s, c = f"{where}.track", f"{where}.supports", f"{where}.catenary"
    if not 0 <= track.cant <= track.max_cant:
        raise InputError(f"{t}.cant: must lie in 0..max_cant ({track.max_cant} m), got {track.cant}")
    if track.max_cant >= track.gauge:
        raise InputError(f"{t}.max_cant: must stay well below the gauge ({track.gauge} m), got {track.max_cant}")
    if track.cut_depth > 0 and track.embankment_height > 0:
        raise InputError(f"{t}.cut_depth: a track runs on an embankment or in a cutting, not both (embankment_height is {track.embankment_height})")
    if not 0 <= track.crib_height <= track.sleeper_height:
        raise InputError(f"{t}.crib_height: the ballast between the sleepers must lie in 0..sleeper_height ({track.sleeper_height} m), got {track.crib_height}")
    if track.tracks > 1 and track.track_spacing <= track.sleeper_length:
        raise InputError(f"{t}.track_spacing: must exceed the sleeper length ({track.sleeper_length} m) or the tracks overlap, got {track.track_spacing}")
    if track.gauge <= track.rail.head_width:
        raise InputError(f"{t}.gauge: must exceed the rail head width ({track.rail.head_width} m), got {track.gauge}")
    alignment = track_alignment(track, t)
    section = CrossSection.of(track)
    if track.ground_width / 2 <= section.embankment_toe_half:
        raise InputError(f"{t}.ground_width: must exceed the embankment's width ({2 * section.embankment_toe_half:.3g} m), got {track.ground_width}")

    if sup.span_jitter >= sup.span:
        raise InputError(f"{s}.span_jitter: must stay below span ({sup.span} m), got {sup.span_jitter} (a span must keep a length)")
    if sup.mast_offset < track.sleeper_length / 2 + 0.3:
        raise InputError(
            f"{s}.mast_offset: a mast must stand clear of the sleepers, at least {track.sleeper_length / 2 + 0.3:.3g} m from the track centre, got "
            f"{sup.mast_offset}"
        )
    limits = {"single": (1, 2), "both_sides": (1, 4), "gantry": (2, 5), "auto": (1, 5)}[sup.layout]
    if not limits[0] <= track.tracks <= limits[1]:
        raise InputError(f"{s}.layout: {sup.layout} serves {limits[0]} to {limits[1]} tracks, {t}.tracks is {track.tracks}")

    if not math.isfinite(cat.sag_exponent):
        raise InputError(f"{c}.sag_exponent: must be a finite number, got {cat.sag_exponent}")
    if cat.double_contact_probability > 0:
        _positive(cat.double_contact_spacing, f"{c}.double_contact_spacing")
    if cat.dropper_jitter >= cat.dropper_spacing / 2:
        raise InputError(f"{c}.dropper_jitter: must stay below half the dropper spacing ({cat.dropper_spacing / 2} m), got {cat.dropper_jitter}")
    if cat.stagger >= sup.mast_offset:
        raise InputError(f"{c}.stagger: must stay below the mast offset ({sup.mast_offset} m), got {cat.stagger}")
    longest = sup.span + sup.span_jitter
    sag = lambda ref: catenary.sag_for_span(longest, ref, cat.sag_reference_length, cat.sag_exponent)  # noqa: E731
    clearance = cat.system_height - sag(cat.messenger_wire_sag) + sag(cat.contact_wire_sag)
    if cat.auxiliary_messenger:
        _positive(cat.auxiliary_messenger_diameter, f"{c}.auxiliary_messenger_diameter")
        _positive(cat.auxiliary_messenger_sag, f"{c}.auxiliary_messenger_sag", allow_zero=True)
        low = cat.auxiliary_messenger_height - sag(cat.auxiliary_messenger_sag) + sag(cat.contact_wire_sag)
        high = clearance - cat.auxiliary_messenger_height + sag(cat.auxiliary_messenger_sag) - sag(cat.contact_wire_sag)
        if min(low, high) < MIN_DROPPER / 2:
            raise InputError(
                f"{c}.auxiliary_messenger_height: the auxiliary messenger must hang clear of the contact wire and the messenger over a {longest:g} m span "
                f"(0.075 m each), got {cat.auxiliary_messenger_height}"
            )
    if cat.enabled and clearance < MIN_DROPPER:
        raise InputError(
            f"{c}.system_height: the messenger would sag to {clearance:.3g} m above the contact wire over a {longest:g} m span; raise it or lower "
            "messenger_wire_sag"
        )
    messenger = section.rail_top + cat.contact_wire_height + cat.system_height
    lowest = float(min(section.surface(section.offsets[0] - sup.mast_offset), section.surface(section.offsets[-1] + sup.mast_offset)))
    if sup.layout != "gantry" and lowest + sup.mast_height < messenger + STAY_RISE + 0.1:
        raise InputError(
            f"{s}.mast_height: a mast must reach above the cantilever ({messenger + STAY_RISE + 0.1 - lowest:.3g} m over its base), got {sup.mast_height}"
        )

    for i, chainage in enumerate(st.chainages):
        if not 0 <= chainage <= alignment.length:
            raise InputError(f"{where}.stations.chainages[{i}]: must lie along the line, 0..{alignment.length:.6g} m, got {chainage}")


# ----------------------------------------------------------------------------- level of detail
MIN_TOLERANCE = 1e-4  # m: no shape is modelled finer than this
MIN_WIRE_SIDES = 6  # a hexagon's width varies +-5 % with the viewing angle, a square's +-17 %: thin wires keep their hit rate
MAX_WIRE_SIDES = 12


@dataclass(frozen=True)
class RailwayDetailPlan:
    """What to build and how finely (:func:`level_of_detail`).

    centreline_tolerance : m, chord error of the sampled alignment
    track_trim, ground_trim : (start, end) chainages (m) of the track parts and of the ground strip
    stone_radius : m around each optical centre where ballast stones are modelled (0: none)
    stone_trims : ``(k, (start, end))``: the chainages where stones of patch k can lie (none without stones):
        around each static optical centre near enough to the ballast, or along a moving sensor's path in
        consecutive stretches of at most ``STONE_STRETCH`` m of line that do not overlap
    stone_centres : per entry of ``stone_trims``, ``(c, 3)`` world points: stones lie within ``stone_radius``
        of one of them (the station; for a path, points along it every ``stone_radius / 8`` at most)
    supports : indices of the supports to build
    wires : per wire of ``layout.wires``, ``(samples, sides)``, or ``None`` when not built
    droppers : per dropper set of ``layout.droppers``, True when built
    """

    centreline_tolerance: float
    track_trim: tuple[float, float]
    ground_trim: tuple[float, float]
    stone_radius: float
    stone_trims: list[tuple[int, tuple[float, float]]]
    stone_centres: list[np.ndarray]
    supports: list[int]
    wires: list[tuple[int, int] | None]
    droppers: list[bool]


def wire_tolerance(wire: Wire, view) -> float:
    """Largest modelling error (m) of ``wire`` the view cannot see: half the beam spacing at its nearest distance."""
    distance = float(view.segment_distance(wire.start, wire.end)[0]) - wire.sag
    return max(float(view.tolerance(max(distance, 0.5))), MIN_TOLERANCE)


def _within(alignment: Alignment, view, reach: float, lateral: float) -> tuple[float, float]:
    """Chainage interval of the alignment whose cross-section (``lateral`` m either side) may lie within ``reach`` of the view."""
    s = np.linspace(0.0, alignment.length, max(2, int(np.ceil(alignment.length)) + 1))
    near = view.distance(alignment.point(s)) <= reach + lateral
    if not near.any():
        return (0.0, 0.0)
    step = s[1] - s[0]
    return (max(0.0, float(s[near].min()) - step), min(alignment.length, float(s[near].max()) + step))


def level_of_detail(layout: RailwayLayout, params, view=None) -> RailwayDetailPlan:
    """Detail of every part of ``layout`` for a :class:`~.lod.SensorView` (``None`` or ``detail.mode: fixed``:
    everything, wires at ``catenary.points_per_10m``, no stones).

    Sensor-driven: wires sampled so that chords and polygonal cross-section together stay within half
    the beam spacing at their nearest distance, the alignment likewise at its nearest distance,
    ballast stones only within ``stone_size / (2 step)`` of an optical centre, and nothing whose
    every point lies beyond the sensor's range.
    """
    alignment, track = layout.alignment, params.track
    everything = (0.0, alignment.length)
    if view is None or params.detail.mode == "fixed":
        per_10m = params.catenary.points_per_10m
        wires = [(catenary.thesis_sample_count(w.length, per_10m), 6) for w in layout.wires]
        return RailwayDetailPlan(0.005, everything, everything, 0.0, [], [], list(range(len(layout.supports))), wires, [True] * len(layout.droppers))
    reach = view.max_range
    nearest = float(view.distance(alignment.point(alignment.nearest_chainage(view.positions))).min())
    centreline_tolerance = max(float(view.tolerance(max(nearest, 0.5))), MIN_TOLERANCE)
    track_trim = _within(alignment, view, reach, layout.section.embankment_toe_half)
    ground_trim = _within(alignment, view, reach, track.ground_width / 2)
    stone_radius = view.resolve_radius(params.detail.stone_size) if params.detail.stones else 0.0
    stone_trims, stone_centres = [], []
    if stone_radius > 0 and isinstance(view, PathView):
        stone_trims, stone_centres = _path_stones(alignment, view, stone_radius, layout.section.ballast_toe_half)
    elif stone_radius > 0:
        for k, position in enumerate(view.positions):  # each centre's own stretch, so each frame exports only its own stones
            own = SensorView(position[None], view.step, stone_radius)
            trim = _within(alignment, own, stone_radius, layout.section.ballast_toe_half)
            if trim[1] > trim[0]:
                stone_trims.append((k, trim))
                stone_centres.append(np.asarray(position, float)[None])
    supports = []
    for support in layout.supports:
        extent = max(abs(m.lateral) for m in support.masts) + max(m.top for m in support.masts)
        if view.distance(support.frame[:3, 3])[0] <= reach + extent:
            supports.append(support.index)
    wires = []
    for wire in layout.wires:
        if float(view.segment_distance(wire.start, wire.end)[0]) - wire.sag > reach:
            wires.append(None)
            continue
        tolerance = wire_tolerance(wire, view)
        sides = min(polygon_sides(wire.diameter / 2, tolerance / 2, MIN_WIRE_SIDES), MAX_WIRE_SIDES)
        chords = max(tolerance - section_error(wire.diameter / 2, sides), tolerance / 2)  # section and chords share it
        wires.append((catenary.samples_for_tolerance(wire.sag, chords), sides))
    droppers = [bool((view.segment_distance(d.lower, d.upper) <= reach).any()) for d in layout.droppers]
    return RailwayDetailPlan(centreline_tolerance, track_trim, ground_trim, stone_radius, stone_trims, stone_centres, supports, wires, droppers)


STONE_STRETCH = 20.0  # m of line per stones object along a path: a frame exports the stretches in its reach


def _path_stones(alignment: Alignment, view: PathView, radius: float, lateral: float) -> tuple[list, list]:
    """Stones along a moving sensor's path: the line within ``radius`` (+ ``lateral`` m of ballast either
    side) of the path, cut into consecutive stretches of at most ``STONE_STRETCH`` m (their trims touch
    and never overlap, so no stone is made twice); each stretch's centres are the path's points near it."""
    trim = _within(alignment, view, radius, lateral)
    if not trim[1] > trim[0]:
        return [], []
    centres = view.samples(radius / 8.0)  # points of the path: the distance to them overshoots the path's by < radius / 128
    cuts = np.linspace(trim[0], trim[1], int(np.ceil((trim[1] - trim[0]) / STONE_STRETCH)) + 1)
    trims, groups = [], []
    for k, (s0, s1) in enumerate(zip(cuts[:-1], cuts[1:])):
        line = alignment.point(np.linspace(s0, s1, max(2, int(np.ceil(s1 - s0)) + 1)))
        stretch = SensorView(line, view.step, view.max_range)
        near = centres[stretch.distance(centres) <= radius + lateral + 1.0]
        if len(near):
            trims.append((k, (float(s0), float(s1))))
            groups.append(near)
    return trims, groups
