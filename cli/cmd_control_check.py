"""``serpar control-check``: the paper's controller figures, measured (seed 000 §3-§4)."""

from __future__ import annotations

import argparse
import sys

from serpar.checks.control_check import PAPER, STAGES, run_control_check
from serpar.cli import arg_types
from serpar.cli.output import print_json, progress, table
from serpar.errors import UnknownNameError

STAGE_HELP = "path, descent, press, round_trip, tracking"


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("control-check", help="arm and Stewart controller figures beside the "
                                             "paper's (exit 1 if a bound fails)")
    p.add_argument("--no-noise", action="store_true",
                   help="ideal sensors (default: torque noise, bias drift, encoder quantisation)")
    p.add_argument("--seed", type=arg_types.seed, default=0, help="sensor noise seed (default 0)")
    p.add_argument("--stage", action="append", help=f"run only this stage (repeatable): {STAGE_HELP}")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_control_check)
    return p


def _xyz(values: list[float], digits: int = 4) -> str:
    return " / ".join(f"{v:.{digits}f}" for v in values)


def cmd_control_check(args: argparse.Namespace) -> int:
    stages = tuple(args.stage) if args.stage else STAGES
    for s in stages:
        if s not in STAGES:
            raise UnknownNameError("stage", s, STAGES)
    bar = progress(len(stages), "control-check", enabled=sys.stderr.isatty())

    def step(name: str) -> None:
        bar.set_postfix_str(name)
        bar.update(1)

    report = run_control_check(not args.no_noise, args.seed, stages, step)
    bar.close()
    if args.json:
        print_json(report.as_dict())
        return 0 if all(report.passed().values()) else 1
    r, ok = report.results, report.passed()
    rows = []
    if "path" in r:
        rows.append(["1 path to (0.4, 0.3, 0.25) m: max deviation X/Y/Z [mm]",
                     _xyz(r["path"]["max_deviation_mm"]), PAPER["path"], ok["path"]])
        rows.append(["  final error X/Y/Z [mm]", _xyz(r["path"]["final_error_mm"]), "", ""])
    if "descent" in r:
        rows.append(["2 0.2 m down z, force-position: final error X/Y/Z [mm]",
                     _xyz(r["descent"]["final_error_mm"]), PAPER["descent"], ok["descent"]])
        rows.append(["  max path deviation X/Y/Z [mm]", _xyz(r["descent"]["max_deviation_mm"]),
                     "", ""])
    if "round_trip" in r:
        rt = r["round_trip"]
        rows.append([f"4 Stewart IK->FK, {rt['poses']} poses: max error [m]",
                     f"{rt['max_position_error_m']:.2e}", PAPER["round_trip"], ok["round_trip"]])
    if "tracking" in r:
        tr = r["tracking"]
        rows.append([f"4 Stewart commanded vs simulated, {tr['poses']} poses [um, deg]",
                     f"{tr['max_position_error_m'] * 1e6:.3f}, {tr['max_rotation_error_deg']:.1e}",
                     PAPER["tracking"], ok["tracking"]])
    print(f"serpar control-check  sensor noise {'on' if report.noise else 'off'}")
    print(table(["figure", "measured", "paper / bound", "pass"],
                [[a, b, c, "" if d == "" else ("PASS" if d else "FAIL")] for a, b, c, d in rows]))
    if "press" in r:
        print("\n3 journal pressed on the baseplate at F_d = 5 N (true contact force)")
        print(table(["law", "peak [N]", "overshoot [%]", "settling +-5% [s]", "steady [N]",
                     "estimate [N]", "saturation"],
                    [[k, f"{v['peak_force_n']:.2f}", f"{v['overshoot_pct']:.1f}",
                      "never" if v["settling_time_s"] != v["settling_time_s"] else
                      f"{v['settling_time_s']:.3f}", f"{v['steady_force_n']:.3f}",
                      f"{v['steady_estimate_n']:.3f}", v["saturation"]]
                     for k, v in r["press"].items()]))
    return 0 if all(ok.values()) else 1
