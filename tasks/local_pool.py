"""Episodes in local worker processes (``--workers W``), robust to a worker that dies and to
an interrupt.

* At most W episodes are in flight, each in its own process (spawned, not forked: a child
  forked after this process has rendered inherits its EGL context and can hang in the first
  render, seen in ``serpar bench --episode``).
* An episode that raises gives the job's own error record. A worker that dies (killed, out of
  memory, a crash in native code) breaks the pool and every episode then in flight; those are
  run again one at a time in a fresh pool, so the one that kills its worker again is recorded
  as an error and the others' records are kept. The run goes on either way.
* On an interrupt the caller calls :meth:`LocalPool.stop`: each busy worker gets SIGINT once
  (workers ignore any further one, and an idle worker ignores it), ends its episode as the
  serial run would (the holes that finished, a partial episode record, where it stopped, its
  recording closed) and returns that; the workers still busy after the grace period are
  killed.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from types import FrameType
from typing import Any

from serpar.tasks.episode import signal_name
from serpar.tasks.episode_config import EpisodeConfig
from serpar.tasks.worker_life import end_with_parent

Record = dict[str, object]
GRACE_S = 120.0
"""How long interrupted workers get to close their episodes (a recording's tables and rerun
file are written then) before they are killed."""

_state = {"busy": False, "stopped": False}


def _on_signal(signum: int, frame: FrameType | None) -> None:
    """In a worker: the first SIGINT or SIGTERM during an episode interrupts it; others are
    ignored (a second one must not cut the recording's writing short)."""
    if _state["busy"] and not _state["stopped"]:
        _state["stopped"] = True
        raise KeyboardInterrupt(signal.Signals(signum).name)


def _init_worker(parent: int) -> None:
    end_with_parent(parent)
    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)


def _in_worker(job: Callable[..., list[Record]], cfg: EpisodeConfig, label: str | None) -> list[Record]:
    _state["busy"] = True
    try:
        return job(cfg, None, label)
    finally:
        _state["busy"] = False


def _tag(label: str | None) -> dict[str, object]:
    return {} if label is None else {"config": label}


class LocalPool:
    """Iterate for each episode's records as it finishes; :meth:`stop` when done or stopped."""

    def __init__(self, configs: Sequence[EpisodeConfig], labels: Sequence[str | None],
                 job: Callable[..., list[Record]], workers: int) -> None:
        self.job, self.workers = job, workers
        self.todo: deque[tuple[EpisodeConfig, str | None]] = deque(zip(configs, labels))
        self.suspects: deque[tuple[EpisodeConfig, str | None]] = deque()
        """Episodes in flight when a worker died: run again one at a time."""
        self.running: dict[Future, tuple[EpisodeConfig, str | None, bool]] = {}
        self.pool: ProcessPoolExecutor | None = None
        self.broke = False
        """A worker died: the pool is replaced once the episodes in flight have failed."""

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(max_workers=self.workers, initializer=_init_worker,
                                   initargs=(os.getpid(),),
                                   mp_context=multiprocessing.get_context("spawn"))

    def _submit(self, cfg: EpisodeConfig, label: str | None, solo: bool) -> bool:
        assert self.pool is not None
        try:
            fut = self.pool.submit(_in_worker, self.job, cfg, label)
        except BrokenProcessPool:  # a worker died since the last results came in
            self.broke = True
            return False
        self.running[fut] = (cfg, label, solo)
        return True

    def _fill(self) -> None:
        if self.broke:
            return
        if self.suspects:  # alone, so a worker that dies again names its episode
            if not self.running and self._submit(*self.suspects[0], solo=True):
                self.suspects.popleft()
            return
        while self.todo and len(self.running) < self.workers and self._submit(*self.todo[0], solo=False):
            self.todo.popleft()

    def _outcome(self, fut: Future) -> list[Record] | None:
        """The finished future's records; None when its worker pool broke (a suspect now)."""
        cfg, label, solo = self.running.pop(fut)
        exc = fut.exception()
        if exc is None:
            return fut.result()
        if isinstance(exc, BrokenProcessPool):
            self.broke = True
            if not solo:
                self.suspects.append((cfg, label))
                return None
        if isinstance(exc, KeyboardInterrupt):  # outside the job's own handling
            return [{"kind": "interrupted", "signal": signal_name(exc), "episode": cfg.seed, "cycle": None,
                     "hole": None, "phase": None, **_tag(label)}]
        why = "its worker process died" if isinstance(exc, BrokenProcessPool) else "the worker failed"
        return [{"kind": "error", "episode_seed": cfg.seed,
                 "error": f"{why} ({type(exc).__name__}: {exc})", **_tag(label)}]

    def __iter__(self) -> Iterator[list[Record]]:
        self.pool = self._new_pool()
        self._fill()
        while self.running or self.broke:
            if self.running:
                done, _ = wait(self.running, return_when=FIRST_COMPLETED)
                for fut in done:
                    records = self._outcome(fut)
                    if records is not None:
                        yield records
            if self.broke:  # every episode still in flight fails with the pool: then a fresh one
                for fut in wait(list(self.running)).done:
                    records = self._outcome(fut)
                    if records is not None:
                        yield records
                self.pool.shutdown(wait=False, cancel_futures=True)
                self.pool, self.broke = self._new_pool(), False
            self._fill()

    def _processes(self) -> list[Any]:
        return list((getattr(self.pool, "_processes", None) or {}).values())

    def stop(self, interrupted: bool, notify: Callable[[str], None] | None = None) -> list[list[Record]]:
        """Shut the pool down; when `interrupted`, first collect what the busy workers finished
        (see the module doc). Returns those records, one list per episode."""
        late: list[list[Record]] = []
        if self.pool is None:
            return late
        try:
            if interrupted and self.running:
                if notify:
                    notify(f"interrupted: {len(self.running)} worker(s) closing their episodes "
                           f"(up to {GRACE_S:.0f} s; interrupt again to stop them now)")
                for proc in self._processes():
                    if proc.pid is not None and proc.is_alive():
                        os.kill(proc.pid, signal.SIGINT)
                try:
                    wait(list(self.running), timeout=GRACE_S)
                except KeyboardInterrupt:  # a second one: stop waiting, keep what is in
                    pass
                for fut in [f for f in self.running if f.done()]:
                    records = self._outcome(fut)
                    if records is not None:
                        late.append(records)
        finally:
            procs = self._processes()
            self.pool.shutdown(wait=False, cancel_futures=True)
            if self.running:  # still busy: would keep this process from exiting
                for proc in procs:
                    if proc.is_alive():
                        proc.kill()
            self.pool = None
        return late
