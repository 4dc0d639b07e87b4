"""`serpar replay`: camera frames logged where rerun's viewer draws them, the layout sent with
the file, and the web server on this machine only, on free ports, refusing a broken file and
stopped with serpar. A short recording is built through the functions an episode records
with (real scene geometry, real rendered frames); the browser test opens it in headless
Chromium and finds each frame on the screen."""

from __future__ import annotations

import contextlib
import signal
import socket
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import psutil
import pytest
import rerun.blueprint as rrb
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rerun.chunk import RrdReader

from serpar.checks import browser_replay
from serpar.cli.entry import main
from serpar.errors import ConfigError
from serpar.sim.render import CameraRenderer
from serpar.sim.scene import build_scene
from serpar.tasks import replay_server as server
from serpar.tasks import rerun_scene

CAMERAS = ("top_left", "top_right")
"""The in-hand pair sees only its backlight without a conductor in hand: frames of one grey level."""


@pytest.fixture(scope="module")
def rrd(tmp_path_factory) -> Path:
    """0.1 s of the cell as the episode recorder writes it: the scene, poses, a shot of the top
    pair (rendered at 640x480), signals and a phase."""
    scene = build_scene()
    m, d = scene.model, scene.data
    mujoco.mj_forward(m, d)
    renderer = CameraRenderer(m)
    frames = {c: renderer.render(d, c, 640, 480) for c in CAMERAS}
    renderer.close()
    path = tmp_path_factory.mktemp("replay") / "episode.rrd"
    rec = rerun_scene.open_stream(path, "test")
    rerun_scene.log_geometry(rec, m)
    poses = rerun_scene.PoseTrack(rec, m, d)
    poses.sample(d, 0.0)
    rerun_scene.log_text(rec, "phase", "settle", 0.0)
    rerun_scene.log_frames(rec, m, d, frames, 0.05)
    t = np.arange(100) * 1e-3
    rerun_scene.send_signals(rec, t, {"q1": np.sin(t), "q2": np.cos(t), "leg1": t, "leg_cmd1": t})
    poses.sample(d, 0.1)
    poses.send(rec)
    rec.flush()
    rec.disconnect()
    return path


def free_ports() -> int:
    """P with P and P+1 free on 127.0.0.1."""
    for _ in range(50):
        with socket.socket() as s:
            s.bind((server.LOCAL, 0))
            port = s.getsockname()[1]
        if port < 65534:
            try:
                server.check_port_free(server.LOCAL, port, "viewer")
                server.check_port_free(server.LOCAL, port + 1, "data")
                return port
            except ConfigError:
                continue
    raise RuntimeError("no free port pair")


def listening(ports: tuple[int, ...]) -> list[tuple[str, int]]:
    """Every listening TCP socket on these ports, any process, any address."""
    return sorted((c.laddr.ip, c.laddr.port) for c in psutil.net_connections(kind="tcp")
                  if c.status == psutil.CONN_LISTEN and c.laddr.port in ports)


def test_frames_sit_below_their_pinhole(rrd):
    """rerun 0.41 shows a frame in a 2-D view only below a pinhole entity, and a Transform3D
    on the pinhole's entity would take its place: pose, pinhole and frame on three levels."""
    columns: dict[str, set[str]] = {}
    for chunk in RrdReader(rrd).store().stream():
        columns.setdefault(chunk.entity_path, set()).update(chunk.to_record_batch().schema.names)
    for cam in CAMERAS:
        pose, pinhole = f"/{rerun_scene.camera_path(cam)}", f"/{rerun_scene.camera_path(cam)}/pinhole"
        archetypes = {p: {c.split(":")[0] for c in columns[p] if ":" in c} for p in (pose, pinhole, pinhole + "/image")}
        assert archetypes == {pose: {"Transform3D"}, pinhole: {"Pinhole"}, pinhole + "/image": {"EncodedImage"}}


def test_layout_has_a_named_view_per_camera_and_every_signal_group(rrd):
    paths, note = server.entity_paths(rrd)
    assert note is None
    bp = rerun_scene.blueprint(paths)
    top, bottom = bp.root_container.contents
    scene, grid = top.contents
    assert isinstance(scene, rrb.Spatial3DView)
    views = {v.name: v.origin for v in grid.contents}
    assert views == {c: f"/{rerun_scene.camera_path(c)}/pinhole/image" for c in CAMERAS}
    # the 3-D view keeps the cell and the frustums, not the frames (drawn metres wide there)
    assert set(scene.contents) == {"/cell/**", *(f"- {o}" for o in views.values())}
    tabs, log = bottom.contents
    assert [v.name for v in tabs.contents] == ["q", "leg"] and isinstance(log, rrb.TextLogView)


@pytest.mark.parametrize("content", [b"", b"not a recording at all", "random", "truncated", "cut_before_footer"])
def test_a_broken_file_is_refused_in_one_line(rrd, tmp_path, capsys, content):
    good = rrd.read_bytes()
    if content == "random":
        content = np.random.default_rng(0).bytes(100_000)
    elif content == "truncated":
        content = good[: len(good) // 2]
    elif content == "cut_before_footer":  # mid-message, as a full disk or a killed copy leaves it
        content = good[: good.rfind(b"RRF2FOOT") - 1000]
    bad = tmp_path / "bad.rrd"
    bad.write_bytes(content)
    port = free_ports()
    assert main(["replay", "--web", str(bad), "--port", str(port)]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1
    assert out.err.startswith(f"serpar: error: {bad}: not a readable rerun recording (")
    assert listening((port, port + 1)) == []


def test_a_recording_without_footer_is_served_with_a_note(tmp_path):
    """A writer stopped before its footer (here: the process exits at once) leaves whole
    messages; they are decoded one by one and served, with a note."""
    path = tmp_path / "cut.rrd"
    code = (f"import os, rerun as rr\nrec = rr.RecordingStream('serpar'); rec.save(r'{path}')\n"
            "rec.log('a', rr.Points3D([[0, 0, 0]])); rec.flush(); os._exit(0)\n")
    subprocess.run([sys.executable, "-c", code], check=True)
    assert b"FOOT" not in path.read_bytes()
    paths, note = server.entity_paths(path)
    assert "/a" in paths and "has no footer" in note


@pytest.mark.parametrize("which", ["viewer", "data"])
def test_a_busy_port_is_refused_before_starting(rrd, capsys, which):
    port = free_ports()
    busy = port if which == "viewer" else port + 1
    with socket.socket() as holder:
        holder.bind((server.LOCAL, busy))
        holder.listen()
        assert main(["replay", "--web", str(rrd), "--port", str(port)]) == 2
        out = capsys.readouterr()
        assert out.out == "" and out.err.count("\n") == 1
        assert f"port {busy} ({which}) is already in use on 127.0.0.1" in out.err and "--port" in out.err
        assert listening((port, port + 1)) == [(server.LOCAL, busy)]  # only the holder


def test_bind_is_checked_and_opening_up_is_said(rrd, capsys, monkeypatch):
    assert main(["replay", "--web", str(rrd), "--bind", "localhost"]) == 2
    assert "--bind localhost: not an IP address" in capsys.readouterr().err
    served = []
    monkeypatch.setattr(server, "serve", lambda path, paths, args, ready, on_ready: served.append(args) or 0)
    port = free_ports()
    assert main(["replay", "--web", str(rrd), "--bind", "0.0.0.0", "--port", str(port)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1 and lines[0].startswith("--bind 0.0.0.0: the viewer listens beyond this machine")
    assert served[0][:3] == ["--serve-web", "--bind", "0.0.0.0"]
    assert main(["replay", "--web", str(rrd), "--port", str(port)]) == 0
    assert capsys.readouterr().out == "" and served[1][:3] == ["--serve-web", "--bind", "127.0.0.1"]
    assert server.viewer_url("::1", 9090) == "http://[::1]:9090/?url=rerun%2Bhttp%3A%2F%2F%5B%3A%3A1%5D%3A9091%2Fproxy"


@contextlib.contextmanager
def serving(rrd: Path, port: int):
    proc = subprocess.Popen([sys.executable, "-m", "serpar", "replay", "--web", str(rrd), "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith(f"serving {rrd} at http://127.0.0.1:{port}/"), (line, proc.stderr.read())
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_the_viewer_listens_on_localhost_and_dies_with_serpar(rrd, sig):
    port = free_ports()
    with serving(rrd, port) as proc:
        viewers = psutil.Process(proc.pid).children(recursive=True)
        assert viewers and all("rerun" in v.name() for v in viewers)
        # both ports, on the loopback address only (rerun's own default would be 0.0.0.0)
        assert listening((port, port + 1)) == [(server.LOCAL, port), (server.LOCAL, port + 1)]
        proc.send_signal(sig)  # as `kill PID` or Ctrl-C does
        assert proc.wait(timeout=30) == 0
        _, alive = psutil.wait_procs(viewers, timeout=10)
        assert alive == []
    assert listening((port, port + 1)) == []
    server.check_port_free(server.LOCAL, port, "viewer")  # free to serve again at once
    server.check_port_free(server.LOCAL, port + 1, "data")


@pytest.mark.slow
@pytest.mark.skipif(browser_replay.find_browser() is None,
                    reason=f"needs a browser ({', '.join(browser_replay.BROWSERS)}); "
                           ".ci/run installs Debian's chromium where none is found")
def test_a_browser_shows_every_camera_frame(rrd, tmp_path):
    """Headless Chromium with software WebGL opens `serpar replay --web` as a user would; each
    camera's frame is found on the screen, with the spread of grey levels of the frame itself
    (the grey box rerun 0.41 drew for frames logged on the pinhole's entity has none)."""
    port = free_ports()
    with browser_replay.replay(rrd, port) as (proc, url):
        panels, shot = browser_replay.check(rrd, url, timeout_s=120)
    assert proc.returncode == 0  # stopped by SIGTERM, cleanly
    browser_replay.save_screenshot(shot, tmp_path / "replay.png")
    assert {p.camera for p in panels} == set(CAMERAS)
    for p in panels:
        assert p.shown, p
        assert p.score > 0.9 and p.box[2] >= browser_replay.MIN_WIDTH
    assert listening((port, port + 1)) == []


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.floats(0, 1), flip=st.integers(0, 2**31 - 1), junk=st.binary(max_size=64))
def test_a_damaged_rrd_is_read_or_refused_in_one_line(rrd, tmp_path, cut, flip, junk):
    """The .rrd reader under fuzzing: a cut, a flipped byte or trailing junk ends in the
    entities and at most a note, or a one-line ConfigError; never a traceback."""
    good = bytearray(rrd.read_bytes())
    data = good[: max(1, int(cut * len(good)))]
    data[flip % len(data)] ^= 0xFF
    bad = tmp_path / "fuzzed.rrd"
    bad.write_bytes(bytes(data) + junk)
    try:
        paths, note = server.entity_paths(bad)
    except ConfigError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(f"{bad}: not a readable rerun recording")
        return
    assert isinstance(paths, list) and (note is None or "\n" not in note)
