"""A diagnosis model as MJCF: the arm with the physics a diagnosis established, one
self-contained file any MuJoCo user can load (``mujoco.MjModel.from_xml_path``).

The file is the arm's own MJCF (assets/arm/panda.xml, no meshes, its comments kept) with the
changes of :func:`serpar.sim.plants.arm_changes.apply_arm_plant` written into it at full
precision; everything else stays as that file writes it. (``MjSpec.to_xml`` would write 6
significant digits and re-express fromto, axis-angle and inertias, moving compiled fields by up
to 1e-5.) :func:`round_trip` compares every compiled field of the file with the in-memory model. Each changed element carries its fitted value +- sigma and the
evidence in a comment; the header lists what MuJoCo cannot express. The model itself rides
along in ``<custom><text name="serpar.model">`` so that ``serpar run`` (``plant_model:``) and
``serpar diagnose --model`` read the file back; :func:`read_mjcf_model` refuses a file whose
elements no longer match that model (edited by hand), rather than simulate one and report the
other.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim.arm import ACTUATOR_NAMES, ARM_XML, JOINT_NAMES, TORQUE_SENSOR_NAMES, build_arm_spec
from serpar.sim.model_file import DiagnosisModel, model_dict, parse_model, read_model_file
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.arm_changes import PAYLOAD_BODY, ArmPlantChanges, apply_arm_plant
from serpar.sim.plants.from_model_file import APPLY, KNOWN_EFFECTS, arm_plant_changes

MODEL_TEXT = "serpar.model"
"""Name of the ``<custom><text>`` element holding the model file's JSON."""
INTERP_NAMES = ("zoh", "linear", "cubic")
"""MJCF names of a history's interpolation, by MuJoCo's number."""
ORIENTATIONS = ("quat", "axisangle", "euler", "xyaxes", "zaxis")
XML_SUFFIXES = (".xml", ".mjcf")


@dataclass(frozen=True)
class MjcfExport:
    path: Path
    applied: tuple[str, ...]
    """Effects written into the file."""
    not_expressed: tuple[str, ...]
    """One line per effect (or part) MuJoCo cannot express, with why (also in the header)."""
    round_trip_max: float
    """Largest difference of any compiled field, file against in-memory model (0: exact)."""
    round_trip_field: str
    """Where that difference is ("" when exact)."""


def is_mjcf_path(path: str | Path) -> bool:
    return Path(path).suffix.lower() in XML_SUFFIXES


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


def _export_spec(changes: ArmPlantChanges, model: DiagnosisModel) -> mujoco.MjSpec:
    """The exported arm: the plant, its name and the model it carries."""
    spec = arm_spec(changes)
    spec.modelname = "serpar_panda_diagnosed"
    spec.add_text(name=MODEL_TEXT, data=json.dumps(model_dict(model), sort_keys=True))
    return spec


def _number(v: float) -> str:
    """The shortest text that reads back as exactly ``v`` (integers without ".0")."""
    text = repr(float(v))
    return text.removesuffix(".0")


def _numbers(values: object) -> str:
    return " ".join(_number(v) for v in np.atleast_1d(np.asarray(values, float)).ravel())


def _orientation(el: ET.Element, obj: mujoco.MjsBody | mujoco.MjsSite) -> None:
    for attr in ORIENTATIONS:
        el.attrib.pop(attr, None)
    el.set("quat", _numbers(obj.quat))


def _inertial(el: ET.Element, body: mujoco.MjsBody) -> None:
    inertial = el.find("inertial")
    if inertial is None:
        inertial = ET.Element("inertial")
        el.insert(0, inertial)
    inertial.attrib.clear()
    inertial.attrib.update(pos=_numbers(body.ipos), mass=_number(body.mass),
                           fullinertia=_numbers(body.fullinertia))


def _write_changes(root: ET.Element, nominal: mujoco.MjSpec, plant: mujoco.MjSpec) -> None:
    """Write what ``plant`` changed against ``nominal`` into the source file's elements, at
    full precision; a body the plant added (the payload) is added under its parent."""
    kinds = {"body": "body", "joint": "joint", "site": "site", "motor": "actuator",
             "general": "actuator", "position": "actuator", "velocity": "actuator"}
    found = {(kinds[el.tag], el.get("name")): el for el in root.iter()
             if el.tag in kinds and el.get("name")}
    for section in root.iter("sensor"):
        found.update({("sensor", el.get("name")): el for el in section if el.get("name")})
    for joint in plant.joints:
        el, old = found["joint", joint.name], nominal.joint(joint.name)
        for attr in ("frictionloss", "ref"):
            if getattr(joint, attr) != getattr(old, attr):
                el.set(attr, _number(getattr(joint, attr)))
        if not np.array_equal(joint.damping, old.damping):
            el.set("damping", _number(joint.damping[0]))
        if not np.array_equal(joint.solref_friction, old.solref_friction):
            el.set("solreffriction", _numbers(joint.solref_friction))
    for body in plant.bodies[1:]:
        old = nominal.body(body.name)
        if old is None:  # added by the plant: a body with an explicit inertial
            parent = found["body", body.parent.name]
            el = ET.SubElement(parent, "body", name=body.name, pos=_numbers(body.pos))
            _inertial(el, body)
            found["body", body.name] = el
            continue
        el = found["body", body.name]
        if not np.array_equal(body.pos, old.pos):
            el.set("pos", _numbers(body.pos))
        if body.alt.type != old.alt.type or not np.array_equal(body.quat, old.quat):
            _orientation(el, body)
        if body.mass != old.mass or not np.array_equal(body.fullinertia, old.fullinertia,
                                                        equal_nan=True):
            _inertial(el, body)
    for site in plant.sites:
        old, el = nominal.site(site.name), found["site", site.name]
        if not np.array_equal(site.pos, old.pos):
            el.set("pos", _numbers(site.pos))
        if site.alt.type != old.alt.type or not np.array_equal(site.quat, old.quat):
            _orientation(el, site)
    for sensor in plant.sensors:
        old, el = nominal.sensor(sensor.name), found["sensor", sensor.name]
        if (sensor.delay, sensor.nsample, sensor.interp) != (old.delay, old.nsample, old.interp):
            el.set("delay", _number(sensor.delay))
            el.set("nsample", str(int(sensor.nsample)))
            el.set("interp", INTERP_NAMES[int(sensor.interp)])
    for act in plant.actuators:
        old, el = nominal.actuator(act.name), found["actuator", act.name]
        if (act.delay, act.nsample, act.interp) != (old.delay, old.nsample, old.interp):
            el.set("delay", _number(act.delay))
            el.set("nsample", str(int(act.nsample)))
            el.set("interp", INTERP_NAMES[int(act.interp)])


def _source_tree() -> ET.Element:
    """The arm's MJCF as written (its comments kept)."""
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    return ET.fromstring(ARM_XML.read_text(), parser=parser)


def _joint_of(param: str) -> int | None:
    m = re.search(r"(\d+)$", param.split(".")[0])
    return int(m.group(1)) if m else None


def _annotate(root: ET.Element, model: DiagnosisModel) -> None:
    """A comment before each changed element: its effect's parameters +- sigma, the evidence."""
    parents = {child: parent for parent in root.iter() for child in parent}
    targets: dict[str, list[tuple[str, str, str]]] = {}  # element -> (effect, values, evidence)
    for effect in model.effects:
        if effect not in APPLY:
            continue
        block = model.block(effect)
        per_joint: dict[int | None, list[str]] = {}
        for n, v, s in zip(block.names, block.values, block.std):
            per_joint.setdefault(_joint_of(n), []).append(f"{n} = {v:.6g} +- {s:.2g}")
        why = dict(model.evidence).get(effect, f"fitted on {model.source or model.path}")
        if effect in ("joint_friction", "link_friction", "encoder_offset", "encoder"):
            for j, name in enumerate(JOINT_NAMES, 1):
                if j in per_joint:
                    targets.setdefault(name, []).append((effect, "; ".join(per_joint[j]), why))
        elif effect in ("link_inertia", "geometric"):
            for j in range(1, len(JOINT_NAMES) + 1):
                if j in per_joint:
                    targets.setdefault(f"link{j}", []).append((effect, "; ".join(per_joint[j]), why))
        else:
            text = "; ".join(x for xs in per_joint.values() for x in xs)
            where_all = {"payload": (PAYLOAD_BODY,), "sensor_timing": TORQUE_SENSOR_NAMES}
            for where in where_all.get(effect, ACTUATOR_NAMES):
                targets.setdefault(where, []).append((effect, text, why))
    for el in list(root.iter()):
        notes = targets.get(el.get("name", ""))
        if notes and el in parents:
            parent = parents[el]
            text = " | ".join(f"{e}: {t} ({why})" for e, t, why in notes)
            parent.insert(list(parent).index(el), ET.Comment(f" serpar diagnose: {text} "))


def _header(model: DiagnosisModel, changes: ArmPlantChanges) -> str:
    evidence = dict(model.evidence)
    lines = [
        ("serpar export-mjcf: the arm of assets/arm/panda.xml with the physics a diagnosis "
         f"established ({model.source or model.path})."),
        ("Changed values at full precision (the shortest decimal that reads back exactly); "
         "everything else as assets/arm/panda.xml writes it."),
        ("Each effect's MJCF form (e.g. joint_friction: frictionloss = Fc, damping = nominal + "
         "Fv): serpar/sim/plants/from_model_file.py."),
        ("Every joint's solreffriction is serpar's (PhysicsConfig.arm_friction_timeconst): "
         "MuJoCo's default 0.02 s friction row pushes a joint braked faster than v/0.02 s "
         "along its motion."),
        "Established effects: " + (", ".join(model.effects) or "none") + "."]
    lines += [f"  {e}: {evidence[e]}" for e in model.effects if e in evidence]
    lines.append("Not expressed in MuJoCo (left out of the elements below):"
                 if changes.not_applied else "Everything established is expressed below.")
    lines += [f"  - {n}" for n in changes.not_applied]
    return "<!--\n" + "\n".join(lines).replace("--", "- -") + "\n-->\n"


def round_trip(spec: mujoco.MjSpec, path: Path) -> tuple[float, str]:
    """Largest absolute difference over every numeric field of the two compiled models, and
    the field it is in ("" when they are equal)."""
    a, b = spec.compile(), mujoco.MjModel.from_xml_path(str(path))
    worst, worst_field = 0.0, ""
    for attr in dir(a):
        x = getattr(a, attr, None)
        if not isinstance(x, np.ndarray) or x.dtype.kind not in "fi":
            continue
        y = getattr(b, attr)
        if x.shape != y.shape:
            raise ConfigError(f"{path}: round trip changed {attr}'s shape {x.shape} -> {y.shape}")
        if x.size:
            diff = float(np.max(np.abs(x.astype(float) - y.astype(float))))
            if diff > worst:
                worst, worst_field = diff, attr
    return worst, worst_field


def export_arm_mjcf(model: DiagnosisModel, out: str | Path) -> MjcfExport:
    """Write ``model`` (its established effects) as one MJCF of the arm at ``out``."""
    foreign = [e for e in model.effects if e not in KNOWN_EFFECTS]
    if foreign:
        raise ConfigError(f"{model.path}: effect(s) {', '.join(foreign)} are not the arm's; "
                          f"export-mjcf writes the arm ({', '.join(APPLY)}); a Stewart model "
                          "goes to serpar run as its .stewart_params.json")
    changes = arm_plant_changes(model)
    spec = _export_spec(changes, model)
    root = _source_tree()
    root.set("model", spec.modelname)
    _write_changes(root, build_arm_spec(), spec)
    option = root.find("option")
    if option is None:
        option = ET.Element("option")
        root.insert(list(root).index(root.find("compiler")) + 1, option)
    option.set("timestep", _number(spec.option.timestep))
    _annotate(root, model)
    custom = root.find("custom")
    if custom is None:
        custom = ET.SubElement(root, "custom")
    ET.SubElement(custom, "text", name=MODEL_TEXT, data=spec.texts[0].data)
    ET.indent(root, "  ")
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(_header(model, changes) + ET.tostring(root, encoding="unicode") + "\n")
    return MjcfExport(path, tuple(e for e in model.effects if e in APPLY), changes.not_applied,
                      *round_trip(spec, path))


def read_mjcf_model(path: str | Path) -> DiagnosisModel:
    """The model an exported MJCF carries; ConfigError if the file has none or its elements
    no longer compile to what that model gives (the file was edited)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"MJCF {p} not found (written by serpar export-mjcf or diagnose --mjcf)")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"{p} is not valid XML: {exc}") from None
    text = root.find(f"custom/text[@name='{MODEL_TEXT}']")
    if text is None:
        raise ConfigError(f"{p}: no <custom><text name=\"{MODEL_TEXT}\"> element: serpar reads "
                          "back only the MJCF it exported (serpar export-mjcf MODEL.json)")
    try:
        raw = json.loads(text.get("data", ""))
    except json.JSONDecodeError:
        raise ConfigError(f"{p}: its {MODEL_TEXT} text is not a serpar model (JSON)") from None
    model = parse_model(raw, str(p))
    worst, where = round_trip(_export_spec(arm_plant_changes(model), model), p)
    if worst > 0:
        raise ConfigError(f"{p}: its elements differ from the model it carries ({where} by "
                          f"{worst:.3g}): edited after export? Export it again from the model file")
    return model


def read_any_model(path: str | Path) -> DiagnosisModel:
    """A model file: ``.model.json`` or an exported MJCF."""
    return read_mjcf_model(path) if is_mjcf_path(path) else read_model_file(path)
