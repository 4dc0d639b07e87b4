"""The candidate library of the Stewart family and its rank test.

Each candidate extends the nominal leg lengths or joint table (names match
``serpar.twins.stewart_twin.EFFECTS``):

- ``stewart_geometry``: seed 000's 42 kinematic parameters, per leg dl, dP xyz (platform
  frame), dB xyz (base frame), restricted to those this pose set can tell apart;
- ``leg_thermal_drift``: every leg grows by the factor 1 + kappa t (t since the recording
  started), one parameter;
- ``leg_compliance``: leg i shortens by c_i times its static axial force (weight of platform,
  payload and legs at the measured pose; sim/stewart_statics.py);
- ``leg_encoder_offset``: leg i is shorter than its encoder says by o_i;
- ``leg_encoder_scale``: leg i's encoder reads its stroke (from the encoder zero, l_min) times
  1 + s_i (a screw-lead or resolution error): the leg is shorter than it says by s_i x stroke;
- ``leg_thermal_nonuniform``: leg i grows by the factor 1 + g_i (1 - exp(-r t)), one rate r
  for all (a leg's motor warming its own cylinder to a new steady state; r -> 0 is linear).

Rank test as in arm_static_effects.py: a parameter is kept only if its column of the whitened
Jacobian at the nominal model stands clear (QR, RANK_TOL) of the columns kept before it. The
geometric order of preference is dl, then dB, then dP: a leg-length error is the simplest
reading of what it explains, a base-joint error the next (the platform joints move with it).
Bounds admit either sign: an absent effect's estimate then scatters about zero.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_static_effects import independent_columns
from serpar.diagnosis.family import Effect

if TYPE_CHECKING:
    from serpar.diagnosis.stewart_family import StewartFamily

GEOMETRY, THERMAL, COMPLIANCE, ENCODER = ("stewart_geometry", "leg_thermal_drift",
                                          "leg_compliance", "leg_encoder_offset")
SCALE, WARMING = "leg_encoder_scale", "leg_thermal_nonuniform"
COLUMNS = ("dl", "dPx", "dPy", "dPz", "dBx", "dBy", "dBz")
"""Per-leg order of calibration/stewart_params.py (and of StewartConfig.joint_errors)."""
PREFERENCE = (0, 4, 5, 6, 1, 2, 3)
"""Columns in the order the rank test prefers them: dl, dB xyz, dP xyz."""
GEOMETRY_BOUND_M = 5e-3
"""Half of serpar.sim.stewart.MAX_JOINT_ERROR: dl and an encoder offset add up within it."""
ENCODER_BOUND_M = 5e-3
COMPLIANCE_BOUND = 1e-5
"""[m/N] 0.1 N/um: far softer than any leg that holds a platform."""
THERMAL_BOUND = 1e-3
"""Largest relative growth over the recording (87 K of steel)."""
SCALE_BOUND = 0.02
"""Largest relative encoder scale error: a wrong screw lead or resolution setting."""
WARMING_RATES = (1 / 3, 60.0)
"""Rates of the per-leg warming, in units of 1 / (the campaign's length): from a time constant
three times the campaign (near linear) to a fiftieth of it."""
WARMING_PROBE = 1e-4
"""Per-leg growth at which the rank test looks at the rate's column (zero at g = 0)."""
N_LEGS = 6


def geometry_name(flat: int) -> str:
    leg, col = divmod(flat, len(COLUMNS))
    name = COLUMNS[col]
    return f"{name[:2]}{leg + 1}{name[2:]}" if len(name) > 2 else f"{name}{leg + 1}"


def full_effects(duration_s: float) -> list[Effect]:
    """Every candidate with all its parameters (geometry in the preferred order)."""
    order = [leg * len(COLUMNS) + c for c in PREFERENCE for leg in range(N_LEGS)]
    legs = range(1, N_LEGS + 1)
    out = [Effect(GEOMETRY, "Stewart joint positions and leg lengths (kinematic parameters)",
                  tuple(geometry_name(i) for i in order), ("m",) * len(order),
                  np.zeros(len(order)), np.full(len(order), -GEOMETRY_BOUND_M),
                  np.full(len(order), GEOMETRY_BOUND_M))]
    if duration_s > 0:
        k = THERMAL_BOUND / duration_s
        out.append(Effect(THERMAL, "thermal growth of the legs over time", ("kappa",), ("1/s",),
                          np.zeros(1), np.full(1, -k), np.full(1, k)))
    out.append(Effect(COMPLIANCE, "axial leg compliance under the platform's load",
                      tuple(f"c{i}" for i in legs), ("m/N",) * N_LEGS, np.zeros(N_LEGS),
                      np.zeros(N_LEGS), np.full(N_LEGS, COMPLIANCE_BOUND), physical_lower=True))
    out.append(Effect(ENCODER, "leg encoder zero offsets", tuple(f"o{i}" for i in legs),
                      ("m",) * N_LEGS, np.zeros(N_LEGS), np.full(N_LEGS, -ENCODER_BOUND_M),
                      np.full(N_LEGS, ENCODER_BOUND_M)))
    out.append(Effect(SCALE, "leg encoder scale errors (reading proportional to the stroke)",
                      tuple(f"s{i}" for i in legs), ("1",) * N_LEGS, np.zeros(N_LEGS),
                      np.full(N_LEGS, -SCALE_BOUND), np.full(N_LEGS, SCALE_BOUND)))
    if duration_s > 0:
        lo, hi = (r / duration_s for r in WARMING_RATES)
        out.append(Effect(WARMING, "thermal growth of individual legs, levelling off over time "
                          "(each leg's own warm-up)",
                          tuple(f"g{i}" for i in legs) + ("rate",), ("1",) * N_LEGS + ("1/s",),
                          np.r_[np.zeros(N_LEGS), 3.0 / duration_s],
                          np.r_[np.full(N_LEGS, -THERMAL_BOUND), lo],
                          np.r_[np.full(N_LEGS, THERMAL_BOUND), hi]))
    return out


def geometry_flat_index(name: str) -> int:
    """Index into the flattened (6, 7) joint-error table of a geometry parameter name."""
    for flat in range(N_LEGS * len(COLUMNS)):
        if geometry_name(flat) == name:
            return flat
    raise ValueError(f"not a geometry parameter: {name!r}")


def candidate_effects(fam: StewartFamily, rows: NDArray[np.int64]) -> tuple[Effect, ...]:
    """The effects restricted to what the given rows' poses can identify (columns of the
    exact Jacobian at the nominal model)."""
    out = []
    for effect in full_effects(fam.duration_s):
        fam.register(effect)
        probe = effect.x0.copy()
        if effect.name == WARMING:  # the rate's column is zero while no leg grows
            probe[:N_LEGS] = WARMING_PROBE
        jac = fam.jacobian({effect.name: probe}, rows)
        keep = independent_columns(jac, 0)
        if keep.size:
            out.append(effect.restricted(keep))
    for e in out:
        fam.register(e)
    return tuple(out)
