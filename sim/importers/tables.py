"""A table as read from a file, before it meets the recording schema: named columns of one
length, each numeric (float64, NaN where a field is empty) or text, and how a row is named in
messages (a text file's line, a .mat row, a bag message)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from serpar.sim.recording import RecordingError


@dataclass(frozen=True)
class RawTable:
    source: str
    """The file (or files) read, for messages."""
    columns: dict[str, NDArray]
    """Column name -> values (float64, or object for text as read)."""
    row_word: str = "row"
    first_row: int = 1
    """The label of row 0 (a text file's line number of its first data row)."""
    row_labels: NDArray[np.int64] | None = None
    """Per-row labels when rows are not consecutive (text files with blank or comment lines)."""
    notes: tuple[str, ...] = ()
    """What the reader passed over, in words (nothing is dropped silently)."""

    @property
    def n_rows(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    def where(self, i: int) -> str:
        label = int(self.row_labels[i]) if self.row_labels is not None else i + self.first_row
        return f"{self.source} {self.row_word} {label}"


def combine(tables: Sequence[RawTable]) -> RawTable:
    """Several files as one table (e.g. joints in separate files): the same number of rows in
    each; with more than one file, a column is named ``<file stem>.<column>``, or just the stem
    for a file of one unnamed column."""
    if len(tables) == 1:
        return tables[0]
    counts = {t.source: t.n_rows for t in tables}
    if len(set(counts.values())) > 1:
        listed = ", ".join(f"{Path(s).name}: {n}" for s, n in counts.items())
        raise RecordingError(f"the files have different numbers of rows ({listed}); files read "
                             "side by side must hold the same samples")
    columns: dict[str, NDArray] = {}
    for t in tables:
        stem = Path(t.source).stem
        for name, values in t.columns.items():
            key = name if name == stem or name.startswith(stem + ".") else f"{stem}.{name}"
            if key in columns:
                raise RecordingError(f"two files give column {key!r}; rename one file")
            columns[key] = values
    first = tables[0]
    return RawTable(" + ".join(t.source for t in tables), columns, first.row_word, first.first_row,
                    first.row_labels, tuple(n for t in tables for n in t.notes))
