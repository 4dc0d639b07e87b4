"""The scoring's plate contact sensor (MuJoCo's contact sensor, aimed at one part at a time)
reads the same force as summing the contacts by hand."""

import mujoco
import numpy as np

from serpar.checks.arm_checks import DOWN, press_setup
from serpar.controllers.arm_controller import ControlLaw
from serpar.controllers.arm_laws import CartesianTarget, ForceTarget
from serpar.sim import names
from serpar.sim.contact import ContactForceProbe, aim_plate_contact, body_geoms
from serpar.sim.scene import SceneConfig


def test_plate_contact_sensor_matches_the_contact_sum_of_the_part_it_is_aimed_at():
    scene, ctrl, contact_tcp = press_setup(False, scene_config=SceneConfig(n_conductors=2))
    m, d = scene.model, scene.data
    plate = [g for g in range(m.ngeom) if m.body(m.geom_bodyid[g]).name.startswith(names.PLATE)]
    held, resting = (int(b) for b in scene.conductor_bodies)  # conductor 0 is in the hand
    probe = ContactForceProbe(m, body_geoms(m, held), plate)
    rot = d.site_xmat[m.site(names.ARM + "tcp").id].reshape(3, 3).copy()
    target = CartesianTarget(contact_tcp - np.array([0, 0, 5e-4]), rot)
    on_resting, on_held, largest, worst = aim_plate_contact(m, resting), None, 0.0, 0.0
    for period in range(600):
        ctrl.track(target, ControlLaw.FORCE_POSITION, ForceTarget(DOWN, 5.0))
        ctrl.update(m, d)
        if period == 300:
            assert np.all(d.sensordata[on_resting] == 0.0)  # the tray part never touches the plate
            on_held = aim_plate_contact(m, held)
        for _ in range(ctrl.substeps):
            mujoco.mj_step(m, d)
            if on_held is not None:
                summed = np.linalg.norm(probe.force(d))
                largest = max(largest, summed)
                worst = max(worst, abs(summed - np.linalg.norm(d.sensordata[on_held])))
    assert largest > 3.0  # pressed onto the plate at ~5 N
    assert worst < 1e-9
