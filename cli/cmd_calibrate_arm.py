"""``serpar calibrate arm``: gravity-aware kinematic calibration of the arm (seed 003), on the
simulated Panda or on a panda_1-layout point-consistency folder, with the geometric error
model in MD-H(+beta) form (seed 003), POE/screw form (seed 001) or both side by side;
``--robot FILE``: another arm from its URDF/MJCF (geometric model only)."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from serpar.calibration.arm_campaign import (
    PAPER_MEAN_REDUCTION,
    check_models,
    fold_dict,
    fold_scheme,
    real_data_calibration,
    simulated_calibration,
)
from serpar.calibration.panda_data import load_panda_folder
from serpar.calibration.poe_calibration import GAUGE
from serpar.calibration.robot_campaign import noise_bound_rms, robot_calibration
from serpar.cli import arg_types
from serpar.cli.output import print_json, progress, table
from serpar.cli.robot_option import add_robot_option
from serpar.errors import ConfigError
from serpar.kinematics.robot import PANDA, Robot
from serpar.sim.plants.static_arm import GeometricCampaignConfig, run_geometric_campaign
from serpar.sim.plants.static_panda import TruthConfig, run_campaign
from serpar.sim.robot_file import load_robot

if TYPE_CHECKING:
    from serpar.calibration.arm_calibration import ArmCalibration, ComplianceTest
    from serpar.calibration.arm_campaign import FoldRow, SimRow

MODEL_CHOICES = ("geometric", "gravity")  # serpar.calibration.arm_campaign.MODELS
FORM_CHOICES = ("mdh", "poe", "both")  # serpar.calibration.arm_error_models.FORMS, or both of them
FORM_NAMES = {"mdh": "MD-H", "poe": "POE"}
MAX_TERMS = 6
"""Terms of a correlated parameter's relation printed (a POE base error spreads over ~15)."""


def register_arm(calibrate_sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``arm`` subcommand to the ``calibrate`` group's subparsers; returns its parser."""
    p = calibrate_sub.add_parser(
        "arm", help="arm calibration, geometry-only vs gravity-aware (seed 003), MD-H or POE "
                    "error model (seeds 003, 001)")
    p.add_argument("--model", choices=MODEL_CHOICES, action="append",
                   help="calibrate with this model only (repeatable; default both)")
    p.add_argument("--form", choices=FORM_CHOICES, default="mdh",
                   help="geometric error model: mdh (default; MD-H+beta, seed 003), poe "
                        "(product of exponentials with per-joint twist errors, seed 001), or "
                        "both side by side on the same measurements")
    p.add_argument("--data", metavar="DIR",
                   help="a panda_1-layout folder (<placement>/hole_0.csv, hole_1.csv; two "
                        "placements or more, other files are skipped with a note): train on "
                        "the other placements, test on one, each in turn")
    p.add_argument("--seed", type=arg_types.seed, default=3,
                   help="hidden errors, poses and tracker noise of the simulated arm (default 3)")
    add_robot_option(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_calibrate_arm)
    return p


def _um(v: float) -> str:
    return f"{v * 1e6:.1f}"


def _mm(v: float) -> str:
    return f"{v * 1e3:.3f}"


def cmd_calibrate_arm(args: argparse.Namespace) -> int:
    from pathlib import Path


    robot = load_robot(getattr(args, "robot", None))
    default_models = MODEL_CHOICES if robot is PANDA else ("geometric",)
    models = check_models(tuple(dict.fromkeys(args.model)) if args.model else default_models,
                          robot)
    form = getattr(args, "form", "mdh")
    forms = ("mdh", "poe") if form == "both" else (form,)
    if args.data is not None:
        if not Path(args.data).is_dir():
            raise ConfigError(f"--data {args.data!r}: folder does not exist")
        return _real(args.data, models, args.json, forms, robot)
    if robot is not PANDA:
        return _robot_simulated(robot, args.seed, args.json, forms)
    return _simulated(args.seed, models, args.json, forms)


def _robot_simulated(robot: Robot, seed: int, as_json: bool, forms: tuple[str, ...]) -> int:
    """The geometric campaign of an arm from its model file (serpar.calibration.robot_campaign)."""
    cfg = GeometricCampaignConfig(seed=seed)
    camp = run_geometric_campaign(robot, cfg)
    results = {f: robot_calibration(robot, cfg, f, camp) for f in forms}
    if as_json:
        print_json(results[forms[0]].as_dict() if len(forms) == 1
                   else {"robot": {"name": robot.name, "source": robot.source},
                         "forms": {f: r.as_dict() for f, r in results.items()}})
        return 0
    bound = noise_bound_rms(cfg.tracker_sigma_m)
    print(f"Simulated {robot.label}, {robot.n_joints} joints, seed {cfg.seed}, geometric "
          f"campaign (rigid joints, no gravity model): hidden link errors "
          f"{cfg.link_pos_sigma_m * 1e3:g} mm / {cfg.link_rot_sigma_rad * 1e3:g} mrad, base "
          f"{cfg.base_pos_sigma_m * 1e3:g} mm / {cfg.base_rot_sigma_rad * 1e3:g} mrad, SMR "
          f"{cfg.tool_pos_sigma_m * 1e3:g} mm (1 sigma); tracker noise "
          f"{cfg.tracker_sigma_m * 1e6:g} um (held-out RMS floor {bound * 1e6:.1f} um); "
          f"{cfg.n_train} training + {cfg.n_verify} verification poses")
    names = {"uncalibrated": "uncalibrated", "geometric": "geometry-only"}
    rows = []
    for form, res in results.items():
        for r in res.rows:
            if r.calibration is None and form != forms[0]:
                continue
            label = _label(names[r.label], form, forms, r.calibration)
            rows.append([label, _um(r.verify.rms), _um(r.verify.mean), _um(r.verify.max),
                         _um(r.verify_truth.rms), f"{r.verify.rms / bound:.2f}",
                         "" if r.calibration is None else f"{r.calibration.report.rank}"])
    print(table(["verification poses [um]", "rms", "mean", "max", "rms vs truth",
                 "rms / noise floor", "params"], rows))
    for form, res in results.items():
        cal = res.row("geometric").calibration
        if cal is not None:
            _print_report(_label("geometry-only", form, forms, True), cal, None)
    return 0


def _simulated(seed: int, models: tuple[str, ...], as_json: bool,
               forms: tuple[str, ...] = ("mdh",)) -> int:

    cfg = TruthConfig(seed=seed)
    camp = run_campaign(cfg)  # one campaign for every form; ~2 s a form: no progress bar
    results = {f: simulated_calibration(cfg, models, f, camp) for f in forms}
    result = results[forms[0]]
    if as_json:
        print_json(result.as_dict() if len(forms) == 1
                   else {"forms": {f: r.as_dict() for f, r in results.items()}})
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
    for form, res in results.items():
        for r in res.rows:
            if r.calibration is None and form != forms[0]:
                continue  # the nominal model is the same in both forms
            rows.append(_sim_row(_label(names[r.label], form, forms, r.calibration), r))
    print(table(["verification poses [um]", "mean |x|", "mean |y|", "mean |z|", "mean",
                 "max |x|", "max |y|", "max |z|", "max", "mean vs truth", "params",
                 "train rms/sigma"], rows))
    if {"geometric", "gravity"} <= set(models):
        red = {f: r.reduction("geometric", "gravity") for f, r in results.items()}
        print(table(["gravity-aware vs geometry-only: mean error lower by", "X", "Y", "Z"],
                    [[_label("this simulation", f, forms, True),
                      *(f"{100 * x:.0f} %" for x in red[f])] for f in forms]
                    + [["seed 003 (real 7-DoF robot)", f"{100 * PAPER_MEAN_REDUCTION['x']:.0f} %",
                        f"{100 * PAPER_MEAN_REDUCTION['y']:.0f} %", "not given"]]))
    for form, res in results.items():
        for r in res.rows:
            if r.calibration is not None:
                _print_report(_label(names[r.label], form, forms, True), r.calibration,
                              r.compliance_test)
    return 0


def _label(name: str, form: str, forms: tuple[str, ...], calibrated: object) -> str:
    """Row label: the form is named unless the output is the default MD-H one alone."""
    return name if forms == ("mdh",) or calibrated is None else f"{name} ({FORM_NAMES[form]})"


def _sim_row(label: str, r: SimRow) -> list[object]:
    v, t = r.verify, r.verify_truth
    cal = r.calibration
    return [label, *map(_um, v.mean_abs), _um(v.mean), *map(_um, v.max_abs), _um(v.max),
            _um(t.mean), "" if cal is None else f"{cal.report.rank}",
            "" if cal is None else f"{cal.residual_rms:.2f}"]


def _print_report(label: str, cal: ArmCalibration, test: ComplianceTest | None) -> None:
    rep = cal.report
    skip = ("socket",)
    print(f"{label}: {rep.rank} independent parameters, condition {rep.condition:.3g}")
    print("  non-functional: " + (", ".join(rep.names[i] for i in rep.non_functional) or "none"))
    weak = [rep.names[i] for i in rep.weak if not rep.names[i].startswith(skip)]
    print("  weakly identifiable: " + (", ".join(weak) or "none"))
    rel = [s for s in rep.relations(max_terms=MAX_TERMS) if not s.startswith(skip)]
    print(f"  correlated ({len(rel)}, fixed at nominal): " + "; ".join(rel))
    if cal.model.form == "poe":

        print(f"  gauge: {GAUGE}")
    if test is not None:
        verdict = ("kept" if test.significant else
                   "not significant: the geometric fit is used")
        print(f"  compliances vs geometry-only: F({test.dof[0]}, {test.dof[1]}) = "
              f"{test.f_statistic:.3g}, p = {test.p_value:.2g} -> {verdict}")
    if cal.model.gravity:
        print("  joint compliance [1e-4 rad/(N m)]: "
              + " ".join(f"{c * 1e4:.3f}" for c in cal.compliance))


def _real(folder: str, models: tuple[str, ...], as_json: bool,
          forms: tuple[str, ...] = ("mdh",), robot: Robot = PANDA) -> int:
    data = load_panda_folder(folder, robot)  # once: its notes are printed, every form reuses it
    n_folds = len(data.placements)
    with progress(n_folds * len(forms), "calibrate arm", enabled=sys.stderr.isatty()) as bar:
        by_form = {f: real_data_calibration(data, models, bar.update, f, robot) for f in forms}
    # fold by fold; the "nominal" row (ball offset only) is the same model in both forms
    rows = [r for test in dict.fromkeys(r.test for r in by_form[forms[0]])
            for f in forms for r in by_form[f]
            if r.test == test and (r.label != "nominal" or f == forms[0])]
    if as_json:
        print_json({"folder": folder, "scheme": fold_scheme(n_folds), "notes": list(data.notes),
                    **({} if robot is PANDA else
                       {"robot": {"name": robot.name, "source": robot.source}}),
                    "folds": [fold_dict(r) for r in rows]})
        return 0
    arm = "the Panda" if robot is PANDA else robot.label
    print(f"Point-consistency data {folder}: {fold_scheme(n_folds)}; "
          f"'nominal' = {arm}'s nominal table with only the ball offset fitted")
    for note in data.notes:
        print(f"note: {note}")
    names = {"nominal": "nominal", "geometric": "geometry-only", "gravity": "gravity-aware"}

    def label(r: FoldRow) -> str:
        return _label(names[r.label], r.calibration.model.form, forms, r.label != "nominal" or None)

    print(table(["held out", "model", "ball offset x/y/z [mm]", "train spread rms [mm]",
                 "test spread rms [mm]", "test spread max [mm]", "test 50 mm distance err [mm]",
                 "fitted (incl. sockets)"],
                [[r.test, label(r), "/".join(f"{v * 1e3:.2f}" for v in r.ball_offset_m),
                  _mm(r.train.spread_rms), _mm(r.held_out.spread_rms),
                  _mm(r.held_out.spread_max),
                  " ".join(f"{d * 1e3:+.3f}" for d in r.held_out.distance_errors),
                  r.calibration.report.rank] for r in rows]))
    last = {(r.label, r.calibration.model.form): r for r in rows}
    for f in forms:
        for name in models:
            r = last[(name, f)]
            _print_report(f"{label(r)} (held out {r.test})", r.calibration, r.compliance_test)
    return 0
