"""The other two identification solvers of issue 6, for comparison with Levenberg-Marquardt
(:func:`serpar.calibration.stewart_identification.identify_lm`) on the same measurements:

* total least squares, seed 000 Eq. 7-8: the pose-error model dQ = J_x dx with
  J_x = J_p^-1 J_c, solved from the SVD of the augmented matrix [J_x | dQ] and iterated
  (the model is re-linearised at each estimate, as the seed iterates until the pose error
  meets the requirement);
* the improved particle swarm of seed 002 Eq. 27-28 (inertia weight and learning factors
  that change linearly over the iterations) on seed 002's Eq. 26 objective, the sum of
  squared leg-length differences.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from serpar.calibration.stewart_identification import (
    N_LEGS,
    N_PARAMS,
    PARAMS_PER_LEG,
    StewartIdentification,
    StewartMeasurements,
    identification_jacobian,
    leg_residuals,
    require_identifiable,
    scaled_singular_values,
)
from serpar.errors import ConfigError, IdentificationError
from serpar.kinematics.stewart_kinematics import StewartGeometry, jacobian
from serpar.sim.stewart import MAX_JOINT_ERROR


def pose_error_model(errors: np.ndarray, nominal: StewartGeometry,
                     meas: StewartMeasurements) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 7's dQ (6N,) and J_x (6N, 42) at `errors`: the measured pose's error from where the
    model puts the commanded strokes, dQ_k = J_p^-1 r_k (r_k: the model's leg-length residuals
    at the measured pose), and the parameters' effect on it, J_x = -J_p^-1 J_c.

    Rows per pose: position [m], then rotation [rad] (a small twist in the base frame)."""
    residuals = leg_residuals(errors, nominal, meas)  # (N, 6)
    jc = identification_jacobian(errors, nominal, meas).reshape(len(residuals), N_LEGS, N_PARAMS)
    e = np.asarray(errors, float).reshape(N_LEGS, PARAMS_PER_LEG)
    model = dataclasses.replace(nominal, platform_joints=nominal.P + e[:, 1:4], base_joints=nominal.B + e[:, 4:7])
    jp = jacobian(model, meas.pos, meas.rot)  # (N, 6, 6): leg lengths per pose twist
    dq = np.linalg.solve(jp, residuals[..., None])[..., 0]
    jx = -np.linalg.solve(jp, jc)
    return dq.ravel(), jx.reshape(-1, N_PARAMS)


def tls_step(jx: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """Eq. 8: the total-least-squares solution of jx @ dx = dq from the right singular vector
    of [jx | dq] with the smallest singular value. Columns are scaled to unit norm first (the
    parameters mix lengths; TLS is not scale invariant) and the solution scaled back."""
    norms = np.linalg.norm(jx, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    rhs = float(np.linalg.norm(dq)) or 1.0
    _, _, vt = np.linalg.svd(np.column_stack([jx / norms, dq / rhs]), full_matrices=False)
    v = vt[-1]
    if abs(v[-1]) < 1e-12:
        raise IdentificationError("total least squares: the pose errors are orthogonal to the error "
                                  "model (smallest singular vector has no pose-error component)")
    return -v[:-1] / v[-1] / norms * rhs


def identify_tls(nominal: StewartGeometry, meas: StewartMeasurements, iterations: int = 20,
                 initial: np.ndarray | None = None, tol: float = 1e-13) -> StewartIdentification:
    """Iterated TLS: re-linearise Eq. 7 at each estimate until the update is below `tol` [m]."""
    if not 1 <= iterations <= 100:
        raise ConfigError(f"tls iterations {iterations}: valid 1..100")
    x = np.zeros(N_PARAMS) if initial is None else np.asarray(initial, float).ravel().copy()
    require_identifiable(identification_jacobian(x, nominal, meas))
    done = 0
    for done in range(1, iterations + 1):
        dq, jx = pose_error_model(x, nominal, meas)
        step = tls_step(jx, dq)
        x += step
        if np.max(np.abs(x)) > MAX_JOINT_ERROR:
            # TLS perturbs the Jacobian too: when noise is above the Jacobian's smallest scaled
            # singular values it follows the weakest direction instead of the data.
            raise IdentificationError(
                f"total least squares diverged at iteration {done}: a parameter reached "
                f"{np.max(np.abs(x)) * 1e3:.1f} mm, beyond the model's +-{MAX_JOINT_ERROR * 1e3:g} mm (the "
                "measurement noise exceeds what this pose set's conditioning allows TLS; use lm)")
        if np.max(np.abs(step)) < tol:
            break
    return _result(x, nominal, meas, done)


@dataclass(frozen=True)
class SwarmConfig:
    """Seed 002 Tab. 2's improved PSO, sized for 42 parameters instead of 6 (the seed used
    10 000 particles x 1 000 iterations on 6; that is 2 h of numpy here for 42)."""

    particles: int = 400
    iterations: int = 1500
    c1: tuple[float, float] = (0.5, 1.5)
    """Individual learning factor (min, max): decreases over the run (Eq. 27)."""
    c2: tuple[float, float] = (0.5, 1.5)
    """Social learning factor (min, max): increases over the run."""
    inertia: tuple[float, float] = (0.2, 0.8)
    """Inertia weight (min, max): decreases over the run."""
    search_m: float = 0.01
    """Search range of every parameter, +- [m] (seed 002: +-20 mm for its 6 errors)."""
    max_speed_fraction: float = 0.1
    """Velocity clamp as a fraction of the search range (seed 002: 0.05 of 20... per step)."""
    seed: int = 0

    def __post_init__(self) -> None:
        if not (2 <= self.particles <= 100_000 and 1 <= self.iterations <= 100_000):
            raise ConfigError(f"pso particles {self.particles} (valid 2..100000), iterations "
                              f"{self.iterations} (valid 1..100000)")
        for name in ("c1", "c2", "inertia"):
            lo, hi = getattr(self, name)
            if not 0 <= lo <= hi:
                raise ConfigError(f"pso {name} {getattr(self, name)}: need 0 <= min <= max")
        if not (0 < self.search_m <= 0.05 and 0 < self.max_speed_fraction <= 1):
            raise ConfigError(f"pso search_m {self.search_m} (valid 0..0.05 m), max_speed_fraction "
                              f"{self.max_speed_fraction} (valid 0..1)")


def swarm_objective(x: np.ndarray, nominal: StewartGeometry, meas: StewartMeasurements) -> np.ndarray:
    """Seed 002 Eq. 26 for a swarm: sum of squared leg-length differences, (P, 42) -> (P,)."""
    e = x.reshape(-1, N_LEGS, PARAMS_PER_LEG)
    p = nominal.P + e[:, :, 1:4]  # (P, 6, 3)
    b = nominal.B + e[:, :, 4:7]
    legs = meas.pos[None, :, None, :] + np.einsum("nkj,pij->pnik", meas.rot, p) - b[:, None]
    r = np.linalg.norm(legs, axis=-1) - (nominal.l_min + e[:, None, :, 0] + meas.strokes[None])
    return np.sum(r * r, axis=(1, 2))


def identify_pso(nominal: StewartGeometry, meas: StewartMeasurements,
                 cfg: SwarmConfig = SwarmConfig()) -> StewartIdentification:
    """Eq. 27-28: v <- w v + c1 r1 (pBest - x) + c2 r2 (gBest - x); x <- x + v, within the range."""
    require_identifiable(identification_jacobian(np.zeros(N_PARAMS), nominal, meas))
    rng = np.random.default_rng(cfg.seed)
    lim, vmax = cfg.search_m, cfg.max_speed_fraction * cfg.search_m
    x = rng.uniform(-lim, lim, (cfg.particles, N_PARAMS))
    v = rng.uniform(-vmax, vmax, x.shape)
    cost = swarm_objective(x, nominal, meas)
    best_x, best_cost = x.copy(), cost.copy()
    g = int(np.argmin(cost))
    for t in range(cfg.iterations):
        frac = t / cfg.iterations
        c1 = cfg.c1[1] - (cfg.c1[1] - cfg.c1[0]) * frac
        c2 = cfg.c2[0] + (cfg.c2[1] - cfg.c2[0]) * frac
        w = cfg.inertia[1] - (cfg.inertia[1] - cfg.inertia[0]) * frac
        r1, r2 = rng.random(x.shape), rng.random(x.shape)
        v = np.clip(w * v + c1 * r1 * (best_x - x) + c2 * r2 * (best_x[g] - x), -vmax, vmax)
        x = np.clip(x + v, -lim, lim)
        cost = swarm_objective(x, nominal, meas)
        better = cost < best_cost
        best_x[better], best_cost[better] = x[better], cost[better]
        g = int(np.argmin(best_cost))
    return _result(best_x[g], nominal, meas, cfg.iterations)


def _result(x: np.ndarray, nominal: StewartGeometry, meas: StewartMeasurements,
            iterations: int) -> StewartIdentification:
    r = leg_residuals(x, nominal, meas)
    return StewartIdentification(np.asarray(x).reshape(N_LEGS, PARAMS_PER_LEG), float(np.sqrt(np.mean(r**2))),
                                 scaled_singular_values(identification_jacobian(x, nominal, meas)), iterations)
