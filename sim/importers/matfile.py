"""MATLAB .mat files (v4 to v7; scipy.io): every numeric variable of the common length is a
column (a matrix of k columns is ``<name>.1``..``<name>.k``, samples along its longer side);
anything else (scalars, text, structs, other lengths) is passed over with a note. NumPy .npz
files (npzfile.py) are read into a table the same way (:func:`numeric_table`)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import scipy.io
from numpy.typing import NDArray

from serpar.sim.importers.tables import RawTable
from serpar.sim.recording import RecordingError


def _columns(name: str, value: NDArray) -> dict[str, NDArray] | None:
    if value.dtype.kind not in "iuf" or value.ndim > 2 or value.size < 2:
        return None
    v = np.asarray(value, float)
    if v.ndim == 2 and min(v.shape) == 1:
        v = v.ravel()
    if v.ndim == 1:
        return {name: v}
    if v.shape[0] < v.shape[1]:
        v = v.T  # samples along the longer side
    return {f"{name}.{k + 1}": v[:, k] for k in range(v.shape[1])}


def read_mat(path: str | Path) -> RawTable:
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path} does not exist")
    try:
        data = scipy.io.loadmat(path)
    except NotImplementedError:
        raise RecordingError(f"{path} is a MATLAB v7.3 (HDF5) file; save it with "
                             "save(..., '-v7') or export the variables as CSV") from None
    except (ValueError, OSError) as exc:
        raise RecordingError(f"{path} is not a readable .mat file ({exc})") from None
    return numeric_table(path, {k: v for k, v in data.items() if not k.startswith("__")})


def numeric_table(path: Path, data: dict[str, object], word: str = "variable") -> RawTable:
    """Named arrays (a .mat file's variables, a .npz file's arrays) as one table: each numeric
    vector a column, a matrix ``<name>.1..k``; the rest passed over with a note."""
    found = {k: c for k, v in data.items() if (c := _columns(k, np.asarray(v))) is not None}
    notes = [f"{path.name}: {word} {k!r} is not a numeric vector or matrix: not imported"
             for k in data if k not in found]
    if not found:
        raise RecordingError(f"{path} holds no numeric vector or matrix; {word}s: "
                             f"{', '.join(data) or 'none'}")
    length = Counter(len(next(iter(c.values()))) for c in found.values()).most_common(1)[0][0]
    columns: dict[str, NDArray] = {}
    for k, c in found.items():
        n = len(next(iter(c.values())))
        if n == length:
            columns.update(c)
        else:
            notes.append(f"{path.name}: {word} {k!r} has {n} samples, the others {length}: "
                         "not imported")
    return RawTable(str(path), columns, "row", 1, None, tuple(notes))
