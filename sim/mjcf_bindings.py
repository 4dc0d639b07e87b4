"""What ties an exported MJCF's elements to the model it carries, so that a file edited after
export is read by its elements: per parameter MJCF can express, the element and field it is
written into, the value written and how the parameter follows from the field
(:class:`Binding`), and the payload body's compiled inertial (:class:`PayloadRecord`). Both
ride in the file as JSON (``<custom><text name="serpar.export">``), beside the model itself
(``serpar.model``), so reading needs neither the arm's file nor serpar's exporter.

:func:`apply_edits` compares each bound field of the file's compiled model with the value
written; a field that differs gives its parameter a new value (std 0: a value set by hand, not
fitted), named in a note. An effect the model lacks but whose elements were edited (damping
added to a joint) is added, all its parameters read from the elements.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace

import mujoco
import numpy as np

from serpar.sim.model_file import DiagnosisModel, ParamBlock
from serpar.sim.plants.arm_changes import EXTENT

MODEL_TEXT = "serpar.model"
"""Name of the ``<custom><text>`` element holding the model file's JSON."""
EXPORT_TEXT = "serpar.export"
"""Name of the ``<custom><text>`` element holding the bindings' JSON."""
FRICTION = ("joint_friction", "link_friction")


@dataclass(frozen=True)
class Binding:
    """Parameter ``param`` of ``effect`` is written into ``field`` of element ``name``
    (``kind``: joint, body, actuator, sensor) as ``written``; read back from a value v of
    that field, it is v - base (``add``) or v / base - 1 (``scale``)."""

    effect: str
    param: str
    kind: str
    name: str
    field: str
    written: float
    base: float
    rule: str = "add"

    def param_from(self, value: float) -> float:
        return value / self.base - 1.0 if self.rule == "scale" else value - self.base


@dataclass(frozen=True)
class PayloadRecord:
    """The payload body, on ``parent`` with the flange at ``flange`` in its frame; ``form``:
    the model's parameters (``extent`` Lxx.. or ``inertia`` Ixx..); ``written``: its compiled
    mass, pos (3), quat (4), ipos (3), iquat (4), inertia (3)."""

    body: str
    parent: str
    flange: tuple[float, ...]
    form: str
    written: tuple[float, ...]


@dataclass(frozen=True)
class ExportRecord:
    arm: str
    """``built-in`` (serpar's Panda) or the arm's file (absolute path)."""
    bindings: tuple[Binding, ...]
    payload: PayloadRecord | None = None

    def to_json(self) -> str:
        return json.dumps({"arm": self.arm, "bindings": [asdict(b) for b in self.bindings],
                           "payload": None if self.payload is None else asdict(self.payload)})

    @classmethod
    def from_json(cls, text: str) -> ExportRecord:
        raw = json.loads(text)
        p = raw.get("payload")
        payload = None if p is None else PayloadRecord(
            p["body"], p["parent"], tuple(p["flange"]), p["form"], tuple(p["written"]))
        return cls(raw["arm"], tuple(Binding(**b) for b in raw["bindings"]), payload)


def element_value(m: mujoco.MjModel, kind: str, name: str, field: str) -> float | None:
    """The compiled value of one bound field; None where the element is gone."""
    try:
        if kind == "joint":
            j = m.joint(name)
            if field == "ref":
                return float(m.qpos0[int(j.qposadr[0])])
            return float(getattr(m, f"dof_{field}")[int(j.dofadr[0])])
        if kind == "body":
            return float(getattr(m, f"body_{field}")[m.body(name).id])
        return float(getattr(m, f"{kind}_{field}")[getattr(m, kind)(name).id])
    except KeyError:
        return None


def bind(m: mujoco.MjModel, effect: str, param: str, where: tuple[str, str, str], base: float,
         rule: str = "add") -> Binding:
    """``param`` of ``effect`` bound to ``where`` (kind, name, field), written as ``m`` has it."""
    value = element_value(m, *where)
    return Binding(effect, param, *where, written=float(value if value is not None else np.nan),
                   base=float(base), rule=rule)


def _value(model: DiagnosisModel, effect: str, param: str) -> float:
    return model.block(effect).as_dict().get(param, 0.0) if effect in model.effects else 0.0


def friction_bindings(model: DiagnosisModel, m: mujoco.MjModel, joints: tuple[str, ...],
                      nominal_damping: tuple[float, ...]) -> list[Binding]:
    """Fc<j> -> frictionloss (the sum of the friction effects' Fc, each >= 0), Fv<j> ->
    damping (nominal + the sum of their Fv), bound to the first friction effect of the model
    (joint_friction where it has none): the others' share is the base."""
    present = [e for e in FRICTION if e in model.effects]
    effect = present[0] if present else FRICTION[0]
    others = present[1:]
    out = []
    for j, name in enumerate(joints, 1):
        loss = sum(max(_value(model, o, f"Fc{j}"), 0.0) for o in others)
        damp = nominal_damping[j - 1] + sum(_value(model, o, f"Fv{j}") for o in others)
        out.append(bind(m, effect, f"Fc{j}", ("joint", name, "frictionloss"), loss))
        out.append(bind(m, effect, f"Fv{j}", ("joint", name, "damping"), damp))
    return out


def payload_record(m: mujoco.MjModel, body: str, parent: str, flange: tuple[float, ...],
                   form: str) -> PayloadRecord | None:
    try:
        b = m.body(body).id
    except KeyError:
        return None
    written = np.r_[m.body_mass[b], m.body_pos[b], m.body_quat[b], m.body_ipos[b],
                    m.body_iquat[b], m.body_inertia[b]]
    return PayloadRecord(body, parent, tuple(map(float, flange)), form,
                         tuple(map(float, written)))


def _rot(q: np.ndarray) -> np.ndarray:
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, np.asarray(q, float))
    return r.reshape(3, 3)


def _extent(mass: float, inertia: np.ndarray) -> np.ndarray:
    """Lxx, Lyx, Lyy, Lzx, Lzy, Lzz of a body of ``mass`` and ``inertia`` about its CoM: the
    lower-triangular L with L L^T = its second moment / mass (EXTENT)."""
    second = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    w, v = np.linalg.eigh(second / mass)
    _, r = np.linalg.qr((v * np.sqrt(np.clip(w, 0.0, None))).T)  # M^T = Q R, M M^T = R^T R
    low = r.T * np.where(np.diag(r) < 0, -1.0, 1.0)  # a non-negative diagonal
    return low[np.tril_indices(3)]


def payload_params(m: mujoco.MjModel, rec: PayloadRecord) -> dict[str, float] | None:
    """The payload as the file's elements give it (None: its body is gone)."""
    try:
        b = m.body(rec.body).id
    except KeyError:
        return None
    rb = _rot(m.body_quat[b])
    com = m.body_pos[b] - np.asarray(rec.flange) + rb @ m.body_ipos[b]
    ri = rb @ _rot(m.body_iquat[b])
    inertia = ri @ np.diag(m.body_inertia[b]) @ ri.T
    mass = float(m.body_mass[b])
    out = {"mass": mass, "com_x": com[0], "com_y": com[1], "com_z": com[2]}
    if rec.form == "extent":
        out.update(zip(EXTENT, _extent(mass, inertia)))
    else:
        out.update({"Ixx": inertia[0, 0], "Iyy": inertia[1, 1], "Izz": inertia[2, 2],
                    "Ixy": inertia[0, 1], "Ixz": inertia[0, 2], "Iyz": inertia[1, 2]})
    return {k: float(v) for k, v in out.items()}


def _payload_edit(m: mujoco.MjModel, rec: PayloadRecord
                  ) -> tuple[dict[str, float] | None, bool]:
    """(the payload's parameters from the file, whether its body differs from the written)."""
    try:
        b = m.body(rec.body).id
    except KeyError:
        return None, True
    now = np.r_[m.body_mass[b], m.body_pos[b], m.body_quat[b], m.body_ipos[b],
                m.body_iquat[b], m.body_inertia[b]]
    return payload_params(m, rec), not np.array_equal(now, np.asarray(rec.written))


def _with(model: DiagnosisModel, effect: str, values: dict[str, float],
          names: tuple[str, ...]) -> tuple[ParamBlock, list[str]]:
    """The effect's block with ``values`` in place (std 0 there), and the changes in words."""
    if effect in model.effects:
        old = model.block(effect)
        new_values = [values.get(n, v) for n, v in zip(old.names, old.values)]
        std = [0.0 if n in values else s for n, s in zip(old.names, old.std)]
        words = [f"{n} {v:.6g} -> {values[n]:.6g}" for n, v in zip(old.names, old.values)
                 if n in values and values[n] != v]
        return ParamBlock(old.names, tuple(new_values), tuple(std)), words
    return (ParamBlock(names, tuple(values[n] for n in names), (0.0,) * len(names)),
            [f"{n} = {values[n]:.6g}" for n in names])


def apply_edits(model: DiagnosisModel, rec: ExportRecord, m: mujoco.MjModel, where: str
                ) -> tuple[DiagnosisModel, list[str]]:
    """``model`` with every parameter whose element in ``m`` (the file compiled) differs from
    what was written taken from the element (module docstring), and one note per effect."""
    edits: dict[str, dict[str, float]] = {}
    names: dict[str, list[str]] = {}
    gone = []
    for b in rec.bindings:
        names.setdefault(b.effect, []).append(b.param)
        value = element_value(m, b.kind, b.name, b.field)
        if value is None:
            gone.append(f"{b.kind} {b.name}")
        elif value != b.written:
            edits.setdefault(b.effect, {})[b.param] = b.param_from(value)
    for effect in [e for e in edits if e not in model.effects]:  # every parameter from the file
        for b in (b for b in rec.bindings if b.effect == effect):
            value = element_value(m, b.kind, b.name, b.field)
            edits[effect].setdefault(b.param, b.param_from(value if value is not None else b.base))
    dropped = []
    if rec.payload is not None:
        params, differs = _payload_edit(m, rec.payload)
        if params is None and "payload" in model.effects:
            dropped.append("payload")
        elif params is not None and differs:
            edits["payload"] = params
            names["payload"] = list(params)
    blocks = dict(model.blocks)
    effects = [e for e in model.effects if e not in dropped]
    evidence = dict(model.evidence)
    notes = [(f"{where}: element(s) {', '.join(sorted(set(gone)))} gone: their parameters "
              "kept as the model it carries gives them")] if gone else []
    for effect, values in edits.items():
        block, words = _with(model, effect, values, tuple(names[effect]))
        if not words:
            continue
        blocks[effect] = block
        if effect not in effects:
            effects.append(effect)
        edited = (f"({', '.join(words)}): the file's elements win over the model it carries; a "
                  "value set by hand has std 0")
        evidence[effect] = (f"edited in {where} after export {edited}"
                            + (f"; fitted: {evidence[effect]}" if effect in evidence else ""))
        notes.append(f"{where}: {effect} edited after export {edited}")
    for effect in dropped:
        evidence.pop(effect, None)
        blocks.pop(effect, None)
        notes.append(f"{where}: the payload body was removed after export: payload dropped")
    if not notes:
        return model, []
    return replace(model, path=where, effects=tuple(effects), blocks=tuple(blocks.items()),
                   evidence=tuple(evidence.items())), notes
