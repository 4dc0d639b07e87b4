"""The candidate effects of the arm-dynamics diagnosis: what each adds to the two channels
(link-side torque sensor, drive command; see arm_dynamics_terms.py) at a set of rows.

Names match ``serpar.twins.arm_dynamics_twin.EFFECTS``. Each is an extension of the MuJoCo model,
evaluated with ``mj_rne`` and no hand-written dynamics:

* link inertia and payload are linear in standard inertial parameters, so their regressors
  are built once, at every sample and then windowed exactly like the channels (from the
  arm with all but one link massless, and from 10 reference payload bodies); the payload's
  inertia is fitted through its extent (sim/plants/arm_changes.py), so every fitted tensor
  is a rigid body's;
* friction and sensor gain are linear regressors on the data and the nominal torque; the
  Stribeck fall's regressor is tabulated on a grid of Stribeck speeds and interpolated in
  log speed, so its one non-linear parameter is fitted too;
* latency shifts the windowed command (a cubic spline) by the delay;
* sensor timing shifts the link channel's model by the torque sensors' lag behind the
  encoders, to first order (minus lag x the windowed rate of the nominal link torque);
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

from serpar.diagnosis.arm_dynamics_payload import (
    PayloadRegressor,
    link_rate,
    payload_inertial,
    standard_parameters,
)
from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.family import Effect
from serpar.sim.plants.arm_changes import EXTENT
from serpar.sim.rigid_arm import (
    LINK_BODIES,
    ArmDynamics,
)

Vec = NDArray[np.float64]
J = range(1, 8)

OFFSET_JOINTS = (2, 3, 4, 5, 6)
"""Joints whose encoder offset the dynamics can see: gravity is along joint 1's axis (its
offset changes no torque), and joint 7 turns only the near-axial hand."""

SCALE_JOINTS = (1, 2, 3, 4, 5, 6)
"""Joints whose encoder scale the dynamics can see: joint 1's through the inertia its rates
drive (gravity is along its axis), not joint 7's (it turns only the near-axial hand)."""
SCALE_BOUND = 0.05
"""Largest relative encoder scale error: a wrong gear ratio or resolution setting."""


COMMAND_ONLY = ("joint_friction", "stribeck_friction", "latency")
"""Effects only the drive channel shows (friction inside the drive, before the torque sensor;
a delayed command): without a commanded torque in the recording they are not candidates."""
PAYLOAD_PARAMS = ("mass", "com_x", "com_y", "com_z") + EXTENT
EXTENT_DIAGONAL = np.array([n[1] == n[2] for n in EXTENT])
EXTENT_START = np.where(EXTENT_DIAGONAL, 0.03, 0.0)
"""[m] A small body's extent: the search starts off L = 0, where the inertia's slope is 0."""
"""Link-7 (flange) axes; CoM from the flange origin; inertia tensor about the CoM. The
x0 mass is not zero: at zero mass the CoM has no gradient to start from."""
STICK_VELOCITY = 0.01
"""[rad/s] Below this a joint with dry friction may be stuck, and its Coulomb force is then
anywhere in [-Fc, Fc] (whatever balances the drive): rows weigh such samples as an interval,
not a value. Above it the twin's MuJoCo frictionloss is >= 99 % of Fc, and the encoder
velocity (central difference, noise ~1e-3 rad/s) has a certain sign. The default of
``ArmDynamicsConfig.stick_velocity``; a recording whose joints creep under force control sets
its own (diagnosis/episode_family.py)."""
STRIBECK_SPEEDS = np.geomspace(STICK_VELOCITY, 0.4, 20)
"""[rad/s] Grid of the Stribeck regressor; the search range of the Stribeck speed (a fall
below the speed at which a joint may be stuck could not be seen)."""
LOG_STRIBECK_SPEEDS = np.log(STRIBECK_SPEEDS)


BASELINE = Effect(
    "torque_tare", "torque sensor offsets (tares)", tuple(f"tare{j}" for j in J), ("N m",) * 7,
    np.zeros(7), np.full(7, -20.0), np.full(7, 20.0))
"""Always fitted: a torque sensor's zero drifts between tares on every real arm (Panda:
~0.05 N m), so an offset alone is not missing physics."""

EFFECTS: tuple[Effect, ...] = (
    Effect("joint_friction", "joint friction (Coulomb + viscous, inside the drive)",
           tuple(f"Fc{j}" for j in J) + tuple(f"Fv{j}" for j in J),
           ("N m",) * 7 + ("N m s/rad",) * 7, np.zeros(14),
           np.zeros(14), np.r_[np.full(7, 10.0), np.full(7, 5.0)], physical_lower=True),
    Effect("link_friction", "joint friction on the link side of the torque sensors (Coulomb + "
           "viscous; bearings, seals: in the measured torque as in the command)",
           tuple(f"Fc{j}" for j in J) + tuple(f"Fv{j}" for j in J),
           ("N m",) * 7 + ("N m s/rad",) * 7, np.zeros(14),
           np.zeros(14), np.r_[np.full(7, 10.0), np.full(7, 5.0)], physical_lower=True),
    Effect("stribeck_friction", "Stribeck friction (static friction above the Coulomb level, "
           "falling off with speed: dFs exp(-(v/vs)^2), dFs = Fs - Fc)",
           tuple(f"dFs{j}" for j in J) + ("vs",), ("N m",) * 7 + ("rad/s",),
           np.r_[np.zeros(7), 0.05], np.r_[np.zeros(7), STRIBECK_SPEEDS[0]],
           np.r_[np.full(7, 10.0), STRIBECK_SPEEDS[-1]],
           physical_lower=(True,) * 7 + (False,)),
    Effect("payload", "unmodelled payload at the flange (mass, centre of mass, extent: the "
           "Cholesky factor of its second moment of mass, so its inertia is physical)",
           PAYLOAD_PARAMS, ("kg", "m", "m", "m") + ("m",) * 6,
           np.r_[0.1, 0.0, 0.0, 0.05, EXTENT_START],
           np.r_[-3.0, -0.3, -0.3, -0.3, np.where(EXTENT_DIAGONAL, 0.0, -0.3)],
           np.r_[5.0, 0.3, 0.3, 0.5, np.full(6, 0.3)],
           physical_lower=(False,) * 4 + tuple(bool(d) for d in EXTENT_DIAGONAL),
           excess_words="the nominal model carries {value} at the flange that the arm does not have"),
    Effect("link_inertia", "link mass/inertia error (relative, per link)",
           tuple(f"link{j}" for j in J), ("1",) * 7, np.zeros(7), np.full(7, -0.9), np.full(7, 2.0)),
    Effect("torque_sensor", "torque sensor gain error (relative, per joint)",
           tuple(f"gain{j}" for j in J), ("1",) * 7, np.zeros(7), np.full(7, -0.5), np.full(7, 0.5)),
    # a command cannot act before it is sent: 0 is a physical limit, and a fit that would go
    # below it says "no latency here", not an admissible finding
    Effect("latency", "actuation latency (command reaches the joint late)", ("delay",), ("s",),
           np.zeros(1), np.zeros(1), np.array([0.03]), physical_lower=True),
    Effect("sensor_timing", "torque sensors sampled out of step with the encoders (lag)",
           ("lag",), ("s",), np.zeros(1), np.array([-0.005]), np.array([0.005])),
    Effect("encoder_offset", "joint encoder offsets (measured minus true angle)",
           tuple(f"offset{j}" for j in OFFSET_JOINTS), ("rad",) * len(OFFSET_JOINTS),
           np.zeros(len(OFFSET_JOINTS)), np.full(len(OFFSET_JOINTS), -0.2),
           np.full(len(OFFSET_JOINTS), 0.2)),
    Effect("encoder_scale", "joint encoder scale errors (measured = true angle x (1 + s))",
           tuple(f"scale{j}" for j in SCALE_JOINTS), ("1",) * len(SCALE_JOINTS),
           np.zeros(len(SCALE_JOINTS)), np.full(len(SCALE_JOINTS), -SCALE_BOUND),
           np.full(len(SCALE_JOINTS), SCALE_BOUND)),
)


class EffectModels:
    """Contributions of the candidate effects to (link, drive) at given rows, N m."""

    def __init__(self, terms: Terms, dynamics: ArmDynamics,
                 stick_velocity: float = STICK_VELOCITY) -> None:
        self.terms, self.dyn = terms, dynamics
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
        signed = np.sign(v) * moving
        self.stribeck = np.stack([rows.at(signed * np.exp(-(v / vs) ** 2))
                                  for vs in STRIBECK_SPEEDS])  # speeds x rows x 7
        # rows x joint x link, for the link channel (sensor timing) and the drive channel
        self.inertia_link, self.inertia_drive = self._per_link()
        self.base_link = dynamics.link_torque(terms.q_link, terms.dq_link, terms.ddq_link)
        self.base_drive = dynamics.link_torque(terms.q, terms.dq, terms.ddq)
        payload = PayloadRegressor.of(terms)
        self.payload_link, self.payload_drive = payload.link, payload.drive
        self.payload_mass, self.payload_link_rate = payload.mass, payload.link_rate
        # sensor timing: a link torque read `lag` late is the model's, minus lag x its rate
        full = dynamics.link_torque(terms.q_full, terms.dq_full, terms.a_full)
        self.link_rate = link_rate(terms, full)
        self._offset_cols = np.array(OFFSET_JOINTS) - 1
        self._scale_cols = np.array(SCALE_JOINTS) - 1

    def _per_link(self) -> tuple[Vec, Vec]:
        """Torque of each link's own inertia, windowed per row like the channels: scaling a
        link's mass, first moment and inertia together by s adds s times this (inverse
        dynamics is linear in them). Evaluated at every sample, as the nominal model is."""
        model, t = self.dyn.model, self.terms
        mass, inertia = model.body_mass.copy(), model.body_inertia.copy()
        link, drive, inert, rate = [], [], [], []
        try:
            for name in LINK_BODIES:
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
        self.link_mass = np.stack(inert, axis=3)  # rows x 7 x 7 x link
        self.inertia_link_rate = np.stack(rate, axis=2)
        return np.stack(link, axis=2), np.stack(drive, axis=2)

    def contributions(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                      ) -> tuple[Vec, Vec, Vec, Vec]:
        """(link, drive, link band, drive band): torques the active effects add to each
        channel, and the half-width of the interval each channel's residual may lie in
        unexplained (static friction while a joint may be stuck)."""
        t = self.terms
        link = np.zeros((len(rows), 7))
        drive = np.zeros((len(rows), 7))
        band = np.zeros((len(rows), 7))
        link_band = np.zeros((len(rows), 7))
        if "sensor_timing" in params:
            link -= self._link_rate(params, rows) * params["sensor_timing"][0]
        if "joint_friction" in params:
            p = params["joint_friction"]
            drive += self.coulomb[rows] * p[:7] + self.viscous[rows] * p[7:]
            band += self.stuck[rows] * np.abs(p[:7])
        if "link_friction" in params:
            p = params["link_friction"]
            link += self.coulomb_link[rows] * p[:7] + self.viscous_link[rows] * p[7:]
            drive += self.coulomb[rows] * p[:7] + self.viscous[rows] * p[7:]
            link_band += self.stuck_link[rows] * np.abs(p[:7])
            band += self.stuck[rows] * np.abs(p[:7])
        if "stribeck_friction" in params:
            p = params["stribeck_friction"]
            drive += self._stribeck(float(p[7]), rows) * p[:7]
            band += self.stuck[rows] * np.abs(p[:7])
        if "link_inertia" in params:
            link += self.inertia_link[rows] @ params["link_inertia"]
            drive += self.inertia_drive[rows] @ params["link_inertia"]
        if "payload" in params:
            phi = standard_parameters(payload_inertial(params["payload"]))
            link += self.payload_link[rows] @ phi
            drive += self.payload_drive[rows] @ phi
        if "encoder_offset" in params:
            o = params["encoder_offset"]
            link += self._true_state_torque(rows, True, offset=o)
            drive += self._true_state_torque(rows, False, offset=o)
        if "encoder_scale" in params:
            s = params["encoder_scale"]
            link += self._true_state_torque(rows, True, scale=s)
            drive += self._true_state_torque(rows, False, scale=s)
        if "torque_sensor" in params:
            link += t.tau_link_model[rows] * params["torque_sensor"]
        if "latency" in params:
            shift = float(params["latency"][0]) * t.rate
            centre = t.rows.centre[rows].astype(float)
            # the drive delivered the command of `delay` ago: the model must explain that one
            drive -= t.command(centre - shift) - t.command(centre)
        return link, drive, link_band, band

    def added_inertia(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec | None:
        """rows x 7 x 7: the inertia the active effects add to the nominal model (None: none)."""
        added = None
        if "payload" in params:
            added = self.payload_mass[rows] @ standard_parameters(payload_inertial(params["payload"]))
        if "link_inertia" in params:
            d = self.link_mass[rows] @ params["link_inertia"]
            added = d if added is None else added + d
        return added

    def _state(self, rows: NDArray[np.int64], sensor: bool) -> tuple[Vec, Vec, Vec]:
        t = self.terms
        if sensor:
            return t.q_link[rows], t.dq_link[rows], t.ddq_link[rows]
        return t.q[rows], t.dq[rows], t.ddq[rows]

    def _link_rate(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        """The rate of the link torque the sensors read late: the nominal model's and what a
        payload or a link inertia error adds to it (a lag read against the nominal rate alone
        takes the extra torque's rate for more lag: +2 % with 0.125 kg on the hand)."""
        rate = self.link_rate[rows]
        if "payload" in params:
            rate = rate + self.payload_link_rate[rows] @ standard_parameters(
                payload_inertial(params["payload"]))
        if "link_inertia" in params:
            rate = rate + self.inertia_link_rate[rows] @ params["link_inertia"]
        return rate

    def _true_state_torque(self, rows: NDArray[np.int64], sensor: bool, offset: Vec | None = None,
                           scale: Vec | None = None) -> Vec:
        """What the model's torque changes by at the true joint state: the angle measured minus
        an offset (joints OFFSET_JOINTS), or angle, rate and acceleration measured / (1 + s)
        (joints SCALE_JOINTS)."""
        q, dq, ddq = (x.copy() for x in self._state(rows, sensor))
        if offset is not None:
            q[:, self._offset_cols] -= offset
        if scale is not None:
            for x in (q, dq, ddq):
                x[:, self._scale_cols] /= 1.0 + scale
        base = self.base_link if sensor else self.base_drive
        return self.dyn.link_torque(q, dq, ddq) - base[rows]

    def _stribeck(self, speed: float, rows: NDArray[np.int64]) -> Vec:
        """The Stribeck regressor at ``speed``, interpolated in log speed on the grid."""
        x = np.log(np.clip(speed, STRIBECK_SPEEDS[0], STRIBECK_SPEEDS[-1]))
        grid = LOG_STRIBECK_SPEEDS
        k = int(np.clip(np.searchsorted(grid, x) - 1, 0, len(grid) - 2))
        w = (x - grid[k]) / (grid[k + 1] - grid[k])
        return (1.0 - w) * self.stribeck[k][rows] + w * self.stribeck[k + 1][rows]
