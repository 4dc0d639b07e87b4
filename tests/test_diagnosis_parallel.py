"""A diagnosis's independent fits side by side (diagnosis/parallel.py): forked workers give the
same numbers as one fit after the other, in order, failures included."""

from __future__ import annotations

import multiprocessing
import os
import numpy as np
import pytest

from serpar.diagnosis.parallel import run_all
from serpar.diagnosis.select import SelectConfig, diagnose
from serpar.errors import IdentificationError
from tests.test_diagnosis_engine import Line


def _pid() -> int:
    return os.getpid()


def _fails() -> int:
    raise ValueError("singular")


def test_jobs_run_in_other_processes_and_come_back_in_order() -> None:
    events: list[tuple[str, int]] = []
    got = run_all([lambda k=k: k * k for k in range(7)], workers=2,
                  event=lambda what, i: events.append((what, i)))
    assert got == [(True, k * k) for k in range(7)]
    assert sorted(i for what, i in events if what == "start") == list(range(7))
    assert sorted(i for what, i in events if what == "done") == list(range(7))
    started: list[int] = []
    took: dict[int, float] = {}
    got = run_all([lambda k=k: k for k in range(5)], workers=2, first=[4, 3, 2, 1, 0],
                  event=lambda what, i: started.append(i) if what == "start" else None,
                  seconds=took)
    assert got == [(True, k) for k in range(5)] and started == [4, 3, 2, 1, 0]
    assert sorted(took) == list(range(5)) and all(t >= 0 for t in took.values())
    with pytest.raises(ValueError, match="not an order"):
        run_all([lambda: 1, lambda: 2], workers=2, first=[0, 0])
    pids = {p for ok, p in run_all([_pid] * 4, workers=2)}
    assert os.getpid() not in pids and len(pids) >= 1


def test_a_failing_job_is_returned_not_raised() -> None:
    for workers in (1, 2):
        got = run_all([lambda: 1, _fails, lambda: 3], workers=workers)
        assert [ok for ok, _ in got] == [True, False, True]
        assert isinstance(got[1][1], ValueError) and got[2][1] == 3


def _in_daemon(queue: multiprocessing.Queue) -> None:
    queue.put({p for _, p in run_all([_pid] * 3, workers=2)} == {os.getpid()})


def test_a_daemonic_process_fits_in_itself() -> None:
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_in_daemon, args=(queue,), daemon=True)
    child.start()
    assert queue.get(timeout=60) is True
    child.join(timeout=60)


def test_a_diagnosis_on_two_processes_is_the_serial_one() -> None:
    line = Line({"slope": 0.02, "amp": 0.05})
    serial = diagnose(line, cfg=SelectConfig(workers=1))
    forked = diagnose(line, cfg=SelectConfig(workers=2))
    assert {f.effect for f in serial.findings if f.established} == {"slope", "sine"}
    assert [f.as_dict() for f in forked.findings] == [f.as_dict() for f in serial.findings]
    assert forked.candidates == serial.candidates
    for name, block in serial.model["params"].items():
        assert np.array_equal(forked.model["params"][name]["values"], block["values"])
        assert np.array_equal(forked.model["params"][name]["std"], block["std"])


def test_workers_must_be_non_negative() -> None:
    with pytest.raises(IdentificationError, match="workers=-1"):
        SelectConfig(workers=-1)
