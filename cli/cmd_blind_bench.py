"""``serpar blind-bench``: concealed effects, diagnosed blind, scored (serpar.checks.blind_bench)."""

from __future__ import annotations

import argparse
import sys

from serpar.checks.blind_bench import RMS_TARGET, blind_bench, summarise
from serpar.cli.output import print_json, progress, table
from serpar.twins.registry import DOMAINS


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("blind-bench", help="random concealed effect per trial, diagnosed "
                                           "without the answer, scored")
    p.add_argument("--trials", type=int, default=12, help="number of trials (default 12)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--domain", action="append",
                   help="restrict to a domain (repeatable): arm_static, arm_dynamics, stewart, "
                        "stewart_motion")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_blind_bench)
    return p


def cmd_blind_bench(args: argparse.Namespace) -> int:
    domains = tuple(args.domain) if args.domain else tuple(DOMAINS)
    bar = progress(args.trials, "blind-bench", enabled=sys.stderr.isatty())
    trials = blind_bench(args.trials, args.seed, domains, progress=lambda _t: bar.update(1))
    bar.close()
    summary = summarise(trials)
    if args.json:
        print_json({"summary": summary, "trials": [t.as_dict() for t in trials]})
        return 0
    print(table(["#", "domain", "hidden", "magnitude", "top-ranked", "ok", "held-out RMS/noise",
                 "diagnosis [s]", "error"],
                [[t.index, t.domain, t.effect, f"{t.magnitude:.3g}", t.top_effect or "-",
                  "yes" if t.correct else "NO", f"{t.heldout_rms_ratio:.3g}",
                  f"{t.diagnosis_s:.1f}", (t.error or "")[:60]] for t in trials]))

    def pct(x: object) -> str:
        return "-" if x is None else f"{100 * float(x):.0f} %"  # type: ignore[arg-type]

    print(f"top-ranked effect correct: {pct(summary['top_effect_correct'])} (target >= 90 %); "
          f"'no missing physics' on effect-free trials: "
          f"{pct(summary['no_missing_physics_on_none'])} (target >= 95 %)")
    print(f"held-out RMS / noise floor: median {summary['heldout_rms_ratio_median']:.3g}, "
          f"max {summary['heldout_rms_ratio_max']:.3g}, within {RMS_TARGET}: "
          f"{pct(summary['heldout_rms_within_target'])}; diagnosis wall time median "
          f"{summary['diagnosis_s_median']:.1f} s, max {summary['diagnosis_s_max']:.1f} s; "
          f"{summary['errors']} trial(s) failed")
    return 0
