"""The ``measurements`` table of a recording as static arm data (docs/recording.md).

Columns (one row per measured arm configuration):

- ``q1..qn`` commanded joint angles [rad] (what the encoders report at rest), one per joint of
  the arm (the Panda's seven unless ``--robot`` names another), required;
- ``kind``: ``position`` (a laser tracker saw the tool point at ``x, y, z`` [m], tracker
  frame) or ``point`` (the tool point sat in socket ``socket``, centre unknown); one kind per
  recording;
- optional ``time`` [s] (when the pose was measured), ``approach1..n`` (+1 / -1: the sign of
  each joint's last motion before the pose), ``set`` (``train`` / ``verify``: the campaign's
  own calibration and verification poses), ``placement`` (which fixture placement a socket
  belongs to).

Noise and the nominal tool live in ``meta.model["measurements"]``: ``sigma_m`` (per axis),
``distances`` ([[socket a, socket b, metres]...]), ``tool_offset_m`` (nominal tool point in the
flange frame), ``tool_mass_kg`` (for the nominal gravity torques).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
from numpy.typing import NDArray

from serpar.calibration.panda_data import SOCKET_DISTANCE_M, PandaPointData, load_panda_folder
from serpar.errors import IdentificationError
from serpar.kinematics.robot import PANDA, Robot
from serpar.sim.arm_measurements import PointSet, PositionSet
from serpar.sim.channels import (
    APPROACH,
    MEASUREMENT_HELP,
    MEASUREMENT_KINDS,
    MEASUREMENT_OPTIONAL,
    MEASUREMENT_REQUIRED,
    MEASUREMENT_SETS,
    Q,
    numbered,
)
from serpar.sim.recording import Recording, RecordingMeta

KINDS, SETS = MEASUREMENT_KINDS, MEASUREMENT_SETS
Q_COLS, APPROACH_COLS, COLUMNS_HELP = Q, APPROACH, MEASUREMENT_HELP
_JOINT_COLUMN = re.compile(r"(q|approach)(\d+)")


def columns(robot: Robot) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...], str]:
    """(joint-angle columns, approach columns, every known column, help) for ``robot``."""
    if robot.n_joints == len(Q_COLS):
        q, approach = Q_COLS, APPROACH_COLS
        known = (*MEASUREMENT_REQUIRED, *MEASUREMENT_OPTIONAL)
        return q, approach, known, COLUMNS_HELP
    n = robot.n_joints
    q, approach = numbered("q", n), numbered("approach", n)
    rest = tuple(c for c in (*MEASUREMENT_REQUIRED, *MEASUREMENT_OPTIONAL)
                 if not _JOINT_COLUMN.fullmatch(c))
    help_ = COLUMNS_HELP.replace("q1..q7", f"q1..q{n}").replace("approach1..7", f"approach1..{n}")
    return q, approach, (*q, *approach, *rest), help_


@dataclass(frozen=True)
class StaticArmData:
    q: NDArray[np.float64]
    kind: str
    sigma_m: float
    position: NDArray[np.float64] | None = None
    socket: NDArray[np.int64] | None = None
    distances: tuple[tuple[int, int, float], ...] = ()
    time: NDArray[np.float64] | None = None
    approach: NDArray[np.float64] | None = None
    split: NDArray[np.str_] | None = None
    placement: NDArray[np.str_] | None = None
    tool_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tool_mass_kg: float = 0.0
    hand: bool = False
    """Whether the nominal gravity model carries the Franka Hand (its mass loads the joints)."""
    robot: Robot = PANDA
    """The arm measured: its joint count and limits check ``q``, its chain is the nominal."""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise IdentificationError(f"measurement kind {self.kind!r}; valid: {', '.join(KINDS)}")
        # the calibration types validate shapes, NaNs, joint ranges and reach, one line each
        if self.kind == "position":
            if self.position is None:
                raise IdentificationError("position measurements need columns x, y, z [m]")
            PositionSet(self.q, self.position, self.sigma_m, robot=self.robot)
        else:
            if self.socket is None:
                raise IdentificationError("point measurements need a socket column")
            PointSet(self.q, np.asarray(self.socket, np.int64), self.distances, self.sigma_m,
                     self.sigma_m, robot=self.robot)
        n = len(self.q)
        if self.time is not None and (self.time.shape != (n,) or not np.all(np.isfinite(self.time))):
            raise IdentificationError("measurement time must be one finite value [s] per row")
        if self.approach is not None:
            a = np.asarray(self.approach)
            nj = self.robot.n_joints
            if a.shape != (n, nj) or not np.all(np.isin(a, (-1.0, 1.0))):
                raise IdentificationError(f"approach1..{nj} must be +1 or -1 in every row")
        if self.split is not None:
            bad = sorted(set(self.split.tolist()) - set(SETS))
            if bad:
                raise IdentificationError(f"set values {bad}; valid: {', '.join(SETS)}")

    @property
    def n(self) -> int:
        return len(self.q)


def _col(table: pa.Table, name: str) -> NDArray:
    return table.column(name).to_numpy(zero_copy_only=False)


def static_data(rec: Recording, robot: Robot = PANDA) -> StaticArmData:
    """The static arm data of a recording of ``robot``; IdentificationError names what is
    missing, or a joint count that is not the robot's."""
    table = rec.measurements
    if table is None or table.num_rows == 0:
        raise IdentificationError("the recording has no measurements table")
    cols = table.column_names
    q_cols, approach_cols, known, help_ = columns(robot)
    joints = sorted(int(m.group(2)) for c in cols if (m := _JOINT_COLUMN.fullmatch(c))
                    and m.group(1) == "q")
    if joints and joints == list(range(1, len(joints) + 1)) and len(joints) != robot.n_joints:
        raise IdentificationError(
            f"the measurements have joint-angle columns {', '.join(f'q{j}' for j in joints)}; "
            f"{robot.label} has {robot.n_joints} joints (q1..q{robot.n_joints}); give --robot "
            "the arm that was measured")
    unknown = [c for c in cols if c not in known]
    if unknown:
        raise IdentificationError(f"unknown measurement column(s) {', '.join(unknown)}; "
                                  f"valid: {help_}")
    missing = [c for c in (*q_cols, "kind") if c not in cols]
    if missing:
        raise IdentificationError(f"measurements lack column(s) {', '.join(missing)}; "
                                  f"needed: {help_}")
    kinds = sorted(set(_col(table, "kind").tolist()))
    if len(kinds) != 1:
        raise IdentificationError(f"measurements mix kinds {kinds}; one kind per recording "
                                  f"({', '.join(KINDS)})")
    meta = dict(rec.meta.model.get("measurements", {}))  # type: ignore[arg-type]
    q = np.column_stack([_col(table, c).astype(float) for c in q_cols])
    pos = (np.column_stack([_col(table, c).astype(float) for c in "xyz"])
           if kinds[0] == "position" and all(c in cols for c in "xyz") else None)
    approach = (np.column_stack([_col(table, c).astype(float) for c in approach_cols])
                if all(c in cols for c in approach_cols) else None)
    return StaticArmData(
        q=q, kind=kinds[0], sigma_m=float(meta.get("sigma_m", 50e-6)), position=pos,
        socket=_col(table, "socket").astype(np.int64) if "socket" in cols else None,
        distances=tuple((int(a), int(b), float(d)) for a, b, d in meta.get("distances", [])),
        time=_col(table, "time").astype(float) if "time" in cols else None,
        approach=approach,
        split=_col(table, "set").astype(str) if "set" in cols else None,
        placement=_col(table, "placement").astype(str) if "placement" in cols else None,
        tool_offset_m=tuple(float(v) for v in meta.get("tool_offset_m", (0.0, 0.0, 0.0))),
        tool_mass_kg=float(meta.get("tool_mass_kg", 0.0)), hand=bool(meta.get("hand", False)),
        robot=robot)


def to_recording(data: StaticArmData, source: str, notes: dict[str, object] | None = None
                 ) -> Recording:
    """A measurement-only recording (its signals table holds an empty ``time`` column)."""
    q_cols, approach_cols, _, _ = columns(data.robot)
    cols: dict[str, pa.Array] = {c: pa.array(data.q[:, j]) for j, c in enumerate(q_cols)}
    cols["kind"] = pa.array([data.kind] * data.n)
    if data.position is not None:
        cols.update({c: pa.array(data.position[:, i]) for i, c in enumerate("xyz")})
    if data.socket is not None:
        cols["socket"] = pa.array(np.asarray(data.socket, np.int64))
    if data.time is not None:
        cols["time"] = pa.array(data.time)
    if data.approach is not None:
        cols.update({c: pa.array(data.approach[:, j]) for j, c in enumerate(approach_cols)})
    if data.split is not None:
        cols["set"] = pa.array(data.split.tolist())
    if data.placement is not None:
        cols["placement"] = pa.array(data.placement.tolist())
    model = {"measurements": {"sigma_m": data.sigma_m,
                              "distances": [list(d) for d in data.distances],
                              "tool_offset_m": list(data.tool_offset_m),
                              "tool_mass_kg": data.tool_mass_kg, "hand": data.hand},
             **({} if data.robot is PANDA else
                {"robot": {"name": data.robot.name, "source": data.robot.source}}),
             **(notes or {})}
    meta = RecordingMeta(source=source, sample_rate_hz=1.0, channels=("time",), model=model)
    return Recording(meta, pa.table({"time": pa.array(np.zeros(0))}), pa.table(cols))


def panda_folder_data(folder: str | PandaPointData, sigma_m: float = 50e-6) -> StaticArmData:
    """A panda_1-layout folder (serpar.calibration.panda_data), or its data already loaded
    (whose notes the caller reports), as point data with a placement column."""
    raw = folder if isinstance(folder, PandaPointData) else load_panda_folder(folder)
    q, sock, place, dist = [], [], [], []
    for k, name in enumerate(raw.placements):
        for s, rows in enumerate(raw.q[k]):
            q.append(rows)
            sock.append(np.full(len(rows), 2 * k + s))
            place.extend([name] * len(rows))
        dist.append((2 * k, 2 * k + 1, SOCKET_DISTANCE_M))
    return StaticArmData(np.vstack(q), "point", sigma_m, socket=np.concatenate(sock),
                         distances=tuple(dist), placement=np.asarray(place), robot=raw.robot)
