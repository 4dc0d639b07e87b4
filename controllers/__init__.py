"""Control of the cell: the arm's laws as pure functions, its sensors and wrench estimate,
the Stewart leg servos and plate commander, and the 1 kHz cell runtime that runs them."""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)
