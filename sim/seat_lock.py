"""Seated parts become part of the plate once their hole has been scored.

A journal seated in its H7/h6 bore, shoulder on the plate top, is held by the fit and by
gravity; nothing in the cell pushes it again. Simulated as a free body, though, each seated
part rides in the Stewart platform's island: with its contacts it costs ~0.3 ms per step, and
welded to the plate (an equality constraint) still 12 us per step per part, mostly in
MuJoCo's no-slip pass, which works on every constraint row of the awake
island: with 36 welded parts a control period cost 5.4 ms against 1.1 ms for the bare
platform moving (measured, 5 mm platform ramp).

So after a hole is scored *success* (the insertion itself is fully physical), the part's body
is moved in the scene's MjSpec from the world to the plate, at the pose it physically ended
up in, without its free joint, and the scene is recompiled (MjSpec.recompile carries the state
of every other joint over; ~50 ms with the id check). The part then costs what a plate geom costs. Bodies
welded to one another never collide in MuJoCo, so the part stops touching the plate and its
seated neighbours; the hand and parts still in the tray or in the hand meet it as before.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import numpy as np

from serpar.errors import SerparError
from serpar.sim import names

if TYPE_CHECKING:
    from serpar.sim.scene import Scene

PLATE_BODY = names.PLATE + "baseplate"
_COPY = "_seated"
"""Suffix of the copy while the original still exists (MjSpec attaches copies, not moves)."""
_REFERRING = ("sensors", "equalities", "excludes", "pairs", "tendons", "actuators")
_NAME_FIELDS = ("name", "objname", "refname", "name1", "name2", "bodyname1", "bodyname2", "geomname1",
                "geomname2", "target")
"""The name, and the fields in which an element names another."""


def _pose_in_plate(model: mujoco.MjModel, data: mujoco.MjData, body: int) -> tuple[np.ndarray, np.ndarray]:
    plate = model.body(PLATE_BODY).id
    mujoco.mj_kinematics(model, data)
    rot = data.xmat[plate].reshape(3, 3)
    pos = rot.T @ (data.xpos[body] - data.xpos[plate])
    inv, quat = np.zeros(4), np.zeros(4)
    mujoco.mju_negQuat(inv, data.xquat[plate])
    mujoco.mju_mulQuat(quat, inv, data.xquat[body])
    return pos, quat


def lock_seated(scene: Scene, k: int) -> None:
    """Make conductor k a rigid part of the plate where it is now; recompiles `scene` (its model
    and data are new objects afterwards: see :meth:`serpar.sim.scene.Scene.recompile`)."""
    if not 0 <= k < scene.config.n_conductors:
        raise SerparError(f"conductor {k} out of range: the scene has conductors 0..{scene.config.n_conductors - 1}")
    if is_locked(scene, k):
        raise SerparError(f"conductor {k} is already locked in the plate")
    spec, m, d = scene.spec, scene.model, scene.data
    pos, quat = _pose_in_plate(m, d, m.body(names.conductor_body(k)).id)
    original = spec.body(names.conductor_body(k))
    spec.copy_during_attach = True
    frame = spec.body(PLATE_BODY).add_frame(pos=pos.tolist(), quat=quat.tolist())
    copy = frame.attach_body(original, "", _COPY)
    spec.delete(original)
    for joint in list(copy.joints):  # the free joint
        spec.delete(joint)
    # Deleting the original deleted what referred to it (the plate contact sensor); the attach
    # had copied those too, referring to the copy: they take the originals' names back.
    referring = [e for kind in _REFERRING for e in getattr(spec, kind) if e.name.endswith(_COPY)]
    for element in (copy, *copy.geoms, *copy.sites, *referring):
        for field in _NAME_FIELDS:
            value = getattr(element, field, None)
            if isinstance(value, str) and value.endswith(_COPY):
                setattr(element, field, value.removesuffix(_COPY))
    scene.recompile()


def is_locked(scene: Scene, k: int) -> bool:
    """Whether conductor k is part of the plate."""
    m = scene.model
    return m.body(int(m.body(names.conductor_body(k)).parentid[0])).name == PLATE_BODY
