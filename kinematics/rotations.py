"""Rotation helpers (pure numpy): quaternions, fixed-axis Euler angles, SO(3) exponential."""

from __future__ import annotations

import numpy as np


def quat_to_rot(quat: np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion (w, x, y, z), normalised first; broadcasts."""
    q = np.asarray(quat, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    rows = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def euler_to_rot(eps: np.ndarray, phi: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """R = Rz(theta) Ry(phi) Rx(eps) [rad]: rotations about the fixed base x, y, z axes in turn.

    Our reading of the seed's (epsilon, phi, theta) (roll, pitch, yaw); broadcasts.
    """
    ce, se = np.cos(eps), np.sin(eps)
    cp, sp = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    rows = [[ct * cp, ct * sp * se - st * ce, ct * sp * ce + st * se],
            [st * cp, st * sp * se + ct * ce, st * sp * ce - ct * se],
            [-sp, cp * se, cp * ce]]
    return np.stack([np.stack(np.broadcast_arrays(*r), axis=-1) for r in rows], axis=-2)


def so3_exp(w: np.ndarray) -> np.ndarray:
    """exp([w]x): rotation by |w| rad about w (Rodrigues; series near 0 keeps it exact)."""
    w = np.asarray(w, dtype=float)
    th = float(np.linalg.norm(w))
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if th < 1e-8:  # sin(t)/t and (1-cos t)/t^2 to O(t^2): below 1e-16 relative error
        return np.eye(3) + k + 0.5 * k @ k
    return np.eye(3) + np.sin(th) / th * k + (1 - np.cos(th)) / th**2 * k @ k


def rotation_angle(rot_a: np.ndarray, rot_b: np.ndarray) -> np.ndarray:
    """Angle of rot_a^T rot_b [rad]; atan2 form stays accurate for tiny angles; broadcasts."""
    d = np.swapaxes(rot_a, -1, -2) @ rot_b
    skew = np.stack([d[..., 2, 1] - d[..., 1, 2], d[..., 0, 2] - d[..., 2, 0],
                     d[..., 1, 0] - d[..., 0, 1]], axis=-1)
    trace = d[..., 0, 0] + d[..., 1, 1] + d[..., 2, 2]
    return np.arctan2(0.5 * np.linalg.norm(skew, axis=-1), 0.5 * (trace - 1))
