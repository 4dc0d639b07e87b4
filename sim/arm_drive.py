"""What the arm's hardware does between a controller and the physics: the addresses of one arm
in a compiled model (looked up once, used in step loops), the drives' torque limits and the
encoders' quantisation. Shared by the controllers and the simulated "real" arms (sim/plants/)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.arm import (
    ACTUATOR_NAMES,
    JOINT_NAMES,
    TCP_SITE,
    TORQUE_AXIS,
    TORQUE_LIMITS,
    TORQUE_SENSOR_NAMES,
)

Vec = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ArmIndex:
    """Addresses of one arm in a compiled model; looked up once, used inside step loops."""

    qpos: NDArray[np.int64]
    dof: NDArray[np.int64]
    actuators: NDArray[np.int64]
    tcp_site: int
    torque_adr: NDArray[np.int64]
    """sensordata address of each joint torque (the joint-axis component of tau_J{i})."""
    torque_sensors: NDArray[np.int64]
    """Sensor id of each tau_J{i} (its ``delay``, its history)."""

    @classmethod
    def from_model(cls, model: mujoco.MjModel, prefix: str = "") -> ArmIndex:
        def lookup(kind: mujoco.mjtObj, name: str) -> int:
            k = mujoco.mj_name2id(model, kind, prefix + name)
            if k < 0:
                raise ConfigError(f"{prefix + name!r} not in the model; check the arm prefix {prefix!r}")
            return k

        joints = [lookup(mujoco.mjtObj.mjOBJ_JOINT, n) for n in JOINT_NAMES]
        sensors = [lookup(mujoco.mjtObj.mjOBJ_SENSOR, n) for n in TORQUE_SENSOR_NAMES]
        return cls(
            qpos=np.array([model.jnt_qposadr[j] for j in joints]),
            dof=np.array([model.jnt_dofadr[j] for j in joints]),
            actuators=np.array([lookup(mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in ACTUATOR_NAMES]),
            tcp_site=lookup(mujoco.mjtObj.mjOBJ_SITE, TCP_SITE),
            torque_adr=np.array([model.sensor_adr[s] + TORQUE_AXIS for s in sensors]),
            torque_sensors=np.array(sensors),
        )


def quantise(q: Vec, counts_per_rev: int) -> Vec:
    """Encoder reading of q: the nearest count (no quantisation when counts_per_rev is 0)."""
    if counts_per_rev == 0:
        return q.copy()
    step = 2 * np.pi / counts_per_rev
    return np.rint(q / step) * step  # np.round's decimals=0 is rint, without its Python wrapper


_TORQUE_LIMITS = np.asarray(TORQUE_LIMITS)


def saturate_torque(tau: Vec) -> tuple[Vec, NDArray[np.bool_]]:
    """Clip to the Panda torque limits; returns (clipped torque, which joints saturated)."""
    return np.clip(tau, -_TORQUE_LIMITS, _TORQUE_LIMITS), np.abs(tau) > _TORQUE_LIMITS
