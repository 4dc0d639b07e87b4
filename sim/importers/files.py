"""Which reader a file needs, and several files read side by side as one table."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from serpar.sim.importers.matfile import read_mat
from serpar.sim.importers.npzfile import read_npz
from serpar.sim.importers.rosbag import read_rosbag
from serpar.sim.importers.tables import RawTable, combine
from serpar.sim.importers.text import read_text
from serpar.sim.recording import RecordingError

FORMATS = ("auto", "text", "mat", "npz", "rosbag")
READERS = {"mat": read_mat, "npz": read_npz, "text": read_text}


def file_format(path: Path, chosen: str = "auto") -> str:
    """auto: .mat -> mat; .npz -> npz; a bag folder, .db3 or .mcap -> rosbag; anything else
    -> text."""
    if chosen not in FORMATS:
        raise RecordingError(f"format {chosen!r}; valid: {', '.join(FORMATS)}")
    if chosen != "auto":
        return chosen
    if path.suffix.lower() in (".mat", ".npz"):
        return path.suffix.lower()[1:]
    if path.is_dir() or path.suffix.lower() in (".db3", ".mcap"):
        return "rosbag"
    return "text"


def read_files(files: Sequence[str | Path], fmt: str = "auto", topic: str | None = None
               ) -> RawTable:
    if not files:
        raise RecordingError("no file given")
    tables = []
    for f in files:
        path = Path(f)
        kind = file_format(path, fmt)
        if topic is not None and kind != "rosbag":
            raise RecordingError(f"--topic is for a ROS 2 bag; {path} is read as {kind}")
        tables.append(read_rosbag(path, topic) if kind == "rosbag" else READERS[kind](path))
    return combine(tables)
