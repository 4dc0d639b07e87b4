"""``serpar ablate``: the paper's argument as one table (issue 5)."""

from __future__ import annotations

import argparse
import sys

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.checks.ablation import ablation_arms, run_ablation, spread_holes
from serpar.cli import arg_types
from serpar.cli.cmd_run import check_ray
from serpar.cli.output import json_line, progress, stage, table
from serpar.errors import ConfigError
from serpar.tasks.episode_config import EpisodeConfig
from serpar.tasks.platform_model import prepare_models
from serpar.tasks.run_episodes import episode_configs


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("ablate", help="success rate per configuration: serial alone, Stewart "
                                      "uncalibrated / calibrated, impedance vs force-position")
    p.add_argument("--episodes", type=int, default=1, help="episodes per configuration (default 1)")
    p.add_argument("--holes", type=int, default=6, help="holes per episode, 1..36, spread evenly over the grid (default 6: its diagonal, "
                        "0, 7, 14, 21, 28, 35)")
    p.add_argument("--seed", type=arg_types.seed, default=0, help="seed of the first episode (default 0)")
    p.add_argument("--workers", type=int, help="parallel local processes (default 2; 1 with --ray)")
    p.add_argument("--ray", metavar="ADDRESS",
                   help="run the episodes on a Ray cluster: local, auto or ray://HOST:PORT (cluster extra)")
    p.add_argument("--json", action="store_true", help="JSON lines (strict JSON: null, never NaN): every hole, "
                                                       "then one line per configuration")
    p.set_defaults(func=cmd_ablate)
    return p


def _fmt_rate(s) -> str:
    lo, hi = s.wilson95
    return f"{100 * s.success_rate:.0f} % ({100 * lo:.0f}-{100 * hi:.0f})" if s.holes else "-"


def cmd_ablate(args: argparse.Namespace) -> int:
    if args.workers is None:
        args.workers = 1 if args.ray else 2
    if args.episodes < 1 or args.workers < 1:
        raise ConfigError(f"--episodes {args.episodes}, --workers {args.workers}: both must be >= 1")
    check_ray(args.ray, args.workers)
    base = EpisodeConfig(seed=args.seed, holes=spread_holes(args.holes))
    calibrated_pairs(base.camera_width, stage=stage)
    arms = ablation_arms(base)
    prepare_models([cfg for arm in arms for cfg in episode_configs(arm.config, args.episodes)], stage=stage)
    bar = progress(len(arms) * args.episodes * args.holes, "holes", enabled=sys.stderr.isatty())

    def on_hole(r: dict) -> None:
        bar.update(1)
        bar.set_postfix_str(f"{r.get('config')}: hole {r['hole']} {r['outcome']}")
        if args.json:
            print(json_line(r), flush=True)

    remote = args.workers > 1 or args.ray is not None  # holes arrive per finished episode

    def on_records(records: list[dict]) -> None:
        if remote:
            for r in records:
                if r["kind"] == "hole":
                    on_hole(r)

    results, records = run_ablation(arms, args.episodes, args.workers, on_records,
                                    None if remote else on_hole, ray_address=args.ray)
    bar.close()
    if args.json:
        for res in results:
            print(json_line(res.as_dict()))
    else:
        rows = []
        for res in results:
            s = res.summary
            fails = ", ".join(f"{k} {v}" for k, v in s.counts.items() if v and k != "success") or "-"
            rows.append([res.name, s.holes, _fmt_rate(s), fails, f"{res.misalignment_mm:.3f}",
                         f"{s.peak_force_n['mean']:.1f}", f"{s.cycle_time_s['mean']:.2f}"])
        print(table(["configuration", "holes", "success (95 % Wilson)", "failures", "misalign. mm",
                     "peak N", "cycle s"], rows))
        faults = sum(r.summary.sim_faults for r in results)
        if faults:
            print(f"{faults} hole(s) ended by a simulation breakdown (counted as their phase's failure)")
    interrupted = any(r["kind"] == "interrupted" for r in records)
    return 130 if interrupted else 0
