"""External wrench at the TCP from the joint torque sensors and the dynamic model (seed 000 Eq. 2).

Link-side dynamics: M(q) ddq + c(q, dq) + g(q) = tau_J + J^T F_ext, so the external joint
torque is tau_ext = M ddq + c + g - tau_J and F_ext solves J^T F_ext = tau_ext in the
least-squares sense (7 joints, 6 wrench components). F_ext is the wrench the environment
applies at the TCP (force; torque about the TCP; arm base frame). The robot pushes on the
environment with F_s = -F_ext.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_model import NominalArm
from serpar.errors import ConfigError

Vec = NDArray[np.float64]
_EYE6 = np.eye(6)


def external_joint_torque(nominal: NominalArm, ddq: Vec, tau_J: Vec) -> Vec:
    """tau_ext = M_link ddq + c + g - tau_J (nominal must be loaded with the measured q, dq)."""
    return nominal.link_torque(ddq) - tau_J


def tcp_wrench(jac: Vec, tau_ext: Vec, damping: float = 1e-9) -> Vec:
    """Least-squares F_ext with J^T F_ext = tau_ext; damping keeps it finite near singularities."""
    return np.linalg.solve(jac @ jac.T + damping * _EYE6, jac @ tau_ext)


def lowpass_alpha(cutoff_hz: float, dt: float) -> float:
    """Smoothing factor of a first-order low-pass at `cutoff_hz` sampled every `dt`."""
    if cutoff_hz <= 0:
        return 1.0  # no filtering
    tau = 1.0 / (2 * np.pi * cutoff_hz)
    return dt / (tau + dt)


@dataclass(frozen=True)
class WrenchEstimatorConfig:
    """Filters of the estimate (Franka's O_F_ext_hat_K is likewise low-passed)."""

    accel_cutoff_hz: float = 10.0
    """Low-pass on the differentiated joint velocity; 0 ignores M ddq (quasi-static)."""
    wrench_cutoff_hz: float = 50.0
    """Low-pass on the external joint torque; 0 means unfiltered."""
    tare_window: int = 100
    """Samples the tare averages (0.1 s at 1 kHz), so it removes the bias, not one noise draw."""

    def __post_init__(self) -> None:
        if self.tare_window < 1:
            raise ConfigError(f"tare_window={self.tare_window} must be >= 1 sample")
        for name in ("accel_cutoff_hz", "wrench_cutoff_hz"):
            if not float(getattr(self, name)) >= 0:
                raise ConfigError(f"{name}={getattr(self, name)} must be >= 0 (0 disables)")


class WrenchEstimator:
    """Filtered differentiation of dq, Eq. 2, a joint-space low-pass and tare, then J^T.

    Tare and filtering act on tau_ext in joint space: a joint torque sensor bias is a
    constant joint torque, so it is removed at every configuration, whereas a wrench tare
    would only be right at the configuration where it was taken.
    """

    def __init__(self, config: WrenchEstimatorConfig = WrenchEstimatorConfig()) -> None:
        self.config = config
        self._prev_dq: Vec | None = None
        self._ddq = np.zeros(7)
        self.tau_ext = np.zeros(7)
        """Low-passed external joint torque before the tare [N m]."""
        self.tau_offset = np.zeros(7)
        self._recent = np.zeros((config.tare_window, 7))  # ring buffer of raw tau_ext
        self._n_seen = 0
        self.wrench = np.zeros(6)
        """Current F_ext estimate at the TCP (after the tare)."""
        self._started = False

    def tare(self) -> None:
        """Zero the estimate now (call with the TCP free of contact, as on the real arm)."""
        n = min(self._n_seen, len(self._recent))
        self.tau_offset = self._recent[:n].mean(axis=0) if n else np.zeros(7)
        self.wrench = np.zeros(6)

    def update(self, nominal: NominalArm, dq: Vec, tau_J: Vec, dt: float) -> Vec:
        cfg = self.config
        if cfg.accel_cutoff_hz > 0 and self._prev_dq is not None:
            a = lowpass_alpha(cfg.accel_cutoff_hz, dt)
            self._ddq += a * ((dq - self._prev_dq) / dt - self._ddq)
        self._prev_dq = dq.copy()
        raw = external_joint_torque(nominal, self._ddq, tau_J)
        if self._started:
            self.tau_ext += lowpass_alpha(cfg.wrench_cutoff_hz, dt) * (raw - self.tau_ext)
        else:  # start the filter at the first sample, not at zero
            self.tau_ext, self._started = raw.copy(), True
        self._recent[self._n_seen % len(self._recent)] = raw
        self._n_seen += 1
        self.wrench = tcp_wrench(nominal.tcp_jacobian(), self.tau_ext - self.tau_offset)
        return self.wrench
