"""What each candidate effect of the arm-dynamics diagnosis (arm_dynamics_library.py) adds to
the two channels (link-side torque sensor, drive; see arm_dynamics_terms.py) at a set of rows,
for any arm.

Names match ``serpar.twins.arm_dynamics_twin.EFFECTS``. Each is an extension of the MuJoCo model,
evaluated with ``mj_rne`` and no hand-written dynamics:

* link inertia and payload are linear in standard inertial parameters, so their regressors
  are built once, at every sample and then windowed exactly like the channels (from the
  arm with all but one link massless, and from 10 reference payload bodies); the payload's
  inertia is fitted through its extent (sim/plants/arm_changes.py), so every fitted tensor
  is a rigid body's;
* the published sigmoid friction is evaluated from each window's full-rate velocity
  (arm_dynamics_sigmoid.py);
* friction, rotor inertia, a coupled motor's terms and sensor gain are linear regressors on
  the data and the nominal torque; the Stribeck fall's is tabulated on a grid of speeds and
  interpolated in log speed (arm_dynamics_stribeck.py), so each joint's speed is fitted too;
* a tilted base turns gravity (arm_dynamics_tilt.py: exact, MuJoCo's gravity torque per axis);
* latency shifts the windowed command (a cubic spline) by the delay;
* sensor timing shifts the link channel's model by the torque sensors' lag behind the
  encoders: the windowed nominal link torque read from a cubic spline through it, what a
  payload or link inertia error adds to first order;
* encoder offsets and scale errors are evaluated exactly per call, ``mj_rne`` at the true
  angles (and, for a scale, rates) of the rows asked for (a few hundred), so no linearisation
  error enters a fit.

Friction and the payload's extent are fitted under their physical bounds (>= 0). Mass, link
inertia, gain and delay errors may take either sign: a nominal model can carry too much as well
as too little, and an absent effect's estimate then scatters about zero with an honest
uncertainty instead of piling up on a bound.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_inertial import NAME as INERTIAL
from serpar.diagnosis.arm_dynamics_inertial import LinkInertial
from serpar.diagnosis.arm_dynamics_library import (
    EXTENT_START,
    STICK_VELOCITY,
    Channels,
    Coupling,
    arm_effects,
    tare,
)
from serpar.diagnosis.arm_dynamics_payload import (
    PayloadRegressor,
    link_rate,
    payload_inertial,
    standard_parameters,
)
from serpar.diagnosis.arm_dynamics_signals import windowed_spline
from serpar.diagnosis.arm_dynamics_sigmoid import NAME as SIGMOID
from serpar.diagnosis.arm_dynamics_sigmoid import SigmoidFriction
from serpar.diagnosis.arm_dynamics_stribeck import StribeckFall
from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.arm_dynamics_tilt import NAME as TILT
from serpar.diagnosis.arm_dynamics_tilt import BaseTilt
from serpar.diagnosis.family import Effect
from serpar.diagnosis.memo import Memo
from serpar.sim.rigid_arm import PANDA_ARM, ArmDynamics

Vec = NDArray[np.float64]

__all__ = ["ADDS_INERTIA", "BASELINE", "EFFECTS", "EXTENT_START", "STICK_VELOCITY", "EffectModels"]

ADDS_INERTIA = ("payload", "link_inertia")
"""Effects that add to the arm's inertia (and so to each row's acceleration noise)."""

BASELINE = tare(7)
"""Always fitted: a torque sensor's zero drifts between tares on every real arm (Panda:
~0.05 N m), so an offset alone is not missing physics. (The Panda's; any arm's:
``arm_dynamics_library.tare``.)"""

EFFECTS: tuple[Effect, ...] = arm_effects(7, Channels(link=True, drive="command"),
                                          (2, 3, 4, 5, 6), (1, 2, 3, 4, 5, 6),
                                          np.asarray(PANDA_ARM.n * [0.0]))
"""The Panda's candidates for a recording with torque sensors and the command (the joints
its encoder errors show in: those :func:`~arm_dynamics_library.visible_joints` finds on
its model)."""


class EffectModels:
    """Contributions of the candidate effects to (link, drive) at given rows, N m."""

    def __init__(self, terms: Terms, dynamics: ArmDynamics,
                 stick_velocity: float = STICK_VELOCITY, offset_joints: tuple[int, ...] = (),
                 scale_joints: tuple[int, ...] = (), couplings: tuple[Coupling, ...] = (),
                 inertial: LinkInertial | None = None) -> None:
        self.terms, self.dyn = terms, dynamics
        self.inertial = inertial
        self.n = terms.n
        rows = terms.rows
        v = terms.dq_full
        # friction: Coulomb sign where the joint surely moves, the viscous velocity, and the
        # window's weight of possibly stuck samples, all windowed like the command
        moving = np.abs(v) >= stick_velocity
        self.coulomb = rows.at(np.sign(v) * moving)
        self.viscous = rows.at(v)
        self.stuck = rows.at((~moving).astype(float))
        # the same, windowed like the link-side sensor channel (friction the sensor reads)
        self.coulomb_link = rows.link_at(np.sign(v) * moving)
        self.viscous_link = rows.link_at(v)
        self.stuck_link = rows.link_at((~moving).astype(float))
        self.stribeck = StribeckFall(rows, v, moving)
        self.sigmoid = SigmoidFriction(terms)
        self.tilt = BaseTilt(terms, dynamics)
        # rotor inertia: the windowed acceleration, as the nominal armature term enters
        self.acceleration = rows.at(terms.a_full)
        self.couplings = couplings
        # a coupled motor turns with both its joints: its Coulomb sign is that of their sum
        self.motor_sign, self.motor_stuck = {}, {}
        for c in couplings:
            speed = v[:, c.joint - 1] + v[:, c.motor - 1]
            turning = np.abs(speed) >= stick_velocity
            self.motor_sign[c] = rows.at(np.sign(speed) * turning)
            self.motor_stuck[c] = rows.at((~turning).astype(float))
        # rows x joint x link, for the link channel (sensor timing) and the drive channel
        self.inertia_link, self.inertia_drive = self._per_link()
        self.base_link = dynamics.link_torque(terms.q_link, terms.dq_link, terms.ddq_link)
        self.base_drive = dynamics.link_torque(terms.q, terms.dq, terms.ddq)
        payload = PayloadRegressor.of(terms, dynamics.arm)
        self.flange = np.asarray(dynamics.arm.flange_pos, float)
        self.payload_link, self.payload_drive = payload.link, payload.drive
        self.payload_mass, self.payload_link_rate = payload.mass, payload.link_rate
        # sensor timing: a link torque read `lag` late is the windowed nominal model's `lag`
        # earlier (a cubic spline through it at every sample, as the latency reads the command)
        full = dynamics.link_torque(terms.q_full, terms.dq_full, terms.a_full)
        self.link_spline = windowed_spline(terms.rows, full, link=True)
        self.link_now = self.link_spline(terms.rows.centre.astype(float))
        self._offset_cols = np.array(offset_joints, np.int64) - 1
        self._scale_cols = np.array(scale_joints, np.int64) - 1
        self._memo: Memo[tuple[Vec, Vec]] = Memo()

    def _per_link(self) -> tuple[Vec, Vec]:
        """Torque of each link's own inertia, windowed per row like the channels: scaling a
        link's mass, first moment and inertia together by s adds s times this (inverse
        dynamics is linear in them). Evaluated at every sample, as the nominal model is."""
        model, t = self.dyn.model, self.terms
        mass, inertia = model.body_mass.copy(), model.body_inertia.copy()
        link, drive, inert, rate = [], [], [], []
        try:
            for name in self.dyn.arm.link_bodies:
                b = model.body(name).id
                model.body_mass[:], model.body_inertia[:] = 0.0, 0.0
                model.body_mass[b], model.body_inertia[b] = mass[b], inertia[b]
                tau = self.dyn.link_torque(t.q_full, t.dq_full, t.a_full)
                link.append(t.rows.link_at(tau))
                drive.append(t.rows.at(tau))
                rate.append(link_rate(t, tau))
                inert.append(self.dyn.mass_link_and_full(t.q)[0])
        finally:
            model.body_mass[:], model.body_inertia[:] = mass, inertia
        self.link_mass = np.stack(inert, axis=3)  # rows x n x n x link
        self.inertia_link_rate = np.stack(rate, axis=2)
        return np.stack(link, axis=2), np.stack(drive, axis=2)

    def _payload(self, params: Mapping[str, Vec]) -> Vec:
        return standard_parameters(payload_inertial(params["payload"]), self.flange)

    def contributions(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                      ) -> tuple[Vec, Vec, Vec, Vec]:
        """(link, drive, link band, drive band): torques the active effects add to each
        channel, and the half-width of the interval each channel's residual may lie in
        unexplained (static friction while a joint may be stuck)."""
        t, n = self.terms, self.n
        link = np.zeros((len(rows), n))
        drive = np.zeros((len(rows), n))
        band = np.zeros((len(rows), n))
        link_band = np.zeros((len(rows), n))
        if "sensor_timing" in params:
            link += self._read_late(params, rows)
        if "joint_friction" in params:
            p = params["joint_friction"]
            drive += self.coulomb[rows] * p[:n] + self.viscous[rows] * p[n:]
            band += self.stuck[rows] * np.abs(p[:n])
        if "link_friction" in params:
            p = params["link_friction"]
            link += self.coulomb_link[rows] * p[:n] + self.viscous_link[rows] * p[n:]
            drive += self.coulomb[rows] * p[:n] + self.viscous[rows] * p[n:]
            link_band += self.stuck_link[rows] * np.abs(p[:n])
            band += self.stuck[rows] * np.abs(p[:n])
        if SIGMOID in params:  # smooth through zero speed: no stiction band
            drive += self.sigmoid.torque(params[SIGMOID], rows)
        if "stribeck_friction" in params:
            p = params["stribeck_friction"]
            drive += self.stribeck.regressor(p[n:], rows) * p[:n]
            band += self.stuck[rows] * np.abs(p[:n])
        if "armature" in params:
            drive += self.acceleration[rows] * params["armature"]
        for name, c in self._coupled(params):
            p, m, j = params[name], c.motor - 1, c.joint - 1
            # each joint's drive takes the motor's inertia and viscous friction in the other
            # joint's motion (its own are the joint's Ia, Fv), and its Coulomb friction
            for here, other in ((j, m), (m, j)):
                drive[:, here] += (p[0] * self.acceleration[rows, other]
                                   + p[1] * self.viscous[rows, other]
                                   + p[2] * self.motor_sign[c][rows])
                band[:, here] += self.motor_stuck[c][rows] * abs(p[2])
        if "link_inertia" in params:
            link += self.inertia_link[rows] @ params["link_inertia"]
            drive += self.inertia_drive[rows] @ params["link_inertia"]
        if INERTIAL in params and self.inertial is not None:
            d_link, d_drive = self.inertial.contribution(params[INERTIAL], rows)
            link += d_link
            drive += d_drive
        if TILT in params:
            d_link, d_drive = self.tilt.torque(params[TILT], rows)
            link += d_link
            drive += d_drive
        if "payload" in params:
            phi = self._payload(params)
            link += self.payload_link[rows] @ phi
            drive += self.payload_drive[rows] @ phi
        for name in ("encoder_offset", "encoder_scale"):
            if name in params:
                d_link, d_drive = self._encoder(name, params[name], rows)
                link += d_link
                drive += d_drive
        if "torque_sensor" in params:
            if t.has_link:
                link += t.tau_link_model[rows] * params["torque_sensor"]
            else:  # the drive torque's own gain (current x torque constant)
                drive += t.tau_full_model[rows] * params["torque_sensor"]
        if "latency" in params:
            shift = float(params["latency"][0]) * t.rate
            centre = t.rows.centre[rows].astype(float)
            # the drive delivered the command of `delay` ago: the model must explain that one
            drive -= t.command(centre - shift) - t.command(centre)
        return link, drive, link_band, band

    def _encoder(self, name: str, values: Vec, rows: NDArray[np.int64]) -> tuple[Vec, Vec]:
        """(link, drive) torque change of an encoder offset or scale, exact (``mj_rne`` at the
        true states), for the channels the recording has; the last few are kept, since a
        difference Jacobian asks for them again with other effects' parameters moved."""
        kind = {"offset": values} if name == "encoder_offset" else {"scale": values}
        zeros = np.zeros((len(rows), self.n))
        t = self.terms
        return self._memo(lambda: (
            self._true_state_torque(rows, True, **kind) if t.has_link else zeros,
            self._true_state_torque(rows, False, **kind) if t.has_command else zeros),
            name, values, rows)

    def _coupled(self, params: Mapping[str, Vec]) -> list[tuple[str, Coupling]]:
        if len(self.couplings) == 1:
            return [("coupled_pair", self.couplings[0])] if "coupled_pair" in params else []
        return [(f"coupled_pair{c.joint}{c.motor}", c) for c in self.couplings
                if f"coupled_pair{c.joint}{c.motor}" in params]

    def added_inertia(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec | None:
        """rows x n x n: the inertia the active effects add to the nominal model (None: none)."""
        added = None
        if "payload" in params:
            added = self.payload_mass[rows] @ self._payload(params)
        if "link_inertia" in params:
            d = self.link_mass[rows] @ params["link_inertia"]
            added = d if added is None else added + d
        return added

    def _state(self, rows: NDArray[np.int64], sensor: bool) -> tuple[Vec, Vec, Vec]:
        t = self.terms
        if sensor:
            return t.q_link[rows], t.dq_link[rows], t.ddq_link[rows]
        return t.q[rows], t.dq[rows], t.ddq[rows]

    def _read_late(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        """What the link channel's model changes by when the sensors read ``lag`` late: the
        nominal model's windowed torque ``lag`` earlier minus now (exact but for the spline: at
        1.6 ms a first-order shift leaves lag^2/2 x its second derivative, ~2 sigma on the most
        loaded joints of a 12-hole cell), and lag x the rate of what a payload or a link
        inertia error adds (a lag read against the nominal torque alone takes the extra
        torque's rate for more lag: +2 % with 0.125 kg on the hand; its second order is
        negligible beside the nominal's)."""
        lag = float(params["sensor_timing"][0])
        centre = self.terms.rows.centre[rows].astype(float)
        late = self.link_spline(centre - lag * self.terms.rate) - self.link_now[rows]
        if "payload" in params:
            late -= lag * (self.payload_link_rate[rows] @ self._payload(params))
        if "link_inertia" in params:
            late -= lag * (self.inertia_link_rate[rows] @ params["link_inertia"])
        return late

    def misread_sensitivity(self, joint: int, sensor: bool, proportional: bool,
                            step: float = 1e-5) -> Vec:
        """Every row x n: the model torque's change per unit misreading of ``joint`` (0-based),
        at zero: a relative scale s (angle, rate and acceleration read x (1 + s)) or, not
        ``proportional``, an offset [rad] (the angle alone). The model evaluated at the true
        state, the reading undone, minus at the reading, over the step."""
        q, dq, ddq = (x.copy() for x in self._state(np.arange(len(self.terms.q)), sensor))
        if proportional:
            for x in (q, dq, ddq):
                x[:, joint] *= 1.0 - step  # / (1 + step), to first order
        else:
            q[:, joint] -= step
        base = self.base_link if sensor else self.base_drive
        return (self.dyn.link_torque(q, dq, ddq) - base) / step

    def _true_state_torque(self, rows: NDArray[np.int64], sensor: bool, offset: Vec | None = None,
                           scale: Vec | None = None) -> Vec:
        """What the model's torque changes by at the true joint state: the angle measured minus
        an offset, or angle, rate and acceleration measured / (1 + s), on the joints whose
        errors the dynamics can see (arm_dynamics_library.visible_joints)."""
        q, dq, ddq = (x.copy() for x in self._state(rows, sensor))
        if offset is not None:
            q[:, self._offset_cols] -= offset
        if scale is not None:
            for x in (q, dq, ddq):
                x[:, self._scale_cols] /= 1.0 + scale
        base = self.base_link if sensor else self.base_drive
        return self.dyn.link_torque(q, dq, ddq) - base[rows]
