"""A rigid payload on the arm's flange for the arm-dynamics diagnosis: its standard inertial
parameters (in which inverse dynamics is linear) and the massless arm that carries only it,
whose inverse dynamics builds the payload candidate's regressor (arm_dynamics_effects.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.sim.plants.arm_changes import inertia_from_extent
from serpar.sim.rigid_arm import PANDA_ARM, ArmDynamics, ArmModel

if TYPE_CHECKING:  # arm_dynamics_terms imports this module (load_torque)
    from serpar.diagnosis.arm_dynamics_terms import Terms

Vec = NDArray[np.float64]


def payload_inertial(p: Vec) -> Vec:
    """The payload candidate's parameters (mass, CoM from the flange, extent: the Cholesky
    factor of the mass's second moment, :data:`~serpar.sim.plants.arm_changes.EXTENT`) ->
    (mass, CoM, inertia about the CoM: xx, yy, zz, xy, xz, yz). Fitted in the extent, the
    inertia is physically consistent for every parameter value."""
    return np.r_[p[:4], inertia_from_extent(float(p[0]), p[4:10])]


PANDA_FLANGE = np.array(PANDA_ARM.flange_pos)


def standard_parameters(p: Vec, flange: Vec = PANDA_FLANGE) -> Vec:
    """(mass, CoM from the flange, inertia about the CoM) -> (m, m c, inertia about the flange
    body's origin: xx, yy, zz, xy, xz, yz), in which inverse dynamics is linear. ``flange``:
    the flange origin in the flange body's frame (the arm's ``flange_pos``)."""
    m = p[0]
    c = np.asarray(flange, float) + p[1:4]
    i_com = np.array([[p[4], p[7], p[8]], [p[7], p[5], p[9]], [p[8], p[9], p[6]]])
    i_o = i_com + m * (c @ c * np.eye(3) - np.outer(c, c))  # parallel axes
    return np.r_[m, m * c, i_o[0, 0], i_o[1, 1], i_o[2, 2], i_o[0, 1], i_o[0, 2], i_o[1, 2]]


def set_payload(model: mujoco.MjModel, body: int, p: Vec, flange: Vec = PANDA_FLANGE) -> None:
    model.body_mass[body] = p[0]
    model.body_ipos[body] = np.asarray(flange, float) + p[1:4]
    i = np.array([[p[4], p[7], p[8]], [p[7], p[5], p[9]], [p[8], p[9], p[6]]])
    w, axes = np.linalg.eigh(i)
    if np.linalg.det(axes) < 0:
        axes[:, 0] *= -1.0
    model.body_inertia[body] = w
    mujoco.mju_mat2Quat(model.body_iquat[body], axes.ravel())


def load_torque(q: Vec, dq: Vec, ddq: Vec, load: Vec) -> Vec:
    """samples x 7: the torque of a declared load (rows of mass, CoM in the flange frame; a
    point mass, as libfranka's m_load / F_x_Cload without I_load) on the arm's motion."""
    out = np.zeros_like(q)
    held = load[:, 0] > 0
    if not held.any():
        return out
    dyn, body = payload_model()
    for values in np.unique(load[held], axis=0):  # the load changes only at grasp and release
        rows = held & np.all(load == values, axis=1)
        set_payload(dyn.model, body, np.r_[values, np.zeros(6)])
        out[rows] = dyn.link_torque(q[rows], dq[rows], ddq[rows])
    return out


def payload_model(arm: ArmModel = PANDA_ARM) -> tuple[ArmDynamics, int]:
    """The arm with a payload body on its flange body and every other body massless: its
    inverse dynamics is the payload's torque alone (body set by :func:`set_payload`)."""
    spec = arm.make_spec()
    body = spec.body(arm.flange_body).add_body(name="diagnosis_payload", pos=[0, 0, 0])
    body.mass, body.inertia, body.explicitinertial = 1.0, [1e-6, 1e-6, 1e-6], True
    # an inertial frame off the body frame (position and rotation) at compile time: else
    # MuJoCo marks the body "sameframe" and ignores later edits of body_ipos / body_iquat
    body.ipos = np.asarray(arm.flange_pos) + [0.01, 0.02, 0.03]
    body.iquat = [0.9, 0.1, 0.2, 0.3]
    model = spec.compile()
    b = model.body("diagnosis_payload").id
    model.body_mass[:] = 0.0
    model.body_inertia[:] = 0.0
    return ArmDynamics(model, arm), b


def link_rate(terms: Terms, tau: Vec) -> Vec:
    """The rate of a torque at every sample, windowed like the link-side sensor channel (what a
    sensor reading late misses: lag x this)."""
    return terms.rows.link_at(np.gradient(tau, axis=0) * terms.rate)


@dataclass(frozen=True)
class PayloadRegressor:
    """Per row, the torque per standard inertial parameter of a rigid payload on link 7 (mass,
    first moments, inertia about the link-7 origin: :func:`standard_parameters`), windowed like
    the channels: rows x joint x 10 for the link channel, the drive channel and the link
    channel's rate; rows x 7 x 7 x 10 for the joint-space inertia it adds."""

    link: Vec
    drive: Vec
    link_rate: Vec
    mass: Vec

    @classmethod
    def of(cls, terms: Terms, arm: ArmModel = PANDA_ARM) -> PayloadRegressor:
        """Inverse dynamics is linear in the standard parameters, so the torques of 10 payload
        bodies with independent parameter vectors, evaluated at every sample, give it."""
        dyn, body = payload_model(arm)
        flange = np.asarray(arm.flange_pos, float)
        rng = np.random.default_rng(0)
        phis, link, drive, rate, mass = [], [], [], [], []
        for _ in range(10):
            p = np.r_[rng.uniform(0.5, 2.0), rng.uniform(-0.1, 0.1, 3), rng.uniform(0.0, 0.01, 6)]
            p[4:7] += 0.02  # diagonal-dominant: a positive-definite tensor
            set_payload(dyn.model, body, p, flange)
            phis.append(standard_parameters(p, flange))
            tau = dyn.link_torque(terms.q_full, terms.dq_full, terms.a_full)
            link.append(terms.rows.link_at(tau))
            drive.append(terms.rows.at(tau))
            rate.append(link_rate(terms, tau))
            mass.append(dyn.mass_link_and_full(terms.q)[0])
        inv = np.linalg.inv(np.array(phis).T)  # columns: the bodies' parameter vectors
        return cls(np.stack(link, axis=2) @ inv, np.stack(drive, axis=2) @ inv,
                   np.stack(rate, axis=2) @ inv, np.stack(mass, axis=3) @ inv)


def _entries(m: Vec) -> Vec:
    """A symmetric 3 x 3 (x k) as its xx, yy, zz, xy, xz, yz entries."""
    return np.stack([m[0, 0], m[1, 1], m[2, 2], m[0, 1], m[0, 2], m[1, 2]])


def standard_jacobian(p: Vec, flange: Vec = PANDA_FLANGE) -> Vec:
    """10 x 10: d :func:`standard_parameters` (:func:`payload_inertial` (p)) / d p, analytic
    (the map is a polynomial of degree three: mass times the extent's square, mass times the
    CoM's square)."""
    m, d, ext = float(p[0]), np.asarray(p[1:4], float), np.asarray(p[4:10], float)
    c = np.asarray(flange, float) + d
    eye = np.eye(3)
    rows, cols = np.tril_indices(3)
    # EXTENT's order: Lxx, Lyx, Lyy, Lzx, Lzy, Lzz = the lower triangle row by row
    low = np.zeros((3, 3))
    low[rows, cols] = ext
    gram = low @ low.T
    out = np.zeros((10, 10))
    # by the mass
    out[0, 0] = 1.0
    out[1:4, 0] = c
    out[4:, 0] = _entries(np.trace(gram) * eye - gram + (c @ c) * eye - np.outer(c, c))
    # by the CoM offset
    for k in range(3):
        e = eye[k]
        out[1 + k, 1 + k] = m
        out[4:, 1 + k] = _entries(m * (2.0 * c[k] * eye - np.outer(e, c) - np.outer(c, e)))
    # by the extent: S = m L L^T, inertia about the CoM tr(S) 1 - S
    for a, (i, j) in enumerate(zip(rows, cols)):
        unit = np.zeros((3, 3))
        unit[i, j] = 1.0
        ds = m * (unit @ low.T + low @ unit.T)
        out[4:, 4 + a] = _entries(np.trace(ds) * eye - ds)
    return out
