"""The assembled cell: parts, tolerances, cameras, and that parts rest where they should."""

import mujoco
import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.info import scene_info
from serpar.sim.scene import SceneConfig, build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene(SceneConfig(seed=3))


def test_cell_has_both_robots_sensors_and_cameras(scene):
    m = scene.model
    assert m.opt.timestep == SceneConfig().physics.timestep
    acts = {m.actuator(i).name for i in range(m.nu)}
    assert {f"arm/tau{i}" for i in range(1, 8)} <= acts and "arm/grip" in acts
    assert {f"stewart/leg{i}" for i in range(1, 7)} <= acts
    sensors = {m.sensor(i).name for i in range(m.nsensor)}
    assert {f"arm/tau_J{i}" for i in range(1, 8)} <= sensors
    assert {m.camera(i).name for i in range(m.ncam)} == {"top_left", "top_right", "inspect_left",
                                                         "inspect_right"}
    assert np.all(m.cam_resolution == [2048, 1536])
    assert len(scene.hole_sites) == 36 and len(scene.conductor_bodies) == 36


def test_drawn_diameters_are_the_built_geometry(scene):
    m = scene.model
    for k in (0, 17, 35):
        journal = m.geom(f"{names.conductor(k)}journal")
        # the contact surface: the cylinder shrunk by the edge round plus that margin
        assert (journal.size[0] + journal.margin[0]) * 2 == pytest.approx(scene.diameters.journals[k], abs=1e-12)
    info = scene_info(scene)
    assert 0 <= info["clearance_um"]["min"] and info["clearance_um"]["max"] <= 16
    assert info["bore_roundness_um_worst"] < 0.5


def test_hole_grid_pitch_and_height(scene):
    xyz = scene.data.site_xpos[scene.hole_sites]
    d01 = np.linalg.norm(xyz[1] - xyz[0])
    d06 = np.linalg.norm(xyz[6] - xyz[0])
    assert d01 == pytest.approx(0.010, abs=1e-9) and d06 == pytest.approx(0.010, abs=1e-9)


def test_conductors_stay_in_tray_and_arm_holds(scene):
    m, d = scene.model, scene.data
    scene.reset()
    start = d.xpos[scene.conductor_bodies].copy()
    for _ in range(2000):  # 0.2 s
        scene.gravity_hold_arm()
        mujoco.mj_step(m, d)
    moved = np.linalg.norm(d.xpos[scene.conductor_bodies] - start, axis=1)
    assert moved.max() < 20e-6  # parts settle on their 3-ball supports, nothing falls
    assert np.abs(d.qpos[scene.arm_qpos_adr] - scene.model.qpos0[scene.arm_qpos_adr]).max() < 10


def test_config_validation_messages():
    with pytest.raises(ConfigError, match="valid 0..36"):
        SceneConfig(n_conductors=40)
    with pytest.raises(ConfigError, match="integer"):
        SceneConfig(seed=1.5)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="valid: uniform, normal"):
        SceneConfig(tolerance_distribution="beta")
