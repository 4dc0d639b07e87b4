"""The "real" Stewart platform of the Stewart twins: the MuJoCo model of sim/stewart.py
(universal joints, actuated slides under the PID leg servos, spherical joints as connect
constraints) with whatever physics the twin adds, brought to rest at each commanded pose.

What MuJoCo expresses here, per hidden effect:
- joint-position errors: the model is built from the erroneous joint table
  (``StewartConfig.joint_errors``), so the platform lands where its built kinematics say;
- axial leg compliance: a passive slide ``comp{i}`` with joint stiffness k in series with each
  actuated slide (a screw, nut and bearing stack is a spring the encoder cannot see); MuJoCo
  finds the deflection under the platform's and payload's weight;
- thermal growth: the rod body sits further out along its leg (``body_pos``) by the growth at
  the time of the hold: uniform and linear in time (``growth_per_s``) and/or per leg and
  saturating (``growth_saturation`` with ``growth_tau_s``: a leg warming towards its steady
  temperature with its own time constant);
- encoder zero offset and scale error: the servo closes its loop on the encoder, which reads
  the true stroke x (1 + scale) plus the offset, so the slide settles where that reading
  equals the command (``Reality.stroke_for_reading``) while the recorded leg channel reads it.

Why each hold starts at a quasi-static estimate rather than being driven there: a stepped
command takes the servo's integral ~0.6 s (6000 substeps) to settle to 0.1 um. Started at the
rigid kinematics with the servo integral at the static leg forces and the springs deflected
by them, MuJoCo confirms its own equilibrium (loop constraints, compliance, the legs' weight)
in 0.01-0.2 s (compliant legs 0.2-1 s: the series spring leaves the platform's slow mode
lightly damped). Started from the rigid kinematics alone it comes to the same rest pose within
0.5 um (tests/test_diagnosis_stewart.py), so the estimate only saves time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError, UnstableSimulation
from serpar.kinematics.stewart_kinematics import N_LEGS, StewartGeometry, forward_kinematics
from serpar.sim.physics import PhysicsConfig
from serpar.sim.stewart import StewartConfig, build_stewart_spec
from serpar.sim.stewart_statics import nominal_load, static_leg_forces

Vec = NDArray[np.float64]

CHUNK_S = 0.01
"""Settling is checked every CHUNK_S of simulated time."""
REST_M = 1e-8
"""At rest: the platform moved less than this [m] over one chunk. With the servo integral's
~80 ms time constant it is then within ~0.1 um of rest: 2 % of the 5 um noise of a 1 s hold's
mean of motion capture."""
MAX_SETTLE_S = 3.0
COMPLIANCE_DAMPING_RATIO = 1.0
COMPLIANCE_ARMATURE_KG = 1.0
"""Reflected inertia of the passive spring's moving parts; keeps its mode (with the 0.1 kg
rod) below 1/(2 dt) for the stiffest legs the twins draw."""
MAX_ENCODER_SCALE = 0.05
"""Largest |encoder scale error| a Reality takes: 5 % is a wrong encoder setting, not an error."""
MAX_GROWTH = 0.01
"""Largest |relative leg growth| at saturation: 1 % is ~870 K of steel."""
MAX_GROWTH_PER_S = 1e-5
"""Largest |uniform growth rate|: 1e-5 /s is ~870 K of steel in 15 min."""


@dataclass(frozen=True)
class Reality:
    """Hidden physics of one twin platform (all zero / None: the nominal platform)."""

    joint_errors: Vec | None = None
    """(6, 7) dl, dP xyz, dB xyz [m] built into the model."""
    compliance_m_per_n: Vec | None = None
    """(6,) axial compliance of the passive spring in each leg [m/N]; None: rigid legs."""
    encoder_offset_m: Vec = field(default_factory=lambda: np.zeros(N_LEGS))
    """(6,) encoder reading minus true stroke x (1 + scale) [m]."""
    encoder_scale: Vec = field(default_factory=lambda: np.zeros(N_LEGS))
    """(6,) relative scale error of each encoder: it reads the true stroke (from its zero, the
    slide at l_min) x (1 + scale)."""
    growth_per_s: float = 0.0
    """Relative leg length growth per second (thermal expansion coefficient x warming rate)."""
    growth_saturation: Vec | None = None
    """(6,) relative growth of each leg once warm (expansion coefficient x its steady warming);
    with ``growth_tau_s``, leg i grows by growth_saturation_i (1 - exp(-t / tau_i)) on top of
    ``growth_per_s`` t. None: no saturating growth."""
    growth_tau_s: Vec | None = None
    """(6,) thermal time constant of each leg [s] (used with ``growth_saturation``)."""
    payload_kg: float = 0.0
    payload_com_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Payload centre of mass in the platform frame [m]."""

    def __post_init__(self) -> None:
        if self.compliance_m_per_n is not None:
            c = np.asarray(self.compliance_m_per_n, float)
            if c.shape != (N_LEGS,) or not np.all(c > 0):
                raise ConfigError(f"compliance_m_per_n must be {N_LEGS} positive values [m/N]")
        if np.asarray(self.encoder_offset_m).shape != (N_LEGS,):
            raise ConfigError(f"encoder_offset_m must be {N_LEGS} values [m]")
        scale = np.asarray(self.encoder_scale, float)
        if scale.shape != (N_LEGS,) or not np.all(np.abs(scale) <= MAX_ENCODER_SCALE):
            raise ConfigError(f"encoder_scale must be {N_LEGS} values in "
                              f"[-{MAX_ENCODER_SCALE:g}, {MAX_ENCODER_SCALE:g}]")
        if not (np.isfinite(self.growth_per_s) and abs(self.growth_per_s) <= MAX_GROWTH_PER_S):
            raise ConfigError(f"growth_per_s {self.growth_per_s}: valid |x| <= {MAX_GROWTH_PER_S:g} /s")
        if (self.growth_saturation is None) != (self.growth_tau_s is None):
            raise ConfigError("growth_saturation and growth_tau_s go together (both or neither)")
        if self.growth_saturation is not None:
            sat = np.asarray(self.growth_saturation, float)
            tau = np.asarray(self.growth_tau_s, float)
            if sat.shape != (N_LEGS,) or not np.all(np.abs(sat) <= MAX_GROWTH):
                raise ConfigError(f"growth_saturation must be {N_LEGS} values in "
                                  f"[-{MAX_GROWTH:g}, {MAX_GROWTH:g}] (relative growth)")
            if tau.shape != (N_LEGS,) or not np.all((tau > 0) & np.isfinite(tau)):
                raise ConfigError(f"growth_tau_s must be {N_LEGS} finite values > 0 [s]")
        if self.payload_kg < 0:
            raise ConfigError(f"payload_kg {self.payload_kg} must be >= 0")

    def relative_growth(self, t: float) -> float | Vec:
        """Thermal growth of each leg relative to its length at time ``t`` [s]."""
        linear = self.growth_per_s * t  # the uniform drift alone stays a scalar (bit-identical)
        if self.growth_saturation is None:
            return linear
        return linear + np.asarray(self.growth_saturation) * -np.expm1(-t / np.asarray(self.growth_tau_s))

    def stroke_for_reading(self, reading: Vec) -> Vec:
        """True stroke [m] at which the encoders read ``reading`` (where the servo holds them)."""
        return (reading - self.encoder_offset_m) / (1.0 + np.asarray(self.encoder_scale))


def platform_spec(reality: Reality, physics: PhysicsConfig) -> tuple[mujoco.MjSpec, StewartConfig]:
    errors = None if reality.joint_errors is None else tuple(map(tuple, reality.joint_errors))
    cfg = StewartConfig(joint_errors=errors)
    spec = build_stewart_spec(cfg, physics)
    physics.apply(spec)
    if reality.payload_kg > 0:
        load = spec.body("platform").add_body(name="payload", pos=list(reality.payload_com_m))
        load.mass = reality.payload_kg
        load.inertia = [reality.payload_kg * 0.05**2 / 6] * 3  # a 5 cm solid cube
        load.explicitinertial = True
        load.ipos, load.iquat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]
    if reality.compliance_m_per_n is not None:
        for i, c in enumerate(np.asarray(reality.compliance_m_per_n, float), start=1):
            k = 1.0 / c
            damp = 2.0 * COMPLIANCE_DAMPING_RATIO * np.sqrt(k * (COMPLIANCE_ARMATURE_KG + cfg.rod_mass))
            spec.body(f"rod{i}").add_joint(
                name=f"comp{i}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1.0],
                stiffness=[k, 0.0, 0.0], damping=[damp, 0.0, 0.0],
                armature=COMPLIANCE_ARMATURE_KG)
    return spec, cfg


class PlatformPlant:
    """The compiled twin platform and the ids it needs (looked up once)."""

    def __init__(self, reality: Reality, physics: PhysicsConfig | None = None) -> None:
        physics = physics or PhysicsConfig(sleep=False)
        spec, self.cfg = platform_spec(reality, physics)
        self.reality = reality
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        m = self.model

        def jid(name: str) -> int:
            return int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name))

        legs = [jid(f"leg{i}") for i in range(1, N_LEGS + 1)]
        self.slide_q = m.jnt_qposadr[legs]
        self.hinge_q = np.array([[m.jnt_qposadr[jid(f"u{i}_{s}")] for s in "ab"]
                                 for i in range(1, N_LEGS + 1)])
        self.comp_q = (m.jnt_qposadr[[jid(f"comp{i}") for i in range(1, N_LEGS + 1)]]
                       if reality.compliance_m_per_n is not None else None)
        self.free_q = int(m.jnt_qposadr[jid("platform_free")])
        cyl = [m.body(f"cyl{i}").id for i in range(1, N_LEGS + 1)]
        rod = [m.body(f"rod{i}").id for i in range(1, N_LEGS + 1)]
        self.rod_body = np.array(rod)
        self.cyl_rot = np.array([_quat_rot(m.body_quat[b]) for b in cyl])
        self.B = m.body_pos[cyl].copy()
        """Built base joints in the base (= world) frame."""
        centre = m.site("platform_centre").id
        self.P = np.array([m.site_pos[m.site(f"p_joint{i}").id] for i in range(1, N_LEGS + 1)]) \
            - m.site_pos[centre]
        self.rod_pos0 = m.body_pos[rod].copy()
        self.L0 = self.rod_pos0[:, 2] - m.qpos0[self.slide_q]
        """Joint-to-joint leg length at zero stroke, per leg (l_min + dl)."""
        self.centre_site = centre
        self.load = nominal_load(reality.payload_kg, reality.payload_com_m)
        self._act: Vec | None = None
        self._geom = StewartGeometry(self.P, self.B, float(self.L0.mean()), self.cfg.stroke,
                                     home_pos=tuple(self.cfg.home_pos))

    def settle(self, strokes: Vec, t: float, guess: tuple[Vec, Vec], informed: bool = True,
               max_s: float = MAX_SETTLE_S) -> tuple[Vec, Vec, Vec, float]:
        """Rest pose (pos, rot) in the base frame with the slides at ``strokes`` [m] (the
        servo's target in true stroke), the slide positions reached, and the simulated
        settling time [s]. ``t``: time since the start of the recording (thermal growth).
        ``informed``: start from the quasi-static estimate (servo integral at the static leg
        forces, springs deflected by them); else from the rigid kinematics and the previous
        hold's integral (slower; the twin's tests check both reach one equilibrium)."""
        m, d = self.model, self.data
        growth = self.reality.relative_growth(t) * (self.L0 + strokes)
        m.body_pos[self.rod_body, 2] = self.rod_pos0[:, 2] + growth
        length = self.L0 + growth + strokes
        pos, rot, _ = forward_kinematics(self._geom, length - self._geom.l_min, guess[0], guess[1])
        deflection = np.zeros(N_LEGS)
        act = self._act
        if informed:
            force = static_leg_forces(self.P, self.B, pos[None], rot[None], self.load)[0]
            act = force / self.cfg.leg_ki
            if self.reality.compliance_m_per_n is not None:
                deflection = -np.asarray(self.reality.compliance_m_per_n) * force
                pos, rot, _ = forward_kinematics(self._geom, length + deflection - self._geom.l_min,
                                                 pos, rot)
        mujoco.mj_resetData(m, d)
        d.qpos[self.free_q:self.free_q + 3] = pos
        mujoco.mju_mat2Quat(d.qpos[self.free_q + 3:self.free_q + 7], np.ascontiguousarray(rot).ravel())
        legs = pos + self.P @ rot.T - self.B
        for i in range(N_LEGS):
            u = self.cyl_rot[i].T @ (legs[i] / np.linalg.norm(legs[i]))
            d.qpos[self.hinge_q[i]] = (np.arctan2(-u[1], u[2]), np.arcsin(np.clip(u[0], -1, 1)))
        d.qpos[self.slide_q] = strokes
        if self.comp_q is not None:
            d.qpos[self.comp_q] = deflection
        d.ctrl[:] = strokes
        if act is not None:
            d.act[:] = act
        steps = max(1, round(CHUNK_S / m.opt.timestep))
        last = pos.copy()
        elapsed = 0.0
        while elapsed < max_s:
            mujoco.mj_step(m, d, nstep=steps)
            elapsed += CHUNK_S
            now = d.site_xpos[self.centre_site].copy()
            if np.max(np.abs(now - last)) < REST_M and np.max(np.abs(d.qvel)) < 1e-5:
                break
            last = now
        if d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
            raise UnstableSimulation(f"the twin platform went unstable settling at strokes "
                                     f"{np.round(strokes * 1e3, 3)} mm (MuJoCo bad qacc)")
        self._act = d.act.copy()
        rot_now = d.site_xmat[self.centre_site].reshape(3, 3).copy()
        return now, rot_now, d.qpos[self.slide_q].copy(), elapsed

    def actuator_force(self) -> Vec:
        """Axial force each servo exerts at rest [N] (positive: pushing the leg out)."""
        return self.data.actuator_force.copy()


def _quat_rot(q: Vec) -> Vec:
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, np.asarray(q, float))
    return r.reshape(3, 3)
