"""Rounded cylinders by shrink and margin: the journal's edge round (``ConductorConfig.edge_radius``,
the cell's) and the GPU scene's added rounding (``TrialSceneConfig.rounding``) give the same
contacts as the sharp part where a face meets a cylinder's side, the same mass, the margin on
the explicit pairs; the tip's chamfer is tangent to the journal's round."""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.conductor import ConductorConfig, tip_frustum
from serpar.sim.tolerances import HOLE_H7, JOURNAL_H6
from serpar.sim.trial_scene import PART, TrialSceneConfig, build_trial_spec
from serpar.tasks.warp_batch import mesh_vertices

SHARP = TrialSceneConfig(at_origin=True, seat_plane=True, conductor=ConductorConfig(edge_radius=0.0))
ROUNDED = dataclasses.replace(SHARP, rounding=(1e-6, 50e-6))
CELL = TrialSceneConfig(at_origin=True, seat_plane=True)  # the journal's 10 um edge round
CELL_GPU = dataclasses.replace(CELL, rounding=(1e-6, 50e-6))
HOLE, JOURNAL = HOLE_H7.nominal, JOURNAL_H6.nominal


def _journal_contacts(cfg: TrialSceneConfig, push: float) -> list[tuple[int, float]]:
    """(facet, depth) of the journal's contacts with the journal upright in the bore, its side
    ``push`` [m] past the +x facet's face, the shoulder 0.3 mm above the plate."""
    model = build_trial_spec(cfg, HOLE, JOURNAL).compile()
    data = mujoco.MjData(model)
    part = model.body(names.conductor_body(PART))
    adr = model.jnt_qposadr[part.jntadr[0]]
    data.qpos[adr:adr + 7] = [(HOLE - JOURNAL) / 2 + push, 0.0, 3e-4, 1.0, 0.0, 0.0, 0.0]
    mujoco.mj_forward(model, data)
    journal = model.geom(f"{names.conductor(PART)}journal").id
    out = []
    for c in data.contact[:data.ncon]:
        if journal in c.geom:
            active = c.dist < c.includemargin
            out.append((int(c.geom[0] + c.geom[1] - journal), c.dist - c.includemargin if active else np.inf))
    return out


@pytest.mark.parametrize("push", [0.2e-6, 2e-6])
@pytest.mark.parametrize("rounded", [ROUNDED, CELL, CELL_GPU], ids=["gpu", "cell", "cell+gpu"])
def test_the_rounded_journal_presses_on_the_facet_as_the_sharp_one(push: float, rounded) -> None:
    sharp, round_ = _journal_contacts(SHARP, push), _journal_contacts(rounded, push)
    assert sharp and {f for f, _ in sharp} == {f for f, d in round_ if np.isfinite(d)}
    assert min(d for _, d in sharp) == pytest.approx(-push, abs=2e-9)
    assert min(d for _, d in round_) == pytest.approx(-push, abs=2e-9)


def _part_inertial(model: mujoco.MjModel) -> tuple[float, np.ndarray, np.ndarray]:
    body = model.body(names.conductor_body(PART))
    return float(body.mass[0]), body.ipos.copy(), body.inertia.copy()


def test_rounding_keeps_the_parts_mass_and_sets_the_pairs_margin() -> None:
    sharp = build_trial_spec(SHARP, HOLE, JOURNAL).compile()
    rounded = build_trial_spec(ROUNDED, HOLE, JOURNAL).compile()
    (m0, c0, i0), (m1, c1, i1) = _part_inertial(sharp), _part_inertial(rounded)
    assert m1 == pytest.approx(m0, rel=1e-12)
    np.testing.assert_allclose(i1, i0, rtol=1e-12)
    np.testing.assert_allclose(c1, c0, rtol=1e-12, atol=1e-15)
    part_body = rounded.geom(f"{names.conductor(PART)}body").id
    pairs = [i for i in range(rounded.npair) if part_body in (rounded.pair_geom1[i], rounded.pair_geom2[i])]
    assert len(pairs) == 3  # two pads and the seat
    assert np.allclose(rounded.pair_margin[pairs], 50e-6) and np.allclose(sharp.pair_margin[pairs], 0.0)


def test_a_rounding_larger_than_the_cylinder_is_refused() -> None:
    with pytest.raises(ConfigError, match="rounding"):
        build_trial_spec(dataclasses.replace(SHARP, rounding=(1e-3, 0.0)), HOLE, JOURNAL)


def test_a_rounding_that_is_not_two_radii_is_refused() -> None:
    with pytest.raises(ConfigError, match="two edge radii"):
        TrialSceneConfig(rounding=(1e-6,))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="two edge radii"):
        TrialSceneConfig(rounding=(-1e-6, 0.0))


def test_the_tips_chamfer_is_tangent_to_the_journals_round() -> None:
    """Section (radial, z): the round's centre (r - rho, z_edge + rho); the chamfer's 45 deg face
    lies 1 % of rho outside the round's tangent line and its ring at the tangent height, inside
    the journal's radius; at rho = 0 the ring is flush on the cylinder's edge."""
    r, cfg = JOURNAL / 2, ConductorConfig()
    rho, z_edge = cfg.edge_radius, -cfg.journal_length + cfg.tip_chamfer
    assert rho == 10e-6
    model = build_trial_spec(CELL, HOLE, JOURNAL).compile()
    local = mesh_vertices(model, model.geom(f"{names.conductor(PART)}tip").id)
    radial, z = np.hypot(local[:, 0], local[:, 1]), local[:, 2]
    top = z > z.mean()
    r_top, r_bottom, z_top, z_bottom = tip_frustum(r, cfg)
    assert np.allclose(radial[top], r_top, atol=1e-10) and np.allclose(radial[~top], r_bottom, atol=1e-10)
    assert z[top].max() - z[~top].min() == pytest.approx(z_top - z_bottom, abs=1e-10)
    # the face's distance from the round's centre along the face's outward normal (1, -1)/sqrt 2
    centre = np.array([r - rho, z_edge + rho])
    for point in ((r_top, z_top), (r_bottom, z_bottom)):
        assert (np.array(point) - centre) @ np.array([1, -1]) / np.sqrt(2) == pytest.approx(1.01 * rho, abs=1e-12)
    assert r_top < r and z_top == pytest.approx(z_edge + (1 - np.sqrt(0.5)) * rho)
    assert tip_frustum(r, ConductorConfig(edge_radius=0.0))[::2] == (r, z_edge)
    with pytest.raises(ConfigError, match="edge_radius"):
        ConductorConfig(edge_radius=-1e-6)


def test_the_journals_round_keeps_the_parts_mass() -> None:
    cell = build_trial_spec(CELL, HOLE, JOURNAL).compile()
    (m0, c0, i0) = _part_inertial(build_trial_spec(SHARP, HOLE, JOURNAL).compile())
    (m1, c1, i1) = _part_inertial(cell)
    assert m1 == pytest.approx(m0, rel=1e-12)
    np.testing.assert_allclose(c1, c0, atol=1e-8)  # the round's and chamfer's shapes: 2 nm
    np.testing.assert_allclose(i1, i0, rtol=1e-4)
    journal = cell.geom(f"{names.conductor(PART)}journal")
    assert journal.margin[0] == pytest.approx(10e-6) and journal.size[0] == pytest.approx(JOURNAL / 2 - 10e-6)


def test_the_gpus_shared_tip_is_moved_onto_each_worlds_chamfer() -> None:
    """MuJoCo Warp's worlds share the thinnest journal's tip mesh; moved along the axis by the
    radius change (tasks/warp_batch.py), its 45 deg face lies on the world's own chamfer face."""
    from serpar.tasks.warp_batch import _mesh_geom_poses
    shared = build_trial_spec(CELL_GPU, HOLE, JOURNAL_H6.min).compile()
    own = build_trial_spec(CELL_GPU, HOLE, JOURNAL_H6.max).compile()
    tip = own.geom(f"{names.conductor(PART)}tip").id
    moved = _with_geom_pos(shared, _mesh_geom_poses(shared, own)["geom_pos"])

    def face_line(model: mujoco.MjModel) -> np.ndarray:  # radial - z: one constant on a 45 deg cone
        v = mesh_vertices(model, tip)
        return np.hypot(v[:, 0], v[:, 1]) - v[:, 2]

    want = face_line(own).max()
    for model in (own, moved):
        assert np.allclose(face_line(model), want, atol=2e-9)  # the polygon's vertices lie on the cone
    assert shared.geom_pos[tip, 2] - moved.geom_pos[tip, 2] == pytest.approx((JOURNAL_H6.max - JOURNAL_H6.min) / 2, abs=1e-10)


def _with_geom_pos(model: mujoco.MjModel, geom_pos: np.ndarray) -> mujoco.MjModel:
    out = copy.copy(model)
    out.geom_pos[:] = geom_pos
    return out
