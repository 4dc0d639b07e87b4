"""The static arm's extended model: how each candidate effect moves the tool point.

Everything here is a pure function of the parameters and the measured configuration, so the
family (:mod:`serpar.diagnosis.arm_static_family`) can evaluate any combination of effects:

- geometric: MD-H(+beta) parameter errors of :mod:`serpar.kinematics.mdh` (base set only);
- joint_compliance: link angle = encoder angle + c_j tau_g,j (nominal gravity torque);
- backlash: link angle = encoder angle + b_j s_j, with s_j the side of the clearance the link
  rests on: the side gravity pushes it to when the gravity torque beats the gearbox friction
  f, else the side the last approach left it on (``approach`` +1: the motor came from below,
  the link lags at -b);
- encoder: link angle = (1 + s_j) encoder angle + o_j (transmission ratio and zero errors);
- thermal_drift: every length of the chain (link a, d and the tool offset; not the tracker
  registration) grows by the factor 1 + kappa t.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from serpar.kinematics.mdh import Chain, elementary

STEP_WIDTH_NM = 0.005
"""Width [N m] of the smooth step between the two sides of a backlash: the transition of a
gearbox's stick-slip is not a mathematical step, and least squares needs a slope."""


def forward_rows(chain: Chain, values: NDArray[np.float64], q: NDArray[np.float64]
                 ) -> NDArray[np.float64]:
    """(N, 3) tool points for per-row element values (N, E) and joint angles (N, n)."""
    n = q.shape[0]
    pose = np.tile(np.eye(4), (n, 1, 1))
    for e, (kind, j) in enumerate(zip(chain.kinds, chain.joint)):
        v = values[:, e] + (q[:, j] if j >= 0 else 0.0)
        pose = pose @ elementary(kind, v)
    return pose[:, :3, 3]


def backlash_side(tau: NDArray[np.float64], approach: NDArray[np.float64] | None,
                  friction: float) -> NDArray[np.float64]:
    """(N, n) side in [-1, 1] of the clearance the link rests on."""
    if approach is None:
        # no record of the approach: only gravity decides (a light joint's side is unknown)
        return np.tanh(tau / STEP_WIDTH_NM)
    step = 0.5 * (1.0 + np.tanh((approach * tau - friction) / STEP_WIDTH_NM))
    return approach * (2.0 * step - 1.0)


def length_elements(chain: Chain) -> NDArray[np.int64]:
    """Elements that are lengths of the arm itself (translations outside the base frame)."""
    return np.array([e for e, (name, kind) in enumerate(zip(chain.names, chain.kinds))
                     if kind[0] == "t" and not name.startswith("base.")], int)


def element_jacobian(chain: Chain, values: NDArray[np.float64], q: NDArray[np.float64]
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Tool points (N, 3) and d point / d element value (N, 3, E): u x (p - o) for a
    rotation, u for a translation (the frame after the element holds its world axis)."""
    n = q.shape[0]
    pose = np.tile(np.eye(4), (n, 1, 1))
    axes = np.empty((n, chain.size, 3))
    origins = np.empty((n, chain.size, 3))
    for e, (kind, j) in enumerate(zip(chain.kinds, chain.joint)):
        v = values[:, e] + (q[:, j] if j >= 0 else 0.0)
        pose = pose @ elementary(kind, v)
        axes[:, e] = pose[:, :3, "xyz".index(kind[1])]
        origins[:, e] = pose[:, :3, 3]
    p = pose[:, :3, 3]
    rot = np.array([k[0] == "r" for k in chain.kinds])
    g = np.where(rot[None, :, None], np.cross(axes, p[:, None, :] - origins), axes)
    return p, g.transpose(0, 2, 1)


def joint_effect(name: str, names: tuple[str, ...], p: NDArray[np.float64],
                 q: NDArray[np.float64], tau: NDArray[np.float64],
                 approach: NDArray[np.float64] | None,
                 dtau: NDArray[np.float64] | None = None
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A joint-space effect: link minus encoder angle (N, 7), and its derivative with
    respect to each parameter (k, N, 7). Parameter names: c_j compliance [rad/(N m)], b_j
    backlash half-clearance [rad], f gearbox friction [N m], o_j encoder zero [rad], s_j
    encoder scale [-] (j = 1..7). ``dtau`` (N, 7, 7): d tau_g / dq at the encoder angles;
    with it the compliance deflection is self-consistent to first order (the gravity torque
    at the deflected, not the commanded, configuration)."""
    if name == "joint_compliance" and dtau is not None:
        return _compliance(names, p, tau, dtau)
    friction = float(p[names.index("f")]) if "f" in names else 0.0
    side = dside = None
    if name == "backlash":
        side = backlash_side(tau, approach, friction)
        if approach is not None:
            th = np.tanh((approach * tau - friction) / STEP_WIDTH_NM)
            dside = -approach * (1.0 - th**2) / STEP_WIDTH_NM
    offset = np.zeros_like(q)
    deriv = np.zeros((len(names), *q.shape))
    for k, (value, pname) in enumerate(zip(p, names)):
        if pname == "f":
            continue
        j = int(pname[1:]) - 1
        col = {"c": tau[:, j], "o": np.ones(len(q)), "s": q[:, j]}.get(pname[0])
        if pname[0] == "b":
            col = side[:, j]  # type: ignore[index]
        if col is None:
            raise ValueError(f"unknown joint-effect parameter {pname!r}")
        offset[:, j] += value * col
        deriv[k, :, j] = col
    if "f" in names and dside is not None:
        b = np.zeros(q.shape[1])
        for value, pname in zip(p, names):
            if pname[0] == "b":
                b[int(pname[1:]) - 1] = value
        deriv[names.index("f")] = b[None, :] * dside
    return offset, deriv


def _compliance(names: tuple[str, ...], p: NDArray[np.float64], tau: NDArray[np.float64],
                dtau: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """delta = C (tau + G delta)  =>  delta = (I - C G)^-1 C tau; a 2-fold compliance error
    of a Panda-size arm deflects ~0.02 rad, where tau_g changes by ~1 N m (0.3 mm at the tool)."""
    n_j = tau.shape[1]
    c = np.zeros(n_j)
    idx = [int(name[1:]) - 1 for name in names]
    c[idx] = p
    a = np.eye(n_j)[None] - c[None, :, None] * dtau
    a_inv = np.linalg.inv(a)
    delta = np.einsum("njk,nk->nj", a_inv, c * tau)
    t_eff = tau + np.einsum("njk,nk->nj", dtau, delta)
    deriv = np.stack([a_inv[:, :, j] * t_eff[:, j, None] for j in idx])
    return delta, deriv
