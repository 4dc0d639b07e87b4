"""Do batched trials reproduce the episode's insertions? (``serpar montecarlo --validate``)

An episode runs as ``serpar run`` runs it; as each insertion starts (at the hover, after the
tare: where a trial starts), the cell's truth is read: the part's diameters,
how it sits in the grip, where its tip is against the hole's axis and how its axis leans
against the hole's. The same geometry becomes a trial (no vision error; the offset and the
lean are the truth's), run in the trial scene with the batched controller, and the two
outcomes and peak forces are set side by side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.checks.montecarlo import scene_config, trial_config
from serpar.checks.montecarlo_config import MonteCarloConfig
from serpar.controllers.batch_sensors import trial_seeds
from serpar.controllers.cell_runtime import CellRuntime
from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.arm import HOME_Q, TCP_SITE
from serpar.sim.trial_scene import TrialIds, build_trial_spec
from serpar.tasks.episode import HoleRecord, run_episode
from serpar.tasks.episode_config import EpisodeConfig
from serpar.tasks.insertion_batch import Trial, TrialResult, run_trials
from serpar.tasks.platform_model import prepare_models
from serpar.tasks.trial_start import TrialDraw, plan_start

PEAK_TOLERANCE = 0.05
"""The issue's bar: a reproduced insertion's peak force within 5 % of the episode's."""
NOISE_STREAMS = 4
"""Sensor-noise streams each insertion is replayed with: the first is the trial's own (the
row's outcome and peak); the others show how much the peak moves with the noise alone (on a
sub-micrometre fit an entry impact in one 1 ms period may or may not happen)."""


@dataclass(frozen=True)
class CellInsertion:
    """One insertion of an episode where its trial would start, and how it ended."""

    hole: int
    conductor: int
    draw: TrialDraw
    height_mm: float
    """The true tip above the true hole entry."""
    record: HoleRecord | None = None


@dataclass(frozen=True)
class ValidationRow:
    episode: CellInsertion
    trial: TrialResult
    stream_peaks: tuple[float, ...]
    """The trial's peak force [N] with each sensor-noise stream (the first is ``trial``'s)."""

    @property
    def same_outcome(self) -> bool:
        return self.episode.record is not None and self.trial.outcome.value == self.episode.record.outcome

    @property
    def peak_ratio(self) -> float:
        rec = self.episode.record
        return float("nan") if rec is None else self.trial.peak_force_n / rec.peak_force_n

    def as_dict(self) -> dict[str, object]:
        rec = self.episode.record
        d = self.episode.draw
        return {"hole": self.episode.hole, "conductor": self.episode.conductor,
                "clearance_um": (d.hole_diameter - d.journal_diameter) * 1e6,
                "start_offset_mm": float(np.hypot(*d.hole_error) * 1e3),
                "start_tilt_deg": float(np.degrees(np.hypot(*d.vision_tilt))),
                "episode_outcome": None if rec is None else rec.outcome,
                "trial_outcome": self.trial.outcome.value,
                "episode_peak_n": None if rec is None else rec.peak_force_n,
                "trial_peak_n": self.trial.peak_force_n,
                "episode_misalignment_mm": None if rec is None else rec.lateral_misalignment_mm,
                "trial_misalignment_mm": self.trial.lateral_misalignment_mm,
                "trial_peak_streams_n": list(self.stream_peaks),
                "same_outcome": self.same_outcome, "peak_ratio": self.peak_ratio}


def read_insertion(rt: CellRuntime, hole: int, conductor: int) -> CellInsertion:
    """The cell's truth at the trial's start: diameters, grasp, tip offset and lean."""
    m, d, scene = rt.scene.model, rt.scene.data, rt.scene
    prefix = names.conductor(conductor)
    tip, shoulder = d.site_xpos[m.site(prefix + "tip").id], d.site_xpos[m.site(prefix + "shoulder").id]
    h = int(scene.hole_sites[hole])
    hole_pos, hole_rot = d.site_xpos[h], d.site_xmat[h].reshape(3, 3)
    tcp = m.site(names.ARM + TCP_SITE).id
    tcp_pos, tcp_rot = d.site_xpos[tcp], d.site_xmat[tcp].reshape(3, 3)
    axis = (tip - shoulder) / np.linalg.norm(tip - shoulder)  # body -> tip
    in_hole = hole_rot.T @ (tip - hole_pos)
    lean = hole_rot.T @ axis  # against the hole's -z
    # The trial turns the hand so that its measured axis points down the (vertical) hole: a
    # vision error (a, b) about the TCP x, y leans the true axis by (a, -b) in the world's x, y.
    tilt = (float(lean[0]), float(-lean[1]))
    shoulder_tcp = tcp_rot.T @ (shoulder - tcp_pos)
    axis_tcp = tcp_rot.T @ axis
    draw = TrialDraw(float(scene.diameters.holes[hole]), float(scene.diameters.journals[conductor]),
                     float(scene.diameters.bodies[conductor]), float(shoulder_tcp[0]),
                     float(np.arctan2(axis_tcp[0], axis_tcp[2])), (0.0, 0.0), tilt,
                     (float(-in_hole[0]), float(-in_hole[1])))
    return CellInsertion(hole, conductor, draw, float(in_hole[2] * 1e3))


def episode_insertions(cfg: EpisodeConfig) -> list[CellInsertion]:
    """Run the episode; each insertion's start (on the Stewart path) with its hole record."""
    starts: dict[int, CellInsertion] = {}
    records: list[HoleRecord] = []
    prepare_models([cfg])

    def on_insert(rt: CellRuntime, hole: int, conductor: int) -> None:
        starts[hole] = read_insertion(rt, hole, conductor)

    run_episode(cfg, calibrated_pairs(cfg.camera_width), on_record=records.append, on_insert=on_insert)
    out = []
    for rec in records:
        if rec.hole in starts:
            s = starts[rec.hole]
            out.append(CellInsertion(s.hole, s.conductor, s.draw, s.height_mm, rec))
    return out


def replay_as_trials(insertions: list[CellInsertion], threads: int = 2,
                     streams: int = 1) -> list[ValidationRow]:
    """Each insertion's start as a trial, all in one batch, with ``streams`` sensor-noise
    streams each (the first, ``trial_seeds(0, [k])``, gives the row's trial)."""
    mc = MonteCarloConfig()
    scene = scene_config(mc)
    trials = []
    for k, ins in enumerate(insertions):
        d = ins.draw
        model = build_trial_spec(scene, d.hole_diameter, d.journal_diameter, d.body_diameter).compile()
        start = plan_start(model, TrialIds.of(model), d, np.asarray(scene.entry),
                           scene.conductor.journal_length, np.array(HOME_Q), ins.height_mm * 1e-3)
        trials += [Trial(model, start, trial_seeds(s, [k])[0], d.hole_diameter) for s in range(streams)]
    results = run_trials(trials, scene.chamfer, trial_config(mc), threads)
    return [ValidationRow(ins, results[k * streams],
                          tuple(r.peak_force_n for r in results[k * streams:(k + 1) * streams]))
            for k, ins in enumerate(insertions)]


def validate(holes: int, seed: int, threads: int = 2, streams: int = NOISE_STREAMS) -> dict[str, object]:
    """An episode of ``holes`` holes (seed ``seed``) against its insertions replayed as trials:
    the rows, how many outcomes agree and how many peaks are within 5 % (each trial also run
    with ``streams`` - 1 further sensor-noise streams: its peak's spread per row)."""
    if streams < 1:
        raise ConfigError(f"--streams {streams}: at least 1 sensor-noise stream")
    rows = replay_as_trials(episode_insertions(EpisodeConfig(seed=seed, holes=holes)), threads, streams)
    peaks = [abs(r.peak_ratio - 1.0) <= PEAK_TOLERANCE for r in rows]
    return {"episode_seed": seed, "insertions": len(rows), "noise_streams": streams,
            "same_outcome": sum(r.same_outcome for r in rows), "peak_within_5pct": sum(peaks),
            "rows": [r.as_dict() for r in rows]}
