"""``serpar import FILE... [--map src=channel,...] [--spec F.yaml] --out DIR``: data as
published into the recording schema (serpar.sim.importers). ``import-csv`` is its old name,
kept as an alias. A flag and the spec may be combined, but not both set one thing."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from serpar.calibration.arm_static_data import static_data
from serpar.cli.out_paths import add_force, out_folder
from serpar.cli.output import print_json
from serpar.errors import ConfigError
from serpar.sim.importers.assemble import ImportOptions, parse_map, to_recording
from serpar.sim.importers.files import FORMATS, file_format, read_files
from serpar.sim.importers.spec import SPEC_KEYS, ImportSpec, load_spec
from serpar.sim.recording import RecordingError, write_recording

BAG_MAP = "time=time,position=q,velocity=dq,effort=tau_J"
"""A JointState topic's default map (the libfranka channel names)."""


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("import", aliases=["import-csv"],
                       help="turn published data (CSV/TSV/text, .mat, ROS 2 bag) into a recording")
    p.add_argument("files", nargs="+", metavar="FILE",
                   help="the data: one table, or one file per channel side by side (e.g. "
                        "q1.txt ... q7.txt, one value per line); a ROS 2 bag folder or .mcap")
    p.add_argument("--format", choices=FORMATS, default="auto",
                   help="auto (default: .mat -> mat, a bag folder / .db3 / .mcap -> rosbag, "
                        "else text: comma, tab, semicolon or whitespace separated)")
    p.add_argument("--map", help="source_column=channel pairs, comma-separated, e.g. "
                                 "t=time,j1=q1; a matrix source maps a channel family "
                                 "(tau=tau_J for tau.1..tau.7). Default: the columns named as "
                                 f"channels; for a bag {BAG_MAP}")
    p.add_argument("--topic", help="the bag's sensor_msgs/msg/JointState topic (default: its "
                                   "only one)")
    p.add_argument("--rate", type=float, help="the control grid's rate in Hz (default: from the "
                                              "stamps); samples one period apart when no "
                                              "column is time")
    p.add_argument("--no-grid", action="store_true",
                   help="keep non-uniform stamps as they are (default: put them on the grid, "
                        "repairs counted)")
    p.add_argument("--table", default="signals", help="signals (default) or measurements")
    p.add_argument("--sigma", help="noise sigma per channel (SI), e.g. q1=1e-5,tau_J1=0.05; "
                                   "for measurements: sigma_m=15e-6")
    p.add_argument("--model", help="JSON merged into meta.model (e.g. the measurements' "
                                   "tool_offset_m, distances)")
    p.add_argument("--spec", metavar="F.yaml",
                   help=f"how the data becomes a recording, in YAML (keys "
                        f"{', '.join(SPEC_KEYS)}): column map, source rate, scale, a "
                        "motor-to-joint map, decimation to an output rate, noise sigma from a "
                        "rest segment; see docs/recording.md")
    p.add_argument("--out", required=True, help="output recording folder (an existing one is refused "
                                                "unless --force, which replaces its recording files)")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_import)
    return p


def _sigma(text: str | None) -> dict[str, float]:
    sigma: dict[str, float] = {}
    for item in filter(None, (text or "").split(",")):
        name, _, value = item.partition("=")
        try:
            sigma[name.strip()] = float(value)
        except ValueError:
            raise RecordingError(f"--sigma entry {item!r} is not channel=number") from None
    return sigma


def _refuse_both(args: argparse.Namespace, spec: ImportSpec | None, extra: dict) -> None:
    """A flag and the spec that set one thing: which one was meant is not ours to guess."""
    if spec is None:
        return
    if args.table != "signals":
        raise RecordingError("--spec is for time series (--table signals)")
    pairs = (("--map", "map", bool(args.map and spec.map)),
             ("--rate", "source_rate", args.rate is not None and spec.source_rate is not None),
             ("--model's robot", "robot", "robot" in extra and spec.robot is not None))
    both = [f"{flag} and the spec's {key}" for flag, key, clash in pairs if clash]
    if both:
        raise ConfigError(f"{both[0]} both set it; give one (the spec: {args.spec})")


def cmd_import(args: argparse.Namespace) -> int:
    folder = out_folder(args.out, "--out", args.force)  # before any file is read
    sigma = _sigma(args.sigma)
    try:
        extra = json.loads(args.model) if args.model else {}
    except json.JSONDecodeError as exc:
        raise RecordingError(f"--model is not valid JSON: {exc.msg}") from None
    if not isinstance(extra, dict):
        raise RecordingError(f"--model must be a JSON object, got {type(extra).__name__}")
    spec = load_spec(args.spec) if args.spec else None
    _refuse_both(args, spec, extra)
    if args.table == "measurements":
        meas = dict(extra.get("measurements", {}))
        if "sigma_m" in sigma:
            meas["sigma_m"] = sigma.pop("sigma_m")
        extra["measurements"] = meas
    rate = args.rate if args.rate is not None else spec.source_rate if spec else None
    options = ImportOptions(args.table, rate, not args.no_grid)
    raw = read_files(args.files, args.format, args.topic)
    bag = all(file_format(Path(f), args.format) == "rosbag" for f in args.files)
    mapping = (parse_map(args.map) if args.map else dict(spec.map) if spec and spec.map
               else parse_map(BAG_MAP) if bag else None)
    rec, report = to_recording(raw, mapping, options, sigma, extra, spec)
    if args.table == "measurements":
        static_data(rec)  # validate now, one line, rather than at diagnosis time
    folder.clear()
    out = write_recording(folder.path, rec)
    if args.json:
        print_json({"out": str(out), "channels": list(rec.meta.channels),
                    "sample_rate_hz": rec.meta.sample_rate_hz,
                    "rows_written": rec.signals.num_rows, **report.as_dict()})
        return 0
    rows = rec.signals.num_rows
    resampled = (f" ({rows} at {rec.meta.sample_rate_hz:g} Hz written)"
                 if report.spec and rows != report.rows else "")
    print(f"wrote {out}: {report.rows} rows kept{resampled}, {len(report.excluded)} isolated bad "
          f"sample(s) excluded" + "".join(f"\n  {w}: {why}" for w, why in report.excluded))
    if report.grid is not None:
        print("  " + report.grid.words())
    for step in report.conversions:
        print(f"  {step}")
    for note in report.notes:
        print(f"  note: {note}", file=sys.stderr)
    return 0
