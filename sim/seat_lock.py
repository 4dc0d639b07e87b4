"""Seated parts ride on the plate as one rigid piece once their hole has been scored.

A journal seated in its H7/h6 bore, shoulder on the plate top, is held by the fit and by
gravity; nothing in the cell pushes it again. Simulated with its contacts, though, each seated
part costs ~0.3 ms per step (journal against 16 bore facets, shoulder on the seat box) every
time the platform moves and wakes it, so the late holes of a 36-hole episode cost 3-5x the
first. After a hole is scored *success* (the insertion itself is fully physical), the part is
welded to the plate where it physically ended up, and only its contacts with the plate are
switched off: the gripper, a held part or a neighbour still collide with it (they meet a
rigidly held part instead of one that could wiggle inside 0-16 um of clearance).

Every conductor has an inactive weld ``seat_lock<k>`` to the baseplate, built with the scene;
:func:`lock_seated` sets its relative pose to the current one and activates it, and
:func:`is_locked` says which are active.
"""

from __future__ import annotations

import mujoco
import numpy as np

from sim import collision, names
from sim.errors import SimError

PLATE_BODY = names.PLATE + "baseplate"
WELD_SOLREF = (0.0005, 1.0)
"""Stiff: 0.5 ms (5 physics steps), critically damped."""
WELD_SOLIMP = (0.99, 0.99, 0.001, 0.5, 2.0)
"""Impedance 0.99: a soft constraint yields (1 - d)/d of its load. With these, a locked part
sags 0.025 um under its weight and moves 0.12 um against the plate during an abrupt 3 mm
platform lift (tests/test_seat_lock; 0.39 / 1.5 um at 2 ms)."""


def lock_name(k: int) -> str:
    return f"seat_lock{k}"


def add_seat_locks(spec: mujoco.MjSpec, n_conductors: int) -> None:
    """One inactive weld per conductor to the baseplate (the relative pose is set on locking)."""
    for k in range(n_conductors):
        spec.add_equality(name=lock_name(k), type=mujoco.mjtEq.mjEQ_WELD,
                          objtype=mujoco.mjtObj.mjOBJ_BODY,
                          name1=PLATE_BODY, name2=f"{names.conductor(k)}conductor",
                          active=False, solref=list(WELD_SOLREF), solimp=list(WELD_SOLIMP))


def _weld_id(model: mujoco.MjModel, k: int) -> int:
    eq = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, lock_name(k))
    if eq < 0:
        raise SimError(f"the scene has no {lock_name(k)}: conductor {k} out of range "
                       f"(the scene has {model.neq} equality constraints)")
    return eq


def lock_seated(model: mujoco.MjModel, data: mujoco.MjData, k: int) -> None:
    """Weld conductor k to the plate at its current relative pose; stop its plate contacts.

    Changes ``model`` (the weld's relative pose and the part's collision bits) and ``data``
    (eq_active): a model shared between episodes must not be locked."""
    eq = _weld_id(model, k)
    b1, b2 = int(model.eq_obj1id[eq]), int(model.eq_obj2id[eq])
    mujoco.mj_kinematics(model, data)
    # MuJoCo's weld holds  x1 + R1 relpos = x2 + R2 anchor  and the orientation of body 2
    # relative to body 1 at relquat = q1^-1 q2 (checked: zero residual rows on locking):
    # anchor 0 on body 2 (the part: the weld acts at the part, not at the plate's centre up to
    # 35 mm away, where the part's weight would be a lever), relpos and relquat from now.
    rot1 = data.xmat[b1].reshape(3, 3)
    relpos = rot1.T @ (data.xpos[b2] - data.xpos[b1])
    relquat = np.zeros(4)
    inv1 = np.zeros(4)
    mujoco.mju_negQuat(inv1, data.xquat[b1])
    mujoco.mju_mulQuat(relquat, inv1, data.xquat[b2])
    model.eq_data[eq, 0:3] = 0.0
    model.eq_data[eq, 3:6] = relpos
    model.eq_data[eq, 6:10] = relquat
    model.eq_data[eq, 10] = 1.0  # torquescale
    for g in range(int(model.body_geomadr[b2]), int(model.body_geomadr[b2] + model.body_geomnum[b2])):
        model.geom_contype[g], model.geom_conaffinity[g] = collision.SEATED_LOCKED
    # The body-level bits too (compiled as the OR over the body's geoms): MuJoCo's broad phase
    # then drops the part/plate pair before walking the plate's 600-geom tree for it, which
    # cost ~20 us per locked part per step while the platform was awake.
    model.body_contype[b2], model.body_conaffinity[b2] = collision.SEATED_LOCKED
    data.eq_active[eq] = 1


def is_locked(model: mujoco.MjModel, data: mujoco.MjData, k: int) -> bool:
    return bool(data.eq_active[_weld_id(model, k)])
