"""Recordings: one schema for simulated and real data (DESIGN.md §4, docs/recording.md).

A recording is a folder with ``meta.json`` and tables in Parquet (default) or CSV:
``signals`` (time series, libfranka column names where one exists) and optionally
``measurements`` (static calibration sets). This module writes, reads and validates them;
it knows nothing about where the numbers came from.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from serpar.errors import SerparError
from serpar.sim.channels import KNOWN_HELP, PHASE, TIME, is_channel, plausible_max
from serpar.sim.strict_json import dumps

SCHEMA_VERSION = 1
SOURCES = ("sim", "real")
FORMATS = ("parquet", "csv")
TABLES = ("signals", "measurements")

class RecordingError(SerparError, ValueError):
    """A recording that does not follow the schema (one line, naming the problem)."""


@dataclass(frozen=True)
class PhaseSegment:
    name: str
    start: float
    """[s], from the recording's time origin."""
    end: float


@dataclass(frozen=True)
class RecordingMeta:
    """``meta.json``: what the tables are and how far to trust them."""

    source: str
    """'sim' or 'real'."""
    sample_rate_hz: float
    channels: tuple[str, ...]
    noise_sigma: dict[str, float] = field(default_factory=dict)
    """Per-channel measurement noise, SI units (what 'beyond noise' is judged against)."""
    phases: tuple[PhaseSegment, ...] = ()
    model: dict[str, object] = field(default_factory=dict)
    """The model or config the recording was made with (for a sim) or against (real)."""
    schema_version: int = SCHEMA_VERSION
    units: str = "SI"

    def __post_init__(self) -> None:
        if self.source not in SOURCES:
            raise RecordingError(f"source {self.source!r}; valid: {', '.join(SOURCES)}")
        if self.schema_version != SCHEMA_VERSION:
            raise RecordingError(f"schema version {self.schema_version}; this serpar reads {SCHEMA_VERSION}")
        if self.units != "SI":
            raise RecordingError(f"units {self.units!r}; recordings are in SI units")
        if not self.sample_rate_hz > 0:
            raise RecordingError(f"sample_rate_hz must be > 0, got {self.sample_rate_hz}")
        check_channels(self.channels)
        unknown = sorted(set(self.noise_sigma) - set(self.channels))
        if unknown:
            raise RecordingError(f"noise_sigma names channels not recorded: {', '.join(unknown)}")
        for p in self.phases:
            if not p.start <= p.end:
                raise RecordingError(f"phase {p.name!r} ends before it starts ({p.start} > {p.end})")

    def as_json(self) -> dict[str, object]:
        d = asdict(self)
        d["channels"] = list(self.channels)
        d["phases"] = [asdict(p) for p in self.phases]
        return d

    @classmethod
    def from_json(cls, d: object) -> RecordingMeta:
        if not isinstance(d, dict):
            raise RecordingError(f"meta.json: expected a JSON object, got {type(d).__name__}")
        try:
            channels = d["channels"]
            if not isinstance(channels, list) or not all(isinstance(c, str) for c in channels):
                raise RecordingError("meta.json: channels must be a list of channel names")
            phases = tuple(PhaseSegment(str(p["name"]), _number(p["start"], "phase start"),
                                        _number(p["end"], "phase end")) for p in d.get("phases", []))
            sigma = {str(k): _number(v, f"noise_sigma[{k}]") for k, v in dict(d.get("noise_sigma", {})).items()}
            bad = [k for k, v in sigma.items() if v < 0]
            if bad:
                raise RecordingError(f"meta.json: noise_sigma of {', '.join(bad)} must be >= 0 "
                                     "(0: an ideal sensor)")
            return cls(source=d["source"], sample_rate_hz=_number(d["sample_rate_hz"], "sample_rate_hz"),
                       channels=tuple(channels), noise_sigma=sigma,
                       phases=phases, model=dict(d.get("model", {})),
                       schema_version=int(d.get("schema_version", -1)), units=d.get("units", "SI"))
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, RecordingError):
                raise
            raise RecordingError(f"meta.json: missing or malformed field ({exc}); needs source, "
                                 "sample_rate_hz, channels") from None


def _number(value: object, what: str) -> float:
    """A finite JSON number (a string or boolean is not one)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RecordingError(f"meta.json: {what} must be a finite number, got {value!r}")
    return float(value)


def check_channels(channels: tuple[str, ...] | list[str]) -> None:
    """Every name must be a schema channel; 'time' must be present, names unique."""
    bad = [c for c in channels if not is_channel(c)]
    if bad:
        raise RecordingError(f"unknown channel(s) {', '.join(bad)}; valid: {KNOWN_HELP}")
    if TIME not in channels:
        raise RecordingError("the signals need a 'time' channel [s]")
    if len(set(channels)) != len(channels):
        raise RecordingError("channel names repeat")


@dataclass(frozen=True)
class Recording:
    meta: RecordingMeta
    signals: pa.Table
    measurements: pa.Table | None = None

    def column(self, name: str) -> np.ndarray:
        if name not in self.signals.column_names:
            raise RecordingError(f"no channel {name!r}; recorded: {', '.join(self.signals.column_names)}")
        return self.signals.column(name).to_numpy()

    def phase(self, name: str) -> pa.Table:
        """Rows of the signals within the named phase segment(s)."""
        segs = [p for p in self.meta.phases if p.name == name]
        if not segs:
            raise RecordingError(f"no phase {name!r}; recorded: {', '.join(sorted({p.name for p in self.meta.phases}))}")
        t = self.column("time")
        mask = np.zeros(len(t), bool)
        for p in segs:
            mask |= (t >= p.start) & (t <= p.end)
        return self.signals.filter(pa.array(mask))


def write_recording(folder: str | Path, recording: Recording, fmt: str = "parquet") -> Path:
    """Write `recording` into `folder` (created); returns the folder."""
    if fmt not in FORMATS:
        raise RecordingError(f"format {fmt!r}; valid: {', '.join(FORMATS)}")
    _check_signals(recording.meta, recording.signals)
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    (out / "meta.json").write_text(dumps(recording.meta.as_json(), indent=2))
    tables = {"signals": recording.signals, "measurements": recording.measurements}
    for name, table in tables.items():
        if table is None:
            continue
        if fmt == "parquet":  # floats byte-stream-split + zstd: ~40 % smaller than the default, lossless
            floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
            pq.write_table(table, out / f"{name}.parquet", compression="zstd",
                           use_dictionary=[c for c in table.column_names if c not in floats],
                           use_byte_stream_split=floats)
        else:
            pacsv.write_csv(table, out / f"{name}.csv")
    return out


def read_recording(folder: str | Path) -> Recording:
    """Read and validate a recording folder."""
    src = Path(folder)
    if not (src / "meta.json").is_file():
        raise RecordingError(f"{src} is not a recording: no meta.json")
    try:
        meta = RecordingMeta.from_json(json.loads((src / "meta.json").read_text()))
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{src / 'meta.json'} is not valid JSON: {exc.msg} (line {exc.lineno})") from None
    except UnicodeDecodeError:
        raise RecordingError(f"{src / 'meta.json'} is not text (UTF-8 JSON)") from None
    tables: dict[str, pa.Table | None] = {}
    for name in TABLES:
        parquet, csv = src / f"{name}.parquet", src / f"{name}.csv"
        path = parquet if parquet.is_file() else csv if csv.is_file() else None
        tables[name] = None if path is None else _read_table(path)
    if tables["signals"] is None:
        raise RecordingError(f"{src} has no signals.parquet or signals.csv")
    _check_signals(meta, tables["signals"])
    return Recording(meta, tables["signals"], tables["measurements"])


def _read_table(path: Path) -> pa.Table:
    try:
        return pq.read_table(path) if path.suffix == ".parquet" else pacsv.read_csv(path)
    except (pa.ArrowException, OSError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        kind = "Parquet" if path.suffix == ".parquet" else "CSV"
        raise RecordingError(f"{path} is not a readable {kind} table (truncated or corrupt?): {first}") from None


def _check_signals(meta: RecordingMeta, signals: pa.Table) -> None:
    cols = signals.column_names
    if list(cols) != list(meta.channels):
        missing = sorted(set(meta.channels) - set(cols))
        extra = sorted(set(cols) - set(meta.channels))
        raise RecordingError(f"signals columns differ from meta.json channels (missing: {', '.join(missing) or '-'}; "
                             f"not in meta: {', '.join(extra) or '-'})")
    for name in cols:
        if name == PHASE:
            continue
        kind = signals.schema.field(name).type
        if not (pa.types.is_floating(kind) or pa.types.is_integer(kind)) or pa.types.is_boolean(kind):
            raise RecordingError(f"channel {name} holds {kind} values; the signals are numbers (SI units)")
        values = signals.column(name).to_numpy(zero_copy_only=False).astype(float)
        finite = np.isfinite(values)
        if not finite.all():
            row = int(np.flatnonzero(~finite)[0])
            raise RecordingError(f"channel {name} has {int((~finite).sum())} missing or non-finite values "
                                 f"(first at row {row}); `serpar import` fills isolated gaps on the grid")
        bound = plausible_max(name)
        if bound is not None and values.size and float(np.max(np.abs(values))) > bound[0]:
            row = int(np.argmax(np.abs(values)))
            raise RecordingError(f"channel {name} reaches {values[row]:g} at row {row}, beyond any plausible "
                                 f"value in {bound[1]} (|x| <= {bound[0]:g}): wrong units or a corrupt value")
    t = signals.column("time").to_numpy(zero_copy_only=False)
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        raise RecordingError("time must increase strictly")


class SignalRecorder:
    """Collects rows of named channels (one preallocated numeric block, growing by doubling);
    the 'phase' channel, if recorded, holds strings."""

    def __init__(self, channels: tuple[str, ...], capacity: int = 4096) -> None:
        check_channels(channels)
        self.channels = channels
        self.numeric = tuple(c for c in channels if c != "phase")
        """Order of the values :meth:`append_row` takes."""
        self._n = 0
        self._block = np.empty((max(capacity, 1), len(self.numeric)))
        self._has_phase = "phase" in channels
        self._phase: list[str] = []

    def append(self, values: dict[str, float | str]) -> None:
        """One sample: a value for every channel (a missing or unknown name is an error)."""
        if set(values) != set(self.channels):
            missing = sorted(set(self.channels) - set(values))
            extra = sorted(set(values) - set(self.channels))
            raise RecordingError(f"sample channels differ (missing: {', '.join(missing) or '-'}; "
                                 f"unknown: {', '.join(extra) or '-'})")
        row = np.array([float(values[c]) for c in self.numeric])  # type: ignore[arg-type]
        self.append_row(row, str(values["phase"]) if self._has_phase else None)

    def append_row(self, row: np.ndarray, phase: str | None = None) -> None:
        """One sample as the values of :attr:`numeric` in order (the 1 kHz path: no per-name work)."""
        if self._n == len(self._block):
            self._block = np.concatenate([self._block, np.empty_like(self._block)])
        self._block[self._n] = row
        if self._has_phase:
            self._phase.append("" if phase is None else phase)
        self._n += 1

    def __len__(self) -> int:
        return self._n

    def column(self, name: str) -> np.ndarray:
        """The samples of one numeric channel so far (a view)."""
        return self._block[:self._n, self.numeric.index(name)]

    def table(self) -> pa.Table:
        cols = {c: (pa.array(self._phase, pa.string()) if c == "phase" else pa.array(self.column(c)))
                for c in self.channels}
        return pa.table(cols)
