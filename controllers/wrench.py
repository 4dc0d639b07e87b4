"""External wrench at the TCP from the joint torque sensors: a generalised-momentum observer.

Link-side dynamics: M(q) ddq + C dq + g(q) = tau_J + tau_ext, tau_ext = J^T F_ext. The
observer of De Luca & Mattone (2003), the standard one for torque-sensed arms (Haddadin et al.
2017, "Robot Collisions: A Survey on Detection, Isolation, and Identification"),

    r = K_O (p - integral(tau_J + C^T dq - g + r) dt - p0),    p = M(q) dq,

obeys dr/dt = K_O (tau_ext - r): a first-order low-pass of the external joint torque that
needs no acceleration, so the velocity noise is never differentiated by itself
(controllers/momentum.py derives the integrand from MuJoCo's functions). F_ext then solves
J^T F_ext = r in the least-squares sense (7 joints, 6 wrench components). F_ext is the wrench
the environment applies at the TCP (force; torque about the TCP; arm base frame). The robot
pushes on the environment with F_s = -F_ext.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_model import NominalArm
from serpar.controllers.momentum import MomentumTerms
from serpar.errors import ConfigError

Vec = NDArray[np.float64]
_EYE6 = np.eye(6)


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


class WrenchEstimator:
    """The momentum observer, a joint-space low-pass and tare, then (J^T)^+.

    Tare and filtering act on tau_ext in joint space: a joint torque sensor bias is a
    constant joint torque, so it is removed at every configuration, whereas a wrench tare
    would only be right at the configuration where it was taken.
    """

    def __init__(self, config: WrenchEstimatorConfig = WrenchEstimatorConfig()) -> None:
        self.config = config
        self._terms: MomentumTerms | None = None
        self._p = np.zeros(7)
        self._beta = np.zeros(7)
        self.residual = np.zeros(7)
        """The observer's r: external joint torque, first-order in K_O [N m]."""
        self.tau_ext = np.zeros(7)
        """Low-passed external joint torque before the tare [N m]."""
        self.tau_offset = np.zeros(7)
        self._recent = np.zeros((config.tare_window, 7))  # ring buffer of tau_ext
        self._n_seen = 0
        self.wrench = np.zeros(6)
        """Current F_ext estimate at the TCP (after the tare)."""

    def tare(self) -> None:
        """Zero the estimate now (call with the TCP free of contact, as on the real arm)."""
        n = min(self._n_seen, len(self._recent))
        self.tau_offset = self._recent[:n].mean(axis=0) if n else np.zeros(7)
        self.wrench = np.zeros(6)

    def update(self, nominal: NominalArm, tau_J: Vec, dt: float) -> Vec:
        """One control period; `nominal` must be loaded with the measured q, dq."""
        cfg = self.config
        if self._terms is None or self._terms.nominal is not nominal:
            self._terms = MomentumTerms(nominal)
            self._n_seen = 0
        p, beta = self._terms.momentum(), self._terms.beta()
        if self._n_seen > 0:  # r(0) = 0, p0 = p(0): the first tau_J may predate any command
            # The integral form differenced over one period, dp - (tau_J - beta + r) dt (beta
            # by the trapezoid; tau_J is the torque sensors' period mean), with the exact
            # zero-order-hold discretisation of dr/dt = K_O (tau_ext - r).
            raw = (p - self._p) / dt - tau_J + 0.5 * (beta + self._beta)
            self.residual += -np.expm1(-cfg.observer_gain * dt) * (raw - self.residual)
            self.tau_ext += lowpass_alpha(cfg.wrench_cutoff_hz, dt) * (self.residual - self.tau_ext)
        self._p, self._beta = p, beta
        self._recent[self._n_seen % len(self._recent)] = self.tau_ext
        self._n_seen += 1
        self.wrench = tcp_wrench(nominal.tcp_jacobian(), self.tau_ext - self.tau_offset)
        return self.wrench
