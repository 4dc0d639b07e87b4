"""A diagnosis model file turned into changes of the simulated arm (sim/plants/arm_changes.py), so that
`serpar run` simulates the cell the diagnosis found, not the nominal one.

Per effect (parameter names as the families write them: arm_dynamics_effects.py,
arm_static_effects.py, kinematics/mdh.py):

| effect | parameters | plant |
|---|---|---|
| joint_friction | Fc<j> [N m], Fv<j> [N m s/rad] | joint ``frictionloss`` = Fc; ``damping`` = nominal + Fv |
| link_friction | as joint_friction | added to the same (the cell's sensors then read it as drive friction: noted) |
| payload | mass, com_x/y/z (from the flange), Ixx..Iyz (about the CoM) or the extent Lxx..Lzz | a body on link 7 at the flange |
| link_inertia | link<j> (relative) | link j's mass and inertia x (1 + link<j>) |
| encoder_offset | offset<j> = measured - true [rad] | joint ``ref`` = offset |
| encoder | o<j> (link = (1 + s) q + o), s<j> | joint ``ref`` = -o; the scale s is not expressible |
| geometric | j<i>.alpha/a/theta/d/beta | body link<i>'s pos/quat (beta: the next frame) |
| latency | delay [s] | arm actuators' ``delay`` |
| sensor_timing | lag [s] | the joint torque sensors' ``delay`` (linear between steps) |
| sigmoid_friction | phi1_j [N m], phi2_j [s/rad], phi3_j [rad/s] | a drive torque before every substep (sim/plants/drive_friction.py), beside joint_friction's |
| stribeck_friction | dFs<j> [N m], vs<j> [rad/s] | the same drive torque: dFs exp(-(v/vs)^2), its sign smoothed |
| armature | Ia<j> [kg m^2] | joint ``armature`` = nominal + Ia (at least 0) |

Not expressible, and reported (``ArmPlantChanges.not_applied``), with the reason in
:data:`NOT_APPLICABLE`. A value the plant cannot take (negative friction or mass, a non-physical
inertia tensor) is clamped or left out, and reported too: nothing is dropped silently.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from serpar.errors import ConfigError
from serpar.sim.arm import JOINT_NAMES, N_JOINTS, build_arm_spec
from serpar.sim.model_file import DiagnosisModel, ParamBlock, read_model_file
from serpar.sim.plants.arm_changes import (
    EXTENT,
    MDH_PARAMS,
    ArmPlantChanges,
    PayloadBody,
    inertia_from_extent,
    inertia_problem,
)
from serpar.sim.plants.drive_friction import SPEEDS, STEEPNESS, DriveFrictionLaw

J = range(1, N_JOINTS + 1)
NOT_APPLICABLE: dict[str, str] = {
    "joint_compliance": "a compliant joint needs a passive stiff hinge between motor and link "
                        "(an extra DoF per joint that the arm's controllers, recordings and "
                        "qpos addresses do not have)",
    "backlash": "a clearance needs a passive limited hinge between motor and link (an extra "
                "DoF per joint that the arm's controllers, recordings and qpos addresses do "
                "not have)",
    "thermal_drift": "link lengths that grow with elapsed time: an MjModel's geometry is fixed "
                     "for an episode",
    "torque_sensor": "a torque sensor's gain is its calibration, not physics: MuJoCo's torque "
                     "sensors have no gain",
    "base_tilt": "a tilted arm base is not yet mapped onto the cell's arm mount (turning the "
                 "cell's gravity would tilt the platform and the plate too)",
    "encoder_scale": "a transmission-ratio error between reading and link: a MuJoCo hinge has no "
                     "gear between its qpos and the link angle",
    "coupled_pair": "the cell's Panda has one motor per joint: a coupled motor belongs to "
                    "another arm",
    "link_inertial": "base inertial parameters do not fix the links' masses, centres of mass "
                     "and inertias a MuJoCo body needs (several standard sets give them)",
    "contact_friction": "the journal/bore friction belongs to the cell's contacts, not the arm: "
                        "set the episode config's contact_friction to 0.2 + d_mu",
}
PAYLOAD = ("mass", "com_x", "com_y", "com_z", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
"""The payload as an inertia tensor about its CoM (also accepted: the extent, :data:`EXTENT`,
in place of Ixx..Iyz, as ``serpar diagnose`` fits it)."""
PAYLOAD_EXTENT = PAYLOAD[:4] + EXTENT
POINT_MASS_INERTIA = 1e-9
"""[kg m^2] Principal moments given to a payload whose fitted tensor is not physical."""


@dataclass
class _Draft:
    """The changes being collected (mutable while one file is mapped)."""

    nominal_damping: tuple[float, ...]
    fields: dict[str, object] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def per_joint(self, key: str, start: tuple[float, ...]) -> list[float]:
        return self.fields.setdefault(key, list(start))  # type: ignore[return-value]


def _names(effect: str, block: ParamBlock, valid: tuple[str, ...]) -> dict[str, float]:
    bad = [n for n in block.names if n not in valid]
    if bad:
        raise ConfigError(f"{effect}: unknown parameter(s) {', '.join(bad)}; valid: "
                          f"{', '.join(valid)}")
    return block.as_dict()


def _friction(block: ParamBlock, d: _Draft, effect: str = "joint_friction") -> None:
    p = _names(effect, block, tuple(f"Fc{j}" for j in J) + tuple(f"Fv{j}" for j in J))
    loss, damping = d.per_joint("frictionloss", (0.0,) * 7), d.per_joint("damping", d.nominal_damping)
    for j in J:
        fc, fv = p.get(f"Fc{j}", 0.0), p.get(f"Fv{j}", 0.0)
        loss[j - 1] += max(fc, 0.0)
        if fc < 0:  # the fit admits negative values so that an absent effect is not biased
            d.notes.append(f"{effect} Fc{j} = {fc:.3g} N m < 0: applied as 0")
        if damping[j - 1] + fv < 0:
            d.notes.append(f"{effect} Fv{j} = {fv:.3g} N m s/rad takes the damping below "
                           "0: applied as 0")
        damping[j - 1] = max(damping[j - 1] + fv, 0.0)


def _drive(law: DriveFrictionLaw, d: _Draft) -> None:
    old = d.fields.get("drive")
    d.fields["drive"] = law if old is None else old.plus(law)  # type: ignore[union-attr]


def _sigmoid(block: ParamBlock, d: _Draft) -> None:
    """A joint whose phi1 is 0 (or not fitted) has no sigmoid: its phi2, phi3 do nothing."""
    p = _names("sigmoid_friction", block, tuple(f"phi{k}_{j}" for k in (1, 2, 3) for j in J))
    phi1, phi2, phi3 = [], [], []
    for j in J:
        swing = p.get(f"phi1_{j}", 0.0)
        if swing < 0:
            d.notes.append(f"sigmoid_friction phi1_{j} = {swing:.3g} N m < 0: applied as 0")
        steep = p.get(f"phi2_{j}", 1.0)
        if swing > 0 and not STEEPNESS[0] <= steep <= STEEPNESS[1]:
            d.notes.append(f"sigmoid_friction phi2_{j} = {steep:.3g} s/rad: applied as "
                           f"{STEEPNESS[0]:g}..{STEEPNESS[1]:g}")
        phi1.append(max(swing, 0.0))
        phi2.append(float(np.clip(steep, *STEEPNESS)))
        phi3.append(p.get(f"phi3_{j}", 0.0) if swing > 0 else 0.0)
    _drive(DriveFrictionLaw(sigmoids=((tuple(phi1), tuple(phi2), tuple(phi3)),)), d)


def _stribeck(block: ParamBlock, d: _Draft) -> None:
    p = _names("stribeck_friction", block, tuple(f"dFs{j}" for j in J) + tuple(f"vs{j}" for j in J))
    excess, speed = [], []
    for j in J:
        fall = p.get(f"dFs{j}", 0.0)
        if fall < 0:
            d.notes.append(f"stribeck_friction dFs{j} = {fall:.3g} N m < 0 (static friction "
                           "below the Coulomb level): applied as 0")
        excess.append(max(fall, 0.0))
        speed.append(float(np.clip(p.get(f"vs{j}", 0.05), *SPEEDS)))
    _drive(DriveFrictionLaw(stribeck_excess=tuple(excess), stribeck_speed=tuple(speed)), d)


def _armature(block: ParamBlock, d: _Draft) -> None:
    p = _names("armature", block, tuple(f"Ia{j}" for j in J))
    d.fields["armature"] = [p.get(f"Ia{j}", 0.0) for j in J]


def _link_friction(block: ParamBlock, d: _Draft) -> None:
    _friction(block, d, "link_friction")
    d.notes.append("link_friction: applied as joint friction (the motion is the same); the "
                   "cell's torque sensors read it as friction inside the drive")


def _payload(block: ParamBlock, d: _Draft) -> None:
    form = PAYLOAD_EXTENT if "Lxx" in block.names else PAYLOAD
    p = _names("payload", block, form)
    missing = [n for n in form if n not in p]
    if missing:
        raise ConfigError(f"payload: parameter(s) {', '.join(missing)} missing; a body needs all "
                          f"of {', '.join(PAYLOAD)} (or {', '.join(EXTENT)} for Ixx..Iyz)")
    if p["mass"] <= 0:
        d.notes.append(f"payload: fitted mass {p['mass']:.3g} kg <= 0, no body has it: not applied")
        return
    inertia = (inertia_from_extent(p["mass"], tuple(p[n] for n in EXTENT)) if form is PAYLOAD_EXTENT
               else tuple(p[n] for n in PAYLOAD[4:]))
    why = inertia_problem(inertia)
    if why:
        d.notes.append(f"payload inertia not physical ({why}): applied as a point mass")
        inertia = (POINT_MASS_INERTIA,) * 3 + (0.0,) * 3
    d.fields["payload"] = PayloadBody(p["mass"], (p["com_x"], p["com_y"], p["com_z"]),
                                      inertia)  # type: ignore[arg-type]


def _links(block: ParamBlock, d: _Draft) -> None:
    p = _names("link_inertia", block, tuple(f"link{j}" for j in J))
    d.fields["link_mass_scale"] = [p.get(f"link{j}", 0.0) for j in J]


def _offsets(block: ParamBlock, d: _Draft) -> None:
    p = _names("encoder_offset", block, tuple(f"offset{j}" for j in J))
    ref = d.per_joint("joint_ref", (0.0,) * 7)
    for j in J:  # offset = measured - true = qpos - link angle = ref
        ref[j - 1] += p.get(f"offset{j}", 0.0)


def _encoder(block: ParamBlock, d: _Draft) -> None:
    p = _names("encoder", block, tuple(f"o{j}" for j in J) + tuple(f"s{j}" for j in J))
    ref = d.per_joint("joint_ref", (0.0,) * 7)
    for j in J:  # link = q + o: the reading minus the link angle is -o
        ref[j - 1] -= p.get(f"o{j}", 0.0)
        if p.get(f"s{j}", 0.0):
            d.notes.append(f"encoder s{j} = {p[f's{j}']:.3g}: a transmission-ratio error is not "
                           "expressible (a MuJoCo hinge has no gear between reading and link)")


def _geometric(block: ParamBlock, d: _Draft) -> None:
    mdh = [[0.0] * len(MDH_PARAMS) for _ in J]
    valid = tuple(f"j{j}.{k}" for j in J for k in MDH_PARAMS)
    skipped = []
    for name, value in block.as_dict().items():
        frame = name.split(".")[0]
        if frame in ("base", "tool"):
            skipped.append(f"{name} = {value:.3g}")
        elif name in valid:
            mdh[int(frame[1:]) - 1][MDH_PARAMS.index(name.split(".")[1])] = value
        else:
            raise ConfigError(f"geometric: unknown parameter {name!r}; valid: j<1-7>."
                              f"{{{','.join(MDH_PARAMS)}}}, base.*, tool.*")
    if skipped:
        d.notes.append(f"geometric {', '.join(skipped)}: the arm's mounting / the measuring tool's "
                       "frame, not the arm (a rigid motion of the whole arm leaves point-"
                       "consistency data unchanged): not applied")
    d.fields["mdh_errors"] = tuple(tuple(r) for r in mdh)


def _delay(effect: str, param: str, field_name: str, why: str) -> Callable[[ParamBlock, _Draft], None]:
    """A delay effect as a MuJoCo history ``delay``: a negative one is not physical."""
    def apply(block: ParamBlock, d: _Draft) -> None:
        value = _names(effect, block, (param,)).get(param, 0.0)
        if value < 0:
            d.notes.append(f"{effect} {param} = {value:.3g} s < 0 ({why}): not applied")
        else:
            d.fields[field_name] = value
    return apply


_latency = _delay("latency", "delay", "actuation_delay", "a command cannot act early")
_sensor_timing = _delay("sensor_timing", "lag", "torque_sensor_delay",
                        "a torque sensor cannot read ahead of the joint")


APPLY: dict[str, Callable[[ParamBlock, _Draft], None]] = {
    "joint_friction": _friction, "link_friction": _link_friction, "payload": _payload, "link_inertia": _links,
    "encoder_offset": _offsets, "encoder": _encoder, "geometric": _geometric,
    "latency": _latency, "sensor_timing": _sensor_timing, "sigmoid_friction": _sigmoid,
    "stribeck_friction": _stribeck, "armature": _armature,
}
KNOWN_EFFECTS: tuple[str, ...] = tuple(APPLY) + tuple(NOT_APPLICABLE)


def _nominal_damping() -> tuple[float, ...]:
    spec = build_arm_spec()  # the MJCF is the one source of the nominal damping
    return tuple(float(spec.joint(n).damping[0]) for n in JOINT_NAMES)


def arm_plant_changes(model: DiagnosisModel) -> ArmPlantChanges:
    """The plant changes of a validated model file; ConfigError names an unknown effect or
    parameter, or a value outside what the plant accepts."""
    unknown = [e for e in model.effects if e not in KNOWN_EFFECTS]
    if unknown:
        raise ConfigError(f"{model.path}: unknown effect(s) {', '.join(unknown)}; valid: "
                          f"{', '.join(KNOWN_EFFECTS)}")
    d = _Draft(_nominal_damping())
    try:
        for effect in model.effects:
            if effect in APPLY:
                APPLY[effect](model.block(effect), d)
            else:
                d.notes.append(f"{effect}: not applicable to the plant: {NOT_APPLICABLE[effect]}")
        if model.empirical:
            d.notes.append(f"empirical: {len(model.empirical)} term(s) describing residual no "
                           "effect explains; a description, not physics the plant can take")
        for base in model.baseline_blocks:
            d.notes.append(f"{base}: the recording's own baseline (refitted on every "
                           "recording), not plant physics")
        fields = {k: tuple(v) if isinstance(v, list) else v for k, v in d.fields.items()}
        return ArmPlantChanges(**fields, source=model.path,  # type: ignore[arg-type]
                               not_applied=tuple(d.notes))
    except ConfigError as exc:
        raise ConfigError(f"{model.path}: {exc}") from None


def arm_plant_from_file(path: str | Path) -> ArmPlantChanges:
    """Read, validate and map a model file (``EpisodeConfig.plant_model``)."""
    return arm_plant_changes(read_model_file(path))


def applied_parts(changes: ArmPlantChanges) -> list[str]:
    """The parts of the plant that ``changes`` moves off nominal, in words."""
    return [name for name, on in (
        ("joint friction", bool(changes.frictionloss or changes.damping)),
        (f"drive friction ({changes.drive.words()})" if changes.drive else "",
         bool(changes.drive)),
        ("rotor inertia (armature)", bool(changes.armature)),
        ("payload body", changes.payload is not None),
        ("link mass/inertia", bool(changes.link_mass_scale)),
        ("encoder offsets (joint ref)", bool(changes.joint_ref)),
        ("link frames (MD-H errors)", bool(changes.mdh_errors)),
        ("actuation delay", changes.actuation_delay > 0),
        ("torque sensor delay", changes.torque_sensor_delay > 0)) if on]


def plant_report(changes: ArmPlantChanges) -> list[str]:
    """Lines for the user: what was applied, then one warning per thing that was not."""
    lines = [f"plant model {changes.source}: applied {', '.join(applied_parts(changes)) or 'nothing'}"]
    return lines + [f"warning: {note}" for note in changes.not_applied]
