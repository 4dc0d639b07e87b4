"""``serpar error-analysis``: seed 001's screw-theory Monte Carlo of the end error."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from serpar.checks import tool_changer_robot as s1
from serpar.checks.error_analysis import CHUNK, ErrorAnalysisConfig, run_error_analysis
from serpar.cli import arg_types
from serpar.cli.out_paths import add_force, out_folder
from serpar.cli.output import print_json, progress, table
from serpar.errors import ConfigError

ROBOT_CHOICES = ("seed001", "panda")  # serpar.checks.error_analysis.ROBOTS
SIGMA_CHOICES = ("table2", "table1")  # serpar.checks.error_analysis.SIGMA_TABLES


def _positive_int(text: str) -> int:
    """argparse type: a positive integer, with a one-line message saying so otherwise."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1 or str(value) != text.strip().lstrip("+"):
        raise argparse.ArgumentTypeError(f"{text!r}: valid values are positive integers, "
                                         f"e.g. 20000")
    return value


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``error-analysis`` subcommand to a subparsers object; returns its parser."""
    p = sub.add_parser("error-analysis",
                       help="seed 001 screw-vector Monte Carlo of the end position/orientation "
                            "error (Tables 3, 5, Eq. 26), sensitivities, Fig. 6 plots")
    p.add_argument("--robot", choices=ROBOT_CHOICES, default="seed001",
                   help="seed001: the paper's tool-changing robot (Table 2, default); "
                        "panda: serpar's arm at its home pose with Table 1's errors")
    p.add_argument("--samples", type=_positive_int, default=20_000,
                   help="Monte Carlo robots per error source (default 20000, as the paper)")
    p.add_argument("--sigmas", choices=SIGMA_CHOICES, default=None,
                   help="transmission-error sigmas: table2 (per link/joint, seed001 default) or "
                        "table1 (per error type; the only choice for panda)")
    p.add_argument("--seed", type=arg_types.seed, default=1, help="random seed (default 1)")
    p.add_argument("--plot", metavar="DIR",
                   help="write error_transmission.png, error_clearance.png (Fig. 6 layout) "
                        "and sensitivity.png into DIR (a folder that holds files is refused "
                        "unless --force)")
    p.add_argument("--json", action="store_true", help="print JSON")
    add_force(p)
    p.set_defaults(func=cmd_error_analysis)
    return p


def _plot_dir(arg: str | None, force: bool) -> Path | None:
    if arg is None:
        return None
    out = Path(arg)
    if not out.parent.is_dir():
        raise ConfigError(f"--plot {arg!r}: folder {str(out.parent)!r} does not exist")
    out_folder(out, "--plot", force)  # not a file, writable; one that holds files needs --force
    out.mkdir(exist_ok=True)
    return out


def _g(x: float) -> str:
    return f"{x:.4g}"


def _stats_rows(stats: dict, paper: dict) -> list[list[str]]:
    units = {"dphi": "rad", "dtheta": "rad", "dpsi": "rad"}
    rows = []
    for name, ours in stats.items():
        ref = paper.get(name)
        rows.append([name, units.get(name, "mm"), *map(_g, ours),
                     *(map(_g, ref) if ref else ["-"] * 4)])
    return rows


def _save_density(errors: dict, title: str, path: Path) -> None:
    """3-D cloud and x-y, x-z, y-z projection densities of dP, laid out like seed 001 Fig. 6."""
    import matplotlib.pyplot as plt
    import numpy as np

    d = np.column_stack([errors["dx"], errors["dy"], errors["dz"]])
    fig = plt.figure(figsize=(10, 9))
    fig.suptitle(title)
    ax = fig.add_subplot(2, 2, 1, projection="3d")
    ax.scatter(*d[:5000].T, s=0.5, c="tab:red", rasterized=True)
    ax.set(xlabel="dx [mm]", ylabel="dy [mm]", zlabel="dz [mm]", title="3-D distribution")
    for k, (i, j, label) in enumerate(((0, 1, "(a) x-y"), (0, 2, "(b) x-z"), (1, 2, "(c) y-z"))):
        ax = fig.add_subplot(2, 2, k + 2)
        _, _, _, im = ax.hist2d(d[:, i], d[:, j], bins=60, density=True, cmap="jet")
        fig.colorbar(im, ax=ax, label="density [1/mm^2]")
        ax.set(xlabel=f"d{'xyz'[i]} [mm]", ylabel=f"d{'xyz'[j]} [mm]",
               title=f"{label} plane projection density")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _save_sensitivity(sens, title: str, path: Path) -> None:
    """Bar per parameter: the end error it causes alone at its sigma (log axis, zeros hidden)."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    colors = {"length": "tab:blue", "drive": "tab:orange", "deflection": "tab:green"}
    contrib = sens.contribution_mm()
    fig, ax = plt.subplots(figsize=(max(8, 0.35 * len(sens.names)), 4.5))
    ax.bar(range(len(sens.names)), contrib, color=[colors[g] for g in sens.groups])
    ax.set_xticks(range(len(sens.names)), sens.names, rotation=70, fontsize=8)
    ax.set(ylabel="1-sigma end position error [mm]", yscale="log", title=title,
           ylim=(1e-3 * contrib.max(), 2 * contrib.max()))
    ax.legend(handles=[Patch(color=c, label=g) for g, c in colors.items()])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _write_plots(result, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")  # headless
    c = result.config
    head = f"{c.robot}, {c.samples} samples"
    paths = [out / "error_transmission.png", out / "error_clearance.png", out / "sensitivity.png"]
    _save_density(result.transmission.errors, f"End position error, transmission errors "
                  f"({c.sigmas}), {head}", paths[0])
    _save_density(result.clearance.errors, f"End position error, joint clearance (Table 4), "
                  f"{head}", paths[1])
    _save_sensitivity(result.sensitivity, f"Sensitivity: end error from each parameter alone "
                      f"at its sigma ({c.robot}, {c.sigmas})", paths[2])
    return [str(p) for p in paths]


def cmd_error_analysis(args: argparse.Namespace) -> int:
    config = ErrorAnalysisConfig(robot=args.robot, sigmas=args.sigmas, samples=args.samples,
                                 seed=args.seed)  # validates: bad input fails fast
    out = _plot_dir(args.plot, args.force)
    show = sys.stderr.isatty() and args.samples > CHUNK
    with progress(2 * args.samples, "error-analysis", enabled=show) as bar:
        result = run_error_analysis(config, progress=bar.update)
    plots = _write_plots(result, out) if out is not None else []
    trans, clear, sens = result.transmission, result.clearance, result.sensitivity
    if args.json:
        print_json(result.as_dict() | {"plots": plots, "paper_seed001": {
            "ideal_position": s1.PAPER_IDEAL_POSITION, "table3": s1.PAPER_TABLE3,
            "table5": s1.PAPER_TABLE5, "position_reliability": s1.PAPER_POSITION_RELIABILITY,
            "angle_reliability": s1.PAPER_ANGLE_RELIABILITY}})
        return 0
    pos = ", ".join(f"{round(v * 1e3, 1) + 0.0:.1f}" for v in result.tool_pose[:3, 3])
    print(f"error analysis: robot {config.robot}, transmission sigmas {config.sigmas}, "
          f"{config.samples} samples per source, seed {config.seed}")
    print(f"nominal tool position [{pos}] mm (seed 001 prints {list(s1.PAPER_IDEAL_POSITION)}, "
          f"no unit)")
    if config.robot != "seed001":
        print("the paper's columns below are for seed 001's robot, shown for scale only")
    head = ["row", "unit", "mean", "std", "max", "min",
            "paper mean", "paper std", "paper max", "paper min"]
    print("\ntransmission errors (links, drives, axis deflection) vs seed 001 Table 3:")
    print(table(head, _stats_rows(trans.stats(), s1.PAPER_TABLE3)))
    print("\njoint clearance (axial, radial, deflection; Table 4) vs seed 001 Table 5:")
    print(table(head, _stats_rows(clear.stats(), s1.PAPER_TABLE5)))
    t_rel = trans.position_reliability(config.thresholds_mm)
    c_rel = clear.position_reliability(config.thresholds_mm)
    rows = [[f"P(|dP| < {t:g} mm)", _g(t_rel[t]), _g(c_rel[t]),
             _g(s1.PAPER_POSITION_RELIABILITY.get(t, float("nan")))] for t in t_rel]
    r = config.angle_threshold_rad
    rows += [[f"P(|{a}| < {r:g} rad)", _g(pt), _g(pc), _g(pp)] for a, pt, pc, pp in zip(
        ("dphi", "dtheta", "dpsi"), trans.angle_reliability(r), clear.angle_reliability(r),
        s1.PAPER_ANGLE_RELIABILITY)]
    print("\nreliability (Eq. 25):")
    print(table(["event", "transmission", "clearance", "paper Eq. 26"], rows))
    contrib = sens.contribution_mm()
    rows = [[n, g, f"{sg * 1e3:.4g} mm" if u == "m" else f"{sg:.4g} rad",
             " ".join(f"{v:+.3f}" for v in sens.position[:, k]),
             "mm/mm" if u == "m" else "mm/mrad", f"{contrib[k]:.3f}"]
            for k, (n, g, u, sg) in enumerate(zip(sens.names, sens.groups, sens.units, sens.sigma))
            if g != "deflection"]
    print("\nsensitivity of the end position (first order, POE error Jacobian):")
    print(table(["parameter", "group", "sigma", "dP/dparam (x y z)", "unit", "1-sigma |dP| [mm]"],
                rows))
    rows = [[g or "all", *(f"{v:.4f}" for v in sens.linear_std_mm(g))]
            for g in ("length", "drive", "deflection", None)]
    rows.append(["Monte Carlo", *(f"{trans.stats()[k][1]:.4f}" for k in ("dx", "dy", "dz"))])
    rows.append(["paper Table 3", *(f"{s1.PAPER_TABLE3[k][1]:.4f}" for k in ("dx", "dy", "dz"))])
    print("\ntransmission std of dx, dy, dz [mm] by error source (first order):")
    print(table(["source", "dx", "dy", "dz"], rows))
    for p in plots:
        print(f"wrote {p}")
    return 0
