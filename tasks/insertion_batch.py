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
over trials runs within a period. A batch is a fixed number of slots: a trial that ends leaves
its slot to the next one waiting (streaming), so no thread idles while the slowest trial of a
batch finishes; a trial's result does not depend on its slot or its neighbours.
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
from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.arm import GRIP_ACTUATOR
from serpar.sim.arm_drive import ArmIndex
from serpar.sim.trial_scene import TrialIds
from serpar.tasks.episode_steps import FOLLOW_STOP_ABOVE
from serpar.tasks.hole_cycle import GRASP_SQUEEZE
from serpar.tasks.insertion import InsertionConfig
from serpar.tasks.trial_phases import (
    DONE,
    TrialResult,
    TrialSlots,
    classify,
    follow,
    health,
    score,
    stall,
    targets,
)
from serpar.tasks.trial_start import TrialStart, write_start

Arr = NDArray[np.float64]
__all__ = ["Trial", "TrialConfig", "TrialResult", "run_trials"]


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


@dataclass(frozen=True, eq=False)
class Trial:
    """One trial: its scene (with its part diameters), start and sensor-noise stream."""

    model: mujoco.MjModel
    start: TrialStart
    seed: Seed
    hole_diameter: float


def run_trials(trials: Sequence[Trial], chamfer: float, cfg: TrialConfig = TrialConfig(),
               nthread: int = 1, on_period: Callable[[int], None] | None = None,
               slots: int | None = None, on_result: Callable[[int, TrialResult], None] | None = None,
               probe: Callable[[mujoco.batch.Batch, TrialSlots], None] | None = None,
               engine: Callable[[mujoco.MjModel, int], mujoco.batch.Batch] | None = None
               ) -> list[TrialResult]:
    """Run ``trials`` to their ends in ``slots`` simulations at a time (default: all at once),
    each started as a slot frees (their models must share one spec's sizes; the bore's entry
    ``chamfer`` [m]); ``on_period(active)`` after every control period, ``on_result(i, r)`` as
    trial i ends. Each trial is read from ``trials`` once, when its slot takes it (a lazy
    sequence builds its scene then). ``probe(batch, slots)`` sees the plant and the trials'
    states after every period, before ended trials leave their slots (a recorder's hook).
    ``engine(model, slots)`` makes the plant's batch (default: ``mujoco.batch.Batch`` on
    ``nthread`` threads; tasks/warp_batch.py's ``WarpBatch`` for MuJoCo Warp)."""
    if not trials:
        raise ConfigError("run_trials needs at least one trial")
    runner = _Runner(trials, chamfer, cfg, nthread, min(len(trials), slots or len(trials)), engine)
    return runner.run(on_period, on_result, probe)


@dataclass
class _Runner:
    trials: Sequence[Trial]
    chamfer: float
    cfg: TrialConfig
    nthread: int
    n: int
    """Slots (simulations in the batch)."""
    engine: Callable[[mujoco.MjModel, int], mujoco.batch.Batch] | None = None
    results: list[TrialResult | None] = field(init=False)

    def __post_init__(self) -> None:
        self._first = self.trials[0]
        first = self._first.model
        self.ids, self.arm = TrialIds.of(first), ArmIndex.from_model(first, names.ARM)
        self.batch = (self.engine(first, self.n) if self.engine is not None
                      else mujoco.batch.Batch(first, self.n, self.nthread))
        self.models = [first] * self.n  # each slot's trial model, set as it loads
        self.ctl = BatchArmController(self.n, first.opt.timestep, self.cfg.controller,
                                      seeds=[self._first.seed] * self.n, nthread=self.nthread)
        for output in ("site_xpos", "site_xmat", "sensordata", "qfrc_bias"):
            self.batch.bind(output)  # an output bound later reads zero until the next call fills it
        self.grip = first.actuator(names.ARM + GRIP_ACTUATOR).id
        self.tau = np.zeros((self.n, len(self.arm.dof)))
        window = round(self.cfg.insertion.stall_s / self.ctl.dt) + 1
        self.s = TrialSlots(self.n, self.cfg.settle_s, self.chamfer, window)
        self.occupant = np.full(self.n, -1)
        self.next = 0
        self.results = [None] * len(self.trials)

    def _load(self, slots: NDArray[np.intp]) -> None:
        """The next waiting trials into ``slots``, at their start, the arm holding itself against
        gravity as it was at the hover, the part squeezed, a fresh controller."""
        k = np.arange(self.next, self.next + slots.size)
        self.next += slots.size
        trials = [self._first if i == 0 else self.trials[int(i)] for i in k]
        for slot, t in zip(slots, trials):
            if (t.model.sensor_delay[self.arm.torque_sensors].any()
                    or t.model.actuator_delay[self.arm.actuators].any()):
                raise ConfigError("a trial's torque sensors or arm actuators have a delay: the "
                                  "batch's period mean is the undelayed one "
                                  "(controllers/arm_sensors.py TorqueADC)")
            self.models[slot] = t.model
        batch, arm, ids = self.batch, self.arm, self.ids
        batch.set_models(self.models)
        batch.reset(ids=slots, stage=mujoco.mjtStage.mjSTAGE_NONE)
        qpos = batch.bind("qpos")
        for slot, t in zip(slots, trials):
            write_start(qpos[slot], ids, t.start)
        batch.bind("qvel")[slots] = 0.0
        batch.forward(ids=slots)
        ctrl = batch.bind("ctrl")
        ctrl[slots[:, None], arm.actuators] = batch.bind("qfrc_bias")[slots[:, None], arm.dof]
        ctrl[slots, self.grip] = self.cfg.squeeze_n
        self.ctl.restart(slots, [t.seed for t in trials])
        starts = [t.start for t in trials]
        rot, axis = np.stack([st.rot for st in starts]), np.stack([st.axis for st in starts])
        self.ctl.track(np.stack([st.start for st in starts]), rot, ids=slots)
        goal = np.stack([st.seat for st in starts]) + self.cfg.insertion.overtravel * axis
        stop_after = np.array([st.height for st in starts]) - self.cfg.follow_stop_above
        plate0 = batch.bind("mocap_pos")[slots, ids.plate_mocap].copy()
        mouth = np.array([t.hole_diameter / 2 + self.chamfer for t in trials])
        self.s.load(slots, rot, axis, goal, stop_after, plate0, mouth)
        self.tau[slots] = batch.bind("sensordata")[slots[:, None], arm.torque_adr]
        self.occupant[slots] = k

    def _finish(self, on_result: Callable[[int, TrialResult], None] | None) -> None:
        """Score the trials that ended and start waiting ones in their slots."""
        ended = np.flatnonzero((self.s.phase == DONE) & (self.occupant >= 0))
        if not ended.size:
            return
        for slot, r in zip(ended, classify(self.batch, self.s, ended, self.ids, self.cfg.insertion)):
            k = int(self.occupant[slot])
            self.results[k] = r
            if on_result is not None:
                on_result(k, r)
        self.occupant[ended] = -1
        waiting = min(ended.size, len(self.trials) - self.next)
        if waiting:
            self._load(ended[:waiting])

    def run(self, on_period: Callable[[int], None] | None,
            on_result: Callable[[int, TrialResult], None] | None,
            probe: Callable[[mujoco.batch.Batch, TrialSlots], None] | None = None) -> list[TrialResult]:
        self._load(np.arange(self.n))
        batch, arm, ins, s, ctl = self.batch, self.arm, self.cfg.insertion, self.s, self.ctl
        qpos, qvel, ctrl, mocap = batch.bind("qpos"), batch.bind("qvel"), batch.bind("ctrl"), batch.bind("mocap_pos")
        substeps, dt, model = ctl.substeps, ctl.dt, self._first.model
        adc = TorqueADC(arm, substeps).weights
        force_adr = np.arange(self.ids.plate_force.start, self.ids.plate_force.stop)
        control = np.zeros((self.n, substeps, model.nu))
        while (active := np.flatnonzero(s.phase != DONE)).size:
            q, dq = qpos[:, arm.qpos].copy(), qvel[:, arm.dof].copy()
            targets(ctl, s, active, ins)
            follow(ctl, s, active, mocap, self.ids.plate_mocap)
            held_cmd = ctrl[:, arm.actuators].copy()
            new = ctl.update(q, dq, self.tau)
            control[:, :, :] = ctrl[:, None, :]
            control[:, :, arm.actuators] = new[:, None, :]
            control[:, 0, arm.actuators] = 0.5 * (held_cmd + new)
            try:
                rec = batch.rollout(substeps, control[active], record=("sensordata",), ids=active)
            except mujoco.batch.SimulationError as exc:
                for i in active[batch.status[active] != 0]:
                    s.fault[int(i)] = batch.error(int(i)) or str(exc)
                rec = {"sensordata": np.zeros((active.size, substeps, model.nsensordata))}
            ctrl[active[:, None], arm.actuators] = new[active]
            sens = rec["sensordata"]
            self.tau[active] = np.einsum("s,nsj->nj", adc, sens[:, :, arm.torque_adr])
            force = np.linalg.norm(sens[:, :, force_adr], axis=2).mean(axis=1)
            s.t[active] += dt
            score(batch, s, active, force, self.ids)
            stall(ctl, s, active, ins)
            health(batch, s, active, qvel, model.dof_length)
            if probe is not None:
                probe(batch, s)
            if on_period is not None:
                on_period(int(active.size))
            self._finish(on_result)
        return [r for r in self.results if r is not None]
