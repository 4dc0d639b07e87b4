"""Loader of the ``panda_1`` point-consistency layout (``../shared/realdata/README.md``).

Layout: one folder per placement of the two-socket calibration tool
(``front/``, ``right/``, ``back-high/`` in the real data), each holding ``hole_0.csv`` and
``hole_1.csv``: one arm configuration per row, seven joint angles in radians (joint 1
first), no header. The sockets' centres are :data:`SOCKET_DISTANCE_M` apart.

Every row and every folder is used or the load fails with what is wrong: a folder without
both socket files, a stray file, a row that is not seven finite numbers, a socket with too
few rows. Nothing is dropped.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError
from serpar.sim.arm import N_JOINTS
from serpar.sim.arm_measurements import PointSet

SOCKET_FILES = ("hole_0.csv", "hole_1.csv")
SOCKET_DISTANCE_M = 0.050
MIN_ROWS = 3
"""Fewer configurations than this cannot show a socket's spread."""
IGNORED_FILES = ("LICENSE", "README.md")


@dataclass(frozen=True)
class PandaPointData:
    """Joint angles per tool placement and socket: ``q[placement][socket]`` is (N, 7)."""

    folder: str
    placements: tuple[str, ...]
    q: tuple[tuple[NDArray[np.float64], ...], ...]

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
                        sigma_distance=sigma, tau_gravity=tau_gravity)

    def joint_angles(self, placements: tuple[str, ...]) -> NDArray[np.float64]:
        return np.vstack([rows for name in placements
                          for rows in self.q[self.placements.index(name)]])


def load_panda_folder(folder: str | Path) -> PandaPointData:
    """Read a panda_1-layout folder; IdentificationError names what is missing or wrong."""
    root = Path(folder)
    if not root.is_dir():
        raise IdentificationError(f"data folder {str(root)!r} does not exist")
    entries = sorted(p for p in root.iterdir() if not p.name.startswith("."))
    stray = [p.name for p in entries if p.is_file() and p.name not in IGNORED_FILES]
    if stray:
        raise IdentificationError(f"{root}: unexpected file(s) {stray}; expected one folder "
                                  f"per tool placement holding {' and '.join(SOCKET_FILES)}")
    dirs = [p for p in entries if p.is_dir()]
    if not dirs:
        raise IdentificationError(f"{root}: no tool-placement folders; expected e.g. "
                                  f"front/{SOCKET_FILES[0]} and front/{SOCKET_FILES[1]}")
    q = []
    for d in dirs:
        names = sorted(p.name for p in d.iterdir() if not p.name.startswith("."))
        missing = [f for f in SOCKET_FILES if f not in names]
        extra = [f for f in names if f not in SOCKET_FILES]
        if missing or extra:
            what = (f"missing {', '.join(missing)}" if missing else "") + \
                   ("; " if missing and extra else "") + \
                   (f"unexpected {', '.join(extra)}" if extra else "")
            raise IdentificationError(f"{d}: {what} (a placement folder holds exactly "
                                      f"{' and '.join(SOCKET_FILES)})")
        q.append(tuple(_read_csv(d / f) for f in SOCKET_FILES))
    return PandaPointData(str(root), tuple(d.name for d in dirs), tuple(q))


def _read_csv(path: Path) -> NDArray[np.float64]:
    rows = []
    with path.open(newline="") as fh:
        for line_no, row in enumerate(csv.reader(fh), start=1):
            if not row or all(not c.strip() for c in row):
                raise IdentificationError(f"{path} line {line_no}: empty row")
            if len(row) != N_JOINTS:
                raise IdentificationError(f"{path} line {line_no}: expected {N_JOINTS} joint "
                                          f"angles, got {len(row)} values")
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
