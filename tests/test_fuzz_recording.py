"""Property-based fuzzing of the recording reader: a damaged meta.json, a truncated or
overwritten signals table, or values no robot gives end in a recording or a one-line
RecordingError, never a traceback; an accepted recording's values are finite and plausible."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from serpar.sim.channels import plausible_max
from serpar.sim.recording import (
    Recording,
    RecordingError,
    RecordingMeta,
    read_recording,
    write_recording,
)

FUZZ = settings(max_examples=120, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
CHANNELS = ("time", "q1", "tau_J1", "leg1", "x_temperature")


def _good(n: int = 50) -> Recording:
    t = np.arange(n) * 1e-3
    cols = {"time": t, "q1": 0.1 * np.sin(t), "tau_J1": np.cos(t), "leg1": 0.27 + 0 * t,
            "x_temperature": 20 + t}
    meta = RecordingMeta("sim", 1000.0, CHANNELS, noise_sigma={"q1": 1e-4, "tau_J1": 0.05})
    return Recording(meta, pa.table(cols))


@pytest.fixture(scope="module")
def good_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_recording(tmp_path_factory.mktemp("rec") / "good", _good())


def _copy(good: Path, tmp: Path) -> Path:
    dst = tmp / "rec"
    if dst.exists():
        shutil.rmtree(dst)
    return Path(shutil.copytree(good, dst))


def _read_or_one_line(folder: Path) -> Recording | None:
    try:
        return read_recording(folder)
    except RecordingError as exc:
        assert str(exc) and "\n" not in str(exc), str(exc)
        return None


json_values = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(-5, 10**4),
                                     st.floats(allow_nan=False), st.text(max_size=10)),
                           lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                   st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                           max_leaves=8)


@FUZZ
@given(field=st.sampled_from(["source", "sample_rate_hz", "channels", "noise_sigma", "phases",
                              "schema_version", "units", "model", "extra"]), value=json_values)
def test_damaged_meta_json(good_folder: Path, tmp_path: Path, field: str, value: object) -> None:
    folder = _copy(good_folder, tmp_path)
    meta = json.loads((folder / "meta.json").read_text())
    meta[field] = value
    (folder / "meta.json").write_text(json.dumps(meta))
    rec = _read_or_one_line(folder)
    if rec is not None:
        assert rec.meta.sample_rate_hz > 0 and all(s >= 0 for s in rec.meta.noise_sigma.values())


@FUZZ
@given(data=st.binary(max_size=300), keep=st.floats(0, 1))
def test_truncated_or_overwritten_parquet(good_folder: Path, tmp_path: Path, data: bytes, keep: float) -> None:
    folder = _copy(good_folder, tmp_path)
    parquet = folder / "signals.parquet"
    raw = parquet.read_bytes()
    parquet.write_bytes(raw[:int(keep * len(raw))] + data)
    _read_or_one_line(folder)


@FUZZ
@given(column=st.sampled_from(CHANNELS[1:]), row=st.integers(0, 49),
       value=st.one_of(st.floats(), st.sampled_from([1e300, -1e300, 57.3, 1e4])))
def test_values_no_robot_gives(good_folder: Path, tmp_path: Path, column: str, row: int, value: float) -> None:
    folder = _copy(good_folder, tmp_path)
    table = pq.read_table(folder / "signals.parquet")
    values = table.column(column).to_numpy().copy()
    values[row] = value
    pq.write_table(table.set_column(table.column_names.index(column), column, pa.array(values)),
                   folder / "signals.parquet")
    rec = _read_or_one_line(folder)
    if rec is not None:
        got = rec.column(column)
        assert np.isfinite(got).all()
        bound = plausible_max(column)
        assert bound is None or np.abs(got).max() <= bound[0]


def test_named_cases(good_folder: Path, tmp_path: Path) -> None:
    folder = _copy(good_folder, tmp_path)
    parquet = folder / "signals.parquet"
    parquet.write_bytes(parquet.read_bytes()[:100])
    with pytest.raises(RecordingError, match="not a readable Parquet table"):
        read_recording(folder)
    folder = _copy(good_folder, tmp_path)
    meta = json.loads((folder / "meta.json").read_text())
    meta["sample_rate_hz"] = "1000"
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(RecordingError, match="sample_rate_hz must be a finite number, got '1000'"):
        read_recording(folder)
    folder = _copy(good_folder, tmp_path)
    table = pq.read_table(folder / "signals.parquet")
    tau = table.column("tau_J1").to_numpy().copy()
    tau[7] = 1e300
    pq.write_table(table.set_column(2, "tau_J1", pa.array(tau)), folder / "signals.parquet")
    with pytest.raises(RecordingError, match="tau_J1 reaches 1e.300 at row 7, beyond any plausible value in N m"):
        read_recording(folder)
