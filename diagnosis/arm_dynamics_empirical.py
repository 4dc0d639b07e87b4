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
- a drift in time: linear, or saturating 1 - exp(-t / tau).

Only the joint's own variables enter its channels: a torque acting in one joint's drive
(ripple, friction) shows in that joint's channel; the nominal model already carries how the
others move.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.empirical import BasisGroup

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


def _group(channel: str, variable: str, shape: str, label: str, column: int, windowed: Vec,
           sigma: Vec, detail: dict[str, float] | None = None) -> BasisGroup:
    """A channel-local group from its windowed basis at every row (rows, k)."""
    white = windowed / sigma[:, None]
    return BasisGroup(channel, variable, shape, label, "N m",
                      columns=lambda rows: white[rows], physical=lambda rows: windowed[rows],
                      column=column, detail=detail or {})


def arm_library(t: Terms, channels: tuple[str, ...], blocks: tuple[str, ...]) -> list[BasisGroup]:
    """Every group of the arm's library over the family's ``channels`` (``blocks``: ``link``
    and/or ``drive``, n channels each, in that order)."""
    out: list[BasisGroup] = []
    q, v = t.q_full, t.dq_full
    time = np.arange(len(q)) / t.rate
    span = max(time[-1], 1e-9)
    drifts = [("linear", time / span)] + [
        (f"1 - exp(-t / {tau * span:.0f} s)", 1.0 - np.exp(-time / (tau * span))) for tau in DRIFT_TAUS]
    n = t.n
    kinds = {"link": (t.rows.link_at, t.sigma_link), "drive": (t.rows.at, t.sigma_drive)}
    for j in range(n):
        for b, block in enumerate(blocks):
            column, name = b * n + j, channels[b * n + j]
            window, sigma = kinds[block]
            s = sigma[:, j]
            qj, vj = f"q{j + 1}", f"dq{j + 1}"
            for k in CYCLES_PER_TURN:
                phase = k * q[:, j]
                out.append(_group(name, qj, "periodic",
                                  f"sin, cos(2 pi {qj} / {360 / k:.4g} deg)", column,
                                  window(np.column_stack([np.sin(phase), np.cos(phase)])), s,
                                  {"period_deg": 360.0 / k}))
            out.append(_group(name, vj, "reversal step", f"tanh({vj} / {REVERSAL_SPEED} rad/s)",
                              column, window(np.tanh(v[:, j] / REVERSAL_SPEED)[:, None]), s,
                              {"speed": REVERSAL_SPEED}))
            for vt in TRANSITION_SPEEDS:
                step = np.tanh(v[:, j] / vt)
                out.append(_group(name, vj, "smooth step",
                                  f"tanh({vj} / {vt} rad/s), tanh^2({vj} / {vt} rad/s)", column,
                                  window(np.column_stack([step, step**2])), s, {"speed": vt}))
            for vs in STRIBECK_SPEEDS:
                bump = np.sign(v[:, j]) * np.exp(-((v[:, j] / vs) ** 2))
                out.append(_group(name, vj, "stribeck", f"sign({vj}) exp(-({vj} / {vs} rad/s)^2)",
                                  column, window(bump[:, None]), s, {"speed": vs}))
            for label, profile in drifts:
                out.append(_group(name, "time", "drift", label, column, window(profile[:, None]), s))
    return out
