"""The arm-dynamics residual's Jacobian for the fit (diagnosis/fit.py takes a family's own).

Forward differences as scipy's ``"2-point"`` takes them (step sqrt(eps) max(1, |x|), signed
like x) for every effect's parameters, and exact columns for the torque tares: a tare enters
the link channel linearly, so its column is minus its interpolation weight at the row, through
the stiction band, over the row's sigma. An episode's drifting tare has seven parameters per
knot, hundreds in all, each of which cost a whole residual evaluation by differences: with
them exact, a 12-hole episode's Jacobian costs ~30 residual evaluations instead of ~290.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_effects import BASELINE
from serpar.diagnosis.arm_dynamics_terms import Terms

Vec = NDArray[np.float64]
FD_STEP = float(np.sqrt(np.finfo(float).eps))
"""scipy.optimize's relative step for 2-point differences."""


def forward_step(x: float) -> float:
    """scipy's 2-point step at ``x``, as the float it lands on minus ``x``."""
    return (x + FD_STEP * (1.0 if x >= 0 else -1.0) * max(1.0, abs(x))) - x


class _ArmFamily(Protocol):
    terms: Terms
    _knots: Vec | None

    def residual(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec: ...

    def misfits(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                 ) -> tuple[Vec, Vec, Vec, Vec, Vec, Vec]: ...


def _tare_weights(family: _ArmFamily, rows: NDArray[np.int64]) -> Vec:
    """knots x rows: each knot's weight in the tare of each row (1 for a constant tare)."""
    knots = family._knots
    if knots is None:
        return np.ones((1, len(rows)))
    t = family.terms.time[rows]
    eye = np.eye(len(knots))
    return np.stack([np.interp(t, knots, eye[k]) for k in range(len(knots))])


def tare_columns(family: _ArmFamily, params: Mapping[str, Vec], rows: NDArray[np.int64]
                 ) -> sp.csr_matrix:
    """The residual's exact derivative by every tare parameter (knot-major, 7 per knot),
    sparse: a row's link channel depends on the two knots around it, its drive channel on none."""
    link, _, link_band, _, sigma_link, _ = family.misfits(params, rows)
    slope = (np.abs(link) > link_band) / sigma_link  # rows x 7: through the band, whitened
    weights = _tare_weights(family, rows)  # knots x rows
    n_ch = 14 if family.terms.has_command else 7
    knot, row = np.nonzero(weights)
    r_idx, c_idx, vals = [], [], []
    for j in range(7):
        v = -weights[knot, row] * slope[row, j]
        keep = v != 0
        r_idx.append(row[keep] * n_ch + j)
        c_idx.append(knot[keep] * 7 + j)
        vals.append(v[keep])
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(r_idx), np.concatenate(c_idx))),
                         shape=(len(rows) * n_ch, weights.shape[0] * 7))


def residual_jacobian(family: _ArmFamily, params: Mapping[str, Vec], rows: NDArray[np.int64]
                      ) -> Vec:
    """Columns in the mapping's block order (each block's parameters in its order)."""
    rows = np.asarray(rows, np.int64)
    base = family.residual(params, rows)
    cols = []
    for name, values in params.items():
        values = np.asarray(values, float)
        if name == BASELINE.name:
            cols.append(tare_columns(family, params, rows).toarray())
            continue
        for i in range(values.size):
            v = values.copy()
            step = forward_step(v[i])
            v[i] += step
            cols.append(((family.residual({**params, name: v}, rows) - base) / step)[:, None])
    return np.hstack(cols) if cols else np.zeros((base.size, 0))
