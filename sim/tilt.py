"""Gravity in a tilted base's frame: the one definition of the two tilt angles, shared by the
arm-dynamics twin's tilted plant and the diagnosis' ``base_tilt``.

The angles turn the model's gravity direction (unit u) about two axes perpendicular to it,
e1 and e2 = u x e1 (e1: the base x axis made perpendicular to u; for gravity along -z,
alpha tilts about x, beta about y):

    gvec(alpha, beta) = |g| (cos(alpha) cos(beta) u + sin(beta) e1 + sin(alpha) cos(beta) e2)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Vec = NDArray[np.float64]


def tilted_gravity(gravity: Vec, angles: Vec) -> tuple[Vec, Vec]:
    """(gvec, d gvec / d angles as 3 x 2) for the file's ``gravity`` turned by (alpha, beta)."""
    g = float(np.linalg.norm(gravity))
    u = gravity / g
    x = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = x - u * (x @ u)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    a, b = float(angles[0]), float(angles[1])
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    vec = g * (ca * cb * u + sb * e1 + sa * cb * e2)
    d_a = g * (-sa * cb * u + ca * cb * e2)
    d_b = g * (-ca * sb * u + cb * e1 - sa * sb * e2)
    return vec, np.column_stack([d_a, d_b])
