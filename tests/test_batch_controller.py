"""The batched arm controller stack (controllers/batch_*.py): its model terms against MuJoCo's own
functions on an MjData, a trial's law the same in any batch, the one-arm adapter (ArmController,
the batch at N = 1 on an MjData plant) against a mujoco.batch plant in closed loop, and per-trial
noise streams. The numbers of the single-arm stack the batch replaced are held by
tests/test_arm_controller_reference.py."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from controller_support import rotation
from mujoco.batch import Batch

from serpar.controllers import arm_laws, batch_laws, batch_linalg
from serpar.controllers.arm_controller import (
    ArmController,
    ArmControllerConfig,
    ArmSensors,
    ControlLaw,
    controller_config,
)
from serpar.controllers.arm_laws import CartesianTarget, ForceTarget
from serpar.controllers.arm_sensors import ArmSensorConfig
from serpar.controllers.batch_controller import BatchArmController
from serpar.controllers.batch_laws import LAW_CODE, BatchCartesianTarget, BatchForceTarget
from serpar.controllers.batch_model import MDOT_STEP_RAD, BatchNominalArm
from serpar.controllers.batch_sensors import BatchArmSensors, plant_arm_state, trial_seeds
from serpar.errors import ConfigError, LimitError
from serpar.sim.arm import HOME_Q, build_arm_spec
from serpar.sim.arm_drive import ArmIndex

CONFIG = ArmControllerConfig()


def _worst(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))))


def _states(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    q = np.asarray(HOME_Q) + rng.normal(0.0, 0.3, (n, 7))
    dq = rng.normal(0.0, 0.8, (n, 7))
    dq[1] = 0.0  # a trial at rest: Mdot dq is zero without a difference
    return q, dq


def _mujoco_terms(model: mujoco.MjModel, q: np.ndarray, dq: np.ndarray) -> dict[str, np.ndarray]:
    """The reference: MuJoCo's own functions on an MjData of the arm at (q, dq) (mj_jacSite,
    mj_jacDot, mj_fullM, mj_rne), and Mdot dq by the central difference of mj_fullM."""
    index = ArmIndex.from_model(model)
    dof, site = index.dof, index.tcp_site
    data = mujoco.MjData(model)

    def at(qq: np.ndarray, vel: np.ndarray) -> np.ndarray:
        data.qpos[index.qpos], data.qvel[dof] = qq, vel
        for stage in (mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_crb, mujoco.mj_comVel):
            stage(model, data)
        full = np.zeros((model.nv, model.nv))
        mujoco.mj_fullM(model, data, full)
        return full[np.ix_(dof, dof)]

    speed = float(np.linalg.norm(dq))
    mdot = np.zeros(7)
    if speed:
        step = MDOT_STEP_RAD * dq / speed
        mdot = (at(q + step, dq) - at(q - step, dq)) @ dq * (speed / (2 * MDOT_STEP_RAD))
    mass = at(q, dq)
    rne = np.zeros(model.nv)
    mujoco.mj_rne(model, data, 0, rne)
    jac, jdot = np.zeros((6, model.nv)), np.zeros((6, model.nv))
    mujoco.mj_jacSite(model, data, jac[:3], jac[3:], site)
    mujoco.mj_jacDot(model, data, jdot[:3], jdot[3:], data.site_xpos[site], model.site_bodyid[site])
    link = mass - np.diag(model.dof_armature[dof])
    return {"pos": data.site_xpos[site].copy(), "rot": data.site_xmat[site].reshape(3, 3).copy(),
            "jac": jac[:, dof].copy(), "jdot": jdot[:, dof], "jdot_dq": jdot[:, dof] @ dq,
            "mass": mass, "bias": rne[dof] + model.dof_damping[dof] * dq, "mdot_dq": mdot,
            "beta": rne[dof] - mdot, "momentum": link @ dq}


def test_batch_nominal_terms_equal_mujocos_functions() -> None:
    rng = np.random.default_rng(5)
    q, dq = _states(rng, 6)
    batch = BatchNominalArm(6)
    batch.load(q, dq)
    terms = batch.terms()
    ours = {"pos": terms.pos, "rot": terms.rot, "jac": terms.jac,
            "jdot": batch.tcp_jacobian_dot(), "jdot_dq": terms.jdot_dq, "mass": terms.mass,
            "bias": terms.bias, "mdot_dq": batch.mass_dot_dq(), "beta": batch.beta(),
            "momentum": batch.momentum()}
    worst: dict[str, float] = {}
    for i in range(6):
        for name, value in _mujoco_terms(batch.model, q[i], dq[i]).items():
            worst[name] = max(worst.get(name, 0.0), _worst(value, ours[name][i]))
    assert max(worst.values()) <= 1e-12, worst
    assert np.abs(ours["mdot_dq"][1]).max() == 0.0 and np.abs(ours["mdot_dq"][0]).max() > 1e-3
    # the joint-space laws' terms skip Jdot dq and are otherwise the same
    lean = batch.terms(jdot=False)
    assert lean.jdot_dq is None and np.array_equal(lean.jac, terms.jac)


def test_atan2_is_the_c_librarys() -> None:
    rng = np.random.default_rng(0)
    y = np.abs(rng.normal(size=20000)) * rng.choice([0.0, 1e-12, 1e-3, 1.0, 1e3], 20000)
    x = rng.normal(size=20000)
    ours = batch_laws.atan2(y, x)
    libm = np.array([math.atan2(a, b) for a, b in zip(y, x)])
    assert np.array_equal(ours, libm)  # np.arctan2 differs in ~2 % of these on AVX-512


def test_orientation_error_equals_mujoco_quaternions() -> None:
    rng = np.random.default_rng(2)
    rot = np.stack([rotation(rng.normal(0.0, 2.0, 3)) for _ in range(400)])
    target = np.stack([rotation(rng.normal(0.0, 2.0, 3)) for _ in range(400)])
    target[:50] = rot[:50]  # no error
    target[50:100] = np.stack([rotation(np.array([np.pi - 1e-9, 0, 0])) @ r for r in rot[50:100]])
    ours = batch_laws.orientation_error(rot, target)  # 400 rows: the vectorised copy
    single = np.stack([arm_laws.orientation_error(a, b) for a, b in zip(rot, target)])
    assert _worst(ours, single) <= 1e-12
    assert np.array_equal(ours, single)
    few = batch_laws.ROWWISE_MAX  # a few rows: MuJoCo's own, row by row
    assert np.array_equal(batch_laws.orientation_error(rot[:few], target[:few]), single[:few])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_trials_law_is_the_same_in_any_batch(seed: int) -> None:
    """A trial's torque and force offset in a batch of 20 in mixed laws equal its own at N = 1
    (each law runs on a gather of its rows; the orientation error is the vectorised copy of
    MuJoCo's functions for 9 rows and MuJoCo's own for one)."""
    rng = np.random.default_rng(seed)
    n = 20
    q, dq = _states(rng, n)
    nominal = BatchNominalArm(n)
    nominal.load(q, dq)
    terms = nominal.terms()
    laws = [ControlLaw.JOINT_PD] * 2 + [ControlLaw.IMPEDANCE] * 9 + [ControlLaw.FORCE_POSITION] * 9
    law = rng.permutation(np.array([LAW_CODE[k] for k in laws], dtype=np.int8))
    assert batch_laws.ROWWISE_MAX < 9
    cart = BatchCartesianTarget(
        terms.pos + rng.normal(0.0, 0.02, (n, 3)),
        np.stack([rotation(rng.normal(0.0, 0.3, 3)) @ r for r in terms.rot]),
        rng.normal(0.0, 0.05, (n, 6)), rng.normal(0.0, 0.2, (n, 6)))
    axis = rng.normal(size=(n, 3))
    force = BatchForceTarget(axis / np.linalg.norm(axis, axis=1)[:, None], rng.uniform(0, 8, n))
    targets = batch_laws.BatchTargets(
        law, q + rng.normal(0, 0.01, (n, 7)), rng.normal(0, 0.1, (n, 7)), cart, force,
        np.arange(n) % 3 != 1, rng.uniform(-0.01, 0.01, n),
        np.asarray(HOME_Q) + rng.normal(0, 0.1, (n, 7)))
    push = rng.uniform(0, 8, n)
    tau = batch_laws.law_torque(terms, targets, push, CONFIG)
    offsets = batch_laws.next_force_offset(targets.offset, force, push, CONFIG.force_position, 1e-3)
    one = BatchNominalArm(1)
    for i in range(n):
        one.load(q[i:i + 1], dq[i:i + 1])
        alone = batch_laws.BatchTargets(*(
            t.take([i]) if isinstance(t, BatchCartesianTarget | BatchForceTarget) else t[i:i + 1]
            for t in targets))
        ref = batch_laws.law_torque(one.terms(), alone, push[i:i + 1], CONFIG)
        assert np.array_equal(ref[0], tau[i]), (i, ref[0] - tau[i])
        assert offsets[i] == batch_laws.next_force_offset(
            targets.offset[i:i + 1], force.take([i]), push[i:i + 1], CONFIG.force_position, 1e-3)[0]
    assert np.abs(tau).max() > 1.0


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
            target = CartesianTarget(pos + OFFSET, rotation(TURN) @ rot)
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
            ctrl.track(pos + OFFSET, rotation(TURN) @ rot)
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

    # the one-arm view reads an MjData plant into the same model (tau_J latched, q and dq from data)
    model = build_arm_spec().compile()
    data = mujoco.MjData(model)
    sensors = ArmSensors(ArmIndex.from_model(model),
                         BatchArmSensors(config, trial_seeds(11, [2]), chunk=7))
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


def test_one_singular_operational_inertia_does_not_stop_the_batch() -> None:
    """J M^-1 J^T of an arm at a singularity is singular: that world gets the pseudo-inverse, the
    others exactly the inverse they get alone (a diverged world reset to qpos0 used to raise
    LinAlgError over the whole batch)."""
    rng = np.random.default_rng(0)
    regular = rng.normal(size=(6, 6))
    regular = regular @ regular.T + 6 * np.eye(6)
    rank5 = rng.normal(size=(6, 5))
    singular = rank5 @ rank5.T
    singular[:, 5] = singular[:, 0]
    singular[5, :] = singular[0, :]  # two equal rows: LU meets an exact zero pivot
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.inv(np.stack([regular, singular]))
    out = batch_linalg.inverse_each(np.stack([regular, singular]))
    assert np.array_equal(out[0], np.linalg.inv(regular))
    assert np.allclose(out[1], np.linalg.pinv(singular))
