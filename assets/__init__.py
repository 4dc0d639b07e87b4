"""Per-object model data shipped with serpar (one folder per physical thing).

Each folder has a README saying where its numbers come from. Python code that
turns these numbers into MuJoCo specs lives in :mod:`sim`.
"""

from pathlib import Path

ASSETS_DIR = Path(__file__).resolve().parent


def asset_path(*parts: str) -> Path:
    """Absolute path of a file inside the assets package."""
    return ASSETS_DIR.joinpath(*parts)
