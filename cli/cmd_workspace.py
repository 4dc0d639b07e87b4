"""``serpar workspace``: Monte Carlo workspace of the Stewart platform (seed 000 §4.1)."""

from __future__ import annotations

import argparse
import sys

from serpar.checks.workspace import (
    CHUNK,
    PAPER_SAMPLES,
    PAPER_VALID,
    l_min_scan,
    workspace_monte_carlo,
)
from serpar.checks.workspace_plot import plot_workspace
from serpar.cli import arg_types
from serpar.cli.out_paths import add_force, out_file
from serpar.cli.output import print_json, progress, table
from serpar.errors import ConfigError
from serpar.sim.stewart import stewart_geometry

HINGE_CHOICES = ("deflection", "cardan", "normal")  # serpar.kinematics.stewart_kinematics order


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``workspace`` subcommand to a subparsers object; returns its parser."""
    p = sub.add_parser("workspace", help="Stewart workspace Monte Carlo vs the seed's 136 534 "
                                         "of 200 000 valid poses")
    p.add_argument("--samples", type=int, default=200_000,
                   help="number of uniform samples in the seed's box (default 200000)")
    p.add_argument("--seed", type=arg_types.seed, default=0, help="random seed (default 0)")
    p.add_argument("--hinge-definition", choices=HINGE_CHOICES, default="deflection",
                   help="hinge angle: deflection from the home leg direction (default), "
                        "cardan (per-axis, = the MuJoCo stops) or normal (from the plate normal)")
    p.add_argument("--plot", help="write the point cloud (Fig. 6 layout) to this .png (an existing file is "
                                  "refused unless --force)")
    add_force(p)
    p.add_argument("--l-min-scan", action="store_true",
                   help="also report the l_min (and stroke) the seed's 68.3 %% would need")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_workspace)
    return p


def _check(args: argparse.Namespace) -> None:
    if args.samples <= 0:
        raise ConfigError(f"--samples {args.samples}: must be a positive integer")
    if args.plot is not None:
        out_file(args.plot, "--plot", args.force, suffix=".png", parents=False)


def cmd_workspace(args: argparse.Namespace) -> int:
    _check(args)  # before the computation: bad input fails fast

    geom = stewart_geometry()
    show = sys.stderr.isatty() and args.samples > CHUNK
    with progress(args.samples, "workspace", enabled=show) as bar:
        result, points = workspace_monte_carlo(geom, args.samples, args.seed,
                                               args.hinge_definition, progress=bar.update)
    scan = (l_min_scan(geom, args.samples, args.seed, args.hinge_definition)
            if args.l_min_scan else None)
    plot = None
    if args.plot is not None:

        plot = str(plot_workspace(points, args.plot, samples=result.samples))
    if args.json:
        print_json(result.as_dict() | {"plot": plot,
                                       "l_min_scan": scan.as_dict() if scan else None})
        return 0
    paper = PAPER_VALID / PAPER_SAMPLES
    print(f"Stewart workspace Monte Carlo: seed {result.seed}, hinge angles "
          f"'{result.hinge_definition}', l_min {result.l_min_m * 1e3:g} mm")
    print(table(["", "samples", "valid", "fraction"],
                [["this model", result.samples, result.valid,
                  f"{100 * result.fraction:.2f} % +- {100 * result.fraction_std:.2f}"],
                 ["seed 000 §4.1", PAPER_SAMPLES, PAPER_VALID, f"{100 * paper:.2f} %"]]))
    print(table(["limit", "violated by", "sole reason for"],
                [[k, v, result.only[k]] for k, v in result.rejected.items()]))
    if scan is not None:
        match = (", ".join(f"{v * 1e3:.1f}" for v in scan.l_min_matching_paper_m) + " mm"
                 if scan.l_min_matching_paper_m else "none")
        need = f"{scan.stroke_for_paper_m * 1e3:.1f} mm" if scan.stroke_for_paper_m else "none"
        print(f"l_min scan: best l_min {scan.best_l_min_m * 1e3:.1f} mm gives "
              f"{100 * scan.best_fraction:.2f} %; hinge limits alone pass "
              f"{100 * scan.hinge_ok_fraction:.2f} %; l_min matching {100 * paper:.2f} %: {match}")
        print(f"stroke limits alone: at best {100 * scan.stroke_only_best_fraction:.2f} %; "
              f"stroke needed for {100 * paper:.2f} %: {need}")
    if plot:
        print(f"wrote {plot}")
    return 0
