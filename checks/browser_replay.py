"""Does `serpar replay --web` show the camera frames in a real browser? Headless Chromium
(software WebGL, no display needed) opens the served viewer; each camera's last frame in
the recording is searched for in the screenshot, and where it is found its panel must be a
picture, not the flat grey box rerun draws when the frame is not shown.

    python -m serpar.checks.browser_replay DIR/episode_0/episode.rrd --out shot.png

Chromium is driven over its DevTools protocol with a small WebSocket client from the
standard library, so the check needs nothing but a ``chromium`` on the PATH.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import dataclasses
import io
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from urllib.request import Request, urlopen

import cv2
import numpy as np
from PIL import Image
from rerun.chunk import RrdReader

from serpar.errors import ConfigError
from serpar.tasks import rerun_scene
from serpar.tasks.replay_server import LOCAL, check_port_free

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
WINDOW = (1600, 1000)
MIN_SCORE, MIN_WIDTH, STD_RATIO, MIN_STD = 0.8, 100, (0.65, 1.35), 4.0
"""A panel passes where the frame matches (normalised correlation) at least MIN_WIDTH px wide
and its grey levels spread as the frame's own do (std ratio): the grey box has no spread, and
a chance match on small UI detail (text, the 3-D view) is small, weak and spreads otherwise.
A frame of one grey level (an empty backlit in-hand shot) cannot be told from the grey box:
frames under MIN_STD are not checked."""
_FRAME = re.compile(rf"/{rerun_scene.ROOT}/cameras/([^/]+)(/{rerun_scene.PINHOLE}/{rerun_scene.IMAGE})?")
"""A camera's frames; before the fix they were on the camera's own (pinhole) entity."""
_BLOB = "EncodedImage:blob"


def find_browser() -> str | None:
    return next((b for b in map(shutil.which, BROWSERS) if b), None)


def last_frames(rrd: Path) -> dict[str, np.ndarray]:
    """Each camera's last frame in the recording (grey levels): what the viewer shows at the
    end of the timeline, where it opens."""
    best: dict[str, tuple[int, np.ndarray]] = {}
    for chunk in RrdReader(rrd).stream():
        m = _FRAME.fullmatch(chunk.entity_path)
        if not m or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if _BLOB not in batch.schema.names:
            continue
        times = batch.column(rerun_scene.TIMELINE).cast("int64").to_numpy()
        times = np.where(batch.column(_BLOB).is_null().to_numpy(zero_copy_only=False), np.iinfo(np.int64).min, times)
        k = int(np.argmax(times))
        if m[1] not in best or times[k] > best[m[1]][0]:
            blob = bytes(batch.column(_BLOB)[k].values[0].values.to_numpy())
            best[m[1]] = (int(times[k]), np.asarray(Image.open(io.BytesIO(blob)).convert("L")))
    return {name: image for name, (_, image) in sorted(best.items())}


@dataclasses.dataclass(frozen=True)
class Panel:
    camera: str
    box: tuple[int, int, int, int]
    """x, y, width, height of the best match in the screenshot [px]."""
    score: float
    """Normalised correlation of the frame with the screenshot there (1: identical)."""
    std: float
    """Spread of the grey levels there; the grey box rerun draws instead of a frame has ~0."""
    frame_std: float
    """The same of the frame itself (a backlit in-hand shot is mostly white: a low spread)."""

    @property
    def shown(self) -> bool:
        lo, hi = STD_RATIO
        return self.score >= MIN_SCORE and self.box[2] >= MIN_WIDTH and lo <= self.std / self.frame_std <= hi


def _best_match(image: np.ndarray, frame: np.ndarray, widths: np.ndarray) -> tuple[float, tuple[int, int, int, int]]:
    best = (-1.0, (0, 0, 0, 0))
    for width in np.unique(widths.astype(int)):
        height = round(width * frame.shape[0] / frame.shape[1])
        if not (8 <= width <= image.shape[1] and 8 <= height <= image.shape[0]):
            continue
        tpl = cv2.resize(frame, (int(width), height), interpolation=cv2.INTER_AREA)
        _, score, _, (x, y) = cv2.minMaxLoc(cv2.matchTemplate(image, tpl, cv2.TM_CCOEFF_NORMED))
        if score > best[0]:
            best = (float(score), (x, y, int(width), height))
    return best


def find_panel(shot: np.ndarray, camera: str, frame: np.ndarray) -> Panel:
    """Multi-scale template match of the frame in the (grey) screenshot: the viewer fits the
    frame into its panel, so its size on screen is unknown and the layout is not assumed.
    Coarse on a half-size screenshot, then refined at full size around the best match."""
    half = cv2.resize(shot, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    _, (x, y, w, h) = _best_match(half, frame, np.geomspace(40, half.shape[1], 50))
    x0, y0, pad = max(0, 2 * x - 16), max(0, 2 * y - 16), 16
    roi = shot[y0:2 * (y + h) + pad, x0:2 * (x + w) + pad]
    score, (x, y, w, h) = _best_match(roi, frame, 2 * w * np.linspace(0.95, 1.05, 11))
    x, y = x + x0, y + y0
    return Panel(camera, (x, y, w, h), score, float(shot[y:y + h, x:x + w].std()), float(frame.std()))


class _DevTools:
    """Just enough of a WebSocket client (RFC 6455) for Chromium's DevTools: masked text
    frames out, text frames in (payloads of several MB for a screenshot)."""

    def __init__(self, ws_url: str) -> None:
        m = re.fullmatch(r"ws://([^/:]+):(\d+)(/.*)", ws_url)
        assert m, ws_url
        self.sock = socket.create_connection((m[1], int(m[2])), timeout=60)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET {m[3]} HTTP/1.1\r\nHost: {m[1]}:{m[2]}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        assert b" 101 " in head.split(b"\r\n")[0], head
        self._id = 0

    def _recv_exact(self, n: int) -> bytes:
        buf = bytearray()
        while len(buf) < n:
            part = self.sock.recv(n - len(buf))
            if not part:
                raise ConnectionError("DevTools closed the connection")
            buf += part
        return bytes(buf)

    def _recv(self) -> str:
        data = b""
        while True:
            b0, b1 = self._recv_exact(2)
            n = b1 & 0x7F
            n = int.from_bytes(self._recv_exact(2 if n == 126 else 8), "big") if n >= 126 else n
            data += self._recv_exact(n)
            if b0 & 0x80:  # FIN: the message is complete
                return data.decode()

    def call(self, method: str, **params: object) -> dict:
        self._id += 1
        payload = json.dumps({"id": self._id, "method": method, "params": params}).encode()
        n = len(payload)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + n.to_bytes(2, "big"))
        mask = os.urandom(4)
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))
        while True:
            msg = json.loads(self._recv())
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]


class Browser:
    """Headless Chromium with software WebGL (SwiftShader), in its own profile and process group."""

    def __init__(self, binary: str) -> None:
        self.profile = tempfile.TemporaryDirectory(prefix="serpar-chromium-")
        args = [binary, "--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                "--ignore-gpu-blocklist", "--no-first-run", f"--window-size={WINDOW[0]},{WINDOW[1]}",
                "--remote-debugging-port=0", f"--user-data-dir={self.profile.name}", "about:blank"]
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        port_file = Path(self.profile.name) / "DevToolsActivePort"  # Chromium writes its port here
        deadline = time.monotonic() + 30
        while not port_file.is_file() or len(port_file.read_text().splitlines()) < 2:
            if time.monotonic() > deadline or self.proc.poll() is not None:
                self.close()
                raise RuntimeError("chromium did not start its DevTools server")
            time.sleep(0.1)
        port = port_file.read_text().splitlines()[0]
        page = json.loads(urllib_get(f"http://127.0.0.1:{port}/json/new?about:blank", method="PUT"))
        self.tools = _DevTools(page["webSocketDebuggerUrl"])

    def open(self, url: str) -> None:
        self.tools.call("Page.navigate", url=url)

    def screenshot(self) -> np.ndarray:
        png = base64.b64decode(self.tools.call("Page.captureScreenshot", format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    def close(self) -> None:
        tools = getattr(self, "tools", None)
        if tools is not None:
            tools.sock.close()
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            self.proc.wait(timeout=10)
        self.profile.cleanup()


def urllib_get(url: str, method: str = "GET") -> str:
    with urlopen(Request(url, method=method), timeout=10) as r:
        return r.read().decode()


def free_port_pair(start: int = 9300) -> int:
    """The first P >= start with P and P+1 free on 127.0.0.1 (what `serpar replay --web` needs)."""
    for port in range(start, 65534):
        try:
            check_port_free(LOCAL, port, "viewer")
            check_port_free(LOCAL, port + 1, "data")
            return port
        except ConfigError:
            continue
    raise ConfigError(f"no two free ports from {start} on")


@contextlib.contextmanager
def replay(rrd: Path, port: int) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """`serpar replay --web` as a user runs it; yields the process and the URL it printed,
    and stops it with SIGTERM at the end."""
    proc = subprocess.Popen([sys.executable, "-m", "serpar", "replay", "--web", str(rrd), "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stderr is not None
        line = proc.stdout.readline()  # printed once both ports listen
        if not line.startswith("serving "):
            proc.wait(timeout=30)
            raise RuntimeError(f"serpar replay --web exited {proc.returncode}: {proc.stderr.read().strip()}")
        yield proc, line.rsplit(" at ", 1)[1].strip()
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=30)


def check(rrd: Path, url: str, timeout_s: float = 150.0, wait_s: float = 10.0) -> tuple[list[Panel], np.ndarray]:
    """Open `url` (the viewer serving `rrd`), wait `wait_s`, then until every camera's last
    frame shows or `timeout_s` passes; the panels found and the last screenshot (RGB)."""
    frames = {c: f for c, f in last_frames(rrd).items() if f.std() >= MIN_STD}
    if not frames:
        raise ConfigError(f"{rrd}: no camera frames (other than flat ones) under /{rerun_scene.ROOT}/cameras")
    binary = find_browser()
    if binary is None:
        raise ConfigError(f"no browser found (tried {', '.join(BROWSERS)}); e.g. apt-get install chromium")
    browser = Browser(binary)
    try:
        browser.open(url)
        deadline = time.monotonic() + timeout_s
        time.sleep(wait_s)  # the viewer's WebAssembly loads and compiles first, then the data streams in
        while True:
            shot = browser.screenshot()
            grey = cv2.cvtColor(shot, cv2.COLOR_RGB2GRAY)
            panels = [find_panel(grey, camera, frame) for camera, frame in frames.items()]
            if all(p.shown for p in panels) or time.monotonic() > deadline:
                return panels, shot
            time.sleep(3)
    finally:
        browser.close()


def save_screenshot(shot: np.ndarray, out: Path) -> Path:
    """PNG with a 256-colour palette: the viewer's flat UI keeps its look at a third of the size."""
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(shot).quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m serpar.checks.browser_replay", description=__doc__.split("\n\n")[0])
    parser.add_argument("file", metavar="FILE.rrd", type=Path)
    parser.add_argument("--out", type=Path, help="write the screenshot here (PNG)")
    parser.add_argument("--port", type=int, help="viewer port (default: the first free pair from 9300)")
    parser.add_argument("--timeout", type=float, default=150.0, help="seconds to wait for the frames (default 150)")
    parser.add_argument("--wait", type=float, default=10.0,
                        help="seconds before the first look (default 10; longer lets all the data stream in)")
    args = parser.parse_args(argv)
    port = args.port or free_port_pair()
    with replay(args.file, port) as (_, url):
        panels, shot = check(args.file, url, args.timeout, args.wait)
    for p in panels:
        x, y, w, h = p.box
        print(f"{p.camera:14s} {'shown' if p.shown else 'NOT SHOWN':9s} match {p.score:.3f}  std {p.std:5.1f} "
              f"(frame {p.frame_std:5.1f})  at x={x} y={y} {w}x{h} px")
    if args.out:
        print(f"screenshot: {save_screenshot(shot, args.out)}")
    return 0 if all(p.shown for p in panels) else 1


if __name__ == "__main__":
    sys.exit(main())
