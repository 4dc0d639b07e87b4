"""The user's own arm with the physics a diagnosis established, as one MJCF (``serpar diagnose
REC --robot FILE --mjcf OUT.xml``, ``serpar export-mjcf M --robot FILE``): the arm of FILE as
serpar's dynamics model reads it (:meth:`serpar.sim.rigid_arm.ArmModel.make_spec`, a URDF
converted by MuJoCo, every repair named in the header), the file's own contact setting, and
each established effect written into its elements:

| effect | MJCF |
|---|---|
| joint_friction, link_friction | joint ``frictionloss`` = Fc (the sum of both), ``damping`` = the file's + Fv |
| armature | joint ``armature`` = the file's + Ia |
| payload | a body on the flange body at the flange, its inertial at the CoM |
| link_inertia | link j's mass and inertia x (1 + link<j>), CoM kept |
| encoder_offset | joint ``ref`` = the file's + offset |

Fc replaces the file's frictionloss: the diagnosis's nominal prediction (``mj_rne``) has no dry
friction, so Fc is the joint's whole Coulomb level. What MJCF cannot express for this arm
(:data:`WHY_NOT`) stays in the model text the file carries, named in the header.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim.arm_from_file import arm_from_file
from serpar.sim.mjcf_bindings import (
    EXPORT_TEXT,
    FRICTION,
    MODEL_TEXT,
    ExportRecord,
    bind,
    friction_bindings,
    payload_record,
)
from serpar.sim.mjcf_notes import (
    NO_MJCF_FORM,
    Where,
    effect_notes,
    evidence_of,
    joint_of,
    not_expressed_lines,
)
from serpar.sim.mjcf_writer import MjcfExport, write_export
from serpar.sim.model_file import DiagnosisModel, model_dict
from serpar.sim.plants.arm_changes import EXTENT, PayloadBody, inertia_from_extent, inertia_problem
from serpar.sim.plants.from_model_file import (
    NOT_APPLICABLE,
    PAYLOAD,
    PAYLOAD_EXTENT,
    POINT_MASS_INERTIA,
)
from serpar.sim.rigid_arm import ArmModel
from serpar.sim.robot_dynamics import dynamics_model
from serpar.sim.robot_file import read_spec
from serpar.sim.tilt import tilted_gravity

PAYLOAD_NAME = "serpar_payload"
EXPRESSED = ("joint_friction", "link_friction", "armature", "payload", "link_inertia",
             "encoder_offset", "base_tilt")
WHY_NOT: dict[str, str] = {
    **NOT_APPLICABLE,
    "latency": "an actuation delay is an actuator's delay, and serpar's model of the arm keeps "
               "none of the file's actuators (they are its controller's)",
    "sensor_timing": "a torque sensor's delay, and serpar's model of the arm has no sensors",
    **NO_MJCF_FORM,
    "coupled_pair": "one motor turning two joints loads one joint's drive with another joint's "
                    "motion; a MuJoCo joint's armature and friction act on its own motion only",
    "geometric": "serpar's geometric parameters are errors of MD-H frames; the file's link "
                 "frames are its own",
    "link_inertial": "base inertial parameters are combinations of the links' masses, first "
                     "moments and inertias: they do not give each body its own inertial",
}


@dataclass(frozen=True)
class RobotPlant:
    spec: mujoco.MjSpec
    applied: tuple[str, ...]
    not_expressed: tuple[str, ...]
    arm: ArmModel


def why_not(effect: str) -> str:
    """Why MJCF cannot express ``effect`` for an arm from its file."""
    if effect.startswith("coupled_pair"):
        return WHY_NOT["coupled_pair"]
    return WHY_NOT.get(effect, "no MJCF form in serpar's exporter")


def friction_values(model: DiagnosisModel, n: int, damping: np.ndarray, notes: list[str]
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """(frictionloss, damping) per joint from the model's friction effects (None: none
    established); ``damping``: the file's. Negative values are applied as 0 and noted."""
    present = [e for e in FRICTION if e in model.effects]
    if not present:
        return None
    loss, damp = np.zeros(n), np.array(damping, float)
    for effect in present:
        p = model.block(effect).as_dict()
        for j in range(1, n + 1):
            fc, fv = p.get(f"Fc{j}", 0.0), p.get(f"Fv{j}", 0.0)
            if fc < 0:
                notes.append(f"{effect} Fc{j} = {fc:.3g} N m < 0: applied as 0")
            loss[j - 1] += max(fc, 0.0)
            damp[j - 1] += fv
    for j in np.flatnonzero(damp < 0):
        notes.append(f"friction takes joint {j + 1}'s damping below 0: applied as 0")
    return loss, np.maximum(damp, 0.0)


def _payload(spec: mujoco.MjSpec, arm: ArmModel, model: DiagnosisModel, notes: list[str]) -> str:
    """Add the payload body; its name ("" where not applied)."""
    block = model.block("payload")
    p = block.as_dict()
    form = PAYLOAD_EXTENT if "Lxx" in p else PAYLOAD
    missing = [n for n in form if n not in p]
    if missing:
        raise ConfigError(f"{model.path}: payload parameter(s) {', '.join(missing)} missing; "
                          f"a body needs all of {', '.join(PAYLOAD)} (or {', '.join(EXTENT)})")
    if p["mass"] <= 0:
        notes.append(f"payload: fitted mass {p['mass']:.3g} kg <= 0, no body has it: not applied")
        return ""
    inertia = (inertia_from_extent(p["mass"], tuple(p[n] for n in EXTENT))
               if form is PAYLOAD_EXTENT else tuple(p[n] for n in PAYLOAD[4:]))
    if inertia_problem(inertia):
        notes.append(f"payload inertia not physical ({inertia_problem(inertia)}): applied as a "
                     "point mass")
        inertia = (POINT_MASS_INERTIA,) * 3 + (0.0,) * 3
    body = PayloadBody(p["mass"], (p["com_x"], p["com_y"], p["com_z"]), inertia)  # type: ignore[arg-type]
    taken = {b.name for b in spec.bodies}
    name = next(n for n in [PAYLOAD_NAME] + [f"{PAYLOAD_NAME}{k}" for k in range(2, 99)]
                if n not in taken)  # an exported file read as the arm has one already
    el = spec.body(arm.flange_body).add_body(name=name, pos=list(arm.flange_pos))
    el.explicitinertial = True
    el.mass, el.ipos, el.fullinertia = body.mass, list(body.com), list(body.inertia)
    return name


def _links(spec: mujoco.MjSpec, arm: ArmModel, model: DiagnosisModel, notes: list[str]) -> None:
    p = model.block("link_inertia").as_dict()
    for j, name in enumerate(arm.link_bodies, 1):
        scale = p.get(f"link{j}", 0.0)
        if not scale:
            continue
        if scale <= -1:
            notes.append(f"link_inertia link{j} = {scale:.3g}: no mass left, not applied")
            continue
        body = spec.body(name)
        if not body.explicitinertial:  # its inertia from its geoms: make it the body's own
            spec.adopt_inertial(body)
        body.mass *= 1.0 + scale  # first moment and inertia with it: the CoM stays
        if np.all(np.isfinite(body.fullinertia)):
            body.fullinertia = [v * (1.0 + scale) for v in body.fullinertia]
        else:
            body.inertia = [v * (1.0 + scale) for v in body.inertia]


def fitted_arm(model: DiagnosisModel, robot: str | Path) -> ArmModel:
    """The arm of ``robot``; ConfigError where ``model``'s joints are not all its joints."""
    arm = arm_from_file(str(robot))
    top = max([joint_of(n) or 0 for e in model.effects if e in EXPRESSED and e != "payload"
               for n in model.block(e).names] + [0])
    if top > arm.n:
        raise ConfigError(f"{model.path}: its parameters reach joint {top}, the robot "
                          f"{arm.name} ({robot}) has {arm.n} joints: export it with the arm it "
                          "was fitted on (--robot)")
    return arm


def robot_plant(model: DiagnosisModel, robot: str | Path) -> tuple[RobotPlant, str]:
    """The arm of ``robot`` with ``model``'s effects (what was clamped or left out among its
    ``not_expressed``), and the payload body's name ("" where none)."""
    arm = fitted_arm(model, robot)
    spec = arm.make_spec()
    spec.option.disableflags = read_spec(robot)[0].option.disableflags  # the file's contacts
    nominal = spec.compile()
    dofs = [int(nominal.joint(n).dofadr[0]) for n in arm.joint_names]
    notes: list[str] = []
    joints = [spec.joint(n) for n in arm.joint_names]
    friction = friction_values(model, arm.n, nominal.dof_damping[dofs], notes)
    if friction is not None:
        for joint, loss, damp in zip(joints, *friction):
            joint.frictionloss = float(loss)
            damping = np.array(joint.damping, float)  # [linear, higher-order terms]
            damping[0] = damp
            joint.damping = damping
    if "armature" in model.effects:
        p = model.block("armature").as_dict()
        for j, joint in enumerate(joints, 1):
            value = joint.armature + p.get(f"Ia{j}", 0.0)
            if value < 0:
                notes.append(f"armature Ia{j} takes joint {j}'s armature below 0: applied as 0")
            joint.armature = max(value, 0.0)
    if "encoder_offset" in model.effects:  # offset = measured - true = qpos - link angle
        degree = bool(spec.compiler.degree)  # an MJCF in degrees (a URDF is in radians)
        for name, value in model.block("encoder_offset").as_dict().items():
            j = int(name.removeprefix("offset"))
            joints[j - 1].ref += float(np.degrees(value)) if degree else value
    if "link_inertia" in model.effects:
        _links(spec, arm, model, notes)
    if "base_tilt" in model.effects:  # the base is the world here: gravity turns in it
        p = model.block("base_tilt").as_dict()
        spec.option.gravity = tilted_gravity(np.array(spec.option.gravity, float),
                                             np.array([p["alpha"], p["beta"]]))[0]
    payload = _payload(spec, arm, model, notes) if "payload" in model.effects else ""
    applied = tuple(e for e in model.effects if e in EXPRESSED)
    not_expressed = [f"{e}: {why_not(e)}" for e in model.effects if e not in EXPRESSED]
    not_expressed += notes + [f"{b}: the recording's own baseline (refitted on every "
                              "recording), not the arm's physics" for b in model.baseline_blocks]
    if model.empirical:
        not_expressed.append(f"empirical: {len(model.empirical)} term(s) describing residual no "
                             "effect explains; a description, not physics")
    return RobotPlant(spec, applied, tuple(not_expressed), arm), payload


def robot_export_spec(model: DiagnosisModel, robot: str | Path) -> tuple[RobotPlant, str]:
    """The exported arm: the plant, the model it carries and the bindings; the payload body."""
    plant, payload = robot_plant(model, robot)
    spec, arm = plant.spec, plant.arm
    m = spec.compile()
    nominal = arm.make_spec().compile()
    dof = {n: int(nominal.joint(n).dofadr[0]) for n in arm.joint_names}
    bindings = friction_bindings(model, m, arm.joint_names,
                                 tuple(float(nominal.dof_damping[dof[n]]) for n in arm.joint_names))
    for j, name in enumerate(arm.joint_names, 1):
        bindings.append(bind(m, "armature", f"Ia{j}", ("joint", name, "armature"),
                             nominal.dof_armature[dof[name]]))
    for j, body in enumerate(arm.link_bodies, 1):
        bindings.append(bind(m, "link_inertia", f"link{j}", ("body", body, "mass"),
                             nominal.body(body).mass[0], "scale"))
    if "encoder_offset" in model.effects:
        for name in model.block("encoder_offset").names:
            joint = arm.joint_names[int(name.removeprefix("offset")) - 1]
            bindings.append(bind(m, "encoder_offset", name, ("joint", joint, "ref"),
                                 nominal.qpos0[int(nominal.joint(joint).qposadr[0])]))
    form = "extent" if payload and "Lxx" in model.block("payload").names else "inertia"
    record = ExportRecord(str(Path(robot).resolve()), tuple(bindings),
                          payload_record(m, payload, arm.flange_body, arm.flange_pos, form)
                          if payload else None)
    for text in [t for t in spec.texts if t.name in (MODEL_TEXT, EXPORT_TEXT)]:
        spec.delete(text)  # an exported file read as the arm: its model is now the nominal
    spec.add_text(name=MODEL_TEXT, data=json.dumps(model_dict(model), sort_keys=True))
    spec.add_text(name=EXPORT_TEXT, data=record.to_json())
    return plant, payload


def _header(model: DiagnosisModel, plant: RobotPlant, robot: str | Path, payload: str) -> list[str]:
    arm, original = plant.arm, read_spec(robot)[0]
    left = [f"{len(getattr(original, k))} {k}" for k in ("actuators", "sensors", "keys",
                                                          "tendons", "equalities")
            if getattr(original, k)]
    locked = dynamics_model(robot).locked
    lines = [
        (f"serpar (diagnose, export-mjcf): the arm of {robot} ({arm.n} joints: "
         f"{', '.join(arm.joint_names)}) as serpar's dynamics model reads it, with the physics "
         f"a diagnosis established ({model.source or model.path})."),
        ("Every number at full precision (the shortest decimal that reads back as the same "
         "double): every compiled field equals serpar's in-memory model."),
        ("Left out of serpar's model of the file (its controller's, not the arm's): "
         + (", ".join(left) if left else "nothing") + "; joints beyond the flange locked: "
         + (", ".join(locked) if locked else "none") + "."),
        *arm.notes,
        ("MJCF forms: friction: frictionloss = Fc (the whole Coulomb level: the diagnosis's "
         "nominal prediction has no dry friction, so the file's frictionloss is replaced), "
         "damping = the file's + Fv; armature = the file's + Ia; "
         + (f"payload: body {payload} on {arm.flange_body} at the flange; " if payload else "")
         + "link_inertia: each link body's mass and inertia x (1 + link<j>), CoM kept; "
         "encoder_offset: joint ref = the file's + offset."),
        "Established effects: " + (", ".join(model.effects) or "none") + "."]
    lines += [f"  {e}: {evidence_of(model, e)}" for e in model.effects]
    lines += not_expressed_lines(plant.not_expressed)
    lines.append(f'The model itself: <custom><text name="{MODEL_TEXT}">; serpar diagnose takes it '
                 f"back as its model (with {Path(robot).name} as the robot), an element edited "
                 "after export winning over it.")
    return lines


def export_robot_mjcf(model: DiagnosisModel, robot: str | Path, out: str | Path) -> MjcfExport:
    """Write the arm of ``robot`` with ``model``'s established effects at ``out``."""
    if model.kind.startswith("stewart"):
        raise ConfigError(f"{model.path}: a Stewart platform's model ({model.kind}), not an "
                          "arm's; it goes to serpar run as its .stewart_params.json")
    plant, payload = robot_export_spec(model, robot)
    arm = plant.arm

    def place(effect: str, j: int | None) -> list[Where]:
        if effect in ("joint_friction", "link_friction", "armature", "encoder_offset"):
            return [("joint", arm.joint_names[j - 1])] if j and j <= arm.n else []
        if effect == "link_inertia":
            return [("body", arm.link_bodies[j - 1])] if j and j <= arm.n else []
        return [("body", payload)] if effect == "payload" and payload else []

    notes = effect_notes(model, plant.applied, place)
    return write_export(plant.spec, out, _header(model, plant, robot, payload), notes,
                        plant.applied, plant.not_expressed)
