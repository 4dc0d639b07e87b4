"""``serpar calibrate arm --robot FILE``: the geometric calibration campaign of any arm read from
its model file (:mod:`serpar.sim.plants.static_arm`: hidden link, base and tool errors, 150
training + 100 verification poses, 15 um tracker noise), in either form of the error model.

What it shows, and the bound it is held to: after calibration the held-out error against the
tracker cannot fall below the tracker's own noise, RMS ``sigma * sqrt(3)`` of a 3-D point
(:func:`noise_bound_rms`); what remains above it is the identified parameters' own noise
(``sigma * sqrt(p / N)`` at the tool, p parameters, N training poses). Geometric only: the
gravity-aware model needs the arm's dynamic model, which only the Panda has here.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from serpar.calibration.arm_calibration import position_error_stats
from serpar.calibration.arm_campaign import SimRow, _fit
from serpar.calibration.arm_error_models import FORMS, chain_forward
from serpar.calibration.poe_calibration import robot_poe_chain
from serpar.errors import UnknownNameError
from serpar.kinematics.robot import Robot
from serpar.sim.plants.static_arm import GeometricCampaignConfig, run_geometric_campaign
from serpar.sim.plants.static_panda import Campaign


def noise_bound_rms(sigma_m: float) -> float:
    """RMS distance [m] of a 3-D point measured with ``sigma_m`` per axis from the truth: the
    floor of any model's held-out error against the tracker."""
    return sigma_m * math.sqrt(3.0)


@dataclass(frozen=True)
class RobotSimResult:
    robot: Robot
    config: GeometricCampaignConfig
    rows: tuple[SimRow, ...]
    form: str = "mdh"

    def row(self, label: str) -> SimRow:
        return next(r for r in self.rows if r.label == label)

    def as_dict(self) -> dict[str, object]:
        rows = {r.label: {"verify": r.verify.as_dict(), "verify_truth": r.verify_truth.as_dict(),
                          **({"parameters": r.calibration.report.rank,
                              "residual_rms_sigma": r.calibration.residual_rms}
                             if r.calibration else {})}
                for r in self.rows}
        return {"robot": {"name": self.robot.name, "source": self.robot.source,
                          "n_joints": self.robot.n_joints},
                "form": self.form, "campaign": asdict(self.config), "rows": rows,
                "noise_bound_rms_m": noise_bound_rms(self.config.tracker_sigma_m),
                "gravity": "not modelled: geometric campaign (only the Panda has a dynamic model)"}


def robot_calibration(robot: Robot, cfg: GeometricCampaignConfig, form: str = "mdh",
                      campaign: Campaign | None = None) -> RobotSimResult:
    """Nominal and geometrically calibrated errors on the verification poses of the hidden
    plant; ``campaign``: measurements already taken (both forms on the same data)."""
    if form not in FORMS:
        raise UnknownNameError("error-model form", form, FORMS)
    chain = (robot.chain(cfg.tool_offset_m) if form == "mdh"
             else robot_poe_chain(robot, cfg.tool_offset_m))
    camp = run_geometric_campaign(robot, cfg) if campaign is None else campaign
    nominal = chain_forward(chain, chain.values(), camp.verify.q)[:, :3, 3]
    rows = [SimRow("uncalibrated", position_error_stats(nominal, camp.verify.position),
                   position_error_stats(nominal, camp.verify_truth), None)]
    cal, _ = _fit(chain, "geometric", camp.train)
    pred = cal.predict_positions(camp.verify.q)
    rows.append(SimRow("geometric", position_error_stats(pred, camp.verify.position),
                       position_error_stats(pred, camp.verify_truth), cal))
    return RobotSimResult(robot, cfg, tuple(rows), form)
