"""Where each number of ``MjSpec.to_xml``'s tree comes from at full precision (for
:mod:`serpar.sim.mjcf_writer`): per element, the compiled model's row (what to_xml writes for
an element it re-expresses: a fromto as pos/quat/size, an orientation as a unit quat, an
inertia in its principal frame, angles in radians) and the authored spec element (defaults,
assets, and what sits in a ``<frame>``, whose compiled values are in the body's frame and no
longer the frame's).

The compiled row comes first: where to_xml re-expressed an element, the authored value is no
longer what the text means, and where it did not, the two are the same number. The writer
takes the first candidate that prints as to_xml's 6 digits.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import mujoco
import numpy as np

Getter = Callable[[mujoco.MjModel, int], object]
Arr = np.ndarray

PREFIX = {"body": "body", "geom": "geom", "site": "site", "camera": "cam", "light": "light",
          "actuator": "actuator", "sensor": "sensor", "tendon": "tendon", "equality": "eq",
          "key": "key", "pair": "pair", "material": "mat", "joint": "jnt"}
"""The compiled model's field prefix per element kind (``geom_size``...)."""
ALIAS = {"solreflimit": "solref_limit", "solimplimit": "solimp_limit",
         "solreffriction": "solref_friction", "solimpfriction": "solimp_friction",
         "actuatorfrcrange": "actfrcrange", "fluidcoef": "fluid_coefs", "user": "userdata",
         "diaginertia": "inertia", "polycoef": "data", "anchor": "data", "vertex": "uservert",
         "normal": "usernormal", "texcoord": "usertexcoord", "face": "userface",
         "elevation": "userdata"}
"""XML attribute -> spec attribute, where the names differ."""
INERTIAL_ALIAS = {"pos": "ipos", "quat": "iquat", "diaginertia": "inertia"}


SCALAR_JOINTS = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


def _dof(m: mujoco.MjModel, j: int, values: Arr, poly: Arr | None = None) -> Arr:
    d = int(m.jnt_dofadr[j])
    return values[d:d + 1] if poly is None else np.r_[values[d], poly[d]]


def _qpos(values_of: Callable[[mujoco.MjModel], Arr]) -> Getter:
    def get(m: mujoco.MjModel, j: int) -> object:
        if int(m.jnt_type[j]) not in SCALAR_JOINTS:
            return None
        a = int(m.jnt_qposadr[j])
        return values_of(m)[a:a + 1]
    return get


COMPILED: dict[str, dict[str, Getter]] = {
    "inertial": {"pos": lambda m, b: m.body_ipos[b], "quat": lambda m, b: m.body_iquat[b],
                 "mass": lambda m, b: m.body_mass[b:b + 1],
                 "diaginertia": lambda m, b: m.body_inertia[b]},
    "joint": {"ref": _qpos(lambda m: m.qpos0), "springref": _qpos(lambda m: m.qpos_spring),
              "stiffness": lambda m, j: np.r_[m.jnt_stiffness[j], m.jnt_stiffnesspoly[j]],
              "damping": lambda m, j: _dof(m, j, m.dof_damping, m.dof_dampingpoly),
              "armature": lambda m, j: _dof(m, j, m.dof_armature),
              "frictionloss": lambda m, j: _dof(m, j, m.dof_frictionloss),
              "actuatorfrcrange": lambda m, j: m.jnt_actfrcrange[j],
              "solreflimit": lambda m, j: m.jnt_solref[j],
              "solimplimit": lambda m, j: m.jnt_solimp[j],
              "solreffriction": lambda m, j: m.dof_solref[int(m.jnt_dofadr[j])],
              "solimpfriction": lambda m, j: m.dof_solimp[int(m.jnt_dofadr[j])]},
    "geom": {"fluidcoef": lambda m, g: m.geom_fluid[g, 1:6]},
    "tendon": {"springlength": lambda m, t: m.tendon_lengthspring[t],
               "damping": lambda m, t: np.r_[m.tendon_damping[t], m.tendon_dampingpoly[t]],
               "stiffness": lambda m, t: np.r_[m.tendon_stiffness[t], m.tendon_stiffnesspoly[t]],
               "solreflimit": lambda m, t: m.tendon_solref_lim[t],
               "solimplimit": lambda m, t: m.tendon_solimp_lim[t],
               "solreffriction": lambda m, t: m.tendon_solref_fri[t],
               "solimpfriction": lambda m, t: m.tendon_solimp_fri[t],
               "actuatorfrcrange": lambda m, t: m.tendon_actfrcrange[t]},
    "actuator": {"damping": lambda m, a: np.r_[m.actuator_damping[a], m.actuator_dampingpoly[a]]},
    "equality": {"polycoef": lambda m, e: m.eq_data[e, :5], "anchor": lambda m, e: m.eq_data[e, :3],
                 "relpose": lambda m, e: m.eq_data[e, 3:10],
                 "torquescale": lambda m, e: m.eq_data[e, 10:11]},
}
"""Compiled values whose field is not ``<prefix>_<attr>`` (joint values live per dof or per
qpos address; an inertial is its body's)."""
AUTHORED_SLICE = {"relpose": slice(3, 10), "torquescale": slice(10, 11)}
ACTUATOR_TAGS = ("general", "motor", "position", "velocity", "intvelocity", "damper",
                 "cylinder", "muscle", "adhesion", "dcmotor")
TREE_KINDS = {"body": "body", "joint": "joint", "freejoint": "joint", "geom": "geom",
              "site": "site", "camera": "camera", "light": "light", "frame": "frame"}
SECTION_KINDS = {"actuator": "actuator", "sensor": "sensor", "tendon": "tendon",
                 "equality": "equality", "keyframe": "key", "contact": "pair"}
ASSET_KINDS = ("mesh", "material", "texture", "hfield")


@dataclass(frozen=True)
class ElementSources:
    """The full-precision values one XML element's numbers may come from."""

    label: str
    authored: object = None
    kind: str = ""
    model: mujoco.MjModel | None = None
    id: int = -1
    alias: dict[str, str] = field(default_factory=dict)
    orientation: Arr | None = None
    """The authored orientation resolved to a quat (what the compiler makes of it)."""
    compiled_frame: bool = True
    """False where the compiled pos/quat are not what to_xml wrote (inside a <frame>)."""
    mesh_frame: bool = False
    """A mesh geom: to_xml writes its pos/quat recovered from the compiled ones by undoing
    the mesh's own offset, a few ulps off what was authored; the authored pos/quat are what
    compiles to the model again, so they are taken if they agree to to_xml's digits."""

    fixed: dict[str, Arr] | None = None
    """Values known by position alone (a tendon's wraps): the only candidates."""

    def loose(self, attr: str) -> bool:
        return self.mesh_frame and attr in ("pos", "quat")

    def _compiled(self, attr: str) -> object:
        if self.model is None or self.id < 0:
            return None
        if attr in ("pos", "quat", "axis", "dir") and (self.mesh_frame or not self.compiled_frame):
            return None
        special = COMPILED.get(self.kind, {})
        if attr in special:
            return special[attr](self.model, self.id)
        if self.kind == "option":
            return getattr(self.model.opt, attr, None)
        values = getattr(self.model, f"{PREFIX.get(self.kind, self.kind)}_{attr}", None)
        return values[self.id] if isinstance(values, np.ndarray) else None

    def _authored(self, attr: str) -> object:
        if self.authored is None:
            return None
        name = self.alias.get(attr, ALIAS.get(attr, attr))
        value = getattr(self.authored, name, None)
        if attr in AUTHORED_SLICE and value is not None:
            value = np.asarray(value, float)[AUTHORED_SLICE[attr]]
        return value

    def candidates(self, attr: str) -> Iterator[Arr]:
        if self.fixed is not None:
            found = [self.fixed.get(attr)]
        else:
            found = [self._compiled(attr), self._authored(attr)]
        if attr == "quat" and self.orientation is not None:
            found.insert(1, self.orientation)
        for value in found:
            if value is None or callable(value):
                continue
            try:
                arr = np.atleast_1d(np.asarray(value)).ravel()
                arr = arr if arr.dtype == np.float32 else arr.astype(float)  # float32 kept
            except (TypeError, ValueError):
                continue
            yield arr


def _unit(q: list[float]) -> Arr:
    """``q`` normalised as MuJoCo's compiler does (mjuu_normvec: the same operations in the
    same order, and a vector within 1e-14 of unit length left as it is)."""
    norm = 0.0
    for v in q:
        norm += v * v
    norm = math.sqrt(norm)
    if norm < 1e-14 or abs(norm - 1.0) <= 1e-14:
        return np.array(q)
    return np.array([v / norm for v in q])


def _resolved(spec: mujoco.MjSpec, el: object) -> Arr | None:
    """The orientation the compiler makes of what was authored (a frame's has no compiled
    field to take it from): a quat normalised, any other form resolved."""
    alt = getattr(el, "alt", None)
    if alt is None:
        return None
    if alt.type == mujoco.mjtOrientation.mjORIENTATION_QUAT:
        return _unit([float(v) for v in el.quat])
    return np.asarray(spec.resolve_orientation(bool(spec.compiler.degree),
                                               spec.compiler.eulerseq, alt), float)


def _tree(body_el: object, spec: mujoco.MjSpec, model: mujoco.MjModel
          ) -> Iterator[tuple[object, ElementSources]]:
    for el in body_el:
        if not isinstance(el.tag, str):
            continue
        kind = TREE_KINDS.get(el.tag)
        name = el.get("name", "")
        if el.tag == "inertial":
            body = spec.body(body_el.get("name", ""))
            if body is not None:
                yield el, ElementSources(f"{body.name}.inertial", body, "inertial", model,
                                         body.id, dict(INERTIAL_ALIAS))
            continue
        if kind is None or not name:
            continue
        obj = getattr(spec, kind)(name)
        if obj is None:
            continue
        in_frame = getattr(obj, "frame", None) is not None
        mesh = kind == "geom" and obj.type == mujoco.mjtGeom.mjGEOM_MESH
        yield el, ElementSources(name, obj, kind, model, getattr(obj, "id", -1),
                                 orientation=_resolved(spec, obj),
                                 compiled_frame=not (in_frame or kind == "frame"),
                                 mesh_frame=mesh)
        if el.tag in ("body", "frame"):
            yield from _tree(el, spec, model)


def _defaults(el: object, spec: mujoco.MjSpec) -> Iterator[tuple[object, ElementSources]]:
    default = spec.find_default(el.get("class", "main"))
    for child in el:
        if not isinstance(child.tag, str):
            continue
        if child.tag == "default":
            yield from _defaults(child, spec)
            continue
        part = "actuator" if child.tag in ACTUATOR_TAGS else child.tag
        obj = getattr(default, part, None) if default is not None else None
        if obj is not None:
            yield child, ElementSources(f"default {el.get('class', 'main')}", obj)


def _tendon_wraps(el: object, t: int, model: mujoco.MjModel
                  ) -> Iterator[tuple[object, ElementSources]]:
    adr = int(model.tendon_adr[t])
    for k, wrap in enumerate(w for w in el if isinstance(w.tag, str)):
        prm = model.wrap_prm[adr + k:adr + k + 1]
        yield wrap, ElementSources(f"{el.get('name')} wrap {k}",
                                   fixed={"coef": prm, "divisor": prm})


def sources_of(root: object, spec: mujoco.MjSpec, model: mujoco.MjModel
               ) -> Iterator[tuple[object, ElementSources]]:
    """Each element of to_xml's tree that may hold numbers, with its sources; every element
    of the tree is named (the writer's temporary names)."""
    for section in root:
        tag = section.tag
        if not isinstance(tag, str):
            continue
        if tag == "compiler":
            yield section, ElementSources("compiler", spec.compiler)
        elif tag == "option":
            yield section, ElementSources("option", spec.option, "option", model, 0)
        elif tag == "statistic":
            yield section, ElementSources("statistic", spec.stat)
        elif tag == "visual":
            for part in section:
                obj = getattr(spec.visual, part.tag, None) or getattr(spec.visual, f"{part.tag}_", None)
                yield part, ElementSources(f"visual {part.tag}", obj)
        elif tag == "default":
            yield from _defaults(section, spec)
        elif tag == "asset":
            for el in section:
                if el.tag in ASSET_KINDS and el.get("name"):
                    obj = getattr(spec, el.tag)(el.get("name"))
                    yield el, ElementSources(el.get("name"), obj, el.tag, model, getattr(obj, "id", -1))
        elif tag == "worldbody":
            yield from _tree(section, spec, model)
        elif tag == "custom":
            for el in section:
                if el.tag == "numeric" and el.get("name"):
                    yield el, ElementSources(el.get("name"), spec.numeric(el.get("name")))
        elif tag in SECTION_KINDS:
            kind = SECTION_KINDS[tag]
            for el in section:
                name = el.get("name") if isinstance(el.tag, str) else None
                obj = getattr(spec, kind)(name) if name else None
                if obj is None:
                    continue
                yield el, ElementSources(name, obj, kind, model, obj.id)
                if kind == "tendon":
                    yield from _tendon_wraps(el, obj.id, model)
