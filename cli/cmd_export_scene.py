"""``serpar export-scene --out cell.xml``: the whole cell of an episode as one MJCF that MuJoCo's
own viewer opens (tasks/scene_export.py); ``serpar view``: that cell in the viewer, where a
display exists."""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys

from serpar.cli import arg_types
from serpar.cli.out_paths import add_force, out_file
from serpar.cli.output import print_json
from serpar.errors import ConfigError
from serpar.sim.config_io import load_yaml_config
from serpar.sim.scene import build_scene
from serpar.tasks.episode_config import EpisodeConfig, scene_config
from serpar.tasks.scene_export import export_scene

CONFIG_HELP = ("episode config YAML, as serpar run --config (keys of "
               "serpar.tasks.episode_config.EpisodeConfig): its plant model and friction follow")
SEED_HELP = "the episode's seed: its tolerance draw and the cell's hidden errors (default: the config's, 0)"


def _add_cell(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=arg_types.seed, help=SEED_HELP)
    p.add_argument("--config", metavar="F.yaml", help=CONFIG_HELP)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export-scene", help="write the whole cell as one MJCF (MuJoCo's viewer "
                                            "opens it; every compiled field equal to serpar's)")
    p.add_argument("--out", required=True, metavar="cell.xml", help="the MJCF to write")
    _add_cell(p)
    add_force(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_export_scene)
    v = sub.add_parser("view", help="open the cell in MuJoCo's viewer (needs a display)")
    _add_cell(v)
    v.set_defaults(func=cmd_view)


def cell_config(args: argparse.Namespace) -> EpisodeConfig:
    cfg = load_yaml_config(EpisodeConfig, args.config) if args.config else EpisodeConfig()
    return cfg if args.seed is None else dataclasses.replace(cfg, seed=args.seed)


def cmd_export_scene(args: argparse.Namespace) -> int:
    out = out_file(args.out, "--out", args.force, suffix=".xml")
    cfg = cell_config(args)
    result = export_scene(cfg, out)
    m = result.mjcf
    if args.json:
        print_json({"mjcf": str(m.path), "seed": result.seed,
                    "round_trip_max_abs": m.round_trip_max,
                    "round_trip_field": m.round_trip_field or None,
                    "differs_from_the_cell_beyond_the_key": list(result.beyond_the_key),
                    "not_in_the_file": list(result.not_in_model)})
        return 0
    exact = "exact" if m.round_trip_max == 0 else f"{m.round_trip_max:.3g} in {m.round_trip_field}"
    print(f"wrote {m.path}: the cell of seed {result.seed}; round trip {exact}"
          + ("" if not result.beyond_the_key
             else f"; differs from the cell in {', '.join(result.beyond_the_key)}"))
    print(f"open it: python -m mujoco.viewer --mjcf {m.path}  (keyframe 'home': the start state)")
    for line in result.not_in_model:
        print(f"done in code at run time: {line}")
    return 0


def has_display() -> bool:
    """Whether a window can open: macOS and Windows always; elsewhere an X or Wayland display."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY")
                                                       or os.environ.get("WAYLAND_DISPLAY"))


def cmd_view(args: argparse.Namespace) -> int:
    cfg = cell_config(args)
    if not has_display():
        raise ConfigError("no display (DISPLAY and WAYLAND_DISPLAY unset): write the cell with "
                          "`serpar export-scene --out cell.xml` and open it where one is")
    import mujoco.viewer  # a GUI library (GLFW): only where a window can open

    scene = build_scene(scene_config(cfg))  # at the home state
    mujoco.viewer.launch(scene.model, scene.data)
    return 0
