"""Property-based fuzzing of the text importer (`serpar import`): any CSV/TSV/whitespace text
ends in a recording or a one-line RecordingError, never a traceback, and an accepted
recording holds only finite, plausible values on a strictly increasing time grid."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from serpar.sim.channels import plausible_max
from serpar.sim.importers.assemble import ImportOptions, to_recording
from serpar.sim.importers.files import read_files
from serpar.sim.recording import RecordingError

FUZZ = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

plain = st.floats(-3, 3).map(lambda v: f"{v:.6f}")
junk = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers(-10, 10).map(str),
                 st.sampled_from(["", "nan", "1e300", "-", "abc", "1,5", "0x10", "  ", '"1"']))
headers = st.lists(st.sampled_from(["time", "q1", "tau_J1", "dq2", "leg1", "bogus", "x_t"]),
                   min_size=1, max_size=4, unique=True) | st.lists(st.sampled_from(["time", "q1", "??"]),
                                                                  min_size=1, max_size=4)


@st.composite
def texts(draw: st.DrawFn) -> str:
    header = draw(headers)
    delimiter = draw(st.sampled_from([",", "\t", ";", " "]))
    n = draw(st.integers(0, 12))
    cells = st.one_of(plain, junk) if draw(st.booleans()) else plain  # half the files mostly valid
    rows = []
    for k in range(n):
        row = [f"{k * 1e-3:.4f}" if h == "time" and draw(st.booleans()) else draw(cells) for h in header]
        rows.append(delimiter.join(row))
    lines = ([delimiter.join(header)] if draw(st.booleans()) else []) + rows
    return "\n".join(lines) + draw(st.sampled_from(["", "\n", "\n\n", "\ngarbage"]))


def _import(path) -> None:
    try:
        rec, _ = to_recording(read_files([path]), None, ImportOptions(rate_hz=1000.0))
    except RecordingError as exc:
        assert str(exc) and "\n" not in str(exc), str(exc)
        return
    t = rec.column("time")
    assert np.all(np.diff(t) > 0)
    for name in rec.meta.channels:
        if name == "phase":
            continue
        v = rec.column(name)
        assert np.isfinite(v).all(), name
        bound = plausible_max(name)
        assert bound is None or np.abs(v).max(initial=0) <= bound[0], name


@FUZZ
@given(text=texts(), suffix=st.sampled_from([".csv", ".tsv", ".txt"]))
def test_any_text_imports_or_fails_in_one_line(tmp_path, text: str, suffix: str) -> None:
    path = tmp_path / f"log{suffix}"
    path.write_text(text)
    _import(path)


@FUZZ
@given(data=st.binary(max_size=200))
def test_any_bytes_import_or_fail_in_one_line(tmp_path, data: bytes) -> None:
    path = tmp_path / "log.csv"
    path.write_bytes(data)
    _import(path)


def test_value_no_robot_gives_is_named(tmp_path) -> None:
    path = tmp_path / "log.csv"
    path.write_text("time,q1,tau_J1\n0,0.1,1\n0.001,0.1,1e300\n0.002,0.1,1\n")
    with pytest.raises(RecordingError, match=r"tau_J1 reaches 1e\+300, beyond any plausible value in N m"):
        to_recording(read_files([path]), None, ImportOptions(rate_hz=1000.0))
