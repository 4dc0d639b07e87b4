"""The arm can reach every tray pocket and every hole with the gripper pointing down."""

import numpy as np
import pytest

from serpar.sim.poses import solve_tcp_pose
from serpar.sim.scene import SceneConfig, build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene(SceneConfig())


def test_every_conductor_and_hole_is_reachable_top_down(scene):
    d = scene.data
    grasp = 0.5 * scene.config.conductor.body_length
    targets = [d.xpos[b] + [0, 0, grasp] for b in scene.conductor_bodies]
    # Hover with the journal tip 2 mm above the entry: shoulder 3.5 mm up, grasp 5 mm above it.
    hover = scene.config.conductor.journal_length + 0.002 + grasp
    targets += [d.site_xpos[s] + [0, 0, hover] for s in scene.hole_sites]
    for t in targets:
        q = solve_tcp_pose(scene, np.asarray(t))  # raises if the residual exceeds 1 um
        assert q.shape == (7,)
