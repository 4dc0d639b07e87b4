"""The simulated "real" Panda of the arm calibration campaign (seed 003 §7): MuJoCo physics,
never the calibration model's own formula.

The arm's MJCF (``serpar.sim.arm``) is edited with ``mujoco.MjSpec``: every link body frame (pos,
quat) and the base are moved by hidden geometric errors drawn per seed, the gripper's finger
mechanism is replaced by a laser-tracker target (SMR on a bracket) whose centre is the tool
point, and each joint is held by a stiff position servo (``position`` actuator, kp = joint
stiffness): the encoder reports the commanded angle while the link settles under gravity at
the commanded angle plus tau_gravity / k. The tracker sees the SMR centre at that static
equilibrium, with 15 um noise per axis.

Hidden-error magnitudes (seed 003's identified D-H errors, its Table 4, are not in the seed's
text; these are typical of a small industrial arm): link frames 0.2 mm and 0.5 mrad (1 sigma
per axis), base registration 1 mm and 1 mrad, SMR position on the bracket 0.5 mm.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.kinematics.mdh import Chain, panda_chain
from serpar.sim.arm import (
    FLANGE_D,
    HAND_BODY,
    JOINT_NAMES,
    LINK_NAMES,
    N_JOINTS,
    Q_MAX,
    Q_MIN,
    build_arm_spec,
)
from serpar.sim.arm_measurements import PositionSet

STIFFNESS_NM_PER_RAD: tuple[float, ...] = (2.0e4, 1.0e4, 1.0e4, 1.0e4, 5.0e3, 5.0e3, 5.0e3)
"""Hidden joint stiffness of the simulated arm [N m/rad]: harmonic drive plus torque sensor,
the size reported for arms of the Panda's class (order 1e4 N m/rad on the big joints)."""
TOOL_BODY = "smr"
FINGER_MECHANISM = "finger_carrier"
EQUILIBRIUM_TOL_RAD = 1e-13


@dataclass(frozen=True)
class TruthConfig:
    """The hidden plant and its measurement campaign (seed 003: 150 + 100 poses)."""

    seed: int = 3
    link_pos_sigma_m: float = 0.2e-3
    link_rot_sigma_rad: float = 0.5e-3
    base_pos_sigma_m: float = 1.0e-3
    base_rot_sigma_rad: float = 1.0e-3
    tool_pos_sigma_m: float = 0.5e-3
    stiffness: tuple[float, ...] | None = STIFFNESS_NM_PER_RAD
    """Joint stiffness [N m/rad]; None: rigid joints (no gravity deflection)."""
    tool_offset_m: tuple[float, float, float] = (0.0, 0.06, 0.12)
    """Nominal SMR centre in the flange frame (the bracket drawing)."""
    tool_mass_kg: float = 0.3
    tracker_sigma_m: float = 15e-6
    n_train: int = 150
    n_verify: int = 100
    joint_margin_rad: float = 0.15
    min_tool_height_m: float = 0.15
    errors: bool = True
    """False: the nominal geometry (the gravity model the controller uses)."""
    hand: bool = True
    """Keep the Franka Hand (its finger mechanism is always replaced by the tool)."""

    def __post_init__(self) -> None:
        sigmas = {k: getattr(self, k) for k in ("link_pos_sigma_m", "link_rot_sigma_rad",
                                               "base_pos_sigma_m", "base_rot_sigma_rad",
                                               "tool_pos_sigma_m", "tracker_sigma_m",
                                               "tool_mass_kg", "joint_margin_rad")}
        for name, value in sigmas.items():
            if not (np.isfinite(value) and value >= 0):
                raise ConfigError(f"TruthConfig.{name} must be >= 0, got {value!r}")
        if self.stiffness is not None and (len(self.stiffness) != N_JOINTS
                                           or min(self.stiffness) <= 0):
            raise ConfigError(f"TruthConfig.stiffness must be {N_JOINTS} positive values "
                              "[N m/rad] or None for rigid joints")
        if self.n_train < 1 or self.n_verify < 1:
            raise ConfigError("TruthConfig.n_train and n_verify must be positive")
        if len(self.tool_offset_m) != 3:
            raise ConfigError("TruthConfig.tool_offset_m must be 3 values [m]")

    def nominal_chain(self) -> Chain:
        """The calibration's starting model: the Panda's table with the drawn SMR offset."""
        return panda_chain(self.tool_offset_m)


@dataclass(frozen=True)
class HiddenErrors:
    """Per body (link0 = base, link1..7) position [m] and rotation-vector [rad] errors, and
    the SMR's position error [m]. Never read by the calibration."""

    pos: NDArray[np.float64]
    rot: NDArray[np.float64]
    tool: NDArray[np.float64]


def draw_errors(cfg: TruthConfig) -> HiddenErrors:
    rng = np.random.default_rng([cfg.seed, 3])
    scale_p = np.r_[cfg.base_pos_sigma_m, np.full(N_JOINTS, cfg.link_pos_sigma_m)]
    scale_r = np.r_[cfg.base_rot_sigma_rad, np.full(N_JOINTS, cfg.link_rot_sigma_rad)]
    on = 1.0 if cfg.errors else 0.0
    pos = on * rng.normal(size=(N_JOINTS + 1, 3)) * scale_p[:, None]
    rot = on * rng.normal(size=(N_JOINTS + 1, 3)) * scale_r[:, None]
    return HiddenErrors(pos, rot, on * rng.normal(size=3) * cfg.tool_pos_sigma_m)


def build_model(cfg: TruthConfig, errors: HiddenErrors) -> mujoco.MjModel:
    """The arm with ``errors`` applied, the SMR tool and (if stiff) one servo per joint."""
    spec = build_arm_spec()
    for element in (*spec.actuators, *spec.equalities, *spec.tendons):
        spec.delete(element)
    spec.delete(spec.body(FINGER_MECHANISM if cfg.hand else HAND_BODY))
    for i, name in enumerate(LINK_NAMES):
        body = spec.body(name)
        quat = np.asarray(body.quat, float) / np.linalg.norm(body.quat)
        mujoco.mju_quatIntegrate(quat, errors.rot[i], 1.0)  # quat * exp(rot), body frame
        body.pos = np.asarray(body.pos, float) + errors.pos[i]
        body.quat = quat
    tool = spec.body(LINK_NAMES[-1]).add_body(name=TOOL_BODY)
    tool.pos = np.array([0.0, 0.0, FLANGE_D]) + np.asarray(cfg.tool_offset_m) + errors.tool
    if cfg.tool_mass_kg > 0:
        tool.mass = cfg.tool_mass_kg
        tool.inertia = np.full(3, 1e-5)
        tool.explicitinertial = True
    tool.add_site(name=TOOL_BODY)
    if cfg.stiffness is not None:
        for joint, k in zip(JOINT_NAMES, cfg.stiffness):
            act = spec.add_actuator(name=f"servo_{joint}", target=joint,
                                    trntype=mujoco.mjtTrn.mjTRN_JOINT)
            act.set_to_position(kp=k, dampratio=1.0)
    return spec.compile()


@dataclass
class ArmPlant:
    """A compiled arm and its data, for static measurements."""

    cfg: TruthConfig
    model: mujoco.MjModel
    data: mujoco.MjData = field(init=False)

    def __post_init__(self) -> None:
        self.data = mujoco.MjData(self.model)
        self._site = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, TOOL_BODY)
        self._dof = np.array([self.model.jnt_dofadr[mujoco.mj_name2id(
            self.model, mujoco.mjtObj.mjOBJ_JOINT, j)] for j in JOINT_NAMES])

    def settle(self, q_cmd: NDArray[np.float64], max_iter: int = 200) -> NDArray[np.float64]:
        """Link angles at static equilibrium for commanded angles ``q_cmd`` (N, 7): the
        servo torque k (q_cmd - q) balances MuJoCo's gravity and passive forces."""
        q_cmd = np.atleast_2d(q_cmd)
        out = np.empty_like(q_cmd)
        d = self.data
        for n, qc in enumerate(q_cmd):
            d.qpos[:] = 0.0
            d.qvel[:] = 0.0
            d.qpos[self._dof] = qc
            if self.cfg.stiffness is not None:
                d.ctrl[:] = qc
                k = np.asarray(self.cfg.stiffness)
                for _ in range(max_iter):
                    mujoco.mj_forward(self.model, d)
                    force = d.qfrc_actuator + d.qfrc_passive - d.qfrc_bias + d.qfrc_constraint
                    step = force[self._dof] / k
                    d.qpos[self._dof] += step
                    if np.abs(step).max() < EQUILIBRIUM_TOL_RAD:
                        break
                else:
                    raise ConfigError(f"pose {n}: no static equilibrium in {max_iter} steps")
            out[n] = d.qpos[self._dof]
        return out

    def tool_points(self, q_link: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 3) SMR centres in the world (tracker) frame at link angles ``q_link``."""
        pts = np.empty((len(q_link), 3))
        for n, q in enumerate(np.atleast_2d(q_link)):
            self.data.qpos[self._dof] = q
            mujoco.mj_kinematics(self.model, self.data)
            pts[n] = self.data.site_xpos[self._site]
        return pts

    def gravity_torques(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """(N, 7) generalized gravity forces [N m] at joint angles q (zero velocity)."""
        tau = np.empty((len(q), N_JOINTS))
        for n, qq in enumerate(np.atleast_2d(q)):
            self.data.qpos[self._dof] = qq
            self.data.qvel[:] = 0.0
            mujoco.mj_forward(self.model, self.data)
            tau[n] = -self.data.qfrc_bias[self._dof]
        return tau


def nominal_plant(cfg: TruthConfig) -> ArmPlant:
    """The controller's model: nominal geometry, the nominal SMR, rigid joints."""
    nominal = replace(cfg, errors=False, stiffness=None)
    return ArmPlant(nominal, build_model(nominal, draw_errors(nominal)))


def sample_poses(cfg: TruthConfig, nominal: ArmPlant, n: int, rng: np.random.Generator
                 ) -> NDArray[np.float64]:
    """Uniform joint angles inside the limits less a margin, tool above the table."""
    lo = np.asarray(Q_MIN) + cfg.joint_margin_rad
    hi = np.asarray(Q_MAX) - cfg.joint_margin_rad
    poses: list[NDArray[np.float64]] = []
    while len(poses) < n:
        q = rng.uniform(lo, hi, size=(2 * n, N_JOINTS))
        high = nominal.tool_points(q)[:, 2] > cfg.min_tool_height_m
        poses.extend(q[high])
    return np.asarray(poses[:n])


@dataclass(frozen=True)
class Campaign:
    """Training and verification measurements; the noise-free truth is for evaluation only."""

    train: PositionSet
    verify: PositionSet
    train_truth: NDArray[np.float64]
    verify_truth: NDArray[np.float64]
    deflection_rad: NDArray[np.float64]
    """(N_train + N_verify, 7) link-side minus commanded angles at equilibrium."""


def run_campaign(cfg: TruthConfig) -> Campaign:
    """Measure the hidden plant at cfg.n_train + cfg.n_verify random poses."""
    rng = np.random.default_rng([cfg.seed, 0])
    nominal = nominal_plant(cfg)
    plant = ArmPlant(cfg, build_model(cfg, draw_errors(cfg)))
    q = sample_poses(cfg, nominal, cfg.n_train + cfg.n_verify, rng)
    q_link = plant.settle(q)
    truth = plant.tool_points(q_link)
    seen = truth + rng.normal(size=truth.shape) * cfg.tracker_sigma_m
    tau = nominal.gravity_torques(q)
    split = cfg.n_train
    sets = [PositionSet(q[s], seen[s], cfg.tracker_sigma_m, tau[s])
            for s in (slice(0, split), slice(split, None))]
    return Campaign(sets[0], sets[1], truth[:split], truth[split:], q_link - q)
