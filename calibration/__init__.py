"""Calibration of the cell: identification maths (arm MD-H/POE with seed 003's gravity-aware
model, Stewart 42-parameter TLS/LM/PSO) and the in-cell campaigns that feed it (camera pairs
from board views, the Stewart platform from motion capture or the top stereo pair, the arm from
laser-tracker / point-consistency sets), with the on-disk caches a real cell would keep."""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)
