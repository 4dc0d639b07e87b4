"""``serpar import-csv CSV --map col=channel,... --out DIR``: plain CSV into the recording
schema (serpar.sim.csv_import)."""

from __future__ import annotations

import argparse
import json

from serpar.calibration.arm_static_data import static_data
from serpar.cli.output import print_json
from serpar.sim.csv_import import import_csv, parse_map
from serpar.sim.recording import RecordingError, write_recording


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("import-csv", help="turn a CSV with a column map into a recording")
    p.add_argument("csv", help="CSV file with a header row")
    p.add_argument("--map", required=True,
                   help="csv_column=channel pairs, comma-separated, e.g. t=time,j1=q1")
    p.add_argument("--table", default="signals", help="signals (default) or measurements")
    p.add_argument("--sigma", help="noise sigma per channel (SI), e.g. q1=1e-5,tau_J1=0.05; "
                                   "for measurements: sigma_m=15e-6")
    p.add_argument("--model", help="JSON merged into meta.model (e.g. the measurements' "
                                   "tool_offset_m, distances)")
    p.add_argument("--out", required=True, help="output recording folder")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_import_csv)
    return p


def cmd_import_csv(args: argparse.Namespace) -> int:
    sigma: dict[str, float] = {}
    for item in filter(None, (args.sigma or "").split(",")):
        name, _, value = item.partition("=")
        try:
            sigma[name.strip()] = float(value)
        except ValueError:
            raise RecordingError(f"--sigma entry {item!r} is not channel=number") from None
    try:
        extra = json.loads(args.model) if args.model else {}
    except json.JSONDecodeError as exc:
        raise RecordingError(f"--model is not valid JSON: {exc.msg}") from None
    if args.table == "measurements":
        meas = dict(extra.get("measurements", {}))
        if "sigma_m" in sigma:
            meas["sigma_m"] = sigma.pop("sigma_m")
        extra["measurements"] = meas
    rec, report = import_csv(args.csv, parse_map(args.map), args.table, sigma, extra)
    if args.table == "measurements":

        static_data(rec)  # validate now, one line, rather than at diagnosis time
    out = write_recording(args.out, rec)
    if args.json:
        print_json({"out": str(out), **report.as_dict()})
    else:
        print(f"wrote {out}: {report.rows} rows kept, {len(report.excluded)} isolated bad "
              f"sample(s) excluded" + "".join(f"\n  line {ln}: {why}" for ln, why in report.excluded))
    return 0
