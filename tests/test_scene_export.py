"""The whole cell as one MJCF (``serpar export-scene``): every compiled field of the file's model
equals the cell's in-memory model (the keyframe aside), the keyframe is the state an episode
starts from, the seed and the config reach the file, and the commands' bad input is one line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from serpar.sim.mjcf_writer import differences
from serpar.sim.scene import build_scene
from serpar.tasks.episode_config import EpisodeConfig, scene_config
from serpar.tasks.scene_export import HOME_KEY, export_scene


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("scene") / "cell.xml"
    return out, export_scene(EpisodeConfig(seed=2), out)


def test_every_compiled_field_equals_the_cell_model(exported) -> None:
    out, result = exported
    assert result.mjcf.round_trip_max == 0.0, result.mjcf.round_trip_field
    assert result.beyond_the_key == ()
    # and read independently: the file against a freshly built cell of the same seed
    cell = build_scene(scene_config(EpisodeConfig(seed=2))).model
    read = mujoco.MjModel.from_xml_path(str(out))
    assert differences(cell, read, ignore=("key_", "nkey", "names_map", "_sizes")) == {}
    assert read.nmesh == cell.nmesh > 36  # the drawn bores and the parts, inline


def _drift(m: mujoco.MjModel, key: bool) -> tuple[float, float]:
    """(arm joints [rad], platform [m]) moved in 50 ms with the controls held, from qpos0 and
    zero controls, or from the home key."""
    d = mujoco.MjData(m)
    if key:
        mujoco.mj_resetDataKeyframe(m, d, m.key(HOME_KEY).id)
    mujoco.mj_forward(m, d)
    arm = [m.joint(f"arm/joint{j}").qposadr[0] for j in range(1, 8)]
    platform = m.body("stewart/platform").id
    q, p = d.qpos[arm].copy(), d.xpos[platform].copy()
    for _ in range(500):
        mujoco.mj_step(m, d)
    return float(np.abs(d.qpos[arm] - q).max()), float(np.linalg.norm(d.xpos[platform] - p))


def test_the_home_key_is_the_start_state_and_holds_still(exported) -> None:
    """From qpos0 and zero controls the arm falls and the legs run to zero stroke; at the key
    (the cell's reset state: the ready pose, gravity-holding torques, the home strokes) both
    stay put with no controller for 50 ms."""
    out, _ = exported
    m = mujoco.MjModel.from_xml_path(str(out))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key(HOME_KEY).id)
    scene = build_scene(scene_config(EpisodeConfig(seed=2)))
    np.testing.assert_array_equal(d.qpos, scene.data.qpos)
    np.testing.assert_array_equal(d.ctrl, scene.data.ctrl)
    arm0, platform0 = _drift(m, key=False)
    arm, platform = _drift(m, key=True)
    assert arm < 1e-6 and arm0 > 1e-2  # rad
    assert platform < 1e-3 and platform0 > 1e-2  # m


def test_the_seed_and_the_config_reach_the_file(exported, tmp_path) -> None:
    out, _ = exported
    other = export_scene(EpisodeConfig(seed=3, arm_friction=1.0, arm_friction_form="gaz"),
                         tmp_path / "cell3.xml")
    assert other.mjcf.round_trip_max == 0.0
    a, b = (mujoco.MjModel.from_xml_path(str(p)) for p in (out, other.mjcf.path))
    assert not np.array_equal(a.mesh_vert, b.mesh_vert)  # another tolerance draw of the bores
    (drive,) = other.mjcf.not_expressed
    assert drive.startswith("sigmoid drive friction") and "no MJCF form" in drive
    assert drive in other.mjcf.path.read_text()


def _serpar(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {"MUJOCO_GL": "egl", "PATH": "/usr/bin:/bin"}
    return subprocess.run([sys.executable, "-m", "serpar", *args], cwd=cwd, text=True,
                          capture_output=True, env=env, timeout=300, check=False)


def test_an_existing_file_is_refused_and_view_needs_a_display(exported) -> None:
    out, _ = exported
    done = _serpar("export-scene", "--out", str(out), cwd=out.parent)
    assert done.returncode == 2 and done.stderr.count("\n") == 1
    assert "already exists; --force overwrites it" in done.stderr
    view = _serpar("view", "--seed", "1", cwd=out.parent)  # no DISPLAY in this environment
    assert view.returncode == 2 and view.stderr.count("\n") == 1
    assert "no display" in view.stderr and "serpar export-scene --out" in view.stderr
