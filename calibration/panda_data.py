"""Loader of the ``panda_1`` point-consistency layout (``../shared/realdata/README.md``).

Layout: one folder per placement of the two-socket calibration tool
(``front/``, ``right/``, ``back-high/`` in the real data), each holding ``hole_0.csv`` and
``hole_1.csv``: one arm configuration per row, one joint angle per joint in radians (joint 1
first; seven for the Panda, the default arm), no header. The sockets' centres are
:data:`SOCKET_DISTANCE_M` apart.

Every row of every socket file is used or the load fails with what is wrong: a placement
folder with one socket file but not the other, a row that is not one finite number per joint, a
socket with too few rows, no placement folder at all. What published folders carry besides
(``hole_0_pose.csv``, ``comments.txt``, a ``photos/`` folder without socket files) is not
read, and each such file or folder is named in :attr:`PandaPointData.notes`, so nothing is
dropped unsaid.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError
from serpar.kinematics.robot import PANDA, Robot
from serpar.sim.arm_measurements import PointSet

SOCKET_FILES = ("hole_0.csv", "hole_1.csv")
SOCKET_DISTANCE_M = 0.050
MIN_ROWS = 3
"""Fewer configurations than this cannot show a socket's spread."""
IGNORED_FILES = ("LICENSE", "README.md")
"""Top-level files a published folder is expected to carry: skipped without a note."""
READ_FOR = f"a placement folder is read for {' and '.join(SOCKET_FILES)}"


@dataclass(frozen=True)
class PandaPointData:
    """Joint angles per tool placement and socket: ``q[placement][socket]`` is (N, 7)."""

    folder: str
    placements: tuple[str, ...]
    q: tuple[tuple[NDArray[np.float64], ...], ...]
    notes: tuple[str, ...] = ()
    """One line per file or folder of the data folder that was not read, and why."""
    robot: Robot = PANDA
    """The arm the rows' joint angles belong to (its joint count and limits)."""

    def point_set(self, placements: tuple[str, ...], sigma: float = 50e-6,
                  tau_gravity: NDArray[np.float64] | None = None) -> PointSet:
        """The named placements as one point-consistency set: two sockets each, the fixture
        distance between the two of every placement. ``tau_gravity`` rows follow the order
        of :meth:`joint_angles`."""
        unknown = [p for p in placements if p not in self.placements]
        if unknown:
            raise IdentificationError(f"unknown tool placement(s) {unknown}; valid: "
                                      f"{', '.join(self.placements)}")
        q, point, distances = [], [], []
        for k, name in enumerate(placements):
            for s, rows in enumerate(self.q[self.placements.index(name)]):
                q.append(rows)
                point.append(np.full(len(rows), 2 * k + s))
            distances.append((2 * k, 2 * k + 1, SOCKET_DISTANCE_M))
        return PointSet(np.vstack(q), np.concatenate(point), tuple(distances), sigma=sigma,
                        sigma_distance=sigma, tau_gravity=tau_gravity, robot=self.robot)

    def joint_angles(self, placements: tuple[str, ...]) -> NDArray[np.float64]:
        return np.vstack([rows for name in placements
                          for rows in self.q[self.placements.index(name)]])


def load_panda_folder(folder: str | Path, robot: Robot = PANDA) -> PandaPointData:
    """Read a panda_1-layout folder of ``robot``'s joint angles (one per joint a row);
    IdentificationError names what is missing or wrong. Files and folders that are not
    socket files are skipped and named in ``notes``."""
    root = Path(folder)
    if not root.is_dir():
        raise IdentificationError(f"data folder {str(root)!r} does not exist")
    entries = _visible(root)
    notes = [_ignored(root, p, "not a socket file") for p in entries
             if p.is_file() and p.name not in IGNORED_FILES]
    placements, q = [], []
    for d in (p for p in entries if p.is_dir()):
        names = {p.name for p in _visible(d) if p.is_file()}
        if not names & set(SOCKET_FILES):
            # photos/, scans/...: a folder of the publication, not a tool placement
            notes.append(_ignored(root, d, "no socket file in it"))
            continue
        missing = [f for f in SOCKET_FILES if f not in names]
        if missing:
            raise IdentificationError(f"{d}: missing {', '.join(missing)} (a placement folder "
                                      f"holds {' and '.join(SOCKET_FILES)})")
        notes.extend(_ignored(root, p, "not a socket file") for p in _visible(d)
                     if p.name not in SOCKET_FILES or not p.is_file())
        placements.append(d.name)
        q.append(tuple(_read_csv(d / f, robot) for f in SOCKET_FILES))
    if not placements:
        seen = [_rel(root, p) for p in entries if p.name not in IGNORED_FILES]
        skipped = f" (ignored: {', '.join(seen)})" if seen else ""
        raise IdentificationError(f"{root}: no tool-placement folders{skipped}; expected e.g. "
                                  f"front/{SOCKET_FILES[0]} and front/{SOCKET_FILES[1]}")
    return PandaPointData(str(root), tuple(placements), tuple(q), tuple(notes), robot)


def _visible(folder: Path) -> list[Path]:
    """A folder's entries in name order; hidden ones (.DS_Store, .git) are not the data's."""
    return sorted(p for p in folder.iterdir() if not p.name.startswith("."))


def _rel(root: Path, path: Path) -> str:
    """``path`` as the user sees it inside the data folder; a folder ends in ``/``."""
    return path.relative_to(root).as_posix() + ("/" if path.is_dir() else "")


def _ignored(root: Path, path: Path, why: str) -> str:
    return f"ignored {_rel(root, path)}: {why} ({READ_FOR})"


def _read_csv(path: Path, robot: Robot) -> NDArray[np.float64]:
    rows = []
    with path.open(newline="") as fh:
        for line_no, row in enumerate(csv.reader(fh), start=1):
            if not row or all(not c.strip() for c in row):
                raise IdentificationError(f"{path} line {line_no}: empty row")
            if len(row) != robot.n_joints:
                raise IdentificationError(f"{path} line {line_no}: expected {robot.n_joints} "
                                          f"joint angles ({robot.label}), got {len(row)} values"
                                          f"{robot.other_arm_hint}")
            try:
                values = [float(c) for c in row]
            except ValueError:
                raise IdentificationError(f"{path} line {line_no}: not a number in {row} "
                                          "(no header expected)") from None
            if not np.all(np.isfinite(values)):
                raise IdentificationError(f"{path} line {line_no}: NaN or infinite angle")
            rows.append(values)
    if len(rows) < MIN_ROWS:
        raise IdentificationError(f"{path}: {len(rows)} configuration(s); need at least "
                                  f"{MIN_ROWS} per socket")
    return np.asarray(rows)
