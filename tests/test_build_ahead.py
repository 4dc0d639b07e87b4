"""Trial scenes built ahead in worker processes (serpar.checks.build_ahead)."""

from __future__ import annotations

from functools import partial
from operator import pow

import mujoco
import numpy as np
import pytest

from serpar.checks.build_ahead import BuildAhead
from serpar.checks.montecarlo import build_trial
from serpar.checks.montecarlo_config import MonteCarloConfig
from serpar.errors import ConfigError


def test_results_come_back_in_order_each_once() -> None:
    with BuildAhead(partial(pow, 2), 0, 40, workers=2, window=4) as ahead:
        assert [ahead.get(k) for k in (0, 1, 2)] == [1, 2, 4]
        assert ahead.get(10) == 2**10  # a jump ahead: the builds go on from there
        assert ahead.get(11) == 2**11
        with pytest.raises(ConfigError, match="trial 5 was already taken"):
            ahead.get(5)  # skipped by the jump: dropped
        with pytest.raises(ConfigError, match="trial 11 was already taken"):
            ahead.get(11)


def test_one_worker_is_refused_with_the_reason() -> None:
    with pytest.raises(ConfigError, match="workers 1: >= 2"):
        BuildAhead(partial(pow, 2), 0, 4, workers=1)


def test_a_trial_built_in_a_worker_is_the_one_built_here() -> None:
    cfg = MonteCarloConfig()
    with BuildAhead(partial(build_trial, cfg, 3), 5, 7, workers=2) as ahead:
        there = ahead.get(5)
    here = build_trial(cfg, 3, 5)
    assert np.array_equal(there.start.q, here.start.q)
    assert there.hole_diameter == here.hole_diameter
    for field in ("geom_size", "geom_pos", "body_pos", "body_mass", "mesh_vert", "pair_solref"):
        assert np.array_equal(getattr(there.model, field), getattr(here.model, field)), field
    a, b = mujoco.MjData(there.model), mujoco.MjData(here.model)
    for d in (a, b):
        d.qpos[:] = there.model.qpos0
        mujoco.mj_step(there.model if d is a else here.model, d)
    assert np.array_equal(a.qacc, b.qacc)
