"""``serpar replay FILE.rrd``: an episode recording (``serpar run --record``) in the rerun viewer."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

from serpar.cli.output import fail
from serpar.errors import ConfigError

DEFAULT_PORT = 9090


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("replay", help="open an episode recording (episode.rrd of run --record) in the "
                                      "rerun viewer, or serve it to a browser with --web")
    p.add_argument("file", metavar="FILE.rrd", help="a rerun recording, e.g. DIR/episode_0/episode.rrd")
    p.add_argument("--web", action="store_true",
                   help="serve the web viewer instead of opening a window (machines without a display)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"--web: HTTP port of the viewer (default {DEFAULT_PORT}); the data goes over the next port")
    p.set_defaults(func=cmd_replay)
    return p


def check_file(file: str) -> Path:
    path = Path(file)
    if path.suffix != ".rrd":
        raise ConfigError(f"{file}: not a rerun recording (.rrd); `serpar run --record DIR` writes "
                          "DIR/episode_<seed>/episode.rrd")
    if not path.is_file():
        raise ConfigError(f"{file}: no such file")
    return path


def has_display() -> bool:
    if not sys.platform.startswith("linux"):
        return True  # macOS and Windows viewers need no X/Wayland variable
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def cmd_replay(args: argparse.Namespace) -> int:
    path = check_file(args.file)
    viewer = [sys.executable, "-m", "rerun"]  # the viewer bundled with this rerun-sdk
    if not args.web:
        if not has_display():
            return fail(f"no display ($DISPLAY and $WAYLAND_DISPLAY unset): serve it to a browser with "
                        f"`serpar replay --web {args.file}`")
        return subprocess.call([*viewer, str(path)])
    if not 1024 <= args.port < 65535:
        raise ConfigError(f"--port {args.port}: valid 1024..65534 (the data uses port + 1)")
    data_port = args.port + 1
    url = (f"http://localhost:{args.port}/?url=rerun%2Bhttp%3A%2F%2Flocalhost%3A{data_port}%2Fproxy")
    print(f"serving {path} at {url}\n(ports {args.port} and {data_port}; from another machine tunnel both, "
          f"e.g. ssh -L {args.port}:localhost:{args.port} -L {data_port}:localhost:{data_port}; Ctrl-C stops)",
          flush=True)
    return subprocess.call([*viewer, "--web-viewer", "--web-viewer-port", str(args.port),
                            "--port", str(data_port), str(path)])
