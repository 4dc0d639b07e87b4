"""Collision filter bits: which geoms may touch which (MuJoCo contype/conaffinity).

Two geoms collide when ``(a.contype & b.conaffinity) or (b.contype & a.conaffinity)``;
MuJoCo's default is 1/1 for both. One exception keeps a seated journal cheap to simulate:

A conductor's Ø5 body rests with its flat shoulder on the plate top around its bore. The plate
top there is made of the bore's 16 ring boxes and 16 chamfer boxes, and flat face-on-face
contact gives up to 4 contacts per box: 96 contacts (~400 constraint rows) per seated part,
which never sleeps because the plate rides on the always-awake Stewart platform. So the
plate's bore and bar geoms do not collide with conductor bodies; instead one invisible *seat*
box on the plate, whose top face is the plate top, does (and collides with nothing else).
The surface the shoulder can reach is the same: the Ø5 body covers the Ø1.9 mm bore mouth
wherever it touches the plate. Journals and tips still meet the real bore geometry.
"""

from __future__ import annotations

import mujoco

DEFAULT = 1
_SEAT = 2

SEAT_GROUP = 3
"""Geom group of the seat box: hidden in renders (MuJoCo shows groups 0-2 by default)."""


def conductor_body(geom: mujoco.MjsGeom) -> None:
    """A conductor's body cylinder: touches everything default and the plate's seat box."""
    geom.contype, geom.conaffinity = _SEAT, DEFAULT | _SEAT


def plate_surface(geom: mujoco.MjsGeom) -> None:
    """A plate bar, bore facet or the fixture: touches everything default except conductor
    bodies."""
    geom.contype, geom.conaffinity = 0, DEFAULT


def plate_seat(geom: mujoco.MjsGeom) -> None:
    """The plate's seat box: touches conductor bodies only."""
    geom.contype, geom.conaffinity = 0, _SEAT
    geom.group = SEAT_GROUP
    geom.rgba = [0.0, 0.0, 0.0, 0.0]
