"""Exceptions of the :mod:`identify` package: one base class, messages say what is missing."""

from sim.errors import SimError


class IdentificationError(SimError, ValueError):
    """Measurements that cannot identify the model: too few, non-finite, wrong shape, or a
    pose set that leaves parameter combinations unidentifiable."""
