"""An exported MJCF read back (``plant_model: arm.xml``, ``serpar diagnose --model arm.xml``,
``serpar export-mjcf arm.xml``): the model it carries, with every element a user edited after
export winning over it (:func:`serpar.sim.mjcf_bindings.apply_edits`), each edit named in a
note; what MJCF cannot express comes from the model text. A change in a field no effect is
written into (a geom's size, a body's position) is not part of serpar's model: it is named in
a note too, so nothing read differs silently from the file."""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco

from serpar.errors import ConfigError
from serpar.sim.mjcf_bindings import EXPORT_TEXT, MODEL_TEXT, ExportRecord, apply_edits
from serpar.sim.mjcf_panda import BUILT_IN, panda_export_spec, panda_record
from serpar.sim.mjcf_robot import robot_export_spec
from serpar.sim.mjcf_writer import differences
from serpar.sim.model_file import DiagnosisModel, parse_model, read_model_file
from serpar.sim.robot_file import mujoco_error

XML_SUFFIXES = (".xml", ".mjcf")
NOT_COMPARED = ("_", "text_", "name", "path", "mesh_pathadr", "tex_pathadr", "hfield_pathadr",
                "skin_pathadr")
"""Fields a rebuilt model differs in by construction (the carried text and its sizes, asset
paths)."""
REBUILD_TOLERANCE = 1e-9
"""A parameter read from an element and applied again may differ from it by rounding
(v - base + base); a hand edit is far larger."""
_NOTED: set[tuple[str, int]] = set()


@dataclass(frozen=True)
class MjcfRead:
    model: DiagnosisModel
    notes: tuple[str, ...]
    """One line per edit read from the elements (or found where serpar reads none)."""
    arm: str
    """``built-in`` (serpar's Panda) or the arm's file."""


def is_mjcf_path(path: str | Path) -> bool:
    return Path(path).suffix.lower() in XML_SUFFIXES


def _text(root: ET.Element, name: str) -> str | None:
    el = root.find(f"custom/text[@name='{name}']")
    return None if el is None else el.get("data", "")


def _rebuilt(model: DiagnosisModel, arm: str) -> mujoco.MjSpec | None:
    """The file as ``model`` exports it (None where the arm's file is not here)."""
    if arm == BUILT_IN:
        return panda_export_spec(model)[0]
    if not Path(arm).is_file():
        return None
    return robot_export_spec(model, arm)[0].spec


def read_mjcf(path: str | Path) -> MjcfRead:
    """The model an exported MJCF carries, its edited elements read in (module docstring);
    ConfigError for a file serpar did not export."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"MJCF {p} not found (written by serpar export-mjcf or diagnose --mjcf)")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as exc:
        raise ConfigError(f"{p} is not valid XML: {exc}") from None
    text = _text(root, MODEL_TEXT)
    if text is None:
        raise ConfigError(f"{p}: no <custom><text name=\"{MODEL_TEXT}\"> element: serpar reads "
                          "back only the MJCF it exported (serpar export-mjcf MODEL.json)")
    try:
        model = parse_model(json.loads(text), str(p))
    except json.JSONDecodeError:
        raise ConfigError(f"{p}: its {MODEL_TEXT} text is not a serpar model (JSON)") from None
    try:
        compiled = mujoco.MjModel.from_xml_path(str(p))
    except Exception as exc:  # noqa: BLE001 (MuJoCo raises ValueError or its own kinds)
        raise ConfigError(f"{p}: MuJoCo cannot read it ({mujoco_error(exc)})") from None
    record_text = _text(root, EXPORT_TEXT)
    try:  # an export of serpar before the bindings rode along is of the Panda
        record = (ExportRecord.from_json(record_text) if record_text is not None
                  else panda_record(model, panda_export_spec(model)[0].compile()))
    except (json.JSONDecodeError, KeyError, TypeError):
        raise ConfigError(f"{p}: its {EXPORT_TEXT} text is not serpar's (JSON of the "
                          "exported elements); export it again from the model file") from None
    updated, notes = apply_edits(model, record, compiled, str(p))
    try:
        expected = _rebuilt(updated, record.arm)
    except ConfigError as exc:  # an edited value outside what serpar's plant takes
        expected = None
        notes.append(f"{p}: the model as edited is not one serpar can build ({exc}); other "
                     "edits not checked")
    if expected is not None:
        unread = _unread(expected.compile(), compiled, record, updated is not model
                         and "payload" in updated.effects)
        if unread:
            notes.append(f"{p}: {unread} from what its model gives, in elements no effect of "
                         "serpar's model is written into: MuJoCo simulates it, serpar's model "
                         "does not hold it")
    return MjcfRead(updated, tuple(notes), record.arm)


def _unread(expected: mujoco.MjModel, file: mujoco.MjModel, record: ExportRecord,
            payload_read: bool) -> str:
    """The fields in which the file differs from what the model read from it gives, in words
    ("" when none). The payload body's own frame and inertial are read into the payload
    (its CoM and tensor, wherever the edit put them), so they are not counted."""
    found = differences(expected, file, NOT_COMPARED)
    payload = {-1}
    if payload_read and record.payload is not None:
        payload = {file.body(record.payload.body).id}
    words = [f"{field} differs by {diff:.3g}" for field, (diff, rows) in sorted(found.items())
             if diff > REBUILD_TOLERANCE
             and not (field.startswith("body_") and rows and set(rows) <= payload)]
    return ", ".join(words[:4]) + (f" and {len(words) - 4} more" if len(words) > 4 else "")


def read_mjcf_model(path: str | Path) -> DiagnosisModel:
    """The model of :func:`read_mjcf`; its notes go to stderr once per file version (the
    readers of a model file, serpar run's plant_model and diagnose --model among them, have
    no other way to tell the user that the file's elements won)."""
    read = read_mjcf(path)
    key = (str(Path(path).resolve()), Path(path).stat().st_mtime_ns)
    if read.notes and key not in _NOTED:
        _NOTED.add(key)
        for line in read.notes:
            print(f"note: {line}", file=sys.stderr)
    return read.model


def read_any_model(path: str | Path) -> DiagnosisModel:
    """A model file: ``.model.json`` or an exported MJCF."""
    return read_mjcf_model(path) if is_mjcf_path(path) else read_model_file(path)
