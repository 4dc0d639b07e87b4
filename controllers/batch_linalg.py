"""Linear algebra over a batch of trials (a leading axis of N): each as one trial's own call
would compute it, so a batch of one is bitwise the single-trial controller."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Arr = NDArray[np.float64]


def mat_vec(mat: Arr, vec: Arr) -> Arr:
    """(..., m, n) @ (..., n) -> (..., m): np.matmul runs the BLAS gemv per trial that a single
    ``mat @ vec`` runs, bitwise the same where each trial's matrix has the single one's memory
    layout (C or Fortran order picks the kernel); np.einsum sums in another order."""
    return np.matmul(mat, vec[..., None])[..., 0]


def dot(a: Arr, b: Arr) -> Arr:
    """Row-wise a . b over (..., n) by BLAS ddot, as a single ``a @ b`` on vectors."""
    return np.matmul(a[..., None, :], b[..., :, None])[..., 0, 0]


def inverse_each(a: Arr) -> Arr:
    """The inverse of each matrix of a stack; a singular one (an arm at a singularity, a world a
    failed step left at qpos0) gets its pseudo-inverse instead of stopping every world."""
    try:
        return np.linalg.inv(a)
    except np.linalg.LinAlgError:
        out = np.empty_like(a)
        for i, m in enumerate(a):
            try:
                out[i] = np.linalg.inv(m)
            except np.linalg.LinAlgError:
                out[i] = np.linalg.pinv(m)
        return out
