"""Terminal output helpers: aligned tables, strict JSON, one-line errors, progress bars and
stage lines."""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from typing import Any, Self

from serpar.sim.strict_json import dumps


def print_json(obj: Any) -> None:
    """Indented strict JSON on stdout (NaN and infinities as null)."""
    sys.stdout.write(dumps(obj, indent=2) + "\n")


def json_line(obj: Any) -> str:
    """One strict JSON line (NaN and infinities as null): what the JSON-lines outputs print."""
    return dumps(obj)


def table(headers: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """Plain aligned text table."""
    cells = [list(map(str, headers))] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def fail(message: str, code: int = 2) -> int:
    """Print a one-line error to stderr and return the exit code."""
    sys.stderr.write(f"serpar: error: {message}\n")
    return code


def progress(total: int, desc: str, enabled: bool = True):
    """A tqdm bar on stderr (silent when stderr is not a terminal and not forced)."""
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, file=sys.stderr, disable=not enabled, leave=False)


@contextlib.contextmanager
def stage(text: str) -> Iterator[None]:
    """Progress of one long step without counts (a calibration) on stderr: a line when it
    starts and one with its elapsed time when it ends (naming the step when stderr is not a
    terminal; on a terminal the second line ticks every second meanwhile). The library takes
    this as its ``stage`` callback."""
    err, t0 = sys.stderr, time.perf_counter()
    tty, ended = err.isatty(), "stopped after"
    err.write(f"{text} ...\n")
    err.flush()
    stop = threading.Event()

    def tick() -> None:
        while not stop.wait(1.0):
            err.write(f"\r  {time.perf_counter() - t0:.0f} s")
            err.flush()

    ticker = threading.Thread(target=tick, daemon=True)
    if tty:
        ticker.start()
    try:
        yield
        ended = "done in"
    finally:
        stop.set()
        if tty:
            ticker.join()
        what = "\r " if tty else text.split(" (")[0] + ":"  # a log line names its step
        err.write(f"{what} {ended} {time.perf_counter() - t0:.1f} s\n")
        err.flush()


class StageLines:
    """Progress of a run made of named stages (a diagnosis: each candidate, each fold) on
    stderr, always (also with --json, whose object stays on stdout): one line per stage with
    the elapsed time, and a line repeating the current stage whenever ``every_s`` pass without
    one, so a user sees the run is alive."""

    def __init__(self, prefix: str, every_s: float = 30.0) -> None:
        self.prefix, self.every_s = prefix, every_s
        self.t0 = time.perf_counter()
        self.last, self.current = self.t0, "starting"
        self.finished: list[str] = []
        """The stages before the current one, in order (what an interrupted run did)."""
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._beat = threading.Thread(target=self._heartbeat, daemon=True)
        self._beat.start()

    def _write(self, text: str) -> None:
        with self._lock:
            now = time.perf_counter()
            sys.stderr.write(f"{self.prefix} [{now - self.t0:6.1f} s] {text}\n")
            sys.stderr.flush()
            self.last = now

    def __call__(self, text: str) -> None:
        if self.current != "starting":
            self.finished.append(self.current)
        self.current = text
        self._write(text)

    def beside(self, text: str) -> None:
        """A line of work running beside the current stage (a rerun in its own process): it
        counts as finished, and the stage the run is in stays the current one."""
        self.finished.append(text)
        self._write(text)

    def _heartbeat(self) -> None:
        while not self._stop.wait(1.0):
            if time.perf_counter() - self.last >= self.every_s:
                self._write(f"still: {self.current}")

    def close(self, word: str = "done") -> None:
        if self._stop.is_set():
            return  # closed already (interrupted)
        self._stop.set()
        self._write(word)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, kind: type[BaseException] | None, *_: object) -> None:
        self.close("done" if kind is None else "failed")

    def interrupted(self, as_json: bool, **about: object) -> int:
        """Stop on Ctrl-C: a last line on stderr; with ``as_json`` the summary object on stdout
        (``about``, the stages finished and the one it was in; no verdict). The exit status."""
        self.close(f"interrupted in: {self.current}")
        if as_json:
            print_json({**about, "interrupted": True, "finished": list(self.finished),
                        "interrupted_at": self.current,
                        "elapsed_s": time.perf_counter() - self.t0})
        return 130
