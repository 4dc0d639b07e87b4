"""Step 6 for many trials at once: the episode's insertion over a batch of trial scenes.

Each trial runs the episode's insertion (tasks/insertion.py): a settle with the part squeezed
and the arm holding its start, the tare, the guarded approach along the measured journal axis
under impedance control until the wrench estimate reads contact, then the force-position push
ramped to F_d until the TCP stops advancing or the time runs out; scored on the simulator's
truth as the episode scores it. The controller is :class:`BatchArmController` (bit for bit
the episode's at a batch of one); the plant is a ``mujoco.batch.Batch`` stepped one control
period at a time by ``rollout`` (the command held over the period, the substep that switches
it given the mean of old and new as in controllers/cell_runtime.py, the torque sensors' period
mean from the recorded substeps with the episode's :class:`TorqueADC` weights). No Python loop
over trials runs within a period.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import mujoco
import mujoco.batch
import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_controller import ArmControllerConfig, ControlLaw, controller_config
from serpar.controllers.arm_sensors import TorqueADC
from serpar.controllers.batch_controller import BatchArmController
from serpar.controllers.batch_sensors import Seed
from serpar.controllers.cell_runtime import MAX_SPEED
from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.arm import GRIP_ACTUATOR
from serpar.sim.arm_drive import ArmIndex
from serpar.sim.trial_scene import TrialIds
from serpar.tasks.episode_config import Outcome
from serpar.tasks.episode_steps import FOLLOW_DEADBAND, FOLLOW_STOP_ABOVE
from serpar.tasks.hole_cycle import GRASP_SQUEEZE
from serpar.tasks.insertion import InsertionConfig
from serpar.tasks.trial_start import TrialStart, write_start

Arr = NDArray[np.float64]
SETTLE, APPROACH, PUSH, DONE = 0, 1, 2, 3
FOLLOW_EVERY = 10
"""Control periods between the platform's corrections (100 Hz, tasks/episode_steps.py)."""
CONTACT_FORCE_N = 0.05
"""A period-mean plate force above this is first contact (tasks/insertion.py)."""


@dataclass(frozen=True)
class TrialConfig:
    insertion: InsertionConfig = field(default_factory=InsertionConfig)
    settle_s: float = 0.15
    """Squeeze and hold before the approach: the pads' grip builds up and the wrench estimate
    has its tare window (0.1 s) of contact-free readings."""
    follow_stop_above: float = FOLLOW_STOP_ABOVE
    """The platform follows the TCP's sideways wander until the measured tip is this far above
    the believed entry, every 10 periods past a 2 um dead band, as the episode's
    (tasks/episode_steps.py HoleUnderJournal)."""
    law: ControlLaw = ControlLaw.FORCE_POSITION
    controller: ArmControllerConfig = field(default_factory=lambda: controller_config(True))
    squeeze_n: float = GRASP_SQUEEZE

    def __post_init__(self) -> None:
        if self.law is ControlLaw.JOINT_PD:
            raise ConfigError("insertion law: force_position or impedance")
        window = self.controller.wrench.tare_window / self.controller.rate_hz
        if not window <= self.settle_s <= 5.0:
            raise ConfigError(f"settle_s {self.settle_s}: valid {window:g}..5 s (the tare's window)")


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
class _Slots:
    """Per-trial state of the insertion (arrays over the batch)."""

    n: int
    settle_s: float
    bore_start: float
    """Depth below the entry where the straight bore begins (the chamfer's foot) [m]."""
    mouth_radius: Arr
    """Each trial's hole radius at its entry (bore radius + chamfer) [m]: a tip ending farther off
    the axis missed the hole (past the plate's edge, where a neighbour hole would be)."""
    phase: NDArray[np.int8] = field(init=False)
    t: Arr = field(init=False)
    t_phase: Arr = field(init=False)
    t_begin: Arr = field(init=False)
    """When the approach began (the time limit counts from there)."""
    timed_out: NDArray[np.bool_] = field(init=False)
    start: Arr = field(init=False)
    held: Arr = field(init=False)
    peak: Arr = field(init=False)
    t_contact: Arr = field(init=False)
    lateral: Arr = field(init=False)
    fault: list[str] = field(init=False)
    calls: NDArray[np.int64] = field(init=False)
    """Approach periods so far (the platform acts every FOLLOW_EVERY)."""
    shift: Arr = field(init=False)
    """Where the platform last put the hole, against its start [m]."""

    def __post_init__(self) -> None:
        n = self.n
        self.phase = np.full(n, SETTLE, dtype=np.int8)
        self.t, self.t_phase, self.t_begin = np.zeros(n), np.zeros(n), np.zeros(n)
        self.timed_out = np.zeros(n, dtype=bool)
        self.start, self.held = np.zeros((n, 3)), np.zeros((n, 3))
        self.peak, self.t_contact, self.lateral = np.zeros(n), np.full(n, np.nan), np.full(n, np.nan)
        self.fault = [""] * n
        self.calls, self.shift = np.zeros(n, dtype=np.int64), np.zeros((n, 3))


def _in_hole_frame(xpos: Arr, xmat: Arr, site: int, hole: int) -> Arr:
    rot = xmat[:, hole].reshape(-1, 3, 3)
    return np.einsum("nji,nj->ni", rot, xpos[:, site] - xpos[:, hole])


@dataclass(frozen=True, eq=False)
class Trial:
    """One trial: its scene (with its part diameters), start and sensor-noise stream."""

    model: mujoco.MjModel
    start: TrialStart
    seed: Seed
    hole_diameter: float


def run_trials(trials: Sequence[Trial], chamfer: float, cfg: TrialConfig = TrialConfig(),
               nthread: int = 1, on_period: Callable[[int], None] | None = None) -> list[TrialResult]:
    """Run one batch of trials to their ends (their models must share one spec's sizes; the
    bore's entry ``chamfer`` [m]); ``on_period(active)`` after every control period."""
    n = len(trials)
    if not n:
        raise ConfigError("run_trials needs at least one trial")
    models, starts, seeds = [t.model for t in trials], [t.start for t in trials], [t.seed for t in trials]
    model, ins = models[0], cfg.insertion
    ids, arm = TrialIds.of(model), ArmIndex.from_model(model, names.ARM)
    batch = mujoco.batch.Batch(model, n, nthread)
    batch.set_models(list(models))
    ctl = BatchArmController(n, model.opt.timestep, cfg.controller, seeds=list(seeds), nthread=nthread)
    substeps, dt = ctl.substeps, ctl.dt
    adc = TorqueADC(arm, substeps).weights
    qpos, qvel, ctrl = batch.bind("qpos"), batch.bind("qvel"), batch.bind("ctrl")
    for output in ("site_xpos", "site_xmat", "sensordata", "qfrc_bias"):
        batch.bind(output)  # an output bound later reads zero until the next call fills it
    _place(batch, starts, ids, arm, model)
    grip = model.actuator(names.ARM + GRIP_ACTUATOR).id
    ctrl[:, grip] = cfg.squeeze_n
    s = _Slots(n, cfg.settle_s, chamfer, np.array([t.hole_diameter / 2 + chamfer for t in trials]))
    rot = np.stack([st.rot for st in starts])
    axis = np.stack([st.axis for st in starts])
    goal = np.stack([st.seat for st in starts]) + ins.overtravel * axis
    window = round(ins.stall_s / dt) + 1
    ring, nring = np.zeros((n, window)), np.zeros(n, dtype=np.int64)
    ctl.track(np.stack([st.start for st in starts]), rot)
    batch.forward()
    tau = batch.bind("sensordata")[:, arm.torque_adr].copy()
    force_adr = np.arange(ids.plate_force.start, ids.plate_force.stop)
    control = np.zeros((n, substeps, model.nu))
    mocap = batch.bind("mocap_pos")
    plate0 = mocap[:, ids.plate_mocap].copy()
    stop_after = np.array([st.height for st in starts]) - cfg.follow_stop_above
    while (active := np.flatnonzero(s.phase != DONE)).size:
        q, dq = qpos[:, arm.qpos].copy(), qvel[:, arm.dof].copy()
        _targets(ctl, s, active, rot, axis, goal, ins, dt)
        _follow(ctl, s, active, axis, mocap, ids.plate_mocap, plate0, stop_after)
        held_cmd = ctrl[:, arm.actuators].copy()
        new = ctl.update(q, dq, tau)
        control[:, :, :] = ctrl[:, None, :]
        control[:, :, arm.actuators] = new[:, None, :]
        control[:, 0, arm.actuators] = 0.5 * (held_cmd + new)
        try:
            rec = batch.rollout(substeps, control[active], record=("sensordata",), ids=active)
        except mujoco.batch.SimulationError as exc:
            for i in active[batch.status[active] != 0]:
                s.fault[i] = batch.error(int(i)) or str(exc)
            rec = {"sensordata": np.zeros((active.size, substeps, model.nsensordata))}
        ctrl[active[:, None], arm.actuators] = new[active]
        sens = rec["sensordata"]
        tau[active] = np.einsum("s,nsj->nj", adc, sens[:, :, arm.torque_adr])
        force = np.linalg.norm(sens[:, :, force_adr], axis=2).mean(axis=1)
        s.t[active] += dt
        _score(batch, s, active, force, ids)
        _stall(ctl, s, active, axis, ring, nring, window, ins)
        _health(batch, s, active, qvel)
        if on_period is not None:
            on_period(int(active.size))
    return _classify(batch, s, ids, ins)


def _place(batch: mujoco.batch.Batch, starts: Sequence[TrialStart], ids: TrialIds, arm: ArmIndex,
           model: mujoco.MjModel) -> None:
    """Every trial's start state into the batch's rows."""
    qpos, qvel = batch.bind("qpos"), batch.bind("qvel")
    batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
    for i, st in enumerate(starts):
        write_start(qpos[i], ids, st)
    qvel[:] = 0.0
    batch.forward()
    # The arm starts holding itself against gravity, as it was at the hover.
    batch.bind("ctrl")[:, arm.actuators] = batch.bind("qfrc_bias")[:, arm.dof]


def _targets(ctl: BatchArmController, s: _Slots, active: NDArray[np.intp], rot: Arr, axis: Arr,
             goal: Arr, ins: InsertionConfig, dt: float) -> None:
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
                           np.einsum("ni,ni->n", axis[a], goal[a] - s.start[a]))
        ctl.track(s.start[a] + along[:, None] * axis[a], rot[a],
                  np.concatenate([ins.approach_speed * axis[a], np.zeros((a.size, 3))], axis=1),
                  law=ControlLaw.IMPEDANCE, ids=a)
        touched = a[ctl.measured_push()[a] > ins.contact_n]
        s.held[touched], s.t_phase[touched], s.phase[touched] = pos[touched], s.t[touched], PUSH
    p = active[s.phase[active] == PUSH]
    if p.size:
        since = s.t[p] - s.t_phase[p]
        ramp = np.where(since >= ins.force_ramp_s, ins.force_n, ins.contact_n + (
            ins.force_n - ins.contact_n) * since / max(ins.force_ramp_s, 1e-12))
        ctl.track(s.held[p], rot[p], law=ControlLaw.FORCE_POSITION, force_axis=axis[p], force=ramp,
                  ids=p)


def _follow(ctl: BatchArmController, s: _Slots, active: NDArray[np.intp], axis: Arr, mocap: Arr,
            plate: int, plate0: Arr, stop_after: Arr) -> None:
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
    travelled = np.einsum("ni,ni->n", shift, axis[a])
    shift -= travelled[:, None] * axis[a]
    moved = (travelled <= stop_after[a]) & (np.linalg.norm(shift - s.shift[a], axis=1) >= FOLLOW_DEADBAND)
    a, shift = a[moved], shift[moved]
    s.shift[a] = shift
    mocap[a, plate] = plate0[a] + shift


def _score(batch: mujoco.batch.Batch, s: _Slots, active: NDArray[np.intp], force: Arr,
           ids: TrialIds) -> None:
    """Peak plate force (1 ms means) and, at first contact, the tip's lateral offset."""
    s.peak[active] = np.maximum(s.peak[active], force)
    first = active[(force > CONTACT_FORCE_N) & np.isnan(s.t_contact[active])]
    if first.size:
        xpos, xmat = batch.bind("site_xpos")[first], batch.bind("site_xmat")[first]
        tip = _in_hole_frame(xpos, xmat, ids.tip_site, ids.hole_site)
        s.t_contact[first], s.lateral[first] = s.t[first], np.hypot(tip[:, 0], tip[:, 1])


def _stall(ctl: BatchArmController, s: _Slots, active: NDArray[np.intp], axis: Arr, ring: Arr,
           nring: NDArray[np.int64], window: int, ins: InsertionConfig) -> None:
    """The push ends once ramped and the TCP advanced less than stall_speed over stall_s (the
    window, not one period: one encoder count is ~3 um at the TCP); or at the time limit."""
    p = active[s.phase[active] == PUSH]
    if p.size:
        pos, _ = ctl.nominal.tcp_pose()
        ring[p, nring[p] % window] = np.einsum("ni,ni->n", axis[p], pos[p])
        nring[p] += 1
        full = nring[p] >= window
        newest, oldest = ring[p, (nring[p] - 1) % window], ring[p, nring[p] % window]
        ramped = s.t[p] - s.t_phase[p] >= ins.force_ramp_s
        stalled = p[full & ramped & (newest - oldest < ins.stall_speed * ins.stall_s)]
        s.phase[stalled] = DONE
    moving = active[(s.phase[active] == APPROACH) | (s.phase[active] == PUSH)]
    out = moving[s.t[moving] - s.t_begin[moving] >= ins.time_limit_s - 1e-9]
    s.phase[out], s.timed_out[out] = DONE, True


def _health(batch: mujoco.batch.Batch, s: _Slots, active: NDArray[np.intp], qvel: Arr) -> None:
    """A trial the simulator could not finish ends as a fault (named), the others go on: a
    MuJoCo warning, a non-finite state or a body faster than MAX_SPEED (cell_runtime.py)."""
    warned = batch.warning[active, :, 0].sum(axis=1) > 0  # (nsim, mjNWARNING, [number, info])
    v = qvel[active]
    bad = warned | ~np.isfinite(v).all(axis=1) | (np.abs(np.nan_to_num(v, nan=np.inf)).max(axis=1) > MAX_SPEED)
    for i in active[bad]:
        if not s.fault[i]:
            s.fault[i] = ("MuJoCo warning" if warned[np.flatnonzero(active == i)[0]] else
                          "state blew up or went non-finite") + f" at t = {s.t[i]:.3f} s"
    for i in active:
        if s.fault[i]:
            s.phase[i] = DONE


def _classify(batch: mujoco.batch.Batch, s: _Slots, ids: TrialIds, ins: InsertionConfig
              ) -> list[TrialResult]:
    """The episode's outcome of each trial (tasks/insertion.py _classify), or sim_fault."""
    batch.forward()
    xpos, xmat = batch.bind("site_xpos"), batch.bind("site_xmat")
    shoulder = _in_hole_frame(xpos, xmat, ids.shoulder_site, ids.hole_site)[:, 2]
    tip = _in_hole_frame(xpos, xmat, ids.tip_site, ids.hole_site)
    tip_depth, tip_off = -tip[:, 2], np.hypot(tip[:, 0], tip[:, 1])
    out = []
    for i in range(s.n):
        t_ins = s.t[i] - s.t_contact[i] if np.isfinite(s.t_contact[i]) else float("nan")
        lateral, peak, short = s.lateral[i] * 1e3, float(s.peak[i]), float(shoulder[i])
        if s.fault[i]:
            outcome, reason = Outcome.SIM_FAULT, s.fault[i]
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
