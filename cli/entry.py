"""The ``serpar`` command: parses arguments and calls into the packages. No physics here."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence

from serpar.cli import (
    arg_types,
    cmd_ablate,
    cmd_bench,
    cmd_blind_bench,
    cmd_calibrate,
    cmd_control_check,
    cmd_diagnose,
    cmd_error_analysis,
    cmd_export_mjcf,
    cmd_export_scene,
    cmd_import,
    cmd_montecarlo,
    cmd_replay,
    cmd_run,
    cmd_sim2real,
    cmd_twin,
    cmd_vision_check,
    cmd_workspace,
)
from serpar.cli.out_paths import add_force, out_file
from serpar.cli.output import fail, print_json, progress, table
from serpar.errors import SerparError
from serpar.sim.config_io import load_yaml_config
from serpar.sim.info import scene_info
from serpar.sim.physics import PhysicsConfig
from serpar.sim.poses import apply_state
from serpar.sim.render import CameraRenderer, save_png
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.validation import CHECKS, run_checks


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit 2, no usage dump)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(2)

    def parse_args(self, args=None, namespace=None):  # type: ignore[override]
        """As argparse's, but an unknown flag is named with the valid flags of its command."""
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            command = self._command_parser(parsed)
            flags = sorted({o for a in command._actions for o in a.option_strings if o.startswith("--")})
            self.error(f"unrecognized argument(s) {' '.join(extras)}"
                       + (f" for {command.prog}; valid flags: {', '.join(flags)}" if flags else ""))
        return parsed

    def _command_parser(self, parsed: argparse.Namespace) -> argparse.ArgumentParser:
        """The innermost (sub)command parser the arguments chose (serpar calibrate arm: its own)."""
        parser: argparse.ArgumentParser = self
        while True:
            sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
            name = getattr(parsed, sub.dest, None) if sub is not None else None
            if sub is None or name not in sub.choices:
                return parser
            parser = sub.choices[name]


def _scene_config(args: argparse.Namespace):
    cfg = load_yaml_config(SceneConfig, args.config) if args.config else SceneConfig()
    if args.seed is not None:
        cfg = dataclasses.replace(cfg, seed=args.seed)
    return cfg


def cmd_info(args: argparse.Namespace) -> int:
    info = scene_info(build_scene(_scene_config(args)))
    if args.json:
        print_json(info)
        return 0
    c = info["counts"]
    print(f"serpar cell  seed={info['seed']}  timestep={info['timestep_s'] * 1e3:g} ms")
    print(f"bodies {c['bodies']}  geoms {c['geoms']}  dof {c['dof']}  actuators {c['actuators']}  "
          f"sensors {c['sensors']}  cameras {c['cameras']}  equality constraints {c['equality_constraints']}")
    print("actuators: " + ", ".join(info["actuators"]))
    print("sensors:   " + ", ".join(info["sensors"]))
    print(table(["camera", "resolution", "f [mm]", "f [px]", "pixel [um]", "fovy [deg]"],
                [[k["name"], "x".join(map(str, k["resolution"])), k["focal_length_mm"],
                  k["focal_px"][0], k["pixel_um"], k["fovy_deg"]] for k in info["cameras"]]))
    holes, journals = info["holes_um"], info["journals_um"]
    print(f"holes (H7, um): n={len(holes)} min {min(holes):.3f} max {max(holes):.3f}")
    if journals:
        print(f"journals (h6, um): n={len(journals)} min {min(journals):.3f} max {max(journals):.3f}")
        cl = info["clearance_um"]
        print(f"diametral clearance any pair (um): min {cl['min']:.3f} mean {cl['mean']:.3f} "
              f"max {cl['max']:.3f}")
    print(f"bores: {info['bore_facets']} facets, roundness error <= {info['bore_roundness_um_worst']} um, "
          f"chamfer {info['chamfer_mm']} mm")
    print(table(["hole", "diameter [um]"], [[k, f"{v:.3f}"] for k, v in enumerate(holes)])
          if args.verbose else "(--verbose lists every hole and journal)")
    if args.verbose and journals:
        print(table(["conductor", "journal [um]", "body [um]"],
                    [[k, f"{j:.3f}", f"{b:.3f}"] for k, (j, b) in
                     enumerate(zip(journals, info["bodies_um"]))]))
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    out_file(args.out, "--out", args.force, suffix=".png")  # before any rendering
    scene = build_scene(_scene_config(args))
    apply_state(scene, args.state)
    renderer = CameraRenderer(scene.model)
    image = renderer.render(scene.data, args.camera, args.width, args.height)
    out = save_png(image, args.out)
    renderer.close()
    print(f"wrote {out} ({image.shape[1]}x{image.shape[0]}) from camera {args.camera}")
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    physics = load_yaml_config(PhysicsConfig, args.physics) if args.physics else PhysicsConfig()
    names = args.check or list(CHECKS)
    bar = progress(len(names), "validate", enabled=sys.stderr.isatty())

    started: list[str] = []

    def step(name: str) -> None:
        if started:  # the previous check has finished
            bar.update(1)
        started.append(name)
        bar.set_postfix_str(name)

    results = run_checks(args.check, physics, progress=step)
    bar.update(1)
    bar.close()
    if args.json:
        print_json({"timestep_s": physics.timestep, "checks": [r.as_dict() for r in results],
                    "passed": all(r.passed for r in results)})
    else:
        print(table(["#", "check", "measured", "limit", "result", "detail"],
                    [[i + 1, r.description, f"{r.value:.4g} {r.unit}", f"{r.comparison} {r.limit:g} {r.unit}",
                      "PASS" if r.passed else "FAIL", r.detail] for i, r in enumerate(results)]))
    return 0 if all(r.passed for r in results) else 1


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="serpar", description="serpar: a MuJoCo simulator of a serial-parallel precision "
                     "assembly cell (Panda arm, 6-UPS Stewart platform, H7/h6 journal insertion, stereo vision). "
                     "Start with `serpar run --holes 3`.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def scene_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("--seed", type=arg_types.seed, help="seed of the tolerance draws (integer; default 0)")
        p.add_argument("--config", help="scene config YAML (keys of serpar.sim.scene.SceneConfig)")

    p = sub.add_parser("info", help="bodies, DoF, actuators, sensors, cameras, drawn diameters")
    scene_args(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--verbose", "-v", action="store_true", help="list every hole and journal")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("render", help="render one camera offscreen to a PNG")
    scene_args(p)
    p.add_argument("--camera", required=True,
                   help="overview, top_left, top_right, inspect_left or inspect_right")
    p.add_argument("--out", required=True, help="output .png path (an existing file is refused unless --force)")
    add_force(p)
    p.add_argument("--width", type=int, help="image width (stereo cameras: 4:3 with height)")
    p.add_argument("--height", type=int, help="image height")
    p.add_argument("--state", default="home",
                   help="preview state: home (default) or inspect (a conductor in hand at the "
                        "in-hand cameras; kinematic pose for pictures)")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("validate", help="physical validation checks, PASS/FAIL (exit 1 on FAIL)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--check", action="append",
                   help="run only this check (repeatable): rim_rest, aligned_insertion, "
                        "lateral_penetration, noisy_stepping, stewart_loops")
    p.add_argument("--physics", help="physics config YAML (keys of serpar.sim.physics.PhysicsConfig)")
    p.set_defaults(func=cmd_validate)


    cmd_control_check.register(sub)
    cmd_run.register(sub)
    cmd_ablate.register(sub)
    cmd_workspace.register(sub)
    cmd_vision_check.register(sub)
    cmd_bench.register(sub)
    cmd_replay.register(sub)
    cmd_calibrate.register(sub)
    cmd_error_analysis.register(sub)
    cmd_diagnose.register(sub)
    cmd_export_mjcf.register(sub)
    cmd_export_scene.register(sub)
    cmd_sim2real.register(sub)
    cmd_twin.register(sub)
    cmd_blind_bench.register(sub)
    cmd_import.register(sub)
    cmd_montecarlo.register(sub)
    # the commands by their own names (aliases such as import-csv stay in the list below)
    sub.metavar = "{" + ",".join(a.dest for a in sub._choices_actions) + "}"
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except SerparError as exc:
        return fail(str(exc))
    except KeyboardInterrupt:
        return fail("interrupted", 130)
