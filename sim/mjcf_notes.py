"""The comments of an exported MJCF or URDF (:mod:`serpar.sim.mjcf_export`,
:mod:`serpar.sim.mjcf_robot`, :mod:`serpar.sim.urdf_export`): beside each element an effect
changed, that effect's values +- sigma and the evidence the diagnosis gave; a header naming
what the file is, how each effect is written and what the format cannot express."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence

from serpar.sim.model_file import DiagnosisModel

Where = tuple[str, str]
"""(kind, name) of an element: kind is ``joint``, ``body``, ``actuator`` or ``sensor``."""
SECTIONS = {"actuator": "actuator", "sensor": "sensor"}


def joint_of(param: str) -> int | None:
    """The 1-based joint (or link) a parameter belongs to (``Fc3``, ``link3``, ``j3.alpha``,
    ``offset3``: 3), None for one of the whole arm (``mass``, ``delay``)."""
    m = re.search(r"(\d+)$", param.split(".")[0])
    return int(m.group(1)) if m else None


def evidence_of(model: DiagnosisModel, effect: str) -> str:
    return dict(model.evidence).get(effect, f"fitted on {model.source or model.path}")


def effect_notes(model: DiagnosisModel, effects: Sequence[str],
                 place: Callable[[str, int | None], Sequence[Where]]) -> dict[Where, list[str]]:
    """Per element, one line per effect written into it: its parameters of that element
    (``Fc3 = 0.51 +- 0.012; Fv3 = ...``) and the evidence. ``place(effect, joint)`` names the
    elements a parameter of ``joint`` (None: of the whole arm) is written into."""
    out: dict[Where, list[str]] = {}
    for effect in effects:
        block = model.block(effect)
        per_joint: dict[int | None, list[str]] = {}
        for n, v, s in zip(block.names, block.values, block.std):
            per_joint.setdefault(joint_of(n), []).append(f"{n} = {v:.6g} +- {s:.2g}")
        why = evidence_of(model, effect)
        if all(j is None for j in per_joint):  # one element set for the whole block
            text = "; ".join(x for xs in per_joint.values() for x in xs)
            for where in place(effect, None):
                out.setdefault(where, []).append(f"{effect}: {text} ({why})")
            continue
        for j, values in per_joint.items():
            for where in place(effect, j):
                out.setdefault(where, []).append(f"{effect}: {'; '.join(values)} ({why})")
    return out


def _safe(text: str) -> str:
    return text.replace("--", "- -")  # "--" may not appear inside an XML comment


def annotate(root: ET.Element, notes: Mapping[Where, Sequence[str]]) -> None:
    """A comment before each element of ``notes`` (found by kind and name)."""
    parents = {child: parent for parent in root.iter() for child in parent}
    found: dict[Where, ET.Element] = {}
    world = root.find("worldbody")
    for el in [] if world is None else world.iter():
        if el.tag in ("joint", "body") and el.get("name"):
            found[el.tag, el.get("name", "")] = el
    for tag, kind in SECTIONS.items():
        for section in root.findall(tag):
            found.update({(kind, el.get("name", "")): el for el in section if el.get("name")})
    for where, lines in notes.items():
        el = found.get(where)
        if el is None or el not in parents or not lines:
            continue
        parent = parents[el]
        text = " | ".join(lines)
        parent.insert(list(parent).index(el), ET.Comment(_safe(f" serpar diagnose: {text} ")))


def header(lines: Sequence[str]) -> str:
    """An XML comment of ``lines``, for the top of a written file."""
    return "<!--\n" + _safe("\n".join(lines)) + "\n-->\n"


NO_MJCF_FORM: dict[str, str] = {
    "stribeck_friction": "MuJoCo's frictionloss is one dry level (the Coulomb part, from "
                         "joint_friction): a fall with speed has no MJCF form",
    "sigmoid_friction": "MuJoCo's frictionloss is one dry level, symmetric about zero speed: a "
                        "sigmoid with an offset has no MJCF form",
}
"""Drive friction an MJCF cannot hold (the model text carries it)."""


def not_expressed_lines(items: Sequence[str]) -> list[str]:
    if not items:
        return ["Everything established is expressed below."]
    return ["Not expressed in the elements below (in the model text only):"] + [f"  - {n}"
                                                                             for n in items]
