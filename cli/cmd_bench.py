"""``serpar bench``: physics steps per second of the cell, bare and under the control loop."""

from __future__ import annotations

import argparse
import os
import sys

from serpar.checks.bench import BenchConfig, run_bench
from serpar.checks.bench_diagnose import diagnose_bench
from serpar.checks.bench_episode import against_goals, episode_bench
from serpar.checks.bench_montecarlo import montecarlo_bench
from serpar.cli.output import print_json, progress, table


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("bench", help="steps per second of the full cell: bare mj_step (the floor), with "
                                     "and without sleeping, and serpar's control loop in free motion "
                                     "and in contact, with its overhead over the floor")
    p.add_argument("--seconds", type=float, default=0.2, help="simulated seconds per timing (default 0.2)")
    p.add_argument("--repeats", type=int, default=3, help="timings per figure, best kept (default 3)")
    p.add_argument("--episode", action="store_true",
                   help="also time the assembly task: one hole cycle, the 36-hole episode (estimated "
                        "from it) and 2 workers vs 1 (adds ~1 min); each figure is printed beside "
                        "its goal")
    p.add_argument("--montecarlo", action="store_true",
                   help="also time serpar montecarlo: one batch of 32 insertion trials at 1 thread "
                        "and at every core, trials/s, the scaling and the overhead over bare batched "
                        "stepping, and a trial scene's build in place and in processes (adds ~2 min)")
    p.add_argument("--diagnose", action="store_true",
                   help="also time serpar diagnose on a 60-s arm-dynamics twin with a mix of "
                        "concealed effects, full candidate library (its goal: <= 2 min on 2 cores; "
                        "it runs longer today, docs/diagnosis.md)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_bench)
    return p


def cmd_bench(args: argparse.Namespace) -> int:
    cfg = BenchConfig(sim_seconds=args.seconds, repeats=args.repeats)
    threads = tuple(sorted({1, os.cpu_count() or 1}))
    bar = progress(5 + 3 * args.episode + (len(threads) + 1) * args.montecarlo
                   + 2 * args.diagnose, "bench",
                   enabled=sys.stderr.isatty())

    def tick(name: str) -> None:
        bar.set_postfix_str(name)
        bar.update(1)

    report = run_bench(cfg, tick)
    if args.episode:

        floor = report["bare"]["cell_36_conductors"]["steps_per_s"]  # type: ignore[index]
        report["episode"] = episode_bench(tick=tick, bare_steps_per_s=float(floor))
    if args.montecarlo:
        report["montecarlo"] = montecarlo_bench(threads=threads, tick=tick)
    if args.diagnose:
        report["diagnose"] = diagnose_bench(tick=tick)
    bar.close()
    report["goals"] = against_goals(report)
    if args.json:
        print_json(report)
        return 0
    print(f"serpar bench  timestep {report['timestep_s'] * 1e3:g} ms, best of {cfg.repeats} x "
          f"{cfg.sim_seconds:g} s simulated")
    rows = [[f"bare mj_step: {name.replace('_', ' ')}", f"{r['steps_per_s']:,.0f}", f"{r['realtime_factor']:.2f}", ""]
            for name, r in report["bare"].items()]
    for phase in ("free_motion", "in_contact"):
        r = report[phase]
        label = phase.replace("_", " ")
        rows.append([f"control loop, {label}", f"{r['loop']['steps_per_s']:,.0f}",
                     f"{r['loop']['realtime_factor']:.2f}", f"{r['overhead']:.2f}x"])
        rows.append(["  bare mj_step replaying it (controls, gate)", f"{r['bare']['steps_per_s']:,.0f}",
                     f"{r['bare']['realtime_factor']:.2f}", ""])
        rows.append(["  bare mj_step replaying it, cell as built", f"{r['bare_as_built']['steps_per_s']:,.0f}",
                     f"{r['bare_as_built']['realtime_factor']:.2f}", f"{r['vs_as_built']:.2f}x"])
    print(table(["", "steps/s", "x real time", "loop / bare"], rows))
    if args.episode:
        e = report["episode"]
        c, w = e["hole_cycle"], e["two_episodes_of_one_hole"]
        print(table(["assembly task", "wall s", "simulated s", "x real time"], [
            ["one hole cycle (mean)", f"{c['wall_s']:.1f}", f"{c['sim_s']:.2f}", f"{c['realtime_factor']:.2f}"],
            [(f"  of it in mj_step ({c['physics_steps']:,.0f} steps; at the bare rate "
             f"{c['steps_at_bare_rate_s']:.1f} s)"), f"{c['physics_wall_s']:.1f}", "",
             f"wall / physics {c['wall_over_physics']:.2f}"],
            ["episode set-up (scene, settle, registration)", f"{e['episode_setup_wall_s']:.1f}", "", ""],
            ["36-hole episode, estimated", f"{e['episode_36_holes_estimated_wall_s']:.0f}", "", ""],
            ["2 one-hole episodes, 1 worker", f"{w['workers_1_s']:.1f}", "", ""],
            ["2 one-hole episodes, 2 workers", f"{w['workers_2_s']:.1f}", "", f"speed-up {w['speedup']:.2f}x"]]))
    if args.montecarlo:
        mc = report["montecarlo"]
        print(table([f"montecarlo, {mc['trials']} trials", "wall s", "trials/s", "steps/s", "bare steps/s",
                     "loop / bare", "scaling"],
                    [[f"{n} thread(s)", f"{r['wall_s']:.1f}", f"{r['trials_per_s']:.2f}",
                      f"{r['steps_per_s']:,.0f}", f"{r['bare_steps_per_s']:,.0f}", f"{r['overhead']:.2f}x",
                      f"{mc['scaling'][n]:.2f}x"] for n, r in mc["by_threads"].items()]))
        print(table(["trial scene built", "ms per trial"],
                    [["in place" if w == "1" else f"ahead on {w} processes", f"{ms:.1f}"]
                     for w, ms in mc["scene_build_ms"].items()]))
    if args.diagnose:
        dg = report["diagnose"]
        print(table(["diagnosis", "wall s", "candidates", "concealed", "established"],
                    [[dg["recording"], f"{dg['diagnosis_s']:.1f}", dg["candidates"],
                      ", ".join(dg["concealed"]), ", ".join(dg["established"]) or "-"]]))
    goals = report["goals"]
    print(table(["figure", "measured", "goal", ""],
                [[g["label"], f"{g['value']:.2f}", g["goal"], "met" if g["met"] else "SHORT"] for g in goals.values()]))
    return 0
