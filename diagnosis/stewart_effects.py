"""The candidate library of the Stewart family and its rank test.

Each candidate extends the nominal leg lengths or joint table (names match
``serpar.twins.stewart_twin.EFFECTS``):

- ``stewart_geometry``: seed 000's 42 kinematic parameters, per leg dl, dP xyz (platform
  frame), dB xyz (base frame), restricted to those this pose set can tell apart;
- ``leg_thermal_drift``: every leg grows by the factor 1 + kappa t (t since the recording
  started), one parameter;
- ``leg_compliance``: leg i shortens by c_i times its static axial force (weight of platform,
  payload and legs at the measured pose; sim/stewart_statics.py);
- ``leg_encoder_offset``: leg i is shorter than its encoder says by o_i.

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
        jac = fam.jacobian({effect.name: effect.x0}, rows)
        keep = independent_columns(jac, 0)
        if keep.size:
            out.append(effect.restricted(keep))
    for e in out:
        fam.register(e)
    return tuple(out)
