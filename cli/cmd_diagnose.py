"""``serpar diagnose REC``: where the nominal model and a recording differ, which physics it
left out, the fitted model, and the held-out improvement (serpar.diagnosis)."""

from __future__ import annotations

import argparse
from pathlib import Path

from serpar.cli import arg_types
from serpar.cli.cmd_export_mjcf import export_summary, print_export, print_urdf, urdf_summary
from serpar.cli.out_paths import add_force, out_file, out_files
from serpar.cli.output import StageLines, print_json, table
from serpar.cli.robot_option import add_robot_option
from serpar.diagnosis.arm_dynamics_family import ArmDynamicsConfig
from serpar.diagnosis.choose import family_from_recording, load_for_diagnosis, load_notes
from serpar.diagnosis.config_model import is_config_path, model_from_episode_config
from serpar.diagnosis.prior import PriorFamily
from serpar.diagnosis.report_html import write_report
from serpar.diagnosis.select import default_config, diagnose
from serpar.errors import ConfigError
from serpar.sim.mjcf_export import export_mjcf, read_any_model
from serpar.sim.model_file import parse_model
from serpar.sim.plants.from_model_file import KNOWN_EFFECTS, applied_parts, arm_plant_changes
from serpar.sim.robot_file import load_robot
from serpar.sim.urdf_export import export_urdf, require_urdf


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("diagnose", help="locate sim-vs-real differences, name and fit the "
                                        "missing physics, score it on held-out data")
    p.add_argument("recording", help="a recording folder (docs/recording.md) or a "
                                     "panda_1-layout folder")
    p.add_argument("--report", metavar="OUT.html",
                   help="write an HTML report (plots embedded) and OUT.model.json beside it "
                        "(Stewart geometry or encoder offsets: also OUT.stewart_params.json, "
                        "for serpar run's stewart_calibration); existing files are refused unless --force")
    p.add_argument("--mjcf", metavar="OUT.xml",
                   help="also write the updated arm as one MJCF (established effects, full "
                        "precision; serpar export-mjcf writes it from a model file): serpar's "
                        "Panda, or the --robot arm")
    p.add_argument("--urdf", metavar="OUT.urdf",
                   help="also write the --robot URDF with each joint's <dynamics> friction and "
                        "damping from the established friction")
    add_force(p)
    p.add_argument("--model", metavar="M.model.json|M.xml|CELL.yaml",
                   help="diagnose against a previous diagnosis's model file (or its MJCF "
                        "export), or against the "
                        "cell an episode config (serpar run --config YAML) builds: its arm "
                        "friction and plant model; their effects are fixed in the nominal "
                        "prediction (default: the nominal arm); the written model is M's "
                        "updated by what this recording shows")
    p.add_argument("--seed", type=arg_types.seed, default=0, help="seed of the train/held-out split "
                                                       "where the recording does not fix it")
    add_robot_option(p)
    p.add_argument("--train", type=arg_types.span, metavar="START:END",
                   help="arm dynamics: train on the windows inside START:END seconds from the "
                        "first sample (with --heldout; the resampling folds stay inside it); "
                        "default: alternate 2-s blocks of the whole recording")
    p.add_argument("--heldout", type=arg_types.span, metavar="START:END",
                   help="arm dynamics: hold out the windows inside START:END seconds (with --train)")
    p.add_argument("--withhold", action="append", default=[], metavar="EFFECT",
                   help="diagnose without this candidate (repeatable): how the verdict reads "
                        "where the library lacks a form, as the blind bench's withheld trials")
    arg_types.add_fit_workers(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_diagnose)
    return p


def print_diagnosis(diag, source: str) -> None:  # type: ignore[no-untyped-def]
    print(f"serpar diagnose {source}: {diag.kind}, {diag.n_train_rows} training / "
          f"{diag.n_heldout_rows} held-out rows, {diag.wall_s:.1f} s")
    print("\nWHERE (nominal model, baseline fitted; residual / noise sigma):")
    print(table(["channel", "split by", "label", "n", "RMS/sigma", "p", "beyond noise"],
                [[r.channel, r.group, r.label, r.n, f"{r.rms_whitened:.3g}", f"{r.p_value:.2g}",
                  "YES" if r.flagged else ""] for r in diag.locate_before]))
    print("\nWHAT:")
    if not diag.findings:
        print(f"  {diag.verdict}")
    for f in diag.findings:
        print(f"  {f.rank}. {f.words()}")
    print(f"\nheld-out RMS / noise: {diag.heldout_rms_before:.3g} before -> "
          f"{diag.heldout_rms_after:.3g} after (noise floor 1, p = {diag.heldout_p_after:.2g}); "
          f"{100 * diag.explained:.1f} % of the excess held-out residual explained")
    if diag.physical is not None:
        print("held-out RMS in physical units, before -> after: " + ", ".join(
            f"{r.channel} {r.before:.3g} -> {r.after:.3g} {r.unit}" for r in diag.physical.rms))
    print(f"verdict: {diag.verdict}")
    if diag.not_identifiable:
        print("not identifiable on these data: " + "; ".join(diag.not_identifiable))


def plant_summary(model: dict) -> dict[str, list[str]] | None:  # type: ignore[type-arg]
    """What `serpar run` (EpisodeConfig.plant_model) will apply of a written arm model, and
    what it cannot; None for a model of another domain."""

    if not all(e in KNOWN_EFFECTS for e in model["effects"]):
        return None
    try:
        changes = arm_plant_changes(parse_model(model, "the model"))
    except ConfigError as exc:  # the diagnosis stands; only its use as a plant fails
        return {"applied": [], "not_applied": [f"not usable as a plant model: {exc}"]}
    return {"applied": applied_parts(changes), "not_applied": list(changes.not_applied)}


def cmd_diagnose(args: argparse.Namespace) -> int:
    import dataclasses


    if args.report:  # before any work: the report, its model file and a Stewart parameter file
        report = Path(args.report)
        out_files([report, *(report.with_name(report.stem + s) for s in (".model.json", ".stewart_params.json"))],
                  "--report", args.force)
    mjcf = out_file(args.mjcf, "--mjcf", args.force, suffix=".xml") if args.mjcf else None
    urdf = out_file(args.urdf, "--urdf", args.force, suffix=".urdf") if args.urdf else None
    robot = load_robot(getattr(args, "robot", None))
    if urdf is not None:  # before any work: a URDF to write back
        require_urdf(robot.source)
    rec = load_for_diagnosis(args.recording, robot)
    train, heldout = getattr(args, "train", None), getattr(args, "heldout", None)
    if (train is None) != (heldout is None):
        raise ConfigError("--train and --heldout go together: give both spans, e.g. "
                          "--train 0.1:6 --heldout 6:7.5")
    dynamics = None if train is None else ArmDynamicsConfig(train_span=train, heldout_span=heldout)
    family = family_from_recording(rec, robot, dynamics)
    notes = load_notes(rec) + list(getattr(family, "notes", ()))  # the data's, then the family's
    withheld = list(dict.fromkeys(args.withhold))
    if withheld:
        names = [e.name for e in family.effects]
        unknown = [w for w in withheld if w not in names]
        if unknown:
            raise ConfigError(f"--withhold {', '.join(unknown)}: not a candidate of this "
                              f"recording's family; valid: {', '.join(names)}")
        family.effects = tuple(e for e in family.effects if e.name not in withheld)
        notes.append(f"candidates withheld (--withhold): {', '.join(withheld)}")
    prior = None
    if args.model:

        read = model_from_episode_config if is_config_path(args.model) else read_any_model
        family = prior = PriorFamily(family, read(args.model))
    with StageLines("diagnose") as step:  # one line per stage on stderr, always
        try:
            diag = diagnose(family, args.seed, default_config(family, args.workers), step)
        except KeyboardInterrupt:  # Ctrl-C: where it stopped, no verdict
            return step.interrupted(args.json, recording=str(args.recording))
    if prior is not None:  # the written model: M's effects, corrected, plus the new ones
        diag = dataclasses.replace(diag, model=prior.combined_model(diag.model))
    plant = plant_summary({"source": str(args.recording), **diag.model})
    if robot.source != "built-in":  # serpar run's cell holds the Panda, not this arm
        why = f"a model of {robot.label}: serpar run's cell has the Panda"
        plant = {"applied": [], "not_applied": [why]}
    paths, exported, urdf_written = None, None, None
    if args.report:

        paths = write_report(diag, Path(args.report), str(args.recording), family)
    if mjcf is not None or urdf is not None:
        written_model = parse_model(diag.model_file(str(args.recording)), "the model")
        if mjcf is not None:
            exported = export_mjcf(written_model, mjcf, robot.source)
        if urdf is not None:
            urdf_written = export_urdf(written_model, robot.source, urdf)
    if args.json:
        out = diag.as_dict()
        if paths:
            out["report"], out["model_file"] = str(paths[0]), str(paths[1])
            out["exported_files"] = [str(p) for p in paths[2]]
        if prior is not None:
            out["prior_model"], out["fixed_effects"] = args.model, list(prior.fixed)
        out["plant"] = plant
        out["mjcf"] = None if exported is None else export_summary(exported)
        out["urdf"] = None if urdf_written is None else urdf_summary(urdf_written)
        out["notes"] = notes
        if getattr(args, "robot", None):
            out["robot"] = {"name": robot.name, "source": robot.source}
        print_json(out)
    else:
        for note in notes:
            print(f"note: {note}")
        if prior is not None:
            print(f"against {args.model}: {', '.join(prior.fixed) or 'no effects'} fixed at its "
                  "values (a finding on one of them is a correction)")
        print_diagnosis(diag, str(args.recording))
        if paths:
            print(f"report: {paths[0]}   model: {paths[1]}"
                  + "".join(f"   for serpar run: {p}" for p in paths[2]))
        if plant is not None and diag.model["effects"]:
            print("as a plant model (`serpar run`, plant_model:): applies "
                  f"{', '.join(plant['applied']) or 'nothing'}"
                  + "".join(f"\n  warning: {n}" for n in plant["not_applied"]))
        if exported is not None:
            print_export(exported)
        if urdf_written is not None:
            print_urdf(urdf_written)
    return 0
