"""``serpar vision-check``: calibration, conductor, hole and in-hand vision, scored against truth."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from serpar.checks.vision_check import VisionCheckConfig, run_vision_check, total_ticks
from serpar.cli import arg_types
from serpar.cli.out_paths import add_force, out_folder
from serpar.cli.output import print_json, progress, table

TARGETS = {"hole_p95_mm": 0.05, "offset_mm": 0.02, "tilt_deg": 0.1, "occupancy": 1.0}
"""The issue's targets at full resolution (2048 x 1536)."""


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("vision-check", help="stereo calibration and the vision of steps 1, 2, 4, scored "
                                            "against the simulator's truth (exit 1 if a full-size target fails)")
    p.add_argument("--width", type=int, action="append", choices=(2048, 1024, 512),
                   help="readout width, repeatable (default: 2048 and 1024)")
    p.add_argument("--poses", type=int, default=10, help="random platform poses for steps 1-2 (default 10)")
    p.add_argument("--occupied", type=int, default=6, help="conductors seated in holes per scene (default 6)")
    p.add_argument("--trials", type=int, default=10, help="in-hand inspections for step 4 (default 10)")
    p.add_argument("--seed", type=arg_types.seed, default=0, help="scene, pose and noise seed (default 0)")
    p.add_argument("--no-noise", action="store_true", help="clean renders (default: sensor noise and "
                                                           "lighting variation)")
    p.add_argument("--overlay", metavar="DIR", help="write detection overlays (PNG) for every step here (a "
                                                    "folder that holds files is refused unless --force)")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_vision_check)
    return p


def _s(stats: dict, digits: int = 4) -> str:
    return " / ".join(f"{stats[k]:.{digits}f}" for k in ("mean", "p95", "max"))


def passed(result: dict) -> dict[str, bool]:
    """The issue's targets, judged on one width's results."""
    return {
        "hole_p95": result["step2_holes"]["centre_error_mm"]["p95"] <= TARGETS["hole_p95_mm"]
        and not result["step2_holes"]["failures"],
        "occupancy": result["step2_holes"]["occupancy_accuracy"] >= TARGETS["occupancy"],
        "offset": result["step4_inhand"]["offset_error_mm"]["max"] <= TARGETS["offset_mm"]
        and not result["step4_inhand"]["failures"],
        "tilt": result["step4_inhand"]["tilt_error_deg"]["max"] <= TARGETS["tilt_deg"],
    }


def _print_width(width: str, r: dict) -> None:
    print(f"\n== {width} x {int(width) * 3 // 4} ==")
    rows = []
    for name, c in r["calibration"].items():
        sc = c["score"]
        rms = c["rms_px"]
        rows.append([name, f"{rms['bundle']:.3f} (cam {rms['left']:.3f}/{rms['right']:.3f}, stereo {rms['stereo']:.3f})", f"{c['rectified_row_error_px']:.3f}",
                     f"{sc['left']['fx_error_pct']:+.3f} / {sc['right']['fx_error_pct']:+.3f}",
                     f"{sc['baseline_error_mm']:+.4f}",
                     f"{sc['left']['position_error_mm']:.3f} / {sc['right']['position_error_mm']:.3f}",
                     f"{sc['left']['rotation_error_deg']:.4f} / {sc['right']['rotation_error_deg']:.4f}",
                     f"{sc['triangulation_error_mm']['mean']:.4f} / {sc['triangulation_error_mm']['max']:.4f}",
                     f"{c['views']['both']}", f"{sum(c['seconds'].values()):.1f}"])
    print(table(["pair", "reproj. RMS [px]", "rectified dy [px]", "focal err L/R [%]", "baseline err [mm]",
                 "position err L/R [mm]", "rotation err L/R [deg]", "3-D err mean/max [mm]", "views",
                 "time [s]"], rows))
    s1, s2, s4 = r["step1_tray"], r["step2_holes"], r["step4_inhand"]
    rows = [
        ["1 conductor tops in the tray [mm]", _s(s1["error_mm"]),
         f"{s1['error_mm']['n']} found, {s1['missed']} missed, {s1['false_detections']} false",
         f"{s1['seconds_per_frame_pair']:.2f}"],
        ["2 hole centres [mm]", _s(s2["centre_error_mm"]),
         (f"{s2['holes_seen']}/{s2['holes_total']} holes, {s2['platform_poses']} platform poses; "
          f"target p95 <= {TARGETS['hole_p95_mm']}"), f"{s2['seconds_per_frame_pair']:.2f}"],
        ["  hole axes [deg]", _s(s2["axis_error_deg"], 3), "", ""],
        ["  per-hole triangulation, no plate fit [mm]", _s(s2["raw_triangulated_error_mm"]), "", ""],
        ["  occupied/empty", f"{100 * s2['occupancy_accuracy']:.1f} %", "target 100 %", ""],
        ["4 in-hand journal offset [mm]", _s(s4["offset_error_mm"]),
         f"{s4['trials']} grasps; target <= {TARGETS['offset_mm']}", f"{s4['seconds_per_inspection']:.2f}"],
        ["  tilt [deg]", _s(s4["tilt_error_deg"], 3), f"target <= {TARGETS['tilt_deg']}", ""],
        ["  tip along the TCP z [mm]", _s(s4["tip_error_mm"]), "", ""],
    ]
    print(table(["step", "error mean / p95 / max", "", "vision time [s]"], rows))
    for failure in s2["failures"] + s4["failures"]:
        print(f"  typed failure: {failure}")


def cmd_vision_check(args: argparse.Namespace) -> int:
    if args.overlay:  # before any rendering
        out_folder(args.overlay, "--overlay", args.force)
    cfg = VisionCheckConfig(widths=tuple(args.width) if args.width else (2048, 1024), platform_poses=args.poses,
                            occupied=args.occupied, inhand_trials=args.trials, seed=args.seed,
                            noise=not args.no_noise, overlay_dir=Path(args.overlay) if args.overlay else None)
    bar = progress(total_ticks(cfg), "vision-check", enabled=sys.stderr.isatty())
    report = run_vision_check(cfg, lambda: bar.update(1))
    bar.close()
    full = report.get("2048")
    ok = passed(full) if isinstance(full, dict) else {}
    if args.json:
        report["targets"] = TARGETS
        report["passed_full_resolution"] = ok
        print_json(report)
        return 0 if all(ok.values()) else 1
    print(f"serpar vision-check  seed {cfg.seed}  noise {'on' if cfg.noise else 'off'}")
    for width in cfg.widths:
        _print_width(str(width), report[str(width)])
    if ok:
        print("\nfull-resolution targets: " + ", ".join(f"{k} {'PASS' if v else 'FAIL'}" for k, v in ok.items()))
    if args.overlay:
        print(f"overlays written under {args.overlay}/<width>/")
    return 0 if all(ok.values()) else 1
