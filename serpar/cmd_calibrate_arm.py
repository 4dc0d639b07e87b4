"""``serpar calibrate arm``: gravity-aware kinematic calibration of the arm (seed 003), on the
simulated Panda or on a panda_1-layout point-consistency folder."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from serpar.output import print_json, progress, table

if TYPE_CHECKING:
    from identify.arm_calibration import ArmCalibration, ComplianceTest

MODEL_CHOICES = ("geometric", "gravity")  # tasks.arm_calibration_run.MODELS


def register_arm(calibrate_sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``arm`` subcommand to the ``calibrate`` group's subparsers; returns its parser."""
    p = calibrate_sub.add_parser(
        "arm", help="MD-H(+beta) arm calibration, geometry-only vs gravity-aware (seed 003)")
    p.add_argument("--model", choices=MODEL_CHOICES, action="append",
                   help="calibrate with this model only (repeatable; default both)")
    p.add_argument("--data", metavar="DIR",
                   help="a panda_1-layout folder (<placement>/hole_0.csv, hole_1.csv): train on "
                        "two placements, test on the third, each in turn")
    p.add_argument("--seed", type=int, default=3,
                   help="hidden errors, poses and tracker noise of the simulated arm (default 3)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_calibrate_arm)
    return p


def _um(v: float) -> str:
    return f"{v * 1e6:.1f}"


def _mm(v: float) -> str:
    return f"{v * 1e3:.3f}"


def cmd_calibrate_arm(args: argparse.Namespace) -> int:
    from pathlib import Path

    from sim.errors import ConfigError

    models = tuple(dict.fromkeys(args.model)) if args.model else MODEL_CHOICES
    if args.data is not None:
        if not Path(args.data).is_dir():
            raise ConfigError(f"--data {args.data!r}: folder does not exist")
        return _real(args.data, models, args.json)
    return _simulated(args.seed, models, args.json)


def _simulated(seed: int, models: tuple[str, ...], as_json: bool) -> int:
    from tasks.arm_calibration_run import PAPER_MEAN_REDUCTION, simulated_calibration
    from tasks.arm_truth import TruthConfig

    cfg = TruthConfig(seed=seed)
    result = simulated_calibration(cfg, models)  # ~2 s: no progress bar
    if as_json:
        print_json(result.as_dict())
        return 0
    stiff = "/".join(f"{k / 1e3:g}" for k in cfg.stiffness) if cfg.stiffness else "rigid"
    print(f"Simulated Panda, seed {cfg.seed}: hidden link errors {cfg.link_pos_sigma_m * 1e3:g} mm"
          f" / {cfg.link_rot_sigma_rad * 1e3:g} mrad, base {cfg.base_pos_sigma_m * 1e3:g} mm / "
          f"{cfg.base_rot_sigma_rad * 1e3:g} mrad, SMR {cfg.tool_pos_sigma_m * 1e3:g} mm (1 sigma);"
          f" joint stiffness {stiff} kN m/rad (gravity deflection up to "
          f"{result.max_deflection_rad.max() * 1e3:.2f} mrad); tracker noise "
          f"{cfg.tracker_sigma_m * 1e6:g} um; {cfg.n_train} training + {cfg.n_verify} "
          "verification poses")
    names = {"uncalibrated": "uncalibrated", "geometric": "geometry-only",
             "gravity": "gravity-aware"}
    rows = []
    for r in result.rows:
        v, t = r.verify, r.verify_truth
        cal = r.calibration
        rows.append([names[r.label], *map(_um, v.mean_abs), _um(v.mean),
                     *map(_um, v.max_abs), _um(v.max), _um(t.mean),
                     "" if cal is None else f"{cal.report.rank}",
                     "" if cal is None else f"{cal.residual_rms:.2f}"])
    print(table(["verification poses [um]", "mean |x|", "mean |y|", "mean |z|", "mean",
                 "max |x|", "max |y|", "max |z|", "max", "mean vs truth", "params",
                 "train rms/sigma"], rows))
    if {"geometric", "gravity"} <= set(models):
        red = result.reduction("geometric", "gravity")
        print(table(["gravity-aware vs geometry-only: mean error lower by", "X", "Y", "Z"],
                    [["this simulation", *(f"{100 * x:.0f} %" for x in red)],
                     ["seed 003 (real 7-DoF robot)", f"{100 * PAPER_MEAN_REDUCTION['x']:.0f} %",
                      f"{100 * PAPER_MEAN_REDUCTION['y']:.0f} %", "not given"]]))
    for r in result.rows:
        if r.calibration is not None:
            _print_report(names[r.label], r.calibration, r.compliance_test)
    return 0


def _print_report(label: str, cal: ArmCalibration, test: ComplianceTest | None) -> None:
    rep = cal.report
    skip = ("socket",)
    print(f"{label}: {rep.rank} independent parameters, condition {rep.condition:.3g}")
    print("  non-functional: " + (", ".join(rep.names[i] for i in rep.non_functional) or "none"))
    weak = [rep.names[i] for i in rep.weak if not rep.names[i].startswith(skip)]
    print("  weakly identifiable: " + (", ".join(weak) or "none"))
    rel = [s for s in rep.relations() if not s.startswith(skip)]
    print(f"  correlated ({len(rel)}, fixed at nominal): " + "; ".join(rel))
    if test is not None:
        verdict = ("kept" if test.significant else
                   "not significant: the geometric fit is used")
        print(f"  compliances vs geometry-only: F({test.dof[0]}, {test.dof[1]}) = "
              f"{test.f_statistic:.3g}, p = {test.p_value:.2g} -> {verdict}")
    if cal.model.gravity:
        print("  joint compliance [1e-4 rad/(N m)]: "
              + " ".join(f"{c * 1e4:.3f}" for c in cal.compliance))


def _real(folder: str, models: tuple[str, ...], as_json: bool) -> int:
    from pathlib import Path

    from tasks.arm_calibration_run import fold_dict, real_data_calibration

    n_folds = sum(1 for p in Path(folder).iterdir() if p.is_dir() and not p.name.startswith("."))
    with progress(n_folds, "calibrate arm", enabled=sys.stderr.isatty()) as bar:
        rows = real_data_calibration(folder, models, bar.update)
    if as_json:
        print_json({"folder": folder, "folds": [fold_dict(r) for r in rows]})
        return 0
    print(f"Point-consistency data {folder}: train on two tool placements, test on the third; "
          "'nominal' = the Panda's nominal table with only the ball offset fitted")
    names = {"nominal": "nominal", "geometric": "geometry-only", "gravity": "gravity-aware"}
    print(table(["held out", "model", "ball offset x/y/z [mm]", "train spread rms [mm]",
                 "test spread rms [mm]", "test spread max [mm]", "test 50 mm distance err [mm]",
                 "fitted (incl. sockets)"],
                [[r.test, names[r.label], "/".join(f"{v * 1e3:.2f}" for v in r.ball_offset_m),
                  _mm(r.train.spread_rms), _mm(r.held_out.spread_rms),
                  _mm(r.held_out.spread_max),
                  " ".join(f"{d * 1e3:+.3f}" for d in r.held_out.distance_errors),
                  r.calibration.report.rank] for r in rows]))
    last = {r.label: r for r in rows}
    for label in models:
        _print_report(f"{names[label]} (held out {last[label].test})", last[label].calibration,
                      last[label].compliance_test)
    return 0
