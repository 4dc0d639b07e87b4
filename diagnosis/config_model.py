"""A simulator config as the nominal model of a diagnosis (``serpar diagnose REC --model
cell.yaml``): the arm physics an episode config gives the simulated cell, as a model file's
effects, so a recording is compared with the cell that config builds rather than with the
controllers' frictionless arm.

What carries over (tasks/episode_config.py's ``scene_config``):

- ``arm_friction`` x the Panda's dry friction levels (serpar.sim.arm.PANDA_COULOMB_FRICTION) as the
  ``joint_friction`` effect (Fc; Fv 0: the cell's arm adds no viscous term); with
  ``arm_friction_form: gaz`` the same levels, the sigmoid's level at speed (its offset and its
  smooth passage through zero are outside the effect's form: said in the model's evidence);
- ``plant_model``: that diagnosis model file's effects; its joint friction, when it has one,
  replaces ``arm_friction``'s, as it does in the cell.

Nothing else in an episode config changes the arm's dynamics (the Stewart errors, cameras and
tolerances belong to other parts of the cell), so nothing else is taken.
"""

from __future__ import annotations

from pathlib import Path

from serpar.errors import ConfigError
from serpar.sim.arm import PANDA_COULOMB_FRICTION
from serpar.sim.config_io import load_yaml_config
from serpar.sim.mjcf_export import read_any_model
from serpar.sim.model_file import DiagnosisModel, ParamBlock
from serpar.tasks.episode_config import EpisodeConfig

CONFIG_SUFFIXES = (".yaml", ".yml")
JOINTS = range(1, len(PANDA_COULOMB_FRICTION) + 1)


def is_config_path(path: str | Path) -> bool:
    return Path(path).suffix.lower() in CONFIG_SUFFIXES


def model_from_episode_config(path: str | Path) -> DiagnosisModel:
    """The arm physics of the cell an episode config (``serpar run --config`` YAML) builds."""

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"config {p} not found (an episode config YAML, as `serpar run "
                          "--config` takes)")
    return model_from_config(load_yaml_config(EpisodeConfig, str(p)), str(p))


def model_from_config(cfg: EpisodeConfig, source: str) -> DiagnosisModel:
    """The arm physics of the cell ``cfg`` builds (``source``: where the config came from)."""
    p = source
    effects: list[str] = []
    blocks: list[tuple[str, ParamBlock]] = []
    if cfg.plant_model is not None:
        plant = read_any_model(cfg.plant_model)
        effects += plant.effects
        blocks += [b for b in plant.blocks if b[0] in plant.effects]
    if cfg.arm_friction and "joint_friction" not in effects:
        names = tuple(f"Fc{j}" for j in JOINTS) + tuple(f"Fv{j}" for j in JOINTS)
        values = tuple(cfg.arm_friction * f for f in PANDA_COULOMB_FRICTION) + (0.0,) * len(JOINTS)
        effects.append("joint_friction")
        blocks.append(("joint_friction", ParamBlock(names, values, (0.0,) * len(names))))
    gaz = ("the level at speed of the Gaz sigmoid the config names (arm_friction_form: gaz); "
           "its offset and its passage through zero are not in this form")
    evidence = (("joint_friction", gaz),) if cfg.arm_friction_form == "gaz" and cfg.arm_friction else ()
    return DiagnosisModel(str(p), f"episode config {p}", "arm_dynamics", tuple(effects),
                          tuple(blocks), evidence=evidence)
