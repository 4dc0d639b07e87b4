"""Monte Carlo motion-error analysis with screw (POE) error models, seed 001's method.

Every joint i of the chain carries error screws defined at the zero configuration and
applied just before its motion (seed 001 Eqs. 22 and 33):

    T' = prod_i [ D_i  A_i  S_i  exp(xi_i' (q_i + dq_i)) ]  M'

- xi_i', M' come from the link lengths with their errors (Eq. 24: the axis points move);
- dq_i is the drive (transmission) error of the joint, rad or m;
- D_i = exp(xi_u e_u) exp(xi_v e_v): axis deflection, rotations about the two axes
  perpendicular to the joint axis through its centre (Eqs. 20, 31, 35);
- A_i = exp((0, w_i) d_i): axial clearance, the distal chain slides along the joint axis;
- S_i: radial clearance, a translation by s_i (cos t_i u + sin t_i v), t_i ~ U[0, 2 pi]
  (the clearance rod of Eq. 42, carried through the chain instead of added in the base frame).

Two error sets are sampled (transmission: Tables 1/2; clearance: Table 4, revolute joints only
as in Eq. 36), each pushed through the chain for all samples at once. Statistics, reliability
(Eqs. 25-26) and the linear sensitivities (POE error Jacobian) that explain them follow.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from serpar.checks.tool_changer_robot import (
    PAPER_ANGLE_THRESHOLD_RAD,
    PAPER_POSITION_RELIABILITY,
    PAPER_SAMPLES,
    ArmModel,
    ClearanceErrors,
    ErrorSample,
    TransmissionErrors,
    sample_clearance,
    sample_transmission,
    seed001_model,
    table1_errors,
    table2_errors,
)
from serpar.errors import ConfigError
from serpar.kinematics import poe
from serpar.sim import arm

Array = np.ndarray

ROBOTS: tuple[str, ...] = ("seed001", "panda")
SIGMA_TABLES: tuple[str, ...] = ("table2", "table1")
CHUNK = 5_000
"""Samples pushed through the chain per numpy call (bounds memory, drives the progress bar)."""


def _panda_model() -> ArmModel:
    """serpar's Panda (sim/arm.py MDH table) at its home pose; the tool is the grasp point (TCP)."""

    slots = ([("a", i) for i, v in enumerate(arm.MDH_A) if v != 0.0]
             + [("d", i) for i, v in enumerate(arm.MDH_D) if v != 0.0])
    table = {"a": arm.MDH_A, "d": arm.MDH_D}
    nominal = tuple(table[k][i] for k, i in slots) + (arm.FLANGE_D + arm.TCP_OFFSET,)

    def geometry(lengths: Array) -> tuple[Array, Array, Array]:
        ln = np.asarray(lengths, dtype=float)
        cols = {"a": np.zeros(ln.shape[:-1] + (arm.N_JOINTS,)),
                "d": np.zeros(ln.shape[:-1] + (arm.N_JOINTS,))}
        for j, (k, i) in enumerate(slots):
            cols[k][..., i] = ln[..., j]
        return poe.mdh_frames(cols["a"], cols["d"], arm.MDH_ALPHA, ln[..., -1])

    return ArmModel("panda", tuple(f"{k}{i + 1}" for k, i in slots) + ("d_tool",), nominal,
                    arm.JOINT_NAMES, (False,) * arm.N_JOINTS, tuple(arm.HOME_Q), geometry)


def arm_model(name: str) -> ArmModel:
    """The seed 001 tool-changing robot (Table 2) or serpar's Panda."""
    if name == "seed001":
        return seed001_model()
    if name == "panda":
        return _panda_model()
    raise ConfigError(f"unknown robot {name!r}; valid: {', '.join(ROBOTS)}")


def transmission_errors(model: ArmModel, table: str) -> TransmissionErrors:
    """Table 2's per-link and per-joint sigmas (seed001 only) or Table 1's per-type ones."""
    valid = SIGMA_TABLES if model.name == "seed001" else ("table1",)
    if table not in valid:
        raise ConfigError(f"sigma table {table!r} for robot {model.name!r}; valid: "
                          f"{', '.join(valid)}")
    return table2_errors() if table == "table2" else table1_errors(len(model.lengths_m),
                                                                   model.prismatic)


def perturbed_poses(model: ArmModel, sample: ErrorSample) -> Array:
    """Tool poses (N, 4, 4) of the sampled robots at the working configuration (module doc)."""
    axes, points, home = model.geometry(np.asarray(model.lengths_m) + sample.dl)
    u, v = poe.perpendicular_axes(axes)
    zero = np.zeros_like(axes)
    pri = np.asarray(model.prismatic)
    screws = [(poe.twist(u, points), sample.deflection[..., 0]),
              (poe.twist(v, points), sample.deflection[..., 1]),
              (np.concatenate([zero, axes], -1), sample.axial),
              (np.concatenate([zero, u], -1), sample.radial[..., 0]),
              (np.concatenate([zero, v], -1), sample.radial[..., 1])]
    screws = [(xi, ang) for xi, ang in screws if np.any(ang)]  # skip sources that are off
    joint_angles = np.asarray(model.q) + sample.dq
    screws.append((poe.twist(axes, points, pri), joint_angles))
    twists = np.stack([xi for xi, _ in screws], -2)  # (N, n, k, 6): error screws, then the joint
    angles = np.stack([ang for _, ang in screws], -1)
    n = len(sample.dq)
    return poe.product_of_exponentials(twists.reshape(n, -1, 6), angles.reshape(n, -1)) @ home


ROWS: tuple[str, ...] = ("dp", "norm", "dx", "dy", "dz", "dphi", "dtheta", "dpsi")
"""Error rows: dp = |P'| - |P| (signed, like Table 3's dp), norm = |P' - P|, components [mm];
X-Y-Z fixed-axis angles of R' R^T [rad]."""


def pose_errors(nominal: Array, poses: Array) -> dict[str, Array]:
    """Per-sample end errors of poses (N, 4, 4) against the nominal tool pose, rows of ROWS."""
    from scipy.spatial.transform import Rotation

    p0, p = nominal[:3, 3], poses[:, :3, 3]
    dp = (p - p0) * 1e3
    rel = poses[:, :3, :3] @ nominal[:3, :3].T
    ang = Rotation.from_matrix(rel).as_euler("xyz")
    radial = (np.linalg.norm(p, axis=1) - np.linalg.norm(p0)) * 1e3
    cols = (radial, np.linalg.norm(dp, axis=1), *dp.T, *ang.T)
    return dict(zip(ROWS, cols))


@dataclass(frozen=True)
class MonteCarloResult:
    """Per-sample end errors of one error source ("transmission" or "clearance")."""

    source: str
    errors: dict[str, Array] = field(repr=False)

    def stats(self) -> dict[str, tuple[float, float, float, float]]:
        """(mean, std, max, min) per row, as in Tables 3 and 5."""
        return {k: (float(v.mean()), float(v.std(ddof=1)), float(v.max()), float(v.min()))
                for k, v in self.errors.items()}

    def position_reliability(self, thresholds_mm: tuple[float, ...]) -> dict[float, float]:
        """Eq. 25: P(|dP| < T), the fraction of samples whose position error is below T."""
        return {t: float(np.mean(self.errors["norm"] < t)) for t in thresholds_mm}

    def angle_reliability(self, threshold_rad: float) -> tuple[float, float, float]:
        """Eq. 25: P(|d angle| < R) for each of the three angles."""
        return tuple(float(np.mean(np.abs(self.errors[k]) < threshold_rad))
                     for k in ("dphi", "dtheta", "dpsi"))


def monte_carlo(model: ArmModel, draw: Callable[[int], ErrorSample], samples: int, source: str,
                progress: Callable[[int], None] | None = None) -> MonteCarloResult:
    """Push `samples` drawn robots through the chain, CHUNK at a time."""
    nominal = model.tool_pose()
    parts: list[dict[str, Array]] = []
    for start in range(0, samples, CHUNK):
        n = min(CHUNK, samples - start)
        parts.append(pose_errors(nominal, perturbed_poses(model, draw(n))))
        if progress is not None:
            progress(n)
    return MonteCarloResult(source, {k: np.concatenate([p[k] for p in parts]) for k in ROWS})


@dataclass(frozen=True)
class Sensitivity:
    """Linear end-error gains of every error parameter at the working configuration."""

    names: tuple[str, ...]
    groups: tuple[str, ...]
    """"length", "drive" or "deflection" per parameter."""
    units: tuple[str, ...]
    """"m" or "rad" per parameter."""
    sigma: Array
    """(k,) the parameter's standard deviation [m or rad]."""
    position: Array
    """(3, k) d(tool position)/d(parameter) [m per m or per rad]."""
    rotation: Array
    """(3, k) d(tool rotation vector)/d(parameter) [rad per m or per rad]."""

    def contribution_mm(self) -> Array:
        """(k,) one-sigma position error each parameter causes alone [mm]."""
        return 1e3 * self.sigma * np.linalg.norm(self.position, axis=0)

    def linear_std_mm(self, group: str | None = None) -> Array:
        """(3,) first-order std of dx, dy, dz from all parameters (or one group) [mm]."""
        keep = np.array([group is None or g == group for g in self.groups])
        return 1e3 * np.sqrt(((self.position * self.sigma) ** 2)[:, keep].sum(axis=1))


def _twists_home(model: ArmModel, lengths: Array) -> tuple[Array, Array]:
    axes, points, home = model.geometry(lengths)
    return poe.twist(axes, points, model.prismatic), home


def sensitivity(model: ArmModel, errors: TransmissionErrors, step: float = 1e-6) -> Sensitivity:
    """Gains from the POE error Jacobian (the paper's control-variable curves, linearised).

    A link length moves axis points and M: its twist derivative (central difference of the
    geometry map, which is linear in the lengths, so exact to rounding) goes through
    :func:`poe.error_jacobian`. A drive error is a space-Jacobian column; a deflection the error
    screw Ad(P_{i-1}) xi_u (or xi_v) of its joint.
    """
    lengths, q = np.asarray(model.lengths_m, dtype=float), np.asarray(model.q, dtype=float)
    twists, home = model.nominal()
    pre = poe.prefix_poses(twists, q)
    j_err = poe.error_jacobian(twists, q)
    cols = []
    for k in range(len(lengths)):
        dl = np.eye(len(lengths))[k] * step
        (tp, mp), (tm, mm) = _twists_home(model, lengths + dl), _twists_home(model, lengths - dl)
        dm = poe.log_twist(mp @ np.linalg.inv(mm))
        cols.append(j_err @ np.concatenate([(tp - tm).ravel(), dm]) / (2 * step))
    axes, points, _ = model.geometry(lengths)
    u, v = poe.perpendicular_axes(axes)
    deflect = [poe.adjoint(pre[i]) @ poe.twist(d[i], points[i])
               for i in range(len(q)) for d in (u, v)]
    j6 = np.column_stack(cols + list(poe.space_jacobian(twists, q).T) + deflect)
    joints = model.joint_names
    names = (model.length_names + joints + tuple(f"{j}_{d}" for j in joints for d in "uv"))
    groups = (("length",) * len(lengths) + ("drive",) * len(q) + ("deflection",) * 2 * len(q))
    units = (("m",) * len(lengths) + tuple("m" if p else "rad" for p in model.prismatic)
             + ("rad",) * 2 * len(q))
    sigma = np.concatenate([errors.link_sigma_m, errors.drive_sigma,
                            np.full(2 * len(q), errors.deflection_sigma_rad)])
    tool = pre[-1] @ home
    return Sensitivity(names, groups, units, sigma, poe.point_jacobian(j6, tool[:3, 3]), j6[:3])


@dataclass(frozen=True)
class ErrorAnalysisConfig:
    """What to analyse; validated on construction so bad input fails before any sampling."""

    robot: str = "seed001"
    sigmas: str | None = None
    """Transmission-error table: None picks table2 for seed001 and table1 otherwise."""
    samples: int = PAPER_SAMPLES
    seed: int = 1
    thresholds_mm: tuple[float, ...] = tuple(PAPER_POSITION_RELIABILITY)
    angle_threshold_rad: float = PAPER_ANGLE_THRESHOLD_RAD
    clearance: ClearanceErrors = field(default_factory=ClearanceErrors)

    def __post_init__(self) -> None:
        model = arm_model(self.robot)  # an unknown robot raises, naming the valid ones
        if self.sigmas is None:
            object.__setattr__(self, "sigmas", "table2" if self.robot == "seed001" else "table1")
        transmission_errors(model, self.sigmas)  # so does a table the robot does not have
        for name in ("samples", "seed"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise ConfigError(f"{name} {value!r}: must be an integer")
        if self.samples < 1:
            raise ConfigError(f"samples {self.samples}: must be a positive integer, e.g. 20000")
        limits = (*self.thresholds_mm, self.angle_threshold_rad)
        if not self.thresholds_mm or not all(np.isfinite(t) and t > 0 for t in limits):
            raise ConfigError(f"thresholds {limits}: must be positive numbers")


@dataclass(frozen=True)
class ErrorAnalysisResult:
    config: ErrorAnalysisConfig
    tool_pose: Array
    transmission: MonteCarloResult
    clearance: MonteCarloResult
    sensitivity: Sensitivity

    def as_dict(self) -> dict:
        """JSON-ready summary (no per-sample arrays)."""
        c, s = self.config, self.sensitivity

        def summary(mc: MonteCarloResult) -> dict:
            return {"stats": mc.stats(),
                    "position_reliability": {str(t): p for t, p in
                                             mc.position_reliability(c.thresholds_mm).items()},
                    "angle_reliability": mc.angle_reliability(c.angle_threshold_rad)}

        return {"robot": c.robot, "sigmas": c.sigmas, "samples": c.samples, "seed": c.seed,
                "units": {"position": "mm", "angle": "rad"},
                "tool_position_mm": (self.tool_pose[:3, 3] * 1e3).tolist(),
                "transmission": summary(self.transmission),
                "clearance": summary(self.clearance),
                "sensitivity": [{"name": n, "group": g, "sigma": float(sg),
                                 "gain_xyz": s.position[:, k].tolist(),
                                 "contribution_mm": float(s.contribution_mm()[k])}
                                for k, (n, g, sg) in enumerate(zip(s.names, s.groups, s.sigma))],
                "linear_std_mm": {g: s.linear_std_mm(g).tolist()
                                  for g in ("length", "drive", "deflection")}
                | {"all": s.linear_std_mm().tolist()}}


def run_error_analysis(config: ErrorAnalysisConfig,
                       progress: Callable[[int], None] | None = None) -> ErrorAnalysisResult:
    """Both Monte Carlo runs (2 x samples robots, one seeded Generator) and the sensitivities."""
    model = arm_model(config.robot)
    errors = transmission_errors(model, config.sigmas)
    rng = np.random.default_rng(config.seed)
    trans = monte_carlo(model, lambda n: sample_transmission(model, errors, n, rng),
                        config.samples, "transmission", progress)
    clear = monte_carlo(model, lambda n: sample_clearance(model, config.clearance, n, rng),
                        config.samples, "clearance", progress)
    return ErrorAnalysisResult(config, model.tool_pose(), trans, clear, sensitivity(model, errors))
