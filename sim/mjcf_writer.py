"""One MJCF file from an ``MjSpec`` at full precision: every compiled field of the file's model
equals the in-memory model's (:func:`round_trip`: max |diff| 0), loadable by plain
``mujoco.MjModel.from_xml_path`` from any directory.

``MjSpec.to_xml`` gets the structure right (defaults, assets, the tree, sections) but writes
every number with 6 significant digits (C++ stream precision; one within 1e-12 of an integer as
that integer), and writes what compiling made of the element rather than what was authored: a capsule's ``fromto`` as pos/quat/size, an
axis-angle or Euler orientation as a normalised quat, ``fullinertia`` as the principal frame
(quat + diaginertia), angles in radians. Read back, those 6 digits move the model (serpar's
Panda: subtree masses by 1.4e-5 kg; a UR5e: ``dof_invweight0`` by 3.5e-3). Here to_xml's tree
is kept and each number in it is replaced by the full-precision value it rounds: the authored
value where the element is written as authored, the compiled one where to_xml re-expressed it
(the compiler's normalisation leaves a unit quat or axis bit for bit as it is, so the compiled
value compiles to itself). Every replacement is checked: the new value must print as to_xml's
digits, so an element is never given another one's number; a number no source matches is
left as to_xml wrote it and named (:attr:`PreciseTree.kept`), and the round trip shows whether
it matters. Values are written as the shortest decimal that reads back as the same double.

Unnamed elements are paired with their spec element through temporary names, given only for
the duration of ``to_xml`` and removed from the tree. Mesh, texture and height-field files are
referenced by path from the written file's folder, so it loads from wherever it is written.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim.mjcf_notes import Where, annotate, header
from serpar.sim.mjcf_sources import ElementSources, sources_of

TMP = "serpar_tmp_"
"""Prefix of the temporary names (a user's own element is unlikely to be named so)."""
NAMED_KINDS = ("bodies", "joints", "geoms", "sites", "cameras", "lights", "frames", "actuators",
               "sensors", "tendons", "equalities", "keys", "pairs", "excludes")
FILE_ASSETS = ("mesh", "texture", "hfield", "skin")
INT_MAX = 2**31 - 1


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
    kept: tuple[str, ...] = ()
    """Numbers left at to_xml's 6 digits (:attr:`PreciseTree.kept`)."""


@dataclass(frozen=True)
class PreciseTree:
    root: ET.Element
    model: mujoco.MjModel
    """The spec compiled (the in-memory model the file must equal)."""
    kept: tuple[str, ...]
    """``tag name.attr`` of each number left at to_xml's 6 digits (no source matched it)."""


def number(v: float) -> str:
    """The shortest text that reads back as exactly ``v`` (integers without ".0")."""
    return repr(float(v)).removesuffix(".0")


def _number32(v: np.float32) -> str:
    """A single-precision value (a colour, a material's specular) as its shortest text, where
    that text read as a double and rounded to single is ``v`` again (as MuJoCo reads it)."""
    text = str(v)
    return text.removesuffix(".0") if np.float32(float(text)) == v else number(float(v))


def numbers(values: object) -> str:
    arr = np.atleast_1d(np.asarray(values)).ravel()
    if arr.dtype == np.float32:
        return " ".join(_number32(v) for v in arr)
    return " ".join(number(v) for v in arr.astype(float))


def _floats(text: str) -> list[float] | None:
    try:
        return [float(t) for t in text.split()]
    except ValueError:
        return None


def _as_written(v: float) -> float:
    """``v`` as to_xml prints it: within 1e-12 of an integer, that integer; else 6 significant
    digits (MuJoCo's mjXUtil::WriteAttr)."""
    nearest = round(v) if abs(v) < INT_MAX else None
    if nearest is not None and abs(v - nearest) < 1e-12:
        return float(nearest)
    return float(f"{v:.6g}")


def _prints_as(candidate: np.ndarray, written: list[float], loose: bool = False) -> bool:
    """Whether ``candidate`` printed as to_xml prints reads as ``written``: the check that a
    value belongs to the attribute it replaces (``loose``: to its 6 digits and 1e-9, for what to_xml derived
    with rounding errors of its own)."""
    if candidate.size < len(written):
        return False
    if loose:
        return bool(np.allclose(candidate[:len(written)], written, rtol=1e-5, atol=1e-9))
    return all(_as_written(float(c)) == w for c, w in zip(candidate[:len(written)], written))


def _name_all(spec: mujoco.MjSpec) -> list[object]:
    """Give every unnamed element a temporary name; the elements renamed."""
    renamed, k = [], 0
    for kind in NAMED_KINDS:
        for el in getattr(spec, kind):
            if not el.name:
                el.name = f"{TMP}{k}"
                renamed.append(el)
                k += 1
    return renamed


def _resolve_files(root: ET.Element, spec: mujoco.MjSpec, out_dir: Path | None) -> None:
    """Asset files by path from the written file's folder (absolute where no relative path
    exists), so the file loads from wherever it is written; the spec's asset folders go."""
    compiler = root.find("compiler")
    base = Path(spec.modelfiledir or ".")
    dirs = {"mesh": spec.meshdir or spec.compiler.meshdir,
            "hfield": spec.meshdir or spec.compiler.meshdir,
            "skin": spec.meshdir or spec.compiler.meshdir,
            "texture": spec.texturedir or spec.compiler.texturedir}
    asset = root.find("asset")
    for el in [] if asset is None else list(asset):
        file = el.get("file")
        if el.tag not in FILE_ASSETS or not file:
            continue
        path = Path(file)
        if not path.is_absolute():
            path = base / (dirs[el.tag] or "") / path
        path = path.resolve()
        if out_dir is not None:
            try:
                el.set("file", os.path.relpath(path, out_dir.resolve()))
                continue
            except ValueError:  # another drive (Windows): no relative path
                pass
        el.set("file", str(path))
    if compiler is not None:
        for attr in ("meshdir", "texturedir", "assetdir"):
            compiler.attrib.pop(attr, None)


SITE_SIZE_DEFAULT = (0.005, 0.005, 0.005)
"""What MJCF's parser gives a site's size components the file leaves out."""


def _precise(el: ET.Element, sources: ElementSources, kept: list[str]) -> None:
    if el.tag == "site" and "size" not in el.attrib:  # to_xml leaves out a size whose first
        # component is the default; the parser would fill the rest with the default too
        size = next(iter(sources.candidates("size")), None)
        if size is not None and size.size == 3 and tuple(size) != SITE_SIZE_DEFAULT:
            el.set("size", numbers(size))
    for attr, text in list(el.attrib.items()):
        written = _floats(text)
        if not written or attr in ("name", "class", "childclass"):
            continue
        loose = sources.loose(attr)
        for candidate in sources.candidates(attr):
            if _prints_as(candidate, written, loose):
                # to_xml drops a site's trailing sizes, which the parser then fills with its
                # default 0.005 rather than the spec's value: write them all
                whole = el.tag == "site" and attr == "size"
                el.set(attr, numbers(candidate if whole else candidate[:len(written)]))
                break
        else:
            kept.append(f"{el.tag} {sources.label}.{attr}")


def precise_tree(spec: mujoco.MjSpec, out_dir: Path | None = None) -> PreciseTree:
    """``spec`` as to_xml writes it, every number at full precision (module docstring)."""
    renamed = _name_all(spec)
    try:
        model = spec.compile()
        text = spec.to_xml()
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        root = ET.fromstring(text, parser=parser)
        kept: list[str] = []
        for el, sources in sources_of(root, spec, model):
            _precise(el, sources, kept)
    finally:
        for el in renamed:
            el.name = ""
    model = spec.compile()  # names restored: the model the file must equal
    for el in root.iter():
        if el.get("name", "").startswith(TMP):
            del el.attrib["name"]
    for el in root.iterfind("custom/text"):  # to_xml's CDATA, which ElementTree cannot keep
        el.set("data", el.text or "")
        el.text = None
    _resolve_files(root, spec, out_dir)
    return PreciseTree(root, model, tuple(kept))


def mjcf_text(root: ET.Element, header: str = "") -> str:
    """The tree as an MJCF file's text, ``header`` (an XML comment or "") first."""
    ET.indent(root, "  ")
    return header + ET.tostring(root, encoding="unicode") + "\n"


def differences(a: mujoco.MjModel, b: mujoco.MjModel, ignore: tuple[str, ...] = ()
                ) -> dict[str, tuple[float, tuple[int, ...]]]:
    """Per numeric field of two compiled models that differs, the largest absolute
    difference and the rows (first index) it differs in; a field whose shape differs, inf and
    no rows. Fields starting with one of ``ignore`` are not compared."""
    out: dict[str, tuple[float, tuple[int, ...]]] = {}
    for attr in dir(a):
        if ignore and attr.startswith(ignore):
            continue
        x = getattr(a, attr, None)
        if not isinstance(x, np.ndarray) or x.dtype.kind not in "fiu" or not x.size:
            continue
        y = getattr(b, attr)
        if x.shape != y.shape:
            out[attr] = (float("inf"), ())
            continue
        diff = np.abs(x.astype(float) - y.astype(float)).reshape(len(x), -1).max(axis=1)
        if diff.max() > 0:
            out[attr] = (float(diff.max()), tuple(int(r) for r in np.flatnonzero(diff)))
    return out


def round_trip(expected: mujoco.MjSpec | mujoco.MjModel, path: Path) -> tuple[float, str]:
    """Largest absolute difference over every numeric field of the two compiled models (the
    in-memory one and the file's, read by plain MuJoCo), and the field it is in ("" when
    they are equal)."""
    a = expected.compile() if isinstance(expected, mujoco.MjSpec) else expected
    found = differences(a, mujoco.MjModel.from_xml_path(str(path)))
    for attr, (diff, rows) in found.items():
        if not rows:
            raise ConfigError(f"{path}: round trip changed {attr}'s shape")
    if not found:
        return 0.0, ""
    field = max(found, key=lambda k: found[k][0])
    return found[field][0], field


def write_export(spec: mujoco.MjSpec, out: str | Path, lines: list[str],
                 notes: dict[Where, list[str]], applied: tuple[str, ...],
                 not_expressed: tuple[str, ...]) -> MjcfExport:
    """Write ``spec`` at ``out`` at full precision, the header ``lines`` first and the
    ``notes`` beside their elements; the round trip against the in-memory model."""
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    tree = precise_tree(spec, path.parent)
    annotate(tree.root, notes)
    path.write_text(mjcf_text(tree.root, header(lines)))
    return MjcfExport(path, applied, not_expressed, *round_trip(tree.model, path), tree.kept)
