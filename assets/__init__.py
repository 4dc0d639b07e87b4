"""Per-object model data shipped with serpar (one folder per physical thing).

Each folder has a README saying where its numbers come from. Python code that
turns these numbers into MuJoCo specs lives in :mod:`sim`.
"""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)

from pathlib import Path

ASSETS_DIR = Path(__file__).resolve().parent


def asset_path(*parts: str) -> Path:
    """Absolute path of a file inside the assets package."""
    return ASSETS_DIR.joinpath(*parts)
