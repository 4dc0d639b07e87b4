"""Measurements that reproduce the seeds' figures and serpar's own: controller, Stewart and vision
checks with their test scenes, benchmarks, the ablation table, the workspace Monte Carlo, seed
001's error analysis and the diagnosis blind bench."""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)
