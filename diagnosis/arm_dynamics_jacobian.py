"""The arm-dynamics residual's Jacobian for the fit (diagnosis/fit.py takes a family's own).

Exact columns for the effects linear in their parameters (friction, rotor inertia, a coupled
motor, a torque gain: :func:`linear_columns`), for the sigmoid friction's, the Stribeck fall's
and the payload's (:func:`payload_columns`: held from the first step on in a cell with a hand's
load, its 10 columns by differences cost ten residual evaluations per iteration of every later
fit), forward differences as scipy's ``"2-point"`` takes them (step sqrt(eps) max(1, |x|),
signed like x) for every other effect's,
and exact columns for the torque tares: a tare enters
the link channel linearly, so its column is minus its interpolation weight at the row, through
the stiction band, over the row's sigma. An episode's drifting tare has seven parameters per
knot, hundreds in all, each of which cost a whole residual evaluation by differences: with
them exact, a 12-hole episode's Jacobian costs ~30 residual evaluations instead of ~290.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Protocol

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_effects import INERTIAL, SIGMOID, TILT, EffectModels
from serpar.diagnosis.arm_dynamics_payload import standard_jacobian
from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.family import Effect
from serpar.diagnosis.memo import Memo

Vec = NDArray[np.float64]
FD_STEP = float(np.sqrt(np.finfo(float).eps))
"""scipy.optimize's relative step for 2-point differences."""


def forward_step(x: float) -> float:
    """scipy's 2-point step at ``x``, as the float it lands on minus ``x``."""
    return (x + FD_STEP * (1.0 if x >= 0 else -1.0) * max(1.0, abs(x))) - x


class _ArmFamily(Protocol):
    terms: Terms
    _knots: Vec | None
    baseline: Effect | None
    channels: tuple[str, ...]
    tare_block: str
    _blocks: tuple[str, ...]
    _models: EffectModels
    n: int

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
    """The residual's exact derivative by every tare parameter (knot-major, n per knot),
    sparse: a row's measured channel (the link-side sensors, else the drive torque) depends on
    the two knots around it, any other channel on none."""
    link, drive, link_band, band, sigma_link, sigma_drive = family.misfits(params, rows)
    if family.tare_block == "link":
        slope = (np.abs(link) > link_band) / sigma_link  # rows x n: through the band, whitened
    else:
        slope = (np.abs(drive) > band) / sigma_drive
    n = family.n
    first = family._blocks.index(family.tare_block) * n
    knots = family._knots
    pattern = _PATTERNS(lambda: _tare_pattern(_tare_weights(family, rows), n,
                                              len(family.channels), first),
                        family.terms.time[rows], np.zeros(0) if knots is None else knots,
                        f"{n} {len(family.channels)} {first}")
    weight, gather, indices, indptr, shape = pattern
    b = sp.csr_matrix((weight * slope.ravel()[gather], indices, indptr), shape=shape)
    b.eliminate_zeros()  # rows inside the band: no column (a profile with none stops)
    return b


_PATTERNS: Memo[tuple[Vec, NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
                      tuple[int, int]]] = Memo()
"""The tare columns' sparsity and weights per row set (the slope through the band changes
with the parameters, the rest does not)."""


def _tare_pattern(weights: Vec, n: int, n_ch: int, first: int
                  ) -> tuple[Vec, NDArray[np.int64], NDArray[np.int64], NDArray[np.int64],
                             tuple[int, int]]:
    """CSR layout of the tare columns for knot weights (knots x rows): minus each entry's
    weight, the index of its slope in ``slope.ravel()``, the column indices, the row pointer
    and the shape."""
    knot, row = np.nonzero(weights)
    j = np.arange(n)
    res_row = (row[:, None] * n_ch + first + j[None, :]).ravel()
    col = (knot[:, None] * n + j[None, :]).ravel()
    weight = -np.repeat(weights[knot, row], n)
    gather = (row[:, None] * n + j[None, :]).ravel()
    order = np.lexsort((col, res_row))
    shape = (weights.shape[1] * n_ch, weights.shape[0] * n)
    indptr = np.r_[0, np.cumsum(np.bincount(res_row, minlength=shape[0]))]
    return weight[order], gather[order], col[order], indptr, shape


LINEAR = ("joint_friction", "link_friction", "armature", "torque_sensor", INERTIAL)
"""Effects linear in their parameters that leave the rows' sigma alone (a coupled motor's
block too): their residual columns are exact (:func:`linear_columns`), not differences."""
EXACT = (*LINEAR, SIGMOID, TILT, "stribeck_friction")
"""Effects whose columns are exact: the linear ones, the sigmoid friction's and the base
tilt's (analytic), the Stribeck fall's (of its log-speed interpolant)."""


def linear_columns(models: EffectModels, name: str, params: Mapping[str, Vec],
                   rows: NDArray[np.int64]) -> tuple[Vec, Vec, Vec, Vec] | None:
    """d(link model), d(drive model), d(link band), d(drive band) per parameter of ``name``
    (each params x rows x n), or None where the effect is not linear (differences then)."""
    t, n, k = models.terms, models.n, len(rows)
    p = params[name]
    size = p.size
    link, drive = np.zeros((size, k, n)), np.zeros((size, k, n))
    link_band, band = np.zeros((size, k, n)), np.zeros((size, k, n))
    j = np.arange(n)
    if name in ("joint_friction", "link_friction"):
        sign = np.sign(p[:n])
        drive[j, :, j] = models.coulomb[rows].T
        drive[n + j, :, j] = models.viscous[rows].T
        band[j, :, j] = (models.stuck[rows] * sign).T
        if name == "link_friction":
            link[j, :, j] = models.coulomb_link[rows].T
            link[n + j, :, j] = models.viscous_link[rows].T
            link_band[j, :, j] = (models.stuck_link[rows] * sign).T
    elif name == "armature":
        drive[j, :, j] = models.acceleration[rows].T
    elif name == SIGMOID:
        drive = models.sigmoid.columns(p, rows)
    elif name == "stribeck_friction":
        drive, band = models.stribeck.columns(p, rows, models.stuck[rows])
    elif name == TILT:
        link, drive = models.tilt.columns(p, rows)
        if not t.has_link:
            link = np.zeros_like(drive)
    elif name == INERTIAL:
        if models.inertial is None:
            return None
        link, drive = models.inertial.columns_at(rows)
        if not t.has_link:
            link = np.zeros_like(drive)
    elif name == "torque_sensor":
        if t.has_link:
            link[j, :, j] = t.tau_link_model[rows].T
        else:
            drive[j, :, j] = t.tau_full_model[rows].T
    else:
        coupling = dict(models._coupled(params)).get(name)
        if coupling is None:
            return None
        a, m = coupling.joint - 1, coupling.motor - 1
        for here, other in ((a, m), (m, a)):
            drive[0, :, here] = models.acceleration[rows, other]
            drive[1, :, here] = models.viscous[rows, other]
            drive[2, :, here] = models.motor_sign[coupling][rows]
            band[2, :, here] = models.motor_stuck[coupling][rows] * np.sign(p[2])
    return link, drive, link_band, band


def _exact(family: _ArmFamily, params: Mapping[str, Vec], rows: NDArray[np.int64], name: str,
           misfit: tuple[Vec, ...]) -> Vec | None:
    """The exact columns of an effect linear in its parameters (arm_dynamics_effects.LINEAR,
    a coupled motor): through the stiction band where the misfit is outside it, whitened."""
    parts = linear_columns(family._models, name, params, rows)
    if parts is None:
        return None
    d_link, d_drive, d_link_band, d_band = parts
    link, drive, link_band, band, sigma_link, sigma_drive = misfit
    outside_link = (np.abs(link) > link_band).astype(float)
    outside = (np.abs(drive) > band).astype(float)
    out = {"link": -outside_link * (d_link + np.sign(link) * d_link_band) / sigma_link,
           "drive": -outside * (d_drive + np.sign(drive) * d_band) / sigma_drive}
    # params x rows x (blocks x n), row-major like the residual
    cols = np.concatenate([out[b] for b in family._blocks], axis=2)
    return cols.reshape(cols.shape[0], -1).T


def payload_columns(family: _ArmFamily, params: Mapping[str, Vec], rows: NDArray[np.int64],
                    misfit: tuple[Vec, ...]) -> Vec:
    """The residual's exact derivative by the payload's 10 parameters: its torque is linear in
    the standard inertial parameters (the link channel's read ``lag`` late where the sensors'
    timing is fitted), the rows' sigma carries the inertia it adds (the acceleration noise's
    share), and the standard parameters are a polynomial in the payload's
    (:func:`~serpar.diagnosis.arm_dynamics_payload.standard_jacobian`)."""
    models, t = family._models, family.terms
    link, drive, link_band, band, sigma_link, sigma_drive = misfit
    d_phi = standard_jacobian(np.asarray(params["payload"], float), models.flange)
    d_link = models.payload_link[rows]
    if "sensor_timing" in params:
        d_link = d_link - float(params["sensor_timing"][0]) * models.payload_link_rate[rows]
    d_drive = models.payload_drive[rows]
    # sigma^2 = measured + sum_m (M + added)_jm^2 acc_var_m (+ a tare's variance): its change
    added = models.added_inertia(params, rows)
    d_added = models.payload_mass[rows]  # rows x n x n x 10
    out = {}
    for name, e, b, sigma, d_model, mass in (
            ("link", link, link_band, sigma_link, d_link, t.mass_link[rows]),
            ("drive", drive, band, sigma_drive, d_drive, t.mass_full[rows])):
        g = np.sign(e) * np.maximum(np.abs(e) - b, 0.0)
        d_sigma = np.einsum("rjm,m,rjmk->rjk", mass + added, t.acc_var, d_added) / sigma[..., None]
        outside = (np.abs(e) > b).astype(float)
        d_r = (-outside[..., None] * d_model - (g / sigma)[..., None] * d_sigma) / sigma[..., None]
        out[name] = d_r @ d_phi  # rows x n x 10
    cols = np.concatenate([out[b] for b in family._blocks], axis=1)
    return cols.reshape(-1, cols.shape[-1])


def residual_jacobian(family: _ArmFamily, params: Mapping[str, Vec], rows: NDArray[np.int64],
                      skip: Collection[str] = ()) -> Vec:
    """Columns in the mapping's block order (each block's parameters in its order), the blocks
    in ``skip`` left out (a fit by variable projection has its tare's columns apart, sparse)."""
    rows = np.asarray(rows, np.int64)
    base = family.residual(params, rows)
    misfit = family.misfits(params, rows)
    cols = []
    for name, values in params.items():
        if name in skip:
            continue
        values = np.asarray(values, float)
        if family.baseline is not None and name == family.baseline.name:
            cols.append(tare_columns(family, params, rows).toarray())
            continue
        if name == "payload":
            cols.append(payload_columns(family, params, rows, misfit))
            continue
        exact = (_exact(family, params, rows, name, misfit)
                 if name in EXACT or name.startswith("coupled_pair") else None)
        if exact is not None:
            cols.append(exact)
            continue
        for i in range(values.size):
            v = values.copy()
            step = forward_step(v[i])
            v[i] += step
            cols.append(((family.residual({**params, name: v}, rows) - base) / step)[:, None])
    return np.hstack(cols) if cols else np.zeros((base.size, 0))
