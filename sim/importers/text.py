"""Text tables: comma, tab, semicolon or whitespace separated, with or without a header row;
a file of one unnamed column (one value per line) is named after the file. Blank lines and
lines starting with ``#`` or ``%`` are passed over."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from serpar.sim.importers.tables import RawTable
from serpar.sim.recording import RecordingError

DELIMITERS = (",", "\t", ";")
COMMENT = ("#", "%")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    return [f.strip() for f in next(csv.reader(io.StringIO(line), delimiter=delimiter))]


def read_text(path: str | Path) -> RawTable:
    """One text file as a raw table (fields kept as text; assemble.py parses numbers, so an
    error names the line)."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path} does not exist")
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise RecordingError(f"{path} is not a text file (not UTF-8); binary formats: .mat, "
                             "a ROS 2 bag folder or .mcap") from None
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1)
             if ln.strip() and not ln.lstrip().startswith(COMMENT)]
    if not lines:
        raise RecordingError(f"{path} holds no data lines")
    first = lines[0][1]
    delimiter = next((d for d in DELIMITERS if d in first), None)
    fields = _split(first, delimiter)
    has_header = not all(_is_number(f) for f in fields)
    if has_header:
        names = fields
        body = lines[1:]
        if len(set(names)) != len(names):
            raise RecordingError(f"{path} line {lines[0][0]}: column names repeat ({', '.join(names)})")
    else:
        names = [path.stem] if len(fields) == 1 else [f"{path.stem}.{k + 1}" for k in range(len(fields))]
        body = lines
    if not body:
        raise RecordingError(f"{path} has a header but no data rows")
    rows = []
    for n, ln in body:
        row = _split(ln, delimiter)
        if len(row) != len(names):
            raise RecordingError(f"{path} line {n}: {len(row)} fields, expected {len(names)} "
                                 f"({'the header has' if has_header else 'the first line has'} "
                                 f"{len(names)})")
        rows.append(row)
    cells = np.array(rows, dtype=object)
    labels = np.array([n for n, _ in body], dtype=np.int64)
    return RawTable(str(path), {name: cells[:, k] for k, name in enumerate(names)}, "line",
                    int(labels[0]), labels)
