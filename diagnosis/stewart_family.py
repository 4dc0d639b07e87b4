"""A Stewart platform recording as a diagnosis :class:`~serpar.diagnosis.family.Family`.

Nominal model: the platform's joint table (sim/stewart.py's StewartConfig, from
``meta.model["stewart"]``) and rigid legs whose joint-to-joint lengths are what the encoders
say. At each rest hold (diagnosis/stewart_data.py) the model predicts the platform
pose by forward kinematics from the measured leg lengths; the residual is the measured minus
the predicted pose (position per axis, rotation vector per axis, base frame), divided by the
noise of the hold's mean. No baseline: the pose is measured in the Stewart base frame.

The candidates (stewart_effects.py) extend the leg lengths and the joint table; each has an
exact Jacobian (implicit differentiation of the leg closure), which the engine uses.
Training and held-out rows: the first 60 % and the last 40 % of the holds in time (an
extrapolation in time, and, when a campaign widens its poses as it goes, in space).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from serpar.calibration.stewart_params import save_stewart_parameters
from serpar.diagnosis.empirical import BasisGroup
from serpar.diagnosis.family import Effect, LocateRow
from serpar.diagnosis.locate import locate_rows
from serpar.diagnosis.stewart_data import StewartHolds, read_stewart
from serpar.diagnosis.stewart_effects import (
    COLUMNS,
    COMPLIANCE,
    ENCODER,
    GEOMETRY,
    N_LEGS,
    SCALE,
    THERMAL,
    WARMING,
    candidate_effects,
    geometry_flat_index,
)
from serpar.diagnosis.stewart_empirical import stewart_library
from serpar.diagnosis.units import UnitView, pose_view
from serpar.errors import IdentificationError
from serpar.sim.recording import Recording
from serpar.sim.stewart import StewartConfig
from serpar.sim.stewart_statics import (
    forward_kinematics,
    pose_jacobian,
    so3_log_batch,
    static_leg_forces,
)

Vec = NDArray[np.float64]
KIND = "stewart"
HOLDOUT_SHARE = 0.4
AXES = ("platform x", "platform y", "platform z", "platform rx", "platform ry", "platform rz")
MAX_NOMINAL_MISFIT = (0.02, 0.1)
"""[m], [rad]: beyond this the poses do not belong to the platform the legs describe."""


class StewartFamily:
    """Rest holds of a Stewart platform: commanded and measured legs, measured poses."""

    kind = KIND

    def __init__(self, holds: StewartHolds) -> None:
        self.h = holds
        geom = StewartConfig(**holds.config).geometry()  # type: ignore[arg-type]
        self.P, self.B = np.array(geom.P), np.array(geom.B)
        self.home = np.asarray(geom.home_pos)
        self.stroke = holds.legs - StewartConfig(**holds.config).l_min  # type: ignore[arg-type]
        """(n, 6) what each leg's encoder reads from its zero (the scale candidate's lever)."""
        self.duration_s = float(np.ptp(holds.time))
        self.n_samples = holds.n
        self.baseline: Effect | None = None
        jac, _, _ = pose_jacobian(self.P, self.B, holds.pos, holds.rot)
        self.jac_meas = jac
        """(n, 6, 6) leg Jacobian at the measured poses (locate's leg-space residual)."""
        self.force = static_leg_forces(self.P, self.B, holds.pos, holds.rot, holds.load)
        """(n, 6) static axial leg forces [N] at the measured poses (compliance regressor)."""
        # noise of a hold's mean: the instrument's, plus the encoders' through the kinematics
        jinv = np.linalg.inv(jac)
        leg_var = np.einsum("nij,nij->ni", jinv, jinv) * holds.sigma_leg**2
        inst = np.r_[[holds.sigma_pos**2] * 3, [holds.sigma_rot**2] * 3]
        self.sigma = np.sqrt((inst[None, :] + leg_var) / holds.count[:, None])
        self._geo_idx = np.zeros(0, np.int64)
        self._names: dict[str, tuple[str, ...]] = {}
        self._check_nominal()
        self.effects: tuple[Effect, ...] = candidate_effects(self, np.arange(holds.n))
        excluded = f"; {holds.n_excluded} samples in motion not used" if holds.n_excluded else ""
        self.kind = f"{KIND} ({holds.n} rest holds of {holds.n_samples} samples{excluded})"

    def register(self, effect: Effect) -> None:
        """Which geometric parameters a ``stewart_geometry`` block holds, in order."""
        if effect.name == GEOMETRY:
            self._geo_idx = np.array([geometry_flat_index(n) for n in effect.param_names])
        self._names[effect.name] = effect.param_names

    def _per_leg(self, params: Mapping[str, Vec], name: str) -> Vec:
        """A per-leg block's values on all six legs (legs the rank test dropped at zero)."""
        out = np.zeros(N_LEGS)
        for n, v in zip(self._names.get(name, ()), params[name], strict=False):
            if n[1:].isdigit():
                out[int(n[1:]) - 1] = v
        return out

    def _warming(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                 ) -> tuple[Vec, float, Vec]:
        """Per-leg saturating growth: (g (6,), rate [1/s], 1 - exp(-rate t) (n,))."""
        names = self._names.get(WARMING, ())
        values = dict(zip(names, params[WARMING], strict=False))
        rate = float(values.get("rate", 3.0 / max(self.duration_s, 1e-9)))
        return self._per_leg(params, WARMING), rate, 1.0 - np.exp(-rate * self.h.time[rows])

    # -- the model -------------------------------------------------------------------------
    def _model(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
               ) -> tuple[Vec, Vec, Vec, Vec, Vec, Vec]:
        """Joint tables P, B (6, 3), leg lengths before thermal growth and compliance (n, 6),
        growth factor (n, 6), predicted pose (n, 3), (n, 3, 3)."""
        h = self.h
        err = np.zeros(6 * len(COLUMNS))
        if GEOMETRY in params:
            err[self._geo_idx] = params[GEOMETRY]
        err = err.reshape(6, len(COLUMNS))
        P, B = self.P + err[:, 1:4], self.B + err[:, 4:7]
        base = h.legs[rows] + err[:, 0]
        if ENCODER in params:
            base = base - params[ENCODER]
        if SCALE in params:
            base = base - self._per_leg(params, SCALE) * self.stroke[rows]
        factor = np.ones((len(rows), N_LEGS))
        if THERMAL in params:
            factor = factor + params[THERMAL][0] * h.time[rows, None]
        if WARMING in params:
            g, _, shape = self._warming(params, rows)
            factor = factor + g * shape[:, None]
        length = base * factor
        if COMPLIANCE in params:
            length = length - params[COMPLIANCE] * self.force[rows]
        pos, rot = forward_kinematics(P, B, length, h.pos[rows], h.rot[rows])
        return P, B, base, factor, pos, rot

    def predict(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> tuple[Vec, Vec]:
        """Predicted platform poses (n, 3), (n, 3, 3) of the given holds."""
        return self._model(params, np.asarray(rows, np.int64))[4:]

    def residual(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        rows = np.asarray(rows, np.int64)
        pos, rot = self.predict(params, rows)
        h = self.h
        r = np.hstack([h.pos[rows] - pos,
                       so3_log_batch(h.rot[rows] @ np.swapaxes(rot, -1, -2))])
        return (r / self.sigma[rows]).ravel()

    def jacobian(self, params: Mapping[str, Vec], rows: NDArray[np.int64],
                 skip: Collection[str] = ()) -> Vec:
        """Exact d residual / d parameters (columns in the order of ``params``): the pose
        moves by J^-1 (dL - d|leg|), J the leg Jacobian at the predicted pose."""
        rows = np.asarray(rows, np.int64)
        P, B, base, factor, pos, rot = self._model(params, rows)
        jac, u, _ = pose_jacobian(P, B, pos, rot)
        jinv = np.linalg.inv(jac)  # (n, 6 pose, 6 legs)
        n = len(rows)
        cols = []
        for name in params:  # the blocks in ``skip`` left out
            if name in skip:
                continue
            if name == GEOMETRY:
                dleg = np.zeros((n, 6, len(self._geo_idx)))  # d(L - |leg|) per leg
                ur = np.einsum("nij,njk->nik", u, rot)  # u_i^T R (platform-frame dP)
                for k, flat in enumerate(self._geo_idx):
                    leg, col = divmod(int(flat), len(COLUMNS))
                    dleg[:, leg, k] = (factor[:, leg] if col == 0 else -ur[:, leg, col - 1] if col < 4
                                       else u[:, leg, col - 4])
            elif name == THERMAL:
                dleg = (self.h.time[rows, None] * base)[..., None]
            elif name == COMPLIANCE:
                dleg = -self.force[rows][:, :, None] * np.eye(6)[None]
            elif name == ENCODER:
                dleg = -factor[:, :, None] * np.eye(6)[None]
            elif name == SCALE:
                legs = [int(n[1:]) - 1 for n in self._names[SCALE]]
                dleg = (-factor * self.stroke[rows])[:, :, None] * np.eye(6)[None][:, :, legs]
            elif name == WARMING:
                g, rate, shape = self._warming(params, rows)
                legs = [int(n[1:]) - 1 for n in self._names[WARMING] if n != "rate"]
                dleg = (base * shape[:, None])[:, :, None] * np.eye(6)[None][:, :, legs]
                if "rate" in self._names[WARMING]:
                    t = self.h.time[rows]
                    d_rate = base * g * (t * np.exp(-rate * t))[:, None]
                    dleg = np.concatenate([dleg, d_rate[:, :, None]], axis=2)
            else:
                raise IdentificationError(f"unknown Stewart effect {name!r}; valid: "
                                          f"{', '.join(e.name for e in self.effects)}")
            cols.append(-np.einsum("nij,njk->nik", jinv, dleg) / self.sigma[rows][:, :, None])
        out = np.concatenate(cols, axis=2) if cols else np.zeros((n, 6, 0))
        return out.reshape(n * 6, -1)

    # -- Family protocol -------------------------------------------------------------------
    def empirical_library(self) -> list[BasisGroup]:
        """One leg at a time, drifting in time or in proportion to its stroke."""
        return stewart_library(self, StewartConfig(**self.h.config).l_min)  # type: ignore[arg-type]

    def noise_ratio(self, rows: NDArray[np.int64], whitened: Vec) -> tuple[float, str] | None:
        """The position noise the samples show about their hold's mean, over the stated one."""
        s = self.h.scatter_pos
        if not (np.isfinite(s) and self.h.sigma_pos > 0):
            return None
        return s / self.h.sigma_pos, "scatter of the samples within each rest hold"

    def in_units(self, rows: NDArray[np.int64]) -> UnitView:
        """Each hold's platform pose (mm, mrad), measured against the model's."""
        return pose_view(self.h.time[rows], "time [s]", self.sigma[rows], self.h.pos[rows])

    def split(self, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """The first 60 % of the holds in time train, the last 40 % are held out."""
        order = np.argsort(self.h.time, kind="stable")
        cut = round((1.0 - HOLDOUT_SHARE) * self.h.n)
        return np.sort(order[:cut]), np.sort(order[cut:])

    def locate(self, rows: NDArray[np.int64], whitened: Vec) -> list[LocateRow]:
        rows = np.asarray(rows, np.int64)
        w = np.asarray(whitened, float).reshape(len(rows), 6)
        groups: list[tuple[str, str, str, Vec]] = []
        for a, axis in enumerate(AXES):
            groups.append((axis, "all", "all holds", w[:, a]))
        # leg-space discrepancy of each leg: J (measured - predicted), over its own sigma
        dx = w * self.sigma[rows]
        jac = self.jac_meas[rows]
        dl = np.einsum("nij,nj->ni", jac, dx)
        sl = np.sqrt(np.einsum("nij,nj->ni", jac**2, self.sigma[rows] ** 2))
        for i in range(6):
            groups.append((f"leg {i + 1}", "leg", "all holds", dl[:, i] / sl[:, i]))
        h = self.h
        tilt = np.degrees(np.linalg.norm(so3_log_batch(h.rot[rows]), axis=1))
        reach = np.maximum(np.linalg.norm(h.pos[rows] - self.home, axis=1) / 0.04, tilt / 5.0)
        cut = float(np.median(reach))
        groups.append(("platform pose", "region", f"inner half (reach <= {cut:.2f} of 40 mm / 5 deg)",
                       w[reach <= cut].ravel()))
        groups.append(("platform pose", "region", "outer half", w[reach > cut].ravel()))
        load = np.max(np.abs(self.force[rows]), axis=1)
        lcut = float(np.median(load))
        groups.append(("platform pose", "regime", f"leg loads above {lcut:.0f} N", w[load > lcut].ravel()))
        groups.append(("platform pose", "regime", f"leg loads up to {lcut:.0f} N", w[load <= lcut].ravel()))
        t = h.time[rows]
        edges = np.linspace(0.0, max(self.duration_s, 1e-9), 4)
        for k in range(3):
            m = (t >= edges[k]) & ((t < edges[k + 1]) if k < 2 else (t <= edges[k + 1]))
            groups.append(("platform pose", "time", f"t {edges[k]:.0f}-{edges[k + 1]:.0f} s", w[m].ravel()))
        return locate_rows(groups)

    # -- the updated model for serpar run --------------------------------------------------
    def export(self, params: Mapping[str, Vec], stem: Path) -> list[Path]:
        """With geometry or encoder offsets established: ``<stem>.stewart_params.json`` in the
        calibration/stewart_params.py format (``stewart_calibration: <file>`` of ``serpar run``); an
        encoder offset o is the leg-length error dl = -o. Other effects have no place in it."""
        if GEOMETRY not in params and ENCODER not in params:
            return []

        err = np.zeros(6 * len(COLUMNS))
        if GEOMETRY in params:
            err[self._geo_idx] = params[GEOMETRY]
        err = err.reshape(6, len(COLUMNS))
        if ENCODER in params:
            err[:, 0] -= params[ENCODER]
        left = sorted(set(params) - {GEOMETRY, ENCODER})
        info = {"source": "serpar diagnose", "effects": sorted(set(params) & {GEOMETRY, ENCODER}),
                "not_expressible": left}
        return [save_stewart_parameters(Path(f"{stem}.stewart_params.json"), err, info)]

    def _check_nominal(self) -> None:
        rows = np.arange(self.h.n)
        try:
            pos, rot = self.predict({}, rows)
        except IdentificationError:
            pos = np.full((self.h.n, 3), np.inf)
            rot = np.repeat(np.eye(3)[None], self.h.n, axis=0)
        dp = np.linalg.norm(self.h.pos - pos, axis=1)
        da = np.linalg.norm(so3_log_batch(self.h.rot @ np.swapaxes(rot, -1, -2)), axis=1)
        k = int(np.argmax(np.where(np.isfinite(dp), dp / MAX_NOMINAL_MISFIT[0], np.inf)
                          + da / MAX_NOMINAL_MISFIT[1]))
        if not (dp[k] <= MAX_NOMINAL_MISFIT[0] and da[k] <= MAX_NOMINAL_MISFIT[1]):
            raise IdentificationError(
                f"the platform pose and the leg lengths disagree by {dp[k] * 1e3:.3g} mm / "
                f"{np.degrees(da[k]):.3g} deg at the hold at t = {self.h.time[k]:.1f} s (valid: "
                f"<= {MAX_NOMINAL_MISFIT[0] * 1e3:g} mm, {np.degrees(MAX_NOMINAL_MISFIT[1]):.3g} "
                "deg): a recording of another platform, or a pose not in the Stewart base frame")


def family_from_recording(rec: Recording) -> StewartFamily:
    """The Stewart family of ``rec`` (IdentificationError names what the recording lacks)."""
    return StewartFamily(read_stewart(rec))
