"""What the arm-dynamics family is built from, besides the signals: the tare's noise and knots,
the check that the torques are this arm's in N m, the joints whose encoder errors the dynamics
can see, and the coupled drives the recording declares."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_library import Coupling, visible_joints
from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.family import Effect
from serpar.errors import IdentificationError
from serpar.sim.recording import Recording
from serpar.sim.rigid_arm import ArmDynamics

Vec = NDArray[np.float64]

PIN_SHARE = 0.5
"""A drifting tare's knot is kept only with a training row within this share of the spacing:
a knot that only distant rows pin is fixed by leverage, and noise swings it."""
SCALE_RANGE = (0.5, 2.0)
"""Accepted regression slope of a joint's measured on its nominal torque: a payload or a gain
error moves it by tens of per cent; N mm for N m, or another robot, by far more."""
SCALE_MIN_RMS = 1.0
"""[N m] Joints whose nominal torque varies less than this are not tested for scale."""
SCALE_SLACK = 0.1
"""Torque the physics a diagnosis looks for may add to a joint (a payload, friction), as a
share of the most varying joint's nominal variation: the range widens by it over the joint's
own variation. On a wrist that carries little of the model's torque a real payload moves the
slope far past the range (the iiwa's joint 6 under a 1.1-kg payload: 3.4, range 0.5-5.8);
a channel in N mm or motor-side is off by 50-1000 times, on any joint."""
PROBE_ROWS = 200
"""Rows at which the encoder errors' visibility is probed (evenly spread)."""
TOP_SHARE = 0.25
"""A row is in a joint's "high gravity load" / "high acceleration" regime when it is in the
top quarter of that joint's |g| / |q̈| over the recording."""
TIME_BINS = 3


def stated_tare_walk(rec: Recording) -> float:
    """The torque sensors' bias random walk [N m/sqrt(s)] the recording states as part of its
    noise model (``model.arm_sensors.torque_bias_walk``, as `serpar run --record` writes it),
    0 when it states none."""
    sensors = rec.meta.model.get("arm_sensors")
    walk = sensors.get("torque_bias_walk", 0.0) if isinstance(sensors, dict) else 0.0
    return float(walk) if isinstance(walk, (int, float)) and np.isfinite(walk) and walk > 0 else 0.0


def bridge_variance(time: Vec, knots: Vec, walk: float) -> Vec:
    """Per row, the variance of a random-walk tare (intensity `walk`) about the piecewise-linear
    tare through `knots`: a Brownian bridge between two knots, w^2 (t - a)(b - t)/(b - a), and
    a free walk beyond the end knots, where the tare is held constant. It belongs to the
    stated noise: a held-out row's tare is interpolated across a block no training row pins."""
    if len(knots) == 0:
        return np.full(len(time), walk**2 * (time[-1] - time[0]))
    i = np.clip(np.searchsorted(knots, time), 1, max(len(knots) - 1, 1))
    a, b = knots[i - 1], knots[np.minimum(i, len(knots) - 1)]
    inside = (time >= knots[0]) & (time <= knots[-1]) & (b > a)
    var = np.where(inside, (time - a) * (b - time) / np.where(b > a, b - a, 1.0), 0.0)
    var = np.where(time < knots[0], knots[0] - time, var)
    var = np.where(time > knots[-1], time - knots[-1], var)
    return walk**2 * var


def drifting_tare(time: Vec, pinned_by: Vec, spacing_s: float, base: Effect
                  ) -> tuple[Vec, Effect]:
    """Knot times (every ``spacing_s`` from the first row, each with a ``pinned_by`` time
    within one spacing) and the baseline Effect of a piecewise-linear tare per sensor
    (constant beyond the end knots); ``base``: the constant tare it replaces."""
    grid = time[0] + spacing_s * np.arange(int(np.ceil((time[-1] - time[0]) / spacing_s)) + 1)
    near = np.abs(grid[:, None] - pinned_by[None, :]).min(axis=1) < PIN_SHARE * spacing_s
    knots = grid[near]
    names = tuple(f"{p}@{t - time[0]:.0f}s" for t in knots for p in base.param_names)
    k = len(names)
    return knots, Effect(base.name, "torque sensor offsets (tares), drifting in time", names,
                         ("N m",) * k, np.zeros(k), np.full(k, -20.0), np.full(k, 20.0))


def check_scale(terms: Terms, arm_name: str, drive_name: str) -> None:
    """IdentificationError when a torque channel does not scale like the nominal model: units
    other than N m, motor-side torques, or a recording of another robot."""
    channels = []
    if terms.has_link:
        channels.append(("tau_J", terms.link + terms.tau_link_model, terms.tau_link_model))
    if terms.has_command:
        channels.append((drive_name, terms.drive + terms.tau_full_model, terms.tau_full_model))
    for name, measured, model in channels:
        x = model - model.mean(axis=0)
        y = measured - measured.mean(axis=0)
        rms = np.sqrt(np.mean(x**2, axis=0))
        for j in np.flatnonzero(rms > SCALE_MIN_RMS):
            slope = float(x[:, j] @ y[:, j] / (x[:, j] @ x[:, j]))
            slack = SCALE_SLACK * float(rms.max()) / float(rms[j])
            if not SCALE_RANGE[0] - slack <= slope <= SCALE_RANGE[1] + slack:
                raise IdentificationError(
                    f"{name}{j + 1} varies {slope:.3g} times as much as the nominal model of "
                    f"{arm_name} predicts from q: not in N m, motor-side (give the gear ratios "
                    "in serpar import --spec's joint_map), or a recording of another robot")


def encoder_visibility(terms: Terms, dynamics: ArmDynamics) -> tuple[tuple[int, ...],
                                                                      tuple[int, ...]]:
    """(offset joints, scale joints): the joints whose encoder offset moves the gravity load,
    and whose encoder scale (angle, rate and acceleration together) moves the torques, by at
    least ``VISIBLE_SHARE`` of the most sensitive joint's at the recording's states."""
    idx = np.unique(np.linspace(0, len(terms.q) - 1, min(PROBE_ROWS, len(terms.q))).astype(int))
    q, dq, ddq = terms.q[idx], terms.dq[idx], terms.ddq[idx]
    g0, tau0 = dynamics.gravity(q), dynamics.link_torque(q, dq, ddq)
    step, rel = 1e-3, 1e-2
    offset, scale = np.zeros(terms.n), np.zeros(terms.n)
    for j in range(terms.n):
        shifted = q.copy()
        shifted[:, j] += step
        offset[j] = np.abs(dynamics.gravity(shifted) - g0).max() / step
        q2, v2, a2 = q.copy(), dq.copy(), ddq.copy()
        for x in (q2, v2, a2):
            x[:, j] *= 1.0 + rel
        scale[j] = np.abs(dynamics.link_torque(q2, v2, a2) - tau0).max() / rel
    return visible_joints(offset), visible_joints(scale)


def declared_couplings(rec: Recording, n: int) -> tuple[Coupling, ...]:
    """Coupled drives the recording declares: the torque map of its import (``serpar import
    --spec``'s ``joint_map``, meta.model["import"]["spec"]) with an off-diagonal entry T[a, m] (motor m
    also drives joint a), or an explicit ``meta.model["couplings"]`` list of [joint, motor]
    pairs (1-based; a twin's)."""
    model = rec.meta.model if isinstance(rec.meta.model, dict) else {}
    pairs: list[tuple[int, int]] = []
    explicit = model.get("couplings")
    if isinstance(explicit, list):
        pairs += [(int(a), int(m)) for a, m in explicit]
    imported = model.get("import")
    spec = imported.get("spec") if isinstance(imported, dict) else None
    jm = spec.get("joint_map") if isinstance(spec, dict) else None
    torque = jm.get("torque_matrix") if isinstance(jm, dict) else None
    if torque is not None:
        t = np.asarray(torque, float)
        if t.shape == (n, n):
            pairs += [(int(a) + 1, int(m) + 1) for a, m in zip(*np.nonzero(t), strict=True)
                      if a != m]
    bad = [p for p in pairs if not (1 <= p[0] <= n and 1 <= p[1] <= n and p[0] != p[1])]
    if bad:
        raise IdentificationError(f"coupled drives {bad} name joints outside 1..{n}")
    return tuple(Coupling(a, m) for a, m in dict.fromkeys(pairs))


def regime_masks(terms: Terms, phases: tuple[tuple[str, float, float], ...]
                 ) -> dict[tuple[str, str], NDArray[np.bool_]]:
    """The "where" table's regimes: boolean masks over rows (rows, or rows x joints for
    per-joint regimes)."""
    t = terms
    v = t.dq_full
    idx = t.rows.centre[:, None] + np.arange(-t.rows.half, t.rows.half + 1)[None, :]
    window = v[idx]  # rows x window x joints
    reversal = np.any(window > 0, axis=1) & np.any(window < 0, axis=1)

    def top(x: Vec) -> NDArray[np.bool_]:
        mag = np.abs(x)
        # a joint whose |x| never rises above round-off (gravity on joint 1) has no regime
        return (mag >= np.quantile(mag, 1.0 - TOP_SHARE, axis=0)) & (mag > 1e-6)

    masks = {("regime", "velocity reversal"): reversal,
             ("regime", "high gravity load"): top(t.gravity),
             ("regime", "high acceleration"): top(t.ddq)}
    span = t.time[-1] - t.time[0]
    edges = t.time[0] + span * np.arange(TIME_BINS + 1) / TIME_BINS
    for a, b in pairwise(edges):
        masks[("elapsed time", f"{a:.0f}-{b:.0f} s")] = (t.time >= a) & (t.time <= b)
    if len({p[0] for p in phases}) > 1:
        for name, a, b in phases:
            key = ("phase", name)
            inside = (t.time >= a) & (t.time <= b)
            masks[key] = masks.get(key, np.zeros_like(inside)) | inside
    return masks
