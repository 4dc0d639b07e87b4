"""One insertion trial re-run alone into a rerun file, for ``serpar replay``.

A trial's draws, start and sensor noise come from (seed, trial) alone and its result does not
depend on its slot or neighbours (tasks/insertion_batch.py), so a failed trial of a large run
is recorded by running it again by itself: the batch pays nothing for recording, and the
re-run's outcome is checked against the run's. The file holds the trial scene's geoms once,
the moving bodies' poses and the signals once per control period (1 kHz), the phases and the
outcome as text, on the episode recordings' timeline (tasks/rerun_scene.py).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import mujoco.batch
import numpy as np

from serpar.sim.trial_scene import TrialIds
from serpar.tasks import rerun_scene
from serpar.tasks.insertion_batch import Trial, TrialConfig, run_trials
from serpar.tasks.trial_phases import (
    APPROACH,
    DONE,
    PUSH,
    SETTLE,
    TrialResult,
    TrialSlots,
    in_hole_frame,
)
from serpar.tasks.trial_start import place

PHASE_NAMES = {SETTLE: "settle (squeeze, hold, tare)", APPROACH: "approach (impedance, guarded)",
               PUSH: "push (force-position)", DONE: "done"}
SIGNALS = ("plate_force", "tip_x", "tip_y", "tip_z", "plate_shift_x", "plate_shift_y")
"""Per period: the plate's contact force on the part [N] (the period's last substep); the
journal tip in the hole's frame [mm] (z up the axis: the tip's depth is -tip_z); where the
platform has moved the hole from its start [mm]."""


class _Recorder:
    """The probe :func:`run_trials` calls after every period, for a batch of one trial."""

    def __init__(self, trial: Trial, path: Path, name: str) -> None:
        model = trial.model
        self.ids = TrialIds.of(model)
        data = mujoco.MjData(model)
        place(model, data, self.ids, trial.start)
        self.rec = rerun_scene.open_stream(path, name)
        rerun_scene.log_geometry(self.rec, model)
        self.poses = rerun_scene.PoseTrack(self.rec, model, data)
        self.t: list[float] = []
        self.rows: list[np.ndarray] = []
        self.phase = -1
        self.bound = False

    def __call__(self, batch: mujoco.batch.Batch, s: TrialSlots) -> None:
        t = float(s.t[0])
        if self.bound:
            self.poses.add(t, batch.bind("xpos")[0], batch.bind("xquat")[0])
        else:  # an output bound now reads zero until the next period fills it
            batch.bind("xpos"), batch.bind("xquat")
            self.bound = True
        ids = self.ids
        sites_x, sites_m = batch.bind("site_xpos"), batch.bind("site_xmat")
        tip = in_hole_frame(sites_x[:1], sites_m[:1], ids.tip_site, ids.hole_site)[0]
        force = float(np.linalg.norm(batch.bind("sensordata")[0, ids.plate_force]))
        self.t.append(t)
        self.rows.append(np.r_[force, tip * 1e3, s.shift[0, :2] * 1e3])
        phase = int(s.phase[0])
        if phase != self.phase:
            self.phase = phase
            rerun_scene.log_text(self.rec, "phase", PHASE_NAMES[phase], t)

    def close(self, result: TrialResult, expected: str | None) -> None:
        t = self.t[-1] if self.t else 0.0
        text = f"{result.outcome.value}: {result.reason}"
        if expected is not None and expected != result.outcome.value:
            text += f" (the run scored it {expected}: the re-run differs)"
        rerun_scene.log_text(self.rec, "events", text, t)
        self.poses.send(self.rec)
        if self.t:
            rows = np.array(self.rows)
            rerun_scene.send_signals(self.rec, np.array(self.t), dict(zip(SIGNALS, rows.T)))
        self.rec.flush()
        self.rec.disconnect()


def record_trial(trial: Trial, chamfer: float, cfg: TrialConfig, path: str | Path, name: str,
                 expected: str | None = None) -> TrialResult:
    """Run ``trial`` alone and write it to ``path`` (a .rrd); returns its result. ``expected``:
    the outcome the trial had in its run, said in the file when the re-run's differs."""
    recorder = _Recorder(trial, Path(path), name)
    result = run_trials([trial], chamfer, cfg, probe=recorder)[0]
    recorder.close(result, expected)
    return result
