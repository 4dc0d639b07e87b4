"""The batched arm controller stack (controllers/batch_*.py) against the single-arm one: model
terms, laws, a closed loop over a mujoco.batch plant, and per-trial noise streams."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from mujoco.batch import Batch

from serpar.controllers import arm_laws, batch_laws
from serpar.controllers.arm_controller import (
    ArmController,
    ArmControllerConfig,
    ControlLaw,
    controller_config,
)
from serpar.controllers.arm_laws import CartesianTarget, ForceTarget
from serpar.controllers.arm_model import NominalArm
from serpar.controllers.arm_sensors import ArmSensorConfig, ArmSensors
from serpar.controllers.batch_controller import BatchArmController
from serpar.controllers.batch_laws import LAW_CODE, BatchCartesianTarget, BatchForceTarget
from serpar.controllers.batch_model import BatchNominalArm
from serpar.controllers.batch_sensors import BatchArmSensors, plant_arm_state, trial_seeds
from serpar.controllers.momentum import MomentumTerms
from serpar.errors import ConfigError, LimitError
from serpar.sim.arm import HOME_Q, build_arm_spec
from serpar.sim.arm_drive import ArmIndex

CONFIG = ArmControllerConfig()


def _rotation(rotvec: np.ndarray) -> np.ndarray:
    quat, mat = np.zeros(4), np.zeros(9)
    angle = float(np.linalg.norm(rotvec))
    mujoco.mju_axisAngle2Quat(quat, rotvec / angle, angle)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)


def _worst(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))))


def _states(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    q = np.asarray(HOME_Q) + rng.normal(0.0, 0.3, (n, 7))
    dq = rng.normal(0.0, 0.8, (n, 7))
    dq[1] = 0.0  # a trial at rest: Mdot dq is zero without a difference
    return q, dq


def test_batch_nominal_terms_equal_nominal_arm() -> None:
    rng = np.random.default_rng(5)
    q, dq = _states(rng, 6)
    batch = BatchNominalArm(6)
    batch.load(q, dq)
    terms = batch.terms()
    jdot = batch.tcp_jacobian_dot()
    mdq, beta, momentum = batch.mass_dot_dq(), batch.beta(), batch.momentum()
    single = NominalArm()
    worst: dict[str, float] = {}
    for i in range(6):
        single.load(q[i], dq[i])
        momenta = MomentumTerms(single)
        pos, rot = single.tcp_pose()
        jd = single.tcp_jacobian_dot()  # mj_jacDot
        pairs = {"pos": (pos, terms.pos[i]), "rot": (rot, terms.rot[i]),
                 "jac": (single.tcp_jacobian(), terms.jac[i]), "jdot": (jd, jdot[i]),
                 "jdot_dq": (jd @ dq[i], terms.jdot_dq[i]), "mass": (single.mass(), terms.mass[i]),
                 "bias": (single.bias(), terms.bias[i]), "mdot_dq": (momenta.mass_dot_dq(), mdq[i]),
                 "beta": (momenta.beta(), beta[i]), "momentum": (momenta.momentum(), momentum[i])}
        for name, (a, b) in pairs.items():
            worst[name] = max(worst.get(name, 0.0), _worst(a, b))
    assert max(worst.values()) <= 1e-12, worst
    assert np.abs(mdq[1]).max() == 0.0 and np.abs(mdq[0]).max() > 1e-3  # the rest path is taken


def test_atan2_is_the_c_librarys() -> None:
    rng = np.random.default_rng(0)
    y = np.abs(rng.normal(size=20000)) * rng.choice([0.0, 1e-12, 1e-3, 1.0, 1e3], 20000)
    x = rng.normal(size=20000)
    ours = batch_laws.atan2(y, x)
    libm = np.array([math.atan2(a, b) for a, b in zip(y, x)])
    assert np.array_equal(ours, libm)  # np.arctan2 differs in ~2 % of these on AVX-512


def test_orientation_error_equals_mujoco_quaternions() -> None:
    rng = np.random.default_rng(2)
    rot = np.stack([_rotation(rng.normal(0.0, 2.0, 3)) for _ in range(400)])
    target = np.stack([_rotation(rng.normal(0.0, 2.0, 3)) for _ in range(400)])
    target[:50] = rot[:50]  # no error
    target[50:100] = np.stack([_rotation(np.array([np.pi - 1e-9, 0, 0])) @ r for r in rot[50:100]])
    ours = batch_laws.orientation_error(rot, target)
    single = np.stack([arm_laws.orientation_error(a, b) for a, b in zip(rot, target)])
    assert _worst(ours, single) <= 1e-12
    assert np.array_equal(ours, single)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_laws_equal_arm_laws_per_trial(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 5
    q, dq = _states(rng, n)
    nominal = BatchNominalArm(n)
    nominal.load(q, dq)
    terms = nominal.terms()
    laws = [ControlLaw.JOINT_PD, ControlLaw.IMPEDANCE, ControlLaw.FORCE_POSITION,
            ControlLaw.IMPEDANCE, ControlLaw.FORCE_POSITION]
    has_force = np.array([False, False, True, True, True])
    cart = BatchCartesianTarget(
        terms.pos + rng.normal(0.0, 0.02, (n, 3)),
        np.stack([_rotation(rng.normal(0.0, 0.3, 3)) @ r for r in terms.rot]),
        rng.normal(0.0, 0.05, (n, 6)), rng.normal(0.0, 0.2, (n, 6)))
    axis = rng.normal(size=(n, 3))
    force = BatchForceTarget(axis / np.linalg.norm(axis, axis=1)[:, None], rng.uniform(0, 8, n))
    targets = batch_laws.BatchTargets(
        np.array([LAW_CODE[law] for law in laws], dtype=np.int8), q + rng.normal(0, 0.01, (n, 7)),
        rng.normal(0, 0.1, (n, 7)), cart, force, has_force, rng.uniform(-0.01, 0.01, n),
        np.asarray(HOME_Q) + rng.normal(0, 0.1, (n, 7)))
    push = rng.uniform(0, 8, n)
    tau = batch_laws.law_torque(terms, targets, push, CONFIG)
    offsets = batch_laws.next_force_offset(targets.offset, force, push, CONFIG.force_position, 1e-3)
    single = NominalArm()
    for i, law in enumerate(laws):
        single.load(q[i], dq[i])
        target = CartesianTarget(cart.pos[i], cart.rot[i], cart.vel[i], cart.acc[i])
        ft = ForceTarget(force.axis[i], float(force.force[i]))
        if law is ControlLaw.JOINT_PD:
            ref = arm_laws.joint_pd_torque(single, targets.q[i], targets.dq[i], CONFIG.joint)
        elif law is ControlLaw.IMPEDANCE:
            ff = np.concatenate([ft.force * ft.axis, np.zeros(3)]) if has_force[i] else None
            ref = arm_laws.impedance_torque(single, target, CONFIG.impedance, ff,
                                            targets.posture[i])
        else:
            ref = arm_laws.force_position_torque(single, target, CONFIG.force_position, ft,
                                                 float(push[i]), float(targets.offset[i]),
                                                 targets.posture[i])
        assert _worst(ref, tau[i]) <= 1e-12, (law, ref - tau[i])
        assert np.array_equal(ref, tau[i]), law
        assert offsets[i] == arm_laws.next_force_offset(float(targets.offset[i]), ft,
                                                        float(push[i]), CONFIG.force_position,
                                                        1e-3)


# --- closed loop: ArmController on an MjData against BatchArmController on a Batch ------------
HOLD, IMPEDANCE, FORCE_POSITION = 30, 150, 150
"""Control periods of each phase (JOINT_PD holding the start, then the two Cartesian laws)."""
OFFSET = np.array([0.02, -0.01, 0.015])
TURN = np.array([0.015, -0.025, 0.04])
DOWN = np.array([0.0, 0.0, -1.0])


def _plant() -> tuple[mujoco.MjModel, ArmIndex]:
    model = build_arm_spec().compile()
    model.opt.timestep = 1e-4  # 10 substeps per 1 kHz period, as the cell
    return model, ArmIndex.from_model(model)


def _run_single(model: mujoco.MjModel, index: ArmIndex, noise: bool, seed: int) -> np.ndarray:
    data = mujoco.MjData(model)
    data.qpos[index.qpos] = HOME_Q
    mujoco.mj_forward(model, data)
    ctrl = ArmController(model, "", controller_config(noise), seed)
    taus = []
    for k in range(HOLD + IMPEDANCE + FORCE_POSITION):
        if k == HOLD:
            pos, rot = ctrl.nominal.tcp_pose()
            target = CartesianTarget(pos + OFFSET, _rotation(TURN) @ rot)
            ctrl.track(target, ControlLaw.IMPEDANCE)
        if k == HOLD + IMPEDANCE:  # nothing to push on: the force loop still runs
            ctrl.tare()
            ctrl.track(target, ControlLaw.FORCE_POSITION, ForceTarget(DOWN, 3.0))
        taus.append(ctrl.update(model, data).copy())
        mujoco.mj_step(model, data, nstep=ctrl.substeps)
    return np.array(taus)


def _run_batch(model: mujoco.MjModel, index: ArmIndex, noise: bool,
               seeds: list[np.random.SeedSequence]) -> np.ndarray:
    n = len(seeds)
    plant = Batch(model, n, 1)
    qpos, qvel, ctrl_in = plant.bind("qpos"), plant.bind("qvel"), plant.bind("ctrl")
    sensordata = plant.bind("sensordata")  # bound before the first call, so it is filled
    plant.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
    qpos[:, index.qpos] = HOME_Q
    plant.forward()
    ctrl = BatchArmController(n, model.opt.timestep, controller_config(noise), seeds=seeds,
                              chunk=64)
    taus = []
    for k in range(HOLD + IMPEDANCE + FORCE_POSITION):
        if k == HOLD:
            pos, rot = ctrl.nominal.tcp_pose()
            ctrl.track(pos + OFFSET, _rotation(TURN) @ rot)
        if k == HOLD + IMPEDANCE:
            ctrl.tare()
            ctrl.track(ctrl.cart_pos.copy(), ctrl.cart_rot.copy(), law=ControlLaw.FORCE_POSITION,
                       force_axis=DOWN, force=3.0)
        tau = ctrl.update(*plant_arm_state(qpos, qvel, sensordata, index))
        ctrl_in[:, index.actuators] = tau
        taus.append(tau.copy())
        plant.step(nstep=ctrl.substeps)
    assert np.all(ctrl.force_offset > 1e-4)  # the force-position reference really moved
    return np.array(taus).transpose(1, 0, 2)  # (trial, period, joint)


def test_closed_loop_batch_equals_arm_controller_ideal_sensors() -> None:
    model, index = _plant()
    single = _run_single(model, index, noise=False, seed=0)
    assert np.abs(single).max() > 10.0  # the arm really moves and holds against gravity
    seeds = trial_seeds(0, range(3))
    for batch in (_run_batch(model, index, False, seeds), _run_batch(model, index, False, seeds[:1])):
        worst = max(_worst(single, trial) for trial in batch)
        assert worst <= 1e-9, worst  # N m, over 330 periods of JOINT_PD, IMPEDANCE, FORCE_POSITION
        # In this environment the batch-of-one is bit-identical; a failure here with the bound
        # above holding means an array layout or BLAS kernel now differs (harmless round-off).
        assert worst == 0.0


def test_closed_loop_with_noise_trial_i_equals_arm_controller_seed_i() -> None:
    """Each trial's stream is the SeedSequence ArmSensors(seed) uses: with noise on, trial i of
    a batch of 3 reads and commands what ArmController(seed=i) does, bit for bit."""
    model, index = _plant()
    batch = _run_batch(model, index, True, [np.random.SeedSequence(s) for s in range(3)])
    for s in range(3):
        assert np.array_equal(batch[s], _run_single(model, index, noise=True, seed=s))
    assert _worst(batch[0], batch[1]) > 1e-3  # different streams, different noise


def test_trial_noise_does_not_depend_on_the_batch() -> None:
    config, dt = ArmSensorConfig(), 1e-3
    rng = np.random.default_rng(9)
    q, dq, tau = (rng.normal(size=(250, 4, 7)) for _ in range(3))
    alone = BatchArmSensors(config, trial_seeds(11, [2]), chunk=100)
    four = BatchArmSensors(config, trial_seeds(11, range(4)), chunk=64)
    reads_alone = [alone.read(q[k, 2:3], dq[k, 2:3], tau[k, 2:3], dt) for k in range(250)]
    reads_four = [four.read(q[k], dq[k], tau[k], dt) for k in range(250)]
    for a, b in zip(reads_alone, reads_four):
        for field in ("q", "dq", "tau_J"):
            assert np.array_equal(getattr(a, field)[0], getattr(b, field)[2])
    noise = np.array([r.tau_J - tau[k] for k, r in enumerate(reads_four)])
    assert _worst(noise[:, 0], noise[:, 1]) > 0.01  # trials do not share a stream
    assert 0.015 < float(np.std(noise - noise.mean(axis=0))) < 0.025  # sigma 0.02 N m white

    # the same SeedSequence drives ArmSensors identically (its tau_J latched, q and dq from data)
    model = build_arm_spec().compile()
    data = mujoco.MjData(model)
    sensors = ArmSensors(ArmIndex.from_model(model), config, trial_seeds(11, [2])[0])
    for k, expected in enumerate(reads_alone[:50]):
        data.qpos[:7], data.qvel[:7] = q[k, 2], dq[k, 2]
        sensors.latch(tau[k, 2])
        got = sensors.read(model, data, dt)
        assert np.array_equal(got.tau_J, expected.tau_J[0])
        assert np.array_equal(got.dq, expected.dq[0]) and np.array_equal(got.q, expected.q[0])

    # a slot restarted with trial 2's stream reads as a fresh sensor of trial 2
    four.reseed(np.array([1]), trial_seeds(11, [2]))
    for k in range(120):  # slot 1 fed trial 2's inputs
        again = four.read(q[k, [0, 2, 2, 3]], dq[k, [0, 2, 2, 3]], tau[k, [0, 2, 2, 3]], dt)
        assert np.array_equal(again.tau_J[1], reads_alone[k].tau_J[0])
        assert np.array_equal(again.dq[1], reads_alone[k].dq[0])


def test_restarted_slot_runs_as_a_fresh_controller() -> None:
    """A slot given a new trial (Monte Carlo slot reuse) forgets its old one: sensors, observer,
    force offset and law state all start over, so it commands what a fresh controller does."""
    rng = np.random.default_rng(4)
    q = np.asarray(HOME_Q) + rng.normal(0.0, 0.05, (2, 7))
    dq, tau = rng.normal(0.0, 0.1, (2, 7)), rng.normal(0.0, 5.0, (2, 7))
    used = BatchArmController(2, 1e-4, controller_config(True), seeds=trial_seeds(3, [0, 1]))
    for _ in range(40):
        used.update(q, dq, tau)
    pos, rot = used.nominal.tcp_pose()
    used.track(pos, rot, law=ControlLaw.FORCE_POSITION, force_axis=DOWN, force=2.0)
    for _ in range(40):
        used.update(q, dq, tau)
    used.restart([1], trial_seeds(3, [7]))
    fresh = BatchArmController(1, 1e-4, controller_config(True), seeds=trial_seeds(3, [7]))
    for ctrl, rows in ((used, slice(None)), (fresh, slice(1, 2))):
        for k in range(60):
            if k == 20:
                ctrl.track(pos[1:], rot[1:], law=ControlLaw.FORCE_POSITION, force_axis=DOWN,
                           force=2.0, ids=[ctrl.n - 1])
            ctrl.update(q[rows], dq[rows], tau[rows])
    assert np.array_equal(used.tau[1], fresh.tau[0]) and np.abs(fresh.tau).max() > 1.0
    assert used.force_offset[1] == fresh.force_offset[0] != 0.0


def test_batch_controller_rejects_bad_input() -> None:
    ctrl = BatchArmController(2, 1e-4)
    with pytest.raises(ConfigError, match="force target"):
        ctrl.track(np.zeros(3), np.eye(3), law=ControlLaw.FORCE_POSITION)
    with pytest.raises(ConfigError, match="unit"):
        ctrl.track(np.zeros(3), np.eye(3), law=ControlLaw.FORCE_POSITION, force_axis=[0, 0, 2.0],
                   force=1.0)
    with pytest.raises(LimitError, match="trial 1: joint4"):
        ctrl.hold_joints(np.array([0, 0, 0, 0.5, 0, 1, 0]), ids=[1])
    with pytest.raises(ConfigError, match="shape"):
        ctrl.nominal.load(np.zeros((3, 7)), np.zeros((3, 7)))
    with pytest.raises(ConfigError, match="seeds"):
        BatchArmController(2, 1e-4, seeds=trial_seeds(0, range(3)))
    with pytest.raises(ConfigError, match="whole number"):
        BatchArmController(2, 3e-4)
