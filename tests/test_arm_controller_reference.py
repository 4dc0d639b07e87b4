"""ArmController against torques recorded from the single-arm stack it replaced.

tests/data/arm_controller_reference.npz was written by :func:`record` at commit 2530edc, when
ArmController still ran its own copy of the laws, model terms, observer and sensor model
(arm_laws.py, arm_model.NominalArm, momentum.MomentumTerms, wrench.WrenchEstimator,
arm_sensors.ArmSensors). Since then ArmController is a view of BatchArmController at N=1; the
episode's figures were measured with the old stack, so every recorded number must come back to
within floating-point reassociation. Bit for bit holds on the CPU that wrote the fixture only:
MuJoCo's and BLAS's vector paths differ between CPUs at the last bit (an AMD EPYC without
AVX-512 gives 2.7e-12 N m in tau and 3.3e-12 N in F_s after 360 closed-loop periods, the
ulp-level difference growing through the loop), so the bound is ``ULP_BOUND`` (1e-9), five
orders of magnitude under any change of the laws (a dropped term or gain moves tau by > 1e-4).
The loop uses only ArmController's public interface, as the cell runtime drives it
(torque sensors latched from the period mean of :class:`TorqueADC`), and visits every law,
the unset JOINT_PD target, a feed-forward force under IMPEDANCE, a posture target and a tare.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
from controller_support import rotation

from serpar.controllers.arm_controller import ArmController, ControlLaw, controller_config
from serpar.controllers.arm_laws import CartesianTarget, ForceTarget
from serpar.controllers.arm_sensors import TorqueADC
from serpar.sim.arm import HOME_Q, build_arm_spec
from serpar.sim.arm_drive import ArmIndex

FIXTURE = Path(__file__).parent / "data" / "arm_controller_reference.npz"
PERIODS = 360
SIGNALS = ("tau", "wrench", "push", "offset", "q", "dq", "tau_J")
CASES = {"ideal": (False, 0), "noise_seed3": (True, 3)}
MEASURED = ("q", "dq", "tau_J")
"""Kept for the noisy case only (the ideal case's measurement is the plant's, and feeds tau)."""
ULP_BOUND = 1e-9
"""Largest |difference| from the fixture (N m, N, rad, rad/s): reassociation across CPUs."""


def closed_loop(noise: bool, seed: int) -> dict[str, np.ndarray]:
    """Per control period: torques, wrench, F_s, force offset and the measurement."""
    model = build_arm_spec().compile()
    model.opt.timestep = 1e-4  # 10 substeps per 1 kHz period, as the cell
    index = ArmIndex.from_model(model)
    data = mujoco.MjData(model)
    data.qpos[index.qpos] = HOME_Q
    mujoco.mj_forward(model, data)
    ctrl = ArmController(model, "", controller_config(noise), seed)
    adc = TorqueADC(index, ctrl.substeps)
    out: dict[str, list[np.ndarray]] = {name: [] for name in SIGNALS}
    target = None
    for k in range(PERIODS):
        if k == 20:  # the first 20 periods hold the first reading (no target set)
            ctrl.hold_joints(np.asarray(HOME_Q) + 0.02, np.full(7, 0.01))
        if k == 60:
            pos, rot = ctrl.nominal.tcp_pose()
            target = CartesianTarget(pos + np.array([0.02, -0.01, 0.015]),
                                     rotation(np.array([0.015, -0.025, 0.04])) @ rot,
                                     vel=np.array([0.01, 0.0, -0.01, 0.0, 0.02, 0.0]),
                                     acc=np.array([0.0, 0.1, 0.0, 0.05, 0.0, 0.0]))
            ctrl.track(target, ControlLaw.IMPEDANCE)
        if k == 140:  # Eq. 3's F_d fed forward, and a posture target
            ctrl.q_posture = np.asarray(HOME_Q) + 0.05
            ctrl.track(target, ControlLaw.IMPEDANCE, ForceTarget(np.array([0.0, 0.0, -1.0]), 2.0))
        if k == 180:  # nothing to push on: the force loop still runs
            ctrl.tare()
            ctrl.track(target, ControlLaw.FORCE_POSITION, ForceTarget(np.array([0.0, 0.0, -1.0]), 3.0))
        if k == 330:
            ctrl.hold_joints(np.asarray(HOME_Q))
        mean = adc.mean()
        if mean is not None:
            ctrl.sensors.latch(mean)
        out["tau"].append(ctrl.update(model, data).copy())
        out["wrench"].append(ctrl.wrench.copy())
        out["push"].append(np.array([ctrl.measured_push()]))
        out["offset"].append(np.array([ctrl.force_offset]))
        meas = ctrl.measurement
        assert meas is not None
        for name in ("q", "dq", "tau_J"):
            out[name].append(np.array(getattr(meas, name), dtype=float))
        for s in range(ctrl.substeps):
            mujoco.mj_step(model, data)
            adc.sample(data, s)
    return {name: np.array(rows) for name, rows in out.items()}


def record(path: Path = FIXTURE) -> None:
    """Write the fixture (run once, with the pre-rewire stack; never to make a failure pass)."""
    arrays = {f"{case}/{name}": values for case, (noise, seed) in CASES.items()
              for name, values in closed_loop(noise, seed).items()
              if noise or name not in MEASURED}
    np.savez_compressed(path, **arrays)


def test_arm_controller_reproduces_the_pre_rewire_stack_to_the_last_bits() -> None:
    reference = np.load(FIXTURE)
    for case, (noise, seed) in CASES.items():
        got = closed_loop(noise, seed)
        for name in SIGNALS if noise else set(SIGNALS) - set(MEASURED):
            expected = reference[f"{case}/{name}"]
            assert got[name].shape == expected.shape, (case, name)
            worst = float(np.max(np.abs(got[name] - expected)))
            assert worst <= ULP_BOUND, (case, name, worst)
        # the loop really exercises the laws: torque against gravity, a moving force reference
        assert np.abs(got["tau"]).max() > 10.0 and np.abs(got["offset"]).max() > 1e-4
    assert np.abs(reference["noise_seed3/wrench"] - reference["ideal/wrench"]).max() > 1e-3
