"""Generic pose sets: the same measurement layout as a campaign, on random configurations.

Why: which parameters are redundant is a property of the model and the measurement type
(seed 003 §4.2), not of one campaign's poses. The redundancy analysis therefore runs on a
generic pose set, and a campaign is then checked to identify everything the generic set does.
For point consistency the generic set must itself be consistent: every configuration of a
socket reaches the same point (found by inverse kinematics), else the data's own scatter
would make, e.g., a rotation of the base frame look identifiable when it only moves every
socket.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from serpar.calibration.arm_error_models import ArmModel, Layout, layout
from serpar.errors import IdentificationError
from serpar.kinematics.mdh import Chain, chain_frames, forward, pose_jacobian
from serpar.kinematics.robot import PANDA, Robot
from serpar.sim.arm_measurements import Measurements, PointSet

GENERIC_POSES = 64
PER_SOCKET = 16
IK_TOL_M = 1e-10
IK_ATTEMPTS = 20


def position_ik(chain: Chain, values: NDArray[np.float64], target: NDArray[np.float64],
                q0: NDArray[np.float64], iterations: int = 60, robot: Robot = PANDA
                ) -> NDArray[np.float64]:
    """Damped least-squares IK of the tool point to ``target`` (3,) from each start q0 (M, n),
    clipped to the robot's joint limits; returns (M, n) with the rows that did not converge
    NaN."""
    q = np.array(q0, float)
    lo, hi = np.asarray(robot.q_min), np.asarray(robot.q_max)
    cols = chain.joint_elements
    for _ in range(iterations):
        frames = chain_frames(chain, values, q)
        err = target[None, :] - frames.tool[:, :3, 3]
        jac = pose_jacobian(chain, frames)[:, :3, cols]
        jjt = jac @ jac.transpose(0, 2, 1) + 1e-6 * np.eye(3)
        q = np.clip(q + np.einsum("nji,nj->ni", jac, np.linalg.solve(jjt, err[..., None])[..., 0]),
                    lo, hi)
    miss = np.linalg.norm(forward(chain, values, q)[:, :3, 3] - target, axis=1)
    q[miss > IK_TOL_M] = np.nan
    return q


def consistent_sockets(chain: Any, values: NDArray[np.float64], counts: NDArray[np.int64],
                       rng: np.random.Generator, forward_fn: Callable[..., NDArray[np.float64]] = forward,
                       ik_fn: Callable[..., NDArray[np.float64]] = position_ik,
                       robot: Robot = PANDA
                       ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Joint angles (sum(counts), n) and socket ids: per socket a random reachable point, then
    `count` IK solutions within the robot's limits that reach it under the model
    (`forward_fn`/`ik_fn` of its form)."""
    lo, hi = np.asarray(robot.q_min), np.asarray(robot.q_max)
    q_all, ids = [], []
    for s, count in enumerate(counts):
        target = forward_fn(chain, values, rng.uniform(lo, hi)[None, :])[0, :3, 3]
        found: list[NDArray[np.float64]] = []
        for _ in range(IK_ATTEMPTS):
            q = ik_fn(chain, values, target, rng.uniform(lo, hi, size=(2 * count, len(lo))),
                      robot=robot)
            found.extend(q[np.all(np.isfinite(q), axis=1)])
            if len(found) >= count:
                break
        else:
            raise IdentificationError("could not build a generic point-consistency pose set "
                                      "(inverse kinematics failed); check the tool offset")
        q_all.append(np.asarray(found[:count]))
        ids.append(np.full(count, s))
    return np.vstack(q_all), np.concatenate(ids)


def generic_design(model: ArmModel, meas: Measurements, x0: NDArray[np.float64],
                   seed: int = 0) -> tuple[Measurements, NDArray[np.float64]]:
    """The same measurement layout on random joint angles (consistent sockets for a
    PointSet), and its start point: x0's chain errors, zero compliance, its own sockets."""
    rng = np.random.default_rng(seed)
    lay: Layout = layout(model, meas)
    dchain = lay.split(x0)[1]
    values = model.chain.values(dchain)
    if isinstance(meas, PointSet):
        counts = np.maximum(np.bincount(meas.point), PER_SOCKET)
        q, point = consistent_sockets(model.chain, values, counts, rng, robot=meas.robot)
    else:
        q = rng.uniform(meas.robot.q_min, meas.robot.q_max,
                        size=(max(meas.n_poses, GENERIC_POSES), meas.robot.n_joints))
    tau = None
    if meas.tau_gravity is not None:
        spread = np.asarray(meas.tau_gravity).std(axis=0)
        spread[spread < 1e-9 * max(spread.max(), 1e-300)] = 0.0  # never loaded: keep it so
        tau = rng.normal(size=q.shape) * spread
    x = np.array(x0, float)
    x[lay.size - lay.n_compliance:] = 0.0  # redundancy does not depend on the compliance
    if isinstance(meas, PointSet):
        gen = replace(meas, q=q, point=point, tau_gravity=tau)
        p = forward(model.chain, values, q)[:, :3, 3]
        centres = np.array([p[point == s].mean(axis=0) for s in range(len(counts))])
        x[:3 * lay.n_points] = centres.ravel()
        return gen, x
    fields: dict[str, object] = {"q": q, "tau_gravity": tau, "position": np.zeros((len(q), 3))}
    if hasattr(meas, "rotation"):
        fields["rotation"] = np.tile(np.eye(3), (len(q), 1, 1))
    return replace(meas, **fields), x
