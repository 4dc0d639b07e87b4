"""Argument types shared by every command, so a flag is checked the same way everywhere
(``--seed -1`` is refused at parse time with the valid range, not deep inside numpy)."""

from __future__ import annotations

import argparse
import math


def seed(text: str) -> int:
    """A random seed: a non-negative integer (numpy's generators take no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid int value: {text!r}; a seed is 0, 1, 2, ...") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value}: a seed is a non-negative integer (0, 1, 2, ...)")
    return value


def span(text: str) -> tuple[float, float]:
    """``START:END`` seconds from the first sample, START < END, both >= 0."""
    start, sep, end = text.partition(":")
    try:
        a, b = float(start), float(end)
    except ValueError:
        a = b = float("nan")
    if not sep or not (0 <= a < b) or not math.isfinite(b):
        raise argparse.ArgumentTypeError(f"{text!r} is not START:END in seconds from the first "
                                         "sample (0 <= START < END), e.g. 0.1:6")
    return a, b


def workers(text: str) -> int:
    """A count of local processes: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid int value: {text!r}; workers are 1, 2, ..."
                                         ) from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value}: workers are 1, 2, ... local processes")
    return value


def add_fit_workers(p: argparse.ArgumentParser) -> None:
    """``--workers N`` of a command that diagnoses (diagnose, sim2real)."""
    p.add_argument("--workers", type=workers, default=0,
                   help="local processes that fit the diagnosis's candidates and resampled "
                        "folds side by side (default: one per core; the findings are the same)")
