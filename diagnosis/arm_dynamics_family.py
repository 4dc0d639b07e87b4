"""Arm time series (q, tau_J, tau_J_d at ~1 kHz) as a diagnosis family: the nominal model's
inverse dynamics against the recording, per joint and per channel (arm_dynamics_terms.py),
with the candidate effects of arm_dynamics_effects.py.

Rows are windows (arm_dynamics_signals.py): one row = 14 whitened residuals, the link-side
torque sensor (channel ``tau_J<j>``) and the drive command (channel ``tau_J_d<j>``) of each
joint. Training and held-out rows are alternate blocks of ``ArmDynamicsConfig.block_s`` seconds; the
windows tile the time axis, so no held-out sample enters a training row.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_config import ArmDynamicsConfig, Span
from serpar.diagnosis.arm_dynamics_effects import ADDS_INERTIA, EffectModels
from serpar.diagnosis.arm_dynamics_empirical import arm_library, misread_library
from serpar.diagnosis.arm_dynamics_grouping import hold_grouped
from serpar.diagnosis.arm_dynamics_inertial import LinkInertial
from serpar.diagnosis.arm_dynamics_jacobian import residual_jacobian, tare_columns
from serpar.diagnosis.arm_dynamics_library import (
    COMMAND_ONLY,
    Channels,
    arm_effects,
    tare,
)
from serpar.diagnosis.arm_dynamics_setup import (
    bridge_variance,
    check_scale,
    declared_couplings,
    drifting_tare,
    encoder_visibility,
    regime_masks,
    stated_tare_walk,
)
from serpar.diagnosis.arm_dynamics_signals import (
    DRIVE_PREFIX,
    read_arm_series,
)
from serpar.diagnosis.arm_dynamics_terms import Terms, compute_terms, row_sigma
from serpar.diagnosis.empirical import BasisGroup
from serpar.diagnosis.family import Effect, LocateRow
from serpar.diagnosis.locate import locate_rows
from serpar.diagnosis.memo import Memo
from serpar.diagnosis.residual import consecutive_noise_ratio
from serpar.diagnosis.stability import default_folds
from serpar.diagnosis.units import UnitView, per_row
from serpar.errors import IdentificationError
from serpar.sim import channels as ch
from serpar.sim.recording import Recording
from serpar.sim.rigid_arm import PANDA_ARM, ArmDynamics, ArmModel

Vec = NDArray[np.float64]

KIND = "arm_dynamics"
CHANNELS: tuple[str, ...] = ch.TAU_J + ch.TAU_J_D
"""The Panda's residual columns of one row with sensors and command, in order."""
MAX_EFFECTS_DRIVE = 6
"""Effects a measured drive torque may need at once: friction, its Stribeck fall, rotor
inertia, a coupled motor, link inertia, a gain (a real drive has them all; each must still
earn its place and hold up under resampling)."""


class ArmDynamicsFamily:
    """The :class:`~serpar.diagnosis.family.Family` of one arm recording, for any arm."""

    kind = KIND
    tells_rivals = True
    """Whether "A or B" is tested (diagnosis/rivals.py): every row carries every channel of
    the arm, and the rivals are non-nested forms of the arm's physics."""

    def __init__(self, terms: Terms, dynamics: ArmDynamics, cfg: ArmDynamicsConfig,
                 phases: tuple[tuple[str, float, float], ...] = (), tare_walk: float = 0.0,
                 effects: tuple[Effect, ...] | None = None,
                 models: EffectModels | None = None) -> None:
        self.terms, self.cfg, self.arm = terms, cfg, dynamics.arm
        n = self.n = terms.n
        drive = ch.numbered(DRIVE_PREFIX if terms.drive_measured else "tau_J_d", n)
        blocks = ([ch.numbered("tau_J", n)] if terms.has_link else []) + (
            [drive] if terms.has_command else [])
        self.channels: tuple[str, ...] = tuple(c for b in blocks for c in b)
        self._blocks = (("link",) if terms.has_link else ()) + (
            ("drive",) if terms.has_command else ())
        # one joint's torque through the sensor and through the drive (diagnosis/channel_check.py)
        self.sibling_channels: tuple[int, ...] | None = (
            tuple(range(n, 2 * n)) + tuple(range(n)) if len(self._blocks) == 2 else None)
        # the tares sit on the measured torque: the link-side sensors, else the drive torque
        self.tare_block = "link" if terms.has_link else "drive"
        self._base = tare(n, "tare" if terms.has_link else "drive_tare")
        self.baseline: Effect | None = self._base
        self._knots: Vec | None = None
        self._tare_walk = tare_walk
        self._tare_var: Vec | None = None
        if cfg.tare_knot_s is not None:
            self.pin_tare_knots(np.arange(len(terms.time)))
        self._misfit_memo: Memo[tuple[Vec, Vec, Vec, Vec, Vec, Vec]] = Memo()
        self._sigma_memo: Memo[tuple[Vec, Vec]] = Memo()
        self._models = models or EffectModels(terms, dynamics, cfg.stick_velocity)
        self.effects: tuple[Effect, ...] = effects if effects is not None else arm_effects(
            n, Channels(terms.has_link, None), (), (), dynamics.armature)
        self.notes: tuple[str, ...] = () if terms.has_command else (
            ("no commanded torque (tau_J_d) nor drive torque (tau_drive) in the recording: only "
             "the torque sensors' channel is compared, and friction inside the drive, rotor "
             "inertia and latency (which only the drive's torque shows) are not candidates"),)
        if terms.has_command and not terms.has_link:
            self.notes += ((f"no link-side torque sensors (tau_J): friction and rotor inertia are "
                            f"named as drive effects; {', '.join(COMMAND_ONLY)} needs a command"
                            if terms.drive_measured else
                            "no link-side torque sensors (tau_J): the command alone is compared"),)
        self.n_samples = len(terms.time)
        self._phases = phases
        self._regimes = regime_masks(terms, phases)
        if terms.drive_measured:
            self.max_effects = MAX_EFFECTS_DRIVE
        # a CAD model against a real arm leaves a residual so large that a new effect started
        # on its bound stops after one step (diagnosis/fit.py START_INSIDE)
        self.start_inside = not dynamics.arm.is_panda

    # -- Family protocol -------------------------------------------------------------------
    def residual(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        link, drive, link_band, band, sigma_link, sigma_drive = self.misfits(params, rows)
        # stiction: within the band a residual is static friction, not a misfit
        drive = np.sign(drive) * np.maximum(np.abs(drive) - band, 0.0)
        link = np.sign(link) * np.maximum(np.abs(link) - link_band, 0.0)
        parts = {"link": link / sigma_link, "drive": drive / sigma_drive}
        return np.hstack([parts[b] for b in self._blocks]).ravel()

    def jacobian(self, params: Mapping[str, Vec], rows: NDArray[np.int64],
                 skip: Collection[str] = ()) -> Vec:
        """d residual / d params, the blocks in ``skip`` left out
        (diagnosis/arm_dynamics_jacobian.py)."""
        return residual_jacobian(self, params, rows, skip)

    def baseline_columns(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                         ) -> sp.csr_matrix:
        """d residual / d tare, sparse (fitted by variable projection: diagnosis/separable.py)."""
        return tare_columns(self, params, rows)

    def misfits(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                 ) -> tuple[Vec, Vec, Vec, Vec, Vec, Vec]:
        """Per row and joint: the link and drive misfits before the stiction band, the band of
        each, and each channel's sigma [N m] (kept for the last few asked: the residual, its
        Jacobian and the tare's columns ask at the same point; read-only)."""
        rows = np.asarray(rows, np.int64)
        key = [rows] + [x for name in sorted(params) for x in (name, params[name])]
        return self._misfit_memo(lambda: self._misfits(params, rows), *key)

    def _misfits(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                 ) -> tuple[Vec, Vec, Vec, Vec, Vec, Vec]:
        t = self.terms
        link_model, drive_model, link_band, band = self._models.contributions(params, rows)
        link = t.link[rows] - link_model
        drive = t.drive[rows] - drive_model
        if self._base.name in params:
            if self.tare_block == "link":
                link = link - self._tare(params[self._base.name], rows)
            else:
                drive = drive - self._tare(params[self._base.name], rows)
        inertial = [x for name in ADDS_INERTIA if name in params for x in (name, params[name])]
        sigma_link, sigma_drive = self._sigma_memo(lambda: self._sigmas(params, rows), rows,
                                                   *inertial)
        out = (link, drive, link_band, band, sigma_link, sigma_drive)
        for x in out:  # kept by the memos and handed out again: nobody may change them
            x.flags.writeable = False
        return out

    def _sigmas(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> tuple[Vec, Vec]:
        """Each row's link and drive sigma: a payload or link inertia the fit adds changes the
        acceleration noise's share."""
        t = self.terms
        added = self._models.added_inertia(params, rows)
        if added is None:
            sigma_link, sigma_drive = t.sigma_link[rows], t.sigma_drive[rows]
        else:
            sigma_link, sigma_drive = row_sigma(t.measurement_var, t.acc_var,
                                                t.mass_link[rows] + added, t.mass_full[rows] + added)
        if self._tare_var is not None:
            sigma_link = np.sqrt(sigma_link**2 + self._tare_var[rows, None])
        return sigma_link, sigma_drive

    def noise_ratio(self, rows: NDArray[np.int64], whitened: Vec) -> tuple[float, str] | None:
        """The data's noise over the stated sigma, from sample-to-sample differences (white
        sensor noise survives them, the slow residual of missing physics cancels)."""
        r = consecutive_noise_ratio(rows, whitened, len(self.channels))
        return None if r is None else (r, "sample-to-sample differences")

    def in_units(self, rows: NDArray[np.int64]) -> UnitView:
        """Each joint's torque channels in N m (windowed, as compared): the sensor's and the
        drive's, where the recording has them; measured = the windowed recording."""
        t, n = self.terms, len(self.channels)
        channel, axis = per_row(t.time[rows], n)
        link = (t.sigma_link[rows] if self._tare_var is None
                else np.sqrt(t.sigma_link[rows] ** 2 + self._tare_var[rows, None]))
        sigma = {"link": link, "drive": t.sigma_drive[rows]}
        measured = {"link": t.link[rows] + t.tau_link_model[rows],
                    "drive": t.drive[rows] + t.tau_full_model[rows]}
        return UnitView(self.channels, ("N m",) * n, channel,
                        np.hstack([sigma[b] for b in self._blocks]).ravel(), axis,
                        "time [s]", np.hstack([measured[b] for b in self._blocks]).ravel())

    def empirical_library(self) -> list[BasisGroup]:
        """Shapes in each joint's angle, velocity and time, and each joint's angle misread
        (diagnosis/arm_dynamics_empirical.py)."""
        return (arm_library(self.terms, self.channels, self._blocks, self.cfg.stick_velocity)
                + misread_library(self._models, self.terms, self._blocks))

    def split(self, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        if self.cfg.train_span is not None and self.cfg.heldout_span is not None:
            train, held = self._span(self.cfg.train_span), self._span(self.cfg.heldout_span)
            return train, held
        block = np.floor((self.terms.time - self.terms.time[0]) / self.cfg.block_s).astype(int)
        first = int(rng.integers(2))  # which parity trains: either way, whole blocks
        train = np.flatnonzero(block % 2 == first)
        held = np.flatnonzero(block % 2 != first)
        if train.size == 0 or held.size == 0:
            raise IdentificationError(f"a recording of {self.terms.time[-1] - self.terms.time[0]:.1f} s "
                                      f"gives no two {self.cfg.block_s} s blocks to train and hold out")
        return train, held

    def folds(self, k: int) -> list[tuple[NDArray[np.int64], NDArray[np.int64]]]:
        """Resampling folds: inside the training span where one is given, else over every row."""
        if self.cfg.train_span is None:
            return default_folds(self.n_samples, k)
        rows = self._span(self.cfg.train_span)
        return [(rows[a], rows[b]) for a, b in default_folds(len(rows), k)]

    def _span(self, span: Span) -> NDArray[np.int64]:
        """Rows whose whole window lies inside ``span`` (seconds from the first sample)."""
        t = self.terms
        start = t.time[0] - t.rows.half / t.rate  # the first sample's time
        half = t.rows.half / t.rate
        rel = t.time - start
        rows = np.flatnonzero((rel - half >= span[0]) & (rel + half <= span[1]))
        if rows.size == 0:
            raise IdentificationError(f"no window lies inside {span[0]:g}:{span[1]:g} s (the "
                                      f"recording covers 0:{rel[-1] + half:.3g} s)")
        return rows

    def locate(self, rows: NDArray[np.int64], whitened: Vec) -> list[LocateRow]:
        rows = np.asarray(rows, np.int64)
        w = np.asarray(whitened, float).reshape(len(rows), len(self.channels))
        groups = []
        for c, channel in enumerate(self.channels):
            j = c % self.n
            groups.append((channel, "all", "all rows", w[:, c]))
            for (group, label), mask in self._regimes.items():
                m = mask[rows] if mask.ndim == 1 else mask[rows, j]
                groups.append((channel, group, label, w[m, c]))
        return locate_rows(groups)

    def pin_tare_knots(self, train: NDArray[np.int64]) -> None:
        """Keep the drifting tare's knots that training rows pin (a row within one spacing):
        a knot only held-out rows could fix would be a free parameter fitted on nothing."""
        if self.cfg.tare_knot_s is not None:
            # the knots move: misfits and sigmas kept are of the old ones
            self._misfit_memo, self._sigma_memo = Memo(), Memo()
            self._knots, self.baseline = drifting_tare(self.terms.time, self.terms.time[train],
                                                       self.cfg.tare_knot_s, self._base)
            if self._tare_walk > 0:
                self._tare_var = bridge_variance(self.terms.time, self._knots, self._tare_walk)

    def _tare(self, values: Vec, rows: NDArray[np.int64]) -> Vec:
        """Per-row tares (rows, n): constant, or interpolated between the knots."""
        if self._knots is None:
            return values
        table = values.reshape(len(self._knots), self.n)
        t = self.terms.time[rows]
        return np.stack([np.interp(t, self._knots, table[:, j]) for j in range(self.n)], axis=1)


def family_from_recording(rec: Recording, cfg: ArmDynamicsConfig | None = None,
                          arm: ArmModel = PANDA_ARM, breaks_allowed: bool = False
                          ) -> ArmDynamicsFamily:
    """The arm-dynamics family of `rec` for ``arm`` (IdentificationError names what the
    recording lacks); ``breaks_allowed`` as :func:`read_arm_series`'s."""
    cfg = cfg or ArmDynamicsConfig()
    series = read_arm_series(rec, arm, breaks_allowed)
    dynamics = ArmDynamics(arm=arm)
    terms = compute_terms(series, cfg.smoothing, dynamics)
    drive_name = DRIVE_PREFIX if terms.drive_measured else "tau_J_d"
    check_scale(terms, arm.name, drive_name)
    offsets, scales = encoder_visibility(terms, dynamics)
    couplings = declared_couplings(rec, arm.n)
    inertial = None if arm.inertials_identified else LinkInertial(terms, dynamics)
    models = EffectModels(terms, dynamics, cfg.stick_velocity, offsets, scales, couplings,
                          inertial)
    drive = (("measured" if terms.drive_measured else "command") if terms.has_command else None)
    effects = arm_effects(arm.n, Channels(terms.has_link, drive), offsets, scales,
                          dynamics.armature, couplings, arm.friction_bounds)
    if inertial is not None:
        effects += (inertial.effect,)
    effects, held = hold_grouped(effects, terms, dynamics, couplings)
    phases = tuple((p.name, p.start, p.end) for p in rec.meta.phases)
    family = ArmDynamicsFamily(terms, dynamics, cfg, phases, stated_tare_walk(rec), effects,
                               models)
    family.notes += arm.notes + held
    return family
