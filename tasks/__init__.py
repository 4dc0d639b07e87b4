"""The six-step assembly task of seed 000 §5.2: the episode config, the steps of a hole cycle,
the episode loop, its recorder and the runners (serial, worker processes, Ray)."""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)
