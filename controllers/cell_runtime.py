"""The cell running under its controllers: one object that owns the 1 kHz loop.

Each control period it updates the arm controller and the gripper servo, advances the
physics by the substeps, checks that the integration is healthy and calls the observers
(recording, progress). Stewart leg commands are written by the task and held by the leg
servos in MuJoCo itself. Motion primitives (`serpar.tasks.motions`) drive it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from serpar.controllers.arm_controller import ArmController, ArmControllerConfig
from serpar.controllers.arm_sensors import TorqueADC
from serpar.controllers.gripper_servo import GripperServo
from serpar.controllers.stewart_servo import StewartServo
from serpar.errors import ConfigError, UnstableSimulation
from serpar.sim import names
from serpar.sim.collision_gate import CollisionGate
from serpar.sim.plants.drive_friction import DriveFriction
from serpar.sim.scene import Scene
from serpar.sim.stewart import MAX_JOINT_ERROR
from serpar.sim.transit_step import TransitStep

MAX_SPEED = 10.0
"""Any point faster than this [m/s] means the integration blew up: each dof's speed times
MuJoCo's ``dof_length`` (1 for a slide, the body's size for a hinge or a rotation), so a
turn is judged by how fast the body's extent moves. Nothing in the cell moves faster than
~1 m/s. A part tilted against its pocket's wall and squeezed straight by the pads spins at up
to ~170 rad/s (the pads' 2.5e-4 J of compression at 20 N in a 1.7 g part of inertia 1.7e-8
kg m^2): 1.3 m/s at its 7.5 mm, a snap, not a blow-up (at the old 100 rad/s per dof it was
filed as one)."""
GATE_EVERY = 5
"""Control periods between two decisions of the collision gate (sim/collision_gate.py): one
decision costs ~55 us of numpy, and its margin grows with what moved since the last one."""
STEP_TIMER = int(mujoco.mjtTimer.mjTIMER_STEP)
GATED_BODIES = (names.PLATE + "baseplate", names.TRAY + "tray")


Observer = Callable[["CellRuntime"], None]


@dataclass
class CellRuntime:
    """A compiled cell, its arm controller, gripper and Stewart command interface."""

    scene: Scene
    arm: ArmController
    gripper: GripperServo
    stewart: StewartServo
    """Commands legs through the platform's *model* (nominal or calibrated geometry)."""
    time: float = 0.0
    phase: str = "start"
    """What the task is doing (annotations in recordings)."""
    observers: list[Observer] = field(default_factory=list)
    substep_probe: Callable[[], None] | None = None
    """Called after every physics substep when set (e.g. to average a contact force over the
    control period the way a 1 kHz sensor integrates it); None keeps the fast path."""
    load_mass: float = 0.0
    load_com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    """The load the task says the hand carries (libfranka's setLoad: mass [kg], centre of mass
    in the flange frame [m]); recorded as m_load / F_x_Cload, so a diagnosis's nominal model
    carries it too. The controllers' model leaves it out (grams, at these parts)."""
    gate: CollisionGate | None = None
    """Keeps the plate and the tray out of collision detection while nothing can reach them
    (no change to any contact; None: always in)."""
    transit: TransitStep | None = None
    """The transit step while the gate has everything out (sim/transit_step.py); None: the fine
    step throughout."""
    drive: DriveFriction | None = None
    """Drive friction MuJoCo has no element for (the published Panda form), set before every
    substep; None: the arm's friction is its joints' own (``frictionloss``)."""
    physics_wall_s: float = 0.0
    """Wall time spent inside ``mj_step`` over the runtime's control periods [s]: MuJoCo's
    own step timer (``data.timer[mjTIMER_STEP]``) read around each period's substeps, the
    differences summed (a reset or a recompile zeroes the timer, never inside a period)."""
    physics_steps: int = 0
    """The ``mj_step`` calls those were (the timer's count)."""
    _warnings: int = 0
    _adc: TorqueADC | None = None
    _adcs: dict[int, TorqueADC] = field(default_factory=dict)
    _gate_tick: int = 0

    @classmethod
    def create(cls, scene: Scene, arm_config: ArmControllerConfig, seed: int,
               stewart: StewartServo | None = None, gate: bool = True,
               arm: ArmController | None = None, transit: bool = True) -> CellRuntime:
        """Controllers for `scene`; `stewart` defaults to the platform's nominal model (which
        differs from a platform built with hidden joint errors by those errors); `gate`: the
        collision gate of the plate and the tray (bit-identical physics, fewer broad-phase boxes);
        `arm`: a controller already running on `scene` (else a new one holding the joints);
        `transit`: the transit step where the gate has everything out (needs the gate)."""
        if stewart is None:
            stewart = StewartServo.from_model(scene.model, scene.config.stewart.geometry(),
                                              names.STEWART, match_tol=MAX_JOINT_ERROR)
        if arm is None:
            arm = ArmController(scene.model, names.ARM, arm_config, seed)
            arm.hold_joints(scene.data.qpos[scene.arm_qpos_adr].copy())
        rt = cls(scene, arm, GripperServo.from_model(scene.model, arm.dt), stewart)
        if gate:
            rt.gate = CollisionGate(scene.model, scene.data, GATED_BODIES)
            if transit:
                rt.transit = TransitStep(scene.model, scene.config.physics)
        scene.on_recompile.append(rt._rebind)
        return rt

    def _rebind(self, scene: Scene) -> None:
        """A recompiled scene: the drive, the gate and the step size start over on the new
        model."""
        if self.drive is not None:
            self.drive = DriveFriction.of_arm(scene.model, names.ARM, self.drive.law,
                                              scene.config.physics.longest_step)
        self._adcs.clear()  # the next ones read the sensors' delays from the new model
        if self.gate is not None:
            self.gate.bind(scene.model, scene.data)
        if self.transit is not None:
            self.transit.bind(scene.model)
            self._match_step()

    def _match_step(self) -> None:
        """Substeps per control period for the model's timestep now (the ADC follows in step)."""
        self.arm.substeps = self.arm.config.substeps(self.scene.model.opt.timestep)

    @property
    def dt(self) -> float:
        return self.arm.dt

    def step(self) -> None:
        """One control period, sampled like the real arm: q and dq at its start, tau_J the
        mean over the period that just ended (:class:`TorqueADC`), the command held over it
        from its start."""
        m, d = self.scene.model, self.scene.data
        period_mean = None if self._adc is None else self._adc.mean()
        if period_mean is not None:
            self.arm.sensors.latch(period_mean)
        if self.gate is not None:
            self._gate_tick -= 1
            if self._gate_tick <= 0:
                self._gate_tick = GATE_EVERY
                self.gate.update(d)
            transit = self.transit
            if transit is not None and transit.set(not self.gate.any_on() and transit.platform_still(d), d):
                self._match_step()
        if self._adc is None or len(self._adc.weights) != self.arm.substeps:
            self._adc = self._adcs.get(self.arm.substeps) or self._adcs.setdefault(
                self.arm.substeps, TorqueADC(self.arm.index, self.arm.substeps, m))
        motors = self.arm.index.actuators
        held = d.ctrl[motors]  # a copy: the command of the period that ends now
        self.arm.update(m, d)
        self.gripper.update(d)
        new = d.ctrl[motors]
        # The leapfrog step lets the force of a substep act as if centred on its start, so a
        # command switched at t_k would act half a substep early; the substep on which it
        # switches gets the mean of the old and new command, which centres the switch on t_k.
        d.ctrl[motors] = 0.5 * (held + new)
        probe, adc, drive = self.substep_probe, self._adc, self.drive
        timer = d.timer[STEP_TIMER]
        physics_before, steps_before = timer.duration, timer.number
        for s in range(self.arm.substeps):
            if drive is not None:
                drive(d)
            mujoco.mj_step(m, d)
            adc.sample(d, s, m)
            if probe is not None:
                probe()
            if s == 0:  # after the switch substep: the command alone
                d.ctrl[motors] = new
        self.physics_wall_s += timer.duration - physics_before
        self.physics_steps += timer.number - steps_before
        if adc.reads_period_end:
            # drives that act late put a switch inside the period; the torque at its end is one
            # the next command does not touch yet (the trajectory is unchanged by this forward)
            if drive is not None:
                drive(d)
            mujoco.mj_forward(m, d)
            adc.end(d)
        self.time += self.arm.dt
        self._check_health()
        for observer in self.observers:
            observer(self)

    def set_load(self, mass: float, com_in_flange: np.ndarray | None = None) -> None:
        """Declare the carried load, as libfranka's ``setLoad`` (0: nothing in the hand)."""
        if not (math.isfinite(mass) and mass >= 0):
            raise ConfigError(f"load mass {mass} kg: must be finite and >= 0")
        self.load_mass = float(mass)
        self.load_com = np.zeros(3) if com_in_flange is None else np.asarray(com_in_flange, float)

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / self.dt)):
            self.step()

    def reset_health(self) -> None:
        """Forget counted warnings and the torque sensors' running period (after the state
        was restored from a snapshot or the scene recompiled: the next reading is a sample);
        the collision gate puts everything back in until it has seen the new state move."""
        self._warnings = 0
        self._adc = None
        if self.gate is not None:
            self.gate.reset()
        if self.transit is not None and self.transit.set(False):
            self._match_step()

    def _check_health(self) -> None:
        d = self.scene.data
        counts = d.warning.number  # one array read: a per-warning Python loop cost 5 % of a cycle
        warnings = int(counts.sum())
        if warnings > self._warnings:
            kinds = [mujoco.mjtWarning(i).name for i in np.flatnonzero(counts)]
            self._warnings = warnings
            raise UnstableSimulation(f"MuJoCo warning ({', '.join(kinds)}) at t = {self.time:.3f} s")
        # One reduction per array: a NaN or inf anywhere makes the sum non-finite.
        if not (math.isfinite(float(d.qpos.sum())) and math.isfinite(float(d.qvel.sum()))):
            raise UnstableSimulation(f"NaN or infinite state at t = {self.time:.3f} s")
        m = self.scene.model
        speed = np.abs(d.qvel) * m.dof_length
        dof = int(np.argmax(speed))
        if speed[dof] > MAX_SPEED:
            body = m.body(m.dof_bodyid[dof]).name
            raise UnstableSimulation(f"state blew up ({body} moving at {speed[dof]:.3g} > "
                                     f"{MAX_SPEED} m/s) at t = {self.time:.3f} s")
