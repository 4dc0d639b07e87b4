"""``serpar montecarlo``: first-pass yield by physics, thousands of sampled insertions."""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path

from serpar.checks.montecarlo import (
    BATCH,
    GPU_OR_RAY,
    MonteCarloResult,
    run_montecarlo,
    write_parquet,
)
from serpar.checks.montecarlo_config import MonteCarloConfig
from serpar.checks.montecarlo_gpu import CHECK_SAMPLE, check_sample, run_gpu
from serpar.checks.montecarlo_record import FOLDER, failed_rows, record_failed
from serpar.checks.montecarlo_report import sensitivity_rows, write_montecarlo_report
from serpar.checks.montecarlo_validation import NOISE_STREAMS, validate
from serpar.cli import arg_types
from serpar.cli.cmd_run import check_ray
from serpar.cli.out_paths import add_force, out_file, out_folder
from serpar.cli.output import print_json, progress, table
from serpar.errors import ConfigError
from serpar.sim.config_io import load_yaml_config
from serpar.sim.strict_json import dumps
from serpar.tasks.warp_batch import check_device

OUT_FILES = ("trials.parquet", "summary.json")
"""What --out DIR holds (and FOLDER/trial_<k>.rrd, the failed trials recorded)."""
RECORD_FAILED = 10


def _defaults() -> str:
    d = MonteCarloConfig()
    return ", ".join(f"{f.name} {getattr(d, f.name)}" for f in dataclasses.fields(d))


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "montecarlo", help="first-pass yield by physics: N sampled insertion trials, batched",
        description="Runs N insertion trials (step 6 from the hover, the tip 2.5 mm above the hole "
                    "with the platform following it down to 0.3 mm, the episode's arm, gripper, "
                    "force-position controller and contact) with part diameters and cell errors "
                    "drawn per trial; prints the share seated first time with its Wilson 95 % "
                    "interval, outcome counts and the error source "
                    f"that drives the failures. Error budget defaults: {_defaults()}.")
    p.add_argument("--config", metavar="DIST.yaml",
                   help="error budget: YAML with any fields of MonteCarloConfig (defaults above; "
                        "docs/montecarlo.md)")
    p.add_argument("--trials", type=int, default=1000, help="number of trials (default 1000)")
    p.add_argument("--seed", type=arg_types.seed, default=0, help="random seed (default 0)")
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1,
                   help=f"CPU threads of the batched physics (default: all, {os.cpu_count()})")
    p.add_argument("--batch", type=int, default=BATCH,
                   help=f"simulations at a time, a trial starting as another ends; with --ray, trials "
                        f"per task (default {BATCH}; results do not depend on it)")
    p.add_argument("--ray", metavar="ADDRESS",
                   help="one Ray task per batch on a cluster: local, auto or ray://HOST:PORT "
                        "(cluster extra); results equal a local run's")
    p.add_argument("--gpu", action="store_true",
                   help="experimental, its agreement not yet measured on a GPU (docs/montecarlo.md): run the "
                        "trials on MuJoCo Warp on this machine's CUDA GPU (float32, the scene at the "
                        "origin; the gpu extra: pip install 'serpar[gpu]'), then re-run a random sample "
                        "in float64 on the CPU cores and report the agreement")
    p.add_argument("--gpu-check", type=int, metavar="K", default=CHECK_SAMPLE,
                   help=f"with --gpu: trials re-run in float64 on the CPU, each also with its lateral "
                        f"offset moved -/+2 um to find boundary trials (default {CHECK_SAMPLE})")
    p.add_argument("--validate", type=int, metavar="HOLES",
                   help="instead: run a HOLES-hole episode (seed --seed) and replay each of its "
                        "insertions as a trial from the state it started in; prints outcomes and "
                        "peak forces side by side")
    p.add_argument("--streams", type=int, metavar="K", default=None,
                   help=f"with --validate: replay each insertion with K sensor-noise streams, the "
                        f"first the trial's own, and show its peak's spread (default {NOISE_STREAMS})")
    p.add_argument("--out", metavar="DIR", help="write DIR/trials.parquet (one row per trial), "
                                                f"DIR/summary.json and the failed trials' recordings, "
                                                f"DIR/{FOLDER}/trial_<k>.rrd")
    p.add_argument("--record-failed", type=int, metavar="K", default=None,
                   help=f"with --out: re-run the first K failed trials alone and record each for "
                        f"`serpar replay` (default {RECORD_FAILED}; 0: none)")
    p.add_argument("--report", metavar="OUT.html", help="HTML report with the plots")
    add_force(p)
    p.add_argument("--json", action="store_true", help="one JSON summary object")
    p.set_defaults(func=cmd_montecarlo)
    return p


def summary(result: MonteCarloResult) -> dict[str, object]:
    lo, hi = result.wilson95
    peaks = [r.result.peak_force_n for r in result.rows]
    return {"trials": len(result.rows), "trials_asked": result.trials_asked,
            "interrupted": result.interrupted, "seed": result.seed,
            "success_rate": result.success_rate, "ci_low": lo, "ci_high": hi,
            "outcomes": result.counts, "wall_s": result.wall_s, "errors": result.errors,
            "notes": result.notes,
            "peak_force_n": {"mean": sum(peaks) / len(peaks) if peaks else None,
                             "max": max(peaks) if peaks else None},
            "sensitivity": {s: {"auc": a, "mean_seated": ok, "mean_failed": bad}
                            for s, a, ok, bad in sensitivity_rows(result)},
            "seed001": result.seed001(), "config": dataclasses.asdict(result.config)}


def cmd_montecarlo(args: argparse.Namespace) -> int:
    if args.trials < 1 or args.threads < 1 or args.batch < 1:
        raise ConfigError(f"--trials {args.trials}, --threads {args.threads}, --batch {args.batch}: "
                          "each must be >= 1")
    check_ray(args.ray, 1)
    if args.gpu:
        if args.ray:
            raise ConfigError(GPU_OR_RAY)
        if args.gpu_check < 1:
            raise ConfigError(f"--gpu-check {args.gpu_check}: a sample of at least 1 trial")
        check_device("cuda")  # before any work: the extra and a CUDA device
    if args.streams is not None and args.validate is None:
        raise ConfigError(f"--streams {args.streams} goes with --validate HOLES (the noise streams "
                          "an episode's insertions are replayed with)")
    if args.validate is not None:
        return _validate(args)
    cfg = load_yaml_config(MonteCarloConfig, args.config) if args.config else MonteCarloConfig()
    out = out_folder(args.out, "--out", args.force, OUT_FILES) if args.out else None
    if args.record_failed is not None and (args.record_failed < 0 or out is None):
        raise ConfigError(f"--record-failed {args.record_failed}: a count >= 0, with --out DIR "
                          "(the recordings go to DIR/failed/)")
    record = RECORD_FAILED if args.record_failed is None else args.record_failed
    report = out_file(args.report, "--report", args.force, suffix=".html") if args.report else None
    bar = progress(args.trials, "trials", enabled=sys.stderr.isatty())

    seated = [0, 0]

    def on_rows(rows: list) -> None:
        bar.update(len(rows))
        seated[0] += sum(r.result.outcome.value == "success" for r in rows)
        seated[1] += len(rows)
        bar.set_postfix_str(f"{seated[0]}/{seated[1]} seated")

    if args.gpu:
        result = run_gpu(cfg, args.trials, args.seed, args.batch, "cuda", on_rows)
    else:
        result = run_montecarlo(cfg, args.trials, args.seed, args.threads, args.batch, on_rows,
                                ray_address=args.ray)
    for error in result.errors:
        sys.stderr.write(f"serpar montecarlo: {error}\n")
    for note in result.notes:
        sys.stderr.write(f"serpar montecarlo: note: {note}\n")
    bar.close()
    if result.interrupted:
        sys.stderr.write(f"serpar montecarlo: interrupted; {len(result.rows)} of {args.trials} trials "
                         "finished and are reported\n")
    if not result.rows:
        raise ConfigError("no trial finished")
    info = summary(result) | {"recorded": [], "engine": "mujoco_warp float32 (cuda)" if args.gpu
                              else "mujoco.batch float64 (cpu)"}
    if args.gpu and result.rows:
        info["gpu_check"] = check_sample(result, args.gpu_check, args.threads)
    if out is not None:
        out.clear()
        out.path.mkdir(parents=True, exist_ok=True)
        for stale in (out.path / FOLDER).glob("trial_*.rrd"):
            stale.unlink()
        write_parquet(result, out.path / OUT_FILES[0])
        info["recorded"] = _record(result, out.path, record)
        (out.path / OUT_FILES[1]).write_text(dumps(info, indent=2) + "\n")
    if report is not None:
        write_montecarlo_report(result, report)
    if args.json:
        print_json(info | {"out": str(out.path) if out else None, "report": str(report) if report else None})
        return 0
    lo, hi = result.wilson95
    print(f"{len(result.rows)} trials ({result.wall_s:.0f} s): seated first time "
          f"{100 * result.success_rate:.2f} % (Wilson 95 % {100 * lo:.2f}-{100 * hi:.2f} %)")
    print(table(["outcome", "trials"], [[k, v] for k, v in result.counts.items()]))
    s001 = result.seed001()
    if s001 is not None:
        within, paper = s001["p_position_within_mm"], s001["paper_p_position_within_mm"]
        print("seed 001's error budget on this arm: " + "; ".join(
            f"P(|dP| < {d} mm) = {within[d]:.4f} (paper, its robot: {paper[d]})" for d in within)  # type: ignore[index]
            + f"; P(seated) = {s001['p_seated']:.4f}")
    _say_recorded(info.get("recorded", []), len(failed_rows(result)))
    if "gpu_check" in info:
        g = info["gpu_check"]
        print(f"float64 CPU re-run of {g['sampled']} GPU trials: same outcome {g['agree']}/{g['compared']}"
              f" (boundary trials apart: {g['boundary_agree']}/{g['boundary']}); GPU/CPU peak force "
              f"median ratio {g['peak_ratio_median']}")
    print(table(["error source", "AUC (failed vs seated)", "mean seated", "mean failed"],
                [[s, "-" if a is None else f"{a:.3f}", f"{ok:.4g}", f"{bad:.4g}"]
                 for s, a, ok, bad in sensitivity_rows(result)]))
    return 0


def _record(result: MonteCarloResult, out: Path, limit: int) -> list[dict[str, object]]:
    """Record up to ``limit`` failed trials; Ctrl-C keeps the ones recorded."""
    n = min(limit, len(failed_rows(result)))
    done: list[dict[str, object]] = []
    if not n:
        return done
    bar = progress(n, "recording failed trials", enabled=sys.stderr.isatty())
    try:
        for d in record_failed(result, out, limit):
            done.append(d)
            bar.update(1)
    except KeyboardInterrupt:
        sys.stderr.write(f"serpar montecarlo: recording interrupted; {len(done)} of {n} failed trials "
                         "recorded\n")
    bar.close()
    for d in done:
        if d["rerun_outcome"] != d["outcome"]:
            sys.stderr.write(f"serpar montecarlo: trial {d['trial']} re-ran as {d['rerun_outcome']}, "
                             f"not {d['outcome']}: {d['file']} shows the re-run\n")
    return done


def _say_recorded(recorded: list, failed: int) -> None:
    if recorded:
        print(f"{len(recorded)} of {failed} failed trials recorded: serpar replay {recorded[0]['file']}"
              + (" (and the others beside it)" if len(recorded) > 1 else ""))


def _validate(args: argparse.Namespace) -> int:
    if not 1 <= args.validate <= 36:
        raise ConfigError(f"--validate {args.validate}: holes 1..36")
    streams = NOISE_STREAMS if args.streams is None else args.streams
    report = validate(args.validate, args.seed, args.threads, streams)
    if args.json:
        print_json(report)
        return 0
    rows = report["rows"]
    print(table(["hole", "clearance um", "episode", "trial", "peak N episode", "trial", "ratio",
                 f"trial, {streams} noise streams", "misalign. mm episode", "trial"],
                [[r["hole"], f"{r['clearance_um']:.1f}", r["episode_outcome"], r["trial_outcome"],
                  f"{r['episode_peak_n']:.3f}", f"{r['trial_peak_n']:.3f}", f"{r['peak_ratio']:.3f}",
                  f"{min(r['trial_peak_streams_n']):.3f}-{max(r['trial_peak_streams_n']):.3f}",
                  f"{r['episode_misalignment_mm']:.4f}", f"{r['trial_misalignment_mm']:.4f}"]
                 for r in rows]))  # type: ignore[union-attr]
    print(f"same outcome {report['same_outcome']}/{report['insertions']}; peak force within 5 % "
          f"{report['peak_within_5pct']}/{report['insertions']}")
    return 0
