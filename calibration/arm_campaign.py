"""Orchestrators of ``serpar calibrate arm``: the simulated campaign of seed 003 (150
training + 100 verification poses on the MuJoCo plant of :mod:`serpar.sim.plants.static_panda`) and the
leave-one-placement-out evaluation of a panda_1-layout point-consistency folder (two
placements or more: with two, each is calibrated on alone and scored on the other).

Both run the same pipeline (:func:`serpar.calibration.arm_calibration.calibrate`) with the same
regularisation prior, for the geometric and the gravity-aware model, in either form of the
geometric error model: ``mdh`` (MD-H+beta, seed 003) or ``poe`` (product of exponentials,
seed 001).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.calibration.arm_calibration import (
    ArmCalibration,
    ComplianceTest,
    ConsistencyStats,
    ErrorStats,
    calibrate,
    calibrate_gravity_aware,
    consistency_stats,
    position_error_stats,
)
from serpar.calibration.arm_error_models import FORMS, ArmModel, Prior, chain_forward
from serpar.calibration.arm_identifiability import IdentifiabilityReport
from serpar.calibration.panda_data import PandaPointData, load_panda_folder
from serpar.calibration.poe_calibration import PoeChain, panda_poe_chain, robot_poe_chain
from serpar.errors import IdentificationError, UnknownNameError
from serpar.kinematics.mdh import Chain, panda_chain
from serpar.kinematics.robot import PANDA, Robot, frame_transform
from serpar.sim.arm_measurements import Measurements
from serpar.sim.plants.static_panda import Campaign, TruthConfig, nominal_plant, run_campaign

MODELS = ("geometric", "gravity")
PAPER_MEAN_REDUCTION = {"x": 0.20, "y": 0.17}
"""Seed 003 (abstract, §7.3): gravity-aware mean X / Y error below geometry-only's."""
REAL_GRAVITY_PLANT = TruthConfig(tool_mass_kg=0.0, hand=False, tool_offset_m=(0.0, 0.0, 0.0))
"""Gravity model for the real Panda: the bare arm (the ball is fixed to the flange; its mass
is unknown and taken as zero), nominal geometry."""
MIN_PLACEMENTS = 2
"""Tool placements a real-data calibration needs: one to calibrate on and one held out. One
placement (two sockets, one fixture distance) identifies the same chain parameters as two:
on panda_1 25 of them either way (condition 376-1080 alone vs 414-676 for two), so training
on a single placement is well posed, only less well averaged."""


def check_models(models: tuple[str, ...], robot: Robot = PANDA) -> tuple[str, ...]:
    """The models asked for, each known; the gravity-aware one only for the Panda, the one arm
    with a nominal dynamic model here."""
    for m in models:
        if m not in MODELS:
            raise UnknownNameError("calibration model", m, MODELS)
    if robot is not PANDA and "gravity" in models:
        raise IdentificationError(f"--model gravity needs the arm's dynamic model, which only "
                                  f"the Panda has here; for {robot.label} use --model geometric")
    return models


def form_chain(form: str, tool_offset: tuple[float, float, float] = (0.0, 0.0, 0.0),
               robot: Robot = PANDA) -> Chain | PoeChain:
    """The nominal arm in the named form of the geometric error model (:data:`FORMS`)."""
    if form not in FORMS:
        raise UnknownNameError("error-model form", form, FORMS)
    if robot is PANDA:
        return panda_chain(tool_offset) if form == "mdh" else panda_poe_chain(tool_offset)
    return robot.chain(tool_offset) if form == "mdh" else robot_poe_chain(robot, tool_offset)


def _fit(chain: Chain | PoeChain, name: str, meas: Measurements, start: NDArray[np.float64] | None = None
         ) -> tuple[ArmCalibration, ComplianceTest | None]:
    """One model's calibration; the gravity-aware one keeps its compliances only when the
    training data support them (F-test), so it cannot do worse than geometry by over-fitting."""
    model = ArmModel(chain, gravity=name == "gravity", prior=Prior())
    if model.gravity:
        return calibrate_gravity_aware(model, meas, start)
    return calibrate(model, meas, start), None


@dataclass(frozen=True)
class SimRow:
    label: str
    verify: ErrorStats
    """Model prediction vs the tracker's verification measurements (as the paper)."""
    verify_truth: ErrorStats
    """Model prediction vs the noise-free SMR centre (simulation only)."""
    calibration: ArmCalibration | None
    compliance_test: ComplianceTest | None = None


@dataclass(frozen=True)
class SimResult:
    config: TruthConfig
    rows: tuple[SimRow, ...]
    max_deflection_rad: NDArray[np.float64]
    form: str = "mdh"

    def reduction(self, a: str, b: str) -> tuple[float, float, float]:
        """Relative drop of the mean |x|, |y|, |z| error from row ``a`` to row ``b``."""
        ra, rb = (next(r for r in self.rows if r.label == k).verify for k in (a, b))
        return tuple(1.0 - vb / va for va, vb in zip(ra.mean_abs, rb.mean_abs))

    def as_dict(self) -> dict[str, object]:
        rows = {r.label: {"verify": r.verify.as_dict(), "verify_truth": r.verify_truth.as_dict(),
                          **(_cal_dict(r.calibration, r.compliance_test) if r.calibration else {})}
                for r in self.rows}
        out: dict[str, object] = {"form": self.form, "seed": self.config.seed,
                                  "n_train": self.config.n_train,
                                  "n_verify": self.config.n_verify,
                                  "stiffness_nm_per_rad": self.config.stiffness,
                                  "max_deflection_rad": self.max_deflection_rad.tolist(),
                                  "rows": rows, "paper_mean_reduction": PAPER_MEAN_REDUCTION}
        if {"geometric", "gravity"} <= set(rows):
            out["mean_reduction_xyz"] = list(self.reduction("geometric", "gravity"))
        return out


def simulated_calibration(cfg: TruthConfig, models: tuple[str, ...] = MODELS,
                          form: str = "mdh", campaign: Campaign | None = None) -> SimResult:
    """Uncalibrated and calibrated errors on the verification poses of the hidden plant, with
    the ``form`` of the error model; ``campaign``: measurements of ``cfg`` already taken (so
    both forms can be compared on the same data), else measured here."""
    check_models(models)
    chain = cfg.nominal_chain() if form == "mdh" else form_chain(form, cfg.tool_offset_m)
    camp = run_campaign(cfg) if campaign is None else campaign
    nominal = chain_forward(chain, chain.values(), camp.verify.q)[:, :3, 3]
    rows = [SimRow("uncalibrated", position_error_stats(nominal, camp.verify.position),
                   position_error_stats(nominal, camp.verify_truth), None)]
    for name in models:
        cal, test = _fit(chain, name, camp.train)
        pred = cal.predict_positions(camp.verify.q, camp.verify.tau_gravity)
        rows.append(SimRow(name, position_error_stats(pred, camp.verify.position),
                           position_error_stats(pred, camp.verify_truth), cal, test))
    return SimResult(cfg, tuple(rows), np.abs(camp.deflection_rad).max(axis=0), form)


@dataclass(frozen=True)
class FoldRow:
    test: str
    label: str
    train: ConsistencyStats
    held_out: ConsistencyStats
    ball_offset_m: NDArray[np.float64]
    """Ball centre in the nominal flange frame."""
    calibration: ArmCalibration
    compliance_test: ComplianceTest | None = None


def real_data_calibration(folder: str | PandaPointData, models: tuple[str, ...] = MODELS,
                          progress: Callable[[int], object] | None = None, form: str = "mdh",
                          robot: Robot = PANDA) -> tuple[FoldRow, ...]:
    """Per tool placement: calibrate on the other placements (one or more), score the held-out
    one. ``folder``: a panda_1-layout folder, or its data already loaded (whose notes the
    caller reports). The "nominal" row is the Panda's nominal table with only the ball offset
    fitted. ``progress(1)`` is called after each held-out placement; ``form``: of the error
    model; ``robot``: the arm measured (the Panda by default; another arm: geometric only, and
    loaded data must be of that arm)."""
    check_models(models, robot)
    chain = form_chain(form, robot=robot)
    data = folder if isinstance(folder, PandaPointData) else load_panda_folder(folder, robot)
    if data.robot is not robot:
        raise IdentificationError(f"{data.folder}: read as {data.robot.label}'s joint angles, "
                                  f"calibrated as {robot.label}'s; load it with the same robot")
    if len(data.placements) < MIN_PLACEMENTS:
        raise IdentificationError(f"{data.folder}: {len(data.placements)} tool placement "
                                  f"folder(s) ({', '.join(data.placements)}); calibrating on "
                                  "one placement and testing on another held out needs at "
                                  f"least {MIN_PLACEMENTS}")
    plant = nominal_plant(REAL_GRAVITY_PLANT) if robot is PANDA else None
    rows = []
    for test in data.placements:
        train = tuple(p for p in data.placements if p != test)
        sets = [data.point_set(p, tau_gravity=None if plant is None
                               else plant.gravity_torques(data.joint_angles(p)))
                for p in (train, (test,))]
        ball = calibrate(ArmModel(chain, only=("tool.t",)), sets[0])
        fits = [("nominal", (ball, None))] + [(m, _fit(chain, m, sets[0], ball.chain_errors))
                                             for m in models]
        for label, (cal, f_test) in fits:
            stats = [consistency_stats(cal.predict_positions(s.q, s.tau_gravity), s)
                     for s in sets]
            rows.append(FoldRow(test, label, stats[0], stats[1], _ball(chain, cal, robot), cal,
                                f_test))
        if progress is not None:
            progress(1)
    return tuple(rows)


def fold_scheme(n_placements: int) -> str:
    """How :func:`real_data_calibration` splits ``n_placements`` placements, in words."""
    if n_placements == MIN_PLACEMENTS:
        return "train on one tool placement, test on the other, each in turn"
    return (f"train on {n_placements - 1} tool placements, test on the remaining one, each "
            "in turn")


def _ball(chain: Chain | PoeChain, cal: ArmCalibration, robot: Robot = PANDA
          ) -> NDArray[np.float64]:
    """Tool point relative to the nominal flange: tool translation plus the last joint's d
    error (the two are one redundant pair; whichever the analysis kept holds the sum), less
    the flange's own offset, in the flange frame. In POE form the tool error alone places it
    (M's frame is the flange's at q = 0)."""
    err = cal.chain_errors
    if isinstance(chain, PoeChain):
        return chain.tool_shift(err)  # chain built with a zero offset
    values = chain.values(err)
    names = chain.names
    tool = np.array([values[names.index(f"tool.t{a}")] for a in "xyz"])
    flange = frame_transform(robot.flange)
    shift = tool + np.array([0.0, 0.0, err[names.index(f"j{robot.n_joints}.d")]])
    return flange[:3, :3].T @ (shift - flange[:3, 3])


def _cal_dict(cal: ArmCalibration, test: ComplianceTest | None) -> dict[str, object]:
    rep: IdentifiabilityReport = cal.report
    return {"identifiability": rep.as_dict(), "residual_rms_sigma": cal.residual_rms,
            "nfev": cal.nfev,
            "compliance_rad_per_nm": cal.compliance.tolist() if cal.model.gravity else None,
            "compliance_test": test.as_dict() if test else None}


def fold_dict(row: FoldRow) -> dict[str, object]:
    return {"test": row.test, "model": row.label, "form": row.calibration.model.form,
            "train": row.train.as_dict(),
            "held_out": row.held_out.as_dict(), "ball_offset_m": row.ball_offset_m.tolist(),
            **_cal_dict(row.calibration, row.compliance_test)}
