"""The shapes of the six toys: signed-distance parts in millimetres, y up, facing +z.

Each toy is a :class:`Shape`: its parts in union order, each smooth-unioned
into the parts before it (or carved out of them), and the grid step its
surface is meshed at (:mod:`meshsal.objects.toys`).  A part's name says what
it is (``"hoof"``, ``"lens"``); the paint (:mod:`meshsal.objects.toy_paint`)
colours each vertex by the name of the part whose surface passes closest.

The toys differ where a 30 mm touch can tell: the cow and the dromedary are
soft, rounded bodies on round legs; the glasses are thin tubes and flat
lenses; the cup is a large gently curved wall with a sharp-ish rim and a
handle loop; the hand is a flat palm with finger cylinders and nails; the
plane is a long cylinder with thin flat wings and fins.

Examples
--------
>>> shape = cup()
>>> [part.name for part in shape.parts], shape.spacing
(['body', 'handle', 'rim', 'inside'], 1.4)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from meshsal.objects import sdf

__all__ = ["Part", "Shape", "CUP_HEIGHT", "cow", "glasses", "cup", "hand", "plane", "dromedary"]


@dataclass(frozen=True)
class Part:
    """One signed-distance part, smooth-unioned (or carved, ``carve=True``) into the parts before it.

    ``sdf`` maps (k, 3) points to (k,) signed distances (mm, negative
    inside); ``blend`` is the smooth union's radius (mm).
    """

    name: str
    sdf: Callable[[np.ndarray], np.ndarray]
    blend: float = 0.0
    carve: bool = False


@dataclass(frozen=True)
class Shape:
    """A toy's parts in union order and the marching-cubes grid step (mm) that meshes them."""

    parts: tuple[Part, ...]
    spacing: float


#: The cup's height (mm): its rim's paint follows it.
CUP_HEIGHT = 100.0


def _mirror_x(fn):
    """The part and its mirror image across x = 0 (exact when the part lies in x > 0)."""

    def mirrored(P):
        Q = P.copy()
        Q[:, 0] = np.abs(Q[:, 0])
        return fn(Q)

    return mirrored


def _union(*fns):
    return lambda P: np.min([fn(P) for fn in fns], axis=0)


def cow() -> Shape:
    S = sdf
    head_rot = S.rotation([1, 0, 0], 30)
    parts = (
        Part("body", lambda P: S.round_box(P, [0, 72, 0], [30, 28, 58], 22)),
        Part("body", lambda P: S.ellipsoid(P, [0, 68, 0], [33, 30, 56]), 10),
        Part("neck", lambda P: S.round_cone(P, [0, 80, 40], [0, 90, 72], 20, 15), 8),
        Part("head", lambda P: S.ellipsoid(P, [0, 92, 84], [15, 17, 22], head_rot), 6),
        Part("muzzle", lambda P: S.ellipsoid(P, [0, 79, 99], [15.5, 12, 11]), 5),
        Part("eye", _mirror_x(lambda P: S.sphere(P, [13, 94, 90], 4.6)), 1),
        Part("ear", _mirror_x(lambda P: S.ellipsoid(P, [20, 101, 72], [9, 3, 5.5], S.rotation([0, 0, 1], 20))), 3),
        Part("horn", _mirror_x(lambda P: S.round_cone(P, [8, 104, 80], [19, 114, 78], 3.8, 2.2)), 2),
        Part(
            "leg",
            _mirror_x(
                _union(
                    lambda P: S.round_cone(P, [18, 62, 40], [18, 9, 41], 11, 7.5),
                    lambda P: S.round_cone(P, [18, 62, -40], [18, 9, -41], 12, 7.5),
                )
            ),
            6,
        ),
        Part("hoof", _mirror_x(_union(*(_hoof(z) for z in (41, -41)))), 2),
        Part("udder", lambda P: S.sphere(P, [0, 46, -26], 13), 6),
        Part("udder", _mirror_x(_union(*(_teat(z) for z in (-21, -31)))), 2),
        Part("tail", lambda P: S.capsule(P, [0, 90, -57], [0, 42, -66], 3.0), 3),
        Part("tuft", lambda P: S.ellipsoid(P, [0, 38, -66], [5, 9, 5]), 2),
    )
    return Shape(parts, spacing=1.25)


def _hoof(z):
    return lambda P: sdf.cylinder(P, [18, 0, z], [18, 11, z], 8.2, 2.0)


def _teat(z):
    return lambda P: sdf.capsule(P, [5, 38, z], [5.5, 30, z], 2.8)


def glasses() -> Shape:
    S = sdf
    lens_half, corner = [25.0, 18.0], 11.0
    parts = (
        Part("lens", _mirror_x(lambda P: S.rounded_plate(P, [33, 0, 0], lens_half, corner, 1.5, 0.7))),
        Part("frame", _mirror_x(lambda P: S.rounded_ring(P, [33, 0, 0], lens_half, corner, 2.8)), 1.0),
        Part("frame", _mirror_x(lambda P: S.capsule(P, [9, 9, 0.5], [0, 12, 0.5], 2.6)), 1.5),
        Part("pad", _mirror_x(lambda P: S.ellipsoid(P, [9.5, -5, -4], [2.2, 4.5, 3.2])), 1.5),
        Part("hinge", _mirror_x(lambda P: S.round_box(P, [59, 7, -3], [4, 5, 5], 2)), 1.5),
        Part("temple", _mirror_x(lambda P: S.capsule(P, [60, 7, -6], [63, 7, -110], 2.4)), 1.5),
        Part("temple", _mirror_x(lambda P: S.round_cone(P, [63, 7, -110], [63, -14, -130], 2.4, 3.0)), 1.0),
    )
    return Shape(parts, spacing=0.9)


def cup() -> Shape:
    S = sdf
    radius, height, wall = 44.0, CUP_HEIGHT, 4.5

    def handle(P):
        loop = S.torus(P, [radius + 3, 50, 0], 22, 5.5, S.rotation([1, 0, 0], 90))
        # Keep the loop out of the cup's hollow: cut it at the wall's middle.
        return np.maximum(loop, radius - 0.5 * wall - np.hypot(P[:, 0], P[:, 2]))

    parts = (
        Part("body", lambda P: S.cylinder(P, [0, 0, 0], [0, height, 0], radius, 5)),
        Part("handle", handle, 4),
        Part("rim", lambda P: S.torus(P, [0, height - 2.5, 0], radius - 0.5 * wall, 0.5 * wall + 1.0), 1.5),
        Part("inside", lambda P: S.cylinder(P, [0, 8, 0], [0, height + 40, 0], radius - wall, 6), 1.5, carve=True),
    )
    return Shape(parts, spacing=1.4)


# Finger base x, length, base and tip radius, spread (degrees about z, + towards the pinky side).
_FINGERS = (
    (-26.0, 70.0, 9.5, 7.5, 8.0),
    (-8.5, 79.0, 10.0, 8.0, 2.0),
    (8.5, 74.0, 9.5, 7.5, -3.0),
    (25.0, 58.0, 8.5, 6.5, -10.0),
)


def _chain(start, direction, lengths, curl_deg, curl_axis) -> list[np.ndarray]:
    """Joint positions of a digit that bends by ``curl_deg`` about ``curl_axis`` at each joint."""
    joints = [np.asarray(start, dtype=np.float64)]
    d = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    for length in lengths:
        joints.append(joints[-1] + length * d)
        d = sdf.rotation(curl_axis, curl_deg) @ d
    return joints


def _digit(joints, radii, blend: float) -> list[Part]:
    """Tapered segments between consecutive joints; the first blends into the palm."""
    return [
        Part(
            "skin",
            lambda P, a=joints[k], b=joints[k + 1], ra=radii[k], rb=radii[k + 1]: sdf.round_cone(P, a, b, ra, rb),
            blend if k == 0 else 1.0,
        )
        for k in range(len(joints) - 1)
    ]


def hand() -> Shape:
    S = sdf
    parts = [
        Part("skin", lambda P: S.round_box(P, [0, 45, 0], [40, 42, 13], 11)),
        Part("skin", lambda P: S.round_box(P, [0, -22, 0], [27, 32, 17], 14), 12),
        Part("skin", lambda P: S.ellipsoid(P, [-24, 28, -5], [17, 24, 13]), 8),
    ]
    nails = []
    curl_axis = [1.0, 0.0, 0.0]
    for x, length, r0, r1, spread in _FINGERS:
        direction = sdf.rotation([0, 0, 1], spread) @ np.array([0.0, 1.0, 0.0])
        joints = _chain([x, 80.0, 0.0], direction, [0.45 * length, 0.30 * length, 0.25 * length], 10.0, curl_axis)
        radii = np.linspace(r0, r1, 4)
        parts += _digit(joints, radii, 6.0)
        nails.append((joints[2], joints[3], radii[3]))
    joints = _chain([-30.0, 25.0, 3.0], [-0.45, 0.89, 0.15], [30.0, 25.0, 21.0], -8.0, [0.3, 0.0, 1.0])
    radii = (13.0, 11.0, 9.5, 8.5)
    parts += _digit(joints, radii, 7.0)
    nails.append((joints[2], joints[3], radii[3]))
    for a, b, r in nails:
        # A flat lens on the back (+z) of the last segment, ending just short of the tip.
        axis = (b - a) / np.linalg.norm(b - a)
        back = np.array([0.0, 0.0, 1.0]) - axis * axis[2]
        back /= np.linalg.norm(back)
        rot = np.column_stack([np.cross(axis, back), back, axis])
        center = b - 0.45 * r * axis + 0.85 * r * back
        radii = [0.75 * r, 0.25 * r, 1.2 * r]
        parts.append(Part("nail", lambda P, c=center, radii=radii, rot=rot: S.ellipsoid(P, c, radii, rot), 1.0))
    return Shape(tuple(parts), spacing=1.3)


def plane() -> Shape:
    S = sdf
    fin_rot = np.column_stack([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    wing = [(0, 30), (100, -14), (100, -28), (0, -12), (-100, -28), (-100, -14)]
    stabilizer = [(0, -84), (38, -106), (38, -116), (0, -110), (-38, -116), (-38, -106)]
    fin = [(4, -76), (46, -106), (46, -118), (4, -114)]
    parts = (
        Part("fuselage", lambda P: S.capsule(P, [0, 0, -80], [0, 0, 68], 13)),
        Part("fuselage", lambda P: S.round_cone(P, [0, 0, -80], [0, 8, -114], 13, 4), 4),
        Part("wing", lambda P: S.prism(P, wing, [0, -5, 0], 2.6, 1.2), 5),
        Part("tail", lambda P: S.prism(P, stabilizer, [0, 7, 0], 2.0, 0.9), 3),
        Part("fin", lambda P: S.prism(P, fin, [0, 0, 0], 2.2, 1.0, fin_rot), 3),
        Part("pylon", _mirror_x(lambda P: S.round_box(P, [38, -10, 12], [2, 6, 12], 1.5)), 2),
        Part("engine", _mirror_x(lambda P: S.cylinder(P, [38, -17, -4], [38, -17, 30], 8, 3)), 2),
    )
    return Shape(parts, spacing=1.2)


def dromedary() -> Shape:
    S = sdf
    head_rot = S.rotation([1, 0, 0], 12)
    legs = []
    for z in (38.0, -36.0):
        legs += [
            lambda P, z=z: S.round_cone(P, [14, 98, z], [14, 56, z + 1], 11, 6.5),
            lambda P, z=z: S.round_cone(P, [14, 56, z + 1], [14, 8, z], 6.5, 5),
            lambda P, z=z: S.sphere(P, [14, 56, z + 1], 7.2),
        ]
    parts = (
        Part("coat", lambda P: S.ellipsoid(P, [0, 105, 0], [26, 27, 52])),
        Part("hump", lambda P: S.ellipsoid(P, [0, 127, -3], [20, 26, 30]), 12),
        Part("coat", lambda P: S.round_cone(P, [0, 108, 38], [0, 100, 66], 17, 11), 8),
        Part("coat", lambda P: S.round_cone(P, [0, 100, 66], [0, 142, 90], 11, 9), 6),
        Part("coat", lambda P: S.ellipsoid(P, [0, 148, 100], [10, 11, 20], head_rot), 5),
        Part("muzzle", lambda P: S.ellipsoid(P, [0, 143, 114], [8.5, 8.5, 8]), 4),
        Part("eye", _mirror_x(lambda P: S.sphere(P, [8.6, 152, 100], 2.8)), 1),
        Part("ear", _mirror_x(lambda P: S.ellipsoid(P, [6.5, 158, 93], [2.5, 5, 3])), 1.5),
        Part("coat", _mirror_x(_union(*legs)), 6),
        Part("foot", _mirror_x(_union(*(_foot(z) for z in (40, -34)))), 3),
        Part("coat", lambda P: S.capsule(P, [0, 112, -50], [0, 76, -58], 2.6), 3),
        Part("tuft", lambda P: S.ellipsoid(P, [0, 73, -58], [4, 7, 4]), 2),
    )
    return Shape(parts, spacing=1.3)


def _foot(z):
    return lambda P: sdf.ellipsoid(P, [14, 4.5, z], [8, 4.5, 10])
