"""``serpar replay FILE.rrd``: an episode recording (``serpar run --record``) in the rerun viewer."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from serpar.cli.output import fail
from serpar.errors import ConfigError
from serpar.tasks import replay_server as server

DEFAULT_PORT = 9090


def register(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    p = sub.add_parser("replay", help="open an episode recording (episode.rrd of run --record, or a failed "
                                      "trial of montecarlo --out: DIR/failed/trial_<k>.rrd) in the "
                                      "rerun viewer, or serve it to a browser with --web")
    p.add_argument("file", metavar="FILE.rrd", help="a rerun recording, e.g. DIR/episode_0/episode.rrd; "
                                                    "a truncated or corrupt file is refused")
    p.add_argument("--web", action="store_true",
                   help="serve the web viewer instead of opening a window (machines without a display); "
                        "it runs until Ctrl-C or SIGTERM, which also stop the viewer")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"--web: HTTP port of the viewer (default {DEFAULT_PORT}); the data goes over the next "
                        "port; both must be free")
    p.add_argument("--bind", metavar="ADDRESS", default=server.LOCAL,
                   help=f"the address the viewer's servers listen on (default {server.LOCAL}: this machine only); "
                        "e.g. 0.0.0.0 opens them to the network")
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
    bind = server.check_bind(args.bind)
    if not args.web:
        if not has_display():
            return fail(f"no display ($DISPLAY and $WAYLAND_DISPLAY unset): serve it to a browser with "
                        f"`serpar replay --web {args.file}`")
        paths = _read(path)
        _say_if_open(bind, "its SDK port")
        return server.serve(path, paths, ["--bind", bind], ready=None, on_ready=None)
    if not 1024 <= args.port < 65535:
        raise ConfigError(f"--port {args.port}: valid 1024..65534 (the data uses port + 1)")
    data_port = args.port + 1
    paths = _read(path)  # a corrupt file is refused before anything listens
    server.check_port_free(bind, args.port, "viewer")
    server.check_port_free(bind, data_port, "data")
    _say_if_open(bind, f"ports {args.port} and {data_port}")
    host = server.url_host(bind)
    tunnel = (f"from another machine tunnel both, e.g. ssh -L {args.port}:{host}:{args.port} "
              f"-L {data_port}:{host}:{data_port}; " if server.is_loopback(bind) else "")
    ready = (f"serving {path} at {server.viewer_url(bind, args.port)}\n(ports {args.port} and {data_port} "
             f"on {bind}; {tunnel}Ctrl-C or SIGTERM stops it)")
    return server.serve(path, paths, ["--serve-web", "--bind", bind, "--web-viewer-port", str(args.port),
                                      "--port", str(data_port)],
                        ready=(bind, (args.port, data_port)), on_ready=lambda: print(ready, flush=True))


def _read(path: Path) -> list[str]:
    paths, note = server.entity_paths(path)
    if note:
        print(f"serpar: note: {note}", file=sys.stderr)
    return paths


def _say_if_open(bind: str, ports: str) -> None:
    """--bind beyond loopback is said, once: the recording is then open to the network."""
    if not server.is_loopback(bind):
        print(f"--bind {bind}: the viewer listens beyond this machine; whoever reaches it on {ports} "
              "sees the recording", flush=True)
