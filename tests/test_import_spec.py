"""`serpar import --spec F.yaml` (sim/importers/spec.py, jointmap.py, resample.py): a coupled
wrist's motor side mapped to the joint side exactly and with power conserved, anti-aliased
decimation, noise sigma from a rest segment, .npz input, one-line errors through the CLI, and
the Staubli TX40 data as published (../shared/realdata/staubli_tx40)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from serpar.cli.entry import main
from serpar.errors import SerparError
from serpar.sim.importers.assemble import ImportOptions, to_recording
from serpar.sim.importers.files import read_files
from serpar.sim.importers.spec import load_spec
from serpar.sim.recording import RecordingError, read_recording

DOCS = Path(__file__).resolve().parents[1] / "docs" / "examples"
TX40 = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "staubli_tx40"
N = np.array([32.0, 32.0, 45.0, -48.0, 45.0, 32.0])
OFFSETS = np.array([0.0, -np.pi / 2, np.pi / 2, 0.0, 0.0, 0.0])
HEADER = ",".join(f"Joint_{k}" for k in range(1, 7))


def _motor_matrix() -> np.ndarray:
    r = np.diag(N)
    r[5, 4] = N[5]  # the coupled wrist: motor 6 turns with joint 5
    return r


def _spec(tmp_path: Path, text: str, name: str = "spec.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _csv(path: Path, block: np.ndarray) -> Path:
    np.savetxt(path, block, delimiter=",", header=HEADER, comments="", fmt="%.17g")
    return path


MAP = "\n".join([*(f"  pos.Joint_{k}: q{k}" for k in range(1, 7)),
                 *(f"  cur.Joint_{k}: tau_drive{k}" for k in range(1, 7))])
JOINT_MAP = f"""joint_map:
  motor_matrix: {_motor_matrix().tolist()}
  offsets: {OFFSETS.tolist()}
  from: [q, tau_drive]
"""


def _wrist_files(tmp_path: Path, n: int = 2000, rate: float = 1000.0
                 ) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    """Known joint angles (q1 up to 2.2 rad: 70 rad on its motor) and torques, written as the
    motor side sees them."""
    t = np.arange(n) / rate
    k = np.arange(1, 7)
    q = 0.3 * np.sin(2 * np.pi * 0.4 * k[:, None] * t + k[:, None]) + OFFSETS[:, None]
    q[0] = 2.2 * np.sin(2 * np.pi * 0.5 * t + 1.0)
    tau = 5.0 * np.cos(2 * np.pi * 0.3 * k[:, None] * t)
    r = _motor_matrix()
    theta = r @ (q - OFFSETS[:, None])
    tau_m = np.linalg.solve(r.T, tau)  # tau = R^T tau_m
    return (_csv(tmp_path / "pos.csv", theta.T), _csv(tmp_path / "cur.csv", tau_m.T), q, tau)


def _run(files: list[Path], spec: Path, **options):
    return to_recording(read_files([str(f) for f in files]), dict(load_spec(spec).map),
                        ImportOptions(**options), spec=load_spec(spec))


def test_coupled_wrist_joint_map_recovers_angles_and_torques_and_conserves_power(tmp_path) -> None:
    pos, cur, q, tau = _wrist_files(tmp_path)
    theta = np.loadtxt(pos, delimiter=",", skiprows=1)
    assert np.abs(theta[:, 0]).max() > 70  # motor-side: far beyond any joint angle
    spec = _spec(tmp_path, f"map:\n{MAP}\nsource_rate: 1000\n{JOINT_MAP}")
    rec, rep = _run([pos, cur], spec)
    got_q = np.stack([rec.column(f"q{k}") for k in range(1, 7)])
    got_tau = np.stack([rec.column(f"tau_drive{k}") for k in range(1, 7)])
    np.testing.assert_allclose(got_q, q, atol=1e-13)
    np.testing.assert_allclose(got_tau, tau, atol=1e-12)
    tau_m = np.loadtxt(cur, delimiter=",", skiprows=1).T
    motor_power = np.sum(tau_m * np.gradient(theta.T, axis=1), axis=0)
    joint_power = np.sum(got_tau * np.gradient(got_q, axis=1), axis=0)
    np.testing.assert_allclose(joint_power, motor_power, rtol=1e-10, atol=1e-12)
    imp = rec.meta.model["import"]
    assert imp["spec"]["joint_map"]["power_error"] < 1e-12
    assert any("tau_drive1..tau_drive6 = T tau_m, T = inv(A).T" in c for c in rep.conversions)
    # without the joint map the motor-side 70 rad is refused, as any value no joint gives
    plain = _spec(tmp_path, f"map:\n{MAP}\nsource_rate: 1000\n", "plain.yaml")
    with pytest.raises(RecordingError, match="channel q1 reaches .* SI units"):
        _run([pos, cur], plain)


def test_decimation_keeps_a_sine_and_removes_a_tone_above_the_output_band(tmp_path) -> None:
    rate, n = 5000.0, 10000
    t = np.arange(n) / rate
    slow = 0.5 * np.sin(2 * np.pi * 3.0 * t + 0.2)
    tone = 0.1 * np.cos(2 * np.pi * 2000.0 * t + 0.3)  # plain subsampling: a 0.096 offset
    spec = _spec(tmp_path, "map: {q1: q1}\nsource_rate: 5000\nrate: 1000\n")
    for name, signal in (("sine", slow), ("both", slow + tone)):
        (tmp_path / "q1.txt").write_text("\n".join(f"{v:.17g}" for v in signal))
        rec, rep = _run([tmp_path / "q1.txt"], spec)
        t_out = rec.column("time")
        assert rec.signals.num_rows == 2000 and rec.meta.sample_rate_hz == 1000.0
        np.testing.assert_allclose(t_out, np.arange(2000) / 1000.0, atol=1e-12)
        error = np.abs(rec.column("q1") - 0.5 * np.sin(2 * np.pi * 3.0 * t_out + 0.2))
        if name == "sine":
            assert error.max() < 1e-5  # zero phase, edges included
        else:  # the tone is gone; only within the filter's half-length (20 samples) of an
            # edge does the tone's value on the edge sample leak in (resample.py)
            assert error[20:-20].max() < 1e-5 and error.max() < 0.1
    assert rec.meta.model["import"]["spec"]["decimation"]["factor"] == 5
    assert any(c.startswith("decimated 5000 Hz -> 1000 Hz (/5)") for c in rep.conversions)


def test_sigma_from_a_rest_segment_recovers_the_noise(tmp_path) -> None:
    rng = np.random.default_rng(4)
    t = np.arange(6000) / 1000.0
    q = np.where(t < 3.0, 0.4 * np.sin(np.pi * t / 3.0) ** 2, 0.0) + 0.3
    q_noisy = q + rng.normal(0, 2e-5, t.size)
    tau = 2.0 + 0.01 * t + rng.normal(0, 0.05, t.size)  # a slow drift: the line takes it
    path = tmp_path / "log.csv"
    np.savetxt(path, np.c_[t, q_noisy, tau], delimiter=",", header="t,j1,m1", comments="",
               fmt="%.17g")
    spec = _spec(tmp_path, "map: {t: time, j1: q1, m1: tau_drive1}\nsigma_from_rest: [3.5, 6.0]\n")
    rec, rep = _run([path], spec)
    assert rec.meta.noise_sigma["q1"] == pytest.approx(2e-5, rel=0.05)
    assert rec.meta.noise_sigma["tau_drive1"] == pytest.approx(0.05, rel=0.05)
    assert "sigma of q1, tau_drive1 from the rest segment 3.5-6 s" in " ".join(rep.conversions)
    given = to_recording(read_files([path]), {"time": "t", "q1": "j1", "tau_drive1": "m1"},
                         ImportOptions(), {"q1": 1e-3}, spec=load_spec(spec))[0]
    assert given.meta.noise_sigma["q1"] == 1e-3  # --sigma wins over the rest segment


def test_npz_arrays_and_matrices_are_source_columns(tmp_path) -> None:
    rng = np.random.default_rng(5)
    q, tau = rng.uniform(-1, 1, (300, 6)), rng.uniform(-5, 5, (6, 300))  # tau: joints x time
    path = tmp_path / "log.npz"
    np.savez(path, t=np.arange(300) / 500.0, q=q, tau=tau, gain=np.float64(3.0),
             label=np.array(["a", "b"], dtype=object))
    spec = _spec(tmp_path, "map: {t: time, q: q, tau: tau_J}\nscale: {tau: 0.5}\n")
    rec, rep = _run([path], spec)
    assert rec.meta.channels[:3] == ("time", "q1", "q2")
    assert rec.meta.sample_rate_hz == pytest.approx(500.0)
    np.testing.assert_allclose(rec.column("q6"), q[:, 5])
    np.testing.assert_allclose(rec.column("tau_J4"), 0.5 * tau[3])
    assert any("'gain'" in n for n in rep.notes) and any("'label'" in n for n in rep.notes)
    assert "scaled: tau_J1..tau_J6 x 0.5" in rep.conversions


SINGULAR = "map: {q1: q1, q2: q2}\nsource_rate: 100\njoint_map: {matrix: [[1, 2], [2, 4]]}\n"


@pytest.mark.parametrize("spec_text, needle", [
    (SINGULAR, "spec.yaml: joint_map.matrix is singular (condition number"),
    ("map: {q1: q1}\nsource_rate: 1000\nrate: 300\n",
     ("spec.yaml: rate: the source's 1000 Hz / 300 Hz = 3.33333 is not an integer; valid: "
     "1000/k for an integer k, the nearest 333.333 Hz (/3) and 250 Hz (/4)")),
    ("map: {q1: q1}\nsource_rate: 1000\nsample_rate: 10\n",
     ("spec.yaml: unknown key(s) sample_rate; valid: map, source_rate, scale, joint_map, rate, "
     "sigma_from_rest, robot")),
    ("map: {q1: q1}\nsource_rate: 1000\nsigma_from_rest: [0.5, 1.9]\n",
     "spec.yaml: sigma_from_rest [0.5, 1.9] s: joint q1 is not at rest there"),
    ("map: {q1: q1}\nsource_rate: 1000\njoint_map: {matrix: [[1]], frm: q}\n",
     "spec.yaml: joint_map: unknown key(s) frm; valid: matrix, motor_matrix, offsets"),
    ("map: {q1: q1\nsource_rate: 1000\n", "is not valid YAML at line 2, column"),
    ("map: {q1: q1}\nrate: fast\n", "spec.yaml: rate: expected a number, got 'fast'"),
])
def test_bad_spec_is_one_line_exit_2(tmp_path, capsys, spec_text, needle) -> None:
    t = np.arange(2000) / 1000.0
    (tmp_path / "q1.txt").write_text("\n".join(f"{v:.9f}" for v in 0.01 * t))  # moving
    spec = _spec(tmp_path, spec_text)
    argv = ["import", str(tmp_path / "q1.txt"), "--spec", str(spec), "--out",
            str(tmp_path / "out")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err, err


def test_a_flag_and_the_spec_may_not_both_set_one_thing(tmp_path, capsys) -> None:
    (tmp_path / "q1.txt").write_text("0.1\n0.2\n0.3\n")
    spec = _spec(tmp_path, "map: {q1: q1}\nsource_rate: 1000\n")
    base = ["import", str(tmp_path / "q1.txt"), "--spec", str(spec), "--out",
            str(tmp_path / "out")]
    assert main([*base, "--rate", "1000"]) == 2
    assert "--rate and the spec's source_rate both set it" in capsys.readouterr().err
    assert main([*base, "--map", "q1=q1"]) == 2
    assert "--map and the spec's map both set it" in capsys.readouterr().err
    assert main([*base, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["spec"]["source_rate_hz"] == 1000.0


values = st.one_of(st.none(), st.booleans(), st.integers(-3, 5000), st.floats(allow_nan=True),
                   st.text(max_size=8), st.lists(st.floats(-50, 50), max_size=3),
                   st.lists(st.lists(st.integers(-2, 2), min_size=0, max_size=3), max_size=3),
                   st.dictionaries(st.sampled_from(["q", "q1", "j1", "tau_drive", "x"]),
                                   st.one_of(st.text(max_size=6), st.floats()), max_size=3))
joint_maps = st.dictionaries(st.sampled_from(["matrix", "motor_matrix", "offsets",
                                              "torque_matrix", "from", "to", "bogus"]), values,
                             max_size=4)
specs = st.dictionaries(st.sampled_from(["map", "source_rate", "scale", "rate", "robot",
                                         "sigma_from_rest", "bogus"]), values, max_size=5)


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(spec=specs, joint_map=st.none() | joint_maps, raw=st.none() | st.text(max_size=40))
def test_any_spec_loads_or_fails_in_one_line(tmp_path, spec, joint_map, raw) -> None:
    text = raw if raw is not None else yaml.safe_dump(
        spec | ({"joint_map": joint_map} if joint_map is not None else {}))
    path = _spec(tmp_path, text)
    try:
        load_spec(path)
    except SerparError as exc:
        assert str(exc) and "\n" not in str(exc), str(exc)


def _urdf_limits(path: Path) -> list[tuple[float, float]]:
    joints = [j for j in ET.parse(path).getroot().iter("joint") if j.get("type") == "revolute"]
    return [(float(j.find("limit").get("lower")), float(j.find("limit").get("upper")))
            for j in joints]


@pytest.mark.skipif(not TX40.is_dir(), reason="../shared/realdata/staubli_tx40 not present")
def test_tx40_as_published_imports_with_the_documented_spec(tmp_path, capsys) -> None:
    out = tmp_path / "tx40"
    assert main(["import", str(TX40 / "pos_read_data.csv"), str(TX40 / "curr_data.csv"),
                 "--spec", str(DOCS / "tx40_import.yaml"), "--out", str(out)]) == 0
    rec = read_recording(out)
    assert rec.signals.num_rows == 9000 and rec.meta.sample_rate_hz == 1000.0
    assert rec.meta.channels == ("time", *(f"q{k}" for k in range(1, 7)),
                                 *(f"tau_drive{k}" for k in range(1, 7)))
    limits = _urdf_limits(TX40 / "urdf" / "tx40_mdh_modified.urdf")
    assert len(limits) == 6
    for k, (lo, hi) in enumerate(limits, start=1):
        q = rec.column(f"q{k}")
        assert lo <= q.min() and q.max() <= hi, (k, q.min(), q.max(), lo, hi)
    assert {"q1", "tau_drive1", "tau_drive6"} <= set(rec.meta.noise_sigma)
    assert rec.meta.model["import"]["spec"]["decimation"]["factor"] == 5
