"""Generic pose sets for either form of the arm model (:mod:`serpar.calibration.arm_design` builds them
with the MD-H chain's own kinematics).

Only a point-consistency set needs the kinematics: its generic sockets must be consistent
under the start model (every configuration of a socket reaches the same point), found here by
inverse kinematics through :func:`serpar.calibration.arm_error_models.chain_kinematics`, so the POE form gets
the same redundancy analysis as the MD-H one. Other layouts need only random joint angles and
are delegated to :func:`serpar.calibration.arm_design.generic_design` unchanged.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from serpar.calibration.arm_design import IK_TOL_M, PER_SOCKET, consistent_sockets, generic_design
from serpar.calibration.arm_error_models import ArmModel, chain_forward, chain_kinematics, layout
from serpar.calibration.poe_calibration import PoeChain
from serpar.kinematics.mdh import Chain
from serpar.kinematics.robot import PANDA, Robot
from serpar.sim.arm_measurements import Measurements, PointSet


def tool_ik(chain: Chain | PoeChain, values: NDArray[np.float64], target: NDArray[np.float64],
            q0: NDArray[np.float64], iterations: int = 60, robot: Robot = PANDA
            ) -> NDArray[np.float64]:
    """Damped least-squares IK of the tool point to ``target`` (3,) from each start q0 (M, n),
    clipped to the robot's joint limits, either form; rows that did not converge are NaN."""
    q = np.array(q0, float)
    lo, hi = np.asarray(robot.q_min), np.asarray(robot.q_max)
    for _ in range(iterations):
        tool, _, jac_q = chain_kinematics(chain, values, q, params=False)
        err = target[None, :] - tool[:, :3, 3]
        jac = jac_q[:, :3]
        jjt = jac @ jac.transpose(0, 2, 1) + 1e-6 * np.eye(3)
        step = np.einsum("nji,nj->ni", jac, np.linalg.solve(jjt, err[..., None])[..., 0])
        q = np.clip(q + step, lo, hi)
    miss = np.linalg.norm(chain_forward(chain, values, q)[:, :3, 3] - target, axis=1)
    q[miss > IK_TOL_M] = np.nan
    return q


def design_for(model: ArmModel, meas: Measurements, x0: NDArray[np.float64], seed: int = 0
               ) -> tuple[Measurements, NDArray[np.float64]]:
    """:func:`serpar.calibration.arm_design.generic_design` for either form of ``model``."""
    if model.form == "mdh" or not isinstance(meas, PointSet):
        return generic_design(model, meas, x0, seed)
    rng = np.random.default_rng(seed)
    lay = layout(model, meas)
    values = model.chain.values(lay.split(x0)[1])
    counts = np.maximum(np.bincount(meas.point), PER_SOCKET)
    q, point = consistent_sockets(model.chain, values, counts, rng, chain_forward, tool_ik,
                                  meas.robot)
    tau = None
    if meas.tau_gravity is not None:
        # the same rule as arm_design: random loads of the campaign's spread, zero where the
        # campaign never loads a joint (its compliance stays non-functional)
        spread = np.asarray(meas.tau_gravity).std(axis=0)
        spread[spread < 1e-9 * max(spread.max(), 1e-300)] = 0.0
        tau = rng.normal(size=q.shape) * spread
    x = np.array(x0, float)
    x[lay.size - lay.n_compliance:] = 0.0
    p = chain_forward(model.chain, values, q)[:, :3, 3]
    x[:3 * lay.n_points] = np.array([p[point == s].mean(axis=0)
                                     for s in range(len(counts))]).ravel()
    return replace(meas, q=q, point=point, tau_gravity=tau), x
