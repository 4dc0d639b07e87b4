"""Pose sets for the Stewart calibration (issue 6): seed 000 Table 3's 20 poses, random poses,
and an optimised set that maximises the smallest singular value of the identification
Jacobian; and the accuracy the identified model can be expected to reach from the
measurement noise and that Jacobian."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from serpar.assets import asset_path
from serpar.calibration.stewart_identification import (
    MIN_POSES,
    N_PARAMS,
    StewartMeasurements,
    identification_jacobian,
    scaled_singular_values,
)
from serpar.errors import IdentificationError
from serpar.kinematics.stewart_kinematics import (
    StewartGeometry,
    check_pose,
    inverse_kinematics,
    jacobian,
)

TABLE2_HEIGHT = 0.245
"""Height of the spherical-joint plane in seed 000's Table 2 pose [m]; Table 3's Z is above it."""


def table3_poses() -> tuple[np.ndarray, np.ndarray]:
    """Seed 000 Table 3's 20 poses as (pos (20, 3) [m], rot (20, 3, 3)); see assets/stewart/README.md."""
    rows = np.loadtxt(asset_path("stewart", "table3_poses.csv"), delimiter=",", comments="#", skiprows=4)
    x, eps, y, phi, z, theta = rows[:, 1:].T
    pos = np.column_stack([x, y, z]) * 1e-3 + [0.0, 0.0, TABLE2_HEIGHT]
    rot = Rotation.from_euler("xyz", np.column_stack([eps, phi, theta]), degrees=True).as_matrix()
    return pos, rot


def _measurements_at(geometry: StewartGeometry, pos: np.ndarray, rot: np.ndarray) -> StewartMeasurements:
    """The nominal platform exactly at the poses: what the identification Jacobian needs."""
    return StewartMeasurements(inverse_kinematics(geometry, pos, rot), pos, rot)


def smallest_singular_value(geometry: StewartGeometry, pos: np.ndarray, rot: np.ndarray) -> float:
    """Of the column-scaled identification Jacobian at the nominal model, relative to the largest."""
    sv = scaled_singular_values(identification_jacobian(np.zeros(N_PARAMS), geometry,
                                                        _measurements_at(geometry, pos, rot)))
    return float(sv[-1] / sv[0])


def optimal_poses(geometry: StewartGeometry, n: int, candidates: tuple[np.ndarray, np.ndarray],
                  seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """`n` poses chosen from `candidates` (pos, rot) to make the identification well conditioned:
    a greedy D-optimal start (each pose adds the most log-volume of J^T J), then exchange passes
    that swap a chosen pose for a candidate while that raises the smallest singular value."""
    cand_pos, cand_rot = candidates
    if not MIN_POSES <= n <= len(cand_pos):
        raise IdentificationError(f"optimal pose set of {n}: need {MIN_POSES}..{len(cand_pos)} poses "
                                  f"(the 42 parameters need at least {MIN_POSES}; {len(cand_pos)} candidates)")
    jac = identification_jacobian(np.zeros(N_PARAMS), geometry, _measurements_at(geometry, cand_pos, cand_rot))
    jac = jac / np.linalg.norm(jac, axis=0)
    blocks = jac.reshape(len(cand_pos), -1, N_PARAMS)
    info = 1e-9 * np.eye(N_PARAMS)
    chosen: list[int] = []
    for _ in range(n):
        inv = np.linalg.inv(info)
        gain = [np.linalg.slogdet(np.eye(blocks.shape[1]) + b @ inv @ b.T)[1] if k not in chosen else -np.inf
                for k, b in enumerate(blocks)]
        chosen.append(int(np.argmax(gain)))
        info = info + blocks[chosen[-1]].T @ blocks[chosen[-1]]

    def score(idx: list[int]) -> float:
        return float(np.linalg.svd(jac.reshape(len(cand_pos), -1, N_PARAMS)[idx].reshape(-1, N_PARAMS),
                                   compute_uv=False)[-1])

    best = score(chosen)
    rng = np.random.default_rng(seed)
    for _ in range(3):  # exchange passes
        improved = False
        for slot in rng.permutation(n):
            for k in rng.permutation(len(cand_pos))[:60]:
                if k in chosen:
                    continue
                trial = chosen.copy()
                trial[slot] = int(k)
                s = score(trial)
                if s > best:
                    best, chosen, improved = s, trial, True
        if not improved:
            break
    return cand_pos[chosen], cand_rot[chosen]


def reachable(geometry: StewartGeometry, pos: np.ndarray, rot: np.ndarray) -> list[str]:
    """Limit problems of each pose ('pose k: ...'), empty when all are within strokes and hinges."""
    return [f"pose {k + 1}: {'; '.join(p)}" for k, (q, r) in enumerate(zip(pos, rot)) if (p := check_pose(geometry, q, r))]


def predicted_error_rms(geometry: StewartGeometry, train: tuple[np.ndarray, np.ndarray],
                        verify: tuple[np.ndarray, np.ndarray], sigma_pos_m: float,
                        sigma_angle_rad: float) -> float:
    """RMS position error [m] of the identified model at the `verify` poses that the measurement
    noise alone leaves (first order): the pose noise maps into the leg-closure residuals through
    the leg Jacobian J_p, the least-squares estimate's covariance is
    (J^T J)^-1 J^T S J (J^T J)^-1, and the verify poses' error is J_p^-1 J_c dx."""
    meas = _measurements_at(geometry, *train)
    jc = identification_jacobian(np.zeros(N_PARAMS), geometry, meas)
    jp = jacobian(geometry, meas.pos, meas.rot)  # (N, 6, 6)
    noise = np.diag([sigma_pos_m**2] * 3 + [sigma_angle_rad**2] * 3)
    s_blocks = jp @ noise @ np.swapaxes(jp, 1, 2)
    s = np.zeros((jc.shape[0], jc.shape[0]))
    for k, block in enumerate(s_blocks):
        s[6 * k:6 * k + 6, 6 * k:6 * k + 6] = block
    a = np.linalg.pinv(jc)
    cov = a @ s @ a.T
    vmeas = _measurements_at(geometry, *verify)
    vjc = identification_jacobian(np.zeros(N_PARAMS), geometry, vmeas).reshape(len(vmeas.pos), 6, N_PARAMS)
    vjx = np.linalg.solve(jacobian(geometry, vmeas.pos, vmeas.rot), vjc)[:, :3]  # position rows
    var = np.einsum("nij,jk,nik->n", vjx, cov, vjx)  # E|dp|^2 per pose
    return float(np.sqrt(np.mean(var)))
