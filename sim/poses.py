"""Preview states for pictures: kinematic poses (no dynamics), e.g. a conductor in hand at the
inspection point so the in-hand cameras have something to see.

These set positions directly and call mj_forward; they are for rendering and
tests, never a substitute for the task's grasp or insertion.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.optimize import least_squares

from serpar.errors import ConfigError, UnknownNameError
from serpar.sim import names
from serpar.sim.arm import FINGER_JOINT_NAMES, Q_MAX, Q_MIN, TCP_SITE
from serpar.sim.scene import Scene

STATES: tuple[str, ...] = ("home", "inspect")
GRASP_HEIGHT = 0.006
"""TCP (pad centre) above the conductor's shoulder [m]: the fingertips end 4 mm below the
TCP, so they stay 2 mm clear of the plate when the shoulder seats."""
DOWN = np.array([0.0, 0.0, -1.0])
REST_WEIGHT = 1e-4
"""[m/rad] Weight of the pull toward a rest posture in the inverse kinematics: small enough
that the pose stays within ~0.02 um (residual ~ weight^2 |q - rest| / |J|)."""


def solve_tcp_pose(scene: Scene, position: np.ndarray, approach: np.ndarray = DOWN,
                   yaw_hint: float | None = None, rotation: np.ndarray | None = None,
                   q_start: np.ndarray | None = None) -> np.ndarray:
    """Arm joint angles putting the TCP at `position` with its z axis along `approach`
    (or, when `rotation` is given, its whole frame at that rotation matrix).

    Damped least squares within the joint limits (scipy); raises if the residual > 1 um.
    """
    site = scene.model.site(names.ARM + TCP_SITE).id
    return solve_site_pose(scene.model, scene.data.qpos, scene.arm_qpos_adr, site, position,
                           approach, yaw_hint, rotation, q_start)


def solve_site_pose(model: mujoco.MjModel, qpos: np.ndarray, arm_qpos_adr: np.ndarray, site: int,
                    position: np.ndarray, approach: np.ndarray = DOWN, yaw_hint: float | None = None,
                    rotation: np.ndarray | None = None, q_start: np.ndarray | None = None,
                    rest: np.ndarray | None = None) -> np.ndarray:
    """:func:`solve_tcp_pose` for any model holding the arm: `qpos` the state the other joints
    keep, `arm_qpos_adr` the arm joints' addresses, `site` the TCP's id; `rest`: of the
    redundant arm's solutions, the one nearest these joint angles (the elbow where a posture
    task pulling toward `rest` would leave it; the pose then within ~0.01 um)."""
    m = model
    work = mujoco.MjData(m)
    work.qpos[:] = qpos

    def residual(q: np.ndarray) -> np.ndarray:
        work.qpos[arm_qpos_adr] = q
        mujoco.mj_kinematics(m, work)
        rot = work.site_xmat[site].reshape(3, 3)
        extra = [] if rest is None else [REST_WEIGHT * (q - rest)]
        if rotation is not None:
            return np.concatenate([work.site_xpos[site] - position, 0.1 * (rot - rotation).ravel(), *extra])
        res = [work.site_xpos[site] - position, 0.1 * (rot[:, 2] - approach), *extra]
        if yaw_hint is not None:
            res.append([0.01 * (np.arctan2(rot[1, 0], rot[0, 0]) - yaw_hint)])
        return np.concatenate(res)

    q0 = np.asarray(qpos, float)[arm_qpos_adr].copy() if q_start is None else np.asarray(q_start, float)
    sol = least_squares(residual, q0, bounds=(np.array(Q_MIN), np.array(Q_MAX)), xtol=1e-14,
                        ftol=1e-14, gtol=1e-14)
    if np.linalg.norm(sol.fun[:3]) > 1e-6 or (rotation is not None and np.linalg.norm(sol.fun[3:12]) > 1e-6):
        raise ConfigError(f"TCP target {np.round(position, 4)} m is out of the arm's reach "
                          f"(residual {np.linalg.norm(sol.fun[:3]) * 1e3:.2f} mm)")
    return sol.x


def put_in_hand(scene: Scene, conductor: int, grasp_height: float) -> None:
    """Place `conductor` between the fingers at the arm's current pose, journal along the TCP z,
    held `grasp_height` above its shoulder; fingers just touching (no squeeze yet).

    An initial condition for checks and pictures; the task grasps by physics.
    """
    if not 0 <= conductor < len(scene.conductor_bodies):
        raise ConfigError(f"conductor {conductor}: valid 0..{len(scene.conductor_bodies) - 1}")
    m, d = scene.model, scene.data
    radius = scene.diameters.bodies[conductor] / 2
    for j in FINGER_JOINT_NAMES:
        d.qpos[m.joint(names.ARM + j).qposadr[0]] = radius
    mujoco.mj_kinematics(m, d)
    site = m.site(names.ARM + TCP_SITE).id
    rot = d.site_xmat[site].reshape(3, 3)
    adr = m.jnt_qposadr[m.body(scene.conductor_bodies[conductor]).jntadr[0]]
    shoulder = d.site_xpos[site] + grasp_height * rot[:, 2]
    # Conductor z = -TCP z (body up, journal down); x along the TCP x.
    part_rot = np.column_stack([rot[:, 0], -rot[:, 1], -rot[:, 2]])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, part_rot.ravel())
    d.qpos[adr:adr + 3], d.qpos[adr + 3:adr + 7] = shoulder, quat
    mujoco.mj_forward(m, d)


def pose_inspect(scene: Scene, conductor: int = 0) -> None:
    """Arm at the in-hand inspection point, fingers closed on `conductor` (journal down)."""
    pair = next((p for p in scene.config.stereo_pairs if p.name == "inspect"), None)
    if pair is None:
        raise ConfigError("the scene has no 'inspect' stereo pair")
    tcp = np.array(pair.target) + np.array([0.0, 0.0, GRASP_HEIGHT])
    # Fingers squeeze across the cameras' line of sight, so the part is seen between them.
    scene.data.qpos[scene.arm_qpos_adr] = solve_tcp_pose(scene, tcp, yaw_hint=np.pi / 2)
    put_in_hand(scene, conductor, GRASP_HEIGHT)


def apply_state(scene: Scene, state: str) -> None:
    """Put `scene` into a named preview state."""
    if state not in STATES:
        raise UnknownNameError("state", state, STATES)
    scene.reset()
    if state == "inspect":
        pose_inspect(scene)
