"""The GPU scene's rounded part (``TrialSceneConfig.rounding``): the same contacts as the sharp
part's where a face meets a cylinder's side, the same mass, the margin on the explicit pairs;
and the tip's ring inset (``ConductorConfig.tip_inset``)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.tolerances import HOLE_H7, JOURNAL_H6
from serpar.sim.trial_scene import PART, TrialSceneConfig, build_trial_spec
from serpar.tasks.warp_batch import mesh_vertices

SHARP = TrialSceneConfig(at_origin=True, seat_plane=True)
ROUNDED = dataclasses.replace(SHARP, rounding=(1e-6, 50e-6))
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
def test_the_rounded_journal_presses_on_the_facet_as_the_sharp_one(push: float) -> None:
    sharp, rounded = _journal_contacts(SHARP, push), _journal_contacts(ROUNDED, push)
    assert sharp and {f for f, _ in sharp} == {f for f, d in rounded if np.isfinite(d)}
    assert min(d for _, d in sharp) == pytest.approx(-push, abs=2e-9)
    assert min(d for _, d in rounded) == pytest.approx(-push, abs=2e-9)


def test_rounding_keeps_the_parts_mass_and_sets_the_pairs_margin() -> None:
    sharp = build_trial_spec(SHARP, HOLE, JOURNAL).compile()
    rounded = build_trial_spec(ROUNDED, HOLE, JOURNAL).compile()
    body = names.conductor_body(PART)
    assert rounded.body(body).mass[0] == pytest.approx(sharp.body(body).mass[0], rel=1e-12)
    np.testing.assert_allclose(rounded.body(body).inertia, sharp.body(body).inertia, rtol=1e-12)
    np.testing.assert_allclose(rounded.body(body).ipos, sharp.body(body).ipos, rtol=1e-12, atol=1e-15)
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


def test_the_tip_inset_puts_the_tips_ring_inside_the_journal() -> None:
    from serpar.sim.conductor import ConductorConfig
    for inset in (0.0, 1e-7):
        cfg = dataclasses.replace(SHARP, conductor=ConductorConfig(tip_inset=inset))
        model = build_trial_spec(cfg, HOLE, JOURNAL).compile()
        local = mesh_vertices(model, model.geom(f"{names.conductor(PART)}tip").id)
        assert np.hypot(local[:, 0], local[:, 1]).max() == pytest.approx(JOURNAL / 2 - inset, abs=1e-10)
    with pytest.raises(ConfigError, match="tip_inset"):
        ConductorConfig(tip_inset=-1e-7)
