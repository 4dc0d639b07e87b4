"""NumPy .npz files: each array is a source column (1-D) or a matrix source (2-D, columns
``<name>.1..k``), read like a .mat file's variables (matfile.numeric_table). Object arrays are
never unpickled: a published file is data, not code to run."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from serpar.sim.importers.matfile import numeric_table
from serpar.sim.importers.tables import RawTable
from serpar.sim.recording import RecordingError


def read_npz(path: str | Path) -> RawTable:
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path} does not exist")
    arrays: dict[str, object] = {}
    try:
        with np.load(path, allow_pickle=False) as data:
            for name in data.files:
                try:
                    arrays[name] = data[name]
                except ValueError:  # an object array (needs pickle): noted as not numeric
                    arrays[name] = None
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise RecordingError(f"{path} is not a readable .npz file ({exc})") from None
    return numeric_table(path, arrays, "array")
