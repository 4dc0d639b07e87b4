"""Which inertia-like parameters a recording cannot tell from the links' own inertial
parameters (FIGAROH's base-parameter stage, as one question): a rotor inertia Ia_j adds
Ia_j q̈_j to joint j's drive, and where some combination of the links' standard inertial
parameters (mass, first moments, inertia tensor: 10 per link) adds the same torque at every
row, no data of this arm tell them apart (the TX40's Ia1 with Izz1, Ia2 with Izz2 + ...).

Such a parameter is held at the model file's value and named, never fitted: a fit would put
into the rotor whatever the link inertias of the file have wrong.

The links' regressor is inverse dynamics, linear in the standard parameters: one probe body
per link (attached at the link's frame, its inertial frame off the body frame so MuJoCo keeps
later edits), every other body massless, 10 independent parameter sets each.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_library import Coupling
from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.family import Effect
from serpar.sim.rigid_arm import ArmDynamics

Vec = NDArray[np.float64]

GROUPED_TOL = 1e-6
"""A column whose component outside the span of the links' inertial columns is below this
share of its norm is a combination of them (numerical round-off is ~1e-12; a parameter the
data separate leaves ~1e-2 or more)."""
_PARAM_SETS = 10
SAMPLES = 400
"""Samples spread over the recording at which the columns are compared (more than the 10 x
links parameters, so a span of them is a real test)."""


def _probe_model(dyn: ArmDynamics) -> tuple[ArmDynamics, list[int]]:
    arm = dyn.arm
    spec = arm.make_spec()
    for i, name in enumerate(arm.link_bodies):
        body = spec.body(name).add_body(name=f"grouping_probe{i}", pos=[0, 0, 0])
        body.mass, body.inertia, body.explicitinertial = 1.0, [1e-3, 1e-3, 1e-3], True
        body.ipos, body.iquat = [0.01, 0.02, 0.03], [0.9, 0.1, 0.2, 0.3]
    model = spec.compile()
    probes = [model.body(f"grouping_probe{i}").id for i in range(len(arm.link_bodies))]
    model.body_mass[:] = 0.0
    model.body_inertia[:] = 0.0
    return ArmDynamics(model, arm), probes


def _set(model: mujoco.MjModel, body: int, p: Vec) -> Vec:
    """Give ``body`` mass p[0], CoM p[1:4], principal inertia p[4:7] about axes p[7:10]
    (a rotation vector); returns the standard parameters (m, m c, inertia about the body
    origin: xx, yy, zz, xy, xz, yz)."""
    m, c = p[0], p[1:4]
    quat = np.zeros(4)
    mujoco.mju_axisAngle2Quat(quat, p[7:10] / max(np.linalg.norm(p[7:10]), 1e-12),
                              float(np.linalg.norm(p[7:10])))
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, quat)
    r = rot.reshape(3, 3)
    i_com = r @ np.diag(p[4:7]) @ r.T
    model.body_mass[body], model.body_ipos[body] = m, c
    model.body_inertia[body], model.body_iquat[body] = p[4:7], quat
    i_o = i_com + m * (c @ c * np.eye(3) - np.outer(c, c))
    return np.r_[m, m * c, i_o[0, 0], i_o[1, 1], i_o[2, 2], i_o[0, 1], i_o[0, 2], i_o[1, 2]]


def link_regressor_at(dyn: ArmDynamics, q: Vec, dq: Vec, ddq: Vec) -> Vec:
    """states x n x (10 x links): the torque per standard inertial parameter of every link
    (m, m c, inertia about the link frame's origin: xx, yy, zz, xy, xz, yz) at the states."""
    probe, bodies = _probe_model(dyn)
    rng = np.random.default_rng(0)
    cols = []
    for body in bodies:
        taus, phis = [], []
        for _ in range(_PARAM_SETS):
            p = np.r_[rng.uniform(0.5, 2.0), rng.uniform(-0.2, 0.2, 3), rng.uniform(0.01, 0.05, 3),
                      rng.uniform(-np.pi, np.pi, 3)]
            phis.append(_set(probe.model, body, p))
            taus.append(probe.link_torque(q, dq, ddq))
        probe.model.body_mass[body] = 0.0
        probe.model.body_inertia[body] = 0.0
        cols.append(np.stack(taus, axis=2) @ np.linalg.inv(np.array(phis).T))
    return np.concatenate(cols, axis=2)


def link_regressor(terms: Terms, dyn: ArmDynamics, samples: NDArray[np.int64]) -> Vec:
    """(samples x n) x (10 x links): :func:`link_regressor_at` at the recording's ``samples``
    (unwindowed: a window is linear and the same for every column, so it changes no span)."""
    y = link_regressor_at(dyn, terms.q_full[samples], terms.dq_full[samples],
                          terms.a_full[samples])
    return y.reshape(-1, y.shape[2])


def grouped(columns: Vec, links: Vec) -> NDArray[np.bool_]:
    """Per column of ``columns``: is it (to :data:`GROUPED_TOL`) in the span of ``links``?"""
    scale = np.linalg.norm(links, axis=0)
    basis = links[:, scale > 0] / scale[scale > 0]
    u, s, _ = np.linalg.svd(basis, full_matrices=False)
    span = u[:, s > s[0] * 1e-10] if s.size else u[:, :0]
    out = []
    for c in columns.T:
        norm = np.linalg.norm(c)
        rest = c - span @ (span.T @ c)
        out.append(norm == 0 or np.linalg.norm(rest) < GROUPED_TOL * norm)
    return np.array(out, bool)


def rotor_columns(terms: Terms, samples: NDArray[np.int64], joint: int, motor: int) -> Vec:
    """(samples x n): the torque of a unit rotor inertia on ``joint``'s drive with ``motor``'s
    acceleration (0-based; joint == motor: the joint's own armature)."""
    col = np.zeros((len(samples), terms.n))
    col[:, joint] = terms.a_full[samples, motor]
    return col.reshape(-1)


def hold_grouped(effects: tuple[Effect, ...], terms: Terms, dyn: ArmDynamics,
                 couplings: tuple[Coupling, ...]) -> tuple[tuple[Effect, ...], tuple[str, ...]]:
    """The effects with every rotor-inertia parameter the links' inertial parameters take the
    same torque as held at the file's value (``Effect.fix``), and one note naming them."""
    names = [e.name for e in effects]
    targets: list[tuple[int, int, int, int]] = []  # effect, parameter, joint, motor (0-based)
    if "armature" in names:
        k = names.index("armature")
        targets += [(k, j, j, j) for j in range(terms.n)]
    for c in couplings:
        for k, e in enumerate(effects):
            if e.name.startswith("coupled_pair") and e.param_names[0] == f"Iam{c.motor}":
                targets.append((k, 0, c.joint - 1, c.motor - 1))
    if not targets:
        return effects, ()
    samples = np.unique(np.linspace(2, len(terms.q_full) - 3, SAMPLES).astype(np.int64))
    links = link_regressor(terms, dyn, samples)
    # a coupled motor's inertia: each of its joints with the other's acceleration
    columns = np.column_stack([rotor_columns(terms, samples, j, m) if j == m else
                               rotor_columns(terms, samples, j, m)
                               + rotor_columns(terms, samples, m, j)
                               for _, _, j, m in targets])
    held = grouped(columns, links)
    out = list(effects)
    named = []
    for (k, i, _, _), g in zip(targets, held, strict=True):
        if g:
            out[k] = out[k].fix([i])
            named.append(out[k].param_names[i])
    if not named:
        return effects, ()
    note = (f"{', '.join(named)} cannot be identified from these data: the links' inertial "
            "parameters (the model file's masses, first moments and inertias) take the same "
            "torque at every row, so they are held at the model file's value (grouped with "
            "the link inertias, as in a base-parameter set)")
    return tuple(out), (note,)
