"""Independent fits of one diagnosis on every core.

The candidates of one forward-selection step are fitted from the same model, and the fits of
the resampled folds from the same final model: each is a pure function of the family and its
arguments, so they run in forked worker processes (the family, with its precomputed
regressors, is shared copy-on-write, never pickled) and come back in order, the same numbers
as one after the other. A diagnosis spends almost all its time in these fits (scipy's
``least_squares``, one BLAS thread each), so on a 2-core machine two fit at once.

Serial where forking cannot serve: one job or one core, a platform without ``fork``, or a
daemonic process (a ``multiprocessing.Pool`` worker may not have children).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
from collections.abc import Callable, Sequence
from typing import TypeVar

T = TypeVar("T")

_JOBS: Sequence[Callable[[], object]] = ()
"""The jobs of the current :func:`run_all`, set before the workers fork (they inherit it)."""


def cores() -> int:
    """Cores this process may run on (its affinity, not the machine's count)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def can_fork() -> bool:
    return ("fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


def _quiet_worker() -> None:
    # Ctrl-C reaches the whole process group: the parent handles it and ends the pool
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _timed(job: Callable[[], object]) -> tuple[tuple[bool, object], float]:
    t0 = time.perf_counter()
    try:
        outcome: tuple[bool, object] = (True, job())
    except Exception as exc:  # noqa: BLE001 - the caller decides what a failed fit means
        outcome = (False, exc)
    return outcome, time.perf_counter() - t0


def _run(i: int) -> tuple[int, tuple[bool, object], float]:
    """Job ``i`` of :data:`_JOBS`, in a worker."""
    return (i, *_timed(_JOBS[i]))


Event = Callable[[str, int], None]
"""``event("start" | "done", i)``: job i began, job i ended (in the parent, for progress)."""


def run_all(jobs: Sequence[Callable[[], T]], workers: int = 0, event: Event | None = None,
            first: Sequence[int] | None = None, seconds: dict[int, float] | None = None
            ) -> list[tuple[bool, T | Exception]]:
    """``(True, result)`` or ``(False, the exception it raised)`` of every job, in order.
    ``workers``: processes at most (0: one per core). ``first``: the order in which the jobs
    are handed to the workers (the longest first: a step ends with its slowest job, so it
    should not start last); ``seconds``: filled with each job's wall time."""
    global _JOBS
    tell = event or (lambda _what, _i: None)
    took = seconds if seconds is not None else {}
    n = min(workers or cores(), len(jobs))
    if n <= 1 or not can_fork():
        out: list[tuple[bool, T | Exception]] = []
        for i, job in enumerate(jobs):
            tell("start", i)
            outcome, took[i] = _timed(job)
            out.append(outcome)  # type: ignore[arg-type]
            tell("done", i)
        return out
    order = list(first) if first is not None else list(range(len(jobs)))
    if sorted(order) != list(range(len(jobs))):
        raise ValueError(f"run_all: first={order} is not an order of the {len(jobs)} jobs")
    _JOBS = jobs
    try:
        with multiprocessing.get_context("fork").Pool(n, initializer=_quiet_worker) as pool:
            for i in order[:n]:
                tell("start", i)
            got: dict[int, tuple[bool, T | Exception]] = {}
            # a worker takes the next job when it finishes one: the (n + k)-th starts as the
            # k-th ends
            for k, (i, outcome, dt) in enumerate(pool.imap_unordered(_run, order)):
                got[i], took[i] = outcome, dt  # type: ignore[assignment]
                tell("done", i)
                if n + k < len(jobs):
                    tell("start", order[n + k])
        return [got[i] for i in range(len(jobs))]
    finally:
        _JOBS = ()


def results(outcomes: Sequence[tuple[bool, T | Exception]]) -> list[T]:
    """The results of :func:`run_all`, or the first exception in order (what running the jobs
    one after the other raises)."""
    for ok, got in outcomes:
        if not ok:
            raise got  # type: ignore[misc]
    return [got for _, got in outcomes]  # type: ignore[misc]
