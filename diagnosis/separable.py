"""Variable projection for a baseline that enters the residual piecewise linearly.

An episode's drifting torque tare has seven parameters per 2-s knot, hundreds in all, against
a few tens for the effects. Fitted jointly, every trust-region step of the fit factorises the
whole Jacobian (thousands of rows by hundreds of columns) and the tares' poor scaling costs
iterations. But the tare enters the link channel linearly, through the stiction band, so for
given effect parameters the best tare is a small convex problem of its own. Golub and
Pereyra's variable projection fits the effects on the residual with the tare solved out:

    r_p(theta) = r(theta, t*(theta)),  t*(theta) = argmin_t |r(theta, t)|^2
    J_p = (I - B (B^T B)^-1 B^T) J_theta          (Kaufman's approximation)

where B is the residual's derivative by the tare (sparse: a row depends on the two knots
around it) and J_theta by the effects. At a solution (theta, t*(theta)) is a stationary point
of the joint problem, and the effects' covariance from J_p equals the joint fit's (the Schur
complement), so the fit's answer is the joint fit's, reached with small factorisations.

A family offers ``baseline_columns(params, rows)`` (sparse d residual / d baseline, exact for
the rows' current side of the band) to be fitted this way; :func:`fit_model` falls back to the
joint fit otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve

Vec = NDArray[np.float64]
Rows = NDArray[np.int64]

MAX_STEPS = 30
"""Gauss-Newton steps of one profile; a convex piecewise-linear problem settles its side of
the band in a few, after which a step is exact."""
RIDGE = 1e-12
"""Relative ridge on the normal matrix: a knot no row outside the band reaches is not moved
(its column is zero there) instead of making the matrix singular."""
REL_TOL = 1e-13
"""A profile is done when a step lowers the sum of squares by less than this share of it."""


class SeparableFamily(Protocol):
    def residual(self, params: Mapping[str, Vec], rows: Rows) -> Vec: ...

    def baseline_columns(self, params: Mapping[str, Vec], rows: Rows) -> sp.csr_matrix: ...


DENSE_COLUMNS = 64
"""A baseline with at most this many columns (one constant tare per sensor) is solved dense:
sparse factorisation costs more than it saves on a handful of columns."""


class _Normal:
    """The factorised normal matrix of ``b``, with the ridge: ``solve(b.T @ y)``."""

    def __init__(self, b: sp.csr_matrix) -> None:
        self._dense = b.shape[1] <= DENSE_COLUMNS
        normal = b.T @ b
        normal = normal.toarray() if self._dense else normal.tocsc()
        diag = normal.diagonal()
        scale = float(diag.max()) if diag.size and diag.max() > 0 else 1.0
        ridge = RIDGE * scale
        if self._dense:
            self._factor = cho_factor(normal + ridge * np.eye(normal.shape[0]))
        else:
            self._lu = spla.splu(normal + sp.identity(normal.shape[0], format="csc") * ridge)

    def solve(self, rhs: Vec) -> Vec:
        return cho_solve(self._factor, rhs) if self._dense else self._lu.solve(rhs)


def profile(family: SeparableFamily, params: Mapping[str, Vec], name: str, lower: Vec,
            upper: Vec, rows: Rows) -> tuple[Vec, Vec]:
    """The baseline ``name`` that minimises the residual's sum of squares with every other
    block held at ``params`` (start: ``params[name]``), and that residual."""
    t = np.clip(np.asarray(params[name], float), lower, upper)
    current = {**params, name: t}
    r = family.residual(current, rows)
    cost = float(r @ r)
    for _ in range(MAX_STEPS):
        b = family.baseline_columns(current, rows)
        if b.nnz == 0:
            break
        step = -_Normal(b).solve(np.asarray(b.T @ r).ravel())
        for _halving in range(30):
            trial_t = np.clip(t + step, lower, upper)
            trial = {**params, name: trial_t}
            r_new = family.residual(trial, rows)
            new_cost = float(r_new @ r_new)
            if new_cost <= cost:
                break
            step = step / 2
        else:
            break
        gain = cost - new_cost
        t, current, r, cost = trial_t, trial, r_new, new_cost
        if gain <= REL_TOL * max(cost, 1e-300):
            break
    return t, r


def projected(jac: Vec, n_base: int, b: sp.csr_matrix) -> Vec:
    """The effects' columns of ``jac`` (after the first ``n_base``, the baseline's) with their
    component along the baseline's columns ``b`` removed."""
    rest = jac[:, n_base:]
    if b.nnz == 0 or rest.shape[1] == 0:
        return rest
    coef = _Normal(b).solve(np.asarray(b.T @ rest))
    return rest - b @ coef
