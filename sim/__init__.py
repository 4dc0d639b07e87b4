"""The cell and its variants in MuJoCo: scene assembly from assets/, physics settings, contact,
sensors, rendering, the recording schema and its I/O, validation; plants/ holds the simulated
"real" machines (friction, backlash, payload, delays) that episodes, twins and diagnosis share."""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)
