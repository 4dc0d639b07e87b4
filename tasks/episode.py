"""One assembly episode: the six steps of seed 000 §5.2 for each hole to fill.

1 locate conductors and 2 find empty holes (top cameras, one shot per cycle), 3 grasp and
carry, 4 in-hand inspection (inspect cameras), 5 the Stewart platform brings the hole under
the held journal (or, serial robot alone, the arm goes to the hole), 6 compliant insertion.
Each hole ends as an :class:`HoleRecord` with one outcome; a simulation that breaks down ends
its hole as a failure with the reason, and the episode goes on from the state before it. An
interrupt (Ctrl-C, or SIGTERM where the caller turns it into KeyboardInterrupt("SIGTERM")) ends
the episode with :class:`EpisodeInterrupted`: what finished, and where it stopped.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from serpar.controllers.arm_controller import ControlLaw, controller_config
from serpar.controllers.cell_runtime import CellRuntime
from serpar.controllers.plate_commander import PlateCommander
from serpar.errors import SerparError, UnstableSimulation
from serpar.sim.scene import Scene, build_scene
from serpar.tasks.episode_config import (
    EpisodeConfig,
    Outcome,
    cell_log,
    drive_friction,
    scene_config,
)
from serpar.tasks.episode_recorder import EpisodeRecorder
from serpar.tasks.episode_steps import CycleFailure, HoleCycle
from serpar.tasks.platform_model import believed_errors
from serpar.vision.camera import StereoPair
from serpar.vision.imaging import Camera, ImagingConfig

SETTLE_S = 0.3


@dataclass(frozen=True)
class HoleRecord:
    """How one hole cycle ended (JSON-ready)."""

    episode_seed: int
    cycle: int
    hole: int | None
    conductor: int | None
    outcome: str
    reason: str
    peak_force_n: float
    lateral_misalignment_mm: float
    insertion_time_s: float
    depth_shortfall_mm: float
    clearance_um: float
    """Drawn diametral clearance of the hole/journal pair (simulator's draw) [um]."""
    cycle_time_s: float
    """Simulated time of the whole cycle [s]."""
    wall_s: float
    sim_fault: bool = False
    """The cycle ended because the integration broke down (see reason)."""
    phase_s: dict[str, float] = dataclasses.field(default_factory=dict)
    """Simulated seconds per phase (locate, grasp, inspect, align, insert, release)."""
    physics_wall_s: float = 0.0
    """Wall time of the cycle's ``mj_step`` calls (MuJoCo's step timer) [s]."""
    physics_steps: int = 0
    """How many ``mj_step`` calls the cycle made."""

    def as_dict(self) -> dict[str, object]:
        return {"kind": "hole", **dataclasses.asdict(self)}


@dataclass(frozen=True)
class EpisodeSummary:
    seed: int
    holes: int
    """Holes finished (all the config's when complete)."""
    successes: int
    counts: dict[str, int]
    sim_time_s: float
    wall_s: float
    complete: bool = True
    """False: the episode was interrupted before its last hole ended."""
    physics_wall_s: float = 0.0
    """Wall time of the episode's ``mj_step`` calls (MuJoCo's step timer) [s]."""
    setup_wall_s: float = 0.0
    """Wall time before the first hole cycle: the cell built, settled, the platform registered."""

    def as_dict(self) -> dict[str, object]:
        return {"kind": "episode", **dataclasses.asdict(self)}


def signal_name(exc: BaseException) -> str:
    """Which signal a KeyboardInterrupt stands for: its first argument when that names one
    (the command line raises KeyboardInterrupt("SIGTERM") on SIGTERM), else SIGINT."""
    name = exc.args[0] if exc.args else None
    return name if isinstance(name, str) and name.startswith("SIG") else "SIGINT"


class EpisodeInterrupted(KeyboardInterrupt):
    """An episode stopped by an interrupt: `where` ({signal, episode, cycle, hole, phase}: the
    cycle under way (or, between cycles, the next one, phase "between cycles"), its hole if
    chosen yet, the cell's phase) and `summary` of the holes that finished (complete=False)."""

    def __init__(self, where: dict[str, object], summary: EpisodeSummary) -> None:
        super().__init__(where["signal"])
        self.where, self.summary = where, summary


def build_runtime(cfg: EpisodeConfig) -> tuple[CellRuntime, PlateCommander]:
    scene: Scene = build_scene(scene_config(cfg))
    rt = CellRuntime.create(scene, controller_config(cfg.sensor_noise), seed=cfg.seed)
    rt.drive = drive_friction(cfg, scene)
    plate = PlateCommander.create(scene.model, scene.data, scene.config.stewart, believed_errors(cfg))
    rt.observers.append(lambda r: plate.update(r.scene.data, r.time))
    return rt, plate


class _Snapshot:
    """The physics state and command state at the start of a cycle, to go on from after a
    breakdown (the broken cycle's part is then left out)."""

    def __init__(self, rt: CellRuntime, plate: PlateCommander) -> None:
        m, d = rt.scene.model, rt.scene.data
        self.spec = mujoco.mjtState.mjSTATE_INTEGRATION
        self.state = np.empty(mujoco.mj_stateSize(m, self.spec))
        mujoco.mj_getState(m, d, self.state, self.spec)
        self.time, self.commanded = rt.time, plate.commanded.copy()
        self.gripper = rt.gripper.command()
        self.load = (rt.load_mass, rt.load_com.copy())

    def restore(self, rt: CellRuntime, plate: PlateCommander) -> None:
        m, d = rt.scene.model, rt.scene.data
        mujoco.mj_setState(m, d, self.state, self.spec)
        mujoco.mj_forward(m, d)
        for warning in d.warning:
            warning.number = 0
        rt.reset_health()
        rt.time = self.time
        plate.reset_to(self.commanded)
        rt.arm.hold_joints(d.qpos[rt.scene.arm_qpos_adr].copy())
        # read the restored arm: the next move starts from the measured pose, which would
        # otherwise be the broken cycle's last (a jump the arm answers at its torque limits)
        rt.arm.update(m, d)
        rt.gripper.resume(self.gripper)
        rt.set_load(*self.load)


def run_episode(cfg: EpisodeConfig, pairs: dict[str, StereoPair],
                on_record: Callable[[HoleRecord], None] | None = None,
                runtime: tuple[CellRuntime, PlateCommander] | None = None,
                recording: str | Path | None = None, concealed: bool = False,
                on_insert: Callable[[CellRuntime, int, int], None] | None = None) -> EpisodeSummary:
    """Fill the holes of `cfg`; `on_record` receives each hole's record as it ends; `recording`
    names a folder for the episode's recording (signals, meta.json, episode.rrd); `concealed`:
    its meta.json holds what a real cell's log would (:func:`cell_log`), not the physics;
    `on_insert(runtime, hole, conductor)` as each insertion starts (HoleCycle.on_insert)."""
    t_wall = time.perf_counter()
    rt, plate = runtime or build_runtime(cfg)
    imaging = ImagingConfig(width=cfg.camera_width) if cfg.sensor_noise else ImagingConfig.ideal(cfg.camera_width)
    camera = Camera(rt.scene.model, imaging, seed=cfg.seed)
    recorder = None
    if recording is not None:

        about = {"cell_log": cell_log(cfg)} if concealed else {"episode_config": dataclasses.asdict(cfg)}
        recorder = EpisodeRecorder(rt, recording, about, name=f"episode_{cfg.seed}")
        rt.observers.append(recorder)
        camera.on_frames = recorder.frames
    rebind = [lambda scene: camera.rebind(scene.model), lambda scene: rt.reset_health()]
    if recorder is not None:
        rebind.append(recorder.rebind)
    rt.scene.on_recompile.extend(rebind)
    law = ControlLaw.FORCE_POSITION if cfg.controller == "force_position" else ControlLaw.IMPEDANCE
    cycle = HoleCycle(rt, plate, camera, pairs, cfg, law)
    cycle.on_insert = on_insert
    counts = {o.value: 0 for o in Outcome}
    n = cfg.holes if isinstance(cfg.holes, int) else len(cfg.holes)
    done, current = 0, None  # holes finished; the cycle under way
    setup, physics0 = float("nan"), rt.physics_wall_s  # a runtime given may have run before
    try:
        rt.run(SETTLE_S)
        cycle.register_platform()
        setup = time.perf_counter() - t_wall
        for k in range(n):
            current = k
            wanted = None if isinstance(cfg.holes, int) else cfg.holes[k]
            snap, t0, w0 = _Snapshot(rt, plate), rt.time, time.perf_counter()
            p0, n0 = rt.physics_wall_s, rt.physics_steps
            broken = False
            try:
                result = cycle.run(wanted)
            except CycleFailure as failure:
                result = failure.as_result()
            except (UnstableSimulation, SerparError) as exc:
                result, broken = cycle.fault_result(exc), True
            except (ValueError, IndexError, ArithmeticError) as exc:  # a defect: record it, go on
                result, broken = cycle.fault_result(RuntimeError(f"{type(exc).__name__}: {exc}")), True
            record = HoleRecord(cfg.seed, k, result.hole, result.conductor, result.outcome.value,
                                result.reason, result.peak_force_n, result.lateral_misalignment_mm,
                                result.insertion_time_s, result.depth_shortfall_mm, result.clearance_um,
                                rt.time - t0, time.perf_counter() - w0, broken,
                                cycle.phase_durations(rt.time), rt.physics_wall_s - p0,
                                rt.physics_steps - n0)
            if recorder is not None:  # before a restore turns the clock back
                recorder.note(f"hole {record.hole}: {record.outcome} ({record.reason})")
            if broken:
                snap.restore(rt, plate)
            counts[record.outcome] += 1
            done, current = done + 1, None
            if recorder is not None:
                recorder.hole_done(record.as_dict())
            if on_record:
                on_record(record)
        if recorder is not None:
            recorder.complete = True
    except KeyboardInterrupt as exc:
        between = current is None and 0 < done < n  # a cycle ended, the next one not begun
        where = {"signal": signal_name(exc), "episode": cfg.seed, "cycle": done if between else current,
                 "hole": None if current is None else cycle.hole,
                 "phase": "between cycles" if between else rt.phase}
        if recorder is not None:
            recorder.ended = {"interrupted": where}
        partial = EpisodeSummary(cfg.seed, done, counts["success"], counts, rt.time,
                                 time.perf_counter() - t_wall, complete=False,
                                 physics_wall_s=rt.physics_wall_s - physics0, setup_wall_s=setup)
        raise EpisodeInterrupted(where, partial) from None
    except BaseException as exc:
        if recorder is not None:
            recorder.ended = {"error": f"{type(exc).__name__}: {exc}"}
        raise
    finally:
        for hook in rebind:
            rt.scene.on_recompile.remove(hook)
        camera.close()
        if recorder is not None:  # also after an error: the recording shows how it got there
            rt.observers.remove(recorder)
            recorder.close()
    return EpisodeSummary(cfg.seed, n, counts["success"], counts, rt.time, time.perf_counter() - t_wall,
                          physics_wall_s=rt.physics_wall_s - physics0, setup_wall_s=setup)
