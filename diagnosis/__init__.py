"""Sim-vs-real discrepancy diagnosis (issue 7): locate where the nominal model and a
recording differ, hypothesise candidate effects, fit and select them on a training split,
score on held-out data, and report.

Public API: the domain contract (:class:`Effect`, :class:`LocateRow`, :class:`Family`);
the engine lives in :mod:`serpar.diagnosis.select`.
"""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)

from serpar.diagnosis.family import Effect, Family, LocateRow

__all__ = ["Effect", "Family", "LocateRow"]
