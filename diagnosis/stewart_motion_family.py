"""A MOVING Stewart platform recording as a diagnosis :class:`~serpar.diagnosis.family.Family`
(kind ``stewart_motion``): every sample, not only rest holds, so latencies become visible.

Nominal model, per sample (stewart_motion_effects.py reads the recording):

- leg tracking: the measured legs are MuJoCo's nominal platform driven by the recorded
  commands (NominalTrack); residual (measured - predicted) / the encoders' noise;
- pose: the measured platform pose is the forward kinematics of the measured legs at the same
  instant (the rest-hold family's model, diagnosis/stewart_family.py); residual per axis
  over the mocap noise plus the encoders' noise through the kinematics.

Candidates: ``leg_servo_lag`` (the legs follow the nominal response tau late: actuation
latency), ``mocap_latency`` (the pose is the kinematics of the legs tau earlier, from the
legs' cubic spline: sensing latency), and the rest-hold family's static candidates that still
apply to the pose (stewart_effects.py: joint geometry restricted by its rank test, encoder
offsets, and leg compliance under the static load when a payload is given; thermal drift is a
campaign-scale effect that a recording of seconds cannot tell). Every Jacobian column is
exact. Training and held-out rows: the first 60 % and the last 40 % of the samples in time (a
contiguous segment the fit never saw).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from serpar.diagnosis.arm_static_effects import independent_columns
from serpar.diagnosis.family import Effect, LocateRow
from serpar.diagnosis.locate import locate_rows
from serpar.diagnosis.residual import consecutive_noise_ratio
from serpar.diagnosis.stewart_effects import (
    COLUMNS,
    COMPLIANCE,
    ENCODER,
    GEOMETRY,
    SCALE,
    full_effects,
    geometry_flat_index,
)
from serpar.diagnosis.stewart_motion_effects import (
    MOCAP_LATENCY,
    SERVO_LAG,
    MotionSamples,
    NominalTrack,
    latency_effects,
    nominal_track,
    read_motion,
)
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
KIND = "stewart_motion"
HOLDOUT_SHARE = 0.4
AXES = ("platform x", "platform y", "platform z", "platform rx", "platform ry", "platform rz")
MAX_POSE_MISFIT = (0.02, 0.1)
MAX_LEG_MISFIT_M = 0.01
"""Beyond these [m], [rad], [m] the recording is not of the nominal platform."""


class StewartMotionFamily:
    """A platform moving continuously: commanded and measured legs, measured poses."""

    kind = KIND

    def __init__(self, data: MotionSamples, track: NominalTrack) -> None:
        self.s, self.track = data, track
        geom = StewartConfig(**data.config).geometry()  # type: ignore[arg-type]
        self.P, self.B, self.l_min = np.array(geom.P), np.array(geom.B), float(geom.l_min)
        self.n_samples = data.n
        self.baseline: Effect | None = None
        self.spline = CubicSpline(data.time, data.legs, axis=0)
        self.dspline = self.spline.derivative()
        jac, _, _ = pose_jacobian(self.P, self.B, data.pos, data.rot)
        self.jac_meas = jac
        jinv = np.linalg.inv(jac)
        leg_var = np.einsum("nij,nij->ni", jinv, jinv) * data.sigma_leg**2
        inst = np.r_[[data.sigma_pos**2] * 3, [data.sigma_rot**2] * 3]
        self.sigma = np.hstack([np.sqrt(inst[None, :] + leg_var),
                                np.full((data.n, 6), data.sigma_leg)])
        self.force = static_leg_forces(self.P, self.B, data.pos, data.rot, data.load)
        self.speed = np.linalg.norm(np.gradient(data.pos, data.time, axis=0), axis=1)
        self._geo_idx = np.zeros(0, np.int64)
        self._check_nominal()
        self.effects: tuple[Effect, ...] = self._candidates()
        self.kind = f"{KIND} ({data.n} samples over {data.time[-1]:.1f} s)"

    def register(self, effect: Effect) -> None:
        if effect.name == GEOMETRY:
            self._geo_idx = np.array([geometry_flat_index(n) for n in effect.param_names])

    def _candidates(self) -> tuple[Effect, ...]:
        """Static candidates restricted by the rank test (stewart_effects.py), then the
        latencies."""
        rows = np.arange(self.n_samples)
        out = []
        for e in full_effects(0.0):
            if e.name == COMPLIANCE and self.s.load.payload_kg <= 0:
                continue
            if e.name == SCALE:  # not modelled for a moving platform (stewart_family.py is)
                continue
            self.register(e)
            keep = independent_columns(self.jacobian({e.name: e.x0}, rows), 0)
            if keep.size:
                out.append(e.restricted(keep))
        for e in out:
            self.register(e)
        return tuple(out) + latency_effects()

    # -- the model -------------------------------------------------------------------------
    def _pose_model(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                    ) -> tuple[Vec, Vec, Vec, Vec]:
        """Joint tables P, B, and the predicted poses (n, 3), (n, 3, 3) of the given rows."""
        s = self.s
        err = np.zeros(6 * len(COLUMNS))
        if GEOMETRY in params:
            err[self._geo_idx] = params[GEOMETRY]
        err = err.reshape(6, len(COLUMNS))
        P, B = self.P + err[:, 1:4], self.B + err[:, 4:7]
        if MOCAP_LATENCY in params:
            length = self.spline(np.clip(s.time[rows] - params[MOCAP_LATENCY][0], 0.0,
                                         s.time[-1]))
        else:
            length = s.legs[rows]
        length = length + err[:, 0]
        if ENCODER in params:
            length = length - params[ENCODER]
        if COMPLIANCE in params:
            length = length - params[COMPLIANCE] * self.force[rows]
        pos, rot = forward_kinematics(P, B, length, s.pos[rows], s.rot[rows])
        return P, B, pos, rot

    def _legs(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> tuple[Vec, Vec]:
        """Predicted leg lengths and their rates (n, 6) of the given rows."""
        tau = params[SERVO_LAG][0] if SERVO_LAG in params else 0.0
        slides, rates = self.track.at(self.s.time[rows] - tau)
        return self.l_min + slides, rates

    def residual(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        rows = np.asarray(rows, np.int64)
        s = self.s
        _, _, pos, rot = self._pose_model(params, rows)
        legs, _ = self._legs(params, rows)
        r = np.hstack([s.pos[rows] - pos, so3_log_batch(s.rot[rows] @ np.swapaxes(rot, -1, -2)),
                       s.legs[rows] - legs])
        return (r / self.sigma[rows]).ravel()

    def jacobian(self, params: Mapping[str, Vec], rows: NDArray[np.int64],
                 skip: Collection[str] = ()) -> Vec:
        """Exact d residual / d parameters (columns in the order of ``params``): the pose
        moves by J^-1 dL, J the leg Jacobian at the predicted pose (as stewart.py); the
        tracking residual moves by the nominal legs' rate times d tau."""
        rows = np.asarray(rows, np.int64)
        P, B, pos, rot = self._pose_model(params, rows)
        jac, u, _ = pose_jacobian(P, B, pos, rot)
        jinv = np.linalg.inv(jac)
        n = len(rows)
        cols = []
        for name in params:  # the blocks in ``skip`` left out
            if name in skip:
                continue
            track = None
            if name == GEOMETRY:
                dleg = np.zeros((n, 6, len(self._geo_idx)))
                ur = np.einsum("nij,njk->nik", u, rot)
                for k, flat in enumerate(self._geo_idx):
                    leg, col = divmod(int(flat), len(COLUMNS))
                    dleg[:, leg, k] = (1.0 if col == 0 else -ur[:, leg, col - 1] if col < 4
                                       else u[:, leg, col - 4])
            elif name == COMPLIANCE:
                dleg = -self.force[rows][:, :, None] * np.eye(6)[None]
            elif name == ENCODER:
                dleg = -np.broadcast_to(np.eye(6), (n, 6, 6))
            elif name == MOCAP_LATENCY:
                t = self.s.time[rows] - params[name][0]
                inside = ((t >= 0.0) & (t <= self.s.time[-1]))[:, None]
                dleg = (-self.dspline(np.clip(t, 0.0, self.s.time[-1])) * inside)[..., None]
            elif name == SERVO_LAG:
                dleg = np.zeros((n, 6, 1))
                track = self._legs(params, rows)[1][..., None]
            else:
                raise IdentificationError(f"unknown Stewart motion effect {name!r}; valid: "
                                          f"{', '.join(e.name for e in getattr(self, 'effects', ()))}")
            pose = -np.einsum("nij,njk->nik", jinv, dleg)
            track = np.zeros_like(pose) if track is None else track
            cols.append(np.concatenate([pose, track], axis=1) / self.sigma[rows][:, :, None])
        out = np.concatenate(cols, axis=2) if cols else np.zeros((n, 12, 0))
        return out.reshape(n * 12, -1)

    # -- Family protocol -------------------------------------------------------------------
    def noise_ratio(self, rows: NDArray[np.int64], whitened: Vec) -> tuple[float, str] | None:
        """The data's noise over the stated sigma, from sample-to-sample differences."""
        r = consecutive_noise_ratio(rows, whitened, 12)
        return None if r is None else (r, "sample-to-sample differences")

    def in_units(self, rows: NDArray[np.int64]) -> UnitView:
        """The platform pose (mm, mrad) and each leg's tracking (mm), per sample."""
        s = self.s
        return pose_view(s.time[rows], "time [s]", self.sigma[rows], s.pos[rows], s.legs[rows])

    def split(self, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """The first 60 % of the samples in time train, the last 40 % are held out."""
        cut = round((1.0 - HOLDOUT_SHARE) * self.n_samples)
        order = np.argsort(self.s.time, kind="stable")
        return np.sort(order[:cut]), np.sort(order[cut:])

    def locate(self, rows: NDArray[np.int64], whitened: Vec) -> list[LocateRow]:
        rows = np.asarray(rows, np.int64)
        w = np.asarray(whitened, float).reshape(len(rows), 12)
        groups: list[tuple[str, str, str, Vec]] = []
        for a, axis in enumerate(AXES):
            groups.append((axis, "all", "all samples", w[:, a]))
        for i in range(6):
            groups.append((f"leg {i + 1} tracking", "all", "all samples", w[:, 6 + i]))
        speed = self.speed[rows]
        cut = float(np.median(speed))
        for label, m in ((f"platform speed <= {cut * 1e3:.1f} mm/s", speed <= cut),
                         (f"platform speed > {cut * 1e3:.1f} mm/s", speed > cut)):
            groups.append(("platform pose", "regime", label, w[m, :6].ravel()))
            groups.append(("leg tracking", "regime", label, w[m, 6:].ravel()))
        t = self.s.time[rows]
        edges = np.linspace(0.0, max(float(self.s.time[-1]), 1e-9), 4)
        for k in range(3):
            m = (t >= edges[k]) & ((t < edges[k + 1]) if k < 2 else (t <= edges[k + 1]))
            label = f"t {edges[k]:.0f}-{edges[k + 1]:.0f} s"
            groups.append(("platform pose", "time", label, w[m, :6].ravel()))
            groups.append(("leg tracking", "time", label, w[m, 6:].ravel()))
        return locate_rows(groups)

    def _check_nominal(self) -> None:
        rows = np.arange(self.n_samples)
        s = self.s
        legs, _ = self._legs({}, rows)
        dl = np.max(np.abs(s.legs - legs), axis=1)
        k = int(np.argmax(dl))
        if dl[k] > MAX_LEG_MISFIT_M:
            raise IdentificationError(
                f"leg {int(np.argmax(np.abs(s.legs[k] - legs[k]))) + 1} is {dl[k] * 1e3:.3g} mm "
                f"from where the nominal servo takes it at t = {s.time[k]:.2f} s (valid: <= "
                f"{MAX_LEG_MISFIT_M * 1e3:g} mm): leg_cmd and leg are not commands and encoders "
                "of this platform")
        try:
            _, _, pos, rot = self._pose_model({}, rows)
        except IdentificationError:
            raise IdentificationError("the platform pose and the leg lengths do not belong to "
                                      "one platform (forward kinematics fails)") from None
        dp = np.linalg.norm(s.pos - pos, axis=1)
        da = np.linalg.norm(so3_log_batch(s.rot @ np.swapaxes(rot, -1, -2)), axis=1)
        k = int(np.argmax(dp / MAX_POSE_MISFIT[0] + da / MAX_POSE_MISFIT[1]))
        if not (dp[k] <= MAX_POSE_MISFIT[0] and da[k] <= MAX_POSE_MISFIT[1]):
            raise IdentificationError(
                f"the platform pose and the leg lengths disagree by {dp[k] * 1e3:.3g} mm / "
                f"{np.degrees(da[k]):.3g} deg at t = {s.time[k]:.2f} s (valid: <= "
                f"{MAX_POSE_MISFIT[0] * 1e3:g} mm, {np.degrees(MAX_POSE_MISFIT[1]):.3g} deg)")


def family_from_recording(rec: Recording) -> StewartMotionFamily:
    """The Stewart motion family of ``rec`` (IdentificationError names what it lacks)."""
    data = read_motion(rec)
    return StewartMotionFamily(data, nominal_track(data, rec))
