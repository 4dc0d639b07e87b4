"""``serpar calibrate stewart`` (and the ``arm`` subcommand of :mod:`serpar.cli.cmd_calibrate_arm`): the 42-parameter Stewart calibration of seed 000 §4.2-4.3,
solvers side by side (issue 6)."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from serpar.calibration.stewart_calibration import (
    SOLVERS,
    StewartCalibrationConfig,
    measured_noise,
    run_calibration,
)
from serpar.calibration.stewart_calibration_plots import plot_report
from serpar.calibration.stewart_campaign import MocapNoise
from serpar.calibration.stewart_params import save_stewart_parameters
from serpar.calibration.stewart_solvers import SwarmConfig
from serpar.calibration.stewart_stereo import StereoConfig
from serpar.cli import arg_types
from serpar.cli.cmd_calibrate_arm import register_arm
from serpar.cli.out_paths import add_force, out_file, out_folder
from serpar.cli.output import print_json, progress, table
from serpar.errors import ConfigError

PAPER = {"before_mm": (4.9863, 4.5961, 4.6987), "before_deg": (0.4810, 0.4743, 0.4969),
         "after_mm": (0.0089, 0.0098, 0.0098)}
"""Seed 000 §4.3 (Figs. 8-9): initial and calibrated maximum errors along x, y, z."""


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("calibrate", help="kinematic calibration: stewart (seed 000 §4.2), arm (seeds 001, 003)")
    group = p.add_subparsers(dest="target", metavar="{stewart,arm}", required=True)
    register_arm(group)
    s = group.add_parser("stewart", help="hidden errors -> measure -> identify -> compensate -> re-measure")
    s.add_argument("--poses", default="table3", help="table3 (default, seed 000 Table 3), optimal, or a count "
                                                     "of random poses")
    s.add_argument("--n-poses", type=int, default=20, help="pose count for --poses optimal (default 20)")
    s.add_argument("--noise", type=float, nargs=2, metavar=("MM", "DEG"), default=(0.05, 0.02),
                   help="motion-capture noise, 1 sigma (default 0.05 mm 0.02 deg; 0 0 = noise-free)")
    s.add_argument("--solver", default="all", help="tls, lm, pso, or all (default), comma-separated")
    s.add_argument("--errors", default="seed000", help="hidden errors: seed000 (default: drawn to seed 000's "
                                                       "+-5 mm / +-0.5 deg box), table5, or a parameters file")
    s.add_argument("--source", default="cell", help="what measures the platform poses: cell (default: motion capture "
                                                    "in the MuJoCo cell), stereo (the top stereo pair in the cell, "
                                                    "from rendered pixels; --noise unused, the cameras' error is "
                                                    "measured and reported) or kinematic (exact kinematics + mocap)")
    s.add_argument("--camera-width", type=int, default=2048, help="stereo readout width: 2048 (default), 1024, 512")
    s.add_argument("--verify", type=int, default=30, help="random verification poses (default 30)")
    s.add_argument("--seed", type=arg_types.seed, default=0)
    s.add_argument("--out", help="write the parameters identified by the best solver (a stewart_calibration "
                                 "file; an existing one is refused unless --force)")
    s.add_argument("--plot", metavar="DIR", help="write per-pose error plots before/after (like Figs. 8-9; a "
                                                 "folder that holds files is refused unless --force)")
    add_force(s)
    s.add_argument("--json", action="store_true", help="print JSON")
    s.set_defaults(func=cmd_calibrate_stewart)
    return p


def config_from(args: argparse.Namespace):
    solvers = SOLVERS if args.solver == "all" else tuple(s.strip() for s in args.solver.split(","))
    poses, n = args.poses, args.n_poses
    if poses.isdigit():
        poses, n = "random", int(poses)
    elif poses not in ("table3", "optimal"):
        raise ConfigError(f"--poses {args.poses!r}; valid: table3, optimal, or a pose count")

    return StewartCalibrationConfig(poses=poses, n_poses=n, noise=MocapNoise(args.noise[0] * 1e-3, args.noise[1]),
                                    solvers=solvers, errors=args.errors, source=args.source,
                                    stereo=StereoConfig(width=args.camera_width),
                                    verify_poses=args.verify, swarm=SwarmConfig(seed=args.seed), seed=args.seed)


def _row(label: str, errs) -> list[str]:
    mm = errs.max_abs[:3] * 1e3
    deg = np.degrees(errs.max_abs[3:])
    return [label, *(f"{v:.4f}" for v in mm), *(f"{v:.5f}" for v in deg), f"{errs.u_bar * 1e3:.4f}",
            f"{errs.e_bar * 1e3:.4f}"]


def report_dict(report) -> dict:
    def errs(e) -> dict:
        return {"max_abs_mm": (e.max_abs[:3] * 1e3).tolist(), "max_abs_deg": np.degrees(e.max_abs[3:]).tolist(),
                "u_bar_mm": e.u_bar * 1e3, "e_bar_mm": e.e_bar * 1e3, "rms_mm": e.rms * 1e3,
                "rms_deg": float(np.degrees(e.rms_angle))}

    return {"source": report.source, "measurement": measurement_dict(report),
            "smallest_singular_value": report.smallest_singular_value, "predicted_rms_mm": report.predicted_rms_m * 1e3,
            "hidden_max_mm": float(np.abs(report.hidden).max() * 1e3),
            "before": {"train": errs(report.before_train), "verify": errs(report.before_verify)},
            "solvers": [{"solver": o.solver, "seconds": o.seconds, "failure": o.failure,
                         **({} if o.failure else {"train": errs(o.train), "verify": errs(o.verify),
                                                  "parameter_error_max_mm": o.parameter_error_max_m * 1e3,
                                                  "residual_rms_mm": o.identification.residual_rms_m * 1e3,
                                                  "unreachable_poses": len(o.unreachable)})}
                        for o in report.outcomes], "paper": PAPER}


def measurement_dict(report) -> dict:
    """Which instrument measured the training poses and how well (against the simulator's truth)."""

    c = report.campaign
    pos, ang = measured_noise(c) if c is not None else (float("nan"), float("nan"))
    out = {"instrument": "top stereo pair" if report.source == "stereo" else "motion capture",
           "planned_poses": report.planned_poses, "measured_poses": len(report.train_poses[0]),
           "skipped": [{"pose": k + 1, "reason": why} for k, why in (c.skipped if c else ())],
           "measured_sigma_mm": pos * 1e3, "measured_sigma_deg": float(np.degrees(ang)),
           "sigma_used_mm": report.noise_used[0] * 1e3, "sigma_used_deg": float(np.degrees(report.noise_used[1]))}
    if c is not None and len(c.kept):
        out["rms_3d_mm"] = float(np.sqrt(np.mean(np.sum(c.position_error**2, axis=1))) * 1e3)
        out["max_3d_mm"] = float(np.linalg.norm(c.position_error, axis=1).max() * 1e3)
        out["max_angle_deg"] = float(np.degrees(np.linalg.norm(c.angle_error, axis=1).max()))
        out["mean_error_mm"] = (c.position_error.mean(axis=0) * 1e3).tolist()
    if c is not None and c.registration_error is not None:
        out["registration_error_mm"] = c.registration_error[0] * 1e3
        out["registration_error_deg"] = float(np.degrees(c.registration_error[1]))
    return out


def cmd_calibrate_stewart(args: argparse.Namespace) -> int:
    cfg = config_from(args)
    if args.out:  # before the campaign
        out_file(args.out, "--out", args.force)
    if args.plot:
        out_folder(args.plot, "--plot", args.force)
    bar = progress(2 + 2 * len(cfg.solvers), "campaign stages", enabled=sys.stderr.isatty())

    def stage(text: str) -> None:
        bar.update(1)
        bar.set_postfix_str(text)

    report = run_calibration(cfg, on_stage=stage)
    bar.close()
    good = [o for o in report.outcomes if o.failure is None]
    best = min(good, key=lambda o: o.verify.rms) if good else None
    if args.out and best is not None:
        save_stewart_parameters(args.out, best.identification.errors,
                                {"solver": best.solver, "poses": cfg.poses, "source": cfg.source,
                                 **({"frame": "registered at home by the top stereo pair"}
                                    if cfg.source == "stereo" else {})})
    if args.plot:

        plot_report(report, args.plot)
    if args.json:
        print_json(report_dict(report))
        return 0 if good else 1
    m = measurement_dict(report)
    noise = (f"stereo pair at {cfg.stereo.width} px" if cfg.source == "stereo" else
             f"mocap noise {cfg.noise.position_m * 1e3:g} mm / {cfg.noise.angle_deg:g} deg")
    print(f"serpar calibrate stewart  poses {cfg.poses} ({m['measured_poses']} of {m['planned_poses']} measured), "
          f"source {cfg.source} ({noise}), hidden errors {cfg.errors} "
          f"(largest {np.abs(report.hidden).max() * 1e3:.3f} mm)")
    print(f"poses measured by {m['instrument']}: error against the simulator's truth, per axis RMS "
          f"{m['measured_sigma_mm']:.4f} mm / {m['measured_sigma_deg']:.4f} deg"
          + (f" (3-D RMS {m['rms_3d_mm']:.4f} mm, max {m['max_3d_mm']:.4f} mm, {m['max_angle_deg']:.4f} deg)"
             if "rms_3d_mm" in m else "")
          + (f"; home registration off by {m['registration_error_mm']:.4f} mm / {m['registration_error_deg']:.4f} "
             "deg (common to every pose: a gauge, cancels)" if "registration_error_mm" in m else ""))
    for skip in m["skipped"]:
        print(f"  skipped pose {skip['pose']}: {skip['reason']}")
    if m["skipped"]:
        print(f"  {len(m['skipped'])} of {m['planned_poses']} poses skipped, reported above")
    if cfg.source == "stereo":
        print("platform errors are scored in the frame registered at home (where the cell uses the model), "
              "so the home pose's own error is not counted before or after")
    head = ["", "max |x| mm", "max |y| mm", "max |z| mm", "rx deg", "ry deg", "rz deg", "U-bar mm", "E-bar mm"]
    rows = [_row("before (training poses)", report.before_train), ["paper before", *map(str, PAPER["before_mm"]),
            *map(str, PAPER["before_deg"]), "", ""]]
    for o in report.outcomes:
        rows.append([f"after {o.solver}", "failed (see below)", *[""] * 7] if o.failure
                    else _row(f"after {o.solver} (training)", o.train))
    rows.append(["paper after (TLS)", *map(str, PAPER["after_mm"]), "", "", "", "", ""])
    rows.append(_row("before (verification poses)", report.before_verify))
    rows += [_row(f"after {o.solver} (verification)", o.verify) for o in good]
    print(table(head, rows))
    print(table(["solver", "run time s", "leg residual rms um", "largest parameter error mm"],
                [[o.solver, f"{o.seconds:.2f}", "-" if o.failure else f"{o.identification.residual_rms_m * 1e6:.3f}",
                  "-" if o.failure else f"{o.parameter_error_max_m * 1e3:.4f}"] for o in report.outcomes]))
    print(f"identification Jacobian: smallest/largest scaled singular value {report.smallest_singular_value:.2e}; "
          f"noise-predicted RMS position error at the verification poses {report.predicted_rms_m * 1e3:.4f} mm "
          f"(sigma {report.noise_used[0] * 1e3:.4f} mm / {np.degrees(report.noise_used[1]):.4f} deg"
          f"{', measured' if cfg.source == 'stereo' else ''})"
          + (f", {best.solver} reached {best.verify.rms * 1e3:.4f} mm ({best.verify.rms / report.predicted_rms_m:.2f}x)"
             if best is not None and report.predicted_rms_m > 0 else ""))
    for o in report.outcomes:
        if o.failure:
            print(f"{o.solver}: {o.failure}")
        if o.unreachable:
            print(f"{o.solver}: {len(o.unreachable)} pose(s) beyond the identified model's strokes, not scored")
    if args.out and best is not None:
        print(f"wrote the {best.solver} parameters to {args.out} (EpisodeConfig.stewart_calibration)")
    return 0 if good else 1
