"""The held-out residual in physical units (N m, mm, mrad) per channel, next to the whitened
one: what a roboticist judges a fit by.

A family that can say what its residual entries are gives :meth:`in_units` (rows ->
:class:`UnitView`): each whitened entry's channel, the factor that turns it back into the
channel's unit (its noise sigma), where its row lies (time or measurement number) and,
where the family has it, the value the recording shows there. The same rows are held out
before and after the fit, so one view serves both."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Vec = NDArray[np.float64]


@dataclass(frozen=True)
class UnitView:
    channels: tuple[str, ...]
    units: tuple[str, ...]
    """One per channel."""
    channel: NDArray[np.int64]
    """Per residual entry: its index in ``channels``."""
    scale: Vec
    """Per entry: physical value = whitened value x scale (the entry's sigma in its unit)."""
    axis: Vec
    """Per entry: where its row lies (``axis_label``)."""
    axis_label: str
    measured: Vec | None = None
    """Per entry: what the recording shows there, in the channel's unit (None: not defined)."""


@dataclass(frozen=True)
class ChannelRms:
    channel: str
    unit: str
    n: int
    before: float
    after: float

    def as_dict(self) -> dict[str, object]:
        return {"channel": self.channel, "unit": self.unit, "n": self.n,
                "rms_before": self.before, "rms_after": self.after}


@dataclass(frozen=True)
class PhysicalResidual:
    """The held-out residual before and after the fit, in each channel's unit."""

    view: UnitView
    before: Vec
    after: Vec

    @property
    def rms(self) -> tuple[ChannelRms, ...]:
        out = []
        for c, (name, unit) in enumerate(zip(self.view.channels, self.view.units, strict=True)):
            m = self.view.channel == c
            if m.any():
                out.append(ChannelRms(name, unit, int(m.sum()),
                                      float(np.sqrt(np.mean(self.before[m] ** 2))),
                                      float(np.sqrt(np.mean(self.after[m] ** 2)))))
        return tuple(out)

    def as_dict(self) -> list[dict[str, object]]:
        return [r.as_dict() for r in self.rms]


def in_units(family: object, rows: NDArray[np.int64], before: Vec, after: Vec
             ) -> PhysicalResidual | None:
    """The held-out residual in physical units, or None when the family (or the family it
    wraps, ``inner``) has no ``in_units`` hook or its view does not fit the residual."""
    hook = getattr(family, "in_units", None) or getattr(getattr(family, "inner", None),
                                                        "in_units", None)
    if not callable(hook) or len(rows) == 0:
        return None
    view: UnitView = hook(np.asarray(rows, np.int64))
    if view.scale.size != before.size or before.size != after.size:
        return None
    return PhysicalResidual(view, before * view.scale, after * view.scale)


def per_row(rows_axis: Vec, n_channels: int) -> tuple[NDArray[np.int64], Vec]:
    """(channel, axis) per entry of a residual laid out row by row, ``n_channels`` per row."""
    return (np.tile(np.arange(n_channels), len(rows_axis)),
            np.repeat(np.asarray(rows_axis, float), n_channels))


POSE_CHANNELS = ("x", "y", "z", "rx", "ry", "rz")


def pose_view(axis: Vec, axis_label: str, sigma: Vec, pos: Vec, legs: Vec | None = None
              ) -> UnitView:
    """A platform's pose residual per row (position [m], rotation vector [rad], then any leg
    lengths [m]; ``sigma`` rows x channels in those units) in mm and mrad."""
    n = sigma.shape[1]
    names = POSE_CHANNELS + tuple(f"leg {i + 1}" for i in range(n - 6))
    units = ("mm",) * 3 + ("mrad",) * 3 + ("mm",) * (n - 6)
    channel, at = per_row(axis, n)
    measured = np.full(sigma.shape, np.nan)  # a rotation residual has no measured value
    measured[:, :3] = 1e3 * pos
    if legs is not None:
        measured[:, 6:] = 1e3 * legs
    return UnitView(names, units, channel, 1e3 * sigma.ravel(), at, axis_label, measured.ravel())
