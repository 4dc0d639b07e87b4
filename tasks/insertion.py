"""Step 6: compliant insertion of the held journal, and how it ended.

The robot's side: a guarded approach along the hole axis under impedance control until the
wrench estimate reports contact, then the chosen law (direct force-position, seed Fig. 4, or
impedance with F_d fed forward, Eq. 3) pushes at F_d until the TCP stops advancing or the
time limit. The simulator's side (scoring only): where the shoulder ended relative to the
hole entry, the true peak contact force, and the lateral misalignment at first contact.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from serpar.controllers.arm_controller import ControlLaw
from serpar.controllers.arm_laws import CartesianTarget, ForceTarget
from serpar.controllers.cell_runtime import CellRuntime
from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.contact import aim_plate_contact
from serpar.tasks.episode_config import Outcome


@dataclass(frozen=True)
class InsertionConfig:
    force_n: float = 5.0
    """F_d along the hole axis [N]."""
    contact_n: float = 1.0
    """Estimated push that ends the guarded approach [N]."""
    approach_speed: float = 0.004
    """[m/s] along the axis toward the expected contact."""
    overtravel: float = 0.003
    """How far past the expected seat the approach target lies [m]."""
    force_ramp_s: float = 0.3
    """After contact F_d ramps from contact_n to force_n over this long [s]: a step to the full
    push presses a tip that met the chamfer off-axis up into the grip, and the part snaps down
    into the bore when the tip slides off the chamfer's foot."""
    stall_speed: float = 2e-4
    """The push ends when the TCP advances slower than this [m/s] ..."""
    stall_s: float = 0.3
    """... for this long [s]."""
    seat_tolerance: float = 2e-5
    """Seated: shoulder within this of the hole entry along the axis [m]."""
    time_limit_s: float = 10.0
    damage_force_n: float = 20.0

    def __post_init__(self) -> None:
        if not 0 < self.contact_n < self.force_n < self.damage_force_n:
            raise ConfigError("need 0 < contact_n < force_n < damage_force_n, got "
                              f"{self.contact_n}, {self.force_n}, {self.damage_force_n}")
        if not (self.approach_speed > 0 and self.stall_speed > 0 and self.time_limit_s > 0):
            raise ConfigError("approach_speed, stall_speed and time_limit_s must be > 0")
        if not self.force_ramp_s >= 0:
            raise ConfigError(f"force_ramp_s {self.force_ramp_s} must be >= 0 (0 = a step)")

    def push_at(self, since_contact: float) -> float:
        """F_d [N] `since_contact` seconds after the guarded approach ended."""
        if since_contact >= self.force_ramp_s:
            return self.force_n
        return self.contact_n + (self.force_n - self.contact_n) * since_contact / self.force_ramp_s


@dataclass(frozen=True)
class InsertionResult:
    outcome: Outcome
    reason: str
    peak_force_n: float
    """Peak contact force between the part and the baseplate [N], each sample the mean over one
    1 ms control period (what a 1 kHz force sensor reports; the solver's single-substep spike
    when the shoulder contact activates is ~4x that and lasts 0.1 ms)."""
    lateral_misalignment_mm: float
    """Tip centre to hole axis at first contact (true) [mm]; nan if never touched."""
    insertion_time_s: float
    """From first contact to the end of the push [s]."""
    depth_shortfall_mm: float
    """Shoulder above the hole entry at the end (true) [mm]; 0 = seated."""

    def as_dict(self) -> dict[str, object]:
        out = dict(self.__dict__)
        out["outcome"] = self.outcome.value
        return out


class _Truth:
    """Reads the simulator for scoring: part/plate contact force, tip and shoulder vs hole."""

    def __init__(self, rt: CellRuntime, conductor: int, hole: int) -> None:
        m = rt.scene.model
        self.rt, self.hole_site = rt, int(rt.scene.hole_sites[hole])
        self.force_adr = aim_plate_contact(m, int(rt.scene.conductor_bodies[conductor]))
        self.tip = m.site(f"{names.conductor(conductor)}tip").id
        self.shoulder = m.site(f"{names.conductor(conductor)}shoulder").id
        self._sum, self._n = 0.0, 0
        self.bore_start = rt.scene.config.baseplate.chamfer
        """Depth below the entry where the straight bore begins (the chamfer's foot) [m]."""

    def force(self) -> float:
        return float(np.linalg.norm(self.rt.scene.data.sensordata[self.force_adr]))

    def accumulate(self) -> None:
        self._sum, self._n = self._sum + self.force(), self._n + 1

    def period_mean(self) -> float:
        """Mean force over the substeps since the last call."""
        mean = self._sum / max(self._n, 1)
        self._sum, self._n = 0.0, 0
        return mean

    def _in_hole_frame(self, site: int) -> np.ndarray:
        d = self.rt.scene.data
        rot = d.site_xmat[self.hole_site].reshape(3, 3)
        return rot.T @ (d.site_xpos[site] - d.site_xpos[self.hole_site])

    def lateral(self) -> float:
        return float(np.linalg.norm(self._in_hole_frame(self.tip)[:2]))

    def tip_depth(self) -> float:
        return float(-self._in_hole_frame(self.tip)[2])

    def shoulder_height(self) -> float:
        return float(self._in_hole_frame(self.shoulder)[2])


def insert(rt: CellRuntime, seat_tcp: np.ndarray, rot: np.ndarray, axis: np.ndarray,
           law: ControlLaw, conductor: int, hole: int,
           config: InsertionConfig = InsertionConfig(),
           follow: Callable[[np.ndarray], None] | None = None) -> InsertionResult:
    """Insert from the current hover: `seat_tcp` is where the TCP would be with the part
    seated (as vision and the in-hand measurement predict), `axis` the insertion direction.

    `follow`, if given, gets the measured TCP position every control period of the guarded
    approach, until contact (the Stewart path keeps the hole under the journal with it)."""
    if law is ControlLaw.JOINT_PD:
        raise ConfigError("insertion law: force_position or impedance")
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    truth = _Truth(rt, conductor, hole)
    start, _ = rt.arm.nominal.tcp_pose()
    start = start.copy()
    goal = np.asarray(seat_tcp, float) + config.overtravel * axis
    rt.substep_probe = truth.accumulate
    try:
        return _push(rt, truth, start, goal, rot, axis, law, config, follow)
    finally:
        rt.substep_probe = None


def _push(rt: CellRuntime, truth: _Truth, start: np.ndarray, goal: np.ndarray, rot: np.ndarray,
          axis: np.ndarray, law: ControlLaw, config: InsertionConfig,
          follow: Callable[[np.ndarray], None] | None) -> InsertionResult:
    t0, peak, lateral, t_contact = rt.time, 0.0, float("nan"), None
    held: CartesianTarget | None = None
    t_held = t0
    window: deque[float] = deque(maxlen=round(config.stall_s / rt.dt) + 1)
    while rt.time - t0 < config.time_limit_s:
        if held is None:
            travelled = (rt.time - t0) * config.approach_speed
            along = min(travelled, float(axis @ (goal - start)))
            rt.arm.track(CartesianTarget(start + along * axis, rot,
                                         np.concatenate([config.approach_speed * axis, np.zeros(3)])),
                         ControlLaw.IMPEDANCE)
            if rt.arm.measured_push() > config.contact_n:
                pos, _ = rt.arm.nominal.tcp_pose()
                held, t_held = CartesianTarget(pos.copy(), rot), rt.time
            elif follow is not None:
                follow(rt.arm.nominal.tcp_pose()[0])
        if held is not None:
            rt.arm.track(held, law, ForceTarget(axis, config.push_at(rt.time - t_held)))
        rt.step()
        force = truth.period_mean()
        peak = max(peak, force)
        if t_contact is None and force > 0.05:
            t_contact, lateral = rt.time, truth.lateral()
        if held is not None:
            # Advance over the last stall_s, not per period: one encoder count is ~3 um at the
            # TCP, i.e. 3 mm/s of apparent speed in a single 1 ms period.
            pos, _ = rt.arm.nominal.tcp_pose()
            window.append(float(axis @ pos))
            ramped = rt.time - t_held >= config.force_ramp_s  # a stall at a partial push is no end
            if ramped and len(window) == window.maxlen and window[-1] - window[0] < config.stall_speed * config.stall_s:
                break
    timed_out = rt.time - t0 >= config.time_limit_s
    return _classify(truth, config, peak, lateral, t_contact, rt.time, timed_out)


def _classify(truth: _Truth, config: InsertionConfig, peak: float, lateral: float,
              t_contact: float | None, t_end: float, timed_out: bool) -> InsertionResult:
    shortfall = truth.shoulder_height()
    t_ins = float("nan") if t_contact is None else t_end - t_contact
    if peak > config.damage_force_n:
        outcome, reason = Outcome.OVERFORCE, f"peak {peak:.1f} N > {config.damage_force_n:g} N"
    elif shortfall <= config.seat_tolerance:
        outcome, reason = Outcome.SUCCESS, "seated"
    elif timed_out:
        outcome, reason = Outcome.TIMEOUT, f"not seated after {config.time_limit_s:g} s"
    elif truth.tip_depth() <= truth.bore_start:  # never entered the straight bore
        outcome, reason = Outcome.ALIGN_FAIL, f"tip on the rim or chamfer, {lateral * 1e3:.3f} mm off axis"
    else:
        outcome, reason = Outcome.JAM, f"stuck {shortfall * 1e3:.3f} mm short of seated"
    return InsertionResult(outcome, reason, peak, lateral * 1e3, t_ins, max(shortfall, 0.0) * 1e3)
