"""Contact force sums between groups of geoms (for scoring and checks, not for control)."""

from __future__ import annotations

from collections.abc import Collection

import mujoco
import numpy as np

from serpar.sim.physics import PhysicsConfig


class ContactForceProbe:
    """Total contact force that one group of geoms exerts on another, fast enough to read
    after every physics substep: the groups are boolean masks over the model's geoms, so the
    contacts are filtered in one vectorised pass and only the matches are resolved."""

    def __init__(self, model: mujoco.MjModel, geoms: Collection[int],
                 others: Collection[int] | None = None) -> None:
        self.model = model
        self.on = np.zeros(model.ngeom, bool)
        self.on[list(geoms)] = True
        self.by = np.ones(model.ngeom, bool)
        if others is not None:
            self.by[:] = False
            self.by[list(others)] = True
        self._f6 = np.zeros(6)

    def force(self, data: mujoco.MjData) -> np.ndarray:
        """[N, world frame] on `geoms` from `others` (default: anything)."""
        total = np.zeros(3)
        if data.ncon == 0:
            return total
        con = data.contact
        g1, g2 = con.geom1, con.geom2
        on2 = self.on[g2] & self.by[g1]  # the contact force acts on geom2 along the frame normal
        idx = np.flatnonzero(on2 | (self.on[g1] & self.by[g2]))
        adr = con.efc_address[idx]
        idx, adr = idx[adr >= 0], adr[adr >= 0]  # excluded contacts carry no force
        if not len(idx):
            return total
        if self.model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC:  # efc_force is in the contact frame
            k = np.arange(3)
            dim = con.dim[idx][:, None]  # a frictionless (condim 1) contact has the normal row only
            f = np.where(k < dim, data.efc_force[adr[:, None] + np.minimum(k, dim - 1)], 0.0)
        else:
            f = np.empty((len(idx), 3))
            for k, i in enumerate(idx):
                mujoco.mj_contactForce(self.model, data, int(i), self._f6)
                f[k] = self._f6[:3]
        sign = np.where(on2[idx], 1.0, -1.0)
        return np.einsum("n,nk,nkj->j", sign, f, con.frame[idx].reshape(-1, 3, 3))


def contact_force_on(model: mujoco.MjModel, data: mujoco.MjData, geoms: Collection[int],
                     others: Collection[int] | None = None) -> np.ndarray:
    """Total contact force [N, world frame] that `others` (default: anything) exert on `geoms`
    (one-off reads; build a :class:`ContactForceProbe` to read it repeatedly)."""
    return ContactForceProbe(model, geoms, others).force(data)


CONTACT_REDUCE_NETFORCE = 3
"""Contact sensor `reduce` code for "netforce" (MuJoCo's mjtConReduce has no Python enum)."""


PLATE_CONTACT = "plate_contact"
"""Name of the sensor of the contact force between the conductor being scored and the plate."""


def add_plate_contact_sensor(spec: mujoco.MjSpec, part_body: str, plate_body: str) -> None:
    """A MuJoCo contact sensor: the net contact force [N] between one part and the baseplate
    body, summed by MuJoCo in C at every step (cheap enough to read after every substep, which
    the insertion's scoring does). :func:`aim_plate_contact` points it at another part."""
    force = int(mujoco.mjtConDataField.mjCONDATA_FORCE)
    spec.add_sensor(name=PLATE_CONTACT, type=mujoco.mjtSensor.mjSENS_CONTACT,
                    objtype=mujoco.mjtObj.mjOBJ_BODY, objname=part_body,
                    reftype=mujoco.mjtObj.mjOBJ_BODY, refname=plate_body,
                    intprm=[1 << force, CONTACT_REDUCE_NETFORCE, 1])


def aim_plate_contact(model: mujoco.MjModel, part_body: int) -> slice:
    """Point the plate contact sensor at body `part_body` (one sensor, not one per part: 36
    contact sensors cost 2-5 us per step, as much as the scoring saves); returns where its
    force [N, 3 values] sits in data.sensordata."""
    sensor = model.sensor(PLATE_CONTACT)
    model.sensor_objid[sensor.id] = part_body
    return slice(int(sensor.adr[0]), int(sensor.adr[0]) + 3)


def add_pad_pairs(spec: mujoco.MjSpec, pads: Collection[str], part_geom: str, physics: PhysicsConfig) -> None:
    """Explicit contact pairs between the gripper pads and one part's gripped geom (a
    conductor's body), so that their friction rows get their own damping
    (``physics.grip_solreffriction``; MuJoCo sets solreffriction on explicit pairs only). The
    pads' contype (``serpar.sim.arm.PAD_CONTYPE``) keeps MuJoCo from also making the same
    contacts from the collision bits. Normal direction, friction and condim are the pad's:
    what the pad's priority gave these contacts before."""
    for pad_name in pads:
        pad = spec.geom(pad_name)
        mu, spin, roll = pad.friction
        spec.add_pair(name=f"{pad_name}|{part_geom}", geomname1=pad_name, geomname2=part_geom,
                      condim=pad.condim, friction=[mu, mu, spin, roll, roll],
                      solref=list(physics.grip_solref), solimp=list(pad.solimp),
                      solreffriction=list(physics.grip_solreffriction))


def body_geoms(model: mujoco.MjModel, body_id: int) -> set[int]:
    """Geom ids of one body."""
    start = model.body_geomadr[body_id]
    return set(range(start, start + model.body_geomnum[body_id]))
