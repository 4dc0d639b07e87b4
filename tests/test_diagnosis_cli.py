"""serpar twin / diagnose / import-csv on the command line, and the CSV importer's bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from serpar.cli.entry import main
from serpar.sim.csv_import import import_csv, parse_map
from serpar.sim.recording import RecordingError

PANDA_1 = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "panda_1"


def test_twin_then_diagnose_with_report(tmp_path, capsys) -> None:
    out = tmp_path / "twin"
    assert main(["twin", "--effect", "thermal_drift", "--seed", "2", "--out", str(out)]) == 0
    answer = json.loads((out / "answer.json").read_text())
    assert answer["effect"] == "thermal_drift"
    assert "thermal" not in (out / "meta.json").read_text()  # the truth stays out
    capsys.readouterr()
    report = tmp_path / "r.html"
    assert main(["diagnose", str(out), "--json", "--report", str(report)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["top_effect"] == "thermal_drift"
    assert report.read_text().count("data:image/png;base64") == 2
    model = json.loads(Path(result["model_file"]).read_text())
    assert model["effects"] == ["thermal_drift"]


def test_twin_bad_effect_lists_choices(tmp_path, capsys) -> None:
    assert main(["twin", "--effect", "gremlins", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "gremlins" in err and "joint_compliance" in err and err.count("\n") == 1


def test_diagnose_a_folder_without_recording(tmp_path, capsys) -> None:
    assert main(["diagnose", str(tmp_path)]) == 2
    assert "not a recording" in capsys.readouterr().err


@pytest.mark.skipif(not PANDA_1.is_dir(), reason="../shared/realdata/panda_1 not present")
def test_panda_1_real_data(capsys) -> None:
    assert main(["diagnose", str(PANDA_1), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["top_effect"] == "geometric"
    assert result["heldout_rms_whitened_after"] < 0.1 * result["heldout_rms_whitened_before"]


def _csv(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _text(edit: dict[int, str] | None = None, n: int = 200) -> str:
    """Header t,j1,torque and n rows at 1 kHz; ``edit`` replaces whole data rows."""
    rows = [f"{0.001 * i:.3f},{0.001 * i:.3f},0.5" for i in range(n)]
    for i, row in (edit or {}).items():
        rows[i] = row
    return "t,j1,torque\n" + "\n".join(rows) + "\n"


def test_csv_import_good_and_isolated_bad_sample_counted(tmp_path) -> None:
    text = _text({10: "0.010,nan,0.5"})
    rec, rep = import_csv(_csv(tmp_path / "a.csv", text), parse_map("t=time,j1=q1,torque=tau_J1"),
                          sigma={"q1": 1e-5})
    assert rep.rows == 199 and rep.excluded == ((12, "q1 (j1) is nan"),)
    assert rec.meta.model["import"]["excluded_count"] == 1
    assert abs(rec.meta.sample_rate_hz - 1000) < 1e-6


@pytest.mark.parametrize("text, mapping, match", [
    (_text(), "t=time,nope=q1", "not in"),
    (_text(), "t=time,j1=q9", "unknown channel"),
    (_text(), "j1=q1", "time"),
    (_text({2: "0.002,0.002,0.5,7"}), "t=time,j1=q1", "mismatched lengths"),
    (_text({2: "0.0005,0.002,0.5"}), "t=time,j1=q1", "does not increase"),
    (_text({2: "0.002,,0.5", 3: "0.003,,0.5"}), "t=time,j1=q1", "consecutive"),
    (_text({k: f"{0.001 * k:.3f},,0.5" for k in range(5, 200, 10)}), "t=time,j1=q1",
     "more than 1 %"),
    (_text({2: "0.002,abc,0.5"}), "t=time,j1=q1", "not a number"),
    (_text({7: "0.007,90.0,0.5"}), "t=time,j1=q1", "SI units"),
    (_text(), "t=time,j1", "csv_column=channel"),
])
def test_csv_import_bad_input_is_one_line(tmp_path, text, mapping, match) -> None:
    with pytest.raises(RecordingError, match=match) as info:
        import_csv(_csv(tmp_path / "b.csv", text), parse_map(mapping))
    assert "\n" not in str(info.value)


def test_csv_measurements_to_diagnosis(tmp_path, capsys) -> None:
    from serpar.twins.arm_static_twin import make_twin

    rec, _ = make_twin(None, None, 4)
    m = rec.measurements
    cols = ["q1", "q2", "q3", "q4", "q5", "q6", "q7", "x", "y", "z", "kind"]
    lines = [",".join(f"c_{c}" for c in cols)]
    arr = {c: m.column(c).to_pylist() for c in cols}
    lines += [",".join(str(arr[c][i]) for c in cols) for i in range(m.num_rows)]
    csv = _csv(tmp_path / "m.csv", "\n".join(lines) + "\n")
    out = tmp_path / "rec"
    meta = json.dumps({"measurements": {"tool_offset_m": [0.0, 0.06, 0.12],
                                        "tool_mass_kg": 0.3, "hand": True}})
    assert main(["import-csv", str(csv), "--table", "measurements", "--map",
                 ",".join(f"c_{c}={c}" for c in cols), "--sigma", "sigma_m=15e-6",
                 "--model", meta, "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(out), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["verdict"] == "no missing physics found beyond noise"
    assert np.isfinite(result["heldout_rms_whitened_after"])
