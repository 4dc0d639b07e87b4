"""Test-scene construction for in-hand inspection (step 4): a conductor put between the
fingers kinematically with a chosen grasp error, the measured TCP pose the real cell
would use, and the ground truth the vision result is scored against.

Nothing here is a grasp: positions are set directly and ``mj_forward`` is called, like
:func:`serpar.sim.poses.put_in_hand`. Only tests and scoring use it; ``vision/`` never does.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.calibration.camera_truth import true_camera
from serpar.controllers.arm_model import NominalArm
from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.arm import FINGER_JOINT_NAMES, TCP_SITE
from serpar.sim.arm_drive import quantise
from serpar.sim.poses import GRASP_HEIGHT, pose_inspect, solve_tcp_pose
from serpar.sim.scene import Scene
from serpar.vision.camera import StereoPair

Vec = NDArray[np.float64]
PAD_HALF_HEIGHT = 0.004
"""Pads reach 4 mm either side of the TCP along its z (assets/arm/panda.xml)."""


@dataclass(frozen=True)
class GraspError:
    """Where the conductor sits in the hand relative to the nominal grasp (TCP frame).

    The nominal grasp has the journal on the TCP z axis, the shoulder `grasp_height` below
    the TCP (along +z). The error tilts the part about the TCP by the rotation vector
    (tilt_x, tilt_y, 0), spins it about its own axis, then shifts it by `offset`.
    """

    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """[m] in the TCP frame."""
    tilt: tuple[float, float] = (0.0, 0.0)
    """Rotation vector components about TCP x and y [rad]."""
    spin: float = 0.0
    """About the conductor's own axis [rad] (moves the rendered facets)."""

    def __post_init__(self) -> None:
        if max(abs(v) for v in self.offset) > 0.002 or max(abs(v) for v in self.tilt) > 0.2:
            raise ConfigError("grasp error must stay within 2 mm and 0.2 rad "
                              "(the part stays in the hand)")


def random_grasp_error(rng: np.random.Generator, max_offset: float = 3e-4,
                       max_tilt: float = np.radians(2.0), max_axial: float = 2e-4) -> GraspError:
    """Uniform lateral offset (+-max_offset in TCP x and y), axial offset and tilt."""
    lateral, tilt = rng.uniform(-max_offset, max_offset, 2), rng.uniform(-max_tilt, max_tilt, 2)
    return GraspError(offset=(float(lateral[0]), float(lateral[1]),
                              float(rng.uniform(-max_axial, max_axial))),
                      tilt=(float(tilt[0]), float(tilt[1])), spin=float(rng.uniform(0, 2 * np.pi)))


def _rotvec(v: Vec) -> Vec:
    quat = np.zeros(4)
    angle = float(np.linalg.norm(v))
    mujoco.mju_axisAngle2Quat(quat, v / angle if angle > 0 else np.array([0, 0, 1.0]), angle)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)


def put_in_hand_with_error(scene: Scene, conductor: int, error: GraspError = GraspError(),
                           grasp_height: float = GRASP_HEIGHT) -> None:
    """Place `conductor` in the hand at the arm's current pose with a grasp `error`.

    Each finger is opened until its pad face just touches the (offset, tilted) body over the
    pad's height, so pads and part do not overlap in the pictures; the fingers are set
    independently here (kinematic construction, not the coupled hand's physics).
    """
    if not 0 <= conductor < len(scene.conductor_bodies):
        raise ConfigError(f"conductor {conductor}: valid 0..{len(scene.conductor_bodies) - 1}")
    m, d = scene.model, scene.data
    mujoco.mj_kinematics(m, d)
    site = m.site(names.ARM + TCP_SITE).id
    tcp_pos, tcp_rot = d.site_xpos[site].copy(), d.site_xmat[site].reshape(3, 3).copy()
    tilt = _rotvec(np.array([error.tilt[0], error.tilt[1], 0.0]))
    nominal = np.diag([1.0, -1.0, -1.0])  # conductor z = -TCP z, x along the TCP x
    rot_tcp = tilt @ nominal @ _rotvec(np.array([0.0, 0.0, error.spin]))
    pos_tcp = tilt @ np.array([0.0, 0.0, grasp_height]) + np.asarray(error.offset)
    # Body surface (the pads' z band) in the TCP frame -> finger openings that just touch it.
    radius = scene.diameters.bodies[conductor] / 2
    ang = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    z = np.linspace(0, scene.config.conductor.body_length, 101)
    ring = np.stack(np.broadcast_arrays(radius * np.cos(ang)[:, None],
                                        radius * np.sin(ang)[:, None], z[None, :]), -1)
    ring = ring.reshape(-1, 3)
    surf = ring @ rot_tcp.T + pos_tcp
    band = surf[np.abs(surf[:, 2]) <= PAD_HALF_HEIGHT]
    openings = (max(band[:, 1].max(), 0.0), max(-band[:, 1].min(), 0.0))  # pad_left faces +y
    for j, q in zip(FINGER_JOINT_NAMES, openings):
        d.qpos[m.joint(names.ARM + j).qposadr[0]] = q
    adr = m.jnt_qposadr[m.body(scene.conductor_bodies[conductor]).jntadr[0]]
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, (tcp_rot @ rot_tcp).ravel())
    d.qpos[adr:adr + 3], d.qpos[adr + 3:adr + 7] = tcp_pos + tcp_rot @ pos_tcp, quat
    mujoco.mj_forward(m, d)


INSPECT_ROLL = np.radians(5.0)
"""Lean of the presented part in the inspect images [rad] (TCP z turned about the cameras'
viewing direction). A slanted edge crosses pixel columns along its length, so the renderer's
4x multisampling (edge coverage in quarter pixels) averages out along it, as in the ISO 12233
slanted-edge method; an exactly upright edge keeps one quantisation error over its length."""


def pose_inspect_with_error(scene: Scene, error: GraspError = GraspError(), conductor: int = 0,
                            roll: float = INSPECT_ROLL) -> None:
    """Arm at the in-hand inspection point, TCP z leaning by `roll` about the world y (the
    inspect cameras' viewing direction), holding `conductor` with grasp `error`."""
    pair = next((p for p in scene.config.stereo_pairs if p.name == "inspect"), None)
    if pair is None:
        raise ConfigError("the scene has no 'inspect' stereo pair")
    pose_inspect(scene, conductor)
    approach = np.array([np.sin(roll), 0.0, -np.cos(roll)])
    tcp = np.array(pair.target) - GRASP_HEIGHT * approach
    scene.data.qpos[scene.arm_qpos_adr] = solve_tcp_pose(scene, tcp, approach, yaw_hint=np.pi / 2)
    put_in_hand_with_error(scene, conductor, error)


def empty_hand(scene: Scene, conductor: int = 0, roll: float = INSPECT_ROLL) -> None:
    """Arm at the inspection point, fingers closed on nothing, `conductor` back in the tray."""
    pose_inspect_with_error(scene, GraspError(), conductor, roll)
    m, d = scene.model, scene.data
    for j in FINGER_JOINT_NAMES:
        d.qpos[m.joint(names.ARM + j).qposadr[0]] = 0.0
    adr = m.jnt_qposadr[m.body(scene.conductor_bodies[conductor]).jntadr[0]]
    d.qpos[adr:adr + 7] = m.qpos0[adr:adr + 7]
    mujoco.mj_forward(m, d)


def measured_tcp(scene: Scene, counts_per_rev: int = 2**20,
                 arm: NominalArm | None = None) -> tuple[Vec, Vec]:
    """TCP pose as the cell knows it: encoder-quantised joints through the nominal arm model."""
    arm = arm or NominalArm()
    q = quantise(scene.data.qpos[scene.arm_qpos_adr].copy(), counts_per_rev)
    arm.load(q, np.zeros_like(q))
    return arm.tcp_pose()


@dataclass(frozen=True, eq=False)
class InHandTruth:
    """The grasped conductor's journal in the (true) TCP frame [m]."""

    tip: Vec
    """Journal tip centre."""
    axis: Vec
    """Unit vector from the body toward the journal tip."""

    @property
    def tilt(self) -> float:
        return float(np.arccos(np.clip(self.axis[2], -1.0, 1.0)))


def true_in_hand(scene: Scene, conductor: int = 0) -> InHandTruth:
    """Ground truth from the simulator (scoring only)."""
    m, d = scene.model, scene.data
    site = m.site(names.ARM + TCP_SITE).id
    pos, rot = d.site_xpos[site], d.site_xmat[site].reshape(3, 3)
    tip = d.site(f"{names.conductor(conductor)}tip").xpos
    body_rot = d.xmat[scene.conductor_bodies[conductor]].reshape(3, 3)
    return InHandTruth(tip=rot.T @ (tip - pos), axis=rot.T @ -body_rot[:, 2])


def true_pair(scene: Scene, size: tuple[int, int]) -> StereoPair:
    """The simulator's exact inspect cameras at `size` (scoring and development only)."""
    m, d = scene.model, scene.data
    return StereoPair(true_camera(m, d, "inspect_left", size),
                      true_camera(m, d, "inspect_right", size))
