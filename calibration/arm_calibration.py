"""Arm kinematic calibration as staged pure functions (FIGAROH's regressor -> base parameters
-> solve -> metrics), for the geometric and the gravity-aware model of seed 003, in either
form of the geometric error model (MD-H+beta or POE, :attr:`serpar.calibration.arm_error_models.ArmModel.form`).

1. :func:`identifiability_of`: error Jacobian of a generic pose set of the campaign's layout
   -> which parameters are independent, correlated or non-functional; then the campaign's own
   Jacobian must identify them all (too few poses and rank-deficient pose sets fail here,
   saying what is missing);
2. :func:`solve`: Levenberg-Marquardt (scipy ``least_squares``) on the independent
   parameters only, the others held at nominal (the redundancy elimination); the paper's
   regularisation, optional, as a Gaussian prior (:class:`serpar.calibration.arm_error_models.Prior`) that
   keeps weakly identifiable combinations near nominal;
3. :func:`position_error_stats` / :func:`consistency_stats`: the metrics on held-out data.

:func:`calibrate` runs stages 1-2; :func:`calibrate_gravity_aware` fits both models and keeps
the compliances only if an F-test on the training residuals says the data support them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.stats
from numpy.typing import NDArray
from scipy.optimize import least_squares

from serpar.calibration.arm_error_models import (
    ArmModel,
    Layout,
    fitted_mask,
    initial_parameters,
    layout,
    parameter_names,
    predict,
    preference,
    prior_sigma,
    residuals_and_jacobian,
)
from serpar.calibration.arm_identifiability import (
    IdentifiabilityReport,
    check_design,
    identifiability,
)
from serpar.calibration.poe_design import design_for
from serpar.errors import IdentificationError
from serpar.sim.arm_measurements import Measurements, PointSet

COMPLIANCE_ALPHA = 0.01
"""Significance level at which the joint compliances must improve the fit to be kept."""
GROSS_ERROR_M = 0.05
"""A measured tool point this far from the nominal prediction is a wrong frame or pairing."""


@dataclass(frozen=True)
class ArmCalibration:
    """An identified model: the full parameter vector (layout of :mod:`serpar.calibration.arm_error_models`)."""

    model: ArmModel
    layout: Layout
    names: tuple[str, ...]
    x: NDArray[np.float64]
    report: IdentifiabilityReport
    covariance: NDArray[np.float64]
    """Covariance of the independent parameters from the stated noise levels (and the prior,
    if the model has one), not rescaled by the residuals."""
    residual_rms: float
    """RMS of the noise-weighted residuals: about 1 when the model explains the data."""
    n_residuals: int
    nfev: int

    @property
    def chain_errors(self) -> NDArray[np.float64]:
        return self.layout.split(self.x)[1]

    @property
    def compliance(self) -> NDArray[np.float64]:
        return self.layout.split(self.x)[2]

    @property
    def points(self) -> NDArray[np.float64]:
        return self.layout.split(self.x)[0]

    def predict_positions(self, q: NDArray[np.float64], tau: NDArray[np.float64] | None = None
                          ) -> NDArray[np.float64]:
        """(N, 3) tool points at encoder angles q."""
        return predict(self.model, self.x, self.layout, q, tau)[:, :3, 3]


def identifiability_of(model: ArmModel, meas: Measurements,
                       x0: NDArray[np.float64] | None = None) -> IdentifiabilityReport:
    """Stage 1: the model's redundancies (from a generic pose set of the same layout), with
    the condition number of this pose set. IdentificationError when the campaign has too few
    poses or leaves a parameter unidentifiable that the generic set identifies."""
    x0 = initial_parameters(model, meas) if x0 is None else np.asarray(x0, float)
    names = parameter_names(model, meas)
    fitted, order = fitted_mask(model, meas), preference(model, meas)
    gen, gen_x0 = design_for(model, meas, x0)
    generic = identifiability(residuals_and_jacobian(model, gen, gen_x0)[1], names, fitted,
                              order)
    jac = residuals_and_jacobian(model, meas, x0)[1]
    keep = np.zeros(len(names), bool)
    keep[list(generic.independent)] = True
    actual = identifiability(jac, names, keep, order)
    check_design(actual, generic, meas.n_poses, jac.shape[0])
    return replace(generic, condition=actual.condition, weak=actual.weak)


def solve(model: ArmModel, meas: Measurements, report: IdentifiabilityReport,
          x0: NDArray[np.float64]) -> ArmCalibration:
    """Stage 2: Levenberg-Marquardt on the independent parameters."""
    free = np.asarray(report.independent, int)
    prior = 1.0 / prior_sigma(model, meas)[free]  # 0 where none; the prior's mean is zero
    cache: dict[bytes, tuple[NDArray[np.float64], NDArray[np.float64]]] = {}

    def full(z: NDArray[np.float64]) -> NDArray[np.float64]:
        x = x0.copy()
        x[free] = z
        return x

    def evaluate(z: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        key = z.tobytes()
        if key not in cache:
            cache.clear()
            r, j = residuals_and_jacobian(model, meas, full(z))
            r, j = np.r_[r, prior * z], np.vstack([j[:, free], np.diag(prior)])
            cache[key] = (r, j)
        return cache[key]

    sol = least_squares(lambda z: evaluate(z)[0], x0[free], jac=lambda z: evaluate(z)[1],
                        method="lm", x_scale="jac", xtol=1e-13, ftol=1e-13, gtol=1e-13)
    r, j = evaluate(sol.x)
    cov = np.linalg.pinv(j.T @ j)
    r = r[:len(r) - len(free)]
    return ArmCalibration(model, layout(model, meas), parameter_names(model, meas), full(sol.x),
                          report, cov, float(np.sqrt(np.mean(r**2))), len(r), int(sol.nfev))


def calibrate(model: ArmModel, meas: Measurements,
              start: NDArray[np.float64] | None = None) -> ArmCalibration:
    """Identify ``model`` from ``meas``: start point, stage 1, stage 2. ``start`` (chain
    errors, e.g. a tool offset fitted first) must not sit at a special configuration such as
    a tool point on the last joint's axis, where the redundancies differ from the solution's."""
    x0 = initial_parameters(model, meas, start)
    if hasattr(meas, "position"):
        nominal = predict(model, x0, layout(model, meas), meas.q, meas.tau_gravity)[:, :3, 3]
        gap = np.linalg.norm(nominal - meas.position, axis=1)
        far = np.flatnonzero(gap > GROSS_ERROR_M)
        if far.size:
            raise IdentificationError(
                f"measured point of pose {int(far[0])} is {gap[far[0]] * 1e3:.1f} mm from the "
                f"nominal model's ({far.size} pose(s) beyond {GROSS_ERROR_M * 1e3:g} mm): "
                "wrong frame, unit, tool offset or joint/point pairing")
    return solve(model, meas, identifiability_of(model, meas, x0), x0)


@dataclass(frozen=True)
class ComplianceTest:
    """F-test of the gravity-aware against the geometric model on the training data: is the
    drop in the residual sum of squares more than the extra compliances would buy from noise
    alone? Scale-free, so it holds when the stated noise level is only a guess."""

    f_statistic: float
    p_value: float
    dof: tuple[int, int]
    significant: bool

    def as_dict(self) -> dict[str, object]:
        return {"f_statistic": self.f_statistic, "p_value": self.p_value,
                "dof": list(self.dof), "significant": self.significant}


def compliance_test(geometric: ArmCalibration, gravity: ArmCalibration,
                    alpha: float = COMPLIANCE_ALPHA) -> ComplianceTest:
    rss_geo = geometric.residual_rms**2 * geometric.n_residuals
    rss_grav = gravity.residual_rms**2 * gravity.n_residuals
    extra = gravity.report.rank - geometric.report.rank
    dof = gravity.n_residuals - gravity.report.rank
    if extra <= 0 or dof <= 0:
        raise IdentificationError(f"cannot test the compliances: {extra} extra parameter(s), "
                                  f"{dof} residual degree(s) of freedom")
    f = max(rss_geo - rss_grav, 0.0) / extra / (rss_grav / dof)
    p = float(scipy.stats.f.sf(f, extra, dof))
    return ComplianceTest(float(f), p, (extra, dof), p < alpha)


def calibrate_gravity_aware(model: ArmModel, meas: Measurements,
                            start: NDArray[np.float64] | None = None,
                            alpha: float = COMPLIANCE_ALPHA
                            ) -> tuple[ArmCalibration, ComplianceTest]:
    """The gravity-aware calibration that does not over-fit: the compliances are kept only
    when the data support them (:func:`compliance_test`), else the geometric fit is returned."""
    gravity = calibrate(replace(model, gravity=True), meas, start)
    geometric = calibrate(replace(model, gravity=False), meas, start)
    test = compliance_test(geometric, gravity, alpha)
    return (gravity if test.significant else geometric), test


@dataclass(frozen=True)
class ErrorStats:
    """Position errors (model - measured) over a pose set [m]."""

    mean_abs: tuple[float, float, float]
    max_abs: tuple[float, float, float]
    mean: float
    max: float
    rms: float

    def as_dict(self) -> dict[str, object]:
        return {"mean_abs_xyz_m": list(self.mean_abs), "max_abs_xyz_m": list(self.max_abs),
                "mean_m": self.mean, "max_m": self.max, "rms_m": self.rms}


def position_error_stats(predicted: NDArray[np.float64], measured: NDArray[np.float64]
                         ) -> ErrorStats:
    err = np.asarray(predicted, float) - np.asarray(measured, float)
    norm = np.linalg.norm(err, axis=1)
    return ErrorStats(tuple(np.abs(err).mean(axis=0)), tuple(np.abs(err).max(axis=0)),
                      float(norm.mean()), float(norm.max()), float(np.sqrt(np.mean(norm**2))))


@dataclass(frozen=True)
class ConsistencyStats:
    """Point consistency of a socket set: how far each pose's predicted centre lies from its
    socket's mean centre, and how far the mean centres miss the fixture distances [m]."""

    spread_mean: float
    spread_rms: float
    spread_max: float
    distance_errors: tuple[float, ...]

    def as_dict(self) -> dict[str, object]:
        return {"spread_mean_m": self.spread_mean, "spread_rms_m": self.spread_rms,
                "spread_max_m": self.spread_max,
                "distance_errors_m": list(self.distance_errors)}


def consistency_stats(predicted: NDArray[np.float64], meas: PointSet) -> ConsistencyStats:
    p = np.asarray(predicted, float)
    centres = np.array([p[meas.point == i].mean(axis=0) for i in range(meas.n_points)])
    spread = np.linalg.norm(p - centres[meas.point], axis=1)
    dist = tuple(float(np.linalg.norm(centres[a] - centres[b]) - d)
                 for a, b, d in meas.distances)
    return ConsistencyStats(float(spread.mean()), float(np.sqrt(np.mean(spread**2))),
                            float(spread.max()), dist)
