"""One hole cycle of the episode as explicit phases, each working from what the cell knows.

The cell's knowledge: images from the two calibrated stereo pairs, the arm's measured joints
through its nominal model, the wrench estimate, and the Stewart platform's model with the
poses it commanded. The simulator's truth enters only the scoring (:mod:`serpar.tasks.insertion`)
and the drawn clearance written into the record.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.controllers.arm_controller import ControlLaw
from serpar.controllers.cell_runtime import CellRuntime
from serpar.controllers.plate_commander import PlateCommander, inverse
from serpar.sim.scene import SceneConfig
from serpar.sim.seat_lock import lock_seated
from serpar.sim.tolerances import BODY_H6
from serpar.tasks.episode_config import EpisodeConfig, Outcome
from serpar.tasks.hole_cycle import (
    CLEAR_Z,
    HAND_DOWN,
    HOVER,
    inspect_rotation,
    inspection_tcp,
    pick,
    release,
    seat_tcp,
    travel,
)
from serpar.tasks.insertion import InsertionConfig, insert
from serpar.tasks.motions import tcp_pose
from serpar.vision.camera import StereoPair
from serpar.vision.errors import ConductorNotInView, VisionError
from serpar.vision.imaging import Camera
from serpar.vision.inhand import inspect_in_hand
from serpar.vision.layout import plate_in_view, plate_layout, tray_pockets, tray_region
from serpar.vision.plate import PlateMeasurement, locate_holes
from serpar.vision.tray_conductors import locate_conductors

TOP = ("top_left", "top_right")
INSPECT = ("inspect_left", "inspect_right")
NOMINAL = SceneConfig()
"""The cell as designed: what vision and the task assume (the drawn diameters are unknown)."""
WAIT_POSE = np.array([0.45, -0.20, CLEAR_Z])
"""Where the arm waits while the top cameras look (out of their view of plate and tray)."""
STATION_ENTRY = np.array([0.60, 0.0, 0.299])
"""Fixed insertion station: where the Stewart brings each hole's entry (the grid centre at home)."""
PLATFORM_SETTLE_S = 0.4
"""Hold after a platform ramp: the leg PIDs settle to ~1 um."""
UP = np.array([0.0, 0.0, 1.0])
FOLLOW_DEADBAND = 2e-6
"""Sideways TCP wander below which the platform is not re-commanded [m] (encoder resolution
at the TCP is ~3 um)."""
FOLLOW_STOP_ABOVE = 3e-4
"""The platform stops following when the journal tip is this far above the hole entry, as
vision placed it [m]: a margin over the entry's height error (~0.05 mm) and the chamfers'
0.1 mm legs, so the hole never moves while the tip may touch it."""


@dataclass(frozen=True)
class CycleResult:
    hole: int | None
    conductor: int | None
    outcome: Outcome
    reason: str
    peak_force_n: float = float("nan")
    lateral_misalignment_mm: float = float("nan")
    insertion_time_s: float = float("nan")
    depth_shortfall_mm: float = float("nan")
    clearance_um: float = float("nan")


class HoleUnderJournal:
    """Keeps the hole under the held journal during the guarded approach (Stewart path).

    The arm's dry joint friction lets the TCP wander sideways by ~0.1 mm as it moves down from
    the hover; its encoders see the wander (the measured TCP), and the platform shifts the hole
    with it every `every` control periods (10: 100 Hz). Only the sideways part is followed:
    the approach itself stays the arm's.

    Following stops once the TCP has come `stop_after` along the axis: a hole that follows a
    tip already on its chamfer runs away from it as the chamfer pushes the tip toward the
    axis, and the stiff platform drives the chamfer into the compliant arm."""

    def __init__(self, plate: PlateCommander, data: mujoco.MjData, hole_in_plate: np.ndarray,
                 axis_in_plate: np.ndarray, entry: np.ndarray, axis: np.ndarray, start: np.ndarray,
                 stop_after: float, every: int = 10) -> None:
        self.plate, self.data, self.every, self.stop_after = plate, data, every, stop_after
        self.hole_in_plate, self.axis_in_plate = hole_in_plate, axis_in_plate
        self.entry, self.axis, self.start = entry, axis, np.asarray(start, float).copy()
        self.shift, self.calls = np.zeros(3), 0

    def __call__(self, tcp: np.ndarray) -> None:
        self.calls += 1
        if self.calls % self.every:
            return
        shift = tcp - self.start
        travelled = float(shift @ self.axis)
        if travelled > self.stop_after:
            return
        shift -= travelled * self.axis
        if np.linalg.norm(shift - self.shift) < FOLLOW_DEADBAND:
            return
        self.shift = shift
        goal = self.plate.goal_for(self.hole_in_plate, self.axis_in_plate, self.entry + shift, -self.axis)
        self.plate.nudge(self.data, goal)


class CycleFailure(Exception):
    """A cycle that ended before insertion, with its outcome."""

    def __init__(self, result: CycleResult) -> None:
        super().__init__(result.reason)
        self.result = result

    def as_result(self) -> CycleResult:
        return self.result


class HoleCycle:
    """The phases of one hole; keeps what the cell has learnt across cycles."""

    def __init__(self, rt: CellRuntime, plate: PlateCommander, camera: Camera,
                 pairs: dict[str, StereoPair], cfg: EpisodeConfig, law: ControlLaw) -> None:
        self.rt, self.plate, self.camera, self.cfg, self.law = rt, plate, camera, cfg, law
        size = camera.config.size
        self.top, self.inspect = pairs["top"].scaled(size), pairs["inspect"].scaled(size)
        self.spent_pockets: set[int] = set()
        self.attempted: set[int] = set()
        self.holes_in_plate: np.ndarray | None = None
        self.axis_in_plate = UP
        self.viewing_pose: np.ndarray | None = None
        """Platform pose of the registration shot (Stewart path): where the top pair sees the
        whole plate."""
        self.hole: int | None = None
        self.conductor: int | None = None
        self.phase = "start"
        self.phase_start: dict[str, float] = {}
        self.on_insert: Callable[[CellRuntime, int, int], None] | None = None
        """Called with (runtime, hole, conductor) as each insertion starts, after the tare
        (serpar montecarlo's validation reads the cell's state there)."""

    def _enter(self, phase: str) -> None:
        self.phase = phase
        self.phase_start[phase] = self.rt.time
        self.rt.phase = phase

    def phase_durations(self, end: float) -> dict[str, float]:
        """Simulated seconds spent in each phase of the last cycle."""
        items = sorted(self.phase_start.items(), key=lambda kv: kv[1])
        ends = [t for _, t in items[1:]] + [end]
        return {name: round(e - t, 4) for (name, t), e in zip(items, ends)}
    # --- vision --------------------------------------------------------------------------
    def _look_top(self) -> tuple[list, PlateMeasurement]:
        frames = self.camera.shoot(self.rt.scene.data, TOP)
        left, right = frames[TOP[0]], frames[TOP[1]]
        sightings = locate_conductors(self.top, left, right, tray_region(NOMINAL), NOMINAL.conductor,
                                      pockets=tray_pockets(NOMINAL))
        plate = locate_holes(self.top, left, right, NOMINAL.baseplate, NOMINAL.conductor, plate_layout(NOMINAL))
        return sightings, plate

    def register_platform(self) -> None:
        """Register the Stewart base to the camera frame and learn the holes in the plate frame
        (one top shot, platform settled at home, arm out of view)."""
        self._enter("register")
        travel(self.rt, WAIT_POSE, HAND_DOWN)
        _, plate = self._look_top()
        self.plate.register(plate)
        self.viewing_pose = self.plate.commanded.copy()
        plate_T_base = inverse(self.plate.plate_pose())
        centres = np.array([h.centre for h in plate.holes])
        self.holes_in_plate = centres @ plate_T_base[:3, :3].T + plate_T_base[:3, 3]
        self.axis_in_plate = plate_T_base[:3, :3] @ plate.normal

    def _bring_plate_into_view(self) -> float:
        """If the platform has carried the plate where the top pair cannot see all of it (a far
        hole at the station), ramp it back to the viewing pose while the arm clears the view;
        returns when the plate will have settled (simulation time), or 0."""
        if self.viewing_pose is None:
            return 0.0
        pair = self.top
        if plate_in_view(plate_layout(NOMINAL), NOMINAL.baseplate, self.plate.plate_pose(), self.holes_in_plate,
                         (pair.left, pair.right), above=NOMINAL.conductor.body_length):
            return 0.0
        ramp = self.plate.move_to(self.rt.scene.data, self.viewing_pose, self.rt.time)
        return self.rt.time + ramp + PLATFORM_SETTLE_S

    # --- the cycle -----------------------------------------------------------------------
    def _fail(self, outcome: Outcome, reason: str) -> CycleFailure:
        return CycleFailure(CycleResult(self.hole, self.conductor, outcome, f"{self.phase}: {reason}"))

    def fault_result(self, exc: Exception) -> CycleResult:
        outcome = {"grasp": Outcome.GRASP_FAIL, "insert": Outcome.JAM}.get(self.phase, Outcome.DROPPED)
        if self.conductor is None:
            outcome = Outcome.VISION_MISS
        return CycleResult(self.hole, self.conductor, outcome, f"{self.phase}: {exc}")

    def run(self, wanted: int | None) -> CycleResult:
        rt, d = self.rt, self.rt.scene.data
        self.hole = self.conductor = None
        self.phase_start = {}
        self._enter("locate")  # steps 1 and 2 share one top shot
        ready = self._bring_plate_into_view()
        travel(rt, WAIT_POSE, HAND_DOWN)
        if ready > rt.time:
            rt.run(ready - rt.time)
        try:
            sightings, plate = self._look_top()
        except VisionError as exc:
            raise self._fail(Outcome.VISION_MISS, str(exc)) from None
        sightings = [s for s in sightings if s.pocket is not None and s.pocket not in self.spent_pockets]
        empty = [h for h in plate.indices("empty") if h not in self.attempted]
        self.hole = wanted if wanted is not None else (empty[0] if empty else None)
        if self.hole is None or self.hole not in empty:
            raise self._fail(Outcome.VISION_MISS, f"hole {self.hole} not seen empty" if self.hole is not None
                             else "no empty hole found")
        self.attempted.add(self.hole)
        if not sightings:
            raise self._fail(Outcome.VISION_MISS, "no conductor found in the tray")
        sighting = sightings[0]
        self.conductor = int(sighting.pocket)  # conductor k starts in pocket k (scoring only)
        self.spent_pockets.add(self.conductor)
        stewart = self.cfg.stewart_correction
        if stewart:  # the coarse move runs while the arm picks
            goal = self.plate.goal_for(self.holes_in_plate[self.hole], self.axis_in_plate, STATION_ENTRY, UP)
            self.plate.move_to(d, goal, rt.time)

        self._enter("grasp")
        body = BODY_H6.nominal
        width = pick(rt, sighting, body)
        if width < 0.5 * body:
            raise self._fail(Outcome.GRASP_FAIL, f"jaw closed to {width * 1e3:.2f} mm: nothing held")

        self._enter("inspect")
        travel(rt, inspection_tcp(rt.scene), inspect_rotation())
        rt.run(0.1)
        frames = self.camera.shoot(d, INSPECT)
        pos, rot = tcp_pose(rt)
        try:
            held = inspect_in_hand(self.inspect, frames[INSPECT[0]], frames[INSPECT[1]], pos, rot,
                                   NOMINAL.conductor)
        except ConductorNotInView as exc:  # nothing between the fingers: lost on the way
            raise self._fail(Outcome.DROPPED, str(exc)) from None
        except VisionError as exc:
            raise self._fail(Outcome.VISION_MISS, str(exc)) from None
        lj = NOMINAL.conductor.journal_length

        self._enter("align")
        if stewart:
            travel(rt, seat_tcp(STATION_ENTRY, HAND_DOWN, held, lj) + HOVER * UP, HAND_DOWN)
            pos, rot = tcp_pose(rt)
            axis = rot @ held.axis  # journal direction, body -> tip (down)
            shoulder = pos + rot @ (held.tip - lj * held.axis)
            entry = shoulder + HOVER * axis
            goal = self.plate.goal_for(self.holes_in_plate[self.hole], self.axis_in_plate, entry, -axis)
            ramp = self.plate.move_to(d, goal, rt.time)
            rt.run(ramp + PLATFORM_SETTLE_S)
            seat, approach = pos + HOVER * axis, axis
            follow = HoleUnderJournal(self.plate, d, self.holes_in_plate[self.hole], self.axis_in_plate,
                                      entry, axis, pos, stop_after=HOVER - lj - FOLLOW_STOP_ABOVE)
        else:
            h = plate.holes[self.hole]
            seat = seat_tcp(h.centre, HAND_DOWN, held, lj)
            travel(rt, seat + HOVER * h.axis, HAND_DOWN)
            approach = -h.axis
            follow = None

        self._enter("insert")
        rt.arm.tare()
        if self.on_insert is not None:
            self.on_insert(rt, self.hole, self.conductor)
        cfg = InsertionConfig(damage_force_n=self.cfg.damage_force_n, time_limit_s=self.cfg.hole_time_limit_s)
        result = insert(rt, seat, HAND_DOWN, approach, self.law, self.conductor, self.hole, cfg, follow)
        self._enter("release")
        release(rt, body)
        if result.outcome is Outcome.SUCCESS:  # scored: from here the part rides with the plate
            lock_seated(rt.scene, self.conductor)
        diam = rt.scene.diameters
        clearance = 1e6 * (diam.holes[self.hole] - diam.journals[self.conductor])
        return CycleResult(self.hole, self.conductor, result.outcome, result.reason, result.peak_force_n,
                           result.lateral_misalignment_mm, result.insertion_time_s,
                           result.depth_shortfall_mm, clearance)

