"""A diagnosis model as MJCF: an arm with the physics a diagnosis established, one file any
MuJoCo user can load (``mujoco.MjModel.from_xml_path``), every compiled field equal to serpar's
in-memory model (round trip: max |diff| 0).

- :mod:`serpar.sim.mjcf_writer` writes any ``MjSpec`` at full precision (to_xml's tree, each
  number replaced by the full-precision value it rounds; no source text needed);
- :mod:`serpar.sim.mjcf_panda`: serpar's Panda (``serpar export-mjcf M``, ``diagnose --mjcf``);
- :mod:`serpar.sim.mjcf_robot`: the user's own arm from its URDF/MJCF (``--robot FILE``);
- :mod:`serpar.sim.mjcf_read`: the file read back, an element edited after export winning
  over the model text it carries (:mod:`serpar.sim.mjcf_bindings` ties the two);
- :mod:`serpar.sim.urdf_export`: the user's URDF with the friction its ``<dynamics>`` holds.

Each changed element carries its fitted value +- sigma and the evidence in a comment; the
header lists what the format cannot express (:mod:`serpar.sim.mjcf_notes`).
"""

from __future__ import annotations

from pathlib import Path

from serpar.sim.mjcf_bindings import MODEL_TEXT
from serpar.sim.mjcf_panda import BUILT_IN, arm_spec, export_panda_mjcf
from serpar.sim.mjcf_read import is_mjcf_path, read_any_model, read_mjcf, read_mjcf_model
from serpar.sim.mjcf_robot import export_robot_mjcf
from serpar.sim.mjcf_writer import MjcfExport, round_trip
from serpar.sim.model_file import DiagnosisModel

__all__ = ["MODEL_TEXT", "MjcfExport", "arm_spec", "export_arm_mjcf", "export_mjcf",
           "export_robot_mjcf", "is_mjcf_path", "read_any_model", "read_mjcf",
           "read_mjcf_model", "round_trip"]

export_arm_mjcf = export_panda_mjcf
"""serpar's Panda with ``model``'s effects (the name every caller of the cell's export uses)."""


def export_mjcf(model: DiagnosisModel, out: str | Path, robot: str | None = None) -> MjcfExport:
    """``model`` as the MJCF of ``robot`` (an arm's URDF/MJCF file), or of serpar's Panda where
    ``robot`` is None or ``built-in``."""
    if robot is None or robot == BUILT_IN:
        return export_panda_mjcf(model, out)
    return export_robot_mjcf(model, robot, out)
