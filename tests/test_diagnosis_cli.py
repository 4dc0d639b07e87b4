"""serpar twin / diagnose / import-csv on the command line (the importers: test_import.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from arm_cal_support import published_copy

from serpar.cli.entry import main

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
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert result["top_effect"] == "thermal_drift"
    # progress on stderr also with --json: a line per stage with its elapsed time, then done
    stages = [line for line in captured.err.splitlines() if line.startswith("diagnose [")]
    assert stages[0].endswith("baseline") and stages[-1].endswith("done"), captured.err
    assert any(line.endswith("thermal_drift") for line in stages)
    text = report.read_text()  # where, held-out whitened, and the fit in mm: traces, residuals
    assert text.count("data:image/png;base64") == 4 and "Held-out fit in physical units" in text
    model = json.loads(Path(result["model_file"]).read_text())
    assert model["effects"] == ["thermal_drift"]


def test_diagnose_withholds_a_candidate(tmp_path, capsys) -> None:
    """--withhold takes a candidate out of the library (the blind bench's withheld trials); an
    unknown name is one line listing the recording's candidates."""
    out = tmp_path / "twin"
    assert main(["twin", "--effect", "thermal_drift", "--seed", "2", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(out), "--withhold", "gremlins"]) == 2
    err = capsys.readouterr().err
    assert "gremlins" in err and "thermal_drift" in err and err.count("\n") == 1
    assert main(["diagnose", str(out), "--json", "--withhold", "thermal_drift"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["top_effect"] != "thermal_drift"
    assert "thermal_drift" not in {c["effect"] for c in result["candidates"]}
    assert "candidates withheld (--withhold): thermal_drift" in result["notes"]


def test_a_diagnosis_stopped_by_ctrl_c_says_where_and_gives_no_verdict(tmp_path, capsys,
                                                                      monkeypatch) -> None:
    """Ctrl-C during the candidates: exit 130; the summary object lists the stages finished
    and the one it was in, and holds no verdict; stderr's last line says where it stopped."""
    out = tmp_path / "twin"
    assert main(["twin", "--effect", "thermal_drift", "--seed", "2", "--out", str(out)]) == 0
    capsys.readouterr()
    import serpar.cli.cmd_diagnose as cmd

    def stopped(family, seed, cfg, report):
        report("baseline")
        report("candidate thermal_drift")
        raise KeyboardInterrupt
    monkeypatch.setattr(cmd, "diagnose", stopped)
    assert main(["diagnose", str(out), "--json"]) == 130
    captured = capsys.readouterr()
    result = json.loads(captured.out)
    assert result["interrupted"] is True and "verdict" not in result
    assert result["finished"] == ["baseline"]
    assert result["interrupted_at"] == "candidate thermal_drift"
    last = captured.err.splitlines()[-1]
    assert last.startswith("diagnose [") and last.endswith("interrupted in: candidate thermal_drift")


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
    assert result["notes"] == []


@pytest.mark.skipif(not PANDA_1.is_dir(), reason="../shared/realdata/panda_1 not present")
def test_panda_1_as_published_with_two_placements(tmp_path, capsys) -> None:
    root, extras = published_copy(tmp_path, drop=("right",))
    assert main(["diagnose", str(root), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert sorted(n.split(":")[0] for n in result["notes"]) == sorted(f"ignored {e}"
                                                                      for e in extras)
    assert result["top_effect"] == "geometric"
    # one placement trains, the other is held out: 119 -> 19 sigma (with all three
    # placements 105 -> 6.9, the bound 0.1 above); the geometry still removes most of it
    assert result["heldout_rms_whitened_after"] < 0.2 * result["heldout_rms_whitened_before"]
    assert main(["diagnose", str(root)]) == 0
    text = capsys.readouterr().out
    assert all(f"note: ignored {e}: " in text for e in extras)


def _csv(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


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
