"""The empirical basis library of an arm time series (diagnosis/empirical.py): per joint and
torque channel, shapes in that joint's own angle and velocity and in time, evaluated at full
rate and windowed exactly like the channel they act on.

- periodic in q_j: sin and cos of 2 pi q_j / P, P = 360 deg / k for k = 1, 1.5, ... 40 (half a
  cycle per turn apart: over the ~1 rad a joint sweeps, the nearest grid period slips less
  than 0.05 of a cycle from any true one);
- a step at reversals of q_j: tanh(dq_j / v_t), a sharp one (v_t 0.01 rad/s: dry friction)
  and smooth ones with the joint's own transition speed v_t in TRANSITION_SPEEDS (a
  friction that passes through zero at rest over 1 / phi2, the published sigmoid's);
- a fall from standstill: sign(dq_j) exp(-(dq_j / v_s)^2) for v_s in STRIBECK_SPEEDS;
- a drift in time: linear, or saturating 1 - exp(-t / tau);
- a misread angle (:func:`misread_library`): one joint's reading off in proportion to its
  angle from the encoder zero, carried through the nominal model to every channel.

A selected group's speed or time constant is then refined between the grid's neighbours
(:func:`serpar.diagnosis.empirical.tune`), within bounds the physics sets.

Only the joint's own variables enter its channels: a torque acting in one joint's drive
(ripple, friction) shows in that joint's channel; the nominal model already carries how the
others move. A misread angle is the exception, since the model itself moves every joint's
gravity and inertia with it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_library import STICK_VELOCITY
from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.empirical import BasisGroup, RestBand, Tuning

if TYPE_CHECKING:
    from serpar.diagnosis.arm_dynamics_effects import EffectModels

Vec = NDArray[np.float64]

CYCLES_PER_TURN = np.arange(1.0, 40.01, 0.5)
STRIBECK_SPEEDS = (0.02, 0.05, 0.1, 0.2)
"""[rad/s] Stribeck velocities tried (published Panda fits: 0.01-0.1 rad/s)."""
REVERSAL_SPEED = 0.01
"""[rad/s] Width of the sharp step at reversal (the diagnosis' stick velocity)."""
TRANSITION_SPEEDS = (0.03, 0.1, 0.2, 0.4)
"""[rad/s] Widths of the smooth steps (Gaz et al.'s Panda sigmoid, as a tanh: 2 / phi2 = 0.12-0.4 rad/s)."""
DRIFT_TAUS = (1 / 6, 1 / 3)
"""Time constants of the saturating drifts, as shares of the recording's length."""


SMOOTH_STEP_BOUNDS = (REVERSAL_SPEED, 1.0)
"""[rad/s] A smooth step's width refined within these: below, the sharp step at reversal;
above, a viscous slope over the speeds an arm moves at."""
STRIBECK_BOUNDS = (0.005, 0.5)
"""[rad/s] Stribeck velocities refined within these (lubricated contacts: 0.001-0.1 m/s at
the contact, a few mrad/s to tenths of a rad/s at the joint)."""
DRIFT_BOUNDS = (1 / 50, 2.0)
"""Time constants of a saturating drift refined within these, as shares of the recording:
faster is a step at the start, slower is a linear drift."""


def _group(channel: str, variable: str, shape: str, label: str, column: int, windowed: Vec,
           sigma: Vec, detail: dict[str, float] | None = None,
           tuning: Tuning | None = None, stuck: Vec | None = None,
           onset: tuple[float, ...] = ()) -> BasisGroup:
    """A channel-local group from its windowed basis at every row (rows, k); a friction's
    ``stuck`` (the windowed share of samples where the joint may be stuck) and ``onset`` (its
    columns' odd part at the stick velocity) make its band at rest."""
    white = windowed / sigma[:, None]
    rest = None
    if stuck is not None:
        band = stuck / sigma
        rest = RestBand(lambda rows: band[rows], onset)
    return BasisGroup(channel, variable, shape, label, "N m",
                      columns=lambda rows: white[rows], physical=lambda rows: windowed[rows],
                      column=column, detail=detail or {}, tuning=tuning, rest=rest)


def _tuned(name: str, low: float, high: float, make: Callable[[float], BasisGroup],
           value: float) -> BasisGroup:
    """``make(value)`` carrying a :class:`Tuning` that makes it at any other value."""
    def at(x: float) -> BasisGroup:
        g = make(x)
        return BasisGroup(g.channel, g.variable, g.shape, g.label, g.unit, g.columns,
                          g.physical, g.column, g.detail, Tuning(name, low, high, at), g.rest)
    return at(value)


def arm_library(t: Terms, channels: tuple[str, ...], blocks: tuple[str, ...],
                stick_velocity: float = STICK_VELOCITY) -> list[BasisGroup]:
    """Every group of the arm's library over the family's ``channels`` (``blocks``: ``link``
    and/or ``drive``, n channels each, in that order). Below ``stick_velocity`` a joint may be
    stuck: a dry step or a Stribeck fall has no sign there, and holds the joint within its
    level (the candidates' stiction band)."""
    out: list[BasisGroup] = []
    q, v = t.q_full, t.dq_full
    time = np.arange(len(q)) / t.rate
    span = max(time[-1], 1e-9)
    n = t.n
    kinds = {"link": (t.rows.link_at, t.sigma_link), "drive": (t.rows.at, t.sigma_drive)}
    for j in range(n):
        for b, block in enumerate(blocks):
            column, name = b * n + j, channels[b * n + j]
            window, sigma = kinds[block]
            s = sigma[:, j]
            qj, vj, vel = f"q{j + 1}", f"dq{j + 1}", v[:, j]
            moving = np.abs(vel) >= stick_velocity
            signed = np.sign(vel) * moving
            stuck = window((~moving).astype(float)[:, None])[:, 0]
            for k in CYCLES_PER_TURN:
                phase = k * q[:, j]
                out.append(_group(name, qj, "periodic",
                                  f"sin, cos(2 pi {qj} / {360 / k:.4g} deg)", column,
                                  window(np.column_stack([np.sin(phase), np.cos(phase)])), s,
                                  {"period_deg": 360.0 / k}))
            out.append(_group(name, vj, "reversal step", f"tanh({vj} / {REVERSAL_SPEED} rad/s)",
                              column, window((np.tanh(vel / REVERSAL_SPEED) * moving)[:, None]), s,
                              {"speed": REVERSAL_SPEED}, stuck=stuck,
                              onset=(float(np.tanh(stick_velocity / REVERSAL_SPEED)),)))

            def smooth(vt: float, name: str = name, vj: str = vj, vel: Vec = vel,
                       column: int = column, window: Callable[[Vec], Vec] = window,
                       s: Vec = s, stuck: Vec = stuck) -> BasisGroup:
                step = np.tanh(vel / vt)
                return _group(name, vj, "smooth step",
                              f"tanh({vj} / {vt:.3g} rad/s), tanh^2({vj} / {vt:.3g} rad/s)",
                              column, window(np.column_stack([step, step**2])), s, {"speed": vt},
                              stuck=stuck, onset=(float(np.tanh(stick_velocity / vt)), 0.0))

            def fall(vs: float, name: str = name, vj: str = vj, vel: Vec = vel,
                     column: int = column, window: Callable[[Vec], Vec] = window,
                     s: Vec = s, signed: Vec = signed, stuck: Vec = stuck) -> BasisGroup:
                bump = signed * np.exp(-((vel / vs) ** 2))
                return _group(name, vj, "stribeck", f"sign({vj}) exp(-({vj} / {vs:.3g} rad/s)^2)",
                              column, window(bump[:, None]), s, {"speed": vs}, stuck=stuck,
                              onset=(float(np.exp(-((stick_velocity / vs) ** 2))),))

            def drift(tau: float, name: str = name, column: int = column,
                      window: Callable[[Vec], Vec] = window, s: Vec = s) -> BasisGroup:
                profile = 1.0 - np.exp(-time / tau)
                return _group(name, "time", "drift", f"1 - exp(-t / {tau:.4g} s)", column,
                              window(profile[:, None]), s, {"tau_s": tau})

            out += [_tuned("speed", *SMOOTH_STEP_BOUNDS, smooth, vt) for vt in TRANSITION_SPEEDS]
            out += [_tuned("speed", *STRIBECK_BOUNDS, fall, vs) for vs in STRIBECK_SPEEDS]
            out.append(_group(name, "time", "drift", "linear", column,
                              window((time / span)[:, None]), s))
            out += [_tuned("tau_s", DRIFT_BOUNDS[0] * span, DRIFT_BOUNDS[1] * span, drift,
                           tau * span) for tau in DRIFT_TAUS]
    return out


def misread_library(models: EffectModels, t: Terms, blocks: tuple[str, ...]) -> list[BasisGroup]:
    """Per joint j: its reading off by s x q_j (an encoder scale, a gear or belt ratio wrong
    between reading and link), one coefficient s. The model computes every joint's torque at
    the read angles, rates and accelerations, so the group spans all channels: its column is
    the model's change per unit s, whitened, in the family's row-major (row, channel) order.
    The encoder-offset candidate carries a constant misreading: the group is screened by what
    it adds beside one (``beside``), as the model refitted with it moves that back."""
    sigma = {"link": t.sigma_link, "drive": t.sigma_drive}

    def whitened(j: int, proportional: bool) -> Vec:
        x = np.stack([models.misread_sensitivity(j, block == "link", proportional) / sigma[block]
                      for block in blocks], axis=1)  # rows x blocks x n
        return x.reshape(len(x), -1)

    out: list[BasisGroup] = []
    for j in range(t.n):
        scale = whitened(j, True)
        if not np.any(scale):
            continue  # a reading the model's torque does not depend on
        offset = whitened(j, False)
        angle = t.q[:, j]
        out.append(BasisGroup(
            f"q{j + 1}", f"q{j + 1}", "proportional", f"q{j + 1} x (1 + s)", "rad",
            columns=lambda rows, w=scale: w[np.asarray(rows, np.int64)].reshape(-1, 1),
            physical=lambda rows, a=angle: a[np.asarray(rows, np.int64), None],
            beside=lambda rows, w=offset: w[np.asarray(rows, np.int64)].reshape(-1, 1)))
    return out
