"""The rerun viewer process behind ``serpar replay``: the recording checked before it is
served, its layout sent with it, the two ports checked free on the one address it binds,
and the viewer stopped with serpar.

rerun's own command line (the binary bundled with rerun-sdk) does the serving: its
``--bind`` sets the address of both the web page's HTTP server and the gRPC data server
(measured with ``ss -ltn``: both on 127.0.0.1 with ``--bind 127.0.0.1``; rerun's default is
0.0.0.0). ``--serve-web`` serves without opening a browser, which ``--web-viewer`` would try.
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from types import FrameType
from urllib.parse import quote

import rerun_cli
from rerun.chunk import RrdReader

from serpar.errors import ConfigError, SerparError
from serpar.tasks import rerun_scene

LOCAL = "127.0.0.1"
READY_TIMEOUT_S = 30.0
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


def entity_paths(path: Path) -> tuple[list[str], str | None]:
    """The recording's entities, read through rerun's own reader: a truncated, corrupt or
    foreign file is refused here instead of being served as an empty or broken viewer.
    Also a note when the file has no footer (an older rerun wrote it, or its writer was cut
    short at a message boundary): every message is decoded then, and what it holds is served."""
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")  # rerun warns of a footer-less file; the note says it once
            reader = RrdReader(path)
        if not any("footer" in str(w.message) for w in caught):
            return list(reader.store().schema().entity_paths()), None
        paths = sorted({chunk.entity_path for chunk in reader.stream()})  # decodes every message
    except (RuntimeError, ValueError, OSError) as exc:  # what rerun's reader raises, and the file's own
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        reason = reason.removeprefix(f"Failed to read RRD file at {path}: ")
        raise ConfigError(f"{path}: not a readable rerun recording ({reason})") from None
    return paths, (f"{path} has no footer (written by an older rerun, or its writer was stopped): "
                   "serving the messages it holds")


def check_bind(address: str) -> str:
    try:
        return str(ipaddress.ip_address(address))
    except ValueError:
        raise ConfigError(f"--bind {address}: not an IP address (e.g. {LOCAL}, 0.0.0.0, ::)") from None


def is_wildcard(address: str) -> bool:
    return ipaddress.ip_address(address).is_unspecified


def is_loopback(address: str) -> bool:
    return ipaddress.ip_address(address).is_loopback


def check_port_free(address: str, port: int, role: str) -> None:
    """Bind the port the way a server does; the viewer would otherwise start next to (or fail
    behind) whatever holds it, and the URL would show that server's data."""
    family = socket.AF_INET6 if ipaddress.ip_address(address).version == 6 else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        # As servers do: a port left in TIME_WAIT by the last replay is free; one listening is not.
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((address, port))
        except OSError as exc:
            if exc.errno == errno.EADDRNOTAVAIL:
                raise ConfigError(f"--bind {address}: not an address of this machine") from None
            raise ConfigError(f"port {port} ({role}) is already in use on {address}; "
                              f"choose free ports with --port P (viewer on P, data on P+1)") from None


def viewer_binary() -> list[str]:
    """rerun's viewer binary as `python -m rerun` would run it, started directly: the
    wrapper would be a second process in between, left behind if serpar is killed."""
    override = os.environ.get("RERUN_CLI_PATH")
    binary = Path(override) if override else Path(rerun_cli.__file__).with_name("rerun" + (
        ".exe" if sys.platform.startswith("win") else ""))
    return [str(binary)] if binary.is_file() else [sys.executable, "-m", "rerun"]


def url_host(address: str) -> str:
    """The host a browser uses: the bound address, or this machine's name for all interfaces."""
    host = socket.gethostname() if is_wildcard(address) else address
    return f"[{host}]" if ":" in host else host


def viewer_url(address: str, port: int) -> str:
    host = url_host(address)
    return f"http://{host}:{port}/?url={quote(f'rerun+http://{host}:{port + 1}/proxy', safe='')}"


def _connect_host(address: str) -> str:
    if is_wildcard(address):
        return "::1" if ipaddress.ip_address(address).version == 6 else LOCAL
    return address


def _listening(address: str, port: int) -> bool:
    with contextlib.suppress(OSError), socket.create_connection((_connect_host(address), port), timeout=0.5):
        return True
    return False


class Viewer:
    """One rerun viewer process in its own process group, so that it and anything it starts
    are signalled as one by :meth:`stop`."""

    def __init__(self, args: list[str], log: Path) -> None:
        self._log = log.open("w")
        self.proc = subprocess.Popen([*viewer_binary(), *args], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=self._log, start_new_session=True)

    def wait_listening(self, address: str, ports: tuple[int, ...]) -> None:
        deadline = time.monotonic() + READY_TIMEOUT_S
        while not all(_listening(address, p) for p in ports):
            if self.proc.poll() is not None:
                raise SerparError(f"the rerun viewer exited with code {self.proc.returncode}: {self.last_log_line()}")
            if time.monotonic() > deadline:
                raise SerparError(f"the rerun viewer did not listen on ports {ports} within {READY_TIMEOUT_S:.0f} s")
            time.sleep(0.1)

    def last_log_line(self) -> str:
        self._log.flush()
        lines = [ln.strip() for ln in Path(self._log.name).read_text(errors="replace").splitlines() if ln.strip()]
        return lines[-1] if lines else "no output"

    def wait(self) -> int:
        return self.proc.wait()

    def _signal(self, sig: int) -> None:
        with contextlib.suppress(ProcessLookupError):
            if hasattr(os, "killpg"):
                os.killpg(self.proc.pid, sig)
            else:  # Windows: no process groups to signal
                self.proc.terminate()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self._signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._signal(getattr(signal, "SIGKILL", signal.SIGTERM))
                self.proc.wait()
        self._log.close()


class _Stopped(Exception):
    """Raised from a signal handler so the waiting code unwinds and stops the viewer."""


@contextlib.contextmanager
def stopped_by_signals() -> Iterator[Callable[[], None]]:
    """SIGINT, SIGTERM and SIGHUP end the block (as :class:`_Stopped`, caught by the caller):
    without handlers SIGTERM would end serpar at once and leave the viewer serving. Yields
    `quiet`: after it, signals are ignored, so a second Ctrl-C cannot cut the viewer's stop short."""
    stopping: list[bool] = []

    def handler(signum: int, frame: FrameType | None) -> None:
        if not stopping:
            stopping.append(True)
            raise _Stopped(signal.Signals(signum).name)

    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield lambda: stopping.append(True)
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def serve(path: Path, paths: list[str], viewer_args: list[str], ready: tuple[str, tuple[int, ...]] | None,
          on_ready: Callable[[], None] | None) -> int:
    """Run the viewer on `path` (whose :func:`entity_paths` are `paths`) with serpar's layout
    until it exits or serpar is signalled (then 0). `ready` (address, ports): wait until it
    listens there before calling `on_ready`, so a URL is only given once it answers."""
    with tempfile.TemporaryDirectory(prefix="serpar-replay-") as tmp:
        layout = Path(tmp) / "layout.rbl"
        rerun_scene.blueprint(paths).save(rerun_scene.APP_ID, layout)
        with stopped_by_signals() as quiet:
            viewer: Viewer | None = None
            try:
                viewer = Viewer([*viewer_args, str(path), str(layout)], Path(tmp) / "viewer.log")
                if ready is not None:
                    viewer.wait_listening(*ready)
                if on_ready is not None:
                    on_ready()
                code = viewer.wait()
                if code != 0:
                    raise SerparError(f"the rerun viewer exited with code {code}: {viewer.last_log_line()}")
                return 0
            except _Stopped:
                return 0
            finally:
                quiet()
                if viewer is not None:
                    viewer.stop()
