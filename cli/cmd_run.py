"""``serpar run``: assembly episodes, headless (issue 5)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import signal
import sys
from collections.abc import Iterator

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.calibration.stewart_params import load_stewart_parameters
from serpar.cli import arg_types
from serpar.cli.out_paths import add_force, existing_folders, out_folder
from serpar.cli.output import json_line, progress, stage, table
from serpar.errors import ConfigError
from serpar.sim.config_io import load_yaml_config
from serpar.sim.plants.from_model_file import plant_report
from serpar.tasks.episode import signal_name
from serpar.tasks.episode_config import EpisodeConfig, arm_plant_of
from serpar.tasks.platform_model import prepare_models
from serpar.tasks.ray_runner import check_reachable, require_ray
from serpar.tasks.run_episodes import (
    episode_configs,
    interrupted_record,
    recording_folder,
    run_many,
    summarise,
)

EXIT = {"SIGINT": 130, "SIGTERM": 143}
"""Exit status of an interrupted run: 128 + the signal's number."""


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("run", help="assembly episodes: the six steps for every hole, outcomes and "
                                   "success rate")
    p.add_argument("--config", help="episode config YAML (keys of serpar.tasks.episode_config.EpisodeConfig; "
                                    "plant_model: a `serpar diagnose` model file gives the simulated "
                                    "arm the physics it found)")
    p.add_argument("--episodes", type=int, default=1, help="number of episodes, consecutive seeds (default 1)")
    p.add_argument("--holes", type=int, help="holes to fill per episode, 1..36 (default: the config's, 36)")
    p.add_argument("--seed", type=arg_types.seed, help="seed of the first episode (default: the config's, 0)")
    p.add_argument("--workers", type=int, default=1,
                   help="episodes in parallel local processes (same results as serial; default 1)")
    p.add_argument("--ray", metavar="ADDRESS",
                   help="run the episodes on a Ray cluster instead of local workers: 'local' starts one "
                        "on this machine, 'auto' joins the running cluster, ray://HOST:PORT a remote one "
                        "(needs the cluster extra)")
    p.add_argument("--json", action="store_true",
                   help="JSON lines on stdout (strict JSON: null, never NaN): one per hole, one per "
                        "episode, then the summary")
    p.add_argument("--record", metavar="DIR",
                   help="record each episode into DIR/episode_<seed>/: signals.parquet + meta.json "
                        "(docs/recording.md; complete and the hole outcomes, updated after each hole) "
                        "and episode.rrd for `serpar replay`; an existing DIR/episode_<seed> is "
                        "refused unless --force")
    add_force(p)
    p.set_defaults(func=cmd_run)
    p.epilog = ("Ctrl-C (SIGINT) or SIGTERM stops the run: the holes that finished are kept and "
                "counted, the episode under way is closed (its recording too, complete: false), "
                "and the summary says where it stopped; exit 130 (SIGINT) or 143 (SIGTERM).")
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

        for line in plant_report(arm_plant_of(cfg.plant_model)):  # type: ignore[arg-type]
            print(line, file=sys.stderr)
    if args.episodes < 1:
        raise ConfigError(f"--episodes {args.episodes}: must be >= 1")
    if args.workers < 1:
        raise ConfigError(f"--workers {args.workers}: must be >= 1")
    check_ray(args.ray, args.workers)
    return cfg


def check_ray(address: str | None, workers: int) -> None:
    """--ray excludes --workers > 1, and needs Ray installed: both fail before any work."""
    if address is None:
        return

    if workers > 1:
        raise ConfigError(f"--ray and --workers {workers}: choose one (Ray places the episodes on its own CPUs)")
    require_ray()
    check_reachable(address)


def record_root(folder: str, seeds: list[int], force: bool) -> str:
    """The --record folder, checked and created now so a bad path, or an episode folder that
    exists already (without --force), fails before any episode runs."""
    root = out_folder(folder, "--record", force=True).path  # writable (its contents: per episode)
    if not force:
        existing_folders([recording_folder(root, s) for s in seeds], "--record", root)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--record {folder}: cannot create the folder ({exc.strerror or exc})") from None
    return folder


def _pct(x: float) -> str:
    return "n/a" if math.isnan(x) else f"{100 * x:.1f}"


def interrupted_words(where: dict) -> str:
    """Where an interrupted run stopped, in one line."""
    if where.get("episode") is None:
        at = f"during {where['phase']}" if where.get("phase") else "between episodes"
    else:
        hole = f" (hole {where['hole']})" if where.get("hole") is not None else ""
        cycle = f", cycle {where['cycle']}{hole}" if where.get("cycle") is not None else ""
        at = f"in episode {where['episode']}{cycle}, phase {where.get('phase') or 'setup'}"
    others = len(where.get("stopped", [])) - 1
    return (f"interrupted by {where['signal']} {at}" + (f" (and {others} more episode(s) under way)" if others > 0
            else "") + f"; {where.get('episodes_not_started', 0)} episode(s) not started")


def print_summary(summary) -> None:
    lo, hi = summary.wilson95
    partial = f" ({summary.partial_episodes} interrupted)" if summary.partial_episodes else ""
    print(f"{summary.episodes} episode(s){partial}, {summary.holes} holes: success {summary.successes}/{summary.holes}"
          f" = {_pct(summary.success_rate)} % (95 % Wilson {_pct(lo)}-{_pct(hi)} %)")
    print(table(["outcome", "holes"], [[k, v] for k, v in summary.counts.items() if v]))
    ct, pf = summary.cycle_time_s, summary.peak_force_n
    if summary.holes:
        print(f"cycle time (simulated) mean {ct['mean']:.2f} s, max {ct['max']:.2f} s; "
              f"peak contact force mean {pf['mean']:.2f} N, max {pf['max']:.2f} N")
    if summary.wall_s:
        print(f"wall time {summary.wall_s:.1f} s, of which in MuJoCo's steps "
              f"{summary.physics_wall_s:.1f} s; setting up (before the first hole) "
              f"{summary.setup_wall_s:.1f} s")
    if summary.interrupted:
        print(interrupted_words(summary.interrupted))
    if summary.sim_faults:
        print(f"{summary.sim_faults} hole(s) ended by a simulation breakdown (see the records' reason)")
    if summary.errors:
        print(f"{summary.errors} episode(s) failed to run (error records)")


def _print_recordings(root: str, seeds: list[int]) -> None:
    done = [recording_folder(root, s) for s in seeds if (recording_folder(root, s) / "meta.json").is_file()]
    if done:
        print(f"recorded {len(done)} episode(s) in {root}: {', '.join(d.name for d in done)}; "
              f"view with: serpar replay {done[0] / 'episode.rrd'}", file=sys.stderr)


@contextlib.contextmanager
def interrupts() -> Iterator[None]:
    """SIGTERM behaves as Ctrl-C: KeyboardInterrupt("SIGTERM") (its name travels with it)."""
    def on_term(signum: int, frame: object) -> None:
        raise KeyboardInterrupt("SIGTERM")

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def cmd_run(args: argparse.Namespace) -> int:
    cfg = episode_config(args)
    configs = episode_configs(cfg, args.episodes)
    if args.record is not None:
        record_root(args.record, [c.seed for c in configs], args.force)
    with interrupts():
        try:  # the camera pairs and the Stewart campaign once, before workers (minutes, the first time)
            calibrated_pairs(cfg.camera_width, stage=stage)
            prepare_models(configs, stage=stage)
        except KeyboardInterrupt as exc:
            stop = interrupted_record([], [], signal_name(exc), len(configs))
            return report(args, [{**stop, "phase": "calibration"}])
        return run(args, cfg, configs)


def run(args: argparse.Namespace, cfg: EpisodeConfig, configs: list[EpisodeConfig]) -> int:
    n_holes = cfg.holes if isinstance(cfg.holes, int) else len(cfg.holes)
    bar = progress(n_holes * len(configs), "holes", enabled=sys.stderr.isatty())

    def on_hole(record: dict) -> None:
        bar.update(1)
        bar.set_postfix_str(f"hole {record['hole']}: {record['outcome']}")
        if args.json:
            print(json_line(record), flush=True)

    remote = args.workers > 1 or args.ray is not None  # holes arrive per finished episode

    def on_records(records: list[dict]) -> None:
        for r in records:
            if remote and r["kind"] == "hole":
                on_hole(r)
            elif r["kind"] != "hole" and args.json:
                print(json_line(r), flush=True)

    def notify(message: str) -> None:
        print(message, file=sys.stderr, flush=True)

    records = run_many(configs, args.workers, on_records, None if remote else on_hole,
                       record_dir=args.record, ray_address=args.ray, notify=notify)
    bar.close()
    if args.record:
        _print_recordings(args.record, [c.seed for c in configs])
    return report(args, records)


def report(args: argparse.Namespace, records: list[dict]) -> int:
    """The summary (a JSON line or text) and the exit status: 130/143 if interrupted, 1 if no
    hole was attempted, else 0."""
    summary = summarise(records)
    if args.json:
        print(json_line(summary.as_dict()), flush=True)
    else:
        print_summary(summary)
    if summary.interrupted is not None:
        if args.json:  # the text summary says it on stdout
            print(f"{interrupted_words(summary.interrupted)}: the summary covers the holes that finished",
                  file=sys.stderr)
        return EXIT.get(str(summary.interrupted["signal"]), 130)
    return 0 if summary.holes else 1
