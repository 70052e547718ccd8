"""Triangle meshes of overhead-line supports: masts, bars, tubes, insulators. Pure numpy.

Every function returns ``(vertices (n, 3) float64 metres, triangles (m, 3) int32)`` in the
support's level frame (x along the track, y to the left, z up), like :mod:`.primitives`.
"""

from __future__ import annotations

import numpy as np

from ...geometry import primitives

H_SECTION = (0.30, 0.30, 0.02)  # m: flange width (along y), depth (along x), plate thickness
LATTICE = (0.40, 0.05, 0.025, 0.6)  # m: square width, corner chord, brace, panel height


def _perpendiculars(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([0.0, 0.0, 1.0]) if abs(direction[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(direction, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(direction, u)


def tube(p0, p1, radius: float, sides: int = 8):
    """A capped prism of ``sides`` sides around the segment ``p0``-``p1`` ((3,) m each)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    axis = p1 - p0
    length = float(np.linalg.norm(axis))
    if length == 0:
        raise ValueError("tube: the two ends coincide")
    u, v = _perpendiculars(axis / length)
    phi = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = radius * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v)
    vertices = np.concatenate([p0 + ring, p1 + ring, [p0, p1]])
    return vertices, primitives.capped_ring_triangles(sides)


def bar(p0, p1, size: float):
    """A square bar of side ``size`` (m) from ``p0`` to ``p1``."""
    return tube(p0, p1, size / np.sqrt(2.0), 4)


def h_section(height: float, base=(0.0, 0.0, 0.0)):
    """An H-section mast of ``height`` (m) standing on ``base``, flanges across the track (along y)."""
    width, depth, t = H_SECTION
    parts = [
        primitives.translated(primitives.box(t, width, height), (-depth / 2 + t / 2, 0, height / 2)),
        primitives.translated(primitives.box(t, width, height), (depth / 2 - t / 2, 0, height / 2)),
        primitives.translated(primitives.box(depth - 2 * t, t, height), (0, 0, height / 2)),
    ]
    return primitives.translated(primitives.merge(parts), base)


def lattice(height: float, base=(0.0, 0.0, 0.0)):
    """A square lattice mast of ``height`` (m) on ``base``: four corner chords and zig-zag braces on each face."""
    width, chord, brace, panel = LATTICE
    h = width / 2 - chord / 2
    corners = [(-h, -h), (h, -h), (h, h), (-h, h)]
    parts = [primitives.translated(primitives.box(chord, chord, height), (x, y, height / 2)) for x, y in corners]
    levels = np.arange(0.0, height - 1e-9, panel)
    for face in range(4):
        (x0, y0), (x1, y1) = corners[face], corners[(face + 1) % 4]
        for i, z in enumerate(levels):
            z1 = min(z + panel, height)
            a, b = ((x0, y0), (x1, y1)) if i % 2 == 0 else ((x1, y1), (x0, y0))
            parts.append(bar((a[0], a[1], z), (b[0], b[1], z1), brace))
    return primitives.translated(primitives.merge(parts), base)


def mast(kind: str, height: float, base=(0.0, 0.0, 0.0)):
    """The mast of ``kind`` (``h_section`` or ``lattice``)."""
    return h_section(height, base) if kind == "h_section" else lattice(height, base)


def insulator(p0, p1, radius: float = 0.06, sheds: int = 4):
    """A rod insulator from ``p0`` to ``p1``: a thin core with ``sheds`` wider discs."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    parts = [tube(p0, p1, radius * 0.35, 6)]
    axis = p1 - p0
    for f in (np.arange(sheds) + 0.5) / sheds:
        centre = p0 + f * axis
        parts.append(tube(centre - 0.01 * axis, centre + 0.01 * axis, radius, 8))
    return primitives.merge(parts)


TUBE = 0.025  # m, radius of cantilever tubes
ARM = 0.02  # m, radius of registration arms


STEADY_ARM = 0.012  # m, radius of steady arms
CLAMP = (0.08, 0.03)  # m: length along the wire and half height of a steady arm's contact-wire clamp


def cantilever(root_y: float, attach_y: float, contact_z: float, messenger_z: float, stay_rise: float, drop_from: float | None = None,
               arm_length: float = 1.2, arm_rise: float = 0.2, steady_arm: float = 0.0):
    """The cantilever carrying one track's wires, its registration arm and its insulators, in the support frame.

    root_y : lateral (m) of the cantilever's root: a mast's face, or a drop tube under a beam
        (``drop_from``: the beam's underside height, m; the drop tube runs down from it)
    attach_y : lateral (m) where the messenger and the contact wire hang
    contact_z, messenger_z : heights (m) of the contact wire and the messenger at the support
    arm_length : horizontal reach (m) of the registration arm from its root to the contact wire;
        at most 0.6 of |attach_y - root_y| keeps the main tube above the arm
    arm_rise : height (m) of the arm's root above the contact wire
    steady_arm : horizontal reach (m) of a steady arm apart from the registration arm (0: none): the
        registration arm stops at a hinge that far from the wire, and a thinner steady arm runs from the
        hinge down to a clamp on the contact wire (``"steady arm"`` in the result)
    Returns ``{"cantilever": mesh, "registration arm": mesh, "insulator": mesh}`` (and ``"steady arm"``).
    A stay tube runs level at ``messenger_z + stay_rise`` from the root to above the wires, a main
    tube rises to it from below the contact wire, a hanger drops to the messenger; a registration
    tube hangs from the main tube to the arm's root, and the arm runs from there down to the contact wire.
    """
    toward = np.sign(attach_y - root_y) or 1.0
    stay_z = messenger_z + stay_rise
    low_z = contact_z - 0.3
    stay = ((0.0, root_y, stay_z), (0.0, attach_y, stay_z))
    main = ((0.0, root_y, low_z), (0.0, attach_y, stay_z))
    parts = [tube(*stay, TUBE), tube(*main, TUBE), tube((0.0, attach_y, stay_z), (0.0, attach_y, messenger_z), TUBE * 0.6)]
    if drop_from is not None:
        parts.append(tube((0.0, root_y, drop_from), (0.0, root_y, low_z - 0.1), TUBE * 1.6))
    arm_root_y = attach_y - toward * arm_length
    arm_root = (0.0, arm_root_y, contact_z + arm_rise)
    u = (arm_root_y - root_y) / (attach_y - root_y)
    on_main = (0.0, arm_root_y, low_z + u * (stay_z - low_z))
    parts.append(tube(on_main, arm_root, TUBE * 0.8))  # the registration tube
    wire = np.array([0.0, attach_y, contact_z])
    pieces = {}
    if steady_arm > 0:
        hinge = wire + (np.asarray(arm_root, float) - wire) * (steady_arm / arm_length)
        arm = tube(arm_root, hinge, ARM)
        clamp = primitives.translated(primitives.box(CLAMP[0], 2 * STEADY_ARM, 2 * CLAMP[1]), tuple(wire + (0.0, 0.0, CLAMP[1] * 0.5)))
        pieces["steady arm"] = primitives.merge([tube(hinge, wire + (0.0, 0.0, CLAMP[1]), STEADY_ARM), clamp])
    else:
        arm = tube(arm_root, (0.0, attach_y, contact_z), ARM)
    insulators = []
    for a, b in (stay, main):
        a, b = np.asarray(a, float), np.asarray(b, float)
        direction = (b - a) / np.linalg.norm(b - a)
        insulators.append(insulator(a + 0.1 * direction, a + 0.5 * direction))
    insulators = primitives.merge(insulators)
    return {"cantilever": primitives.merge(parts), "registration arm": arm, "insulator": insulators} | pieces


def gantry(left_y: float, right_y: float, base_left: float, base_right: float, top: float, kind: str):
    """A portal: two legs of ``kind`` at laterals ``left_y`` and ``right_y`` (bases in m) up to ``top``,
    and a box beam across them just under the top. Returns the mesh and the beam's underside height."""
    beam_depth = 0.4
    parts = [mast(kind, top - base_left, (0.0, left_y, base_left)), mast(kind, top - base_right, (0.0, right_y, base_right))]
    width = abs(left_y - right_y) + 0.4
    parts.append(primitives.translated(primitives.box(0.3, width, beam_depth), (0.0, (left_y + right_y) / 2, top - beam_depth / 2)))
    return primitives.merge(parts), top - beam_depth


def bracket(mast_y: float, outward: float, reach: float, z: float):
    """A level bracket (a square bar, class mast) from a mast at ``mast_y`` ``reach`` m outwards at height ``z``."""
    return bar((0.0, mast_y, z), (0.0, mast_y + outward * reach, z), 0.05)


WEIGHT = (0.2, 1.6)  # m: radius and height of a tensioning weight stack (about 25 cast-iron discs)


def tensioning_weight(mast_y: float, behind: float, top: float):
    """An anchor at a mast (lateral ``mast_y``, top ``top``, m): a bracket ``behind`` m along the track (away from the
    line) carrying a pulley, its rope and the weight stack under it. Returns ``{"anchor": mesh, "tensioning weight": mesh}``."""
    wheel_z = top - 0.6
    x = behind
    bracket = bar((0.0, mast_y, wheel_z + 0.3), (x, mast_y, wheel_z + 0.3), 0.06)
    pulley = tube((x, mast_y - 0.03, wheel_z), (x, mast_y + 0.03, wheel_z), 0.25, 12)
    hanger = tube((x, mast_y, wheel_z + 0.3), (x, mast_y, wheel_z + 0.25), 0.02, 6)
    rope = tube((x, mast_y, wheel_z - 0.25), (x, mast_y, 2.4 + WEIGHT[1]), 0.008, 6)
    stack = tube((x, mast_y, 2.4), (x, mast_y, 2.4 + WEIGHT[1]), WEIGHT[0], 16)
    return {"anchor": primitives.merge([bracket, pulley, hanger, rope]), "tensioning weight": stack}


ROPE = 0.008  # m, radius of an anchor rope


def anchor_ropes(ends, target):
    """Ropes from each of the wire ends ``ends`` ((n, 3), m) to ``target`` ((3,), an anchor's pulley): where a
    tension section's run leaves service and is pulled off to its anchor."""
    target = np.asarray(target, float)
    return primitives.merge([tube(np.asarray(end, float), target, ROPE, 6) for end in np.asarray(ends, float).reshape(-1, 3)])


def pulley_top(mast_y: float, behind: float, top: float) -> tuple[float, float, float]:
    """Where a rope leaves the pulley of :func:`tensioning_weight` towards the line (its rim's top), support frame (m)."""
    return (behind, mast_y, top - 0.6 + 0.25)


def section_insulator(length: float = 1.8):
    """A section insulator around a contact wire, centred on the origin along x: two runners and a body (m)."""
    body = primitives.box(length * 0.5, 0.12, 0.08)
    runners = [primitives.translated(primitives.box(length, 0.02, 0.03), (0.0, y, -0.01)) for y in (-0.05, 0.05)]
    return primitives.merge([primitives.translated(body, (0.0, 0.0, 0.05)), *runners])
