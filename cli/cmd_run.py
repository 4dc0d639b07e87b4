"""``serpar run``: assembly episodes, headless (issue 5)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.calibration.stewart_params import load_stewart_parameters
from serpar.cli.output import progress, table
from serpar.errors import ConfigError
from serpar.sim.config_io import load_yaml_config
from serpar.sim.plants.from_model_file import arm_plant_from_file, plant_report
from serpar.tasks.episode_config import EpisodeConfig
from serpar.tasks.platform_model import prepare_models
from serpar.tasks.ray_runner import check_reachable, require_ray
from serpar.tasks.run_episodes import episode_configs, recording_folder, run_many, summarise


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("run", help="assembly episodes: the six steps for every hole, outcomes and "
                                   "success rate")
    p.add_argument("--config", help="episode config YAML (keys of serpar.tasks.episode_config.EpisodeConfig; "
                                    "plant_model: a `serpar diagnose` model file gives the simulated "
                                    "arm the physics it found)")
    p.add_argument("--episodes", type=int, default=1, help="number of episodes, consecutive seeds (default 1)")
    p.add_argument("--holes", type=int, help="holes to fill per episode, 1..36 (default: the config's, 36)")
    p.add_argument("--seed", type=int, help="seed of the first episode (default: the config's, 0)")
    p.add_argument("--workers", type=int, default=1,
                   help="episodes in parallel local processes (same results as serial; default 1)")
    p.add_argument("--ray", metavar="ADDRESS",
                   help="run the episodes on a Ray cluster instead of local workers: 'local' starts one "
                        "on this machine, 'auto' joins the running cluster, ray://HOST:PORT a remote one "
                        "(needs the cluster extra)")
    p.add_argument("--json", action="store_true",
                   help="JSON lines on stdout: one per hole, one per episode, then the summary")
    p.add_argument("--record", metavar="DIR",
                   help="record each episode into DIR/episode_<seed>/: signals.parquet + meta.json "
                        "(docs/recording.md) and episode.rrd for `serpar replay`")
    p.set_defaults(func=cmd_run)
    return p


def episode_config(args: argparse.Namespace):
    cfg = load_yaml_config(EpisodeConfig, args.config) if args.config else EpisodeConfig()
    if args.holes is not None:
        cfg = dataclasses.replace(cfg, holes=args.holes)
    if args.seed is not None:
        cfg = dataclasses.replace(cfg, seed=args.seed)
    if cfg.calibration_file is not None:  # a bad file fails now, not in every episode

        load_stewart_parameters(cfg.calibration_file)
    if cfg.plant_model is not None:  # what the simulated arm gets, and what it cannot take

        for line in plant_report(arm_plant_from_file(cfg.plant_model)):
            print(line, file=sys.stderr)
    if args.episodes < 1:
        raise ConfigError(f"--episodes {args.episodes}: must be >= 1")
    if args.workers < 1:
        raise ConfigError(f"--workers {args.workers}: must be >= 1")
    check_ray(args.ray, args.workers)
    if args.record is not None:
        record_root(args.record)
    return cfg


def check_ray(address: str | None, workers: int) -> None:
    """--ray excludes --workers > 1, and needs Ray installed: both fail before any work."""
    if address is None:
        return

    if workers > 1:
        raise ConfigError(f"--ray and --workers {workers}: choose one (Ray places the episodes on its own CPUs)")
    require_ray()
    check_reachable(address)


def record_root(folder: str) -> str:
    """The --record folder, created now so a bad path fails before any episode runs."""
    from pathlib import Path


    try:
        Path(folder).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--record {folder}: cannot create the folder ({exc.strerror or exc})") from None
    return folder


def _line(record: dict) -> str:
    return json.dumps(record, default=float)


def print_summary(summary) -> None:
    lo, hi = summary.wilson95
    print(f"{summary.episodes} episode(s), {summary.holes} holes: success {summary.successes}/{summary.holes}"
          f" = {100 * summary.success_rate:.1f} % (95 % Wilson {100 * lo:.1f}-{100 * hi:.1f} %)")
    print(table(["outcome", "holes"], [[k, v] for k, v in summary.counts.items() if v]))
    ct, pf = summary.cycle_time_s, summary.peak_force_n
    print(f"cycle time (simulated) mean {ct['mean']:.2f} s, max {ct['max']:.2f} s; "
          f"peak contact force mean {pf['mean']:.2f} N, max {pf['max']:.2f} N")
    if summary.sim_faults:
        print(f"{summary.sim_faults} hole(s) ended by a simulation breakdown (see the records' reason)")
    if summary.errors:
        print(f"{summary.errors} episode(s) failed to run (error records)")


def _print_recordings(root: str, seeds: list[int]) -> None:
    done = [recording_folder(root, s) for s in seeds if (recording_folder(root, s) / "meta.json").is_file()]
    if done:
        print(f"recorded {len(done)} episode(s) in {root}: {', '.join(d.name for d in done)}; "
              f"view with: serpar replay {done[0] / 'episode.rrd'}", file=sys.stderr)


def cmd_run(args: argparse.Namespace) -> int:
    cfg = episode_config(args)
    configs = episode_configs(cfg, args.episodes)
    n_holes = cfg.holes if isinstance(cfg.holes, int) else len(cfg.holes)
    def log(message: str) -> None:
        print(message, file=sys.stderr)

    calibrated_pairs(cfg.camera_width, log=log)  # once, before workers
    prepare_models(configs, log)  # the Stewart campaign too
    bar = progress(n_holes * len(configs), "holes", enabled=sys.stderr.isatty())

    def on_hole(record: dict) -> None:
        bar.update(1)
        bar.set_postfix_str(f"hole {record['hole']}: {record['outcome']}")
        if args.json:
            print(_line(record), flush=True)

    remote = args.workers > 1 or args.ray is not None  # holes arrive per finished episode

    def on_records(records: list[dict]) -> None:
        for r in records:
            if remote and r["kind"] == "hole":
                on_hole(r)
            elif r["kind"] != "hole" and args.json:
                print(_line(r), flush=True)

    records = run_many(configs, args.workers, on_records, None if remote else on_hole,
                       record_dir=args.record, ray_address=args.ray)
    bar.close()
    if args.record:
        _print_recordings(args.record, [c.seed for c in configs])
    summary = summarise(records)
    if args.json:
        print(_line(summary.as_dict()))
    else:
        print_summary(summary)
    interrupted = any(r["kind"] == "interrupted" for r in records)
    if interrupted:
        print("interrupted: the results above cover the finished episodes", file=sys.stderr)
    return 130 if interrupted else (0 if not math.isnan(summary.success_rate) else 1)
