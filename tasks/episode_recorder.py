"""Recording an episode (``serpar run --record``): the schema's signals at 1 kHz
(docs/recording.md) and a rerun file with the scene, body poses, camera frames and phases.

An observer of the :class:`CellRuntime`, called after each control period's physics step.
Row k is time t_k, the start of period k: what the arm's sensors read at t_k (the
controller's input), the torque and wrench estimate it computed from them, and the plant
state at t_k (legs, platform, gripper, contact), kept from the previous call. After a state
restore (a broken cycle) the cell's clock jumps back; the recording's ``time`` goes on
(``x_sim_time`` is the cell's clock) and the period with the stale plant sample is skipped.

meta.json is there from the start and rewritten (atomically) after each hole: ``complete``
(false until the episode has ended normally), ``holes`` (each finished hole's outcome), and
for an episode that did not complete, ``ended`` (where it was interrupted, or its error).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
from pathlib import Path

import mujoco
import numpy as np

from serpar.controllers.cell_runtime import CellRuntime
from serpar.sim import channels as ch
from serpar.sim.contact import ContactForceProbe
from serpar.sim.recording import (
    PhaseSegment,
    Recording,
    RecordingMeta,
    SignalRecorder,
    write_recording,
)
from serpar.sim.scene import Scene
from serpar.sim.seat_lock import PLATE_BODY
from serpar.sim.strict_json import dumps
from serpar.tasks import rerun_scene

POSE_HZ = 50.0
"""Body poses for the rerun file (the signals are at the control rate)."""
RRD_NAME = "episode.rrd"
META_NAME = "meta.json"
SIGNALS_NAME = "signals.parquet"
WRITING = ".writing"
"""Sub-folder the tables are written into before they are moved in place."""


ARM = (ch.TIME, *ch.Q, *ch.DQ, *ch.TAU_J, *ch.TAU_J_D, *ch.F_EXT, ch.M_LOAD, *ch.F_X_CLOAD,
       *ch.TCP_POSITION, *ch.TCP_QUAT)
PLANT = (*ch.LEG_CMD, *ch.LEG, *ch.PLATFORM_POSITION, *ch.PLATFORM_QUAT, ch.GRIPPER_WIDTH,
         *ch.CONTACT_FORCE)
SIM_TIME = ch.USER_PREFIX + "sim_time"
CHANNELS = (ARM[0], ch.PHASE, *ARM[1:], *PLANT, SIM_TIME)
_I = {c: i for i, c in enumerate(c for c in CHANNELS if c != ch.PHASE)}


def _span(first: str, last: str) -> slice:
    return slice(_I[first], _I[last] + 1)


Q, DQ, TJ, TJD = (_span(c[0], c[-1]) for c in (ch.Q, ch.DQ, ch.TAU_J, ch.TAU_J_D))
F, EE_P, EE_Q = (_span(c[0], c[-1]) for c in (ch.F_EXT, ch.TCP_POSITION, ch.TCP_QUAT))
PL = _span(PLANT[0], PLANT[-1])
LOAD_MASS, LOAD_COM = _I[ch.M_LOAD], _span(ch.F_X_CLOAD[0], ch.F_X_CLOAD[-1])
NOTES = {
    "time": "start of each 1 ms control period; continues across state restores (x_sim_time is the cell's clock)",
    "q, dq, tau_J": "the arm's sensor model (20-bit encoders, velocity and joint torque noise, torque bias "
                    "drift); q, dq at the period's start, tau_J the mean over the period that ended there",
    "m_load, F_x_Cload": "the load the task declared when it grasped a part (libfranka setLoad: nominal "
                         "mass, CoM in the flange frame), 0 with an empty hand",
    "tau_J_d": "joint torques commanded from that sample (saturated), applied over the period",
    "O_F_ext_hat_K": "the controller's external wrench estimate at the TCP, arm base frame (zeroed by each tare)",
    "O_T_EE": "TCP pose from the nominal arm model at the measured joints, arm base frame",
    "leg_cmd, leg": "leg lengths l_min + stroke: commanded, and the simulated stroke (no encoder noise; "
                    "the hidden leg-length errors are not in either)",
    "platform": "true platform pose (site platform_centre) in the Stewart base frame",
    "contact_force": "total contact force the conductors exert on the baseplate, world frame, "
                     "at the period's last physics substep (not a 1 ms mean); seated parts' weight included",
}


def _plate_load_probe(scene: Scene) -> ContactForceProbe:
    """Contact force on the plate from the conductors."""
    m = scene.model
    plate = np.flatnonzero(m.geom_bodyid == m.body(PLATE_BODY).id)
    parts = np.flatnonzero(np.isin(m.geom_bodyid, scene.conductor_bodies))
    return ContactForceProbe(m, plate, parts)


class EpisodeRecorder:
    """Attach with ``rt.observers.append(recorder)`` (and ``camera.on_frames = recorder.frames``);
    :meth:`close` writes signals, meta.json and the rerun file into `folder`."""

    def __init__(self, rt: CellRuntime, folder: str | Path, model: dict[str, object],
                 name: str = "episode") -> None:

        self.rt, self.folder, self.model = rt, Path(folder), model
        self.folder.mkdir(parents=True, exist_ok=True)
        for stale in (META_NAME, SIGNALS_NAME, RRD_NAME):  # a previous recording's (--force)
            (self.folder / stale).unlink(missing_ok=True)
        self.complete = False
        """Set once the episode has ended normally; meta.json says so when written."""
        self.ended: dict[str, object] | None = None
        """Why an incomplete episode ended: {"interrupted": {...}} or {"error": "..."}."""
        self._holes: list[dict[str, object]] = []
        m, d = rt.scene.model, rt.scene.data
        self._dt = rt.dt
        self._signals = SignalRecorder(CHANNELS, capacity=1 << 16)
        self._row = np.zeros(len(_I))
        self._plant = np.zeros(PL.stop - PL.start)
        self._quat = np.zeros(4)
        self._legs = np.array(rt.stewart.actuator_ids)
        self._leg_qpos = m.jnt_qposadr[m.actuator_trnid[self._legs, 0]]
        self._l_min = rt.stewart.geometry.l_min
        self._fingers = tuple(int(a) for a in rt.gripper.finger_qpos)
        base = rt.stewart.base_body  # welded to the world: its frame is read once
        self._base_rt, self._base_pos = d.xmat[base].reshape(3, 3).T.copy(), d.xpos[base].copy()
        self._plate_load = _plate_load_probe(rt.scene)
        self._t_prev, self._offset, self._last = rt.time, 0.0, -np.inf
        self._phase_names: list[str] = []
        self._phase_starts: list[float] = []
        self._calls, self._pose_every = 0, max(1, round(1.0 / (POSE_HZ * rt.dt)))
        self._rr = rerun_scene
        self._rec = rerun_scene.open_stream(self.folder / RRD_NAME, name)
        rerun_scene.log_geometry(self._rec, m)
        self._poses = rerun_scene.PoseTrack(self._rec, m, d)
        self._sample_plant()
        self._poses.sample(d, rt.time)
        self._write_meta(self.meta())

    def rebind(self, scene: Scene) -> None:
        """After the scene was recompiled (a seated part moved into the plate)."""
        self._plate_load = _plate_load_probe(scene)
        self._poses.rebind(scene.model)

    # --- the 1 kHz path ------------------------------------------------------------------
    def __call__(self, rt: CellRuntime) -> None:
        t_meas, self._t_prev = self._t_prev, rt.time
        if abs(rt.time - self._dt - t_meas) > 0.5 * self._dt:  # state restored: plant sample is stale
            self._offset = max(self._offset, self._last + 2 * self._dt - rt.time)  # time goes on
            self._sample_plant()
            return
        arm, row = rt.arm, self._row
        meas = arm.measurement
        t = t_meas + self._offset
        row[0] = t
        row[Q], row[DQ], row[TJ], row[TJD], row[F] = meas.q, meas.dq, meas.tau_J, arm.tau, arm.wrench
        row[LOAD_MASS], row[LOAD_COM] = rt.load_mass, rt.load_com
        pos, rot = arm.nominal.tcp_pose()  # the nominal model at the measured joints
        row[EE_P] = pos
        mujoco.mju_mat2Quat(self._quat, rot.ravel())
        row[EE_Q] = self._quat
        row[PL] = self._plant
        row[-1] = t_meas
        if not self._phase_names or rt.phase != self._phase_names[-1]:
            self._phase_names.append(rt.phase)
            self._phase_starts.append(t)
            self._rr.log_text(self._rec, "phase", rt.phase, t)
        self._last = t
        self._signals.append_row(row, rt.phase)
        self._sample_plant()
        self._calls += 1
        if self._calls % self._pose_every == 0:
            self._poses.sample(rt.scene.data, rt.time + self._offset)

    def _sample_plant(self) -> None:
        d, p, base = self.rt.scene.data, self._plant, PL.start
        p[0:6] = d.ctrl[self._legs]
        p[6:12] = d.qpos[self._leg_qpos]
        p[0:12] += self._l_min
        site, rbt = self.rt.stewart.platform_site, self._base_rt
        p[_I[ch.PLATFORM_POSITION[0]] - base:_I[ch.PLATFORM_POSITION[-1]] - base + 1] = rbt @ (d.site_xpos[site] - self._base_pos)
        mujoco.mju_mat2Quat(self._quat, (rbt @ d.site_xmat[site].reshape(3, 3)).ravel())
        p[_I[ch.PLATFORM_QUAT[0]] - base:_I[ch.PLATFORM_QUAT[-1]] - base + 1] = self._quat
        p[_I[ch.GRIPPER_WIDTH] - base] = d.qpos[self._fingers[0]] + d.qpos[self._fingers[1]]
        p[-3:] = self._plate_load.force(d)

    # --- rare events ---------------------------------------------------------------------
    def frames(self, frames: dict[str, np.ndarray]) -> None:
        """Camera hook: the shot's frames into the rerun file at the current time."""
        d = self.rt.scene.data
        self._rr.log_frames(self._rec, self.rt.scene.model, d, frames, self.rt.time + self._offset)

    def note(self, text: str) -> None:
        """An annotation in the rerun file (e.g. how a hole ended)."""
        self._rr.log_text(self._rec, "events", text, self.rt.time + self._offset)

    def hole_done(self, outcome: dict[str, object]) -> None:
        """A hole's outcome (its record, wall time left out so the file is reproducible) into
        meta.json now: what finished survives an interrupted or crashed run."""
        self._holes.append({k: v for k, v in outcome.items() if k not in ("kind", "wall_s")})
        self._write_meta(self.meta())

    def _write_meta(self, meta: RecordingMeta) -> None:
        status: dict[str, object] = {"complete": self.complete, "holes": self._holes}
        if not self.complete and self.ended is not None:
            status["ended"] = self.ended
        path = self.folder / META_NAME
        partial = path.with_name(f".{META_NAME}.{os.getpid()}.partial")
        partial.write_text(dumps({**meta.as_json(), **status}, indent=2))
        os.replace(partial, path)  # a reader sees the old file or the new one, never half

    def meta(self) -> RecordingMeta:
        """meta.json of what has been recorded so far."""
        sensors = self.rt.arm.config.sensors
        step = 2 * np.pi / sensors.encoder_counts_per_rev if sensors.encoder_counts_per_rev else 0.0
        sigma = {**{c: step / np.sqrt(12) for c in ch.Q},  # uniform quantisation error
                 **{c: sensors.velocity_noise_std for c in ch.DQ},
                 **{c: sensors.torque_noise_std for c in ch.TAU_J}}
        model = json.loads(dumps({**self.model, "arm_sensors": dataclasses.asdict(sensors),  # strict: NaN -> null
                                  "stewart_l_min": self._l_min, "channel_notes": NOTES}))
        time = self._signals.column(ch.TIME)  # a phase ends at its last row
        ends = [*time[np.searchsorted(time, self._phase_starts[1:]) - 1], self._last]
        phases = tuple(PhaseSegment(n, s, float(e)) for n, s, e in zip(self._phase_names, self._phase_starts, ends))
        return RecordingMeta(source="sim", sample_rate_hz=1.0 / self._dt, channels=CHANNELS, noise_sigma=sigma,
                             phases=phases, model=model)

    def recording(self) -> Recording:
        """What has been recorded so far, in the schema (DESIGN.md §4)."""
        return Recording(self.meta(), self._signals.table())

    def close(self) -> Path:
        """Write signals.parquet and meta.json (with :attr:`complete`, the holes and, if
        incomplete, :attr:`ended`), finish the rerun file; returns the folder."""
        rec, staging = self.recording(), self.folder / WRITING
        try:
            write_recording(staging, rec)  # whole tables first, then moved in place
            os.replace(staging / SIGNALS_NAME, self.folder / SIGNALS_NAME)
        finally:  # meta.json and the rerun file even when the table cannot be written
            self._write_meta(rec.meta)
            shutil.rmtree(staging, ignore_errors=True)
            self._poses.send(self._rec)
            self._rr.send_signals(self._rec, self._signals.column(ch.TIME),
                                  {c: self._signals.column(c) for c in CHANNELS
                                   if c not in (ch.TIME, ch.PHASE, SIM_TIME)})
            self._rec.flush()
            self._rec.disconnect()
        return self.folder
