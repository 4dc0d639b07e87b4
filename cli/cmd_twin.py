"""``serpar twin --effect NAME|none``: a recording of a "real" plant with one concealed
effect; the truth goes to ``answer.json`` beside it, never into the recording."""

from __future__ import annotations

import argparse

import numpy as np

from serpar.cli import arg_types
from serpar.cli.out_paths import RECORDING_FILES, add_force, out_folder
from serpar.cli.output import print_json
from serpar.cli.robot_option import add_robot_option
from serpar.errors import ConfigError
from serpar.sim.recording import write_recording
from serpar.sim.strict_json import dumps
from serpar.twins.arm_dynamics_twin import DURATION, DURATION_RANGE
from serpar.twins.cell_twin import ANSWER_FILE, PLANT_FILE, check_effect, make_cell_twin
from serpar.twins.cell_twin import EFFECTS as CELL_EFFECTS
from serpar.twins.registry import ANY_ARM, domain_for, effects, make_twin


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("twin", help="make a recording of a plant with a concealed effect "
                                    "(truth in answer.json)")
    p.add_argument("--effect", required=True,
                   help="an effect name (serpar twin --effect list shows them) or none; with "
                        "--domain cell also mix (two to four drawn effects), with --domain "
                        "arm_dynamics also mix (one friction form and two other effects)")
    p.add_argument("--domain", help="arm_static, arm_dynamics, stewart, stewart_motion, or cell: "
                                    "an assembly episode of a cell with concealed physics, "
                                    "recorded as serpar run --record does (needed only with "
                                    "none or mix; default arm_static)")
    p.add_argument("--holes", type=int, default=12,
                   help="--domain cell: holes of the recorded episode (default 12)")
    p.add_argument("--magnitude", type=float,
                   help="size of the effect (units per domain twin module, e.g. "
                        "twins/stewart_twin.py: K, m/N, m, 1 or x Table 5; default: its default "
                        "size)")
    add_robot_option(p)
    p.add_argument("--duration", type=float,
                   help=f"--domain {ANY_ARM}: seconds recorded, {DURATION_RANGE[0]:g}.."
                        f"{DURATION_RANGE[1]:g} (default {DURATION:g}); with --robot or "
                        f"--duration and --effect none the domain is {ANY_ARM}")
    p.add_argument("--sigma-error", type=float, default=1.0,
                   help="the recording states its noise sigma this many times too small "
                        "(default 1: stated correctly)")
    p.add_argument("--seed", type=arg_types.seed, default=0, help="random seed (default 0)")
    p.add_argument("--out", required=False, help="output folder (recording + answer.json; an existing one "
                                                 "is refused unless --force)")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_twin)
    return p


def cmd_twin(args: argparse.Namespace) -> int:
    if args.effect == "list":
        table = effects()
        print("none (any domain), " + ", ".join(f"{e} ({d})" for e, d in table.items())
              + "; --domain arm_dynamics: mix; --domain cell: mix, " + ", ".join(CELL_EFFECTS))
        return 0
    if not args.out:
        raise ConfigError("--out DIR is required (the recording goes there, the truth to "
                          "DIR/answer.json)")
    if args.domain == "cell" or (args.domain is None and args.effect == "mix"):
        return _cell_twin(args)
    _check_duration(args.duration)
    effect = None if args.effect == "none" else args.effect
    domain_for(effect, args.domain, args.robot, args.duration)  # a refusal before any work
    folder = out_folder(args.out, "--out", args.force, RECORDING_FILES + ("answer.json",))
    rec, answer = make_twin(effect, args.magnitude, args.seed, args.domain, args.sigma_error,
                            args.robot, args.duration)
    folder.clear()
    out = write_recording(folder.path, rec)
    (out / "answer.json").write_text(dumps(answer, indent=2))
    if args.json:
        print_json({"out": str(out), "answer_file": str(out / "answer.json"),
                    "effect": answer.get("effect"), "domain": answer.get("domain")})
    else:
        print(f"wrote {out} ({answer.get('domain')}, effect {answer.get('effect')}); "
              f"the truth is in {out / 'answer.json'}")
    return 0


def _check_duration(duration: float | None) -> None:
    lo, hi = DURATION_RANGE
    if duration is not None and not (np.isfinite(duration) and lo <= duration <= hi):
        raise ConfigError(f"--duration {duration:g} s: valid {lo:g}..{hi:g} s (the {ANY_ARM} "
                          f"twin's recording; default {DURATION:g} s)")


def _cell_twin(args: argparse.Namespace) -> int:
    """``--domain cell``: a recorded episode of a concealed cell (twins/cell_twin.py)."""
    import sys

    folder = out_folder(args.out, "--out", args.force,
                        (f"episode_{args.seed}", ANSWER_FILE, PLANT_FILE))
    if args.magnitude is not None or args.sigma_error != 1.0:
        raise ConfigError("--magnitude and --sigma-error do not apply to --domain cell (its "
                          "effects are drawn from twins/cell_twin.py's ranges)")
    if args.robot is not None or args.duration is not None:
        raise ConfigError(f"--robot and --duration are taken by --domain {ANY_ARM} only; "
                          "--domain cell is the Panda cell's episode (its length: --holes)")
    check_effect(args.effect)  # a bad name fails before any work
    folder.clear()
    show = not args.json

    def on_hole(record) -> None:  # type: ignore[no-untyped-def]
        if show:
            print(f"hole {record.hole}: {record.outcome} ({record.cycle_time_s:.1f} s)",
                  file=sys.stderr)

    answer = make_cell_twin(args.effect, args.seed, args.holes, folder.path, on_hole)
    names = [str(e["effect"]) for e in answer["effects"]]  # type: ignore[index, union-attr]
    if args.json:
        print_json({"out": str(folder.path), "recording": answer["recording"],
                    "answer_file": str(folder.path / ANSWER_FILE), "effect": args.effect,
                    "domain": "cell", "holes": args.holes, "successes": answer["successes"]})
    else:
        print(f"wrote {answer['recording']} (cell, {args.holes} holes, {answer['successes']} "
              f"seated; {len(names)} concealed effect(s)); the truth is in "
              f"{folder.path / ANSWER_FILE}")
    return 0
