"""Robot files as published, made readable: each repair is unambiguous and named (link or body,
value); anything else is one line naming what was found. Used by :mod:`serpar.sim.robot_file`
(kinematics) and :mod:`serpar.sim.robot_dynamics` (the file's masses and inertias as a model).

- **A repeated URDF element** where the format has one (two ``<inertial>`` in a link, two
  ``<origin>`` in an inertial or a joint...): MuJoCo's URDF reader refuses the whole file
  ("repeated element"). Only then is the XML touched: identical copies (same attributes as
  numbers, same children) keep one; different copies of a link's inertial or of a joint's
  element are refused (which one is the arm's would be a guess); different copies inside a
  ``<visual>`` or ``<collision>`` drop that element (serpar uses no geometry of a robot file).
- **Mesh geoms whose files are absent** (a ROS ``package://`` path, a missing file): dropped,
  named once with the count. They carry no inertia where a body's inertia is its own
  ``<inertial>`` (a URDF, see :func:`serpar.sim.robot_dynamics.dynamics_model`); a body whose
  inertia MuJoCo would take from such a geom is refused instead: its mass is unknown.
"""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco

from serpar.errors import ConfigError

_SINGLE = {"link": ("inertial",), "inertial": ("origin", "mass", "inertia"),
           "visual": ("origin", "geometry", "material"),
           "collision": ("origin", "geometry", "material"),
           "joint": ("origin", "parent", "child", "axis", "limit", "dynamics", "calibration",
                     "mimic", "safety_controller")}
"""Children that URDF gives once per element (MuJoCo's reader refuses a second one)."""
_SHAPES = ("visual", "collision")


def _value(text: str) -> object:
    """An attribute as numbers where it is numbers ("1" equals "1.0", "0 0 0.1" "0 0 .1")."""
    try:
        return tuple(float(t) for t in text.split())
    except ValueError:
        return text.strip()


def _canon(el: ET.Element) -> tuple:
    return (el.tag, tuple(sorted((k, _value(v)) for k, v in el.attrib.items())),
            tuple(_canon(c) for c in el))


def _dedupe(el: ET.Element, owner: str, where: str, source: str) -> list[str]:
    """Drop identical repeats of ``el``'s once-only children, recursively; refuse different ones
    (a visual's or collision's own conflicts are the caller's: they raise _Ambiguous)."""
    repairs = []
    for tag in _SINGLE.get(el.tag, ()):
        copies = el.findall(tag)
        if len(copies) < 2:
            continue
        if any(_canon(c) != _canon(copies[0]) for c in copies[1:]):
            if el.tag in _SHAPES:
                raise _Ambiguous(tag, len(copies))
            raise ConfigError(f"--robot {source}: {owner} has {len(copies)} different <{tag}> "
                              f"elements{where}; which one counts is ambiguous: keep one")
        for c in copies[1:]:
            el.remove(c)
        repairs.append(f"{owner}: {len(copies)} identical <{tag}> elements{where}, "
                       f"{len(copies) - 1} dropped")
    for child in el.findall("inertial"):  # a link's visuals and collisions: repair_urdf's
        repairs += _dedupe(child, owner, " in its <inertial>", source)
    return repairs


class _Ambiguous(Exception):
    def __init__(self, tag: str, n: int) -> None:
        super().__init__(tag, n)
        self.tag, self.n = tag, n


def repair_urdf(path: Path) -> tuple[str, tuple[str, ...]]:
    """The URDF's text with its repeated elements repaired (module docstring), and the repairs."""
    namespaces = [ns for _, ns in ET.iterparse(path, events=("start-ns",))]
    for prefix, uri in namespaces:  # keep the file's prefixes (drake:, xacro:) on the way out
        try:
            ET.register_namespace(prefix, uri)
        except ValueError:  # a prefix ElementTree reserves (ns0...): it writes its own
            pass
    root = ET.parse(path).getroot()
    repairs: list[str] = []
    for el in root:
        if el.tag not in ("link", "joint"):
            continue
        owner = f"{el.tag} {el.get('name', '?')!r}"
        for shape in [c for c in el if c.tag in _SHAPES]:
            try:
                repairs += _dedupe(shape, owner, f" in a <{shape.tag}>", str(path))
            except _Ambiguous as amb:
                el.remove(shape)
                repairs.append(f"{owner}: a <{shape.tag}> with {amb.n} different <{amb.tag}> "
                               "elements dropped (serpar uses no geometry of a robot file)")
        repairs += _dedupe(el, owner, "", str(path))
    out = io.StringIO()
    ET.ElementTree(root).write(out, encoding="unicode")
    return out.getvalue(), tuple(repairs)


def mesh_file(spec: mujoco.MjSpec, mesh: mujoco.MjsMesh) -> Path | None:
    """Where MuJoCo will open a mesh's file (the model's folder, then meshdir); None: no file."""
    if not mesh.file:
        return None
    path = Path(mesh.file)
    if not path.is_absolute():
        path = Path(spec.modelfiledir or ".") / (spec.compiler.meshdir or "") / path
    return path


def drop_absent_meshes(spec: mujoco.MjSpec, source: str) -> tuple[str, ...]:
    """Delete the mesh geoms (and meshes) whose files are absent; one repair naming them. A
    body whose inertia MuJoCo takes from such a geom (``inertiafromgeom`` true, or auto and no
    explicit inertial: MJCF's default) is refused: its mass would change."""
    absent = {m.name: m.file for m in spec.meshes
              if (f := mesh_file(spec, m)) is not None and not f.is_file()}
    if not absent:
        return ()
    mode = spec.compiler.inertiafromgeom
    every = mode == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
    auto = mode == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
    geoms = [g for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH and g.meshname in absent]
    for g in geoms:
        body = g.parent
        carries = g.mass != 0 and g.density != 0
        if carries and (every or (auto and not body.explicitinertial)):
            raise ConfigError(f"--robot {source}: body {body.name or '#?'!r} takes its inertia "
                              f"from mesh {g.meshname!r}, whose file {absent[g.meshname]} is "
                              "absent; give the mesh file or an <inertial> for the body")
        spec.delete(g)
    for m in [m for m in spec.meshes if m.name in absent]:
        spec.delete(m)
    files = sorted(set(absent.values()))
    more = f" and {len(files) - 1} more" if len(files) > 1 else ""
    geom_s = "geom" if len(geoms) == 1 else "geoms"
    return (f"dropped {len(geoms)} mesh {geom_s} whose files are absent ({files[0]}{more})",)
