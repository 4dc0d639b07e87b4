"""Concealed-effect twins: recordings of a simulated "real" plant (sim/plants/) with one piece
of physics the nominal model lacks, for the blind bench and the diagnosis tests."""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)
