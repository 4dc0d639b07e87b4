"""A sim2real rerun (:func:`serpar.checks.sim2real.rerun`) in a process of its own while this one
works on: a rerun runs its episodes one after another on one core, so beside it the diagnosis,
or a second rerun, takes the other cores.

The child is spawned, not forked (a process that has rendered passes its EGL context on to a
forked child, which can then hang in its first render), ends with its parent, and sends its
progress lines back to the parent's ``tick``. A Ctrl-C reaches it with its parent's (one
process group): it ends its episode as a rerun in the parent would, the finished holes and
their recording kept; :meth:`BackgroundRerun.stop` sends it SIGINT where only the parent got
one, and kills it after the grace period.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import shutil
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

from serpar.errors import ConfigError

Tick = Callable[[str], None]
GRACE_S = 120.0
"""How long an interrupted child gets to close its episode's recording before it is killed."""


def _child(parent: int, episodes: list, out: Path, plant_model: str | None,
           contact_friction: float | None, lines: multiprocessing.Queue) -> None:
    from serpar.checks.sim2real import rerun
    from serpar.tasks.worker_life import end_with_parent

    end_with_parent(parent)
    first = {"taken": False}

    def on_interrupt(signum: int, frame: object) -> None:
        # the first SIGINT (the terminal's, or stop()'s) ends the episode; a second one must
        # not cut its recording's writing short
        if not first["taken"]:
            first["taken"] = True
            raise KeyboardInterrupt(signal.Signals(signum).name)

    signal.signal(signal.SIGINT, on_interrupt)
    try:
        folders = rerun(episodes, out, plant_model, contact_friction,
                        lambda text: lines.put(("line", text)))
        lines.put(("done", [str(f) for f in folders]))
    except KeyboardInterrupt:
        lines.put(("interrupted", ""))
    except Exception as exc:  # the parent raises it: one line, the child's traceback not needed
        lines.put(("error", f"{type(exc).__name__}: {exc}"))


class BackgroundRerun:
    """``rerun(episodes, out, plant_model, contact_friction, tick)`` started now in a spawned
    process; :meth:`result` waits for its folders."""

    def __init__(self, episodes: list, out: Path, plant_model: str | None,
                 contact_friction: float | None, tick: Tick) -> None:
        ctx = multiprocessing.get_context("spawn")
        self.out, self.tick = out, tick
        self._lines: multiprocessing.Queue = ctx.Queue()
        self._end: tuple[str, object] | None = None
        self._proc = ctx.Process(target=_child, daemon=True,
                                 args=(os.getpid(), episodes, out, plant_model, contact_friction,
                                       self._lines))
        self._proc.start()
        self._drain = threading.Thread(target=self._forward, daemon=True)
        self._drain.start()

    def _forward(self) -> None:
        """Pass the child's progress lines on until it ends (or dies without a word)."""
        while True:
            try:
                kind, body = self._lines.get(timeout=1.0)
            except queue.Empty:
                if not self._proc.is_alive():
                    self._end = self._end or ("error", f"its process ended (exit code "
                                                        f"{self._proc.exitcode}) without a result")
                    return
                continue
            if kind == "line":
                self.tick(str(body))
            else:
                self._end = (kind, body)
                return

    def finished(self) -> bool:
        return self._end is not None or not self._drain.is_alive()

    def result(self) -> list[Path]:
        """The rerun's folders, once it has finished; its error as a ConfigError, a Ctrl-C it
        took as KeyboardInterrupt."""
        self._drain.join()
        self._proc.join()
        kind, body = self._end or ("error", "no result")
        if kind == "done":
            return [Path(p) for p in body]  # type: ignore[union-attr]
        if kind == "interrupted":
            raise KeyboardInterrupt(f"{self.out.name} rerun interrupted")
        raise ConfigError(f"the {self.out.name} rerun failed: {body}")

    def stop(self) -> None:
        """On an interrupt: SIGINT to the child if it is still running (once), then wait for it
        to close its recording; kill it after :data:`GRACE_S`."""
        if self._proc.is_alive() and self._end is None:
            try:
                os.kill(self._proc.pid, signal.SIGINT)  # type: ignore[arg-type]
            except ProcessLookupError:
                pass
        self._proc.join(GRACE_S)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()
        self._drain.join(timeout=2.0)

    def cancel(self) -> None:
        """Not needed after all: the child killed and its output removed."""
        if self._proc.is_alive():
            self._proc.kill()
        self._proc.join()
        self._drain.join(timeout=2.0)
        shutil.rmtree(self.out, ignore_errors=True)


Job = tuple[list, Path, "str | None", "float | None"]
"""A rerun's arguments: (episodes, out, plant_model, contact_friction)."""


def reruns_side_by_side(jobs: list[Job], tick: Tick, workers: int = 0) -> list[list[Path]]:
    """Every rerun of ``jobs``, at most ``workers`` at a time (0: one per core), each in its own
    process; their folders in the jobs' order. A rerun that fails stops the others (their
    finished holes kept) and raises; so does a Ctrl-C."""
    workers = workers or os.cpu_count() or 1
    todo = list(enumerate(jobs))[::-1]
    running: dict[int, BackgroundRerun] = {}
    folders: list[list[Path]] = [[] for _ in jobs]
    try:
        while todo or running:
            while todo and len(running) < workers:
                k, job = todo.pop()
                running[k] = BackgroundRerun(*job, tick)
            done = [k for k, run in running.items() if run.finished()]
            if not done:
                time.sleep(0.2)
            for k in done:
                folders[k] = running.pop(k).result()
    except BaseException:
        for run in running.values():
            run.stop()
        raise
    return folders
