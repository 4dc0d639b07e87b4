"""The arm's calibration models and their error Jacobians, one function for every
measurement type (seed 003 §4-5).

The parameter vector is laid out in the order the redundancy analysis prefers to keep
parameters: the unknown socket centres of a point-consistency set first (nuisance
parameters: a base-frame error that only moves every socket is absorbed by them), then the
chain's base, link and tool errors, then the joint compliances.

Geometric model: the tool frame of the kinematic chain at the encoder angles q, in either of
two forms: the MD-H(+beta) chain of :mod:`serpar.kinematics.mdh` (seed 003) or the product of
exponentials of :mod:`serpar.calibration.poe_calibration` (seed 001); :func:`chain_kinematics` hides
which, so everything below serves both.
Gravity-aware model (seed 003 §5, as joint compliance): the links stand at
``q + c * tau_g(q)``, with ``tau_g`` the nominal model's gravity torque (supplied with the
measurements) and ``c`` [rad/(N m)] one compliance per joint, so the deflection enters the
error Jacobian through the joint columns, ``dJ/dc_j = J_q_j * tau_g,j``. Like the paper
the deflection is computed from nominal parameters, not from the erroneous geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from serpar.calibration.poe_calibration import PoeChain, poe_kinematics
from serpar.errors import ConfigError, IdentificationError
from serpar.kinematics.mdh import Chain, chain_frames, forward, pose_jacobian
from serpar.sim.arm_measurements import Measurements, PointSet, PoseSet

FORMS = ("mdh", "poe")
"""The two forms of the geometric error model (:attr:`ArmModel.form`)."""


@dataclass(frozen=True)
class Prior:
    """Seed 003's regularised least squares as a Gaussian prior on the errors (zero mean):
    a direction the data barely sees (a nearly redundant wrist combination when the tool
    point lies close to the last axis) stays near nominal instead of absorbing noise."""

    length_m: float = 2e-3
    angle_rad: float = 20e-3
    compliance: float = 1e-3
    """[rad/(N m)]: 1000 N m/rad, far softer than any arm joint."""
    tool_m: float | None = None
    """Prior on the tool offset [m]; None: the offset is unknown (a ball of unknown length)."""

    def __post_init__(self) -> None:
        for name in ("length_m", "angle_rad", "compliance", "tool_m"):
            value = getattr(self, name)
            if name == "tool_m" and value is None:
                continue
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"Prior.{name} must be a positive number, got {value!r}")


@dataclass(frozen=True)
class ArmModel:
    """Which error model to identify: ``gravity`` adds one compliance per joint; ``only``
    (name prefixes, e.g. ``("tool.t",)``) restricts the fitted chain parameters; ``prior``
    regularises the solve (None: plain least squares, unbiased)."""

    chain: Chain | PoeChain
    gravity: bool = False
    only: tuple[str, ...] = ()
    prior: Prior | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.chain, (Chain, PoeChain)):
            raise ConfigError("ArmModel.chain must be an serpar.kinematics.mdh.Chain (form mdh) or an "
                              "serpar.calibration.poe_calibration.PoeChain (form poe)")
        if self.prior is not None and not isinstance(self.prior, Prior):
            raise ConfigError("ArmModel.prior must be an serpar.calibration.arm_error_models.Prior or None")
        for prefix in self.only:
            if not any(n.startswith(prefix) for n in self.chain.names):
                raise ConfigError(f"ArmModel.only: no chain parameter starts with {prefix!r}; "
                                  f"names look like {', '.join(self.chain.names[:8])}, ...")

    @property
    def label(self) -> str:
        return "gravity" if self.gravity else "geometric"

    @property
    def form(self) -> str:
        """``mdh`` or ``poe`` (one of :data:`FORMS`)."""
        return "poe" if isinstance(self.chain, PoeChain) else "mdh"


def chain_kinematics(chain: Chain | PoeChain, values: NDArray[np.float64],
                     q: NDArray[np.float64], params: bool = True
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Tool frames (N, 4, 4), their Jacobian (N, 6, E) with respect to the chain's values and
    (N, 6, n) with respect to the joint angles, rows [d position; d rotation], either form.
    ``params=False``: the POE form skips the parameter Jacobian (returned empty, (N, 6, 0))."""
    if isinstance(chain, PoeChain):
        kin = poe_kinematics(chain, values, q, params)
        jac = kin.jacobian if kin.jacobian is not None else np.zeros(kin.tool.shape[:1] + (6, 0))
        return kin.tool, jac, kin.joint_jacobian
    frames = chain_frames(chain, values, q)
    jac = pose_jacobian(chain, frames)
    # a joint's angle adds to its theta element, so both have the same column
    return frames.tool, jac, jac[:, :, chain.joint_elements]


def chain_forward(chain: Chain | PoeChain, values: NDArray[np.float64], q: NDArray[np.float64]
                  ) -> NDArray[np.float64]:
    """(N, 4, 4) tool frames, either form."""
    if isinstance(chain, PoeChain):
        return poe_kinematics(chain, values, q, params=False).tool
    return forward(chain, values, q)


@dataclass(frozen=True)
class Layout:
    """Where each block sits in the parameter vector."""

    n_points: int
    n_chain: int
    n_compliance: int

    @property
    def size(self) -> int:
        return 3 * self.n_points + self.n_chain + self.n_compliance

    def split(self, x: NDArray[np.float64]
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """(points (P, 3), chain errors (E,), compliances (n_compliance,))."""
        x = np.asarray(x, float)
        p = 3 * self.n_points
        return (x[:p].reshape(self.n_points, 3), x[p:p + self.n_chain],
                x[p + self.n_chain:])


def layout(model: ArmModel, meas: Measurements) -> Layout:
    n_points = meas.n_points if isinstance(meas, PointSet) else 0
    return Layout(n_points, model.chain.size, model.chain.n_joints if model.gravity else 0)


def parameter_names(model: ArmModel, meas: Measurements) -> tuple[str, ...]:
    lay = layout(model, meas)
    points = [f"socket{i}.{a}" for i in range(lay.n_points) for a in "xyz"]
    compliance = [f"c{j + 1}" for j in range(lay.n_compliance)]
    return tuple(points) + model.chain.names + tuple(compliance)


PREFERENCE = (("socket", 0), ("tool.t", 1), (".beta", 3), ("tool.r", 4), ("c", 5))
"""Rank in which the redundancy analysis keeps parameters (lower first; chain parameters not
listed rank 2): socket centres, then the tool offset (what a point-consistency campaign is
asked for), then the D-H parameters, then beta, which seed 003 uses only where the four D-H
parameters cannot describe a link (parallel axes), then tool rotations and compliances."""
POE_PREFERENCE = (("socket", 0), ("tool.t", 1), ("base.", 3), ("tool.r", 4), ("c", 5))
"""The same for the POE form, with the base frame after the joint twists: a base error is
the same rigid motion of every twist and of M, so the gauge is fixed by holding the base at
nominal (the twists are expressed directly in the measurement frame; POE needs no base)."""


def preference(model: ArmModel, meas: Measurements) -> NDArray[np.int64]:
    """Per parameter, its rank in :data:`PREFERENCE` (:data:`POE_PREFERENCE` for the POE form)."""
    table = POE_PREFERENCE if model.form == "poe" else PREFERENCE

    def rank(name: str) -> int:
        for key, r in table:
            if name.startswith(key) or (key.startswith(".") and name.endswith(key)):
                return r
        return 2
    return np.array([rank(n) for n in parameter_names(model, meas)])


def prior_sigma(model: ArmModel, meas: Measurements) -> NDArray[np.float64]:
    """Per parameter, the prior standard deviation of its error (inf: no prior)."""
    lay = layout(model, meas)
    sigma = np.full(lay.size, np.inf)
    if model.prior is not None:
        p = 3 * lay.n_points
        tool = np.inf if model.prior.tool_m is None else model.prior.tool_m
        sigma[p:p + lay.n_chain] = [
            (tool if n.startswith("tool.t") else model.prior.length_m) if k[0] == "t"
            else model.prior.angle_rad for n, k in zip(model.chain.names, model.chain.kinds)]
        sigma[p + lay.n_chain:] = model.prior.compliance
    return sigma


def fitted_mask(model: ArmModel, meas: Measurements) -> NDArray[np.bool_]:
    """Parameters the model may move (all but chain parameters excluded by ``only``)."""
    names = parameter_names(model, meas)
    chain = set(model.chain.names)
    return np.array([n not in chain or not model.only or n.startswith(model.only)
                     for n in names])


def joint_angles(model: ArmModel, compliance: NDArray[np.float64], q: NDArray[np.float64],
                 tau: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """Link-side angles: the encoder angles plus the gravity deflection of the model."""
    q = np.atleast_2d(np.asarray(q, float))
    if not model.gravity:
        return q
    if tau is None:
        raise IdentificationError("the gravity model needs tau_gravity (nominal-model gravity "
                                  "torques at every pose); the measurement set has none")
    return q + np.asarray(compliance)[None, :] * np.atleast_2d(tau)


def predict(model: ArmModel, x: NDArray[np.float64], lay: Layout, q: NDArray[np.float64],
            tau: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """(N, 4, 4) tool frames the identified model predicts at encoder angles q."""
    _, dchain, comp = lay.split(x)
    return chain_forward(model.chain, model.chain.values(dchain),
                         joint_angles(model, comp, q, tau))


def initial_parameters(model: ArmModel, meas: Measurements,
                       chain_errors: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """Chain errors ``chain_errors`` (default zero), zero compliance, socket centres at the
    mean prediction of their poses."""
    lay = layout(model, meas)
    x = np.zeros(lay.size)
    if chain_errors is not None:
        x[3 * lay.n_points:3 * lay.n_points + lay.n_chain] = model.chain.values(
            chain_errors) - model.chain.values()
    if isinstance(meas, PointSet):
        p = predict(model, x, lay, meas.q, meas.tau_gravity)[:, :3, 3]
        centres = np.array([p[meas.point == i].mean(axis=0) for i in range(lay.n_points)])
        x[:3 * lay.n_points] = centres.ravel()
    return x


def residuals_and_jacobian(model: ArmModel, meas: Measurements, x: NDArray[np.float64]
                           ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Noise-weighted residuals (model - measurement) / sigma and their Jacobian (m, P)."""
    lay = layout(model, meas)
    points, dchain, comp = lay.split(x)
    tau = meas.tau_gravity
    q_link = joint_angles(model, comp, meas.q, tau)
    tool, jac, jac_q = chain_kinematics(model.chain, model.chain.values(dchain), q_link)
    blocks = [np.zeros((len(meas.q), 6, 3 * lay.n_points)), jac]   # jac: (N, 6, E)
    if model.gravity:
        blocks.append(jac_q * np.asarray(tau)[:, None, :])
    full = np.concatenate(blocks, axis=2)                          # (N, 6, P)
    tool_p = tool[:, :3, 3]
    if isinstance(meas, PointSet):
        return _point_rows(meas, lay, points, tool_p, full)
    r = [(tool_p - meas.position).ravel() / meas.sigma]
    j = [full[:, :3].reshape(-1, lay.size) / meas.sigma]
    if isinstance(meas, PoseSet):
        err = Rotation.from_matrix(tool[:, :3, :3] @ meas.rotation.transpose(0, 2, 1))
        r.append(err.as_rotvec().ravel() / meas.sigma_rotation)
        j.append(full[:, 3:].reshape(-1, lay.size) / meas.sigma_rotation)
    return np.concatenate(r), np.concatenate(j)


def _point_rows(meas: PointSet, lay: Layout, points: NDArray[np.float64],
                tool_p: NDArray[np.float64], full: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    n = len(meas.q)
    jac = full[:, :3].copy()                                       # (N, 3, P)
    cols = 3 * np.asarray(meas.point)[:, None] + np.arange(3)[None, :]
    jac[np.arange(n)[:, None], np.arange(3)[None, :], cols] = -1.0
    r = [(tool_p - points[meas.point]).ravel() / meas.sigma]
    j = [jac.reshape(-1, lay.size) / meas.sigma]
    for a, b, dist in meas.distances:
        gap = points[a] - points[b]
        length = float(np.linalg.norm(gap))
        row = np.zeros(lay.size)
        unit = gap / length if length > 0 else np.zeros(3)
        row[3 * a:3 * a + 3], row[3 * b:3 * b + 3] = unit, -unit
        r.append(np.array([(length - dist) / meas.sigma_distance]))
        j.append(row[None, :] / meas.sigma_distance)
    return np.concatenate(r), np.concatenate(j)
