"""serpar's own Panda with the physics a diagnosis established, as one MJCF (``serpar
export-mjcf``, ``diagnose --mjcf`` without ``--robot``): the arm of assets/arm/panda.xml with
the changes of :func:`serpar.sim.plants.arm_changes.apply_arm_plant`, written by the
full-precision writer (:mod:`serpar.sim.mjcf_writer`), stepping at the cell's timestep."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco

from serpar.errors import ConfigError
from serpar.sim.arm import (
    ACTUATOR_NAMES,
    FLANGE_D,
    JOINT_NAMES,
    TORQUE_SENSOR_NAMES,
    build_arm_spec,
)
from serpar.sim.mjcf_bindings import (
    EXPORT_TEXT,
    MODEL_TEXT,
    Binding,
    ExportRecord,
    bind,
    friction_bindings,
    payload_record,
)
from serpar.sim.mjcf_notes import NO_MJCF_FORM, Where, effect_notes, not_expressed_lines
from serpar.sim.mjcf_writer import MjcfExport, write_export
from serpar.sim.model_file import DiagnosisModel, model_dict
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.arm_changes import (
    FLANGE_BODY,
    PAYLOAD_BODY,
    ArmPlantChanges,
    apply_arm_plant,
)
from serpar.sim.plants.from_model_file import APPLY, KNOWN_EFFECTS, arm_plant_changes

BUILT_IN = "built-in"
DRIVE_TORQUE = {e: f"{why}; serpar's cell applies it as a drive torque before every step "
                   "(sim/plants/drive_friction.py)" for e, why in NO_MJCF_FORM.items()}
"""The cell's drive-friction effects, which the plant takes and an MJCF cannot express."""
MODEL_NAME = "serpar_panda_diagnosed"


def arm_spec(changes: ArmPlantChanges) -> mujoco.MjSpec:
    """The arm's spec with ``changes``, stepping at the cell's timestep, its joints' dry
    friction rows as stiff as the cell's (``PhysicsConfig.arm_friction_timeconst``)."""
    physics = PhysicsConfig()
    spec = build_arm_spec()
    spec.option.timestep = physics.timestep
    apply_arm_plant(spec, changes, spec.option.timestep)
    for joint in JOINT_NAMES:
        spec.joint(joint).solref_friction = [physics.arm_friction_timeconst, 1.0]
    return spec


def panda_record(model: DiagnosisModel, m: mujoco.MjModel) -> ExportRecord:
    """The bindings of the Panda's elements (:mod:`serpar.sim.mjcf_bindings`): ``m`` is the
    exported arm compiled."""
    nominal = build_arm_spec()
    damping = tuple(float(nominal.joint(n).damping[0]) for n in JOINT_NAMES)
    out: list[Binding] = friction_bindings(model, m, JOINT_NAMES, damping)
    out += [bind(m, "link_inertia", f"link{j}", ("body", f"link{j}", "mass"),
                 nominal.body(f"link{j}").mass, "scale") for j in range(1, len(JOINT_NAMES) + 1)]
    out += [bind(m, "armature", f"Ia{j}", ("joint", name, "armature"),
                 nominal.joint(name).armature) for j, name in enumerate(JOINT_NAMES, 1)]
    if "encoder_offset" in model.effects:  # the offsets the diagnosis fits, and no others
        for name in model.block("encoder_offset").names:
            j = int(name.removeprefix("offset"))
            out.append(bind(m, "encoder_offset", name, ("joint", JOINT_NAMES[j - 1], "ref"),
                            0.0))
    out.append(bind(m, "latency", "delay", ("actuator", ACTUATOR_NAMES[0], "delay"), 0.0))
    out.append(bind(m, "sensor_timing", "lag", ("sensor", TORQUE_SENSOR_NAMES[0], "delay"),
                    0.0))
    form = "extent" if "payload" in model.effects and "Lxx" in model.block("payload").names \
        else "inertia"
    return ExportRecord(BUILT_IN, tuple(out),
                        payload_record(m, PAYLOAD_BODY, FLANGE_BODY, (0.0, 0.0, FLANGE_D), form))


def panda_export_spec(model: DiagnosisModel) -> tuple[mujoco.MjSpec, ArmPlantChanges]:
    """The exported arm: the plant, its name, the model it carries and the bindings."""
    changes = arm_plant_changes(model)
    spec = arm_spec(changes)
    spec.modelname = MODEL_NAME
    record = panda_record(model, spec.compile())
    spec.add_text(name=MODEL_TEXT, data=json.dumps(model_dict(model), sort_keys=True))
    spec.add_text(name=EXPORT_TEXT, data=record.to_json())
    return spec, changes


def _place(effect: str, j: int | None) -> list[Where]:
    if effect in ("joint_friction", "link_friction", "encoder_offset", "encoder", "armature"):
        return [("joint", JOINT_NAMES[j - 1])] if j and j <= len(JOINT_NAMES) else []
    if effect in ("link_inertia", "geometric"):
        return [("body", f"link{j}")] if j and j <= len(JOINT_NAMES) else []
    if effect == "payload":
        return [("body", PAYLOAD_BODY)]
    if effect == "sensor_timing":
        return [("sensor", n) for n in TORQUE_SENSOR_NAMES]
    if effect == "latency":
        return [("actuator", n) for n in ACTUATOR_NAMES]
    return []


def _header(model: DiagnosisModel, not_expressed: tuple[str, ...]) -> list[str]:
    evidence = dict(model.evidence)
    lines = [
        ("serpar export-mjcf: serpar's Panda (assets/arm/panda.xml) with the physics a "
         f"diagnosis established ({model.source or model.path})."),
        ("Every number at full precision (the shortest decimal that reads back as the same "
         "double): every compiled field equals serpar's in-memory model."),
        ("Each effect's MJCF form (e.g. joint_friction: frictionloss = Fc, damping = nominal + "
         "Fv): serpar/sim/plants/from_model_file.py."),
        ("Every joint's solreffriction is serpar's (PhysicsConfig.arm_friction_timeconst): "
         "MuJoCo's default 0.02 s friction row pushes a joint braked faster than v/0.02 s "
         "along its motion."),
        "Established effects: " + (", ".join(model.effects) or "none") + "."]
    lines += [f"  {e}: {evidence[e]}" for e in model.effects if e in evidence]
    lines += not_expressed_lines(not_expressed)
    lines.append(f'The model itself: <custom><text name="{MODEL_TEXT}">; an element edited '
                 "after export wins over it when serpar reads the file back.")
    return lines


def export_panda_mjcf(model: DiagnosisModel, out: str | Path) -> MjcfExport:
    """Write ``model`` (its established effects) as one MJCF of serpar's Panda at ``out``."""
    foreign = [e for e in model.effects if e not in KNOWN_EFFECTS]
    if foreign:
        raise ConfigError(f"{model.path}: effect(s) {', '.join(foreign)} are not the arm's; "
                          f"export-mjcf writes the arm ({', '.join(APPLY)}); a Stewart model "
                          "goes to serpar run as its .stewart_params.json")
    spec, changes = panda_export_spec(model)
    drive = tuple(e for e in model.effects if e in DRIVE_TORQUE)
    applied = tuple(e for e in model.effects if e in APPLY and e not in drive)
    not_expressed = tuple(f"{e}: {DRIVE_TORQUE[e]}" for e in drive) + changes.not_applied
    notes = effect_notes(model, applied, _place)
    return write_export(spec, out, _header(model, not_expressed), notes, applied, not_expressed)
