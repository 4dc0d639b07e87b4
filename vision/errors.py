"""Exceptions of :mod:`vision`: one base class; each failure is typed so the task loop can act on it."""

from __future__ import annotations

from serpar.errors import SerparError


class VisionError(SerparError):
    """Base class for every error raised by :mod:`vision`."""


class ImageError(VisionError, ValueError):
    """An image of the wrong size, type or channel count."""


class TargetNotFound(VisionError):
    """The calibration target was not detected in an image (or in too few images)."""


class PlateNotFound(VisionError):
    """The baseplate's hole grid could not be recovered from the images."""


class HoleNotVisible(VisionError):
    """A hole the caller asked about is out of view or occluded in at least one camera."""

    def __init__(self, hole: int, reason: str) -> None:
        self.hole = hole
        super().__init__(f"hole {hole} cannot be seen: {reason}")


class ConductorNotInView(VisionError):
    """No conductor (or not the expected one) where the step looked for it."""


class CalibrationError(VisionError):
    """A calibration step failed to converge or produced an implausible result."""
