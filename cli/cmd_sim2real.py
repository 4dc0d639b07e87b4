"""``serpar sim2real REAL_DIR``: the simulator against a real cell's assembly outcomes, before
and after a diagnosis of that cell's recordings (checks/sim2real.py)."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from serpar.checks.background_rerun import BackgroundRerun
from serpar.checks.sim2real import (
    OutcomeDiff,
    beyond_ci,
    carried_words,
    compare,
    diagnose_cell,
    established,
    outcomes_of,
    real_episodes,
    updated_contact_friction,
    write_updated,
)
from serpar.checks.sim2real_bore import updated_rerun
from serpar.checks.sim2real_confirm import confirmed_update, to_confirm
from serpar.checks.sim2real_report import write_sim2real_report
from serpar.cli import arg_types
from serpar.cli.cmd_export_mjcf import export_summary
from serpar.cli.out_paths import add_force, out_file, out_folder
from serpar.cli.output import StageLines, print_json, table
from serpar.diagnosis.config_model import model_from_config
from serpar.diagnosis.task_outcomes import OUTCOMES, RESOLUTION
from serpar.errors import ConfigError
from serpar.sim.mjcf_export import is_mjcf_path, read_any_model


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("sim2real", help="compare the simulator's assembly outcomes with a real "
                                        "cell's recordings, diagnose them, and compare again")
    p.add_argument("real_dir", metavar="REAL_DIR",
                   help="serpar run --record episodes of the real cell (never written to)")
    p.add_argument("--model", metavar="M.model.json|M.xml",
                   help="the simulator's arm model to start from (default: the nominal cell)")
    p.add_argument("--out", help="output folder (default REAL_DIR_sim2real): the reruns, "
                                 "updated.model.json, updated.xml")
    p.add_argument("--report", metavar="OUT.html", help="write the HTML report (table, plots)")
    p.add_argument("--seed", type=arg_types.seed, default=0,
                   help="seed of the diagnosis's split, and of the parts where a log has no seed")
    arg_types.add_fit_workers(p)
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_sim2real)
    return p


def further(before: dict[str, OutcomeDiff], after: dict[str, OutcomeDiff]) -> list[str]:
    """Outcomes the update moved further from the cell, beyond what they are measured to, with
    their differences before -> after."""
    out = []
    for n in OUTCOMES:
        b, a = before[n].diff, after[n].diff
        if b is None or a is None or abs(a) <= abs(b) + RESOLUTION.get(n, 0.0):
            continue
        where = ("no CI from one hole" if after[n].ci is None
                 else "now beyond its CI" if beyond_ci(n, after[n]) else "within its CI")
        out.append(f"{n} ({b:+.4g} -> {a:+.4g} {OUTCOMES[n]}, {where})")
    return out


def verdict(before: dict[str, OutcomeDiff], after: dict[str, OutcomeDiff],
            found: list[str] | None = None) -> str:
    """What the update did to the outcomes beyond their CIs, and every outcome it moved further
    from the cell, named with the effects the update added (``found``)."""
    missed = [n for n in OUTCOMES if beyond_ci(n, before[n])]
    away = further(before, after)
    worse = ("; further from the cell after the update: " + ", ".join(away)
             + f" (the update carries {', '.join(found or []) or 'no established effect'}: an "
               "effect the cell does not have, or one its value does not fit, or physics the "
               "update lacks, moves it)") if away else ""
    if all(before[n].ci is None for n in OUTCOMES):  # one hole: nothing to judge a difference by
        return ("no outcome has a CI (one hole each; two or more give one): the differences "
                "stand unjudged" + worse)
    if not missed:
        return ("the nominal simulator's outcomes agree with the real cell's within their CIs"
                + worse)
    fixed = [n for n in missed if after[n].diff is not None
             and abs(after[n].diff) < abs(before[n].diff) and not beyond_ci(n, after[n])]  # type: ignore[arg-type]
    still = [n for n in missed if n not in fixed]
    return (f"beyond the CI with the nominal simulator: {', '.join(missed)}; after the update "
            f"smaller and within the CI: {', '.join(fixed) or 'none'}"
            + (f"; not: {', '.join(still)}" if still else "") + worse)


def cmd_sim2real(args: argparse.Namespace) -> int:
    real = Path(args.real_dir)
    out = Path(args.out) if args.out else real.with_name(real.name.rstrip("/") + "_sim2real")
    if out.resolve() == real.resolve() or real.resolve() in out.resolve().parents:
        raise ConfigError(f"--out {out}: inside REAL_DIR; sim2real never writes into the real "
                          "cell's recordings")
    report = out_file(args.report, "--report", args.force, suffix=".html") if args.report else None
    episodes = real_episodes(real, args.seed)
    start_model = None
    if args.model:
        if not (is_mjcf_path(args.model) or args.model.endswith(".json")):
            raise ConfigError(f"--model {args.model}: a model file (.model.json or an exported .xml)")
        read_any_model(args.model)  # a bad file fails before any simulation
        start_model = args.model
    folder = out_folder(out, "--out", args.force, ("updated.model.json", "updated.xml"))
    folder.clear()
    out.mkdir(parents=True, exist_ok=True)
    running: list[BackgroundRerun] = []
    with StageLines("sim2real") as step:  # one line per stage on stderr, always (--json too)
        try:
            notes = [n for e in episodes for n in e.notes]
            real_outcomes = outcomes_of([e.folder for e in episodes])
            n = len(real_outcomes)
            step(f"{n} hole{'s' * (n != 1)} in {len(episodes)} recording(s); the nominal "
                 "simulator on the same holes, beside the diagnosis")
            # a rerun holds one core: the diagnosis, independent of it, takes the others
            nominal_run = BackgroundRerun(episodes, out / "nominal", start_model, None,
                                          step.beside)
            running.append(nominal_run)
            step("diagnosing the real recordings against the nominal simulator")
            nominal = dataclasses.replace(episodes[0].config, plant_model=start_model)
            diag, model, more = diagnose_cell(episodes, nominal, start_model or "the nominal cell",
                                              args.seed, step, args.workers)
            notes += more
            if not nominal_run.finished():
                step("diagnosed; waiting for the nominal rerun")
            nominal_outcomes = outcomes_of(nominal_run.result())
            running.clear()
            before = compare(real_outcomes, nominal_outcomes)
            step(f"established: {', '.join(f.effect for f in diag.established) or 'nothing'}; the "
                 "updated simulator on the same holes")
            model, bore, updated, bore_note = updated_rerun(episodes, real_outcomes, model, out,
                                                            step, nominal_outcomes, step.beside)
            notes += [bore_note] if bore_note else []
            model_path, exported = write_updated(model, out)
            contact = updated_contact_friction(model)
            found = established(diag, model)
            after = compare(real_outcomes, outcomes_of(updated))
            carried = to_confirm([str(f["effect"]) for f in found], bore.mu, diag.findings,
                                 model["effects"])  # type: ignore[arg-type]
            model, after, checked = confirmed_update(
                episodes, real_outcomes, before, after, updated, model,
                model_from_config(nominal, start_model or "the nominal cell"), carried, out, step,
                step.beside, args.workers)
            dropped = [c.effect for c in checked if c.dropped]
            if dropped:
                model_path, exported = write_updated(model, out)
                contact = updated_contact_friction(model)
        except KeyboardInterrupt:  # Ctrl-C: the finished reruns stay in OUT; no verdict
            for run in running:
                run.stop()
            return step.interrupted(args.json, real_dir=str(real), out=str(out))
    words = (verdict(before, after, [e for e in carried if e not in dropped])
             + carried_words(diag, model)
             + (f"; dropped after the rerun (the outcomes they move moved away from the cell): "
                f"{', '.join(dropped)}" if dropped else "")
             + "".join(f"; {c.effect} not confirmed on holes {', '.join(map(str, c.holes))} but "
                       f"kept: {c.kept_because}" for c in checked if c.kept_because))
    if report is not None:
        write_sim2real_report(report, str(real), before, after, found, notes, words)
    if args.json:
        print_json({"real_dir": str(real), "out": str(out), "holes": len(real_outcomes),
                    "outcomes": {n: {"unit": OUTCOMES[n], "before": before[n].as_dict(),
                                     "after": after[n].as_dict()} for n in OUTCOMES},
                    "established": found, "diagnosis_verdict": diag.verdict,
                    "not_identifiable": list(diag.not_identifiable),
                    "bore_friction": bore.as_dict(),
                    "confirmed_by_rerun": [c.as_dict() for c in checked],
                    "dropped_after_rerun": dropped,
                    "updated_model": str(model_path), "mjcf": export_summary(exported),
                    "contact_friction": contact, "further_after_update": further(before, after),
                    "verdict": words, "notes": notes,
                    "report": None if report is None else str(report)})
        return 0
    for n in notes:
        print(f"note: {n}")
    print(table(["outcome", "unit", "holes", "nominal: real - sim", "updated: real - sim"],
                [[n, OUTCOMES[n], before[n].n, before[n].words(), after[n].words()] for n in OUTCOMES]))
    print(f"diagnosis: {diag.verdict}")
    if diag.not_identifiable:
        print("not identifiable on these holes: " + "; ".join(diag.not_identifiable))
    print(bore.words())
    for c in checked:
        print(f"rerun check: {c.words()}")
    print(f"verdict: {words}")
    print(f"updated model: {model_path}   MJCF: {exported.path}"
          + (f"   report: {report}" if report else ""))
    return 0

