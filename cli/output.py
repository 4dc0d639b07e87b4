"""Terminal output helpers: aligned tables, strict JSON, one-line errors, progress bars and
stage lines."""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

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
