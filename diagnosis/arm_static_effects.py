"""The candidate library of the static arm family and its rank test.

Each effect starts from its full parameter list; a parameter is kept only when its column of
the (whitened) residual Jacobian stands clear of the span of the baseline's columns and of
the effect's columns kept before it (sequential QR, unit columns, distance > RANK_TOL). The
Jacobian is taken by central differences at the baseline fitted to every row and a probe
point of the effect (a backlash's friction threshold only shows once there is a clearance).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from serpar.calibration.arm_error_models import PREFERENCE
from serpar.diagnosis.family import Effect

if TYPE_CHECKING:
    from serpar.diagnosis.arm_static_family import StaticArmFamily

RANK_TOL = 1e-6
"""A unit column closer than this to the span of the kept ones is not identifiable here."""
NULL_TOL = 1e-9


def chain_rank(name: str) -> int:
    """serpar.calibration.arm_error_models's order of preference for keeping a chain parameter."""
    for key, r in PREFERENCE:
        if name.startswith(key) or (key.startswith(".") and name.endswith(key)):
            return r
    return 2


def independent_columns(jac: NDArray[np.float64], n_fixed: int, tol: float = RANK_TOL
                        ) -> NDArray[np.int64]:
    """Indices (>= n_fixed, relative to the full matrix) of the columns kept after the first
    ``n_fixed`` (always kept), in column order."""
    norms = np.linalg.norm(jac, axis=0)
    scale = norms.max() if norms.size else 0.0
    basis = np.zeros((jac.shape[0], 0))
    for c in range(n_fixed):
        if norms[c] > NULL_TOL * scale:
            basis = _extend(basis, jac[:, c] / norms[c])
    kept = []
    for c in range(n_fixed, jac.shape[1]):
        if norms[c] <= NULL_TOL * scale:
            continue
        u = jac[:, c] / norms[c]
        rest = u - basis @ (basis.T @ u)
        rest = rest - basis @ (basis.T @ rest)  # re-orthogonalise (Gram-Schmidt twice)
        if np.linalg.norm(rest) > tol:
            kept.append(c)
            basis = _extend(basis, rest / np.linalg.norm(rest))
    return np.asarray(kept, np.int64)


def _extend(basis: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    rest = u - basis @ (basis.T @ u)
    n = np.linalg.norm(rest)
    return basis if n < 1e-12 else np.column_stack([basis, rest / n])


def _full_effects(fam: StaticArmFamily) -> list[tuple[Effect, NDArray[np.float64]]]:
    """Every candidate with all its parameters, and the probe point of its rank test."""

    chain, out = fam.chain, []
    base = set(fam.baseline.param_names) if fam.baseline is not None else set()
    geo = sorted((i for i, n in enumerate(chain.names) if n not in base),
                 key=lambda i: (chain_rank(chain.names[i]), i))
    names = tuple(chain.names[i] for i in geo)
    units = tuple("m" if chain.kinds[i][0] == "t" else "rad" for i in geo)
    out.append((Effect("geometric", "geometric (MD-H) parameter errors", names, units,
                       np.zeros(len(geo)), np.full(len(geo), -0.05), np.full(len(geo), 0.05)),
                np.zeros(len(geo))))
    fam.geo_idx = np.asarray(geo, int)
    nj = chain.n_joints  # the arm's joints (the Panda's 7 unless --robot names another)
    j = range(1, nj + 1)
    out.append((Effect("joint_compliance", "joint compliance (gravitational deflection)",
                       tuple(f"c{k}" for k in j), ("rad/(N m)",) * nj,
                       np.zeros(nj), np.zeros(nj), np.full(nj, 1e-3),
                       physical_lower=True),
                np.zeros(nj)))
    friction = fam.data.approach is not None
    bn = tuple(f"b{k}" for k in j) + (("f",) if friction else ())
    bu = ("rad",) * nj + (("N m",) if friction else ())
    lo = np.zeros(len(bn))
    hi = np.r_[np.full(nj, 0.02), [3.0] if friction else []]
    x0 = np.r_[np.zeros(nj), [0.2] if friction else []]
    out.append((Effect("backlash", "joint backlash (clearance between motor and link)", bn, bu,
                       x0, lo, hi, physical_lower=True), np.r_[np.full(nj, 1e-3), x0[nj:]]))
    en = tuple(f"o{k}" for k in j) + tuple(f"s{k}" for k in j)
    out.append((Effect("encoder", "encoder offset and scale (transmission error)", en,
                       ("rad",) * nj + ("-",) * nj, np.zeros(2 * nj),
                       np.full(2 * nj, -0.05), np.full(2 * nj, 0.05)),
                np.zeros(2 * nj)))
    if fam.t is not None and np.ptp(fam.t) > 0:
        out.append((Effect("thermal_drift", "thermal drift of link lengths over time",
                           ("kappa",), ("1/s",), np.zeros(1), np.full(1, -1e-6),
                           np.full(1, 1e-6)), np.zeros(1)))
    return out


def _jacobian(fam: StaticArmFamily, fixed: dict[str, NDArray[np.float64]], name: str,
              x: NDArray[np.float64], scale: NDArray[np.float64], rows: NDArray[np.int64]
              ) -> NDArray[np.float64]:
    cols = []
    for i in range(x.size):
        h = np.zeros_like(x)
        h[i] = scale[i]
        hi = fam.residual({**fixed, name: x + h}, rows)
        lo = fam.residual({**fixed, name: x - h}, rows)
        cols.append((hi - lo) / (2 * scale[i]))
    return np.column_stack(cols) if cols else np.zeros((len(fam.residual(fixed, rows)), 0))


def candidate_effects(fam: StaticArmFamily) -> tuple[Effect, ...]:
    """The effects of ``fam`` restricted to what its measurements can identify."""
    rows = np.arange(fam.n_samples)
    b = fam.baseline
    assert b is not None
    sol = least_squares(lambda x: fam.residual({"baseline": x}, rows), b.x0,
                        bounds=(b.lower, b.upper), method="trf", x_scale="jac")
    fixed = {"baseline": sol.x}
    jb = _jacobian(fam, {}, "baseline", sol.x, np.full(b.n_params, 1e-6), rows)
    effects = []
    full = _full_effects(fam)
    fam.param_names = {e.name: e.param_names for e, _ in full}
    for effect, probe in full:
        step = np.maximum((effect.upper - effect.lower) * 1e-5, 1e-12)
        je = _jacobian(fam, fixed, effect.name, probe, step, rows)
        keep = independent_columns(np.column_stack([jb, je]), jb.shape[1]) - jb.shape[1]
        if keep.size:
            if effect.name == "geometric":
                fam.geo_idx = fam.geo_idx[keep]
            effects.append(effect.restricted(keep))
    return tuple(effects)
