"""`serpar import`: data as published (sim/importers/) into the recording schema. Small files
made here for every reader: CSV with isolated bad samples, whitespace and one value per line,
joints in separate files, MATLAB .mat, a ROS 2 bag written with rosbags; jittered stamps with
missed ticks put on the grid with the repairs counted; bad input one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_typestore

from serpar.cli.entry import main
from serpar.sim.importers.assemble import ImportOptions, parse_map, to_recording
from serpar.sim.importers.files import read_files
from serpar.sim.recording import RecordingError, read_recording

RATE = 1000.0


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _text(edit: dict[int, str] | None = None, n: int = 200) -> str:
    """Header t,j1,torque and n rows at 1 kHz; ``edit`` replaces whole data rows."""
    rows = [f"{0.001 * i:.3f},{0.001 * i:.3f},0.5" for i in range(n)]
    for i, row in (edit or {}).items():
        rows[i] = row
    return "t,j1,torque\n" + "\n".join(rows) + "\n"


def _import(files, mapping: str | None, **options):
    return to_recording(read_files([str(f) for f in files]),
                        parse_map(mapping) if mapping else None, ImportOptions(**options))


def _column(rec, name: str) -> np.ndarray:
    return np.asarray(rec.signals.column(name).to_numpy(), float)


def test_csv_isolated_bad_sample_is_counted_and_its_tick_filled(tmp_path) -> None:
    path = _write(tmp_path / "a.csv", _text({10: "0.010,nan,0.5"}))
    rec, rep = _import([path], "t=time,j1=q1,torque=tau_J1")
    assert rep.rows == 199 and rep.excluded == ((f"{path} line 12", "q1 (j1) is nan"),)
    assert rec.meta.model["import"]["excluded_count"] == 1
    assert rep.grid is not None and rep.grid.filled_ticks == 1 and rep.grid.dropped_samples == 0
    assert rec.signals.num_rows == 200 and abs(rec.meta.sample_rate_hz - RATE) < 1e-6
    assert _column(rec, "q1")[10] == pytest.approx(0.010, abs=1e-12)  # interpolated


@pytest.mark.parametrize("text, mapping, match", [
    (_text(), "t=time,nope=q1", "not in"),
    (_text(), "t=time,j1=q17", "unknown channel"),
    (_text(), "j1=q1", "mapped to time"),
    (_text({2: "0.002,0.002,0.5,7"}), "t=time,j1=q1", "line 4: 4 fields, expected 3"),
    (_text({2: "0.0005,0.002,0.5"}), "t=time,j1=q1", "does not increase"),
    (_text({2: "0.002,,0.5", 3: "0.003,,0.5"}), "t=time,j1=q1", "bad samples in a row"),
    (_text({k: f"{0.001 * k:.3f},,0.5" for k in range(5, 200, 10)}), "t=time,j1=q1",
     "more than 1 %"),
    (_text({2: "0.002,abc,0.5"}), "t=time,j1=q1", "line 4, column 'j1': 'abc' is not a number"),
    (_text({7: "0.007,90.0,0.5"}), "t=time,j1=q1", "SI units"),
    (_text(), "t=time,j1", "source_column=channel"),
])
def test_bad_text_input_is_one_line(tmp_path, text, mapping, match) -> None:
    with pytest.raises(RecordingError, match=match) as info:
        _import([_write(tmp_path / "b.csv", text)], mapping)
    assert "\n" not in str(info.value)


def _jittered(n: int = 3000, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 1 kHz log: stamps jittered by up to 0.4 ms, ~8 % of the ticks missed (runs of up to
    3), the signal a smooth function of the true tick time."""
    rng = np.random.default_rng(seed)
    ticks = np.arange(n)
    missed = rng.random(n) < 0.05
    for start in np.flatnonzero(rng.random(n) < 0.01):  # a few runs of 2-3
        missed[start:start + rng.integers(2, 4)] = True
    missed[[0, -1]] = False
    kept = ticks[~missed]
    stamps = 12.5 + kept / RATE + rng.uniform(-0.4e-3, 0.4e-3, kept.size)
    return kept, stamps, np.sin(2 * np.pi * 0.7 * kept / RATE)


def test_jittered_stamps_and_missed_ticks_go_on_the_grid_counted(tmp_path) -> None:
    kept, stamps, q = _jittered()
    text = "time q1\n" + "\n".join(f"{t:.6f} {v:.9f}" for t, v in zip(stamps, q, strict=True))
    rec, rep = _import([_write(tmp_path / "log.txt", text + "\n")], None)  # whitespace, no map
    g = rep.grid
    assert g is not None
    n_ticks = int(kept[-1]) + 1
    assert (g.ticks, g.filled_ticks, g.dropped_samples) == (n_ticks, n_ticks - kept.size, 0)
    assert g.filled_ticks / g.ticks > 0.06 and g.longest_gap_ticks >= 2
    assert g.rate_hz == pytest.approx(RATE, rel=1e-5) and 0.35e-3 < g.max_stamp_offset_s < 0.45e-3
    t = _column(rec, "time")
    assert np.ptp(np.diff(t)) < 1e-9 and rec.signals.num_rows == n_ticks
    truth = np.sin(2 * np.pi * 0.7 * np.arange(n_ticks) / RATE)
    assert np.max(np.abs(_column(rec, "q1") - truth)) < 1e-4  # filled ticks interpolated
    assert rec.meta.model["import"]["grid"]["filled_ticks"] == g.filled_ticks


def test_a_long_gap_is_lost_data_not_jitter(tmp_path) -> None:
    t = np.r_[np.arange(100), np.arange(200, 300)] / RATE
    text = "time,q1\n" + "\n".join(f"{v:.4f},0.1" for v in t)
    with pytest.raises(RecordingError, match="100 ticks .* missing after t = 0.099"):
        _import([_write(tmp_path / "gap.csv", text)], None)


def test_one_value_per_line_in_separate_files_with_a_rate(tmp_path) -> None:
    q = np.random.default_rng(1).uniform(-1, 1, (500, 7))
    files = [_write(tmp_path / f"q{j + 1}.txt", "\n".join(f"{v:.9f}" for v in q[:, j]))
             for j in range(7)]
    rec, rep = _import(files, ",".join(f"q{j}=q{j}" for j in range(1, 8)), rate_hz=RATE)
    assert rec.meta.channels == ("time", *(f"q{j}" for j in range(1, 8)))
    assert rep.grid is None and rec.meta.sample_rate_hz == RATE
    np.testing.assert_allclose(_column(rec, "q7"), q[:, 6], atol=1e-9)
    with pytest.raises(RecordingError, match="different numbers of rows"):
        _import([files[0], _write(tmp_path / "short.txt", "0.1\n0.2\n")], None, rate_hz=RATE)
    with pytest.raises(RecordingError, match="--rate HZ"):
        _import(files, "q1=q1")


def test_mat_file_matrices_map_onto_channel_families(tmp_path) -> None:
    n = 400
    rng = np.random.default_rng(2)
    q, tau = rng.uniform(-1, 1, (n, 7)), rng.uniform(-5, 5, (7, n))  # tau stored joints x time
    path = tmp_path / "log.mat"
    scipy.io.savemat(path, {"t": np.arange(n) / RATE, "q": q, "tau": tau, "fs": 1000.0,
                            "robot": "panda"})
    rec, rep = _import([path], "t=time,q=q,tau=tau_J")
    np.testing.assert_allclose(_column(rec, "q3"), q[:, 2])
    np.testing.assert_allclose(_column(rec, "tau_J7"), tau[6])
    assert any("'fs'" in n for n in rep.notes) and any("'robot'" in n for n in rep.notes)
    bad = tmp_path / "bad.mat"
    bad.write_bytes(b"MATLAB 5.0 MAT-file, garbage" + bytes(200))
    with pytest.raises(RecordingError, match="not a readable .mat file"):
        _import([bad], None)


def _bag(path: Path, n: int = 300, topic: str = "/franka/joint_states") -> np.ndarray:
    """A ROS 2 bag of JointState at 1 kHz whose joints arrive in a shuffled order."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    JointState, Header = store.types["sensor_msgs/msg/JointState"], store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    q = np.random.default_rng(3).uniform(-1, 1, (n, 7))
    names = [f"panda_joint{j}" for j in range(1, 8)]
    with Writer(path, version=9) as writer:
        conn = writer.add_connection(topic, JointState.__msgtype__, typestore=store)
        writer.add_connection("/rosout_like", "std_msgs/msg/String", typestore=store)
        for i in range(n):
            order = np.roll(np.arange(7), i % 7)
            ns = 5_000_000 + 1_000_000 * i
            msg = JointState(Header(Time(1700 + ns // 10**9, ns % 10**9), "base"),
                             [names[k] for k in order], q[i, order], 0.1 * q[i, order],
                             2.0 * q[i, order])
            writer.write(conn, 1_700_000_000_000_000_000 + ns, store.serialize_cdr(msg, conn.msgtype))
    return q


def test_ros2_bag_joint_states_import_with_the_default_map(tmp_path, capsys) -> None:
    q = _bag(tmp_path / "bag")
    out = tmp_path / "rec"
    assert main(["import", str(tmp_path / "bag"), "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["sample_rate_hz"] == pytest.approx(RATE)
    rec = read_recording(out)
    assert {"q1", "dq7", "tau_J4"} <= set(rec.meta.channels)
    np.testing.assert_allclose(_column(rec, "q5"), q[:, 4], atol=1e-12)
    np.testing.assert_allclose(_column(rec, "tau_J2"), 2.0 * q[:, 1], atol=1e-12)
    assert _column(rec, "time")[0] == 0.0
    assert any("panda_joint1, panda_joint2" in n for n in summary["notes"])
    assert main(["import", str(tmp_path / "bag"), "--topic", "/nope", "--out", str(out), "--force"]) == 2
    assert "no sensor_msgs/msg/JointState topic '/nope'" in capsys.readouterr().err


def test_import_csv_keeps_its_old_name(tmp_path, capsys) -> None:
    path = _write(tmp_path / "a.csv", _text())
    assert main(["import-csv", str(path), "--map", "t=time,j1=q1", "--out",
                 str(tmp_path / "r"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rows_kept"] == 200 and summary["grid"] is None
    assert any("torque" in n for n in summary["notes"])  # the unmapped column is named
