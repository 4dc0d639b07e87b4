"""The phases of a batch of insertion trials, each a set of array operations over the trials in
it: the settle and tare, the guarded approach, the push, the platform following the TCP down,
the scoring on the simulator's truth, the health check and the outcome (tasks/insertion.py's
logic for one arm, here for many; tasks/insertion_batch.py runs them period by period)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import mujoco.batch
import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_controller import ControlLaw
from serpar.controllers.batch_controller import BatchArmController
from serpar.controllers.cell_runtime import MAX_SPEED
from serpar.sim.trial_scene import TrialIds
from serpar.tasks.episode_config import Outcome
from serpar.tasks.episode_steps import FOLLOW_DEADBAND
from serpar.tasks.insertion import InsertionConfig

Arr = NDArray[np.float64]
SETTLE, APPROACH, PUSH, DONE = 0, 1, 2, 3
FOLLOW_EVERY = 10
"""Control periods between the platform's corrections (100 Hz, tasks/episode_steps.py)."""
CONTACT_FORCE_N = 0.05
"""A period-mean plate force above this is first contact (tasks/insertion.py)."""


@dataclass(frozen=True)
class TrialResult:
    outcome: Outcome
    reason: str
    peak_force_n: float
    lateral_misalignment_mm: float
    insertion_time_s: float
    depth_shortfall_mm: float
    sim_time_s: float
    """Simulated time from the start of the approach to the end."""


@dataclass
class TrialSlots:
    """Per-slot state of a batch of trials (arrays over the slots); a slot holds one trial at a
    time and :meth:`load` starts the next one in it."""

    n: int
    settle_s: float
    bore_start: float
    """Depth below the entry where the straight bore begins (the chamfer's foot) [m]."""
    window: int
    """Control periods in the stall window (stall_s)."""

    def __post_init__(self) -> None:
        n = self.n
        self.phase = np.full(n, DONE, dtype=np.int8)
        self.t, self.t_phase, self.t_begin = np.zeros(n), np.zeros(n), np.zeros(n)
        """Time since the trial's start, since its phase began, since its approach began (the
        time limit counts from there)."""
        self.timed_out = np.zeros(n, dtype=bool)
        self.start, self.held = np.zeros((n, 3)), np.zeros((n, 3))
        self.peak, self.t_contact, self.lateral = np.zeros(n), np.full(n, np.nan), np.full(n, np.nan)
        self.fault: dict[int, str] = {}
        """Why a slot's trial could not be finished (its slot: a fault ends only that trial)."""
        self.calls, self.shift = np.zeros(n, dtype=np.int64), np.zeros((n, 3))
        """Approach periods so far (the platform acts every FOLLOW_EVERY); where the platform
        last put the hole, against its start [m]."""
        self.ring, self.nring = np.zeros((n, self.window)), np.zeros(n, dtype=np.int64)
        """The TCP's advance along the axis over the last stall window, per slot."""
        # the trial's geometry: hand rotation, insertion axis, approach goal, how far the
        # platform follows, the plate's start, the hole's radius at its entry
        self.rot, self.axis, self.goal = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)), np.zeros((n, 3))
        self.stop_after, self.plate0, self.mouth_radius = np.zeros(n), np.zeros((n, 3)), np.zeros(n)

    def load(self, slots: NDArray[np.intp], rot: Arr, axis: Arr, goal: Arr, stop_after: Arr,
             plate0: Arr, mouth_radius: Arr) -> None:
        """New trials in ``slots``: settling, nothing seen yet."""
        self.phase[slots] = SETTLE
        for a in (self.t, self.t_phase, self.t_begin, self.peak, self.start, self.held, self.shift,
                  self.ring):
            a[slots] = 0.0
        self.timed_out[slots], self.calls[slots], self.nring[slots] = False, 0, 0
        self.t_contact[slots], self.lateral[slots] = np.nan, np.nan
        for i in slots:
            self.fault.pop(int(i), None)
        self.rot[slots], self.axis[slots], self.goal[slots] = rot, axis, goal
        self.stop_after[slots], self.plate0[slots], self.mouth_radius[slots] = stop_after, plate0, mouth_radius


def in_hole_frame(xpos: Arr, xmat: Arr, site: int, hole: int) -> Arr:
    """A site's position in the hole's frame (x, y across the axis, z up it), per slot [m]."""
    rot = xmat[:, hole].reshape(-1, 3, 3)
    return np.einsum("nji,nj->ni", rot, xpos[:, site] - xpos[:, hole])


def targets(ctl: BatchArmController, s: TrialSlots, active: NDArray[np.intp], ins: InsertionConfig
            ) -> None:
    """Each trial's law and target for this period (tasks/insertion.py's _push)."""
    pos, _ = ctl.nominal.tcp_pose()
    pos = pos.copy()
    ready = active[(s.phase[active] == SETTLE) & (s.t[active] >= s.settle_s - 1e-9)]
    if ready.size:  # the insert begins: tare with the TCP free, approach from where it is
        ctl.tare(ready)
        s.start[ready], s.phase[ready] = pos[ready], APPROACH
        s.t_phase[ready] = s.t_begin[ready] = s.t[ready]
    a = active[s.phase[active] == APPROACH]
    if a.size:
        along = np.minimum((s.t[a] - s.t_phase[a]) * ins.approach_speed,
                           np.einsum("ni,ni->n", s.axis[a], s.goal[a] - s.start[a]))
        ctl.track(s.start[a] + along[:, None] * s.axis[a], s.rot[a],
                  np.concatenate([ins.approach_speed * s.axis[a], np.zeros((a.size, 3))], axis=1),
                  law=ControlLaw.IMPEDANCE, ids=a)
        touched = a[ctl.measured_push()[a] > ins.contact_n]
        s.held[touched], s.t_phase[touched], s.phase[touched] = pos[touched], s.t[touched], PUSH
    p = active[s.phase[active] == PUSH]
    if p.size:
        since = s.t[p] - s.t_phase[p]
        ramp = np.where(since >= ins.force_ramp_s, ins.force_n, ins.contact_n + (
            ins.force_n - ins.contact_n) * since / max(ins.force_ramp_s, 1e-12))
        ctl.track(s.held[p], s.rot[p], law=ControlLaw.FORCE_POSITION, force_axis=s.axis[p], force=ramp,
                  ids=p)


def follow(ctl: BatchArmController, s: TrialSlots, active: NDArray[np.intp], mocap: Arr, plate: int
           ) -> None:
    """The platform keeps the hole under the measured TCP during the approach (only sideways,
    only until the tip is ``follow_stop_above`` over the entry): the episode's HoleUnderJournal,
    with the plate moved where its legs would put it."""
    a = active[s.phase[active] == APPROACH]
    if not a.size:
        return
    s.calls[a] += 1
    a = a[s.calls[a] % FOLLOW_EVERY == 0]
    pos, _ = ctl.nominal.tcp_pose()
    shift = pos[a] - s.start[a]
    travelled = np.einsum("ni,ni->n", shift, s.axis[a])
    shift -= travelled[:, None] * s.axis[a]
    moved = (travelled <= s.stop_after[a]) & (np.linalg.norm(shift - s.shift[a], axis=1) >= FOLLOW_DEADBAND)
    a, shift = a[moved], shift[moved]
    s.shift[a] = shift
    mocap[a, plate] = s.plate0[a] + shift


def score(batch: mujoco.batch.Batch, s: TrialSlots, active: NDArray[np.intp], force: Arr,
           ids: TrialIds) -> None:
    """Peak plate force (1 ms means) and, at first contact, the tip's lateral offset."""
    s.peak[active] = np.maximum(s.peak[active], force)
    first = active[(force > CONTACT_FORCE_N) & np.isnan(s.t_contact[active])]
    if first.size:
        xpos, xmat = batch.bind("site_xpos")[first], batch.bind("site_xmat")[first]
        tip = in_hole_frame(xpos, xmat, ids.tip_site, ids.hole_site)
        s.t_contact[first], s.lateral[first] = s.t[first], np.hypot(tip[:, 0], tip[:, 1])


def stall(ctl: BatchArmController, s: TrialSlots, active: NDArray[np.intp], ins: InsertionConfig
          ) -> None:
    """The push ends once ramped and the TCP advanced less than stall_speed over stall_s (the
    window, not one period: one encoder count is ~3 um at the TCP); or at the time limit."""
    p = active[s.phase[active] == PUSH]
    if p.size:
        pos, _ = ctl.nominal.tcp_pose()
        w, ring, nring = s.window, s.ring, s.nring
        ring[p, nring[p] % w] = np.einsum("ni,ni->n", s.axis[p], pos[p])
        nring[p] += 1
        full = nring[p] >= w
        newest, oldest = ring[p, (nring[p] - 1) % w], ring[p, nring[p] % w]
        ramped = s.t[p] - s.t_phase[p] >= ins.force_ramp_s
        stalled = p[full & ramped & (newest - oldest < ins.stall_speed * ins.stall_s)]
        s.phase[stalled] = DONE
    moving = active[(s.phase[active] == APPROACH) | (s.phase[active] == PUSH)]
    out = moving[s.t[moving] - s.t_begin[moving] >= ins.time_limit_s - 1e-9]
    s.phase[out], s.timed_out[out] = DONE, True


def health(batch: mujoco.batch.Batch, s: TrialSlots, active: NDArray[np.intp], qvel: Arr,
           dof_length: Arr) -> None:
    """A trial the simulator could not finish ends as a fault (named), the others go on: a
    MuJoCo warning, a non-finite state or a point faster than MAX_SPEED (cell_runtime.py: each
    dof's speed times its ``dof_length``)."""
    warned = batch.warning[active, :, 0].sum(axis=1) > 0  # (nsim, mjNWARNING, [number, info])
    v = qvel[active] * dof_length
    bad = warned | ~np.isfinite(v).all(axis=1) | (np.abs(np.nan_to_num(v, nan=np.inf)).max(axis=1) > MAX_SPEED)
    for k in np.flatnonzero(bad):  # rare: the per-trial loop runs only over the broken ones
        s.fault.setdefault(int(active[k]), ("MuJoCo warning" if warned[k] else "state blew up or went "
                                             "non-finite") + f" at t = {s.t[active[k]]:.3f} s")
    for i in s.fault:
        s.phase[i] = DONE


def classify(batch: mujoco.batch.Batch, s: TrialSlots, slots: NDArray[np.intp], ids: TrialIds,
             ins: InsertionConfig) -> list[TrialResult]:
    """The episode's outcome of the trials in ``slots`` (tasks/insertion.py _classify), or
    sim_fault."""
    batch.forward(ids=slots)
    xpos, xmat = batch.bind("site_xpos"), batch.bind("site_xmat")
    shoulder = in_hole_frame(xpos, xmat, ids.shoulder_site, ids.hole_site)[:, 2]
    tip = in_hole_frame(xpos, xmat, ids.tip_site, ids.hole_site)
    tip_depth, tip_off = -tip[:, 2], np.hypot(tip[:, 0], tip[:, 1])
    out = []
    for i in slots:
        t_ins = s.t[i] - s.t_contact[i] if np.isfinite(s.t_contact[i]) else float("nan")
        lateral, peak, short = s.lateral[i] * 1e3, float(s.peak[i]), float(shoulder[i])
        if int(i) in s.fault:
            outcome, reason = Outcome.SIM_FAULT, s.fault[int(i)]
        elif peak > ins.damage_force_n:
            outcome, reason = Outcome.OVERFORCE, f"peak {peak:.1f} N > {ins.damage_force_n:g} N"
        elif short <= ins.seat_tolerance:
            outcome, reason = Outcome.SUCCESS, "seated"
        elif s.timed_out[i]:
            outcome, reason = Outcome.TIMEOUT, f"not seated after {ins.time_limit_s:g} s"
        elif tip_depth[i] <= s.bore_start or tip_off[i] > s.mouth_radius[i]:
            outcome, reason = Outcome.ALIGN_FAIL, f"tip on the rim or chamfer, {lateral:.3f} mm off axis"
        else:
            outcome, reason = Outcome.JAM, f"stuck {short * 1e3:.3f} mm short of seated"
        out.append(TrialResult(outcome, reason, peak, float(lateral), float(t_ins),
                               max(short, 0.0) * 1e3, float(s.t[i] - s.t_begin[i])))
    return out
