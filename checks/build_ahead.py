"""Trial scenes built ahead in worker processes.

A trial's scene costs ~17 ms to build here (its spec and compile ~4 ms, the start's inverse
kinematics ~14 ms), one at a time on the Python thread that runs the batch. On CPU cores that
hides behind the physics of the trials already running; a GPU batch of 10 000 worlds waits
for all of them before its first step (~3 min on one core). :class:`BuildAhead` keeps up to
``window`` builds in flight on ``workers`` processes (spawned: a forked child of a process
holding a CUDA context or MuJoCo's thread pool is not safe) and hands results back in order;
a model comes back pickled (~100 kB) and is bit-identical to one built here.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Generic, TypeVar

from serpar.errors import ConfigError

T = TypeVar("T")


class BuildAhead(Generic[T]):
    """``build(k)`` for k in ``first..stop-1`` on ``workers`` processes, ``window`` in flight.

    ``build`` must be picklable (a module-level function or a ``functools.partial`` of one).
    :meth:`get` asks in increasing order (a run's slots take trials in order); the builds
    skipped by a jump ahead are dropped."""

    def __init__(self, build: Callable[[int], T], first: int, stop: int, workers: int,
                 window: int | None = None) -> None:
        if workers < 2:
            raise ConfigError(f"BuildAhead workers {workers}: >= 2 (one builds in place)")
        self.build, self.stop = build, stop
        self.window = window or 8 * workers
        self._next = first
        self._pending: dict[int, Future[T]] = {}
        self._pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))

    def get(self, k: int) -> T:
        for skipped in [i for i in self._pending if i < k]:
            self._pending.pop(skipped).cancel()
        if k not in self._pending:
            if k < self._next:
                raise ConfigError(f"trial {k} was already taken from the builds (asked in order)")
            self._next = k
        while self._next < self.stop and len(self._pending) < self.window:
            self._pending[self._next] = self._pool.submit(self.build, self._next)
            self._next += 1
        return self._pending.pop(k).result()

    def close(self) -> None:
        for future in self._pending.values():
            future.cancel()
        self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> BuildAhead[T]:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()
