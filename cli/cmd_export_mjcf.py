"""``serpar export-mjcf MODEL --out OUT.xml``: a diagnosis model file as one MJCF of the arm
(sim/mjcf_export.py) that plain MuJoCo loads, and that ``serpar run`` and ``serpar diagnose
--model`` take back."""

from __future__ import annotations

import argparse

from serpar.cli.out_paths import add_force, out_file
from serpar.cli.output import print_json
from serpar.sim.mjcf_export import MjcfExport, export_arm_mjcf, read_any_model


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("export-mjcf", help="write a diagnosis model (OUT.model.json) as the "
                                           "arm's MJCF: established effects only, full precision")
    p.add_argument("model", metavar="MODEL.model.json",
                   help="a model file of serpar diagnose --report (or an MJCF it exported)")
    p.add_argument("--out", required=True, metavar="OUT.xml", help="the MJCF to write")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_export_mjcf)
    return p


def export_summary(result: MjcfExport) -> dict[str, object]:
    return {"mjcf": str(result.path), "applied": list(result.applied),
            "not_expressed": list(result.not_expressed),
            "round_trip_max_abs": result.round_trip_max,
            "round_trip_field": result.round_trip_field or None}


def print_export(result: MjcfExport) -> None:
    print(f"wrote {result.path}: {', '.join(result.applied) or 'no effect (the nominal arm)'}; "
          f"round trip {'exact' if result.round_trip_max == 0 else f'{result.round_trip_max:.3g} in {result.round_trip_field}'}")
    for line in result.not_expressed:
        print(f"not expressed: {line}")


def cmd_export_mjcf(args: argparse.Namespace) -> int:
    out = out_file(args.out, "--out", args.force, suffix=".xml")
    result = export_arm_mjcf(read_any_model(args.model), out)
    if args.json:
        print_json(export_summary(result))
    else:
        print_export(result)
    return 0
