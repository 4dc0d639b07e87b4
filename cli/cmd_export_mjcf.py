"""``serpar export-mjcf MODEL --out OUT.xml``: a diagnosis model file as one MJCF of the arm
(sim/mjcf_export.py) that plain MuJoCo loads, and that ``serpar run`` and ``serpar diagnose
--model`` take back: serpar's Panda, or with ``--robot FILE`` the user's own arm (``--urdf
OUT.urdf``: also the user's URDF with the friction its ``<dynamics>`` holds)."""

from __future__ import annotations

import argparse

from serpar.cli.out_paths import add_force, out_file
from serpar.cli.output import print_json
from serpar.sim.mjcf_export import MjcfExport, export_mjcf, is_mjcf_path, read_mjcf
from serpar.sim.mjcf_panda import BUILT_IN
from serpar.sim.model_file import read_model_file
from serpar.sim.urdf_export import UrdfExport, export_urdf, require_urdf

ROBOT_HELP = ("the arm's URDF/MJCF: write that arm with the model's effects (default: serpar's "
              "Panda, or the arm an exported MJCF given as MODEL is of)")


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("export-mjcf", help="write a diagnosis model (OUT.model.json) as the "
                                           "arm's MJCF: established effects only, full precision")
    p.add_argument("model", metavar="MODEL.model.json",
                   help="a model file of serpar diagnose --report (or an MJCF it exported)")
    p.add_argument("--out", required=True, metavar="OUT.xml", help="the MJCF to write")
    p.add_argument("--robot", metavar="FILE", help=ROBOT_HELP)
    p.add_argument("--urdf", metavar="OUT.urdf",
                   help="also write the --robot URDF with each joint's <dynamics> friction and "
                        "damping from the model")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_export_mjcf)
    return p


def export_summary(result: MjcfExport) -> dict[str, object]:
    return {"mjcf": str(result.path), "applied": list(result.applied),
            "not_expressed": list(result.not_expressed),
            "round_trip_max_abs": result.round_trip_max,
            "round_trip_field": result.round_trip_field or None}


def urdf_summary(result: UrdfExport) -> dict[str, object]:
    return {"urdf": str(result.path), "joints": list(result.joints),
            "not_held": list(result.not_held)}


def print_export(result: MjcfExport) -> None:
    exact = ("exact" if result.round_trip_max == 0
             else f"{result.round_trip_max:.3g} in {result.round_trip_field}")
    print(f"wrote {result.path}: {', '.join(result.applied) or 'no effect (the nominal arm)'}; "
          f"round trip {exact}")
    for line in result.not_expressed:
        print(f"not expressed: {line}")


def print_urdf(result: UrdfExport) -> None:
    print(f"wrote {result.path}: <dynamics> of {len(result.joints)} joint(s)")
    for line in result.not_held:
        print(f"not held by the URDF: {line}")


def cmd_export_mjcf(args: argparse.Namespace) -> int:
    out = out_file(args.out, "--out", args.force, suffix=".xml")
    urdf = out_file(args.urdf, "--urdf", args.force, suffix=".urdf") if args.urdf else None
    notes: tuple[str, ...] = ()
    robot = args.robot
    if is_mjcf_path(args.model):
        read = read_mjcf(args.model)
        model, notes = read.model, read.notes
        robot = robot or (None if read.arm == BUILT_IN else read.arm)
    else:
        model = read_model_file(args.model)
    if urdf is not None:
        require_urdf(robot)
    result = export_mjcf(model, out, robot)
    written = export_urdf(model, robot, urdf) if urdf is not None else None
    if args.json:
        print_json({**export_summary(result), "robot": robot or BUILT_IN, "notes": list(notes),
                    "urdf": None if written is None else urdf_summary(written)})
    else:
        for line in notes:
            print(f"note: {line}")
        print_export(result)
        if written is not None:
            print_urdf(written)
    return 0
