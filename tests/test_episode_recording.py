"""Episode recordings (``serpar run --record``, ``serpar replay``): a short stretch of the cell
recorded through the same observer and camera hook the episode uses, with a state restore in
it; the folder reads back equal, in the schema, and its rerun file opens in the rerun SDK."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from serpar.checks.vision_scenes import seat_conductor
from serpar.sim.recording import check_channels, read_recording
from serpar.sim.seat_lock import lock_seated
from serpar.tasks.episode import _Snapshot, build_runtime
from serpar.tasks.episode_config import EpisodeConfig
from serpar.tasks.episode_recorder import CHANNELS, RRD_NAME, EpisodeRecorder
from serpar.vision.imaging import Camera, ImagingConfig

STEP = 2 * np.pi / 2**20
"""Encoder resolution of the default arm sensors [rad]."""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """0.1 s settling with conductor 0 in hole 0, which is then locked into the plate (a
    recompile: new model and data) and the platform nudged up 20 um; a top shot; 0.05 s of
    moving, a snapshot restore, 0.05 s more."""
    cfg = EpisodeConfig(stewart_calibration="none")
    rt, plate = build_runtime(cfg)
    seat_conductor(rt.scene, 0, 0)
    truth: dict[float, np.ndarray] = {rt.time: rt.scene.data.qpos[rt.scene.arm_qpos_adr].copy()}
    recorder = EpisodeRecorder(rt, tmp_path_factory.mktemp("rec") / "episode_0",
                               {"episode_config": dataclasses.asdict(cfg)})
    rt.observers += [recorder,
                     lambda r: truth.setdefault(r.time, r.scene.data.qpos[r.scene.arm_qpos_adr].copy())]
    camera = Camera(rt.scene.model, ImagingConfig.ideal(1024))
    camera.on_frames = recorder.frames
    rt.scene.on_recompile += [recorder.rebind, lambda scene: camera.rebind(scene.model)]
    rt.phase = "settle"
    rt.run(0.1)
    lock_seated(rt.scene, 0)
    legs = list(rt.stewart.actuator_ids)
    rt.stewart.command_strokes(rt.scene.data, rt.scene.data.ctrl[legs] + 2e-5)
    camera.shoot(rt.scene.data, ("top_left", "top_right"))
    snap, t_restore = _Snapshot(rt, plate), rt.time
    rt.phase = "move"
    rt.run(0.05)
    snap.restore(rt, plate)  # how the episode goes on after a broken cycle
    rt.run(0.05)
    camera.close()
    rt.observers.remove(recorder)
    rec = recorder.recording()
    return rec, recorder.close(), truth, t_restore


def test_recording_reads_back_equal(recorded):
    rec, folder, _, _ = recorded
    back = read_recording(folder)
    assert back.meta == rec.meta
    assert back.signals.column_names == list(CHANNELS)
    for c in CHANNELS:
        if c == "phase":
            assert back.signals.column(c).to_pylist() == rec.signals.column(c).to_pylist()
        else:
            np.testing.assert_array_equal(back.column(c), rec.signals.column(c).to_numpy())
    assert [p.name for p in back.meta.phases] == ["settle", "move"]
    n = back.signals.num_rows
    assert back.phase("settle").num_rows + back.phase("move").num_rows == n == 199  # one stale period skipped


def test_channels_and_meta_follow_the_schema(recorded):
    rec, _, _, _ = recorded
    check_channels(rec.meta.channels)
    for group in ("q", "dq", "tau_J", "tau_J_d"):
        assert all(f"{group}{i}" in CHANNELS for i in range(1, 8))
    assert {"O_F_ext_hat_K6", "leg_cmd6", "leg6", "O_T_EE_qz", "platform_qz", "gripper_width"} <= set(CHANNELS)
    assert rec.meta.source == "sim" and rec.meta.sample_rate_hz == pytest.approx(1000.0)
    assert rec.meta.noise_sigma["q1"] == pytest.approx(STEP / np.sqrt(12))
    assert rec.meta.noise_sigma["tau_J1"] == 0.02 and rec.meta.noise_sigma["dq1"] == 1e-3
    assert rec.meta.model["episode_config"]["seed"] == 0 and "channel_notes" in rec.meta.model


def test_measured_joints_match_the_plant_within_an_encoder_count(recorded):
    rec, _, truth, t_restore = recorded
    sim_t, t = rec.column("x_sim_time"), rec.column("time")
    before = sim_t < t_restore
    q = np.column_stack([rec.column(f"q{i}") for i in range(1, 8)])
    expected = np.array([truth[s] for s in sim_t[before]])
    assert np.max(np.abs(q[before] - expected)) <= STEP / 2 + 1e-12
    assert np.all(np.diff(t) > 0) and np.any(np.diff(sim_t) < 0)  # time goes on across the restore
    # the plant channels: legs hold their commands (same quantity, metres), unit quaternions
    legs = np.column_stack([rec.column(f"leg{i}") - rec.column(f"leg_cmd{i}") for i in range(1, 7)])
    assert np.max(np.abs(legs)) < 1e-4 and np.all(np.abs(rec.column("leg1") - 0.27) < 0.01)
    for quat in ("O_T_EE_q", "platform_q"):
        norm = np.linalg.norm(np.column_stack([rec.column(quat + a) for a in "wxyz"]), axis=1)
        np.testing.assert_allclose(norm, 1.0, atol=1e-9)


def test_rrd_opens_in_the_rerun_sdk(recorded):
    from rerun.chunk import RrdReader

    rec, folder, _, _ = recorded
    path = folder / RRD_NAME
    assert path.is_file() and path.stat().st_size > 10_000
    rows: dict[str, int] = {}
    for chunk in RrdReader(path).store().stream():
        if not chunk.is_static:
            rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    n = rec.signals.num_rows
    assert rows["/signals/q"] == rows["/signals/leg"] == rows["/signals/O_F_ext_hat_K"] == n
    assert rows["/cell/cameras/top_left"] >= 1 and rows["/cell/cameras/top_right"] >= 1
    assert rows["/phase"] == 2  # one annotation per phase change
    assert rows["/cell/arm/link7"] >= 9  # 50 Hz body poses over 0.2 s
    # The part locked into the plate mid-recording is followed under its new body id: it moves
    # when, and only when, the plate does.
    assert rows["/cell/conductor0/conductor"] == rows["/cell/plate/baseplate"] > 1
    paths = set(RrdReader(path).store().schema().entity_paths())
    assert "/cell/arm/link0" in paths  # a static body, posed once
    assert any(p.startswith("/cell/plate/baseplate/geoms/") for p in paths)  # the static scene


def test_replay_errors_are_one_line(tmp_path, capsys, monkeypatch):
    from serpar.cli.entry import main

    assert main(["replay", str(tmp_path / "missing.rrd")]) == 2
    assert capsys.readouterr().err.strip().endswith("missing.rrd: no such file")
    (tmp_path / "notes.txt").write_text("x")
    assert main(["replay", str(tmp_path / "notes.txt")]) == 2
    assert "not a rerun recording (.rrd)" in capsys.readouterr().err
    (tmp_path / "e.rrd").write_bytes(b"x")
    monkeypatch.setattr("sys.platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["replay", str(tmp_path / "e.rrd")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "serpar replay --web" in err


def test_run_passes_the_record_folder_through(tmp_path, monkeypatch):
    import serpar.tasks.run_episodes as runner
    from serpar.cli.entry import main

    seen = []

    def fake(cfg, on_hole=None, label=None, record_dir=None):
        if record_dir is not None:
            seen.append(runner.recording_folder(record_dir, cfg.seed, label))
        return [{"kind": "episode", "seed": cfg.seed}]

    monkeypatch.setattr(runner, "run_one", fake)
    plain = runner.run_many([EpisodeConfig(seed=s) for s in (3, 4)])
    recorded = runner.run_many([EpisodeConfig(seed=s) for s in (3, 4)], record_dir=str(tmp_path))
    assert plain == recorded
    assert seen == [tmp_path / "episode_3", tmp_path / "episode_4"]
    (tmp_path / "file").write_text("x")
    assert main(["run", "--record", str(tmp_path / "file" / "sub")]) == 2  # before any episode runs


def test_run_episode_writes_its_recording_even_when_it_fails(tmp_path, monkeypatch):
    """The wiring in run_episode: the recorder sees the settle, and a failing episode still
    leaves its recording (here the platform registration is made to fail)."""
    from types import SimpleNamespace

    from serpar.errors import SerparError
    from serpar.tasks.episode import run_episode
    from serpar.tasks.episode_steps import HoleCycle

    def fail(self):
        self._enter("register")
        raise SerparError("injected")

    monkeypatch.setattr(HoleCycle, "register_platform", fail)
    pair = SimpleNamespace(scaled=lambda size: pair)
    with pytest.raises(SerparError, match="injected"):
        run_episode(EpisodeConfig(camera_width=1024, stewart_calibration="none"), {"top": pair, "inspect": pair},
                    recording=tmp_path / "ep")
    back = read_recording(tmp_path / "ep")
    assert back.signals.num_rows == 300 and [p.name for p in back.meta.phases] == ["start"]
    assert back.meta.model["episode_config"]["camera_width"] == 1024
    assert (tmp_path / "ep" / RRD_NAME).stat().st_size > 10_000
