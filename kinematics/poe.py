"""Product-of-exponentials (screw) kinematics as pure, batched numpy functions.

Conventions (seed 001 Eqs. 3-13): a twist is xi = (w, v) in R^6, angular part first, in the
base (space) frame at the zero configuration; a revolute joint with unit axis s through point
r has xi = (s, -s x r), a prismatic one xi = (0, s). The pose of a chain is
T(q) = exp(xi_1 q_1) ... exp(xi_n q_n) M with M the tool pose at q = 0. Every function takes
leading batch dimensions ("...") so a Monte Carlo over 10^4 perturbed robots is one call.

The error Jacobian (:func:`error_jacobian`) is the linear map from perturbations of every
twist and of M to the spatial twist error dT T^-1 (Okamura & Park's POE calibration model);
a kinematic calibration solves exactly that linear system, so it lives here.
"""

from __future__ import annotations

from math import factorial

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import expm

from serpar.errors import IdentificationError

Array = NDArray[np.float64]

_SMALL = 1e-4
"""Below this rotation angle [rad] the exp coefficients use their Taylor series (error < 1e-20)."""


def skew(w: ArrayLike) -> Array:
    """(..., 3) -> (..., 3, 3) antisymmetric matrix with skew(w) @ x == cross(w, x) (Eq. 6)."""
    w = np.asarray(w, dtype=float)
    z = np.zeros(w.shape[:-1])
    return np.stack([np.stack([z, -w[..., 2], w[..., 1]], -1),
                     np.stack([w[..., 2], z, -w[..., 0]], -1),
                     np.stack([-w[..., 1], w[..., 0], z], -1)], -2)


def twist(axis: ArrayLike, point: ArrayLike, prismatic: ArrayLike = False) -> Array:
    """Unit twist of a joint (Eqs. 3-4, pitch 0): (s, -s x r) revolute, (0, s) prismatic.

    axis (..., 3) is normalised here so a deflected axis can be passed as is; prismatic is a
    bool broadcastable to the batch shape.
    """
    s = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(s, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise IdentificationError("a joint axis has zero length; give a direction vector")
    s = s / norm
    r = np.asarray(point, dtype=float)
    pri = np.asarray(prismatic, dtype=bool)[..., None]
    rev = np.concatenate([s, -np.cross(s, r)], axis=-1)
    return np.where(pri, np.concatenate([np.zeros_like(s), s], axis=-1), rev)


def exp_twist(xi: ArrayLike, theta: ArrayLike) -> Array:
    """exp(xi^ theta) as (..., 4, 4), closed form (Eqs. 7-8) for any |w| including 0.

    R = I + A W + B W^2, p = (I theta + B W theta + C W^2 theta) v with W = skew(w) and
    A, B, C the Rodrigues coefficients of phi = |w theta|.
    """
    xi = np.asarray(xi, dtype=float)
    theta = np.asarray(theta, dtype=float)
    xi, theta = np.broadcast_arrays(xi, theta[..., None])
    theta = theta[..., 0]
    w, v = xi[..., :3] * theta[..., None], xi[..., 3:] * theta[..., None]
    phi = np.linalg.norm(w, axis=-1)
    p2 = phi * phi
    small = phi < _SMALL
    safe = np.where(small, 1.0, phi)
    a = np.where(small, 1 - p2 / 6 + p2 * p2 / 120, np.sin(safe) / safe)
    b = np.where(small, 0.5 - p2 / 24 + p2 * p2 / 720, (1 - np.cos(safe)) / safe**2)
    c = np.where(small, 1 / 6 - p2 / 120 + p2 * p2 / 5040, (safe - np.sin(safe)) / safe**3)
    wx = skew(w)
    wx2 = wx @ wx
    eye = np.eye(3)
    rot = eye + a[..., None, None] * wx + b[..., None, None] * wx2
    vmat = eye + b[..., None, None] * wx + c[..., None, None] * wx2
    out = np.zeros(w.shape[:-1] + (4, 4))
    out[..., :3, :3] = rot
    out[..., :3, 3] = np.einsum("...ij,...j->...i", vmat, v)
    out[..., 3, 3] = 1.0
    return out


def product_of_exponentials(twists: ArrayLike, q: ArrayLike) -> Array:
    """exp(xi_1 q_1) ... exp(xi_n q_n): twists (..., n, 6), q (..., n) -> (..., 4, 4)."""
    e = exp_twist(twists, q)
    out = e[..., 0, :, :]
    for i in range(1, e.shape[-3]):
        out = out @ e[..., i, :, :]
    return out


def forward_kinematics(twists: ArrayLike, q: ArrayLike, home: ArrayLike) -> Array:
    """Tool pose T(q) = prod exp(xi_i q_i) M (Eq. 13); home M is the tool pose at q = 0."""
    twists = np.asarray(twists, dtype=float)
    q = np.asarray(q, dtype=float)
    if twists.shape[-1] != 6 or twists.shape[-2] != q.shape[-1]:
        raise IdentificationError(f"twists must be (..., n, 6) with n = len(q) = {q.shape[-1]}, "
                                  f"got {twists.shape}")
    return product_of_exponentials(twists, q) @ np.asarray(home, dtype=float)


def adjoint(t: ArrayLike) -> Array:
    """Ad_T (..., 6, 6) mapping twists (w, v) from the frame moved by T: [[R, 0], [p^ R, R]]."""
    t = np.asarray(t, dtype=float)
    rot, p = t[..., :3, :3], t[..., :3, 3]
    out = np.zeros(t.shape[:-2] + (6, 6))
    out[..., :3, :3] = rot
    out[..., 3:, 3:] = rot
    out[..., 3:, :3] = skew(p) @ rot
    return out


def ad(xi: ArrayLike) -> Array:
    """Lie bracket matrix ad_xi (6, 6) of a twist (w, v): [[w^, 0], [v^, w^]]."""
    xi = np.asarray(xi, dtype=float)
    out = np.zeros(xi.shape[:-1] + (6, 6))
    out[..., :3, :3] = skew(xi[..., :3])
    out[..., 3:, 3:] = skew(xi[..., :3])
    out[..., 3:, :3] = skew(xi[..., 3:])
    return out


def left_jacobian(x: ArrayLike) -> Array:
    """d exp(X + dX) exp(X)^-1 = J(X) dX with J = sum ad_X^k / (k+1)! (6, 6), via scipy expm."""
    block = np.zeros((12, 12))
    block[:6, :6] = ad(x)
    block[:6, 6:] = np.eye(6)
    return expm(block)[:6, 6:]


_SERIES_BELOW = 0.5
"""Below this rotation angle [rad] :func:`se3_left_jacobian` sums the coefficients' Taylor
series: the closed forms cancel catastrophically there (D's numerator is ~angle^5 / 60)."""
_SERIES_TERMS = 10


def _series(phi2: Array, first: int, term) -> Array:
    """sum_k term(k) phi^(2(k - first)) for k = first .. first + _SERIES_TERMS - 1."""
    out = np.zeros_like(phi2)
    for k in reversed(range(first, first + _SERIES_TERMS)):
        out = out * phi2 + term(k)
    return out


def se3_left_jacobian(x: ArrayLike) -> Array:
    """Closed form of :func:`left_jacobian`, batched: x (..., 6) -> (..., 6, 6).

    [[J(w), 0], [Q(w, v), J(w)]] with J the SO(3) left Jacobian and Q Barfoot's (State
    Estimation for Robotics, Eq. 7.86, reordered to this module's angular-first twists);
    why: the calibration evaluates it for every parameter block at every solver step, and
    expm of a 12 x 12 matrix costs ~10 ms on a busy core.
    """
    x = np.asarray(x, dtype=float)
    w, v = x[..., :3], x[..., 3:]
    phi2 = np.sum(w * w, axis=-1)
    phi = np.sqrt(phi2)
    small = phi < _SERIES_BELOW
    p = np.where(small, 1.0, phi)
    # coefficients: a = (1 - cos)/phi^2, b = (phi - sin)/phi^3,
    # c = (phi^2 + 2 cos - 2)/(2 phi^4), d = (2 phi - 3 sin + phi cos)/(2 phi^5)
    closed = ((1 - np.cos(p)) / p**2, (p - np.sin(p)) / p**3,
              (p * p + 2 * np.cos(p) - 2) / (2 * p**4),
              (2 * p - 3 * np.sin(p) + p * np.cos(p)) / (2 * p**5))
    series = (_series(phi2, 0, lambda k: (-1) ** k / factorial(2 * k + 2)),
              _series(phi2, 0, lambda k: (-1) ** k / factorial(2 * k + 3)),
              _series(phi2, 0, lambda k: (-1) ** k / factorial(2 * k + 4)),
              _series(phi2, 2, lambda k: (-1) ** k * (k - 1) / factorial(2 * k + 1)))
    a, b, c, d = (np.where(small, s, f)[..., None, None] for s, f in zip(series, closed))
    wx, vx = skew(w), skew(v)
    wx2 = wx @ wx
    wvw = wx @ vx @ wx
    jac = np.eye(3) + a * wx + b * wx2
    q = (0.5 * vx + b * (wx @ vx + vx @ wx + wvw) + c * (wx2 @ vx + vx @ wx2 - 3 * wvw)
         + d * (wvw @ wx + wx @ wvw))
    out = np.zeros(x.shape[:-1] + (6, 6))
    out[..., :3, :3] = jac
    out[..., 3:, 3:] = jac
    out[..., 3:, :3] = q
    return out


def prefix_poses(twists: ArrayLike, q: ArrayLike) -> list[Array]:
    """P_0 = I, P_i = exp(xi_1 q_1) ... exp(xi_i q_i) for i = 0..n (unbatched).

    Ad(P_{i-1}) carries a twist defined at the zero configuration just before joint i (an
    error screw of that joint) to the spatial frame at q.
    """
    out = [np.eye(4)]
    for xi, qi in zip(np.asarray(twists, dtype=float), np.asarray(q, dtype=float)):
        out.append(out[-1] @ exp_twist(xi, qi))
    return out


def perpendicular_axes(axis: ArrayLike) -> tuple[Array, Array]:
    """Two unit vectors u, v with (u, v, axis) right-handed and orthonormal, (..., 3) each.

    u is the base axis least aligned with the joint axis, made orthogonal to it: for axes along
    base axes this gives the deflection directions of seed 001 Eq. 35 (x, y for a z joint;
    y, z for an x joint).
    """
    w = np.asarray(axis, dtype=float)
    w = w / np.linalg.norm(w, axis=-1, keepdims=True)
    pick = np.eye(3)[np.argmin(np.abs(w) + 1e-9 * np.arange(3), axis=-1)]
    u = pick - np.sum(pick * w, axis=-1, keepdims=True) * w
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    return u, np.cross(w, u)


def space_jacobian(twists: ArrayLike, q: ArrayLike) -> Array:
    """(6, n) spatial Jacobian: column i = Ad(P_{i-1}) xi_i, the joint twist at q."""
    twists, q = np.asarray(twists, dtype=float), np.asarray(q, dtype=float)
    pre = prefix_poses(twists, q)
    return np.stack([adjoint(pre[i]) @ twists[i] for i in range(len(q))], axis=1)


def error_jacobian(twists: ArrayLike, q: ArrayLike) -> Array:
    """(6, 6n + 6) map from (d xi_1, ..., d xi_n, d m) to the spatial error twist dT T^-1.

    d xi_i perturbs twist i additively; d m perturbs the tool pose on the left,
    M' = exp(d m^) M. Column block i is Ad(P_{i-1}) J(xi_i q_i) q_i (chain rule through
    exp), the last block Ad(P_n).
    """
    twists, q = np.asarray(twists, dtype=float), np.asarray(q, dtype=float)
    pre = prefix_poses(twists, q)
    blocks = [adjoint(pre[i]) @ left_jacobian(twists[i] * q[i]) * q[i] for i in range(len(q))]
    return np.concatenate(blocks + [adjoint(pre[-1])], axis=1)


def point_jacobian(twist_jacobian: ArrayLike, point: ArrayLike) -> Array:
    """(3, k) velocity of a point p under spatial twists (6, k): dp = dv + dw x p."""
    j = np.asarray(twist_jacobian, dtype=float)
    return j[3:] - skew(point) @ j[:3]


def log_twist(t: ArrayLike) -> Array:
    """Small-pose log: the twist (w, v) with exp(xi^) = T, first order (for |w| << 1)."""
    t = np.asarray(t, dtype=float)
    r = t[..., :3, :3]
    w = 0.5 * np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                        r[..., 1, 0] - r[..., 0, 1]], -1)
    return np.concatenate([w, t[..., :3, 3]], axis=-1)


def mdh_frames(a: ArrayLike, d: ArrayLike, alpha: ArrayLike, tool_d: ArrayLike
               ) -> tuple[Array, Array, Array]:
    """Zero-configuration joint axes, axis points and tool pose of a modified-DH (Craig) chain.

    Frame i = frame i-1 RotX(alpha_i) TransX(a_i) TransZ(d_i) at q = 0; joint i turns about its
    z axis through its origin, and the tool is TransZ(tool_d) from the last frame. a, d
    (..., n) may carry a batch of perturbed tables; returns axes (..., n, 3), points
    (..., n, 3) and M (..., 4, 4), the inputs of :func:`twist` and :func:`forward_kinematics`.
    """
    a, d = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(d, dtype=float))
    alpha = np.asarray(alpha, dtype=float)
    if alpha.shape != a.shape[-1:]:
        raise IdentificationError(f"MDH alpha must have {a.shape[-1]} entries, got {alpha.shape}")
    frame = np.broadcast_to(np.eye(4), a.shape[:-1] + (4, 4)).copy()
    axes, points = [], []
    for i in range(a.shape[-1]):
        link = np.zeros(a.shape[:-1] + (4, 4))
        ca, sa = np.cos(alpha[i]), np.sin(alpha[i])
        link[..., 0, 0] = link[..., 3, 3] = 1.0
        link[..., 1, 1], link[..., 1, 2], link[..., 2, 1], link[..., 2, 2] = ca, -sa, sa, ca
        link[..., 0, 3], link[..., 1, 3], link[..., 2, 3] = a[..., i], -sa * d[..., i], ca * d[..., i]
        frame = frame @ link
        axes.append(frame[..., :3, 2])
        points.append(frame[..., :3, 3])
    tool = np.broadcast_to(np.eye(4), frame.shape).copy()
    tool[..., 2, 3] = tool_d
    return np.stack(axes, -2), np.stack(points, -2), frame @ tool
