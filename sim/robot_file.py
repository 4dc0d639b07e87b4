"""An arm read from its model file, URDF or MJCF (``--robot FILE``): the serial chain of hinge
joints from the world to the flange, its joint limits, and its nominal MD-H(+beta) table
(:func:`serpar.kinematics.robot.mdh_from_axes` of the compiled joint axes at q = 0).

The file is read as published (:func:`read_spec`): a URDF that MuJoCo's reader refuses for a
repeated element is repaired where that is unambiguous (:mod:`serpar.sim.robot_repair`). For
the kinematics, meshes are dropped before compiling: the kinematics do not need them, and a
URDF's ``package://`` mesh paths do not resolve outside ROS. Bodies left without mass then get
MuJoCo's lower bound (``boundmass``) so the model compiles; the masses matter only to the
nominal gravity torques (:func:`gravity_torques`), never to the kinematics. The file's masses
and inertias as they are, for dynamics: :func:`serpar.sim.robot_dynamics.dynamics_model`.

The flange is the first site or body named one of :data:`FLANGE_NAMES`, else the last
jointed body's frame. The chain is the joints on the path from the world to the flange; joints
beyond the flange (a gripper) are not the arm's and are left out; any other joint (a second
branch, a slide joint or a floating base on the path) is one line saying what was found.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.kinematics.robot import PANDA, Robot, mdh_from_axes
from serpar.sim.robot_repair import repair_urdf

FLANGE_NAMES = ("flange", "tool0", "attachment_site", "ee_site", "end_effector")
"""Names under which a model marks its flange (Franka, ROS-Industrial, MuJoCo Menagerie)."""
FORMATS = ".urdf, .xml (MJCF)"
_JOINT_TYPES = {int(mujoco.mjtJoint.mjJNT_FREE): "free", int(mujoco.mjtJoint.mjJNT_BALL): "ball",
                int(mujoco.mjtJoint.mjJNT_SLIDE): "slide (prismatic)",
                int(mujoco.mjtJoint.mjJNT_HINGE): "hinge"}


@dataclass(frozen=True)
class RobotModel:
    """The compiled model and where its chain sits in it."""

    model: mujoco.MjModel
    joints: tuple[int, ...]
    """Joint ids of the chain, base to flange."""
    flange: tuple[str, int]
    """(``site`` or ``body``, id) of the flange frame."""

    @property
    def qpos(self) -> NDArray[np.int64]:
        return np.asarray(self.model.jnt_qposadr[list(self.joints)], np.int64)

    @property
    def dof(self) -> NDArray[np.int64]:
        return np.asarray(self.model.jnt_dofadr[list(self.joints)], np.int64)


def mujoco_error(exc: Exception) -> str:
    """MuJoCo's message on one line (its second line names the element at fault)."""
    return "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())


def read_spec(path: str | Path) -> tuple[mujoco.MjSpec, tuple[str, ...]]:
    """The model file as MuJoCo reads it, and the repairs that made it readable (only for a
    URDF that MuJoCo refuses for a repeated element; :mod:`serpar.sim.robot_repair`)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"--robot {path}: no such file; give a URDF or MJCF file ({FORMATS})")
    try:
        return mujoco.MjSpec.from_file(str(path)), ()
    except Exception as exc:  # noqa: BLE001 (MuJoCo raises ValueError or its own kinds)
        why = mujoco_error(exc)
    if "repeated element" in why:
        try:
            text, repairs = repair_urdf(path)
            spec = mujoco.MjSpec.from_string(text) if repairs else None
        except ConfigError:
            raise
        except Exception as exc:  # noqa: BLE001
            why = f"{why}; after repairing the repeats: {mujoco_error(exc)}"
        else:
            if spec is not None:  # else a repeat this reader does not repair: MuJoCo's words
                spec.modelfiledir = f"{path.resolve().parent}/"  # relative meshes, as from_file
                return spec, repairs
    raise ConfigError(f"--robot {path}: MuJoCo cannot read it ({why}); give a URDF or MJCF "
                      f"file ({FORMATS})")


def robot_spec(path: str | Path) -> mujoco.MjSpec:
    """The model file as an editable spec, meshes removed (module docstring)."""
    spec, _ = read_spec(path)
    spec.compiler.fusestatic = False  # keep a URDF's fixed tool0 link as a body of its own
    for geom in [g for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH]:
        spec.delete(geom)
    for mesh in list(spec.meshes):
        spec.delete(mesh)
    spec.compiler.boundmass = max(spec.compiler.boundmass, 1e-3)
    spec.compiler.boundinertia = max(spec.compiler.boundinertia, 1e-6)
    return spec


def compile_spec(spec: mujoco.MjSpec, path: str | Path) -> mujoco.MjModel:
    try:
        return spec.compile()
    except Exception as exc:  # noqa: BLE001
        raise ConfigError(f"--robot {path}: MuJoCo cannot compile it "
                          f"({mujoco_error(exc)})") from None


def _flange(model: mujoco.MjModel) -> tuple[str, int]:
    for name in FLANGE_NAMES:
        for kind, obj in (("site", mujoco.mjtObj.mjOBJ_SITE), ("body", mujoco.mjtObj.mjOBJ_BODY)):
            i = mujoco.mj_name2id(model, obj, name)
            if i >= 0:
                return kind, i
    jointed = sorted({int(b) for b in model.jnt_bodyid})
    return "body", (jointed[-1] if jointed else 0)


def _path(model: mujoco.MjModel, body: int) -> list[int]:
    """Bodies from the world's child down to ``body``."""
    out = []
    while body > 0:
        out.append(body)
        body = int(model.body_parentid[body])
    return out[::-1]


def _name(model: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(model, obj, i) or f"#{i}"


def read_chain(model: mujoco.MjModel, source: str) -> RobotModel:
    """The chain of hinge joints from the world to the flange; ConfigError naming what else
    was found (another joint type on the path, a joint on a branch off it, no joint)."""
    kind, fid = _flange(model)
    fbody = int(model.site_bodyid[fid]) if kind == "site" else fid
    on_path = set(_path(model, fbody))
    chain, branch = [], []
    for j in range(model.njnt):
        body = int(model.jnt_bodyid[j])
        if body in on_path:
            chain.append(j)
        elif fbody not in _path(model, body):  # not distal to the flange: a second branch
            branch.append(j)

    def jname(j: int) -> str:
        return _name(model, mujoco.mjtObj.mjOBJ_JOINT, j)

    obj = mujoco.mjtObj.mjOBJ_SITE if kind == "site" else mujoco.mjtObj.mjOBJ_BODY
    where = f"{kind} {_name(model, obj, fid)!r}"
    if branch:
        raise ConfigError(f"--robot {source}: not a single serial chain: joint(s) "
                          f"{', '.join(repr(jname(j)) for j in branch)} lie on a branch off the "
                          f"path from the base to the flange ({where}); give an arm with one "
                          f"chain, or name its flange one of {', '.join(FLANGE_NAMES)}")
    other = [j for j in chain if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE]
    if other:
        raise ConfigError(f"--robot {source}: the chain to the flange ({where}) has "
                          + ", ".join(f"a {_JOINT_TYPES[int(model.jnt_type[j])]} joint "
                                      f"{jname(j)!r}" for j in other)
                          + "; only hinge (revolute) joints are supported")
    if not chain:
        raise ConfigError(f"--robot {source}: no hinge joint between the base and the flange "
                          f"({where}); not an arm")
    return RobotModel(model, tuple(chain), (kind, fid))


def _zero_kinematics(rm: RobotModel) -> mujoco.MjData:
    data = mujoco.MjData(rm.model)
    data.qpos[rm.qpos] = 0.0  # q = 0 is qpos = 0 (a joint's ref only moves qpos0)
    mujoco.mj_kinematics(rm.model, data)
    return data


def _frame(rot: NDArray[np.float64], pos: NDArray[np.float64]) -> NDArray[np.float64]:
    t = np.eye(4)
    t[:3, :3] = np.asarray(rot).reshape(3, 3)
    t[:3, 3] = pos
    return t


@lru_cache(maxsize=8)
def load_robot_model(path: str) -> RobotModel:
    """The compiled model file and its chain (cached: every reader of one file shares it)."""
    return read_chain(compile_spec(robot_spec(path), path), path)


def robot_from_model(rm: RobotModel, name: str, source: str) -> Robot:
    m, d = rm.model, _zero_kinematics(rm)
    j = list(rm.joints)
    bodies = np.array([_frame(d.xmat[b], d.xpos[b]) for b in m.jnt_bodyid[j]])
    kind, fid = rm.flange
    flange = (_frame(d.site_xmat[fid], d.site_xpos[fid]) if kind == "site"
              else _frame(d.xmat[fid], d.xpos[fid]))
    base, links, fl = mdh_from_axes(d.xaxis[j], d.xanchor[j], bodies, flange)
    limited = np.asarray(m.jnt_limited[j], bool)
    rng = np.asarray(m.jnt_range[j], float)
    # an unlimited hinge turns freely: +-pi covers every angle it can report once wrapped
    q_min = np.where(limited, rng[:, 0], -np.pi)
    q_max = np.where(limited, rng[:, 1], np.pi)
    return Robot(name, base, links, fl, tuple(map(float, q_min)), tuple(map(float, q_max)),
                 source)


def load_robot(path: str | Path | None) -> Robot:
    """The arm of a URDF/MJCF file (named after the model, else the file); None: the Panda."""
    if path is None:
        return PANDA
    rm = load_robot_model(str(path))
    name = mujoco.mj_id2name(rm.model, mujoco.mjtObj.mjOBJ_MODEL, 0) or Path(path).stem
    return robot_from_model(rm, name, str(path))


def gravity_torques(robot: Robot, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N, n) gravity torques [N m] of the robot file's own inertials at joint angles q (the
    nominal model a controller of that arm would use); zero for a built-in robot without file."""
    q = np.atleast_2d(np.asarray(q, float))
    if robot.source == "built-in":
        return np.zeros_like(q)
    rm = load_robot_model(robot.source)
    data = mujoco.MjData(rm.model)
    tau = np.empty_like(q)
    for k, row in enumerate(q):
        data.qpos[rm.qpos] = row
        data.qvel[:] = 0.0
        mujoco.mj_forward(rm.model, data)
        tau[k] = -data.qfrc_bias[rm.dof]
    return tau
