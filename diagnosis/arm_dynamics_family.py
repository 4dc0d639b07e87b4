"""Arm time series (q, tau_J, tau_J_d at ~1 kHz) as a diagnosis family: the nominal model's
inverse dynamics against the recording, per joint and per channel (arm_dynamics_terms.py),
with the candidate effects of arm_dynamics_effects.py.

Rows are windows (arm_dynamics_signals.py): one row = 14 whitened residuals, the link-side
torque sensor (channel ``tau_J<j>``) and the drive command (channel ``tau_J_d<j>``) of each
joint. Training and held-out rows are alternate blocks of :data:`BLOCK_S` seconds; the
windows tile the time axis, so no held-out sample enters a training row.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_effects import (
    BASELINE,
    COMMAND_ONLY,
    EFFECTS,
    STICK_VELOCITY,
    EffectModels,
)
from serpar.diagnosis.arm_dynamics_empirical import arm_library
from serpar.diagnosis.arm_dynamics_jacobian import residual_jacobian, tare_columns
from serpar.diagnosis.arm_dynamics_signals import SmoothingConfig, read_arm_series
from serpar.diagnosis.arm_dynamics_terms import Terms, compute_terms, row_sigma
from serpar.diagnosis.empirical import BasisGroup
from serpar.diagnosis.family import Effect, LocateRow
from serpar.diagnosis.locate import locate_rows
from serpar.diagnosis.residual import consecutive_noise_ratio
from serpar.diagnosis.units import UnitView, per_row
from serpar.errors import IdentificationError
from serpar.sim import channels as ch
from serpar.sim.recording import Recording
from serpar.sim.rigid_arm import ArmDynamics

Vec = NDArray[np.float64]

KIND = "arm_dynamics"
BLOCK_S = 2.0
"""Length of the alternating training / held-out time blocks [s]."""
CHANNELS: tuple[str, ...] = ch.TAU_J + ch.TAU_J_D
"""Residual columns of one row, in order (a recording without tau_J_d: tau_J alone)."""
TOP_SHARE = 0.25
"""A row is in a joint's "high gravity load" / "high acceleration" regime when it is in the
top quarter of that joint's |g| / |q̈| over the recording."""
TIME_BINS = 3
SCALE_RANGE = (0.5, 2.0)
"""Accepted regression slope of a joint's measured on its nominal torque: a payload or a gain
error moves it by tens of per cent; N mm for N m, or another robot, by far more."""
PIN_SHARE = 0.5
"""A drifting tare's knot is kept only with a training row within this share of the spacing:
a knot that only distant rows pin is fixed by leverage, and noise swings it."""
SCALE_MIN_RMS = 1.0
"""[N m] Joints whose nominal torque varies less than this are not tested for scale."""


@dataclass(frozen=True)
class ArmDynamicsConfig:
    smoothing: SmoothingConfig = field(default_factory=SmoothingConfig)
    block_s: float = BLOCK_S
    tare_knot_s: float | None = None
    """None: one constant tare per torque sensor. A spacing [s]: each sensor's tare is a
    piecewise-linear function of time with knots this far apart (the baseline then has 7 values
    per knot), for recordings long enough that the sensor zero's random walk shows."""
    stick_velocity: float = STICK_VELOCITY
    """[rad/s] Below this speed a joint with dry friction may be stuck (its friction anywhere in
    +-Fc): the rows weigh it as an interval."""

    def __post_init__(self) -> None:
        if not 0.0 < self.stick_velocity < 1.0:
            raise IdentificationError(f"ArmDynamicsConfig.stick_velocity={self.stick_velocity} "
                                      "rad/s must be in (0, 1)")
        if not self.block_s > 0:
            raise IdentificationError(f"ArmDynamicsConfig.block_s={self.block_s} must be > 0")
        if self.tare_knot_s is not None and not self.tare_knot_s > 0:
            raise IdentificationError(f"ArmDynamicsConfig.tare_knot_s={self.tare_knot_s} must be "
                                      "> 0 or None")


class ArmDynamicsFamily:
    """The :class:`~serpar.diagnosis.family.Family` of one arm recording."""

    kind = KIND

    def __init__(self, terms: Terms, dynamics: ArmDynamics, cfg: ArmDynamicsConfig,
                 phases: tuple[tuple[str, float, float], ...] = (), tare_walk: float = 0.0) -> None:
        self.terms, self.cfg = terms, cfg
        self.baseline: Effect | None = BASELINE
        self._knots: Vec | None = None
        self._tare_walk = tare_walk
        self._tare_var: Vec | None = None
        if cfg.tare_knot_s is not None:
            self.pin_tare_knots(np.arange(len(terms.time)))
        self.channels = CHANNELS if terms.has_command else ch.TAU_J
        self.effects: tuple[Effect, ...] = (EFFECTS if terms.has_command else
                                            tuple(e for e in EFFECTS if e.name not in COMMAND_ONLY))
        self.notes: tuple[str, ...] = () if terms.has_command else (
            ("no commanded torque (tau_J_d) in the recording: only the torque sensors' channel "
             f"is compared, and {', '.join(COMMAND_ONLY)} (which only the command shows: "
             "friction inside the drive acts before the torque sensor) are not candidates"),)
        self.n_samples = len(terms.time)
        self._models = EffectModels(terms, dynamics, cfg.stick_velocity)
        self._phases = phases
        self._regimes = self._regime_masks()

    # -- Family protocol -------------------------------------------------------------------
    def residual(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        link, drive, link_band, band, sigma_link, sigma_drive = self.misfits(params, rows)
        # stiction: within the band a residual is static friction, not a misfit
        drive = np.sign(drive) * np.maximum(np.abs(drive) - band, 0.0)
        link = np.sign(link) * np.maximum(np.abs(link) - link_band, 0.0)
        if not self.terms.has_command:
            return (link / sigma_link).ravel()
        return np.hstack([link / sigma_link, drive / sigma_drive]).ravel()

    def jacobian(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        """d residual / d params (diagnosis/arm_dynamics_jacobian.py)."""
        return residual_jacobian(self, params, rows)

    def baseline_columns(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                         ) -> sp.csr_matrix:
        """d residual / d tare, sparse (fitted by variable projection: diagnosis/separable.py)."""
        return tare_columns(self, params, rows)

    def misfits(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                 ) -> tuple[Vec, Vec, Vec, Vec, Vec, Vec]:
        """Per row and joint: the link and drive misfits before the stiction band, the band of
        each, and each channel's sigma [N m]."""
        rows = np.asarray(rows, np.int64)
        t = self.terms
        link_model, drive_model, link_band, band = self._models.contributions(params, rows)
        link = t.link[rows] - link_model
        if BASELINE.name in params:
            link = link - self._tare(params[BASELINE.name], rows)
        drive = t.drive[rows] - drive_model
        added = self._models.added_inertia(params, rows)
        if added is None:
            sigma_link, sigma_drive = t.sigma_link[rows], t.sigma_drive[rows]
        else:
            sigma_link, sigma_drive = row_sigma(t.measurement_var, t.acc_var,
                                                t.mass_link[rows] + added, t.mass_full[rows] + added)
        if self._tare_var is not None:
            sigma_link = np.sqrt(sigma_link**2 + self._tare_var[rows, None])
        return link, drive, link_band, band, sigma_link, sigma_drive

    def noise_ratio(self, rows: NDArray[np.int64], whitened: Vec) -> tuple[float, str] | None:
        """The data's noise over the stated sigma, from sample-to-sample differences (white
        sensor noise survives them, the slow residual of missing physics cancels)."""
        r = consecutive_noise_ratio(rows, whitened, len(self.channels))
        return None if r is None else (r, "sample-to-sample differences")

    def in_units(self, rows: NDArray[np.int64]) -> UnitView:
        """Each joint's torque channels in N m (windowed, as compared): the sensor's and, with
        a command, the command's; measured = the windowed recording."""
        t, n = self.terms, len(self.channels)
        channel, axis = per_row(t.time[rows], n)
        link = (t.sigma_link[rows] if self._tare_var is None
                else np.sqrt(t.sigma_link[rows] ** 2 + self._tare_var[rows, None]))
        sigma = np.hstack([link, t.sigma_drive[rows]])[:, :n]
        measured = np.hstack([t.link[rows] + t.tau_link_model[rows],
                              t.drive[rows] + t.tau_full_model[rows]])[:, :n]
        return UnitView(self.channels, ("N m",) * n, channel, sigma.ravel(), axis,
                        "time [s]", measured.ravel())

    def empirical_library(self) -> list[BasisGroup]:
        """Shapes in each joint's angle, velocity and time (diagnosis/arm_dynamics_empirical.py)."""
        groups = arm_library(self.terms)
        return groups if self.terms.has_command else [g for g in groups if g.channel in ch.TAU_J]

    def split(self, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        block = np.floor((self.terms.time - self.terms.time[0]) / self.cfg.block_s).astype(int)
        first = int(rng.integers(2))  # which parity trains: either way, whole blocks
        train = np.flatnonzero(block % 2 == first)
        held = np.flatnonzero(block % 2 != first)
        if train.size == 0 or held.size == 0:
            raise IdentificationError(f"a recording of {self.terms.time[-1] - self.terms.time[0]:.1f} s "
                                      f"gives no two {self.cfg.block_s} s blocks to train and hold out")
        return train, held

    def locate(self, rows: NDArray[np.int64], whitened: Vec) -> list[LocateRow]:
        rows = np.asarray(rows, np.int64)
        w = np.asarray(whitened, float).reshape(len(rows), len(self.channels))
        groups = []
        for c, channel in enumerate(self.channels):
            j = c % 7
            groups.append((channel, "all", "all rows", w[:, c]))
            for (group, label), mask in self._regimes.items():
                m = mask[rows] if mask.ndim == 1 else mask[rows, j]
                groups.append((channel, group, label, w[m, c]))
        return locate_rows(groups)

    def pin_tare_knots(self, train: NDArray[np.int64]) -> None:
        """Keep the drifting tare's knots that training rows pin (a row within one spacing):
        a knot only held-out rows could fix would be a free parameter fitted on nothing."""
        if self.cfg.tare_knot_s is not None:
            self._knots, self.baseline = drifting_tare(self.terms.time, self.terms.time[train],
                                                       self.cfg.tare_knot_s)
            if self._tare_walk > 0:
                self._tare_var = bridge_variance(self.terms.time, self._knots, self._tare_walk)

    def _tare(self, values: Vec, rows: NDArray[np.int64]) -> Vec:
        """Per-row tares (rows, 7): constant, or interpolated between the knots."""
        if self._knots is None:
            return values
        table = values.reshape(len(self._knots), 7)
        t = self.terms.time[rows]
        return np.stack([np.interp(t, self._knots, table[:, j]) for j in range(7)], axis=1)

    # -- where -----------------------------------------------------------------------------
    def _regime_masks(self) -> dict[tuple[str, str], NDArray[np.bool_]]:
        """Boolean masks over rows (rows, or rows x joints for per-joint regimes)."""
        t = self.terms
        v = t.dq_full
        idx = t.rows.centre[:, None] + np.arange(-t.rows.half, t.rows.half + 1)[None, :]
        window = v[idx]  # rows x window x joints
        reversal = np.any(window > 0, axis=1) & np.any(window < 0, axis=1)

        def top(x: Vec) -> NDArray[np.bool_]:
            mag = np.abs(x)
            # a joint whose |x| never rises above round-off (gravity on joint 1) has no regime
            return (mag >= np.quantile(mag, 1.0 - TOP_SHARE, axis=0)) & (mag > 1e-6)

        masks = {("regime", "velocity reversal"): reversal,
                 ("regime", "high gravity load"): top(t.gravity),
                 ("regime", "high acceleration"): top(t.ddq)}
        span = t.time[-1] - t.time[0]
        edges = t.time[0] + span * np.arange(TIME_BINS + 1) / TIME_BINS
        for a, b in pairwise(edges):
            masks[("elapsed time", f"{a:.0f}-{b:.0f} s")] = (t.time >= a) & (t.time <= b)
        if len({p[0] for p in self._phases}) > 1:
            for name, a, b in self._phases:
                key = ("phase", name)
                inside = (t.time >= a) & (t.time <= b)
                masks[key] = masks.get(key, np.zeros_like(inside)) | inside
        return masks


def family_from_recording(rec: Recording, cfg: ArmDynamicsConfig | None = None
                          ) -> ArmDynamicsFamily:
    """The arm-dynamics family of `rec` (IdentificationError names what the recording lacks)."""
    cfg = cfg or ArmDynamicsConfig()
    series = read_arm_series(rec)
    dynamics = ArmDynamics()
    terms = compute_terms(series, cfg.smoothing, dynamics)
    check_scale(terms)
    phases = tuple((p.name, p.start, p.end) for p in rec.meta.phases)
    return ArmDynamicsFamily(terms, dynamics, cfg, phases, stated_tare_walk(rec))


def stated_tare_walk(rec: Recording) -> float:
    """The torque sensors' bias random walk [N m/sqrt(s)] the recording states as part of its
    noise model (``model.arm_sensors.torque_bias_walk``, as `serpar run --record` writes it),
    0 when it states none."""
    sensors = rec.meta.model.get("arm_sensors")
    walk = sensors.get("torque_bias_walk", 0.0) if isinstance(sensors, dict) else 0.0
    return float(walk) if isinstance(walk, (int, float)) and np.isfinite(walk) and walk > 0 else 0.0


def bridge_variance(time: Vec, knots: Vec, walk: float) -> Vec:
    """Per row, the variance of a random-walk tare (intensity `walk`) about the piecewise-linear
    tare through `knots`: a Brownian bridge between two knots, w^2 (t - a)(b - t)/(b - a), and
    a free walk beyond the end knots, where the tare is held constant. It belongs to the
    stated noise: a held-out row's tare is interpolated across a block no training row pins."""
    if len(knots) == 0:
        return np.full(len(time), walk**2 * (time[-1] - time[0]))
    i = np.clip(np.searchsorted(knots, time), 1, max(len(knots) - 1, 1))
    a, b = knots[i - 1], knots[np.minimum(i, len(knots) - 1)]
    inside = (time >= knots[0]) & (time <= knots[-1]) & (b > a)
    var = np.where(inside, (time - a) * (b - time) / np.where(b > a, b - a, 1.0), 0.0)
    var = np.where(time < knots[0], knots[0] - time, var)
    var = np.where(time > knots[-1], time - knots[-1], var)
    return walk**2 * var


def drifting_tare(time: Vec, pinned_by: Vec, spacing_s: float) -> tuple[Vec, Effect]:
    """Knot times (every ``spacing_s`` from the first row, each with a ``pinned_by`` time
    within one spacing) and the baseline Effect of a piecewise-linear tare per sensor
    (constant beyond the end knots)."""
    grid = time[0] + spacing_s * np.arange(int(np.ceil((time[-1] - time[0]) / spacing_s)) + 1)
    near = np.abs(grid[:, None] - pinned_by[None, :]).min(axis=1) < PIN_SHARE * spacing_s
    knots = grid[near]
    names = tuple(f"tare{j}@{t - time[0]:.0f}s" for t in knots for j in range(1, 8))
    k = len(names)
    return knots, Effect(BASELINE.name, "torque sensor offsets (tares), drifting in time", names,
                         ("N m",) * k, np.zeros(k), np.full(k, -20.0), np.full(k, 20.0))


def check_scale(terms: Terms) -> None:
    """IdentificationError when a torque channel does not scale like the nominal model: units
    other than N m, or a recording of another robot."""
    channels = (("tau_J", terms.link + terms.tau_link_model, terms.tau_link_model),
                ("tau_J_d", terms.drive + terms.tau_full_model, terms.tau_full_model))
    for name, measured, model in channels[:2 if terms.has_command else 1]:
        x = model - model.mean(axis=0)
        y = measured - measured.mean(axis=0)
        for j in np.flatnonzero(np.sqrt(np.mean(x**2, axis=0)) > SCALE_MIN_RMS):
            slope = float(x[:, j] @ y[:, j] / (x[:, j] @ x[:, j]))
            if not SCALE_RANGE[0] <= slope <= SCALE_RANGE[1]:
                raise IdentificationError(
                    f"{name}{j + 1} varies {slope:.3g} times as much as the nominal Panda model "
                    "predicts from q: not in N m, or a recording of another robot")
