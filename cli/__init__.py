"""The ``serpar`` command line (``serpar`` / ``python -m serpar``): parse arguments, call into the
packages, print. No physics here."""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)

from serpar.cli.entry import main

__all__ = ["main"]
