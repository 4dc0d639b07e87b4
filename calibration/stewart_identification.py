"""Stewart kinematic calibration, seed 000 §4.2: the 42-parameter error model (per leg dl,
dP xyz, dB xyz), its identification Jacobian and a Levenberg-Marquardt solve.

Measurements are what a calibration campaign gets: for each pose k the strokes the leg
servos were commanded (s_k, from the model in use) and the platform pose a measuring device
saw (pos_k, rot_k, in the Stewart base frame). The residual of leg i at pose k is the
inverse-kinematics closure of seed 000 Eq. 5, in leg-length form:

    r_ki = | pos_k + R_k (P_i + dP_i) - (B_i + dB_i) | - (l_min + dl_i + s_ki)

which is linear in dl and smooth in dP, dB, so LM converges from zero in a few iterations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from serpar.errors import IdentificationError
from serpar.kinematics.stewart_kinematics import StewartGeometry
from serpar.sim.stewart import MAX_JOINT_ERROR

N_LEGS = 6
PARAMS_PER_LEG = 7
N_PARAMS = N_LEGS * PARAMS_PER_LEG
MIN_POSES = 7
"""42 parameters need at least 42 leg equations: seven poses (seed 000 §4.2)."""
RANK_TOL = 1e-9
"""Singular values below this times the largest mean an unidentifiable combination."""


@dataclass(frozen=True)
class StewartMeasurements:
    """Commanded strokes and measured platform poses of one campaign."""

    strokes: np.ndarray
    """(N, 6) commanded strokes [m]."""
    pos: np.ndarray
    """(N, 3) measured platform-centre positions in the Stewart base frame [m]."""
    rot: np.ndarray
    """(N, 3, 3) measured platform orientations."""

    def __post_init__(self) -> None:
        n = len(self.strokes)
        shapes = {"strokes": (n, N_LEGS), "pos": (n, 3), "rot": (n, 3, 3)}
        for name, shape in shapes.items():
            value = np.asarray(getattr(self, name), float)
            if value.shape != shape:
                raise IdentificationError(f"{name} has shape {value.shape}, expected {shape} for {n} poses")
            if not np.all(np.isfinite(value)):
                raise IdentificationError(f"{name} contains NaN or infinite values")
        if n < MIN_POSES:
            raise IdentificationError(f"{n} poses give {6 * n} equations for {N_PARAMS} parameters; "
                                      f"need at least {MIN_POSES} poses")


@dataclass(frozen=True)
class StewartIdentification:
    errors: np.ndarray
    """(6, 7) identified dl, dP xyz, dB xyz per leg [m]."""
    residual_rms_m: float
    singular_values: np.ndarray
    """Of the identification Jacobian at the solution (column-scaled to unit norm)."""
    iterations: int


def leg_residuals(errors: np.ndarray, nominal: StewartGeometry, meas: StewartMeasurements) -> np.ndarray:
    """(N, 6) leg-length closure residuals [m] of the error model at `errors` (6, 7)."""
    e = np.asarray(errors, float).reshape(N_LEGS, PARAMS_PER_LEG)
    legs = _legs(e, nominal, meas)
    return np.linalg.norm(legs, axis=-1) - (nominal.l_min + e[:, 0] + meas.strokes)


def identification_jacobian(errors: np.ndarray, nominal: StewartGeometry,
                            meas: StewartMeasurements) -> np.ndarray:
    """d(residuals, flattened pose-major)/d(errors, flattened leg-major): (6N, 42)."""
    e = np.asarray(errors, float).reshape(N_LEGS, PARAMS_PER_LEG)
    legs = _legs(e, nominal, meas)
    unit = legs / np.linalg.norm(legs, axis=-1, keepdims=True)  # (N, 6, 3)
    n = len(meas.strokes)
    jac = np.zeros((n, N_LEGS, N_LEGS, PARAMS_PER_LEG))
    leg = np.arange(N_LEGS)
    jac[:, leg, leg, 0] = -1.0
    jac[:, leg, leg, 1:4] = np.einsum("nik,nkj->nij", unit, meas.rot)  # u^T R
    jac[:, leg, leg, 4:7] = -unit
    return jac.reshape(n * N_LEGS, N_PARAMS)


def identify_lm(nominal: StewartGeometry, meas: StewartMeasurements,
                initial: np.ndarray | None = None) -> StewartIdentification:
    """Levenberg-Marquardt (scipy `least_squares(method='lm')`) with the analytic Jacobian; if
    noise pushes a parameter past the model's +-MAX_JOINT_ERROR, the bounded trust-region
    solve instead. IdentificationError if the pose set leaves a combination unidentifiable."""
    x0 = np.zeros(N_PARAMS) if initial is None else np.asarray(initial, float).ravel()
    require_identifiable(identification_jacobian(x0, nominal, meas))
    def fun(x: np.ndarray) -> np.ndarray:
        return leg_residuals(x, nominal, meas).ravel()

    def jac(x: np.ndarray) -> np.ndarray:
        return identification_jacobian(x, nominal, meas)

    sol = least_squares(fun, x0, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    if np.max(np.abs(sol.x)) > MAX_JOINT_ERROR:
        # Noise drove a weakly identifiable combination past what the platform model accepts:
        # solve again within the model's range (the parameters' physical prior).
        sol = least_squares(fun, np.clip(x0, -MAX_JOINT_ERROR, MAX_JOINT_ERROR), jac=jac, method="trf",
                            bounds=(-MAX_JOINT_ERROR, MAX_JOINT_ERROR), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return StewartIdentification(sol.x.reshape(N_LEGS, PARAMS_PER_LEG),
                                 float(np.sqrt(np.mean(sol.fun**2))), scaled_singular_values(jac(sol.x)), int(sol.nfev))


def require_identifiable(jac: np.ndarray) -> None:
    """IdentificationError when the pose set leaves a parameter combination unidentifiable."""
    sv = scaled_singular_values(jac)
    if sv[-1] < RANK_TOL * sv[0]:
        raise IdentificationError(f"the pose set is rank deficient: {int(np.sum(sv < RANK_TOL * sv[0]))} "
                                  "parameter combination(s) cannot be identified; add poses with "
                                  "more rotation and translation spread")


def scaled_singular_values(jac: np.ndarray) -> np.ndarray:
    """Singular values after scaling each column to unit norm (units differ by parameter)."""
    norms = np.linalg.norm(jac, axis=0)
    return np.linalg.svd(jac / np.where(norms > 0, norms, 1.0), compute_uv=False)


def _legs(e: np.ndarray, nominal: StewartGeometry, meas: StewartMeasurements) -> np.ndarray:
    p = nominal.P + e[:, 1:4]
    b = nominal.B + e[:, 4:7]
    return meas.pos[:, None, :] + np.einsum("njk,ik->nij", meas.rot, p) - b
