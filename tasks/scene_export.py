"""The whole cell of an episode as one MJCF (``serpar export-scene``): arm, Stewart platform,
plate with its drawn bores, tray, conductors and the stereo cameras, every compiled field
equal to the model ``serpar run`` simulates (round trip: max |diff| 0, sim/mjcf_writer.py).

The file opens in MuJoCo's own viewer (``python -m mujoco.viewer --mjcf cell.xml``). It holds
one keyframe more than the cell's model, ``home``: the state an episode starts from (the arm
in its ready pose held against gravity, the legs at their home strokes), since from ``qpos0``
and zero controls the arm falls and the legs run to zero stroke. The
procedural meshes (bores, chamfers, the conductors' bodies) are written inline at full
precision, so the one file is the whole cell. What the cell does in code at run time is named
in the file's header: the controllers, the sensors' noise, the transit step, seating a part
into the plate, and drive friction that has no MJCF form (sim/mjcf_notes.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco

from serpar.sim.mjcf_notes import NO_MJCF_FORM
from serpar.sim.mjcf_writer import MjcfExport, differences, write_export
from serpar.sim.scene import Scene, build_scene
from serpar.tasks.episode_config import EpisodeConfig, drive_friction, scene_config

HOME_KEY = "home"
RUN_TIME = (
    ("the arm's and the platform's controllers, and the arm's sensors with their noise "
    "(serpar's control loop at 1 kHz; the actuators here take torques and leg strokes)"),
    ("the transit step: serpar steps at the cell's transit timestep where nothing precise can "
    "happen (sim/transit_step.py); this file holds the fine timestep"),
    "a seated conductor moved into the plate's body (sim/seat_lock.py)",
)
"""What the cell does in code while it runs, not in the model."""


@dataclass(frozen=True)
class SceneExport:
    mjcf: MjcfExport
    seed: int
    not_in_model: tuple[str, ...]
    """What the cell does at run time (:data:`RUN_TIME`, drive friction), named in the header."""
    beyond_the_key: tuple[str, ...]
    """Fields of the file's model that differ from the cell's in-memory model other than the
    keyframe's (empty: the file is the cell's model plus ``home``)."""


def _drive_lines(cfg: EpisodeConfig, scene: Scene) -> list[str]:
    friction = drive_friction(cfg, scene)
    if friction is None:
        return []
    law, out = friction.law, []
    if law.sigmoids:
        out.append(f"sigmoid drive friction (Gaz et al.'s form) on the arm's joints: "
                   f"{NO_MJCF_FORM['sigmoid_friction']}")
    if law.stribeck_excess:
        out.append(f"a Stribeck fall on the arm's joints: {NO_MJCF_FORM['stribeck_friction']}")
    return out


def export_scene(cfg: EpisodeConfig, out: str | Path) -> SceneExport:
    """Write the cell of ``cfg`` (seed, tolerance draw, plant model, friction) at ``out``."""
    scene = build_scene(scene_config(cfg))  # reset: the home state
    model, data = scene.model, scene.data
    spec = scene.spec
    spec.add_key(name=HOME_KEY, time=0.0, qpos=data.qpos.tolist(), qvel=data.qvel.tolist(),
                 act=data.act.tolist(), ctrl=data.ctrl.tolist(),
                 mpos=data.mocap_pos.ravel().tolist(), mquat=data.mocap_quat.ravel().tolist())
    drive = _drive_lines(cfg, scene)
    not_in_model = (*RUN_TIME, *drive)
    lines = [(f"serpar's assembly cell, seed {cfg.seed} (serpar export-scene): arm, Stewart "
             "platform, plate with its drawn bores, tray, conductors, stereo cameras."),
             (f"Open it at the state an episode starts from: keyframe '{HOME_KEY}' (the viewer's "
             "Load key)."),
             "Done in code at run time, not in this file:"] + [f"  - {x}" for x in not_in_model]
    result = write_export(spec, out, lines, {}, (), tuple(drive))
    read = mujoco.MjModel.from_xml_path(str(result.path))
    # the keyframe adds its fields, its name (names_map) and its count (_sizes), nothing else
    beyond = tuple(sorted(differences(model, read, ignore=("key_", "nkey", "names_map", "_sizes"))))
    return SceneExport(result, cfg.seed, not_in_model, beyond)
