"""The arm of a robot file (URDF or MJCF) as a dynamics model: the file's masses, centres of mass,
inertias, armature, damping and friction loss exactly as written (the arm-dynamics diagnosis's
nominal model, and the nominal model of its twins).

The kinematics reader (:func:`serpar.sim.robot_file.robot_spec`) bounds every body's mass and
inertia (MuJoCo's ``boundmass``/``boundinertia``) so that any file compiles; that is harmless for
kinematics and wrong for dynamics, so here no value is bounded silently:

- A URDF link's inertia is its ``<inertial>`` (``inertiafromgeom`` false unless the file's own
  ``<mujoco><compiler>`` says otherwise): MuJoCo would otherwise give a link without one the
  mass of its collision shapes at 1000 kg/m³. An MJCF keeps its own rule.
- The file as published (:mod:`serpar.sim.robot_repair`): repeated URDF elements repaired where
  unambiguous, mesh geoms whose files are absent dropped (they carry no inertia here).
- The arm's chain only (the joints from the world to the flange,
  :func:`serpar.sim.robot_file.read_chain`; a slide joint on it is refused): joints beyond the
  flange (a gripper's) are locked, their bodies kept with their masses, which the arm carries.
  The file's actuators, sensors and keyframes are its controller's, not the arm's, and go; so
  do equality constraints and tendons, except ones that couple the chain's joints (refused).
  Contacts are off: the arm alone in free space, and a file's collision shapes would only
  touch each other.
- MuJoCo refuses a body that a joint moves with no mass or inertia. Where the file gives a
  chain body (near) none (below :data:`TINY`) but its joint moves mass, the missing value is
  set to :data:`BOUND` (about each principal axis), named with the body in ``repairs``; a
  joint that moves no mass, or has no inertia about its axis from the file, is one line.

:func:`dynamics_model` gives the compiled arm (:class:`DynamicsRobot`); :func:`dynamics_spec`
the same as an editable spec, for a caller that adds to the arm before compiling.
"""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.robot_file import RobotModel, compile_spec, read_chain, read_spec
from serpar.sim.robot_repair import drop_absent_meshes

TINY = 1e-12
"""kg, kg m²: a mass or principal inertia below this is one the file does not give."""
BOUND = 1e-6
"""kg, kg m²: what such a value becomes where MuJoCo needs one (0.1 % of a 1 g, 3 cm part's)."""
_AXIS_TINY = 1e-10  # kg m²: a joint-space inertia this small is none (a real link's is > 1e-6)
_OBJ = mujoco.mjtObj


@dataclass(frozen=True, eq=False)
class DynamicsRobot:
    """A robot file's arm as MuJoCo dynamics (module docstring); q = the chain's qpos."""

    model: mujoco.MjModel
    """The compiled arm: chain joints only, contacts off. Copy it before editing."""
    name: str
    source: str
    joints: tuple[int, ...]
    """Joint ids of the chain, base to flange."""
    joint_names: tuple[str, ...]
    qpos: tuple[int, ...]
    dof: tuple[int, ...]
    moved: tuple[tuple[int, ...], ...]
    """Per chain joint, the body ids it moves (its body and every body beyond it)."""
    flange_body: int
    flange_pose: NDArray[np.float64]
    """(4, 4) the flange frame in ``flange_body``'s frame."""
    gravity: NDArray[np.float64]
    """(3,) m/s² in the world (base) frame."""
    armature: NDArray[np.float64]
    """(n,) kg m² per chain dof, as the file gives (0 where it gives none)."""
    damping: NDArray[np.float64]
    """(n,) N m s/rad per chain dof."""
    frictionloss: NDArray[np.float64]
    """(n,) N m per chain dof."""
    repairs: tuple[str, ...]
    """Each repair made to read the file, naming the body or link and the value used."""
    locked: tuple[str, ...]
    """Joints beyond the flange, locked (their bodies kept, welded)."""

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def link_bodies(self) -> tuple[str, ...]:
        """The body each chain joint turns (its child link), by name."""
        return tuple(_name(self.model, _OBJ.mjOBJ_BODY, moved[0]) for moved in self.moved)


def _urdf(path: Path) -> tuple[bool, bool]:
    """(a URDF, its own <mujoco><compiler> sets inertiafromgeom)."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError:
        return False, False
    compiler = root.find("mujoco/compiler")
    return root.tag == "robot", compiler is not None and "inertiafromgeom" in compiler.attrib


def _subtree(model: mujoco.MjModel, body: int) -> tuple[int, ...]:
    def under(b: int) -> bool:
        while b > 0 and b != body:
            b = int(model.body_parentid[b])
        return b == body
    return tuple(b for b in range(model.nbody) if under(b))


def _frozen(values: NDArray[np.float64]) -> NDArray[np.float64]:
    out = np.array(values, float)
    out.setflags(write=False)  # a frozen dataclass's arrays stay as read
    return out


def _name(model: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(model, obj, i) or f"#{i}"


def _probe(spec: mujoco.MjSpec, source: str) -> mujoco.MjModel:
    """The file compiled with every mass and inertia bounded to TINY: the file's own values
    wherever they are real, and the spec's element ids set for the edits that follow."""
    bounds = spec.compiler.boundmass, spec.compiler.boundinertia
    spec.compiler.boundmass, spec.compiler.boundinertia = max(bounds[0], TINY), max(bounds[1], TINY)
    try:
        return compile_spec(spec, source)
    finally:
        spec.compiler.boundmass, spec.compiler.boundinertia = bounds


def _arm_only(spec: mujoco.MjSpec, probe: mujoco.MjModel, chain: RobotModel,
              source: str) -> tuple[str, ...]:
    """Lock the joints beyond the flange; drop actuators, sensors, keyframes, contact pairs and
    couplings (refusing one that couples the chain's joints). The locked joints' names."""
    on_chain = set(chain.joints)
    dofs = [int(probe.jnt_dofadr[j]) for j in chain.joints]
    arm = set(_subtree(probe, int(probe.jnt_bodyid[chain.joints[0]])))
    data = mujoco.MjData(probe)
    mujoco.mj_forward(probe, data)
    for t in range(probe.ntendon):  # the tendon Jacobian's row t (sparse, structure in model)
        adr, nnz = int(probe.ten_J_rowadr[t]), int(probe.ten_J_rownnz[t])
        cols = probe.ten_J_colind[adr:adr + nnz]
        if any(c in dofs and v != 0 for c, v in zip(cols, data.ten_J[adr:adr + nnz])):
            raise ConfigError(f"--robot {source}: tendon {_name(probe, _OBJ.mjOBJ_TENDON, t)!r} "
                              "acts on the arm's joints; serpar's arm dynamics takes the joints "
                              "as independent: remove the tendon")
    for e in range(probe.neq):
        kind, a, b = int(probe.eq_type[e]), int(probe.eq_obj1id[e]), int(probe.eq_obj2id[e])
        if kind == mujoco.mjtEq.mjEQ_JOINT:
            hit = a in on_chain or b in on_chain
        elif kind in (mujoco.mjtEq.mjEQ_CONNECT, mujoco.mjtEq.mjEQ_WELD):
            hit = a in arm or b in arm
        else:
            hit = False
        if hit:
            raise ConfigError(f"--robot {source}: equality "
                              f"{_name(probe, _OBJ.mjOBJ_EQUALITY, e)!r} constrains the arm; "
                              "serpar's arm dynamics takes an open chain: remove the equality")
    locked = [j for j in spec.joints if j.id not in on_chain]
    names = tuple(_name(probe, _OBJ.mjOBJ_JOINT, j.id) for j in locked)
    for el in (locked + list(spec.actuators) + list(spec.sensors) + list(spec.keys)
               + list(spec.equalities) + list(spec.tendons) + list(spec.pairs)):
        spec.delete(el)
    return names


def _fmt(values: NDArray[np.float64]) -> str:
    return ", ".join("0" if v <= TINY else f"{v:.4g}" for v in values)


def _bound_moving(spec: mujoco.MjSpec, probe: mujoco.MjModel, chain: RobotModel,
                  source: str) -> dict[int, tuple[bool, NDArray[np.bool_], str]]:
    """Set BOUND where a chain joint's own body has (near) no mass or inertia but the joint
    moves mass; per body repaired: (mass bounded, which principal moments, the repair)."""
    bodies = {b.id: b for b in spec.bodies}
    out = {}
    for j in chain.joints:
        b = int(probe.jnt_bodyid[j])
        mass, inertia = float(probe.body_mass[b]), np.array(probe.body_inertia[b])
        low_m, low_i = mass <= TINY, inertia <= TINY
        if not (low_m or low_i.any()):
            continue
        jname, bname = _name(probe, _OBJ.mjOBJ_JOINT, j), _name(probe, _OBJ.mjOBJ_BODY, b)
        if not any(probe.body_mass[k] > TINY for k in _subtree(probe, b)):
            raise ConfigError(f"--robot {source}: joint {jname!r} moves no mass: the file's "
                              "inertials are missing; dynamics needs them")
        body = bodies[b]
        body.explicitinertial = True
        body.mass = BOUND if low_m else mass
        body.ipos, body.iquat = np.array(probe.body_ipos[b]), np.array(probe.body_iquat[b])
        body.fullinertia = [np.nan] * 6  # the principal moments below, in the file's frame
        body.inertia = np.where(low_i, BOUND, inertia)
        low = " and ".join((["mass 0 kg"] if low_m else [])
                           + ([f"principal inertia ({_fmt(inertia)}) kg m²"] if low_i.any() else []))
        done = ", ".join(([f"each zero moment set to {BOUND:g} kg m²"] if low_i.any() else [])
                         + ([f"mass set to {BOUND:g} kg"] if low_m else [f"its {mass:g} kg kept"]))
        out[b] = (low_m, low_i, (f"body {bname!r} (turned by {jname!r}): {low}, below what "
                                 f"MuJoCo takes: {done}"))
    return out


def _axis_inertia(model: mujoco.MjModel, rm: RobotModel,
                  bounded: dict[int, tuple[bool, NDArray[np.bool_], str]]) -> NDArray[np.float64]:
    """Per chain joint, the most inertia about its axis that the file's own values give (the
    joint-space inertia's diagonal without armature or the bounds) at q = 0 and 4 random q."""
    m = copy.copy(model)
    for b, (low_m, low_i, _) in bounded.items():
        m.body_mass[b] = 0.0 if low_m else m.body_mass[b]
        m.body_inertia[b][low_i] = 0.0
    m.dof_armature[:] = 0.0
    data = mujoco.MjData(m)
    j = list(rm.joints)
    lo = np.where(m.jnt_limited[j], m.jnt_range[j, 0], -np.pi)
    hi = np.where(m.jnt_limited[j], m.jnt_range[j, 1], np.pi)
    rng = np.random.default_rng(0)
    out, full = np.zeros(len(j)), np.zeros((m.nv, m.nv))
    for q in [np.zeros(len(j)), *rng.uniform(lo, hi, (4, len(j)))]:
        data.qpos[:] = m.qpos0
        data.qpos[rm.qpos] = q
        mujoco.mj_kinematics(m, data)  # no factorisation: the file's M may well be singular
        mujoco.mj_comPos(m, data)
        mujoco.mj_crb(m, data)
        mujoco.mj_fullM(m, data, full)
        out = np.maximum(out, np.diag(full)[rm.dof])
    return out


def _read(path: Path) -> tuple[mujoco.MjSpec, mujoco.MjModel, RobotModel, tuple[str, ...],
                              tuple[str, ...]]:
    """The dynamics spec, its compiled model and chain, the repairs and the locked joints."""
    source = str(path)
    spec, repairs = read_spec(path)
    is_urdf, own_rule = _urdf(path)
    spec.compiler.fusestatic = False  # keep a URDF's fixed tool0 link as a body of its own
    if is_urdf and not own_rule:
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    repairs += drop_absent_meshes(spec, source)
    spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    probe = _probe(spec, source)
    chain = read_chain(probe, source)
    locked = _arm_only(spec, probe, chain, source)
    bounded = _bound_moving(spec, probe, chain, source)
    model = compile_spec(spec, source)
    rm = read_chain(model, source)
    notes = {b: text for b, (_, _, text) in bounded.items()}
    for k, axis in enumerate(_axis_inertia(model, rm, bounded)):
        if axis > _AXIS_TINY:
            continue
        j = rm.joints[k]
        jname = _name(model, _OBJ.mjOBJ_JOINT, j)
        mine = [b for b in _subtree(model, int(model.jnt_bodyid[j]))
                if b in bounded and bounded[b][1].any()]
        if not mine:
            raise ConfigError(f"--robot {source}: joint {jname!r} has no inertia about its "
                              "axis: the file's inertials are missing; dynamics needs them")
        notes[mine[0]] += f"; the file gives {jname!r} no other inertia about its axis"
    return spec, model, rm, repairs + tuple(notes[b] for b in sorted(notes)), locked


def dynamics_spec(path: str | Path) -> tuple[mujoco.MjSpec, tuple[str, ...]]:
    """The editable spec of :func:`dynamics_model` (every repair made, joints beyond the flange
    locked), for a caller that adds to the arm before compiling (a twin's concealed effect),
    and the repairs."""
    spec, _, _, repairs, _ = _read(Path(path))
    return spec, repairs


def dynamics_model(path: str | Path) -> DynamicsRobot:
    """The robot file's arm as a dynamics model (module docstring); ConfigError, one line, for
    a file that cannot be one."""
    path = Path(path)
    _, model, rm, repairs, locked = _read(path)
    kind, fid = rm.flange
    pose, rot = np.eye(4), np.zeros(9)
    if kind == "site":
        fbody = int(model.site_bodyid[fid])
        mujoco.mju_quat2Mat(rot, model.site_quat[fid])
        pose[:3, :3], pose[:3, 3] = rot.reshape(3, 3), model.site_pos[fid]
    else:
        fbody = fid
    dof = list(rm.dof)
    return DynamicsRobot(
        model=model, name=mujoco.mj_id2name(model, _OBJ.mjOBJ_MODEL, 0) or path.stem,
        source=str(path), joints=rm.joints,
        joint_names=tuple(_name(model, _OBJ.mjOBJ_JOINT, j) for j in rm.joints),
        qpos=tuple(map(int, rm.qpos)), dof=tuple(map(int, dof)),
        moved=tuple(_subtree(model, int(model.jnt_bodyid[j])) for j in rm.joints),
        flange_body=fbody, flange_pose=_frozen(pose), gravity=_frozen(model.opt.gravity),
        armature=_frozen(model.dof_armature[dof]), damping=_frozen(model.dof_damping[dof]),
        frictionloss=_frozen(model.dof_frictionloss[dof]), repairs=repairs, locked=locked)
