"""``serpar blind-bench``: concealed effects, diagnosed blind, scored (serpar.checks.blind_bench)."""

from __future__ import annotations

import argparse
import sys

from serpar.checks.blind_bench import KINDS, RMS_TARGET, Trial, blind_bench, check_robot
from serpar.checks.blind_bench_summary import summarise
from serpar.cli import arg_types
from serpar.cli.output import print_json, progress, table
from serpar.cli.robot_option import add_robot_option
from serpar.twins.registry import ANY_ARM, DOMAINS


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("blind-bench", help="random concealed effect per trial, diagnosed "
                                           "without the answer, scored")
    p.add_argument("--trials", type=int, default=12, help="number of trials (default 12)")
    p.add_argument("--seed", type=arg_types.seed, default=0, help="random seed (default 0)")
    p.add_argument("--domain", action="append",
                   help="restrict to a domain (repeatable): arm_static, arm_dynamics, stewart, "
                        "stewart_motion")
    p.add_argument("--kind", action="append", choices=tuple(KINDS),
                   help="draw only trials of this kind (repeatable): effect (in the library), "
                        "outside (outside it, or its candidate withheld), none, wrong_sigma")
    p.add_argument("--library-only", action="store_true",
                   help="draw no effect outside the candidate library (the kinds effect, none "
                        "and wrong_sigma)")
    add_robot_option(p)
    p.add_argument("--workers", type=int, default=1,
                   help="trials run at once, each in its own process (default 1; the trials "
                        "and their scores are the same for any number)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_blind_bench)
    return p


def cmd_blind_bench(args: argparse.Namespace) -> int:
    # another arm: its arm-dynamics twins (the other domains are the Panda cell's)
    default = (ANY_ARM,) if args.robot else tuple(DOMAINS)
    domains = tuple(args.domain) if args.domain else default
    check_robot(domains, args.robot)
    tty = sys.stderr.isatty()
    bar = progress(args.trials, "blind-bench", enabled=tty)
    done = 0

    def on_trial(t: Trial) -> None:
        # a bar on a terminal; elsewhere (a headless run, a log file) one line per trial
        nonlocal done
        done += 1
        if tty:
            bar.update(1)
        else:
            print(f"blind-bench {done}/{args.trials}: trial {t.index} {t.effect}: "
                  f"{', '.join(t.established) or 'nothing established'} "
                  f"({'A or B' if t.undecided else 'right' if t.correct else 'NOT right'}, "
                  f"{t.diagnosis_s:.0f} s)", file=sys.stderr, flush=True)

    trials = blind_bench(args.trials, args.seed, domains, progress=on_trial,
                         library_only=args.library_only,
                         kinds=tuple(args.kind) if args.kind else None, robot=args.robot,
                         workers=args.workers)
    bar.close()
    summary = summarise(trials)
    if args.json:
        print_json({"summary": summary, "trials": [t.as_dict() for t in trials]})
        return 0
    print(table(["#", "domain", "hidden", "stated sigma", "magnitude", "established", "suspected",
                 "characterised (first)", "ok", "held-out RMS/noise", "noise est.",
                 "diagnosis [s]", "error"],
                [[t.index, t.domain, t.effect,
                  f"/{t.sigma_error:g}" if t.sigma_error != 1 else "right",
                  f"{t.magnitude:.3g}", ", ".join(t.established) or "-",
                  ", ".join(t.suspected) or "-", t.characterised[0] if t.characterised else "-",
                  "A or B" if t.undecided else "yes" if t.correct else "NO",
                  f"{t.heldout_rms_ratio:.3g}" + ("" if t.empirical_rms is None
                                                  else f" ({t.empirical_rms:.3g} with term)"),
                  "-" if t.noise_ratio is None else f"{t.noise_ratio:.2f}",
                  f"{t.diagnosis_s:.1f}", (t.error or "")[:60]] for t in trials]))

    def pct(x: object) -> str:
        return "-" if x is None else f"{100 * float(x):.0f} %"  # type: ignore[arg-type]

    rows = summary["rows"]
    print(table(["trials", "n", "A or B", "correct (of the rest)", "target",
                 "wrong findings established", "held-out RMS/noise median / max"],
                [[r["what"], r["trials"], r["a_or_b"], pct(r["correct"]), f">= {pct(r['target'])}",
                  r["wrong_findings_established"],
                  "-" if r["heldout_rms_median"] is None else
                  f"{r['heldout_rms_median']:.3g} / {r['heldout_rms_max']:.3g}"
                  + ("" if r.get("heldout_rms_with_empirical_median") is None else
                     f" ({r['heldout_rms_with_empirical_median']:.3g} with the empirical term)")]
                 for r in rows.values()]))
    print(f"wrong findings established on any trial: {summary['wrong_findings_established']} "
          f"(target 0); held-out RMS / noise within {RMS_TARGET} where sigma is stated right: "
          f"{pct(summary['heldout_rms_within_target'])}; diagnosis wall time median "
          f"{summary['diagnosis_s_median']:.1f} s, max {summary['diagnosis_s_max']:.1f} s; "
          f"{summary['errors']} trial(s) failed")
    return 0
