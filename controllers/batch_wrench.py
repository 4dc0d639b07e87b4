"""The momentum observer, low-pass, tare and (J^T)^+ of :mod:`serpar.controllers.wrench` for N
trials; each trial keeps its own count of updates, so trials may start at different periods."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from serpar.controllers.batch_model import BatchNominalArm, mat_vec
from serpar.controllers.wrench import WrenchEstimatorConfig, lowpass_alpha
from serpar.sim.arm import N_JOINTS

Arr = NDArray[np.float64]
_EYE6 = np.eye(6)
_DEFAULT_CONFIG = WrenchEstimatorConfig()


def tcp_wrench(jac: Arr, tau_ext: Arr, damping: float = 1e-9) -> Arr:
    """(N, 6) least-squares F_ext with J^T F_ext = tau_ext (see wrench.tcp_wrench)."""
    lhs = np.matmul(jac, jac.transpose(0, 2, 1)) + damping * _EYE6
    return np.linalg.solve(lhs, mat_vec(jac, tau_ext)[..., None])[..., 0]


class BatchWrenchEstimator:
    """``WrenchEstimator`` over a leading batch axis N (arrays, not a list of estimators)."""

    def __init__(self, n: int, config: WrenchEstimatorConfig = _DEFAULT_CONFIG) -> None:
        self.config, self.n = config, n
        self.residual = np.zeros((n, N_JOINTS))
        """The observer's r per trial [N m]."""
        self.tau_ext = np.zeros((n, N_JOINTS))
        """Low-passed external joint torque before the tare [N m]."""
        self.tau_offset = np.zeros((n, N_JOINTS))
        self.wrench = np.zeros((n, 6))
        """Current F_ext estimate at each TCP (after the tare)."""
        self._p = np.zeros((n, N_JOINTS))
        self._beta = np.zeros((n, N_JOINTS))
        self._recent = np.zeros((n, config.tare_window, N_JOINTS))  # ring buffers of tau_ext
        self._n_seen = np.zeros(n, dtype=np.int64)

    def reset(self, ids: NDArray[np.intp]) -> None:
        """New trials in slots `ids`: as a freshly built estimator."""
        for a in (self.residual, self.tau_ext, self.tau_offset, self.wrench, self._p, self._beta,
                  self._recent):
            a[ids] = 0.0
        self._n_seen[ids] = 0

    def tare(self, ids: NDArray[np.intp] | None = None) -> None:
        """Zero the estimates of trials `ids` (all when None) now: the mean of each one's ring."""
        ids = np.arange(self.n) if ids is None else np.asarray(ids)
        counts = np.minimum(self._n_seen[ids], self.config.tare_window)
        # one mean per distinct fill level (in practice one or two), in WrenchEstimator's order
        for c in np.unique(counts):
            rows = ids[counts == c]
            self.tau_offset[rows] = self._recent[rows, :c].mean(axis=1) if c else 0.0
        self.wrench[ids] = 0.0

    def update(self, nominal: BatchNominalArm, jac: Arr, tau_J: Arr, dt: float) -> Arr:
        """One control period; `nominal` loaded with the measured state, `jac` its (N, 6, 7)
        TCP Jacobians, `tau_J` the (N, 7) measured joint torques."""
        cfg = self.config
        p, beta = nominal.momentum(), nominal.beta()
        seen = (self._n_seen > 0)[:, None]  # r(0) = 0, p0 = p(0) per trial
        raw = (p - self._p) / dt - tau_J + 0.5 * (beta + self._beta)
        residual = self.residual + -np.expm1(-cfg.observer_gain * dt) * (raw - self.residual)
        self.residual = np.where(seen, residual, self.residual)
        tau_ext = self.tau_ext + lowpass_alpha(cfg.wrench_cutoff_hz, dt) * (self.residual
                                                                            - self.tau_ext)
        self.tau_ext = np.where(seen, tau_ext, self.tau_ext)
        self._p, self._beta = p, beta
        self._recent[np.arange(self.n), self._n_seen % cfg.tare_window] = self.tau_ext
        self._n_seen += 1
        self.wrench = tcp_wrench(jac, self.tau_ext - self.tau_offset)
        return self.wrench
