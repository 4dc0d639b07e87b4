"""Concealed-effect twins of a static arm campaign (issue 7): a "real" Panda with one hidden
effect (or none), measured by a laser tracker, written as a recording; the truth goes to a
separate answer dictionary, never into the recording.

Every twin shares the campaign nuisances the diagnosis must fit anyway (tracker registration
1 mm / 1 mrad, SMR offset on its bracket 0.5 mm, tracker noise 15 um) and seed 003's design:
150 calibration poses (``set`` = train) and 100 verification poses (verify). The plant is
MuJoCo's (``serpar.sim.plants.static_panda``): the tool point is a site of the compiled arm at the link
angles MuJoCo settles to. Per effect, the physics that carries it and how it is concealed:

- ``geometric``: link frames moved in the MJCF (0.2 mm, 0.5 mrad x magnitude).
- ``joint_compliance``: a position servo of stiffness k per joint settles the arm under
  MuJoCo gravity (``ArmPlant.settle``; k = arm_truth's stiffness / magnitude). Concealed:
  the calibration poses lie in a narrow box (+-0.3 rad) around one working posture, where a
  geometric recalibration absorbs the deflection; verification spans the workspace.
- ``backlash``: joints 2-6 (two or three of them) have a clearance of +-0.5 mrad x magnitude
  about the motor angle (a limited hinge, gearbox friction 0.3 N m), and each pose is
  reached by a simulated approach (``serpar.sim.plants.backlash``). Concealed: calibration poses are
  always approached from below, verification poses from above.
- ``encoder``: gear-ratio errors (0.1 % x magnitude) and encoder zeros (0.5 mrad x
  magnitude): the link stands at (1 + s) q + o. A sensor mapping, so no physics beyond the
  kinematics expresses it.
- ``thermal_drift``: the arm warms by 5 K/h x magnitude during a two-hour campaign; every
  link frame offset and the tool bracket of the MuJoCo model grow by 23e-6/K (aluminium).
  Concealed: the calibration is the first 60 % of the campaign, verification the rest.
"""

from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.calibration.arm_static_data import StaticArmData, to_recording
from serpar.errors import ConfigError
from serpar.sim.arm import LINK_NAMES, N_JOINTS, Q_MAX, Q_MIN
from serpar.sim.plants.backlash import settle_with_backlash
from serpar.sim.plants.static_panda import (
    STIFFNESS_NM_PER_RAD,
    TOOL_BODY,
    ArmPlant,
    HiddenErrors,
    TruthConfig,
    build_model,
    nominal_plant,
    sample_poses,
)
from serpar.sim.recording import Recording

EFFECTS = ("geometric", "joint_compliance", "backlash", "encoder", "thermal_drift")
N_TRAIN, N_VERIFY = 150, 100
BACKLASH_RAD = 0.5e-3
BACKLASH_JOINTS = (2, 3, 4, 5, 6)
GEAR_FRICTION_NM = 0.3
EXPANSION_PER_K = 23e-6
WARMING_K_PER_S = 5.0 / 3600.0
CAMPAIGN_S = 7200.0


def _check(effect: str | None, magnitude: float | None) -> float:
    if effect is not None and effect not in EFFECTS:
        raise ConfigError(f"unknown static arm effect {effect!r}; valid: {', '.join(EFFECTS)}")
    mag = 1.0 if magnitude is None else float(magnitude)
    if not (np.isfinite(mag) and mag > 0):
        raise ConfigError(f"magnitude must be a positive multiple of the effect's default "
                          f"size, got {magnitude!r}")
    return mag


def _nuisance(rng: np.random.Generator, geometric: float) -> HiddenErrors:
    """Tracker registration and SMR offset always; link frame errors for ``geometric``."""
    pos = np.zeros((N_JOINTS + 1, 3))
    rot = np.zeros((N_JOINTS + 1, 3))
    pos[0], rot[0] = rng.normal(size=3) * 1e-3, rng.normal(size=3) * 1e-3
    pos[1:] = rng.normal(size=(N_JOINTS, 3)) * 0.2e-3 * geometric
    rot[1:] = rng.normal(size=(N_JOINTS, 3)) * 0.5e-3 * geometric
    return HiddenErrors(pos, rot, rng.normal(size=3) * 0.5e-3)


def _poses(effect: str | None, cfg: TruthConfig, rng: np.random.Generator
           ) -> NDArray[np.float64]:
    nominal = nominal_plant(cfg)
    if effect != "joint_compliance":
        return sample_poses(cfg, nominal, N_TRAIN + N_VERIFY, rng)
    centre = sample_poses(replace(cfg, joint_margin_rad=0.5), nominal, 1, rng)[0]
    narrow = []
    while len(narrow) < N_TRAIN:  # the narrow calibration box, tool above the table
        q = np.clip(centre + rng.uniform(-0.3, 0.3, size=(N_TRAIN, N_JOINTS)), Q_MIN, Q_MAX)
        narrow.extend(q[nominal.tool_points(q)[:, 2] > cfg.min_tool_height_m])
    return np.vstack([np.asarray(narrow[:N_TRAIN]), sample_poses(cfg, nominal, N_VERIFY, rng)])


def make_twin(effect: str | None, magnitude: float | None, seed: int
              ) -> tuple[Recording, dict[str, object]]:
    """The recording of a campaign on a plant with ``effect`` (None: no hidden effect) and
    the answer (effect, magnitude, physical parameters)."""
    mag = _check(effect, magnitude)
    rng = np.random.default_rng([seed, 7])
    cfg = TruthConfig(seed=seed, stiffness=None)
    errors = _nuisance(rng, mag if effect == "geometric" else 0.0)
    q = _poses(effect, cfg, rng)
    split = np.array(["train"] * N_TRAIN + ["verify"] * N_VERIFY)
    order = rng.permutation(len(q))  # measured in random order; time follows that order
    time = np.empty(len(q))
    time[order] = np.linspace(0.0, CAMPAIGN_S, len(q))
    answer: dict[str, object] = {"effect": effect or "none", "magnitude": mag if effect else 0.0,
                                 "seed": seed}
    approach = None
    if effect == "joint_compliance":
        stiff = tuple(k / mag for k in STIFFNESS_NM_PER_RAD)
        plant = ArmPlant(replace(cfg, stiffness=stiff), build_model(replace(cfg, stiffness=stiff), errors))
        points = plant.tool_points(plant.settle(q))
        answer["compliance_rad_per_nm"] = [1.0 / k for k in stiff]
    elif effect == "backlash":

        joints = tuple(int(j) for j in sorted(rng.choice(BACKLASH_JOINTS, size=rng.integers(2, 4), replace=False)))
        half = np.zeros(N_JOINTS)
        half[[j - 1 for j in joints]] = BACKLASH_RAD * mag
        approach = np.where(split[:, None] == "train", 1.0, -1.0) * np.ones((1, N_JOINTS))
        model = build_model(cfg, errors)
        q_link, moving = settle_with_backlash(model, q, approach, half, GEAR_FRICTION_NM)
        points = ArmPlant(cfg, model).tool_points(q_link)
        answer.update(backlash_half_rad=half.tolist(), joints=list(joints),
                      friction_nm=GEAR_FRICTION_NM, creeping_poses=int(moving.sum()))
    elif effect == "encoder":
        scale = rng.normal(size=N_JOINTS) * 1e-3 * mag
        offset = rng.normal(size=N_JOINTS) * 0.5e-3 * mag
        points = ArmPlant(cfg, build_model(cfg, errors)).tool_points((1 + scale) * q + offset)
        answer.update(scale=scale.tolist(), offset_rad=offset.tolist())
    elif effect == "thermal_drift":
        order_t = np.argsort(time)  # calibration first, verification later in the campaign
        split = np.where(np.argsort(order_t) < int(0.6 * len(q)), "train", "verify")
        kappa = EXPANSION_PER_K * WARMING_K_PER_S * mag
        points = _thermal_points(cfg, errors, q, time, kappa)
        answer["kappa_per_s"] = kappa
    else:
        points = ArmPlant(cfg, build_model(cfg, errors)).tool_points(q)
        if effect == "geometric":
            answer.update(link_pos_error_m=errors.pos[1:].tolist(),
                          link_rot_error_rad=errors.rot[1:].tolist())
    seen = points + rng.normal(size=points.shape) * cfg.tracker_sigma_m
    data = StaticArmData(q, "position", cfg.tracker_sigma_m, position=seen, time=time,
                         approach=approach, split=split, tool_offset_m=cfg.tool_offset_m,
                         tool_mass_kg=cfg.tool_mass_kg, hand=cfg.hand)
    rec = to_recording(data, "sim", {"twin": "static arm campaign (laser tracker)"})
    return rec, answer


def _thermal_points(cfg: TruthConfig, errors: HiddenErrors, q: NDArray[np.float64],
                    time: NDArray[np.float64], kappa: float) -> NDArray[np.float64]:
    """Tool points with every link frame offset and the tool bracket grown by 1 + kappa t."""
    model = build_model(cfg, errors)
    bodies = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n)
              for n in (*LINK_NAMES[1:], TOOL_BODY)]
    cold = model.body_pos[bodies].copy()
    plant = ArmPlant(cfg, model)
    out = np.empty((len(q), 3))
    for n, (qq, t) in enumerate(zip(q, time)):
        model.body_pos[bodies] = cold * (1.0 + kappa * t)
        out[n] = plant.tool_points(qq[None, :])[0]
    model.body_pos[bodies] = cold
    return out
