"""Does the residual of each channel an effect changes show that change, and no other channel?

Two tests on the held-out rows, where a family's residual has parallel channels (its
``channels``, e.g. each joint's sensor and drive torque):

- **Matching**: in at least ``MIN_CHANNEL_SHARE`` of the channels the effect changes materially
  (by ``MATERIAL_CORRECTION`` sigma RMS or more), the channel's own best scale of the change
  (least squares of the residual without it on its change) lies within ``MATCH_RANGE``: 1 up to
  noise for an effect the data hold. A latency that stands in for friction near standstill
  moves every joint's command by a few sigma; some joints want a third of that delay, others
  twice or three times it.
- **Mirrored**: a family whose channels come in siblings (``sibling_channels``: one joint's
  torque seen by its link-side sensor and by its drive) lets an effect that acts on one of them
  alone (a sensor's gain, the drive's friction) be told from a cause that acts on the joint's
  torque itself: where the sibling's residual, which the effect cannot touch, holds
  ``MIRROR_SHARE`` or more of the same change (in N m, least squares), the effect absorbs in
  its own channel what the joint's torque does in both. A joint encoder's scale error moves
  the predicted torque of sensor and drive alike; a torque-sensor gain fitted to it removes
  the sensor's half and leaves the drive's.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.family import Family

Rows = NDArray[np.int64]

MIN_CHANNEL_SHARE = 0.8
MATCH_RANGE = (0.75, 2.0)
MATERIAL_CORRECTION = 1.0
"""[sigma, RMS over the held-out rows] A channel the effect changes by less is not judged."""
MIRROR_SHARE = 0.5
"""A sibling channel that holds this share of the change (its own least-squares scale) shows
it; one the effect truly acts on alone holds 0 up to noise."""


@dataclass(frozen=True)
class ChannelCheck:
    """Per residual channel on the held-out rows: where the effect acts materially, in which
    of those the residual shows what it changes, and which of them it changes alone while the
    sibling channel's residual shows the same change (``mirrored``: channel, sibling, scale)."""

    material: tuple[str, ...]
    matching: tuple[str, ...]
    mirrored: tuple[tuple[str, str, float], ...] = ()

    @property
    def share(self) -> float:
        return len(self.matching) / len(self.material) if self.material else 1.0

    def reasons(self) -> list[str]:
        """Why these channels say the effect is not what the data show (empty: they agree)."""
        why = []
        if self.share < MIN_CHANNEL_SHARE:
            off = [c for c in self.material if c not in self.matching]
            why.append(f"of the {len(self.material)} channels it changes, the residual shows "
                       f"that change in {len(self.matching)} only (not in {', '.join(off[:4])}"
                       f"{' ...' if len(off) > 4 else ''}, whose residual holds under "
                       f"{MATCH_RANGE[0]:g}x or over {MATCH_RANGE[1]:g}x of it): it stands in "
                       f"for something else")
        if self.mirrored:
            shown = ", ".join(f"{s} holds {k:.2g}x of what it changes in {c}"
                              for c, s, k in self.mirrored[:3])
            more = f" and {len(self.mirrored) - 3} more" if len(self.mirrored) > 3 else ""
            why.append(f"it cannot act on a channel whose residual shows the same change ({shown}"
                       f"{more}): the joint's torque itself differs, in both channels; it "
                       f"stands in for something else")
        return why


def channel_check(family: Family, params: Mapping[str, NDArray[np.float64]], name: str,
                  heldout: Rows) -> ChannelCheck | None:
    """None when the family's residual has no parallel channels."""
    channels = getattr(family, "channels", None)
    if not channels:
        return None
    n = len(channels)
    with_it = family.residual(params, heldout)
    without = family.residual({k: v for k, v in params.items() if k != name}, heldout)
    if with_it.size != n * len(heldout):
        return None
    a, b = with_it.reshape(-1, n), without.reshape(-1, n)
    change = b - a  # what the effect removes from each channel's residual
    power = np.mean(change**2, axis=0)
    scale = np.mean(b * change, axis=0) / np.maximum(power, 1e-300)  # the channel's own fit
    material = np.flatnonzero(power >= MATERIAL_CORRECTION**2)
    lo, hi = MATCH_RANGE
    return ChannelCheck(tuple(channels[i] for i in material),
                        tuple(channels[i] for i in material if lo <= scale[i] <= hi),
                        _mirrored(family, b, change, power, material, heldout))


def _mirrored(family: Family, without: NDArray[np.float64], change: NDArray[np.float64],
              power: NDArray[np.float64], material: NDArray[np.int64], heldout: Rows
              ) -> tuple[tuple[str, str, float], ...]:
    """(channel, sibling, the sibling's scale) where the effect changes the channel alone and
    the sibling's residual holds at least MIRROR_SHARE of that change, compared in the
    channels' units (each row's sigma undone)."""
    siblings = getattr(family, "sibling_channels", None)
    if not siblings:
        return ()
    channels = family.channels
    sigma = family.in_units(heldout).scale.reshape(-1, len(channels))
    out = []
    for i in material:
        k = siblings[i]
        # about their means: a constant is the sensor's tare, not the joint's torque
        moved = change[:, i] * sigma[:, i]
        moved = moved - moved.mean()
        if k < 0 or power[k] >= MATERIAL_CORRECTION**2 or np.mean(
                (moved / sigma[:, i]) ** 2) < MATERIAL_CORRECTION**2:
            continue  # no sibling, one the effect changes too, or a change that is a tare's
        there = without[:, k] * sigma[:, k]
        shown = float(np.sum((there - there.mean()) * moved) / np.sum(moved**2))
        if shown >= MIRROR_SHARE:
            out.append((channels[i], channels[k], shown))
    return tuple(out)
