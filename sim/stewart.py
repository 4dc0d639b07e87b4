"""The 6-UPS Stewart platform (seed 000 §4.1, Table 2) built in code with MjSpec.

Frames: the base frame has the base (universal) joint centres B_i at z = 0;
the platform frame has its origin at the centre of the platform (spherical)
joint plane, joints at (P_x, P_y, 0). Table 2 lists the platform at Z = 245 mm.

Each leg is an open chain base -> cyl{i} (universal joint: hinges u{i}_a,
u{i}_b) -> rod{i} (slide leg{i}, qpos = actuator stroke s_i). The spherical
joint closes the loop as an equality ``connect`` loop{i} between the sites
rod_end{i} and p_joint{i}: a ball constraint has no stop, so the seed's 30 deg
upper-hinge limit is only checked kinematically (:func:`spherical_angles_deg`).
Leg length joint-centre to joint-centre is L_i = l_min + s_i.

Table 2 as printed is architecture-singular (the six leg lines are dependent at
every pose: with locked legs the platform has a self-motion and falls along it).
``swap_legs12`` (default on) exchanges the platform and base columns of legs 1
and 2, a likely misprint; see assets/stewart/README.md.

The maths (IK, FK, leg Jacobian, hinge angles, limits) is in
:mod:`serpar.kinematics.stewart_kinematics`, the joint table in :mod:`serpar.kinematics.stewart_table`;
this module builds the MuJoCo model and delegates to them.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.kinematics.rotations import quat_to_rot
from serpar.kinematics.stewart_kinematics import (
    N_LEGS,
    StewartGeometry,
    forward_kinematics,
    inverse_kinematics,
    jacobian,
    singularity_measure,
)
from serpar.kinematics.stewart_table import load_joint_table, table_geometry
from serpar.sim.physics import PhysicsConfig

__all__ = ["N_LEGS", "StewartConfig", "build_stewart_spec", "built_geometry", "home_strokes",
           "initial_pose", "leg_space_masses",
           "load_joint_table", "loop_site_ids", "loop_violation", "spherical_angles_deg",
           "stewart_geometry", "stroke_for_pose"]

MAX_JOINT_ERROR = 0.01
"""Largest hidden joint or leg-length error accepted [m] (seed 000 simulates +-5 mm)."""
CYL_RGBA = (0.55, 0.56, 0.58, 1.0)  # anodised grey motor/cylinder housing
ROD_RGBA = (0.20, 0.40, 0.80, 1.0)  # blue piston rod
PLATFORM_RGBA = (0.45, 0.47, 0.50, 1.0)  # grey anodised aluminium: the bright plate stands out
BASE_RGBA = (0.30, 0.30, 0.32, 1.0)


@dataclass(frozen=True)
class StewartConfig:
    """Geometry, masses and leg servo of the Stewart platform (SI units)."""

    l_min: float = 0.2468
    """Leg length at zero stroke [m]; not in the seed, chosen so the stroke spans Z 240-290 mm."""
    stroke: float = 0.0508
    """Actuator stroke [m] (seed §4.1: 0 <= L_i <= 50.8 mm)."""
    home_z: float = 0.265
    """Height of the platform frame above the base frame at home [m] (about mid-stroke)."""
    lower_hinge_limit_deg: float = 20.0
    upper_hinge_limit_deg: float = 30.0
    swap_legs12: bool = True
    """Exchange P and B of legs 1, 2 of Table 2 (misprint fix; False: the singular table)."""
    platform_mass: float = 2.87
    """Aluminium disc r = 130 mm, t = 20 mm: 2700 kg/m^3 * pi r^2 t = 2.87 kg."""
    cyl_mass: float = 0.20
    rod_mass: float = 0.10
    leg_armature: float = 25.0
    """Reflected rotor inertia per slide [kg]: J (2 pi / lead)^2, J = 1.6e-5 kg m^2, lead 5 mm."""
    leg_kp: float = 1.6e6
    """Servo stiffness [N/m]: sqrt(kp / m) ~ 2 pi 40 Hz for the lightest leg-space mode (25 kg)."""
    leg_kv: float = 1.28e4
    """Servo damping [N s/m]: 2 omega_n m, critically damped for the lightest leg-space mode."""
    leg_ki: float = 2.0e7
    """Integral gain [N/(m s)]: removes gravity sag; Routh margin 4 at the heaviest mode (250 kg)"""
    leg_imax: float = 300.0
    """Anti-windup clamp of the integral force [N]; gravity loads each leg with ~ 20 N."""
    leg_force_limit: float = 1000.0
    """Peak actuator force [N]: ~50x the static load, typical of a 100-400 W electric cylinder."""
    loop_solimp: tuple[float, float, float, float, float] = (0.9999, 0.99999, 1e-6, 0.5, 2.0)
    """Impedance of the spherical-joint connects (solref comes from PhysicsConfig): with d0 =
    0.995 (the contact setting) a step command opens the loops 0.74 um, with 0.9999 0.17 um."""
    hinge_damping: float = 0.01
    """Viscous friction of the universal-joint bearings [N m s/rad]."""
    platform_radius: float = 0.13
    platform_thickness: float = 0.020
    base_radius: float = 0.17
    base_thickness: float = 0.01
    joint_errors: tuple[tuple[float, ...], ...] | None = None
    """Geometric errors of the *built* platform, per leg (dl, dPx, dPy, dPz, dBx, dBy, dBz) [m]
    as in seed 000 Table 5. The MuJoCo model is built with them; :meth:`geometry` (what the
    platform's controller believes) does not know them. None: a perfect platform."""

    def __post_init__(self) -> None:
        if self.joint_errors is not None:
            err = np.asarray(self.joint_errors, dtype=float)
            if err.shape != (N_LEGS, 7) or not np.all(np.isfinite(err)):
                raise ConfigError(f"joint_errors must be {N_LEGS} rows of 7 finite numbers "
                                  f"(dl, dP xyz, dB xyz) [m], got shape {err.shape}")
            if np.max(np.abs(err)) > MAX_JOINT_ERROR:
                raise ConfigError(f"joint_errors up to {np.max(np.abs(err)) * 1e3:.3g} mm; valid: "
                                  f"|error| <= {MAX_JOINT_ERROR * 1e3:g} mm")
            object.__setattr__(self, "joint_errors", tuple(tuple(float(v) for v in row) for row in err))
        positive = ("l_min", "stroke", "platform_mass", "cyl_mass", "rod_mass", "leg_kp",
                    "leg_force_limit", "platform_radius", "platform_thickness",
                    "base_radius", "base_thickness")
        for name in positive:
            if not float(getattr(self, name)) > 0:
                raise ConfigError(f"{name}={getattr(self, name)} must be > 0")
        for name in ("leg_armature", "leg_kv", "leg_ki", "leg_imax", "hinge_damping"):
            if not float(getattr(self, name)) >= 0:
                raise ConfigError(f"{name}={getattr(self, name)} must be >= 0")
        d0, dw, width = self.loop_solimp[:3]
        if not (0 < d0 <= dw < 1 and width > 0):
            raise ConfigError(f"loop_solimp {self.loop_solimp}: need 0 < d0 <= dmax < 1, width > 0")
        # The geometry checks the hinge limits and that home is within the stroke.
        geom = self.geometry()
        s_home = inverse_kinematics(geom, self.home_pos, np.eye(3))
        if not np.all((s_home > 0) & (s_home < self.stroke)):
            raise ConfigError(f"home_z={self.home_z} m needs strokes inside (0, {self.stroke}) m, "
                              f"got {np.round(s_home, 5)}")
        inv_cond = float(singularity_measure(jacobian(geom, self.home_pos, np.eye(3))))
        if inv_cond < 1e-6:  # the legs cannot hold the platform: a mechanism, not a robot
            raise ConfigError(f"joint table singular at home (sigma ratio {inv_cond:.1e}); "
                              "Table 2 as printed needs swap_legs12=True")
        # Routh-Hurwitz for m s^3 + kv s^2 + kp s + ki, for every leg-space mode at home:
        # the platform's poorly conditioned directions weigh ~20x more than the Z mode.
        m_max = float(leg_space_masses(self)[-1])
        if self.leg_ki > 0 and not self.leg_kv * self.leg_kp > m_max * self.leg_ki:
            raise ConfigError(f"unstable leg servo: need kv*kp > m_max*ki, m_max={m_max:.1f} kg, "
                              f"i.e. leg_ki < {self.leg_kv * self.leg_kp / m_max:.3g}")

    @property
    def servo_natural_hz(self) -> float:
        """Natural frequency of the lightest (fastest) leg-space mode [Hz]."""
        return float(np.sqrt(self.leg_kp / leg_space_masses(self)[0]) / (2 * np.pi))

    @property
    def servo_damping_ratio(self) -> float:
        """Damping ratio of the lightest leg-space mode (heavier modes are less damped)."""
        return float(self.leg_kv / (2 * np.sqrt(self.leg_kp * leg_space_masses(self)[0])))

    @property
    def home_pos(self) -> np.ndarray:
        return np.array([0.0, 0.0, self.home_z])

    def geometry(self) -> StewartGeometry:
        """Kinematic geometry (joints, l_min, stroke, hinge limits, home) for the kinematics."""
        return table_geometry(self.swap_legs12, self.l_min, self.stroke,
                              self.lower_hinge_limit_deg, self.upper_hinge_limit_deg, self.home_z)


def built_geometry(cfg: StewartConfig) -> tuple[StewartGeometry, np.ndarray]:
    """The platform as built: geometry with the joint errors, and the leg-length errors dl [m]
    (leg length = l_min + dl_i + stroke_i). Equals the nominal geometry without errors."""
    nominal = cfg.geometry()
    if cfg.joint_errors is None:
        return nominal, np.zeros(N_LEGS)
    err = np.asarray(cfg.joint_errors)
    built = StewartGeometry(nominal.P + err[:, 1:4], nominal.B + err[:, 4:7], nominal.l_min,
                            nominal.stroke, nominal.lower_hinge_limit_deg,
                            nominal.upper_hinge_limit_deg, nominal.home_pos)
    return built, err[:, 0].copy()


def initial_pose(cfg: StewartConfig) -> tuple[np.ndarray, np.ndarray]:
    """Where the built platform stands when its legs hold the nominal home strokes (pos, rot in
    the base frame): the home pose exactly without joint errors."""
    if cfg.joint_errors is None:
        return cfg.home_pos, np.eye(3)
    built, dl = built_geometry(cfg)
    pos, rot, _ = forward_kinematics(built, home_strokes(cfg) + dl, cfg.home_pos, np.eye(3))
    return pos, rot


def stewart_geometry(cfg: StewartConfig | None = None) -> StewartGeometry:
    """The :class:`StewartGeometry` of a config (default config when None)."""
    return (cfg or StewartConfig()).geometry()


def stroke_for_pose(pos: np.ndarray, quat: np.ndarray,
                    cfg: StewartConfig | None = None) -> np.ndarray:
    """Nominal inverse kinematics: s_i = |pos + R(quat) P_i - B_i| - l_min (quat is w,x,y,z)."""
    return inverse_kinematics(stewart_geometry(cfg), np.asarray(pos, dtype=float),
                              quat_to_rot(quat))


def leg_space_masses(cfg: StewartConfig) -> np.ndarray:
    """Sorted eigen-masses [kg] the six leg servos see at home: (J M^-1 J^T)^-1 + armature + rod.

    J maps the platform twist (origin velocity, angular velocity) to stroke rates; M is the
    disc's spatial inertia about the platform origin. Leg hinge inertias are neglected.
    """
    m, r, t = cfg.platform_mass, cfg.platform_radius, cfg.platform_thickness
    c = np.array([[0, -t / 2, 0], [t / 2, 0, 0], [0, 0, 0]])  # skew of the COM offset (0, 0, t/2)
    inertia = np.diag([m * (3 * r * r + t * t) / 12] * 2 + [m * r * r / 2]) - m * c @ c
    mass = np.block([[m * np.eye(3), -m * c], [m * c, inertia]])
    jac = jacobian(cfg.geometry(), cfg.home_pos, np.eye(3))
    lam = np.linalg.inv(jac @ np.linalg.solve(mass, jac.T))
    return np.linalg.eigvalsh(lam) + cfg.leg_armature + cfg.rod_mass


def home_strokes(cfg: StewartConfig = StewartConfig()) -> np.ndarray:
    """Leg commands that hold the home pose (the model's qpos0 has them already)."""
    return stroke_for_pose(cfg.home_pos, np.array([1.0, 0, 0, 0]), cfg)


def _leg_frame(direction: np.ndarray) -> np.ndarray:
    """Quaternion of a frame whose z is the leg axis and whose x is horizontal."""
    z = direction / np.linalg.norm(direction)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)  # legs are never vertical (62 mm horizontal offset)
    rot = np.column_stack([x, np.cross(z, x), z])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot.ravel())
    return quat


PLATFORM_SLEEP = mujoco.mjtSleepPolicy.mjSLEEP_ALLOWED
"""Actuated trees never sleep by default (mjSLEEP_AUTO), so every part seated in the plate,
which touches the platform's tree, stayed awake: 6 seated parts made a still cell's step 10x
dearer. The still platform may sleep; `StewartServo` wakes it whenever a command changes."""


def build_stewart_spec(cfg: StewartConfig = StewartConfig(),
                       physics: PhysicsConfig | None = None) -> mujoco.MjSpec:
    """MjSpec of the platform as built (with `cfg.joint_errors`) at the pose the nominal home
    strokes give it (home exactly without errors); qpos0 closes every loop exactly."""
    physics = physics or PhysicsConfig()
    spec = mujoco.MjSpec()
    spec.modelname = "stewart"
    spec.compiler.degree = False  # MjSpec defaults to degrees; every angle below is in radians
    built, dl = built_geometry(cfg)
    p, b = built.P, built.B
    s_home = home_strokes(cfg)  # the controller's home command; the built platform stands at:
    pos0, rot0 = initial_pose(cfg)
    no_contact = {"contype": 0, "conaffinity": 0}
    cyl_len, rod_len = 0.16, 0.15  # visual: rod stays inside the cylinder over the full stroke

    base = spec.worldbody.add_body(name="base")  # static: the legs hang off it
    base.add_geom(name="base_disc", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                  size=[cfg.base_radius, cfg.base_thickness / 2, 0],
                  pos=[0, 0, -cfg.base_thickness / 2], rgba=BASE_RGBA)

    lim = cfg.lower_hinge_limit_deg * np.pi / 180
    for i in range(1, N_LEGS + 1):
        length = cfg.l_min + dl[i - 1] + s_home[i - 1]
        direction = pos0 + rot0 @ p[i - 1] - b[i - 1]
        cyl = base.add_body(name=f"cyl{i}", pos=b[i - 1], quat=_leg_frame(direction))
        cyl.sleep = PLATFORM_SLEEP
        for suffix, axis in (("a", [1.0, 0, 0]), ("b", [0, 1.0, 0])):
            # Cardan joint: the neutral axis is the home leg direction, limits about it.
            cyl.add_joint(name=f"u{i}_{suffix}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=axis,
                          range=[-lim, lim], limited=mujoco.mjtLimited.mjLIMITED_TRUE,
                          damping=cfg.hinge_damping)
        cyl.add_geom(name=f"cyl{i}_geom", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                     fromto=[0, 0, 0, 0, 0, cyl_len], size=[0.02, 0, 0], mass=cfg.cyl_mass,
                     rgba=CYL_RGBA, **no_contact)
        rod = cyl.add_body(name=f"rod{i}", pos=[0, 0, length])
        # ref = home stroke: the body is placed at s_home, so qpos0 = s_home closes the loop.
        rod.add_joint(name=f"leg{i}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1.0],
                      ref=s_home[i - 1], range=[0, cfg.stroke],
                      limited=mujoco.mjtLimited.mjLIMITED_TRUE, armature=cfg.leg_armature)
        rod.add_geom(name=f"rod{i}_geom", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                     fromto=[0, 0, -rod_len, 0, 0, 0], size=[0.008, 0, 0], mass=cfg.rod_mass,
                     rgba=ROD_RGBA, **no_contact)
        rod.add_site(name=f"rod_end{i}", size=[0.006, 0, 0], rgba=ROD_RGBA)

    quat0 = np.zeros(4)
    mujoco.mju_mat2Quat(quat0, np.ascontiguousarray(rot0).ravel())
    plat = spec.worldbody.add_body(name="platform", pos=pos0, quat=quat0)
    plat.sleep = PLATFORM_SLEEP
    plat.add_freejoint(name="platform_free")
    plat.add_geom(name="platform_disc", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                  size=[cfg.platform_radius, cfg.platform_thickness / 2, 0],
                  pos=[0, 0, cfg.platform_thickness / 2], mass=cfg.platform_mass,
                  rgba=PLATFORM_RGBA)
    plat.add_site(name="platform_centre", size=[0.004, 0, 0])
    plat.add_site(name="fixture", pos=[0, 0, cfg.platform_thickness], size=[0.004, 0, 0])
    for i in range(1, N_LEGS + 1):
        plat.add_site(name=f"p_joint{i}", pos=p[i - 1], size=[0.005, 0, 0])

    for i in range(1, N_LEGS + 1):
        # Spherical joint as a stiff ball constraint between two coincident sites.
        spec.add_equality(name=f"loop{i}", type=mujoco.mjtEq.mjEQ_CONNECT,
                          objtype=mujoco.mjtObj.mjOBJ_SITE, name1=f"rod_end{i}",
                          name2=f"p_joint{i}", solref=list(physics.precision_solref),
                          solimp=list(cfg.loop_solimp))
        act = spec.add_actuator(name=f"leg{i}", target=f"leg{i}",
                                trntype=mujoco.mjtTrn.mjTRN_JOINT)
        # PID with only the position input: one control per leg, kv acts as damping; imax
        # clamps the integral state [m s], so the force clamp is divided by ki.
        imax = cfg.leg_imax / cfg.leg_ki if cfg.leg_ki > 0 else -1
        act.set_to_pid(kp=cfg.leg_kp, kv=cfg.leg_kv, ki=cfg.leg_ki if cfg.leg_ki > 0 else -1,
                       imax=imax, ctrlspec=int(mujoco.mjtCtrlInput.mjINPUT_POS))
        act.ctrlrange = [0, cfg.stroke]
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-cfg.leg_force_limit, cfg.leg_force_limit]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        spec.add_sensor(name=f"stroke{i}", type=mujoco.mjtSensor.mjSENS_JOINTPOS,
                        objtype=mujoco.mjtObj.mjOBJ_JOINT, objname=f"leg{i}")
    for name, kind in (("platform_pos", mujoco.mjtSensor.mjSENS_FRAMEPOS),
                       ("platform_quat", mujoco.mjtSensor.mjSENS_FRAMEQUAT)):
        spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE,
                        objname="platform_centre")
    return spec


def loop_site_ids(model: mujoco.MjModel, prefix: str = "") -> tuple[np.ndarray, np.ndarray]:
    """Site ids (rod_end, p_joint) of the six loops; look them up once, outside step loops."""
    def sid(name: str) -> int:
        k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, prefix + name)
        if k < 0:
            raise ConfigError(f"site {prefix + name!r} not in the model; check prefix {prefix!r}")
        return k
    ends = np.array([sid(f"rod_end{i}") for i in range(1, N_LEGS + 1)])
    joints = np.array([sid(f"p_joint{i}") for i in range(1, N_LEGS + 1)])
    return ends, joints


def loop_violation(model: mujoco.MjModel, data: mujoco.MjData, prefix: str = "",
                   site_ids: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """Largest gap between a rod end and its platform joint [m] (needs site_xpos up to date)."""
    ends, joints = site_ids if site_ids is not None else loop_site_ids(model, prefix)
    return float(np.max(np.linalg.norm(data.site_xpos[ends] - data.site_xpos[joints], axis=1)))


def spherical_angles_deg(model: mujoco.MjModel, data: mujoco.MjData,
                         cfg: StewartConfig = StewartConfig(), prefix: str = "") -> np.ndarray:
    """Deflection of each spherical joint from its home leg direction, in the platform frame [deg].

    The connect constraint has no stop; compare against cfg.upper_hinge_limit_deg.
    """
    home_dir = stewart_geometry(cfg).home_directions
    plat = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, prefix + "platform")
    rot_plat = data.xmat[plat].reshape(3, 3)
    out = np.empty(N_LEGS)
    for i in range(N_LEGS):
        rod = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"{prefix}rod{i + 1}")
        axis_plat = rot_plat.T @ data.xmat[rod].reshape(3, 3)[:, 2]  # leg axis seen by the platform
        out[i] = np.degrees(np.arccos(np.clip(axis_plat @ home_dir[i], -1.0, 1.0)))
    return out
