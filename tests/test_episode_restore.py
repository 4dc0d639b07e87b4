"""Going on after a broken hole cycle: the state restored, the arm's controller reads the
restored arm, so the next move starts where the arm is (not where the broken cycle left the
measurement) and no torque limit is met."""

from __future__ import annotations

import numpy as np

from serpar.sim.arm import TORQUE_LIMITS
from serpar.tasks.episode import _Snapshot, build_runtime
from serpar.tasks.episode_config import EpisodeConfig
from serpar.tasks.hole_cycle import HAND_DOWN
from serpar.tasks.motions import move_tcp, tcp_pose


def test_the_move_after_a_restore_starts_at_the_restored_arm() -> None:
    rt, plate = build_runtime(EpisodeConfig(stewart_calibration="none"))
    rt.run(0.05)
    start, _ = tcp_pose(rt)
    snap = _Snapshot(rt, plate)
    move_tcp(rt, start + np.array([0.0, 0.08, -0.05]), HAND_DOWN, speed=0.2, settle_s=0.0)
    moved, _ = tcp_pose(rt)
    assert np.linalg.norm(moved - start) > 0.05
    snap.restore(rt, plate)
    restored, _ = tcp_pose(rt)
    assert np.linalg.norm(restored - start) < 1e-4  # the measurement is the restored arm's
    peak = np.zeros(7)

    def watch(r) -> None:
        peak[:] = np.maximum(peak, np.abs(r.arm.tau))

    rt.observers.append(watch)
    move_tcp(rt, start + np.array([0.03, 0.0, 0.0]), HAND_DOWN, speed=0.2, settle_s=0.0)
    assert np.all(peak < 0.8 * np.asarray(TORQUE_LIMITS)), peak
