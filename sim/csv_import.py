"""Plain CSV with a column map -> a recording of the schema (docs/recording.md).

``signals``: the map names the CSV column of each schema channel (``time`` required; values
SI). ``measurements``: it names the measurement columns (q1..q7, x/y/z or socket, ...).
Bad input is one line naming the problem and the valid choices: a map entry naming a CSV
column that is not there or a channel that the schema does not know, rows with a different
number of fields than the header, a non-numeric value, time that does not increase, values
whose scale does not fit SI (joint angles in degrees, millimetres). Isolated bad samples (an
empty or NaN value with good rows on both sides) are excluded, counted and listed in
``meta.model["import"]``; a run of them, or more than MAX_BAD_FRACTION, is an error. Nothing
is dropped silently.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

from serpar.sim.channels import MEASUREMENT_HELP, MEASUREMENT_OPTIONAL, MEASUREMENT_REQUIRED
from serpar.sim.recording import Recording, RecordingError, RecordingMeta, check_channels

TABLES = ("signals", "measurements")
MAX_BAD_FRACTION = 0.01
STRING_CHANNELS = ("phase", "kind", "set", "placement")
SCALE_LIMITS = {"q": (2 * math.pi + 0.1, "rad"), "dq": (20.0, "rad/s"),
                "tau_J": (500.0, "N m"), "leg": (2.0, "m"), "x": (5.0, "m"), "y": (5.0, "m"),
                "z": (5.0, "m")}
"""Largest plausible magnitude per channel family: beyond it the unit is wrong."""


@dataclass(frozen=True)
class ImportReport:
    rows: int
    excluded: tuple[tuple[int, str], ...]
    """(CSV line, reason) of each excluded sample."""

    def as_dict(self) -> dict[str, object]:
        return {"rows_kept": self.rows, "excluded_count": len(self.excluded),
                "excluded": [{"line": ln, "reason": r} for ln, r in self.excluded]}


def parse_map(text: str) -> dict[str, str]:
    """``col=channel,col2=channel2`` -> {channel: csv column}."""
    out: dict[str, str] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        if "=" not in item:
            raise RecordingError(f"--map entry {item!r} is not csv_column=channel")
        col, chan = (s.strip() for s in item.split("=", 1))
        if chan in out:
            raise RecordingError(f"--map names channel {chan!r} twice")
        out[chan] = col
    if not out:
        raise RecordingError("--map is empty; give csv_column=channel pairs, e.g. t=time,j1=q1")
    return out


def _family(channel: str) -> str:
    return channel.rstrip("0123456789").rstrip("_") if channel not in "xyz" else channel


def _read(path: Path) -> tuple[list[str], list[list[str]]]:
    if not path.is_file():
        raise RecordingError(f"{path} does not exist")
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if not header:
            raise RecordingError(f"{path} is empty; expected a header row of column names")
        rows = []
        for line, row in enumerate(reader, start=2):
            if len(row) != len(header):
                raise RecordingError(f"{path} line {line}: {len(row)} fields, the header has "
                                     f"{len(header)} (mismatched lengths)")
            rows.append(row)
    if not rows:
        raise RecordingError(f"{path} has a header but no data rows")
    return [h.strip() for h in header], rows


def import_csv(path: str | Path, mapping: dict[str, str], table: str = "signals",
               sigma: dict[str, float] | None = None, extra_model: dict | None = None
               ) -> tuple[Recording, ImportReport]:
    """Read ``path`` through ``mapping`` ({channel: csv column}) into a recording."""
    if table not in TABLES:
        raise RecordingError(f"table {table!r}; valid: {', '.join(TABLES)}")
    header, rows = _read(Path(path))
    missing = [c for c in mapping.values() if c not in header]
    if missing:
        raise RecordingError(f"CSV column(s) {', '.join(missing)} not in {path}; its columns: "
                             f"{', '.join(header)}")
    if table == "signals":
        check_channels(tuple(mapping))
    else:
        unknown = [c for c in mapping if c not in (*MEASUREMENT_REQUIRED, *MEASUREMENT_OPTIONAL)]
        if unknown:
            raise RecordingError(f"unknown measurement column(s) {', '.join(unknown)}; valid: "
                                 f"{MEASUREMENT_HELP}")
    cols: dict[str, list] = {}
    bad: dict[int, str] = {}
    for chan, col in mapping.items():
        k = header.index(col)
        if chan in STRING_CHANNELS:
            cols[chan] = [r[k].strip() for r in rows]
            continue
        values = []
        for i, r in enumerate(rows):
            text = r[k].strip()
            try:
                v = float(text) if text else float("nan")
            except ValueError:
                raise RecordingError(f"{path} line {i + 2}, column {col!r}: {text!r} is not a "
                                     "number") from None
            if not math.isfinite(v):
                bad.setdefault(i, f"{chan} ({col}) is {text or 'empty'}")
            values.append(v)
        cols[chan] = values
    _check_bad(path, bad, len(rows))
    keep = np.array([i not in bad for i in range(len(rows))])
    arrays = {c: (np.asarray(v, float)[keep] if c not in STRING_CHANNELS
                  else np.asarray(v, object)[keep]) for c, v in cols.items()}
    _check_scale(arrays)
    excluded = tuple((i + 2, bad[i]) for i in sorted(bad))
    lines = np.flatnonzero(keep) + 2
    report = ImportReport(int(keep.sum()), excluded)
    model = {"import": {"csv": str(path), **report.as_dict()}, **(extra_model or {})}
    pa_cols = {c: pa.array(list(v)) if c in STRING_CHANNELS else pa.array(v)
               for c, v in arrays.items()}
    if table == "measurements":
        meta = RecordingMeta("real", 1.0, ("time",), model=model)
        return Recording(meta, pa.table({"time": pa.array(np.zeros(0))}), pa.table(pa_cols)), report
    t = arrays["time"]
    step = np.diff(t)
    if np.any(step <= 0):
        i = int(np.flatnonzero(step <= 0)[0])
        raise RecordingError(f"{path} line {lines[i + 1]}: time {t[i + 1]:g} s does not increase "
                             f"(previous {t[i]:g} s); time must increase strictly")
    rate = 1.0 / float(np.median(step)) if step.size else 1.0
    order = ("time", *(c for c in mapping if c != "time"))
    sig = {c: float(s) for c, s in (sigma or {}).items()}
    unknown = sorted(set(sig) - set(order))
    if unknown:
        raise RecordingError(f"--sigma names channel(s) not imported: {', '.join(unknown)}; "
                             f"imported: {', '.join(order)}")
    meta = RecordingMeta("real", rate, order, noise_sigma=sig, model=model)
    return Recording(meta, pa.table({c: pa_cols[c] for c in order})), report


def _check_bad(path: str | Path, bad: dict[int, str], n: int) -> None:
    if not bad:
        return
    idx = sorted(bad)
    run = [i for i in idx if i + 1 in bad]
    if run:
        raise RecordingError(f"{path}: bad samples on consecutive lines {run[0] + 2} and "
                             f"{run[0] + 3} ({bad[run[0]]}); only isolated bad samples are "
                             "excluded, a run of them is missing data")
    if len(idx) > MAX_BAD_FRACTION * n:
        raise RecordingError(f"{path}: {len(idx)} bad samples in {n} rows (first at line "
                             f"{idx[0] + 2}: {bad[idx[0]]}), more than "
                             f"{100 * MAX_BAD_FRACTION:g} % that may be excluded")


def _check_scale(arrays: dict[str, np.ndarray]) -> None:
    for chan, v in arrays.items():
        fam = _family(chan)
        if fam in SCALE_LIMITS and v.dtype != object and v.size:
            limit, unit = SCALE_LIMITS[fam]
            peak = float(np.max(np.abs(v)))
            if peak > limit:
                raise RecordingError(f"channel {chan} reaches {peak:g}, beyond any plausible "
                                     f"value in {unit} (|x| <= {limit:g}); the recording must "
                                     "be in SI units (degrees or millimetres?)")
