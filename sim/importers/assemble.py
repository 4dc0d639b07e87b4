"""A raw table (tables.py) onto the recording schema (docs/recording.md).

``signals``: the map names the source column of each schema channel (``time``, or ``--rate``
for samples one period apart); a matrix source (``q.1``..``q.7``) maps onto a numbered channel
family at once (``q=q``). Without a map, every column named as a schema channel is taken.
``measurements``: the map names the measurement columns (q1..q7, x/y/z or socket, ...).

Bad input is one line naming the problem and the valid choices: a source column that is not
there, a channel the schema does not know, a non-numeric value, time that does not increase,
values whose scale does not fit SI (degrees, millimetres). Isolated bad samples (empty or NaN
with good rows either side) are excluded, counted and listed in ``meta.model["import"]``; a run
of them, or more than MAX_BAD_FRACTION, is an error. Columns not mapped are named in a note.
A time series whose stamps are not uniform is put on the grid (grid.py), the repairs
counted. Nothing is dropped silently.

With a spec (``--spec F.yaml``, spec.py): ``scale`` and ``joint_map`` after the bad samples are
excluded and before the plausibility checks (jointmap.py), ``rate`` (decimation) after the
grid and ``sigma_from_rest`` on the output (resample.py); each conversion noted in
``meta.model["import"]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pyarrow as pa
from numpy.typing import NDArray

from serpar.sim.channels import (
    MEASUREMENT_HELP,
    MEASUREMENT_OPTIONAL,
    MEASUREMENT_REQUIRED,
    TIME,
    is_channel,
    plausible_max,
)
from serpar.sim.importers.grid import GridRepair, on_grid
from serpar.sim.importers.jointmap import joint_side, scale
from serpar.sim.importers.resample import decimate, rest_sigma
from serpar.sim.importers.spec import ImportSpec
from serpar.sim.importers.tables import RawTable
from serpar.sim.recording import Recording, RecordingError, RecordingMeta, check_channels

TABLES = ("signals", "measurements")
MAX_BAD_FRACTION = 0.01
STRING_CHANNELS = ("phase", "kind", "set", "placement")


@dataclass(frozen=True)
class ImportOptions:
    table: str = "signals"
    rate_hz: float | None = None
    """The control grid's rate; None: from the stamps. Required when no column is time."""
    grid: bool = True
    """Put non-uniform stamps on the grid (False: keep them; the diagnosis may refuse them)."""

    def __post_init__(self) -> None:
        if self.table not in TABLES:
            raise RecordingError(f"table {self.table!r}; valid: {', '.join(TABLES)}")
        if self.rate_hz is not None and not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise RecordingError(f"--rate {self.rate_hz}: a sample rate in Hz, > 0")


@dataclass(frozen=True)
class ImportReport:
    rows: int
    excluded: tuple[tuple[str, str], ...]
    """(where, reason) of each excluded sample."""
    grid: GridRepair | None = None
    notes: tuple[str, ...] = ()
    conversions: tuple[str, ...] = ()
    """What the spec did, in words (scale, joint map, decimation, sigma)."""
    spec: dict[str, object] | None = None
    """The spec and what it did, machine-readable."""

    def as_dict(self) -> dict[str, object]:
        out = {"rows_kept": self.rows, "excluded_count": len(self.excluded),
               "excluded": [{"where": w, "reason": r} for w, r in self.excluded],
               "grid": self.grid.as_dict() if self.grid else None, "notes": list(self.notes)}
        if self.spec is not None:
            out |= {"conversions": list(self.conversions), "spec": self.spec}
        return out


def parse_map(text: str) -> dict[str, str]:
    """``col=channel,col2=channel2`` -> {channel: source column}."""
    out: dict[str, str] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        if "=" not in item:
            raise RecordingError(f"--map entry {item!r} is not source_column=channel")
        col, chan = (s.strip() for s in item.split("=", 1))
        if chan in out:
            raise RecordingError(f"--map names channel {chan!r} twice")
        out[chan] = col
    if not out:
        raise RecordingError("--map is empty; give source_column=channel pairs, e.g. t=time,j1=q1")
    return out


def expand_map(mapping: dict[str, str], names: list[str]) -> dict[str, str]:
    """A matrix source onto a numbered family: ``q=q`` with columns q.1..q.7 -> q1..q7."""
    out: dict[str, str] = {}
    for chan, col in mapping.items():
        parts = [n for n in names if n.startswith(col + ".") and n[len(col) + 1:].isdigit()]
        if col not in names and parts:
            for n in sorted(parts, key=lambda n: int(n[len(col) + 1:])):
                out[f"{chan}{n[len(col) + 1:]}"] = n
        else:
            out[chan] = col
    return out


def _numbers(raw: RawTable, chan: str, col: str, bad: dict[int, str]) -> NDArray[np.float64]:
    values = raw.columns[col]
    if values.dtype != object:
        v = np.asarray(values, float)
    else:
        v = np.empty(values.size)
        for i, text in enumerate(values):
            text = str(text).strip()
            try:
                v[i] = float(text) if text else math.nan
            except ValueError:
                raise RecordingError(f"{raw.where(i)}, column {col!r}: {text!r} is not a "
                                     "number") from None
    for i in np.flatnonzero(~np.isfinite(v)):
        bad.setdefault(int(i), f"{chan} ({col}) is {values[i] if values.dtype == object and str(values[i]).strip() else 'empty or NaN'}")
    return v


def _check_bad(raw: RawTable, bad: dict[int, str]) -> None:
    if not bad:
        return
    idx = sorted(bad)
    run = [i for i in idx if i + 1 in bad]
    if run:
        raise RecordingError(f"{raw.where(run[0])} and the next: bad samples in a row "
                             f"({bad[run[0]]}); only isolated bad samples are excluded, a run "
                             "of them is missing data")
    if len(idx) > MAX_BAD_FRACTION * raw.n_rows:
        raise RecordingError(f"{raw.source}: {len(idx)} bad samples in {raw.n_rows} rows (first "
                             f"at {raw.where(idx[0])}: {bad[idx[0]]}), more than "
                             f"{100 * MAX_BAD_FRACTION:g} % that may be excluded")


def _check_scale(arrays: dict[str, NDArray]) -> None:
    for chan, v in arrays.items():
        bound = plausible_max(chan)
        if bound is not None and v.dtype != object and v.size:
            limit, unit = bound
            peak = float(np.max(np.abs(v)))
            if peak > limit:
                raise RecordingError(f"channel {chan} reaches {peak:g}, beyond any plausible "
                                     f"value in {unit} (|x| <= {limit:g}); the recording must "
                                     "be in SI units (degrees or millimetres?)")


def _check_names(mapping: dict[str, str], raw: RawTable, table: str) -> None:
    missing = [c for c in mapping.values() if c not in raw.columns]
    if missing:
        stems = any(n.endswith(f".{c}") for c in missing for n in raw.columns)
        raise RecordingError(f"column(s) {', '.join(missing)} not in {raw.source}; its columns: "
                             f"{', '.join(raw.columns)}" + (" (with several files a column is "
                             "<file stem>.<column>)" if stems else ""))
    if table == "signals":
        check_channels(tuple(mapping) if TIME in mapping else (TIME, *mapping))
    else:
        unknown = [c for c in mapping if c not in (*MEASUREMENT_REQUIRED, *MEASUREMENT_OPTIONAL)]
        if unknown:
            raise RecordingError(f"unknown measurement column(s) {', '.join(unknown)}; valid: "
                                 f"{MEASUREMENT_HELP}")


def default_map(raw: RawTable) -> dict[str, str]:
    """Every column named as a schema channel, as itself."""
    found = {c: c for c in raw.columns if is_channel(c)}
    if not found:
        raise RecordingError(f"no column of {raw.source} is a schema channel (its columns: "
                             f"{', '.join(list(raw.columns)[:12])}); give --map source=channel,...")
    return found


def to_recording(raw: RawTable, mapping: dict[str, str] | None, options: ImportOptions,
                 sigma: dict[str, float] | None = None, extra_model: dict | None = None,
                 spec: ImportSpec | None = None) -> tuple[Recording, ImportReport]:
    """``raw`` through ``mapping`` ({channel: source column}; None: :func:`default_map`) and,
    given one, the spec's conversions."""
    if spec is not None and options.table != "signals":
        raise RecordingError("--spec is for time series (--table signals)")
    if spec is not None and spec.source_rate is not None:
        if options.rate_hz not in (None, spec.source_rate):
            raise RecordingError(f"--rate {options.rate_hz:g} and the spec's source_rate "
                                 f"{spec.source_rate:g} both set the source's rate; give one")
        options = replace(options, rate_hz=spec.source_rate)
    mapping = expand_map(mapping, list(raw.columns)) if mapping else default_map(raw)
    _check_names(mapping, raw, options.table)
    unmapped = [c for c in raw.columns if c not in mapping.values()]
    notes = list(raw.notes)
    if unmapped:
        notes.append(f"column(s) not mapped, not imported: {', '.join(unmapped)}")
    bad: dict[int, str] = {}
    arrays = {chan: (np.asarray([str(v).strip() for v in raw.columns[col]], object)
                     if chan in STRING_CHANNELS else _numbers(raw, chan, col, bad))
              for chan, col in mapping.items()}
    _check_bad(raw, bad)
    keep = np.array([i not in bad for i in range(raw.n_rows)])
    arrays = {c: v[keep] for c, v in arrays.items()}
    renames: dict[str, str] = {}
    conversions: list[str] = []
    if spec is not None:  # motor-side values may be far out of range before the joint map
        arrays, conversions = scale(arrays, mapping, spec)
        arrays, renames, mapped = joint_side(arrays, spec)
        conversions += mapped
    _check_scale(arrays)
    excluded = tuple((raw.where(i), bad[i]) for i in sorted(bad))
    if options.table == "measurements":
        report = ImportReport(int(keep.sum()), excluded, None, tuple(notes))
        model = {"import": {"source": raw.source, **report.as_dict()}, **(extra_model or {})}
        meta = RecordingMeta("real", 1.0, ("time",), model=model)
        cols = {c: pa.array(list(v)) if c in STRING_CHANNELS else pa.array(v)
                for c, v in arrays.items()}
        return Recording(meta, pa.table({"time": pa.array(np.zeros(0))}), pa.table(cols)), report
    t, arrays, grid = _time(raw, arrays, keep, options)
    order = (TIME, *(renames.get(c, c) for c in mapping if c != TIME))
    sig = {c: float(s) for c, s in (sigma or {}).items()}
    unknown = sorted(set(sig) - set(order))
    if unknown:
        raise RecordingError(f"--sigma names channel(s) not imported: {', '.join(unknown)}; "
                             f"imported: {', '.join(order)}")
    rate = (grid.rate_hz if grid else options.rate_hz if options.rate_hz
            else 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 1.0)
    done = None
    if spec is not None:
        t, arrays, rate, done = _output(t, arrays, rate, sig, spec, conversions)
    report = ImportReport(int(keep.sum()), excluded, grid, tuple(notes), tuple(conversions),
                          done)
    model = {"import": {"source": raw.source, "map": {c: ch for ch, c in mapping.items()},
                        **report.as_dict()}, **(extra_model or {})}
    if spec is not None and spec.robot is not None:
        model["robot"] = spec.robot
    meta = RecordingMeta("real", rate, order, noise_sigma=sig, model=model)
    cols = {TIME: pa.array(t)} | {c: pa.array(list(v)) if c in STRING_CHANNELS else pa.array(v)
                                  for c, v in arrays.items() if c != TIME}
    return Recording(meta, pa.table({c: cols[c] for c in order})), report


def _output(t: NDArray[np.float64], arrays: dict[str, NDArray], rate: float,
            sig: dict[str, float], spec: ImportSpec, conversions: list[str]
            ) -> tuple[NDArray[np.float64], dict[str, NDArray], float, dict[str, object]]:
    """The spec's conversions on the grid: decimation to ``rate``, then (on the output's
    samples) the noise sigma from the rest segment, written into ``sig`` where not given."""
    t, arrays, rate_out, info = decimate(t, arrays, rate, spec)
    if info.get("factor", 1) > 1:
        conversions.append(f"decimated {info['rate_in_hz']:g} Hz -> {rate_out:g} Hz (/"
                           f"{info['factor']}): {info['filter']}")
    rest, said, rest_info = rest_sigma(t, arrays, sig, spec)
    conversions += said
    sig.update({c: s for c, s in rest.items() if c not in sig})
    return t, arrays, rate_out, {**spec.as_dict(), "rate_in_hz": rate, "rate_out_hz": rate_out,
                                 "decimation": info or None,
                                 "sigma_from_rest": rest_info or None}


def _time(raw: RawTable, arrays: dict[str, NDArray], keep: NDArray[np.bool_],
          options: ImportOptions) -> tuple[NDArray[np.float64], dict[str, NDArray], GridRepair | None]:
    """The time stamps (from the time column, or row / rate) and, where they are not uniform,
    the columns put on the grid."""
    if TIME not in arrays:
        if options.rate_hz is None:
            raise RecordingError("no column is mapped to time; map one (e.g. t=time) or give "
                                 "--rate HZ for samples one period apart")
        t = np.flatnonzero(keep) / options.rate_hz  # an excluded row stays a missed tick
    else:
        t = arrays.pop(TIME)
        rows = np.flatnonzero(keep)
        step = np.diff(t)
        if np.any(step <= 0):
            i = int(np.flatnonzero(step <= 0)[0])
            raise RecordingError(f"{raw.where(int(rows[i + 1]))}: time {t[i + 1]:.9g} s does not "
                                 f"increase (previous {t[i]:.9g} s); time must increase strictly")
    if t.size < 2 or not options.grid:
        return t, arrays, None
    period = 1.0 / options.rate_hz if options.rate_hz else float(np.median(np.diff(t)))
    k = (t - t[0]) / period
    if np.max(np.abs(k - np.arange(t.size))) <= 1e-3:
        return t, arrays, None  # uniform already: nothing to repair
    grid, arrays, repair = on_grid(t, arrays, options.rate_hz, raw.source)
    return grid, arrays, repair
