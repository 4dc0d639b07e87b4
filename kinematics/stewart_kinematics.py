"""Kinematics of the 6-UPS Stewart platform: IK, FK, leg Jacobian, hinge angles, limits.

Pure numpy maths, no MuJoCo. It imports nothing from :mod:`sim` except the dependency-free
:mod:`serpar.errors`, so that ``sim/stewart.py`` can build on it without an import cycle.

Frames and units (SI): the base frame has the universal-joint centres B_i at z = 0; the
platform frame has its origin at the centre of the spherical-joint plane (P_i at z = 0).
A pose is (pos, rot): the platform frame's origin and rotation matrix in the base frame.
Leg length joint centre to joint centre is L_i = l_min + s_i, s_i the actuator stroke.
Every function broadcasts over leading pose axes: pos (..., 3), rot (..., 3, 3).

Hinge angles (seed 000 §4.1: upper alpha <= 30 deg, lower beta <= 20 deg, not defined there),
selected by ``definition``:

- ``"deflection"`` (default): the cone angle between the leg axis and the joint's neutral axis,
  taken as the home leg direction (lower: in the base frame; upper: in the platform frame).
  It is what ``serpar.sim.stewart.spherical_angles_deg`` reports and is how hexapod joints are
  mounted (tilted so the mid-stroke leg sits in the middle of the joint's range). It is
  conservative for the model: a 20 deg cone lies inside the MuJoCo universal joint's
  +-20 deg per-axis box, so a pose that passes never touches the stops.
- ``"cardan"``: lower beta = max(|a|, |b|) of the universal joint's two hinge angles about
  the home leg direction (x horizontal, then y), exactly the MuJoCo stops ``u{i}_a/b``;
  upper as ``"deflection"``.
- ``"normal"``: the angle between the leg axis and the mounting plate's normal (base z for the
  lower joint, platform R z for the upper). Every leg already tilts 13.1 deg from vertical at
  home (61.9 mm horizontal offset over 265 mm), so only 6.9 deg of beta are left: it rejects
  most of the seed's box, which is why it is not the default.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np

from serpar.errors import ConfigError, LimitError
from serpar.kinematics.rotations import so3_exp

N_LEGS = 6
HingeDefinition = Literal["deflection", "cardan", "normal"]
HINGE_DEFINITIONS: tuple[str, ...] = ("deflection", "cardan", "normal")
SINGULAR_INV_COND = 1e-12
"""Below this sigma_min/sigma_max the leg Jacobian is treated as singular (double precision)."""


def _joint_tuple(name: str, value: object) -> tuple[tuple[float, float, float], ...]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (N_LEGS, 3) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name} must be a finite {N_LEGS}x3 array [m], got shape {arr.shape}")
    return tuple((float(x), float(y), float(z)) for x, y, z in arr)


@dataclass(frozen=True)
class StewartGeometry:
    """Nominal geometry and joint limits of a 6-UPS platform (metres, degrees)."""

    platform_joints: tuple[tuple[float, float, float], ...]
    """P_i: spherical-joint centres in the platform frame (6x3; array-like accepted)."""
    base_joints: tuple[tuple[float, float, float], ...]
    """B_i: universal-joint centres in the base frame (6x3; array-like accepted)."""
    l_min: float
    """Leg length at zero stroke [m]."""
    stroke: float
    """Actuator stroke [m]: valid strokes are [0, stroke]."""
    lower_hinge_limit_deg: float = 20.0
    upper_hinge_limit_deg: float = 30.0
    home_pos: tuple[float, float, float] = (0.0, 0.0, 0.265)
    """Home pose (no rotation): its leg directions are the joints' neutral axes."""

    def __post_init__(self) -> None:
        # Tuples keep the dataclass hashable and immutable; numpy views come from P and B.
        object.__setattr__(self, "platform_joints", _joint_tuple("platform_joints",
                                                                 self.platform_joints))
        object.__setattr__(self, "base_joints", _joint_tuple("base_joints", self.base_joints))
        home = np.asarray(self.home_pos, dtype=float)
        if home.shape != (3,) or not np.all(np.isfinite(home)):
            raise ConfigError(f"home_pos must be 3 finite numbers [m], got {self.home_pos}")
        object.__setattr__(self, "home_pos", tuple(float(v) for v in home))
        for name in ("l_min", "stroke"):
            if not float(getattr(self, name)) > 0:
                raise ConfigError(f"{name}={getattr(self, name)} must be > 0")
        for name in ("lower_hinge_limit_deg", "upper_hinge_limit_deg"):
            if not 0 < float(getattr(self, name)) <= 90:
                raise ConfigError(f"{name}={getattr(self, name)}: valid range 0 < x <= 90")
        s_home = inverse_kinematics(self, home, np.eye(3))
        if not np.all((s_home >= 0) & (s_home <= self.stroke)):
            raise ConfigError(f"home_pos {self.home_pos} m needs strokes in [0, {self.stroke}] m, "
                              f"got {np.round(s_home, 5)}")

    @cached_property
    def P(self) -> np.ndarray:  # the paper's symbol
        return _readonly(np.array(self.platform_joints))

    @cached_property
    def B(self) -> np.ndarray:  # the paper's symbol
        return _readonly(np.array(self.base_joints))

    @cached_property
    def home_directions(self) -> np.ndarray:
        """Unit leg directions at home (6x3): the hinges' neutral axes."""
        legs = np.asarray(self.home_pos) + self.P - self.B
        return _readonly(legs / np.linalg.norm(legs, axis=1, keepdims=True))


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


# --- kinematics -----------------------------------------------------------------------------

def leg_vectors(geom: StewartGeometry, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Leg vectors B_i -> platform joint i in the base frame, shape (..., 6, 3)."""
    pos = np.asarray(pos, dtype=float)
    rp = np.einsum("...jk,ik->...ij", np.asarray(rot, dtype=float), geom.P)
    return pos[..., None, :] + rp - geom.B


def inverse_kinematics(geom: StewartGeometry, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Closed-form strokes s_i = |pos + R P_i - B_i| - l_min [m]: (3,),(3,3) -> (6,);
    (N,3),(N,3,3) -> (N,6). Limits are not checked (see :func:`check_pose`)."""
    return np.linalg.norm(leg_vectors(geom, pos, rot), axis=-1) - geom.l_min


def jacobian(geom: StewartGeometry, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """d(stroke)/d(twist), shape (..., 6, 6).

    twist = (v, w): v the velocity of the platform origin, w the angular velocity, both in
    the base frame. Row i is (n_i, (R P_i) x n_i), n_i the unit leg vector: the stroke rate is
    the joint velocity v + w x R P_i projected on the leg.
    """
    rp = np.einsum("...jk,ik->...ij", np.asarray(rot, dtype=float), geom.P)
    legs = np.asarray(pos, dtype=float)[..., None, :] + rp - geom.B
    n = legs / np.linalg.norm(legs, axis=-1, keepdims=True)
    return np.concatenate([n, np.cross(rp, n)], axis=-1)


def singularity_measure(jac: np.ndarray) -> np.ndarray:
    """Inverse condition number sigma_min / sigma_max of the leg Jacobian, in [0, 1].

    0 at a singularity (a twist the legs can neither command nor resist), 1 for an isotropic
    pose. Unlike the manipulability |det J| it does not mix metres and radians' scales.
    About 7.9e-3 at home for the corrected Table 2 (condition number 127).
    """
    sv = np.linalg.svd(jac, compute_uv=False)
    return sv[..., -1] / sv[..., 0]


def manipulability(jac: np.ndarray) -> np.ndarray:
    """Yoshikawa's |det J| (unit-dependent; mainly for comparing poses of one robot)."""
    return np.abs(np.linalg.det(jac))


def forward_kinematics(geom: StewartGeometry, strokes: np.ndarray,
                       guess_pos: np.ndarray | None = None, guess_rot: np.ndarray | None = None,
                       tol: float = 1e-12, max_iter: int = 50,
                       ) -> tuple[np.ndarray, np.ndarray, int]:
    """Pose (pos, rot) whose leg lengths are l_min + strokes, and the Newton iterations used.

    Newton on r_i = |pos + R P_i - B_i| - l_min - s_i with the analytic Jacobian; the
    orientation is updated on SO(3), R <- exp([dw]x) R, so it stays a rotation. Converged
    when max |r_i| < tol [m]. The guess defaults to home; FK has up to 40 solutions, Newton
    finds the one connected to the guess. Raises LimitError if singular or not converged.
    """
    s = np.asarray(strokes, dtype=float)
    if s.shape != (N_LEGS,) or not np.all(np.isfinite(s)):
        raise ConfigError(f"strokes must be {N_LEGS} finite numbers [m], got shape {s.shape}")
    pos = np.array(geom.home_pos if guess_pos is None else guess_pos, dtype=float)
    rot = np.eye(3) if guess_rot is None else np.array(guess_rot, dtype=float)
    target = geom.l_min + s
    res = np.inf
    for it in range(max_iter + 1):
        res_vec = np.linalg.norm(leg_vectors(geom, pos, rot), axis=-1) - target
        res = float(np.max(np.abs(res_vec)))
        if res < tol:
            return pos, rot, it
        if it == max_iter or not np.isfinite(res):
            break
        jac = jacobian(geom, pos, rot)
        inv_cond = float(singularity_measure(jac))
        if inv_cond < SINGULAR_INV_COND:
            raise LimitError(f"forward kinematics: leg Jacobian sigma_min/sigma_max {inv_cond:.1e}"
                             f" outside [{SINGULAR_INV_COND:g}, 1] (singular) at iteration {it}")
        step = np.linalg.solve(jac, -res_vec)
        # Cap the step (50 mm / 0.5 rad) so a far guess cannot jump to a mirrored branch.
        scale = min(1.0, 0.05 / max(np.linalg.norm(step[:3]), 1e-300),
                    0.5 / max(np.linalg.norm(step[3:]), 1e-300))
        pos = pos + scale * step[:3]
        rot = so3_exp(scale * step[3:]) @ rot
    raise LimitError(f"forward kinematics: leg-length residual {res:.3g} m outside [0, {tol:g}] m "
                     f"after {max_iter} iterations; strokes {np.round(s * 1e3, 3)} mm unreachable "
                     "from the guess")


# --- hinge angles and limits ----------------------------------------------------------------

def cardan_angles_deg(geom: StewartGeometry, pos: np.ndarray,
                      rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) [deg], each (..., 6): universal-joint angles as the MuJoCo hinges u{i}_a, u{i}_b.

    The joint frame has z = home leg direction, x = horizontal (z_world x z), y = z x x; the
    leg axis is Rx(a) Ry(b) z = (sin b, -sin a cos b, cos a cos b) in that frame.
    """
    legs = leg_vectors(geom, pos, rot)
    n = legs / np.linalg.norm(legs, axis=-1, keepdims=True)
    z = geom.home_directions
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x, axis=1, keepdims=True)  # legs are never vertical (61.9 mm offset)
    y = np.cross(z, x)
    dx, dy, dz = (np.einsum("...ij,ij->...i", n, e) for e in (x, y, z))
    return np.degrees(np.arctan2(-dy, dz)), np.degrees(np.arcsin(np.clip(dx, -1.0, 1.0)))


def hinge_angles_deg(geom: StewartGeometry, pos: np.ndarray, rot: np.ndarray,
                     definition: HingeDefinition = "deflection",
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(beta, alpha) [deg], each (..., 6): lower (universal) and upper (spherical) joint angles.

    See the module docstring for the definitions.
    """
    if definition not in HINGE_DEFINITIONS:
        raise ConfigError(f"hinge definition {definition!r}; valid: {', '.join(HINGE_DEFINITIONS)}")
    rot = np.asarray(rot, dtype=float)
    legs = leg_vectors(geom, pos, rot)
    n = legs / np.linalg.norm(legs, axis=-1, keepdims=True)
    n_plat = np.einsum("...kj,...ik->...ij", rot, n)  # R^T n_i: the leg seen by the platform
    if definition == "normal":
        z = np.array([0.0, 0.0, 1.0])
        lower, upper = _angle_deg(n, z), _angle_deg(n_plat, z)
    else:
        lower = _angle_deg(n, geom.home_directions)
        upper = _angle_deg(n_plat, geom.home_directions)
    if definition == "cardan":
        a, b = cardan_angles_deg(geom, pos, rot)
        lower = np.maximum(np.abs(a), np.abs(b))
    return lower, upper


def _angle_deg(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angle between unit vectors [deg]; atan2 keeps small angles exact (arccos loses ~1e-6)."""
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1),
                                 np.sum(u * v, axis=-1)))


LIMIT_NAMES: tuple[str, ...] = ("stroke_low", "stroke_high", "lower_hinge", "upper_hinge")


def limit_violations(geom: StewartGeometry, pos: np.ndarray, rot: np.ndarray,
                     definition: HingeDefinition = "deflection") -> dict[str, np.ndarray]:
    """Per-leg violation masks (..., 6) keyed by LIMIT_NAMES, plus the values that were tested."""
    s = inverse_kinematics(geom, pos, rot)
    beta, alpha = hinge_angles_deg(geom, pos, rot, definition)
    return {"stroke_low": s < 0.0, "stroke_high": s > geom.stroke,
            "lower_hinge": beta > geom.lower_hinge_limit_deg,
            "upper_hinge": alpha > geom.upper_hinge_limit_deg,
            "strokes": s, "beta_deg": beta, "alpha_deg": alpha}


def check_pose(geom: StewartGeometry, pos: np.ndarray, rot: np.ndarray,
               definition: HingeDefinition = "deflection") -> list[str]:
    """Violated limits of one pose, one message each naming leg, limit and valid range."""
    v = limit_violations(geom, pos, rot, definition)
    out = []
    for i in range(N_LEGS):
        if v["stroke_low"][i] or v["stroke_high"][i]:
            out.append(f"leg {i + 1} stroke {v['strokes'][i] * 1e3:.3f} mm outside "
                       f"[0, {geom.stroke * 1e3:g}] mm")
        if v["lower_hinge"][i]:
            out.append(f"leg {i + 1} lower hinge (beta, {definition}) {v['beta_deg'][i]:.2f} deg "
                       f"outside [0, {geom.lower_hinge_limit_deg:g}] deg")
        if v["upper_hinge"][i]:
            out.append(f"leg {i + 1} upper hinge (alpha, {definition}) {v['alpha_deg'][i]:.2f} deg"
                       f" outside [0, {geom.upper_hinge_limit_deg:g}] deg")
    return out


def require_pose(geom: StewartGeometry, pos: np.ndarray, rot: np.ndarray,
                 definition: HingeDefinition = "deflection") -> np.ndarray:
    """Strokes of a pose that respects every limit; LimitError listing the violations otherwise."""
    pos, rot = np.asarray(pos, dtype=float), np.asarray(rot, dtype=float)
    if pos.shape != (3,) or rot.shape != (3, 3):
        raise ConfigError(f"one pose needs pos (3,) and rot (3, 3), got {pos.shape}, {rot.shape}")
    problems = check_pose(geom, pos, rot, definition)
    if problems:
        raise LimitError("; ".join(problems))
    return inverse_kinematics(geom, pos, rot)
