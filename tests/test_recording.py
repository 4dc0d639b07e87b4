"""The recording schema: what is written is read back equal, in both formats; anything off
the schema is a one-line RecordingError."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest

from serpar.sim.recording import (
    PhaseSegment,
    Recording,
    RecordingError,
    RecordingMeta,
    SignalRecorder,
    read_recording,
    write_recording,
)

CHANNELS = ("time", "phase", *(f"q{i}" for i in range(1, 8)), *(f"tau_J{i}" for i in range(1, 8)),
            "leg_cmd1", "leg1", "x_temperature")


def _recording(n: int = 500) -> Recording:
    rng = np.random.default_rng(0)
    rec = SignalRecorder(CHANNELS, capacity=64)  # grows past its first capacity
    for k in range(n):
        row: dict[str, float | str] = {c: float(rng.normal(scale=0.3)) for c in CHANNELS}
        row["time"] = k * 1e-3
        row["phase"] = "approach" if k < 200 else "insert"
        rec.append(row)
    meta = RecordingMeta(source="sim", sample_rate_hz=1000.0, channels=CHANNELS,
                         noise_sigma={"tau_J1": 0.02, "q1": 6e-6},
                         phases=(PhaseSegment("approach", 0.0, 0.1995), PhaseSegment("insert", 0.2, 0.499)),
                         model={"seed": 0})
    return Recording(meta, rec.table())


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_round_trip_is_equal(tmp_path, fmt):
    rec = _recording()
    back = read_recording(write_recording(tmp_path / "r", rec, fmt))
    assert back.meta == rec.meta
    for c in CHANNELS:
        a, b = rec.signals.column(c).to_numpy(zero_copy_only=False), back.column(c)
        if c == "phase":
            assert list(a) == list(b)
        else:
            np.testing.assert_array_equal(a, b)  # CSV writes shortest round-trip decimals
    assert back.phase("approach").num_rows == 200 and back.phase("insert").num_rows == 300


def test_off_schema_is_a_one_line_error(tmp_path):
    with pytest.raises(RecordingError, match=r"unknown channel\(s\) joint1; valid: time, phase, q1..16"):
        RecordingMeta(source="sim", sample_rate_hz=1e3, channels=("time", "joint1"))
    with pytest.raises(RecordingError, match="source 'robot'; valid: sim, real"):
        RecordingMeta(source="robot", sample_rate_hz=1e3, channels=("time",))
    with pytest.raises(RecordingError, match="noise_sigma names channels not recorded: q9"):
        RecordingMeta(source="real", sample_rate_hz=1e3, channels=("time", "q1"), noise_sigma={"q9": 1.0})
    rec = SignalRecorder(("time", "q1"))
    with pytest.raises(RecordingError, match="missing: q1"):
        rec.append({"time": 0.0})
    folder = write_recording(tmp_path / "r", _recording(10))
    meta = json.loads((folder / "meta.json").read_text())
    meta["schema_version"] = 99
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(RecordingError, match="schema version 99"):
        read_recording(folder)
    with pytest.raises(RecordingError, match="no meta.json"):
        read_recording(tmp_path)


def test_time_must_increase():
    meta = RecordingMeta(source="sim", sample_rate_hz=1e3, channels=("time", "q1"))
    table = pa.table({"time": [0.0, 0.002, 0.001], "q1": [0.0, 0.0, 0.0]})
    with pytest.raises(RecordingError, match="time must increase"):
        write_recording("/tmp/never_written", Recording(meta, table))
