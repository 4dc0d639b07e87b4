"""The held-out fit in physical units (diagnosis/units.py): per channel RMS before and after in
N m / mm / mrad, consistent with the whitened residual, in the JSON and the HTML report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from serpar.cli.entry import main
from serpar.diagnosis.choose import family_from_recording
from serpar.diagnosis.select import diagnose
from serpar.twins.registry import make_twin


def _diagnosed(domain: str, effect: str, seed: int):  # type: ignore[no-untyped-def]
    rec, answer = make_twin(effect, None, seed, domain=domain)
    return diagnose(family_from_recording(rec), seed=0), answer


def test_payload_fit_in_newton_metres() -> None:
    d, _ = _diagnosed("arm_dynamics", "payload", 1)
    p = d.physical
    assert p is not None and {r.unit for r in p.rms} == {"N m"} and len(p.rms) == 14
    # the payload's weight is visible: joint 2's command misses by N m before, by mN after
    by = {r.channel: r for r in p.rms}
    assert by["tau_J_d2"].before > 1.0 and all(r.after < 0.02 for r in p.rms)
    # consistent with the whitened figure: physical / sigma is the whitened residual
    np.testing.assert_allclose(p.after / p.view.scale, d.heldout_after, rtol=1e-12)
    assert p.view.measured is not None and np.all(np.isfinite(p.view.measured))


def test_point_consistency_fit_in_millimetres() -> None:
    d, _ = _diagnosed("arm_static", "joint_compliance", 0)
    p = d.physical
    assert p is not None and [r.channel for r in p.rms][:3] == ["x", "y", "z"]
    assert {r.unit for r in p.rms} == {"mm"}
    assert max(r.after for r in p.rms) < max(r.before for r in p.rms)


def test_stewart_fit_in_millimetres_and_milliradians() -> None:
    d, _ = _diagnosed("stewart", "leg_encoder_offset", 1)
    p = d.physical
    assert p is not None
    units = {r.channel: r.unit for r in p.rms}
    assert units == {"x": "mm", "y": "mm", "z": "mm", "rx": "mrad", "ry": "mrad", "rz": "mrad"}
    assert all(r.after < r.before for r in p.rms)


@pytest.mark.slow
def test_json_and_report_carry_the_physical_units(tmp_path, capsys) -> None:
    out = tmp_path / "twin"
    assert main(["twin", "--domain", "arm_dynamics", "--effect", "latency", "--seed", "0",
                 "--out", str(out)]) == 0
    capsys.readouterr()
    report = tmp_path / "r.html"
    assert main(["diagnose", str(out), "--json", "--report", str(report)]) == 0
    result = json.loads(capsys.readouterr().out)
    rms = result["heldout_rms_physical"]
    assert [r["channel"] for r in rms][:2] == ["tau_J1", "tau_J2"] and rms[0]["unit"] == "N m"
    # a latency is in the command: it fits every command channel better, the sensors' the same
    assert all(r["rms_after"] < r["rms_before"] for r in rms if r["channel"].startswith("tau_J_d"))
    assert all(r["rms_after"] == pytest.approx(r["rms_before"], rel=0.05) for r in rms
               if not r["channel"].startswith("tau_J_d"))
    text = report.read_text()
    assert "Held-out fit in physical units" in text and "tau_J_d7" in text
    assert text.count("data:image/png;base64") == 4
