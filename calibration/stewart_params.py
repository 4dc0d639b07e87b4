"""Identified Stewart parameters on disk: what `serpar calibrate stewart --out` writes and the
episode's step-5 model reads (the 42 parameters of seed 000: per leg dl, dP xyz, dB xyz)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from serpar.errors import ConfigError
from serpar.sim.stewart import MAX_JOINT_ERROR

FORMAT = "serpar-stewart-parameters"
VERSION = 1
COLUMNS = ("dl", "dPx", "dPy", "dPz", "dBx", "dBy", "dBz")


def save_stewart_parameters(path: str | Path, errors: np.ndarray, info: dict | None = None) -> Path:
    errors = _checked(np.asarray(errors, float), str(path))
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(f".{out.name}.{os.getpid()}.partial")  # a reader never sees half a file
    partial.write_text(json.dumps({"format": FORMAT, "version": VERSION, "units": "m", "columns": COLUMNS,
                                   "joint_errors": errors.tolist(), "info": info or {}}, indent=1))
    os.replace(partial, out)
    return out


def load_stewart_parameters(path: str | Path) -> np.ndarray:
    """(6, 7) identified errors [m]; ConfigError naming what is wrong with the file."""
    try:
        d = json.loads(Path(path).read_text())
    except OSError as exc:
        raise ConfigError(f"stewart_calibration {path}: cannot read ({exc.strerror})") from None
    except ValueError as exc:
        raise ConfigError(f"stewart_calibration {path}: not JSON ({exc})") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT or d.get("version") != VERSION:
        raise ConfigError(f"stewart_calibration {path}: not a {FORMAT} v{VERSION} file "
                          "(write one with `serpar calibrate stewart --out`)")
    return _checked(np.asarray(d.get("joint_errors"), float), str(path))


def _checked(errors: np.ndarray, where: str) -> np.ndarray:
    if errors.shape != (6, len(COLUMNS)) or not np.all(np.isfinite(errors)):
        raise ConfigError(f"stewart_calibration {where}: joint_errors must be 6 rows of "
                          f"{', '.join(COLUMNS)} [m], finite")
    if np.max(np.abs(errors)) > MAX_JOINT_ERROR:
        raise ConfigError(f"stewart_calibration {where}: an error exceeds {MAX_JOINT_ERROR * 1e3:g} mm")
    return errors
