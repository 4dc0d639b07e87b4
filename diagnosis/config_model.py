"""A simulator config as the nominal model of a diagnosis (``serpar diagnose REC --model
cell.yaml``): the arm physics an episode config gives the simulated cell, as a model file's
effects, so a recording is compared with the cell that config builds rather than with the
controllers' frictionless arm.

What carries over (tasks/episode_config.py's ``scene_config``):

- ``arm_friction`` x the Panda's dry friction levels (serpar.sim.arm.PANDA_COULOMB_FRICTION) as the
  ``joint_friction`` effect (Fc; Fv 0: the cell's arm adds no viscous term); with
  ``arm_friction_form: gaz`` Gaz et al.'s sigmoid at that scale as the ``sigmoid_friction``
  effect (phi1 scaled, phi2 and phi3 theirs: the cell's drive torque exactly);
- ``plant_model``: that diagnosis model file's effects; its joint friction, when it has one,
  replaces ``arm_friction``'s, as it does in the cell; its drive friction (sigmoid, Stribeck)
  acts beside the config's.

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
from serpar.sim.plants.drive_friction import gaz_sigmoid_params
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
    evidence: tuple[tuple[str, str], ...] = ()
    if cfg.arm_friction and "joint_friction" not in effects and cfg.arm_friction_form == "gaz":
        if "sigmoid_friction" in effects:
            raise ConfigError(f"config {p}: arm_friction_form gaz and a plant model with its own "
                              "sigmoid_friction act together in the cell, which one model's "
                              "sigmoid cannot state; give the sum in the plant model")
        params = gaz_sigmoid_params(cfg.arm_friction)
        effects.append("sigmoid_friction")
        blocks.append(("sigmoid_friction", ParamBlock(tuple(params), tuple(params.values()),
                                                      (0.0,) * len(params))))
        evidence = (("sigmoid_friction", (f"Gaz et al.'s sigmoid at {cfg.arm_friction:g} x a "
                     "real Panda's (arm_friction_form: gaz)")),)
    elif cfg.arm_friction and "joint_friction" not in effects:
        names = tuple(f"Fc{j}" for j in JOINTS) + tuple(f"Fv{j}" for j in JOINTS)
        values = tuple(cfg.arm_friction * f for f in PANDA_COULOMB_FRICTION) + (0.0,) * len(JOINTS)
        effects.append("joint_friction")
        blocks.append(("joint_friction", ParamBlock(names, values, (0.0,) * len(names))))
    return DiagnosisModel(str(p), f"episode config {p}", "arm_dynamics", tuple(effects),
                          tuple(blocks), evidence=evidence)
