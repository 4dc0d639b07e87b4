"""``--robot FILE``: the one meaning every command gives it (serpar calibrate arm, serpar
diagnose): the arm measured, read from its URDF or MJCF (serpar.sim.robot_file); without it,
the Panda."""

from __future__ import annotations

import argparse

ROBOT_HELP = ("the arm measured, from its URDF or MJCF file (the serial chain of hinge joints "
              "from the base to the flange, its joint limits; meshes are not needed); default: "
              "the Panda")


def add_robot_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robot", metavar="FILE", help=ROBOT_HELP)
