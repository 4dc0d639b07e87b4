"""Sim-vs-real discrepancy diagnosis (issue 7): locate where the nominal model and a
recording differ, hypothesise candidate effects, fit and select them on a training split,
score on held-out data, and report.

Public API: the domain contract (:class:`Effect`, :class:`LocateRow`, :class:`Family`);
the engine lives in :mod:`identify.diagnosis.select`.
"""

from identify.diagnosis.family import Effect, Family, LocateRow

__all__ = ["Effect", "Family", "LocateRow"]
