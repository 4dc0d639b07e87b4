"""The user's own URDF with the friction a diagnosis established (``serpar diagnose REC --robot
FILE.urdf --urdf OUT.urdf``): each chain joint's ``<dynamics damping= friction=>`` set, the
values MuJoCo's URDF reader takes as the joint's ``damping`` and ``frictionloss``, at full
precision and equal to those of the MJCF export (:func:`serpar.sim.mjcf_robot.friction_values`);
every other element as the file has it (parsed and written back with ElementTree, comments
and the text before ``<robot>`` kept). A comment beside each joint's ``<dynamics>`` gives the
values +- sigma and the evidence; one at the top names what a URDF cannot hold."""

from __future__ import annotations

import xml.etree.ElementTree as ET
import xml.parsers.expat
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from serpar.errors import ConfigError
from serpar.sim.mjcf_bindings import FRICTION
from serpar.sim.mjcf_notes import effect_notes, header
from serpar.sim.mjcf_robot import fitted_arm, friction_values, why_not
from serpar.sim.mjcf_writer import number
from serpar.sim.model_file import DiagnosisModel

NOT_HELD = {
    "armature": "a URDF joint has no rotor inertia (the MJCF export writes it: joint armature)",
    "payload": "a payload is a link of its own; the file's links are left as they are (the "
               "MJCF export adds it on the flange)",
    "link_inertia": "the file's <inertial> elements are left as they are (the MJCF export "
                    "scales them)",
    "encoder_offset": "a URDF joint has no reference angle MuJoCo reads (the MJCF export "
                      "writes joint ref)",
    "base_tilt": "a URDF has no gravity (the MJCF export turns <option gravity>)",
}


@dataclass(frozen=True)
class UrdfExport:
    path: Path
    joints: tuple[str, ...]
    """The joints whose <dynamics> were set."""
    not_held: tuple[str, ...]
    """One line per established effect the URDF does not hold, with why."""


def _prolog(raw: bytes) -> str:
    """The text before the root element (XML declaration, the file's leading comments)."""
    parser = xml.parsers.expat.ParserCreate()
    start: list[int] = []

    def first(*_: object) -> None:
        if not start:
            start.append(parser.CurrentByteIndex)
    parser.StartElementHandler = first
    parser.Parse(raw, True)
    return raw[:start[0]].decode("utf-8") if start else ""


def _parse(path: Path) -> tuple[str, ET.Element]:
    raw = path.read_bytes()
    for prefix, uri in [ns for _, ns in ET.iterparse(path, events=("start-ns",))]:
        try:  # keep the file's prefixes (xacro:) on the way out
            ET.register_namespace(prefix, uri)
        except ValueError:
            pass
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    try:
        root = ET.fromstring(raw, parser=parser)
        prolog = _prolog(raw)
    except (ET.ParseError, xml.parsers.expat.ExpatError) as exc:
        raise ConfigError(f"--robot {path} is not valid XML: {exc}") from None
    if root.tag != "robot":
        raise ConfigError(f"--urdf writes the --robot file back as a URDF; {path} is an MJCF "
                          f"(<{root.tag}>): its export is --mjcf")
    return prolog, root


def require_urdf(robot: str | Path | None, flag: str = "--urdf") -> Path:
    """``robot`` if it is a URDF file; else one line saying what --urdf needs."""
    if robot is None or robot == "built-in":
        raise ConfigError(f"{flag} writes the --robot URDF back with its friction; serpar's "
                          "Panda has no URDF: give --robot FILE.urdf (or use --mjcf)")
    _parse(Path(robot))
    return Path(robot)


def _set_dynamics(joint: ET.Element, damping: float, friction: float, note: str) -> None:
    indent = joint.text if joint.text and not joint.text.strip() else "\n    "
    found = joint.findall("dynamics")
    if not found:
        children = list(joint)
        new = ET.Element("dynamics")
        if children:
            new.tail, children[-1].tail = children[-1].tail, indent
        else:
            joint.text, new.tail = indent, indent[:-2] if len(indent) > 2 else "\n"
        joint.append(new)
        found = [new]
    for el in found:  # a repeated copy the same, so that it stays a harmless repeat
        el.set("damping", number(damping))
        el.set("friction", number(friction))
    comment = ET.Comment(f" serpar diagnose: {note} ".replace("--", "- -"))
    comment.tail = indent
    joint.insert(list(joint).index(found[0]), comment)


def export_urdf(model: DiagnosisModel, robot: str | Path, out: str | Path) -> UrdfExport:
    """Write ``robot`` (a URDF) with ``model``'s friction at ``out`` (module docstring)."""
    robot, path = Path(robot), Path(out)
    prolog, root = _parse(robot)
    arm = fitted_arm(model, robot)
    nominal = arm.make_spec().compile()
    damping = np.array([nominal.dof_damping[int(nominal.joint(n).dofadr[0])]
                        for n in arm.joint_names])
    notes: list[str] = []
    values = friction_values(model, arm.n, damping, notes)
    present = [e for e in FRICTION if e in model.effects]
    by_joint = effect_notes(model, present, lambda e, j: [("joint", arm.joint_names[j - 1])]
                            if j and j <= arm.n else [])
    elements = {el.get("name"): el for el in root.findall("joint")}
    done = []
    if values is not None:
        for j, name in enumerate(arm.joint_names):
            if name in elements:
                _set_dynamics(elements[name], float(values[1][j]), float(values[0][j]),
                              " | ".join(by_joint.get(("joint", name), [])))
                done.append(name)
    not_held = [f"{e}: {NOT_HELD.get(e) or why_not(e)}" for e in model.effects
                if e not in FRICTION] + notes
    lines = [
        (f"serpar (diagnose, export-mjcf): {robot} with the joint friction a diagnosis established "
         f"({model.source or model.path}), every other element as the file has it."),
        ("<dynamics friction> is MuJoCo's frictionloss = Fc (the whole Coulomb level), "
         "damping = the file's + Fv, at full precision: "
         + (", ".join(done) if done else "no friction established, no joint changed") + "."),
        "Not held by this URDF:" if not_held else "Everything established is held below.",
        *[f"  - {n}" for n in not_held]]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(prolog + header(lines) + ET.tostring(root, encoding="unicode") + "\n")
    return UrdfExport(path, tuple(done), tuple(not_held))
