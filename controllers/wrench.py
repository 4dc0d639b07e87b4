"""External wrench at the TCP from the joint torque sensors: a generalised-momentum observer.

Link-side dynamics: M(q) ddq + C dq + g(q) = tau_J + tau_ext, tau_ext = J^T F_ext. The
observer of De Luca & Mattone (2003), the standard one for torque-sensed arms (Haddadin et al.
2017, "Robot Collisions: A Survey on Detection, Isolation, and Identification"),

    r = K_O (p - integral(tau_J + C^T dq - g + r) dt - p0),    p = M(q) dq,

obeys dr/dt = K_O (tau_ext - r): a first-order low-pass of the external joint torque that
needs no acceleration, so the velocity noise is never differentiated by itself
(controllers/batch_model.py derives the integrand from MuJoCo's functions). F_ext then solves
J^T F_ext = r in the least-squares sense (7 joints, 6 wrench components). F_ext is the wrench
the environment applies at the TCP (force; torque about the TCP; arm base frame). The robot
pushes on the environment with F_s = -F_ext.

The estimator runs over a leading batch axis N (one arm: N = 1); each trial keeps its own count
of updates, so trials may start at different periods.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.controllers.batch_linalg import mat_vec
from serpar.controllers.batch_model import ArmTerms, BatchNominalArm
from serpar.errors import ConfigError
from serpar.sim.arm import N_JOINTS

Arr = NDArray[np.float64]
_EYE6 = np.eye(6)
DAMPING = 1e-9
"""Of the least squares in :func:`tcp_wrench`: keeps F_ext finite near singularities."""
_DAMPED_EYE = DAMPING * _EYE6  # the same product the call would form, made once


def tcp_wrench(jac: Arr, tau_ext: Arr) -> Arr:
    """Least-squares F_ext with J^T F_ext = tau_ext, over any leading axes: (..., 6, 7) Jacobians,
    (..., 7) torques -> (..., 6)."""
    lhs = np.matmul(jac, jac.swapaxes(-1, -2)) + _DAMPED_EYE
    return np.linalg.solve(lhs, mat_vec(jac, tau_ext)[..., None])[..., 0]


def lowpass_alpha(cutoff_hz: float, dt: float) -> float:
    """Smoothing factor of a first-order low-pass at `cutoff_hz` sampled every `dt`."""
    if cutoff_hz <= 0:
        return 1.0  # no filtering
    tau = 1.0 / (2 * np.pi * cutoff_hz)
    return dt / (tau + dt)


@dataclass(frozen=True)
class WrenchEstimatorConfig:
    """The observer's gain and the low-pass after it (Franka's O_F_ext_hat_K is likewise
    filtered). Velocity noise reaches r through dp/dt, K_O s/(s + K_O) M n_dq, white up to
    Nyquist: a second pole is what bounds it, and for a given delay two equal poles give the
    least noise. Two 20 ms poles leave ~0.02 N at rest with the default sensors (0.03 N is the
    target) and are ~8x faster than the force-position loop they feed (~6 rad/s); faster
    poles cost noise as K^1.5 (docs/controllers.md, "The wrench estimate")."""

    observer_gain: float = 50.0
    """K_O [1/s]: the observer's bandwidth (time constant 1/K_O = 20 ms)."""
    wrench_cutoff_hz: float = 8.0
    """Low-pass on the observer's output (8 Hz = 50 rad/s, the observer's pole); 0: none."""
    tare_window: int = 100
    """Samples the tare averages (0.1 s at 1 kHz), so it removes the bias, not one noise draw."""

    def __post_init__(self) -> None:
        if self.tare_window < 1:
            raise ConfigError(f"tare_window={self.tare_window} must be >= 1 sample")
        if not float(self.observer_gain) > 0:
            raise ConfigError(f"observer_gain={self.observer_gain} must be > 0 [1/s]")
        if not float(self.wrench_cutoff_hz) >= 0:
            raise ConfigError(f"wrench_cutoff_hz={self.wrench_cutoff_hz} must be >= 0 (0 disables)")


_DEFAULT_CONFIG = WrenchEstimatorConfig()


class BatchWrenchEstimator:
    """The momentum observer, a joint-space low-pass and tare, then (J^T)^+, for N trials.

    Tare and filtering act on tau_ext in joint space: a joint torque sensor bias is a
    constant joint torque, so it is removed at every configuration, whereas a wrench tare
    would only be right at the configuration where it was taken.
    """

    def __init__(self, n: int, config: WrenchEstimatorConfig = _DEFAULT_CONFIG) -> None:
        self.config, self.n = config, n
        self.residual = np.zeros((n, N_JOINTS))
        """The observer's r per trial: external joint torque, first-order in K_O [N m]."""
        self.tau_ext = np.zeros((n, N_JOINTS))
        """Low-passed external joint torque before the tare [N m]."""
        self.tau_offset = np.zeros((n, N_JOINTS))
        self.wrench = np.zeros((n, 6))
        """Current F_ext estimate at each TCP (after the tare)."""
        self._p = np.zeros((n, N_JOINTS))
        self._beta = np.zeros((n, N_JOINTS))
        self._recent = np.zeros((n, config.tare_window, N_JOINTS))  # ring buffers of tau_ext
        self._rows = np.arange(n)
        # updates seen: one count while every trial started together (a Python int, the usual
        # case), else one per trial
        self._seen: int | None = 0
        self._n_seen = np.zeros(n, dtype=np.int64)
        self._all_seen = False  # every trial past its first update: no per-trial masking
        self._dt = float("nan")
        self._decay = self._alpha = 0.0

    def reset(self, ids: NDArray[np.intp]) -> None:
        """New trials in slots `ids`: as a freshly built estimator."""
        for a in (self.residual, self.tau_ext, self.tau_offset, self.wrench, self._p, self._beta,
                  self._recent):
            a[ids] = 0.0
        counts = self._counts().copy()
        counts[ids] = 0
        self._seen, self._n_seen = (0, counts) if not counts.any() else (None, counts)
        self._all_seen = False

    def _counts(self) -> NDArray[np.int64]:
        """Each trial's number of updates."""
        return self._n_seen if self._seen is None else np.full(self.n, self._seen)

    def tare(self, ids: NDArray[np.intp] | None = None) -> None:
        """Zero the estimates of trials `ids` (all when None) now: the mean of each one's ring,
        so the tare removes the bias, not one noise draw."""
        ids = self._rows if ids is None else np.asarray(ids)
        counts = np.minimum(self._counts()[ids], self.config.tare_window)
        # one mean per distinct fill level (in practice one or two)
        for c in np.unique(counts):
            rows = ids[counts == c]
            self.tau_offset[rows] = self._recent[rows, :c].mean(axis=1) if c else 0.0
        self.wrench[ids] = 0.0

    def update(self, nominal: BatchNominalArm, terms: ArmTerms, tau_J: Arr, dt: float) -> Arr:
        """One control period; `nominal` loaded with the measured state, `terms` its terms there,
        `tau_J` the (N, 7) measured joint torques (the torque sensors' period mean)."""
        if dt != self._dt:  # the filters' coefficients, once per period length
            cfg = self.config
            self._dt, self._decay = dt, -np.expm1(-cfg.observer_gain * dt)
            self._alpha = lowpass_alpha(cfg.wrench_cutoff_hz, dt)
        p, beta = nominal.momentum(terms.mass), nominal.beta()
        # The integral form differenced over one period, dp - (tau_J - beta + r) dt (beta by the
        # trapezoid), with the exact zero-order-hold discretisation of dr/dt = K_O (tau_ext - r).
        raw = (p - self._p) / dt - tau_J + 0.5 * (beta + self._beta)
        if self._all_seen:
            self.residual += self._decay * (raw - self.residual)
            self.tau_ext += self._alpha * (self.residual - self.tau_ext)
        else:  # r(0) = 0, p0 = p(0) per trial: a first tau_J may predate any command
            seen = (self._counts() > 0)[:, None]
            residual = self.residual + self._decay * (raw - self.residual)
            self.residual = np.where(seen, residual, self.residual)
            tau_ext = self.tau_ext + self._alpha * (self.residual - self.tau_ext)
            self.tau_ext = np.where(seen, tau_ext, self.tau_ext)
            self._all_seen = True  # after this update every trial has been seen
        self._p, self._beta = p, beta
        window = self.config.tare_window
        if self._seen is None:
            self._recent[self._rows, self._n_seen % window] = self.tau_ext
            self._n_seen += 1
        else:  # one slot for all: a basic index, no gather
            self._recent[:, self._seen % window] = self.tau_ext
            self._seen += 1
        self.wrench = tcp_wrench(terms.jac, self.tau_ext - self.tau_offset)
        return self.wrench
